"""Stage `stereo_report`: per pair one picture of the methods side by side (and, for pairs with a truth.npz, the true
disparity and each method's error map), the comparison tables and the quality plots (bad-2.0 where there is truth,
the valid fraction for every pair)."""

from pathlib import Path

import numpy as np

from cvpipe import datasets, io, stereo
from stages._runner import Stage, run
from stages.stereo_disparity import read_truth


def stereo_report(st: Stage) -> None:
    p, a = st.params, st.args
    pairs, _ = datasets.find_stereo(a.pairs)  # what it drops, stereo_disparity recorded
    runs = {}
    for folder in a.disparities:
        r = io.load_json(Path(folder) / "run.json")
        runs[r["method"]] = {**r, "folder": Path(folder)}
    out, pictures = Path(a.out), []
    for pair in st.progress([q for q in pairs if any(q.name in r["pairs"] for r in runs.values())], "stereo pictures"):
        left = io.read_image(pair.left)
        max_disp = next(r["pairs"][pair.name]["max_disp"] for r in runs.values() if pair.name in r["pairs"])
        disps = {m: (np.load(r["folder"] / pair.name / "disparity.npy", allow_pickle=False)
                     if pair.name in r["pairs"] else None) for m, r in runs.items()}
        truth = read_truth(pair.truth, left.shape[:2]) if pair.truth is not None else None
        path = out / f"{pair.name}.png"
        io.save_image(path, stereo.comparison_picture(left, disps, max_disp, truth, p.error_clip))
        what = "top: left image and each method's disparity; bottom: true disparity and each method's |error|" \
            if truth is not None else "left image and each method's disparity (no ground truth)"
        pictures.append({"path": path.as_posix(), "caption": f"{pair.name} (max_disp {max_disp}): {what}"})
    dropped = stereo.merge_dropped(runs)
    io.save_json(a.summary, stereo.report_summary(runs, pictures, dropped, p.error_clip))
    for name, rows in stereo.quality_plots(runs).items():
        io.save_json(Path(a.plots) / f"{name}.json", rows)
    st.made(f"{len(pictures)} pairs compared over {len(runs)} methods, pictures in {out}")
    for d in dropped:
        st.drop(d["item"], d["reason"])


if __name__ == "__main__":
    run(stereo_report, section="stereo.report",
        args={"pairs": "the stereo.data folder", "disparities": "+stereo_disparity output folders, one per method",
              "out": "folder for the pictures", "summary": "summary JSON for the report page",
              "plots": "folder for dvc plots data"})
