"""Numba kernels of the homography recipe over the robust core (:mod:`cvpipe.robust`): the closed-form 4-point
solution, its degeneracy tests, local optimization and the per-hypothesis loop. They only compute:
:func:`cvpipe.homography.find_homography` validates."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..robust.sampling import sample4
from ..robust.stopping import on_new_best, on_rejected
from ._kernels import _denormalize, _lsq, _score, _sq_errors

#: smallest |twice the triangle area| of a sample triple in Hartley-normalized coordinates (mean radius sqrt(2))
_COLLINEAR_EPS = 1e-5
#: smallest |det(Hn)| / ||Hn||_F^3 of a model in Hartley-normalized coordinates (identity: 0.19; a mark covering a
#: tenth of the scene's width: ~5e-3). Below it H nearly collapses the source onto a line or a point, where a
#: cluster of many-to-one matches scores as exact "inliers" and wins the MSAC cost (seen with ORB on repetitive
#: PCB texture: 24 source points matched to one scene point gave models at 3e-5 to 8e-5, and 1e-8)
_MIN_CONDITION = 2e-4
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

    ``state`` (:func:`cvpipe.robust.new_state`) is updated in place, as is ``best_H`` (pixel coordinates).
    Returns the rows used.
    """
    s = state[0]
    n = src.shape[0]
    Hn = np.empty((3, 3))
    tmp = np.empty((3, 3))
    H = np.empty((3, 3))
    e2 = np.empty(n)
    used = 0
    for k in range(u.shape[0]):
        if s.iterations >= s.bound:
            break
        used += 1
        s.iterations += 1
        i0, i1, i2, i3 = sample4(u, k, n)
        if not _minimal_solve(sn, dn, i0, i1, i2, i3, Hn) or _collapsed(Hn):
            s.degenerate += 1
            continue
        _denormalize(Hn, Ts, Tdi, tmp, H)
        cost, cnt, seen, status = _score(src, dst, H, thr2, s.best_cost, s.sprt_a, s.sprt_eps, s.sprt_delta)
        if status != 0 or cost >= s.best_cost:
            if status == 1:
                on_rejected(s, cnt, seen, n, 4, log1mconf, max_iters)
            continue
        raw_cnt = cnt
        if lo and cnt >= 8:
            Hb, cost_b, cnt_b = _local_optimize(src, dst, H, thr2, lo_multiplier, lo_steps, e2)
            s.lo_runs += 1
            _denormalize(Hb, Tsi, Td, tmp, Hn)
            if cost_b < cost and not _collapsed(Hn):
                H[:, :] = Hb
                cost = cost_b
                cnt = cnt_b
        best_H[:, :] = H
        on_new_best(s, cost, cnt, raw_cnt, n, 4, log1mconf, max_iters)
    return used
