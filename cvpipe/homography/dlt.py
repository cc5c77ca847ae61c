"""Hartley-normalized direct linear transform and the input checks shared by the homography estimators."""

from __future__ import annotations

import numpy as np

from ..errors import EstimationError, InputError
from ..geometry import apply_homography, as_points, collinear, hartley_normalization
from ._dlt import denormalize

#: relative size of the smaller principal axis below which a whole point set counts as collinear (1e-7: the
#: 2x2 covariance resolves eigenvalue ratios down to ~1e-15, i.e. axis ratios down to ~3e-8)
_ALL_COLLINEAR_EPS = 1e-7
#: map points through a homography (the name this package has always exported)
transform_points = apply_homography


def _check_pair(src, dst) -> tuple[np.ndarray, np.ndarray]:
    s = as_points("src", src)
    d = as_points("dst", dst)
    if len(s) != len(d):
        raise InputError(f"`src` and `dst` must have the same number of points, got {len(s)} and {len(d)}")
    if len(s) < 4:
        raise InputError(f"a homography needs at least 4 correspondences, got {len(s)}")
    return s, d


def _check_not_collinear(name: str, pts: np.ndarray) -> None:
    """Raise EstimationError when every point lies on one line (or coincides)."""
    if collinear(pts, _ALL_COLLINEAR_EPS):
        raise EstimationError(
            f"all `{name}` points are collinear or coincident, so the homography is undetermined; "
            "supply correspondences spread over a 2-D region"
        )


def _unit_h22(H: np.ndarray) -> np.ndarray:
    """``H`` scaled so that H[2, 2] = 1 (or to unit Frobenius norm if H[2, 2] is 0 or that scaling overflows).

    H[2, 2] may be tiny against the other entries and still right: points 1e12 apart map the unit square with
    H[2, 2] / |H| = 7e-13, and H / H[2, 2] is finite.
    """
    if H[2, 2] != 0.0:
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            scaled = H / H[2, 2]
        if np.isfinite(scaled).all():
            return scaled
    return H / np.linalg.norm(H)  # the origin of src maps to infinity: keep a finite representative


def dlt(src, dst, weights=None) -> np.ndarray:
    """Hartley-normalized direct linear transform: the least-squares homography of >= 4 correspondences.

    Minimizes the algebraic error of ``dst_i x (H src_i) = 0`` in normalized coordinates (Hartley & Zisserman,
    algorithm 4.2), which for exactly 4 points in general position is the exact homography.

    Parameters
    ----------
    src, dst : (N, 2) array_like
        Corresponding points (pixels), N >= 4.
    weights : (N,) array_like, optional
        Non-negative weight per correspondence (default 1).

    Returns
    -------
    H : (3, 3) float64
        Maps ``src`` to ``dst``, ``H[2, 2] = 1``.

    Raises
    ------
    InputError
        Bad shapes, fewer than 4 points, NaN/inf, bad weights.
    EstimationError
        All points collinear, or the system is rank-deficient.

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.homography import dlt
    >>> src = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> dlt(src, 2.0 * src + 1.0).round(12) + 0.0
    array([[2., 0., 1.],
           [0., 2., 1.],
           [0., 0., 1.]])
    """
    s, d = _check_pair(src, dst)
    _check_not_collinear("src", s)
    _check_not_collinear("dst", d)
    if weights is None:
        w = np.ones(len(s))
    else:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (len(s),):
            raise InputError(f"`weights` must have shape ({len(s)},), got {w.shape}")
        if not np.isfinite(w).all() or (w < 0).any():
            raise InputError("`weights` must be finite and non-negative")
    Ts, Td = hartley_normalization(s), hartley_normalization(d)
    sn = s @ Ts[:2, :2].T + Ts[:2, 2]
    dn = d @ Td[:2, :2].T + Td[:2, 2]
    n = len(s)
    x, y, u, v = sn[:, 0], sn[:, 1], dn[:, 0], dn[:, 1]
    one, zero = np.ones(n), np.zeros(n)
    A = np.empty((2 * n, 9))
    A[0::2] = np.stack([x, y, one, zero, zero, zero, -u * x, -u * y, -u], axis=1)
    A[1::2] = np.stack([zero, zero, zero, x, y, one, -v * x, -v * y, -v], axis=1)
    A *= np.repeat(np.sqrt(w), 2)[:, None]
    if len(A) < 9:
        # 4 points give 8 equations: pad to 9 rows so that the SVD returns the null vector as its 9th row
        A = np.vstack([A, np.zeros((9 - len(A), 9))])
    _, sv, vt = np.linalg.svd(A, full_matrices=False)
    # rank 8 is needed for a unique solution: the 8th singular value must not vanish
    if sv[7] <= 1e-12 * sv[0]:
        raise EstimationError("the DLT system is rank-deficient (degenerate configuration); supply more spread points")
    H = np.empty((3, 3))
    denormalize(np.ascontiguousarray(vt[-1].reshape(3, 3)), Ts, np.linalg.inv(Td), H)
    return _unit_h22(H)
