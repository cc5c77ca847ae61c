"""Numba kernels shared by several tasks (compute only; the public Python entry is :func:`cvpipe.linalg.solve_spd`).

``cholesky_solve`` is called directly by the homography Levenberg-Marquardt kernel
(:mod:`cvpipe.homography._kernels`) and, through :func:`cvpipe.linalg.solve_spd`, by the panorama's adjustment;
its two halves, ``cholesky_factor`` and ``cholesky_substitute``, by the homography's inverse iteration."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def cholesky_factor(A, L, shift):
    """The lower Cholesky factor of ``A + shift I`` (A symmetric, n x n) into ``L``; False if that is not positive
    definite."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j] + shift
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    return True


@njit(cache=True, error_model="numpy")
def cholesky_substitute(L, b, x):
    """``x = (L L^T)^-1 b`` by forward and backward substitution (``L`` from :func:`cholesky_factor`)."""
    n = L.shape[0]
    y = np.empty(n)
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


@njit(cache=True, error_model="numpy")
def cholesky_solve(A, b, x):
    """Solve A x = b for a symmetric positive definite A (n x n) by Cholesky; False if A is not positive definite."""
    n = A.shape[0]
    L = np.zeros((n, n))
    if not cholesky_factor(A, L, 0.0):
        return False
    cholesky_substitute(L, b, x)
    return True
