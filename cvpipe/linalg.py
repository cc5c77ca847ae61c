"""Small dense linear algebra shared by the estimators: the symmetric positive definite solve of their
Levenberg-Marquardt steps (:mod:`cvpipe.homography`, :mod:`cvpipe.panorama.refine`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def cholesky_solve(A, b, x):
    """Solve A x = b for a symmetric positive definite A (n x n) by Cholesky; False if A is not positive definite."""
    n = A.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = A[j, j]
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
    return True


def solve_spd(A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """Solve the symmetric positive definite system ``A x = b`` single-threaded (Cholesky, numba).

    The systems are small (8 parameters per image); a threaded LAPACK call costs more in thread start-up than in
    arithmetic on a busy machine.

    Parameters
    ----------
    A : (n, n) float
        Symmetric; only its lower triangle is read.
    b : (n,) float

    Returns
    -------
    (n,) float64 or None
        The solution, or None when ``A`` is not positive definite (or the solution is not finite).

    Examples
    --------
    >>> solve_spd(np.array([[4.0, 2.0], [2.0, 3.0]]), np.array([2.0, 1.0]))
    array([0.5, 0. ])
    >>> solve_spd(np.array([[1.0, 2.0], [2.0, 1.0]]), np.ones(2)) is None
    True
    """
    x = np.empty(len(b))
    ok = cholesky_solve(np.ascontiguousarray(A, np.float64), np.ascontiguousarray(b, np.float64), x)
    return x if ok and np.all(np.isfinite(x)) else None
