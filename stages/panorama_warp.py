"""Stage `panorama_warp`: per set, the used images at the compose resolution warped into the panorama canvas
(`<out>/<set>/warped_<k>.png`, `mask_<k>.png`, `warp.json`; a set that fails is recorded in its warp.json)."""

from pathlib import Path

import numpy as np

from cvpipe import io, panorama
from stages import _panorama as pr
from stages._runner import Stage, run


def _warp(st: Stage, h: dict, folder: Path, out: Path) -> dict:
    """Warp one registered set into ``out``; its ``warp.json`` record."""
    p = st.params
    reg = panorama.Registration.from_json(h)
    images = [io.read_image(folder / name, "color") if k in reg.used else None for k, name in enumerate(h["files"])]
    with st.timer("warp"):
        comp = panorama.compose_inputs(images, reg, [tuple(s) for s in h["work_sizes"]], p.compose_megapix)
        w = panorama.warp_images(comp.images, comp.G, p.projection, comp.focal, comp.ref_size, p.max_canvas_megapix)
    for k, (img, mask) in enumerate(zip(w.images, w.masks)):
        io.save_image(out / f"warped_{k}.png", img)
        io.save_image(out / f"mask_{k}.png", mask)
    return {"ok": True, "corners": w.corners, "size": w.size, "origin": w.origin, "G": np.array(comp.G),
            "compose_sizes": comp.sizes, "used": list(reg.used)}


def panorama_warp(st: Stage) -> None:
    out, records = Path(st.args.out), []
    for f in st.progress(sorted(Path(st.args.homographies).glob("*.json")), "panorama warp"):
        h = io.load_json(f)
        rec = pr.step_record(h, "panorama_warp", f.stem,
                             lambda: _warp(st, h, Path(st.args.images) / f.stem, out / f.stem), st.drop)
        io.save_json(out / f.stem / "warp.json", rec)
        records.append(rec)
    out.mkdir(parents=True, exist_ok=True)
    st.made(pr.step_summary(records, "panorama_warp", f"sets warped into {out}"))


if __name__ == "__main__":
    run(panorama_warp, section="panorama.warp",
        args={"images": "the panorama.data folder", "homographies": "panorama_homographies output",
              "out": "folder for <set>/"})
