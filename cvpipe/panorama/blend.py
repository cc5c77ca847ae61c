"""Blending warped images into one panorama: gain compensation, then multi-band or feather blending of the seams.

* :func:`gain_compensation`: one gain per image so that overlaps agree in mean intensity, kept near 1 (the
  quadratic objective of Brown & Lowe, 2007, solved as a small linear least-squares problem).
* :func:`blend_multiband`: Laplacian-pyramid blending (Burt & Adelson, 1983) of the seam regions: low frequencies
  blend over wide bands, fine detail over narrow ones, so exposure steps vanish without ghosting.
* :func:`blend_feather`: weighted average with weights growing with the distance to each image's border.
* :func:`compose`: gains, seams (:mod:`cvpipe.panorama.seams`) and the chosen blender.
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from .seams import _distance, seam_labels, seam_lines
from .warp import Warped


def _overlaps(w: Warped, step: int):
    """Yield (i, j, gray_i, gray_j) over the subsampled overlap of every pair of warped images."""
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
            gi = _gray(w.images[i][si])[both]
            gj = _gray(w.images[j][sj])[both]
            yield i, j, gi, gj


def _gray(img: np.ndarray) -> np.ndarray:
    img = np.ascontiguousarray(img)
    return (cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img).astype(np.float32)


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

    Averaged over all overlap pixels of all pairs (subsampled), after applying ``gains``; NaN-free: 0.0 when
    nothing overlaps.
    """
    g = np.ones(len(w.images)) if gains is None else np.asarray(gains, float)
    total, count = 0.0, 0
    for i, j, gi, gj in _overlaps(w, _step(w)):
        total += float(np.abs(np.clip(g[i] * gi, 0, 255) - np.clip(g[j] * gj, 0, 255)).sum())
        count += len(gi)
    return total / count if count else 0.0


def _three(a: np.ndarray) -> np.ndarray:
    """A (H, W) float32 array repeated into 3 channels (OpenCV's arithmetic wants equal channel counts)."""
    return cv2.merge([a, a, a])


def blend_multiband(w: Warped, labels: np.ndarray, bands: int, gains: np.ndarray | None = None) -> np.ndarray:
    """Multi-band (Laplacian pyramid) blending of the seam regions.

    Parameters
    ----------
    w : Warped
    labels : (H, W) int16
        From :func:`seam_labels`.
    bands : int
        Pyramid levels below full resolution (>= 1); the blend band of the coarsest level is about ``2**bands``
        pixels wide.
    gains : (N,) float, optional
        Per-image gains applied before blending.

    Returns
    -------
    (H, W, 3) uint8
        The blended canvas, 0 where no image covers it.
    """
    if not isinstance(bands, (int, np.integer)) or not 1 <= bands <= 12:
        raise ValueError(f"`bands` must be an integer in [1, 12], got {bands!r}")
    W, H = w.size
    g = np.ones(len(w.images)) if gains is None else np.asarray(gains, float)
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
    for k, (img, mask, (x, y), (ax0, ay0, ax1, ay1)) in enumerate(zip(w.images, w.masks, w.corners, boxes)):
        h, ww = mask.shape
        sub = np.zeros((ay1 - ay0, ax1 - ax0, 3), np.float32)
        m = np.zeros((ay1 - ay0, ax1 - ax0), np.float32)
        weight = np.zeros_like(m)
        sl = (slice(y - ay0, y - ay0 + h), slice(x - ax0, x - ax0 + ww))
        im = img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        # warped images are 0 outside their mask, so image * mask is the gained image itself
        np.multiply(im, np.float32(g[k]), out=sub[sl], casting="unsafe")
        m[sl] = mask > 0
        own = labels[y:y + h, x:x + ww] == k
        weight[sl] = own
        # normalised pyramids (image * mask and mask blurred together, then divided) extend each level smoothly
        # past the image border, so no artificial black edge leaks into the blend
        gm, gw, norm = sub, m, sub
        for lev in range(bands + 1):
            if lev < bands:
                gm, gw = cv2.pyrDown(gm), cv2.pyrDown(gw)
                nxt = cv2.divide(gm, _three(np.maximum(gw, 1e-6)))
                lap = cv2.pyrUp(nxt, dstsize=(norm.shape[1], norm.shape[0]))
                cv2.subtract(norm, lap, dst=lap)
            else:
                lap = norm
            oy, ox = (ay0 - gy0) >> lev, (ax0 - gx0) >> lev
            hh, wl = weight.shape
            if lev == 0:  # hard weights: copy this image's own pixels
                dst = acc[0][oy + sl[0].start:oy + sl[0].stop, ox + sl[1].start:ox + sl[1].stop]
                cv2.copyTo(lap[sl], own.view(np.uint8), dst)
            else:
                cv2.multiply(lap, _three(weight), dst=lap)
                dst = acc[lev][oy:oy + hh, ox:ox + wl]
                cv2.add(dst, lap, dst=dst)
                dst = wsum[lev][oy:oy + hh, ox:ox + wl]
                cv2.add(dst, weight, dst=dst)
            if lev < bands:
                weight, norm = cv2.pyrDown(weight), nxt
    out = None
    for lev in range(bands, -1, -1):
        level = acc[lev] if lev == 0 else cv2.divide(acc[lev], _three(np.maximum(wsum[lev], 1e-8)))
        if out is None:
            out = level
        else:
            out = cv2.pyrUp(out, dstsize=(level.shape[1], level.shape[0]))
            cv2.add(out, level, dst=out)
    out = out[-gy0:-gy0 + H, -gx0:-gx0 + W]
    # round and saturate to uint8 (convertScaleAbs rounds; negatives are clipped to 0 first)
    pano = cv2.convertScaleAbs(np.maximum(out, 0))
    pano[labels < 0] = 0
    return pano


def blend_feather(w: Warped, labels: np.ndarray, bands: int = 0, gains: np.ndarray | None = None) -> np.ndarray:
    """Feather blending: average weighted by each image's distance to its own border (``bands`` is unused).

    Returns
    -------
    (H, W, 3) uint8
        The blended canvas, 0 where no image covers it.
    """
    W, H = w.size
    g = np.ones(len(w.images)) if gains is None else np.asarray(gains, float)
    acc = np.zeros((H, W, 3), np.float32)
    wsum = np.zeros((H, W), np.float32)
    for k, (img, mask, (x, y)) in enumerate(zip(w.images, w.masks, w.corners)):
        h, ww = mask.shape
        d = _distance(mask)
        im = img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        acc[y:y + h, x:x + ww] += im.astype(np.float32) * (d * np.float32(g[k]))[..., None]
        wsum[y:y + h, x:x + ww] += d
    pano = np.clip(acc / np.maximum(wsum, 1e-8)[..., None] + 0.5, 0, 255).astype(np.uint8)
    pano[labels < 0] = 0
    return pano


#: blender name -> function(warped, labels, bands, gains) -> (H, W, 3) uint8
BLENDERS: dict[str, Callable[..., np.ndarray]] = {"multiband": blend_multiband, "feather": blend_feather}


def compose(w: Warped, blender: str, bands: int, gain: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gain-compensate, find seams and blend.

    Returns
    -------
    pano : (H, W, 3) uint8
    mask : (H, W) bool
        Pixels covered by at least one image.
    seams : (H, W) bool
        Seam lines between the images' regions.
    """
    if blender not in BLENDERS:
        raise ValueError(f"`blender` must be one of {sorted(BLENDERS)}, got {blender!r}")
    gains = gain_compensation(w) if gain else None
    labels = seam_labels(w)
    pano = BLENDERS[blender](w, labels, bands, gains)
    return pano, labels >= 0, seam_lines(labels)
