"""Property tests (hypothesis): the estimators and the image reader raise only cvpipe's own errors.

Whatever the points (NaN/inf, duplicates, collinear, too few, tiny or huge coordinates) or the bytes of an "image"
file, the result is either a valid answer or an exception from :mod:`cvpipe.errors` with a message: never a
numpy, OpenCV or ZeroDivision error from deep inside.
"""

from __future__ import annotations

import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from cvpipe import homography, io
from cvpipe.errors import CvpipeError

#: modest example counts and no deadline: the first example of a test pays for OpenCV's and numpy's first use
FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

_any_float = st.floats(allow_nan=True, allow_infinity=True, width=64)
_coord = st.one_of(
    st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False),  # ordinary pixels
    st.floats(-1e-9, 1e-9, allow_nan=False, allow_infinity=False),  # tiny
    st.floats(-1e15, 1e15, allow_nan=False, allow_infinity=False),  # huge
)


def _points(n, elements=_coord):
    return hnp.arrays(np.float64, (n, 2), elements=elements)


@st.composite
def correspondences(draw):
    """src, dst pairs of the troublesome kinds, each a few to a few dozen points."""
    kind = draw(st.sampled_from(["random", "nonfinite", "duplicates", "collinear", "few", "scaled", "exact"]))
    n = draw(st.integers(0, 3) if kind == "few" else st.integers(4, 40))
    if kind == "nonfinite":
        return draw(_points(n, _any_float)), draw(_points(n, _any_float))
    src = draw(_points(n))
    if kind == "duplicates":
        src = np.repeat(src[:1], n, axis=0) if draw(st.booleans()) else np.concatenate([src[: n // 2]] * 2
                                                                                        + [src[: n % 2]])
    if kind == "collinear":
        t = np.linspace(0, 1, n)[:, None]
        a, b = draw(_points(2))
        src = a + t * (b - a)
    if kind == "exact":  # a true homography, possibly of enormous or minute scale
        s = draw(st.sampled_from([1e-9, 1.0, 1e9]))
        H = np.array([[1.0, 0.1, 5.0], [0.05, 0.9, -3.0], [1e-4, 2e-4, 1.0]])
        src = np.random.default_rng(draw(st.integers(0, 2**16))).uniform(0, 500, (n, 2)) * s
        return src, homography.transform_points(H, src)
    if kind == "scaled":
        return src, src * draw(st.sampled_from([1e-12, 1e12])) + 3.0
    return src, draw(_points(len(src)))


def _only_ours(fn, *args, **kwargs):
    """Call ``fn``; any exception must be a CvpipeError with a message."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # overflow in intermediate products is not an error
        try:
            return fn(*args, **kwargs)
        except CvpipeError as exc:
            assert str(exc), "an error without a message"
            return None
        except Exception as exc:  # noqa: BLE001 - the property under test
            pytest.fail(f"{type(exc).__name__} escaped: {exc}")


@FAST
@given(correspondences())
def test_find_homography_raises_only_our_errors(pair):
    src, dst = pair
    fit = _only_ours(homography.find_homography, src, dst, threshold=3.0, rng=0, max_iters=500)
    if fit is not None:  # a returned model is a real one
        assert fit.H.shape == (3, 3) and np.isfinite(fit.H).all() and fit.H[2, 2] == 1.0
        assert fit.inliers.shape == (len(src),) and fit.num_inliers >= 4


@FAST
@given(correspondences(), st.sampled_from(sorted(homography.METHODS)))
def test_every_method_raises_only_our_errors(pair, method):
    src, dst = pair
    fit = _only_ours(homography.estimate, method, src, dst, threshold=3.0, rng=0, max_iters=500)
    if fit is not None:
        assert np.isfinite(fit.H).all() and fit.num_inliers >= 4


@FAST
@given(st.integers(0, 40), st.floats(1e-9, 1e9), st.floats(1.0, 1e12))
def test_chance_probability_is_a_probability(n, threshold, area):
    rng = np.random.default_rng(n)
    src, dst = rng.uniform(0, 100, (n, 2)), rng.uniform(0, 100, (n, 2))
    p = homography.chance_probability(np.eye(3), src, dst, threshold, area)
    assert 0.0 <= p <= 1.0
    k = int(rng.integers(0, n + 1)) if n else 0
    lnfa = homography.log10_nfa(k, n, p)
    assert not np.isnan(lnfa)


def _pairs_within(src, dst, H, threshold):
    """Brute force: pairs (i, j), i != j, with dehom(H src_i) within ``threshold`` of dst_j."""
    q = np.c_[src, np.ones(len(src))] @ np.asarray(H, float).T
    ok = np.abs(q[:, 2]) > 1e-12
    u = q[:, :2] / np.where(ok, q[:, 2], 1.0)[:, None]
    d2 = ((u[:, None, :] - dst[None, :, :]) ** 2).sum(axis=2)
    hit = (d2 <= threshold ** 2) & ok[:, None]
    np.fill_diagonal(hit, False)
    return int(hit.sum())


@FAST
@given(st.integers(2, 300), st.sampled_from([0.3, 1.0, 3.0, 25.0]), st.integers(0, 3), st.booleans(),
       st.integers(0, 2 ** 31))
def test_chance_probability_counts_exactly_the_pairs_within_the_threshold(n, threshold, decimals, clustered, seed):
    # the permutation estimate bins dst into a grid; it must count the same pairs as comparing every pair (rounded
    # coordinates and a cluster of equal points put pairs exactly on and around the threshold and the cell borders)
    rng = np.random.default_rng(seed)
    src, dst = rng.uniform(0, 200, (n, 2)).round(decimals), rng.uniform(0, 200, (n, 2)).round(decimals)
    if clustered:
        dst[: n // 2] = dst[0]
    H = np.eye(3) + np.diag([0.02, -0.01, 0.0])
    H[:2, 2] = rng.uniform(-5, 5, 2)
    area = 1e12  # the uniform model then gives ~0, so the permutation count is what is returned
    p = homography.chance_probability(H, src, dst, threshold, area)
    assert p == pytest.approx(max(np.pi * threshold ** 2 / area, _pairs_within(src, dst, H, threshold) / (n * (n - 1.0))),
                              rel=1e-12, abs=0)


@FAST
@given(st.integers(2, 300), st.sampled_from([0.3, 1.0, 3.0, 25.0]), st.integers(0, 3), st.booleans(),
       st.integers(0, 2 ** 31))
def test_chance_bound_is_never_below_the_permutation_estimate(n, threshold, decimals, clustered, seed):
    # the bound holds for any model: perspective ones that squeeze every source into the densest part of dst, and
    # points on the grid's cell borders (coordinates rounded to multiples of the threshold) or stacked on one point
    rng = np.random.default_rng(seed)
    src = rng.uniform(-50, 250, (n, 2)).round(decimals)
    dst = (rng.uniform(-50, 250, (n, 2)) / threshold).round(decimals) * threshold
    if clustered:
        dst[: n // 2] = dst[0] + rng.uniform(-threshold, threshold, (n // 2, 2))
    H = np.eye(3) + rng.normal(0, 0.3, (3, 3)) * np.array([[1, 1, 100], [1, 1, 100], [1e-3, 1e-3, 0]])
    # the worst model of all: every source onto one dst point (the densest disc then holds every hit)
    onto = np.array([[0.0, 0.0, dst[0, 0]], [0.0, 0.0, dst[0, 1]], [0.0, 0.0, 1.0]])
    for model in (H, onto):
        for area in (None, 1e12):
            bound = homography.chance_bound(dst, threshold, area)
            assert 0.0 <= bound <= 1.0
            assert bound >= homography.chance_probability(model, src, dst, threshold, area)
            assert bound >= _pairs_within(src, dst, model, threshold) / (n * (n - 1.0))


_MAGIC = [b"", b"\x89PNG\r\n\x1a\n", b"\xff\xd8\xff\xe0", b"BM", b"II*\x00", b"RIFF\x00\x00\x00\x00WEBP", b"P5\n"]


@FAST
@given(st.sampled_from(_MAGIC), st.binary(min_size=0, max_size=2048),
       st.sampled_from([".png", ".jpg", ".bmp", ".tif", ".webp", ".pgm", ".bin"]),
       st.sampled_from(["color", "gray", "unchanged"]))
def test_read_image_of_random_bytes_raises_only_our_errors(magic, payload, suffix, mode):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / f"x{suffix}"
        p.write_bytes(magic + payload)
        img = _only_ours(io.read_image, p, mode)
        if img is not None:
            assert img.size > 0 and min(img.shape[:2]) >= io.MIN_SIDE


@FAST
@given(st.text(min_size=0, max_size=30))
def test_safe_name_accepts_only_plain_names(name):
    try:
        out = io.safe_name(name, "pair name")
    except CvpipeError:
        return
    assert out == name and "/" not in name and "\\" not in name and name not in ("", ".", "..")
    assert Path(name).name == name
