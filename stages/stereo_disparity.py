"""Stage `stereo_disparity@{sgm,opencv_bm,opencv_sgbm}`: disparity of every pair that `stereo_rectify` rectified
(its ``<pair>/left.png`` / ``right.png``; the pairs it dropped it recorded): ``<pair>/disparity.npy`` (float32, NaN =
none, in the rectified left frame), ``<pair>/disparity.png`` (16-bit, round(256 d), 0 = none) and ``run.json`` (per
pair max_disp and where it came from, valid fraction and, with a truth.npz in the same frame, the accuracy; what was
dropped and why), plus the metrics file. max_disp: the pair's own (truth.json ``max_disp`` or calib.txt ``ndisp``),
else the rectification's estimate from the matches, else ``stereo.disparity.max_disp``. A truth.npz is used only for
a pair that needed no rectification (it is in the original frame)."""

from pathlib import Path

import numpy as np

from cvpipe import datasets, io, stereo
from cvpipe.errors import InputError
from cvpipe.params import SECTIONS, load_section
from ._runner import Stage, run


def stereo_disparity(st: Stage) -> None:
    a, method = st.args, st.args.method
    section = load_section(SECTIONS[f"stereo.{method}"], f"stereo.{method}", a.params)
    rectified = Path(a.rectified)
    rects = io.load_json(rectified / "run.json")["pairs"]
    pairs, _ = datasets.find_stereo(a.pairs)  # what it drops and what could not be rectified, stereo_rectify recorded
    out, results, sources = Path(a.out), {}, {}
    todo = [q for q in pairs if q.name in rects]
    max_disps = {}
    for pair in todo:
        candidates = (("pair", pair.max_disp), ("rectification", rects[pair.name].get("max_disp")),
                      ("stereo.disparity", st.params.max_disp))
        sources[pair.name], max_disps[pair.name] = next((k, v) for k, v in candidates if v is not None)

    def pair_data():
        # read here, lazily: each rectified pair travels with its task
        for pair in todo:
            try:
                yield (io.read_image(rectified / pair.name / "left.png"),
                       io.read_image(rectified / pair.name / "right.png"), max_disps[pair.name])
            except InputError as exc:
                yield exc

    by_name = {q.name: q for q in todo}
    for name, (disp, seconds) in st.map(stereo.disparity_item, pair_data(), shared=(method, section),
                                        desc=f"disparity {method}", names=list(by_name)):
        pair = by_name[name]
        st.timings["warmup"] = st.timings.get("warmup", 0.0) + seconds.get("warmup", 0.0)
        st.timings[f"disparity {name}"] = seconds["disparity"]
        in_frame = pair.truth is not None and rects[name]["kind"] == "none"
        truth = datasets.read_stereo_truth(pair.truth, disp.shape) if in_frame else None
        with io.atomic_path(out / name / "disparity.npy") as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, disp.astype(np.float32), allow_pickle=False)
        try:
            io.save_image(out / name / "disparity.png", stereo.to_png16(disp))
        except ValueError as exc:  # disparities of 256 px or more: the npy has them
            st.drop(f"{name}/disparity.png", str(exc))
        results[name] = {**stereo.pair_result(disp, max_disps[name], truth), "truth": truth is not None}
    result = {"method": method, "pairs": results, "dropped": st.dropped, "max_disp_from": sources}
    io.save_json(out / "run.json", result)
    st.save_metrics(a.metrics, stereo.metrics_of(result))
    if not results:
        raise InputError(f"{a.pairs}: no pair could be processed")
    st.made(f"{len(results)} disparity maps in {out}")


if __name__ == "__main__":
    run(stereo_disparity, section="stereo.disparity", item="method",
        args={"pairs": "the stereo.data folder", "rectified": "stereo_rectify's output folder",
              "out": "folder for <pair>/disparity.npy|png and run.json",
              "metrics": "metrics JSON (git-tracked)"},
        options={"method": {"required": True, "choices": sorted(stereo.METHODS)}})
