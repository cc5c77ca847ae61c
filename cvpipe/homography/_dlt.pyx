# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernels of the homography estimator: reprojection errors, Hartley normalization, the normalized DLT's
null vector and the final Levenberg-Marquardt refinement (compute only; :mod:`cvpipe.homography.estimate` and
:mod:`cvpipe.homography.dlt` validate)."""

import numpy as np

from libc.math cimport fabs, isfinite, sqrt, INFINITY

from .._cholesky cimport cholesky_factor, cholesky_substitute
from ._model cimport denormalize as _denormalize, hartley, hartley2, null_vector as _null_vector, scale_to_h22, similarity
from ._model cimport sq_error, sq_errors as _sq_errors


def normalize(const double[:, ::1] p, double collinear_eps):
    """Hartley normalization in one pass: (T (3, 3), normalized points (N, 2), not_collinear).

    ``not_collinear`` is False when the smaller principal axis of the points is below ``collinear_eps`` times the
    larger one (from the 2x2 covariance: ratio of eigenvalues <= eps^2), or all points coincide.
    """
    cdef Py_ssize_t n, i
    cdef double cx, cy, s, a = 0.0, b = 0.0, c = 0.0, x, y, l1, det
    n, cx, cy, s = hartley(&p[0, 0], p.shape[0], NULL)
    T_arr = np.empty((3, 3))
    out_arr = np.empty((n, 2))
    cdef double[:, ::1] T = T_arr, out = out_arr
    similarity(1.0, 0.0, 0.0, &T[0, 0])
    if not s < INFINITY:
        return T_arr, out_arr, False
    with nogil:
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
        l1 = 0.5 * (a + c) + sqrt(0.25 * ((a - c) * (a - c)) + b * b)
        det = a * c - b * b
    return T_arr, out_arr, det > (collinear_eps * collinear_eps) * l1 * l1


def sq_errors(const double[:, ::1] src, const double[:, ::1] dst, const double[:, ::1] H, double[::1] out):
    """Squared one-sided reprojection error per correspondence into ``out`` (inf when mapped to infinity);
    returns ``out``."""
    if src.shape[0]:
        with nogil:
            _sq_errors(&src[0, 0], &dst[0, 0], src.shape[0], &H[0, 0], &out[0])
    return out.base


def denormalize(const double[:, ::1] Hn, const double[:, ::1] Ts, const double[:, ::1] Tdi, double[:, ::1] out):
    """``out = Tdi @ Hn @ Ts`` (3x3)."""
    cdef double tmp[9]
    _denormalize(&Hn[0, 0], &Ts[0, 0], &Tdi[0, 0], tmp, &out[0, 0])


def null_vector(const double[:, ::1] M, double[::1] h):
    """The unit eigenvector of the smallest eigenvalue of the symmetric positive semi-definite ``M`` into ``h``
    by inverse iteration; True when it settled (the smallest eigenvalue is simple)."""
    cdef Py_ssize_t n = M.shape[0]
    cdef double[:, ::1] L = np.empty((n, n))
    cdef double[:, ::1] vecs = np.empty((3, n))
    cdef bint ok
    with nogil:
        ok = _null_vector(M, &h[0], L, vecs[0], vecs[1], vecs[2])
    return ok


cdef inline double _lm_cost(const double* p, const double* xs, const double* ys, const double* us, const double* vs,
                            const double* ws, Py_ssize_t n) noexcept nogil:
    """Weighted sum of squared one-sided reprojection errors of the 8-parameter homography p (H[2, 2] = 1)."""
    cdef double H[9]
    cdef double c = 0.0, e2
    cdef Py_ssize_t i
    cdef int k
    for k in range(8):
        H[k] = p[k]
    H[8] = 1.0
    for i in range(n):
        e2 = sq_error(H, xs[i], ys[i], us[i], vs[i])
        if e2 == INFINITY:
            return INFINITY
        c += ws[i] * e2
    return c


cdef double _lm_refine(const double* src, const double* dst, Py_ssize_t n_all, const double* weight,
                       const double* H0, int max_iter, double* H, unsigned char* used, double* buf,
                       double[:, ::1] A, double[:, ::1] L, double[:, ::1] vecs) noexcept nogil:
    """Levenberg-Marquardt on the weighted one-sided reprojection error sum_i weight_i * |dehom(H src_i) - dst_i|^2
    into ``H``; returns the weighted sum of squared errors in pixels^2.

    Correspondences with weight 0 are ignored. Works in Hartley-normalized coordinates (isotropic scaling of dst,
    so the objective is the pixel one up to a constant) with 8 parameters (H[2, 2] = 1 there). ``used`` (n_all),
    ``buf`` (5 n_all), ``A``, ``L`` (8 x 8) and ``vecs`` (3, 8) are scratch.
    """
    cdef Py_ssize_t n, i, j = 0
    cdef double cx, cy, ss, cX, cY, sd, c, cost, cn, lam, rel, x, y, w, iw, uu, vv, ru, rv
    cdef double g0, g1, g2, g6, g7, h6, h7, wi
    cdef double j00, j01, j02, j11, j12, j22, j06, j07, j16, j17, j26, j27, j36, j37, j46, j47, j56, j57
    cdef double j66, j67, j77
    cdef double t0, t1, t2, t3, t4, t5, t6, t7
    cdef double Ts[9]
    cdef double Tsi[9]
    cdef double Td[9]
    cdef double Tdi[9]
    cdef double tmp[9]
    cdef double Hn[9]
    cdef double p[8]
    cdef double pn[8]
    cdef double Jtr[8]
    cdef double JtJ[64]
    cdef double[::1] negJtr = vecs[0], delta = vecs[1], scratch = vecs[2]
    cdef double* xs = buf
    cdef double* ys = buf + n_all
    cdef double* us = buf + 2 * n_all
    cdef double* vs = buf + 3 * n_all
    cdef double* ws = buf + 4 * n_all
    cdef int it, attempt, a, b, k
    cdef bint improved
    for i in range(n_all):
        used[i] = weight[i] > 0.0
    n, cx, cy, ss, cX, cY, sd = hartley2(src, dst, n_all, used)
    for i in range(n_all):
        if weight[i] > 0.0:
            xs[j] = (src[2 * i] - cx) * ss
            ys[j] = (src[2 * i + 1] - cy) * ss
            us[j] = (dst[2 * i] - cX) * sd
            vs[j] = (dst[2 * i + 1] - cY) * sd
            ws[j] = weight[i]
            j += 1
    similarity(ss, -ss * cx, -ss * cy, Ts)
    similarity(1.0 / ss, cx, cy, Tsi)
    similarity(sd, -sd * cX, -sd * cY, Td)
    similarity(1.0 / sd, cX, cY, Tdi)
    _denormalize(H0, Tsi, Td, tmp, Hn)
    if fabs(Hn[8]) < 1e-12:
        c = 0.0
        for i in range(n_all):
            if weight[i] > 0.0:
                c += weight[i] * sq_error(H0, src[2 * i], src[2 * i + 1], dst[2 * i], dst[2 * i + 1])
        for k in range(9):
            H[k] = H0[k]
        return c
    scale_to_h22(Hn)
    for k in range(8):
        p[k] = Hn[k]
    cost = _lm_cost(p, xs, ys, us, vs, ws, n)
    lam = 1e-3
    rel = 0.0
    for it in range(max_iter):
        t0 = t1 = t2 = t3 = t4 = t5 = t6 = t7 = 0.0
        j00 = j01 = j02 = j11 = j12 = j22 = 0.0
        j06 = j07 = j16 = j17 = j26 = j27 = j36 = j37 = j46 = j47 = j56 = j57 = 0.0
        j66 = j67 = j77 = 0.0
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
            t0 += wi * (g0 * ru)
            t1 += wi * (g1 * ru)
            t2 += wi * (g2 * ru)
            t3 += wi * (g0 * rv)
            t4 += wi * (g1 * rv)
            t5 += wi * (g2 * rv)
            t6 += wi * (g6 * ru + h6 * rv)
            t7 += wi * (g7 * ru + h7 * rv)
            # the upper-left and the middle 3 x 3 blocks are the same sums (g0..g2 equal h3..h5)
            j00 += wi * (g0 * g0)
            j01 += wi * (g0 * g1)
            j02 += wi * (g0 * g2)
            j11 += wi * (g1 * g1)
            j12 += wi * (g1 * g2)
            j22 += wi * (g2 * g2)
            j06 += wi * (g0 * g6)
            j07 += wi * (g0 * g7)
            j16 += wi * (g1 * g6)
            j17 += wi * (g1 * g7)
            j26 += wi * (g2 * g6)
            j27 += wi * (g2 * g7)
            j36 += wi * (g0 * h6)
            j37 += wi * (g0 * h7)
            j46 += wi * (g1 * h6)
            j47 += wi * (g1 * h7)
            j56 += wi * (g2 * h6)
            j57 += wi * (g2 * h7)
            j66 += wi * (g6 * g6 + h6 * h6)
            j67 += wi * (g6 * g7 + h6 * h7)
            j77 += wi * (g7 * g7 + h7 * h7)
        Jtr[0] = t0
        Jtr[1] = t1
        Jtr[2] = t2
        Jtr[3] = t3
        Jtr[4] = t4
        Jtr[5] = t5
        Jtr[6] = t6
        Jtr[7] = t7
        for k in range(64):
            JtJ[k] = 0.0
        JtJ[0] = j00
        JtJ[1] = j01
        JtJ[2] = j02
        JtJ[9] = j11
        JtJ[10] = j12
        JtJ[18] = j22
        JtJ[6] = j06
        JtJ[7] = j07
        JtJ[14] = j16
        JtJ[15] = j17
        JtJ[22] = j26
        JtJ[23] = j27
        JtJ[30] = j36
        JtJ[31] = j37
        JtJ[38] = j46
        JtJ[39] = j47
        JtJ[46] = j56
        JtJ[47] = j57
        JtJ[54] = j66
        JtJ[55] = j67
        JtJ[63] = j77
        for a in range(3):
            for b in range(a, 3):
                JtJ[8 * (3 + a) + 3 + b] = JtJ[8 * a + b]
        for a in range(8):
            for b in range(a):
                JtJ[8 * a + b] = JtJ[8 * b + a]
        improved = False
        for attempt in range(10):
            for a in range(8):
                for b in range(8):
                    A[a, b] = JtJ[8 * a + b]
            for a in range(8):
                A[a, a] += lam * (JtJ[9 * a] + 1e-12)
            for a in range(8):
                negJtr[a] = -Jtr[a]
            if not cholesky_factor(A, L, 0.0):
                lam *= 10.0
                continue
            cholesky_substitute(L, negJtr, delta, scratch)
            for k in range(8):
                pn[k] = p[k] + delta[k]
            cn = _lm_cost(pn, xs, ys, us, vs, ws, n)
            if cn < cost:
                rel = (cost - cn) / (1e-300 if 1e-300 > cost else cost)
                for k in range(8):
                    p[k] = pn[k]
                cost = cn
                lam = lam * 0.1
                if 1e-12 > lam:
                    lam = 1e-12
                improved = True
                break
            lam *= 10.0
        if not improved or rel < 1e-9:
            break
    for k in range(8):
        Hn[k] = p[k]
    Hn[8] = 1.0
    _denormalize(Hn, Ts, Tdi, tmp, H)
    scale_to_h22(H)
    return cost / (sd * sd)


# the final refinement's loss is Tukey's biweight; hard inliers and a Cauchy-like loss were measured and rejected
# (docs/notes/homography.md: the final refinement paragraph)
def finalize(const double[:, ::1] src, const double[:, ::1] dst, const double[:, ::1] H0, double thr2, bint refine,
             int rounds, double wthr2):
    """Inliers of H0 and, with ``refine``, up to ``rounds`` of weighted Levenberg-Marquardt (Tukey's biweight
    ``(1 - e2 / wthr2)^2`` within ``wthr2``, 0 beyond, from the residuals of the previous round). Returns (H (3, 3),
    inlier mask (N,) bool, squared errors (N,))."""
    cdef Py_ssize_t n = src.shape[0], i, cnt = 0, cnt_r, used
    e2_arr = np.empty(n)
    mask_arr = np.empty(n, np.bool_)
    H_arr = np.empty((3, 3))
    cdef double[::1] e2 = e2_arr
    cdef unsigned char[::1] mask = mask_arr
    cdef double[:, ::1] H = H_arr
    cdef double[::1] w, e2r, buf
    cdef unsigned char[::1] use
    cdef double[:, :, ::1] mats
    cdef double[:, ::1] vecs
    cdef double Hr[9]
    cdef double r
    cdef bint finite
    cdef int rnd, k
    with nogil:
        _sq_errors(&src[0, 0], &dst[0, 0], n, &H0[0, 0], &e2[0])
        for i in range(n):
            mask[i] = e2[i] <= thr2
            cnt += mask[i]
        for k in range(9):
            H[k // 3, k % 3] = H0[k // 3, k % 3]
    if not refine or cnt < 4:
        return H_arr, mask_arr, e2_arr
    w = np.empty(n)
    e2r = np.empty(n)
    buf = np.empty(5 * n)
    use = np.empty(n, np.uint8)
    mats = np.empty((2, 8, 8))
    vecs = np.empty((3, 8))
    with nogil:
        for rnd in range(rounds):
            used = 0
            for i in range(n):  # the weight computed beyond the cut-off too, then zeroed: the loop vectorizes
                r = 1.0 - e2[i] / wthr2
                w[i] = r * r
                if e2[i] > wthr2:
                    w[i] = 0.0
            for i in range(n):
                used += w[i] > 0.0
            if used < 4:
                break
            _lm_refine(&src[0, 0], &dst[0, 0], n, &w[0], &H[0, 0], 30, Hr, &use[0], &buf[0], mats[0], mats[1],
                       vecs)
            finite = True
            for k in range(9):
                finite = finite and isfinite(Hr[k])
            if not finite:
                break
            _sq_errors(&src[0, 0], &dst[0, 0], n, Hr, &e2r[0])
            cnt_r = 0
            for i in range(n):
                cnt_r += e2r[i] <= thr2
            if cnt_r < 4:
                break
            for k in range(9):
                H[k // 3, k % 3] = Hr[k]
            for i in range(n):
                e2[i] = e2r[i]
                mask[i] = e2r[i] <= thr2
    return H_arr, mask_arr, e2_arr
