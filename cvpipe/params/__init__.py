"""``params.yaml`` sections as frozen pydantic models.

Each stage's parameters are one model (a :class:`Section`) whose field names are exactly the keys of its
``params.yaml`` section. Every default, range and choice is declared once, on its field: ``Field(ge=..., le=...)``
for a range (a range that several sections share once, as a named type such as :data:`Ratio`), ``Literal[...]`` for
a choice, and :class:`Bound` for a limit set by another field of the same section (``canny_high`` >= ``canny_low``).
The CLI reuses the defaults, and a library function's keyword default that is a field reads it from a module-level
instance (``p1: int = _SGM.p1``) instead of repeating it; tests check that ``params.yaml`` agrees and that no such
signature holds a literal, and the message tests are generated from these declarations. Unknown, mistyped or
out-of-range keys are refused with an
:class:`~cvpipe.errors.InputError` of one line that names the dotted key and what it accepts (```hough.lines.rho`
must be in (0.0, 100.0], got -1``); the same check runs when Python code builds a model directly, and the message
then names the bare field. Types are strict: ``true`` and ``"3"`` are not numbers, ``3.0`` is not an integer, but
``3`` is accepted for a float field (and stored as ``3.0``). Every float is finite and every integer fits a C ``int``
unless its field declares otherwise (:mod:`cvpipe.params.base`); a range the algorithm needs beyond that is declared
on the field (``census_size``: odd, at most 65 pixels), and the command-line flags that set a field are checked by
the same declarations (:func:`~cvpipe.params.base.check_field`).

A new section is a :class:`Section` subclass, one :data:`SECTIONS` entry and the same keys in ``params.yaml``::

    class HoughEdgesParams(Section):
        canny_low: float = Field(50.0, ge=0.0)
        canny_high: Annotated[float, Bound(">=", "canny_low")] = 150.0
        aperture: Literal[3, 5, 7] = 3
        l2_gradient: bool = False

    SECTIONS = {..., "hough.edges": HoughEdgesParams, ...}

Copies with changes go through :func:`replace` (validated; ``model_copy(update=...)`` would skip the checks), dicts
through ``model_dump()``.
"""

from __future__ import annotations

import os
import warnings
from typing import Annotated, Literal

from pydantic import AfterValidator, Field, field_validator
from pydantic_core import PydanticCustomError

# the machinery, re-exported: `from cvpipe.params import Section, from_mapping, load_section` keeps working
from .base import (INT_MAX, INT_MIN, Bound, Section, check_field, from_mapping, load_section,  # noqa: F401
                   must, read_params_file, replace, section_or_default)

#: the feature detectors of :data:`cvpipe.features.DETECTORS` (a test keeps the two equal)
Detector = Literal["sift", "orb", "brisk", "akaze"]

# ranges shared by fields of several sections, each declared once
#: the keypoints kept per image
MaxFeatures = Annotated[int, Field(ge=1, le=1_000_000)]
#: Lowe's ratio test: best / second-best descriptor distance
Ratio = Annotated[float, Field(gt=0.0, le=1.0)]
#: a normalized correlation coefficient
Correlation = Annotated[float, Field(ge=-1.0, le=1.0)]
#: a morphology radius in pixels
Radius = Annotated[int, Field(ge=0, le=50)]
#: a random seed (numpy's generators take no negative one)
Seed = Annotated[int, Field(ge=0)]
#: a RANSAC inlier threshold in pixels
RansacThreshold = Annotated[float, Field(gt=0.0, le=100.0)]

#: the smallest registration or compose resolution, megapixels: 10 000 pixels (100 x 100), below which a photo has
#: too few features to register and a panorama too few pixels to show anything; and the largest
MIN_MEGAPIX, MAX_MEGAPIX = 0.01, 1000.0


def _megapix(value: float) -> float:
    if 0.0 < value < MIN_MEGAPIX:
        raise must(f"be <= 0 (full resolution) or in [{MIN_MEGAPIX}, {MAX_MEGAPIX}]")
    return value


#: a working resolution in megapixels per image, <= 0 for full resolution
Megapix = Annotated[float, Field(le=MAX_MEGAPIX), AfterValidator(_megapix)]


# --------------------------------------------------------------------------------------------- shared sections


class SamplesParams(Section):
    """``samples``: the bundled sample data set."""

    seed: Seed = 20261122
    logo_scenes: int = Field(40, ge=1, le=1000)
    logo_negatives: int = Field(12, ge=0, le=1000)


class FeaturesParams(Section):
    """Keypoint detection (``<task>.features``)."""

    detector: Detector = "sift"
    max_features: MaxFeatures = 4000


class MatchParams(Section):
    """Descriptor matching (``<task>.match``)."""

    ratio: Ratio = 0.8
    cross_check: bool = False


# ---- homography ----


class HomographyEstimateParams(Section):
    """``homography.estimate``: robust homography from the matches (the same settings for every method)."""

    threshold: RansacThreshold = 3.0
    confidence: float = Field(0.999, gt=0.0, lt=1.0)
    max_iters: int = Field(10_000, ge=1, le=10_000_000)
    seed: Seed = 0


class HomographyReportParams(Section):
    """``homography.report``: success criterion and the alignment pictures."""

    success_px: float = Field(3.0, gt=0.0)
    checker_tiles: int = Field(8, ge=1, le=256)


# ---- hough ----


class HoughEdgesParams(Section):
    """``hough.edges``: Canny edge map fed to both Hough implementations."""

    canny_low: float = Field(50.0, ge=0.0)
    canny_high: Annotated[float, Bound(">=", "canny_low")] = 150.0
    aperture: Literal[3, 5, 7] = 3
    l2_gradient: bool = False
    blur_sigma: float = Field(0.0, ge=0.0, le=20.0)


class HoughLinesParams(Section):
    """``hough.lines``: standard Hough transform, identical for ``ours`` and ``opencv``."""

    rho: float = Field(1.0, gt=0.0, le=100.0)
    theta_deg: float = Field(1.0, gt=0.0, le=180.0)
    threshold: int = Field(150, ge=1)
    refine: bool = False
    repeats: int = Field(5, ge=1, le=100)


class HoughReportParams(Section):
    """``hough.report``: when a detected line counts as a sample's true line."""

    rho_tol: float = Field(3.0, gt=0.0)
    theta_tol_deg: float = Field(1.5, gt=0.0, le=90.0)


# ---- defect ----


class DefectFeaturesParams(FeaturesParams):
    """``defect.features``: ORB is 10x faster than SIFT here and ECC does the fine alignment anyway."""

    detector: Detector = "orb"
    max_features: MaxFeatures = 1000


class DefectRegisterParams(Section):
    """``defect.register``: probe -> reference registration (RANSAC on matches, then ECC refinement)."""

    ransac_threshold: float = Field(3.0, gt=0.0, le=100.0)
    min_inliers: int = Field(15, ge=4, le=1_000_000)
    min_inlier_ratio: float = Field(0.1, ge=0.0, le=1.0)
    max_scale_change: float = Field(2.0, ge=1.0, le=100.0)
    min_overlap: float = Field(0.4, gt=0.0, le=1.0)
    ecc_levels: int = Field(2, ge=0, le=6)
    ecc_scale: float = Field(0.5, gt=0.0, le=1.0)
    ecc_iterations: int = Field(25, ge=1, le=10_000)
    ecc_eps: float = Field(1e-4, gt=0.0, le=1.0)
    min_correlation: Correlation = 0.5
    direct_fallback: bool = True
    direct_min_correlation: Correlation = 0.8
    retry_correlation: Correlation = 0.95
    seed: Seed = 0


class DefectDiffParams(Section):
    """``defect.diff``: photometric fit and the misregistration-tolerant difference."""

    smooth_sigma: float = Field(1.0, ge=0.0, le=20.0)
    tolerance_radius: int = Field(3, ge=0, le=20)
    border_margin: int = Field(6, ge=0, le=1000)
    fit_trim: float = Field(3.0, gt=0.0, le=100.0)


class DefectRegionParams(Section):
    """``defect.regions``: threshold, morphology, connected components, verdict."""

    threshold: float = Field(0.15, gt=0.0, le=1.0)
    seed_threshold: Annotated[float, Bound(">=", "threshold")] = Field(0.3, le=1.0)
    seed_radius: Radius = 1
    noise_factor: float = Field(6.0, ge=0.0, le=100.0)
    open_radius: Radius = 1
    close_radius: Radius = 5
    min_area: int = Field(12, ge=1, le=1_000_000)
    merge_distance: float = Field(8.0, ge=-1.0, le=1000.0)
    pad: float = Field(0.0, ge=0.0, le=1000.0)


# `register` is also ABCMeta.register, which pydantic warns about; the field wins on instances, as it should
warnings.filterwarnings("ignore", message='Field name "register" in "InspectParams" shadows', category=UserWarning)


class InspectParams(Section):
    """Every parameter of ``cvpipe.defect.inspect``: the ``defect.<field>`` sections above, one per stage."""

    features: DefectFeaturesParams = Field(default_factory=DefectFeaturesParams)
    match: MatchParams = Field(default_factory=MatchParams)
    register: DefectRegisterParams = Field(default_factory=DefectRegisterParams)
    diff: DefectDiffParams = Field(default_factory=DefectDiffParams)
    regions: DefectRegionParams = Field(default_factory=DefectRegionParams)


def load_inspect_params(path: str | os.PathLike = "params.yaml") -> InspectParams:
    """The ``defect.*`` sections of ``params.yaml`` as one :class:`InspectParams`."""
    return InspectParams(**{name: load_section(SECTIONS[f"defect.{name}"], f"defect.{name}", path)
                            for name in InspectParams.model_fields})


# ---------------------------------------------------------------------------------------------------- panorama


class PanoramaFeaturesParams(FeaturesParams):
    """``panorama.features``: features at the registration resolution (``work_megapix`` million pixels, <= 0 means
    full resolution; ``cv2.Stitcher`` uses 0.6)."""

    max_features: MaxFeatures = 1500
    work_megapix: Megapix = 0.6


class PanoramaMatchParams(Section):
    """``panorama.match``: pairwise matching and the acceptance of a pair as an edge of the match graph; only each
    image's ``candidates`` most promising partners are matched in full (0: every pair). An accepted pair's
    homography is refitted on its inliers with the tighter ``refit_threshold`` (0: no refit), or, with
    ``pair_refine: lk``, fitted to Lucas-Kanade tracks of corners in its overlap (:mod:`cvpipe.panorama.track`)."""

    ratio: Ratio = 0.8
    ransac_threshold: RansacThreshold = 3.0
    min_inliers: int = Field(10, ge=4)
    min_confidence: float = Field(1.0, ge=0.0)
    candidates: int = Field(5, ge=0)
    refit_threshold: Annotated[float, Bound("<=", "ransac_threshold")] = Field(2.0, ge=0.0)
    pair_refine: Literal["none", "lk"] = "none"
    seed: Seed = 0


class PanoramaHomographiesParams(Section):
    """``panorama.homographies``: chaining along the maximum spanning tree, then joint least-squares refinement
    (``refine``: auto, homography, rotation or none)."""

    refine: Literal["auto", "homography", "rotation", "none"] = "homography"
    max_points_per_pair: int = Field(100, ge=4)


class PanoramaWarpParams(Section):
    """``panorama.warp``: projection and compose resolution (``compose_megapix`` <= 0 means full resolution)."""

    projection: Literal["plane", "cylindrical", "spherical"] = "plane"
    compose_megapix: Megapix = -1.0
    max_canvas_megapix: float = Field(200.0, gt=0.0)


class PanoramaBlendParams(Section):
    """``panorama.blend``: exposure compensation (``gain_compensation``: OpenCV's compensator kinds, blocks of
    ``gain_block`` pixels) and the blender (multi-band with ``bands`` levels, or feather)."""

    blender: Literal["multiband", "feather"] = "multiband"
    bands: int = Field(5, ge=1, le=12)
    gain_compensation: Literal["none", "gain", "channels", "blocks", "channel_blocks"] = "gain"
    gain_block: int = Field(32, ge=4, le=1024)


# ---- logo ----


class LogoFeaturesParams(FeaturesParams):
    """``logo.features``: keypoints of gallery and scene photos. ``scene_min_long_side`` enlarges smaller scene
    photos before detection (:func:`cvpipe.features.detect`), so that logos a few dozen pixels wide still get
    keypoints. Gallery images keep their size: an isolated logo crop enlarged several times would leave the scale
    range of the binary detectors' pyramids."""

    scene_min_long_side: int = Field(800, ge=0, le=10_000)


class LogoMatchParams(Section):
    """``logo.match``: scene -> gallery matching (see :func:`cvpipe.logo.match_scene`)."""

    ratio: Ratio = 0.95
    k: int = Field(8, ge=2, le=100)
    per_reference: Annotated[int, Bound("<=", "k")] = Field(1, ge=1)
    min_features: int = Field(8, ge=4, le=100_000)
    reference_features: Annotated[int, Bound(">=", "min_features")] = Field(1000, le=1_000_000)


#: the logo methods of :data:`cvpipe.logo.METHODS`: one detector, or ``fused`` (several under one decision)
LogoMethod = Literal["sift", "orb", "brisk", "akaze", "fused"]

#: the geometric fitters of :data:`cvpipe.logo.MODELS`
LogoModel = Literal["affine_homography", "homography"]

#: score a second or later logo of a scene needs (the first needs ``score_threshold``; the higher one counts).
#: Chosen on ``cvpipe bench logo --protocol loo``, where no value up to 296 loses or gains anything, so the lowest:
#: no stricter rule (docs/notes/logo.md, "Several brands per photo")
DEFAULT_EXTRA_SCORE = 0.0


class LogoVerifyParams(Section):
    """``logo.verify``: homography verification, plausibility checks and the decision threshold.

    ``model`` is the geometric fitter for float descriptors (SIFT), ``binary_model`` for ORB, BRISK and AKAZE (see
    :data:`cvpipe.logo.MODELS`)."""

    model: LogoModel = "affine_homography"
    binary_model: LogoModel = "homography"
    ransac_threshold: float = Field(4.0, gt=0.0, le=100.0)
    max_iters: int = Field(2000, ge=1, le=10_000_000)
    affine_samples: int = Field(500, ge=1, le=10_000_000)
    max_models: int = Field(3, ge=1, le=100)
    min_matches: int = Field(5, ge=4, le=100_000)
    min_inliers: int = Field(5, ge=4, le=100_000)
    min_area: float = Field(0.001, gt=0.0, le=1.0)
    max_area: Annotated[float, Bound(">=", "min_area")] = Field(4.0, le=100.0)
    max_anisotropy: float = Field(6.0, ge=1.0, le=1000.0)
    max_perspective: float = Field(30.0, ge=1.0, le=1e6)
    min_spread: float = Field(0.05, ge=0.0, le=1.0)
    score_threshold: float = 0.0
    angle_tolerance: float = Field(30.0, gt=0.0, le=180.0)
    scale_tolerance: float = Field(2.0, gt=1.0, le=16.0)


class LogoReportParams(Section):
    """``logo.report``: the method whose answers ``cvpipe logo`` gives by default and whose overlays the report shows
    when no scene has ground truth (with ground truth, the most accurate method's). ``fused`` by default: on the
    leave-one-photo-out protocol it finds the most logos at SIFT's precision (``cvpipe bench logo``,
    BENCHMARKS.md), at about 2.4x SIFT's time per scene."""

    method: LogoMethod = "fused"


# ---- stereo ----
# One section per compared method, so that `dvc repro` reruns only the method whose parameters changed (the
# `stereo_disparity` matrix stage reads `stereo.<method>`); the defaults equal the function defaults in
# cvpipe.stereo (a test checks that).


class StereoDisparityParams(Section):
    """``stereo.disparity``: the search range shared by every method (a pair's own truth or calibration wins)."""

    max_disp: int = Field(64, ge=1, le=4096)


#: most pixels a census window covers: its signature holds one bit per pixel but the centre, in a uint64
#: (:func:`cvpipe.stereo.disparity_sgm`)
CENSUS_MAX_PIXELS = 65


def _census_window(size: tuple[int, int]) -> tuple[int, int]:
    if any(s < 1 or s % 2 == 0 for s in size) or size[0] * size[1] > CENSUS_MAX_PIXELS:
        raise must(f"be two odd sizes (height, width) covering at most {CENSUS_MAX_PIXELS} pixels")
    return size


class StereoSgmParams(Section):
    """``stereo.sgm``: our semi-global matching (:func:`cvpipe.stereo.disparity_sgm`)."""

    census_size: Annotated[tuple[int, int], AfterValidator(_census_window)] = (5, 7)
    # the matching cost is stored in 8 bits: hamming + ad_weight * min(AD, ad_trunc) <= 255
    ad_weight: float = Field(0.5, ge=0.0, le=255.0)
    ad_trunc: int = Field(20, ge=1, le=255)
    paths: Literal[4, 8] = 8  # the kernels aggregate 4 or 8 directions only
    p1: int = Field(15, ge=1, le=4095)
    p2: Annotated[int, Bound(">", "p1")] = Field(150, le=4096)
    p2_tau: float = Field(16.0, ge=0.0)
    uniqueness: float = Field(0.0, ge=0.0, le=0.99)
    subpixel: bool = True
    lr_max_diff: float = 2.0
    speckle_size: int = Field(100, ge=0)
    speckle_range: float = Field(2.0, ge=0.0)
    fill: bool = False


#: OpenCV's ``uniquenessRatio``: a margin in percent (OpenCV refuses a negative one)
Uniqueness = Annotated[int, Field(ge=0, le=100)]
#: OpenCV's ``speckleRange``: a disparity step in pixels, at most the largest disparity range
SpeckleRange = Annotated[int, Field(ge=0, le=4096)]


class StereoBmParams(Section):
    """``stereo.opencv_bm``: OpenCV block matching (:func:`cvpipe.stereo.disparity_opencv_bm`)."""

    block_size: int = Field(15, ge=5, le=255)
    uniqueness: Uniqueness = 15
    speckle_size: int = Field(100, ge=0)
    speckle_range: SpeckleRange = 2


class StereoSgbmParams(Section):
    """``stereo.opencv_sgbm``: OpenCV semi-global block matching (:func:`cvpipe.stereo.disparity_opencv_sgbm`)."""

    mode: Literal["sgbm", "hh", "sgbm_3way", "hh4"] = "sgbm"
    block_size: int = Field(3, ge=1, le=11)
    uniqueness: Uniqueness = 10
    speckle_size: int = Field(100, ge=0)
    speckle_range: SpeckleRange = 2
    lr_max_diff: int = 1  # OpenCV's disp12MaxDiff: a negative one disables the left-right check


class StereoRectifyParams(FeaturesParams):
    """``stereo.rectify``: features, matching and the fundamental-matrix fit of :mod:`cvpipe.stereo.rectify`, and when a
    pair counts as already rectified (:func:`cvpipe.stereo.rectify.looks_rectified`)."""

    ratio: Ratio = 0.8
    threshold: float = Field(1.0, gt=0.0, le=100.0)
    margin: float = Field(1.0, ge=0.0, le=1000.0)
    seed: Seed = 0
    rectified_max_dy: float = Field(1.0, gt=0.0, le=100.0)
    rectified_share: float = Field(0.75, gt=0.0, le=1.0)


class StereoDepthParams(Section):
    """``stereo.depth``: which method's disparity becomes depth and a point cloud (pairs with a calibration)."""

    method: Literal["sgm", "opencv_bm", "opencv_sgbm"] = "sgm"


class StereoReportParams(Section):
    """``stereo.report``: the absolute error (pixels) at which the error maps' colour saturates."""

    error_clip: float = Field(4.0, gt=0.0)


# ---- compute (where per-item work runs; never a parameter of a DVC stage: it does not change any result) ----


class ComputeParams(Section):
    """``compute``: where stages run their items (:func:`cvpipe.compute.map_items`).

    ``scheduler`` is ``""`` (in process), ``"local"`` (a Dask LocalCluster of ``workers`` single-threaded processes,
    0 = one per core) or a Dask scheduler address (``tcp://host:8786``). ``window`` bounds the items in flight
    (0 = 4 x the cluster's threads).
    """

    scheduler: str = ""
    workers: int = Field(0, ge=0, le=4096)
    window: int = Field(0, ge=0, le=1_000_000)

    @field_validator("scheduler")
    @classmethod
    def _address(cls, value: str) -> str:
        """The accepted forms of :func:`cvpipe.compute.check_scheduler` (a light import: no Dask)."""
        from ..compute import scheduler_problem

        problem = scheduler_problem(value)
        if problem is None:
            return value.strip()
        raise PydanticCustomError("scheduler", problem.replace("{", "{{").replace("}", "}}"))


#: dotted params.yaml section -> model; the defaults test walks this table. ``compute`` is in no stage's
#: ``params:`` in dvc.yaml: where items run never changes a result, so changing it never reruns a stage
SECTIONS: dict[str, type[Section]] = {
    "samples": SamplesParams, "homography.features": FeaturesParams, "homography.match": MatchParams,
    "homography.estimate": HomographyEstimateParams, "homography.report": HomographyReportParams,
    "hough.edges": HoughEdgesParams, "hough.lines": HoughLinesParams, "hough.report": HoughReportParams,
    "defect.features": DefectFeaturesParams, "defect.match": MatchParams, "defect.register": DefectRegisterParams,
    "defect.diff": DefectDiffParams, "defect.regions": DefectRegionParams, "panorama.features": PanoramaFeaturesParams,
    "panorama.match": PanoramaMatchParams, "panorama.homographies": PanoramaHomographiesParams,
    "panorama.warp": PanoramaWarpParams, "panorama.blend": PanoramaBlendParams, "logo.features": LogoFeaturesParams,
    "logo.match": LogoMatchParams, "logo.verify": LogoVerifyParams, "logo.report": LogoReportParams,
    "stereo.disparity": StereoDisparityParams, "stereo.sgm": StereoSgmParams, "stereo.opencv_bm": StereoBmParams,
    "stereo.opencv_sgbm": StereoSgbmParams, "stereo.report": StereoReportParams, "stereo.rectify": StereoRectifyParams,
    "stereo.depth": StereoDepthParams,
    "compute": ComputeParams,
}
