# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernel of :mod:`cvpipe.linalg` (compute only; the Python module validates and documents)."""

import numpy as np

from ._cholesky cimport cholesky_factor, cholesky_substitute


def cholesky_solve(const double[:, ::1] A, const double[::1] b, double[::1] x):
    """Solve A x = b for a symmetric positive definite A (n x n) by Cholesky; False if A is not positive definite."""
    cdef Py_ssize_t n = A.shape[0]
    cdef double[:, ::1] L = np.zeros((n, n))
    cdef double[::1] y = np.empty(n)
    cdef bint ok
    with nogil:
        ok = cholesky_factor(A, L, 0.0)
        if ok:
            cholesky_substitute(L, b, x, y)
    return ok
