# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The symmetric positive definite solve shared by several kernels (inline, compiled into each module that cimports
it): :mod:`cvpipe.linalg` for the panorama's adjustment, the homography's Levenberg-Marquardt and inverse
iteration."""

from libc.math cimport sqrt


cdef inline bint cholesky_factor(const double[:, ::1] A, double[:, ::1] L, double shift) noexcept nogil:
    """The lower Cholesky factor of ``A + shift I`` (A symmetric, n x n) into ``L``; False if that is not positive
    definite."""
    cdef Py_ssize_t n = A.shape[0], i, j, k
    cdef double s
    for j in range(n):
        s = A[j, j] + shift
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        L[j, j] = sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    return True


cdef inline void cholesky_substitute(const double[:, ::1] L, const double[::1] b, double[::1] x,
                                     double[::1] y) noexcept nogil:
    """``x = (L L^T)^-1 b`` by forward and backward substitution (``L`` from :func:`cholesky_factor`; ``y`` is
    scratch of length n)."""
    cdef Py_ssize_t n = L.shape[0], i, k
    cdef double s
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
