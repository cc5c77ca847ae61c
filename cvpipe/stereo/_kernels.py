"""The numba kernels of semi-global matching (:func:`cvpipe.stereo.sgm.disparity_sgm` validates, documents and calls
them): census cost volume, path aggregation, winner-take-all with the left-right check, speckle removal and the
background fill. They only compute: the checks live in the public functions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..homography._kernels import _SYM6, _jacobi_eigh  # the symmetric 9x9 eigen-solver, shared with the homography
from ..robust.sampling import sample_distinct

#: "infinite" path cost in the int16 path buffers; real path costs stay <= 255 + P2 <= 4351 (checked in disparity_sgm),
#: so _BIG + P1 cannot overflow int16 and _BIG never wins a minimum
_BIG = 16000


@njit(cache=True, inline="always")
def _census_row(padded, y, ry, rx, row, byte):  # pragma: no cover - compiled
    """Census signatures of row ``y`` of an image padded by (ry, rx) into ``row`` (W,) uint64: bit set where the
    neighbour is darker than the centre, neighbours in row-major order without the centre, the first in the highest
    bit. ``byte`` is a (W,) uint8 buffer.

    Eight neighbours at a time are gathered in ``byte`` in 8-bit lanes and shifted into the signatures together:
    the same bits as one neighbour at a time in 64-bit lanes, 3x faster (teddy: 1.2 -> 0.4 ms for both images).
    """
    w = row.shape[0]
    centre = padded[y + ry, rx:rx + w]
    for x in range(w):
        row[x] = 0
    k = 0  # neighbours gathered in ``byte``
    for dy in range(2 * ry + 1):
        for dx in range(2 * rx + 1):
            if dy == ry and dx == rx:
                continue
            nb = padded[y + dy, dx:dx + w]
            if k == 0:
                for x in range(w):
                    byte[x] = np.uint8(nb[x] < centre[x])
            else:
                for x in range(w):
                    byte[x] = np.uint8(np.uint8(byte[x] << np.uint8(1)) | np.uint8(nb[x] < centre[x]))
            k += 1
            if k == 8:
                for x in range(w):
                    row[x] = (row[x] << np.uint64(8)) | np.uint64(byte[x])
                k = 0
    if k > 0:
        for x in range(w):
            row[x] = (row[x] << np.uint64(k)) | np.uint64(byte[x])


@njit(cache=True, inline="always")
def _popcount(v):  # pragma: no cover - compiled
    v = v - ((v >> np.uint64(1)) & np.uint64(0x5555555555555555))
    v = (v & np.uint64(0x3333333333333333)) + ((v >> np.uint64(2)) & np.uint64(0x3333333333333333))
    v = (v + (v >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return (v * np.uint64(0x0101010101010101)) >> np.uint64(56)


@njit(cache=True, parallel=True)
def _cost_volume(pad_l, pad_r, ry, rx, planes_l, planes_r, ad_cap, ad_mult, invalid_cost, cost):  # pragma: no cover
    """Fill ``cost`` (H, W, D) uint8 with the matching cost: census Hamming distance
    + (min(sum_c |L_c - R_c|, ad_cap) * ad_mult) >> 16, and ``invalid_cost`` where x - d < 0.

    ``pad_*`` are the gray images padded by (ry, rx) for the census window; each row's census signatures are
    computed where they are used (one parallel launch, no census images in memory).

    ``planes_*`` are the (H, W, C) uint8 images; ``ad_mult`` = 0 skips the absolute-difference term. The right
    image's rows are reversed once so that the candidates x - d, d = 0, 1, ... of a pixel are consecutive forward,
    which LLVM vectorizes (a negative index expression would need numba's wraparound check).
    """
    h, w, max_disp = cost.shape
    nch = planes_l.shape[2]
    for y in prange(h):
        cen_l = np.empty(w, np.uint64)
        cen_r = np.empty(w, np.uint64)
        byte = np.empty(w, np.uint8)
        _census_row(pad_l, y, ry, rx, cen_l, byte)
        _census_row(pad_r, y, ry, rx, cen_r, byte)
        rev = cen_r[::-1].copy()
        rev_planes = np.empty((nch, w), np.int32)
        for c in range(nch):
            for i in range(w):
                rev_planes[c, i] = planes_r[y, w - 1 - i, c]
        adsum = np.zeros(max_disp, np.int32)
        for x in range(w):
            cl = cen_l[x]
            nd = min(max_disp, x + 1)
            # unsigned indices: a signed base + d would cost numba's wraparound test per load (no per-pixel views,
            # which cost two atomic reference-count updates each)
            base = np.uint64(w - 1 - x)
            # the AD term in int32 throughout (numba widens int32 arithmetic to int64, so every step is cast back):
            # in int64 lanes, with a 64-bit multiply, the colour loop took 5.1 ms on teddy instead of 4.5 ms.
            # ad_cap * ad_mult < 2**24 (disparity_sgm keeps the cost <= 255), so the product fits
            if ad_mult > 0 and nch == 3:
                # colour: the whole cost in one loop (the common case; about 20 % faster than a loop per channel)
                l0 = np.int32(planes_l[y, x, 0])
                l1 = np.int32(planes_l[y, x, 1])
                l2 = np.int32(planes_l[y, x, 2])
                for d in range(nd):
                    i = base + np.uint64(d)
                    a0 = np.int32(abs(np.int32(l0 - rev_planes[0, i])))
                    a1 = np.int32(abs(np.int32(l1 - rev_planes[1, i])))
                    a2 = np.int32(abs(np.int32(l2 - rev_planes[2, i])))
                    ad = np.int32(min(np.int32(np.int32(a0 + a1) + a2), ad_cap))
                    cost[y, x, d] = np.uint8(np.uint8(_popcount(cl ^ rev[i])) + np.uint8(np.int32(ad * ad_mult) >> 16))
            else:
                for d in range(nd):
                    cost[y, x, d] = np.uint8(_popcount(cl ^ rev[base + np.uint64(d)]))
                if ad_mult > 0:
                    for d in range(nd):
                        adsum[d] = 0
                    for c in range(nch):
                        lv = np.int32(planes_l[y, x, c])
                        for d in range(nd):
                            adsum[d] += np.int32(abs(np.int32(lv - rev_planes[c, base + np.uint64(d)])))
                    for d in range(nd):
                        cost[y, x, d] += np.uint8(np.int32(np.int32(min(adsum[d], ad_cap)) * ad_mult) >> 16)
            for d in range(nd, max_disp):
                cost[y, x, d] = invalid_cost
    return cost


# The kernels below index whole arrays with loop-invariant leading indices (buf[x, d]) instead of taking per-pixel
# views (buf[x]): a view costs numba two atomic reference-count updates, which dominated the runtime. Previous and
# current path costs live in distinct arrays (swapped, not offset), else LLVM cannot prove the loops independent.


@njit(cache=True, inline="always")
def _path_start(cost, y, x, cur, cx):  # pragma: no cover - compiled
    """First pixel of a path: L_r = C; returns min_d L_r."""
    m = np.int16(_BIG)
    for d in range(cost.shape[2]):
        v = np.int16(cost[y, x, d])
        cur[cx, d + 1] = v
        m = min(m, v)
    return m


@njit(cache=True, inline="always")
def _path_step(prev, px, mprev, cost, y, x, p1, p2e, cur, cx):  # pragma: no cover - compiled
    """One SGM recursion step from prev[px] to cur[cx] (int16, L_r at 1..D, _BIG at 0 and D + 1).

    L_r(p, d) = C(p, d) + min(L_r(p-r, d), L_r(p-r, d+-1) + P1, min_k L_r(p-r, k) + P2') - min_k L_r(p-r, k).
    Returns min_d L_r(p, d). Every intermediate is cast back to int16 so that LLVM vectorizes the loops 16 or 32
    lanes wide (the first loop has no reduction, the second no dependency on the padded neighbours).
    """
    jump = np.int16(mprev + p2e)
    nd = cost.shape[2]
    for d in range(nd):
        v = np.int16(min(np.int16(min(prev[px, d], prev[px, d + 2]) + p1), prev[px, d + 1]))
        cur[cx, d + 1] = np.int16(np.int16(cost[y, x, d]) + np.int16(min(v, jump)) - mprev)
    m = np.int16(_BIG)
    for d in range(1, nd + 1):
        m = min(m, cur[cx, d])
    return m


@njit(cache=True, inline="always")
def _sum_paths(cur, nk, w, y, x, out):  # pragma: no cover - compiled
    """``out[y, x] = sum_k cur[k * w + x]`` over the ``nk`` directions of a sweep."""
    nd = out.shape[2]
    for d in range(nd):
        out[y, x, d] = np.uint16(cur[x, d + 1])
    for k in range(1, nk):
        for d in range(nd):
            out[y, x, d] += np.uint16(cur[k * w + x, d + 1])


@njit(cache=True)
def _sweep(cost, gray, dy, nk, p1, p2_lut, out):  # pragma: no cover - compiled
    """Store in ``out`` the sum of the path costs arriving from the previous row, sweeping rows in order ``dy``:
    directions (dy, dx) for dx in (-1, 0, 1) when ``nk`` = 3, or (dy, 0) when ``nk`` = 1.

    The previous row's path costs stay in cache-sized row buffers, so the volumes are read once and written once
    per sweep instead of once per direction.
    """
    h, w, nd = cost.shape
    # [k * w + x, 1 + d], rows for three directions whatever ``nk``: with ``nk * w`` rows the interior loop below
    # ran 2.8x slower (LLVM no longer separates the three directions' rows)
    prev = np.full((3 * w, nd + 2), _BIG, np.int16)
    cur = np.full((3 * w, nd + 2), _BIG, np.int16)
    mprev = np.zeros(3 * w, np.int16)
    mcur = np.zeros(3 * w, np.int16)
    for s in range(h):
        y = s if dy > 0 else h - 1 - s
        if s == 0:
            for x in range(w):
                for k in range(nk):
                    mcur[k * w + x] = _path_start(cost, y, x, cur, k * w + x)
                _sum_paths(cur, nk, w, y, x, out)
        elif nk == 1:
            for x in range(w):
                p2e = p2_lut[abs(np.int32(gray[y, x]) - np.int32(gray[y - dy, x]))]
                mcur[x] = _path_step(prev, x, mprev[x], cost, y, x, p1, p2e, cur, x)
                _sum_paths(cur, 1, w, y, x, out)
        else:
            # the interior columns, where all three previous pixels exist: no bounds test (a conditional dx or a
            # per-pixel bounds test made these loops 2-3x slower). The three directions' steps (_path_step's
            # recursion) and their sum share one loop over the disparities: with a loop per direction, per pixel,
            # entering the loops cost more than their arithmetic (at 16 disparities this loop is 2.6x faster)
            for x in range(1, w - 1):
                g = np.int32(gray[y, x])
                qa = p2_lut[abs(g - np.int32(gray[y - dy, x + 1]))]
                qb = p2_lut[abs(g - np.int32(gray[y - dy, x]))]
                qc = p2_lut[abs(g - np.int32(gray[y - dy, x - 1]))]
                ia = x + 1
                ib = w + x
                ic = 2 * w + x - 1
                ma = mprev[ia]
                mb = mprev[ib]
                mc = mprev[ic]
                ja = np.int16(qa + ma)
                jb = np.int16(qb + mb)
                jc = np.int16(qc + mc)
                for d in range(nd):
                    c = np.int16(cost[y, x, d])
                    va = np.int16(min(np.int16(min(prev[ia, d], prev[ia, d + 2]) + p1), prev[ia, d + 1]))
                    va = np.int16(c + np.int16(min(va, ja)) - ma)
                    vb = np.int16(min(np.int16(min(prev[ib, d], prev[ib, d + 2]) + p1), prev[ib, d + 1]))
                    vb = np.int16(c + np.int16(min(vb, jb)) - mb)
                    vc = np.int16(min(np.int16(min(prev[ic, d], prev[ic, d + 2]) + p1), prev[ic, d + 1]))
                    vc = np.int16(c + np.int16(min(vc, jc)) - mc)
                    cur[x, d + 1] = va
                    cur[w + x, d + 1] = vb
                    cur[2 * w + x, d + 1] = vc
                    out[y, x, d] = np.uint16(va) + np.uint16(vb) + np.uint16(vc)
                m0 = np.int16(_BIG)
                m1 = np.int16(_BIG)
                m2 = np.int16(_BIG)
                for d in range(1, nd + 1):
                    m0 = min(m0, cur[x, d])
                    m1 = min(m1, cur[w + x, d])
                    m2 = min(m2, cur[2 * w + x, d])
                mcur[x] = m0
                mcur[w + x] = m1
                mcur[2 * w + x] = m2
            for x in (0, w - 1):
                g = np.int32(gray[y, x])
                for k in range(3):
                    px = x - (k - 1)
                    if px < 0 or px >= w:
                        mcur[k * w + x] = _path_start(cost, y, x, cur, k * w + x)
                    else:
                        p2e = p2_lut[abs(g - np.int32(gray[y - dy, px]))]
                        mcur[k * w + x] = _path_step(prev, k * w + px, mprev[k * w + px], cost, y, x, p1, p2e,
                                                     cur, k * w + x)
                _sum_paths(cur, 3, w, y, x, out)
        prev, cur = cur, prev
        mprev, mcur = mcur, mprev


@njit(cache=True, parallel=True)
def _aggregate(cost, gray, nk, p1, p2_lut, down, up):  # pragma: no cover - compiled
    """Path costs of the row-to-row directions into two (H, W, D) uint16 volumes: ``down`` and ``up``, whose sweeps
    (``nk`` directions each, see :func:`_sweep`) run in parallel. The horizontal paths are added row by row in
    :func:`_winner`, while the row is in cache.
    """
    for i in prange(2):
        if i == 0:
            _sweep(cost, gray, 1, nk, p1, p2_lut, down)
        else:
            _sweep(cost, gray, -1, nk, p1, p2_lut, up)


@njit(cache=True, parallel=True)
def _winner(cost, down, up, gray, p1, p2_lut, uniqueness, subpixel, lr_max_diff):  # pragma: no cover - compiled
    """Add the two horizontal paths of every row to ``down`` + ``up`` into the row's aggregated cost S (W, D), and
    take its winner-take-all disparities: the left image's (float32, -1 = rejected) and the right image's (int32),
    without writing S back to memory; then the left-right check of the row (``lr_max_diff`` < 0 disables it).

    A horizontal path is a chain of dependent steps, so each thread runs four of them at once (two rows, both
    directions), which keeps the core busy while each step waits for the previous one.
    """
    h, w, nd = cost.shape
    disp = np.empty((h, w), np.float32)
    disp_r = np.zeros((h, w), np.int32)
    for i in prange((h + 1) // 2):
        y0 = 2 * i
        y1 = min(y0 + 1, h - 1)  # the last row of an odd height is done twice, identically
        srow = np.empty((2, w, nd), np.uint16)
        la = np.full((4, nd + 2), _BIG, np.int16)  # path buffers: L->R row 0, L->R row 1, R->L row 0, R->L row 1
        lb = np.full((4, nd + 2), _BIG, np.int16)
        for j in range(2):
            y = y0 if j == 0 else y1
            for x in range(w):
                for d in range(nd):
                    srow[j, x, d] = down[y, x, d] + up[y, x, d]
        m0 = _path_start(cost, y0, 0, la, 0)
        m1 = _path_start(cost, y1, 0, la, 1)
        m2 = _path_start(cost, y0, w - 1, la, 2)
        m3 = _path_start(cost, y1, w - 1, la, 3)
        for d in range(nd):
            srow[0, 0, d] += np.uint16(la[0, d + 1])
            srow[1, 0, d] += np.uint16(la[1, d + 1])
            srow[0, w - 1, d] += np.uint16(la[2, d + 1])
            srow[1, w - 1, d] += np.uint16(la[3, d + 1])
        for x in range(1, w):
            xr = w - 1 - x
            q0 = p2_lut[abs(np.int32(gray[y0, x]) - np.int32(gray[y0, x - 1]))]
            q1 = p2_lut[abs(np.int32(gray[y1, x]) - np.int32(gray[y1, x - 1]))]
            q2 = p2_lut[abs(np.int32(gray[y0, xr]) - np.int32(gray[y0, xr + 1]))]
            q3 = p2_lut[abs(np.int32(gray[y1, xr]) - np.int32(gray[y1, xr + 1]))]
            m0 = _path_step(la, 0, m0, cost, y0, x, p1, q0, lb, 0)
            m1 = _path_step(la, 1, m1, cost, y1, x, p1, q1, lb, 1)
            m2 = _path_step(la, 2, m2, cost, y0, xr, p1, q2, lb, 2)
            m3 = _path_step(la, 3, m3, cost, y1, xr, p1, q3, lb, 3)
            for d in range(nd):
                srow[0, x, d] += np.uint16(lb[0, d + 1])
                srow[1, x, d] += np.uint16(lb[1, d + 1])
            for d in range(nd):
                srow[0, xr, d] += np.uint16(lb[2, d + 1])
                srow[1, xr, d] += np.uint16(lb[3, d + 1])
            la, lb = lb, la
        _winner_row(srow[0], y0, uniqueness, subpixel, disp, disp_r)
        _winner_row(srow[1], y1, uniqueness, subpixel, disp, disp_r)
        if lr_max_diff >= 0:
            _lr_check_row(disp, disp_r, y0, lr_max_diff)
            if y1 != y0:
                _lr_check_row(disp, disp_r, y1, lr_max_diff)
    return disp, disp_r


@njit(cache=True, inline="always")
def _winner_row(srow, y, uniqueness, subpixel, disp, disp_r):  # pragma: no cover - compiled
    """Winner-take-all of row ``y`` from its aggregated cost ``srow`` (W, D), into ``disp`` and ``disp_r``.

    Left image: the first (smallest) d with the least cost among d <= x. Right image: D_R(xr) = argmin_d
    S(xr + d, d), gathered while scanning the left pixels: pixel x offers d to xr = x - d, and these candidates are
    kept reversed (index w - 1 - xr = w - 1 - x + d) so that they are contiguous in d. A left pixel is rejected
    when a disparity more than one step from the winner costs less than (1 + uniqueness) times the winner's cost.
    """
    w, nd = srow.shape
    best_r = np.full(w, 65535, np.uint16)
    arg_r = np.zeros(w, np.int32)
    for x in range(w):
        n = min(nd, x + 1)
        m = np.uint16(65535)
        for d in range(n):
            m = min(m, srow[x, d])
        bd = 0
        for d in range(n):
            if srow[x, d] == m:
                bd = d
                break
        # unsigned index: a signed base + d costs a wraparound test that stops LLVM from vectorizing
        base = np.uint64(w - 1 - x)
        for d in range(n):
            i = base + np.uint64(d)
            v = srow[x, d]
            better = v < best_r[i]
            best_r[i] = v if better else best_r[i]
            arg_r[i] = d if better else arg_r[i]
        if uniqueness > 0:
            limit = m * (1.0 + uniqueness)
            rejected = False
            for d in range(n):
                if (d < bd - 1 or d > bd + 1) and srow[x, d] < limit:
                    rejected = True
            if rejected:
                disp[y, x] = -1.0
                continue
        dv = np.float32(bd)
        if subpixel and 0 < bd < n - 1:
            cm = np.float64(srow[x, bd - 1])
            cp = np.float64(srow[x, bd + 1])
            den = cm - 2.0 * np.float64(m) + cp
            if den > 0:
                dv = np.float32(bd + 0.5 * (cm - cp) / den)
        disp[y, x] = dv
    for xr in range(w):
        disp_r[y, xr] = arg_r[w - 1 - xr]


@njit(cache=True, inline="always")
def _lr_check_row(disp, disp_r, y, max_diff):  # pragma: no cover - compiled
    """Reject (set to -1) the left disparities of row ``y`` that the right image's disparity does not confirm within
    ``max_diff``.

    Both integer neighbours of the sub-pixel disparity d are tried (floor and ceil, each compared with the right
    image's disparity at x minus itself); the pixel is kept when either agrees, so sub-pixel refinement does not
    count against the check.
    """
    w = disp.shape[1]
    for x in range(w):
        d = disp[y, x]
        if d < 0:
            continue
        lo = int(d)
        hi = lo + 1 if d > lo else lo
        ok_lo = x - lo >= 0 and abs(lo - disp_r[y, x - lo]) <= max_diff
        ok_hi = x - hi >= 0 and abs(hi - disp_r[y, x - hi]) <= max_diff
        if not (ok_lo or ok_hi):
            disp[y, x] = -1.0


@njit(cache=True, inline="always")
def _find_root(parent, i):  # pragma: no cover - compiled
    """Root of ``i`` in the union-find forest ``parent``, compressing the path on the way."""
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@njit(cache=True)
def _remove_speckles(disp, max_size, max_jump):  # pragma: no cover - compiled
    """Reject 4-connected regions (neighbours within ``max_jump`` px of each other) smaller than ``max_size`` px.

    One pass over the rows labels runs (consecutive accepted pixels of a row, each within ``max_jump`` of its left
    neighbour) and joins each run to the runs above it that it touches within ``max_jump``, in a union-find forest
    whose roots count their regions' pixels; a second pass rejects the pixels of small regions. The regions are
    those of a flood fill, in sequential memory order (about 2x faster than a flood fill's stack).
    """
    h, w = disp.shape
    run = np.empty((h, w), np.int32)
    parent = np.empty(h * w, np.int32)
    size = np.empty(h * w, np.int32)  # pixels of a region, valid at its root
    n = 0
    for y in range(h):
        r = -1  # the current run, -1 after a rejected pixel
        root = -1  # its root: only this row's joins of this run can change it while the run lasts
        left = np.float32(-1.0)
        last_r = -1  # the last pair of runs joined on this row: a run touches the same run above over many pixels
        last_b = -1
        for x in range(w):
            d = disp[y, x]
            if d < 0:
                run[y, x] = -1
                r = -1
                left = d
                continue
            if r < 0 or abs(d - left) > max_jump:
                r = n
                root = n
                parent[n] = n
                size[n] = 0
                n += 1
            size[root] += 1
            run[y, x] = r
            left = d
            if y > 0:
                b = run[y - 1, x]
                if b >= 0 and not (r == last_r and b == last_b) and abs(d - disp[y - 1, x]) <= max_jump:
                    last_r = r
                    last_b = b
                    rb = _find_root(parent, b)
                    if rb > root:
                        parent[rb] = root
                        size[root] += size[rb]
                    elif rb < root:
                        parent[root] = rb
                        size[rb] += size[root]
                        root = rb
    small = np.empty(n, np.bool_)
    for i in range(n):
        small[i] = size[_find_root(parent, i)] < max_size
    for y in range(h):
        for x in range(w):
            r = run[y, x]
            if r >= 0 and small[r]:
                disp[y, x] = -1.0


@njit(cache=True, parallel=True)
def _fill_background(disp):  # pragma: no cover - compiled
    """Fill rejected pixels from the nearest accepted pixels left and right on the row, taking the smaller (farther,
    background) disparity, as occlusions belong to the background (Hirschmueller 2008, section 3.4)."""
    h, w = disp.shape
    out = disp.copy()
    for y in prange(h):
        for x in range(w):
            if disp[y, x] >= 0:
                continue
            left = np.float32(-1.0)
            for xx in range(x - 1, -1, -1):
                if disp[y, xx] >= 0:
                    left = disp[y, xx]
                    break
            right = np.float32(-1.0)
            for xx in range(x + 1, w):
                if disp[y, xx] >= 0:
                    right = disp[y, xx]
                    break
            if left >= 0 and right >= 0:
                out[y, x] = min(left, right)
            elif left >= 0:
                out[y, x] = left
            elif right >= 0:
                out[y, x] = right
    return out


# ------------------------------------------------------------------------------------------------------------------
# The fundamental matrix (:func:`cvpipe.stereo.epipolar.find_fundamental` validates, documents and calls them): the
# Sampson distance and the MSAC cost of a model, the 7-point solver and the scoring of a batch of samples, the
# weighted normalized 8-point solve from its accumulated 9x9 normal matrix, the rank-2 projection, and the
# reweighting rounds of the final refinement. Models are (3, 3) arrays in pixel coordinates (``x2^T F x1 = 0``)
# unless named ``Fn`` (Hartley-normalized coordinates, ``F = T2^T Fn T1``). Failures are status codes, never raised.

#: smallest 7th pivot / 1st pivot of the eliminated 7x9 epipolar system (normalized coordinates) for a sample to
#: count as regular (a repeated or collinear sample has rank below 7)
_RANK_EPS = 1e-9
#: a 7-point cubic whose leading coefficient is below this share of its largest one is skipped (F2 is a solution)
_CUBIC_EPS = 1e-10
#: the final refit weighs every correspondence by Tukey's biweight with at most this cut-off (in units of the
#: threshold), as the homography's final refinement does: real matches have heavier tails than the threshold assumes
_FINAL_WSCALE = 2.0
#: ...and within it the cut-off is Tukey's 4.685 sigma (95 % efficiency under Gaussian noise) of the inliers' noise
#: scale, ``sigma = 1.4826 * median`` of their Sampson distances. SIFT matches are heavy-tailed (on the Middlebury
#: pairs the 90th percentile of the true residuals is 4 sigma, not 1.6), so a cut-off at the noise scale rather
#: than at the threshold takes the tail's pull off the fit. ``_MIN_C`` keeps it from collapsing on exact data
_TUKEY_C = 4.685
_MAD_TO_SIGMA = 1.4826
_MIN_C = 0.05
#: rounds of Sampson-reweighted 8-point refitting of the final model
_REFINE_ROUNDS = 10
#: ...which stop early once a round moves the unit null vector of the 8-point system by less than this
#: (``1 - |v . v_prev|``, about half the squared angle between them)
_REFINE_TOL = 1e-12
#: status of the 8-point solve: solved, fewer than 8 correspondences, rank-deficient normal matrix
FM_OK = 0
FM_TOO_FEW = 1
FM_RANK_DEFICIENT = 2


@njit(cache=True, error_model="numpy")
def _epi(F, x, y, u, v):  # pragma: no cover - compiled
    """(``x2^T F x1``, the squared norm of the first two entries of ``F x1`` and of ``F^T x2``) for x1 = (x, y, 1),
    x2 = (u, v, 1): the Sampson distance is ``|num| / sqrt(den)``."""
    a0 = F[0, 0] * x + F[0, 1] * y + F[0, 2]
    a1 = F[1, 0] * x + F[1, 1] * y + F[1, 2]
    a2 = F[2, 0] * x + F[2, 1] * y + F[2, 2]
    b0 = F[0, 0] * u + F[1, 0] * v + F[2, 0]
    b1 = F[0, 1] * u + F[1, 1] * v + F[2, 1]
    return u * a0 + v * a1 + a2, a0 * a0 + a1 * a1 + b0 * b0 + b1 * b1


@njit(cache=True, error_model="numpy")
def sampson_distances(Fs, p1, p2, out):  # pragma: no cover - compiled
    """``out[m, i]``: Sampson distance of correspondence i under ``Fs[m]`` (inf where the gradient vanishes)."""
    for m in range(Fs.shape[0]):
        F = Fs[m]
        for i in range(p1.shape[0]):
            num, den = _epi(F, p1[i, 0], p1[i, 1], p2[i, 0], p2[i, 1])
            out[m, i] = abs(num) / np.sqrt(den) if den > 0.0 else np.inf
    return out


#: correspondences per block of the MSAC cost: the sum within a block is vectorized, the early exit is tested
#: between blocks
_COST_BLOCK = 64


@njit(cache=True, error_model="numpy")
def _truncated_sampson(f00, f01, f02, f10, f11, f12, f20, f21, f22, x, y, u, v, thr2):  # pragma: no cover
    """``min(d^2, thr2)`` of one correspondence, d its Sampson distance under F (inf when undefined)."""
    a0 = f00 * x + f01 * y + f02
    a1 = f10 * x + f11 * y + f12
    a2 = f20 * x + f21 * y + f22
    b0 = f00 * u + f10 * v + f20
    b1 = f01 * u + f11 * v + f21
    num = u * a0 + v * a1 + a2
    den = a0 * a0 + a1 * a1 + b0 * b0 + b1 * b1
    e = num * num / den if den > 0.0 else np.inf
    return e if e <= thr2 else thr2


@njit(cache=True, error_model="numpy")
def _msac_block(F, q, thr2, start, stop, buf):  # pragma: no cover - compiled
    """``sum_i min(d_i^2, thr2)`` for i in [start, stop) (``buf``: scratch of at least ``_COST_BLOCK``).

    The terms go to ``buf`` in one loop over the rows of ``q`` that the compiler runs on SIMD lanes, then they are
    added in four interleaved partial sums in a fixed order: the sum is the same on every CPU."""
    f00, f01, f02 = F[0, 0], F[0, 1], F[0, 2]
    f10, f11, f12 = F[1, 0], F[1, 1], F[1, 2]
    f20, f21, f22 = F[2, 0], F[2, 1], F[2, 2]
    x1, y1, x2, y2 = q[0], q[1], q[2], q[3]
    m = stop - start
    for j in range(m):
        i = start + j
        buf[j] = _truncated_sampson(f00, f01, f02, f10, f11, f12, f20, f21, f22, x1[i], y1[i], x2[i], y2[i], thr2)
    c0 = c1 = c2 = c3 = 0.0
    full = m - m % 4
    for j in range(0, full, 4):
        c0 += buf[j]
        c1 += buf[j + 1]
        c2 += buf[j + 2]
        c3 += buf[j + 3]
    for j in range(full, m):
        c0 += buf[j]
    return (c0 + c1) + (c2 + c3)


@njit(cache=True, error_model="numpy")
def _msac_from(F, q, thr2, block, cost, bail, buf):  # pragma: no cover - compiled
    """The MSAC cost of F given ``cost``, the sum over the blocks before ``block``; inf as soon as the partial sum
    exceeds ``bail``."""
    n = q.shape[1]
    for start in range(block * _COST_BLOCK, n, _COST_BLOCK):
        cost += _msac_block(F, q, thr2, start, min(start + _COST_BLOCK, n), buf)
        if cost > bail:
            return np.inf
    return cost


@njit(cache=True, error_model="numpy")
def msac_cost(F, q, thr2, bail):  # pragma: no cover - compiled
    """``sum_i min(d_i^2, thr2)`` over the Sampson distances d of F (summed by blocks of ``_COST_BLOCK``); inf as
    soon as the partial sum exceeds ``bail`` (then F cannot be among the models the caller keeps; ``bail = inf``
    gives the plain cost). ``q``: (4, N) rows x1, y1, x2, y2 of the correspondences."""
    return _msac_from(F, q, thr2, 0, 0.0, bail, np.empty(_COST_BLOCK))


@njit(cache=True, error_model="numpy")
def count_within(F, q, thr2, mask):  # pragma: no cover - compiled
    """``mask[i]``: squared Sampson distance of i under F at most ``thr2`` (``q`` as for :func:`msac_cost`);
    returns the count."""
    x1, y1, x2, y2 = q[0], q[1], q[2], q[3]
    for i in range(q.shape[1]):
        num, den = _epi(F, x1[i], y1[i], x2[i], y2[i])
        mask[i] = (num * num / den if den > 0.0 else np.inf) <= thr2
    count = 0
    for i in range(q.shape[1]):
        count += mask[i]
    return count


@njit(cache=True, error_model="numpy")
def _matmul3(A, B, out):  # pragma: no cover - compiled
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]


@njit(cache=True, error_model="numpy")
def denormalize(Fn, T1, T2, tmp, F):  # pragma: no cover - compiled
    """``F = T2^T Fn T1`` (``tmp``: 3x3 scratch)."""
    _matmul3(Fn, T1, tmp)
    for i in range(3):
        for j in range(3):
            F[i, j] = T2[0, i] * tmp[0, j] + T2[1, i] * tmp[1, j] + T2[2, i] * tmp[2, j]


@njit(cache=True, error_model="numpy")
def unit(F):  # pragma: no cover - compiled
    """Scale F in place to unit Frobenius norm with its largest entry (the first in row-major order) positive."""
    s = 0.0
    for i in range(3):
        for j in range(3):
            s += F[i, j] * F[i, j]
    s = math.sqrt(s)
    big = -1.0
    sign = 1.0
    for i in range(3):
        for j in range(3):
            F[i, j] /= s
            if abs(F[i, j]) > big:
                big = abs(F[i, j])
                sign = 1.0 if F[i, j] >= 0.0 else -1.0
    if sign < 0.0:
        for i in range(3):
            for j in range(3):
                F[i, j] = -F[i, j]


@njit(cache=True, error_model="numpy")
def _rank2(F):  # pragma: no cover - compiled
    """Project F in place onto the closest rank-2 matrix (Frobenius): ``F - F v v^T`` with v the right singular
    vector of the smallest singular value (the eigenvector of ``F^T F`` of its smallest eigenvalue)."""
    G = np.empty((3, 3))
    W = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            G[i, j] = F[0, i] * F[0, j] + F[1, i] * F[1, j] + F[2, i] * F[2, j]
    _jacobi_eigh(G, W)
    v0, v1, v2 = W[0, 0], W[1, 0], W[2, 0]
    for i in range(3):
        f = F[i, 0] * v0 + F[i, 1] * v1 + F[i, 2] * v2
        F[i, 0] -= f * v0
        F[i, 1] -= f * v1
        F[i, 2] -= f * v2


@njit(cache=True, error_model="numpy")
def _smallest_warm(M, V):  # pragma: no cover - compiled
    """The eigenvector of the smallest eigenvalue of the symmetric 9x9 ``M`` into column 0 of ``V``, from ``V``
    holding the eigenvectors of a similar matrix (the previous round of a reweighting loop); False when that could
    not be verified (then ``V`` is an orthonormal basis still, and the caller decomposes ``M`` from scratch).

    ``P = V^T M V`` is nearly diagonal; Jacobi rotations in the planes (0, q) only, with the convergence test of
    :func:`cvpipe.homography._kernels._jacobi_eigh` on row 0, make row 0 of P diagonal, so that the rotated column
    0 of V is an eigenvector of M (8 rotations per sweep instead of 36). It is the smallest one, and the rank test
    of the 8-point solve passes, when Gershgorin's disc of row 0 lies below the discs of the other rows and these
    lie above 1e-24 times the largest eigenvalue.
    """
    P = np.empty((9, 9))
    tmp = np.empty((9, 9))
    for i in range(9):
        for j in range(9):
            t = 0.0
            for k in range(9):
                t += M[i, k] * V[k, j]
            tmp[i, j] = t
    for i in range(9):
        for j in range(i, 9):
            t = 0.0
            for k in range(9):
                t += V[k, i] * tmp[k, j]
            P[i, j] = t
            P[j, i] = t
    converged = False
    for sweep in range(20):
        off = 0.0
        for q in range(1, 9):
            off += P[0, q] * P[0, q]
        diag = 0.0
        for k in range(9):
            diag += P[k, k] * P[k, k]
        if off <= 1e-30 * diag or off == 0.0:
            converged = True
            break
        for q in range(1, 9):
            apq = P[0, q]
            if apq == 0.0:
                continue
            theta = (P[q, q] - P[0, 0]) / (2.0 * apq)
            tt = (1.0 if theta >= 0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
            c = 1.0 / math.sqrt(tt * tt + 1.0)
            s = tt * c
            for k in range(9):
                a0 = P[k, 0]
                aq = P[k, q]
                P[k, 0] = c * a0 - s * aq
                P[k, q] = s * a0 + c * aq
            for k in range(9):
                a0 = P[0, k]
                aq = P[q, k]
                P[0, k] = c * a0 - s * aq
                P[q, k] = s * a0 + c * aq
            for k in range(9):
                v0 = V[k, 0]
                vq = V[k, q]
                V[k, 0] = c * v0 - s * vq
                V[k, q] = s * v0 + c * vq
    if not converged:
        return False
    r0 = 0.0
    for q in range(1, 9):
        r0 += abs(P[0, q])
    low = np.inf
    high = P[0, 0] + r0
    for k in range(1, 9):
        r = 0.0
        for j in range(9):
            if j != k:
                r += abs(P[k, j])
        low = min(low, P[k, k] - r)
        high = max(high, P[k, k] + r)
    return P[0, 0] + r0 < low and low > 1e-24 * max(high, 1e-300)


@njit(cache=True, error_model="numpy")
def design_products(x1n, x2n, P):  # pragma: no cover - compiled
    """``P[i, 6 a + b] = q_a r_b`` for correspondence i, q = (u^2, uv, u, v^2, v, 1) of x2n = (u, v) and
    r = (x^2, xy, x, y^2, y, 1) of x1n = (x, y): the normal matrix of the 8-point system with squared weights w2 is
    ``w2 @ P`` (see :func:`eight_point_solve`). Computed once per point set, as the points do not change between
    the reweighting rounds; a row per correspondence, so that the 36 sums advance together (SIMD across them)."""
    for i in range(x1n.shape[0]):
        x = x1n[i, 0]
        y = x1n[i, 1]
        u = x2n[i, 0]
        v = x2n[i, 1]
        r0, r1, r2, r3, r4 = x * x, x * y, x, y * y, y
        for a in range(6):
            if a == 0:
                q = u * u
            elif a == 1:
                q = u * v
            elif a == 2:
                q = u
            elif a == 3:
                q = v * v
            elif a == 4:
                q = v
            else:
                q = 1.0
            P[i, 6 * a] = q * r0
            P[i, 6 * a + 1] = q * r1
            P[i, 6 * a + 2] = q * r2
            P[i, 6 * a + 3] = q * r3
            P[i, 6 * a + 4] = q * r4
            P[i, 6 * a + 5] = q
    return P


@njit(cache=True, error_model="numpy")
def _normal_sums(P, w2, S):  # pragma: no cover - compiled
    """``S = w2 @ P``: 36 sums, each over the correspondences in their order (the 36 advance together as SIMD
    lanes; no sum is reassociated, so it is the same on every CPU). Correspondences of weight 0 are skipped."""
    m = P.shape[1]  # 36; not a constant, so that the loops over it are vectorized rather than unrolled
    n = w2.shape[0]
    full = n - n % 4
    for k in range(m):
        S[k] = 0.0
    for i in range(0, full, 4):
        w0 = w2[i]
        w1 = w2[i + 1]
        w2_ = w2[i + 2]
        w3 = w2[i + 3]
        for k in range(m):
            S[k] += (P[i, k] * w0 + P[i + 1, k] * w1) + (P[i + 2, k] * w2_ + P[i + 3, k] * w3)
    for i in range(full, n):
        w = w2[i]
        for k in range(m):
            S[k] += P[i, k] * w


@njit(cache=True, error_model="numpy")
def eight_point_solve(PT, w2, count, Fn, V, warm):  # pragma: no cover - compiled
    """Weighted normalized 8-point: ``Fn`` becomes the rank-2 projection of the null vector of ``A^T A``, A the rows
    of ``x2^T F x1`` times the weights, whose squares are ``w2`` (0 for the correspondences left out; ``count``:
    the rows used). Returns a status (``FM_*``).

    ``A^T A = sum_i w2_i (x2 x2^T) kron (x1 x1^T)``: the 6 distinct products of x2 times the 6 of x1, 36 sums
    (``PT`` from :func:`design_products`) instead of the 45 of the symmetric 9x9 outer product. Its eigenvectors go
    to the columns of ``V`` (9, 9); with ``warm``, ``V`` holds those of a similar system (the previous round of a
    reweighting loop) and only the smallest one is refined (:func:`_smallest_warm`), with the full decomposition
    when that fails.
    """
    if count < 8:
        return FM_TOO_FEW
    S = np.empty(36)
    _normal_sums(PT, w2, S)
    # entry (3a + b, 3c + d) of the 9x9 matrix is sum w^2 x2_a x2_c x1_b x1_d
    M = np.empty((9, 9))
    for a in range(3):
        for b in range(3):
            for c in range(3):
                for d in range(3):
                    M[3 * a + b, 3 * c + d] = S[6 * _SYM6[a, c] + _SYM6[b, d]]
    if not (warm and _smallest_warm(M, V)):
        ev = _jacobi_eigh(M, V)
        if ev[1] <= 1e-24 * max(ev[8], 1e-300):
            return FM_RANK_DEFICIENT
    for k in range(9):
        Fn[k // 3, k % 3] = V[k, 0]
    _rank2(Fn)
    return FM_OK


@njit(cache=True, error_model="numpy")
def _null2(A, F1, F2, perm):  # pragma: no cover - compiled
    """An orthonormal basis (F1, F2) of the null space of the 7x9 system A (overwritten), by Gauss-Jordan
    elimination with full pivoting; False when A has rank below 7 (7th pivot below ``_RANK_EPS`` of the 1st).
    ``perm``: (9,) int64 scratch."""
    for j in range(9):
        perm[j] = j
    first = 0.0
    for r in range(7):
        big = 0.0
        pi = r
        pj = r
        for i in range(r, 7):
            for j in range(r, 9):
                if abs(A[i, j]) > big:
                    big = abs(A[i, j])
                    pi = i
                    pj = j
        if r == 0:
            first = big
        if not big > _RANK_EPS * first or big == 0.0:
            return False
        if pi != r:
            for j in range(9):
                t = A[r, j]
                A[r, j] = A[pi, j]
                A[pi, j] = t
        if pj != r:
            for i in range(7):
                t = A[i, r]
                A[i, r] = A[i, pj]
                A[i, pj] = t
            t = perm[r]
            perm[r] = perm[pj]
            perm[pj] = t
        inv = 1.0 / A[r, r]
        for j in range(r, 9):
            A[r, j] *= inv
        for i in range(7):
            if i != r:
                f = A[i, r]
                if f != 0.0:
                    for j in range(r, 9):
                        A[i, j] -= f * A[r, j]
    # A = [I | B] in the permuted columns: null vectors x[perm[7 + k]] = 1 (the other free one 0), x[perm[i]] = -B[i, k]
    for k in range(2):
        F = F1 if k == 0 else F2
        for i in range(7):
            c = perm[i]
            F[c // 3, c % 3] = -A[i, 7 + k]
        c = perm[7 + k]
        F[c // 3, c % 3] = 1.0
        c = perm[8 - k]
        F[c // 3, c % 3] = 0.0
    # Gram-Schmidt: F1 unit, F2 unit and orthogonal to it
    s = 0.0
    for i in range(3):
        for j in range(3):
            s += F1[i, j] * F1[i, j]
    s = 1.0 / math.sqrt(s)
    dot = 0.0
    for i in range(3):
        for j in range(3):
            F1[i, j] *= s
            dot += F1[i, j] * F2[i, j]
    s = 0.0
    for i in range(3):
        for j in range(3):
            F2[i, j] -= dot * F1[i, j]
            s += F2[i, j] * F2[i, j]
    s = 1.0 / math.sqrt(s)
    for i in range(3):
        for j in range(3):
            F2[i, j] *= s
    return True


@njit(cache=True, error_model="numpy")
def _det3(F):  # pragma: no cover - compiled
    return (F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]) - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
            + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]))


@njit(cache=True, error_model="numpy")
def _cof_dot(A, B):  # pragma: no cover - compiled
    """``sum_ij cof(A)_ij B_ij`` (= trace(adj(A) B)): the coefficient of t in det(A + t B)."""
    return (B[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]) - B[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
            + B[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]) - B[1, 0] * (A[0, 1] * A[2, 2] - A[0, 2] * A[2, 1])
            + B[1, 1] * (A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]) - B[1, 2] * (A[0, 0] * A[2, 1] - A[0, 1] * A[2, 0])
            + B[2, 0] * (A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]) - B[2, 1] * (A[0, 0] * A[1, 2] - A[0, 2] * A[1, 0])
            + B[2, 2] * (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]))


@njit(cache=True, error_model="numpy")
def _polish(c3, c2, c1, c0, x):  # pragma: no cover - compiled
    """Newton steps on c3 x^3 + c2 x^2 + c1 x + c0 (the coefficients as given: dividing by a small c3 would lose
    the small roots), each kept only while it lowers |p(x)|; returns (x, |p(x)| / its rounding scale)."""
    f = ((c3 * x + c2) * x + c1) * x + c0
    for _ in range(4):
        fp = (3.0 * c3 * x + 2.0 * c2) * x + c1
        if fp == 0.0 or f == 0.0:
            break
        xn = x - f / fp
        fn = ((c3 * xn + c2) * xn + c1) * xn + c0
        if not abs(fn) < abs(f):
            break
        x = xn
        f = fn
    ax = abs(x)
    scale = ((abs(c3) * ax + abs(c2)) * ax + abs(c1)) * ax + abs(c0)
    return x, abs(f) / scale if scale > 0.0 else 0.0


@njit(cache=True, error_model="numpy")
def _cubic_roots(c3, c2, c1, c0, out):  # pragma: no cover - compiled
    """The real roots of c3 a^3 + c2 a^2 + c1 a + c0 into ``out``, their number (0 when the cubic degenerates:
    ``|c3|`` at most ``_CUBIC_EPS`` of the largest coefficient).

    The real root of largest magnitude from the closed form of the monic cubic (Cardano, or the trigonometric form
    for three real roots: accurate for the largest root, not for much smaller ones), refined by Newton on the given
    coefficients; then the quadratic factor of the other two, deflated from the side that keeps it accurate
    (backward from the constant term when the root is the larger one), solved in the stable form. A complex pair
    whose imaginary part is within 1e-8 of its modulus (at least 1) counts as one real (double) root, as for the
    eigenvalues of the companion matrix."""
    scale = max(abs(c3), abs(c2), abs(c1), abs(c0))
    if not (scale > 0.0 and abs(c3) > _CUBIC_EPS * scale):
        return 0
    b = c2 / c3
    c = c1 / c3
    d = c0 / c3
    # depressed cubic t^3 + p t + q = 0 with a = t - b / 3
    b3 = b / 3.0
    p = c - b * b3
    q = (2.0 * b3 * b3 - c) * b3 + d
    hq = 0.5 * q
    tp = p / 3.0
    disc = hq * hq + tp * tp * tp
    if disc > 0.0:
        s = math.sqrt(disc)
        w = -hq - s if hq >= 0.0 else -hq + s  # no cancellation
        A = math.copysign(abs(w) ** (1.0 / 3.0), w)
        r = A + (-tp / A if A != 0.0 else 0.0) - b3
    elif tp == 0.0:  # then q = 0 too: a triple root
        r = -b3
    else:
        rad = 2.0 * math.sqrt(-tp)
        phi = math.acos(min(1.0, max(-1.0, hq / (tp * math.sqrt(-tp))))) / 3.0
        r = 0.0
        for m in range(3):
            t = rad * math.cos(phi - 2.0 * math.pi * m / 3.0) - b3
            if m == 0 or abs(t) > abs(r):
                r = t
    r, _ = _polish(c3, c2, c1, c0, r)
    out[0] = r
    # (a - r)(q2 a^2 + q1 a + q0)
    if r != 0.0 and abs(c3) * abs(r) ** 3 >= abs(c0):  # r is larger than the geometric mean of the other two
        q0 = -c0 / r
        q1 = (q0 - c1) / r
        q2 = (q1 - c2) / r
    else:
        q2 = c3
        q1 = c2 + r * q2
        q0 = c1 + r * q1
    if q2 == 0.0:
        return 1
    dq = q1 * q1 - 4.0 * q2 * q0
    if dq < 0.0:
        re = -q1 / (2.0 * q2)
        im = math.sqrt(-dq) / (2.0 * abs(q2))
        if im <= 1e-8 * max(1.0, math.sqrt(re * re + im * im)):
            out[1], _ = _polish(c3, c2, c1, c0, re)
            return 2
        return 1
    h = -0.5 * (q1 + math.copysign(math.sqrt(dq), q1))
    if h == 0.0:  # q1 = q0 = 0: a double root at 0
        out[1] = 0.0
        return 2
    out[1], _ = _polish(c3, c2, c1, c0, h / q2)
    out[2], _ = _polish(c3, c2, c1, c0, q0 / h)
    return 3


@njit(cache=True, error_model="numpy")
def seven_point(x1n, x2n, pick, Fns, A, F1, F2, D, roots, perm):  # pragma: no cover - compiled
    """The fundamental matrices (normalized coordinates) through the 7 correspondences ``pick`` into ``Fns``
    (3, 3, 3); returns their number, 0 for a degenerate sample.

    The 1 to 3 real roots a of ``det(a F1 + (1 - a) F2) = 0`` over the null space (F1, F2) of the 7x9 system.
    Scratch (none allocated per sample): ``A`` (7, 9), ``F1, F2, D`` (3, 3), ``roots`` (3,), ``perm`` (9,) int64.
    """
    for r in range(7):
        i = pick[r]
        x, y, xp, yp = x1n[i, 0], x1n[i, 1], x2n[i, 0], x2n[i, 1]
        A[r, 0] = xp * x
        A[r, 1] = xp * y
        A[r, 2] = xp
        A[r, 3] = yp * x
        A[r, 4] = yp * y
        A[r, 5] = yp
        A[r, 6] = x
        A[r, 7] = y
        A[r, 8] = 1.0
    if not _null2(A, F1, F2, perm):
        return 0
    for i in range(3):
        for j in range(3):
            D[i, j] = F1[i, j] - F2[i, j]
    # det(a F1 + (1 - a) F2) = det(F2 + a D)
    nr = _cubic_roots(_det3(D), _cof_dot(D, F2), _cof_dot(F2, D), _det3(F2), roots)
    for r in range(nr):
        a = roots[r]
        for i in range(3):
            for j in range(3):
                Fns[r, i, j] = F2[i, j] + a * D[i, j]
    return nr


@njit(cache=True, error_model="numpy")
def ransac_batch(u, x1n, x2n, q, T1, T2, thr2, keep, models, costs):  # pragma: no cover - compiled
    """Solve (:func:`seven_point`) and score the 7-point samples drawn from the uniforms ``u`` (K, 7).

    Each solution goes to ``models`` in pixel coordinates with its MSAC cost in ``costs``. A model whose partial
    cost already exceeds the ``keep``-th lowest cost of the batch is not finished (cost inf): it cannot be among the
    lowest ``keep``, which is all the caller keeps. To find those early, every model is first scored on the first
    block of correspondences and the models are finished in the order of those partial costs; the finished costs do
    not depend on that order. Returns (models, samples that gave a model).
    """
    n = q.shape[1]
    pick = np.empty(7, np.int64)
    buf = np.empty(_COST_BLOCK)
    chosen = np.empty(7, np.int64)
    Fns = np.empty((3, 3, 3))
    tmp = np.empty((3, 3))
    A = np.empty((7, 9))
    F1 = np.empty((3, 3))
    F2 = np.empty((3, 3))
    D = np.empty((3, 3))
    roots = np.empty(3)
    perm = np.empty(9, np.int64)
    m = 0
    regular = 0
    for k in range(u.shape[0]):
        sample_distinct(u, k, n, pick, chosen)
        nr = seven_point(x1n, x2n, pick, Fns, A, F1, F2, D, roots, perm)
        if nr == 0:
            continue
        regular += 1
        for r in range(nr):
            F = models[m]
            denormalize(Fns[r], T1, T2, tmp, F)
            costs[m] = _msac_block(F, q, thr2, 0, min(_COST_BLOCK, n), buf)
            m += 1
    low = np.full(keep, np.inf)  # the lowest costs of the batch so far, ascending
    for j in np.argsort(costs[:m]):
        cost = _msac_from(models[j], q, thr2, 1, costs[j], low[keep - 1], buf)
        costs[j] = cost
        if cost < low[keep - 1]:
            t = keep - 1
            while t > 0 and low[t - 1] > cost:
                low[t] = low[t - 1]
                t -= 1
            low[t] = cost
    return m, regular


@njit(cache=True, error_model="numpy")
def _kth(a, n, k):  # pragma: no cover - compiled
    """Rearrange ``a[:n]`` so that ``a[k]`` is its k-th smallest value (0-based) with no larger value before it and
    no smaller one after it (Hoare's selection with Wirth's partition); returns ``a[k]``."""
    lo = 0
    hi = n - 1
    while lo < hi:
        pivot = a[(lo + hi) // 2]
        i = lo
        j = hi
        while i <= j:
            while a[i] < pivot:
                i += 1
            while pivot < a[j]:
                j -= 1
            if i <= j:
                t = a[i]
                a[i] = a[j]
                a[j] = t
                i += 1
                j -= 1
        if j < k:
            lo = i
        if k < i:
            hi = j
    return a[k]


@njit(cache=True, error_model="numpy")
def noise_cutoff(d, threshold, buf, squared):  # pragma: no cover - compiled
    """Tukey's cut-off ``_TUKEY_C * sigma`` for Sampson distances ``d`` (their squares with ``squared``),
    ``sigma = _MAD_TO_SIGMA * median`` of the distances within ``threshold`` (``threshold`` when there are none),
    kept within ``[_MIN_C, _FINAL_WSCALE]`` times ``threshold``; ``buf``: scratch of len(d)."""
    k = 0
    t = threshold * threshold if squared else threshold
    for i in range(d.shape[0]):
        if d[i] <= t:
            buf[k] = d[i]
            k += 1
    if k == 0:
        sigma = threshold
    else:
        h = k // 2
        med = _kth(buf, k, h)
        if squared:
            med = math.sqrt(med)
        if k % 2 == 0:  # the mean of the two middle values: the largest of the lower half is the other one
            lower = buf[0]
            for i in range(1, h):
                lower = max(lower, buf[i])
            med = ((math.sqrt(lower) if squared else lower) + med) / 2.0
        sigma = _MAD_TO_SIGMA * med
    return min(_FINAL_WSCALE * threshold, max(_TUKEY_C * sigma, _MIN_C * threshold))


@njit(cache=True, error_model="numpy")
def _settled(prev, V):  # pragma: no cover - compiled
    """True when the unit null vector ``V[:, 0]`` moved by less than ``_REFINE_TOL`` from ``prev`` (either sign)."""
    dot = 0.0
    for k in range(9):
        dot += prev[k] * V[k, 0]
    return 1.0 - abs(dot) <= _REFINE_TOL


@njit(cache=True, error_model="numpy")
def refit(PT, q, T1, T2, mask, rounds, w2, F, V, warm):  # pragma: no cover - compiled
    """Sampson-reweighted normalized 8-point on ``mask`` (``rounds`` reweightings; ``w2``: scratch of N): F in
    pixel coordinates, unit norm; ``q`` (4, N): rows x1, y1, x2, y2 of the correspondences. ``PT``, ``V``, ``warm``: as for :func:`eight_point_solve`. Returns a status
    (``FM_*``)."""
    Fn = np.empty((3, 3))
    tmp = np.empty((3, 3))
    prev = np.empty(9)
    x1, y1, x2, y2 = q[0], q[1], q[2], q[3]
    n = q.shape[1]
    cnt = 0
    for i in range(n):
        w2[i] = 1.0 if mask[i] else 0.0
        cnt += mask[i]
    status = eight_point_solve(PT, w2, cnt, Fn, V, warm)
    if status != FM_OK:
        return status
    for _ in range(rounds):
        denormalize(Fn, T1, T2, tmp, F)
        # algebraic residual / its gradient norm = Sampson distance: squared weight 1 / den (the normalization
        # changes the algebraic scale by a constant factor only, and a common scale of the weights changes no
        # eigenvector)
        for i in range(n):
            if mask[i]:
                _, den = _epi(F, x1[i], y1[i], x2[i], y2[i])
                w2[i] = 1.0 / max(den, 1e-300)
        for k in range(9):
            prev[k] = V[k, 0]
        status = eight_point_solve(PT, w2, cnt, Fn, V, True)
        if status != FM_OK:
            return status
        if _settled(prev, V):
            break
    denormalize(Fn, T1, T2, tmp, F)
    unit(F)
    return FM_OK


@njit(cache=True, error_model="numpy")
def refit_robust(PT, q, T1, T2, F, threshold, rounds, d2, iden, w2, use, buf, V, warm):  # pragma: no cover
    """Iteratively reweighted 8-point of F (in place) over every correspondence, weights ``Tukey(d / c) / sqrt(den)``
    with the cut-off c of :func:`noise_cutoff` re-estimated each round; stops early when fewer than 8 fall within
    it. Works on squared distances and weights (no square root per correspondence). ``d2, iden, w2, use, buf``:
    scratch of N; ``V``, ``warm``: as for :func:`refit`. Returns a status (``FM_*``)."""
    Fn = np.empty((3, 3))
    tmp = np.empty((3, 3))
    prev = np.empty(9)
    x1, y1, x2, y2 = q[0], q[1], q[2], q[3]
    n = q.shape[1]
    for r in range(rounds):
        for i in range(n):
            num, de = _epi(F, x1[i], y1[i], x2[i], y2[i])
            r = 1.0 / max(de, 1e-300)
            iden[i] = r
            d2[i] = num * num * r
        c = noise_cutoff(d2, threshold, buf, True)
        c2 = c * c
        cnt = 0
        for i in range(n):
            use[i] = d2[i] < c2
            cnt += use[i]
        if cnt < 8:
            break
        for i in range(n):
            t = 1.0 - d2[i] / c2
            t *= t
            w2[i] = t * t * iden[i] if use[i] else 0.0
        for k in range(9):
            prev[k] = V[k, 0]
        status = eight_point_solve(PT, w2, cnt, Fn, V, warm)
        if status != FM_OK:
            return status
        warm = True
        denormalize(Fn, T1, T2, tmp, F)
        unit(F)
        if r > 0 and _settled(prev, V):
            break
    return FM_OK


@njit(cache=True, error_model="numpy")
def local_optimize(PT, q, T1, T2, F0, thr2, F):  # pragma: no cover - compiled
    """LO of a new so-far-best model: the unweighted 8-point model F of the correspondences within the threshold
    of F0. Returns (ok, MSAC cost of F)."""
    n = q.shape[1]
    mask = np.empty(n, np.bool_)
    if count_within(F0, q, thr2, mask) < 8:
        return False, np.inf
    if refit(PT, q, T1, T2, mask, 0, np.empty(n), F, np.empty((9, 9)), False) != FM_OK:
        return False, np.inf
    return True, msac_cost(F, q, thr2, np.inf)


@njit(cache=True, error_model="numpy")
def _finish(PT, q, T1, T2, F, threshold, min_inliers, d, den, w, use, buf, mask, new, V):  # pragma: no cover
    """The final refinement of one model (F in place): reweighted 8-point refits with inlier re-selection, then the
    robust refit. Returns a status (``FM_*``)."""
    thr2 = threshold * threshold
    count_within(F, q, thr2, mask)
    warm = False
    for _ in range(2):  # refit, re-select inliers, refit (the inlier set settles in one or two rounds)
        status = refit(PT, q, T1, T2, mask, _REFINE_ROUNDS, w, F, V, warm)
        warm = True
        if status != FM_OK:
            return status
        cnt = count_within(F, q, thr2, new)
        same = True
        for i in range(q.shape[1]):
            if new[i] != mask[i]:
                same = False
                break
        if cnt < min_inliers or same:
            break
        mask[:] = new
    if _FINAL_WSCALE > 0:
        return refit_robust(PT, q, T1, T2, F, threshold, _REFINE_ROUNDS, d, den, w, use, buf, V, True)
    return FM_OK


@njit(cache=True, error_model="numpy")
def _same(A, B):  # pragma: no cover - compiled
    for i in range(3):
        for j in range(3):
            if A[i, j] != B[i, j]:
                return False
    return True


@njit(cache=True, error_model="numpy")
def final_refinement(PT, q, T1, T2, starts, threshold, sel2, min_inliers, quick_rounds, full,
                     F):  # pragma: no cover - compiled
    """The multi-start final refinement: each start gets ``quick_rounds`` robust rounds, the ``full`` lowest of
    those (MSAC cost truncated at ``sel2``; ties in the order of ``starts``) get the whole refinement
    (:func:`_finish`), and the lowest cost wins into F. Returns False when every start failed."""
    n = q.shape[1]
    d = np.empty(n)
    den = np.empty(n)
    w = np.empty(n)
    buf = np.empty(n)
    use = np.empty(n, np.bool_)
    mask = np.empty(n, np.bool_)
    new = np.empty(n, np.bool_)
    V = np.empty((9, 9))
    s = starts.shape[0]
    quick = np.empty((s, 3, 3))
    qcost = np.full(s, np.inf)
    for k in range(s):
        quick[k] = starts[k]
        if refit_robust(PT, q, T1, T2, quick[k], threshold, quick_rounds, d, den, w, use, buf, V,
                        False) == FM_OK:
            qcost[k] = msac_cost(quick[k], q, sel2, np.inf)
    order = np.argsort(qcost, kind="mergesort")
    cand = np.empty((3, 3))
    best = np.inf
    found = False
    for t in range(min(full, s)):
        k = order[t]
        if not qcost[k] < np.inf:
            break
        if t > 0 and _same(quick[k], quick[order[t - 1]]):
            continue  # the same start as the previous one (a model that is both a so-far-best and in the pool)
        cand[:, :] = quick[k]
        if _finish(PT, q, T1, T2, cand, threshold, min_inliers, d, den, w, use, buf, mask, new,
                   V) != FM_OK:
            continue
        c = msac_cost(cand, q, sel2, np.inf)
        if c < best:
            best = c
            F[:, :] = cand
            found = True
    return found


@njit(cache=True, error_model="numpy")
def normalize_points(p, eps, T, out):  # pragma: no cover - compiled
    """Hartley normalization of the (N, 2) points ``p`` in one pass over them: ``T`` (3, 3) moves their centroid to
    the origin and their mean distance to it to sqrt(2), ``out`` (N, 2) gets the normalized points. Returns False,
    and leaves both untouched, when the points are collinear or coincide: the smaller principal axis of the centred
    points is at most ``eps`` times the larger one (as :func:`cvpipe.geometry.collinear`, from the 2x2 scatter
    matrix instead of an SVD: its eigenvalue ratio at most eps^2)."""
    n = p.shape[0]
    cx = 0.0
    cy = 0.0
    for i in range(n):
        cx += p[i, 0]
        cy += p[i, 1]
    cx /= n
    cy /= n
    a = b = c = dist = 0.0
    for i in range(n):
        x = p[i, 0] - cx
        y = p[i, 1] - cy
        a += x * x
        b += x * y
        c += y * y
        dist += math.sqrt(x * x + y * y)
    l0 = 0.5 * (a + c) + math.sqrt(0.25 * (a - c) ** 2 + b * b)
    if not l0 > 0.0 or a * c - b * b <= eps * eps * l0 * l0:
        return False
    s = math.sqrt(2.0) / (dist / n)
    T[:, :] = 0.0
    T[0, 0] = s
    T[1, 1] = s
    T[0, 2] = -s * cx
    T[1, 2] = -s * cy
    T[2, 2] = 1.0
    for i in range(n):
        out[i, 0] = (p[i, 0] - cx) * s
        out[i, 1] = (p[i, 1] - cy) * s
    return True
