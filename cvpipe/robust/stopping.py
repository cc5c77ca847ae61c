"""When to stop: the adaptive iteration bound, and Wald's sequential probability ratio test (SPRT) that stops the
verification of a bad hypothesis early (Chum & Matas 2008), with its parameters re-estimated as the run goes.

The rules are compiled (``_core.pxd``, which the recipes' kernels cimport; ``_search`` for Python callers); the SPRT
counts one model per minimal sample."""

from __future__ import annotations

import numpy as np

from . import _search


def iterations_needed(inliers, n, sample_size: int, log1mconf: float, max_iters, sprt_a: float) -> float:
    """Iterations needed to draw, and accept, one all-inlier sample with confidence ``1 - exp(log1mconf)``.

    An all-inlier sample is drawn with probability ``w^sample_size`` (``w = inliers / n``) and survives the SPRT with
    probability about ``1 - 1/sprt_a`` (``sprt_a = inf``: no SPRT). At most ``max_iters``; not rounded (the loops
    compare an integer count with it).
    """
    return _search.iterations_needed(inliers, n, sample_size, log1mconf, max_iters, sprt_a)


def sprt_threshold(eps: float, delta: float, tm: float) -> float:
    """Decision threshold A of the SPRT (Chum & Matas 2008, eq. 2), ``A = K + log A`` by iteration; ``inf`` (no
    SPRT) unless ``0 < delta < eps < 1``."""
    return _search.sprt_threshold(eps, delta, tm)


def on_rejected(state: np.ndarray, consistent: int, seen: int, n: int, sample_size: int, log1mconf: float,
                max_iters) -> None:
    """Record a model the SPRT rejected after ``seen`` points, ``consistent`` of them consistent with it.

    ``state`` is the run's (1,) state array (:func:`cvpipe.robust.new_state`). The consistent share of the rejected
    models estimates ``sprt_delta``; once 20 of them are in and it drifted by more than 10 %, the test is
    redesigned and the bound recomputed.
    """
    _search.on_rejected(state, consistent, seen, n, sample_size, log1mconf, max_iters)


def on_new_best(state: np.ndarray, cost: float, inliers: int, raw_inliers: int, n: int, sample_size: int,
                log1mconf: float, max_iters) -> None:
    """Record a new so-far-best model in the (1,) ``state``: its ``cost``, its ``inliers`` (after local
    optimization) and ``raw_inliers`` (of the minimal model, which estimates the SPRT's ``sprt_eps``: a fresh
    all-inlier minimal model is less accurate than a refitted one); the bound follows the most inliers seen."""
    _search.on_new_best(state, cost, inliers, raw_inliers, n, sample_size, log1mconf, max_iters)
