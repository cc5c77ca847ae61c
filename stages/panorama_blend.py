"""Stage `panorama_blend`: per set, exposure compensation, seams and multi-band (or feather) blending of the canvas
(`<out>/<set>.png`, `<set>_mask.png`, `<set>_seams.png`, `<set>.json`; a failed set is recorded in its JSON)."""

from pathlib import Path

import numpy as np

from cvpipe import io, panorama
from ._runner import Stage, run


def panorama_blend(st: Stage) -> None:
    out, records = Path(st.args.out), []
    folders = sorted(x for x in Path(st.args.warp).iterdir() if x.is_dir())
    sets = [(d.name, io.load_json(d / "warp.json")) for d in folders]

    def set_data(name: str, meta: dict) -> panorama.Warped:
        # read here, lazily: the warped images travel with the set's task
        d, n = Path(st.args.warp) / name, len(meta["corners"])
        return panorama.Warped([io.read_image(d / f"warped_{k}.png", "color") for k in range(n)],
                               [io.read_image(d / f"mask_{k}.png", "gray") for k in range(n)],
                               [tuple(c) for c in meta["corners"]], tuple(meta["size"]), tuple(meta["origin"]))

    for name, failed, got in st.map_sets(sets, panorama.blend_set, set_data, st.params, "panorama blend"):
        rec = failed
        if failed is None:
            pano, mask, seams, rec, seconds = got
            st.timings["blend"] = st.timings.get("blend", 0.0) + seconds
            io.save_image(out / f"{name}.png", pano)
            io.save_image(out / f"{name}_mask.png", mask.astype(np.uint8) * 255)
            io.save_image(out / f"{name}_seams.png", seams.astype(np.uint8) * 255)
        io.save_json(out / f"{name}.json", rec)
        records.append(rec)
    out.mkdir(parents=True, exist_ok=True)
    st.made(st.step_summary(records, f"panoramas blended into {out}"))


if __name__ == "__main__":
    run(panorama_blend, section="panorama.blend",
        args={"warp": "panorama_warp output", "out": "folder for <set>.png, _mask.png, _seams.png, .json"})
