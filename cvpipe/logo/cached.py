"""The gallery and the scenes' features read back from a features stage's folder (``logo_features@det``), for the
``logo_match`` and ``logo_verify`` stages: one ``.npz`` per image at the image's path under the ``logo.data``
folder, and the stage's ``dropped.json``. The only module of the package that reads files."""

from __future__ import annotations

from pathlib import Path

from .. import io
from ..datasets import LogoInputs
from ..features import NPZ_ARRAYS, Features
from ..params import LogoMatchParams
from .gallery import Gallery, Reference, build_gallery


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
        ``{"item", "reason"}`` for each reference left out (no features, too few keypoints).
    """
    reasons, dropped, refs = feature_reasons(features), [], []
    for brand in sorted(inputs.gallery):
        for image in inputs.gallery[brand]:
            name = image.relative_to(root).as_posix()
            got = features_of(features, root, image, reasons)
            if isinstance(got, str):
                dropped.append({"item": name, "reason": got})
                continue
            w, h = (int(v) for v in got["image_size"])
            refs.append(Reference(brand, name, Features.from_arrays(got), (w, h)))
    gallery = build_gallery(refs, params.min_features, params.reference_features)
    dropped += [{"item": n, "reason": f"fewer than {params.min_features} keypoints"} for n in gallery.dropped]
    return gallery, dropped
