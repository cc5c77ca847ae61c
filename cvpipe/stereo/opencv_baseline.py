"""The OpenCV baselines of the disparity step (``cv2.StereoBM`` and ``cv2.StereoSGBM``), returned like
:func:`cvpipe.stereo.sgm.disparity_sgm` (the registry of every method: :mod:`cvpipe.stereo.methods`)."""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from ..errors import check_memory
from ..params import StereoBmParams, StereoSgbmParams
from .sgm import _check_pair, _gray

#: OpenCV StereoSGBM modes by name
SGBM_MODES = {
    "sgbm": cv2.StereoSGBM_MODE_SGBM,
    "hh": cv2.StereoSGBM_MODE_HH,
    "sgbm_3way": cv2.StereoSGBM_MODE_SGBM_3WAY,
    "hh4": cv2.StereoSGBM_MODE_HH4,
}
#: the ``stereo.opencv_bm`` / ``stereo.opencv_sgbm`` defaults: the one declaration of the keyword defaults below
_BM, _SGBM = StereoBmParams(), StereoSgbmParams()


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


def disparity_opencv_bm(left: np.ndarray, right: np.ndarray, max_disp: int, *, block_size: int = _BM.block_size,
                        uniqueness: int = _BM.uniqueness, speckle_size: int = _BM.speckle_size,
                        speckle_range: int = _BM.speckle_range) -> np.ndarray:
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


def disparity_opencv_sgbm(left: np.ndarray, right: np.ndarray, max_disp: int, *, mode: str = _SGBM.mode,
                          block_size: int = _SGBM.block_size, uniqueness: int = _SGBM.uniqueness,
                          speckle_size: int = _SGBM.speckle_size, speckle_range: int = _SGBM.speckle_range,
                          lr_max_diff: int = _SGBM.lr_max_diff) -> np.ndarray:
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
