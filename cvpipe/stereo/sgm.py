"""Disparity of a rectified stereo pair by our semi-global matching (the OpenCV baselines: :mod:`.opencv_baseline`).

Conventions (DESIGN.md): ``left`` and ``right`` are rectified, both (H, W) grayscale or both (H, W, 3) BGR uint8
images as ``cv2.imread`` returns them. A left pixel (x, y) with disparity d matches the right pixel (x - d, y).
``max_disp`` is like OpenCV's ``numDisparities``: the disparities searched are 0 .. max_disp - 1. Every method
returns an (H, W) float32 disparity of the LEFT image in pixels, NaN where it has no (trusted) estimate.

``disparity_sgm`` follows Hirschmueller's semi-global matching (PAMI 2008): a census (optionally plus truncated
absolute-difference) matching cost, cost aggregation along 8 (or 4) scanline directions with penalties P1 / P2 where
P2 shrinks across intensity edges, winner-take-all with a uniqueness test, a parabola through the aggregated costs for
sub-pixel disparity, a left-right consistency check on the same cost volume, rejection of the pixels whose census
window is flat (nothing to match on) and removal of small speckles.
All per-pixel work runs in the compiled kernels of :mod:`._sgm` (Cython with AVX2 intrinsics; the two vertical sweeps
on two OpenMP threads), which only compute: this module validates and documents.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..errors import check_int, check_memory
from ..params import StereoSgmParams
from . import _sgm

#: most bits a census signature can hold (uint64)
_CENSUS_BITS = 64
#: supported numbers of aggregation directions (4: horizontal and vertical; 8: also the diagonals)
_PATHS = (4, 8)
#: most disparities: the kernels index disparities in int16 SIMD lanes
_MAX_DISP = 32767
#: the ``stereo.sgm`` defaults, the one declaration of :func:`disparity_sgm`'s keyword defaults
_SGM = StereoSgmParams()


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
    check_int("max_disp", max_disp, 1, left.shape[1] - 1, note="positive and less than the image width")


def _gray(img: np.ndarray) -> np.ndarray:
    return img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)


def textureless(gray: np.ndarray, window: tuple[int, int]) -> np.ndarray:
    """Pixels whose (height, width) ``window`` holds one grey level only (edges replicated, as the census pads).

    Parameters
    ----------
    gray : (H, W) uint8
        The image.
    window : (int, int)
        Odd (height, width) of the window centred on each pixel.

    Returns
    -------
    (H, W) bool
        True where the window is flat: its census signature is empty and its matching cost the same at every
        disparity, so nothing there can be matched.
    """
    kernel = np.ones((int(window[0]), int(window[1])), np.uint8)
    lo = cv2.erode(gray, kernel, borderType=cv2.BORDER_REPLICATE)
    hi = cv2.dilate(gray, kernel, borderType=cv2.BORDER_REPLICATE)
    return lo == hi


# ----------------------------------------------------------------------------------------------- public API


def disparity_sgm(
    left: np.ndarray,
    right: np.ndarray,
    max_disp: int,
    *,
    census_size: tuple[int, int] = _SGM.census_size, ad_weight: float = _SGM.ad_weight, ad_trunc: int = _SGM.ad_trunc,
    paths: int = _SGM.paths, p1: int = _SGM.p1, p2: int = _SGM.p2, p2_tau: float = _SGM.p2_tau,
    uniqueness: float = _SGM.uniqueness, subpixel: bool = _SGM.subpixel, lr_max_diff: float = _SGM.lr_max_diff,
    speckle_size: int = _SGM.speckle_size, speckle_range: float = _SGM.speckle_range, fill: bool = _SGM.fill,
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
        Disparity of the left image in pixels, NaN where rejected (occluded, ambiguous, inconsistent, speckle,
        textureless: the census window is flat in the left image (:func:`textureless`), or ``x < d`` for every
        candidate).

    Raises
    ------
    ValueError
        Bad images (different sizes, gray mixed with colour, not uint8) or a parameter out of range.
    """
    _check_pair(left, right, max_disp)
    check_int("max_disp", max_disp, 1, _MAX_DISP)
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
    # the cost volume (uint8) + the two sweeps' volumes of path sums (uint16, each sweep writes the rows it reaches
    # first, together about one volume) per pixel and disparity, and ~40 bytes per pixel of disparity maps and
    # speckle buffers: checked before anything is allocated
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
    # the cost volume is uint8; then every path cost is below 255 + p2 <= 4351 (int16 lanes, SGM_BIG = 16000) and
    # the sum of 8 paths below 65535 (uint16)
    if c_max > 255:
        raise ValueError(f"`ad_weight` * `ad_trunc` too large: the matching cost {bits} + {ad_max} "
                         "must stay <= 255")
    gl_pad = cv2.copyMakeBorder(gl, ry, ry, rx, rx, cv2.BORDER_REPLICATE)  # the census window's border: edge pixels
    gr_pad = cv2.copyMakeBorder(gr, ry, ry, rx, rx, cv2.BORDER_REPLICATE)
    steps = np.arange(256, dtype=np.float64)
    p2_lut = np.full(256, p2, np.float64) if p2_tau == 0 else np.floor(p2 * p2_tau / (p2_tau + steps))
    p2_lut = np.maximum(p2_lut, p1 + 1).astype(np.int16)
    # the paths would carry a disparity into a flat window from wherever there is texture (all of a uniform pair
    # would get one): without texture of its own a pixel has no estimate to trust (rejected as its row is finished)
    flat = textureless(gl, census_size).view(np.uint8)
    disp = _sgm.disparity(gl, gl_pad, gr_pad, ry, rx, planes_l, planes_r, ad_cap, ad_mult, c_max, int(max_disp),
                          3 if paths == 8 else 1, int(p1), p2_lut, float(uniqueness), bool(subpixel),
                          float(lr_max_diff), flat)  # -1 = rejected
    if speckle_size > 0:
        _sgm.remove_speckles(disp, int(speckle_size), float(speckle_range), nan=not fill)  # then NaN = rejected
    if fill:
        disp = _sgm.fill_background(disp)
    if fill or speckle_size == 0:
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
    out = _sgm.fill_background(work)
    out[out < 0] = np.nan
    return out
