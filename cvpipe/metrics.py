"""Accuracy metrics against ground truth (small, generic, shared by the tasks' reports and benchmarks)."""

from __future__ import annotations

import numpy as np

from .errors import InputError


def _homography(name: str, H) -> np.ndarray:
    a = np.asarray(H, dtype=np.float64)
    if a.shape != (3, 3):
        raise InputError(f"`{name}` must have shape (3, 3), got {a.shape}")
    if not np.isfinite(a).all():
        raise InputError(f"`{name}` contains NaN or inf")
    return a


def image_corners(width: int, height: int) -> np.ndarray:
    """(4, 2) float64 corners of a width x height image in pixel-centre coordinates: (0, 0), (w-1, 0), (w-1, h-1),
    (0, h-1), clockwise from the top-left (x = column, y = row)."""
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise InputError(f"`{name}` must be an integer >= 1, got {v!r}")
    w, h = float(width - 1), float(height - 1)
    return np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]])


def corner_error(H_est, H_true, width: int, height: int) -> float:
    """Mean distance in pixels between the four image corners mapped by ``H_est`` and by ``H_true``.

    Parameters
    ----------
    H_est, H_true : (3, 3) array_like
        Homographies from the image of size ``width`` x ``height`` (the source) to another image.
    width, height : int
        Size of the source image in pixels; the corners are those of :func:`image_corners`.

    Returns
    -------
    float
        The mean corner distance in pixels of the target image; ``inf`` if ``H_est`` sends a corner to infinity or
        to the other side of the horizon (a sign flip of the homogeneous coordinate relative to ``H_true``).
    """
    He = _homography("H_est", H_est)
    Ht = _homography("H_true", H_true)
    c = np.hstack([image_corners(width, height), np.ones((4, 1))])
    pe = c @ He.T
    pt = c @ Ht.T
    # each H has an arbitrary scale, so only a corner-to-corner change of sign of w_est / w_true reveals a corner
    # sent across the horizon
    if np.any(pe[:, 2] == 0) or np.any(pt[:, 2] == 0) or len(set(np.sign(pe[:, 2] * pt[:, 2]))) != 1:
        return float("inf")
    d = pe[:, :2] / pe[:, 2:3] - pt[:, :2] / pt[:, 2:3]
    return float(np.sqrt((d**2).sum(axis=1)).mean())


# ---- dense maps (stereo disparity): NaN = missing estimate / unknown truth ----


def _known(truth: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """Boolean map of pixels whose truth is known (finite) and, if given, inside ``mask``."""
    known = np.isfinite(truth)
    if mask is not None:
        if mask.shape != truth.shape:
            raise InputError(f"`mask` must have the shape of `truth` {truth.shape}, got {mask.shape}")
        known &= mask.astype(bool)
    return known


def _check_maps(estimate: np.ndarray, truth: np.ndarray) -> None:
    if estimate.shape != truth.shape:
        raise InputError(f"`estimate` must have the shape of `truth` {truth.shape}, got {estimate.shape}")


def bad_pixel_rate(estimate: np.ndarray, truth: np.ndarray, threshold: float, mask: np.ndarray | None = None) -> float:
    """Share of pixels with known truth whose estimate is missing (NaN) or off by more than ``threshold``.

    Parameters
    ----------
    estimate, truth : ndarray, (H, W) float
        Estimated and true values (e.g. disparity in pixels); NaN marks a missing estimate / unknown truth.
    threshold : float
        Largest accepted absolute error (e.g. 1.0 or 2.0 pixels for Middlebury's bad-1.0 / bad-2.0), >= 0.
    mask : ndarray, (H, W) bool, optional
        Restrict the evaluation to these pixels (e.g. non-occluded).

    Returns
    -------
    float
        In [0, 1]; NaN when no pixel has known truth.
    """
    _check_maps(estimate, truth)
    if not threshold >= 0:
        raise InputError(f"`threshold` must be >= 0, got {threshold}")
    known = _known(truth, mask)
    n = int(known.sum())
    if n == 0:
        return float("nan")
    err = np.abs(estimate[known].astype(np.float64) - truth[known])
    good = np.isfinite(err) & (err <= threshold)
    return float(1.0 - good.sum() / n)


def mean_abs_error(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Mean absolute error over pixels where both the estimate and the truth exist (NaN if there are none)."""
    _check_maps(estimate, truth)
    both = _known(truth, mask) & np.isfinite(estimate)
    if not both.any():
        return float("nan")
    return float(np.mean(np.abs(estimate[both].astype(np.float64) - truth[both])))


def density(estimate: np.ndarray, truth: np.ndarray | None = None, mask: np.ndarray | None = None) -> float:
    """Share of pixels with an estimate (finite), over the pixels with known truth when ``truth`` is given."""
    if truth is None:
        known = np.ones(estimate.shape, bool) if mask is None else mask.astype(bool)
    else:
        _check_maps(estimate, truth)
        known = _known(truth, mask)
    n = int(known.sum())
    return float("nan") if n == 0 else float(np.isfinite(estimate[known]).sum() / n)
