"""cvpipe.features and cvpipe.matching on an image pair related by a known homography."""

import cv2
import numpy as np
import pytest

from cvpipe import features, matching
from cvpipe.errors import InputError

H_TRUE = np.array([[0.92, 0.12, 25.0], [-0.10, 0.95, 12.0], [1e-4, -5e-5, 1.0]])


@pytest.fixture(scope="module")
def pair(textured_image):
    h, w = textured_image.shape
    return textured_image, cv2.warpPerspective(textured_image, H_TRUE, (w, h))


@pytest.mark.parametrize("detector", sorted(features.DETECTORS))
def test_every_detector_gives_correct_matches(pair, detector):
    a, b = pair
    fa, fb = features.detect(a, detector, 2000), features.detect(b, detector, 2000)
    assert 100 <= len(fa) <= 2000 and fa.descriptors.shape[0] == len(fa)
    assert fa.binary == (fa.descriptors.dtype == np.uint8)
    idx = matching.match(fa.descriptors, fb.descriptors, ratio=0.8, cross_check=True)
    assert len(idx) >= 50
    proj = cv2.perspectiveTransform(fa.xy[idx[:, 0]][None].astype(np.float64), H_TRUE)[0]
    err = np.linalg.norm(proj - fb.xy[idx[:, 1]], axis=1)
    # ratio test + cross check keep mostly true matches: at least 85 % within 3 px of where H puts them
    assert np.mean(err < 3.0) >= 0.85


def test_brisk_and_akaze_found_through_the_compatibility_lookup():
    assert features.opencv_factory("BRISK")() is not None
    assert features.opencv_factory("AKAZE")() is not None
    with pytest.raises(ImportError, match="has no NOSUCHTHING"):
        features.opencv_factory("NOSUCHTHING")


def test_blank_image_has_no_features():
    f = features.detect(np.full((100, 100), 128, np.uint8), "sift")
    assert len(f) == 0 and f.descriptors.shape == (0, 128)
    assert len(features.detect(np.zeros((100, 100), np.uint8), "orb").descriptors) == 0


def test_max_features_caps_by_response(textured_image):
    f = features.detect(textured_image, "orb", 50)
    assert len(f) == 50 and np.all(np.diff(f.response) <= 0)


def test_roundtrip_arrays(textured_image):
    f = features.detect(textured_image, "akaze", 100)
    g = features.Features.from_arrays(f.to_arrays())
    assert g.detector == "akaze" and np.array_equal(g.descriptors, f.descriptors)


def test_detect_validation():
    with pytest.raises(ValueError, match=r"`detector` must be one of \['akaze', 'brisk', 'orb', 'sift'\]"):
        features.detect(np.zeros((10, 10), np.uint8), "surf")
    with pytest.raises(ValueError, match="`gray` must be a"):
        features.detect(np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(ValueError, match="`max_features` must be an integer >= 1"):
        features.detect(np.zeros((10, 10), np.uint8), max_features=0)
    with pytest.raises(InputError, match="empty"):
        features.detect(np.zeros((0, 10), np.uint8))


def test_match_validation_and_edge_cases():
    a = np.random.default_rng(0).random((20, 128), dtype=np.float32)
    with pytest.raises(ValueError, match=r"`ratio` must be in \(0, 1\], got 1\.5"):
        matching.match(a, a, ratio=1.5)
    with pytest.raises(ValueError, match="same width"):
        matching.match(a, a[:, :64])
    assert matching.match(a[:0], a).shape == (0, 2)
    # identical descriptors: every point matches itself with distance 0 (ratio 1 keeps nearest neighbours)
    idx = matching.match(a, a, ratio=1.0, cross_check=True)
    assert np.array_equal(np.sort(idx[:, 0]), np.arange(20)) and np.all(idx[:, 0] == idx[:, 1])


@pytest.mark.parametrize("detector", ["sift", "orb"])
def test_match_index_gives_the_same_matches_as_match(pair, detector):
    # one prebuilt index queried by a partner must agree with a fresh match (same search, same ratio test): the
    # panorama relies on it to build each image's index only once. Hamming brute force is exact, so ORB agrees
    # exactly; FLANN's KD-trees are randomised per build, so for SIFT a few approximate neighbours may differ
    a, b = pair
    fa, fb = features.detect(a, detector, 1500), features.detect(b, detector, 1500)
    index = matching.MatchIndex(fb.descriptors)
    assert len(index) == len(fb) and index.binary == fb.binary
    for ratio in (0.7, 0.8):
        got = index.query(fa.descriptors, ratio=ratio)
        ref = matching.match(fa.descriptors, fb.descriptors, ratio=ratio)
        if fb.binary:
            assert np.array_equal(got, ref)
        else:
            common = len({tuple(p) for p in got} & {tuple(p) for p in ref})
            assert common >= 0.97 * max(len(got), len(ref)) and len(ref) >= 50


def test_match_index_validation_and_edge_cases():
    a = np.random.default_rng(0).random((40, 128), dtype=np.float32)
    with pytest.raises(ValueError, match=r"`desc` must be 2-D"):
        matching.MatchIndex(a[0])
    index = matching.MatchIndex(a)
    with pytest.raises(ValueError, match=r"`ratio` must be in \(0, 1\], got 0"):
        index.query(a, ratio=0)
    with pytest.raises(ValueError, match=r"`desc_a` must be 2-D with width 128"):
        index.query(a[:, :64])
    assert index.query(a[:0]).shape == (0, 2)
    assert matching.MatchIndex(a[:0]).query(a).shape == (0, 2)
    # fewer than 32 train descriptors: brute force, still every point finds itself
    idx = matching.MatchIndex(a[:10]).query(a[:10], ratio=1.0)
    assert np.array_equal(np.sort(idx[:, 0]), np.arange(10)) and np.all(idx[:, 0] == idx[:, 1])


def test_min_long_side_reports_original_pixels(textured_image):
    """Detecting on a photo enlarged by ``min_long_side`` gives exactly the keypoints of the enlarged photo, moved
    back into the original pixels (centre convention x = (x' + 0.5) / s - 0.5, sizes divided by s)."""
    gray = cv2.cvtColor(textured_image, cv2.COLOR_BGR2GRAY) if textured_image.ndim == 3 else textured_image
    small = cv2.resize(gray, (gray.shape[1] // 2, gray.shape[0] // 2), interpolation=cv2.INTER_AREA)
    long_side = 2 * max(small.shape)
    f = features.detect(small, "sift", 2000, min_long_side=long_side)
    big = cv2.resize(small, (2 * small.shape[1], 2 * small.shape[0]), interpolation=cv2.INTER_CUBIC)
    g = features.detect(big, "sift", 2000)
    assert len(f) == len(g) > 100
    np.testing.assert_allclose(f.xy, (g.xy + 0.5) / 2 - 0.5, atol=1e-4)
    np.testing.assert_allclose(f.size, g.size / 2, rtol=1e-5)
    assert f.xy.min() >= -0.5 and (f.xy.max(axis=0) <= np.array(small.shape[::-1]) - 0.5).all()
    # an image already that long is left alone
    same = features.detect(small, "sift", 2000, min_long_side=max(small.shape))
    np.testing.assert_array_equal(same.xy, features.detect(small, "sift", 2000).xy)


def test_min_long_side_validated(textured_image):
    with pytest.raises(ValueError, match="`min_long_side` must be"):
        features.detect(np.zeros((20, 20), np.uint8), "sift", 100, min_long_side=-1)
