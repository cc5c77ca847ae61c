"""Pictures of command results: pure functions, arrays in and a BGR uint8 array out (the commands save them).

``draw_quads`` outlines found logos with their names, ``checkerboard_warp`` shows image B warped onto image A as a
checkerboard (a good homography makes edges run straight across the tile borders), ``disparity_colormap`` colours a
disparity map and adds a colour bar with its scale. Hough lines are drawn by :func:`cvpipe.hough.draw_lines`.
"""

from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from .errors import InputError

#: distinct BGR colours for successive outlines
PALETTE = ((0, 220, 0), (0, 140, 255), (255, 80, 0), (200, 0, 200), (0, 200, 255), (255, 200, 0))


def to_bgr(image: np.ndarray) -> np.ndarray:
    """A BGR uint8 copy of a gray (H, W) or BGR (H, W, 3) uint8 image."""
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3):
        raise InputError(f"`image` must be (H, W) or (H, W, 3) uint8, got shape {image.shape} dtype {image.dtype}")
    return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()


def draw_quads(image: np.ndarray, quads: Sequence[np.ndarray], labels: Sequence[str] | None = None,
               thickness: int = 0) -> np.ndarray:
    """A BGR copy of ``image`` with each quadrilateral outlined and labelled.

    Parameters
    ----------
    image : ndarray, (H, W) or (H, W, 3) uint8
    quads : sequence of array_like, each (4, 2) float
        Corner pixel coordinates (x, y), in order around the outline.
    labels : sequence of str, optional
        One label per quad, written near its top-most corner.
    thickness : int
        Line thickness in pixels; 0 chooses one from the image size.

    Returns
    -------
    ndarray, (H, W, 3) uint8
    """
    out = to_bgr(image)
    if labels is not None and len(labels) != len(quads):
        raise InputError(f"`labels` must have one entry per quad, got {len(labels)} labels for {len(quads)} quads")
    t = thickness or max(2, round(max(out.shape[:2]) / 300))
    scale = max(0.5, max(out.shape[:2]) / 900)
    for k, quad in enumerate(quads):
        q = np.asarray(quad, np.float64).reshape(-1, 2)
        if q.shape != (4, 2) or not np.isfinite(q).all():
            raise InputError(f"quad {k} must be 4 finite (x, y) corners, got {np.asarray(quad).tolist()}")
        color = PALETTE[k % len(PALETTE)]
        # 4 fractional bits: sub-pixel corners without rounding the outline
        cv2.polylines(out, [np.round(q * 16).astype(np.int32)], True, color, t, cv2.LINE_AA, shift=4)
        if labels is not None:
            top = q[np.argmin(q[:, 1])]
            (w, h), base = cv2.getTextSize(labels[k], cv2.FONT_HERSHEY_SIMPLEX, scale, t)
            x = int(np.clip(top[0], 0, max(0, out.shape[1] - w)))
            y = int(np.clip(top[1] - 2 * t, h + base, out.shape[0] - base))
            cv2.rectangle(out, (x, y - h - base), (x + w, y + base), (0, 0, 0), -1)
            cv2.putText(out, labels[k], (x, y), cv2.FONT_HERSHEY_SIMPLEX, scale, color, t, cv2.LINE_AA)
    return out


def checkerboard_warp(a: np.ndarray, b: np.ndarray, H: np.ndarray, tile: int = 0) -> np.ndarray:
    """Image B warped into A's frame (by the inverse of ``H``, which maps A to B) shown as a checkerboard with A.

    Tiles alternate between A and warped B where B covers A; elsewhere A is shown darkened. Where the homography is
    right, edges and textures continue across tile borders.

    Parameters
    ----------
    a, b : ndarray, (H, W) or (H, W, 3) uint8
        The two images (any sizes).
    H : array_like, (3, 3)
        Homography mapping A's pixel coordinates to B's.
    tile : int
        Tile side in pixels; 0 chooses about 1/8 of A's longer side.

    Returns
    -------
    ndarray, A's (H, W, 3) uint8
    """
    A, B = to_bgr(a), to_bgr(b)
    H = np.asarray(H, np.float64)
    if H.shape != (3, 3) or not np.isfinite(H).all() or abs(np.linalg.det(H)) < 1e-12:
        raise InputError(f"`H` must be a finite invertible 3x3 matrix, got {H.tolist()}")
    h, w = A.shape[:2]
    # H maps A -> B, so sampling B at H(x) for every pixel x of A is WARP_INVERSE_MAP with H itself
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    warped = cv2.warpPerspective(B, H, (w, h), flags=flags)
    cover = cv2.warpPerspective(np.full(B.shape[:2], 255, np.uint8), H, (w, h),
                                flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP) > 0
    t = tile or max(8, max(h, w) // 8)
    yy, xx = np.mgrid[0:h, 0:w]
    use_b = cover & (((yy // t) + (xx // t)) % 2 == 1)
    out = (A // 2)  # outside B: A darkened, so the covered area stands out
    out[cover] = A[cover]
    out[use_b] = warped[use_b]
    return out


def disparity_colormap(disp: np.ndarray, max_disp: float | None = None, bar_width: int = 0) -> np.ndarray:
    """A colour picture of a disparity map (turbo colour map, invalid = black) with a labelled colour bar on the right.

    Parameters
    ----------
    disp : ndarray, (H, W) float
        Disparity in pixels, NaN (or inf) where invalid.
    max_disp : float, optional
        The disparity shown in the brightest colour; default the largest valid value.
    bar_width : int
        Width of the colour bar area in pixels; 0 chooses one from the image width.

    Returns
    -------
    ndarray, (H, W + bar area, 3) uint8
    """
    d = np.asarray(disp, np.float64)
    if d.ndim != 2 or d.size == 0:
        raise InputError(f"`disp` must be a non-empty (H, W) array, got shape {d.shape}")
    valid = np.isfinite(d)
    top = float(max_disp) if max_disp is not None else (float(d[valid].max()) if valid.any() else 1.0)
    top = max(top, 1e-6)
    scaled = np.zeros(d.shape, np.uint8)
    scaled[valid] = np.clip(np.round(d[valid] / top * 255), 0, 255).astype(np.uint8)
    img = cv2.applyColorMap(scaled, cv2.COLORMAP_TURBO)
    img[~valid] = 0
    h = d.shape[0]
    bw = bar_width or max(60, d.shape[1] // 8)
    panel = np.full((h, bw, 3), 255, np.uint8)
    margin = max(8, h // 20)
    bar_h = max(2, h - 2 * margin)
    ramp = np.round(np.linspace(255, 0, bar_h)).astype(np.uint8)[:, None]
    sw = max(6, bw // 4)
    panel[margin:margin + bar_h, 4:4 + sw] = cv2.applyColorMap(np.repeat(ramp, sw, 1), cv2.COLORMAP_TURBO)
    scale = max(0.3, min(0.6, h / 800))
    for frac in (0.0, 0.5, 1.0):
        y = margin + int(round((1 - frac) * (bar_h - 1)))
        cv2.line(panel, (4 + sw, y), (8 + sw, y), (0, 0, 0), 1)
        cv2.putText(panel, f"{frac * top:.0f}", (10 + sw, min(h - 2, y + 5)), cv2.FONT_HERSHEY_SIMPLEX, scale,
                    (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(panel, "px", (4, max(12, margin - 2)), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 1, cv2.LINE_AA)
    return np.hstack([img, panel])
