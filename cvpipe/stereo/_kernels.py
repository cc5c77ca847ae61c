"""The numba kernels of semi-global matching (:func:`cvpipe.stereo.sgm.disparity_sgm` validates, documents and calls
them): census cost volume, path aggregation, winner-take-all with the left-right check, speckle removal and the
background fill. They only compute: the checks live in the public functions.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

#: "infinite" path cost in the int16 path buffers; real path costs stay <= 255 + P2 <= 4351 (checked in disparity_sgm),
#: so _BIG + P1 cannot overflow int16 and _BIG never wins a minimum
_BIG = 16000


@njit(cache=True, inline="always")
def _census_row(padded, y, ry, rx, row):  # pragma: no cover - compiled
    """Census signatures of row ``y`` of an image padded by (ry, rx) into ``row`` (W,) uint64: bit set where the
    neighbour is darker than the centre, neighbours in row-major order without the centre."""
    w = row.shape[0]
    centre = padded[y + ry, rx:rx + w]
    for x in range(w):
        row[x] = 0
    for dy in range(2 * ry + 1):
        for dx in range(2 * rx + 1):
            if dy == ry and dx == rx:
                continue
            nb = padded[y + dy, dx:dx + w]
            for x in range(w):
                row[x] = (row[x] << np.uint64(1)) | np.uint64(nb[x] < centre[x])


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
        _census_row(pad_l, y, ry, rx, cen_l)
        _census_row(pad_r, y, ry, rx, cen_r)
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
            if ad_mult > 0 and nch == 3:
                # colour: the whole cost in one loop (the common case; about 20 % faster than a loop per channel)
                l0 = np.int32(planes_l[y, x, 0])
                l1 = np.int32(planes_l[y, x, 1])
                l2 = np.int32(planes_l[y, x, 2])
                for d in range(nd):
                    i = base + np.uint64(d)
                    ad = (abs(l0 - rev_planes[0, i]) + abs(l1 - rev_planes[1, i]) + abs(l2 - rev_planes[2, i]))
                    cost[y, x, d] = np.uint8(_popcount(cl ^ rev[i]) + ((min(ad, ad_cap) * ad_mult) >> 16))
            else:
                for d in range(nd):
                    cost[y, x, d] = np.uint8(_popcount(cl ^ rev[base + np.uint64(d)]))
                if ad_mult > 0:
                    for d in range(nd):
                        adsum[d] = 0
                    for c in range(nch):
                        lv = np.int32(planes_l[y, x, c])
                        for d in range(nd):
                            adsum[d] += abs(lv - rev_planes[c, base + np.uint64(d)])
                    for d in range(nd):
                        cost[y, x, d] += np.uint8((min(adsum[d], ad_cap) * ad_mult) >> 16)
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


@njit(cache=True)
def _sweep(cost, gray, dy, nk, p1, p2_lut, out):  # pragma: no cover - compiled
    """Store in ``out`` the sum of the path costs arriving from the previous row, sweeping rows in order ``dy``:
    directions (dy, dx) for dx in (-1, 0, 1) when ``nk`` = 3, or (dy, 0) when ``nk`` = 1.

    The previous row's path costs stay in cache-sized row buffers, so the volumes are read once and written once
    per sweep instead of once per direction.
    """
    h, w, nd = cost.shape
    prev = np.full((nk * w, nd + 2), _BIG, np.int16)  # [k * w + x, 1 + d]
    cur = np.full((nk * w, nd + 2), _BIG, np.int16)
    mprev = np.zeros(nk * w, np.int16)
    mcur = np.zeros(nk * w, np.int16)
    # dx = k - k_mid is affine in k and the interior columns need no bounds test: a conditional dx or a per-pixel
    # bounds test made these loops 2-3x slower
    k_mid = nk // 2
    for s in range(h):
        y = s if dy > 0 else h - 1 - s
        if s == 0:
            for x in range(w):
                for k in range(nk):
                    mcur[k * w + x] = _path_start(cost, y, x, cur, k * w + x)
        else:
            for x in range(k_mid, w - k_mid):
                g_row = np.int32(gray[y, x])
                for k in range(nk):
                    px = x - (k - k_mid)
                    p2e = p2_lut[abs(g_row - np.int32(gray[y - dy, px]))]
                    mcur[k * w + x] = _path_step(prev, k * w + px, mprev[k * w + px], cost, y, x, p1, p2e, cur,
                                                 k * w + x)
            for x in (0, w - 1):
                if k_mid == 0:
                    break
                g_row = np.int32(gray[y, x])
                for k in range(nk):
                    px = x - (k - k_mid)
                    if px < 0 or px >= w:
                        mcur[k * w + x] = _path_start(cost, y, x, cur, k * w + x)
                    else:
                        p2e = p2_lut[abs(g_row - np.int32(gray[y - dy, px]))]
                        mcur[k * w + x] = _path_step(prev, k * w + px, mprev[k * w + px], cost, y, x, p1, p2e,
                                                     cur, k * w + x)
        # summing in a separate loop over the row keeps the step loops above vectorized (measured 10x faster)
        for x in range(w):
            for d in range(nd):
                out[y, x, d] = np.uint16(cur[x, d + 1])
            for k in range(1, nk):
                for d in range(nd):
                    out[y, x, d] += np.uint16(cur[k * w + x, d + 1])
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


@njit(cache=True)
def _remove_speckles(disp, max_size, max_jump):  # pragma: no cover - compiled
    """Reject 4-connected regions (neighbours within ``max_jump`` px of each other) smaller than ``max_size`` px."""
    h, w = disp.shape
    label = np.zeros((h, w), np.int32)
    stack = np.empty(h * w, np.int64)
    members = np.empty(h * w, np.int64)
    n_label = 0
    for y0 in range(h):
        for x0 in range(w):
            if label[y0, x0] != 0 or disp[y0, x0] < 0:
                continue
            n_label += 1
            label[y0, x0] = n_label
            top = 0
            stack[top] = y0 * w + x0
            top = 1
            count = 0
            while top > 0:
                top -= 1
                i = stack[top]
                members[count] = i
                count += 1
                y = i // w
                x = i - y * w
                dv = disp[y, x]
                for k in range(4):
                    yy = y + (1 if k == 0 else (-1 if k == 1 else 0))
                    xx = x + (1 if k == 2 else (-1 if k == 3 else 0))
                    if 0 <= yy < h and 0 <= xx < w and label[yy, xx] == 0:
                        dn = disp[yy, xx]
                        if dn >= 0 and abs(dn - dv) <= max_jump:
                            label[yy, xx] = n_label
                            stack[top] = yy * w + xx
                            top += 1
            if count < max_size:
                for j in range(count):
                    i = members[j]
                    disp[i // w, i - (i // w) * w] = -1.0


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
