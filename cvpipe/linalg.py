"""Small dense linear algebra shared by the estimators: the symmetric positive definite solve of their
Levenberg-Marquardt steps (:mod:`cvpipe.homography`, :mod:`cvpipe.panorama.refine`)."""

from __future__ import annotations

import numpy as np

from ._linalg import cholesky_solve


def solve_spd(A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """Solve the symmetric positive definite system ``A x = b`` single-threaded (Cholesky, compiled).

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
