"""Finding a task's items in a user's folder: the folder layouts of the pipeline's ``<task>.data`` parameters.

Each ``find_<task>(folder)`` lists what is there and returns the items plus what it could not use (``dropped``,
each ``{"item", "reason"}``), so that nothing is skipped silently. Ground truth is optional everywhere: an item
carries its truth when the folder's ``truth.json`` (the bundled samples' format) names it, else ``None``. A truth
file is read with a size limit (:data:`TRUTH_MAX_BYTES`) and every field it uses is checked for its type (a name
is a non-empty string, a matrix or a list of lines, boxes or corners is finite numbers of its shape); a file that
breaks this raises :class:`~cvpipe.errors.InputError` naming the file and the field (``probes[1].boxes``). A name
that is not UTF-8 anywhere in the folder is refused before anything is listed, naming the folder and the name.

Layouts (any of png, jpg/jpeg, tif/tiff, bmp, webp, in any letter case):

- hough: the images in the folder.
- homography: pairs ``NAME_a.*`` / ``NAME_b.*``, or subfolders holding exactly two images (sorted by name: A, B).
- defect: ``reference.*`` and the folder ``probes/``.
- logo: ``gallery/`` (one image per brand named after it, or one subfolder per brand) and ``scenes/``.
- stereo: every subfolder is one pair holding ``left.*`` and ``right.*`` (a folder holding them itself is one
  pair); an optional ``calib.txt`` (Middlebury) or ``truth.json`` with ``max_disp`` may set the search range; a
  calibration (``calib.txt`` or an OpenCV ``calib.yml`` / ``calib.yaml``) gives depth.
- panorama: every subfolder is one set, its images in any order.

This module lists, parses small text files and reads a stereo pair's ``truth.npz`` (:func:`read_stereo_truth`);
images are read by :mod:`cvpipe.io`.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError, check_int
from .io import IMAGE_SUFFIXES, check_utf8_names, load_json, load_npz, read_text

TRUTH_FILE = "truth.json"
#: largest ``truth.json`` read, bytes (a truth file holds a few numbers per image)
TRUTH_MAX_BYTES = 64_000_000


def images_in(folder: Path) -> list[Path]:
    """Image files directly inside ``folder`` (any letter case of the suffix), sorted by name."""
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES
                  and not p.name.startswith("."))


def _folder(folder: str | os.PathLike, task: str) -> Path:
    """``folder`` as a Path, refused when it is no folder or holds a name that is not UTF-8
    (:func:`cvpipe.io.check_utf8_names`: DVC cannot hash such a folder)."""
    d = Path(folder)
    if not d.is_dir():
        raise InputError(f"{d}: no such folder (the `{task}.data` parameter must name a folder of {task} images)")
    check_utf8_names(d)
    return d


def _drop(dropped: list[dict], item: Path | str, reason: str) -> None:
    dropped.append({"item": str(item), "reason": reason})


def _shown(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters, for a one-line message."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def read_truth(path: Path) -> dict:
    """A ``truth.json`` as a JSON object, read with the size limit :data:`TRUTH_MAX_BYTES`.

    Raises
    ------
    InputError
        Over the limit, not UTF-8 JSON, nested too deeply, or not an object; the message names the file.
    """
    data = load_json(path, TRUTH_MAX_BYTES, "truth JSON")
    if not isinstance(data, dict):
        raise InputError(f"{path}: expected a JSON object, got {_shown(data)}")
    return data


def _truth(folder: Path, key: str) -> list[tuple[Path, str, dict]]:
    """``(truth file, "key[i]", record)`` for each record under ``key`` of ``folder/truth.json`` (the middle item
    names the record in messages); none when there is no truth file."""
    path = folder / TRUTH_FILE
    if not path.is_file():
        return []
    data = read_truth(path)
    if not isinstance(data.get(key), list):
        raise InputError(f"{path}: field `{key}` must be a list of records")
    for i, rec in enumerate(data[key]):
        if not isinstance(rec, dict):
            raise InputError(f"{path}: field `{key}[{i}]` must be an object")
    return [(path, f"{key}[{i}]", rec) for i, rec in enumerate(data[key])]


def _field(path: Path, rec: dict, where: str, name: str) -> Any:
    """``rec[name]``, naming file and field when it is missing."""
    if name not in rec:
        raise InputError(f"{path}: field `{where}.{name}` is missing")
    return rec[name]


def _text(path: Path, rec: dict, where: str, name: str, null: bool = False) -> str | None:
    """``rec[name]`` as a non-empty string (or None when ``null`` allows a JSON null), naming file and field
    otherwise."""
    value = _field(path, rec, where, name)
    if value is None and null:
        return None
    if not isinstance(value, str) or not value:
        raise InputError(f"{path}: field `{where}.{name}` must be a non-empty string{' or null' if null else ''}, "
                         f"got {_shown(value)}")
    return value


def _file_name(path: Path, rec: dict, where: str) -> str:
    """The bare file name in the record's ``file`` field (a truth file may list ``probes/x.png``)."""
    return Path(_text(path, rec, where, "file")).name


def _first_non_number(value: Any, depth: int, at: str = "") -> tuple[str, Any] | None:
    """``(index, item)`` of the first item of the nested lists ``value`` (``depth`` levels) that is not a JSON
    number (a bool, a string, an object, null or a list nested deeper), or None."""
    if isinstance(value, list) and depth > 0:
        for i, v in enumerate(value):
            got = _first_non_number(v, depth - 1, f"{at}[{i}]")
            if got is not None:
                return got
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return at, value
    return None


def _numbers(path: Path, where: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as a float array of ``shape`` (``-1``: any count, ``[]`` being none) holding finite numbers only;
    InputError naming the file, the field ``where`` and what was wrong otherwise."""
    want = "finite numbers of shape (" + ", ".join("N" if n < 0 else str(n) for n in shape) + \
        ("," if len(shape) == 1 else "") + ")"
    bad = _first_non_number(value, len(shape))
    if bad is not None:
        at, item = bad
        raise InputError(f"{path}: field `{where}` must be {want}, got {_shown(item)}" + (f" at {at}" if at else ""))
    try:
        arr = np.asarray(value, dtype=float)
    except ValueError:
        raise InputError(f"{path}: field `{where}` must be {want}, got lists of unequal length") from None
    except OverflowError:
        raise InputError(f"{path}: field `{where}` must be {want}, got a number too large for a float") from None
    if arr.shape == (0,) and shape[0] < 0:
        arr = arr.reshape((0,) + tuple(max(n, 0) for n in shape[1:]))
    if arr.ndim != len(shape) or any(n >= 0 and a != n for a, n in zip(arr.shape, shape)):
        raise InputError(f"{path}: field `{where}` must be {want}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        at = "".join(f"[{i}]" for i in np.argwhere(~np.isfinite(arr))[0])
        raise InputError(f"{path}: field `{where}` must be {want}, got NaN or infinity at {at}")
    return arr


def _array(path: Path, rec: dict, where: str, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """``rec[name]`` as :func:`_numbers` of ``shape``, naming file and field when it is missing or malformed."""
    return _numbers(path, f"{where}.{name}", _field(path, rec, where, name), shape)


# ---------------------------------------------------------------------------------------------------------- hough


@dataclass(frozen=True)
class HoughImage:
    name: str
    path: Path
    truth_lines: np.ndarray | None = None  # (N, 2) [rho, theta] in cv2.HoughLines convention


def find_hough(folder: str | os.PathLike) -> tuple[list[HoughImage], list[dict]]:
    """The images of ``folder``, each with its true lines when ``truth.json`` lists it."""
    d = _folder(folder, "hough")
    truth: dict[str, np.ndarray] = {}
    for path, where, rec in _truth(d, "images"):
        lines = _array(path, rec, where, "lines", (-1, 2)) if rec.get("lines") is not None else np.zeros((0, 2))
        truth[_text(path, rec, where, "file")] = lines
    items = [HoughImage(f.stem, f, truth.get(f.name)) for f in images_in(d)]
    return _unique(items, "hough"), []


# ----------------------------------------------------------------------------------------------------- homography


@dataclass(frozen=True)
class ImagePair:
    name: str
    a: Path
    b: Path
    H: np.ndarray | None = None  # 3x3, A -> B pixels


_PAIR = re.compile(r"^(?P<name>.+)_(?P<side>[abAB])$")


def find_homography(folder: str | os.PathLike) -> tuple[list[ImagePair], list[dict]]:
    """Pairs ``NAME_a.*``/``NAME_b.*`` in ``folder`` and subfolders of exactly two images."""
    d = _folder(folder, "homography")
    dropped: list[dict] = []
    sides: dict[str, dict[str, Path]] = {}
    for f in images_in(d):
        m = _PAIR.match(f.stem)
        if not m:
            _drop(dropped, f.name, "not part of a pair: name it NAME_a / NAME_b or put the pair in a subfolder")
            continue
        sides.setdefault(m["name"], {})[m["side"].lower()] = f
    pairs = []
    for name, s in sorted(sides.items()):
        if set(s) != {"a", "b"}:
            _drop(dropped, next(iter(s.values())).name, f"pair {name!r} lacks its _{'b' if 'a' in s else 'a'} image")
            continue
        pairs.append(ImagePair(name, s["a"], s["b"]))
    for sub in sorted(p for p in d.iterdir() if p.is_dir() and not p.name.startswith(".")):
        imgs = images_in(sub)
        if len(imgs) != 2:
            _drop(dropped, sub.name, f"a pair folder must hold exactly 2 images, found {len(imgs)}")
            continue
        pairs.append(ImagePair(sub.name, imgs[0], imgs[1]))
    truth = {_text(path, r, where, "name"): _array(path, r, where, "H", (3, 3))
             for path, where, r in _truth(d, "pairs")}
    if truth:
        pairs = [ImagePair(p.name, p.a, p.b, truth.get(p.name)) for p in pairs]
    return _unique(pairs, "homography"), dropped


# --------------------------------------------------------------------------------------------------------- defect


@dataclass(frozen=True)
class Probe:
    name: str
    path: Path
    verdict: str | None = None  # "faulty" / "perfect" when known
    boxes: np.ndarray | None = None  # (N, 4) x1, y1, x2, y2 in probe pixels
    H: np.ndarray | None = None  # reference -> probe


@dataclass(frozen=True)
class DefectInputs:
    reference: Path
    probes: list[Probe] = field(default_factory=list)


def find_defect(folder: str | os.PathLike) -> tuple[DefectInputs, list[dict]]:
    """``reference.*`` and the images of ``probes/``."""
    d = _folder(folder, "defect")
    refs = [f for f in images_in(d) if f.stem.lower() == "reference"]
    if len(refs) != 1:
        raise InputError(f"{d}: expected exactly one reference image `reference.<ext>`, found {len(refs)}")
    probes_dir = d / "probes"
    if not probes_dir.is_dir():
        raise InputError(f"{probes_dir}: no such folder (the probes to inspect go there)")
    truth: dict[str, dict] = {}
    for path, where, r in _truth(d, "probes"):
        verdict = _field(path, r, where, "verdict")
        if verdict not in ("faulty", "perfect"):
            raise InputError(f"{path}: field `{where}.verdict` must be 'faulty' or 'perfect', got {_shown(verdict)}")
        boxes = _array(path, r, where, "boxes", (-1, 4)) if r.get("boxes") is not None else np.zeros((0, 4))
        H = _array(path, r, where, "H", (3, 3)) if r.get("H") is not None else None
        truth[_file_name(path, r, where)] = dict(verdict=verdict, boxes=boxes, H=H)
    probes = [Probe(f.stem, f, **truth.get(f.name, {})) for f in images_in(probes_dir)]
    dropped: list[dict] = []
    if not probes:
        raise InputError(f"{probes_dir}: no probe images found")
    return DefectInputs(refs[0], _unique(probes, "defect")), dropped


# ----------------------------------------------------------------------------------------------------------- logo


@dataclass(frozen=True)
class Scene:
    name: str
    path: Path
    brand: str | None = None  # the true brand (None = none of the gallery's), when known
    quad: np.ndarray | None = None  # (4, 2) true outline in scene pixels
    labelled: bool = False


@dataclass(frozen=True)
class LogoInputs:
    gallery: dict[str, list[Path]]
    scenes: list[Scene]


def find_logo(folder: str | os.PathLike) -> tuple[LogoInputs, list[dict]]:
    """``gallery/`` (``<brand>.<ext>`` or ``<brand>/*.<ext>``) and ``scenes/``."""
    d = _folder(folder, "logo")
    gdir, sdir = d / "gallery", d / "scenes"
    for sub in (gdir, sdir):
        if not sub.is_dir():
            raise InputError(f"{sub}: no such folder (a logo folder holds gallery/ and scenes/)")
    dropped: list[dict] = []

    def once(imgs: list[Path]) -> list[Path]:
        # features are stored per file name without its suffix: `x.png` and `x.jpg` would overwrite each other
        kept: dict[str, Path] = {}
        for f in imgs:
            if f.stem in kept:
                _drop(dropped, f.relative_to(d).as_posix(), f"same name as {kept[f.stem].name}; rename one")
            else:
                kept[f.stem] = f
        return list(kept.values())

    gallery: dict[str, list[Path]] = {f.stem: [f] for f in once(images_in(gdir))}
    for sub in sorted(p for p in gdir.iterdir() if p.is_dir() and not p.name.startswith(".")):
        imgs = once(images_in(sub))
        if not imgs:
            _drop(dropped, f"gallery/{sub.name}", "no images in this brand folder")
            continue
        gallery.setdefault(sub.name, []).extend(imgs)
    if not gallery:
        raise InputError(f"{gdir}: no gallery images (one image per brand, named after the brand)")
    truth: dict[str, dict] = {}
    for path, where, r in _truth(d, "scenes"):
        brand = _text(path, r, where, "brand", null=True)
        if brand is not None and brand not in gallery:
            raise InputError(f"{path}: field `{where}.brand` is {brand!r}, which is not a gallery brand")
        quad = _array(path, r, where, "quad", (4, 2)) if r.get("quad") is not None else None
        truth[_file_name(path, r, where)] = dict(brand=brand, quad=quad, labelled=True)
    scenes = [Scene(f.stem, f, **truth.get(f.name, {})) for f in images_in(sdir)]
    if not scenes:
        raise InputError(f"{sdir}: no scene images found")
    return LogoInputs(gallery, _unique(scenes, "logo")), dropped


# --------------------------------------------------------------------------------------------------------- stereo


@dataclass(frozen=True)
class StereoPair:
    name: str
    left: Path
    right: Path
    max_disp: int | None = None  # from the pair's own truth.json or calib.txt; None = the params.yaml value
    calib: Path | None = None  # calib.txt (Middlebury) or calib.yml / calib.yaml (OpenCV stereo calibration)
    truth: Path | None = None  # truth.npz with `disparity` (float32, NaN = unknown)


#: a pair's calibration file, first found: Middlebury calib.txt or an OpenCV stereo YAML (K1 D1 K2 D2 R T)
CALIB_FILES = ("calib.txt", "calib.yml", "calib.yaml")


def _stereo_pair(d: Path, name: str) -> StereoPair | str:
    imgs = {f.stem.lower(): f for f in images_in(d)}
    if "left" not in imgs or "right" not in imgs:
        return "needs left.<ext> and right.<ext>"
    max_disp = None
    calib = next((d / n for n in CALIB_FILES if (d / n).is_file()), None)
    if (d / TRUTH_FILE).is_file():
        data = read_truth(d / TRUTH_FILE)
        if "max_disp" in data:
            max_disp = check_int("max_disp", data["max_disp"], 1, source=str(d / TRUTH_FILE))
    if max_disp is None and calib is not None and calib.suffix == ".txt":
        try:
            text = read_text(calib, "calibration")
        except InputError:
            text = ""  # stereo_rectify parses the file and drops the pair with the reason
        m = re.search(r"^\s*ndisp\s*=\s*0*([1-9]\d{0,5})\s*$", text, re.M)
        if m:
            max_disp = int(m.group(1))
    truth = d / "truth.npz" if (d / "truth.npz").is_file() else None
    return StereoPair(name, imgs["left"], imgs["right"], max_disp, calib, truth)


def find_stereo(folder: str | os.PathLike) -> tuple[list[StereoPair], list[dict]]:
    """One pair per subfolder with ``left.*`` / ``right.*`` (or the folder itself when it holds them)."""
    d = _folder(folder, "stereo")
    dropped: list[dict] = []
    own = _stereo_pair(d, d.name)
    if isinstance(own, StereoPair):
        return [own], dropped
    pairs = []
    for sub in sorted(p for p in d.iterdir() if p.is_dir() and not p.name.startswith(".")):
        got = _stereo_pair(sub, sub.name)
        if isinstance(got, str):
            _drop(dropped, sub.name, got)
        else:
            pairs.append(got)
    if not pairs:
        raise InputError(f"{d}: no stereo pair found (a pair folder holds left.<ext> and right.<ext>)")
    return pairs, dropped


def read_stereo_truth(path: str | os.PathLike, shape: tuple[int, ...]) -> np.ndarray:
    """The true disparity of a pair: the ``disparity`` array of its ``truth.npz`` (:attr:`StereoPair.truth`).

    Parameters
    ----------
    path : str or path-like
        The pair's ``truth.npz``.
    shape : tuple of int
        ``(H, W)`` of the left image the truth must cover.

    Returns
    -------
    ndarray, (H, W) float32
        Disparity in pixels, NaN where unknown.

    Raises
    ------
    InputError
        The file is unreadable, has no ``disparity`` array, or that array is not numbers of ``shape``.
    """
    disparity = load_npz(path, ("disparity",))["disparity"]
    if disparity.dtype.kind not in "iuf":
        raise InputError(f"{path}: array `disparity` must hold numbers (pixels, NaN = unknown), got dtype "
                         f"{disparity.dtype}")
    if disparity.shape != shape:
        raise InputError(f"{path}: array `disparity` has shape {disparity.shape}, the left image is {shape}")
    return disparity.astype(np.float32)


# ------------------------------------------------------------------------------------------------------- panorama


@dataclass(frozen=True)
class PanoramaSet:
    name: str
    files: list[Path]
    H: list[np.ndarray | None] | None = None  # per image (`files` order): image -> truth's first image pixels


def find_panorama(folder: str | os.PathLike) -> tuple[list[PanoramaSet], list[dict]]:
    """Every subfolder of ``folder`` is one set; a set needs at least two images.

    ``truth.json`` (optional) lists ``sets[]`` with ``name``, ``images`` (file names, also ``<set>/<file>``) and
    ``H`` (per image, image -> first listed image pixels). A set the truth names gets ``H`` with ``None`` for its
    images the truth does not list (e.g. a distractor); a set it does not name gets ``H = None``.
    """
    d = _folder(folder, "panorama")
    dropped: list[dict] = []
    truth: dict[str, dict[str, np.ndarray]] = {}
    for path, where, r in _truth(d, "sets"):
        names = _field(path, r, where, "images")
        Hs = _field(path, r, where, "H")
        if not isinstance(names, list) or not isinstance(Hs, list) or len(names) != len(Hs):
            raise InputError(f"{path}: fields `{where}.images` and `{where}.H` must be lists of equal length")
        truth[_text(path, r, where, "name")] = {
            Path(_text(path, {f"images[{k}]": n}, where, f"images[{k}]")).name:
                _array(path, {f"H[{k}]": h}, where, f"H[{k}]", (3, 3))
            for k, (n, h) in enumerate(zip(names, Hs))
        }
    sets = []
    for sub in sorted(p for p in d.iterdir() if p.is_dir() and not p.name.startswith(".")):
        files = images_in(sub)
        if len(files) < 2:
            _drop(dropped, sub.name, f"a panorama set needs at least 2 images, found {len(files)}")
            continue
        t = truth.get(sub.name)
        H = [t.get(f.name) for f in files] if t else None
        sets.append(PanoramaSet(sub.name, files, H))
    for f in images_in(d):
        _drop(dropped, f.name, "images must be in one subfolder per panorama set")
    if not sets:
        raise InputError(f"{d}: no panorama set found (one subfolder of 2 or more images per set)")
    return sets, dropped


def _unique(items: list, task: str) -> list:
    """Refuse two items of the same name (their outputs would overwrite each other)."""
    seen: dict[str, Any] = {}
    for it in items:
        if it.name in seen:
            raise InputError(f"{task}: two inputs share the name {it.name!r} ({_where(seen[it.name])} and "
                             f"{_where(it)}); rename one")
        seen[it.name] = it
    return items


def _where(item: Any) -> str:
    for attr in ("path", "a", "left"):
        if hasattr(item, attr):
            return str(getattr(item, attr))
    return item.name
