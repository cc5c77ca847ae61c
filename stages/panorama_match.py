"""Stage `panorama_match`: per set, match every candidate pair of images -> the match-confidence graph
(`<out>/<set>.npz`)."""

from pathlib import Path

from cvpipe import io, panorama
from cvpipe.features import Features
from stages._runner import Stage, run


def panorama_match(st: Stage) -> None:
    p, out = st.params, Path(st.args.out)
    sets = sorted(x for x in Path(st.args.features).iterdir() if x.is_dir())
    for d in st.progress(sets, "panorama match"):
        arrays = [io.load_npz(f) for f in sorted(d.glob("*.npz"))]
        feats = [Features.from_arrays(a) for a in arrays]
        sizes = [tuple(int(v) for v in a["work_size"]) for a in arrays]
        with st.timer("match"):
            graph = panorama.match_graph(feats, sizes, ratio=p.ratio, ransac_threshold=p.ransac_threshold,
                                         min_inliers=p.min_inliers, min_confidence=p.min_confidence,
                                         candidates=p.candidates, refit_threshold=p.refit_threshold, rng=p.seed)
        io.save_npz(out / f"{d.name}.npz", **graph.to_arrays(), files=[str(a["image_file"]) for a in arrays],
                    full_sizes=[a["full_size"] for a in arrays])
    out.mkdir(parents=True, exist_ok=True)
    st.made(f"match graphs of {len(sets)} sets in {out}")


if __name__ == "__main__":
    run(panorama_match, section="panorama.match",
        args={"features": "panorama_features output", "out": "folder for <set>.npz"})
