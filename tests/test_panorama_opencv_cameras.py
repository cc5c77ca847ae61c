"""The homographies that cv2.Stitcher's cameras imply (cvpipe.panorama.camera_homographies), on views with known
rotations.

A virtual camera (focal 1000 px, 640x480 views) turns about its vertical axis in front of a photo, so the true
homography between two views is ``Kv R_j R_i^-1 Kv^-1``, known exactly. cv2.Stitcher registers them at 0.25 MP, a
work scale of 0.902, so that a derivation that forgot the work scale (or its direction) would be far off.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cvpipe import panorama
from cvpipe.metrics import corner_error
from cvpipe.samples import photo

F, W, H = 1000.0, 640, 480
YAWS = (-0.2, 0.0, 0.2)


def _rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


@pytest.fixture(scope="module")
def views():
    """Three views and T[i] (photo pixels -> view i pixels); the photo (1482x1000) covers every view."""
    base = cv2.resize(photo("motorcycle"), (1482, 1000), interpolation=cv2.INTER_CUBIC)
    Kb = np.array([[F, 0, 740.5], [0, F, 499.5], [0, 0, 1]])
    Kv = np.array([[F, 0, (W - 1) / 2], [0, F, (H - 1) / 2], [0, 0, 1]])
    T = [Kv @ _rot_y(a) @ np.linalg.inv(Kb) for a in YAWS]
    return [cv2.warpPerspective(base, t, (W, H), flags=cv2.INTER_LINEAR) for t in T], T


def _max_error(G: dict, T: list) -> float:
    return max(corner_error(np.linalg.inv(G[j]) @ G[i], T[j] @ np.linalg.inv(T[i]), W, H)
               for i in range(3) for j in range(3) if i != j)


def test_camera_homographies_match_the_true_rotations(views):
    imgs, T = views
    r = panorama.opencv_stitch_cameras(imgs, 0.25, -1, 1.0, seed=0)
    assert r.status == "OK" and sorted(r.used) == [0, 1, 2]
    assert r.work_scale == pytest.approx(np.sqrt(0.25e6 / (W * H)))
    # cv2.Stitcher's own focal estimate is 1.1-1.4 % off at this resolution (1011-1014 px for 1000, seeds 0-2),
    # which alone moves the far corners of the 0 <-> 2 pair by about 2.5 px; 5 px leaves room for that and is far
    # below what a wrong derivation gives (next test: about 45 px without the work scale, 450 px reversed)
    assert _max_error(r.homographies, T) < 5.0


def test_a_derivation_without_the_work_scale_or_reversed_is_far_off(views):
    imgs, T = views
    r = panorama.opencv_stitch_cameras(imgs, 0.25, -1, 1.0, seed=0)
    st = cv2.Stitcher.create(cv2.Stitcher_PANORAMA)
    st.setRegistrationResol(0.25)
    cv2.setRNGSeed(0)
    assert st.stitch(imgs)[0] == cv2.Stitcher_OK
    cams = st.cameras()
    unscaled = panorama.camera_homographies([c.K() for c in cams], [c.R for c in cams], 1.0)
    assert _max_error(dict(zip(r.used, unscaled)), T) > 30.0
    reversed_ = {k: np.linalg.inv(G) for k, G in r.homographies.items()}
    assert _max_error(reversed_, T) > 100.0


def test_camera_homographies_exact_on_known_cameras():
    # cameras at work scale 0.5 built from the truth: the implied full-resolution homography equals
    # S^-1 K R_j^T R_i K^-1 S to rounding
    s = 0.5
    K = np.array([[F * s, 0, W * s / 2], [0, F * s, H * s / 2], [0, 0, 1]])
    R = [_rot_y(a) for a in YAWS]
    G = panorama.camera_homographies([K] * 3, R, s)
    S = np.array([[s, 0, 0.5 * s - 0.5], [0, s, 0.5 * s - 0.5], [0, 0, 1]])
    expected = np.linalg.inv(S) @ K @ R[2].T @ R[0] @ np.linalg.inv(K) @ S
    got = np.linalg.inv(G[2]) @ G[0]
    np.testing.assert_allclose(got / got[2, 2], expected / expected[2, 2], atol=1e-9)
