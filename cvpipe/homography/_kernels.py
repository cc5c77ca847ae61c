"""Numba kernels of the homography estimator: reprojection errors, Hartley normalization, least squares and
Levenberg-Marquardt refinement. They only compute: callers validate (see :mod:`cvpipe.homography.estimate`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._kernels import cholesky_factor, cholesky_solve, cholesky_substitute  # the one SPD solve (shared)

#: relative size of the smaller principal axis below which a whole point set counts as collinear (1e-7: the
#: 2x2 covariance resolves eigenvalue ratios down to ~1e-15, i.e. axis ratios down to ~3e-8)
_ALL_COLLINEAR_EPS = 1e-7
#: most inverse-iteration steps of :func:`_null_vector` (enough for a factor of 0.45 a step)
_NULL_STEPS = 40
#: index into the 6 unique entries (xx, xy, x, yy, y, 1) of a symmetric 3x3 p p^T
_SYM6 = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]], dtype=np.int64)


@njit(cache=True, inline="always", error_model="numpy")
def _matmul3(A, B, out):
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]


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


@njit(cache=True, inline="always", error_model="numpy")
def _sq_error(H, x, y, u, v):
    """Squared one-sided reprojection error ``|| dehom(H [x, y, 1]) - (u, v) ||^2`` (inf when mapped to infinity):
    the one reprojection loop body of the estimator (scoring, least-squares masks, refinement cost)."""
    w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    if w == 0.0:
        return np.inf
    du = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w - u
    dv = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w - v
    return du * du + dv * dv


@njit(cache=True, error_model="numpy")
def _sq_errors(src, dst, H, out):
    """Squared one-sided reprojection error per correspondence (inf when mapped to infinity)."""
    for i in range(src.shape[0]):
        out[i] = _sq_error(H, src[i, 0], src[i, 1], dst[i, 0], dst[i, 1])
    return out


@njit(cache=True, error_model="numpy")
def _score(src, dst, H, thr2, bail, A, eps, delta):
    """Evaluate H point by point: (MSAC cost, inliers so far, points evaluated, status).

    status 0: all points evaluated; 1: rejected by the SPRT (likelihood ratio above A); 2: the MSAC cost already
    exceeds ``bail`` (the best cost so far), so H cannot win. With ``bail = A = inf``: the plain MSAC cost.
    """
    up = delta / eps
    down = (1.0 - delta) / (1.0 - eps)
    lam = 1.0
    cost = 0.0
    cnt = 0
    n = src.shape[0]
    for i in range(n):
        e2 = _sq_error(H, src[i, 0], src[i, 1], dst[i, 0], dst[i, 1])
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
def _hartley(p, mask):
    """Hartley normalization of the points ``p[mask]``: (count, centroid x, centroid y, scale).

    The scale sqrt(2) / mean distance to the centroid moves the mean distance to sqrt(2); it is ``inf`` when the
    points coincide (callers test ``scale < inf``). The normalized point is ``((x - cx) * s, (y - cy) * s)``.
    """
    n = 0
    cx = cy = 0.0
    for i in range(p.shape[0]):
        if mask[i]:
            n += 1
            cx += p[i, 0]
            cy += p[i, 1]
    cx /= n
    cy /= n
    d = 0.0
    for i in range(p.shape[0]):
        if mask[i]:
            d += math.sqrt((p[i, 0] - cx) ** 2 + (p[i, 1] - cy) ** 2)
    return n, cx, cy, math.sqrt(2.0) * n / d


@njit(cache=True, inline="always", error_model="numpy")
def _denormalize(Hn, Ts, Tdi, tmp, out):
    """``out = Tdi @ Hn @ Ts`` (``tmp``: 3x3 scratch): a model between normalized coordinates back in pixels (or,
    given ``Tsi`` and ``Td``, a pixel model in normalized coordinates)."""
    _matmul3(Hn, Ts, tmp)
    _matmul3(Tdi, tmp, out)


@njit(cache=True, error_model="numpy")
def _normalize(p):
    """Hartley normalization in one pass: (T (3, 3), normalized points (N, 2), not_collinear).

    ``not_collinear`` is False when the smaller principal axis of the points is below ``_ALL_COLLINEAR_EPS`` times
    the larger one (computed from the 2x2 covariance: ratio of eigenvalues <= eps^2), or all points coincide.
    """
    n, cx, cy, s = _hartley(p, np.ones(p.shape[0], np.bool_))
    T = np.eye(3)
    out = np.empty((n, 2))
    if not s < np.inf:
        return T, out, False
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
    H = np.empty((3, 3))
    for k in range(8):
        H[k // 3, k % 3] = p[k]
    H[2, 2] = 1.0
    c = 0.0
    for i in range(xs.shape[0]):
        e2 = _sq_error(H, xs[i], ys[i], us[i], vs[i])
        if e2 == np.inf:
            return np.inf
        c += ws[i] * e2
    return c


@njit(cache=True, error_model="numpy")
def _null_vector(M, h):
    """The unit eigenvector of the smallest eigenvalue of the symmetric positive semi-definite ``M`` (n x n) into
    ``h``, by inverse iteration with the Cholesky factor of ``M + sigma I`` (``sigma = 1e-12 trace M``); True when
    the iterates settled (a step moved them by less than 1e-13).

    The iterates approach the eigenvector by the factor ``(w0 + sigma) / (w1 + sigma)`` a step (``w0 <= w1`` the two
    smallest eigenvalues), so settling within ``_NULL_STEPS`` steps means ``w1 > sigma > 1e-14 w_max``: the
    smallest eigenvalue is simple, as :func:`_lsq` requires. False (the factor is close to 1, or ``M`` is not
    positive semi-definite): the caller decides with :func:`_jacobi_eigh`.
    """
    n = M.shape[0]
    tr = 0.0
    for i in range(n):
        tr += M[i, i]
    if not (tr > 0.0 and tr < np.inf):
        return False
    L = np.zeros((n, n))
    if not cholesky_factor(M, L, 1e-12 * tr):
        return False
    x = np.empty(n)
    y = np.empty(n)
    for i in range(n):  # a fixed start with no special direction
        x[i] = 1.0 / (i + 1.0)
    for step in range(_NULL_STEPS):
        cholesky_substitute(L, x, y)
        norm = 0.0
        dot = 0.0
        for i in range(n):
            norm += y[i] * y[i]
            dot += y[i] * x[i]
        scale = (1.0 if dot >= 0.0 else -1.0) / math.sqrt(norm)
        change = 0.0
        for i in range(n):
            yi = y[i] * scale
            change = max(change, abs(yi - x[i]))
            x[i] = yi
        if change < 1e-13 and step > 0:
            for i in range(n):
                h[i] = x[i]
            return True
    return False


@njit(cache=True, error_model="numpy")
def _lsq(src, dst, mask):
    """Hartley-normalized DLT on the masked correspondences via the 9x9 normal matrix; (H, ok)."""
    H = np.zeros((3, 3))
    n, cx, cy, ss = _hartley(src, mask)
    if n < 4:
        return H, False
    _, cX, cY, sd = _hartley(dst, mask)
    if not (ss < np.inf and sd < np.inf):
        return H, False
    # A^T A of the DLT rows [p, 0, -u p], [0, p, -v p] with p = (x, y, 1) has the block structure
    # [[S, 0, -Su], [0, S, -Sv], [-Su, -Sv, Suv]] with S = sum p p^T, Su = sum u p p^T, Sv = sum v p p^T,
    # Suv = sum (u^2 + v^2) p p^T: 24 sums per point instead of 162 products
    # the sums in local scalars, which the compiler keeps in registers: S0..S5 = sum q, U0..U5 = sum u q,
    # V0..V5 = sum v q, R0..R5 = sum (u^2 + v^2) q, for q = (x^2, xy, x, y^2, y, 1)
    S0 = S1 = S2 = S3 = S4 = S5 = 0.0
    U0 = U1 = U2 = U3 = U4 = U5 = 0.0
    V0 = V1 = V2 = V3 = V4 = V5 = 0.0
    R0 = R1 = R2 = R3 = R4 = R5 = 0.0
    for i in range(src.shape[0]):
        if not mask[i]:
            continue
        x = (src[i, 0] - cx) * ss
        y = (src[i, 1] - cy) * ss
        u = (dst[i, 0] - cX) * sd
        v = (dst[i, 1] - cY) * sd
        q0 = x * x
        q1 = x * y
        q3 = y * y
        r2 = u * u + v * v
        S0 += q0
        S1 += q1
        S2 += x
        S3 += q3
        S4 += y
        S5 += 1.0
        U0 += u * q0
        U1 += u * q1
        U2 += u * x
        U3 += u * q3
        U4 += u * y
        U5 += u * 1.0
        V0 += v * q0
        V1 += v * q1
        V2 += v * x
        V3 += v * q3
        V4 += v * y
        V5 += v * 1.0
        R0 += r2 * q0
        R1 += r2 * q1
        R2 += r2 * x
        R3 += r2 * q3
        R4 += r2 * y
        R5 += r2 * 1.0
    S = np.array([S0, S1, S2, S3, S4, S5])
    Su = np.array([U0, U1, U2, U3, U4, U5])
    Sv = np.array([V0, V1, V2, V3, V4, V5])
    Suv = np.array([R0, R1, R2, R3, R4, R5])
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
    h = np.empty(9)
    if not _null_vector(M, h):
        V = np.empty((9, 9))
        w = _jacobi_eigh(M, V)
        if not (w[1] > 1e-14 * w[8]):
            return H, False
        for k in range(9):
            h[k] = V[k, 0]
    Hn = np.empty((3, 3))
    for k in range(9):
        Hn[k // 3, k % 3] = h[k]
    _denormalize(Hn, _similarity(ss, -ss * cx, -ss * cy), _similarity(1.0 / sd, cX, cY), np.empty((3, 3)), H)
    if H[2, 2] != 0.0:
        H /= H[2, 2]
    return H, True


@njit(cache=True, error_model="numpy")
def _lm_refine(src, dst, weight, H0, max_iter):
    """Levenberg-Marquardt on the weighted one-sided reprojection error sum_i weight_i * |dehom(H src_i) - dst_i|^2.

    Correspondences with weight 0 are ignored. Works in Hartley-normalized coordinates (isotropic scaling of dst,
    so the objective is the pixel one up to a constant) with 8 parameters (H[2, 2] = 1 there). Returns
    (H in pixels, weighted sum of squared errors in pixels^2).
    """
    n_all = src.shape[0]
    used = weight > 0.0
    n, cx, cy, ss = _hartley(src, used)
    _, cX, cY, sd = _hartley(dst, used)
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
    _denormalize(H0, Tsi, Td, tmp, Hn)
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
            # the Jacobian rows are g = d(uu)/dp = (x, y, 1, 0, 0, 0, -uu x, -uu y) / w and
            # h = d(vv)/dp = (0, 0, 0, x, y, 1, -vv x, -vv y) / w; the products with their zero entries are left out
            # (exact zeros add nothing), so the sums below are those of the full 2 x 8 products, in scalars
            g0 = x * iw
            g1 = y * iw
            g2 = iw
            g6 = -uu * x * iw
            g7 = -uu * y * iw
            h6 = -vv * x * iw
            h7 = -vv * y * iw
            wi = ws[i]
            Jtr[0] += wi * (g0 * ru)
            Jtr[1] += wi * (g1 * ru)
            Jtr[2] += wi * (g2 * ru)
            Jtr[3] += wi * (g0 * rv)
            Jtr[4] += wi * (g1 * rv)
            Jtr[5] += wi * (g2 * rv)
            Jtr[6] += wi * (g6 * ru + h6 * rv)
            Jtr[7] += wi * (g7 * ru + h7 * rv)
            # the upper-left and the middle 3 x 3 blocks are the same sums (g0..g2 equal h3..h5)
            JtJ[0, 0] += wi * (g0 * g0)
            JtJ[0, 1] += wi * (g0 * g1)
            JtJ[0, 2] += wi * (g0 * g2)
            JtJ[1, 1] += wi * (g1 * g1)
            JtJ[1, 2] += wi * (g1 * g2)
            JtJ[2, 2] += wi * (g2 * g2)
            JtJ[0, 6] += wi * (g0 * g6)
            JtJ[0, 7] += wi * (g0 * g7)
            JtJ[1, 6] += wi * (g1 * g6)
            JtJ[1, 7] += wi * (g1 * g7)
            JtJ[2, 6] += wi * (g2 * g6)
            JtJ[2, 7] += wi * (g2 * g7)
            JtJ[3, 6] += wi * (g0 * h6)
            JtJ[3, 7] += wi * (g0 * h7)
            JtJ[4, 6] += wi * (g1 * h6)
            JtJ[4, 7] += wi * (g1 * h7)
            JtJ[5, 6] += wi * (g2 * h6)
            JtJ[5, 7] += wi * (g2 * h7)
            JtJ[6, 6] += wi * (g6 * g6 + h6 * h6)
            JtJ[6, 7] += wi * (g6 * g7 + h6 * h7)
            JtJ[7, 7] += wi * (g7 * g7 + h7 * h7)
        for a in range(3):
            for b in range(a, 3):
                JtJ[3 + a, 3 + b] = JtJ[a, b]
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
            if not cholesky_solve(A, negJtr, delta):
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
        if not improved or rel < 1e-9:
            break
    for k in range(8):
        Hn[k // 3, k % 3] = p[k]
    Hn[2, 2] = 1.0
    H = np.empty((3, 3))
    _denormalize(Hn, Ts, Tdi, tmp, H)
    if H[2, 2] != 0.0:
        H /= H[2, 2]
    return H, cost / (sd * sd)


#: the final refinement's loss is Tukey's biweight; hard inliers and a Cauchy-like loss were measured and rejected
#: (docs/notes/homography.md: the final refinement paragraph)
@njit(cache=True, error_model="numpy")
def _weights(e2, thr2, out):
    """IRLS weights of the final refinement from squared residuals: Tukey's biweight (1 - e2 / c^2)^2 within
    c^2 = ``thr2``, 0 beyond."""
    for i in range(e2.shape[0]):
        if e2[i] > thr2:
            out[i] = 0.0
        else:
            r = 1.0 - e2[i] / thr2
            out[i] = r * r
    return out


@njit(cache=True, error_model="numpy")
def _finalize(src, dst, H0, thr2, refine, rounds, wthr2):
    """Inliers of H0 and, with ``refine``, up to ``rounds`` of weighted Levenberg-Marquardt (Tukey weights cut
    off at ``wthr2`` from the residuals of the previous round, see ``_weights``). Returns (H, inlier mask, squared
    errors)."""
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
    w = np.empty(n)
    e2r = np.empty(n)
    for _ in range(rounds):
        _weights(e2, wthr2, w)
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
        cnt_r = 0
        for i in range(n):
            cnt_r += e2r[i] <= thr2
        if cnt_r < 4:
            break
        H = Hr
        for i in range(n):
            e2[i] = e2r[i]
            mask[i] = e2r[i] <= thr2
    return H, mask, e2


@njit(cache=True)
def _chance_hits(src, dst, H, thr2, rows):  # pragma: no cover - compiled
    """Pairs (i, j), i in ``rows``, j != i, with ``|| dehom(H src_i) - dst_j ||^2 <= thr2``.

    The points of ``dst`` are binned into a grid of square cells at least as wide as the threshold (wider when the
    grid would have more than 4 cells per point), so the points within the threshold of a projected source lie in the
    3 x 3 cells around it: O(rows + N) for spread points instead of O(rows x N), and the same count.
    """
    n = dst.shape[0]
    if n == 0:
        return 0
    x0, y0, x1, y1 = _bounding_box(dst)
    # wider by a rounding margin, so that a point within the threshold is never two cells away
    cell = math.sqrt(thr2) * (1.0 + 1e-9)
    cell = max(cell, math.sqrt((x1 - x0) * (y1 - y0) / (4.0 * n)), (x1 - x0) / (4.0 * n), (y1 - y0) / (4.0 * n))
    ncx = np.int64((x1 - x0) / cell) + 1
    ncy = np.int64((y1 - y0) / cell) + 1
    # counting sort of the points by cell: the points of cell c are order[start[c]:start[c + 1]]
    cells = np.empty(n, np.int64)
    start = np.zeros(ncx * ncy + 1, np.int64)
    for j in range(n):
        c = np.int64((dst[j, 0] - x0) / cell) * ncy + np.int64((dst[j, 1] - y0) / cell)
        cells[j] = c
        start[c + 1] += 1
    for c in range(ncx * ncy):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for j in range(n):
        order[fill[cells[j]]] = j
        fill[cells[j]] += 1
    hits = 0
    for i in rows:
        x, y = src[i, 0], src[i, 1]
        w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
        if not abs(w) > 1e-12:
            continue
        u = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w
        v = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w
        fu = (u - x0) / cell
        fv = (v - y0) / cell
        if not (-2.0 < fu < ncx + 1.0 and -2.0 < fv < ncy + 1.0):  # NaN and far outside: no neighbour
            continue
        cu = np.int64(math.floor(fu))
        cv = np.int64(math.floor(fv))
        lo_v = max(cv - 1, 0)
        hi_v = min(cv + 1, ncy - 1)
        if lo_v > hi_v:
            continue
        for cx in range(max(cu - 1, 0), min(cu + 1, ncx - 1) + 1):
            # the cells (cx, lo_v .. hi_v) are one run of the sorted order
            for t in range(start[cx * ncy + lo_v], start[cx * ncy + hi_v + 1]):
                j = order[t]
                if j != i:
                    du = u - dst[j, 0]
                    dv = v - dst[j, 1]
                    if du * du + dv * dv <= thr2:
                        hits += 1
    return hits


@njit(cache=True)
def _distinct_rows(pts, mask):  # pragma: no cover - compiled
    """Number of distinct rows of the (N, 2) ``pts``, and of its rows where ``mask`` is true.

    One pass over an open-addressing hash table of the points (O(N); equal points have equal hashes, and points
    are compared exactly).
    """
    n = pts.shape[0]
    size = 1
    while size < 2 * n:
        size *= 2
    slot = np.full(size, -1, np.int64)  # a row of pts, or -1 for an empty slot
    hit = np.zeros(size, np.bool_)  # a row of this point is in the mask
    n_all = 0
    n_mask = 0
    for i in range(n):
        x = pts[i, 0]
        y = pts[i, 1]
        v = abs(x) * 73856093.0 + abs(y) * 19349663.0
        if not v < 1e15:  # keep the integer conversion in range (the hash only has to be equal for equal points)
            v = v % 1e15 if math.isfinite(v) else 0.0
        h = np.int64(v) & (size - 1)
        while slot[h] >= 0 and not (pts[slot[h], 0] == x and pts[slot[h], 1] == y):
            h = (h + 1) & (size - 1)
        if slot[h] < 0:
            slot[h] = i
            n_all += 1
        if mask[i] and not hit[h]:
            hit[h] = True
            n_mask += 1
    return n_all, n_mask


@njit(cache=True)
def _bounding_box(pts):  # pragma: no cover - compiled
    """(x min, y min, x max, y max) of the (N >= 1, 2) ``pts``."""
    x0, y0 = pts[0, 0], pts[0, 1]
    x1, y1 = x0, y0
    for j in range(pts.shape[0]):
        x0 = min(x0, pts[j, 0])
        y0 = min(y0, pts[j, 1])
        x1 = max(x1, pts[j, 0])
        y1 = max(y1, pts[j, 1])
    return x0, y0, x1, y1


@njit(cache=True)
def _rows_in_order(order, a, b, c, d):  # pragma: no cover - compiled
    """``a[order], b[order], c[order], d[order]`` of four (N, 2) arrays in one pass (NumPy's fancy indexing of
    rows costs about 8 ns per row and array)."""
    n = order.shape[0]
    out = (np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 2)))
    for i in range(n):
        j = order[i]
        out[0][i, 0] = a[j, 0]
        out[0][i, 1] = a[j, 1]
        out[1][i, 0] = b[j, 0]
        out[1][i, 1] = b[j, 1]
        out[2][i, 0] = c[j, 0]
        out[2][i, 1] = c[j, 1]
        out[3][i, 0] = d[j, 0]
        out[3][i, 1] = d[j, 1]
    return out


@njit(cache=True)
def _densest_cell(pts, side):  # pragma: no cover - compiled
    """The most points of ``pts`` (N, 2) in one cell ``[i side, (i + 1) side) x [j side, (j + 1) side)`` of the
    square grid (counted in an open-addressing hash table of the occupied cells); N when a coordinate is too large
    for the grid's integer indices (no bound then)."""
    n = pts.shape[0]
    size = 2
    while size < 2 * n:
        size *= 2
    ci = np.empty(size, np.int64)
    cj = np.empty(size, np.int64)
    count = np.zeros(size, np.int64)
    best = 0
    for k in range(n):
        x = pts[k, 0] / side
        y = pts[k, 1] / side
        if not (abs(x) < 1e18 and abs(y) < 1e18):
            return n
        i = np.int64(math.floor(x))
        j = np.int64(math.floor(y))
        h = (i * np.int64(73856093) + j * np.int64(19349663)) & (size - 1)
        while count[h] > 0 and (ci[h] != i or cj[h] != j):
            h = (h + 1) & (size - 1)
        ci[h] = i
        cj[h] = j
        count[h] += 1
        best = max(best, count[h])
    return best
