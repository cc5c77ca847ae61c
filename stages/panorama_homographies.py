"""Stage `panorama_homographies`: per set, drop the images that match none of the others (with the reason), chain
along the maximum spanning tree of the match graph, refine jointly (`<out>/<set>.json`; a set that fails is
recorded there with its reason)."""

from pathlib import Path

from cvpipe import io, panorama
from ._runner import Stage, run


def panorama_homographies(st: Stage) -> None:
    p, out = st.params, Path(st.args.out)
    ok, files = 0, sorted(Path(st.args.matches).glob("*.npz"))
    recs = {}  # a set's graph travels with its task; its file names and sizes stay here for its record

    def set_data(name: str, _prev: dict):
        arrays = io.load_npz(Path(st.args.matches) / f"{name}.npz", (*panorama.MatchGraph.ARRAYS, "files",
                                                                         "full_sizes"))
        graph = panorama.MatchGraph.from_arrays(arrays)
        recs[name] = {"files": arrays["files"].tolist(), "work_sizes": graph.sizes,
                      "full_sizes": arrays["full_sizes"].tolist()}
        return graph, recs[name]["files"]

    for name, failed, got in st.map_sets([(f.stem, {}) for f in files], panorama.register_set, set_data,
                                         (p, st.sections["panorama.match"]), "panorama homographies"):
        rec = recs.pop(name)
        if failed is not None:  # recorded, so the later stages and the report say which set failed and why
            rec.update(failed)
        else:
            reg, seconds = got
            st.timings["register"] = st.timings.get("register", 0.0) + seconds
            rec.update(reg.to_json(), ok=True)
            for k, why in reg.dropped:
                st.drop(f"{name}/{rec['files'][k]}", why)
            ok += 1
        io.save_json(out / f"{name}.json", rec)
    out.mkdir(parents=True, exist_ok=True)
    st.made(f"homographies of {ok} sets in {out}")


if __name__ == "__main__":
    run(panorama_homographies, section=["panorama.homographies", "panorama.match"],
        args={"matches": "panorama_match output", "out": "folder for <set>.json"})
