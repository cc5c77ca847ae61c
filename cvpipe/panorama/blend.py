"""Blending warped images into one panorama: gain compensation, then multi-band or feather blending of the seams.

* :func:`gain_compensation`: one gain per image so that overlaps agree in mean intensity, kept near 1 (the
  quadratic objective of Brown & Lowe, 2007, solved as a small linear least-squares problem);
  :func:`compensation_gains` also gives OpenCV's other kinds: per colour channel, per block, per block and channel.
* :func:`blend_multiband`: Laplacian-pyramid blending (Burt & Adelson, 1983) of the seam regions: low frequencies
  blend over wide bands, fine detail over narrow ones, so exposure steps vanish without ghosting.
* :func:`blend_feather`: weighted average with weights growing with the distance to each image's border.
* :func:`compose`: gains, seams (:mod:`cvpipe.panorama.seams`) and the chosen blender.
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

import cv2
import numpy as np

from ..errors import check_int
from .seams import _distance, seam_labels, seam_lines
from .warp import Warped


def _overlaps(w: Warped, step: int):
    """Yield (i, j, gray_i, gray_j) over the subsampled overlap of every pair of warped images."""
    # each image's grey once (the conversion is per pixel: the same values as converting each pair's samples)
    greys = [img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) for img in w.images]
    for i, j, _, _, gi, gj in _samples(Warped(greys, w.masks, w.corners, w.size, w.origin), step, channels=False):
        yield i, j, gi[:, 0], gj[:, 0]


def _step(w: Warped, samples: float = 4e5) -> int:
    total = sum(m.size for m in w.masks)
    return max(1, int(np.sqrt(total / samples)))


def gain_compensation(w: Warped, sigma_n: float = 10.0, sigma_g: float = 0.1) -> np.ndarray:
    """One multiplicative gain per image that equalises the mean intensity of the overlaps.

    Minimises ``sum_ij N_ij [ (g_i I_ij - g_j I_ji)^2 / sigma_n^2 ] + sum_i N_i (1 - g_i)^2 / sigma_g^2``, with
    ``I_ij`` the mean grey level of image ``i`` over its overlap with ``j`` (``N_ij`` pixels, subsampled) and
    ``N_i`` the overlap pixels of image ``i``.

    Returns
    -------
    (N,) float64
        Gains (1 for an image without overlaps).
    """
    n = len(w.images)
    rows, rhs = [], []
    weight = np.zeros(n)
    for i, j, gi, gj in _overlaps(w, _step(w)):
        r = np.zeros(n)
        s = np.sqrt(len(gi)) / sigma_n
        r[i], r[j] = s * gi.mean(), -s * gj.mean()
        rows.append(r)
        rhs.append(0.0)
        weight[i] += len(gi)
        weight[j] += len(gi)
    for i in range(n):
        r = np.zeros(n)
        r[i] = np.sqrt(max(weight[i], 1.0)) / sigma_g
        rows.append(r)
        rhs.append(r[i])
    g, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
    return g


def overlap_difference(w: Warped, gains: np.ndarray | None = None) -> float:
    """Ghosting measure: mean absolute grey-level difference between overlapping warped images.

    Averaged over all overlap pixels of all pairs (subsampled), after applying ``gains`` (any form
    :func:`compensation_gains` returns); NaN-free: 0.0 when nothing overlaps.
    """
    if gains is not None and np.ndim(gains[0]) > 0:  # per channel or per pixel: measured on the gained images
        return overlap_difference(apply_gains(w, gains))
    g = np.ones(len(w.images)) if gains is None else np.asarray(gains, float)
    total, count = 0.0, 0
    for i, j, gi, gj in _overlaps(w, _step(w)):
        total += float(np.abs(np.clip(g[i] * gi, 0, 255) - np.clip(g[j] * gj, 0, 255)).sum())
        count += len(gi)
    return total / count if count else 0.0


#: ``gain_compensation`` choices, OpenCV's ``cv2.detail`` exposure compensators (NO, GAIN, CHANNELS, GAIN_BLOCKS,
#: CHANNELS_BLOCKS): one grey gain per image, one gain per colour channel, a smooth map of grey gains over blocks of
#: ``gain_block`` pixels, or one such map per channel
GAIN_CHOICES = ("none", "gain", "channels", "blocks", "channel_blocks")
DEFAULT_GAIN = "gain"
#: side of the blocks of the block compensators, pixels (OpenCV's default)
DEFAULT_GAIN_BLOCK = 32
#: passes of the [1/4, 1/2, 1/4] smoothing over each image's grid of block gains (OpenCV's default)
GAIN_SMOOTHING_PASSES = 2


def _samples(w: Warped, step: int, channels: bool):
    """Yield (i, j, y, x, v_i, v_j) per overlapping pair: canvas rows and columns of the subsampled overlap pixels
    covered by both images and their values there ((m, 3) BGR when ``channels``, else (m, 1) grey), float32."""
    n = len(w.images)
    for i in range(n):
        xi, yi = w.corners[i]
        hi, wi = w.masks[i].shape
        for j in range(i + 1, n):
            xj, yj = w.corners[j]
            hj, wj = w.masks[j].shape
            x0, y0 = max(xi, xj), max(yi, yj)
            x1, y1 = min(xi + wi, xj + wj), min(yi + hi, yj + hj)
            if x1 <= x0 or y1 <= y0:
                continue
            si = (slice(y0 - yi, y1 - yi, step), slice(x0 - xi, x1 - xi, step))
            sj = (slice(y0 - yj, y1 - yj, step), slice(x0 - xj, x1 - xj, step))
            both = (w.masks[i][si] > 0) & (w.masks[j][sj] > 0)
            if both.sum() < 16:
                continue
            rows, cols = np.nonzero(both)
            vals = []
            for k, s in ((i, si), (j, sj)):
                img = w.images[k][s]
                if img.ndim == 2 and channels:
                    img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_GRAY2BGR)
                elif img.ndim == 3 and not channels:
                    img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_BGR2GRAY)
                vals.append(img[both].astype(np.float32).reshape(len(rows), -1))
            yield i, j, y0 + rows * step, x0 + cols * step, vals[0], vals[1]


def _block_grid(w: Warped, k: int, block: int | None) -> tuple[int, int]:
    """Rows and columns of image ``k``'s block grid (one block when ``block`` is None)."""
    if block is None:
        return 1, 1
    h, ww = w.masks[k].shape
    return -(-h // block), -(-ww // block)


def _solve_gains(w: Warped, block: int | None, channels: bool, sigma_n: float, sigma_g: float) -> list:
    """Gains of every block (of every image when ``block`` is None) from the objective of :func:`gain_compensation`
    with blocks in place of images; a list of (rows, cols, C) grids, C = 3 with ``channels`` else 1."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import spsolve

    n = len(w.images)
    grids = [_block_grid(w, k, block) for k in range(n)]
    first = np.cumsum([0] + [r * c for r, c in grids])
    nodes, nc = int(first[-1]), 3 if channels else 1
    keys, counts, sums_a, sums_b = [], [], [], []
    for i, j, y, x, vi, vj in _samples(w, _step(w), channels):
        if block is None:
            a, b = np.full(len(y), first[i]), np.full(len(y), first[j])
        else:
            (xi, yi), (xj, yj) = w.corners[i], w.corners[j]
            a = first[i] + (y - yi) // block * grids[i][1] + (x - xi) // block
            b = first[j] + (y - yj) // block * grids[j][1] + (x - xj) // block
        pair, inv = np.unique(a * nodes + b, return_inverse=True)
        keys.append(pair)
        counts.append(np.bincount(inv, minlength=len(pair)).astype(np.float64))
        sums_a.append(np.stack([np.bincount(inv, vi[:, c], len(pair)) for c in range(nc)], 1))
        sums_b.append(np.stack([np.bincount(inv, vj[:, c], len(pair)) for c in range(nc)], 1))
    gains = np.ones((nodes, nc))
    if keys:
        key, N = np.concatenate(keys), np.concatenate(counts)
        a, b = key // nodes, key % nodes
        Ia, Ib = np.concatenate(sums_a) / N[:, None], np.concatenate(sums_b) / N[:, None]
        weight = np.bincount(a, N, nodes) + np.bincount(b, N, nodes)
        prior = np.maximum(weight, 1.0) / sigma_g ** 2
        for c in range(nc):
            # normal equations of sum N (g_a I_a - g_b I_b)^2 / sigma_n^2 + sum W (1 - g)^2 / sigma_g^2
            rows = np.concatenate([a, b, a, b, np.arange(nodes)])
            cols = np.concatenate([a, b, b, a, np.arange(nodes)])
            vals = np.concatenate([N * Ia[:, c] ** 2, N * Ib[:, c] ** 2, -N * Ia[:, c] * Ib[:, c],
                                   -N * Ia[:, c] * Ib[:, c]]) / sigma_n ** 2
            A = coo_matrix((np.concatenate([vals, prior]), (rows, cols)), shape=(nodes, nodes)).tocsc()
            gains[:, c] = spsolve(A, prior)
    return [gains[first[k]:first[k + 1]].reshape(*grids[k], nc) for k in range(n)]


def _smooth(grid: np.ndarray, passes: int) -> np.ndarray:
    """``grid`` (rows, cols, C) filtered ``passes`` times by [1/4, 1/2, 1/4] along both axes (edges repeated)."""
    for _ in range(passes):
        for axis in (0, 1):
            p = np.pad(grid, [(1, 1) if a == axis else (0, 0) for a in range(3)], mode="edge")
            lo = [slice(None)] * 3
            mid, hi = list(lo), list(lo)
            n = grid.shape[axis]
            lo[axis], mid[axis], hi[axis] = slice(0, n), slice(1, n + 1), slice(2, n + 2)
            grid = 0.25 * p[tuple(lo)] + 0.5 * p[tuple(mid)] + 0.25 * p[tuple(hi)]
    return grid


def _gain_map(grid: np.ndarray, shape: tuple[int, int], block: int) -> np.ndarray:
    """Per-pixel gains (h, w, C) float32 bilinearly interpolated between the block centres of ``grid``."""
    rows, cols, nc = grid.shape
    g = cv2.resize(grid.astype(np.float32), (cols * block, rows * block), interpolation=cv2.INTER_LINEAR)
    return g.reshape(rows * block, cols * block, nc)[:shape[0], :shape[1]]


def compensation_gains(w: Warped, mode: str = DEFAULT_GAIN, block: int = DEFAULT_GAIN_BLOCK,
                       sigma_n: float = 10.0, sigma_g: float = 0.1) -> list | np.ndarray | None:
    """The exposure compensation of ``mode`` (one of :data:`GAIN_CHOICES`), in the form the blenders take.

    All modes minimise the objective of :func:`gain_compensation`; ``channels`` does it per colour channel, the
    block modes with every ``block`` x ``block`` block of every image as an unknown (pairs of overlapping blocks of
    two images give the equations), after which each image's grid of block gains is smoothed
    (:data:`GAIN_SMOOTHING_PASSES` passes of [1/4, 1/2, 1/4]) and interpolated bilinearly to every pixel, as
    OpenCV's block compensators do.

    Parameters
    ----------
    w : Warped
    mode : {"none", "gain", "channels", "blocks", "channel_blocks"}
    block : int
        Block side in pixels (the block modes only), >= 4.
    sigma_n, sigma_g : float
        Standard deviations of the intensity error and of the gains (Brown & Lowe's 10 and 0.1).

    Returns
    -------
    None, (N,) float64, (N, 3) float64 or list of (h, w, 1 or 3) float32
        Nothing to apply (``none``); one gain per image (``gain``), per image and BGR channel (``channels``);
        per image a per-pixel map the size of its warped box (block modes).

    Examples
    --------
    >>> img = np.full((40, 60, 3), (100, 100, 100), np.uint8)
    >>> w = Warped([img, (img * np.array([1.0, 0.5, 1.0])).astype(np.uint8)], [np.full((40, 60), 255, np.uint8)] * 2,
    ...            [(0, 0), (30, 0)], (90, 40), (0, 0))
    >>> g = compensation_gains(w, "channels")
    >>> bool(g[1, 1] / g[0, 1] > 1.3 and abs(g[1, 0] / g[0, 0] - 1) < 1e-9)  # green of image 1 raised, blue not
    True
    """
    if mode not in GAIN_CHOICES:
        raise ValueError(f"`gain_compensation` must be one of {list(GAIN_CHOICES)}, got {mode!r}")
    check_int("gain_block", block, 4)
    if mode == "none":
        return None
    if mode == "gain":
        return gain_compensation(w, sigma_n, sigma_g)
    blocks = mode in ("blocks", "channel_blocks")
    grids = _solve_gains(w, block if blocks else None, mode in ("channels", "channel_blocks"), sigma_n, sigma_g)
    if not blocks:
        return np.stack([g.reshape(3) for g in grids])
    return [_gain_map(_smooth(g, GAIN_SMOOTHING_PASSES), m.shape, block) for g, m in zip(grids, w.masks)]


def _gain_of(gains, k: int) -> np.ndarray:
    """Image ``k``'s gain as float32 broadcastable against its (h, w, 3) pixels: () , (3,) or (h, w, 1 or 3)."""
    return np.asarray(gains[k], np.float32)


def apply_gains(w: Warped, gains) -> Warped:
    """``w`` with the gains of :func:`compensation_gains` applied (uint8, rounded and saturated)."""
    if gains is None:
        return w
    out = []
    for k, img in enumerate(w.images):
        im = img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        out.append(np.clip(im * _gain_of(gains, k) + 0.5, 0, 255).astype(np.uint8))
    return Warped(out, w.masks, w.corners, w.size, w.origin)


def _three(a: np.ndarray) -> np.ndarray:
    """A (H, W) float32 array repeated into 3 channels (OpenCV's arithmetic wants equal channel counts)."""
    return cv2.merge([a, a, a])


#: images whose multiband pyramids are built at once (:func:`blend_multiband`): the steps are memory-bound, so two
#: threads keep two cores busy, and the memory rule (the crops in work never exceed the largest box) rarely fits more
BLEND_THREADS = 2


def _reach_of_own(own: np.ndarray, corner: tuple[int, int], box: tuple[int, int, int, int],
                  P: int) -> tuple[int, int, int, int] | None:
    """The part of an image's padded box (canvas pixels, multiples of ``P``) that its pyramid needs: the box of
    the pixels the seams gave it (``own``, over the image's own box at ``corner``), grown by ``2 * P``, or None when
    it has none.

    A level-l weight spreads about ``2**(l+1)`` pixels beyond the own pixels, and the Laplacian there reads about as
    far again: ``2 * P`` (``P = 2**bands``) covers both at the coarsest level, so every value the blend uses is the
    one the whole box gives (the crop's border reflection stays outside what is read; tested against the whole box).
    """
    x, y = corner
    rows, cols = np.flatnonzero(own.any(1)), np.flatnonzero(own.any(0))
    if len(rows) == 0:
        return None
    reach = 2 * P
    ax0, ay0, ax1, ay1 = box
    return (max(ax0, (x + cols[0] - reach) // P * P), max(ay0, (y + rows[0] - reach) // P * P),
            min(ax1, -(-(x + cols[-1] + 1 + reach) // P) * P), min(ay1, -(-(y + rows[-1] + 1 + reach) // P) * P))


def _level0_laplacian(norm: np.ndarray, nxt: np.ndarray, sl: tuple[slice, slice]) -> np.ndarray:
    """``norm - pyrUp(nxt)`` on the region ``sl`` only (the image's pixels in its crop), with one pixel of ``nxt``
    around it so that the expansion there equals the whole one."""
    y0, y1, x0, x1 = sl[0].start, sl[0].stop, sl[1].start, sl[1].stop
    # pyrUp's output pixel 2i or 2i+1 reads input rows i-1..i+1: expand from one input pixel before to one after
    cy0, cx0 = max(y0 // 2 - 1, 0), max(x0 // 2 - 1, 0)
    cy1, cx1 = min((y1 + 1) // 2 + 1, nxt.shape[0]), min((x1 + 1) // 2 + 1, nxt.shape[1])
    up = cv2.pyrUp(np.ascontiguousarray(nxt[cy0:cy1, cx0:cx1]), dstsize=(2 * (cx1 - cx0), 2 * (cy1 - cy0)))
    up = up[y0 - 2 * cy0:y1 - 2 * cy0, x0 - 2 * cx0:x1 - 2 * cx0]
    return cv2.subtract(norm[sl], up)


def _image_share(w: Warped, own_box: np.ndarray, k: int, crop: tuple[int, int, int, int], bands: int,
                 gain: np.ndarray) -> tuple:
    """Image ``k``'s part of the multiband blend over ``crop`` (canvas pixels, from :func:`_reach_of_own`);
    ``own_box``: which pixels of its box the seams gave it.

    Returns ``(crop, sl, own, lap0, coarse)``: the crop, the image's pixels in it ``sl``, which of them it owns, the
    level-0 Laplacian there (copied where it owns) and, per coarser level, the Laplacian times the blurred seam
    weight and that weight.
    """
    img, mask, (x, y) = w.images[k], w.masks[k], w.corners[k]
    ax0, ay0, ax1, ay1 = crop
    # the part of the image inside the crop, in the crop's and in the image's pixels
    ix0, iy0, ix1, iy1 = max(x, ax0), max(y, ay0), min(x + mask.shape[1], ax1), min(y + mask.shape[0], ay1)
    sl = (slice(iy0 - ay0, iy1 - ay0), slice(ix0 - ax0, ix1 - ax0))
    isl = (slice(iy0 - y, iy1 - y), slice(ix0 - x, ix1 - x))
    sub = np.zeros((ay1 - ay0, ax1 - ax0, 3), np.float32)
    m = np.zeros((ay1 - ay0, ax1 - ax0), np.float32)
    im = img[isl] if img.ndim == 3 else cv2.cvtColor(img[isl], cv2.COLOR_GRAY2BGR)
    # warped images are 0 outside their mask, so image * mask is the gained image itself
    np.multiply(im, gain[isl] if gain.ndim == 3 else gain, out=sub[sl], casting="unsafe")
    m[sl] = mask[isl] > 0
    own = own_box[iy0 - y:iy1 - y, ix0 - x:ix1 - x]
    # level 0 copies `own` pixels; only the coarser levels need the float weight, so level 0's is built, shrunk
    # and dropped before the first Laplacian level exists (memory: the full-size box arrays are the peak)
    weight = np.zeros_like(m)
    weight[sl] = own
    weight = cv2.pyrDown(weight)
    # normalised pyramids (image * mask and mask blurred together, then divided) extend each level smoothly
    # past the image border, so no artificial black edge leaks into the blend
    gm, gw, norm = sub, m, sub
    del sub, m
    coarse = []
    for lev in range(bands + 1):
        if lev < bands:
            gm, gw = cv2.pyrDown(gm), cv2.pyrDown(gw)
            nxt = cv2.divide(gm, _three(np.maximum(gw, 1e-6)))
        if lev == 0:  # hard weights: this image's own pixels, whose Laplacian alone is needed
            lap0 = _level0_laplacian(norm, nxt, sl)
        else:
            if lev < bands:
                lap = cv2.pyrUp(nxt, dstsize=(norm.shape[1], norm.shape[0]))
                cv2.subtract(norm, lap, dst=lap)
            else:
                lap = norm
            cv2.multiply(lap, _three(weight), dst=lap)
            coarse.append((lap, weight))
        if lev < bands:
            norm = nxt
            if lev > 0:  # level 0's weight was shrunk before the loop
                weight = cv2.pyrDown(weight)
    return crop, sl, own, lap0, coarse


def blend_multiband(w: Warped, labels: np.ndarray, bands: int, gains=None) -> np.ndarray:
    """Multi-band (Laplacian pyramid) blending of the seam regions.

    Parameters
    ----------
    w : Warped
    labels : (H, W) int16
        From :func:`seam_labels`.
    bands : int
        Pyramid levels below full resolution (>= 1); the blend band of the coarsest level is about ``2**bands``
        pixels wide.
    gains : optional
        Gains applied before blending, as :func:`compensation_gains` returns them.

    Returns
    -------
    (H, W, 3) uint8
        The blended canvas, 0 where no image covers it.
    """
    check_int("bands", bands, 1, 12)
    W, H = w.size
    g = np.ones(len(w.images)) if gains is None else gains
    P = 1 << bands
    pad = 2 * P
    boxes = []
    for mask, (x, y) in zip(w.masks, w.corners):
        h, ww = mask.shape
        ax0, ay0 = (x - pad) // P * P, (y - pad) // P * P
        ax1, ay1 = -(-(x + ww + pad) // P) * P, -(-(y + h + pad) // P) * P
        boxes.append((ax0, ay0, ax1, ay1))
    bx = np.array(boxes)
    gx0, gy0, gx1, gy1 = bx[:, 0].min(), bx[:, 1].min(), bx[:, 2].max(), bx[:, 3].max()
    acc = [np.zeros(((gy1 - gy0) >> k, (gx1 - gx0) >> k, 3), np.float32) for k in range(bands + 1)]
    # level 0 needs no weight sum: the seam labels give every covered pixel to exactly one image
    wsum = [None] + [np.zeros(((gy1 - gy0) >> k, (gx1 - gx0) >> k), np.float32) for k in range(1, bands + 1)]

    def add(share) -> None:  # in image order, in this thread: the sums do not depend on the threads' timing
        (ax0, ay0, _, _), sl, own, lap0, coarse = share
        oy, ox = ay0 - gy0, ax0 - gx0
        dst = acc[0][oy + sl[0].start:oy + sl[0].stop, ox + sl[1].start:ox + sl[1].stop]
        cv2.copyTo(lap0, own.view(np.uint8), dst)
        for lev, (lap, weight) in enumerate(coarse, 1):
            oy, ox = (ay0 - gy0) >> lev, (ax0 - gx0) >> lev
            hh, wl = weight.shape
            dst = acc[lev][oy:oy + hh, ox:ox + wl]
            cv2.add(dst, lap, dst=dst)
            dst = wsum[lev][oy:oy + hh, ox:ox + wl]
            cv2.add(dst, weight, dst=dst)

    # the images' pyramids are built up to BLEND_THREADS at a time (OpenCV and numpy release the GIL) and added in
    # order; the crops being built at once never cover more pixels than the largest padded box, so the memory peak is
    # the one of building that box alone (what warp.canvas_memory counts)
    room = max((b[2] - b[0]) * (b[3] - b[1]) for b in boxes)
    pending: deque = deque()  # (future, crop pixels)
    with ThreadPoolExecutor(BLEND_THREADS) as pool:
        for k, (mask, (x, y), box) in enumerate(zip(w.masks, w.corners, boxes)):
            own = labels[y:y + mask.shape[0], x:x + mask.shape[1]] == k
            crop = _reach_of_own(own, (x, y), box, P)
            if crop is None:  # the seams gave this image no pixel: it adds nothing at any level
                continue
            area = (crop[2] - crop[0]) * (crop[3] - crop[1])
            while pending and (len(pending) >= BLEND_THREADS or sum(a for _, a in pending) + area > room):
                add(pending.popleft()[0].result())
            pending.append((pool.submit(_image_share, w, own, k, crop, bands, _gain_of(g, k)), area))
        while pending:
            add(pending.popleft()[0].result())
    out = None
    for lev in range(bands, -1, -1):
        level = acc[lev] if lev == 0 else cv2.divide(acc[lev], _three(np.maximum(wsum[lev], 1e-8)))
        acc[lev] = wsum[lev] = None  # each level is freed once collapsed (memory: the canvas arrays are the peak)
        if out is None:
            out = level
        else:
            out = cv2.pyrUp(out, dstsize=(level.shape[1], level.shape[0]))
            cv2.add(out, level, dst=out)
        del level
    out = out[-gy0:-gy0 + H, -gx0:-gx0 + W]
    # round and saturate to uint8 (convertScaleAbs rounds; negatives are clipped to 0 first, in place)
    np.maximum(out, 0, out=out)
    pano = cv2.convertScaleAbs(out)
    del out
    pano[labels < 0] = 0
    return pano


def blend_feather(w: Warped, labels: np.ndarray, bands: int = 0, gains=None) -> np.ndarray:
    """Feather blending: average weighted by each image's distance to its own border (``bands`` is unused).

    Returns
    -------
    (H, W, 3) uint8
        The blended canvas, 0 where no image covers it.
    """
    W, H = w.size
    g = np.ones(len(w.images)) if gains is None else gains
    acc = np.zeros((H, W, 3), np.float32)
    wsum = np.zeros((H, W), np.float32)
    for k, (img, mask, (x, y)) in enumerate(zip(w.images, w.masks, w.corners)):
        h, ww = mask.shape
        d = _distance(mask)
        im = img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        acc[y:y + h, x:x + ww] += im.astype(np.float32) * (d[..., None] * _gain_of(g, k))
        wsum[y:y + h, x:x + ww] += d
    pano = np.clip(acc / np.maximum(wsum, 1e-8)[..., None] + 0.5, 0, 255).astype(np.uint8)
    pano[labels < 0] = 0
    return pano


#: blender name -> function(warped, labels, bands, gains) -> (H, W, 3) uint8
BLENDERS: dict[str, Callable[..., np.ndarray]] = {"multiband": blend_multiband, "feather": blend_feather}


def compose(w: Warped, blender: str, bands: int, gain: str = DEFAULT_GAIN, gain_block: int = DEFAULT_GAIN_BLOCK
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Compensate the exposure (``gain``, one of :data:`GAIN_CHOICES`, blocks of ``gain_block`` pixels), find the
    seams and blend.

    Returns
    -------
    pano : (H, W, 3) uint8
    mask : (H, W) bool
        Pixels covered by at least one image.
    seams : (H, W) bool
        Seam lines between the images' regions.
    """
    pano, mask, seams, _ = _compose(w, blender, bands, gain, gain_block)
    return pano, mask, seams


def _compose(w: Warped, blender: str, bands: int, gain: str, gain_block: int) -> tuple:
    """:func:`compose`, and the gains it applied (for :func:`blend_set`'s record)."""
    if blender not in BLENDERS:
        raise ValueError(f"`blender` must be one of {sorted(BLENDERS)}, got {blender!r}")
    gains = compensation_gains(w, gain, gain_block)
    labels = seam_labels(w)
    pano = BLENDERS[blender](w, labels, bands, gains)
    return pano, labels >= 0, seam_lines(labels), gains


def blend_set(w: Warped, p) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict, float]:
    """Compensate, seam and blend one warped set: the per-set work of the ``panorama_blend`` stage, an item of
    :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    w : Warped
        The set's warped images and masks.
    p : PanoramaBlendParams
        ``blender``, ``bands``, ``gain_compensation``, ``gain_block``.

    Returns
    -------
    (pano, mask, seams, record, seconds)
        The (H, W, 3) uint8 panorama, its (H, W) bool mask and seams, the JSON record (``ok``, ``gains``: one per
        image, per image and channel, or each image's mean gain per channel in the block modes; ``ghosting`` with
        and without the gains) and the seconds the blending took.
    """
    import time

    t0 = time.perf_counter()
    pano, mask, seams, gains = _compose(w, p.blender, p.bands, p.gain_compensation, p.gain_block)
    seconds = time.perf_counter() - t0
    gains = np.ones(len(w.images)) if gains is None else gains
    shown = gains if isinstance(gains, np.ndarray) else np.stack([g.reshape(-1, g.shape[2]).mean(0) for g in gains])
    record = {"ok": True, "gains": shown, "ghosting": overlap_difference(w, gains),
              "ghosting_without_gains": overlap_difference(w)}
    return pano, mask, seams, record, seconds
