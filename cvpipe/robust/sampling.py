"""Minimal samples: distinct indices drawn from uniforms, exact sampling without replacement.

The j-th index of a sample is uniform over the ``n - j`` values not chosen yet: it is drawn in [0, n - j) from the
j-th uniform and walked past the indices already chosen, in increasing order. :func:`sample_distinct` does this for
any sample size; :func:`sample4` is the same draw for 4 indices in scalar, branch-light code, for the homography's
loop of tens of thousands of hypotheses (figures: docs/notes/robust.md); both give the same indices from the same
uniforms.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def sample_distinct(u, row, n, pick, chosen):  # pragma: no cover - compiled
    """``len(pick)`` distinct indices in [0, n) into ``pick`` from as many uniforms ``u[row]`` in [0, 1).

    ``chosen`` is scratch of the same length (the indices chosen so far, kept sorted). ``n >= len(pick)``.
    """
    for j in range(pick.shape[0]):
        r = min(int(u[row, j] * (n - j)), n - j - 1)
        t = 0
        while t < j and r >= chosen[t]:
            r += 1
            t += 1
        for i in range(j, t, -1):
            chosen[i] = chosen[i - 1]
        chosen[t] = r
        pick[j] = r


@njit(cache=True, inline="always", error_model="numpy")
def sample4(u, row, n):  # pragma: no cover - compiled
    """Four distinct indices in [0, n) from the uniforms ``u[row, :4]``: :func:`sample_distinct` for a sample of
    4, as a tuple. ``n >= 4``."""
    a = min(int(u[row, 0] * n), n - 1)
    b = min(int(u[row, 1] * (n - 1)), n - 2)
    c = min(int(u[row, 2] * (n - 2)), n - 3)
    d = min(int(u[row, 3] * (n - 3)), n - 4)
    if b >= a:
        b += 1
    lo = min(a, b)
    hi = max(a, b)
    if c >= lo:
        c += 1
    if c >= hi:
        c += 1
    x0 = min(lo, c)
    x2 = max(hi, c)
    x1 = lo + hi + c - x0 - x2
    if d >= x0:
        d += 1
    if d >= x1:
        d += 1
    if d >= x2:
        d += 1
    return a, b, c, d


@njit(cache=True, error_model="numpy")
def draw_samples(u, n):  # pragma: no cover - compiled
    """One sample of ``u.shape[1]`` distinct indices in [0, n) per row of the uniforms ``u``: (rows, k) int64."""
    k = u.shape[1]
    out = np.empty((u.shape[0], k), np.int64)
    chosen = np.empty(k, np.int64)
    for i in range(u.shape[0]):
        sample_distinct(u, i, n, out[i], chosen)
    return out
