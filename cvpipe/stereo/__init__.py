"""Stereo: the disparity map of a pair, rectified first when needed, and its depth. One module per step.

- :mod:`~cvpipe.stereo.epipolar`: the fundamental matrix (8-point, 7-point, RANSAC: ``find_fundamental``);
- :mod:`~cvpipe.stereo.calibration`: a rig's :class:`Calibration` and the parsers of its files
  (``parse_calibration``);
- :mod:`~cvpipe.stereo.rectify`: uncalibrated (Hartley + Loop-Zhang) and calibrated rectification
  (``rectify_uncalibrated``, ``rectify_calibrated``, ``warp_pair``);
- :mod:`~cvpipe.stereo.pipeline`: the per-pair rectify step of the pipeline (``rectify_pair``);
- :mod:`~cvpipe.stereo.sgm`: our semi-global matching (``disparity_sgm``, ``fill_invalid``, ``textureless``), whose
  compiled kernels are in ``cvpipe.stereo._sgm`` (those of the fundamental matrix in ``_epipolar``);
- :mod:`~cvpipe.stereo.opencv_baseline`: OpenCV's block matching and SGBM (``disparity_opencv_bm``,
  ``disparity_opencv_sgbm``);
- :mod:`~cvpipe.stereo.methods`: the registry of the disparity methods, ours and OpenCV's (``METHODS``,
  ``compute_disparity``; ``disparity_with`` with the ``stereo.<method>`` section, ``METHOD_SECTIONS``);
- :mod:`~cvpipe.stereo.depth`: depth from disparity, the point cloud and its PLY bytes, colour-mapped pictures;
- :mod:`~cvpipe.stereo.report`: accuracy against the truth, the stages' metrics, pictures and report summary.

Examples
--------
>>> import numpy as np
>>> from cvpipe import stereo
>>> rng = np.random.default_rng(0)
>>> right = rng.integers(0, 256, (40, 64), dtype=np.uint8)
>>> left = np.roll(right, 4, axis=1)  # every left pixel (x, y) is the right pixel (x - 4, y)
>>> disp = stereo.disparity_sgm(left, right, 16)
>>> disp.dtype, disp.shape
(dtype('float32'), (40, 64))
>>> bool(np.nanmedian(disp[:, 20:]) == 4.0)
True
"""

from .calibration import Calibration, parse_calibration, parse_middlebury_calib, parse_opencv_calib
from .depth import colorize, depth_from_disparity, parse_ply, ply_bytes, point_cloud
from .epipolar import (FundamentalFit, eight_point, epipoles, find_fundamental, sampson_distance,
                       sampson_least_squares, seven_point)
from .methods import METHOD_SECTIONS, METHODS, compute_disparity, disparity_with
from .opencv_baseline import SGBM_MODES, disparity_opencv_bm, disparity_opencv_sgbm
from .pipeline import KINDS, RectifiedPair, disparity_item, feature_matches, rectify_item, rectify_pair
from .rectify import (DepthGeometry, Rectification, distortion, looks_rectified, max_disp_from_matches,
                      opencv_uncalibrated, rectified_depth_geometry, rectify_calibrated, rectify_uncalibrated,
                      rectifying_homographies, robust_disparity_range, warp_pair)
from .report import (BAD_THRESHOLDS, TRUTH_KEYS, colorize_disparity, comparison_picture, depth_metrics,
                     depth_picture, depth_result, error_picture, evaluate, extend_summary, merge_dropped,
                     metric_key, metrics_of, pair_result, quality_plots, rectification_picture, rectify_metrics,
                     report_summary, to_png16, vertical_error_plot)
from .sgm import disparity_sgm, fill_invalid, textureless

__all__ = [
    "disparity_sgm", "fill_invalid", "textureless",
    "METHODS", "METHOD_SECTIONS", "SGBM_MODES", "compute_disparity", "disparity_with", "disparity_opencv_bm",
    "disparity_opencv_sgbm",
    "FundamentalFit", "eight_point", "seven_point", "sampson_distance", "sampson_least_squares", "epipoles",
    "find_fundamental",
    "Calibration", "parse_calibration", "parse_middlebury_calib", "parse_opencv_calib",
    "DepthGeometry", "Rectification", "distortion", "robust_disparity_range", "rectifying_homographies",
    "rectify_uncalibrated", "opencv_uncalibrated", "rectify_calibrated", "rectified_depth_geometry", "warp_pair",
    "max_disp_from_matches", "looks_rectified",
    "KINDS", "RectifiedPair", "feature_matches", "rectify_pair", "rectify_item", "disparity_item",
    "depth_from_disparity", "point_cloud", "ply_bytes", "parse_ply", "colorize",
    "BAD_THRESHOLDS", "TRUTH_KEYS", "evaluate", "to_png16", "colorize_disparity", "error_picture", "metric_key",
    "pair_result", "metrics_of", "merge_dropped", "comparison_picture", "report_summary", "quality_plots",
    "rectify_metrics", "depth_result", "depth_metrics", "rectification_picture", "depth_picture", "extend_summary",
    "vertical_error_plot",
]
