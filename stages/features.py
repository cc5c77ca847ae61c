"""Stage `<task>_features` (homography, defect, logo): keypoints + descriptors of every image under a folder
(searched recursively), one ``<relative path>.npz`` per image; unreadable images are listed with their reason in
``dropped.json``. ``--section`` names the params.yaml section, ``--detector`` overrides its detector (matrix stages)
and the images under ``--scenes`` get the section's ``scene_min_long_side``."""

import argparse
import sys
from pathlib import Path

from cvpipe import features, io
from cvpipe.errors import InputError
from cvpipe.params import SECTIONS, FeaturesParams, load_section
from stages._runner import Stage, run


def images_under(root: Path) -> list[Path]:
    """Image files anywhere under ``root`` (hidden files and folders skipped), sorted by relative path."""
    if not root.is_dir():
        raise InputError(f"{root}: no such folder")
    return sorted(f for f in root.rglob("*") if f.is_file() and f.suffix.lower() in io.IMAGE_SUFFIXES
                  and not any(part.startswith(".") for part in f.relative_to(root).parts))


def features_stage(st: Stage) -> None:
    a = st.args
    p = load_section(SECTIONS.get(a.section, FeaturesParams), a.section, a.params)
    detector = a.detector or p.detector
    features.check_detector(detector)
    root, out = Path(a.images), Path(a.out)
    files = images_under(root)
    if not files:
        raise InputError(f"{root}: no images found")
    made: dict[Path, Path] = {}
    for f in st.progress(files, f"features {detector}"):
        rel = f.relative_to(root)
        npz = rel.with_suffix(".npz")
        if npz in made:  # photo.jpg and photo.png would share photo.npz
            st.drop(rel.as_posix(), f"same name as {made[npz].as_posix()} (features are stored per name); rename one")
            continue
        try:
            gray = io.read_image(f, "gray")
        except InputError as exc:
            st.drop(rel.as_posix(), str(exc))
            continue
        is_scene = a.scenes is not None and rel.parts[0] == a.scenes
        with st.timer("detect"):
            feats = features.detect(gray, detector, p.max_features,
                                    min_long_side=getattr(p, "scene_min_long_side", 0) if is_scene else 0)
        io.save_npz(out / npz, **feats.to_arrays(), image_size=gray.shape[::-1])
        made[npz] = rel
    io.save_json(out / "dropped.json", st.dropped)
    if not made:
        raise InputError(f"{root}: no readable image")
    st.made(f"{detector} features of {len(made)} images in {out}")


def stage_name(argv: list[str]) -> str:
    """``homography_features``, ``logo_features@sift``: the dvc.yaml name, from ``--section`` and ``--detector``."""
    ap = argparse.ArgumentParser(add_help=False)
    ap.add_argument("--section", default="features")
    ap.add_argument("--detector")
    ns, _ = ap.parse_known_args(argv)
    name = f"{ns.section.split('.')[0]}_features"
    return f"{name}@{ns.detector}" if ns.detector else name


if __name__ == "__main__":
    run(features_stage, name=stage_name(sys.argv[1:]),
        args={"images": "folder searched recursively for images", "out": "folder for <relative path>.npz files"},
        options={"section": {"required": True, "help": "params.yaml section, e.g. homography.features"},
                 "detector": {"help": "override the section's detector (for matrix stages)"},
                 "scenes": {"help": "subfolder of scene photos: they get the section's scene_min_long_side"}})
