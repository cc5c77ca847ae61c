"""Stage `defect_match`: match the reference's keypoints to every probe's (from `defect_features`), one .npz of
index pairs ``[i_reference, i_probe]`` per probe, and matches.json (counts, probes dropped)."""

from pathlib import Path

from cvpipe import datasets, io, matching
from cvpipe.errors import InputError
from cvpipe.features import Features
from ._runner import Stage, run


def defect_match(st: Stage) -> None:
    p, feats, out = st.params, Path(st.args.features), Path(st.args.out)
    inputs, dropped = datasets.find_defect(st.args.images)
    for d in dropped:
        st.drop(d["item"], d["reason"])
    ref = Features.from_arrays(io.load_npz(feats / f"{inputs.reference.stem}.npz", Features.ARRAYS))
    # why defect_features skipped an image, when it says so
    skipped = {d["item"]: d["reason"] for d in (io.load_json(feats / "dropped.json")
                                                if (feats / "dropped.json").is_file() else [])}
    counts = {}
    for probe in st.progress(inputs.probes, "defect match"):
        path = feats / "probes" / f"{probe.name}.npz"
        if not path.is_file():
            st.drop(probe.path.name, skipped.get(f"probes/{probe.path.name}", "no keypoints from defect_features"))
            continue
        with st.timer("match"):
            idx = matching.match_with(ref, Features.from_arrays(io.load_npz(path, Features.ARRAYS)), p)
        io.save_npz(out / f"{probe.name}.npz", index=idx)
        counts[probe.name] = len(idx)
    if not counts:
        raise InputError(f"{st.args.images}: no probe has keypoints to match")
    io.save_json(out / "matches.json", {"matches": counts, "dropped": st.dropped})
    st.made(f"{len(counts)} probes matched ({sum(counts.values())} matches) -> {out}")


if __name__ == "__main__":
    run(defect_match, section="defect.match",
        args={"images": "the defect.data folder", "features": "defect_features output",
              "out": "folder for <probe>.npz and matches.json"})
