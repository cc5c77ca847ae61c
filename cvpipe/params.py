"""``params.yaml`` sections as frozen dataclasses.

Each stage's parameters are one frozen dataclass whose field names are exactly the keys of its ``params.yaml``
section and whose defaults are the single place where defaults are declared (the CLI reuses them; a test checks
that ``params.yaml`` agrees). Unknown or mistyped keys are rejected with a message naming the key.
"""

from __future__ import annotations

import dataclasses
import os
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, TypeVar

import yaml

from .errors import InputError

T = TypeVar("T")


def _check_type(value: Any, tp: Any, key: str) -> Any:
    """Return ``value`` converted to ``tp`` when that is lossless, else raise naming ``key``."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _check_type(value, arg, key)
            except InputError as exc:
                errors.append(str(exc))
        raise InputError(errors[0] if errors else f"`{key}` has the wrong type")
    if origin is typing.Literal:
        choices = typing.get_args(tp)
        if value not in choices:
            raise InputError(f"`{key}` must be one of {list(choices)}, got {value!r}")
        return value
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise InputError(f"`{key}` must be a list, got {value!r}")
        args = typing.get_args(tp)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise InputError(f"`{key}` must be a list of {len(args)} values, got {value!r}")
            return tuple(_check_type(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
        inner = args[0] if args else Any
        return tuple(_check_type(v, inner, f"{key}[{i}]") for i, v in enumerate(value))
    if tp is Any:
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise InputError(f"`{key}` must be true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"`{key}` must be an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"`{key}` must be a number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise InputError(f"`{key}` must be a string, got {value!r}")
        return value
    return value


def from_mapping(cls: type[T], mapping: Any, section: str) -> T:
    """Build the dataclass ``cls`` from a mapping, rejecting unknown keys and wrong types.

    Parameters
    ----------
    cls : dataclass type
        The frozen dataclass of the section.
    mapping : dict or None
        The section's keys; missing keys take the dataclass defaults.
    section : str
        The dotted section name, used in messages (``"logo.match"``).
    """
    if mapping is None:
        mapping = {}
    if not isinstance(mapping, dict):
        raise InputError(f"params section `{section}` must be a mapping, got {type(mapping).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(mapping) - set(fields))
    if unknown:
        raise InputError(
            f"unknown key `{section}.{unknown[0]}` in params; expected one of: {', '.join(sorted(fields))}"
        )
    hints = typing.get_type_hints(cls)
    values = {k: _check_type(v, hints[k], f"{section}.{k}") for k, v in mapping.items()}
    try:
        return cls(**values)
    except ValueError as exc:
        raise InputError(f"params section `{section}`: {exc}") from exc


def read_params_file(path: str | os.PathLike = "params.yaml") -> dict:
    """The whole ``params.yaml`` as a dict (``yaml.safe_load``)."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such file")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise InputError(f"{p}: not valid YAML ({exc})") from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise InputError(f"{p}: expected a mapping of sections at the top level, got {type(data).__name__}")
    return data


def load_section(cls: type[T], section: str, path: str | os.PathLike = "params.yaml") -> T:
    """Load the dotted ``section`` (``"logo.match"``) of ``params.yaml`` into ``cls``."""
    node: Any = read_params_file(path)
    for part in section.split("."):
        if not isinstance(node, dict) or part not in node:
            raise InputError(f"{path}: section `{section}` is missing")
        node = node[part]
    return from_mapping(cls, node, section)


def _in_range(name: str, value: float, lo: float | None = None, hi: float | None = None, *, lo_open=False) -> None:
    """Raise ``ValueError`` naming ``name`` when ``value`` lies outside [lo, hi] ((lo, hi] with ``lo_open``)."""
    bad = (lo is not None and (value <= lo if lo_open else value < lo)) or (hi is not None and value > hi)
    if bad:
        left = "(" if lo_open else "["
        raise ValueError(f"`{name}` must be in {left}{lo if lo is not None else '-inf'}, "
                         f"{hi if hi is not None else 'inf'}], got {value}")


# --------------------------------------------------------------------------------------------- shared sections


@dataclass(frozen=True)
class SamplesParams:
    """``samples``: the bundled sample data set."""

    seed: int = 20261122
    logo_scenes: int = 40
    logo_negatives: int = 12

    def __post_init__(self):
        _in_range("logo_scenes", self.logo_scenes, 1, 1000)
        _in_range("logo_negatives", self.logo_negatives, 0, 1000)


@dataclass(frozen=True)
class FeaturesParams:
    """Keypoint detection (``<task>.features``)."""

    detector: str = "sift"
    max_features: int = 4000

    def __post_init__(self):
        _in_range("max_features", self.max_features, 1, 1_000_000)


@dataclass(frozen=True)
class MatchParams:
    """Descriptor matching (``<task>.match``)."""

    ratio: float = 0.8
    cross_check: bool = False

    def __post_init__(self):
        _in_range("ratio", self.ratio, 0.0, 1.0, lo_open=True)


#: dotted params.yaml section -> dataclass; the defaults test walks this table
SECTIONS: dict[str, type] = {
    "samples": SamplesParams,
    "homography.features": FeaturesParams,
    "homography.match": MatchParams,
}


# ---- homography ----


@dataclass(frozen=True)
class HomographyEstimateParams:
    """``homography.estimate``: robust homography from the matches (the same settings for every method)."""

    threshold: float = 3.0
    confidence: float = 0.999
    max_iters: int = 10_000
    seed: int = 0

    def __post_init__(self):
        _in_range("threshold", self.threshold, 0.0, None, lo_open=True)
        _in_range("confidence", self.confidence, 0.0, 1.0, lo_open=True)
        if self.confidence >= 1.0:
            raise ValueError(f"`confidence` must be in (0, 1), got {self.confidence}")
        _in_range("max_iters", self.max_iters, 1, 10_000_000)


@dataclass(frozen=True)
class HomographyReportParams:
    """``homography.report``: success criterion and the alignment pictures."""

    success_px: float = 3.0
    checker_tiles: int = 8

    def __post_init__(self):
        _in_range("success_px", self.success_px, 0.0, None, lo_open=True)
        _in_range("checker_tiles", self.checker_tiles, 1, 256)


SECTIONS.update({
    "homography.estimate": HomographyEstimateParams,
    "homography.report": HomographyReportParams,
})


# ---- hough ----


@dataclass(frozen=True)
class HoughEdgesParams:
    """``hough.edges``: Canny edge map fed to both Hough implementations."""

    canny_low: float = 50.0
    canny_high: float = 150.0
    aperture: int = 3
    l2_gradient: bool = False
    blur_sigma: float = 0.0

    def __post_init__(self):
        _in_range("canny_low", self.canny_low, 0.0)
        _in_range("canny_high", self.canny_high, self.canny_low)
        if self.aperture not in (3, 5, 7):
            raise ValueError(f"`aperture` must be one of [3, 5, 7], got {self.aperture}")
        _in_range("blur_sigma", self.blur_sigma, 0.0, 20.0)


@dataclass(frozen=True)
class HoughLinesParams:
    """``hough.lines``: standard Hough transform, identical for ``ours`` and ``opencv``."""

    rho: float = 1.0
    theta_deg: float = 1.0
    threshold: int = 150
    refine: bool = False
    repeats: int = 5

    def __post_init__(self):
        _in_range("rho", self.rho, 0.0, 100.0, lo_open=True)
        _in_range("theta_deg", self.theta_deg, 0.0, 180.0, lo_open=True)
        _in_range("threshold", self.threshold, 1)
        _in_range("repeats", self.repeats, 1, 100)


@dataclass(frozen=True)
class HoughReportParams:
    """``hough.report``: when a detected line counts as a sample's true line."""

    rho_tol: float = 3.0
    theta_tol_deg: float = 1.5

    def __post_init__(self):
        _in_range("rho_tol", self.rho_tol, 0.0, lo_open=True)
        _in_range("theta_tol_deg", self.theta_tol_deg, 0.0, 90.0, lo_open=True)


SECTIONS.update({
    "hough.edges": HoughEdgesParams,
    "hough.lines": HoughLinesParams,
    "hough.report": HoughReportParams,
})


# ---- defect ----


@dataclass(frozen=True)
class DefectFeaturesParams(FeaturesParams):
    """``defect.features``: ORB is 10x faster than SIFT here and ECC does the fine alignment anyway."""

    detector: str = "orb"
    max_features: int = 1000


@dataclass(frozen=True)
class DefectRegisterParams:
    """``defect.register``: probe -> reference registration (RANSAC on matches, then ECC refinement)."""

    ransac_threshold: float = 3.0
    min_inliers: int = 15
    min_inlier_ratio: float = 0.1
    max_scale_change: float = 2.0
    min_overlap: float = 0.4
    ecc_levels: int = 2
    ecc_scale: float = 0.5
    ecc_iterations: int = 25
    ecc_eps: float = 1e-4
    min_correlation: float = 0.5
    direct_fallback: bool = True
    direct_min_correlation: float = 0.8
    retry_correlation: float = 0.95
    seed: int = 0

    def __post_init__(self):
        _in_range("ransac_threshold", self.ransac_threshold, 0.0, 100.0, lo_open=True)
        _in_range("min_inliers", self.min_inliers, 4, 1_000_000)
        _in_range("min_inlier_ratio", self.min_inlier_ratio, 0.0, 1.0)
        _in_range("max_scale_change", self.max_scale_change, 1.0, 100.0)
        _in_range("min_overlap", self.min_overlap, 0.0, 1.0, lo_open=True)
        _in_range("ecc_levels", self.ecc_levels, 0, 6)
        _in_range("ecc_scale", self.ecc_scale, 0.0, 1.0, lo_open=True)
        _in_range("ecc_iterations", self.ecc_iterations, 1, 10_000)
        _in_range("ecc_eps", self.ecc_eps, 0.0, 1.0, lo_open=True)
        _in_range("min_correlation", self.min_correlation, -1.0, 1.0)
        _in_range("direct_min_correlation", self.direct_min_correlation, -1.0, 1.0)
        _in_range("retry_correlation", self.retry_correlation, -1.0, 1.0)


@dataclass(frozen=True)
class DefectDiffParams:
    """``defect.diff``: photometric fit and the misregistration-tolerant difference."""

    smooth_sigma: float = 1.0
    tolerance_radius: int = 3
    border_margin: int = 6
    fit_trim: float = 3.0

    def __post_init__(self):
        _in_range("smooth_sigma", self.smooth_sigma, 0.0, 20.0)
        _in_range("tolerance_radius", self.tolerance_radius, 0, 20)
        _in_range("border_margin", self.border_margin, 0, 1000)
        _in_range("fit_trim", self.fit_trim, 0.0, 100.0, lo_open=True)


@dataclass(frozen=True)
class DefectRegionParams:
    """``defect.regions``: threshold, morphology, connected components, verdict."""

    threshold: float = 0.15
    seed_threshold: float = 0.3
    seed_radius: int = 1
    noise_factor: float = 6.0
    open_radius: int = 1
    close_radius: int = 5
    min_area: int = 12
    merge_distance: float = 8.0
    pad: float = 0.0

    def __post_init__(self):
        _in_range("threshold", self.threshold, 0.0, 1.0, lo_open=True)
        _in_range("seed_threshold", self.seed_threshold, self.threshold, 1.0)
        _in_range("seed_radius", self.seed_radius, 0, 50)
        _in_range("noise_factor", self.noise_factor, 0.0, 100.0)
        _in_range("open_radius", self.open_radius, 0, 50)
        _in_range("close_radius", self.close_radius, 0, 50)
        _in_range("min_area", self.min_area, 1, 1_000_000)
        _in_range("merge_distance", self.merge_distance, -1.0, 1000.0)
        _in_range("pad", self.pad, 0.0, 1000.0)


SECTIONS.update({
    "defect.features": DefectFeaturesParams,
    "defect.match": MatchParams,
    "defect.register": DefectRegisterParams,
    "defect.diff": DefectDiffParams,
    "defect.regions": DefectRegionParams,
})


@dataclass(frozen=True)
class InspectParams:
    """Every parameter of ``cvpipe.defect.inspect``: the ``defect.<field>`` sections above, one per stage."""

    features: DefectFeaturesParams = dataclasses.field(default_factory=DefectFeaturesParams)
    match: MatchParams = dataclasses.field(default_factory=MatchParams)
    register: DefectRegisterParams = dataclasses.field(default_factory=DefectRegisterParams)
    diff: DefectDiffParams = dataclasses.field(default_factory=DefectDiffParams)
    regions: DefectRegionParams = dataclasses.field(default_factory=DefectRegionParams)


def load_inspect_params(path: str | os.PathLike = "params.yaml") -> InspectParams:
    """The ``defect.*`` sections of ``params.yaml`` as one :class:`InspectParams`."""
    return InspectParams(**{f.name: load_section(SECTIONS[f"defect.{f.name}"], f"defect.{f.name}", path)
                            for f in dataclasses.fields(InspectParams)})


# ---------------------------------------------------------------------------------------------------- panorama


@dataclass(frozen=True)
class PanoramaFeaturesParams:
    """``panorama.features``: features at the registration resolution (``work_megapix`` million pixels, <= 0 means
    full resolution; ``cv2.Stitcher`` uses 0.6)."""

    detector: str = "sift"
    max_features: int = 1500
    work_megapix: float = 0.6

    def __post_init__(self):
        _in_range("max_features", self.max_features, 1, 1_000_000)
        _in_range("work_megapix", self.work_megapix, None, 1000)


@dataclass(frozen=True)
class PanoramaMatchParams:
    """``panorama.match``: pairwise matching and the acceptance of a pair as an edge of the match graph; only each
    image's ``candidates`` most promising partners are matched in full (0: every pair). An accepted pair's
    homography is refitted on its inliers with the tighter ``refit_threshold`` (0: no refit)."""

    ratio: float = 0.8
    ransac_threshold: float = 3.0
    min_inliers: int = 10
    min_confidence: float = 1.0
    candidates: int = 5
    refit_threshold: float = 2.0
    seed: int = 0

    def __post_init__(self):
        _in_range("candidates", self.candidates, 0, None)
        _in_range("ratio", self.ratio, 0.0, 1.0, lo_open=True)
        _in_range("ransac_threshold", self.ransac_threshold, 0.0, None, lo_open=True)
        _in_range("min_inliers", self.min_inliers, 4, None)
        _in_range("min_confidence", self.min_confidence, 0.0, None)
        _in_range("refit_threshold", self.refit_threshold, 0.0, self.ransac_threshold)


@dataclass(frozen=True)
class PanoramaHomographiesParams:
    """``panorama.homographies``: chaining along the maximum spanning tree, then joint least-squares refinement
    (``refine``: auto, homography, rotation or none)."""

    refine: str = "homography"
    max_points_per_pair: int = 100

    def __post_init__(self):
        if self.refine not in ("auto", "homography", "rotation", "none"):
            raise ValueError(f"`refine` must be one of ['auto', 'homography', 'rotation', 'none'], got {self.refine!r}")
        _in_range("max_points_per_pair", self.max_points_per_pair, 4, None)


@dataclass(frozen=True)
class PanoramaWarpParams:
    """``panorama.warp``: projection and compose resolution (``compose_megapix`` <= 0 means full resolution)."""

    projection: str = "plane"
    compose_megapix: float = -1.0
    max_canvas_megapix: float = 200.0

    def __post_init__(self):
        if self.projection not in ("plane", "cylindrical", "spherical"):
            raise ValueError(f"`projection` must be one of ['plane', 'cylindrical', 'spherical'], "
                             f"got {self.projection!r}")
        _in_range("compose_megapix", self.compose_megapix, None, 1000)
        _in_range("max_canvas_megapix", self.max_canvas_megapix, 0.0, None, lo_open=True)


@dataclass(frozen=True)
class PanoramaBlendParams:
    """``panorama.blend``: exposure compensation (``gain_compensation``: OpenCV's compensator kinds, blocks of
    ``gain_block`` pixels) and the blender (multi-band with ``bands`` levels, or feather)."""

    blender: str = "multiband"
    bands: int = 5
    gain_compensation: Literal["none", "gain", "channels", "blocks", "channel_blocks"] = "gain"
    gain_block: int = 32

    def __post_init__(self):
        if self.blender not in ("multiband", "feather"):
            raise ValueError(f"`blender` must be one of ['feather', 'multiband'], got {self.blender!r}")
        _in_range("bands", self.bands, 1, 12)
        gains = ["none", "gain", "channels", "blocks", "channel_blocks"]
        if self.gain_compensation not in gains:
            raise ValueError(f"`gain_compensation` must be one of {gains}, got {self.gain_compensation!r}")
        _in_range("gain_block", self.gain_block, 4, 1024)


SECTIONS.update({
    "panorama.features": PanoramaFeaturesParams,
    "panorama.match": PanoramaMatchParams,
    "panorama.homographies": PanoramaHomographiesParams,
    "panorama.warp": PanoramaWarpParams,
    "panorama.blend": PanoramaBlendParams,
})


# ---- logo ----


@dataclass(frozen=True)
class LogoFeaturesParams(FeaturesParams):
    """``logo.features``: keypoints of gallery and scene photos. ``scene_min_long_side`` enlarges smaller scene
    photos before detection (:func:`cvpipe.features.detect`), so that logos a few dozen pixels wide still get
    keypoints. Gallery images keep their size: an isolated logo crop enlarged several times would leave the scale
    range of the binary detectors' pyramids."""

    scene_min_long_side: int = 800

    def __post_init__(self):
        super().__post_init__()
        _in_range("scene_min_long_side", self.scene_min_long_side, 0, 10_000)


@dataclass(frozen=True)
class LogoMatchParams:
    """``logo.match``: scene -> gallery matching (see :func:`cvpipe.logos.match_scene`)."""

    ratio: float = 0.95
    k: int = 8
    per_reference: int = 1
    min_features: int = 8
    reference_features: int = 1000
    register_references: bool = False
    reverse_shortlist: int = 0
    reverse_ratio: float = 0.8

    def __post_init__(self):
        _in_range("ratio", self.ratio, 0.0, 1.0, lo_open=True)
        _in_range("reverse_shortlist", self.reverse_shortlist, 0, 100_000)
        _in_range("reverse_ratio", self.reverse_ratio, 0.0, 1.0, lo_open=True)
        _in_range("k", self.k, 2, 100)
        _in_range("per_reference", self.per_reference, 1, self.k)
        _in_range("min_features", self.min_features, 4, 100_000)
        _in_range("reference_features", self.reference_features, self.min_features, 1_000_000)
        if not isinstance(self.register_references, bool):
            raise ValueError(f"`register_references` must be true or false, got {self.register_references!r}")


@dataclass(frozen=True)
class LogoVerifyParams:
    """``logo.verify``: homography verification, plausibility checks and the decision threshold.

    ``model`` is the geometric fitter for float descriptors (SIFT), ``binary_model`` for ORB, BRISK and AKAZE (see
    :data:`cvpipe.logos.MODELS`)."""

    model: str = "affine_homography"
    binary_model: str = "homography"
    ransac_threshold: float = 4.0
    max_iters: int = 2000
    affine_samples: int = 500
    max_models: int = 3
    min_matches: int = 5
    min_inliers: int = 5
    min_area: float = 0.001
    max_area: float = 4.0
    max_anisotropy: float = 6.0
    max_perspective: float = 30.0
    min_spread: float = 0.05
    score_threshold: float = 0.0
    angle_tolerance: float = 30.0
    scale_tolerance: float = 2.0

    def __post_init__(self):
        models = ("affine_homography", "homography")
        for name in ("model", "binary_model"):
            if getattr(self, name) not in models:
                raise ValueError(f"`{name}` must be one of {list(models)}, got {getattr(self, name)!r}")
        _in_range("ransac_threshold", self.ransac_threshold, 0.0, 100.0, lo_open=True)
        _in_range("max_iters", self.max_iters, 1, 10_000_000)
        _in_range("affine_samples", self.affine_samples, 1, 10_000_000)
        _in_range("max_models", self.max_models, 1, 100)
        _in_range("min_matches", self.min_matches, 4, 100_000)
        _in_range("min_inliers", self.min_inliers, 4, 100_000)
        _in_range("min_area", self.min_area, 0.0, 1.0, lo_open=True)
        _in_range("max_area", self.max_area, self.min_area, 100.0)
        _in_range("max_anisotropy", self.max_anisotropy, 1.0, 1000.0)
        _in_range("max_perspective", self.max_perspective, 1.0, 1e6)
        _in_range("min_spread", self.min_spread, 0.0, 1.0)
        _in_range("angle_tolerance", self.angle_tolerance, 0.0, 180.0, lo_open=True)
        _in_range("scale_tolerance", self.scale_tolerance, 1.0, 16.0, lo_open=True)


SECTIONS.update({
    "logo.features": LogoFeaturesParams,
    "logo.match": LogoMatchParams,
    "logo.verify": LogoVerifyParams,
})


# ---- stereo ----
# One section per compared method, so that `dvc repro` reruns only the method whose parameters changed (the
# `stereo_disparity` matrix stage reads `stereo.<method>`); the defaults equal the function defaults in
# cvpipe.stereo (a test checks that).


@dataclass(frozen=True)
class StereoDisparityParams:
    """``stereo.disparity``: the search range shared by every method (a pair's own truth or calibration wins)."""

    max_disp: int = 64

    def __post_init__(self):
        _in_range("max_disp", self.max_disp, 1, 4096)


@dataclass(frozen=True)
class StereoSgmParams:
    """``stereo.sgm``: our semi-global matching (:func:`cvpipe.stereo.disparity_sgm`)."""

    census_size: tuple[int, int] = (5, 7)
    ad_weight: float = 0.5
    ad_trunc: int = 20
    paths: int = 8
    p1: int = 15
    p2: int = 150
    p2_tau: float = 16.0
    uniqueness: float = 0.0
    subpixel: bool = True
    lr_max_diff: float = 2.0
    speckle_size: int = 100
    speckle_range: float = 2.0
    fill: bool = False

    def __post_init__(self):
        if self.paths not in (4, 8) or isinstance(self.paths, bool):  # the kernels aggregate 4 or 8 directions only
            raise ValueError(f"`paths` must be one of [4, 8], got {self.paths}")
        _in_range("p1", self.p1, 1, 4095)
        _in_range("p2", self.p2, self.p1 + 1, 4096)
        _in_range("ad_weight", self.ad_weight, 0.0)
        _in_range("ad_trunc", self.ad_trunc, 1, 255)
        _in_range("p2_tau", self.p2_tau, 0.0)
        _in_range("uniqueness", self.uniqueness, 0.0, 0.99)
        _in_range("speckle_size", self.speckle_size, 0)
        _in_range("speckle_range", self.speckle_range, 0.0)


@dataclass(frozen=True)
class StereoBmParams:
    """``stereo.opencv_bm``: OpenCV block matching (:func:`cvpipe.stereo.disparity_opencv_bm`)."""

    block_size: int = 15
    uniqueness: int = 15
    speckle_size: int = 100
    speckle_range: int = 2

    def __post_init__(self):
        _in_range("block_size", self.block_size, 5, 255)


@dataclass(frozen=True)
class StereoSgbmParams:
    """``stereo.opencv_sgbm``: OpenCV semi-global block matching (:func:`cvpipe.stereo.disparity_opencv_sgbm`)."""

    mode: Literal["sgbm", "hh", "sgbm_3way", "hh4"] = "sgbm"
    block_size: int = 3
    uniqueness: int = 10
    speckle_size: int = 100
    speckle_range: int = 2
    lr_max_diff: int = 1

    def __post_init__(self):
        _in_range("block_size", self.block_size, 1, 11)


@dataclass(frozen=True)
class StereoRectifyParams:
    """``stereo.rectify``: features, matching and the fundamental-matrix fit of :mod:`cvpipe.rectify`, and when a
    pair counts as already rectified (:func:`cvpipe.rectify.looks_rectified`)."""

    detector: Literal["sift", "orb", "brisk", "akaze"] = "sift"
    max_features: int = 4000
    ratio: float = 0.8
    threshold: float = 1.0
    margin: float = 1.0
    seed: int = 0
    rectified_max_dy: float = 1.0
    rectified_share: float = 0.75

    def __post_init__(self):
        _in_range("max_features", self.max_features, 1, 1_000_000)
        _in_range("ratio", self.ratio, 0.0, 1.0, lo_open=True)
        _in_range("threshold", self.threshold, 0.0, 100.0, lo_open=True)
        _in_range("margin", self.margin, 0.0, 1000.0)
        _in_range("seed", self.seed, 0)
        _in_range("rectified_max_dy", self.rectified_max_dy, 0.0, 100.0, lo_open=True)
        _in_range("rectified_share", self.rectified_share, 0.0, 1.0, lo_open=True)


@dataclass(frozen=True)
class StereoDepthParams:
    """``stereo.depth``: which method's disparity becomes depth and a point cloud (pairs with a calibration)."""

    method: Literal["sgm", "opencv_bm", "opencv_sgbm"] = "sgm"


@dataclass(frozen=True)
class StereoReportParams:
    """``stereo.report``: the absolute error (pixels) at which the error maps' colour saturates."""

    error_clip: float = 4.0

    def __post_init__(self):
        _in_range("error_clip", self.error_clip, 0.0, lo_open=True)


SECTIONS.update({
    "stereo.disparity": StereoDisparityParams,
    "stereo.sgm": StereoSgmParams,
    "stereo.opencv_bm": StereoBmParams,
    "stereo.opencv_sgbm": StereoSgbmParams,
    "stereo.report": StereoReportParams,
    "stereo.rectify": StereoRectifyParams,
    "stereo.depth": StereoDepthParams,
})


# ---- compute (where per-item work runs; never a parameter of a DVC stage: it does not change any result) ----


@dataclass(frozen=True)
class ComputeParams:
    """``compute``: where stages run their items (:func:`cvpipe.compute.map_items`).

    ``scheduler`` is ``""`` (in process), ``"local"`` (a Dask LocalCluster of ``workers`` single-threaded processes,
    0 = one per core) or a Dask scheduler address (``tcp://host:8786``). ``window`` bounds the items in flight
    (0 = 4 x the cluster's threads).
    """

    scheduler: str = ""
    workers: int = 0
    window: int = 0

    def __post_init__(self):
        from .compute import check_scheduler

        check_scheduler(self.scheduler, "scheduler")
        _in_range("workers", self.workers, 0, 4096)
        _in_range("window", self.window, 0, 1_000_000)


# not listed in any stage's ``params:`` in dvc.yaml: changing it never reruns a stage
SECTIONS["compute"] = ComputeParams
