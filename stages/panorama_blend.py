"""Stage `panorama_blend`: per set, exposure compensation, seams and multi-band (or feather) blending of the canvas
(`<out>/<set>.png`, `<set>_mask.png`, `<set>_seams.png`, `<set>.json`; a failed set is recorded in its JSON)."""

from pathlib import Path

import numpy as np

from cvpipe import io, panorama
from stages import _panorama as pr
from stages._runner import Stage, run


def _blend(st: Stage, d: Path, meta: dict, out: Path) -> dict:
    p, n = st.params, len(meta["corners"])
    w = panorama.Warped([io.read_image(d / f"warped_{k}.png", "color") for k in range(n)],
                       [io.read_image(d / f"mask_{k}.png", "gray") for k in range(n)],
                       [tuple(c) for c in meta["corners"]], tuple(meta["size"]), tuple(meta["origin"]))
    with st.timer("blend"):
        pano, mask, seams = panorama.compose(w, p.blender, p.bands, p.gain_compensation, p.gain_block)
    gains = panorama.compensation_gains(w, p.gain_compensation, p.gain_block)
    gains = np.ones(n) if gains is None else gains
    io.save_image(out / f"{d.name}.png", pano)
    io.save_image(out / f"{d.name}_mask.png", mask.astype(np.uint8) * 255)
    io.save_image(out / f"{d.name}_seams.png", seams.astype(np.uint8) * 255)
    # one gain per image, per image and channel, or (block modes) each image's mean gain per channel
    shown = gains if isinstance(gains, np.ndarray) else np.stack([g.reshape(-1, g.shape[2]).mean(0) for g in gains])
    return {"ok": True, "gains": shown, "ghosting": panorama.overlap_difference(w, gains),
            "ghosting_without_gains": panorama.overlap_difference(w)}


def panorama_blend(st: Stage) -> None:
    out, records = Path(st.args.out), []
    for d in st.progress(sorted(x for x in Path(st.args.warp).iterdir() if x.is_dir()), "panorama blend"):
        meta = io.load_json(d / "warp.json")
        rec = pr.step_record(meta, "panorama_blend", d.name, lambda: _blend(st, d, meta, out), st.drop)
        io.save_json(out / f"{d.name}.json", rec)
        records.append(rec)
    out.mkdir(parents=True, exist_ok=True)
    st.made(pr.step_summary(records, "panorama_blend", f"panoramas blended into {out}"))


if __name__ == "__main__":
    run(panorama_blend, section="panorama.blend",
        args={"warp": "panorama_warp output", "out": "folder for <set>.png, _mask.png, _seams.png, .json"})
