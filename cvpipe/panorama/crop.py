"""Cropping: the largest axis-aligned rectangle of the panorama without empty pixels."""

from __future__ import annotations

import numpy as np

from . import _crop


def largest_rectangle(mask: np.ndarray) -> tuple[int, int, int, int]:
    """The largest axis-aligned rectangle of non-zero pixels (maximal-histogram method, O(H W)).

    Parameters
    ----------
    mask : (H, W) bool or uint8

    Returns
    -------
    (x, y, w, h)
        Top-left pixel and size; ``(0, 0, 0, 0)`` for an empty mask.

    Examples
    --------
    >>> mask = np.ones((4, 6), bool)
    >>> mask[0, :2] = mask[3, 5] = False
    >>> largest_rectangle(mask)
    (0, 1, 5, 3)
    """
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"`mask` must be 2-D, got shape {mask.shape}")
    return tuple(int(v) for v in _crop.largest_rectangle(np.ascontiguousarray(mask != 0).view(np.uint8)))
