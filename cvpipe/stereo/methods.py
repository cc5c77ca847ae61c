"""The disparity methods by name, ours and OpenCV's: the registry :data:`METHODS`, :func:`compute_disparity`, and
:func:`disparity_with` that takes a method's ``stereo.<method>`` section (:data:`METHOD_SECTIONS`)."""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..errors import InputError
from ..params import Section, StereoBmParams, StereoDepthParams, StereoSgbmParams, StereoSgmParams, section_or_default
from .opencv_baseline import disparity_opencv_bm, disparity_opencv_sgbm
from .sgm import disparity_sgm

#: the ``stereo.depth`` defaults: the one declaration of :func:`compute_disparity`'s default method
_DEPTH = StereoDepthParams()


#: method name -> function(left, right, max_disp, **options) -> (H, W) float32 disparity with NaN
METHODS: dict[str, Callable[..., np.ndarray]] = {
    "sgm": disparity_sgm,
    "opencv_bm": disparity_opencv_bm,
    "opencv_sgbm": disparity_opencv_sgbm,
}


def compute_disparity(left: np.ndarray, right: np.ndarray, max_disp: int, method: str = _DEPTH.method,
                      **options) -> np.ndarray:
    """Disparity of the left image with the registered ``method`` (see :data:`METHODS`); options go to it."""
    if method not in METHODS:
        raise ValueError(f"`method` must be one of {sorted(METHODS)}, got {method!r}")
    return METHODS[method](left, right, max_disp, **options)


#: method name -> its ``params.yaml`` section (``stereo.<method>``), whose fields are the method's keyword options
METHOD_SECTIONS: dict[str, type[Section]] = {
    "sgm": StereoSgmParams,
    "opencv_bm": StereoBmParams,
    "opencv_sgbm": StereoSgbmParams,
}


def disparity_with(left: np.ndarray, right: np.ndarray, max_disp: int, params: Section | None,
                   method: str) -> np.ndarray:
    """:func:`compute_disparity` with the ``stereo.<method>`` section: its fields are the method's options.

    Parameters
    ----------
    left, right : (H, W) or (H, W, 3) uint8
        The rectified pair.
    max_disp : int
        Disparities searched: 0 .. max_disp - 1 pixels.
    params : StereoSgmParams, StereoBmParams, StereoSgbmParams or None
        The section of ``method`` (:data:`METHOD_SECTIONS`; None: its defaults).
    method : str
        A key of :data:`METHODS`.

    Returns
    -------
    (H, W) float32
        Disparity in pixels, NaN where there is none.

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.params import StereoBmParams
    >>> right = np.random.default_rng(0).integers(0, 255, (60, 120)).astype(np.uint8)
    >>> left = np.roll(right, 6, axis=1)  # every pixel 6 px to the right in the left image
    >>> d = disparity_with(left, right, 16, StereoBmParams(block_size=9), "opencv_bm")
    >>> float(np.nanmedian(d))
    6.0
    """
    if method not in METHOD_SECTIONS:
        raise InputError(f"`method` must be one of {sorted(METHOD_SECTIONS)}, got {method!r}")
    p = section_or_default(params, METHOD_SECTIONS[method], f"stereo.{method}")
    return compute_disparity(left, right, max_disp, method, **p.model_dump())
