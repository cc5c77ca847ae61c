"""numba kernels of the Hough transforms: they only compute; the functions of :mod:`cvpipe.hough.transform` and
:mod:`cvpipe.hough.probabilistic` validate the input and document the results.

Imported lazily by the functions that vote, so that ``import cvpipe.hough`` (and ``cvpipe hough --method opencv``)
does not import numba. Every kernel is compiled once and cached on disk (``cache=True``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True)
def _edge_points(edges):
    """Coordinates (float32 x, float32 y) of the nonzero pixels of a C-contiguous uint8 ``edges``, in row-major
    order."""
    h, w = edges.shape
    flat = edges.reshape(h * w)
    count = 0
    for i in range(h * w):
        count += flat[i] != 0
    # counted first: an (H * W) buffer would cost 8 bytes per pixel of a large, sparse edge map
    xs = np.empty(count, np.float32)
    ys = np.empty(count, np.float32)
    # eight pixels at a time, and only the words that hold an edge pixel pixel by pixel: an edge map is mostly
    # zeros (2.6x faster on a 300 x 300 drawing with 3 % edge pixels, the same on a photo with 13 %)
    words = flat[:(h * w) // 8 * 8].view(np.uint64)
    k = 0
    for q in range(words.shape[0]):
        if words[q] != 0:
            for i in range(8 * q, 8 * q + 8):
                if flat[i] != 0:
                    y = i // w
                    xs[k] = i - y * w
                    ys[k] = y
                    k += 1
    for i in range(8 * words.shape[0], h * w):
        if flat[i] != 0:
            y = i // w
            xs[k] = i - y * w
            ys[k] = y
            k += 1
    return xs, ys


@njit(cache=True)
def _vote_rows(xs, ys, tab_cos, tab_sin, acc, n_start, n_stop):
    """Fill accumulator rows ``n_start .. n_stop - 1`` (angles) of ``acc`` (with its zero border)."""
    numrho = acc.shape[1] - 2
    off = (numrho - 1) // 2 + 1
    npts = xs.shape[0]
    idx = np.empty(npts, np.int32)
    hist = np.zeros((4, numrho + 2), np.int32)
    full = npts - npts % 4
    for n in range(n_start, n_stop):
        c = tab_cos[n]
        s = tab_sin[n]
        # float32 products and sum, then round half to even: OpenCV's cvRound(j * tabCos[n] + i * tabSin[n]);
        # this loop vectorises
        for k in range(npts):
            idx[k] = np.int32(np.rint(xs[k] * c + ys[k] * s)) + off
        # four interleaved histograms: neighbouring pixels hit the same bin, and a single histogram would make every
        # increment wait for the previous one
        hist[:] = 0
        for k in range(0, full, 4):
            hist[0, idx[k]] += 1
            hist[1, idx[k + 1]] += 1
            hist[2, idx[k + 2]] += 1
            hist[3, idx[k + 3]] += 1
        for k in range(full, npts):
            hist[0, idx[k]] += 1
        for r in range(numrho + 2):
            acc[n + 1, r] = hist[0, r] + hist[1, r] + hist[2, r] + hist[3, r]


@njit(cache=True)
def _vote_serial(xs, ys, tab_cos, tab_sin, numrho):
    """Accumulator with OpenCV's one-cell zero border, shape (numangle + 2, numrho + 2), int32; one thread."""
    numangle = tab_cos.shape[0]
    acc = np.zeros((numangle + 2, numrho + 2), np.int32)
    _vote_rows(xs, ys, tab_cos, tab_sin, acc, 0, numangle)
    return acc


@njit(cache=True, parallel=True)
def _vote_parallel(xs, ys, tab_cos, tab_sin, numrho, nchunks):
    """As ``_vote_serial``, with the angles split into ``nchunks`` blocks voted in parallel."""
    numangle = tab_cos.shape[0]
    acc = np.zeros((numangle + 2, numrho + 2), np.int32)
    nchunks = max(1, min(nchunks, numangle))
    for chunk in prange(nchunks):
        # each block owns whole accumulator rows, so threads never write to the same cell
        _vote_rows(xs, ys, tab_cos, tab_sin, acc, chunk * numangle // nchunks, (chunk + 1) * numangle // nchunks)
    return acc


@njit(cache=True)
def _is_peak(acc, n, r, threshold):
    """OpenCV's line cell: more than ``threshold`` votes, above the lower rho and angle neighbours, at least the
    higher ones."""
    v = acc[n, r]
    # the threshold test returns on its own, the function is not IR-inlined and callers branch on its result (and
    # keep their loops free of allocations): otherwise the scan of the accumulator runs 5-15x slower
    if v <= threshold:
        return False
    return v > acc[n, r - 1] and v >= acc[n, r + 1] and v > acc[n - 1, r] and v >= acc[n + 1, r]


@njit(cache=True)
def _peaks(acc, threshold):
    """Angle index, rho index and votes of OpenCV's local maxima, sorted like ``hough_cmp_gt``."""
    na = acc.shape[0] - 2
    nr = acc.shape[1] - 2
    width = np.int64(nr + 2)
    cells = np.int64(na + 2) * width
    # the cells above the threshold first (one plain scan into a buffer that could hold every cell; only the part
    # written is touched), then the neighbour test on those only
    candidates = np.empty(na * nr, np.int64)
    above = 0
    for n in range(1, na + 1):
        row = acc[n]
        # most angles of a drawing or a photo have no cell above the threshold: their row's maximum (a loop that
        # vectorizes) rules them out before the branchy scan
        top = np.int32(0)
        for r in range(1, nr + 1):
            top = max(top, row[r])
        if top <= threshold:
            continue
        for r in range(1, nr + 1):
            if row[r] > threshold:
                candidates[above] = n * width + r
                above += 1
    candidates = candidates[:above]
    bases = np.empty(above, np.int64)
    count = 0
    vmax = 0
    for b in candidates:
        n = b // width
        r = b - n * width
        if _is_peak(acc, n, r, threshold):
            bases[count] = b
            count += 1
            vmax = max(vmax, acc[n, r])
    # more votes first, then the smaller flat index (angle-major), as OpenCV's comparator: one int64 key per peak
    keys = np.empty(count, np.int64)
    for k in range(count):
        b = bases[k]
        keys[k] = np.int64(vmax - acc[b // width, b % width]) * cells + b
    keys.sort()
    ns = np.empty(count, np.int64)
    rs = np.empty(count, np.int64)
    votes = np.empty(count, np.int64)
    for k in range(count):
        b = keys[k] % cells
        ns[k] = b // width - 1
        rs[k] = b % width - 1
        votes[k] = acc[ns[k] + 1, rs[k] + 1]
    return ns, rs, votes


@njit(cache=True)
def _refine_fit(xs, ys, rhos, thetas, band, iterations):
    """Total-least-squares line through the edge pixels within ``band`` px of each line; (rho, theta) float64."""
    out_r = rhos.copy()
    out_t = thetas.copy()
    for i in range(rhos.shape[0]):
        rho, theta = rhos[i], thetas[i]
        for _ in range(iterations):
            c, s = math.cos(theta), math.sin(theta)
            cnt = 0
            sx = sy = 0.0
            for k in range(xs.shape[0]):
                if abs(xs[k] * c + ys[k] * s - rho) <= band:
                    cnt += 1
                    sx += xs[k]
                    sy += ys[k]
            if cnt < 3:
                break
            mx, my = sx / cnt, sy / cnt
            cxx = cyy = cxy = 0.0
            for k in range(xs.shape[0]):
                if abs(xs[k] * c + ys[k] * s - rho) <= band:
                    dx, dy = xs[k] - mx, ys[k] - my
                    cxx += dx * dx
                    cyy += dy * dy
                    cxy += dx * dy
            # the normal is the eigenvector of the smaller eigenvalue of the scatter matrix
            phi = 0.5 * math.atan2(2.0 * cxy, cxx - cyy)  # direction of the line
            new_t = phi + 0.5 * math.pi
            # keep the normal on the side of the detected one, then bring theta into [0, pi)
            if math.cos(new_t - theta) < 0:
                new_t += math.pi
            new_r = mx * math.cos(new_t) + my * math.sin(new_t)
            new_t = new_t % (2.0 * math.pi)
            if new_t >= math.pi:
                new_t -= math.pi
                new_r = -new_r
            rho, theta = new_r, new_t
        out_r[i] = rho
        out_t[i] = theta
    return out_r, out_t


@njit(cache=True)
def _ppht(edges, order, tab_cos, tab_sin, numrho, threshold, min_length, max_gap, max_lines):
    """Progressive probabilistic Hough transform; returns (K, 4) int32 segments x1, y1, x2, y2."""
    h, w = edges.shape
    numangle = tab_cos.shape[0]
    acc = np.zeros((numangle, numrho), np.int32)
    mask = np.zeros((h, w), np.uint8)
    voted = np.zeros((h, w), np.uint8)
    xs = np.empty(order.shape[0], np.int64)
    ys = np.empty(order.shape[0], np.int64)
    k = 0
    for i in range(h):
        for j in range(w):
            if edges[i, j] != 0:
                mask[i, j] = 1
                xs[k] = j
                ys[k] = i
                k += 1
    off = (numrho - 1) // 2
    out = np.empty((max_lines, 4), np.int32)
    nout = 0
    ends = np.empty((2, 2), np.int64)
    tend = np.zeros(2, np.int64)
    for idx in order:
        x = xs[idx]
        y = ys[idx]
        if mask[y, x] == 0:
            continue
        fx = np.float32(x)
        fy = np.float32(y)
        best = threshold - 1
        best_n = -1
        for n in range(numangle):
            r = np.int64(np.rint(fx * tab_cos[n] + fy * tab_sin[n])) + off
            acc[n, r] += 1
            if acc[n, r] > best:
                best = acc[n, r]
                best_n = n
        voted[y, x] = 1
        if best_n < 0:
            continue
        # direction along the line: perpendicular to the normal (cos, sin); step one pixel on the major axis
        dx0 = -np.float64(tab_sin[best_n])
        dy0 = np.float64(tab_cos[best_n])
        if abs(dx0) >= abs(dy0):
            sx, sy = 1.0 if dx0 > 0 else -1.0, dy0 / abs(dx0)
        else:
            sx, sy = dx0 / abs(dy0), 1.0 if dy0 > 0 else -1.0
        for side in range(2):
            sgn = 1.0 if side == 0 else -1.0
            gap = 0
            ends[side, 0] = x
            ends[side, 1] = y
            tend[side] = 0
            t = 1
            while True:
                px = int(math.floor(x + sgn * sx * t + 0.5))
                py = int(math.floor(y + sgn * sy * t + 0.5))
                if px < 0 or px >= w or py < 0 or py >= h:
                    break
                if mask[py, px] != 0:
                    gap = 0
                    ends[side, 0] = px
                    ends[side, 1] = py
                    tend[side] = t
                else:
                    gap += 1
                    if gap > max_gap:
                        break
                t += 1
        good = max(abs(ends[1, 0] - ends[0, 0]), abs(ends[1, 1] - ends[0, 1])) >= min_length
        # clear the pixels of the walked segment; a kept segment also takes back their votes
        for side in range(2):
            sgn = 1.0 if side == 0 else -1.0
            for t in range(0 if side == 0 else 1, tend[side] + 1):
                px = int(math.floor(x + sgn * sx * t + 0.5))
                py = int(math.floor(y + sgn * sy * t + 0.5))
                if mask[py, px] != 0:
                    if good and voted[py, px] != 0:
                        qx = np.float32(px)
                        qy = np.float32(py)
                        for n in range(numangle):
                            r = np.int64(np.rint(qx * tab_cos[n] + qy * tab_sin[n])) + off
                            acc[n, r] -= 1
                        voted[py, px] = 0
                    mask[py, px] = 0
        if good:
            out[nout, 0] = ends[0, 0]
            out[nout, 1] = ends[0, 1]
            out[nout, 2] = ends[1, 0]
            out[nout, 3] = ends[1, 1]
            nout += 1
            if nout == max_lines:
                break
    return out[:nout].copy()
