"""The gallery and the scenes' features read back from a features stage's folder (``logo_features@det``), for the
``logo_match`` and ``logo_verify`` stages: one ``.npz`` per image at the image's path under the ``logo.data``
folder, and the stage's ``dropped.json``. The only module of the package that reads files."""

from __future__ import annotations

from pathlib import Path

from .. import io
from ..datasets import LogoInputs
from ..errors import CvpipeError
from ..features import NPZ_ARRAYS, Features
from ..params import LogoMatchParams
from .gallery import Gallery, Reference, blank_reason, build_gallery


def feature_reasons(features: Path) -> dict[str, str]:
    """``item -> reason`` of the features stage's ``dropped.json``, when it wrote one."""
    f = features / "dropped.json"
    return {d["item"]: d["reason"] for d in io.load_json(f)} if f.is_file() else {}


def features_of(features: Path, root: Path, image: Path, reasons: dict[str, str]) -> dict | str:
    """The cached feature arrays of ``image`` (under ``root``), or why there are none (from ``reasons``,
    :func:`feature_reasons`)."""
    rel = image.relative_to(root)
    f = features / rel.with_suffix(".npz")
    if f.is_file():
        return io.load_npz(f, NPZ_ARRAYS)
    return reasons.get(rel.as_posix(), reasons.get(image.name, "no features (logo_features did not process it)"))


def load_gallery(inputs: LogoInputs, root: Path, features: Path, params: LogoMatchParams) -> tuple[Gallery, list[dict]]:
    """The gallery indexed from the cached features.

    Parameters
    ----------
    inputs : LogoInputs
        :func:`cvpipe.datasets.find_logo` of ``root``.
    root : Path
        The ``logo.data`` folder.
    features : Path
        The features stage's output folder.
    params : LogoMatchParams
        ``min_features`` and ``reference_features`` of :func:`~cvpipe.logo.build_gallery`.

    Returns
    -------
    gallery : Gallery
        Every reference file mapped to its brand (the brands in sorted order, a brand's files in the order
        ``find_logo`` lists them).
    dropped : list of dict
        ``{"item", "reason"}`` for each reference left out (no features, blank, too few keypoints); the last entry
        of a brand left with no usable reference adds ``"; brand '<brand>' is not used"``.
    """
    reasons, dropped, refs, brand_of = feature_reasons(features), [], [], {}
    for brand in sorted(inputs.gallery):
        for image in inputs.gallery[brand]:
            name = image.relative_to(root).as_posix()
            brand_of[name] = brand
            got = features_of(features, root, image, reasons)
            if isinstance(got, str):
                dropped.append({"item": name, "reason": got})
                continue
            w, h = (int(v) for v in got["image_size"])
            refs.append(Reference(brand, name, Features.from_arrays(got), (w, h)))
    gallery = build_gallery(refs, params.min_features, params.reference_features)
    few = set(gallery.dropped)
    dropped += [{"item": r.name, "reason": _too_few(root, r, params.min_features)} for r in refs if r.name in few]
    for brand in sorted(set(inputs.gallery) - set(gallery.brands)):
        mine = [d for d in dropped if brand_of.get(d["item"]) == brand]
        if mine:
            mine[-1]["reason"] += f"; brand {brand!r} is not used"
    return gallery, dropped


def _too_few(root: Path, ref: Reference, min_features: int) -> str:
    """Why ``ref`` (fewer than ``min_features`` keypoints) is left out: blank, when it has no keypoint and its image
    (``root / ref.name``) holds one grey level; else the keypoint count."""
    if len(ref.features) == 0:
        try:
            why = blank_reason(io.read_image(root / ref.name, "gray"))
        except CvpipeError:
            why = None  # the features stage read it; gone or changed since, the count still says why
        if why:
            return why
    return f"fewer than {min_features} keypoints"
