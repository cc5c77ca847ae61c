"""Stage `homography_match`: match the features of every pair of `homography.data` (A -> B), one ``<pair>.npz``
(``index``, ``src``, ``dst``, ``size_a``, ``size_b``) per pair. Layout: pairs ``NAME_a.*`` / ``NAME_b.*``, or
subfolders of two images (truth.json optional). Pairs that cannot be matched are listed in ``dropped.json``."""

from pathlib import Path

from cvpipe import datasets, io, matching
from cvpipe.errors import CvpipeError
from cvpipe.features import NPZ_ARRAYS, Features
from ._runner import Stage, run


def homography_match(st: Stage) -> None:
    p, a = st.params, st.args
    root, feats_dir, out = Path(a.images), Path(a.features), Path(a.out)
    pairs, dropped = datasets.find_homography(root)
    for d in dropped:
        st.drop(d["item"], d["reason"])
    # why an image has no features: the features stage's dropped.json (relative paths)
    unreadable = {d["item"]: d["reason"] for d in io.load_json(feats_dir / "dropped.json")}
    made = 0
    for pair in st.progress(pairs, "homography match"):
        rel = [pair.a.relative_to(root), pair.b.relative_to(root)]
        lost = [r.as_posix() for r in rel if not (feats_dir / r.with_suffix(".npz")).is_file()]
        if lost:
            st.drop(pair.name, "; ".join(unreadable.get(r, f"{r}: no features") for r in lost))
            continue
        fa, fb = (io.load_npz(feats_dir / r.with_suffix(".npz"), NPZ_ARRAYS) for r in rel)
        try:
            A, B = Features.from_arrays(fa), Features.from_arrays(fb)
            with st.timer("match"):
                idx = matching.match_with(A, B, p)
        except (CvpipeError, ValueError) as exc:
            st.drop(pair.name, str(exc))
            continue
        io.save_npz(out / f"{pair.name}.npz", index=idx, src=A.xy[idx[:, 0]], dst=B.xy[idx[:, 1]],
                    size_a=fa["image_size"], size_b=fb["image_size"])
        made += 1
    st.finish(out, made, f"pairs matched in {out}", f"{root}: no pair could be matched")


if __name__ == "__main__":
    run(homography_match, section="homography.match",
        args={"images": "the homography.data folder", "features": "homography_features output folder",
              "out": "folder for <pair>.npz"})
