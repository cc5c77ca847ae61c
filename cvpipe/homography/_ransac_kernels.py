"""Numba kernels of the RANSAC loop: minimal samples, their closed-form solution, SPRT scoring, local optimization
and the adaptive iteration bound. They only compute: :func:`cvpipe.homography.find_homography` validates."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._kernels import _denormalize, _lsq, _score, _sq_errors

#: smallest |twice the triangle area| of a sample triple in Hartley-normalized coordinates (mean radius sqrt(2))
_COLLINEAR_EPS = 1e-5
#: smallest |det(Hn)| / ||Hn||_F^3 of a model in Hartley-normalized coordinates (identity: 0.19; a mark covering a
#: tenth of the scene's width: ~5e-3). Below it H nearly collapses the source onto a line or a point, where a
#: cluster of many-to-one matches scores as exact "inliers" and wins the MSAC cost (seen with ORB on repetitive
#: PCB texture: 24 source points matched to one scene point gave models at 3e-5 to 8e-5, and 1e-8)
_MIN_CONDITION = 2e-4
#: SPRT: time of one hypothesis (sample, checks, solve) in units of one point verification, and models per sample
_SPRT_TM = 200.0
_SPRT_MS = 1.0


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
def _refit(src, dst, H, t2, e2, mask):
    """Least squares (normalized DLT) on the correspondences within ``sqrt(t2)`` of H: (H, ok)."""
    _sq_errors(src, dst, H, e2)
    for i in range(src.shape[0]):
        mask[i] = e2[i] <= t2
    return _lsq(src, dst, mask)


@njit(cache=True, error_model="numpy")
def _local_optimize(src, dst, H0, thr2, multiplier, steps, e2):
    """LO step: least squares on the inliers of H0, then iterative least squares while the threshold shrinks
    from ``multiplier * thr`` to ``thr``. Returns the best (H, MSAC cost, inliers) among H0 and the refits."""
    n = src.shape[0]
    best = H0.copy()
    best_cost, best_cnt, _, _ = _score(src, dst, H0, thr2, np.inf, np.inf, 0.5, 0.25)
    mask = np.empty(n, np.bool_)
    H = H0.copy()
    for rep in range(2):
        Hl, ok = _refit(src, dst, H, thr2, e2, mask)
        if not ok:
            break
        H = Hl
        for s in range(steps):
            f = multiplier - (multiplier - 1.0) * s / max(steps - 1, 1)
            Hl, ok = _refit(src, dst, H, thr2 * f * f, e2, mask)
            if not ok:
                break
            H = Hl
        cost, cnt, _, _ = _score(src, dst, H, thr2, np.inf, np.inf, 0.5, 0.25)
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


#: The search state of the RANSAC loop: one float64 array that ``find_homography`` creates (:func:`new_state`) and
#: ``_ransac_chunk`` updates in place, chunk after chunk. Its slots, by name:
#:
#: - ``BEST_COST``: MSAC cost of the best model so far; ``BEST_INLIERS``: its inlier count (after local optimization);
#: - ``BOUND``: iterations the adaptive bound asks for; ``ITERATIONS``: non-degenerate hypotheses scored;
#:   ``DEGENERATE``: samples rejected before scoring; ``LO_RUNS``: local optimizations run;
#: - ``SPRT_EPS``, ``SPRT_DELTA``: the SPRT's inlier share of a good and of a bad model; ``SPRT_A``: its decision
#:   threshold; ``SPRT_TM``: the time of one hypothesis in point verifications;
#: - ``BAD_CONSISTENT``, ``BAD_SEEN``, ``BAD_MODELS``: consistent points and points verified in the models the SPRT
#:   rejected, and how many (they re-estimate ``SPRT_DELTA``).
(BEST_COST, BEST_INLIERS, BOUND, ITERATIONS, DEGENERATE, LO_RUNS, SPRT_EPS, SPRT_DELTA, SPRT_A, BAD_CONSISTENT,
 BAD_SEEN, BAD_MODELS, SPRT_TM) = range(13)


def new_state(max_iters: int, eps: float, delta: float) -> np.ndarray:
    """The search state before the first hypothesis (slots above): no model, the bound at ``max_iters``, the SPRT
    designed for an inlier share ``eps`` of a good model and ``delta`` of a bad one."""
    state = np.zeros(13)
    state[BEST_COST] = np.inf
    state[BOUND] = float(max_iters)
    state[SPRT_EPS], state[SPRT_DELTA], state[SPRT_TM] = eps, delta, _SPRT_TM
    state[SPRT_A] = _sprt_threshold(eps, delta, _SPRT_TM)
    return state


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

    ``state`` (its slots: :func:`new_state`) is updated in place, as is ``best_H`` (pixel coordinates).
    Returns the rows used.
    """
    n = src.shape[0]
    Hn = np.empty((3, 3))
    tmp = np.empty((3, 3))
    H = np.empty((3, 3))
    e2 = np.empty(n)
    used = 0
    for k in range(u.shape[0]):
        if state[ITERATIONS] >= state[BOUND]:
            break
        used += 1
        i0, i1, i2, i3 = _sample4(u[k, 0], u[k, 1], u[k, 2], u[k, 3], n)
        if not _minimal_solve(sn, dn, i0, i1, i2, i3, Hn) or _collapsed(Hn):
            state[DEGENERATE] += 1
            continue
        state[ITERATIONS] += 1
        _denormalize(Hn, Ts, Tdi, tmp, H)
        cost, cnt, seen, status = _score(src, dst, H, thr2, state[BEST_COST], state[SPRT_A], state[SPRT_EPS],
                                         state[SPRT_DELTA])
        if status != 0 or cost >= state[BEST_COST]:
            if status != 1:
                continue
            # rejected by the SPRT: its consistent fraction estimates delta; redesign the test when that drifts
            state[BAD_CONSISTENT] += cnt
            state[BAD_SEEN] += seen
            state[BAD_MODELS] += 1
            if state[BAD_MODELS] >= 20 and state[BAD_SEEN] > 0:
                d = max(state[BAD_CONSISTENT] / state[BAD_SEEN], 1e-4)
                if abs(d - state[SPRT_DELTA]) > 0.1 * state[SPRT_DELTA]:
                    state[SPRT_DELTA] = min(d, 0.5 * state[SPRT_EPS])
                    state[SPRT_A] = _sprt_threshold(state[SPRT_EPS], state[SPRT_DELTA], state[SPRT_TM])
                    state[BOUND] = _bound(state[BEST_INLIERS], n, log1mconf, max_iters, state[SPRT_A])
            continue
        raw_cnt = cnt
        if lo and cnt >= 8:
            Hb, cost_b, cnt_b = _local_optimize(src, dst, H, thr2, lo_multiplier, lo_steps, e2)
            state[LO_RUNS] += 1
            _denormalize(Hb, Tsi, Td, tmp, Hn)
            if cost_b < cost and not _collapsed(Hn):
                H[:, :] = Hb
                cost = cost_b
                cnt = cnt_b
        state[BEST_COST] = cost
        best_H[:, :] = H
        if raw_cnt / n > state[SPRT_EPS]:
            # eps from the unoptimized model: a fresh all-inlier minimal model is less accurate than an LO'd one
            state[SPRT_EPS] = raw_cnt / n
            state[SPRT_DELTA] = min(state[SPRT_DELTA], 0.5 * state[SPRT_EPS])
            state[SPRT_A] = _sprt_threshold(state[SPRT_EPS], state[SPRT_DELTA], state[SPRT_TM])
        if cnt > state[BEST_INLIERS]:
            state[BEST_INLIERS] = cnt
        state[BOUND] = _bound(state[BEST_INLIERS], n, log1mconf, max_iters, state[SPRT_A])
    return used
