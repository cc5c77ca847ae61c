"""Our progressive probabilistic Hough transform (Matas et al. 2000), returning segments like ``cv2.HoughLinesP``.

It is seeded and reproducible but, like OpenCV's, its result depends on the random point order, so it is not
expected to match OpenCV's segment for segment.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError, check_int
from ..params import HoughLinesParams
from . import _vote
from .transform import _check_edges, hough_grid, hough_steps

__all__ = ["hough_lines_probabilistic"]


def hough_lines_probabilistic(
    edges: np.ndarray, threshold: int = 50, min_line_length: float = 30.0, max_line_gap: float = 5.0, *,
    params: HoughLinesParams | None = None, max_lines: int = 100_000, rng: int | np.random.Generator | None = None,
) -> np.ndarray:
    """Our progressive probabilistic Hough transform (segments, like ``cv2.HoughLinesP``).

    Edge pixels are visited in random order; each votes (with the same accumulator geometry as ``hough_lines``).
    When a vote lifts a cell above ``threshold``, the line of that cell is followed in both directions from the
    pixel across gaps of at most ``max_line_gap`` pixels; the pixels passed are removed from further voting, and
    if the run is at least ``min_line_length`` long it becomes a segment and its pixels' votes are taken back.
    Unlike OpenCV, only pixels that have voted are un-voted, so the accumulator never goes negative.

    Parameters
    ----------
    edges : ndarray, shape (H, W), uint8 or bool
        Edge map; nonzero pixels vote.
    threshold : int
        Votes a cell needs to exceed before its line is followed; >= 1.
    min_line_length : float
        Shortest segment kept, in pixels along the major axis; >= 0.
    max_line_gap : float
        Longest run of missing pixels bridged, in pixels; >= 0.
    params : HoughLinesParams or None
        The accumulator resolution: its ``rho`` (pixels) and ``theta_deg`` (degrees, converted by
        :func:`~cvpipe.hough.transform.hough_steps`); None: the section's defaults, 1 px and 1 degree. Its
        ``threshold`` is the standard transform's: this one takes its own.
    max_lines : int
        Stop after this many segments.
    rng : None, int or numpy Generator
        Random visiting order; ``None`` draws fresh entropy.

    Returns
    -------
    ndarray, shape (K, 4), int32
        Segments ``[x1, y1, x2, y2]`` in pixels, in the order they were found.

    Examples
    --------
    >>> import numpy as np
    >>> edges = np.zeros((60, 80), np.uint8)
    >>> edges[20, :] = 255  # the row y = 20: theta = 90 deg, rho = 20 px, 80 pixels
    >>> hough_lines_probabilistic(edges, threshold=20, min_line_length=30, rng=0).tolist()
    [[0, 20, 79, 20]]
    """
    edges = _check_edges(edges)
    threshold = check_int("threshold", threshold, 1)
    max_lines = check_int("max_lines", max_lines, 1)
    for name, value in (("min_line_length", min_line_length), ("max_line_gap", max_line_gap)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not math.isfinite(float(value)) or value < 0:
            raise InputError(f"`{name}` must be a number >= 0, got {value!r}")
    grid = hough_grid(edges.shape, *hough_steps(params))
    rng = np.random.default_rng(rng)
    npts = int(np.count_nonzero(edges))
    order = rng.permutation(npts).astype(np.int64)
    return _vote.ppht(edges, order, grid.tab_cos, grid.tab_sin, grid.numrho, threshold, float(min_line_length),
                      int(math.floor(max_line_gap)), min(max_lines, max(npts, 1)))
