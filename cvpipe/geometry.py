"""Shared 2-D point geometry: point-array validation, Hartley normalization, mapping points through a homography and
image corners (``image_corners`` is defined in :mod:`cvpipe.metrics`, its first user, and re-exported here).

Coordinates are OpenCV's (x = column, y = row, pixels); homographies act on homogeneous column vectors ``[x, y, 1]``.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import EstimationError, InputError
from .metrics import image_corners

__all__ = ["apply_homography", "as_points", "collinear", "hartley_normalization", "image_corners"]


def as_points(name: str, pts) -> np.ndarray:
    """(N, 2) float64 copy of ``pts``, or InputError naming the parameter ``name``; accepts OpenCV's (N, 1, 2) layout.

    Examples
    --------
    >>> as_points("src", [[[1, 2]], [[3, 4]]]).tolist()
    [[1.0, 2.0], [3.0, 4.0]]
    >>> as_points("src", [[1.0, float("nan")]])
    Traceback (most recent call last):
    ...
    cvpipe.errors.InputError: `src` contains NaN or inf (first at row 0)
    """
    try:
        a = np.asarray(pts, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"`{name}` must be a numeric (N, 2) array ({exc})") from exc
    if a.ndim == 3 and a.shape[1] == 1 and a.shape[2] == 2:
        a = a.reshape(-1, 2)
    if a.ndim != 2 or a.shape[1] != 2:
        raise InputError(f"`{name}` must have shape (N, 2), got {a.shape}")
    if not np.isfinite(a).all():  # the whole array first: a reduction over rows of 2 costs 15x more
        bad = ~np.isfinite(a).all(axis=1)
        raise InputError(f"`{name}` contains NaN or inf (first at row {int(np.argmax(bad))})")
    return np.ascontiguousarray(a)


def collinear(pts: np.ndarray, eps: float) -> bool:
    """True when every point of ``pts`` (N, 2) lies on one line (or coincides): the smaller principal axis of the
    centred points is at most ``eps`` times the larger one.

    Examples
    --------
    >>> collinear(np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]), 1e-7)
    True
    >>> collinear(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), 1e-7)
    False
    """
    c = pts - pts.mean(axis=0)
    sv = np.linalg.svd(c, compute_uv=False)
    return bool(sv[0] == 0.0 or sv[1] <= eps * sv[0])


def hartley_normalization(pts: np.ndarray) -> np.ndarray:
    """The similarity T moving the centroid of ``pts`` to the origin and their mean distance to it to sqrt(2).

    Parameters
    ----------
    pts : (N, 2) float
        Points, x = column, y = row (pixels).

    Returns
    -------
    T : (3, 3) float64
        ``T @ [x, y, 1]`` are the normalized homogeneous points.

    Examples
    --------
    >>> hartley_normalization(np.array([[0.0, 0.0], [2.0, 0.0]])).round(4).tolist()
    [[1.4142, 0.0, -1.4142], [0.0, 1.4142, -0.0], [0.0, 0.0, 1.0]]
    """
    pts = np.asarray(pts, dtype=np.float64)
    c = pts.mean(axis=0)
    d = np.sqrt(((pts - c) ** 2).sum(axis=1)).mean()
    if not np.isfinite(d) or d <= 0.0:
        raise EstimationError("all points coincide, so they cannot be normalized; supply distinct points")
    s = math.sqrt(2.0) / d
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


def apply_homography(H, pts) -> np.ndarray:
    """Map points through a homography.

    Parameters
    ----------
    H : (3, 3) array_like
        Homography acting on homogeneous column vectors ``[x, y, 1]``.
    pts : (N, 2) array_like
        Points, x = column, y = row (pixels).

    Returns
    -------
    (N, 2) float64
        The mapped points; a point sent to the line at infinity becomes ``inf``.

    Examples
    --------
    >>> H = [[2.0, 0.0, 1.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]
    >>> apply_homography(H, [[1.0, 1.0], [0.0, 3.0]]).tolist()
    [[3.0, 2.0], [1.0, 6.0]]
    """
    H = np.asarray(H, dtype=np.float64)
    if H.shape != (3, 3):
        raise InputError(f"`H` must have shape (3, 3), got {H.shape}")
    if not np.isfinite(H).all():
        raise InputError("`H` contains NaN or inf")
    p = np.asarray(pts, dtype=np.float64)
    if p.ndim == 3 and p.shape[1:] == (1, 2):
        p = p.reshape(-1, 2)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"`pts` must have shape (N, 2), got {p.shape}")
    q = p @ H[:, :2].T + H[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = q[:, :2] / q[:, 2:3]
    out[q[:, 2] == 0.0] = np.inf
    return out
