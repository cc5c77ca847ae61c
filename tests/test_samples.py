"""The sample data set: deterministic, complete, and its ground truth agrees with the pixels."""

import cv2
import numpy as np
import pytest

from cvpipe import geometry, samples


@pytest.fixture(scope="module")
def built():
    return samples.build_all(7, logo_scenes=10, logo_negatives=3)


def test_deterministic():
    a = samples.make_homography(np.random.default_rng(3))
    b = samples.make_homography(np.random.default_rng(3))
    assert all(np.array_equal(a.images[k], b.images[k]) for k in a.images)
    assert a.truth == b.truth


def test_logo_truth(built):
    logo = built["logo"]
    assert sum(k.startswith("gallery/") for k in logo.images) == 10
    scenes = logo.truth["scenes"]
    assert len(scenes) == 13 and sum(s["brand"] is None for s in scenes) == 3
    for s in scenes:
        img = logo.images[f"scenes/{s['file']}"]
        if s["brand"] is None:
            assert s["quad"] is None
            continue
        quad = np.array(s["quad"])
        assert cv2.contourArea(quad.astype(np.float32)) > 60 * 60  # a visible mark, at least 60x60 px
        assert np.all((quad >= 0) & (quad < [img.shape[1], img.shape[0]]))  # fully inside the scene
        # the card is white: the pixels just inside the quad's corners are bright
        c = quad.mean(0)
        for q in quad:
            x, y = (q + 0.08 * (c - q)).round().astype(int)
            assert img[y, x].mean() > 150


def test_hough_truth_lies_on_drawn_pixels(built):
    for item in built["hough"].truth["images"]:
        # a rasterised line strays up to 0.5 px from the true line and our sample rounding another 0.5 px, so
        # look for the paint within 1 px (3x3 dilation)
        img = cv2.dilate(built["hough"].images[item["file"]].min(axis=2), np.ones((3, 3), np.uint8))
        h, w = img.shape[:2]
        for rho, theta in item["lines"]:
            t = np.linspace(-2 * max(h, w), 2 * max(h, w), 8000)
            x = rho * np.cos(theta) - t * np.sin(theta)
            y = rho * np.sin(theta) + t * np.cos(theta)
            inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
            px = img[y[inside].round().astype(int), x[inside].round().astype(int)]
            # the line was painted white: >= 99 % of points along it have white paint within 1 px
            assert np.mean(px >= 250) >= 0.99


def test_homography_truth_aligns_views(built):
    hs = built["homography"]
    for p in hs.truth["pairs"]:
        a = cv2.cvtColor(hs.images[p["a"]], cv2.COLOR_BGR2GRAY).astype(np.float32)
        b = cv2.cvtColor(hs.images[p["b"]], cv2.COLOR_BGR2GRAY).astype(np.float32)
        H = np.array(p["H"])
        warped = cv2.warpPerspective(a, H, (b.shape[1], b.shape[0]))
        valid = cv2.warpPerspective(np.ones_like(a), H, (b.shape[1], b.shape[0]), flags=cv2.INTER_NEAREST) > 0
        valid = cv2.erode(valid.astype(np.uint8), np.ones((15, 15))) > 0
        assert valid.mean() > 0.2  # the views overlap substantially
        # aligned by the true H, the views correlate strongly (lighting/noise differ, geometry does not)
        r = np.corrcoef(warped[valid], b[valid])[0, 1]
        assert r > 0.85


def test_defect_truth(built):
    d = built["defect"]
    probes = d.truth["probes"]
    assert len(probes) >= 10
    assert {p["verdict"] for p in probes} == {"faulty", "perfect"}
    for p in probes:
        assert (len(p["boxes"]) > 0) == (p["verdict"] == "faulty")
        for x1, y1, x2, y2 in p["boxes"]:
            assert 0 <= x1 < x2 <= 480 and 0 <= y1 < y2 <= 480


def test_stereo_truth(built):
    s = built["stereo"]
    disp = s.arrays["motorcycle/truth.npz"]["disparity"]
    assert disp.shape == s.images["motorcycle/left.png"].shape[:2] == s.images["motorcycle/right.png"].shape[:2]
    truth = s.docs["motorcycle/truth.json"]
    assert np.nanmax(disp) < truth["max_disp"] and truth["max_disp"] % 16 == 0
    assert 0.5 < np.isfinite(disp).mean() < 1.0
    assert not s.truth  # one folder per pair: no truth.json for the stereo folder itself


def test_stereo_unrectified_sample(built):
    """The unrectified pair: its calib.txt parses for the image size, and the true correspondences carried by
    H_unrectify are off the same row (so the pipeline must rectify it) by up to the drawn shift and rotation."""
    from cvpipe.stereo import calibration

    s = built["stereo"]
    calib = calibration.parse_calibration(s.texts["motorcycle_unrectified/calib.txt"], "calib.txt")
    img = s.images["motorcycle_unrectified/right.png"]
    calib.check_size((img.shape[1], img.shape[0]))
    arrays = s.arrays["motorcycle_unrectified/truth.npz"]
    disp = arrays["disparity"]
    ys, xs = np.nonzero(np.isfinite(disp))
    right = geometry.apply_homography(arrays["H_unrectify"], np.column_stack([xs - disp[ys, xs], ys]).astype(float))
    dy = np.abs(right[:, 1] - ys)
    assert np.median(dy) > 1.0  # clearly not rectified (a rectified pair has dy = 0)


def test_panorama_truth_chains(built):
    pano = built["panorama"]
    assert len(pano.truth["sets"]) >= 2
    for s in pano.truth["sets"]:
        assert len(s["images"]) >= 3
        assert np.allclose(np.array(s["H"][0]), np.eye(3), atol=1e-9)
        first = cv2.cvtColor(pano.images[s["images"][0]], cv2.COLOR_BGR2GRAY).astype(np.float32)
        second = cv2.cvtColor(pano.images[s["images"][1]], cv2.COLOR_BGR2GRAY).astype(np.float32)
        H = np.array(s["H"][1])
        warped = cv2.warpPerspective(second, H, (first.shape[1], first.shape[0]))
        valid = cv2.warpPerspective(np.ones_like(second), H, (first.shape[1], first.shape[0])) > 0.999
        valid = cv2.erode(valid.astype(np.uint8), np.ones((9, 9))) > 0
        assert valid.mean() > 0.1  # neighbouring views overlap
        assert np.corrcoef(warped[valid], first[valid])[0, 1] > 0.85
