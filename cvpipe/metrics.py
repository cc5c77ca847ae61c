"""Accuracy measures shared by the tasks' reports and benchmarks (pure functions on arrays)."""

from __future__ import annotations

import numpy as np


def _known(truth: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """Boolean map of pixels whose truth is known (finite) and, if given, inside ``mask``."""
    known = np.isfinite(truth)
    if mask is not None:
        if mask.shape != truth.shape:
            raise ValueError(f"`mask` must have the shape of `truth` {truth.shape}, got {mask.shape}")
        known &= mask.astype(bool)
    return known


def _check_maps(estimate: np.ndarray, truth: np.ndarray) -> None:
    if estimate.shape != truth.shape:
        raise ValueError(f"`estimate` must have the shape of `truth` {truth.shape}, got {estimate.shape}")


def bad_pixel_rate(estimate: np.ndarray, truth: np.ndarray, threshold: float, mask: np.ndarray | None = None) -> float:
    """Share of pixels with known truth whose estimate is missing (NaN) or off by more than ``threshold``.

    Parameters
    ----------
    estimate, truth : ndarray, (H, W) float
        Estimated and true values (e.g. disparity in pixels); NaN marks a missing estimate / unknown truth.
    threshold : float
        Largest accepted absolute error (e.g. 1.0 or 2.0 pixels for Middlebury's bad-1.0 / bad-2.0), >= 0.
    mask : ndarray, (H, W) bool, optional
        Restrict the evaluation to these pixels (e.g. non-occluded).

    Returns
    -------
    float
        In [0, 1]; NaN when no pixel has known truth.
    """
    _check_maps(estimate, truth)
    if not threshold >= 0:
        raise ValueError(f"`threshold` must be >= 0, got {threshold}")
    known = _known(truth, mask)
    n = int(known.sum())
    if n == 0:
        return float("nan")
    err = np.abs(estimate[known].astype(np.float64) - truth[known])
    good = np.isfinite(err) & (err <= threshold)
    return float(1.0 - good.sum() / n)


def mean_abs_error(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Mean absolute error over pixels where both the estimate and the truth exist (NaN if there are none)."""
    _check_maps(estimate, truth)
    both = _known(truth, mask) & np.isfinite(estimate)
    if not both.any():
        return float("nan")
    return float(np.mean(np.abs(estimate[both].astype(np.float64) - truth[both])))


def density(estimate: np.ndarray, truth: np.ndarray | None = None, mask: np.ndarray | None = None) -> float:
    """Share of pixels with an estimate (finite), over the pixels with known truth when ``truth`` is given."""
    if truth is None:
        known = np.ones(estimate.shape, bool) if mask is None else mask.astype(bool)
    else:
        _check_maps(estimate, truth)
        known = _known(truth, mask)
    n = int(known.sum())
    return float("nan") if n == 0 else float(np.isfinite(estimate[known]).sum() / n)
