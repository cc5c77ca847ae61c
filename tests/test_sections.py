"""The section-taking entry points (one parameter convention): each gives exactly what the keyword call with the
section's fields gives, and refuses a parameters object of the wrong section with a one-line InputError naming
``params``."""

import numpy as np
import pytest

from cvpipe import features, hough, matching
from cvpipe.errors import InputError
from cvpipe.homography import estimate, estimate_with, transform_points
from cvpipe.params import HomographyEstimateParams, HoughEdgesParams, HoughLinesParams, MatchParams


def _scene(seed: int = 0) -> np.ndarray:
    """A grey image with rectangles and noise: corners and edges for every detector."""
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 40, (200, 260)).astype(np.uint8)
    for _ in range(12):
        x, y = rng.integers(0, 220), rng.integers(0, 160)
        img[y:y + rng.integers(10, 40), x:x + rng.integers(10, 40)] = rng.integers(80, 255)
    return img


def _refused(call, wrong) -> None:
    with pytest.raises(InputError, match=r"^`params` must be a \w+Params \(the [a-z<>. /]+ section\), got "
                                         + type(wrong).__name__ + "$"):
        call(wrong)


@pytest.mark.parametrize("detector, cross_check", [("sift", False), ("orb", True)])
def test_match_with_equals_keyword_match(detector, cross_check):
    a, b = _scene(0), np.roll(_scene(0), (3, 5), axis=(0, 1))
    fa, fb = features.detect(a, detector, 500), features.detect(b, detector, 500)
    p = MatchParams(ratio=0.7, cross_check=cross_check)
    got = matching.match_with(fa, fb, p)
    want = matching.match(fa.descriptors, fb.descriptors, ratio=0.7, cross_check=cross_check, binary=fa.binary)
    assert len(want) > 0  # the shifted copy matches: the comparison is not between two empty arrays
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(matching.match_with(fa, fb, None), matching.match_with(fa, fb, MatchParams()))


def test_match_with_refuses_another_section():
    fa = features.detect(_scene(0), "orb", 100)
    _refused(lambda p: matching.match_with(fa, fa, p), HoughEdgesParams())
    _refused(lambda p: matching.match_with(fa, fa, p), {"ratio": 0.8})


def test_edges_of_equals_keyword_canny():
    gray = _scene(1)
    p = HoughEdgesParams(canny_low=30.0, canny_high=120.0, aperture=5, l2_gradient=True, blur_sigma=1.5)
    got = hough.edges_of(gray, p)
    want = hough.canny_edges(gray, 30.0, 120.0, aperture=5, l2_gradient=True, blur_sigma=1.5)
    assert want.any()  # some edges, so equality says something
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(hough.edges_of(gray), hough.canny_edges(gray))  # None: the model's defaults


def test_edges_of_refuses_another_section():
    _refused(lambda p: hough.edges_of(_scene(1), p), HoughLinesParams())


@pytest.mark.parametrize("method", ["ours", "opencv_ransac"])
def test_estimate_with_equals_keyword_estimate(method):
    rng = np.random.default_rng(3)
    src = rng.uniform(0, 400, (60, 2))
    dst = transform_points([[1.1, 0.05, 7.0], [-0.02, 0.95, -3.0], [1e-4, 0.0, 1.0]], src)
    dst[:15] += rng.uniform(-40, 40, (15, 2))  # outliers, so RANSAC's sampling (and the seed) matters
    p = HomographyEstimateParams(threshold=2.5, confidence=0.99, max_iters=500, seed=11)
    got = estimate_with(src, dst, p, method)
    want = estimate(method, src, dst, threshold=2.5, confidence=0.99, max_iters=500, rng=11)
    np.testing.assert_array_equal(got.H, want.H)
    np.testing.assert_array_equal(got.inliers, want.inliers)


def test_estimate_with_refuses_another_section():
    src = np.random.default_rng(0).uniform(0, 100, (10, 2))
    _refused(lambda p: estimate_with(src, src, p, "ours"), MatchParams())


@pytest.fixture(scope="module")
def crops():
    from cvpipe.samples import photo

    img = photo("astronaut")
    return [img[:, 200:], img[:, :320]]  # two crops overlapping by 120 columns, right one first


def test_panorama_steps_equal_keyword_calls(crops):
    from cvpipe import panorama
    from cvpipe.params import PanoramaFeaturesParams, PanoramaHomographiesParams, PanoramaMatchParams

    fp = PanoramaFeaturesParams(work_megapix=0.2, max_features=700, detector="sift")
    sizes, feats = panorama.features_of(crops, fp)
    grays, want_sizes = panorama.working_images(crops, 0.2)
    want_feats = panorama.detect_all(grays, "sift", 700)
    assert sizes == want_sizes
    for got, want in zip(feats, want_feats):
        np.testing.assert_array_equal(got.xy, want.xy)
        np.testing.assert_array_equal(got.descriptors, want.descriptors)

    mp = PanoramaMatchParams(ratio=0.75, ransac_threshold=2.5, min_inliers=12, candidates=3, refit_threshold=1.5)
    graph = panorama.match_graph_with(feats, sizes, mp, 7)
    want = panorama.match_graph(feats, sizes, ratio=0.75, ransac_threshold=2.5, min_inliers=12, min_confidence=1.0,
                                candidates=3, refit_threshold=1.5, rng=7)
    assert list(graph.edges) == list(want.edges) == [(0, 1)]  # the crops overlap: one edge to compare
    np.testing.assert_array_equal(graph.inliers, want.inliers)
    np.testing.assert_array_equal(graph.edges[0, 1].H, want.edges[0, 1].H)

    hp = PanoramaHomographiesParams(refine="homography", max_points_per_pair=40)
    reg = panorama.register_with(graph, hp, 5)
    want_reg = panorama.register(graph, refine="homography", max_points_per_pair=40, rng=5)
    assert reg.used == want_reg.used == (0, 1)
    assert reg.G.keys() == want_reg.G.keys()
    for k in want_reg.G:
        np.testing.assert_array_equal(reg.G[k], want_reg.G[k])
    reg_item, _ = panorama.register_set((graph, None), (hp, PanoramaMatchParams(seed=5)))
    for k in want_reg.G:  # the stage's item: seeded by the match section's seed
        np.testing.assert_array_equal(reg_item.G[k], want_reg.G[k])


def test_panorama_steps_refuse_another_section(crops):
    from cvpipe import panorama
    from cvpipe.params import PanoramaFeaturesParams

    _refused(lambda p: panorama.features_of(crops, p), MatchParams())
    sizes, feats = panorama.features_of(crops, PanoramaFeaturesParams(work_megapix=0.1, max_features=300))
    _refused(lambda p: panorama.match_graph_with(feats, sizes, p, 0), MatchParams())
    graph = panorama.match_graph_with(feats, sizes, None, 0)
    _refused(lambda p: panorama.register_with(graph, p, 0), PanoramaFeaturesParams())


@pytest.mark.parametrize("detector", ["sift", "orb"])
def test_detect_with_equals_keyword_detect(detector):
    from cvpipe.params import LogoFeaturesParams

    gray = _scene(2)
    p = LogoFeaturesParams(detector=detector, max_features=300, scene_min_long_side=400)
    for scene, min_long_side in ((False, 0), (True, 400)):  # 260 px long side: a scene is enlarged to 400
        got = features.detect_with(gray, p, scene=scene)
        want = features.detect(gray, detector, 300, min_long_side=min_long_side)
        assert len(want.xy) > 0  # features to compare
        np.testing.assert_array_equal(got.xy, want.xy)
        np.testing.assert_array_equal(got.descriptors, want.descriptors)
        arrays, _ = features.detect_item((gray, scene), p)  # the stage's item
        np.testing.assert_array_equal(arrays["xy"], want.xy)
    # a section without scene_min_long_side detects a scene at its size
    plain = features.detect_with(gray, features_params(detector), scene=True)
    np.testing.assert_array_equal(plain.xy, features.detect(gray, detector, 4000).xy)


def features_params(detector):
    from cvpipe.params import FeaturesParams

    return FeaturesParams(detector=detector)


def test_detect_with_refuses_another_section():
    _refused(lambda p: features.detect_with(_scene(2), p), MatchParams())


@pytest.mark.parametrize("method", ["opencv_bm", "opencv_sgbm"])
def test_disparity_with_equals_keyword_call(method):
    from cvpipe import stereo
    from cvpipe.params import StereoBmParams, StereoSgbmParams

    right = _scene(4)
    left = np.roll(right, 5, axis=1)  # a 5 px disparity everywhere
    p = StereoBmParams(block_size=11, uniqueness=5) if method == "opencv_bm" else \
        StereoSgbmParams(block_size=5, mode="hh", uniqueness=5)
    got = stereo.disparity_with(left, right, 32, p, method)
    options = {k: getattr(p, k) for k in type(p).model_fields}
    want = stereo.compute_disparity(left, right, 32, method, **options)
    assert np.isfinite(want).any()  # some disparities to compare
    np.testing.assert_array_equal(got, want)  # NaN at the same places too


def test_disparity_with_refuses_another_section():
    from cvpipe import stereo
    from cvpipe.params import StereoBmParams

    g = _scene(4)
    _refused(lambda p: stereo.disparity_with(g, g, 16, p, "sgm"), StereoBmParams())  # sgm takes stereo.sgm
    with pytest.raises(InputError, match=r"^`method` must be one of \['opencv_bm', 'opencv_sgbm', 'sgm'\], got 'x'$"):
        stereo.disparity_with(g, g, 16, None, "x")


def test_samples_build_equals_keyword_build_all():
    from cvpipe import samples
    from cvpipe.params import SamplesParams

    got = samples.build(SamplesParams(seed=5, logo_scenes=2, logo_negatives=1))
    want = samples.build_all(5, logo_scenes=2, logo_negatives=1)
    assert got.keys() == want.keys()
    for task in want:
        assert got[task].images.keys() == want[task].images.keys() and want[task].images  # images to compare
        for name, img in want[task].images.items():
            np.testing.assert_array_equal(got[task].images[name], img)
        assert got[task].truth == want[task].truth


def test_samples_build_refuses_another_section():
    from cvpipe import samples

    _refused(samples.build, MatchParams())



def test_opencv_stitch_with_makes_the_keyword_call(crops, monkeypatch):
    # cv2.Stitcher is not repeatable within a process (the same call gave 511 and 507 rows), so the test checks
    # that the section call makes exactly the keyword call, not that two stitches agree
    from cvpipe import panorama
    from cvpipe.panorama import opencv_baseline
    from cvpipe.params import PanoramaFeaturesParams, PanoramaMatchParams, PanoramaWarpParams

    calls = []
    monkeypatch.setattr(opencv_baseline, "opencv_stitch_cameras", lambda *args, **kw: calls.append((args, kw)) or "r")
    fp, mp, wp = PanoramaFeaturesParams(work_megapix=0.2), PanoramaMatchParams(min_confidence=0.8, seed=7), \
        PanoramaWarpParams(compose_megapix=0.3)
    assert panorama.opencv_stitch_with(crops, fp, mp, wp) == "r"
    assert calls == [((crops, 0.2, 0.3, 0.8), {"seed": 7})]  # work_megapix, compose_megapix, min_confidence, seed
    _refused(lambda p: panorama.opencv_stitch_with(crops, fp, p, wp), PanoramaWarpParams())

# the modules whose section entry points' Examples no other test module runs
@pytest.mark.parametrize("name", ["cvpipe.features", "cvpipe.panorama.match", "cvpipe.panorama.opencv_baseline",
                                  "cvpipe.samples", "cvpipe.stereo.methods"])
def test_entry_point_examples_run(name):
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0, f"{name} has no Examples section"
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed"
