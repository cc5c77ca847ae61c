"""Hough line detection, one module per step.

- :mod:`~cvpipe.hough.edges`: Canny edge maps (``canny_edges``, and ``edges_of`` with the ``hough.edges`` section);
- :mod:`~cvpipe.hough.transform`: the standard transform with ``cv2.HoughLines`` semantics (``hough_lines``,
  ``hough_grid``, ``hough_accumulator``), OpenCV's as the baseline (``hough_lines_opencv``, ``IMPLEMENTATIONS``)
  and the entry point that takes the ``hough.lines`` section (``detect_lines``, units by ``hough_steps``);
- :mod:`~cvpipe.hough.probabilistic`: our progressive probabilistic transform (``hough_lines_probabilistic``);
- :mod:`~cvpipe.hough.evaluate`: agreement with OpenCV and with ground truth (``cell_agreement``, ``compare_runs``);
- :mod:`~cvpipe.hough.report`: pictures and the report page (``draw_lines``, ``report_summary``);
- :mod:`~cvpipe.hough._vote`: the compiled kernels of our transforms (edge points, vote, peaks, refinement, the
  probabilistic transform).
"""

from .edges import canny_edges, edges_of
from .evaluate import (cell_agreement, compare_runs, line_cells, line_segment_matches, lines_item, median_seconds,
                       metrics_of, segment_segment_matches, truth_matches)
from .probabilistic import hough_lines_probabilistic
from .report import draw_lines, draw_segments, quality_plot, report_summary
from .transform import (IMPLEMENTATIONS, HoughGrid, detect_lines, get_impl, hough_accumulator, hough_grid,
                        hough_lines, hough_lines_opencv, hough_steps)

__all__ = [
    "HoughGrid",
    "hough_grid",
    "hough_accumulator",
    "hough_lines",
    "hough_lines_opencv",
    "IMPLEMENTATIONS",
    "get_impl",
    "hough_steps",
    "detect_lines",
    "hough_lines_probabilistic",
    "canny_edges",
    "edges_of",
    "line_cells",
    "cell_agreement",
    "line_segment_matches",
    "segment_segment_matches",
    "truth_matches",
    "compare_runs",
    "metrics_of",
    "median_seconds",
    "lines_item",
    "draw_lines",
    "draw_segments",
    "report_summary",
    "quality_plot",
]
