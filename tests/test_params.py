"""cvpipe.params: every range and choice declared on a field refuses a value outside it with a one-line message naming
the dotted key; unknown keys and bools-for-numbers are refused; the defaults a user's params.yaml starts from are the models'.

The range, choice and cross-field cases are generated from the models' own constraint metadata, so a new field or
section is tested by declaring it."""

import dataclasses
import inspect
import re
import typing
from typing import Annotated, Literal, Optional

import annotated_types
import pytest
import yaml

from cvpipe import features, params
from cvpipe.errors import InputError
from cvpipe.params import (Bound, FeaturesParams, HoughLinesParams, InspectParams, MatchParams, Section,
                           StereoSgmParams, from_mapping, load_inspect_params, load_section, read_params_file, replace)


class Demo(Section):
    n: int = 3
    x: float = 0.5
    flag: bool = False
    name: str = "a"
    mode: Literal["fast", "slow"] = "fast"
    pair: tuple[int, int] = (1, 2)
    opt: Optional[float] = None
    hi: Annotated[int, Bound(">=", "n")] = 5


def test_defaults_and_conversion():
    d = from_mapping(Demo, {"x": 2, "pair": [3, 4], "opt": 1}, "demo")
    assert d == Demo(x=2.0, pair=(3, 4), opt=1.0)
    assert isinstance(d.x, float) and isinstance(d.opt, float)  # an int is a float, stored as one
    assert from_mapping(Demo, None, "demo") == Demo()


@pytest.mark.parametrize("mapping, message", [
    ({"nn": 1}, r"unknown key `demo\.nn` in params; expected one of: flag, hi, mode, n, name, opt, pair, x$"),
    ({"n": 1.5}, r"`demo\.n` must be an integer, got 1\.5$"),
    ({"n": 3.0}, r"`demo\.n` must be an integer, got 3\.0$"),
    ({"n": True}, r"`demo\.n` must be an integer, got True$"),
    ({"x": "big"}, r"`demo\.x` must be a number, got 'big'$"),
    ({"x": "3"}, r"`demo\.x` must be a number, got '3'$"),
    ({"x": False}, r"`demo\.x` must be a number, got False$"),
    ({"flag": 1}, r"`demo\.flag` must be true or false, got 1$"),
    ({"name": 3}, r"`demo\.name` must be a string, got 3$"),
    ({"mode": "medium"}, r"`demo\.mode` must be one of \['fast', 'slow'\], got 'medium'$"),
    ({"pair": [1]}, r"`demo\.pair` must be a list of 2 values, got \[1\]$"),
    ({"pair": [1, 2, 3]}, r"`demo\.pair` must be a list of 2 values, got \[1, 2, 3\]$"),
    ({"pair": 5}, r"`demo\.pair` must be a list, got 5$"),
    ({"pair": [1, "b"]}, r"`demo\.pair\[1\]` must be an integer, got 'b'$"),
    ({"opt": "x"}, r"`demo\.opt` must be a number, got 'x'$"),
    ({"hi": 2}, r"`demo\.hi` must be in \[3, 2147483647\], got 2 \(the lower limit is `demo\.n`\)$"),
    ({"n": 9}, r"`demo\.hi` must be in \[9, 2147483647\], got 5 \(the lower limit is `demo\.n`\)$"),
])
def test_rejections_name_the_key(mapping, message):
    with pytest.raises(InputError, match=message):
        from_mapping(Demo, mapping, "demo")


def test_section_not_a_mapping():
    with pytest.raises(InputError, match="section `demo` must be a mapping, got list"):
        from_mapping(Demo, [1, 2], "demo")


def test_messages_name_the_dotted_key_and_its_allowed_range():
    with pytest.raises(InputError, match=r"^`hough\.lines\.theta_deg` must be in \(0\.0, 180\.0\], got -1$"):
        from_mapping(HoughLinesParams, {"theta_deg": -1}, "hough.lines")
    with pytest.raises(InputError, match=r"^`stereo\.sgm\.paths` must be one of \[4, 8\], got 6$"):
        from_mapping(StereoSgmParams, {"paths": 6}, "stereo.sgm")
    with pytest.raises(InputError, match=r"^unknown key `homography\.match\.foo` in params; expected one of: "
                                         r"cross_check, ratio$"):
        from_mapping(MatchParams, {"foo": 1}, "homography.match")
    with pytest.raises(InputError, match=r"`homography\.features\.max_features` must be in \[1, 1000000\], got 0"):
        from_mapping(FeaturesParams, {"max_features": 0}, "homography.features")
    with pytest.raises(InputError, match=r"^`panorama\.match\.candidates` must be in \[0, 2147483647\], got -1$"):
        from_mapping(params.PanoramaMatchParams, {"candidates": -1}, "panorama.match")
    # a field's own limit and the one another field sets are shown together, whichever is broken
    with pytest.raises(InputError, match=r"^`panorama\.match\.refit_threshold` must be in \[0\.0, 5\.0\], got -1\.0 "
                                         r"\(the upper limit is `panorama\.match\.ransac_threshold`\)$"):
        from_mapping(params.PanoramaMatchParams, {"ransac_threshold": 5.0, "refit_threshold": -1.0}, "panorama.match")


def test_models_built_in_python_name_the_field():
    """Python callers get the same check; the message names the bare field (no section is known there)."""
    with pytest.raises(ValueError, match=r"^`rho` must be in \(0\.0, 100\.0\], got -1$") as info:
        HoughLinesParams(rho=-1)
    assert isinstance(info.value, InputError)
    with pytest.raises(InputError, match=r"^`regions` must be a DefectRegionParams, got int$"):
        InspectParams(regions=3)


def test_replace_validates_and_keeps_dataclasses():
    p = InspectParams()
    q = replace(p, regions=replace(p.regions, pad=9.0))
    assert q.regions.pad == 9.0 and q.features == p.features and p.regions.pad == 0.0
    with pytest.raises(InputError, match=r"^`ratio` must be in \(0\.0, 1\.0\], got 2\.0$"):
        replace(MatchParams(), ratio=2.0)
    with pytest.raises(InputError, match=r"`seed_threshold` must be in \[0\.5, 1\.0\], got 0\.3 \(the lower limit"):
        p.regions.replace(threshold=0.5)  # now above seed_threshold 0.3

    @dataclasses.dataclass(frozen=True)
    class Plain:
        a: int = 1
    assert replace(Plain(), a=2) == Plain(a=2)


def test_models_are_frozen_and_hashable():
    p = MatchParams()
    with pytest.raises(ValueError):
        p.ratio = 0.5
    assert hash(p) == hash(MatchParams()) and p == MatchParams() and p != MatchParams(ratio=0.5)


def test_file_errors(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_params_file(tmp_path / "none.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1, 2\n")
    with pytest.raises(InputError, match="not valid YAML"):
        read_params_file(bad)
    top = tmp_path / "list.yaml"
    top.write_text("- 1\n- 2\n")
    with pytest.raises(InputError, match="expected a mapping of sections"):
        read_params_file(top)
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    assert read_params_file(empty) == {}
    with pytest.raises(InputError, match="section `homography.match` is missing"):
        load_section(MatchParams, "homography.match", empty)


def test_unsafe_yaml_is_not_executed(tmp_path):
    evil = tmp_path / "evil.yaml"
    evil.write_text("x: !!python/object/apply:os.system ['echo hacked']\n")
    with pytest.raises(InputError, match="not valid YAML"):
        read_params_file(evil)


def test_inspect_params_default_to_the_stage_sections(tmp_path):
    """The defaults are declared once (the models; tests/test_init.py checks that `cvpipe init` writes them and
    that this repository's params.yaml has every key): the inspect command's parameters read from a params file
    that holds the defaults are the defaults."""
    from cvpipe.init import default_params

    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(default_params()), encoding="utf-8")
    assert load_inspect_params(path) == InspectParams()


def _mirrored_defaults():
    """Every library keyword default that is a params field, in one table: (function, {parameter: (model, field,
    unit conversion or None)}). A function listed here must take the default from the model, never repeat it."""
    import importlib
    import math

    import numpy as np

    from cvpipe import features, homography, hough, matching, stereo
    from cvpipe.params import (DefectDiffParams, FeaturesParams, HomographyEstimateParams, HomographyReportParams,
                               HoughEdgesParams, HoughReportParams, LogoMatchParams, LogoVerifyParams, SamplesParams,
                               StereoBmParams, StereoDepthParams, StereoRectifyParams, StereoReportParams,
                               StereoSgbmParams)

    # the modules themselves (a package re-exports functions under some of these names, e.g. `estimate`)
    estimate, homography_report, gallery, verify, diff, epipolar, pipeline, rectify, stereo_report, samples = (
        importlib.import_module(f"cvpipe.{name}") for name in (
            "homography.estimate", "homography.report", "logo.gallery", "logo.verify", "defect.diff",
            "stereo.epipolar", "stereo.pipeline", "stereo.rectify", "stereo.report", "samples"))

    def same(model, *names):
        return {name: (model, name, None) for name in names}

    est = same(HomographyEstimateParams, "threshold", "confidence", "max_iters")
    rho = same(HoughLinesParams, "rho")
    theta = {"theta": (HoughLinesParams, "theta_deg", math.radians)}  # the accumulator takes radians, like cv2
    lines = {**rho, **theta, **same(HoughLinesParams, "threshold")}
    rect = same(StereoRectifyParams, "threshold", "margin")
    return [
        (stereo.disparity_sgm, same(StereoSgmParams, *StereoSgmParams.model_fields)),
        (stereo.disparity_opencv_bm, same(StereoBmParams, *StereoBmParams.model_fields)),
        (stereo.disparity_opencv_sgbm, same(StereoSgbmParams, *StereoSgbmParams.model_fields)),
        (stereo.compute_disparity, same(StereoDepthParams, "method")),
        (estimate.find_homography, est),
        (estimate.METHODS["opencv_ransac"], est),
        (estimate.METHODS["opencv_magsac"], est),
        (homography.correspondences, {**same(FeaturesParams, "detector", "max_features"),
                                      **same(MatchParams, "ratio", "cross_check")}),
        (homography_report.compare_methods, same(HomographyReportParams, "success_px")),
        (homography_report.alignment_checkerboard, {"tiles": (HomographyReportParams, "checker_tiles", None)}),
        (homography_report.alignment_panel, {"tiles": (HomographyReportParams, "checker_tiles", None)}),
        (hough.canny_edges, {"low": (HoughEdgesParams, "canny_low", None),
                             "high": (HoughEdgesParams, "canny_high", None),
                             **same(HoughEdgesParams, "aperture", "l2_gradient", "blur_sigma")}),
        (hough.hough_grid, {**rho, **theta}),
        (hough.hough_lines, {**lines, **same(HoughLinesParams, "refine")}),
        (hough.hough_lines_opencv, lines),
        (hough.line_cells, {**rho, **theta}),
        (hough.cell_agreement, {**rho, **theta}),
        (hough.truth_matches, {**same(HoughReportParams, "rho_tol"),
                               "theta_tol": (HoughReportParams, "theta_tol_deg", np.deg2rad)}),
        (hough.median_seconds, same(HoughLinesParams, "repeats")),
        (matching.match, same(MatchParams, "ratio", "cross_check")),
        (matching.MatchIndex.query, same(MatchParams, "ratio")),
        (features.detect, same(FeaturesParams, "detector", "max_features")),
        (epipolar.find_fundamental, same(StereoRectifyParams, "threshold")),
        (rectify.rectifying_homographies, same(StereoRectifyParams, "margin")),
        (rectify.rectify_uncalibrated, rect),
        (rectify.opencv_uncalibrated, same(StereoRectifyParams, "threshold")),
        (rectify.rectify_calibrated, same(StereoRectifyParams, "margin")),
        (rectify.looks_rectified, {"max_dy": (StereoRectifyParams, "rectified_max_dy", None)}),
        (pipeline.feature_matches, same(StereoRectifyParams, "detector", "max_features", "ratio", "seed")),
        (pipeline.rectify_pair, {**rect, **same(StereoRectifyParams, "seed", "rectified_max_dy",
                                                "rectified_share")}),
        (stereo_report.comparison_picture, same(StereoReportParams, "error_clip")),
        (stereo_report.error_picture, {"clip": (StereoReportParams, "error_clip", None)}),
        (diff.fit_gain_bias, {"trim": (DefectDiffParams, "fit_trim", None)}),
        (verify.affine_ransac, {"hypotheses": (LogoVerifyParams, "affine_samples", None)}),
        (samples.make_logo, {"n_scenes": (SamplesParams, "logo_scenes", None),
                             "n_negatives": (SamplesParams, "logo_negatives", None)}),
        (gallery.build_gallery, same(LogoMatchParams, "min_features")),
    ]


def test_function_defaults_are_the_model_defaults():
    """The keyword defaults of the library functions are the models' own default objects (declared once, on the
    field): a signature cannot disagree with the model or params.yaml because it does not declare a value."""
    from cvpipe import homography
    from cvpipe.params import HomographyEstimateParams

    for fn, mirrored in _mirrored_defaults():
        sig = inspect.signature(fn).parameters
        for name, (model, field, convert) in mirrored.items():
            declared = model.model_fields[field].default
            got = sig[name].default
            if convert is None:
                assert got is declared, f"{fn.__qualname__}({name}=...) is not {model.__name__}.{field}"
            else:  # a unit conversion of the field's default (degrees -> radians), computed from it
                want = convert(declared)
                assert got == want and type(got) is type(want), f"{fn.__qualname__}({name}=...)"
    assert homography.DEFAULT_MAX_ITERS is HomographyEstimateParams.model_fields["max_iters"].default


def test_function_defaults_repeat_no_literal():
    """No function of the table writes a mirrored default as a literal: each one reads the model (``_SGM.p1``), or
    a module constant computed from the field (``_THETA = math.radians(_LINES.theta_deg)``)."""
    import ast
    import sys
    import textwrap

    for fn, mirrored in _mirrored_defaults():
        node = ast.parse(textwrap.dedent(inspect.getsource(fn))).body[0]
        args = node.args
        positional = args.posonlyargs + args.args
        defaults = dict(zip([a.arg for a in positional[len(positional) - len(args.defaults):]], args.defaults))
        defaults.update({a.arg: d for a, d in zip(args.kwonlyargs, args.kw_defaults) if d is not None})
        module = ast.parse(inspect.getsource(sys.modules[fn.__module__]))
        constants = {t.id: ast.unparse(n.value) for n in module.body if isinstance(n, ast.Assign)
                     for t in ast.walk(n.targets[0]) if isinstance(t, ast.Name)}
        for name, (model, field, convert) in mirrored.items():
            text = ast.unparse(defaults[name])
            where = f"{fn.__module__}.{fn.__qualname__}({name}={text})"
            try:
                ast.literal_eval(defaults[name])
            except ValueError:  # not a literal: good
                pass
            else:
                pytest.fail(f"{where} repeats a literal; read {model.__name__}.{field} instead")
            if convert is None:
                assert isinstance(defaults[name], ast.Attribute) and defaults[name].attr == field, where
            else:
                assert isinstance(defaults[name], ast.Name) and f".{field}" in constants[defaults[name].id], where


def test_detector_choices_are_the_registry():
    """Every `detector` field accepts exactly the detectors cvpipe.features can build."""
    seen = 0
    for section, cls in params.SECTIONS.items():
        if "detector" in cls.model_fields:
            assert set(typing.get_args(cls.model_fields["detector"].annotation)) == set(features.DETECTORS), section
            seen += 1
    assert seen >= 4  # homography, defect, panorama, logo


# ------------------------------------------------------------------ cases generated from the constraint metadata


def _fields():
    for section, cls in params.SECTIONS.items():
        for name, info in cls.model_fields.items():
            yield section, cls, name, info


def _range_cases():
    """(section, cls, field, bad value, the violated limit as printed) for each Field limit of every section."""
    for section, cls, name, info in _fields():
        for m in info.metadata:
            if isinstance(m, annotated_types.Gt):
                yield pytest.param(section, cls, name, m.gt, f"({m.gt!r}, ", id=f"{section}.{name}>")
            elif isinstance(m, annotated_types.Ge):
                yield pytest.param(section, cls, name, m.ge - 1, f"[{m.ge!r}, ", id=f"{section}.{name}>=")
            elif isinstance(m, annotated_types.Lt):
                yield pytest.param(section, cls, name, m.lt, f", {m.lt!r})", id=f"{section}.{name}<")
            elif isinstance(m, annotated_types.Le):
                yield pytest.param(section, cls, name, m.le + 1, f", {m.le!r}]", id=f"{section}.{name}<=")


def _choice_cases():
    for section, cls, name, info in _fields():
        if typing.get_origin(info.annotation) is Literal:
            choices = list(typing.get_args(info.annotation))
            bad = "not-a-choice" if isinstance(choices[0], str) else max(choices) + 1
            yield pytest.param(section, cls, name, choices, bad, id=f"{section}.{name}")


def _bound_cases():
    for section, cls, name, info in _fields():
        for b in info.metadata:
            if isinstance(b, Bound):
                limit = getattr(cls(), b.other)
                # just past the limit: below it for a lower limit (>= and >), above it for an upper one (<=)
                bad = {">=": limit - 1, ">": limit, "<=": limit + 1}[b.op]
                yield pytest.param(section, cls, name, b, limit, bad, id=f"{section}.{name}{b.op}{b.other}")


RANGES, CHOICES, BOUNDS = list(_range_cases()), list(_choice_cases()), list(_bound_cases())


def test_the_generators_find_the_declared_checks():
    """A sanity check of the generators themselves: the documented examples and the cross-field rules are among them."""
    ids = {c.id for c in RANGES + CHOICES + BOUNDS}
    assert {"hough.lines.theta_deg>", "stereo.sgm.paths", "logo.features.detector", "stereo.sgm.p2>p1",
            "hough.edges.canny_high>=canny_low", "panorama.match.refit_threshold<=ransac_threshold",
            "logo.match.per_reference<=k", "defect.regions.seed_threshold>=threshold"} <= ids
    assert len(RANGES) >= 70 and len(CHOICES) >= 10 and len(BOUNDS) >= 6


@pytest.mark.parametrize("section, cls, name, bad, shown", RANGES)
def test_every_range_has_a_message(section, cls, name, bad, shown):
    for build, key in ((lambda: from_mapping(cls, {name: bad}, section), f"{section}.{name}"),
                       (lambda: cls(**{name: bad}), name)):
        with pytest.raises(InputError) as info:
            build()
        msg = str(info.value)
        # "`key` must be in [lo, hi], got bad", and "(the upper limit is `other`)" when another field sets one side
        assert re.fullmatch(rf"`{re.escape(key)}` must be in [\[(]\S+, \S+[\])], got {re.escape(repr(bad))}"
                            r"( \(the (lower|upper) limit is `[\w.]+`\))?", msg), msg
        assert shown in msg, (msg, shown)


@pytest.mark.parametrize("section, cls, name, choices, bad", CHOICES)
def test_every_choice_has_a_message(section, cls, name, choices, bad):
    with pytest.raises(InputError, match=r"^" + re.escape(
            f"`{section}.{name}` must be one of {choices}, got {bad!r}") + "$"):
        from_mapping(cls, {name: bad}, section)
    for c in choices:  # and every choice is accepted
        assert getattr(from_mapping(cls, {name: c}, section), name) == c


@pytest.mark.parametrize("section, cls, name, bound, limit, bad", BOUNDS)
def test_every_cross_field_limit_has_a_message(section, cls, name, bound, limit, bad):
    with pytest.raises(InputError) as info:
        from_mapping(cls, {name: bad}, section)
    msg = str(info.value)
    side = "upper" if bound.op == "<=" else "lower"
    shown = {"<=": f", {limit!r}]", ">=": f"[{limit!r}, ", ">": f"({limit!r}, "}[bound.op]
    assert msg.startswith(f"`{section}.{name}` must be in ") and shown in msg, (msg, shown)
    assert msg.endswith(f", got {bad!r} (the {side} limit is `{section}.{bound.other}`)"), msg
    if bound.op != ">":  # an inclusive limit is itself accepted
        assert getattr(from_mapping(cls, {name: limit}, section), name) == limit


@pytest.mark.parametrize("section, cls", [pytest.param(s, c, id=s) for s, c in params.SECTIONS.items()])
def test_unknown_keys_refused(section, cls):
    with pytest.raises(InputError, match=r"^unknown key `" + section.replace(".", r"\.") + r"\.nope` in params; "
                                         r"expected one of: " + ", ".join(sorted(cls.model_fields)) + "$"):
        from_mapping(cls, {"nope": 1}, section)


NUMBERS = [pytest.param(s, c, n, info.annotation, id=f"{s}.{n}") for s, c, n, info in _fields()
           if info.annotation in (int, float)]


@pytest.mark.parametrize("section, cls, name, tp", NUMBERS)
def test_bools_and_strings_refused_for_numbers(section, cls, name, tp):
    word = "an integer" if tp is int else "a number"
    default = cls.model_fields[name].default
    for bad in (True, False, str(default)):
        with pytest.raises(InputError, match=r"^`" + f"{section}.{name}".replace(".", r"\.") + f"` must be {word}, "):
            from_mapping(cls, {name: bad}, section)
    if tp is float and float(default).is_integer():  # 3 is accepted for 3.0, and stored as a float
        got = getattr(from_mapping(cls, {name: int(default)}, section), name)
        assert got == default and isinstance(got, float)


def test_examples_run():
    """The Examples sections of the params machinery (Section.replace, from_mapping) are true."""
    import doctest

    from cvpipe.params import base

    result = doctest.testmod(base, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0, result


# ----------------------------------------------------------- numbers the code can use: finite, C int, real ranges


FLOATS = [pytest.param(s, c, n, id=f"{s}.{n}") for s, c, n, info in _fields() if info.annotation is float]
INTS = [pytest.param(s, c, n, id=f"{s}.{n}") for s, c, n, info in _fields() if info.annotation is int]


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")], ids=["nan", "inf", "-inf"])
@pytest.mark.parametrize("section, cls, name", FLOATS)
def test_every_float_refuses_nan_and_infinity(section, cls, name, bad):
    """No float parameter takes NaN or an infinity (a range check lets inf through, and NaN compares False)."""
    for build, key in ((lambda: from_mapping(cls, {name: bad}, section), f"{section}.{name}"),
                       (lambda: cls(**{name: bad}), name)):
        with pytest.raises(InputError, match=r"^" + re.escape(f"`{key}` must be a finite number, got {bad!r}") + "$"):
            build()


@pytest.mark.parametrize("section, cls, name", INTS)
def test_every_integer_fits_a_c_int(section, cls, name):
    """An integer parameter reaches OpenCV or a compiled kernel as a C int: 2**31 and beyond are refused with the
    range, and so is anything below -2**31; the message shows the field's own limits where it declares them."""
    for bad in (2**31, 2**70, -(2**31) - 1):
        with pytest.raises(InputError) as info:
            from_mapping(cls, {name: bad}, section)
        msg = str(info.value)
        m = re.fullmatch(rf"`{re.escape(section)}\.{name}` must be in [\[(](-?\d+), (-?\d+)[\])], got {bad}"
                         r"( \(the (lower|upper) limit is `[\w.]+`\))?", msg)
        assert m and -(2**31) <= int(m.group(1)) and int(m.group(2)) <= 2**31 - 1, msg


def test_integer_range_messages():
    with pytest.raises(InputError, match=r"^`hough\.lines\.threshold` must be in \[1, 2147483647\], "
                                         r"got 1180591620717411303424$"):
        from_mapping(HoughLinesParams, {"threshold": 2**70}, "hough.lines")
    with pytest.raises(InputError, match=r"^`demo\.hi` must be in \[3, 2147483647\], got 2147483648 "
                                         r"\(the lower limit is `demo\.n`\)$"):
        from_mapping(Demo, {"hi": 2**31}, "demo")
    assert from_mapping(Demo, {"n": -(2**31), "hi": 2**31 - 1}, "demo").hi == 2**31 - 1  # both ends accepted


def test_a_field_may_allow_non_finite_floats_and_wider_integers():
    """The defaults of the rule are per side: a field that declares a limit, or ``allow_inf_nan``, sets its own."""
    from pydantic import Field

    class Wide(Section):
        big: int = Field(0, ge=0, le=2**63 - 1)
        score: float = Field(0.0, allow_inf_nan=True)

    assert Wide(big=2**40, score=float("-inf")).big == 2**40
    with pytest.raises(InputError, match=r"^`big` must be in \[0, 9223372036854775807\], got 9223372036854775808$"):
        Wide(big=2**63)


@pytest.mark.parametrize("section, name", [(s, n) for s, c, n, info in _fields() if n == "seed"])
def test_seeds_are_non_negative(section, name):
    with pytest.raises(InputError, match=r"^`" + re.escape(f"{section}.{name}") + r"` must be in \[0, 2147483647\], "
                                         r"got -1$"):
        from_mapping(params.SECTIONS[section], {name: -1}, section)


@pytest.mark.parametrize("section, mapping, message", [
    # OpenCV's StereoBM asserts uniquenessRatio >= 0 (a cv2.error from inside compute())
    ("stereo.opencv_bm", {"uniqueness": -5}, r"`stereo\.opencv_bm\.uniqueness` must be in \[0, 100\], got -5"),
    ("stereo.opencv_sgbm", {"uniqueness": -5}, r"`stereo\.opencv_sgbm\.uniqueness` must be in \[0, 100\], got -5"),
    ("stereo.opencv_bm", {"speckle_range": -1}, r"`stereo\.opencv_bm\.speckle_range` must be in \[0, 4096\], got -1"),
    ("stereo.opencv_sgbm", {"speckle_size": -1},
     r"`stereo\.opencv_sgbm\.speckle_size` must be in \[0, 2147483647\], got -1"),
    ("homography.estimate", {"threshold": 1e308},
     r"`homography\.estimate\.threshold` must be in \(0\.0, 100\.0\], got 1e\+308"),
    ("panorama.warp", {"max_canvas_megapix": float("inf")},
     r"`panorama\.warp\.max_canvas_megapix` must be a finite number, got inf"),
    ("panorama.features", {"work_megapix": float("-inf")},
     r"`panorama\.features\.work_megapix` must be a finite number, got -inf"),
    ("panorama.features", {"work_megapix": 1e-9},
     r"`panorama\.features\.work_megapix` must be <= 0 \(full resolution\) or in \[0\.01, 1000\.0\], got 1e-09"),
    ("panorama.warp", {"compose_megapix": 0.005},
     r"`panorama\.warp\.compose_megapix` must be <= 0 \(full resolution\) or in \[0\.01, 1000\.0\], got 0\.005"),
    ("stereo.sgm", {"ad_weight": 256.0}, r"`stereo\.sgm\.ad_weight` must be in \[0\.0, 255\.0\], got 256\.0"),
    # the census signature of an (h, w) window holds h * w - 1 bits in a uint64 (cvpipe.stereo.sgm)
    ("stereo.sgm", {"census_size": [99, 99]},
     r"`stereo\.sgm\.census_size` must be two odd sizes \(height, width\) covering at most 65 pixels, got \[99, 99\]"),
    ("stereo.sgm", {"census_size": [9, 9]}, r"`stereo\.sgm\.census_size` must be two odd .*, got \[9, 9\]"),
    ("stereo.sgm", {"census_size": [4, 5]}, r"`stereo\.sgm\.census_size` must be two odd .*, got \[4, 5\]"),
    ("stereo.sgm", {"census_size": [-1, 5]}, r"`stereo\.sgm\.census_size` must be two odd .*, got \[-1, 5\]"),
])
def test_values_the_algorithms_cannot_take_are_refused_by_the_loader(section, mapping, message):
    with pytest.raises(InputError, match=r"^" + message + "$"):
        from_mapping(params.SECTIONS[section], mapping, section)


@pytest.mark.parametrize("section, mapping", [
    ("panorama.features", {"work_megapix": 0.0}), ("panorama.features", {"work_megapix": -1.0}),
    ("panorama.features", {"work_megapix": 0.01}), ("panorama.warp", {"compose_megapix": -1.0}),
    ("stereo.sgm", {"census_size": [5, 13]}), ("stereo.sgm", {"census_size": [1, 1]}),
    ("stereo.sgm", {"census_size": [7, 9]}), ("stereo.opencv_sgbm", {"lr_max_diff": -1}),
])
def test_the_edges_of_those_ranges_are_accepted(section, mapping):
    got = from_mapping(params.SECTIONS[section], mapping, section)
    assert all(getattr(got, k) == (tuple(v) if isinstance(v, list) else v) for k, v in mapping.items())
