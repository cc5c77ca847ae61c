# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernels of :mod:`cvpipe.stereo.epipolar` (compute only; the Python module validates and documents).

The Sampson distance and the MSAC cost of a model, the 7-point solver and the scoring of a batch of samples, the
weighted normalized 8-point solve from its accumulated 9x9 normal matrix, the rank-2 projection, the reweighting
rounds of the final refinement and the Hartley normalization. Models are (3, 3) float64 C-contiguous arrays in pixel
coordinates (``x2^T F x1 = 0``) unless named ``Fn`` (Hartley-normalized coordinates, ``F = T2^T Fn T1``); inside
they are row-major ``double*``. ``q`` is the (4, N) array of rows x1, y1, x2, y2 of the correspondences. Masks are
bool (or uint8) arrays. Failures are status codes, never raised.
"""

import numpy as np

from libc.math cimport INFINITY, M_PI, acos, copysign, cos, fabs, isnan, pow, sqrt

from ..homography._eigen cimport jacobi_eigh_ptr, sym6
from ..robust._core cimport sample_distinct

cdef enum:
    # correspondences per block of the MSAC cost: the sum within a block is vectorized, the early exit is tested
    # between blocks
    COST_BLOCK = 64
    # rounds of Sampson-reweighted 8-point refitting of the final model
    REFINE_ROUNDS = 10
    # status of the 8-point solve: solved, fewer than 8 correspondences, rank-deficient normal matrix
    OK = 0
    TOO_FEW = 1
    RANK_DEFICIENT = 2

# smallest 7th pivot / 1st pivot of the eliminated 7x9 epipolar system (normalized coordinates) for a sample to
# count as regular (a repeated or collinear sample has rank below 7)
cdef double RANK_EPS = 1e-9
# a 7-point cubic whose leading coefficient is below this share of its largest one is skipped (F2 is a solution)
cdef double CUBIC_EPS = 1e-10
# the final refit weighs every correspondence by Tukey's biweight with at most this cut-off (in units of the
# threshold), as the homography's final refinement does: real matches have heavier tails than the threshold assumes
cdef double FINAL_WSCALE = 2.0
# ...and within it the cut-off is Tukey's 4.685 sigma (95 % efficiency under Gaussian noise) of the inliers' noise
# scale, ``sigma = 1.4826 * median`` of their Sampson distances. SIFT matches are heavy-tailed (on the Middlebury
# pairs the 90th percentile of the true residuals is 4 sigma, not 1.6), so a cut-off at the noise scale rather
# than at the threshold takes the tail's pull off the fit. ``MIN_C`` keeps it from collapsing on exact data
cdef double TUKEY_C = 4.685
cdef double MAD_TO_SIGMA = 1.4826
cdef double MIN_C = 0.05
# a round of the final refinement that moves the unit null vector of the 8-point system by less than this
# (``1 - |v . v_prev|``, about half the squared angle between them) is the last
cdef double REFINE_TOL = 1e-12

# the values that the Python module uses or documents
_RANK_EPS = RANK_EPS
_FINAL_WSCALE = FINAL_WSCALE
_TUKEY_C = TUKEY_C
_MAD_TO_SIGMA = MAD_TO_SIGMA
_MIN_C = MIN_C
_REFINE_ROUNDS = REFINE_ROUNDS
FM_OK = OK
FM_TOO_FEW = TOO_FEW
FM_RANK_DEFICIENT = RANK_DEFICIENT


# ------------------------------------------------------------------------------------------------------ helpers


cdef inline double pymax(double a, double b) noexcept nogil:
    """``max(a, b)`` as Python evaluates it: ``b`` only when ``b > a`` (``a`` when either is NaN)."""
    return b if b > a else a


cdef inline double pymin(double a, double b) noexcept nogil:
    """``min(a, b)`` as Python evaluates it: ``b`` only when ``b < a``."""
    return b if b < a else a


cdef inline bint lt_nan_last(double a, double b) noexcept nogil:
    """The order of the sorts: ``a < b``, NaN after every number."""
    return a < b or (isnan(b) and not isnan(a))


cdef inline double epi(const double* F, double x, double y, double u, double v, double* den) noexcept nogil:
    """``x2^T F x1`` for x1 = (x, y, 1), x2 = (u, v, 1); ``den``: the squared norm of the first two entries of
    ``F x1`` and of ``F^T x2`` (the Sampson distance is ``|num| / sqrt(den)``). The loops over the correspondences
    pass a local copy of F: then no store of theirs can alias it, and they run on SIMD lanes."""
    cdef double a0 = F[0] * x + F[1] * y + F[2]
    cdef double a1 = F[3] * x + F[4] * y + F[5]
    cdef double a2 = F[6] * x + F[7] * y + F[8]
    cdef double b0 = F[0] * u + F[3] * v + F[6]
    cdef double b1 = F[1] * u + F[4] * v + F[7]
    den[0] = a0 * a0 + a1 * a1 + b0 * b0 + b1 * b1
    return u * a0 + v * a1 + a2


# ------------------------------------------------------------------------------------------ distances and costs


cdef inline double msac_block(const double* F, const double* q, Py_ssize_t n, double thr2, Py_ssize_t start,
                              Py_ssize_t stop, double* buf) noexcept nogil:
    """``sum_i min(d_i^2, thr2)`` for i in [start, stop), d the Sampson distance under F (inf when undefined);
    ``buf``: scratch of at least ``COST_BLOCK``.

    The terms go to ``buf`` in one loop that the compiler runs on SIMD lanes, then they are added in four
    interleaved partial sums in a fixed order: the sum is the same on every CPU. ``den`` is a sum of squares, so
    where it is not positive it is 0 or NaN, the quotient is inf or NaN and the term is ``thr2``, as for an
    undefined distance: no test of ``den`` is needed (and none keeps the loop off the SIMD lanes)."""
    cdef double f00 = F[0], f01 = F[1], f02 = F[2], f10 = F[3], f11 = F[4], f12 = F[5]
    cdef double f20 = F[6], f21 = F[7], f22 = F[8]
    cdef const double* x1 = q
    cdef const double* y1 = q + n
    cdef const double* x2 = q + 2 * n
    cdef const double* y2 = q + 3 * n
    cdef Py_ssize_t m = stop - start, j, i, full
    cdef double x, y, u, v, a0, a1, a2, b0, b1, num, den, e, c0, c1, c2, c3
    for j in range(m):
        i = start + j
        x = x1[i]
        y = y1[i]
        u = x2[i]
        v = y2[i]
        a0 = f00 * x + f01 * y + f02
        a1 = f10 * x + f11 * y + f12
        a2 = f20 * x + f21 * y + f22
        b0 = f00 * u + f10 * v + f20
        b1 = f01 * u + f11 * v + f21
        num = u * a0 + v * a1 + a2
        den = a0 * a0 + a1 * a1 + b0 * b0 + b1 * b1
        e = num * num / den
        buf[j] = e if e <= thr2 else thr2
    c0 = 0.0
    c1 = 0.0
    c2 = 0.0
    c3 = 0.0
    full = m - m % 4
    for j in range(0, full, 4):
        c0 += buf[j]
        c1 += buf[j + 1]
        c2 += buf[j + 2]
        c3 += buf[j + 3]
    for j in range(full, m):
        c0 += buf[j]
    return (c0 + c1) + (c2 + c3)


cdef inline double msac_from(const double* F, const double* q, Py_ssize_t n, double thr2, Py_ssize_t block,
                             double cost, double bail, double* buf) noexcept nogil:
    """The MSAC cost of F given ``cost``, the sum over the blocks before ``block``; inf as soon as the partial sum
    exceeds ``bail``."""
    cdef Py_ssize_t start = block * COST_BLOCK
    while start < n:
        cost += msac_block(F, q, n, thr2, start, start + COST_BLOCK if start + COST_BLOCK < n else n, buf)
        if cost > bail:
            return INFINITY
        start += COST_BLOCK
    return cost


cdef inline Py_ssize_t count_within_ptr(const double* F, const double* q, Py_ssize_t n, double thr2,
                                        unsigned char* mask) noexcept nogil:
    """``mask[i]``: squared Sampson distance of i under F (inf when undefined) at most ``thr2``; returns the count.

    ``den`` is a sum of squares: where it is not positive the quotient is inf or NaN, within a finite ``thr2`` as
    little as inf is, so below ``thr2 = inf`` the loop tests the quotient alone (on SIMD lanes)."""
    cdef const double* x1 = q
    cdef const double* y1 = q + n
    cdef const double* x2 = q + 2 * n
    cdef const double* y2 = q + 3 * n
    cdef Py_ssize_t i, count = 0
    cdef double num, den, e
    cdef double f[9]
    for i in range(9):
        f[i] = F[i]
    if thr2 < INFINITY:
        for i in range(n):
            num = epi(f, x1[i], y1[i], x2[i], y2[i], &den)
            mask[i] = num * num / den <= thr2
    else:
        for i in range(n):
            num = epi(f, x1[i], y1[i], x2[i], y2[i], &den)
            e = num * num / den if den > 0.0 else INFINITY
            mask[i] = e <= thr2
    for i in range(n):
        count += mask[i]
    return count


# ------------------------------------------------------------------------------------------------ 3x3 algebra


cdef inline void denormalize_ptr(const double* Fn, const double* T1, const double* T2, double* F) noexcept nogil:
    """``F = T2^T Fn T1``."""
    cdef double tmp[9]
    cdef Py_ssize_t i, j
    for i in range(3):
        for j in range(3):
            tmp[3 * i + j] = Fn[3 * i] * T1[j] + Fn[3 * i + 1] * T1[3 + j] + Fn[3 * i + 2] * T1[6 + j]
    for i in range(3):
        for j in range(3):
            F[3 * i + j] = T2[i] * tmp[j] + T2[3 + i] * tmp[3 + j] + T2[6 + i] * tmp[6 + j]


cdef inline void unit_ptr(double* F) noexcept nogil:
    """Scale F in place to unit Frobenius norm with its largest entry (the first in row-major order) positive."""
    cdef double s = 0.0, big = -1.0, sign = 1.0
    cdef Py_ssize_t k
    for k in range(9):
        s += F[k] * F[k]
    s = sqrt(s)
    for k in range(9):
        F[k] /= s
        if fabs(F[k]) > big:
            big = fabs(F[k])
            sign = 1.0 if F[k] >= 0.0 else -1.0
    if sign < 0.0:
        for k in range(9):
            F[k] = -F[k]


cdef inline void rank2(double* F) noexcept nogil:
    """Project F in place onto the closest rank-2 matrix (Frobenius): ``F - F v v^T`` with v the right singular
    vector of the smallest singular value (the eigenvector of ``F^T F`` of its smallest eigenvalue)."""
    cdef double G[9]
    cdef double W[9]
    cdef double ev[3]
    cdef double v0, v1, v2, f
    cdef Py_ssize_t i, j
    for i in range(3):
        for j in range(3):
            G[3 * i + j] = F[i] * F[j] + F[3 + i] * F[3 + j] + F[6 + i] * F[6 + j]
    jacobi_eigh_ptr(G, W, ev, 3)
    v0 = W[0]
    v1 = W[3]
    v2 = W[6]
    for i in range(3):
        f = F[3 * i] * v0 + F[3 * i + 1] * v1 + F[3 * i + 2] * v2
        F[3 * i] -= f * v0
        F[3 * i + 1] -= f * v1
        F[3 * i + 2] -= f * v2


cdef inline bint same3(const double* A, const double* B) noexcept nogil:
    cdef Py_ssize_t k
    for k in range(9):
        if A[k] != B[k]:
            return False
    return True


# ---------------------------------------------------------------------------------------------- 8-point solve


cdef inline bint smallest_warm(const double* M, double* V) noexcept nogil:
    """The eigenvector of the smallest eigenvalue of the symmetric 9x9 ``M`` into column 0 of ``V``, from ``V``
    holding the eigenvectors of a similar matrix (the previous round of a reweighting loop); False when that could
    not be verified (then ``V`` is an orthonormal basis still, and the caller decomposes ``M`` from scratch).

    ``P = V^T M V`` is nearly diagonal; Jacobi rotations in the planes (0, q) only, with the convergence test of
    the full Jacobi solver on row 0, make row 0 of P diagonal, so that the rotated column 0 of V is an eigenvector
    of M (8 rotations per sweep instead of 36). It is the smallest one, and the rank test of the 8-point solve
    passes, when Gershgorin's disc of row 0 lies below the discs of the other rows and these lie above 1e-24 times
    the largest eigenvalue.
    """
    cdef double P[81]
    cdef double tmp[81]
    cdef Py_ssize_t i, j, k, q, sweep
    cdef double t, off, diag, apq, theta, tt, c, s, a0, aq, r0, r, low, high
    cdef bint converged = False
    for i in range(9):
        for j in range(9):
            t = 0.0
            for k in range(9):
                t += M[9 * i + k] * V[9 * k + j]
            tmp[9 * i + j] = t
    for i in range(9):
        for j in range(i, 9):
            t = 0.0
            for k in range(9):
                t += V[9 * k + i] * tmp[9 * k + j]
            P[9 * i + j] = t
            P[9 * j + i] = t
    for sweep in range(20):
        off = 0.0
        for q in range(1, 9):
            off += P[q] * P[q]
        diag = 0.0
        for k in range(9):
            diag += P[10 * k] * P[10 * k]
        if off <= 1e-30 * diag or off == 0.0:
            converged = True
            break
        for q in range(1, 9):
            apq = P[q]
            if apq == 0.0:
                continue
            theta = (P[10 * q] - P[0]) / (2.0 * apq)
            tt = (1.0 if theta >= 0 else -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0))
            c = 1.0 / sqrt(tt * tt + 1.0)
            s = tt * c
            for k in range(9):
                a0 = P[9 * k]
                aq = P[9 * k + q]
                P[9 * k] = c * a0 - s * aq
                P[9 * k + q] = s * a0 + c * aq
            for k in range(9):
                a0 = P[k]
                aq = P[9 * q + k]
                P[k] = c * a0 - s * aq
                P[9 * q + k] = s * a0 + c * aq
            for k in range(9):
                a0 = V[9 * k]
                aq = V[9 * k + q]
                V[9 * k] = c * a0 - s * aq
                V[9 * k + q] = s * a0 + c * aq
    if not converged:
        return False
    r0 = 0.0
    for q in range(1, 9):
        r0 += fabs(P[q])
    low = INFINITY
    high = P[0] + r0
    for k in range(1, 9):
        r = 0.0
        for j in range(9):
            if j != k:
                r += fabs(P[9 * k + j])
        low = pymin(low, P[10 * k] - r)
        high = pymax(high, P[10 * k] + r)
    return P[0] + r0 < low and low > 1e-24 * pymax(high, 1e-300)


cdef inline void normal_sums(const double* P, const double* w2, Py_ssize_t n, double* S) noexcept nogil:
    """``S = w2 @ P`` (P: (n, 36)): 36 sums, each over the correspondences in their order, four at a time (the 36
    advance together as SIMD lanes; no sum is reassociated, so it is the same on every CPU)."""
    cdef Py_ssize_t full = n - n % 4, i, k
    cdef double w0, w1, w2_, w3, w
    cdef const double* p0
    for k in range(36):
        S[k] = 0.0
    for i in range(0, full, 4):
        w0 = w2[i]
        w1 = w2[i + 1]
        w2_ = w2[i + 2]
        w3 = w2[i + 3]
        p0 = P + 36 * i
        for k in range(36):
            S[k] += (p0[k] * w0 + p0[36 + k] * w1) + (p0[72 + k] * w2_ + p0[108 + k] * w3)
    for i in range(full, n):
        w = w2[i]
        p0 = P + 36 * i
        for k in range(36):
            S[k] += p0[k] * w


cdef inline int eight_point_ptr(const double* PT, const double* w2, Py_ssize_t n, Py_ssize_t count, double* Fn,
                                double* V, bint warm) noexcept nogil:
    """Weighted normalized 8-point: ``Fn`` becomes the rank-2 projection of the null vector of ``A^T A``, A the
    rows of ``x2^T F x1`` times the weights, whose squares are ``w2`` (0 for the correspondences left out;
    ``count``: the rows used); ``PT``: (n, 36) from :func:`design_products`. The eigenvectors go to the columns of
    ``V`` (9x9); with ``warm``, ``V`` holds those of a similar system and only the smallest one is refined
    (:func:`smallest_warm`), with the full decomposition when that fails. Returns a status."""
    cdef double S[36]
    cdef double M[81]
    cdef double ev[9]
    cdef Py_ssize_t a, b, c, d, k
    if count < 8:
        return TOO_FEW
    normal_sums(PT, w2, n, S)
    # entry (3a + b, 3c + d) of the 9x9 matrix is sum w^2 x2_a x2_c x1_b x1_d
    for a in range(3):
        for b in range(3):
            for c in range(3):
                for d in range(3):
                    M[9 * (3 * a + b) + 3 * c + d] = S[6 * sym6(a, c) + sym6(b, d)]
    if not (warm and smallest_warm(M, V)):
        jacobi_eigh_ptr(M, V, ev, 9)
        if ev[1] <= 1e-24 * pymax(ev[8], 1e-300):
            return RANK_DEFICIENT
    for k in range(9):
        Fn[k] = V[9 * k]
    rank2(Fn)
    return OK


# ---------------------------------------------------------------------------------------------- 7-point solve


cdef inline bint null2(double* A, double* F1, double* F2) noexcept nogil:
    """An orthonormal basis (F1, F2) of the null space of the 7x9 system A (row-major, overwritten), by
    Gauss-Jordan elimination with full pivoting; False when A has rank below 7 (7th pivot below ``RANK_EPS`` of
    the 1st)."""
    cdef Py_ssize_t perm[9]
    cdef Py_ssize_t r, i, j, k, pi, pj, pt
    cdef double first = 0.0, big, t, inv, f, s, dot
    cdef double* F
    for j in range(9):
        perm[j] = j
    for r in range(7):
        big = 0.0
        pi = r
        pj = r
        for i in range(r, 7):
            for j in range(r, 9):
                if fabs(A[9 * i + j]) > big:
                    big = fabs(A[9 * i + j])
                    pi = i
                    pj = j
        if r == 0:
            first = big
        if not big > RANK_EPS * first or big == 0.0:
            return False
        if pi != r:
            for j in range(9):
                t = A[9 * r + j]
                A[9 * r + j] = A[9 * pi + j]
                A[9 * pi + j] = t
        if pj != r:
            for i in range(7):
                t = A[9 * i + r]
                A[9 * i + r] = A[9 * i + pj]
                A[9 * i + pj] = t
            pt = perm[r]
            perm[r] = perm[pj]
            perm[pj] = pt
        inv = 1.0 / A[9 * r + r]
        for j in range(r, 9):
            A[9 * r + j] *= inv
        for i in range(7):
            if i != r:
                f = A[9 * i + r]
                if f != 0.0:
                    for j in range(r, 9):
                        A[9 * i + j] -= f * A[9 * r + j]
    # A = [I | B] in the permuted columns: null vectors x[perm[7 + k]] = 1 (the other free one 0), x[perm[i]] = -B[i, k]
    for k in range(2):
        F = F1 if k == 0 else F2
        for i in range(7):
            F[perm[i]] = -A[9 * i + 7 + k]
        F[perm[7 + k]] = 1.0
        F[perm[8 - k]] = 0.0
    # Gram-Schmidt: F1 unit, F2 unit and orthogonal to it
    s = 0.0
    for k in range(9):
        s += F1[k] * F1[k]
    s = 1.0 / sqrt(s)
    dot = 0.0
    for k in range(9):
        F1[k] *= s
        dot += F1[k] * F2[k]
    s = 0.0
    for k in range(9):
        F2[k] -= dot * F1[k]
        s += F2[k] * F2[k]
    s = 1.0 / sqrt(s)
    for k in range(9):
        F2[k] *= s
    return True


cdef inline double det3(const double* F) noexcept nogil:
    return (F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6])
            + F[2] * (F[3] * F[7] - F[4] * F[6]))


cdef inline double cof_dot(const double* A, const double* B) noexcept nogil:
    """``sum_ij cof(A)_ij B_ij`` (= trace(adj(A) B)): the coefficient of t in det(A + t B)."""
    return (B[0] * (A[4] * A[8] - A[5] * A[7]) - B[1] * (A[3] * A[8] - A[5] * A[6])
            + B[2] * (A[3] * A[7] - A[4] * A[6]) - B[3] * (A[1] * A[8] - A[2] * A[7])
            + B[4] * (A[0] * A[8] - A[2] * A[6]) - B[5] * (A[0] * A[7] - A[1] * A[6])
            + B[6] * (A[1] * A[5] - A[2] * A[4]) - B[7] * (A[0] * A[5] - A[2] * A[3])
            + B[8] * (A[0] * A[4] - A[1] * A[3]))


cdef inline double polish(double c3, double c2, double c1, double c0, double x) noexcept nogil:
    """Newton steps on c3 x^3 + c2 x^2 + c1 x + c0 from x (the coefficients as given: dividing by a small c3 would
    lose the small roots), each kept only while it lowers |p(x)|."""
    cdef double f = ((c3 * x + c2) * x + c1) * x + c0, fp, xn, fn
    cdef int it
    for it in range(4):
        fp = (3.0 * c3 * x + 2.0 * c2) * x + c1
        if fp == 0.0 or f == 0.0:
            break
        xn = x - f / fp
        fn = ((c3 * xn + c2) * xn + c1) * xn + c0
        if not fabs(fn) < fabs(f):
            break
        x = xn
        f = fn
    return x


cdef inline int cubic_roots(double c3, double c2, double c1, double c0, double* out) noexcept nogil:
    """The real roots of c3 a^3 + c2 a^2 + c1 a + c0 into ``out``, their number (0 when the cubic degenerates:
    ``|c3|`` at most ``CUBIC_EPS`` of the largest coefficient).

    The real root of largest magnitude from the closed form of the monic cubic (Cardano, or the trigonometric form
    for three real roots: accurate for the largest root, not for much smaller ones), refined by Newton on the given
    coefficients; then the quadratic factor of the other two, deflated from the side that keeps it accurate
    (backward from the constant term when the root is the larger one), solved in the stable form. A complex pair
    whose imaginary part is within 1e-8 of its modulus (at least 1) counts as one real (double) root, as for the
    eigenvalues of the companion matrix."""
    cdef double scale = pymax(pymax(pymax(fabs(c3), fabs(c2)), fabs(c1)), fabs(c0))
    cdef double b, c, d, b3, p, q, hq, tp, disc, s, w, A, r, rad, phi, t, ar, q0, q1, q2, dq, re, im, h
    cdef Py_ssize_t m
    if not (scale > 0.0 and fabs(c3) > CUBIC_EPS * scale):
        return 0
    b = c2 / c3
    c = c1 / c3
    d = c0 / c3
    # depressed cubic t^3 + p t + q = 0 with a = t - b / 3
    b3 = b / 3.0
    p = c - b * b3
    q = (2.0 * b3 * b3 - c) * b3 + d
    hq = 0.5 * q
    tp = p / 3.0
    disc = hq * hq + tp * tp * tp
    if disc > 0.0:
        s = sqrt(disc)
        w = -hq - s if hq >= 0.0 else -hq + s  # no cancellation
        A = copysign(pow(fabs(w), 1.0 / 3.0), w)
        r = A + (-tp / A if A != 0.0 else 0.0) - b3
    elif tp == 0.0:  # then q = 0 too: a triple root
        r = -b3
    else:
        rad = 2.0 * sqrt(-tp)
        phi = acos(pymin(1.0, pymax(-1.0, hq / (tp * sqrt(-tp))))) / 3.0
        r = 0.0
        for m in range(3):
            t = rad * cos(phi - 2.0 * M_PI * <double>m / 3.0) - b3
            if m == 0 or fabs(t) > fabs(r):
                r = t
    r = polish(c3, c2, c1, c0, r)
    out[0] = r
    # (a - r)(q2 a^2 + q1 a + q0)
    ar = fabs(r)
    if r != 0.0 and fabs(c3) * (ar * (ar * ar)) >= fabs(c0):  # r is larger than the geometric mean of the others
        q0 = -c0 / r
        q1 = (q0 - c1) / r
        q2 = (q1 - c2) / r
    else:
        q2 = c3
        q1 = c2 + r * q2
        q0 = c1 + r * q1
    if q2 == 0.0:
        return 1
    dq = q1 * q1 - 4.0 * q2 * q0
    if dq < 0.0:
        re = -q1 / (2.0 * q2)
        im = sqrt(-dq) / (2.0 * fabs(q2))
        if im <= 1e-8 * pymax(1.0, sqrt(re * re + im * im)):
            out[1] = polish(c3, c2, c1, c0, re)
            return 2
        return 1
    h = -0.5 * (q1 + copysign(sqrt(dq), q1))
    if h == 0.0:  # q1 = q0 = 0: a double root at 0
        out[1] = 0.0
        return 2
    out[1] = polish(c3, c2, c1, c0, h / q2)
    out[2] = polish(c3, c2, c1, c0, q0 / h)
    return 3


cdef inline int seven_point_ptr(const double* x1n, const double* x2n, const long long* pick,
                                double* Fns) noexcept nogil:
    """The fundamental matrices (normalized coordinates) through the 7 correspondences ``pick`` of the (N, 2)
    points into ``Fns`` (3 row-major 3x3); returns their number, 0 for a degenerate sample.

    The 1 to 3 real roots a of ``det(a F1 + (1 - a) F2) = 0`` over the null space (F1, F2) of the 7x9 system."""
    cdef double A[63]
    cdef double F1[9]
    cdef double F2[9]
    cdef double D[9]
    cdef double roots[3]
    cdef Py_ssize_t r, i, k
    cdef int nr
    cdef double x, y, xp, yp, a
    for r in range(7):
        i = pick[r]
        x = x1n[2 * i]
        y = x1n[2 * i + 1]
        xp = x2n[2 * i]
        yp = x2n[2 * i + 1]
        A[9 * r] = xp * x
        A[9 * r + 1] = xp * y
        A[9 * r + 2] = xp
        A[9 * r + 3] = yp * x
        A[9 * r + 4] = yp * y
        A[9 * r + 5] = yp
        A[9 * r + 6] = x
        A[9 * r + 7] = y
        A[9 * r + 8] = 1.0
    if not null2(A, F1, F2):
        return 0
    for k in range(9):
        D[k] = F1[k] - F2[k]
    # det(a F1 + (1 - a) F2) = det(F2 + a D)
    nr = cubic_roots(det3(D), cof_dot(D, F2), cof_dot(F2, D), det3(F2), roots)
    for r in range(nr):
        a = roots[r]
        for k in range(9):
            Fns[9 * r + k] = F2[k] + a * D[k]
    return nr


cdef void argsort_quick(const double* a, Py_ssize_t n, Py_ssize_t* R) noexcept nogil:
    """The indices that sort ``a[:n]`` (NaN last) into ``R``: quicksort with the median of three, the larger part
    pushed on a stack and insertion sort below 15 elements (the order of equal values is that of this algorithm)."""
    cdef Py_ssize_t stack_lo[100]
    cdef Py_ssize_t stack_hi[100]
    cdef Py_ssize_t top, low, high, mid, i, j, k, t
    cdef double pivot, v
    for i in range(n):
        R[i] = i
    if n < 2:
        return
    stack_lo[0] = 0
    stack_hi[0] = n - 1
    top = 1
    while top > 0:
        top -= 1
        low = stack_lo[top]
        high = stack_hi[top]
        while high - low >= 15:
            # partition around the median of {low, middle, high}
            mid = (low + high) >> 1
            if lt_nan_last(a[R[mid]], a[R[low]]):
                t = R[low]; R[low] = R[mid]; R[mid] = t
            if lt_nan_last(a[R[high]], a[R[mid]]):
                t = R[high]; R[high] = R[mid]; R[mid] = t
            if lt_nan_last(a[R[mid]], a[R[low]]):
                t = R[low]; R[low] = R[mid]; R[mid] = t
            pivot = a[R[mid]]
            t = R[high]; R[high] = R[mid]; R[mid] = t  # the pivot stashed at the end
            i = low
            j = high - 1
            while True:
                while i < high and lt_nan_last(a[R[i]], pivot):
                    i += 1
                while j >= low and lt_nan_last(pivot, a[R[j]]):
                    j -= 1
                if i >= j:
                    break
                t = R[i]; R[i] = R[j]; R[j] = t
                i += 1
                j -= 1
            t = R[i]; R[i] = R[high]; R[high] = t
            # the larger part on the stack, the smaller one partitioned next
            if high - i > i - low:
                if high > i:
                    stack_lo[top] = i + 1
                    stack_hi[top] = high
                    top += 1
                high = i - 1
            else:
                if i > low:
                    stack_lo[top] = low
                    stack_hi[top] = i - 1
                    top += 1
                low = i + 1
        for i in range(low + 1, high + 1):
            k = R[i]
            v = a[k]
            j = i
            while j > low and lt_nan_last(v, a[R[j - 1]]):
                R[j] = R[j - 1]
                j -= 1
            R[j] = k


cdef void argsort_stable(const double* a, Py_ssize_t n, Py_ssize_t* R) noexcept nogil:
    """The indices that sort ``a[:n]`` (NaN last) into ``R``, equal values in index order (insertion sort)."""
    cdef Py_ssize_t i, j, k
    cdef double v
    for i in range(n):
        R[i] = i
    for i in range(1, n):
        k = R[i]
        v = a[k]
        j = i
        while j > 0 and lt_nan_last(v, a[R[j - 1]]):
            R[j] = R[j - 1]
            j -= 1
        R[j] = k


# -------------------------------------------------------------------------------------- final refinement rounds


cdef inline double kth(double* a, Py_ssize_t n, Py_ssize_t k) noexcept nogil:
    """Rearrange ``a[:n]`` so that ``a[k]`` is its k-th smallest value (0-based) with no larger value before it and
    no smaller one after it (Hoare's selection with Wirth's partition); returns ``a[k]``."""
    cdef Py_ssize_t lo = 0, hi = n - 1, i, j
    cdef double pivot, t
    while lo < hi:
        pivot = a[(lo + hi) // 2]
        i = lo
        j = hi
        while i <= j:
            while a[i] < pivot:
                i += 1
            while pivot < a[j]:
                j -= 1
            if i <= j:
                t = a[i]
                a[i] = a[j]
                a[j] = t
                i += 1
                j -= 1
        if j < k:
            lo = i
        if k < i:
            hi = j
    return a[k]


cdef inline double noise_cutoff_ptr(const double* d, Py_ssize_t n, double threshold, double* buf,
                                    bint squared) noexcept nogil:
    """Tukey's cut-off ``TUKEY_C * sigma`` for Sampson distances ``d`` (their squares with ``squared``),
    ``sigma = MAD_TO_SIGMA * median`` of the distances within ``threshold`` (``threshold`` when there are none),
    kept within ``[MIN_C, FINAL_WSCALE]`` times ``threshold``; ``buf``: scratch of n."""
    cdef Py_ssize_t k = 0, i, h
    cdef double t = threshold * threshold if squared else threshold, sigma, med, lower
    for i in range(n):
        if d[i] <= t:
            buf[k] = d[i]
            k += 1
    if k == 0:
        sigma = threshold
    else:
        h = k // 2
        med = kth(buf, k, h)
        if squared:
            med = sqrt(med)
        if k % 2 == 0:  # the mean of the two middle values: the largest of the lower half is the other one
            lower = buf[0]
            for i in range(1, h):
                lower = pymax(lower, buf[i])
            med = ((sqrt(lower) if squared else lower) + med) / 2.0
        sigma = MAD_TO_SIGMA * med
    return pymin(FINAL_WSCALE * threshold, pymax(TUKEY_C * sigma, MIN_C * threshold))


cdef inline bint settled(const double* prev, const double* V) noexcept nogil:
    """True when the unit null vector ``V[:, 0]`` moved by less than ``REFINE_TOL`` from ``prev`` (either sign)."""
    cdef double dot = 0.0
    cdef Py_ssize_t k
    for k in range(9):
        dot += prev[k] * V[9 * k]
    return 1.0 - fabs(dot) <= REFINE_TOL


cdef int refit_ptr(const double* PT, const double* q, Py_ssize_t n, const double* T1, const double* T2,
                   const unsigned char* mask, Py_ssize_t rounds, double* w2, double* F, double* V,
                   bint warm) noexcept nogil:
    """Sampson-reweighted normalized 8-point on ``mask`` (``rounds`` reweightings; ``w2``: scratch of n): F in
    pixel coordinates, unit norm. ``V``, ``warm``: as for :func:`eight_point_ptr`. Returns a status."""
    cdef double Fn[9]
    cdef double prev[9]
    cdef double f[9]
    cdef const double* x1 = q
    cdef const double* y1 = q + n
    cdef const double* x2 = q + 2 * n
    cdef const double* y2 = q + 3 * n
    cdef Py_ssize_t i, k, cnt = 0, it
    cdef int status
    cdef double den
    for i in range(n):
        w2[i] = 1.0 if mask[i] else 0.0
        cnt += mask[i]
    status = eight_point_ptr(PT, w2, n, cnt, Fn, V, warm)
    if status != OK:
        return status
    for it in range(rounds):
        denormalize_ptr(Fn, T1, T2, F)
        # algebraic residual / its gradient norm = Sampson distance: squared weight 1 / den (the normalization
        # changes the algebraic scale by a constant factor only, and a common scale of the weights changes no
        # eigenvector); in three passes that run on SIMD lanes: every correspondence is scored, those off the mask
        # get 0 again
        for k in range(9):
            f[k] = F[k]
        for i in range(n):
            epi(f, x1[i], y1[i], x2[i], y2[i], &den)
            w2[i] = pymax(den, 1e-300)
        for i in range(n):
            w2[i] = 1.0 / w2[i]
        for i in range(n):
            w2[i] = w2[i] if mask[i] else 0.0
        for k in range(9):
            prev[k] = V[9 * k]
        status = eight_point_ptr(PT, w2, n, cnt, Fn, V, True)
        if status != OK:
            return status
        if settled(prev, V):
            break
    denormalize_ptr(Fn, T1, T2, F)
    unit_ptr(F)
    return OK


cdef int refit_robust_ptr(const double* PT, const double* q, Py_ssize_t n, const double* T1, const double* T2,
                          double* F, double threshold, Py_ssize_t rounds, double* d2, double* iden, double* w2,
                          unsigned char* use, double* buf, double* V, bint warm) noexcept nogil:
    """Iteratively reweighted 8-point of F (in place) over every correspondence, weights ``Tukey(d / c) /
    sqrt(den)`` with the cut-off c of :func:`noise_cutoff_ptr` re-estimated each round; stops early when fewer than
    8 fall within it. Works on squared distances and weights (no square root per correspondence). ``d2, iden, w2,
    use, buf``: scratch of n; ``V``, ``warm``: as for :func:`refit_ptr`. Returns a status."""
    cdef double Fn[9]
    cdef double prev[9]
    cdef double f[9]
    cdef const double* x1 = q
    cdef const double* y1 = q + n
    cdef const double* x2 = q + 2 * n
    cdef const double* y2 = q + 3 * n
    cdef Py_ssize_t i, k, cnt, rnd
    cdef int status
    cdef double num, de, r, c, c2, t
    for rnd in range(rounds):
        # d2 = num^2 / den and iden = 1 / den, den at least 1e-300 (in two passes that run on SIMD lanes)
        for k in range(9):
            f[k] = F[k]
        for i in range(n):
            num = epi(f, x1[i], y1[i], x2[i], y2[i], &de)
            d2[i] = num * num
            iden[i] = pymax(de, 1e-300)
        for i in range(n):
            iden[i] = 1.0 / iden[i]
            d2[i] = d2[i] * iden[i]
        # the early stop below tests r > 0 with r the last correspondence's 1 / den (the round number when n = 0):
        # it is tested from the first round on, unless that den is inf or NaN
        r = iden[n - 1] if n > 0 else <double>rnd
        c = noise_cutoff_ptr(d2, n, threshold, buf, True)
        c2 = c * c
        cnt = 0
        for i in range(n):
            use[i] = d2[i] < c2
            cnt += use[i]
        if cnt < 8:
            break
        for i in range(n):
            t = 1.0 - d2[i] / c2
            t *= t
            w2[i] = t * t * iden[i]
        for i in range(n):
            w2[i] = w2[i] if d2[i] < c2 else 0.0  # (a pass of its own runs on SIMD lanes)
        for k in range(9):
            prev[k] = V[9 * k]
        status = eight_point_ptr(PT, w2, n, cnt, Fn, V, warm)
        if status != OK:
            return status
        warm = True
        denormalize_ptr(Fn, T1, T2, F)
        unit_ptr(F)
        if r > 0 and settled(prev, V):
            break
    return OK


cdef int finish(const double* PT, const double* q, Py_ssize_t n, const double* T1, const double* T2, double* F,
                double threshold, Py_ssize_t min_inliers, double* d, double* den, double* w, unsigned char* use,
                double* buf, unsigned char* mask, unsigned char* fresh, double* V) noexcept nogil:
    """The final refinement of one model (F in place): reweighted 8-point refits with inlier re-selection, then the
    robust refit. Returns a status."""
    cdef double thr2 = threshold * threshold
    cdef bint warm = False, same
    cdef int status, it
    cdef Py_ssize_t cnt, i
    count_within_ptr(F, q, n, thr2, mask)
    for it in range(2):  # refit, re-select inliers, refit (the inlier set settles in one or two rounds)
        status = refit_ptr(PT, q, n, T1, T2, mask, REFINE_ROUNDS, w, F, V, warm)
        warm = True
        if status != OK:
            return status
        cnt = count_within_ptr(F, q, n, thr2, fresh)
        same = True
        for i in range(n):
            if fresh[i] != mask[i]:
                same = False
                break
        if cnt < min_inliers or same:
            break
        for i in range(n):
            mask[i] = fresh[i]
    if FINAL_WSCALE > 0:
        return refit_robust_ptr(PT, q, n, T1, T2, F, threshold, REFINE_ROUNDS, d, den, w, use, buf, V, True)
    return OK


# ------------------------------------------------------------------------------------------- Python interface


def sampson_distances(const double[:, :, ::1] Fs, const double[:, ::1] p1, const double[:, ::1] p2,
                      double[:, ::1] out):
    """``out[m, i]``: Sampson distance of correspondence i under ``Fs[m]`` (inf where the gradient vanishes)."""
    cdef Py_ssize_t m, i
    cdef double num, den
    cdef double f[9]
    with nogil:
        for m in range(Fs.shape[0]):
            for i in range(9):
                f[i] = Fs[m, i // 3, i % 3]
            for i in range(p1.shape[0]):
                num = epi(f, p1[i, 0], p1[i, 1], p2[i, 0], p2[i, 1], &den)
                out[m, i] = fabs(num) / sqrt(den) if den > 0.0 else INFINITY


def msac_cost(const double[:, ::1] F, const double[:, ::1] q, double thr2, double bail):
    """``sum_i min(d_i^2, thr2)`` over the Sampson distances d of F (summed by blocks of ``COST_BLOCK``); inf as
    soon as the partial sum exceeds ``bail`` (``bail = inf`` gives the plain cost)."""
    cdef double buf[COST_BLOCK]
    cdef double cost
    with nogil:
        cost = msac_from(&F[0, 0], &q[0, 0], q.shape[1], thr2, 0, 0.0, bail, buf)
    return cost


def count_within(const double[:, ::1] F, const double[:, ::1] q, double thr2, unsigned char[::1] mask):
    """``mask[i]``: squared Sampson distance of i under F at most ``thr2``; returns the count."""
    cdef Py_ssize_t count
    with nogil:
        count = count_within_ptr(&F[0, 0], &q[0, 0], q.shape[1], thr2, &mask[0])
    return count


def denormalize(const double[:, ::1] Fn, const double[:, ::1] T1, const double[:, ::1] T2, double[:, ::1] F):
    """``F = T2^T Fn T1``."""
    denormalize_ptr(&Fn[0, 0], &T1[0, 0], &T2[0, 0], &F[0, 0])


def unit(double[:, ::1] F):
    """Scale F in place to unit Frobenius norm with its largest entry (the first in row-major order) positive."""
    unit_ptr(&F[0, 0])


def design_products(const double[:, ::1] x1n, const double[:, ::1] x2n, double[:, ::1] P):
    """``P[i, 6 a + b] = q_a r_b`` for correspondence i, q = (u^2, uv, u, v^2, v, 1) of x2n = (u, v) and
    r = (x^2, xy, x, y^2, y, 1) of x1n = (x, y): the normal matrix of the 8-point system with squared weights w2 is
    ``w2 @ P``. A row per correspondence, so that the 36 sums advance together."""
    cdef Py_ssize_t i, a
    cdef double x, y, u, v, r0, r1, r3, qa
    with nogil:
        for i in range(x1n.shape[0]):
            x = x1n[i, 0]
            y = x1n[i, 1]
            u = x2n[i, 0]
            v = x2n[i, 1]
            r0 = x * x
            r1 = x * y
            r3 = y * y
            for a in range(6):
                if a == 0:
                    qa = u * u
                elif a == 1:
                    qa = u * v
                elif a == 2:
                    qa = u
                elif a == 3:
                    qa = v * v
                elif a == 4:
                    qa = v
                else:
                    qa = 1.0
                P[i, 6 * a] = qa * r0
                P[i, 6 * a + 1] = qa * r1
                P[i, 6 * a + 2] = qa * x
                P[i, 6 * a + 3] = qa * r3
                P[i, 6 * a + 4] = qa * y
                P[i, 6 * a + 5] = qa


def eight_point_solve(const double[:, ::1] PT, const double[::1] w2, Py_ssize_t count, double[:, ::1] Fn,
                      double[:, ::1] V, bint warm):
    """Weighted normalized 8-point into ``Fn`` (see :func:`eight_point_ptr`); ``PT`` (N, 36), ``w2`` (N,) the
    squared weights, ``V`` (9, 9). Returns a status (``FM_*``)."""
    cdef int status
    with nogil:
        status = eight_point_ptr(&PT[0, 0], &w2[0], w2.shape[0], count, &Fn[0, 0], &V[0, 0], warm)
    return status


def refit(const double[:, ::1] PT, const double[:, ::1] q, const double[:, ::1] T1, const double[:, ::1] T2,
          const unsigned char[::1] mask, Py_ssize_t rounds, double[::1] w2, double[:, ::1] F, double[:, ::1] V,
          bint warm):
    """Sampson-reweighted normalized 8-point on ``mask`` (see :func:`refit_ptr`). Returns a status (``FM_*``)."""
    cdef int status
    with nogil:
        status = refit_ptr(&PT[0, 0], &q[0, 0], q.shape[1], &T1[0, 0], &T2[0, 0], &mask[0], rounds, &w2[0],
                           &F[0, 0], &V[0, 0], warm)
    return status


def seven_point(const double[:, ::1] x1n, const double[:, ::1] x2n, const long long[::1] pick,
                double[:, :, ::1] Fns):
    """The fundamental matrices (normalized coordinates) through the 7 correspondences ``pick`` into ``Fns``
    (3, 3, 3); returns their number, 0 for a degenerate sample."""
    cdef int nr
    with nogil:
        nr = seven_point_ptr(&x1n[0, 0], &x2n[0, 0], &pick[0], &Fns[0, 0, 0])
    return nr


def ransac_batch(const double[:, ::1] u, const double[:, ::1] x1n, const double[:, ::1] x2n,
                 const double[:, ::1] q, const double[:, ::1] T1, const double[:, ::1] T2, double thr2,
                 Py_ssize_t keep, double[:, :, ::1] models, double[::1] costs):
    """Solve (7-point) and score the 7-point samples drawn from the uniforms ``u`` (K, 7).

    Each solution goes to ``models`` in pixel coordinates with its MSAC cost in ``costs``. A model whose partial
    cost already exceeds the ``keep``-th lowest cost of the batch is not finished (cost inf): it cannot be among the
    lowest ``keep``, which is all the caller keeps. To find those early, every model is first scored on the first
    block of correspondences and the models are finished in the order of those partial costs. Returns (models,
    samples that gave a model).
    """
    cdef Py_ssize_t n = q.shape[1], m = 0, regular = 0, k, r, j, t, idx
    cdef long long[::1] pick = np.empty(7, np.int64)
    cdef long long[::1] chosen = np.empty(7, np.int64)
    cdef Py_ssize_t[::1] order = np.empty(models.shape[0], np.intp)
    cdef double[::1] low = np.full(keep, np.inf)  # the lowest costs of the batch so far, ascending
    cdef double Fns[27]
    cdef double buf[COST_BLOCK]
    cdef double* F
    cdef double cost
    cdef int nr
    with nogil:
        for k in range(u.shape[0]):
            sample_distinct(u, k, n, pick, chosen)
            nr = seven_point_ptr(&x1n[0, 0], &x2n[0, 0], &pick[0], Fns)
            if nr == 0:
                continue
            regular += 1
            for r in range(nr):
                F = &models[m, 0, 0]
                denormalize_ptr(&Fns[9 * r], &T1[0, 0], &T2[0, 0], F)
                costs[m] = msac_block(F, &q[0, 0], n, thr2, 0, COST_BLOCK if COST_BLOCK < n else n, buf)
                m += 1
        argsort_quick(&costs[0], m, &order[0])
        for idx in range(m):
            j = order[idx]
            cost = msac_from(&models[j, 0, 0], &q[0, 0], n, thr2, 1, costs[j], low[keep - 1], buf)
            costs[j] = cost
            if cost < low[keep - 1]:
                t = keep - 1
                while t > 0 and low[t - 1] > cost:
                    low[t] = low[t - 1]
                    t -= 1
                low[t] = cost
    return m, regular


def noise_cutoff(const double[::1] d, double threshold, double[::1] buf, bint squared):
    """Tukey's cut-off for Sampson distances ``d`` (see :func:`noise_cutoff_ptr`); ``buf``: scratch of len(d)."""
    cdef double c
    with nogil:
        c = noise_cutoff_ptr(&d[0], d.shape[0], threshold, &buf[0], squared)
    return c


def local_optimize(const double[:, ::1] PT, const double[:, ::1] q, const double[:, ::1] T1,
                   const double[:, ::1] T2, const double[:, ::1] F0, double thr2, double[:, ::1] F):
    """LO of a new so-far-best model: the unweighted 8-point model F of the correspondences within the threshold
    of F0. Returns (ok, MSAC cost of F)."""
    cdef Py_ssize_t n = q.shape[1]
    cdef unsigned char[::1] mask = np.empty(n, np.uint8)
    cdef double[::1] w2 = np.empty(n)
    cdef double V[81]
    cdef double buf[COST_BLOCK]
    cdef double cost = INFINITY
    cdef bint ok = False
    with nogil:
        if count_within_ptr(&F0[0, 0], &q[0, 0], n, thr2, &mask[0]) >= 8:
            if refit_ptr(&PT[0, 0], &q[0, 0], n, &T1[0, 0], &T2[0, 0], &mask[0], 0, &w2[0], &F[0, 0], V,
                         False) == OK:
                ok = True
                cost = msac_from(&F[0, 0], &q[0, 0], n, thr2, 0, 0.0, INFINITY, buf)
    return ok, cost


def final_refinement(const double[:, ::1] PT, const double[:, ::1] q, const double[:, ::1] T1,
                     const double[:, ::1] T2, const double[:, :, ::1] starts, double threshold, double sel2,
                     Py_ssize_t min_inliers, Py_ssize_t quick_rounds, Py_ssize_t full, double[:, ::1] F):
    """The multi-start final refinement: each start gets ``quick_rounds`` robust rounds, the ``full`` lowest of
    those (MSAC cost truncated at ``sel2``; ties in the order of ``starts``) get the whole refinement
    (:func:`finish`), and the lowest cost wins into F. Returns False when every start failed."""
    cdef Py_ssize_t n = q.shape[1], s = starts.shape[0], k, t, i
    cdef double[::1] d = np.empty(n)
    cdef double[::1] den = np.empty(n)
    cdef double[::1] w = np.empty(n)
    cdef double[::1] buf = np.empty(n)
    cdef unsigned char[::1] use = np.empty(n, np.uint8)
    cdef unsigned char[::1] mask = np.empty(n, np.uint8)
    cdef unsigned char[::1] fresh = np.empty(n, np.uint8)
    cdef double[:, :, ::1] quick = np.empty((s, 3, 3))
    cdef double[::1] qcost = np.full(s, np.inf)
    cdef Py_ssize_t[::1] order = np.empty(s, np.intp)
    cdef double V[81]
    cdef double cand[9]
    cdef double cbuf[COST_BLOCK]
    cdef double best = INFINITY, c
    cdef bint found = False
    for k in range(81):
        V[k] = 0.0
    with nogil:
        for k in range(s):
            for i in range(9):
                quick[k, i // 3, i % 3] = starts[k, i // 3, i % 3]
            if refit_robust_ptr(&PT[0, 0], &q[0, 0], n, &T1[0, 0], &T2[0, 0], &quick[k, 0, 0], threshold,
                                quick_rounds, &d[0], &den[0], &w[0], &use[0], &buf[0], V, False) == OK:
                qcost[k] = msac_from(&quick[k, 0, 0], &q[0, 0], n, sel2, 0, 0.0, INFINITY, cbuf)
        argsort_stable(&qcost[0], s, &order[0])
        for t in range(full if full < s else s):
            k = order[t]
            if not qcost[k] < INFINITY:
                break
            if t > 0 and same3(&quick[k, 0, 0], &quick[order[t - 1], 0, 0]):
                continue  # the same start as the previous one (a model that is both a so-far-best and in the pool)
            for i in range(9):
                cand[i] = quick[k, i // 3, i % 3]
            if finish(&PT[0, 0], &q[0, 0], n, &T1[0, 0], &T2[0, 0], cand, threshold, min_inliers, &d[0], &den[0],
                      &w[0], &use[0], &buf[0], &mask[0], &fresh[0], V) != OK:
                continue
            c = msac_from(cand, &q[0, 0], n, sel2, 0, 0.0, INFINITY, cbuf)
            if c < best:
                best = c
                for i in range(9):
                    F[i // 3, i % 3] = cand[i]
                found = True
    return found


def normalize_points(const double[:, ::1] p, double eps, double[:, ::1] T, double[:, ::1] out):
    """Hartley normalization of the (N, 2) points ``p`` in one pass over them: ``T`` (3, 3) moves their centroid to
    the origin and their mean distance to it to sqrt(2), ``out`` (N, 2) gets the normalized points. Returns False,
    and leaves both untouched, when the points are collinear or coincide: the smaller principal axis of the centred
    points is at most ``eps`` times the larger one (the eigenvalue ratio of their 2x2 scatter matrix at most
    eps^2)."""
    cdef Py_ssize_t n = p.shape[0], i
    cdef double cx = 0.0, cy = 0.0, a = 0.0, b = 0.0, c = 0.0, dist = 0.0, x, y, l0, s
    with nogil:
        for i in range(n):
            cx += p[i, 0]
            cy += p[i, 1]
        cx /= <double>n
        cy /= <double>n
        for i in range(n):
            x = p[i, 0] - cx
            y = p[i, 1] - cy
            a += x * x
            b += x * y
            c += y * y
            dist += sqrt(x * x + y * y)
        l0 = 0.5 * (a + c) + sqrt(0.25 * ((a - c) * (a - c)) + b * b)
    if not l0 > 0.0 or a * c - b * b <= eps * eps * l0 * l0:
        return False
    s = sqrt(2.0) / (dist / <double>n)
    T[:, :] = 0.0
    T[0, 0] = s
    T[1, 1] = s
    T[0, 2] = -s * cx
    T[1, 2] = -s * cy
    T[2, 2] = 1.0
    with nogil:
        for i in range(n):
            out[i, 0] = (p[i, 0] - cx) * s
            out[i, 1] = (p[i, 1] - cy) * s
    return True
