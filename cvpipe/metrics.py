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
