"""The gallery: one index over the descriptors of every reference image of every brand, built once."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np

from ..errors import InputError, check_int, check_memory
from ..features import DETECTORS, Features, check_detector
from ..geometry import image_corners
from ..matching import flann_matcher
from ..params import LogoMatchParams

#: the ``logo.match`` defaults: the one declaration of :func:`build_gallery`'s ``min_features``
_MATCH = LogoMatchParams()


@dataclass(frozen=True)
class Reference:
    """One gallery image of a brand.

    Attributes
    ----------
    brand : str
        Brand name (the gallery file or folder name).
    name : str
        Where the image came from (file name), used in messages.
    features : Features
        Its keypoints and descriptors (positions in reference pixels).
    size : tuple of int
        (width, height) of the reference image in pixels.
    box : tuple of float, optional
        ``(x1, y1, x2, y2)`` corner pixel centres of the logo inside the reference image, when the reference is a
        whole photo with the logo boxed (features then come from inside the box, detected with the photo around
        it so that descriptors near the box edge see real context). Default: the whole image.
    """

    brand: str
    name: str
    features: Features
    size: tuple[int, int]
    box: tuple[float, float, float, float] | None = None

    @property
    def outline(self) -> np.ndarray:
        """(4, 2) logo outline in reference pixels, clockwise from the top-left."""
        if self.box is None:
            return image_corners(*self.size)
        x1, y1, x2, y2 = self.box
        return np.array([[x1, y1], [x2, y1], [x2, y2], [x1, y2]], np.float64)

    @property
    def area(self) -> float:
        """Area of the logo outline, px^2."""
        q = self.outline
        return float((q[1, 0] - q[0, 0]) * (q[2, 1] - q[1, 1]))


@dataclass(frozen=True, eq=False)
class Gallery:
    """The indexed gallery: stacked descriptors of every usable reference and their index: for float descriptors a
    FLANN matcher trained on them, for binary ones the descriptors as rows of 8-byte words, searched exactly.

    Attributes
    ----------
    detector : str
        Detector of every reference (scenes must use the same one).
    brands : tuple of str
        Sorted brand names.
    references : tuple of Reference
        Usable references (at least ``min_features`` keypoints).
    dropped : tuple of str
        Names of references left out for having too few keypoints.
    ref_of : (M,) int64
        Reference index of every stacked descriptor.
    local_of : (M,) int64
        Keypoint index inside its reference of every stacked descriptor.
    brand_of_ref : (R,) int64
        Index into ``brands`` of every reference.
    matcher : cv2.DescriptorMatcher or None
        The FLANN index of float descriptors (None for binary ones).
    words : (M, W) uint64 or None
        Binary descriptors zero-padded to ``W`` whole 8-byte words (None for float ones): the Hamming distance of
        two rows is the sum of their words' bit counts (:func:`cvpipe.logo.match.match_scene`).
    """

    detector: str
    brands: tuple[str, ...]
    references: tuple[Reference, ...]
    dropped: tuple[str, ...]
    ref_of: np.ndarray
    local_of: np.ndarray
    brand_of_ref: np.ndarray
    matcher: cv2.DescriptorMatcher | None = field(repr=False)
    words: np.ndarray | None = field(default=None, repr=False)

    @property
    def binary(self) -> bool:
        return DETECTORS[self.detector][1]

    def __reduce__(self):
        # the trained OpenCV matcher cannot be pickled: a copy (a Dask worker's) re-indexes the usable references,
        # which is deterministic (build_gallery seeds FLANN), so it answers exactly as this one
        return _rebuild, (self.references, self.dropped)


def _rebuild(references: tuple, dropped: tuple) -> "Gallery":
    """The gallery of :meth:`Gallery.__reduce__`: the usable references indexed again, the dropped names kept."""
    from dataclasses import replace

    return replace(build_gallery(references, 4), dropped=dropped)


def _prepare(desc: np.ndarray, binary: bool) -> np.ndarray:
    """RootSIFT for float descriptors (L1 normalise, square root): Hellinger instead of Euclidean distance, which
    matches SIFT histograms better; binary descriptors pass through."""
    if binary:
        return np.ascontiguousarray(desc, np.uint8)
    d = np.asarray(desc, np.float32)
    d = d / (np.abs(d).sum(axis=1, keepdims=True) + 1e-7)
    return np.ascontiguousarray(np.sqrt(np.maximum(d, 0)), np.float32)


def binary_words(desc: np.ndarray) -> np.ndarray:
    """Binary descriptors (N, L) uint8 as (N, ceil(L / 8)) uint64 rows, zero-padded (no bit is added, so Hamming
    distances are unchanged)."""
    d = np.ascontiguousarray(desc, np.uint8)
    return np.ascontiguousarray(np.pad(d, ((0, 0), (0, -d.shape[1] % 8)))).view(np.uint64)


def _strongest(f: Features, n: int) -> Features:
    """The ``n`` keypoints of highest detector response."""
    keep = np.sort(np.argsort(-np.asarray(f.response), kind="stable")[:n])
    return Features(f.xy[keep], f.size[keep], f.angle[keep], f.response[keep], f.descriptors[keep], f.detector)


#: memory a gallery holds per byte of its references' keypoints and descriptors: the references themselves, the
#: stacked descriptors and the matcher's index (measured: 4.3x in the RSS of ``cvpipe logo`` over 30 and 300
#: references of 169 SIFT keypoints on average)
GALLERY_BYTES_PER_FEATURE_BYTE = 5.0


def features_nbytes(features: Features) -> int:
    """Bytes of the arrays of one reference's keypoints and descriptors."""
    return sum(a.nbytes for a in (features.xy, features.size, features.angle, features.response,
                                  features.descriptors))


def check_gallery_memory(feature_bytes: int, references: int) -> None:
    """BudgetError when a gallery of ``references`` images holding ``feature_bytes`` of keypoints and descriptors
    would exceed the memory budget (:func:`cvpipe.errors.memory_budget`); the message names what to change."""
    check_memory(GALLERY_BYTES_PER_FEATURE_BYTE * feature_bytes,
                 f"the gallery of {references} reference images ({feature_bytes / 1e6:.3g} MB of keypoints)",
                 "use fewer gallery images, or fewer keypoints per image (`--max-features`, "
                 "`logo.features.max_features`)")


def blank_reason(gray: np.ndarray) -> str | None:
    """``"blank (one grey level, v)"`` when every pixel of the reference image ``gray`` is ``v`` (no detector finds a
    keypoint in it), else None: why such a gallery image is not used."""
    lo, hi = int(gray.min()), int(gray.max())
    return f"blank (one grey level, {lo})" if lo == hi else None


def _refuse_copies_across_brands(refs: Sequence[Reference]) -> None:
    """InputError naming both files when two brands hold the same picture (the same keypoints and descriptors).

    The ratio test compares a brand's nearest descriptor with the nearest of any other brand: a copy of one brand's
    picture under a second brand name ties every such comparison, and neither brand can be found.
    """
    seen: dict[bytes, Reference] = {}
    for r in refs:
        key = hashlib.sha1(np.ascontiguousarray(r.features.xy).tobytes()
                           + np.ascontiguousarray(r.features.descriptors).tobytes()).digest()
        first = seen.setdefault(key, r)
        if first.brand != r.brand:
            raise InputError(f"{r.name}: the same picture as {first.name}, under another brand ({r.brand!r} and "
                             f"{first.brand!r}); no scene could be told apart between them: keep one, or put both "
                             f"in the folder of one brand (DIR/<brand>/*.<ext>)")


def build_gallery(references: Sequence[Reference], min_features: int = _MATCH.min_features,
                  max_features: int | None = None) -> Gallery:
    """Index the references of every brand once.

    Parameters
    ----------
    references : sequence of Reference
        At least one; all from the same detector.
    min_features : int
        References with fewer keypoints are dropped (listed in ``Gallery.dropped``): they cannot support a
        verified homography.
    max_features : int, optional
        Keep at most this many keypoints per reference, the strongest by detector response. The binary detectors
        find up to 4000 keypoints inside one boxed logo, and the brute-force Hamming search costs in proportion to
        the stacked total. Default: keep all.

    Raises
    ------
    InputError
        Empty gallery, no reference with at least ``min_features`` keypoints (the message names the files), the
        same picture under two brand names (the message names both files), a bad ``min_features`` /
        ``max_features``, or (BudgetError) more references than the memory budget holds.
    ValueError
        Mixed detectors.
    """
    check_int("min_features", min_features, 4)
    refs = list(references)
    if not refs:
        raise InputError("the gallery is empty: expected DIR/<brand>.<ext> or DIR/<brand>/*.<ext> images")
    check_gallery_memory(sum(features_nbytes(r.features) for r in refs), len(refs))
    detectors = sorted({r.features.detector for r in refs})
    if len(detectors) > 1:
        raise ValueError(f"gallery references must share one detector, got {detectors}")
    detector = detectors[0]
    check_detector(detector)
    for r in refs:
        if len(r.size) != 2 or min(r.size) < 1:
            raise ValueError(f"`size` of reference {r.name} must be (width, height) >= 1, got {r.size}")
        if r.box is not None:
            x1, y1, x2, y2 = r.box
            if not (0 <= x1 < x2 <= r.size[0] - 1 and 0 <= y1 < y2 <= r.size[1] - 1):
                raise ValueError(f"`box` of reference {r.name} must lie inside its {r.size[0]}x{r.size[1]} image "
                                 f"with x1 < x2 and y1 < y2, got {r.box}")
    if max_features is not None:
        check_int("max_features", max_features, min_features, note="`min_features`")
        refs = [r if len(r.features) <= max_features else
                Reference(r.brand, r.name, _strongest(r.features, int(max_features)), r.size, r.box) for r in refs]
    usable = [r for r in refs if len(r.features) >= min_features]
    dropped = tuple(r.name for r in refs if len(r.features) < min_features)
    if not usable:
        names = ", ".join(f"{r.name} ({len(r.features)})" for r in refs)
        raise InputError(f"no gallery image yields at least {min_features} keypoints with {detector}: {names}")
    _refuse_copies_across_brands(usable)
    brands = tuple(sorted({r.brand for r in usable}))
    binary = DETECTORS[detector][1]
    desc = np.concatenate([_prepare(r.features.descriptors, binary) for r in usable])
    ref_of = np.concatenate([np.full(len(r.features), i, np.int64) for i, r in enumerate(usable)])
    local_of = np.concatenate([np.arange(len(r.features), dtype=np.int64) for r in usable])
    matcher, words = None, None
    if binary:
        words = binary_words(desc)
    else:
        matcher = flann_matcher()
        matcher.add([desc])
        # FLANN's randomised kd-trees draw from OpenCV's global generator: seeding it here makes the index (and so
        # every answer) a function of the gallery alone, not of whatever ran before in the process (this resets
        # cv2's RNG)
        cv2.setRNGSeed(0)
        matcher.train()
    brand_of_ref = np.array([brands.index(r.brand) for r in usable], np.int64)
    # mapping the references of one brand into a shared frame and verifying them as one model was measured and
    # rejected (no gain on FlickrLogos: docs/notes/logo.md); every reference is verified on its own
    return Gallery(detector, brands, tuple(usable), dropped, ref_of, local_of, brand_of_ref, matcher, words)
