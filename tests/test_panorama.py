"""cvpipe.panorama (its steps: features, match, register, refine, warp, seams, blend, crop) and `cvpipe stitch` on
synthetic views with known homographies.

The views are taken by a virtual camera (focal 500 px) turning about its vertical axis in front of a photo, so the
true homography between any two views is known exactly and is a pure rotation (which the cylindrical and
spherical projections also need).
"""

from __future__ import annotations

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest

import importlib

from cvpipe import cli, panorama
from cvpipe.geometry import apply_homography
from cvpipe.errors import EstimationError, InputError
from cvpipe.params import (PanoramaBlendParams, PanoramaFeaturesParams, PanoramaHomographiesParams,
                           PanoramaMatchParams, PanoramaWarpParams)
from cvpipe.samples import fit, photo

F = 500.0
VIEW = (320, 240)
YAWS = (-0.35, 0.0, 0.35)


def _rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _views(yaws=YAWS, gains=None):
    """Views of a photo (840x360, treated as the picture of a camera with focal F) after turning by ``yaws``.

    Returns the BGR views and T[i] (photo pixels -> view i pixels)."""
    base = fit(photo("astronaut"), 840, 360)
    Kb = np.array([[F, 0, 419.5], [0, F, 179.5], [0, 0, 1]])
    Kv = np.array([[F, 0, (VIEW[0] - 1) / 2], [0, F, (VIEW[1] - 1) / 2], [0, 0, 1]])
    views, T = [], []
    for k, a in enumerate(yaws):
        Ti = Kv @ _rot_y(a) @ np.linalg.inv(Kb)
        v = cv2.warpPerspective(base, Ti, VIEW, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        if gains is not None:
            v = np.clip(v.astype(np.float32) * gains[k], 0, 255).astype(np.uint8)
        views.append(v)
        T.append(Ti)
    return views, T


def _corner_error(H: np.ndarray, H_true: np.ndarray, size=VIEW) -> float:
    w, h = size
    c = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], float)
    return float(np.linalg.norm(apply_homography(H, c) - apply_homography(H_true, c), axis=1).mean())


@pytest.fixture(scope="module")
def views():
    return _views()


@pytest.fixture(scope="module")
def distractor():
    return fit(photo("coffee"), *VIEW)


def _pairwise_errors(pano: panorama.Panorama, T, order):
    """Corner error of every recovered pair homography (view a -> view b) against the truth."""
    errs = []
    for a in pano.homographies:
        for b in pano.homographies:
            if a != b:
                H = np.linalg.inv(pano.homographies[b]) @ pano.homographies[a]
                errs.append(_corner_error(H, T[order[b]] @ np.linalg.inv(T[order[a]])))
    return errs


def test_recovered_homographies_match_truth(views):
    imgs, T = views
    pano = panorama.stitch(imgs, rng=0)
    assert pano.registration.used == (0, 1, 2) and pano.registration.dropped == ()
    assert pano.registration.model == "homography"
    errs = _pairwise_errors(pano, T, [0, 1, 2])  # pairs (0,1) (0,2) (1,0) (1,2) (2,0) (2,1)
    # overlapping neighbours: sub-pixel keypoints, corners extrapolated up to half a view away -> within 1.5 px
    assert max(errs[0], errs[2], errs[3], errs[5]) < 1.5
    # views 0 and 2 do not overlap: their homography is the product of two, 8 free parameters each -> within 4 px
    assert max(errs[1], errs[4]) < 4.0
    # the middle view overlaps both others: the maximum spanning tree is centred on it
    assert pano.registration.reference == 1


def test_rotation_model_extrapolates_across_views(views):
    imgs, T = views
    pano = panorama.stitch(imgs, homographies=PanoramaHomographiesParams(refine="auto"), rng=0)
    # the views really come from a turning camera: auto keeps the 3-parameter rotation model, which pins down
    # even the pair that does not overlap to well under a pixel
    assert pano.registration.model == "rotation"
    assert max(_pairwise_errors(pano, T, [0, 1, 2])) < 1.0
    assert pano.registration.focal == pytest.approx(F, rel=0.01)


@pytest.mark.parametrize("order", [(2, 0, 1), (1, 2, 0)])
def test_input_order_does_not_matter(views, order):
    imgs, T = views
    pano = panorama.stitch([imgs[k] for k in order], rng=0)
    assert pano.registration.used == (0, 1, 2)
    assert max(_pairwise_errors(pano, T, list(order))) < 4.0  # as above, for every pair
    assert order[pano.registration.reference] == 1


def test_distractor_is_dropped_with_reason(views, distractor):
    imgs, T = views
    pano = panorama.stitch([imgs[0], distractor, imgs[1], imgs[2]], rng=0)
    assert pano.registration.used == (0, 2, 3)
    (k, why), = pano.registration.dropped
    assert k == 1 and ("shares no accepted pair" in why or "no feature matches" in why)


def test_cropped_panorama_has_no_empty_pixels(views):
    # no input pixel is darker than 32, so a black output pixel can only be an empty one (multi-band blending can
    # undershoot a dark pixel by a few grey levels near a seam: inputs clamped at 1 gave 0 on one seam's staircase)
    imgs = [np.maximum(v, 32) for v in views[0]]
    for projection in ("plane", "cylindrical", "spherical"):
        pano = panorama.stitch(imgs, warp=PanoramaWarpParams(projection=projection), rng=0)
        assert pano.mask.all(), projection
        # three 320-wide views turned by 20 degrees: the crop keeps well over one view's width
        assert pano.image.shape[1] > 1.5 * VIEW[0] and pano.image.shape[0] > 0.7 * VIEW[1], projection
        assert not (pano.image == 0).all(axis=2).any(), projection


def test_focal_is_estimated_from_the_homographies(views):
    imgs, _ = views
    grays, sizes = panorama.working_images(imgs, 0.6)
    feats = panorama.detect_all(grays, "sift", 1500)
    graph = panorama.match_graph(feats, sizes, ratio=0.8, ransac_threshold=3.0, min_inliers=10, min_confidence=1.0,
                                 rng=0)
    # Szeliski-Shum from estimated homographies: a few percent (the yaw-only motion is the weakly conditioned case)
    assert panorama.estimate_focal(graph.edges, sizes) == pytest.approx(F, rel=0.05)
    reg = panorama.register(graph, refine="rotation", max_points_per_pair=200, rng=0)
    assert reg.model == "rotation" and reg.focal == pytest.approx(F, rel=0.01)


def test_estimate_focal_exact_on_synthetic_homographies():
    K = np.array([[800.0, 0, 319.5], [0, 800.0, 239.5], [0, 0, 1]])
    R = cv2.Rodrigues(np.array([0.05, 0.3, 0.02]))[0]
    edge = panorama.Edge(0, 1, K @ R @ np.linalg.inv(K), None, None, 1.0)
    assert panorama.estimate_focal({(0, 1): edge}, [(640, 480), (640, 480)]) == pytest.approx(800.0, rel=1e-6)


def test_match_graph_and_registration_round_trip(views):
    imgs, _ = views
    grays, sizes = panorama.working_images(imgs, 0.6)
    graph = panorama.match_graph(panorama.detect_all(grays, "sift", 800), sizes, ratio=0.8, ransac_threshold=3.0,
                                 min_inliers=10, min_confidence=1.0, rng=0)
    back = panorama.MatchGraph.from_arrays(graph.to_arrays())
    assert set(back.edges) == set(graph.edges) and back.rejected == graph.rejected
    reg = panorama.register(back, refine="homography", max_points_per_pair=100, rng=0)
    again = panorama.Registration.from_json(json.loads(json.dumps(reg.to_json(), default=np.ndarray.tolist)))
    assert again.used == reg.used and all(np.allclose(again.G[a], reg.G[a]) for a in reg.used)


def _two_constant(v0: float, v1: float) -> panorama.warp.Warped:
    """Two 120x200 constant images overlapping over 80 columns of a 320-wide canvas."""
    imgs = [np.full((120, 200, 3), v0, np.uint8), np.full((120, 200, 3), v1, np.uint8)]
    masks = [np.full((120, 200), 255, np.uint8), np.full((120, 200), 255, np.uint8)]
    return panorama.warp.Warped(imgs, masks, [(0, 0), (120, 0)], (320, 120), (0, 0))


@pytest.mark.parametrize("blender", ["multiband", "feather"])
def test_blending_is_seamless_on_constant_brightness(blender):
    w = _two_constant(137, 137)
    pano, mask, seams = panorama.compose(w, blender, 5, gain="gain")
    assert mask.all() and seams[:, 150:170].any()  # the seam runs through the overlap
    # no step at the seam and no dark halo at the borders: every pixel keeps the constant within rounding
    assert np.abs(pano.astype(int) - 137).max() <= 1


def _border_distance(x0: int, width: int, height: int, canvas=(320, 120)) -> np.ndarray:
    """Distance of every canvas pixel to the border of a ``width`` x ``height`` box at column ``x0`` (0 outside):
    one more than the pixels between it and the nearest edge, as a distance to the first pixel past the box."""
    r = np.arange(canvas[1])[:, None]
    c = np.arange(canvas[0])[None, :] - x0
    d = np.minimum(np.minimum(c + 1, width - c), np.minimum(r + 1, height - r)).astype(np.float64)
    return np.where((c >= 0) & (c < width), d, 0.0)


def test_feather_is_the_distance_weighted_mean_and_gains_shrink_the_seam_step():
    w = _two_constant(90, 150)
    d0, d1 = _border_distance(0, 200, 120), _border_distance(120, 200, 120)
    # the boxes are rectangles, so a chamfer distance (OpenCV's 3x3 L2 mask) is the straight-line count scaled by
    # one constant: the weights' ratio, hence the mean, equals the one of these exact distances
    panos = {}
    for gain, g in (("none", np.ones(2)), ("gain", panorama.gain_compensation(w))):
        panos[gain], _, _ = panorama.compose(w, "feather", 5, gain=gain)
        expected = (d0 * 90 * g[0] + d1 * 150 * g[1]) / (d0 + d1)
        # rounding to uint8 leaves at most half a grey level, plus float32 arithmetic (~1e-4 at 255)
        err = np.abs(panos[gain].astype(np.float64) - expected[..., None]).max()
        assert err <= 0.501, (gain, err)
    plain, gained = panos["none"], panos["gain"]
    # every overlap pixel is a different mix: column 150 of row 60 is 31 px into image 1 and 50 px from image 0's
    # right edge, (50 * 90 + 31 * 150) / 81 = 112.96, not the plain average 120
    assert plain[60, 150, 0] == 113
    # the step between the pixels just outside the overlap (one image each) is 60 grey levels without the gains;
    # with them it is |g1 * 150 - g0 * 90|, about 15 (sigma_n = 10 against sigma_g = 0.1 balance there): under a
    # third of it
    assert int(plain[60, 200, 0]) - int(plain[60, 119, 0]) == 60
    assert abs(int(gained[60, 200, 0]) - int(gained[60, 119, 0])) < 20


def test_gain_compensation_equalises_an_exposure_step():
    w = _two_constant(100, 130)
    gains = panorama.gain_compensation(w)
    # sigma_n = 10 pulls the overlap means together while sigma_g = 0.1 keeps gains near 1; with equal overlap and
    # prior weights the two balance at a step of about 8 grey levels (the same objective as OpenCV's GainCompensator)
    assert 1.0 < gains[0] < 1.15 and 0.85 < gains[1] < 1.0
    assert abs(gains[0] * 100 - gains[1] * 130) < 10.0
    assert panorama.overlap_difference(w, gains) < 10.0 < 29.0 < panorama.overlap_difference(w)
    pano, _, _ = panorama.compose(w, "multiband", 5, gain="gain")
    # the remaining step is spread over the blend band: at most 2 grey levels between neighbours
    assert np.abs(np.diff(pano[60, :, 1].astype(int))).max() <= 2


def test_multiband_hides_a_step_that_a_hard_seam_shows():
    w = _two_constant(90, 150)
    labels = panorama.seam_labels(w)
    pano = panorama.blend_multiband(w, labels, bands=5)
    # a hard cut would jump by 60 grey levels between neighbours; five bands spread it over ~2^5 pixels
    assert np.abs(np.diff(pano[60, :, 0].astype(int))).max() <= 8


def test_largest_rectangle_matches_brute_force():
    rng = np.random.default_rng(3)
    for _ in range(20):
        mask = rng.random((9, 11)) > 0.25
        best = 0
        for y0 in range(9):
            for y1 in range(y0 + 1, 10):
                for x0 in range(11):
                    for x1 in range(x0 + 1, 12):
                        if mask[y0:y1, x0:x1].all():
                            best = max(best, (y1 - y0) * (x1 - x0))
        x, y, w, h = panorama.largest_rectangle(mask)
        assert w * h == best and mask[y:y + h, x:x + w].all()
    assert panorama.largest_rectangle(np.zeros((4, 4), bool)) == (0, 0, 0, 0)


def test_plane_projection_refuses_views_beyond_180_degrees():
    K = np.array([[100.0, 0, 99.5], [0, 100.0, 74.5], [0, 0, 1]])
    G = [np.eye(3), panorama.normalize_det(K @ _rot_y(1.7) @ np.linalg.inv(K))]
    imgs = [np.zeros((150, 200, 3), np.uint8)] * 2
    with pytest.raises(EstimationError, match="cannot hold; use projection cylindrical or spherical"):
        panorama.warp.warp_images(imgs, G, "plane", 100.0, (200, 150), 100.0)
    w = panorama.warp.warp_images(imgs, G, "cylindrical", 100.0, (200, 150), 100.0)
    assert w.size[0] > 300


def test_stitch_cli_json(tmp_path, views, capsys):
    imgs, _ = views
    paths = []
    for k in (2, 0, 1):
        p = tmp_path / f"v{k}.png"
        cv2.imwrite(str(p), imgs[k])
        paths.append(str(p))
    bad = tmp_path / "broken.jpg"
    bad.write_bytes(b"not an image")
    out = tmp_path / "pano.png"
    assert cli.main(["stitch", *paths, str(bad), "-o", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["used"] == paths and res["dropped"][0]["image"] == str(bad)
    assert "unreadable" in res["dropped"][0]["reason"]
    pano = cv2.imread(str(out))
    assert [pano.shape[1], pano.shape[0]] == res["size"]
    # the reported homography of the reference view (input position 2, "v1.png") maps its centre into the panorama where
    # the panorama shows that same pixel
    H = np.array(res["homographies"][2])
    x, y = apply_homography(H, np.array([[160.0, 120.0]]))[0]
    patch = pano[int(round(y)) - 10:int(round(y)) + 10, int(round(x)) - 10:int(round(x)) + 10].astype(int)
    assert np.abs(patch - imgs[1][110:130, 150:170].astype(int)).mean() < 6


def test_stitch_cli_errors(tmp_path, views, distractor, capsys):
    imgs, _ = views
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    cv2.imwrite(str(a), imgs[0])
    cv2.imwrite(str(b), distractor)
    assert cli.main(["stitch", str(a), "-o", str(tmp_path / "p.png")]) == 2
    assert "at least two readable images, got 1" in capsys.readouterr().err
    assert cli.main(["stitch", str(a), str(b), "-o", str(tmp_path / "p.png")]) == 1
    assert "no two images share enough features" in capsys.readouterr().err


def test_validation_errors(views):
    imgs, _ = views
    with pytest.raises(InputError, match="at least two images, got 1"):
        panorama.stitch(imgs[:1])
    with pytest.raises(InputError, match=r"image 1 must be \(H, W\) or \(H, W, 3\) uint8"):
        panorama.stitch([imgs[0], imgs[1].astype(np.float32)])
    with pytest.raises(InputError, match="image 0 is 8x8, expected at least 16x16"):
        panorama.stitch([np.zeros((8, 8), np.uint8), imgs[1]])
    with pytest.raises(ValueError, match="`projection` must be one of"):
        PanoramaWarpParams(projection="fisheye")
    with pytest.raises(ValueError, match="`projection` must be one of"):
        panorama.warp.check_projection("fisheye")
    with pytest.raises(ValueError, match="`blender` must be one of"):
        PanoramaBlendParams(blender="average")
    with pytest.raises(ValueError, match="`blender` must be one of"):
        panorama.compose(_two_constant(1, 1), "average", 5, True)
    with pytest.raises(ValueError, match=r"`bands` must be in \[1, 12\]"):
        PanoramaBlendParams(bands=0)
    with pytest.raises(ValueError, match=r"`bands` must be an integer in \[1, 12\]"):
        panorama.blend_multiband(_two_constant(1, 1), np.zeros((120, 320), np.int16), 13)
    with pytest.raises(ValueError, match="`refine` must be one of"):
        PanoramaHomographiesParams(refine="bundle")
    with pytest.raises(ValueError, match=r"`ratio` must be in \(0.0, 1.0\]"):
        PanoramaMatchParams(ratio=1.5)
    with pytest.raises(ValueError, match=r"`candidates` must be in \[0, 2147483647\]"):
        PanoramaMatchParams(candidates=-1)
    with pytest.raises(ValueError, match=r"`min_inliers` must be in \[4, 2147483647\]"):
        PanoramaMatchParams(min_inliers=3)
    with pytest.raises(ValueError, match=r"`refit_threshold` must be in \[0.0, 3.0\], got 4.0"):
        PanoramaMatchParams(refit_threshold=4.0)
    with pytest.raises(ValueError, match=r"`refit_threshold` must be in \[0.0, 3.0\], got -1.0"):
        PanoramaMatchParams(refit_threshold=-1.0)
    with pytest.raises(ValueError, match=r"`max_points_per_pair` must be in \[4, 2147483647\]"):
        PanoramaHomographiesParams(max_points_per_pair=2)
    with pytest.raises(ValueError, match=r"`max_canvas_megapix` must be in \(0.0, inf\)"):
        PanoramaWarpParams(max_canvas_megapix=0)
    with pytest.raises(ValueError, match=r"`max_features` must be in \[1, 1000000\]"):
        PanoramaFeaturesParams(max_features=0)
    with pytest.raises(ValueError, match="`mask` must be 2-D"):
        panorama.largest_rectangle(np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="`focal` must be positive"):
        panorama.warp.warp_images(imgs, [np.eye(3)] * 3, "cylindrical", 0.0, VIEW, 10.0)
    with pytest.raises(EstimationError, match="canvas would be .* max_canvas_megapix"):
        panorama.warp.warp_images(imgs, [np.eye(3)] * 3, "plane", 1.0, VIEW, 0.01)
    graph = panorama.MatchGraph([VIEW, VIEW], np.zeros((2, 2), int), np.zeros((2, 2), int), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="`refine` must be one of"):
        panorama.register(graph, refine="bundle", max_points_per_pair=10)
    with pytest.raises(EstimationError, match="no two images share enough features"):
        panorama.register(graph, refine="none", max_points_per_pair=10)


def test_gains_lower_the_ghosting_measure_on_real_views():
    imgs, _ = _views(gains=(1.0, 1.25, 0.85))
    pano = panorama.stitch(imgs, rng=0)
    assert pano.mask.all()
    comp = panorama.compose_inputs(imgs, pano.registration, [(i.shape[1], i.shape[0]) for i in imgs], -1)
    w = panorama.warp.warp_images(comp.images, comp.G, "plane", comp.focal, comp.ref_size, 10.0)
    # exposure differences dominate the raw overlap difference; gain compensation removes most of it
    assert panorama.overlap_difference(w, panorama.gain_compensation(w)) < 0.5 * panorama.overlap_difference(w)


def _graph(imgs, candidates):
    grays, sizes = panorama.working_images(imgs, 0.6)
    feats = panorama.detect_all(grays, "sift", 1500)
    return panorama.match_graph(feats, sizes, ratio=0.8, ransac_threshold=3.0, min_inliers=10, min_confidence=1.0,
                                candidates=candidates, rng=0)


def test_candidate_prefilter_skips_pairs_but_keeps_the_edges(views):
    imgs, _ = views
    graph = _graph(imgs, candidates=1)
    # each view's single best partner is a neighbour: the two real overlaps are matched, the far pair is skipped
    assert set(graph.edges) == {(0, 1), (1, 2)}
    assert graph.rejected[(0, 2)].startswith("not a candidate pair")
    assert graph.matches[0, 2] == 0


def test_connectivity_repair_matches_skipped_bridges(views, monkeypatch):
    imgs, _ = views
    # a prefilter that misses the link to view 2: the repair must match a skipped pair joining the two groups
    monkeypatch.setattr(importlib.import_module("cvpipe.panorama.match"), "candidate_pairs", lambda feats, ratio, c: ([(0, 1)], {(0, 2): 9, (1, 2): 3}))
    graph = _graph(imgs, candidates=1)
    assert (1, 2) in graph.edges and (0, 1) in graph.edges
    assert panorama.register(graph, refine="none", max_points_per_pair=50).used == (0, 1, 2)


def test_real_weir_set_drops_the_distractor(data_root):
    from cvpipe import io

    folder = data_root / "stitching_tutorial" / "imgs"
    if not (folder / "weir_noise.jpg").exists():
        pytest.skip("stitching_tutorial not in the data root")
    names = ["weir_2.jpg", "weir_noise.jpg", "weir_3.jpg", "weir_1.jpg"]
    imgs = [io.read_image(folder / n) for n in names]
    pano = panorama.stitch(imgs, warp=PanoramaWarpParams(projection="spherical", compose_megapix=0.2), rng=0)
    # the three weir views overlap; the tutorial's noise picture shares nothing with them
    assert pano.registration.used == (0, 2, 3)
    (k, why), = pano.registration.dropped
    assert names[k] == "weir_noise.jpg" and "shares no accepted pair" in why
    assert pano.mask.all() and pano.image.shape[1] > 2 * pano.image.shape[0]
