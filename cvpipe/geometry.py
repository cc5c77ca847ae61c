"""Point mapping through a homography and image corners (small, shared by the tasks).

``image_corners`` is defined in :mod:`cvpipe.metrics` (its first user) and re-exported here, so that every task
finds both helpers in one place without a second copy."""

from __future__ import annotations

import numpy as np

from .errors import EstimationError
from .metrics import image_corners

__all__ = ["apply_homography", "image_corners"]


def apply_homography(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Map (N, 2) points by the 3x3 homography ``H``.

    Raises
    ------
    EstimationError
        A point maps to infinity.

    Examples
    --------
    >>> apply_homography(np.diag([2.0, 3.0, 1.0]), np.array([[1.0, 1.0]])).tolist()
    [[2.0, 3.0]]
    """
    p = np.c_[np.asarray(pts, np.float64), np.ones(len(pts))] @ np.asarray(H, np.float64).T
    if np.any(np.abs(p[:, 2]) < 1e-12):
        raise EstimationError("a point maps to infinity")
    return p[:, :2] / p[:, 2:3]
