"""Stage `panorama_opencv_stitcher`: the cv2.Stitcher baseline on the same sets and resolutions (failures kept)."""

import argparse
import time
from pathlib import Path

from tqdm import tqdm

from cvpipe import io, panorama
from cvpipe.params import PanoramaFeaturesParams, PanoramaMatchParams, PanoramaWarpParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--images", required=True, help="folder with one sub-folder of photos per set")
    ap.add_argument("--out", required=True, help="folder for <set>.png and <set>.json")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    work = load_section(PanoramaFeaturesParams, "panorama.features", args.params).work_megapix
    conf = load_section(PanoramaMatchParams, "panorama.match", args.params).min_confidence
    compose = load_section(PanoramaWarpParams, "panorama.warp", args.params).compose_megapix
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for d in tqdm(sorted(x for x in Path(args.images).iterdir() if x.is_dir()), desc="cv2.Stitcher", disable=None):
        files = io.list_images(d)
        images = [io.read_image(f, "color") for f in files]
        t0 = time.perf_counter()
        status, pano, used = panorama.opencv_stitch(images, work, compose, conf)
        result = {"ok": status == "OK", "status": status, "used": used, "seconds": time.perf_counter() - t0,
                  "files": [f.name for f in files]}
        if pano is not None:
            io.save_image(out / f"{d.name}.png", pano)
            result["size"] = [pano.shape[1], pano.shape[0]]
        io.save_json(out / f"{d.name}.json", result)


if __name__ == "__main__":
    main()
