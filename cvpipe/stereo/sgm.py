"""Disparity of a rectified stereo pair: our semi-global matching and the OpenCV baselines.

Conventions (DESIGN.md): ``left`` and ``right`` are rectified, both (H, W) grayscale or both (H, W, 3) BGR uint8
images as ``cv2.imread`` returns them. A left pixel (x, y) with disparity d matches the right pixel (x - d, y).
``max_disp`` is like OpenCV's ``numDisparities``: the disparities searched are 0 .. max_disp - 1. Every method
returns an (H, W) float32 disparity of the LEFT image in pixels, NaN where it has no (trusted) estimate.

``disparity_sgm`` follows Hirschmueller's semi-global matching (PAMI 2008): a census (optionally plus truncated
absolute-difference) matching cost, cost aggregation along 8 (or 4) scanline directions with penalties P1 / P2 where
P2 shrinks across intensity edges, winner-take-all with a uniqueness test, a parabola through the aggregated costs for
sub-pixel disparity, a left-right consistency check on the same cost volume and removal of small speckles.
All per-pixel work runs in numba kernels (``cache=True``; ``parallel=True`` where scanlines are independent).
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np
from numba import njit, prange

from .. import metrics
from ..errors import check_memory

#: most bits a census signature can hold (uint64)
_CENSUS_BITS = 64
#: supported numbers of aggregation directions (4: horizontal and vertical; 8: also the diagonals)
_PATHS = (4, 8)


# ----------------------------------------------------------------------------------------------- validation


def _check_pair(left: np.ndarray, right: np.ndarray, max_disp: int) -> None:
    """Validate a stereo pair and the disparity range at the public boundary (ValueError naming the parameter)."""
    for name, img in (("left", left), ("right", right)):
        if not isinstance(img, np.ndarray):
            raise ValueError(f"`{name}` must be a numpy array, got {type(img).__name__}")
        if img.dtype != np.uint8:
            raise ValueError(f"`{name}` must be uint8, got {img.dtype}")
        if not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] == 3)):
            raise ValueError(f"`{name}` must be (H, W) gray or (H, W, 3) BGR, got shape {img.shape}")
    if left.ndim != right.ndim:
        kinds = {2: "grayscale", 3: "BGR"}
        raise ValueError(
            f"`left` and `right` must both be grayscale or both BGR, got {kinds[left.ndim]} and {kinds[right.ndim]}"
        )
    if left.shape[:2] != right.shape[:2]:
        raise ValueError(
            f"`left` and `right` must have the same size, got {left.shape[1]}x{left.shape[0]} and "
            f"{right.shape[1]}x{right.shape[0]}"
        )
    if isinstance(max_disp, (bool, np.bool_)) or not isinstance(max_disp, (int, np.integer)):
        raise ValueError(f"`max_disp` must be an integer, got {max_disp!r}")
    width = left.shape[1]
    if max_disp <= 0 or max_disp >= width:
        raise ValueError(f"`max_disp` must be in [1, {width - 1}] (positive and less than the image width), "
                         f"got {max_disp}")


def _gray(img: np.ndarray) -> np.ndarray:
    return img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)


# ----------------------------------------------------------------------------------------------- numba kernels


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


# ----------------------------------------------------------------------------------------------- public API


def disparity_sgm(
    left: np.ndarray,
    right: np.ndarray,
    max_disp: int,
    *,
    census_size: tuple[int, int] = (5, 7),
    ad_weight: float = 0.5,
    ad_trunc: int = 20,
    paths: int = 8,
    p1: int = 15,
    p2: int = 150,
    p2_tau: float = 16.0,
    uniqueness: float = 0.0,
    subpixel: bool = True,
    lr_max_diff: float = 2.0,
    speckle_size: int = 100,
    speckle_range: float = 2.0,
    fill: bool = False,
) -> np.ndarray:
    """Disparity of the left image by semi-global matching on a census cost.

    Parameters
    ----------
    left, right : ndarray, (H, W) or (H, W, 3) uint8
        Rectified pair, both grayscale or both BGR; a left pixel (x, y) with disparity d matches right (x - d, y).
    max_disp : int
        Number of disparities searched, 0 .. max_disp - 1 (like OpenCV's ``numDisparities``); in [1, W - 1].
    census_size : (int, int)
        Odd (height, width) of the census window; at most 65 pixels so that a signature fits 64 bits.
    ad_weight : float
        Weight of the truncated mean absolute colour difference added to the census Hamming distance (0 = census
        only). The cost of one disparity is ``hamming + floor(ad_weight * min(AD, ad_trunc))`` (fixed point), and
        it must stay <= 255 (uint8 cost volume).
    ad_trunc : int
        Grey levels at which the absolute difference saturates, in [1, 255].
    paths : {8, 4}
        Number of aggregation directions; 4 (horizontal and vertical only) is faster.
    p1, p2 : int
        Penalties, in cost units (Hamming bits), for a disparity change of one pixel and of more than one pixel
        between neighbours on a path; ``1 <= p1 < p2 <= 4096``.
    p2_tau : float
        Grey-level scale of the edge adaptation ``P2' = max(P2 * tau / (tau + |dI|), P1 + 1)``; 0 keeps P2 fixed.
    uniqueness : float
        Reject a pixel when another disparity (not adjacent to the winner) costs less than ``(1 + uniqueness)``
        times the winner's aggregated cost; 0 disables the test.
    subpixel : bool
        Refine the winner with a parabola through the aggregated costs at d - 1, d, d + 1.
    lr_max_diff : float
        Largest accepted difference, in pixels, between the left disparity and the right image's disparity at
        the matched pixel (the floor and the ceil of a sub-pixel disparity are both tried); negative disables the
        left-right check.
    speckle_size : int
        Connected regions with fewer pixels than this are rejected (0 disables speckle removal).
    speckle_range : float
        Largest disparity step, in pixels, between 4-neighbours of one region.
    fill : bool
        Fill rejected pixels with the smaller (background) of the nearest accepted disparities on the same row.
        Off by default: the map then has NaN wherever the estimate is not trusted.

    Returns
    -------
    ndarray, (H, W) float32
        Disparity of the left image in pixels, NaN where rejected (occluded, ambiguous, inconsistent, speckle, or
        ``x < d`` for every candidate).

    Raises
    ------
    ValueError
        Bad images (different sizes, gray mixed with colour, not uint8) or a parameter out of range.
    """
    _check_pair(left, right, max_disp)
    if len(census_size) != 2 or any(int(s) != s or s < 1 or s % 2 == 0 for s in census_size):
        raise ValueError(f"`census_size` must be two odd positive integers (height, width), got {census_size}")
    if census_size[0] * census_size[1] - 1 > _CENSUS_BITS:
        raise ValueError(f"`census_size` must cover at most {_CENSUS_BITS + 1} pixels, got {census_size}")
    if not ad_weight >= 0:
        raise ValueError(f"`ad_weight` must be >= 0, got {ad_weight}")
    if not 1 <= ad_trunc <= 255:
        raise ValueError(f"`ad_trunc` must be in [1, 255], got {ad_trunc}")
    if paths not in _PATHS:
        raise ValueError(f"`paths` must be one of {sorted(_PATHS)}, got {paths!r}")
    if not 1 <= p1 < p2:
        raise ValueError(f"`p1` and `p2` must satisfy 1 <= p1 < p2, got p1={p1}, p2={p2}")
    if p2 > 4096:
        raise ValueError(f"`p2` must be at most 4096, got {p2}")
    if not p2_tau >= 0:
        raise ValueError(f"`p2_tau` must be >= 0, got {p2_tau}")
    if not 0 <= uniqueness < 1:
        raise ValueError(f"`uniqueness` must be in [0, 1), got {uniqueness}")
    if speckle_size < 0:
        raise ValueError(f"`speckle_size` must be >= 0, got {speckle_size}")
    if not speckle_range >= 0:
        raise ValueError(f"`speckle_range` must be >= 0, got {speckle_range}")

    h, w = left.shape[:2]
    # cost (uint8) + the two aggregated volumes (uint16) per pixel and disparity, and ~40 bytes per pixel of
    # disparity maps and speckle buffers: checked before anything is allocated
    check_memory(float(h) * w * (5 * int(max_disp) + 40), f"semi-global matching of {w}x{h} pixels x {max_disp} "
                 "disparities", "lower `--max-disp` or downscale both images (disparities scale with the image)")
    gl, gr = _gray(left), _gray(right)
    planes_l = np.ascontiguousarray(left).reshape(left.shape[0], left.shape[1], -1)  # (H, W, C) views, no copy
    planes_r = np.ascontiguousarray(right).reshape(right.shape[0], right.shape[1], -1)
    ry, rx = census_size[0] // 2, census_size[1] // 2
    nch = 1 if left.ndim == 2 else 3
    # AD term = ad_weight * min(mean_c |dI_c|, ad_trunc) in 16.16 fixed point on the channel sum
    ad_mult = int(round(ad_weight / nch * 65536))
    ad_cap = int(ad_trunc) * nch
    ad_max = (ad_cap * ad_mult) >> 16
    bits = census_size[0] * census_size[1] - 1
    c_max = bits + ad_max
    # the cost volume is uint8; then every path cost is below 255 + p2 <= 4351 (int16 buffers, _BIG = 16000) and
    # the sum of 8 paths below 65535 (uint16 volumes)
    if c_max > 255:
        raise ValueError(f"`ad_weight` * `ad_trunc` too large: the matching cost {bits} + {ad_max} "
                         "must stay <= 255")
    gl_pad = np.pad(gl, ((ry, ry), (rx, rx)), mode="edge")
    gr_pad = np.pad(gr, ((ry, ry), (rx, rx)), mode="edge")
    # the volumes are allocated by numpy, which asks the kernel for huge pages (numba's allocator does not): with
    # 4 KiB pages, first-touch page faults on the tens of MB of volumes cost a sizeable share of the run time
    h, w = gl.shape
    cost = np.empty((h, w, int(max_disp)), np.uint8)
    _cost_volume(gl_pad, gr_pad, ry, rx, planes_l, planes_r, np.int32(ad_cap), np.int32(ad_mult), np.uint8(c_max),
                 cost)
    steps = np.arange(256, dtype=np.float64)
    p2_lut = np.full(256, p2, np.float64) if p2_tau == 0 else np.floor(p2 * p2_tau / (p2_tau + steps))
    p2_lut = np.maximum(p2_lut, p1 + 1).astype(np.int16)
    down = np.empty(cost.shape, np.uint16)
    up = np.empty(cost.shape, np.uint16)
    _aggregate(cost, gl, 3 if paths == 8 else 1, np.int16(p1), p2_lut, down, up)
    # the left-right check runs row by row inside _winner (a negative lr_max_diff disables it)
    disp, _ = _winner(cost, down, up, gl, np.int16(p1), p2_lut, float(uniqueness), bool(subpixel),
                      float(lr_max_diff))
    del cost, down, up
    if speckle_size > 0:
        _remove_speckles(disp, int(speckle_size), float(speckle_range))
    if fill:
        disp = _fill_background(disp)
    disp[disp < 0] = np.nan
    return disp


def fill_invalid(disp: np.ndarray) -> np.ndarray:
    """Fill NaN pixels with the smaller (background) of the nearest valid disparities on the same row.

    The occlusion filling of Hirschmueller (2008): a pixel rejected by the left-right check is most often occluded,
    and occluded pixels belong to the farther surface. Rows without any valid pixel stay NaN.

    Parameters
    ----------
    disp : ndarray, (H, W) float
        Disparity in pixels, NaN = invalid; values must be >= 0.

    Returns
    -------
    ndarray, (H, W) float32
        A filled copy.
    """
    if disp.ndim != 2:
        raise ValueError(f"`disp` must be (H, W), got shape {disp.shape}")
    work = np.where(np.isfinite(disp), disp, -1.0).astype(np.float32)
    if (work[np.isfinite(disp)] < 0).any():
        raise ValueError("`disp` must not contain negative disparities")
    out = _fill_background(work)
    out[out < 0] = np.nan
    return out


# ----------------------------------------------------------------------------------------------- OpenCV baselines

#: OpenCV StereoSGBM modes by name
SGBM_MODES = {
    "sgbm": cv2.StereoSGBM_MODE_SGBM,
    "hh": cv2.StereoSGBM_MODE_HH,
    "sgbm_3way": cv2.StereoSGBM_MODE_SGBM_3WAY,
    "hh4": cv2.StereoSGBM_MODE_HH4,
}


def _from_fixed_point(raw: np.ndarray) -> np.ndarray:
    """OpenCV's int16 disparity (x16, negative = invalid when minDisparity = 0) -> float32 pixels with NaN."""
    disp = raw.astype(np.float32) / float(cv2.StereoMatcher_DISP_SCALE)
    disp[raw < 0] = np.nan
    return disp


def _opencv_num_disp(max_disp: int, width: int) -> int:
    """numDisparities rounded up to OpenCV's required multiple of 16, kept below the width."""
    n = -(-int(max_disp) // 16) * 16
    if n >= width:
        raise ValueError(f"`max_disp` rounded up to a multiple of 16 ({n}) must be less than the width {width} "
                         "for the OpenCV matchers")
    return n


def disparity_opencv_bm(left: np.ndarray, right: np.ndarray, max_disp: int, *, block_size: int = 15,
                        uniqueness: int = 15, speckle_size: int = 100, speckle_range: int = 2) -> np.ndarray:
    """OpenCV block matching (``cv2.StereoBM``) on grayscale, returned like :func:`disparity_sgm`.

    Parameters
    ----------
    left, right, max_disp
        As for :func:`disparity_sgm`; ``max_disp`` is rounded up to a multiple of 16 as OpenCV requires.
    block_size : int
        Odd SAD window side in [5, 255].
    uniqueness : int
        OpenCV ``uniquenessRatio`` in percent.
    speckle_size, speckle_range : int
        OpenCV ``speckleWindowSize`` and ``speckleRange`` (pixels).

    Returns
    -------
    ndarray, (H, W) float32
        Disparity of the left image in pixels, NaN where OpenCV marks it invalid.
    """
    _check_pair(left, right, max_disp)
    if block_size % 2 == 0 or not 5 <= block_size <= 255:
        raise ValueError(f"`block_size` must be odd and in [5, 255], got {block_size}")
    bm = cv2.StereoBM_create(numDisparities=_opencv_num_disp(max_disp, left.shape[1]), blockSize=int(block_size))
    bm.setUniquenessRatio(int(uniqueness))
    bm.setSpeckleWindowSize(int(speckle_size))
    bm.setSpeckleRange(int(speckle_range) * 16)
    disp = _from_fixed_point(bm.compute(_gray(left), _gray(right)))
    disp[disp >= max_disp] = np.nan
    return disp


def disparity_opencv_sgbm(left: np.ndarray, right: np.ndarray, max_disp: int, *, mode: str = "sgbm",
                          block_size: int = 3, uniqueness: int = 10, speckle_size: int = 100,
                          speckle_range: int = 2, lr_max_diff: int = 1) -> np.ndarray:
    """OpenCV semi-global block matching (``cv2.StereoSGBM``), returned like :func:`disparity_sgm`.

    Parameters
    ----------
    left, right, max_disp
        As for :func:`disparity_sgm`; ``max_disp`` is rounded up to a multiple of 16 as OpenCV requires.
    mode : {"sgbm", "hh", "sgbm_3way", "hh4"}
        OpenCV mode: 5 directions in one pass, the full 8-direction algorithm, 3-way parallel, or 4 directions.
    block_size : int
        Odd matching block side in [1, 11]; P1 = 8 * channels * block_size**2 and P2 = 32 * channels *
        block_size**2 as OpenCV's documentation recommends.
    uniqueness, speckle_size, speckle_range, lr_max_diff : int
        OpenCV ``uniquenessRatio`` (percent), ``speckleWindowSize``, ``speckleRange`` (pixels), ``disp12MaxDiff``.

    Returns
    -------
    ndarray, (H, W) float32
        Disparity of the left image in pixels, NaN where OpenCV marks it invalid.
    """
    _check_pair(left, right, max_disp)
    if mode not in SGBM_MODES:
        raise ValueError(f"`mode` must be one of {sorted(SGBM_MODES)}, got {mode!r}")
    if block_size % 2 == 0 or not 1 <= block_size <= 11:
        raise ValueError(f"`block_size` must be odd and in [1, 11], got {block_size}")
    cn = 1 if left.ndim == 2 else 3
    h, w = left.shape[:2]
    nd = _opencv_num_disp(max_disp, w)
    # the full-image modes keep an (H, W, D) int16 cost and path sum; the others a few rows of it
    per = float(h) * w * nd * 4 if mode in ("hh", "hh4") else float(w) * nd * 2 * 16 + float(h) * w * 8
    check_memory(per, f"OpenCV SGBM ({mode}) on {w}x{h} pixels x {nd} disparities",
                 "lower `--max-disp` or downscale both images")
    sgbm = cv2.StereoSGBM_create(
        minDisparity=0, numDisparities=_opencv_num_disp(max_disp, left.shape[1]), blockSize=int(block_size),
        P1=8 * cn * block_size**2, P2=32 * cn * block_size**2, disp12MaxDiff=int(lr_max_diff),
        uniquenessRatio=int(uniqueness), speckleWindowSize=int(speckle_size), speckleRange=int(speckle_range),
        mode=SGBM_MODES[mode],
    )
    disp = _from_fixed_point(sgbm.compute(left, right))
    disp[disp >= max_disp] = np.nan
    return disp


#: method name -> function(left, right, max_disp, **options) -> (H, W) float32 disparity with NaN
METHODS: dict[str, Callable[..., np.ndarray]] = {
    "sgm": disparity_sgm,
    "opencv_bm": disparity_opencv_bm,
    "opencv_sgbm": disparity_opencv_sgbm,
}


def compute_disparity(left: np.ndarray, right: np.ndarray, max_disp: int, method: str = "sgm",
                      **options) -> np.ndarray:
    """Disparity of the left image with the registered ``method`` (see :data:`METHODS`); options go to it."""
    if method not in METHODS:
        raise ValueError(f"`method` must be one of {sorted(METHODS)}, got {method!r}")
    return METHODS[method](left, right, max_disp, **options)


# ----------------------------------------------------------------------------------------------- results


#: bad-pixel thresholds in pixels used by the stages and the benchmark (Middlebury's bad-1.0 and bad-2.0)
BAD_THRESHOLDS = (1.0, 2.0)


def evaluate(disp: np.ndarray, truth: np.ndarray, thresholds: tuple[float, ...] = BAD_THRESHOLDS,
             mask: np.ndarray | None = None) -> dict[str, float]:
    """Accuracy of a disparity map against the truth, over the pixels with known truth.

    Parameters
    ----------
    disp, truth : ndarray, (H, W) float
        Estimated and true disparity in pixels; NaN = no estimate / unknown truth.
    thresholds : tuple of float
        Bad-pixel thresholds in pixels; each gives a key ``bad_<t>`` (e.g. ``bad_2.0``).
    mask : ndarray, (H, W) bool, optional
        Restrict the evaluation to these pixels.

    Returns
    -------
    dict
        ``bad_<t>`` (missing or off by more than t, share of known pixels), ``mean_error`` (pixels, over pixels
        with both an estimate and truth) and ``density`` (share of known pixels with an estimate).
    """
    out = {f"bad_{float(t):.1f}": metrics.bad_pixel_rate(disp, truth, float(t), mask) for t in thresholds}
    out["mean_error"] = metrics.mean_abs_error(disp, truth, mask)
    out["density"] = metrics.density(disp, truth, mask)
    return out


def to_png16(disp: np.ndarray) -> np.ndarray:
    """(H, W) uint16 image of ``round(256 * disparity)``, 0 where NaN (the KITTI convention; exact to 1/256 px).

    Raises ``ValueError`` for negative disparities or disparities of 256 px or more, which the format cannot hold.
    """
    finite = np.isfinite(disp)
    if finite.any() and (disp[finite].min() < 0 or disp[finite].max() >= 256):
        raise ValueError("`disp` must lie in [0, 256) pixels to be stored as a 16-bit PNG")
    out = np.zeros(disp.shape, np.uint16)
    out[finite] = np.clip(np.round(disp[finite] * 256.0), 1, 65535).astype(np.uint16)
    return out


def colorize_disparity(disp: np.ndarray, max_disp: float) -> np.ndarray:
    """(H, W, 3) uint8 BGR picture of a disparity map: turbo colour map over [0, max_disp], black where NaN."""
    if not max_disp > 0:
        raise ValueError(f"`max_disp` must be > 0, got {max_disp}")
    finite = np.isfinite(disp)
    scaled = np.zeros(disp.shape, np.uint8)
    scaled[finite] = np.clip(disp[finite] / float(max_disp) * 255.0, 0, 255).astype(np.uint8)
    pic = cv2.applyColorMap(scaled, cv2.COLORMAP_TURBO)
    pic[~finite] = 0
    return pic


def error_picture(disp: np.ndarray, truth: np.ndarray, clip: float = 4.0) -> np.ndarray:
    """(H, W, 3) uint8 BGR map of |disp - truth|: black (0) to white (>= ``clip`` px) on a hot scale; missing
    estimates with known truth in blue, unknown truth in mid grey."""
    if disp.shape != truth.shape:
        raise ValueError(f"`disp` must have the shape of `truth` {truth.shape}, got {disp.shape}")
    if not clip > 0:
        raise ValueError(f"`clip` must be > 0, got {clip}")
    known = np.isfinite(truth)
    both = known & np.isfinite(disp)
    scaled = np.zeros(disp.shape, np.uint8)
    scaled[both] = np.clip(np.abs(disp[both] - truth[both]) / clip * 255.0, 0, 255).astype(np.uint8)
    pic = cv2.applyColorMap(scaled, cv2.COLORMAP_HOT)
    pic[known & ~both] = (255, 80, 0)
    pic[~known] = (128, 128, 128)
    return pic


# ------------------------------------------------------------------------------- pipeline results and report


def metric_key(name: str) -> str:
    """A pair name as a metrics key: no dots (DVC joins nested keys with dots) and never ``all``."""
    key = str(name).replace(".", "_")
    return "pair_all" if key == "all" else key


def pair_result(disp: np.ndarray, max_disp: int, truth: np.ndarray | None = None) -> dict:
    """The numbers of one disparity map: ``max_disp``, ``valid_fraction`` (share of all pixels with an estimate)
    and, with ``truth``, ``bad_1`` / ``bad_2`` (see :func:`evaluate`), ``density`` and ``mean_error_px``; a value
    that does not exist (no known truth pixel) is left out rather than NaN."""
    out: dict = {"max_disp": int(max_disp), "valid_fraction": float(np.isfinite(disp).mean())}
    if truth is not None:
        ev = evaluate(disp, truth)
        named = {f"bad_{t:g}": ev[f"bad_{float(t):.1f}"] for t in BAD_THRESHOLDS}
        named.update(density=ev["density"], mean_error_px=ev["mean_error"])
        out.update({k: float(v) for k, v in named.items() if np.isfinite(v)})
    return out


#: per-pair keys that need the truth, averaged over the pairs with truth in ``all``
TRUTH_KEYS = tuple(f"bad_{t:g}" for t in BAD_THRESHOLDS) + ("density", "mean_error_px")


def metrics_of(run: dict) -> dict:
    """``{"stereo": {method: {"all": {...}, pair: {...}}}}`` from one ``stereo_disparity`` result ``{"method",
    "pairs": {name: pair_result(...) + {"truth": bool}}}``; ``all`` holds ``pairs``, the mean ``valid_fraction``
    and, over the pairs with truth, ``truth_pairs`` and the mean of each truth key."""
    pairs = run["pairs"]
    summary: dict = {"pairs": len(pairs)}
    if pairs:
        summary["valid_fraction"] = float(np.mean([r["valid_fraction"] for r in pairs.values()]))
    with_truth = [r for r in pairs.values() if r["truth"]]
    if with_truth:
        summary["truth_pairs"] = len(with_truth)
        for k in TRUTH_KEYS:
            vals = [r[k] for r in with_truth if k in r]
            if vals:
                summary[k] = float(np.mean(vals))
    per_pair = {metric_key(n): {k: (int(v) if isinstance(v, bool) else v) for k, v in r.items()}
                for n, r in pairs.items()}
    return {"stereo": {run["method"]: {"all": summary, **per_pair}}}


def merge_dropped(runs: dict) -> list[dict]:
    """The ``dropped`` lists of the methods' runs as one: an (item, reason) that every method dropped is listed
    once, one that only some dropped names them (``"pair (opencv_bm)"``)."""
    seen: dict[tuple[str, str], list[str]] = {}
    for method, run in runs.items():
        for d in run["dropped"]:
            seen.setdefault((d["item"], d["reason"]), []).append(method)
    return [{"item": item if len(ms) == len(runs) else f"{item} ({', '.join(ms)})", "reason": reason}
            for (item, reason), ms in seen.items()]


def _labelled(pic: np.ndarray, label: str, width: int) -> np.ndarray:
    h = max(1, int(round(pic.shape[0] * width / pic.shape[1])))
    bar = np.full((24, width, 3), 255, np.uint8)
    cv2.putText(bar, label, (4, 17), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([bar, cv2.resize(pic, (width, h), interpolation=cv2.INTER_AREA)])


def comparison_picture(left: np.ndarray, disparities: dict, max_disp: int, truth: np.ndarray | None = None,
                       error_clip: float = 4.0, width: int = 320) -> np.ndarray:
    """One pair's methods side by side: the left image and each method's colour-mapped disparity; with ``truth`` a
    second row with the true disparity and each method's error map (:func:`error_picture`).

    Parameters
    ----------
    left : (H, W) or (H, W, 3) uint8
        The left image.
    disparities : dict
        Label -> (H, W) float disparity (NaN = none), or None for a method that failed (a grey panel).
    max_disp : int
        The top of the colour scale (the pair's search range).
    truth : (H, W) float, optional
        True disparity (NaN = unknown).
    error_clip : float
        Absolute error (pixels) at which the error maps saturate.
    width : int
        Width of each panel in pixels.

    Returns
    -------
    (rows * (h + 24), width * (1 + len(disparities)), 3) uint8 BGR
    """
    grey = np.full(left.shape[:2] + (3,), 96, np.uint8)
    top = [_labelled(cv2.cvtColor(left, cv2.COLOR_GRAY2BGR) if left.ndim == 2 else left, "left image", width)]
    for label, d in disparities.items():
        top.append(_labelled(grey if d is None else colorize_disparity(d, max_disp), f"{label}" +
                             (": failed" if d is None else ""), width))
    rows = [np.hstack(top)]
    if truth is not None:
        bottom = [_labelled(colorize_disparity(truth, max_disp), "true disparity", width)]
        for label, d in disparities.items():
            bottom.append(_labelled(grey if d is None else error_picture(d, truth, error_clip),
                                    f"{label} |error|", width))
        rows.append(np.hstack(bottom))
    return np.vstack(rows)


def report_summary(runs: dict, pictures: list[dict], dropped: list[dict], error_clip: float) -> dict:
    """The report page's summary of the stereo task (schema in ``cvpipe.report``).

    Parameters
    ----------
    runs : dict
        Method -> ``stereo_disparity`` result (``{"method", "pairs": {name: {...}}, "dropped"}``).
    pictures : list of dict
        ``{"path", "caption"}`` per pair picture, repo-relative paths.
    dropped : list of dict
        ``{"item", "reason"}`` for every input that was not processed (:func:`merge_dropped`).
    error_clip : float
        The saturation of the error maps (pixels), for the description.
    """
    none = "no ground truth"
    names = list(dict.fromkeys(n for run in runs.values() for n in run["pairs"]))
    truth_pairs = sorted({n for run in runs.values() for n, r in run["pairs"].items() if r["truth"]})

    def pct(v):
        return None if v is None else round(100.0 * v, 2)

    per_method = []
    for method, run in runs.items():
        s = metrics_of(run)["stereo"][method]["all"]
        acc = ([pct(s.get("bad_1")), pct(s.get("bad_2")), None if "mean_error_px" not in s else
                round(s["mean_error_px"], 3), pct(s.get("density"))] if truth_pairs else [none] * 4)
        per_method.append([method, f"{len(run['pairs'])} / {len(names)}", pct(s.get("valid_fraction")), *acc])
    per_pair = []
    for name in names:
        for method, run in runs.items():
            r = run["pairs"].get(name)
            if r is None:
                per_pair.append([name, method, None, "failed", "failed", "failed"])
                continue
            per_pair.append([name, method, r["max_disp"], pct(r["valid_fraction"]),
                             pct(r.get("bad_2")) if r["truth"] else none,
                             (round(r["mean_error_px"], 3) if "mean_error_px" in r else None) if r["truth"] else none])
    tables = [
        {"title": "Per method (means over the pairs)",
         "columns": ["method", "pairs", "valid %", "bad-1.0 %", "bad-2.0 %", "mean error px", "density %"],
         "rows": per_method},
        {"title": "Per pair", "columns": ["pair", "method", "max_disp", "valid %", "bad-2.0 %", "mean error px"],
         "rows": per_pair},
    ]
    if dropped:
        tables.append({"title": "Not processed", "columns": ["input", "reason"],
                       "rows": [[d["item"], d["reason"]] for d in dropped]})
    if truth_pairs:
        truth_note = (f"{len(truth_pairs)} of {len(names)} pairs have a true disparity ({', '.join(truth_pairs)}). "
                      "A pixel is bad when its estimate is missing or off by more than the threshold, over all pixels "
                      "with known truth; mean error is over pixels with an estimate; density is the share of known "
                      f"pixels with an estimate. Error maps: white at {error_clip:g} px or more, blue = missing, "
                      "grey = unknown truth.")
    else:
        truth_note = ("These pairs have no ground truth: the tables give the share of pixels with a (trusted) "
                      "estimate, and the pictures show each method's disparity.")
    return {
        "task": "stereo",
        "title": "Disparity of rectified pairs: our semi-global matching vs OpenCV BM / SGBM",
        "description": (f"Every method searches the pair's disparity range (max_disp). {truth_note} Disparity "
                        "pictures: turbo colour map from 0 to max_disp, black = no estimate. Times: `dvc plots "
                        "show` (outputs/timings) and `cvpipe bench stereo`."),
        "pictures": pictures,
        "tables": tables,
    }


def quality_plots(runs: dict) -> dict[str, list[dict]]:
    """``dvc plots`` rows per file: ``bad_2`` (pairs with truth) and ``valid_fraction`` (every pair), each row
    ``{"pair", "method", "label", <value>}``."""
    bad, valid = [], []
    for method, run in runs.items():
        for name, r in run["pairs"].items():
            base = {"pair": name, "method": method, "label": f"{name} {method}"}
            valid.append({**base, "valid_fraction": r["valid_fraction"]})
            if "bad_2" in r:
                bad.append({**base, "bad_2": r["bad_2"]})
    return {"bad_2": bad, "valid_fraction": valid}
