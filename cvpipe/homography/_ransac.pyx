# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernels of the homography recipe over the robust core (:mod:`cvpipe.robust`): the closed-form 4-point
solution, its degeneracy tests, local optimization and the per-hypothesis loop (compute only;
:func:`cvpipe.homography.find_homography` validates)."""

import numpy as np

from cpython.buffer cimport PyBuffer_Release
from libc.math cimport fabs, INFINITY

from ..robust._core cimport State, on_new_best, on_rejected, sample4, state_view
from ._model cimport collapsed as _collapsed, denormalize, lsq, score, sq_errors


cdef inline double _det3(double ax, double ay, double bx, double by, double cx, double cy) noexcept nogil:
    """det([a b c]) of homogeneous points (z = 1): twice the signed area of triangle abc."""
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


cdef inline bint _minimal_solve(const double* sn, const double* dn, long long i0, long long i1, long long i2,
                                long long i3, double* H) noexcept nogil:
    """Homography (normalized coordinates) through four correspondences into ``H``, or False (``H`` untouched) for
    a degenerate sample: any triple of the four points collinear in either view (|twice the triangle area| below
    1e-5 in Hartley-normalized coordinates, mean radius sqrt(2)), or the orientation of the four triangles not
    preserved consistently (sign(D_src * D_dst) must be the same for all four triples)."""
    cdef double x0 = sn[2 * i0], y0 = sn[2 * i0 + 1], x1 = sn[2 * i1], y1 = sn[2 * i1 + 1]
    cdef double x2 = sn[2 * i2], y2 = sn[2 * i2 + 1], x3 = sn[2 * i3], y3 = sn[2 * i3 + 1]
    cdef double X0 = dn[2 * i0], Y0 = dn[2 * i0 + 1], X1 = dn[2 * i1], Y1 = dn[2 * i1 + 1]
    cdef double X2 = dn[2 * i2], Y2 = dn[2 * i2 + 1], X3 = dn[2 * i3], Y3 = dn[2 * i3 + 1]
    cdef double s012, s312, s032, s013, d012, d312, d032, d013
    cdef double ls0, ls1, ls2, ld0, ld1, ld2, r0, r1, r2
    cdef double a00, a01, a02, a10, a11, a12, a20, a21, a22
    cdef double b00, b01, b02, b10, b11, b12, b20, b21, b22
    cdef double c00, c01, c02, c10, c11, c12, c20, c21, c22
    cdef double eps = 1e-5
    cdef bint sg
    # source basis: M = [p0 p1 p2], lambda = adj(M) p3 (scale-free), components are triangle determinants
    s012 = _det3(x0, y0, x1, y1, x2, y2)
    s312 = _det3(x3, y3, x1, y1, x2, y2)
    s032 = _det3(x0, y0, x3, y3, x2, y2)
    s013 = _det3(x0, y0, x1, y1, x3, y3)
    if fabs(s012) < eps or fabs(s312) < eps or fabs(s032) < eps or fabs(s013) < eps:
        return False
    d012 = _det3(X0, Y0, X1, Y1, X2, Y2)
    d312 = _det3(X3, Y3, X1, Y1, X2, Y2)
    d032 = _det3(X0, Y0, X3, Y3, X2, Y2)
    d013 = _det3(X0, Y0, X1, Y1, X3, Y3)
    if fabs(d012) < eps or fabs(d312) < eps or fabs(d032) < eps or fabs(d013) < eps:
        return False
    sg = s012 * d012 > 0
    if (s312 * d312 > 0) != sg or (s032 * d032 > 0) != sg or (s013 * d013 > 0) != sg:
        return False
    # lambda_k (up to the common factor 1/det): p3 = sum_k lambda_k p_k, by Cramer's rule
    ls0 = s312 / s012
    ls1 = s032 / s012
    ls2 = s013 / s012
    ld0 = d312 / d012
    ld1 = d032 / d012
    ld2 = d013 / d012
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
    b00 = a00 * r0
    b01 = a01 * r0
    b02 = a02 * r0
    b10 = a10 * r1
    b11 = a11 * r1
    b12 = a12 * r1
    b20 = a20 * r2
    b21 = a21 * r2
    b22 = a22 * r2
    # B_dst columns
    c00 = ld0 * X0
    c01 = ld1 * X1
    c02 = ld2 * X2
    c10 = ld0 * Y0
    c11 = ld1 * Y1
    c12 = ld2 * Y2
    c20 = ld0
    c21 = ld1
    c22 = ld2
    H[0] = c00 * b00 + c01 * b10 + c02 * b20
    H[1] = c00 * b01 + c01 * b11 + c02 * b21
    H[2] = c00 * b02 + c01 * b12 + c02 * b22
    H[3] = c10 * b00 + c11 * b10 + c12 * b20
    H[4] = c10 * b01 + c11 * b11 + c12 * b21
    H[5] = c10 * b02 + c11 * b12 + c12 * b22
    H[6] = c20 * b00 + c21 * b10 + c22 * b20
    H[7] = c20 * b01 + c21 * b11 + c22 * b21
    H[8] = c20 * b02 + c21 * b12 + c22 * b22
    return True


cdef inline bint _refit(const double* src, const double* dst, Py_ssize_t n, const double* H, double t2, double* e2,
                        unsigned char* mask, double* out, double[:, ::1] M, double[:, ::1] L, double[::1] x,
                        double[::1] y, double[::1] scratch) noexcept nogil:
    """Least squares (normalized DLT) on the correspondences within ``sqrt(t2)`` of H into ``out``."""
    cdef Py_ssize_t i
    sq_errors(src, dst, n, H, e2)
    for i in range(n):
        mask[i] = e2[i] <= t2
    return lsq(src, dst, n, mask, out, M, L, x, y, scratch)


cdef inline (double, long long) _local_optimize(const double* src, const double* dst, Py_ssize_t n,
                                                const double* H0, double thr2, double multiplier, Py_ssize_t steps,
                                                double* e2, unsigned char* mask, double* best, double[:, ::1] M,
                                                double[:, ::1] L, double[::1] x, double[::1] y,
                                                double[::1] scratch) noexcept nogil:
    """LO step: least squares on the inliers of H0, then iterative least squares while the threshold shrinks
    from ``multiplier * thr`` to ``thr``. The best among H0 and the refits into ``best``; returns its (MSAC cost,
    inliers)."""
    cdef double H[9]
    cdef double Hl[9]
    cdef double best_cost, cost, f
    cdef long long best_cnt, cnt, seen
    cdef int status, k, rep
    cdef Py_ssize_t s, last = steps - 1 if steps - 1 > 1 else 1
    cdef bint ok
    for k in range(9):
        best[k] = H0[k]
        H[k] = H0[k]
    best_cost, best_cnt, seen, status = score(src, dst, n, H0, thr2, INFINITY, INFINITY, 0.5, 0.25)
    for rep in range(2):
        if not _refit(src, dst, n, H, thr2, e2, mask, Hl, M, L, x, y, scratch):
            break
        for k in range(9):
            H[k] = Hl[k]
        for s in range(steps):
            f = multiplier - (multiplier - 1.0) * <double>s / <double>last
            if not _refit(src, dst, n, H, thr2 * f * f, e2, mask, Hl, M, L, x, y, scratch):
                break
            for k in range(9):
                H[k] = Hl[k]
        cost, cnt, seen, status = score(src, dst, n, H, thr2, INFINITY, INFINITY, 0.5, 0.25)
        if cost < best_cost:
            best_cost = cost
            best_cnt = cnt
            for k in range(9):
                best[k] = H[k]
        else:
            break
    return best_cost, best_cnt


def minimal_solve(const double[:, ::1] sn, const double[:, ::1] dn, long long i0, long long i1, long long i2,
                  long long i3, double[:, ::1] H):
    """Homography (normalized coordinates) through the four correspondences ``i0..i3`` of ``sn``, ``dn`` into
    ``H``; False for a degenerate sample."""
    return _minimal_solve(&sn[0, 0], &dn[0, 0], i0, i1, i2, i3, &H[0, 0])


def collapsed(const double[:, ::1] Hn):
    """True when the normalized model (3, 3) is nearly singular."""
    return _collapsed(&Hn[0, 0])


def rows_in_order(const long long[::1] order, const double[:, ::1] a, const double[:, ::1] b,
                  const double[:, ::1] c, const double[:, ::1] d):
    """``np.stack([a[order], b[order], c[order], d[order]])`` of four (N, 2) arrays in one pass: (4, len(order), 2)."""
    cdef Py_ssize_t n = order.shape[0], i
    cdef long long j
    out = np.empty((4, n, 2))
    cdef double[:, :, ::1] o = out
    with nogil:
        for i in range(n):
            j = order[i]
            o[0, i, 0] = a[j, 0]
            o[0, i, 1] = a[j, 1]
            o[1, i, 0] = b[j, 0]
            o[1, i, 1] = b[j, 1]
            o[2, i, 0] = c[j, 0]
            o[2, i, 1] = c[j, 1]
            o[3, i, 0] = d[j, 0]
            o[3, i, 1] = d[j, 1]
    return out


def ransac_chunk(const double[:, :, ::1] pts, const double[:, ::1] Ts, const double[:, ::1] Tdi,
                 const double[:, ::1] Tsi, const double[:, ::1] Td, const double[:, ::1] u, double thr2,
                 double log1mconf, double max_iters, bint lo, double lo_multiplier, Py_ssize_t lo_steps,
                 double[:, ::1] best_H, state):
    """Run hypotheses from the uniforms ``u`` (K, 4) until the adaptive bound is met or ``u`` runs out.

    ``pts`` (4, N, 2): the source points, the destination points and both Hartley-normalized (``Ts``, ``Td``, with
    the inverses ``Tsi``, ``Tdi``), in the order of verification. ``state`` (:func:`cvpipe.robust.new_state`) is
    updated in place, as is ``best_H`` (pixel coordinates). Returns the rows used.
    """
    cdef Py_ssize_t n = pts.shape[1], k, used = 0
    cdef Py_ssize_t e2_rows = (n + 8) // 9, mask_rows = (n + 71) // 72
    # one scratch block: the 9x9 normal matrix and its factor, three 9-vectors, the n squared errors, the n-byte mask
    cdef double[:, ::1] work = np.empty((21 + e2_rows + mask_rows, 9))
    cdef double[:, ::1] M = work[0:9], L = work[9:18]
    cdef double[::1] x = work[18], y = work[19], scratch = work[20]
    cdef double* e2 = &work[21, 0]
    cdef unsigned char* mask = <unsigned char*>&work[21 + e2_rows, 0]
    cdef double Hn[9]
    cdef double H[9]
    cdef double Hb[9]
    cdef double tmp[9]
    cdef const double* srcp = &pts[0, 0, 0]
    cdef const double* dstp = &pts[1, 0, 0]
    cdef const double* snp = &pts[2, 0, 0]
    cdef const double* dnp = &pts[3, 0, 0]
    cdef long long i0, i1, i2, i3, cnt, seen, raw_cnt, cnt_b
    cdef double cost, cost_b
    cdef int status, j
    cdef Py_buffer view
    cdef State* s = state_view(state, &view)
    with nogil:
        for k in range(u.shape[0]):
            if s.iterations >= s.bound:
                break
            used += 1
            s.iterations += 1
            i0, i1, i2, i3 = sample4(u, k, n)
            if not _minimal_solve(snp, dnp, i0, i1, i2, i3, Hn) or _collapsed(Hn):
                s.degenerate += 1
                continue
            denormalize(Hn, &Ts[0, 0], &Tdi[0, 0], tmp, H)
            cost, cnt, seen, status = score(srcp, dstp, n, H, thr2, s.best_cost, s.sprt_a, s.sprt_eps,
                                            s.sprt_delta)
            if status != 0 or cost >= s.best_cost:
                if status == 1:
                    on_rejected(s, cnt, seen, n, 4, log1mconf, max_iters)
                continue
            raw_cnt = cnt
            if lo and cnt >= 8:
                cost_b, cnt_b = _local_optimize(srcp, dstp, n, H, thr2, lo_multiplier, lo_steps, e2, mask, Hb, M, L,
                                                x, y, scratch)
                s.lo_runs += 1
                denormalize(Hb, &Tsi[0, 0], &Td[0, 0], tmp, Hn)
                if cost_b < cost and not _collapsed(Hn):
                    for j in range(9):
                        H[j] = Hb[j]
                    cost = cost_b
                    cnt = cnt_b
            for j in range(9):
                best_H[j // 3, j % 3] = H[j]
            on_new_best(s, cost, cnt, raw_cnt, n, 4, log1mconf, max_iters)
    PyBuffer_Release(&view)
    return used
