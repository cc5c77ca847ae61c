"""Stage `stereo_rectify`: every pair of `stereo.data` in a rectified frame, ``<pair>/left.png``, ``right.png``,
``rect.json`` (kind none / calibrated / uncalibrated, H_left and H_right original -> rectified, the vertical error of
the matches, max_disp when estimated, the depth geometry when there is a calibration) and ``matches.npz`` (the matches
the vertical error is measured on, rectified pixels), plus ``run.json`` (every pair's record, what was dropped and
why) and the metrics file. The rule (calibrated / no-op / uncalibrated): :func:`cvpipe.stereo.pipeline.rectify_pair`.
"""

from pathlib import Path

from cvpipe import datasets, io, stereo
from cvpipe.errors import EstimationError, InputError
from stages._runner import Stage, run


def stereo_rectify(st: Stage) -> None:
    p, a = st.params, st.args
    pairs, dropped = datasets.find_stereo(a.pairs)
    for d in dropped:
        st.drop(d["item"], d["reason"])
    out, records = Path(a.out), {}
    for pair in st.progress(pairs, "rectify"):
        try:
            left, right = io.read_image(pair.left), io.read_image(pair.right)
            calib = None
            if pair.calib is not None:
                calib = stereo.parse_calibration(pair.calib.read_text(encoding="utf-8"), str(pair.calib))
            with st.timer(f"rectify {pair.name}"):
                p1, p2 = stereo.feature_matches(left, right, p.detector, p.max_features, p.ratio, p.seed)
                got = stereo.rectify_pair(left, right, p1, p2, calib, threshold=p.threshold,
                                                   margin=p.margin, seed=p.seed, rectified_max_dy=p.rectified_max_dy,
                                                   rectified_share=p.rectified_share)
        except EstimationError as exc:
            st.drop(pair.name, f"cannot be rectified: {exc}")
            continue
        except (InputError, ValueError, UnicodeDecodeError) as exc:
            st.drop(pair.name, str(exc))
            continue
        io.save_image(out / pair.name / "left.png", got.left)
        io.save_image(out / pair.name / "right.png", got.right)
        io.save_npz(out / pair.name / "matches.npz", left=got.points_left, right=got.points_right)
        io.save_json(out / pair.name / "rect.json", got.record)
        records[pair.name] = got.record
    io.save_json(out / "run.json", {"pairs": records, "dropped": st.dropped})
    io.save_json(a.metrics, stereo.rectify_metrics(records))
    if not records:
        raise InputError(f"{a.pairs}: no pair could be rectified")
    kinds = [r["kind"] for r in records.values()]
    st.made(", ".join(f"{kinds.count(k)} {k}" for k in stereo.KINDS if k in kinds) + f" in {out}")


if __name__ == "__main__":
    run(stereo_rectify, section="stereo.rectify",
        args={"pairs": "the stereo.data folder", "out": "folder for <pair>/{left,right}.png, rect.json, run.json",
              "metrics": "metrics JSON (git-tracked)"})
