"""Simulated views of an image: the image as a camera sees it under a strong tilt (as ASIFT simulates views), so
that a logo photographed at a slant finds a gallery reference it resembles (:func:`cvpipe.logo.reference_views`).

A view with tilt ``t`` and longitude ``phi`` rotates the reference by ``phi``, blurs it across the direction about
to be compressed (anti-aliasing, ``0.8 * sqrt(t^2 - 1)`` pixels) and shrinks that direction by ``t``. Keypoints are
detected on the view and carried back into reference pixels through the inverse affine map (position,
orientation and size), so a view's features verify against the reference's own outline like the reference's.
In a logo gallery each view is a reference of its own: its matches are verified and scored on their own, so the
copies never add up to a larger inlier count than one picture of the mark would give.
"""

from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from .features import Features, detect

#: ``(tilt, longitude in degrees)`` of the simulated views added to each logo gallery reference, per detector. Two tilts of 2
#: (60 degrees from the frontal view) along either image axis: on the leave-one-photo-out protocol they give SIFT's
#: gallery one false answer fewer and the fused method one photo more; more views, or views for AKAZE, add nothing
#: or lose photos (docs/notes/logo.md)
REFERENCE_TILTS: dict[str, tuple[tuple[float, float], ...]] = {"sift": ((2.0, 0.0), (2.0, 90.0))}

#: the view's mask is eroded by this many pixels: a keypoint at the border of the shrunk mask sees the outside
MASK_EROSION = 2


def tilts_for(detector: str) -> tuple[tuple[float, float], ...]:
    """The simulated views :func:`reference_views` adds for ``detector`` (:data:`REFERENCE_TILTS`; none for the
    others)."""
    return REFERENCE_TILTS.get(detector, ())


def check_tilt(tilt: float, longitude: float) -> None:
    """ValueError naming the value unless ``tilt >= 1`` and ``longitude`` is finite."""
    if not (np.isfinite(tilt) and tilt >= 1.0):
        raise ValueError(f"`tilt` must be a finite number >= 1, got {tilt!r}")
    if not np.isfinite(longitude):
        raise ValueError(f"`longitude` must be finite, got {longitude!r}")


def view_transform(size: tuple[int, int], tilt: float, longitude: float) -> tuple[np.ndarray, tuple[int, int]]:
    """The affine map from reference pixels to the view's pixels, and the view's size.

    Parameters
    ----------
    size : (w, h)
        The reference image's size.
    tilt : float
        The factor the rotated image's x axis is shrunk by (>= 1).
    longitude : float
        Rotation before the shrinking, degrees.

    Returns
    -------
    (2, 3) float64, (w, h)
        ``[A | b]``: the rotation, then ``x / tilt``, then the shift that puts the view's corners at
        non-negative pixels.

    Examples
    --------
    >>> M, size = view_transform((200, 100), 2.0, 0.0)
    >>> (M + 0.0).tolist(), size  # + 0.0: no negative zeros
    ([[0.5, 0.0, 0.0], [0.0, 1.0, 0.0]], (100, 100))
    >>> M, size = view_transform((200, 100), 2.0, 90.0)  # the image stands upright, then its rows are halved
    >>> size
    (50, 200)
    """
    check_tilt(tilt, longitude)
    c, s = np.cos(np.radians(longitude)), np.sin(np.radians(longitude))
    A = np.diag([1.0 / tilt, 1.0]) @ np.array([[c, -s], [s, c]])
    w, h = size
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float64) @ A.T
    lo = corners.min(axis=0)
    span = corners.max(axis=0) - lo
    out = (int(np.floor(span[0] + 1e-9)) + 1, int(np.floor(span[1] + 1e-9)) + 1)
    return np.hstack([A, -lo[:, None]]), out


def tilted_view(gray: np.ndarray, tilt: float, longitude: float, mask: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reference ``gray`` as seen under ``tilt`` at ``longitude`` (see the module docstring).

    Parameters
    ----------
    gray : (H, W) uint8
    tilt, longitude : float
        As :func:`view_transform`.
    mask : (H, W) uint8, optional
        Where the mark is (non-zero); default: the whole image.

    Returns
    -------
    view : (h, w) uint8
    view_mask : (h, w) uint8
        The mask carried into the view (255 inside), eroded by :data:`MASK_EROSION` pixels.
    M : (2, 3) float64
        Reference pixels -> view pixels.
    """
    gray = np.asarray(gray)
    if gray.ndim != 2 or gray.dtype != np.uint8:
        raise ValueError(f"`gray` must be a (H, W) uint8 image, got shape {gray.shape} dtype {gray.dtype}")
    size = (gray.shape[1], gray.shape[0])
    M, out = view_transform(size, tilt, longitude)
    # rotate first (no shrinking: an upright copy), blur across the direction to be shrunk, then shrink
    R, rsize = view_transform(size, 1.0, longitude)
    upright = cv2.warpAffine(gray, R, rsize, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    if tilt > 1.0:
        sigma = 0.8 * np.sqrt(tilt * tilt - 1.0)
        upright = cv2.GaussianBlur(upright, (2 * int(np.ceil(3 * sigma)) + 1, 1), sigma)
    # the shrinking in the rotated frame: M = S @ R, with the offsets of both folded into S's shift
    S = np.hstack([np.diag([1.0 / tilt, 1.0]), (M[:, 2] - np.diag([1.0 / tilt, 1.0]) @ R[:, 2])[:, None]])
    view = cv2.warpAffine(upright, S, out, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    whole = np.full(gray.shape, 255, np.uint8) if mask is None else np.where(np.asarray(mask) > 0, 255, 0).astype(np.uint8)
    view_mask = cv2.warpAffine(whole, M, out, flags=cv2.INTER_NEAREST, borderValue=0)
    view_mask = cv2.erode(view_mask, np.ones((2 * MASK_EROSION + 1,) * 2, np.uint8))
    return view, view_mask, M


def features_to_reference(f: Features, M: np.ndarray, size: tuple[int, int]) -> Features:
    """Features found in a view carried back to reference pixels through the inverse of ``M`` (reference ->
    view): positions, orientations (the keypoint's direction mapped by the linear part) and sizes (times the
    square root of its determinant); keypoints that land outside the ``size = (w, h)`` image are dropped."""
    A, b = M[:, :2], M[:, 2]
    Ai = np.linalg.inv(A)
    xy = (f.xy.astype(np.float64) - b) @ Ai.T
    theta = np.radians(f.angle.astype(np.float64))
    d = np.stack([np.cos(theta), np.sin(theta)], axis=1) @ Ai.T
    angle = np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 360.0
    scale = np.sqrt(abs(np.linalg.det(Ai)))
    w, h = size
    ok = (xy[:, 0] >= 0) & (xy[:, 1] >= 0) & (xy[:, 0] <= w - 1) & (xy[:, 1] <= h - 1)
    return Features(xy[ok].astype(np.float32), (f.size[ok] * scale).astype(np.float32),
                    angle[ok].astype(np.float32), f.response[ok], np.ascontiguousarray(f.descriptors[ok]),
                    f.detector)


def view_name(name: str, tilt: float, longitude: float) -> str:
    """How messages name a simulated view of the reference ``name``.

    >>> view_name("bmw.png", 2.0, 90.0)
    'bmw.png (view: tilt 2 at 90 deg)'
    """
    return f"{name} (view: tilt {tilt:g} at {longitude:g} deg)"


def detect_views(gray: np.ndarray, detector: str, max_features: int, mask: np.ndarray | None = None,
                 tilts: Sequence[tuple[float, float]] | None = None) -> list[tuple[tuple[float, float] | None, Features]]:
    """The features of a reference image and of each of its simulated views, all in the image's pixels.

    Parameters
    ----------
    gray : (H, W) uint8
    detector : str
    max_features : int
        Per view.
    mask : (H, W) uint8, optional
        Where the mark is (non-zero); default: the whole image.
    tilts : sequence of (tilt, longitude), optional
        The views (default: :func:`tilts_for` the detector).

    Returns
    -------
    list of ((tilt, longitude) or None, Features)
        The image's own features first (``None``), then one entry per view.
    """
    gray = np.asarray(gray)
    size = (gray.shape[1], gray.shape[0])
    out: list[tuple[tuple[float, float] | None, Features]] = [(None, detect(gray, detector, max_features, mask))]
    for tilt, longitude in (tilts_for(detector) if tilts is None else tilts):
        view, view_mask, M = tilted_view(gray, tilt, longitude, mask)
        out.append(((float(tilt), float(longitude)),
                    features_to_reference(detect(view, detector, max_features, view_mask), M, size)))
    return out


def detect_views_item(item: tuple, shared) -> tuple[dict[str, np.ndarray], float]:
    """:func:`cvpipe.features.detect_item` for the ``logo_features`` stages: a scene photo as there, a gallery image
    with its simulated views (:func:`detect_views`) stacked into the arrays of one ``.npz``, plus ``view`` (per
    keypoint: 0 for the image's own, ``k`` for the k-th view) and ``views`` ((K, 2): each view's tilt and
    longitude), which :func:`split_views` takes apart again (``shared``: the ``logo.features`` section).
    """
    import time

    from .features import detect_item

    gray, scene = item
    if scene:
        return detect_item(item, shared)
    t0 = time.perf_counter()
    found = detect_views(gray, shared.detector, shared.max_features)
    seconds = time.perf_counter() - t0
    stacked = {key: np.concatenate([f.to_arrays()[key] for _, f in found])
               for key in Features.ARRAYS if key != "detector"}
    return {**found[0][1].to_arrays(), **stacked, "image_size": gray.shape[::-1],
            "view": np.concatenate([np.full(len(f), k, np.int16) for k, (_, f) in enumerate(found)]),
            "views": np.array([v for v, _ in found[1:]], np.float64).reshape(-1, 2)}, seconds


def split_views(arrays: dict[str, np.ndarray]) -> list[tuple[tuple[float, float] | None, Features]]:
    """The image's own features and each view's, from the arrays :func:`detect_views_item` wrote (arrays
    without ``view``: the image's own features alone)."""
    feats = Features.from_arrays(arrays)
    if "view" not in arrays:
        return [(None, feats)]
    view = np.asarray(arrays["view"])
    views = np.asarray(arrays["views"], np.float64).reshape(-1, 2)
    out = []
    for k in range(len(views) + 1):
        keep = np.flatnonzero(view == k)
        f = Features(feats.xy[keep], feats.size[keep], feats.angle[keep], feats.response[keep],
                     feats.descriptors[keep], feats.detector)
        out.append((None if k == 0 else (float(views[k - 1][0]), float(views[k - 1][1])), f))
    return out
