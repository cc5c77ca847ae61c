"""When to stop: the adaptive iteration bound, and Wald's sequential probability ratio test (SPRT) that stops the
verification of a bad hypothesis early (Chum & Matas 2008), with its parameters re-estimated as the run goes."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: the SPRT's models per sample (one solution per minimal sample)
_SPRT_MS = 1.0


@njit(cache=True, error_model="numpy")
def iterations_needed(inliers, n, sample_size, log1mconf, max_iters, sprt_a):  # pragma: no cover - compiled
    """Iterations needed to draw, and accept, one all-inlier sample with confidence ``1 - exp(log1mconf)``.

    An all-inlier sample is drawn with probability ``w^sample_size`` (``w = inliers / n``) and survives the SPRT with
    probability about ``1 - 1/sprt_a`` (``sprt_a = inf``: no SPRT). At most ``max_iters``; not rounded (the loops
    compare an integer count with it).
    """
    w = inliers / n
    p = 1.0
    for _ in range(sample_size):
        p *= w
    p *= 1.0 - 1.0 / sprt_a
    if p >= 1.0:
        return 1.0
    if p <= 0.0:
        return float(max_iters)
    den = math.log1p(-p)
    if den >= 0.0:
        return float(max_iters)
    k = log1mconf / den
    if k >= max_iters:
        return float(max_iters)
    return k


@njit(cache=True, error_model="numpy")
def sprt_threshold(eps, delta, tm):  # pragma: no cover - compiled
    """Decision threshold A of the SPRT (Chum & Matas 2008, eq. 2), ``A = K + log A`` by iteration; ``inf`` (no
    SPRT) unless ``0 < delta < eps < 1``."""
    if not (0.0 < delta < eps < 1.0):
        return np.inf
    c = (1.0 - delta) * math.log((1.0 - delta) / (1.0 - eps)) + delta * math.log(delta / eps)
    k = tm * c / _SPRT_MS + 1.0
    a = k
    for _ in range(20):
        a = k + math.log(a)
    return a


@njit(cache=True, error_model="numpy")
def on_rejected(s, consistent, seen, n, sample_size, log1mconf, max_iters):  # pragma: no cover - compiled
    """Record a model the SPRT rejected after ``seen`` points, ``consistent`` of them consistent with it.

    ``s`` is the state record. The consistent share of the rejected models estimates ``sprt_delta``; once 20 of them
    are in and it drifted by more than 10 %, the test is redesigned and the bound recomputed.
    """
    s.bad_consistent += consistent
    s.bad_seen += seen
    s.bad_models += 1
    if s.bad_models >= 20 and s.bad_seen > 0:
        d = max(s.bad_consistent / s.bad_seen, 1e-4)
        if abs(d - s.sprt_delta) > 0.1 * s.sprt_delta:
            s.sprt_delta = min(d, 0.5 * s.sprt_eps)
            s.sprt_a = sprt_threshold(s.sprt_eps, s.sprt_delta, s.sprt_tm)
            s.bound = iterations_needed(s.best_inliers, n, sample_size, log1mconf, max_iters, s.sprt_a)


@njit(cache=True, error_model="numpy")
def on_new_best(s, cost, inliers, raw_inliers, n, sample_size, log1mconf, max_iters):  # pragma: no cover - compiled
    """Record a new so-far-best model: its ``cost``, its ``inliers`` (after local optimization) and ``raw_inliers``
    (of the minimal model, which estimates the SPRT's ``sprt_eps``: a fresh all-inlier minimal model is less
    accurate than a refitted one); the bound follows the most inliers seen."""
    s.best_cost = cost
    if raw_inliers / n > s.sprt_eps and s.sprt_a < np.inf:
        s.sprt_eps = raw_inliers / n
        s.sprt_delta = min(s.sprt_delta, 0.5 * s.sprt_eps)
        s.sprt_a = sprt_threshold(s.sprt_eps, s.sprt_delta, s.sprt_tm)
    if inliers > s.best_inliers:
        s.best_inliers = inliers
    s.bound = iterations_needed(s.best_inliers, n, sample_size, log1mconf, max_iters, s.sprt_a)
