"""Logo recognition: which gallery brand is in a scene photo, and where.

A gallery holds one or more reference images per brand. Their descriptors are stacked into one index that is built
once; every scene descriptor is matched against the whole gallery in one k-nearest-neighbour query, and Lowe's
ratio test compares the best neighbour of a brand with the best neighbour of any *other* brand (so several
reference photos of the same brand do not reject each other's matches). Each reference with enough tentative
matches is verified by a RANSAC homography (:func:`cvpipe.homography.find_homography`; for SIFT by default after an
affine RANSAC has picked the consistent matches, see :data:`MODELS`) and plausibility checks on it: the projected
reference outline must be convex and not mirrored, of sane area relative to the scene, without extreme anisotropy
or perspective, and the inliers must cover a fair part of the reference.

An inlier must land within the RANSAC threshold of its predicted position *and* agree with the model in keypoint
orientation and scale (the reference keypoint's angle and size carried through the model's local Jacobian,
:func:`cvpipe.logo.verify.map_poses`): a chance match agrees in all three far less often than in position alone,
which keeps chance fits rare on busy, enlarged scenes.

The score is an a-contrario significance, ``-log10`` of the expected number of equally good chance fits: the
binomial tail of seeing ``inliers - 4`` of the ``matches - 4`` other matches agree with their prediction when they
are spread at random over the scene with random orientations and scales, times the chance that the 4 sample
matches agree in orientation and scale, multiplied by the number of 4-point hypotheses and of references tried.
Unlike a raw inlier count, it does not grow with the number of tentative matches that a cluttered scene or a
feature-rich reference produces, so it is comparable across brands and separates true logos from the 6-10 inlier
fits that RANSAC finds on any busy photo.

The steps take arrays: ``gallery`` (the index), ``match`` (tentative matches), ``verify`` (model, plausibility,
score), ``detect`` (the recipe: :func:`recognize`, :func:`every_logo`) and ``report`` (evaluation, stage records,
pictures). :mod:`~cvpipe.logo.cached` reads the gallery and the scenes' features back from the features stage's
folder for the stages; the command and the benchmark read their own image folders.

:mod:`~cvpipe.logo.shape` is a cue of another kind for smooth marks that keypoints miss: the silhouette of a mark's
main colour region, calibrated on photos without the brand (the logo benchmark's ``fused+shape`` row).
"""

from .detect import DEFAULT_EXTRA_SCORE, MAX_OVERLAP, Detection, decide, every_logo, quad_iou, recognize, verify_scene
from .fused import METHODS, method_detectors, recognize_fused, verify_fused, verify_method_scene
from .gallery import Gallery, Reference, build_gallery
from .match import Matches, match_item, match_scene
from .shape import (ShapeTemplate, calibrate_shapes, decide_shape, kept_shapes, scene_regions, shape_score,
                    shape_scores, shape_template)
from .report import (NO_TRUTH, brand_recall, confusion, draw_confusion, draw_detection, draw_missed, evaluate,
                     evaluate_records, found_counts, found_plot, missed_record, merge_dropped, metric_key, metrics_of, pick_method, pr_rows, quad_error,
                     report_summary, scene_record)
from .verify import (MODELS, Hypothesis, affine_ransac, fit_affine, map_poses, pose_agrees, pose_probability,
                     shape_problem, significance, tested_references, verify)

__all__ = [
    "DEFAULT_EXTRA_SCORE", "MAX_OVERLAP", "METHODS", "MODELS", "NO_TRUTH", "Detection", "Gallery", "Hypothesis",
    "Matches", "Reference", "ShapeTemplate",
    "affine_ransac", "brand_recall", "build_gallery", "calibrate_shapes", "confusion", "decide", "decide_shape",
    "draw_confusion", "draw_detection",
    "draw_missed", "evaluate", "evaluate_records", "every_logo", "fit_affine", "found_counts", "found_plot",
    "kept_shapes",
    "map_poses", "match_item", "match_scene", "merge_dropped", "method_detectors", "metric_key", "metrics_of",
    "missed_record", "pick_method", "pose_agrees", "pose_probability", "pr_rows", "quad_error", "quad_iou",
    "recognize", "recognize_fused", "report_summary", "scene_record", "scene_regions", "shape_problem",
    "shape_score", "shape_scores", "shape_template", "significance",
    "tested_references", "verify", "verify_fused", "verify_method_scene", "verify_scene",
]
