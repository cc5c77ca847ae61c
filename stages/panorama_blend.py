"""Stage `panorama_blend`: per set, gain compensation, seams and multi-band (or feather) blending of the canvas."""

import argparse
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from cvpipe import blending, io, warping
from cvpipe.params import PanoramaBlendParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--warp", required=True, help="folder of <set>/ from panorama_warp")
    ap.add_argument("--out", required=True, help="folder for <set>.png, <set>_mask.png, <set>_seams.png, <set>.json")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(PanoramaBlendParams, "panorama.blend", args.params)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for d in tqdm(sorted(x for x in Path(args.warp).iterdir() if x.is_dir()), desc="panorama blend", disable=None):
        meta = io.load_json(d / "warp.json")
        result = {"ok": meta["ok"], "error": meta.get("error")}
        if meta["ok"]:
            n = len(meta["corners"])
            w = warping.Warped([io.read_image(d / f"warped_{k}.png", "color") for k in range(n)],
                               [io.read_image(d / f"mask_{k}.png", "gray") for k in range(n)],
                               [tuple(c) for c in meta["corners"]], tuple(meta["size"]), tuple(meta["origin"]))
            t0 = time.perf_counter()
            pano, mask, seams = blending.compose(w, p.blender, p.bands, p.gain_compensation)
            seconds = time.perf_counter() - t0
            gains = blending.gain_compensation(w) if p.gain_compensation else np.ones(n)
            result.update(seconds=seconds, gains=gains, ghosting=blending.overlap_difference(w, gains),
                          ghosting_without_gains=blending.overlap_difference(w))
            io.save_image(out / f"{d.name}.png", pano)
            io.save_image(out / f"{d.name}_mask.png", mask.astype(np.uint8) * 255)
            io.save_image(out / f"{d.name}_seams.png", seams.astype(np.uint8) * 255)
        io.save_json(out / f"{d.name}.json", result)


if __name__ == "__main__":
    main()
