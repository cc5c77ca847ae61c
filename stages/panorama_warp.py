"""Stage `panorama_warp`: per set, the used images at the compose resolution warped into the panorama canvas."""

import argparse
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from cvpipe import io, panorama, warping
from cvpipe.errors import EstimationError
from cvpipe.params import PanoramaWarpParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--images", required=True, help="folder with one sub-folder of photos per set")
    ap.add_argument("--homographies", required=True, help="folder of <set>.json from panorama_homographies")
    ap.add_argument("--out", required=True, help="folder for <set>/warped_<k>.png, mask_<k>.png, warp.json")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(PanoramaWarpParams, "panorama.warp", args.params)
    for f in tqdm(sorted(Path(args.homographies).glob("*.json")), desc="panorama warp", disable=None):
        h = io.load_json(f)
        out = Path(args.out) / f.stem
        out.mkdir(parents=True, exist_ok=True)
        meta = {"ok": h["ok"], "error": h.get("error")}
        if h["ok"]:
            reg = panorama.Registration.from_json(h)
            images = [io.read_image(Path(args.images) / f.stem / name, "color") for name in h["files"]]
            t0 = time.perf_counter()
            try:
                comp = panorama.compose_inputs(images, reg, [tuple(s) for s in h["work_sizes"]], p.compose_megapix)
                w = warping.warp_images(comp.images, comp.G, p.projection, comp.focal, comp.ref_size,
                                        p.max_canvas_megapix)
                meta.update(corners=w.corners, size=w.size, origin=w.origin, G=np.array(comp.G),
                            compose_sizes=comp.sizes, used=list(reg.used))
                for k, (img, mask) in enumerate(zip(w.images, w.masks)):
                    io.save_image(out / f"warped_{k}.png", img)
                    io.save_image(out / f"mask_{k}.png", mask)
            except EstimationError as exc:
                meta.update(ok=False, error=str(exc))
            meta["seconds"] = time.perf_counter() - t0
        io.save_json(out / "warp.json", meta)


if __name__ == "__main__":
    main()
