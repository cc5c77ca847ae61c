# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernel of :mod:`cvpipe.panorama.crop` (compute only; the Python module validates and documents)."""

import numpy as np


def largest_rectangle(const unsigned char[:, ::1] mask):
    """``(x, y, w, h)`` of the largest axis-aligned rectangle of non-zero pixels (a histogram stack per row)."""
    cdef Py_ssize_t H = mask.shape[0], W = mask.shape[1], r, c, top, left
    cdef long long[::1] heights = np.zeros(W + 1, np.int64)
    cdef long long[::1] stack = np.zeros(W + 1, np.int64)
    cdef long long best = 0, bx = 0, by = 0, bw = 0, bh = 0, h, area
    with nogil:
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
