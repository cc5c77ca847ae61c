"""Stage `panorama_match`: per set, match every candidate pair of images -> the match-confidence graph
(`<out>/<set>.npz`)."""

from pathlib import Path

from cvpipe import io, panorama
from cvpipe.features import Features
from ._runner import Stage, run


def panorama_match(st: Stage) -> None:
    p, out = st.params, Path(st.args.out)
    sets = sorted(x for x in Path(st.args.features).iterdir() if x.is_dir())
    meta = {}  # a set's features travel with its task; its file names and sizes stay here for its npz
    track = p.pair_refine != "none"  # then the grey images travel too: the pairs are refined by tracking in them
    keys = (*Features.ARRAYS, "image_file", "full_size", "work_size", *(("work_gray",) if track else ()))

    def set_data():
        for d in sets:
            arrays = [io.load_npz(f, keys) for f in sorted(d.glob("*.npz"))]
            meta[d.name] = ([str(a["image_file"]) for a in arrays], [a["full_size"] for a in arrays])
            yield ([Features.from_arrays(a) for a in arrays], [tuple(int(v) for v in a["work_size"]) for a in arrays],
                   [a["work_gray"] for a in arrays] if track else None)

    for name, (graph, seconds) in st.map(panorama.match_set, set_data(), shared=p, desc="panorama match",
                                         names=[d.name for d in sets]):
        st.timings["match"] = st.timings.get("match", 0.0) + seconds
        files, full_sizes = meta.pop(name)
        io.save_npz(out / f"{name}.npz", **graph.to_arrays(), files=files, full_sizes=full_sizes)
    out.mkdir(parents=True, exist_ok=True)
    st.made(f"match graphs of {len(sets)} sets in {out}")


if __name__ == "__main__":
    run(panorama_match, section="panorama.match",
        args={"features": "panorama_features output", "out": "folder for <set>.npz"})
