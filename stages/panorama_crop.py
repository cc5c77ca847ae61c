"""Stage `panorama_crop`: per set, the largest axis-aligned rectangle of the blended panorama with no empty pixel."""

import argparse
import time
from pathlib import Path

from tqdm import tqdm

from cvpipe import blending, io


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--blend", required=True, help="folder of <set>.png/_mask.png/.json from panorama_blend")
    ap.add_argument("--out", required=True, help="folder for <set>.png and <set>.json")
    args = ap.parse_args()
    src, out = Path(args.blend), Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for f in tqdm(sorted(src.glob("*.json")), desc="panorama crop", disable=None):
        meta = io.load_json(f)
        result = {"ok": meta["ok"], "error": meta.get("error")}
        if meta["ok"]:
            pano = io.read_image(src / f"{f.stem}.png", "color")
            mask = io.read_image(src / f"{f.stem}_mask.png", "gray") > 0
            t0 = time.perf_counter()
            x, y, w, h = blending.largest_rectangle(mask)
            result.update(seconds=time.perf_counter() - t0, crop=[x, y, w, h], size=[w, h],
                          empty_share=float(1.0 - mask[y:y + h, x:x + w].mean()) if w * h else 1.0,
                          empty_share_uncropped=float(1.0 - mask.mean()))
            io.save_image(out / f"{f.stem}.png", pano[y:y + h, x:x + w])
        io.save_json(out / f"{f.stem}.json", result)


if __name__ == "__main__":
    main()
