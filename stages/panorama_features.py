"""Stage `panorama_features`: per set, every image shrunk to the registration resolution, then its features."""

import argparse
import time
from pathlib import Path

from tqdm import tqdm

from cvpipe import io, panorama
from cvpipe.params import PanoramaFeaturesParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--images", required=True, help="folder with one sub-folder of photos per panorama set")
    ap.add_argument("--out", required=True, help="folder for <set>/<image>.npz")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(PanoramaFeaturesParams, "panorama.features", args.params)
    sets = sorted(d for d in Path(args.images).iterdir() if d.is_dir())
    if not sets:
        raise SystemExit(f"cvpipe: error: {args.images}: no set folders")
    for d in tqdm(sets, desc="panorama features", disable=None):
        files = io.list_images(d)
        t0 = time.perf_counter()
        images = [io.read_image(f, "gray") for f in files]
        grays, sizes = panorama.working_images(images, p.work_megapix)
        feats = panorama.detect_all(grays, p.detector, p.max_features)
        seconds = time.perf_counter() - t0
        for f, img, size, ft in zip(files, images, sizes, feats):
            io.save_npz(Path(args.out) / d.name / f"{f.stem}.npz", **ft.to_arrays(), work_size=size,
                        full_size=(img.shape[1], img.shape[0]), image_file=f.name, seconds=seconds / len(files))


if __name__ == "__main__":
    main()
