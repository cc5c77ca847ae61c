"""Minimal samples: distinct indices drawn from uniforms, exact sampling without replacement.

The j-th index of a sample is uniform over the ``n - j`` values not chosen yet: it is drawn in [0, n - j) from the
j-th uniform and walked past the indices already chosen, in increasing order. :func:`sample_distinct` does this for
any sample size; :func:`sample4` is the same draw for 4 indices in scalar, branch-light code, for the homography's
loop of tens of thousands of hypotheses (figures: docs/notes/robust.md); both give the same indices from the same
uniforms. They are compiled (``_core.pxd``, which the recipes' kernels cimport; ``_search`` for Python callers).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from . import _search


def _uniforms(u) -> np.ndarray:
    u = np.ascontiguousarray(u, dtype=np.float64)
    if u.ndim != 2:
        raise InputError(f"the uniforms must be a (rows, sample size) array, got shape {u.shape}")
    return u


def sample_distinct(u, row: int, n: int, pick: np.ndarray, chosen: np.ndarray) -> None:
    """``len(pick)`` distinct indices in [0, n) into ``pick`` from as many uniforms ``u[row]`` in [0, 1).

    Parameters
    ----------
    u : (rows, k) float64 array
        Uniforms in [0, 1), ``k >= len(pick)``.
    row : int
        The row of ``u`` to use.
    n : int
        The range of the indices, ``n >= len(pick)``.
    pick, chosen : (m,) int64 arrays
        The sample (output) and scratch of the same length (the indices chosen so far, kept sorted).
    """
    u = _uniforms(u)
    if not (0 <= row < u.shape[0] and len(pick) <= u.shape[1] and len(chosen) >= len(pick)):
        raise InputError(f"row {row} of uniforms {u.shape} cannot give a sample of {len(pick)} with scratch of "
                         f"{len(chosen)}")
    _search.sample_distinct(u, int(row), int(n), pick, chosen)


def sample4(u, row: int, n: int) -> tuple[int, int, int, int]:
    """Four distinct indices in [0, n) from the uniforms ``u[row, :4]``: :func:`sample_distinct` for a sample of
    4, as a tuple. ``n >= 4``."""
    u = _uniforms(u)
    if not (0 <= row < u.shape[0] and u.shape[1] >= 4):
        raise InputError(f"row {row} of uniforms {u.shape} cannot give a sample of 4")
    return _search.sample4(u, int(row), int(n))


def draw_samples(u, n: int) -> np.ndarray:
    """One sample of ``u.shape[1]`` distinct indices in [0, n) per row of the uniforms ``u``: (rows, k) int64.

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.robust import draw_samples
    >>> idx = draw_samples(np.random.default_rng(0).random((5, 3)), 10)
    >>> idx.shape, bool((np.sort(idx, axis=1)[:, 1:] > np.sort(idx, axis=1)[:, :-1]).all())
    ((5, 3), True)
    """
    return _search.draw_samples(_uniforms(u), int(n))
