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


# ---- stereo ----
# One section per compared method, so that `dvc repro` reruns only the method whose parameters changed (the
# `stereo_disparity` matrix stage reads `stereo.<method>`); the defaults equal the function defaults in
# cvpipe.stereo (a test checks that).


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
        _in_range("paths", self.paths, 4, 8)
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
class StereoReportParams:
    """``stereo.report``: the absolute error (pixels) at which the error maps' colour saturates."""

    error_clip: float = 4.0

    def __post_init__(self):
        _in_range("error_clip", self.error_clip, 0.0, lo_open=True)


SECTIONS.update({
    "stereo.sgm": StereoSgmParams,
    "stereo.opencv_bm": StereoBmParams,
    "stereo.opencv_sgbm": StereoSgbmParams,
    "stereo.report": StereoReportParams,
})
