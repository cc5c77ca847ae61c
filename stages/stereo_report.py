"""Stage `stereo_report`: comparison table, colour-mapped disparities and error maps of every method."""

import argparse
from pathlib import Path

import numpy as np

from cvpipe import io, stereo
from cvpipe.params import StereoReportParams, load_section

COLUMNS = ["method", "bad-1.0 %", "bad-2.0 %", "mean error px", "density %", "seconds"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--inputs", required=True, help="outputs/stereo, holding <method>/disparity.npy + metrics.json")
    ap.add_argument("--samples", required=True, help="data/samples/stereo")
    ap.add_argument("--out", required=True, help="folder for the pictures and table.md")
    ap.add_argument("--summary", required=True, help="summary.json for the report page")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(StereoReportParams, "stereo.report", args.params)
    inputs, samples, out = Path(args.inputs), Path(args.samples), Path(args.out)
    truth = io.load_npz(samples / "truth.npz")["disparity"]
    max_disp = int(io.load_json(samples / "truth.json")["max_disp"])

    pictures = [{"path": (out / "truth.png").as_posix(), "caption": "true disparity (black = unknown)"}]
    io.save_image(out / "truth.png", stereo.colorize_disparity(truth, max_disp))
    rows, timings = [], {}
    for method in stereo.METHODS:
        disp = np.load(inputs / method / "disparity.npy", allow_pickle=False)
        m = io.load_json(inputs / method / "metrics.json")
        rows.append([method, 100 * m["bad_1.0"], 100 * m["bad_2.0"], m["mean_error"], 100 * m["density"],
                     m["seconds"]])
        timings[method] = m["seconds"]
        for kind, pic, caption in (
            ("disparity", stereo.colorize_disparity(disp, max_disp), "disparity (black = none)"),
            ("error", stereo.error_picture(disp, truth, p.error_clip),
             f"|error|, white >= {p.error_clip:g} px, blue = missing, grey = unknown truth"),
        ):
            path = out / f"{method}_{kind}.png"
            io.save_image(path, pic)
            pictures.append({"path": path.as_posix(), "caption": f"{method}: {caption}"})

    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(r[0:1] + [f"{v:.3f}" for v in r[1:]]) + " |" for r in rows]
    with io.atomic_path(out / "table.md") as tmp:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    io.save_json(args.summary, {
        "task": "stereo", "title": "Disparity of a rectified pair: our semi-global matching vs OpenCV BM / SGBM",
        "description": "Middlebury motorcycle pair (scikit-image), true disparity known. A pixel is bad when its "
                       "estimate is missing or off by more than the threshold, over all pixels with known truth; "
                       "mean error is over pixels with an estimate; time excludes the numba compile.",
        "pictures": pictures, "tables": [{"title": "Accuracy and time", "columns": COLUMNS, "rows": rows}],
        "timings": timings})


if __name__ == "__main__":
    main()
