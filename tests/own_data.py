"""Folders laid out as a user's own images would be, built from the bundled samples, with NO truth file.

``build(task, samples, dest)`` writes ``dest`` (e.g. ``data/mine/<task>``) in the layout the README's "Your own images"
section documents, mixing file formats and suffix letter cases, so that a test can run
``dvc exp run -S <task>.data=<dest>`` on it.
"""

from __future__ import annotations

from pathlib import Path

import cv2


def _copy(src: Path, dst: Path) -> None:
    """Re-encode ``src`` into ``dst``'s format (the suffix decides), creating folders."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    img = cv2.imread(str(src), cv2.IMREAD_UNCHANGED)
    assert img is not None, src
    ok, buf = cv2.imencode(dst.suffix.lower() if dst.suffix.lower() != ".jpeg" else ".jpg", img)
    assert ok, dst
    dst.write_bytes(buf.tobytes())


def build_hough(s: Path, d: Path) -> list[str]:
    _copy(s / "camera_lines.png", d / "street.JPG")
    _copy(s / "synthetic_grid.png", d / "grid.tif")
    return ["street", "grid"]


def build_homography(s: Path, d: Path) -> list[str]:
    _copy(s / "0_astronaut_a.jpg", d / "desk_a.jpg")
    _copy(s / "0_astronaut_b.jpg", d / "desk_b.JPEG")
    _copy(s / "1_coffee_a.jpg", d / "cup" / "first.png")
    _copy(s / "1_coffee_b.jpg", d / "cup" / "second.webp")
    return ["desk", "cup"]


def build_defect(s: Path, d: Path) -> list[str]:
    _copy(s / "reference.png", d / "reference.png")
    names = []
    for i, suffix in ((0, ".png"), (1, ".tif"), (2, ".bmp")):
        src = sorted((s / "probes").iterdir())[i]
        _copy(src, d / "probes" / f"part_{i}{suffix}")
        names.append(f"part_{i}")
    return names


def build_logo(s: Path, d: Path) -> list[str]:
    for brand in ("starbucks", "docker"):
        _copy(s / "gallery" / f"{brand}.png", d / "gallery" / f"{brand}.png")
    _copy(s / "gallery" / "ferrari.png", d / "gallery" / "ferrari" / "mark.PNG")
    scenes = sorted((s / "scenes").iterdir())[:4]
    for i, f in enumerate(scenes):
        _copy(f, d / "scenes" / f"photo_{i}.jpg")
    return [f"photo_{i}" for i in range(len(scenes))]


def build_stereo(s: Path, d: Path) -> list[str]:
    _copy(s / "motorcycle" / "left.png", d / "bike" / "left.png")
    _copy(s / "motorcycle" / "right.png", d / "bike" / "right.PNG")
    return ["bike"]


def build_panorama(s: Path, d: Path) -> list[str]:
    views = sorted((s / "coffee").iterdir())
    for i, f in enumerate(reversed(views)):  # any order
        _copy(f, d / "kitchen" / f"img_{i}.jpg")
    return ["kitchen"]


BUILDERS = {"hough": build_hough, "homography": build_homography, "defect": build_defect, "logo": build_logo,
            "stereo": build_stereo, "panorama": build_panorama}


def build(task: str, samples: Path, dest: Path) -> list[str]:
    """Write the user-style folder of ``task`` into ``dest``; return the item names the pipeline should report."""
    return BUILDERS[task](Path(samples) / task, Path(dest))
