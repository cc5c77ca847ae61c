"""Stage `<task>_features`: detect keypoints + descriptors on every image under a folder, one .npz per image."""

import argparse
from pathlib import Path

from cvpipe import features, io
from cvpipe.params import FeaturesParams, SECTIONS, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--images", required=True, help="folder searched recursively for images")
    ap.add_argument("--out", required=True, help="folder for <relative path>.npz files")
    ap.add_argument("--section", required=True, help="params.yaml section, e.g. homography.features")
    ap.add_argument("--detector", help="override the section's detector (for matrix stages)")
    ap.add_argument("--scenes", help="subfolder of scene photos: they get the section's scene_min_long_side")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(SECTIONS.get(args.section, FeaturesParams), args.section, args.params)
    detector = args.detector or p.detector
    root, out = Path(args.images), Path(args.out)
    files = sorted(f for f in root.rglob("*") if f.suffix.lower() in io.IMAGE_SUFFIXES)
    if not files:
        raise SystemExit(f"cvpipe: error: {root}: no images found")
    for f in io.progress(files, f"features {detector}"):
        gray = io.read_image(f, "gray")
        rel = f.relative_to(root).with_suffix(".npz")
        is_scene = args.scenes is not None and rel.parts[0] == args.scenes
        feats = features.detect(gray, detector, p.max_features,
                                min_long_side=getattr(p, "scene_min_long_side", 0) if is_scene else 0)
        io.save_npz(out / rel, **feats.to_arrays(), image_size=gray.shape[::-1])


if __name__ == "__main__":
    main()
