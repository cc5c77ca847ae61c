"""Simulated views of a reference (ASIFT-style tilts): the affine map, keypoints carried back to reference pixels,
the logo gallery's views and their round trip through a features stage's arrays."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cvpipe import logo, views
from cvpipe.features import Features, detect
from cvpipe.geometry import apply_homography, image_corners
from cvpipe.params import LogoFeaturesParams
from cvpipe.samples import fit, paste, photo

from test_logos import _mark


@pytest.mark.parametrize("size, tilt, longitude", [((200, 100), 2.0, 0.0), ((200, 100), 2.0, 90.0),
                                                   ((150, 90), 1.5, 30.0), ((64, 200), 3.0, 135.0)])
def test_view_transform_keeps_the_image_inside_the_view_and_shrinks_one_direction_by_the_tilt(size, tilt, longitude):
    M, (w, h) = views.view_transform(size, tilt, longitude)
    corners = image_corners(*size) @ M[:, :2].T + M[:, 2]
    # the corners' pixel centres fall in the view's pixels (the last one may hold only a part of a pixel)
    assert corners.min() > -1e-9 and corners[:, 0].max() < w and corners[:, 1].max() < h
    assert max(w, h) <= max(size) * 1.5  # no more than the rotated image needs
    # a rotation followed by x / tilt: singular values 1 and 1 / tilt
    np.testing.assert_allclose(np.linalg.svd(M[:, :2], compute_uv=False), [1.0, 1.0 / tilt], atol=1e-12)


def test_keypoint_pose_is_carried_back_through_the_inverse_map():
    M, _ = views.view_transform((200, 100), 2.0, 0.0)  # x halved
    f = Features(np.array([[50.0, 40.0], [10.0, 10.0], [30.0, 20.0]], np.float32), np.full(3, 4.0, np.float32),
                 np.array([0.0, 90.0, 45.0], np.float32), np.ones(3, np.float32), np.zeros((3, 128), np.float32),
                 "sift")
    back = views.features_to_reference(f, M, (200, 100))
    np.testing.assert_allclose(back.xy, [[100, 40], [20, 10], [60, 20]], atol=1e-5)
    # a direction (1, 1) in the view is (2, 1) in the reference: 26.57 degrees; the axes keep theirs
    np.testing.assert_allclose(back.angle, [0.0, 90.0, np.degrees(np.arctan2(1, 2))], atol=1e-4)
    np.testing.assert_allclose(back.size, 4.0 * np.sqrt(2.0), rtol=1e-6)  # sqrt(det) of the inverse: area x 2


def test_keypoints_outside_the_reference_are_dropped():
    M, _ = views.view_transform((100, 100), 2.0, 0.0)
    f = Features(np.array([[60.0, 10.0], [10.0, 10.0]], np.float32), np.ones(2, np.float32), np.zeros(2, np.float32),
                 np.ones(2, np.float32), np.zeros((2, 128), np.float32), "sift")
    np.testing.assert_allclose(views.features_to_reference(f, M, (100, 100)).xy, [[20, 10]])


@pytest.mark.parametrize("tilt, longitude", [(2.0, 0.0), (2.0, 90.0), (2.0, 45.0)])
def test_blobs_found_in_a_view_land_on_their_centres_in_the_reference(tilt, longitude):
    rng = np.random.default_rng(3)
    centres = np.array([(x, y) for y in range(30, 200, 40) for x in range(30, 260, 40)], np.float64)
    centres += rng.uniform(-5, 5, centres.shape)
    yy, xx = np.mgrid[0:230, 0:290]
    img = np.zeros(yy.shape)
    for cx, cy in centres:
        img += np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * 4.0 ** 2))
    gray = np.clip(40 + 200 * img, 0, 255).astype(np.uint8)
    view, view_mask, M = views.tilted_view(gray, tilt, longitude)
    back = views.features_to_reference(detect(view, "sift", 500, view_mask), M, (290, 230))
    nearest = np.linalg.norm(centres[:, None, :] - back.xy[None], axis=2).min(axis=1)
    # a blob of sigma 4 px is about 4 / tilt view pixels across the shrunk direction: SIFT locates its centre to a
    # fraction of a view pixel, which is at most `tilt` = 2 reference pixels. Measured: 0.5-0.6 px for every blob
    # (0.3 px on the image itself); between the blobs SIFT also finds the dark gaps, which are not counted here
    assert (nearest < 1.5).mean() > 0.9, f"{(nearest < 1.5).sum()} of {len(centres)} blobs found"
    assert np.median(nearest) < 1.0


def test_a_bad_tilt_is_refused_naming_it():
    with pytest.raises(ValueError, match="`tilt`"):
        views.view_transform((100, 100), 0.5, 0.0)
    with pytest.raises(ValueError, match="`longitude`"):
        views.view_transform((100, 100), 2.0, float("nan"))


def test_sift_references_get_the_views_and_other_detectors_none():
    gray = cv2.cvtColor(_mark(0), cv2.COLOR_BGR2GRAY)
    sift = logo.reference_views("brand0", "brand0.png", gray, "sift", 1000)
    assert [r.name for r in sift] == ["brand0.png"] + [views.view_name("brand0.png", t, p)
                                                       for t, p in views.REFERENCE_TILTS["sift"]]
    assert all(r.size == (200, 200) and len(r.features) >= 8 for r in sift)
    assert [r.name for r in logo.reference_views("brand0", "brand0.png", gray, "akaze", 1000)] == ["brand0.png"]
    # a view with too few keypoints is left out; the reference itself stays for build_gallery to judge
    blank = np.full((80, 80), 128, np.uint8)
    assert [r.name for r in logo.reference_views("b", "blank.png", blank, "sift", 100, min_features=8)] == ["blank.png"]


@pytest.fixture(scope="module")
def slanted_galleries():
    marks = {f"brand{i}": _mark(i) for i in range(3)}
    out = {}
    for kind, tilts in (("views", None), ("plain", ())):
        out[kind] = logo.build_gallery([r for b, m in marks.items() for r in logo.reference_views(
            b, f"{b}.png", cv2.cvtColor(m, cv2.COLOR_BGR2GRAY), "sift", 1000, tilts=tilts)])
    return marks, out


@pytest.mark.parametrize("brand", ["brand0", "brand1", "brand2"])
def test_a_mark_seen_at_a_slant_is_found_through_a_view(slanted_galleries, brand):
    marks, galleries = slanted_galleries
    # the card turned about its vertical axis until it is a third as wide as high (70 degrees from frontal)
    H = cv2.getPerspectiveTransform(image_corners(200, 200).astype(np.float32),
                                    np.float32([[280, 120], [340, 135], [340, 285], [280, 300]])).astype(np.float64)
    scene = detect(cv2.cvtColor(paste(fit(photo("coffee"), 640, 480), marks[brand], H), cv2.COLOR_BGR2GRAY), "sift")
    det = logo.recognize(galleries["views"], scene, (640, 480), rng=0)
    assert det.brand == brand
    assert galleries["views"].references[det.best.reference].name != f"{brand}.png"  # found through a view
    # corners within 3 px on average (measured 0.8-2.3): under 2 % of the card's 180 px height
    assert logo.quad_error(det.quad, apply_homography(H, image_corners(200, 200))) < 3.0
    # the frontal references alone find no plausible fit there
    assert logo.recognize(galleries["plain"], scene, (640, 480), rng=0).brand is None


def test_a_stage_record_splits_back_into_the_same_views():
    gray = cv2.cvtColor(_mark(2), cv2.COLOR_BGR2GRAY)
    p = LogoFeaturesParams(detector="sift", max_features=600)
    arrays, _ = views.detect_views_item((gray, False), p)
    got = views.split_views(arrays)
    want = views.detect_views(gray, "sift", 600)
    assert [v for v, _ in got] == [v for v, _ in want]
    for (_, a), (_, b) in zip(got, want):
        np.testing.assert_array_equal(a.xy, b.xy)
        np.testing.assert_array_equal(a.descriptors, b.descriptors)
    # a scene photo is stored as before: its own features, no views
    scene, _ = views.detect_views_item((gray, True), p)
    assert "view" not in scene and [v for v, _ in views.split_views(scene)] == [None]
