"""The panorama's numba kernels (they only compute; :mod:`cvpipe.panorama.crop` validates and documents)."""

import numpy as np
from numba import njit


@njit(cache=True)
def _largest_rectangle(mask):
    H, W = mask.shape
    heights = np.zeros(W + 1, np.int64)
    stack = np.zeros(W + 1, np.int64)
    best, bx, by, bw, bh = 0, 0, 0, 0, 0
    for r in range(H):
        for c in range(W):
            heights[c] = heights[c] + 1 if mask[r, c] else 0
        top = 0
        for c in range(W + 1):
            while top > 0 and heights[stack[top - 1]] >= heights[c]:
                h = heights[stack[top - 1]]
                top -= 1
                left = stack[top - 1] + 1 if top > 0 else 0
                area = h * (c - left)
                if area > best:
                    best, bx, by, bw, bh = area, left, r - h + 1, c - left, h
            stack[top] = c
            top += 1
    return bx, by, bw, bh
