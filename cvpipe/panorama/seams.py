"""Seams: every canvas pixel goes to the image in which it lies deepest (largest distance to that image's border),
which puts the seams halfway through each overlap (:func:`seam_labels`); :func:`seam_lines` draws them."""

from __future__ import annotations

import cv2
import numpy as np

from .warp import Warped


def _distance(mask: np.ndarray) -> np.ndarray:
    # pad with zeros so that the box edge counts as the image border
    d = cv2.distanceTransform(np.pad(mask, 1), cv2.DIST_L2, 3)
    return d[1:-1, 1:-1]


def seam_labels(w: Warped) -> np.ndarray:
    """(H, W) int16 canvas: index of the image each pixel is taken from, -1 where no image covers it.

    Examples
    --------
    Two 21x10 images overlapping over 4 columns of a 21x16 canvas: the seam falls halfway through the overlap.

    >>> import numpy as np
    >>> w = Warped([np.zeros((21, 10, 3), np.uint8)] * 2, [np.full((21, 10), 255, np.uint8)] * 2, [(0, 0), (6, 0)],
    ...            (16, 21), (0, 0))
    >>> seam_labels(w)[10]
    array([0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1, 1], dtype=int16)
    """
    W, H = w.size
    labels = np.full((H, W), -1, np.int16)
    best = np.zeros((H, W), np.float32)
    for k, (mask, (x, y)) in enumerate(zip(w.masks, w.corners)):
        d = _distance(mask)
        h, ww = mask.shape
        b = best[y:y + h, x:x + ww]
        upd = d > b
        b[upd] = d[upd]
        labels[y:y + h, x:x + ww][upd] = k
    return labels


def seam_lines(labels: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels where the source image changes to another image (4-neighbourhood)."""
    out = np.zeros(labels.shape, bool)
    a, b = labels[:, :-1], labels[:, 1:]
    d = (a != b) & (a >= 0) & (b >= 0)
    out[:, :-1] |= d
    a, b = labels[:-1], labels[1:]
    d = (a != b) & (a >= 0) & (b >= 0)
    out[:-1] |= d
    return out
