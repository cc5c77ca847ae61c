"""The fast preset (cvpipe.panorama.presets) and the Lucas-Kanade refinement of a pair (cvpipe.panorama.track), on
synthetic views with known homographies; the both-axes error measure of the benchmark."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cvpipe import panorama
from cvpipe.bench.panorama import pair_error_median
from cvpipe.commands import stitch as stitch_command
from cvpipe.metrics import corner_error
from cvpipe.params import PanoramaFeaturesParams, PanoramaMatchParams
from cvpipe.samples import fit, photo

from test_panorama import VIEW, _views


@pytest.fixture(scope="module")
def views():
    return _views()


def test_tracking_corrects_a_homography_a_few_pixels_off(views):
    imgs, T = views
    grays, sizes = panorama.working_images(imgs, -1)
    H_true = T[1] @ np.linalg.inv(T[0])
    off = np.array([[1.0, 0.004, 2.5], [-0.003, 1.0, -2.0], [0, 0, 1]]) @ H_true  # corners 2-4 px off
    assert corner_error(off, H_true, *VIEW) > 2.0
    H, src, dst, tracked = panorama.track_pair(grays[0], grays[1], off, panorama.corners(grays[0]), 10, rng=0)
    # the tracks are sub-pixel, but they lie in the 145 px wide overlap and the corner error is measured at the far
    # corners of the view, about 175 px beyond it, where the fit extrapolates: 0.43 px measured, 1 px leaves room
    assert corner_error(H, H_true, *VIEW) < 1.0
    assert len(src) == len(dst) >= 50 and tracked >= len(src)


def test_tracking_gives_up_without_enough_points(views):
    imgs, T = views
    grays, _ = panorama.working_images(imgs, -1)
    H_true = T[1] @ np.linalg.inv(T[0])
    assert panorama.track_pair(grays[0], grays[1], H_true, np.array([[100.0, 100.0]] * 5), 10) is None


def test_tracking_accepts_images_of_different_sizes(views):
    imgs, T = views
    grays, _ = panorama.working_images(imgs, -1)
    H_true = T[1] @ np.linalg.inv(T[0])
    small = grays[1][:200, :300]  # the same pixels, cropped at the right and bottom: coordinates unchanged
    H, _, _, _ = panorama.track_pair(grays[0], small, H_true, panorama.corners(grays[0]), 10, rng=0)
    # the crop leaves 70 of the 98 tracks in a smaller overlap, so the fit extrapolates further (1.54 px measured
    # against 0.43 px uncropped); a padding that moved the coordinates would be off by the crop, tens of pixels
    assert corner_error(H, H_true, *VIEW) < 2.5


def test_fast_preset_recovers_the_homographies(views):
    imgs, T = views
    pano = panorama.stitch(imgs, **panorama.preset_sections("fast"), rng=0)
    assert pano.registration.used == (0, 1, 2)
    G = pano.homographies
    err = {(i, j): corner_error(np.linalg.inv(G[j]) @ G[i], T[j] @ np.linalg.inv(T[i]), *VIEW)
           for i, j in ((0, 1), (1, 2), (0, 2))}
    # the same bounds as the default preset's test (test_panorama.test_recovered_homographies_match_truth):
    # overlapping neighbours within 1.5 px, views 0 and 2, which do not overlap (a product of two), within 4 px
    assert max(err[(0, 1)], err[(1, 2)]) < 1.5
    assert err[(0, 2)] < 4.0


def test_presets_are_declared_once():
    assert stitch_command.PRESET_CHOICES == panorama.PRESET_CHOICES
    assert stitch_command.DEFAULT_PRESET == panorama.DEFAULT_PRESET
    assert panorama.preset_sections()["features"] == PanoramaFeaturesParams()
    fast = panorama.preset_sections("fast", matching=PanoramaMatchParams(min_inliers=20))
    assert fast["matching"].min_inliers == 20 and fast["matching"].pair_refine == "lk"
    assert set(panorama.PAIR_REFINE_CHOICES) == set(
        __import__("typing").get_args(PanoramaMatchParams.model_fields["pair_refine"].annotation))


def test_preset_and_pair_refine_validation(views):
    imgs, _ = views
    with pytest.raises(ValueError, match="`preset` must be one of"):
        panorama.preset_sections("quick")
    with pytest.raises(ValueError, match="unknown sections"):
        panorama.preset_sections("fast", feature=PanoramaFeaturesParams())
    sizes, feats = panorama.features_of(imgs)
    with pytest.raises(ValueError, match="needs the images"):
        panorama.match_graph(feats, sizes, ratio=0.8, ransac_threshold=3.0, min_inliers=10, min_confidence=1.0,
                             pair_refine="lk")
    with pytest.raises(ValueError, match="`pair_refine` must be one of"):
        panorama.match_graph(feats, sizes, ratio=0.8, ransac_threshold=3.0, min_inliers=10, min_confidence=1.0,
                             pair_refine="ecc")


def test_pair_error_counts_a_left_out_image_as_a_failure():
    H = np.array([[1.0, 0, 10], [0, 1, 0], [0, 0, 1]])
    gt = {(0, 1): H, (1, 2): H, (0, 2): H @ H}
    sizes = [(100, 50)] * 3
    G = {0: np.eye(3), 1: np.linalg.inv(H), 2: np.linalg.inv(H @ H)}  # G_j^-1 G_i = H^(j-i): exact
    assert pair_error_median(G, gt, sizes) == pytest.approx(0.0, abs=1e-9)
    del G[2]  # two of three pairs fail: the median is a failure
    assert pair_error_median(G, gt, sizes) is None
    assert pair_error_median(G, {}, sizes) is None


def test_fast_preset_drops_an_unrelated_photo(views):
    # the tracks' own confidence test must not accept a pair that does not overlap: a photo of something else
    # shares no homography with the views, by matches or by tracks
    imgs, _ = views
    pano = panorama.stitch([*imgs, fit(photo("coffee"), *VIEW)], **panorama.preset_sections("fast"), rng=0)
    assert pano.registration.used == (0, 1, 2)
    assert [k for k, _ in pano.registration.dropped] == [3]


def test_stitch_cli_preset_and_overrides(tmp_path, views, monkeypatch, capsys):
    import cv2

    from cvpipe import cli
    from cvpipe.commands import stitch as command

    imgs, _ = views
    paths = []
    for k in range(3):
        p = tmp_path / f"v{k}.png"
        cv2.imwrite(str(p), imgs[k])
        paths.append(str(p))
    seen = []
    real = panorama.stitch
    monkeypatch.setattr(panorama, "stitch", lambda images, **kw: seen.append(kw) or real(images, **kw))
    out = str(tmp_path / "pano.png")
    assert cli.main(["stitch", *paths, "-o", out, "--preset", "fast", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["used"] == paths
    assert (seen[-1]["features"].detector, seen[-1]["matching"].pair_refine) == ("orb", "lk")
    # a flag given with the preset wins over it, the preset's other fields stay
    assert cli.main(["stitch", *paths, "-o", out, "--preset", "fast", "--detector", "sift", "--json"]) == 0
    capsys.readouterr()
    assert (seen[-1]["features"].detector, seen[-1]["features"].max_features,
            seen[-1]["matching"].pair_refine) == ("sift", 1500, "lk")
    assert command.PRESET_CHOICES == panorama.PRESET_CHOICES
