"""Input checks and the structuring element shared by the defect steps (no public API)."""

from __future__ import annotations

import cv2
import numpy as np

from ..errors import InputError
from ..io import to_gray


def check_gray(name: str, img: np.ndarray) -> np.ndarray:
    """``img`` as an (H, W) uint8 grey image (BGR/BGRA converted), at least 16x16; InputError naming ``name``."""
    img = np.asarray(img)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        img = to_gray(img)
    if img.ndim != 2 or img.dtype != np.uint8:
        raise InputError(f"`{name}` must be a (H, W) or (H, W, 3) uint8 image, got shape {img.shape} "
                         f"dtype {img.dtype}")
    if min(img.shape) < 16:
        raise InputError(f"`{name}` must be at least 16x16 pixels, got {img.shape[1]}x{img.shape[0]}")
    return img


def check_homography(H: np.ndarray) -> np.ndarray:
    """``H`` as a float64 3x3 with ``H[2, 2] == 1``; InputError when it is not finite and invertible."""
    H = np.asarray(H, np.float64)
    if H.shape != (3, 3) or not np.all(np.isfinite(H)) or abs(np.linalg.det(H)) < 1e-12:
        raise InputError(f"`H` must be a finite invertible 3x3 matrix, got {H.tolist()}")
    return H / H[2, 2]


def disc(radius: int) -> np.ndarray:
    """Elliptic structuring element of ``radius`` pixels ((2r+1) x (2r+1) uint8)."""
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
