# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled point-set counts of the homography's test against chance (compute only;
:mod:`cvpipe.homography.estimate` validates): the bounding box, distinct points, the densest grid cell and the
pairs a model brings within the threshold by chance."""

import numpy as np

from libc.math cimport fabs, floor, fmod, isfinite, sqrt


cdef inline (double, double, double, double) _bounding_box(const double[:, ::1] pts) noexcept nogil:
    cdef double x0 = pts[0, 0], y0 = pts[0, 1], x1, y1
    cdef Py_ssize_t j
    x1 = x0
    y1 = y0
    for j in range(pts.shape[0]):
        # min() and max() as Python's: the first argument unless the second is strictly smaller (greater)
        if pts[j, 0] < x0:
            x0 = pts[j, 0]
        if pts[j, 1] < y0:
            y0 = pts[j, 1]
        if pts[j, 0] > x1:
            x1 = pts[j, 0]
        if pts[j, 1] > y1:
            y1 = pts[j, 1]
    return x0, y0, x1, y1


def bounding_box(const double[:, ::1] pts):
    """(x min, y min, x max, y max) of the (N >= 1, 2) ``pts``."""
    return _bounding_box(pts)


def chance_hits(const double[:, ::1] src, const double[:, ::1] dst, const double[:, ::1] H, double thr2,
                const long long[::1] rows):
    """Pairs (i, j), i in ``rows``, j != i, with ``|| dehom(H src_i) - dst_j ||^2 <= thr2``.

    The points of ``dst`` are binned into a grid of square cells at least as wide as the threshold (wider when the
    grid would have more than 4 cells per point), so the points within the threshold of a projected source lie in the
    3 x 3 cells around it: O(rows + N) for spread points instead of O(rows x N), and the same count.
    """
    cdef Py_ssize_t n = dst.shape[0], j, t, r
    cdef double x0, y0, x1, y1, cell, v, x, y, w, u, fu, fv, du, dv
    cdef long long ncx, ncy, c, i, cu, cv, lo_v, hi_v, cx, cx_lo, cx_hi
    cdef long long hits = 0
    if n == 0:
        return 0
    x0, y0, x1, y1 = _bounding_box(dst)
    # wider by a rounding margin, so that a point within the threshold is never two cells away
    cell = sqrt(thr2) * (1.0 + 1e-9)
    v = sqrt((x1 - x0) * (y1 - y0) / (4.0 * n))
    if v > cell:
        cell = v
    v = (x1 - x0) / (4.0 * n)
    if v > cell:
        cell = v
    v = (y1 - y0) / (4.0 * n)
    if v > cell:
        cell = v
    if cell == 0.0:
        raise ZeroDivisionError("division by zero")
    ncx = <long long>((x1 - x0) / cell) + 1
    ncy = <long long>((y1 - y0) / cell) + 1
    # counting sort of the points by cell: the points of cell c are order[start[c]:start[c + 1]] (the four arrays in
    # one block)
    cdef long long nc = ncx * ncy
    cdef long long[::1] work = np.empty(2 * n + 2 * nc + 1, np.int64)
    cdef long long* cells = &work[0]
    cdef long long* order = &work[n]
    cdef long long* start = &work[2 * n]
    cdef long long* fill = &work[2 * n + nc + 1]
    with nogil:
        for c in range(nc + 1):
            start[c] = 0
        for j in range(n):
            c = <long long>((dst[j, 0] - x0) / cell) * ncy + <long long>((dst[j, 1] - y0) / cell)
            cells[j] = c
            start[c + 1] += 1
        for c in range(nc):
            start[c + 1] += start[c]
        for c in range(nc):
            fill[c] = start[c]
        for j in range(n):
            order[fill[cells[j]]] = j
            fill[cells[j]] += 1
        for r in range(rows.shape[0]):
            i = rows[r]
            x = src[i, 0]
            y = src[i, 1]
            w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
            if not fabs(w) > 1e-12:
                continue
            u = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w
            v = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w
            fu = (u - x0) / cell
            fv = (v - y0) / cell
            if not (-2.0 < fu and fu < <double>ncx + 1.0 and -2.0 < fv and fv < <double>ncy + 1.0):
                continue  # NaN and far outside: no neighbour
            cu = <long long>floor(fu)
            cv = <long long>floor(fv)
            lo_v = cv - 1 if cv - 1 > 0 else 0
            hi_v = cv + 1 if cv + 1 < ncy - 1 else ncy - 1
            if lo_v > hi_v:
                continue
            cx_lo = cu - 1 if cu - 1 > 0 else 0
            cx_hi = cu + 1 if cu + 1 < ncx - 1 else ncx - 1
            for cx in range(cx_lo, cx_hi + 1):
                # the cells (cx, lo_v .. hi_v) are one run of the sorted order
                for t in range(start[cx * ncy + lo_v], start[cx * ncy + hi_v + 1]):
                    j = order[t]
                    if j != i:
                        du = u - dst[j, 0]
                        dv = v - dst[j, 1]
                        if du * du + dv * dv <= thr2:
                            hits += 1
    return hits


def distinct_rows(const double[:, ::1] pts, const unsigned char[::1] mask):
    """Number of distinct rows of the (N, 2) ``pts``, and of its rows where the (N,) bool ``mask`` is true.

    One pass over an open-addressing hash table of the points (O(N); equal points have equal hashes, and points
    are compared exactly).
    """
    cdef Py_ssize_t n = pts.shape[0], i
    cdef long long size = 1, h, n_all = 0, n_mask = 0
    cdef double x, y, v
    while size < 2 * n:
        size *= 2
    cdef long long[::1] work = np.empty(2 * size, np.int64)
    cdef long long* slot = &work[0]  # a row of pts, or -1 for an empty slot
    cdef long long* hit = &work[size]  # 1: a row of this point is in the mask
    with nogil:
        for i in range(size):
            slot[i] = -1
            hit[i] = 0
        for i in range(n):
            x = pts[i, 0]
            y = pts[i, 1]
            v = fabs(x) * 73856093.0 + fabs(y) * 19349663.0
            if not v < 1e15:  # keep the integer conversion in range (the hash only has to be equal for equal points)
                v = fmod(v, 1e15) if isfinite(v) else 0.0
            h = <long long>v & (size - 1)
            while slot[h] >= 0 and not (pts[slot[h], 0] == x and pts[slot[h], 1] == y):
                h = (h + 1) & (size - 1)
            if slot[h] < 0:
                slot[h] = i
                n_all += 1
            if mask[i] and not hit[h]:
                hit[h] = 1
                n_mask += 1
    return n_all, n_mask


def densest_cell(const double[:, ::1] pts, double side):
    """The most points of ``pts`` (N, 2) in one cell ``[i side, (i + 1) side) x [j side, (j + 1) side)`` of the
    square grid (counted in an open-addressing hash table of the occupied cells); N when a coordinate is too large
    for the grid's integer indices (no bound then)."""
    cdef Py_ssize_t n = pts.shape[0], k
    cdef long long size = 2, h, i, j, best = 0
    cdef double x, y
    if side == 0.0 and n > 0:
        raise ZeroDivisionError("division by zero")
    while size < 2 * n:
        size *= 2
    cdef long long[::1] work = np.empty(3 * size, np.int64)
    cdef long long* ci = &work[0]
    cdef long long* cj = &work[size]
    cdef long long* count = &work[2 * size]
    with nogil:
        for k in range(size):
            count[k] = 0
        for k in range(n):
            x = pts[k, 0] / side
            y = pts[k, 1] / side
            if not (fabs(x) < 1e18 and fabs(y) < 1e18):
                best = n
                break
            i = <long long>floor(x)
            j = <long long>floor(y)
            # the hash in wrapping 64-bit arithmetic
            h = <long long>((<unsigned long long>i * 73856093ULL + <unsigned long long>j * 19349663ULL)
                            & <unsigned long long>(size - 1))
            while count[h] > 0 and (ci[h] != i or cj[h] != j):
                h = (h + 1) & (size - 1)
            ci[h] = i
            cj[h] = j
            count[h] += 1
            if count[h] > best:
                best = count[h]
    return best
