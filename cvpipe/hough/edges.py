"""Edge maps for the Hough transforms: Canny with an optional Gaussian pre-blur."""

from __future__ import annotations

import cv2
import numpy as np

from ..errors import InputError
from ..params import HoughEdgesParams, section_or_default

__all__ = ["canny_edges", "edges_of"]

#: the ``hough.edges`` defaults: the one declaration of :func:`canny_edges`'s defaults
_EDGES = HoughEdgesParams()


def canny_edges(gray: np.ndarray, low: float = _EDGES.canny_low, high: float = _EDGES.canny_high, *,
                aperture: int = _EDGES.aperture, l2_gradient: bool = _EDGES.l2_gradient,
                blur_sigma: float = _EDGES.blur_sigma) -> np.ndarray:
    """Canny edge map (uint8, 255 = edge) of a grayscale image, with an optional Gaussian pre-blur.

    Parameters
    ----------
    gray : ndarray, shape (H, W), uint8
        Grayscale image.
    low, high : float
        Hysteresis thresholds on the gradient magnitude, 0 <= low <= high.
    aperture : int
        Sobel aperture: 3, 5 or 7.
    l2_gradient : bool
        Use the L2 gradient norm instead of L1.
    blur_sigma : float
        Gaussian sigma in pixels applied before Canny; 0 = none.

    Examples
    --------
    >>> import numpy as np
    >>> gray = np.zeros((40, 40), np.uint8)
    >>> gray[10:30, 10:30] = 200  # a bright square: its outline is the edge
    >>> edges = canny_edges(gray, 50, 150)
    >>> edges.dtype, np.unique(edges).tolist()
    (dtype('uint8'), [0, 255])
    >>> bool(edges[10:30, 10:30].any()) and not edges[15:25, 15:25].any()  # on the outline, not inside
    True
    """
    if not isinstance(gray, np.ndarray) or gray.ndim != 2 or gray.size == 0 or gray.dtype != np.uint8:
        shape = getattr(gray, "shape", None)
        raise InputError(f"`gray` must be a non-empty 2-D uint8 image, got {type(gray).__name__} shape {shape}")
    if not (0 <= low <= high):
        raise InputError(f"need 0 <= `low` <= `high`, got low={low}, high={high}")
    if aperture not in (3, 5, 7):
        raise InputError(f"`aperture` must be one of [3, 5, 7], got {aperture}")
    if blur_sigma < 0:
        raise InputError(f"`blur_sigma` must be >= 0, got {blur_sigma}")
    if blur_sigma > 0:
        gray = cv2.GaussianBlur(gray, (0, 0), blur_sigma)
    return cv2.Canny(gray, float(low), float(high), apertureSize=aperture, L2gradient=bool(l2_gradient))


def edges_of(gray: np.ndarray, params: HoughEdgesParams | None = None) -> np.ndarray:
    """The edge map of the ``hough_edges`` stage: :func:`canny_edges` with the ``hough.edges`` section.

    Parameters
    ----------
    gray : ndarray, shape (H, W), uint8
        Grayscale image.
    params : HoughEdgesParams or None
        The ``hough.edges`` section (``canny_low``, ``canny_high``, ``aperture``, ``l2_gradient``, ``blur_sigma``;
        None: its defaults).

    Returns
    -------
    ndarray, shape (H, W), uint8
        255 = edge, as :func:`canny_edges`.

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.params import HoughEdgesParams
    >>> gray = np.zeros((40, 40), np.uint8)
    >>> gray[10:30, 10:30] = 200
    >>> np.array_equal(edges_of(gray, HoughEdgesParams(canny_low=40.0, blur_sigma=1.0)),
    ...                canny_edges(gray, 40.0, 150.0, blur_sigma=1.0))
    True
    """
    p = section_or_default(params, HoughEdgesParams, "hough.edges")
    return canny_edges(gray, p.canny_low, p.canny_high, aperture=p.aperture, l2_gradient=p.l2_gradient,
                       blur_sigma=p.blur_sigma)
