"""Stage `panorama_homographies`: per set, drop the images that match none of the others (with the reason), chain
along the maximum spanning tree of the match graph, refine jointly (`<out>/<set>.json`; a set that fails is
recorded there with its reason)."""

from pathlib import Path

from cvpipe import io, panorama
from cvpipe.errors import EstimationError
from stages._runner import Stage, run


def panorama_homographies(st: Stage) -> None:
    p, out = st.params, Path(st.args.out)
    seed = st.sections["panorama.match"].seed
    ok = 0
    for f in st.progress(sorted(Path(st.args.matches).glob("*.npz")), "panorama homographies"):
        arrays = io.load_npz(f)
        graph = panorama.MatchGraph.from_arrays(arrays)
        files = arrays["files"].tolist()
        rec = {"files": files, "work_sizes": graph.sizes, "full_sizes": arrays["full_sizes"].tolist()}
        try:
            with st.timer("register"):
                reg = panorama.register(graph, refine=p.refine, max_points_per_pair=p.max_points_per_pair, rng=seed,
                                        ids=files)
        except EstimationError as exc:  # recorded, so the later stages and the report say which set failed and why
            rec.update(ok=False, error=str(exc), failed_in="panorama_homographies")
            st.drop(f.stem, str(exc))
        else:
            rec.update(reg.to_json(), ok=True)
            for k, why in reg.dropped:
                st.drop(f"{f.stem}/{files[k]}", why)
            ok += 1
        io.save_json(out / f"{f.stem}.json", rec)
    out.mkdir(parents=True, exist_ok=True)
    st.made(f"homographies of {ok} sets in {out}")


if __name__ == "__main__":
    run(panorama_homographies, section=["panorama.homographies", "panorama.match"],
        args={"matches": "panorama_match output", "out": "folder for <set>.json"})
