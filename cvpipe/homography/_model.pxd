# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The homography model as inline C shared by the compiled modules of this package: reprojection errors, MSAC
scoring with the SPRT, Hartley normalization, the normalized DLT by inverse iteration and the degeneracy test.

Points are (N, 2) float64 C-contiguous arrays passed as ``const double*`` (x of point i at ``2 i``, y at
``2 i + 1``); 3x3 matrices are row-major ``double*``; masks are ``unsigned char`` (numpy bool viewed as uint8).
"""

from libc.math cimport fabs, pow, sqrt, INFINITY

from .._cholesky cimport cholesky_factor, cholesky_substitute
from ._eigen cimport jacobi_eigh_ptr, sym6


cdef inline void matmul3(const double* A, const double* B, double* out) noexcept nogil:
    """``out = A @ B`` (3x3)."""
    cdef int i, j
    for i in range(3):
        for j in range(3):
            out[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j]


cdef inline void denormalize(const double* Hn, const double* Ts, const double* Tdi, double* tmp,
                             double* out) noexcept nogil:
    """``out = Tdi @ Hn @ Ts`` (``tmp``: 3x3 scratch): a model between normalized coordinates back in pixels (or,
    given ``Tsi`` and ``Td``, a pixel model in normalized coordinates)."""
    matmul3(Hn, Ts, tmp)
    matmul3(Tdi, tmp, out)


cdef inline void similarity(double s, double tx, double ty, double* T) noexcept nogil:
    """``T = [[s, 0, tx], [0, s, ty], [0, 0, 1]]``."""
    T[0] = s
    T[1] = 0.0
    T[2] = tx
    T[3] = 0.0
    T[4] = s
    T[5] = ty
    T[6] = 0.0
    T[7] = 0.0
    T[8] = 1.0


cdef inline void scale_to_h22(double* H) noexcept nogil:
    """``H /= H[2, 2]`` unless ``H[2, 2]`` is 0."""
    cdef double d = H[8]
    cdef int k
    if d != 0.0:
        for k in range(9):
            H[k] = H[k] / d


cdef inline double sq_error(const double* H, double x, double y, double u, double v) noexcept nogil:
    """Squared one-sided reprojection error ``|| dehom(H [x, y, 1]) - (u, v) ||^2`` (inf when mapped to
    infinity)."""
    cdef double w = H[6] * x + H[7] * y + H[8]
    cdef double du, dv
    if w == 0.0:
        return INFINITY
    du = (H[0] * x + H[1] * y + H[2]) / w - u
    dv = (H[3] * x + H[4] * y + H[5]) / w - v
    return du * du + dv * dv


cdef inline void sq_errors(const double* src, const double* dst, Py_ssize_t n, const double* H,
                           double* out) noexcept nogil:
    """Squared one-sided reprojection error per correspondence into ``out``: :func:`sq_error`, with the error
    computed for ``w = 0`` too and then replaced by inf (a conditional store: the loop vectorizes)."""
    cdef Py_ssize_t i
    cdef double h0 = H[0], h1 = H[1], h2 = H[2], h3 = H[3], h4 = H[4], h5 = H[5], h6 = H[6], h7 = H[7], h8 = H[8]
    cdef double x, y, w, du, dv
    for i in range(n):
        x = src[2 * i]
        y = src[2 * i + 1]
        w = h6 * x + h7 * y + h8
        du = (h0 * x + h1 * y + h2) / w - dst[2 * i]
        dv = (h3 * x + h4 * y + h5) / w - dst[2 * i + 1]
        out[i] = du * du + dv * dv
        if w == 0.0:
            out[i] = INFINITY


cdef inline (double, long long, long long, int) score(const double* src, const double* dst, Py_ssize_t n,
                                                      const double* H, double thr2, double bail, double A,
                                                      double eps, double delta) noexcept nogil:
    """Evaluate H point by point: (MSAC cost, inliers so far, points evaluated, status).

    status 0: all points evaluated; 1: rejected by the SPRT (likelihood ratio above A); 2: the MSAC cost already
    exceeds ``bail`` (the best cost so far), so H cannot win. With ``bail = A = inf``: the plain MSAC cost.
    """
    cdef double up = delta / eps
    cdef double down = (1.0 - delta) / (1.0 - eps)
    cdef double lam = 1.0, cost = 0.0, e2, w, du, dv, x, y
    cdef double h0 = H[0], h1 = H[1], h2 = H[2], h3 = H[3], h4 = H[4], h5 = H[5], h6 = H[6], h7 = H[7], h8 = H[8]
    cdef long long cnt = 0
    cdef Py_ssize_t i
    for i in range(n):
        x = src[2 * i]
        y = src[2 * i + 1]
        w = h6 * x + h7 * y + h8
        if w == 0.0:
            e2 = INFINITY
        else:
            du = (h0 * x + h1 * y + h2) / w - dst[2 * i]
            dv = (h3 * x + h4 * y + h5) / w - dst[2 * i + 1]
            e2 = du * du + dv * dv
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


cdef inline (Py_ssize_t, double, double, double) hartley(const double* p, Py_ssize_t n_all,
                                                         const unsigned char* mask) noexcept nogil:
    """Hartley normalization of the points ``p[mask]`` (all of them for a NULL mask): (count, centroid x,
    centroid y, scale).

    The scale sqrt(2) / mean distance to the centroid moves the mean distance to sqrt(2); it is ``inf`` when the
    points coincide. The normalized point is ``((x - cx) * s, (y - cy) * s)``.
    """
    cdef Py_ssize_t i, n = 0
    cdef double cx = 0.0, cy = 0.0, d = 0.0, dx, dy
    for i in range(n_all):
        if mask == NULL or mask[i]:
            n += 1
            cx += p[2 * i]
            cy += p[2 * i + 1]
    cx = cx / <double>n
    cy = cy / <double>n
    for i in range(n_all):
        if mask == NULL or mask[i]:
            dx = p[2 * i] - cx
            dy = p[2 * i + 1] - cy
            d += sqrt(dx * dx + dy * dy)
    return n, cx, cy, sqrt(2.0) * <double>n / d


cdef inline (Py_ssize_t, double, double, double, double, double, double) hartley2(
        const double* src, const double* dst, Py_ssize_t n_all, const unsigned char* mask) noexcept nogil:
    """:func:`hartley` of ``src[mask]`` and of ``dst[mask]`` in the same two passes over the mask: (count, src
    centroid x, y, src scale, dst centroid x, y, dst scale). Each sum adds the same terms in the same order as
    :func:`hartley`."""
    cdef Py_ssize_t i, n = 0
    cdef double cx = 0.0, cy = 0.0, cX = 0.0, cY = 0.0, d = 0.0, D = 0.0, dx, dy
    for i in range(n_all):
        if mask[i]:
            n += 1
            cx += src[2 * i]
            cy += src[2 * i + 1]
            cX += dst[2 * i]
            cY += dst[2 * i + 1]
    cx = cx / <double>n
    cy = cy / <double>n
    cX = cX / <double>n
    cY = cY / <double>n
    for i in range(n_all):
        if mask[i]:
            dx = src[2 * i] - cx
            dy = src[2 * i + 1] - cy
            d += sqrt(dx * dx + dy * dy)
            dx = dst[2 * i] - cX
            dy = dst[2 * i + 1] - cY
            D += sqrt(dx * dx + dy * dy)
    return n, cx, cy, sqrt(2.0) * <double>n / d, cX, cY, sqrt(2.0) * <double>n / D


cdef inline bint collapsed(const double* Hn) noexcept nogil:
    """True when the normalized model is nearly singular: ``|det(Hn)| < 2e-4 ||Hn||_F^3`` (identity: 0.19; a mark
    covering a tenth of the scene's width: ~5e-3). Below it H nearly collapses the source onto a line or a point,
    where a cluster of many-to-one matches scores as exact "inliers" and wins the MSAC cost (seen with ORB on
    repetitive PCB texture: 24 source points matched to one scene point gave models at 3e-5 to 8e-5, and 1e-8)."""
    cdef double det = (Hn[0] * (Hn[4] * Hn[8] - Hn[5] * Hn[7])
                       - Hn[1] * (Hn[3] * Hn[8] - Hn[5] * Hn[6])
                       + Hn[2] * (Hn[3] * Hn[7] - Hn[4] * Hn[6]))
    cdef double norm2 = 0.0, a, t
    cdef int k
    for k in range(9):
        norm2 += Hn[k] * Hn[k]
    a = fabs(det)
    if 1e-100 < norm2 and norm2 < 1e100:
        # norm2 * sqrt(norm2) and pow(norm2, 1.5) (both within 1 ulp of norm2^1.5, and far from underflow and
        # overflow here) differ by less than 1e-15 relatively: outside a band of 1e-12 around the bound the cheap
        # product decides as the power would
        t = 2e-4 * (norm2 * sqrt(norm2))
        if a > t * (1.0 + 1e-12):
            return False
        if a < t * (1.0 - 1e-12):
            return True
    return not a >= 2e-4 * pow(norm2, 1.5)


cdef inline bint null_vector(const double[:, ::1] M, double* h, double[:, ::1] L, double[::1] x, double[::1] y,
                             double[::1] scratch) noexcept nogil:
    """The unit eigenvector of the smallest eigenvalue of the symmetric positive semi-definite ``M`` (n x n) into
    ``h``, by inverse iteration with the Cholesky factor of ``M + sigma I`` (``sigma = 1e-12 trace M``); True when
    the iterates settled (a step moved them by less than 1e-13) within 40 steps.

    The iterates approach the eigenvector by the factor ``(w0 + sigma) / (w1 + sigma)`` a step (``w0 <= w1`` the two
    smallest eigenvalues), so settling means ``w1 > sigma > 1e-14 w_max``: the smallest eigenvalue is simple, as
    :func:`lsq` requires. False (the factor is close to 1, or ``M`` is not positive semi-definite): the caller
    decides with the Jacobi solver. ``L`` (n x n), ``x``, ``y``, ``scratch`` (n) are scratch.
    """
    cdef Py_ssize_t n = M.shape[0], i, step
    cdef double tr = 0.0, norm, dot, scale, change, yi, dv
    for i in range(n):
        tr += M[i, i]
    if not (tr > 0.0 and tr < INFINITY):
        return False
    if not cholesky_factor(M, L, 1e-12 * tr):
        return False
    for i in range(n):  # a fixed start with no special direction
        x[i] = 1.0 / (i + 1.0)
    for step in range(40):
        cholesky_substitute(L, x, y, scratch)
        norm = 0.0
        dot = 0.0
        for i in range(n):
            norm += y[i] * y[i]
            dot += y[i] * x[i]
        scale = (1.0 if dot >= 0.0 else -1.0) / sqrt(norm)
        change = 0.0
        for i in range(n):
            yi = y[i] * scale
            dv = fabs(yi - x[i])
            if dv > change:
                change = dv
            x[i] = yi
        if change < 1e-13 and step > 0:
            for i in range(n):
                h[i] = x[i]
            return True
    return False


cdef inline bint lsq(const double* src, const double* dst, Py_ssize_t n_all, const unsigned char* mask, double* H,
                     double[:, ::1] M, double[:, ::1] L, double[::1] x, double[::1] y,
                     double[::1] scratch) noexcept nogil:
    """Hartley-normalized DLT on the masked correspondences via the 9x9 normal matrix into ``H`` (scaled to
    ``H[2, 2] = 1`` unless that is 0); False (``H`` undefined) for fewer than 4 points, coincident points or a
    smallest eigenvalue that is not simple. ``M``, ``L`` (9 x 9), ``x``, ``y``, ``scratch`` (9) are scratch."""
    cdef Py_ssize_t n, i, a, b, k
    cdef double cx, cy, ss, cX, cY, sd, xx, yy, u, v, q0, q1, q3, r2
    cdef double S0 = 0.0, S1 = 0.0, S2 = 0.0, S3 = 0.0, S4 = 0.0, S5 = 0.0
    cdef double U0 = 0.0, U1 = 0.0, U2 = 0.0, U3 = 0.0, U4 = 0.0, U5 = 0.0
    cdef double V0 = 0.0, V1 = 0.0, V2 = 0.0, V3 = 0.0, V4 = 0.0, V5 = 0.0
    cdef double R0 = 0.0, R1 = 0.0, R2 = 0.0, R3 = 0.0, R4 = 0.0, R5 = 0.0
    cdef double S[6]
    cdef double Su[6]
    cdef double Sv[6]
    cdef double Suv[6]
    cdef double h[9]
    cdef double Vm[81]
    cdef double w[9]
    cdef double Ts[9]
    cdef double Tdi[9]
    cdef double tmp[9]
    n, cx, cy, ss, cX, cY, sd = hartley2(src, dst, n_all, mask)
    if n < 4:
        return False
    if not (ss < INFINITY and sd < INFINITY):
        return False
    # A^T A of the DLT rows [p, 0, -u p], [0, p, -v p] with p = (x, y, 1) has the block structure
    # [[S, 0, -Su], [0, S, -Sv], [-Su, -Sv, Suv]] with S = sum p p^T, Su = sum u p p^T, Sv = sum v p p^T,
    # Suv = sum (u^2 + v^2) p p^T: 24 sums per point, for q = (x^2, xy, x, y^2, y, 1)
    for i in range(n_all):
        if not mask[i]:
            continue
        xx = (src[2 * i] - cx) * ss
        yy = (src[2 * i + 1] - cy) * ss
        u = (dst[2 * i] - cX) * sd
        v = (dst[2 * i + 1] - cY) * sd
        q0 = xx * xx
        q1 = xx * yy
        q3 = yy * yy
        r2 = u * u + v * v
        S0 += q0
        S1 += q1
        S2 += xx
        S3 += q3
        S4 += yy
        S5 += 1.0
        U0 += u * q0
        U1 += u * q1
        U2 += u * xx
        U3 += u * q3
        U4 += u * yy
        U5 += u * 1.0
        V0 += v * q0
        V1 += v * q1
        V2 += v * xx
        V3 += v * q3
        V4 += v * yy
        V5 += v * 1.0
        R0 += r2 * q0
        R1 += r2 * q1
        R2 += r2 * xx
        R3 += r2 * q3
        R4 += r2 * yy
        R5 += r2 * 1.0
    S[0] = S0; S[1] = S1; S[2] = S2; S[3] = S3; S[4] = S4; S[5] = S5
    Su[0] = U0; Su[1] = U1; Su[2] = U2; Su[3] = U3; Su[4] = U4; Su[5] = U5
    Sv[0] = V0; Sv[1] = V1; Sv[2] = V2; Sv[3] = V3; Sv[4] = V4; Sv[5] = V5
    Suv[0] = R0; Suv[1] = R1; Suv[2] = R2; Suv[3] = R3; Suv[4] = R4; Suv[5] = R5
    for a in range(9):
        for b in range(9):
            M[a, b] = 0.0
    for a in range(3):
        for b in range(3):
            k = sym6(a, b)
            M[a, b] = S[k]
            M[3 + a, 3 + b] = S[k]
            M[a, 6 + b] = -Su[k]
            M[6 + a, b] = -Su[k]
            M[3 + a, 6 + b] = -Sv[k]
            M[6 + a, 3 + b] = -Sv[k]
            M[6 + a, 6 + b] = Suv[k]
    if not null_vector(M, h, L, x, y, scratch):
        jacobi_eigh_ptr(&M[0, 0], Vm, w, 9)
        if not (w[1] > 1e-14 * w[8]):
            return False
        for k in range(9):
            h[k] = Vm[9 * k]
    similarity(ss, -ss * cx, -ss * cy, Ts)
    similarity(1.0 / sd, cX, cY, Tdi)
    denormalize(h, Ts, Tdi, tmp, H)
    scale_to_h22(H)
    return True
