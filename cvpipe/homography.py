"""Planar homography estimation: Hartley-normalized DLT, locally optimized RANSAC and Levenberg-Marquardt refinement.

:func:`find_homography` has the semantics of ``cv2.findHomography(src, dst, cv2.RANSAC, threshold)``: ``H`` maps
``src`` to ``dst`` (homogeneous column vectors, ``H[2, 2] = 1``), a correspondence is an inlier when the one-sided
reprojection error ``|| dehom(H @ src_i) - dst_i ||`` is at most ``threshold`` pixels, and the result carries the
boolean inlier mask. The pipeline is

1. Hartley normalization of both point sets (centroid to the origin, mean distance sqrt(2));
2. RANSAC over minimal 4-point samples drawn without replacement, solved in closed form (the two projective bases),
   with degenerate samples rejected before solving (three collinear points in either view, or triangle orientations
   that disagree between the views, which no homography with every point in front of both cameras produces);
3. MSAC scoring (truncated squared error) with Wald's sequential probability ratio test (Chum & Matas 2008: a bad
   hypothesis is dropped after a few dozen points; its parameters are re-estimated as the run goes), an exact
   bail-out once a hypothesis cannot beat the best so far, and the adaptive iteration bound
   ``log(1 - confidence) / log(1 - w^4 (1 - 1/A))`` from the best inlier ratio ``w`` so far (``1/A`` bounds the
   chance that the SPRT rejects a good model); the points are verified in a random order;
4. LO-RANSAC: every so-far-best model is re-estimated by least squares on its inliers, then iteratively with the
   inlier threshold shrinking from ``lo_multiplier * threshold`` to ``threshold``;
5. a final iteratively reweighted Levenberg-Marquardt refinement of the reprojection error (Tukey weights).

The per-hypothesis loop, scoring and refinement are numba kernels (``cache=True``; the first call with a fresh
``NUMBA_CACHE_DIR`` compiles them, about 30 s of CPU once; later processes load them in about a second). Random numbers come from a ``numpy.random.Generator`` in chunks, so
a seeded ``rng`` reproduces a result exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from numba import njit

from .errors import EstimationError, InputError
from .linalg import cholesky_solve as _cholesky_solve

#: default iteration cap of :func:`find_homography` (enough for ~85 % outliers at confidence 0.999)
DEFAULT_MAX_ITERS = 10_000
#: smallest |twice the triangle area| of a sample triple in Hartley-normalized coordinates (mean radius sqrt(2))
_COLLINEAR_EPS = 1e-5
#: smallest |det(Hn)| / ||Hn||_F^3 of a model in Hartley-normalized coordinates (identity: 0.19; a mark covering a
#: tenth of the scene's width: ~5e-3). Below it H nearly collapses the source onto a line or a point, where a
#: cluster of many-to-one matches scores as exact "inliers" and wins the MSAC cost (seen with ORB on repetitive
#: PCB texture: 24 source points matched to one scene point gave models at 3e-5 to 8e-5, and 1e-8)
_MIN_CONDITION = 2e-4
#: relative size of the smaller principal axis below which a whole point set counts as collinear (1e-7: the
#: 2x2 covariance resolves eigenvalue ratios down to ~1e-15, i.e. axis ratios down to ~3e-8)
_ALL_COLLINEAR_EPS = 1e-7
#: SPRT: time of one hypothesis (sample, checks, solve) in units of one point verification, and models per sample
_SPRT_TM = 200.0
_SPRT_MS = 1.0
#: initial SPRT guesses: inlier ratio of a good model and consistent fraction of a bad one (both re-estimated)
_SPRT_EPS0 = 0.05
_SPRT_DELTA0 = 0.01
#: final refinement: IRLS rounds, loss (see ``_weights``: 1 = Tukey biweight) and its cut-off relative to the
#: threshold. The threshold bounds the noise of an inlier, but real matches (SIFT under viewpoint change) have
#: heavier tails: a smooth redescending weight over 3x the threshold (weight 0.79 at the threshold, 0.31 at twice
#: it) gave lower corner errors on the Oxford/CMP pairs than hard inliers (see BENCHMARKS.md), like MAGSAC++'s
#: marginalisation over the noise scale; the returned inlier mask still uses the threshold itself.
_FINAL_ROUNDS = 3
_FINAL_LOSS = 1
_FINAL_WSCALE = 3.0
#: a model is accepted only when its number of false alarms is below this (a-contrario, Moisan & Stival's ORSA: an
#: NFA < 1 means fewer than one model this good is expected from matches that are pure chance)
MAX_NFA = 1.0
#: index into the 6 unique entries (xx, xy, x, yy, y, 1) of a symmetric 3x3 p p^T
_SYM6 = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]], dtype=np.int64)


@dataclass(frozen=True, eq=False)
class HomographyFit:
    """The result of :func:`find_homography`.

    Attributes
    ----------
    H : (3, 3) float64
        Maps ``src`` to ``dst`` (homogeneous column vectors), scaled so that ``H[2, 2] = 1``.
    inliers : (N,) bool
        Correspondences whose reprojection error under ``H`` is at most ``threshold`` pixels.
    iterations : int
        RANSAC hypotheses drawn (degenerate samples that were rejected before solving are not counted).
    rms : float
        Root-mean-square reprojection error of the inliers under ``H``, in pixels of ``dst``.
    log10_nfa : float
        ``log10`` of the number of false alarms of the inlier count (see :func:`log10_nfa`); negative = significant.
    """

    H: np.ndarray
    inliers: np.ndarray
    iterations: int
    rms: float
    log10_nfa: float = float("nan")

    @property
    def num_inliers(self) -> int:
        """Number of inliers."""
        return int(self.inliers.sum())


# ----------------------------------------------------------------------------------------------- validation


def _as_points(name: str, pts) -> np.ndarray:
    """(N, 2) float64 copy of ``pts``; accepts OpenCV's (N, 1, 2) layout too."""
    try:
        a = np.asarray(pts, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"`{name}` must be a numeric (N, 2) array ({exc})") from exc
    if a.ndim == 3 and a.shape[1] == 1 and a.shape[2] == 2:
        a = a.reshape(-1, 2)
    if a.ndim != 2 or a.shape[1] != 2:
        raise InputError(f"`{name}` must have shape (N, 2), got {a.shape}")
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        raise InputError(f"`{name}` contains NaN or inf (first at row {int(np.argmax(bad))})")
    return np.ascontiguousarray(a)


def _check_pair(src, dst) -> tuple[np.ndarray, np.ndarray]:
    s = _as_points("src", src)
    d = _as_points("dst", dst)
    if len(s) != len(d):
        raise InputError(f"`src` and `dst` must have the same number of points, got {len(s)} and {len(d)}")
    if len(s) < 4:
        raise InputError(f"a homography needs at least 4 correspondences, got {len(s)}")
    return s, d


def _check_not_collinear(name: str, pts: np.ndarray) -> None:
    """Raise EstimationError when every point lies on one line (or coincides)."""
    c = pts - pts.mean(axis=0)
    sv = np.linalg.svd(c, compute_uv=False)
    if sv[0] == 0.0 or sv[1] <= _ALL_COLLINEAR_EPS * sv[0]:
        raise EstimationError(
            f"all `{name}` points are collinear or coincident, so the homography is undetermined; "
            "supply correspondences spread over a 2-D region"
        )


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
    """
    pts = np.asarray(pts, dtype=np.float64)
    c = pts.mean(axis=0)
    d = np.sqrt(((pts - c) ** 2).sum(axis=1)).mean()
    if not np.isfinite(d) or d <= 0.0:
        raise EstimationError("all points coincide, so they cannot be normalized; supply distinct points")
    s = math.sqrt(2.0) / d
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


def _unit_h22(H: np.ndarray) -> np.ndarray:
    """``H`` scaled so that H[2, 2] = 1 (or to unit Frobenius norm with H[2, 2] >= 0 if H[2, 2] vanishes)."""
    n = np.linalg.norm(H)
    if abs(H[2, 2]) > 1e-12 * n:
        return H / H[2, 2]
    return H / n  # pragma: no cover - the origin of src maps to infinity: keep a finite representative


# ---------------------------------------------------------------------------------------------- public tools


def transform_points(H, pts) -> np.ndarray:
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
    Hn = vt[-1].reshape(3, 3)
    H = np.linalg.solve(Td, Hn @ Ts)
    return _unit_h22(H)


# ----------------------------------------------------------------------------------------------- numba core


@njit(cache=True, inline="always", error_model="numpy")
def _sample4(u0, u1, u2, u3, n):
    """Four distinct indices in [0, n) from four uniforms in [0, 1): exact sampling without replacement.

    The k-th index is uniform over the n - k values not chosen yet: draw j in [0, n - k) and walk it past the
    already chosen indices in increasing order (branch-light scalar code; this runs once per hypothesis).
    """
    a = min(int(u0 * n), n - 1)
    b = min(int(u1 * (n - 1)), n - 2)
    c = min(int(u2 * (n - 2)), n - 3)
    d = min(int(u3 * (n - 3)), n - 4)
    if b >= a:
        b += 1
    lo = min(a, b)
    hi = max(a, b)
    if c >= lo:
        c += 1
    if c >= hi:
        c += 1
    x0 = min(lo, c)
    x2 = max(hi, c)
    x1 = lo + hi + c - x0 - x2
    if d >= x0:
        d += 1
    if d >= x1:
        d += 1
    if d >= x2:
        d += 1
    return a, b, c, d


@njit(cache=True, inline="always", error_model="numpy")
def _det3(ax, ay, bx, by, cx, cy):
    """det([a b c]) of homogeneous points (z = 1): twice the signed area of triangle abc."""
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@njit(cache=True, inline="always", error_model="numpy")
def _minimal_solve(sn, dn, i0, i1, i2, i3, H):
    """Homography (normalized coordinates) through four correspondences, or False for a degenerate sample.

    Degenerate: any triple of the four points collinear in either view, or the orientation of the four triangles
    not preserved consistently (sign(D_src * D_dst) must be the same for all four triples).
    """
    # source basis: M = [p0 p1 p2], lambda = adj(M) p3 (scale-free), components are triangle determinants
    x0, y0, x1, y1, x2, y2, x3, y3 = (sn[i0, 0], sn[i0, 1], sn[i1, 0], sn[i1, 1],
                                      sn[i2, 0], sn[i2, 1], sn[i3, 0], sn[i3, 1])
    X0, Y0, X1, Y1, X2, Y2, X3, Y3 = (dn[i0, 0], dn[i0, 1], dn[i1, 0], dn[i1, 1],
                                      dn[i2, 0], dn[i2, 1], dn[i3, 0], dn[i3, 1])
    s012 = _det3(x0, y0, x1, y1, x2, y2)
    s312 = _det3(x3, y3, x1, y1, x2, y2)
    s032 = _det3(x0, y0, x3, y3, x2, y2)
    s013 = _det3(x0, y0, x1, y1, x3, y3)
    d012 = _det3(X0, Y0, X1, Y1, X2, Y2)
    d312 = _det3(X3, Y3, X1, Y1, X2, Y2)
    d032 = _det3(X0, Y0, X3, Y3, X2, Y2)
    d013 = _det3(X0, Y0, X1, Y1, X3, Y3)
    eps = _COLLINEAR_EPS
    if (abs(s012) < eps or abs(s312) < eps or abs(s032) < eps or abs(s013) < eps
            or abs(d012) < eps or abs(d312) < eps or abs(d032) < eps or abs(d013) < eps):
        return False
    sg = s012 * d012 > 0
    if (s312 * d312 > 0) != sg or (s032 * d032 > 0) != sg or (s013 * d013 > 0) != sg:
        return False
    # lambda_k (up to the common factor 1/det): p3 = sum_k lambda_k p_k, by Cramer's rule
    ls0, ls1, ls2 = s312 / s012, s032 / s012, s013 / s012
    ld0, ld1, ld2 = d312 / d012, d032 / d012, d013 / d012
    # B_src = [ls0 p0, ls1 p1, ls2 p2]; H = B_dst @ inv(B_src)
    # inv(B_src) = diag(1/ls) @ inv(M_src); inv(M_src) = adj(M_src) / s012
    # adj of M = [[x0 x1 x2], [y0 y1 y2], [1 1 1]]
    a00 = y1 - y2
    a01 = x2 - x1
    a02 = x1 * y2 - x2 * y1
    a10 = y2 - y0
    a11 = x0 - x2
    a12 = x2 * y0 - x0 * y2
    a20 = y0 - y1
    a21 = x1 - x0
    a22 = x0 * y1 - x1 * y0
    # rows of inv(B_src) up to the common 1/s012: row k = adj row k / ls_k
    r0 = 1.0 / ls0
    r1 = 1.0 / ls1
    r2 = 1.0 / ls2
    b00, b01, b02 = a00 * r0, a01 * r0, a02 * r0
    b10, b11, b12 = a10 * r1, a11 * r1, a12 * r1
    b20, b21, b22 = a20 * r2, a21 * r2, a22 * r2
    # B_dst columns
    c00, c01, c02 = ld0 * X0, ld1 * X1, ld2 * X2
    c10, c11, c12 = ld0 * Y0, ld1 * Y1, ld2 * Y2
    c20, c21, c22 = ld0, ld1, ld2
    H[0, 0] = c00 * b00 + c01 * b10 + c02 * b20
    H[0, 1] = c00 * b01 + c01 * b11 + c02 * b21
    H[0, 2] = c00 * b02 + c01 * b12 + c02 * b22
    H[1, 0] = c10 * b00 + c11 * b10 + c12 * b20
    H[1, 1] = c10 * b01 + c11 * b11 + c12 * b21
    H[1, 2] = c10 * b02 + c11 * b12 + c12 * b22
    H[2, 0] = c20 * b00 + c21 * b10 + c22 * b20
    H[2, 1] = c20 * b01 + c21 * b11 + c22 * b21
    H[2, 2] = c20 * b02 + c21 * b12 + c22 * b22
    return True


@njit(cache=True, inline="always", error_model="numpy")
def _matmul3(A, B, out):
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]


@njit(cache=True, error_model="numpy")
def _msac(src, dst, H, thr2, bail):
    """(MSAC cost, inlier count) of H; stops early (count -1) once the cost exceeds ``bail``."""
    h0, h1, h2, h3, h4, h5, h6, h7, h8 = (H[0, 0], H[0, 1], H[0, 2], H[1, 0], H[1, 1], H[1, 2],
                                          H[2, 0], H[2, 1], H[2, 2])
    cost = 0.0
    cnt = 0
    for i in range(src.shape[0]):
        x = src[i, 0]
        y = src[i, 1]
        w = h6 * x + h7 * y + h8
        if w != 0.0:
            iw = 1.0 / w
            du = (h0 * x + h1 * y + h2) * iw - dst[i, 0]
            dv = (h3 * x + h4 * y + h5) * iw - dst[i, 1]
            e2 = du * du + dv * dv
        else:
            e2 = np.inf
        if e2 <= thr2:
            cost += e2
            cnt += 1
        else:
            cost += thr2
        if cost > bail:
            return cost, -1
    return cost, cnt


@njit(cache=True, error_model="numpy")
def _sq_errors(src, dst, H, out):
    """Squared one-sided reprojection error per correspondence (inf when mapped to infinity)."""
    for i in range(src.shape[0]):
        x = src[i, 0]
        y = src[i, 1]
        w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
        if w != 0.0:
            du = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w - dst[i, 0]
            dv = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w - dst[i, 1]
            out[i] = du * du + dv * dv
        else:
            out[i] = np.inf
    return out


@njit(cache=True, error_model="numpy")
def _similarity(s, tx, ty):
    """The 3x3 matrix [[s, 0, tx], [0, s, ty], [0, 0, 1]]."""
    T = np.zeros((3, 3))
    T[0, 0] = s
    T[1, 1] = s
    T[0, 2] = tx
    T[1, 2] = ty
    T[2, 2] = 1.0
    return T


@njit(cache=True, error_model="numpy")
def _jacobi_eigh(M, V):
    """Eigen-decomposition of a small symmetric matrix by cyclic Jacobi rotations (M is overwritten).

    Returns the eigenvalues in ascending order; the columns of ``V`` become the matching unit eigenvectors.
    Plain loops rather than ``np.linalg.eigh`` keep numba's compile time short; for 9x9 this is a few microseconds.
    """
    n = M.shape[0]
    for i in range(n):
        for j in range(n):
            V[i, j] = 1.0 if i == j else 0.0
    for sweep in range(50):
        off = 0.0
        for p in range(n):
            for q in range(p + 1, n):
                off += M[p, q] * M[p, q]
        diag = 0.0
        for p in range(n):
            diag += M[p, p] * M[p, p]
        if off <= 1e-30 * diag or off == 0.0:
            break
        for p in range(n):
            for q in range(p + 1, n):
                apq = M[p, q]
                if apq == 0.0:
                    continue
                theta = (M[q, q] - M[p, p]) / (2.0 * apq)
                tt = (1.0 if theta >= 0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(tt * tt + 1.0)
                s = tt * c
                for k in range(n):
                    mkp = M[k, p]
                    mkq = M[k, q]
                    M[k, p] = c * mkp - s * mkq
                    M[k, q] = s * mkp + c * mkq
                for k in range(n):
                    mpk = M[p, k]
                    mqk = M[q, k]
                    M[p, k] = c * mpk - s * mqk
                    M[q, k] = s * mpk + c * mqk
                for k in range(n):
                    vkp = V[k, p]
                    vkq = V[k, q]
                    V[k, p] = c * vkp - s * vkq
                    V[k, q] = s * vkp + c * vkq
    w = np.empty(n)
    for i in range(n):
        w[i] = M[i, i]
    order = np.argsort(w)
    Vs = V.copy()
    ws = np.empty(n)
    for j in range(n):
        ws[j] = w[order[j]]
        for i in range(n):
            V[i, j] = Vs[i, order[j]]
    return ws


@njit(cache=True, error_model="numpy")
def _lm_cost(p, xs, ys, us, vs, ws):
    """Weighted sum of squared one-sided reprojection errors of the 8-parameter homography p (H[2, 2] = 1)."""
    c = 0.0
    for i in range(xs.shape[0]):
        w = p[6] * xs[i] + p[7] * ys[i] + 1.0
        if w == 0.0:
            return np.inf
        du = (p[0] * xs[i] + p[1] * ys[i] + p[2]) / w - us[i]
        dv = (p[3] * xs[i] + p[4] * ys[i] + p[5]) / w - vs[i]
        c += ws[i] * (du * du + dv * dv)
    return c


@njit(cache=True, error_model="numpy")
def _lsq(src, dst, mask):
    """Hartley-normalized DLT on the masked correspondences via the 9x9 normal matrix; (H, ok)."""
    H = np.zeros((3, 3))
    n = 0
    cx = cy = cX = cY = 0.0
    for i in range(src.shape[0]):
        if mask[i]:
            n += 1
            cx += src[i, 0]
            cy += src[i, 1]
            cX += dst[i, 0]
            cY += dst[i, 1]
    if n < 4:
        return H, False
    cx /= n
    cy /= n
    cX /= n
    cY /= n
    ds = dd = 0.0
    for i in range(src.shape[0]):
        if mask[i]:
            ds += math.sqrt((src[i, 0] - cx) ** 2 + (src[i, 1] - cy) ** 2)
            dd += math.sqrt((dst[i, 0] - cX) ** 2 + (dst[i, 1] - cY) ** 2)
    if ds <= 0.0 or dd <= 0.0:
        return H, False
    ss = math.sqrt(2.0) * n / ds
    sd = math.sqrt(2.0) * n / dd
    # A^T A of the DLT rows [p, 0, -u p], [0, p, -v p] with p = (x, y, 1) has the block structure
    # [[S, 0, -Su], [0, S, -Sv], [-Su, -Sv, Suv]] with S = sum p p^T, Su = sum u p p^T, Sv = sum v p p^T,
    # Suv = sum (u^2 + v^2) p p^T: 24 sums per point instead of 162 products
    S = np.zeros(6)
    Su = np.zeros(6)
    Sv = np.zeros(6)
    Suv = np.zeros(6)
    q = np.empty(6)
    for i in range(src.shape[0]):
        if not mask[i]:
            continue
        x = (src[i, 0] - cx) * ss
        y = (src[i, 1] - cy) * ss
        u = (dst[i, 0] - cX) * sd
        v = (dst[i, 1] - cY) * sd
        q[0] = x * x
        q[1] = x * y
        q[2] = x
        q[3] = y * y
        q[4] = y
        q[5] = 1.0
        r2 = u * u + v * v
        for k in range(6):
            S[k] += q[k]
            Su[k] += u * q[k]
            Sv[k] += v * q[k]
            Suv[k] += r2 * q[k]
    M = np.zeros((9, 9))
    for a in range(3):
        for b in range(3):
            k = _SYM6[a, b]
            M[a, b] = S[k]
            M[3 + a, 3 + b] = S[k]
            M[a, 6 + b] = -Su[k]
            M[6 + a, b] = -Su[k]
            M[3 + a, 6 + b] = -Sv[k]
            M[6 + a, 3 + b] = -Sv[k]
            M[6 + a, 6 + b] = Suv[k]
    V = np.empty((9, 9))
    w = _jacobi_eigh(M, V)
    if not (w[1] > 1e-14 * w[8]):
        return H, False
    Hn = np.empty((3, 3))
    for k in range(9):
        Hn[k // 3, k % 3] = V[k, 0]
    # H = inv(Td) @ Hn @ Ts
    Ts = _similarity(ss, -ss * cx, -ss * cy)
    Tdi = _similarity(1.0 / sd, cX, cY)
    tmp = np.empty((3, 3))
    _matmul3(Hn, Ts, tmp)
    _matmul3(Tdi, tmp, H)
    if H[2, 2] != 0.0:
        H /= H[2, 2]
    return H, True


@njit(cache=True, error_model="numpy")
def _local_optimize(src, dst, H0, thr2, multiplier, steps, e2):
    """LO step: least squares on the inliers of H0, then iterative least squares while the threshold shrinks
    from ``multiplier * thr`` to ``thr``. Returns the best (H, MSAC cost, inliers) among H0 and the refits."""
    n = src.shape[0]
    best = H0.copy()
    best_cost, best_cnt = _msac(src, dst, H0, thr2, np.inf)
    mask = np.empty(n, np.bool_)
    H = H0.copy()
    for rep in range(2):
        _sq_errors(src, dst, H, e2)
        for i in range(n):
            mask[i] = e2[i] <= thr2
        Hl, ok = _lsq(src, dst, mask)
        if not ok:
            break
        H = Hl
        for s in range(steps):
            f = multiplier - (multiplier - 1.0) * s / max(steps - 1, 1)
            t2 = thr2 * f * f
            _sq_errors(src, dst, H, e2)
            for i in range(n):
                mask[i] = e2[i] <= t2
            Hl, ok = _lsq(src, dst, mask)
            if not ok:
                break
            H = Hl
        cost, cnt = _msac(src, dst, H, thr2, np.inf)
        if cost < best_cost:
            best_cost = cost
            best_cnt = cnt
            best = H.copy()
        else:
            break
    return best, best_cost, best_cnt


@njit(cache=True, error_model="numpy")
def _bound(inliers, n, log1mconf, max_iters, A):
    """RANSAC iterations needed to draw and accept one all-inlier 4-sample with the given confidence.

    An all-inlier sample is drawn with probability w^4 and survives the SPRT with probability about 1 - 1/A.
    """
    w = inliers / n
    p = w * w * w * w * (1.0 - 1.0 / A)
    if p >= 1.0:
        return 1
    if p <= 0.0:
        return max_iters
    den = math.log1p(-p)
    if den >= 0.0:
        return max_iters
    k = log1mconf / den
    if k >= max_iters:
        return max_iters
    return max(1, int(math.ceil(k)))


@njit(cache=True, error_model="numpy")
def _sprt_threshold(eps, delta, tm):
    """Decision threshold A of Wald's SPRT for RANSAC (Chum & Matas 2008, eq. 2), A = K + log A by iteration."""
    if not (0.0 < delta < eps < 1.0):
        return np.inf
    c = (1.0 - delta) * math.log((1.0 - delta) / (1.0 - eps)) + delta * math.log(delta / eps)
    k = tm * c / _SPRT_MS + 1.0
    a = k
    for _ in range(20):
        a = k + math.log(a)
    return a


@njit(cache=True, error_model="numpy")
def _score(src, dst, H, thr2, bail, A, eps, delta):
    """Evaluate H point by point: (MSAC cost, inliers so far, points evaluated, status).

    status 0: all points evaluated; 1: rejected by the SPRT (likelihood ratio above A); 2: the MSAC cost already
    exceeds ``bail`` (the best cost so far), so H cannot win.
    """
    h0, h1, h2, h3, h4, h5, h6, h7, h8 = (H[0, 0], H[0, 1], H[0, 2], H[1, 0], H[1, 1], H[1, 2],
                                          H[2, 0], H[2, 1], H[2, 2])
    up = delta / eps
    down = (1.0 - delta) / (1.0 - eps)
    lam = 1.0
    cost = 0.0
    cnt = 0
    n = src.shape[0]
    for i in range(n):
        x = src[i, 0]
        y = src[i, 1]
        w = h6 * x + h7 * y + h8
        if w != 0.0:
            iw = 1.0 / w
            du = (h0 * x + h1 * y + h2) * iw - dst[i, 0]
            dv = (h3 * x + h4 * y + h5) * iw - dst[i, 1]
            e2 = du * du + dv * dv
        else:
            e2 = np.inf
        if e2 <= thr2:
            cost += e2
            cnt += 1
            lam *= up
        else:
            cost += thr2
            lam *= down
            if lam > A:
                return cost, cnt, i + 1, 1
            if cost > bail:
                return cost, cnt, i + 1, 2
    return cost, cnt, n, 0


@njit(cache=True, error_model="numpy")
def _collapsed(Hn):
    """True when the normalized model is nearly singular (see ``_MIN_CONDITION``)."""
    det = (Hn[0, 0] * (Hn[1, 1] * Hn[2, 2] - Hn[1, 2] * Hn[2, 1])
           - Hn[0, 1] * (Hn[1, 0] * Hn[2, 2] - Hn[1, 2] * Hn[2, 0])
           + Hn[0, 2] * (Hn[1, 0] * Hn[2, 1] - Hn[1, 1] * Hn[2, 0]))
    norm2 = 0.0
    for i in range(3):
        for j in range(3):
            norm2 += Hn[i, j] * Hn[i, j]
    return not abs(det) >= _MIN_CONDITION * norm2 ** 1.5


@njit(cache=True, error_model="numpy")
def _ransac_chunk(src, dst, sn, dn, Ts, Tdi, Tsi, Td, u, thr2, log1mconf, max_iters, lo, lo_multiplier, lo_steps,
                  best_H, state):
    """Run hypotheses from the uniforms ``u`` (K, 4) until the adaptive bound is met or ``u`` runs out.

    ``state`` (see ``_STATE``) is updated in place, as is ``best_H`` (pixel coordinates). Returns the rows used.
    """
    n = src.shape[0]
    Hn = np.empty((3, 3))
    tmp = np.empty((3, 3))
    H = np.empty((3, 3))
    e2 = np.empty(n)
    used = 0
    for k in range(u.shape[0]):
        if state[3] >= state[2]:
            break
        used += 1
        i0, i1, i2, i3 = _sample4(u[k, 0], u[k, 1], u[k, 2], u[k, 3], n)
        if not _minimal_solve(sn, dn, i0, i1, i2, i3, Hn) or _collapsed(Hn):
            state[4] += 1
            continue
        state[3] += 1
        _matmul3(Hn, Ts, tmp)
        _matmul3(Tdi, tmp, H)
        cost, cnt, seen, status = _score(src, dst, H, thr2, state[0], state[8], state[6], state[7])
        if status != 0 or cost >= state[0]:
            if status != 1:
                continue
            # rejected by the SPRT: its consistent fraction estimates delta; redesign the test when that drifts
            state[9] += cnt
            state[10] += seen
            state[11] += 1
            if state[11] >= 20 and state[10] > 0:
                d = max(state[9] / state[10], 1e-4)
                if abs(d - state[7]) > 0.1 * state[7]:
                    state[7] = min(d, 0.5 * state[6])
                    state[8] = _sprt_threshold(state[6], state[7], state[12])
                    state[2] = _bound(state[1], n, log1mconf, max_iters, state[8])
            continue
        raw_cnt = cnt
        if lo and cnt >= 8:
            Hb, cost_b, cnt_b = _local_optimize(src, dst, H, thr2, lo_multiplier, lo_steps, e2)
            state[5] += 1
            _matmul3(Hb, Tsi, tmp)
            _matmul3(Td, tmp, Hn)
            if cost_b < cost and not _collapsed(Hn):
                H[:, :] = Hb
                cost = cost_b
                cnt = cnt_b
        state[0] = cost
        best_H[:, :] = H
        if raw_cnt / n > state[6]:
            # eps from the unoptimized model: a fresh all-inlier minimal model is less accurate than an LO'd one
            state[6] = raw_cnt / n
            state[7] = min(state[7], 0.5 * state[6])
            state[8] = _sprt_threshold(state[6], state[7], state[12])
        if cnt > state[1]:
            state[1] = cnt
        state[2] = _bound(state[1], n, log1mconf, max_iters, state[8])
    return used


@njit(cache=True, error_model="numpy")
def _lm_refine(src, dst, weight, H0, max_iter):
    """Levenberg-Marquardt on the weighted one-sided reprojection error sum_i weight_i * |dehom(H src_i) - dst_i|^2.

    Correspondences with weight 0 are ignored. Works in Hartley-normalized coordinates (isotropic scaling of dst,
    so the objective is the pixel one up to a constant) with 8 parameters (H[2, 2] = 1 there). Returns
    (H in pixels, weighted sum of squared errors in pixels^2).
    """
    n_all = src.shape[0]
    n = 0
    cx = cy = cX = cY = 0.0
    for i in range(n_all):
        if weight[i] > 0.0:
            n += 1
            cx += src[i, 0]
            cy += src[i, 1]
            cX += dst[i, 0]
            cY += dst[i, 1]
    cx /= n
    cy /= n
    cX /= n
    cY /= n
    ds = dd = 0.0
    for i in range(n_all):
        if weight[i] > 0.0:
            ds += math.sqrt((src[i, 0] - cx) ** 2 + (src[i, 1] - cy) ** 2)
            dd += math.sqrt((dst[i, 0] - cX) ** 2 + (dst[i, 1] - cY) ** 2)
    ss = math.sqrt(2.0) * n / ds
    sd = math.sqrt(2.0) * n / dd
    xs = np.empty(n)
    ys = np.empty(n)
    us = np.empty(n)
    vs = np.empty(n)
    ws = np.empty(n)
    j = 0
    for i in range(n_all):
        if weight[i] > 0.0:
            xs[j] = (src[i, 0] - cx) * ss
            ys[j] = (src[i, 1] - cy) * ss
            us[j] = (dst[i, 0] - cX) * sd
            vs[j] = (dst[i, 1] - cY) * sd
            ws[j] = weight[i]
            j += 1
    Ts = _similarity(ss, -ss * cx, -ss * cy)
    Tsi = _similarity(1.0 / ss, cx, cy)
    Td = _similarity(sd, -sd * cX, -sd * cY)
    Tdi = _similarity(1.0 / sd, cX, cY)
    tmp = np.empty((3, 3))
    Hn = np.empty((3, 3))
    _matmul3(H0, Tsi, tmp)
    _matmul3(Td, tmp, Hn)
    if abs(Hn[2, 2]) < 1e-12:
        e = np.empty(n_all)
        _sq_errors(src, dst, H0, e)
        c = 0.0
        for i in range(n_all):
            if weight[i] > 0.0:
                c += weight[i] * e[i]
        return H0.copy(), c
    Hn /= Hn[2, 2]
    p = np.empty(8)
    for k in range(8):
        p[k] = Hn[k // 3, k % 3]

    cost = _lm_cost(p, xs, ys, us, vs, ws)
    lam = 1e-3
    JtJ = np.zeros((8, 8))
    Jtr = np.zeros(8)
    J = np.zeros((2, 8))
    A = np.zeros((8, 8))
    negJtr = np.empty(8)
    delta = np.empty(8)
    rel = 0.0
    for it in range(max_iter):
        JtJ[:, :] = 0.0
        Jtr[:] = 0.0
        for i in range(n):
            x = xs[i]
            y = ys[i]
            w = p[6] * x + p[7] * y + 1.0
            iw = 1.0 / w
            uu = (p[0] * x + p[1] * y + p[2]) * iw
            vv = (p[3] * x + p[4] * y + p[5]) * iw
            ru = uu - us[i]
            rv = vv - vs[i]
            J[0, 0] = x * iw
            J[0, 1] = y * iw
            J[0, 2] = iw
            J[0, 3] = 0.0
            J[0, 4] = 0.0
            J[0, 5] = 0.0
            J[0, 6] = -uu * x * iw
            J[0, 7] = -uu * y * iw
            J[1, 0] = 0.0
            J[1, 1] = 0.0
            J[1, 2] = 0.0
            J[1, 3] = x * iw
            J[1, 4] = y * iw
            J[1, 5] = iw
            J[1, 6] = -vv * x * iw
            J[1, 7] = -vv * y * iw
            wi = ws[i]
            for a in range(8):
                Jtr[a] += wi * (J[0, a] * ru + J[1, a] * rv)
                for b in range(a, 8):
                    JtJ[a, b] += wi * (J[0, a] * J[0, b] + J[1, a] * J[1, b])
        for a in range(8):
            for b in range(a):
                JtJ[a, b] = JtJ[b, a]
        improved = False
        for attempt in range(10):
            A[:, :] = JtJ
            for a in range(8):
                A[a, a] += lam * (JtJ[a, a] + 1e-12)
            for a in range(8):
                negJtr[a] = -Jtr[a]
            if not _cholesky_solve(A, negJtr, delta):
                lam *= 10.0
                continue
            pn = p + delta
            cn = _lm_cost(pn, xs, ys, us, vs, ws)
            if cn < cost:
                rel = (cost - cn) / max(cost, 1e-300)
                p = pn
                cost = cn
                lam = max(lam * 0.1, 1e-12)
                improved = True
                break
            lam *= 10.0
        if not improved or rel < 1e-12:
            break
    for k in range(8):
        Hn[k // 3, k % 3] = p[k]
    Hn[2, 2] = 1.0
    H = np.empty((3, 3))
    _matmul3(Hn, Ts, tmp)
    _matmul3(Tdi, tmp, H)
    if H[2, 2] != 0.0:
        H /= H[2, 2]
    return H, cost / (sd * sd)


@njit(cache=True, error_model="numpy")
def _normalize(p):
    """Hartley normalization in one pass: (T (3, 3), normalized points (N, 2), not_collinear).

    ``not_collinear`` is False when the smaller principal axis of the points is below ``_ALL_COLLINEAR_EPS`` times
    the larger one (computed from the 2x2 covariance: ratio of eigenvalues <= eps^2), or all points coincide.
    """
    n = p.shape[0]
    cx = 0.0
    cy = 0.0
    for i in range(n):
        cx += p[i, 0]
        cy += p[i, 1]
    cx /= n
    cy /= n
    md = 0.0
    for i in range(n):
        md += math.sqrt((p[i, 0] - cx) ** 2 + (p[i, 1] - cy) ** 2)
    md /= n
    T = np.eye(3)
    out = np.empty((n, 2))
    if not md > 0.0:
        return T, out, False
    s = math.sqrt(2.0) / md
    a = b = c = 0.0
    for i in range(n):
        x = (p[i, 0] - cx) * s
        y = (p[i, 1] - cy) * s
        out[i, 0] = x
        out[i, 1] = y
        a += x * x
        b += x * y
        c += y * y
    T[0, 0] = s
    T[1, 1] = s
    T[0, 2] = -s * cx
    T[1, 2] = -s * cy
    l1 = 0.5 * (a + c) + math.sqrt(0.25 * (a - c) ** 2 + b * b)
    det = a * c - b * b
    return T, out, det > (_ALL_COLLINEAR_EPS ** 2) * l1 * l1


@njit(cache=True, error_model="numpy")
def _weights(e2, thr2, loss, out):
    """IRLS weights of the final refinement from squared residuals: 0 hard inliers (1 within the threshold),
    1 Tukey biweight (1 - e2 / c^2)^2 with c = threshold, 2 Cauchy-like 1 / (1 + e2 / s^2) (s = threshold / 2)
    within the threshold."""
    for i in range(e2.shape[0]):
        if e2[i] > thr2:
            out[i] = 0.0
        elif loss == 0:
            out[i] = 1.0
        elif loss == 1:
            r = 1.0 - e2[i] / thr2
            out[i] = r * r
        else:
            out[i] = 1.0 / (1.0 + 4.0 * e2[i] / thr2)
    return out


@njit(cache=True, error_model="numpy")
def _msac_cost(e2, thr2):
    c = 0.0
    for i in range(e2.shape[0]):
        c += min(e2[i], thr2)
    return c


@njit(cache=True, error_model="numpy")
def _finalize(src, dst, H0, thr2, refine, rounds, loss, wthr2):
    """Inliers of H0 and, with ``refine``, up to ``rounds`` of weighted Levenberg-Marquardt (weights from the
    residuals of the previous round, see ``_weights``); with hard inliers (loss 0) a round is kept only if the MSAC
    cost does not grow. Returns (H, inlier mask, squared errors)."""
    n = src.shape[0]
    e2 = _sq_errors(src, dst, H0, np.empty(n))
    mask = np.empty(n, np.bool_)
    cnt = 0
    for i in range(n):
        mask[i] = e2[i] <= thr2
        cnt += mask[i]
    H = H0.copy()
    if not refine or cnt < 4:
        return H, mask, e2
    cost = _msac_cost(e2, thr2)
    w = np.empty(n)
    e2r = np.empty(n)
    for _ in range(rounds):
        _weights(e2, wthr2, loss, w)
        used = 0
        for i in range(n):
            used += w[i] > 0.0
        if used < 4:
            break
        Hr, _sse = _lm_refine(src, dst, w, H, 30)
        finite = True
        for i in range(3):
            for j in range(3):
                finite = finite and math.isfinite(Hr[i, j])
        if not finite:
            break
        _sq_errors(src, dst, Hr, e2r)
        cost_r = _msac_cost(e2r, thr2)
        if loss == 0 and cost_r > cost * (1.0 + 1e-9):
            break
        cnt_r = 0
        same = True
        for i in range(n):
            m = e2r[i] <= thr2
            cnt_r += m
            same = same and (m == mask[i])
        if cnt_r < 4:
            break
        H = Hr
        cost = cost_r
        for i in range(n):
            e2[i] = e2r[i]
            mask[i] = e2r[i] <= thr2
        if same and loss == 0:
            break
    return H, mask, e2


# ------------------------------------------------------------------------------------ significance vs chance


def log10_nfa(inliers: int, matches: int, p: float) -> float:
    """``log10`` of the number of false alarms of a homography with ``inliers`` among ``matches``.

    A model is fixed by 4 matches and there are ``C(n, 4)`` of them; under the null hypothesis each of the other
    ``n - 4`` matches agrees with it by chance with probability ``p``, so (ORSA, Moisan & Stival 2004, with the
    binomial tail instead of its bound) ``NFA = C(n, 4) P[Binomial(n - 4, p) >= k - 4]``.

    Parameters
    ----------
    inliers, matches : int
        Inlier count ``k`` and number of putative matches ``n``.
    p : float
        Chance that an unrelated match is an inlier (see :func:`chance_probability`).

    Returns
    -------
    float
        ``log10 NFA``; below ``log10(MAX_NFA) = 0`` the count is significant. ``inf`` for fewer than 4 of either.
    """
    from scipy.special import bdtrc, gammaln

    n, k = int(matches), int(inliers)
    if n < 4 or k < 4:
        return float("inf")
    p = min(max(float(p), 0.0), 1.0)
    log_models = (gammaln(n + 1) - gammaln(5) - gammaln(n - 3)) / math.log(10)
    if k == 4 or p >= 1.0:
        return float(log_models)
    j = k - 4
    if p <= 0.0:
        return float("-inf")
    tail = float(bdtrc(j - 1, n - 4, p))  # P[X > j - 1] = P[X >= j]
    if tail <= 0.0:  # underflow: the first term of the tail bounds it from below and stays finite in logs
        tail_log = (gammaln(n - 3) - gammaln(j + 1) - gammaln(n - 3 - j) + j * math.log(p)
                    + (n - 4 - j) * math.log1p(-p)) / math.log(10)
        return float(log_models + tail_log)
    return float(log_models + math.log10(tail))


@njit(cache=True)
def _chance_hits(src, dst, H, thr2, rows):  # pragma: no cover - compiled
    """Pairs (i, j), i in ``rows``, j != i, with ``|| dehom(H src_i) - dst_j ||^2 <= thr2``."""
    hits = 0
    for i in rows:
        x, y = src[i, 0], src[i, 1]
        w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
        if not abs(w) > 1e-12:
            continue
        u = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w
        v = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w
        for j in range(dst.shape[0]):
            if j != i:
                du = u - dst[j, 0]
                dv = v - dst[j, 1]
                if du * du + dv * dv <= thr2:
                    hits += 1
    return hits


#: at most this many source points enter the permutation estimate of :func:`chance_probability` (O(rows x N))
_CHANCE_ROWS = 2000


def chance_probability(H: np.ndarray, src: np.ndarray, dst: np.ndarray, threshold: float,
                       area: float | None = None) -> float:
    """Chance that an unrelated match is an inlier of ``H``: the larger of two null models.

    - uniform: the destination point falls anywhere in ``area`` (px^2; default the bounding box of ``dst``), so
      ``p = pi threshold^2 / area``;
    - permutation: the pairing is random, the points are the observed ones, so ``p`` is the fraction of pairs
      ``(src_i, dst_j)``, ``i != j``, within ``threshold`` under ``H``. It accounts for clustered keypoints and
      for strongly perspective models that squeeze many sources into the densest part of ``dst`` (how chance
      models of unrelated photos collect their "inliers").
    """
    s = np.ascontiguousarray(src, np.float64)
    d = np.ascontiguousarray(dst, np.float64)
    n = len(s)
    a = points_area(d) if area is None else float(area)
    p_uniform = min(1.0, math.pi * float(threshold) ** 2 / max(a, 1.0))
    if n < 2:
        return p_uniform
    rows = np.arange(n, dtype=np.int64)
    if n > _CHANCE_ROWS:  # evenly spread rows: deterministic and unbiased for the caller's order
        rows = np.linspace(0, n - 1, _CHANCE_ROWS).round().astype(np.int64)
    hits = _chance_hits(s, d, np.ascontiguousarray(H, np.float64), float(threshold) ** 2, rows)
    return max(p_uniform, hits / (len(rows) * (n - 1.0)))


def _distinct(pts: np.ndarray) -> int:
    """Number of distinct rows of an (N, 2) point array."""
    return int(len(np.unique(pts, axis=0))) if len(pts) else 0


def points_area(pts: np.ndarray) -> float:
    """Area in px^2 of the axis-aligned bounding box of ``pts`` (N, 2), at least 1 px on each side."""
    span = np.ptp(np.asarray(pts, np.float64), axis=0) + 1.0
    return float(span[0] * span[1])


def _check_area(area) -> None:
    if area is not None and not (isinstance(area, (int, float, np.integer, np.floating)) and math.isfinite(area)
                                 and area > 0):
        raise InputError(f"`area` must be a finite number of px^2 > 0, got {area!r}")


def _significant(fit: HomographyFit, src: np.ndarray, dst: np.ndarray, threshold: float,
                 area: float | None) -> HomographyFit:
    """:func:`check_significant` for more than 4 correspondences (a minimal set is fitted exactly: nothing to test)."""
    if len(dst) <= 4:
        return fit
    return check_significant(fit, src, dst, threshold, area)


def check_significant(fit: HomographyFit, src, dst, threshold: float, area: float | None = None) -> HomographyFit:
    """``fit`` with its ``log10_nfa`` filled in, or :class:`EstimationError` when its inliers are chance-level.

    Parameters
    ----------
    fit : HomographyFit
        A model estimated from ``src`` -> ``dst``.
    src, dst : (N, 2) array_like
        The putative matches it was estimated from.
    threshold : float
        The inlier threshold in pixels.
    area : float, optional
        Destination image area in px^2 (see :func:`chance_probability`).

    Raises
    ------
    EstimationError
        ``NFA >= MAX_NFA``: as many inliers are expected from unrelated matches; the message has the counts.
    """
    s, d = _as_points("src", src), _as_points("dst", dst)
    inl = np.asarray(fit.inliers, bool)
    # evidence counts distinct points: many matches to one keypoint (or SIFT's copies of a keypoint with several
    # orientations) are one observation, and a model that squeezes a row of sources onto one point gains nothing
    k = min(_distinct(s[inl]), _distinct(d[inl]))
    n = min(_distinct(s), _distinct(d))
    p = chance_probability(fit.H, s, d, threshold, area)
    lnfa = log10_nfa(k, n, p)
    if not lnfa < math.log10(MAX_NFA):
        raise EstimationError(
            f"the best homography has {k} distinct inliers of {n} distinct matches ({fit.num_inliers} of {len(s)} "
            f"in all) within {float(threshold):g} px, which is chance "
            f"level (an unrelated match is an inlier with probability {p:.2g}; NFA 10^{lnfa:.1f} >= {MAX_NFA:g}): "
            "the images do not seem to show the same plane; check that they overlap, or try another --detector "
            "or more features"
        )
    return HomographyFit(H=fit.H, inliers=fit.inliers, iterations=fit.iterations, rms=fit.rms, log10_nfa=lnfa)


# ----------------------------------------------------------------------------------------------- public API


def find_homography(
    src,
    dst,
    threshold: float = 3.0,
    confidence: float = 0.999,
    max_iters: int = DEFAULT_MAX_ITERS,
    rng=None,
    *,
    local_optimization: bool = True,
    refine: bool = True,
    lo_multiplier: float = 3.0,
    lo_steps: int = 4,
    area: float | None = None,
) -> HomographyFit:
    """Robust homography from putative correspondences (LO-RANSAC + Levenberg-Marquardt), like cv2.findHomography.

    Parameters
    ----------
    src, dst : (N, 2) array_like
        Corresponding points in pixels (x = column, y = row); OpenCV's (N, 1, 2) layout is accepted. N >= 4.
    threshold : float
        Maximum one-sided reprojection error ``|| dehom(H src_i) - dst_i ||`` of an inlier, in pixels of ``dst``.
    confidence : float
        Probability in (0, 1) that at least one all-inlier sample was drawn when the adaptive bound stops RANSAC.
    max_iters : int
        Upper bound on the number of hypotheses.
    rng : None, int or numpy.random.Generator
        Seed or generator for the sampling (``np.random.default_rng(rng)``).
    local_optimization : bool
        Re-estimate every so-far-best model from its inliers (LO-RANSAC).
    refine : bool
        Finish with iteratively reweighted Levenberg-Marquardt (Tukey weights) on the reprojection error.
    lo_multiplier, lo_steps : float, int
        The LO threshold shrinks from ``lo_multiplier * threshold`` to ``threshold`` in ``lo_steps`` refits.
    area : float, optional
        Area of the destination image in px^2 for the test against chance (:func:`log10_nfa`); default the bounding
        box of ``dst`` (stricter). With more than 4 correspondences a model whose inlier count is chance-level is
        refused; 4 correspondences are fitted exactly and cannot be tested.

    Returns
    -------
    HomographyFit
        ``H`` (src -> dst, ``H[2, 2] = 1``), ``inliers`` (N,) bool, ``iterations``, ``rms``.

    Raises
    ------
    InputError (a ValueError)
        Shapes differ or are not (N, 2), fewer than 4 correspondences, NaN/inf, parameters out of range.
    EstimationError
        All points collinear, every sample degenerate, no model with at least 4 inliers, or an inlier count that
        chance explains (NFA >= 1); raise ``threshold`` or ``max_iters``, or supply better matches.
    """
    s, d = _check_pair(src, dst)
    _check_area(area)
    if not (isinstance(threshold, (int, float, np.floating, np.integer)) and math.isfinite(threshold)
            and threshold > 0):
        raise InputError(f"`threshold` must be a finite number > 0 pixels, got {threshold!r}")
    if not (isinstance(confidence, (int, float, np.floating)) and 0.0 < confidence < 1.0):
        raise InputError(f"`confidence` must be in (0, 1), got {confidence!r}")
    if isinstance(max_iters, bool) or not isinstance(max_iters, (int, np.integer)) or max_iters < 1:
        raise InputError(f"`max_iters` must be an integer >= 1, got {max_iters!r}")
    if not (isinstance(lo_multiplier, (int, float)) and lo_multiplier >= 1.0):
        raise InputError(f"`lo_multiplier` must be >= 1, got {lo_multiplier!r}")
    if isinstance(lo_steps, bool) or not isinstance(lo_steps, (int, np.integer)) or lo_steps < 1:
        raise InputError(f"`lo_steps` must be an integer >= 1, got {lo_steps!r}")
    gen = np.random.default_rng(rng)
    n = len(s)
    thr2 = float(threshold) ** 2
    Ts, sn, ok_s = _normalize(s)
    Td, dn, ok_d = _normalize(d)
    for name, ok in (("src", ok_s), ("dst", ok_d)):
        if not ok:
            raise EstimationError(
                f"all `{name}` points are collinear or coincident, so the homography is undetermined; "
                "supply correspondences spread over a 2-D region"
            )
    Tdi = np.linalg.inv(Td)
    Tsi = np.linalg.inv(Ts)
    best_H = np.zeros((3, 3))
    # best cost, best inliers, bound, iterations, degenerate samples, LO runs, SPRT eps, delta, A,
    # consistent points seen in bad models, points evaluated in bad models, bad models
    state = np.array([np.inf, 0.0, float(max_iters), 0.0, 0.0, 0.0, _SPRT_EPS0, _SPRT_DELTA0,
                      _sprt_threshold(_SPRT_EPS0, _SPRT_DELTA0, _SPRT_TM), 0.0, 0.0, 0.0, _SPRT_TM])
    log1mconf = math.log1p(-float(confidence))
    # degenerate samples are not counted as iterations; cap the attempts so an all-degenerate set terminates
    attempts, max_attempts, chunk = 0, 10 * int(max_iters) + 100, 256
    # the SPRT assumes the points are verified in random order; the caller's order may be sorted by quality
    perm = gen.permutation(n)
    sp, dp, snp, dnp = s[perm], d[perm], sn[perm], dn[perm]
    while state[3] < state[2] and attempts < max_attempts:
        k = int(min(chunk, max_attempts - attempts))
        u = gen.random((k, 4))
        attempts += _ransac_chunk(sp, dp, snp, dnp, Ts, Tdi, Tsi, Td, u, thr2, log1mconf, int(max_iters),
                                  bool(local_optimization), float(lo_multiplier), int(lo_steps), best_H, state)
        chunk = min(chunk * 2, 8192)
    iterations = int(state[3])
    if iterations == 0:
        raise EstimationError(
            f"all {attempts} sampled 4-point sets were degenerate (collinear or orientation-flipping); "
            "the correspondences are nearly collinear or inconsistent"
        )
    H, mask, e2 = _finalize(s, d, best_H, thr2, bool(refine), _FINAL_ROUNDS, _FINAL_LOSS, thr2 * _FINAL_WSCALE ** 2)
    if refine and _collapsed(Td @ H @ Tsi):  # the refinement drifted to a degenerate model: keep RANSAC's
        H, mask, e2 = _finalize(s, d, best_H, thr2, False, 0, _FINAL_LOSS, thr2)
    if mask.sum() < 4:
        raise EstimationError(
            f"no homography with at least 4 inliers within {threshold} px after {iterations} iterations; "
            "raise `threshold` or `max_iters`, or supply better matches"
        )
    if _collapsed(Td @ H @ Tsi):
        raise EstimationError(
            "the best homography is nearly singular (it collapses the image onto a line or a point): the matches "
            "are dominated by many-to-one correspondences; use a cross check or a stricter ratio test"
        )
    H = _unit_h22(H)
    rms = float(np.sqrt(e2[mask].mean()))
    inl = mask.copy()
    H.setflags(write=False)
    inl.setflags(write=False)
    fit = HomographyFit(H=H, inliers=inl, iterations=iterations, rms=rms)
    return _significant(fit, s, d, threshold, area)


# ----------------------------------------------------------------------------------- matches and pictures


def correspondences(gray_a: np.ndarray, gray_b: np.ndarray, detector: str = "sift", max_features: int = 4000,
                    ratio: float = 0.8, cross_check: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Putative point correspondences A -> B from keypoints, descriptors and the ratio test.

    Parameters
    ----------
    gray_a, gray_b : (H, W) uint8
        The two views.
    detector, max_features, ratio, cross_check
        As in ``cvpipe.features.detect`` and ``cvpipe.matching.match``.

    Returns
    -------
    src, dst : (M, 2) float64
        Matched keypoint positions in A and in B (pixels), best descriptor distance first.
    """
    from . import features, matching

    fa = features.detect(gray_a, detector, max_features)
    fb = features.detect(gray_b, detector, max_features)
    idx = matching.match(fa.descriptors, fb.descriptors, ratio, cross_check, fa.binary)
    return fa.xy[idx[:, 0]].astype(np.float64), fb.xy[idx[:, 1]].astype(np.float64)


def alignment_checkerboard(img_a: np.ndarray, img_b: np.ndarray, H_ab, tiles: int = 8) -> np.ndarray:
    """B warped into A's frame by ``H_ab`` (A -> B), interleaved with A in a checkerboard to show misalignment.

    Parameters
    ----------
    img_a, img_b : (H, W) or (H, W, 3) uint8
        The two views (gray or BGR).
    H_ab : (3, 3) array_like
        Homography mapping A's pixels to B's.
    tiles : int
        Number of checkerboard squares along the longer side of A.

    Returns
    -------
    (Ha, Wa, 3) uint8 BGR
        Dark squares where the warped B does not cover A. Straight edges that continue across squares mean a
        good alignment; steps at square borders are the residual error.
    """
    import cv2

    H = np.asarray(H_ab, dtype=np.float64)
    if H.shape != (3, 3) or not np.isfinite(H).all():
        raise InputError(f"`H_ab` must be a finite (3, 3) array, got shape {H.shape}")
    if isinstance(tiles, bool) or not isinstance(tiles, (int, np.integer)) or tiles < 1:
        raise InputError(f"`tiles` must be an integer >= 1, got {tiles!r}")
    a = img_a if img_a.ndim == 3 else cv2.cvtColor(img_a, cv2.COLOR_GRAY2BGR)
    b = img_b if img_b.ndim == 3 else cv2.cvtColor(img_b, cv2.COLOR_GRAY2BGR)
    h, w = a.shape[:2]
    # sample B at H @ (x, y) for every pixel (x, y) of A
    warped = cv2.warpPerspective(b, H, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    covered = cv2.warpPerspective(np.full(b.shape[:2], 255, np.uint8), H, (w, h),
                                  flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP, borderValue=0) > 0
    side = max(1, int(math.ceil(max(h, w) / tiles)))
    yy, xx = np.mgrid[0:h, 0:w]
    use_b = (((yy // side) + (xx // side)) % 2 == 1) & covered
    out = np.where(use_b[..., None], warped, a)
    out[~covered] = (a[~covered] // 3)
    return out.astype(np.uint8)


def alignment_panel(img_a: np.ndarray, img_b: np.ndarray, panels: dict, tiles: int = 8,
                    width: int = 400) -> np.ndarray:
    """Side-by-side :func:`alignment_checkerboard` pictures, one per labelled homography.

    Parameters
    ----------
    img_a, img_b : uint8 images
        The two views.
    panels : dict
        Label -> H (A -> B, (3, 3) array_like) or None (drawn as a grey "no result" panel).
    tiles : int
        Checkerboard squares along the longer side.
    width : int
        Width of each panel in pixels (A is resized keeping its aspect ratio).

    Returns
    -------
    (h + 24, width * len(panels), 3) uint8 BGR
        The panels with their labels in a bar above each.
    """
    import cv2

    h = max(1, int(round(img_a.shape[0] * width / img_a.shape[1])))
    cols = []
    for label, H in panels.items():
        if H is None:
            pic = np.full((h, width, 3), 96, np.uint8)
        else:
            pic = cv2.resize(alignment_checkerboard(img_a, img_b, np.asarray(H, float), tiles), (width, h),
                             interpolation=cv2.INTER_AREA)
        bar = np.full((24, width, 3), 255, np.uint8)
        cv2.putText(bar, str(label), (4, 17), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        cols.append(np.vstack([bar, pic]))
    return np.hstack(cols)


def metric_key(name: str) -> str:
    """A pair name as a metrics key: no dots (DVC joins nested keys with dots) and never ``all``."""
    key = str(name).replace(".", "_")
    return "pair_all" if key == "all" else key


def compare_methods(pairs: list[dict], runs: dict, success_px: float = 3.0) -> dict:
    """Corner error (pairs with truth), inliers and failures of every method on every matched pair.

    Parameters
    ----------
    pairs : list of dict
        ``{"name", "matches", "size_a": [w, h], "H": (3, 3) true A -> B or None}`` per matched pair.
    runs : dict
        Method -> a ``homography_estimate`` result ``{"pairs": {name: {"H", "inliers", ...}}, "dropped": [...]}``;
        a pair missing from ``pairs`` of a run is a failed estimate.
    success_px : float
        A pair with truth succeeds when its corner error is at most this many pixels.

    Returns
    -------
    dict
        ``methods`` (names), ``pairs`` and ``truth_pairs`` (counts), ``success_px``, ``per_pair`` (name ->
        ``{"matches", "truth": bool, method: {"inliers", "estimated", "corner_error_px" (truth and an estimate),
        "within" (truth)}}``, in the order of ``pairs``) and ``all`` (method -> ``pairs``, ``estimated``,
        ``failures``, ``median_inliers`` (when any estimate) and, when any pair has truth, ``truth_pairs``,
        ``pairs_within``, ``success_rate``, ``median_corner_error_px`` (a failure counts as infinite; omitted when
        infinite) and ``mean_corner_error_px`` (over the successes; omitted without one)).
    """
    from .metrics import corner_error

    methods = list(runs)
    per_pair: dict = {}
    for q in pairs:
        row: dict = {"matches": int(q["matches"]), "truth": q.get("H") is not None}
        for m in methods:
            est = runs[m]["pairs"].get(q["name"])
            r: dict = {"inliers": int(est["inliers"]) if est else 0, "estimated": int(est is not None)}
            if row["truth"]:
                w, h = (int(v) for v in q["size_a"])
                err = corner_error(est["H"], q["H"], w, h) if est else math.inf
                if math.isfinite(err):
                    r["corner_error_px"] = float(err)
                r["within"] = int(err <= success_px)
            row[m] = r
        per_pair[q["name"]] = row
    truth_names = [n for n, row in per_pair.items() if row["truth"]]
    summary: dict = {}
    for m in methods:
        rows = [row[m] for row in per_pair.values()]
        inl = [r["inliers"] for r in rows if r["estimated"]]
        s: dict = {"pairs": len(rows), "estimated": len(inl), "failures": len(rows) - len(inl)}
        if inl:
            s["median_inliers"] = float(np.median(inl))
        if truth_names:
            errs = np.array([per_pair[n][m].get("corner_error_px", math.inf) for n in truth_names])
            ok = errs <= success_px
            s.update(truth_pairs=len(errs), pairs_within=int(ok.sum()), success_rate=float(ok.mean()))
            if np.isfinite(np.median(errs)):
                s["median_corner_error_px"] = float(np.median(errs))
            if ok.any():
                s["mean_corner_error_px"] = float(errs[ok].mean())
        summary[m] = s
    return {"methods": methods, "pairs": len(per_pair), "truth_pairs": len(truth_names), "success_px": success_px,
            "per_pair": per_pair, "all": summary}


def metrics_of(compared: dict) -> dict:
    """The numeric metrics of :func:`compare_methods` output: ``{"homography": {method: {"all": {...}, pair: {...}}}}``
    (DVC shows them as ``homography.<method>.<pair>.corner_error_px``)."""
    out: dict = {}
    for m in compared["methods"]:
        out[m] = {"all": dict(compared["all"][m])}
        for name, row in compared["per_pair"].items():
            out[m][metric_key(name)] = {"matches": row["matches"], **row[m]}
    return {"homography": out}


def picture_panels(compared: dict, name: str, true_H, estimates: dict) -> tuple[dict, str]:
    """The labelled panels of one pair's :func:`alignment_panel` and its caption.

    Parameters
    ----------
    compared : dict
        :func:`compare_methods` output.
    name : str
        The pair.
    true_H : (3, 3) array_like or None
        The true homography A -> B, when known (then it is the first panel).
    estimates : dict
        Method -> estimated H A -> B, or None when the method failed on the pair.
    """
    row = compared["per_pair"][name]
    panels: dict = {} if true_H is None else {"truth": true_H}
    for m in compared["methods"]:
        r = row[m]
        if not r["estimated"]:
            label = f"{m}: failed"
        elif "corner_error_px" in r:
            label = f"{m}: {r['corner_error_px']:.2f} px"
        else:
            label = f"{m}: {r['inliers']} inliers"
        panels[label] = estimates.get(m)
    first = "the true homography, then each method" if true_H is not None else "each method (no ground truth)"
    return panels, f"{name}: B warped onto A as a checkerboard, {first}"


def report_summary(compared: dict, pictures: list, dropped: list[dict]) -> dict:
    """The report page's summary of the homography task (schema in ``cvpipe.report``).

    Parameters
    ----------
    compared : dict
        :func:`compare_methods` output.
    pictures : list of dict
        ``{"path", "caption"}`` per pair picture, repo-relative paths.
    dropped : list of dict
        ``{"item", "reason"}`` for every input, pair or estimate that was not processed.
    """
    methods, px = compared["methods"], compared["success_px"]
    none = "no ground truth"
    has_truth = compared["truth_pairs"] > 0

    def r(v, nd=3):
        return None if v is None else round(float(v), nd)

    per_method = []
    for m in methods:
        s = compared["all"][m]
        per_method.append([m, f"{s['estimated']} / {s['pairs']}", r(s.get("median_inliers"), 1),
                           r(s.get("median_corner_error_px")) if has_truth else none,
                           f"{s['pairs_within']} / {s['truth_pairs']}" if has_truth else none])
    rows = []
    for name, row in compared["per_pair"].items():
        errs = [(r(row[m]["corner_error_px"]) if "corner_error_px" in row[m] else "failed") if row["truth"] else none
                for m in methods]
        inl = [row[m]["inliers"] if row[m]["estimated"] else "failed" for m in methods]
        rows.append([name, row["matches"], *errs, *inl])
    tables = [
        {"title": "Per method",
         "columns": ["method", "pairs estimated", "median inliers", "median corner error (px)",
                     f"pairs within {px:g} px"], "rows": per_method},
        {"title": "Per pair",
         "columns": ["pair", "matches", *(f"{m} corner error (px)" for m in methods),
                     *(f"{m} inliers" for m in methods)], "rows": rows},
    ]
    if dropped:
        tables.append({"title": "Not processed", "columns": ["input", "reason"],
                       "rows": [[d["item"], d["reason"]] for d in dropped]})
    if has_truth:
        truth_note = (f"{compared['truth_pairs']} of {compared['pairs']} pairs have a true homography: corner error is "
                      "the mean distance of A's four corners mapped by the estimated and the true H, and a pair "
                      f"succeeds within {px:g} px.")
        without = [n for n, row in compared["per_pair"].items() if not row["truth"]]
        if without:
            truth_note += f" Without ground truth (inliers only): {', '.join(without)}."
    else:
        truth_note = ("These pairs have no ground truth: the tables compare the methods by inliers (matches within "
                      "the threshold) and the pictures show each method's alignment.")
    return {
        "task": "homography",
        "title": "Our normalized DLT + LO-RANSAC against OpenCV RANSAC and USAC_MAGSAC, on the same matches",
        "description": (
            "The matches of each pair (A, B) go to every estimator with the same threshold, confidence and "
            f"iteration cap. {truth_note} Pictures: B warped into A's frame as a checkerboard, one panel per "
            "method; misalignment shows as steps at the square borders. Times: `dvc plots show` (outputs/timings) "
            "and `cvpipe bench homography`."),
        "pictures": pictures,
        "tables": tables,
    }


def quality_plots(compared: dict) -> dict[str, list[dict]]:
    """``dvc plots`` rows per file: ``corner_error`` (pairs with truth and an estimate) and ``inliers`` (every pair;
    0 for a failed estimate), each row ``{"pair", "method", "label", <value>}``."""
    corner, inliers = [], []
    for name, row in compared["per_pair"].items():
        for m in compared["methods"]:
            base = {"pair": name, "method": m, "label": f"{name} {m}"}
            inliers.append({**base, "inliers": row[m]["inliers"]})
            if "corner_error_px" in row[m]:
                corner.append({**base, "corner_error_px": row[m]["corner_error_px"]})
    return {"corner_error": corner, "inliers": inliers}


# --------------------------------------------------------------------------------------- method registry


def _opencv(method_flag_name: str) -> Callable[..., HomographyFit]:
    def estimate(src, dst, threshold=3.0, confidence=0.999, max_iters=DEFAULT_MAX_ITERS, rng=None, area=None):
        import cv2

        s, d = _check_pair(src, dst)
        _check_area(area)
        if not (math.isfinite(threshold) and threshold > 0):
            raise InputError(f"`threshold` must be a finite number > 0 pixels, got {threshold!r}")
        # ``rng`` is accepted for the common signature and ignored: cv2.findHomography's RANSAC and USAC samplers
        # start from a fixed internal state (the result does not change with cv2.setRNGSeed), so they are
        # deterministic for given points
        H, mask = cv2.findHomography(s, d, getattr(cv2, method_flag_name), float(threshold),
                                     maxIters=int(max_iters), confidence=float(confidence))
        if H is None or mask is None:
            raise EstimationError(f"cv2.findHomography ({method_flag_name}) found no homography; "
                                  "raise `threshold` or supply better matches")
        inl = mask.ravel().astype(bool)
        H = _unit_h22(np.asarray(H, dtype=np.float64))
        e2 = _sq_errors(s, d, H, np.empty(len(s)))
        if inl.sum() < 4:
            raise EstimationError(f"cv2.findHomography ({method_flag_name}) found no homography with at least 4 "
                                  "inliers; raise `threshold` or supply better matches")
        rms = float(np.sqrt(e2[inl].mean()))
        return _significant(HomographyFit(H=H, inliers=inl, iterations=-1, rms=rms), s, d, threshold, area)

    estimate.__name__ = f"opencv_{method_flag_name.lower()}"
    estimate.__doc__ = (f"``cv2.findHomography`` with ``cv2.{method_flag_name}`` behind the find_homography interface "
                        "(deterministic: ``rng`` is ignored).")
    return estimate


#: method name -> estimator with the :func:`find_homography` signature (src, dst, threshold, confidence,
#: max_iters, rng); ``iterations`` is -1 for OpenCV, which does not report it
METHODS: dict[str, Callable[..., HomographyFit]] = {
    "ours": find_homography,
    "opencv_ransac": _opencv("RANSAC"),
    "opencv_magsac": _opencv("USAC_MAGSAC"),
}


def estimate(method: str, src, dst, **kwargs) -> HomographyFit:
    """Run the estimator registered as ``method`` in :data:`METHODS` (keyword arguments as find_homography).

    This is the path of the ``cvpipe homography`` command and the pipeline's estimate stage: every method's model
    must be significant against chance (:func:`check_significant`, with ``area`` or the bounding box of ``dst``),
    and 4 matches, which any homography fits exactly, are not enough to tell (EstimationError).
    """
    try:
        fn = METHODS[method]
    except KeyError:
        raise InputError(f"`method` must be one of {sorted(METHODS)}, got {method!r}") from None
    fit = fn(src, dst, **kwargs)
    n = len(fit.inliers)
    if n <= 4:
        raise EstimationError(f"only {n} matches: a homography fits any 4 exactly, so this one cannot be told "
                              "from chance; supply more matches (more features, a larger ratio)")
    return fit
