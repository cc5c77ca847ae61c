"""Stage `stereo_rectify`: every pair of `stereo.data` in a rectified frame, ``<pair>/left.png``, ``right.png``,
``rect.json`` (kind none / calibrated / uncalibrated, H_left and H_right original -> rectified, the vertical error of
the matches, max_disp when estimated, the depth geometry when there is a calibration) and ``matches.npz`` (the matches
the vertical error is measured on, rectified pixels), plus ``run.json`` (every pair's record, what was dropped and
why) and the metrics file. The rule (calibrated / no-op / uncalibrated): :func:`cvpipe.stereo.pipeline.rectify_pair`.
"""

from pathlib import Path

from cvpipe import datasets, io, stereo
from cvpipe.errors import InputError
from ._runner import Stage, run


def stereo_rectify(st: Stage) -> None:
    p, a = st.params, st.args
    pairs, dropped = datasets.find_stereo(a.pairs)
    for d in dropped:
        st.drop(d["item"], d["reason"])
    out, records = Path(a.out), {}

    def pair_data():
        # read here, lazily: each pair's images and calibration text travel with its task
        for pair in pairs:
            try:
                left, right = io.read_image(pair.left), io.read_image(pair.right)
                calib = None if pair.calib is None else io.read_text(pair.calib, "calibration")
                yield left, right, calib, None if pair.calib is None else str(pair.calib)
            except InputError as exc:
                yield exc

    for name, (got, seconds) in st.map(stereo.rectify_item, pair_data(), shared=p, desc="rectify",
                                       names=[q.name for q in pairs]):
        st.timings[f"rectify {name}"] = seconds
        io.save_image(out / name / "left.png", got.left)
        io.save_image(out / name / "right.png", got.right)
        io.save_npz(out / name / "matches.npz", left=got.points_left, right=got.points_right)
        io.save_json(out / name / "rect.json", got.record)
        records[name] = got.record
    io.save_json(out / "run.json", {"pairs": records, "dropped": st.dropped})
    st.save_metrics(a.metrics, stereo.rectify_metrics(records))
    if not records:
        raise InputError(f"{a.pairs}: no pair could be rectified")
    kinds = [r["kind"] for r in records.values()]
    st.made(", ".join(f"{kinds.count(k)} {k}" for k in stereo.KINDS if k in kinds) + f" in {out}")


if __name__ == "__main__":
    run(stereo_rectify, section="stereo.rectify",
        args={"pairs": "the stereo.data folder", "out": "folder for <pair>/{left,right}.png, rect.json, run.json",
              "metrics": "metrics JSON (git-tracked)"})
