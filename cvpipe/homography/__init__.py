"""Planar homography estimation: Hartley-normalized DLT, locally optimized RANSAC and Levenberg-Marquardt refinement.

:func:`find_homography` has the semantics of ``cv2.findHomography(src, dst, cv2.RANSAC, threshold)``: ``H`` maps
``src`` to ``dst`` (homogeneous column vectors, ``H[2, 2] = 1``), a correspondence is an inlier when the one-sided
reprojection error ``|| dehom(H @ src_i) - dst_i ||`` is at most ``threshold`` pixels, and the result carries the
boolean inlier mask. The pipeline is

1. Hartley normalization of both point sets (centroid to the origin, mean distance sqrt(2));
2. RANSAC over minimal 4-point samples drawn without replacement, solved in closed form (the two projective bases),
   with degenerate samples rejected before solving (three collinear points in either view, or triangle orientations
   that disagree between the views, which no homography with every point in front of both cameras produces);
3. MSAC scoring (truncated squared error) with Wald's sequential probability ratio test (Chum & Matas 2008: a bad
   hypothesis is dropped after a few dozen points; its parameters are re-estimated as the run goes), an exact
   bail-out once a hypothesis cannot beat the best so far, and the adaptive iteration bound
   ``log(1 - confidence) / log(1 - w^4 (1 - 1/A))`` from the best inlier ratio ``w`` so far (``1/A`` bounds the
   chance that the SPRT rejects a good model); the points are verified in a random order;
4. LO-RANSAC: every so-far-best model is re-estimated by least squares on its inliers, then iteratively with the
   inlier threshold shrinking from ``lo_multiplier * threshold`` to ``threshold``;
5. a final iteratively reweighted Levenberg-Marquardt refinement of the reprojection error (Tukey weights).

The per-hypothesis loop, scoring and refinement are compiled Cython kernels (built with the package). Random
numbers come from a ``numpy.random.Generator`` in chunks, so a seeded ``rng`` reproduces a result exactly.

Modules: :mod:`~cvpipe.homography.estimate` (``find_homography``, ``estimate``, ``estimate_with`` for the
``homography.estimate`` section, the OpenCV methods, the test against
chance), :mod:`~cvpipe.homography.dlt`, :mod:`~cvpipe.homography.match` (``correspondences``),
:mod:`~cvpipe.homography.report` (pictures, metrics, summary), and the compiled kernels: ``_ransac`` (4-point solver,
local optimization, the per-hypothesis loop), ``_dlt`` (normalization, errors, the final refinement), ``_chance``
(the counts of the test against chance), over the inline model of ``_model.pxd`` and the eigen-solver of
``_eigen.pxd``. The sampling, the state of the run, the bound, the SPRT, the driver and the NFA are the robust
core's (:mod:`cvpipe.robust`): this package holds the homography's own parts (4-point solver, residual, refits).
"""

from ..geometry import hartley_normalization
from .dlt import dlt, transform_points
from .estimate import (
    DEFAULT_MAX_ITERS,
    MAX_NFA,
    METHODS,
    HomographyFit,
    chance_probability,
    chance_bound,
    check_significant,
    estimate,
    estimate_item,
    estimate_with,
    find_homography,
    log10_nfa,
    points_area,
)
from .match import correspondences
from .report import (
    alignment_checkerboard,
    alignment_panel,
    compare_methods,
    metric_key,
    metrics_of,
    picture_panels,
    quality_plots,
    report_summary,
)

__all__ = [
    "DEFAULT_MAX_ITERS", "MAX_NFA", "METHODS", "HomographyFit", "alignment_checkerboard", "alignment_panel",
    "chance_bound", "chance_probability", "check_significant", "compare_methods", "correspondences", "dlt", "estimate", "estimate_item",
    "estimate_with",
    "find_homography", "hartley_normalization", "log10_nfa", "metric_key", "metrics_of", "picture_panels",
    "points_area", "quality_plots", "report_summary", "transform_points",
]
