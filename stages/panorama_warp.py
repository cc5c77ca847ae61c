"""Stage `panorama_warp`: per set, the used images at the compose resolution warped into the panorama canvas
(`<out>/<set>/warped_<k>.png`, `mask_<k>.png`, `warp.json`; a set that fails is recorded in its warp.json)."""

from pathlib import Path

from cvpipe import io, panorama
from ._runner import Stage, run


def panorama_warp(st: Stage) -> None:
    out, records = Path(st.args.out), []
    sets = [(f.stem, io.load_json(f)) for f in sorted(Path(st.args.homographies).glob("*.json"))]

    def set_data(name: str, h: dict):
        # read here, lazily: the used images travel with the set's task
        used = set(h["used"])
        return h, [io.read_image(Path(st.args.images) / name / f, "color") if k in used else None
                   for k, f in enumerate(h["files"])]

    for name, failed, got in st.map_sets(sets, panorama.warp_set, set_data, st.params, "panorama warp"):
        rec = failed
        if failed is None:
            w, rec, seconds = got
            st.timings["warp"] = st.timings.get("warp", 0.0) + seconds
            for k, (img, mask) in enumerate(zip(w.images, w.masks)):
                io.save_image(out / name / f"warped_{k}.png", img)
                io.save_image(out / name / f"mask_{k}.png", mask)
        io.save_json(out / name / "warp.json", rec)
        records.append(rec)
    out.mkdir(parents=True, exist_ok=True)
    st.made(st.step_summary(records, f"sets warped into {out}"))


if __name__ == "__main__":
    run(panorama_warp, section="panorama.warp",
        args={"images": "the panorama.data folder", "homographies": "panorama_homographies output",
              "out": "folder for <set>/"})
