"""Stage `hough_report`: agreement of our lines with OpenCV's, time ratio, truth recall, and overlays of both."""

import argparse
import math
from pathlib import Path

import numpy as np

from cvpipe import hough, io
from cvpipe.params import HoughReportParams, load_section

#: strongest lines drawn per overlay (all of them still count in the metrics)
MAX_DRAWN = 60


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--images", required=True, help="folder of the sample images (data/samples/hough)")
    ap.add_argument("--truth", required=True, help="data/samples/hough/truth.json")
    ap.add_argument("--ours", required=True, help="outputs of hough_lines@ours")
    ap.add_argument("--opencv", required=True, help="outputs of hough_lines@opencv")
    ap.add_argument("--overlays", required=True, help="folder for <name>.png: ours (left, red), OpenCV (right, green)")
    ap.add_argument("--metrics", required=True, help="metrics JSON")
    ap.add_argument("--summary", required=True, help="summary JSON for the report page")
    ap.add_argument("--plots", required=True, help="folder for dvc plots data (times.json)")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(HoughReportParams, "hough.report", args.params)
    ours, opencv = io.load_json(args.ours), io.load_json(args.opencv)
    metrics = hough.compare_runs(ours, opencv, io.load_json(args.truth), p.rho_tol, math.radians(p.theta_tol_deg))
    metrics["first_call_seconds_ours"] = ours.get("first_call_seconds")
    ref = {Path(i["file"]).stem: i["lines"] for i in opencv["images"]}
    pictures = []
    for f in io.list_images(args.images):
        mine = [i["lines"] for i in ours["images"] if Path(i["file"]).stem == f.stem]
        if not mine:
            continue
        img = io.read_image(f, "color")
        left = hough.draw_lines(img, np.asarray(mine[0])[:MAX_DRAWN], (0, 0, 255))
        right = hough.draw_lines(img, np.asarray(ref[f.stem])[:MAX_DRAWN], (0, 255, 0))
        path = Path(args.overlays) / f"{f.stem}.png"
        io.save_image(path, np.hstack([left, right]))
        pictures.append({"path": path.as_posix(), "caption": f"{f.stem}: ours (red, left), OpenCV (green, right)"})
    io.save_json(args.metrics, metrics)
    io.save_json(args.summary, hough.report_summary(metrics, ours, opencv, pictures[:12]))
    io.save_json(Path(args.plots) / "times.json", hough.time_plot(ours, opencv))


if __name__ == "__main__":
    main()
