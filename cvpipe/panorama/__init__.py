"""Panorama stitching: overlapping photos, in any order, into one seamless panorama.

:func:`stitch` is the recipe; each step is a module (and a DVC stage) of its own:

1. :mod:`~cvpipe.panorama.features`: shrink to the registration resolution (``work_megapix``), detect features;
2. :mod:`~cvpipe.panorama.match`: match the candidate pairs, one homography per pair, the match graph;
3. :mod:`~cvpipe.panorama.register`: the largest connected group, chained along the maximum spanning tree and
   refined jointly (:mod:`~cvpipe.panorama.refine`, Levenberg-Marquardt);
4. :mod:`~cvpipe.panorama.warp`: onto the plane, cylinder or sphere at the compose resolution;
5. :mod:`~cvpipe.panorama.seams` and :mod:`~cvpipe.panorama.blend`: gain compensation, seams, multi-band blending;
6. :mod:`~cvpipe.panorama.crop`: the largest rectangle without empty pixels.

:mod:`~cvpipe.panorama.opencv_baseline` runs ``cv2.Stitcher`` for comparison; :mod:`~cvpipe.panorama.report` builds
the report's tables and pictures.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import EstimationError, InputError
from ..params import (PanoramaBlendParams, PanoramaFeaturesParams, PanoramaHomographiesParams, PanoramaMatchParams,
                      PanoramaWarpParams)
from .blend import (BLENDERS, DEFAULT_GAIN, DEFAULT_GAIN_BLOCK, GAIN_CHOICES, apply_gains, blend_feather,
                    blend_multiband, blend_set, compensation_gains, compose, gain_compensation, overlap_difference)
from .crop import largest_rectangle
from .features import (detect_all, features_and_images_of, features_of, normalize_det, rescale_homographies, resize,
                       resize_matrix, resized_size, scale_for, working_images)
from .match import (Edge, MatchGraph, candidate_pairs, match_graph, match_graph_with, match_set, prefilter_counts,
                    refit)
from .opencv_baseline import (OPENCV_STATUS, OpenCVStitch, camera_homographies, opencv_stitch, opencv_stitch_cameras,
                              opencv_stitch_with)
from .presets import DEFAULT_PRESET, PRESET_CHOICES, PRESETS, preset_sections
from .refine import levenberg_marquardt, nearest_rotation, refine_homographies, refine_rotations
from .register import (REFINEMENTS, Registration, estimate_focal, maximum_spanning_tree, register, register_set,
                       register_with)
from .seams import seam_labels, seam_lines
from .track import DEFAULT_PAIR_REFINE, PAIR_REFINE_CHOICES, corners, track_pair
from .warp import PROJECTIONS, ComposeInputs, Warped, compose_inputs, warp_images, warp_set

__all__ = ["BLENDERS", "DEFAULT_GAIN", "DEFAULT_GAIN_BLOCK", "GAIN_CHOICES", "apply_gains", "compensation_gains",
           "OPENCV_STATUS", "OpenCVStitch", "PROJECTIONS", "REFINEMENTS", "ComposeInputs", "Edge", "MatchGraph",
           "Panorama", "Registration", "Warped", "blend_feather", "blend_multiband", "blend_set",
           "camera_homographies", "candidate_pairs", "compose", "compose_inputs", "detect_all", "estimate_focal",
           "features_and_images_of", "features_of", "gain_compensation", "largest_rectangle", "levenberg_marquardt",
           "match_graph", "match_graph_with", "match_set", "maximum_spanning_tree", "nearest_rotation",
           "normalize_det", "opencv_stitch", "opencv_stitch_cameras", "opencv_stitch_with", "overlap_difference",
           "prefilter_counts", "refine_homographies", "refine_rotations", "refit", "register", "register_set",
           "register_with", "rescale_homographies", "resize", "resize_matrix", "resized_size", "scale_for",
           "seam_labels", "seam_lines", "stitch", "warp_images", "warp_set", "working_images", "DEFAULT_PRESET",
           "PRESET_CHOICES", "PRESETS", "preset_sections", "DEFAULT_PAIR_REFINE", "PAIR_REFINE_CHOICES", "corners",
           "track_pair"]


@dataclass(frozen=True)
class Panorama:
    """Result of :func:`stitch`.

    Attributes
    ----------
    image : (H, W, 3) uint8
        The panorama (cropped when asked).
    mask : (H, W) bool
        Pixels covered by at least one image.
    seams : (H, W) bool
        Seam lines between the images' blending regions (same frame as ``image``).
    registration : Registration
        At the registration resolution.
    homographies : dict int -> (3, 3)
        Input pixels (full resolution) -> reference pixels at the compose resolution ("plane" frame).
    to_panorama : (3, 3)
        Reference (compose resolution) plane pixels -> panorama pixels, valid for ``projection == "plane"``.
    crop : (x, y, w, h)
        Rectangle cut from the blended canvas.
    timings : dict str -> float
        Seconds per step.
    graph : MatchGraph
        The pairwise match graph (at the registration resolution ``graph.sizes``): every accepted pair's own
        homography, before any global model.
    """

    image: np.ndarray
    mask: np.ndarray
    seams: np.ndarray
    registration: Registration
    homographies: dict
    to_panorama: np.ndarray
    crop: tuple
    timings: dict
    graph: MatchGraph | None = None


def _check_images(images: Sequence[np.ndarray]) -> None:
    if len(images) < 2:
        raise InputError(f"a panorama needs at least two images, got {len(images)}")
    for k, img in enumerate(images):
        img = np.asarray(img)
        if img.dtype != np.uint8 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
            raise InputError(f"image {k} must be (H, W) or (H, W, 3) uint8, got shape {img.shape} dtype {img.dtype}")
        if min(img.shape[:2]) < 16:
            raise InputError(f"image {k} is {img.shape[1]}x{img.shape[0]}, expected at least 16x16 pixels")


def stitch(images: Sequence[np.ndarray], features: PanoramaFeaturesParams = PanoramaFeaturesParams(),
           matching: PanoramaMatchParams = PanoramaMatchParams(),
           homographies: PanoramaHomographiesParams = PanoramaHomographiesParams(),
           warp: PanoramaWarpParams = PanoramaWarpParams(), blend: PanoramaBlendParams = PanoramaBlendParams(),
           crop: bool = True, rng=None, ids: Sequence[int] | None = None) -> Panorama:
    """Stitch overlapping photos, given in any order, into one panorama.

    Parameters
    ----------
    images : sequence of (H, W) or (H, W, 3) uint8
        Grayscale or BGR photos; sizes may differ.
    features, matching, homographies, warp, blend : params dataclasses
        The stage parameters (defaults as in ``params.yaml``).
    crop : bool
        Cut the largest axis-aligned rectangle without empty pixels.
    rng : seed or Generator
        For RANSAC and the refinement's point subsets.
    ids : sequence of int, optional
        How messages name the images (default: their positions).

    Returns
    -------
    Panorama

    Raises
    ------
    InputError
        Fewer than two images, wrong dtype or shape.
    EstimationError
        No two images overlap, or the projection cannot hold the views (e.g. ``plane`` beyond 180 degrees).

    Examples
    --------
    Two overlapping crops of one photo, given right one first:

    >>> from cvpipe.samples import photo
    >>> img = photo("astronaut")
    >>> pano = stitch([img[:, 200:], img[:, :320]], rng=0)
    >>> pano.registration.used, pano.image.shape[1] > 480
    ((0, 1), True)
    """
    _check_images(images)
    rng = np.random.default_rng(rng)
    t = {}
    t0 = time.perf_counter()
    work_sizes, feats, grays = features_and_images_of(images, features)
    t["features"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    graph = match_graph_with(feats, work_sizes, matching, rng, grays)
    del grays
    t["match"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    reg = register_with(graph, homographies, rng, ids=ids)
    t["homographies"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    comp = compose_inputs(images, reg, work_sizes, warp.compose_megapix)
    warped = warp_images(comp.images, comp.G, warp.projection, comp.focal, comp.ref_size,
                                 warp.max_canvas_megapix)
    comp_G, comp_sizes = comp.G, comp.sizes
    del comp  # the resized copies: the blend is the memory peak, they need not be alive through it
    t["warp"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    pano, mask, seams = compose(warped, blend.blender, blend.bands, blend.gain_compensation,
                              blend.gain_block)
    t["blend"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    rect = largest_rectangle(mask) if crop else (0, 0, mask.shape[1], mask.shape[0])
    x, y, w, h = rect
    if w == 0 or h == 0:
        raise EstimationError("the panorama has no pixel covered by an image; check the homographies")
    t["crop"] = time.perf_counter() - t0
    to_pano = np.array([[1, 0, -warped.origin[0] - x], [0, 1, -warped.origin[1] - y], [0, 0, 1.0]])
    full_sizes = [(img.shape[1], img.shape[0]) for img in images]
    H_full = {}
    for k, a in enumerate(reg.used):
        H_full[a] = comp_G[k] @ resize_matrix(full_sizes[a], comp_sizes[k])
    return Panorama(pano[y:y + h, x:x + w], mask[y:y + h, x:x + w], seams[y:y + h, x:x + w], reg, H_full,
                    to_pano, tuple(int(v) for v in rect), t, graph)
