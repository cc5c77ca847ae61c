"""Stage `homography_report`: corner error against the truth, inliers and time per method, and one picture per
pair (B warped onto A, checkerboard, one panel per method) so misalignment is visible."""

import argparse
from pathlib import Path

from cvpipe import io
from cvpipe.homography import alignment_panel, report_summary, summarize_methods
from cvpipe.params import HomographyReportParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--truth", required=True, help="data/samples/homography/truth.json")
    ap.add_argument("--images", required=True, help="folder with the pair images")
    ap.add_argument("--estimates", required=True, nargs="+", help="estimate folders, one per method")
    ap.add_argument("--metrics", required=True, help="output metrics JSON (per method)")
    ap.add_argument("--out", required=True, help="folder for per-pair results and pictures")
    ap.add_argument("--summary", required=True, help="summary JSON for the report page")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(HomographyReportParams, "homography.report", args.params)
    truth = io.load_json(args.truth)["pairs"]
    runs = {}
    for folder in args.estimates:
        est = io.load_json(Path(folder) / "estimates.json")
        runs[est["method"]] = est["pairs"]
    metrics, per_pair = summarize_methods(truth, runs, p.success_px)
    out, pictures = Path(args.out), []
    for q in truth:
        io.safe_name(q["name"], f"{args.truth}: pair name")
        a = io.read_image(Path(args.images) / q["a"], "color")
        b = io.read_image(Path(args.images) / q["b"], "color")
        panels = {"truth": q["H"]}
        for method, pairs in runs.items():
            err = per_pair[q["name"]][method]["corner_error_px"]
            label = f"{method} {err:.2f} px" if err is not None else f"{method} failed"
            panels[label] = pairs[q["name"]]["H"]
        io.save_image(out / f"{q['name']}.png", alignment_panel(a, b, panels, p.checker_tiles))
        pictures.append({"path": (out / f"{q['name']}.png").as_posix(),
                         "caption": f"{q['name']}: B warped onto A (checkerboard): truth, then each method"})
    io.save_json(out / "pairs.json", per_pair)
    io.save_json(args.metrics, metrics)
    io.save_json(args.summary, report_summary(metrics, per_pair, pictures, p.success_px))


if __name__ == "__main__":
    main()
