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
from ._runner import Stage, run


def images_under(root: Path) -> list[Path]:
    """Image files anywhere under ``root`` (hidden files and folders skipped), sorted by relative path; a name that is
    not UTF-8 anywhere under ``root`` is refused (:func:`cvpipe.io.check_utf8_names`)."""
    if not root.is_dir():
        raise InputError(f"{root}: no such folder")
    io.check_utf8_names(root)
    return sorted(f for f in root.rglob("*") if f.is_file() and f.suffix.lower() in io.IMAGE_SUFFIXES
                  and not any(part.startswith(".") for part in f.relative_to(root).parts))


def features_stage(st: Stage) -> None:
    a = st.args
    p = load_section(SECTIONS.get(a.section, FeaturesParams), a.section, a.params)
    detector = a.detector or p.detector
    features.check_detector(detector)
    p = p.replace(detector=detector)  # the matrix stages' --detector
    root, out = Path(a.images), Path(a.out)
    files = images_under(root)
    if not files:
        raise InputError(f"{root}: no images found")
    made: dict[Path, Path] = {}
    rels = [f.relative_to(root) for f in files]

    def image_data():
        # read here, lazily: each image travels with its task
        for f, rel in zip(files, rels):
            npz = rel.with_suffix(".npz")
            if npz in made:  # photo.jpg and photo.png would share photo.npz
                yield InputError(f"same name as {made[npz].as_posix()} (features are stored per name); rename one")
                continue
            try:
                gray = io.read_image(f, "gray")
            except InputError as exc:
                yield exc
                continue
            made[npz] = rel
            yield gray, a.scenes is not None and rel.parts[0] == a.scenes

    for name, (arrays, seconds) in st.map(features.detect_item, image_data(), shared=p,
                                          desc=f"features {detector}", names=[r.as_posix() for r in rels]):
        st.timings["detect"] = st.timings.get("detect", 0.0) + seconds
        io.save_npz(out / Path(name).with_suffix(".npz"), **arrays)
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
