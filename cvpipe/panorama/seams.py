"""Seams: every canvas pixel goes to the image in which it lies deepest (largest distance to that image's border),
which puts the seams halfway through each overlap (:func:`seam_labels`); :func:`seam_lines` draws them.

The labels are found on the canvas shrunk by ``scale`` (:data:`DEFAULT_SEAM_SCALE`, as cv2.Stitcher finds its
seams below the compose resolution) and enlarged again, so a seam runs on a ``scale``-pixel staircase, which the
multi-band blend hides (on the Adobe and tutorial sets, 0.003-0.26 grey levels of mean difference to full-resolution
seams, docs/notes/panorama.md); a pixel only ever goes to an image that covers it.
"""

from __future__ import annotations

import cv2
import numpy as np

from .warp import Warped

#: the canvas is shrunk by this factor to find the labels (1: full resolution)
DEFAULT_SEAM_SCALE = 4
#: an image's border pixels that another image's label takes where that one covers them
EDGE_PIXELS = 2
_CROSS = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))


def _distance(mask: np.ndarray) -> np.ndarray:
    # pad with zeros so that the box edge counts as the image border
    d = cv2.distanceTransform(np.pad(mask, 1), cv2.DIST_L2, 3)
    return d[1:-1, 1:-1]


def _labels(masks, corners, size: tuple[int, int]) -> np.ndarray:
    W, H = size
    labels = np.full((H, W), -1, np.int16)
    best = np.zeros((H, W), np.float32)
    for k, (mask, (x, y)) in enumerate(zip(masks, corners)):
        d = _distance(mask)
        h, ww = mask.shape
        b = best[y:y + h, x:x + ww]
        upd = d > b
        np.copyto(b, d, where=upd)
        np.copyto(labels[y:y + h, x:x + ww], np.int16(k), where=upd)
    return labels


def seam_labels(w: Warped, scale: int = DEFAULT_SEAM_SCALE) -> np.ndarray:
    """(H, W) int16 canvas: index of the image each pixel is taken from, -1 where no image covers it.

    ``scale``: the labels are found on the canvas shrunk by this factor and enlarged again (nearest); a pixel that
    lands on an image that does not cover it (within ``scale`` pixels of that image's border) goes to the first
    image that does.

    Examples
    --------
    Two 21x10 images overlapping over 4 columns of a 21x16 canvas: the seam falls halfway through the overlap.

    >>> import numpy as np
    >>> w = Warped([np.zeros((21, 10, 3), np.uint8)] * 2, [np.full((21, 10), 255, np.uint8)] * 2, [(0, 0), (6, 0)],
    ...            (16, 21), (0, 0))
    >>> seam_labels(w, scale=1)[10]
    array([0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1, 1], dtype=int16)
    """
    if scale <= 1:
        return _labels(w.masks, w.corners, w.size)
    W, H = w.size
    small_masks, small_corners = [], []
    for mask, (x, y) in zip(w.masks, w.corners):  # a shrunk pixel is covered when its whole block is
        x0, y0 = -(-x // scale), -(-y // scale)
        x1, y1 = (x + mask.shape[1]) // scale, (y + mask.shape[0]) // scale
        m = mask[y0 * scale - y:y1 * scale - y, x0 * scale - x:x1 * scale - x] if x1 > x0 and y1 > y0 else mask[:0, :0]
        if m.size:
            m = cv2.resize(m, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
            m = np.where(m == 255, np.uint8(255), np.uint8(0))
        small_masks.append(m if m.size else np.zeros((1, 1), np.uint8))
        small_corners.append((min(x0, -(-W // scale) - 1), min(y0, -(-H // scale) - 1)))
    small = _labels(small_masks, small_corners, (-(-W // scale), -(-H // scale)))
    labels = cv2.resize(small, (small.shape[1] * scale, small.shape[0] * scale),
                        interpolation=cv2.INTER_NEAREST)[:H, :W]
    labels = np.ascontiguousarray(labels)
    # an image's outermost pixels are interpolated with the black outside, so where another image covers them they
    # go to that one (as the full-resolution labels do, where the deeper image wins)
    eroded = [[mask] for mask in w.masks]  # eroded[k][e]: image k's mask less its e outermost pixels
    for m in eroded:
        for _ in range(EDGE_PIXELS):
            m.append(cv2.erode(m[-1], _CROSS))
    for k, (m, (x, y)) in enumerate(zip(eroded, w.corners)):
        lab = labels[y:y + m[0].shape[0], x:x + m[0].shape[1]]
        np.copyto(lab, np.int16(-1), where=(lab == k) & (m[-1] == 0))
    for e in range(EDGE_PIXELS, -1, -1):  # to the first image that covers a pixel from deepest inside
        for k, (m, (x, y)) in enumerate(zip(eroded, w.corners)):
            lab = labels[y:y + m[0].shape[0], x:x + m[0].shape[1]]
            np.copyto(lab, np.int16(k), where=(lab < 0) & (m[e] > 0))
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
