# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The symmetric eigen-solver of the small normal matrices (the homography's 9x9 DLT, the fundamental matrix's 9x9
and 3x3 systems), as inline C compiled into each module that cimports it.

``jacobi_eigh(M, V, w)``: M, V (n, n) and w (n,) float64, C-contiguous, n <= 15 (the eigenvalues are ordered by an
insertion sort, NaN last, ties kept in index order). ``jacobi_eigh_ptr`` is the same on raw row-major pointers.
``sym6(a, b)``: the index into the 6 unique entries (xx, xy, x, yy, y, 1) of a symmetric 3x3 ``p p^T``
(``[[0, 1, 2], [1, 3, 4], [2, 4, 5]]``).
"""

from libc.math cimport fabs, isnan, sqrt


cdef inline Py_ssize_t sym6(Py_ssize_t a, Py_ssize_t b) noexcept nogil:
    """Entry (a, b) of ``[[0, 1, 2], [1, 3, 4], [2, 4, 5]]`` (a, b in 0..2)."""
    cdef Py_ssize_t t
    if a > b:
        t = a
        a = b
        b = t
    return 3 * a - (a * (a - 1)) // 2 + (b - a)


cdef inline void jacobi_eigh_ptr(double* M, double* V, double* w, Py_ssize_t n) noexcept nogil:
    """:func:`jacobi_eigh` on row-major (n, n) ``M``, ``V`` and (n,) ``w``."""
    cdef Py_ssize_t i, j, k, p, q, sweep
    cdef double off, diag, apq, theta, tt, c, s, a, b, v
    cdef double wk[16]
    cdef double row[16]
    cdef Py_ssize_t order[16]
    for i in range(n):
        for j in range(n):
            V[i * n + j] = 1.0 if i == j else 0.0
    for sweep in range(50):
        off = 0.0
        for p in range(n):
            for q in range(p + 1, n):
                off += M[p * n + q] * M[p * n + q]
        diag = 0.0
        for p in range(n):
            diag += M[p * n + p] * M[p * n + p]
        if off <= 1e-30 * diag or off == 0.0:
            break
        for p in range(n):
            for q in range(p + 1, n):
                apq = M[p * n + q]
                if apq == 0.0:
                    continue
                theta = (M[q * n + q] - M[p * n + p]) / (2.0 * apq)
                tt = (1.0 if theta >= 0 else -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0))
                c = 1.0 / sqrt(tt * tt + 1.0)
                s = tt * c
                for k in range(n):
                    a = M[k * n + p]
                    b = M[k * n + q]
                    M[k * n + p] = c * a - s * b
                    M[k * n + q] = s * a + c * b
                for k in range(n):
                    a = M[p * n + k]
                    b = M[q * n + k]
                    M[p * n + k] = c * a - s * b
                    M[q * n + k] = s * a + c * b
                for k in range(n):
                    a = V[k * n + p]
                    b = V[k * n + q]
                    V[k * n + p] = c * a - s * b
                    V[k * n + q] = s * a + c * b
    # ascending order by insertion sort (stable; NaN after every number)
    for i in range(n):
        wk[i] = M[i * n + i]
        order[i] = i
    for i in range(1, n):
        k = order[i]
        v = wk[k]
        j = i
        while j > 0 and (v < wk[order[j - 1]] or (isnan(wk[order[j - 1]]) and not isnan(v))):
            order[j] = order[j - 1]
            j -= 1
        order[j] = k
    for j in range(n):
        w[j] = wk[order[j]]
    for i in range(n):
        for j in range(n):
            row[j] = V[i * n + j]
        for j in range(n):
            V[i * n + j] = row[order[j]]


cdef inline void jacobi_eigh(double[:, ::1] M, double[:, ::1] V, double[::1] w) noexcept nogil:
    """Eigen-decomposition of a small symmetric matrix by cyclic Jacobi rotations (``M`` is overwritten).

    The eigenvalues in ascending order into ``w``; the columns of ``V`` become the matching unit eigenvectors.
    ``n <= 15``.
    """
    jacobi_eigh_ptr(&M[0, 0], &V[0, 0], &w[0], M.shape[0])
