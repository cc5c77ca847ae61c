"""Logo recall: the plausibility checks on synthetic correspondences with a known homography, and the fused method
(several detectors under one a-contrario decision)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cvpipe import logo
from cvpipe.features import Features, detect
from cvpipe.params import LogoVerifyParams

REF_W, REF_H = 400, 300
SCENE = (1000, 800)


def _reference(xy: np.ndarray, angle: np.ndarray, size: np.ndarray) -> logo.Reference:
    n = len(xy)
    f = Features(xy.astype(np.float32), size.astype(np.float32), angle.astype(np.float32), np.ones(n, np.float32),
                 np.zeros((n, 128), np.float32), "sift")
    return logo.Reference("mark", "mark.png", f, (REF_W, REF_H))


def _scene(xy: np.ndarray, angle: np.ndarray, size: np.ndarray) -> Features:
    n = len(xy)
    return Features(xy.astype(np.float32), size.astype(np.float32), angle.astype(np.float32), np.ones(n, np.float32),
                    np.zeros((n, 128), np.float32), "sift")


def _gallery(ref: logo.Reference) -> logo.Gallery:
    # verify() reads the references and the detector only; the descriptor index is not needed here
    return logo.Gallery("sift", ("mark",), (ref,), (), np.zeros(0, np.int64), np.zeros(0, np.int64),
                        np.zeros(1, np.int64), None)


def _view(H: np.ndarray, ref_xy: np.ndarray, ref_angle: np.ndarray, ref_size: np.ndarray, rng,
          angle_noise: float, outliers: int):
    """Scene keypoints of the reference keypoints seen through ``H`` (positions within 1 px, orientations within
    ``angle_noise`` degrees of the Jacobian's prediction, sizes within 10 %), plus ``outliers`` random matches."""
    pose = logo.map_poses(H, ref_xy, np.c_[ref_angle, np.log(ref_size)])
    xy = cv2.perspectiveTransform(ref_xy.reshape(-1, 1, 2), H).reshape(-1, 2) + rng.uniform(-1, 1, ref_xy.shape)
    angle = pose[:, 0] + rng.uniform(-angle_noise, angle_noise, len(xy))
    size = np.exp(pose[:, 1]) * rng.uniform(0.9, 1.1, len(xy))
    o_ref = rng.uniform([0, 0], [REF_W, REF_H], (outliers, 2))
    o_xy = rng.uniform([0, 0], SCENE, (outliers, 2))
    return (np.r_[ref_xy, o_ref], np.r_[ref_angle, rng.uniform(-180, 180, outliers)],
            np.r_[ref_size, rng.uniform(4, 40, outliers)],
            np.r_[xy, o_xy], np.r_[angle, rng.uniform(-180, 180, outliers)], np.r_[size, rng.uniform(4, 40, outliers)])


def _verify(ref_xy, ref_angle, ref_size, sc_xy, sc_angle, sc_size, params=None):
    ref = _reference(ref_xy, ref_angle, ref_size)
    n = len(ref_xy)
    m = logo.Matches(np.zeros(n, np.int64), np.arange(n), np.arange(n), np.zeros(n, np.float32))
    hyps = logo.verify(_gallery(ref), m, _scene(sc_xy, sc_angle, sc_size), SCENE, params, rng=0)
    return logo.decide(hyps, params)


def _homography(ref_quad_in_scene: np.ndarray) -> np.ndarray:
    src = np.array([[0, 0], [REF_W - 1, 0], [REF_W - 1, REF_H - 1], [0, REF_H - 1]], np.float32)
    return cv2.getPerspectiveTransform(src, ref_quad_in_scene.astype(np.float32)).astype(np.float64)


def _corner_error(quad, H) -> float:
    truth = cv2.perspectiveTransform(logo.Reference("m", "m", _scene(np.zeros((0, 2)), np.zeros(0), np.zeros(0)),
                                                    (REF_W, REF_H)).outline.reshape(-1, 1, 2), H).reshape(-1, 2)
    return float(np.abs(np.asarray(quad) - truth).max())


def test_thin_mark_is_accepted():
    # a word mark in a loosely boxed reference: 9 keypoints zigzag on a strip 40 px high across the 400 x 300 box, so
    # their hull covers about 0.1 of the box, above `min_spread` (0.05, chosen on the leave-one-photo-out protocol)
    rng = np.random.default_rng(3)
    ref_xy = np.c_[np.linspace(40, 360, 9), 150 + np.resize([-20.0, 20.0], 9) + rng.uniform(-2, 2, 9)]
    H = _homography(np.array([[300, 300], [700, 320], [690, 600], [310, 590]], float))
    data = _view(H, ref_xy, rng.uniform(-180, 180, 9), rng.uniform(6, 20, 9), rng, 10.0, 20)
    det = _verify(*data)
    assert det.brand == "mark"
    # 1 px position noise on 9 points of a strip: the outline far from the strip extrapolates, 10 px covers it
    assert _corner_error(det.quad, H) < 10.0


def _foreshortened(squeeze: float, seed: int = 4):
    """The mark seen at a grazing angle: compressed ``squeeze`` times across, orientations off by up to 25 degrees
    (keypoint orientations are not affine-covariant under a strong tilt; `angle_tolerance` is 30)."""
    rng = np.random.default_rng(seed)
    ref_xy = rng.uniform([20, 20], [REF_W - 20, REF_H - 20], (12, 2))
    w = 400.0 / squeeze
    H = _homography(np.array([[400, 200], [400 + w, 210], [400 + w, 510], [400, 500]], float))
    return H, _view(H, ref_xy, rng.uniform(-180, 180, 12), rng.uniform(6, 20, 12), rng, 25.0, 20)


def test_foreshortened_mark_is_accepted():
    # compressed 5x across (400 px of the reference onto 80 px, 300 onto 300): anisotropy 5, within
    # `max_anisotropy` 6 (chosen on the leave-one-photo-out protocol)
    H, data = _foreshortened(5.0)
    det = _verify(*data)
    assert det.brand == "mark"
    assert _corner_error(det.quad, H) < 10.0  # 12 points spread over the mark, 1 px noise: a few px at the corners


def test_foreshortening_beyond_the_bound_is_refused_with_the_reason():
    # compressed 12x: further than any logo of the tuning photos was seen; the fit is refused and says why
    _, data = _foreshortened(12.0)
    det = _verify(*data)
    assert det.brand is None
    ref = _reference(data[0], data[1], data[2])
    n = len(data[0])
    m = logo.Matches(np.zeros(n, np.int64), np.arange(n), np.arange(n), np.zeros(n, np.float32))
    hyps = logo.verify(_gallery(ref), m, _scene(data[3], data[4], data[5]), SCENE, rng=0)
    assert "anisotropy" in hyps[0].reason


@pytest.mark.parametrize("seed", range(20))
def test_chance_matches_are_refused(seed):
    # 40 matches with random positions, orientations and sizes: whatever RANSAC fits is chance, and the a-contrario
    # score must say so (threshold 0: fewer than one such fit expected per scene)
    rng = np.random.default_rng(100 + seed)
    n = 40
    det = _verify(rng.uniform([0, 0], [REF_W, REF_H], (n, 2)), rng.uniform(-180, 180, n), rng.uniform(4, 40, n),
                  rng.uniform([0, 0], SCENE, (n, 2)), rng.uniform(-180, 180, n), rng.uniform(4, 40, n))
    assert det.brand is None


def test_verify_refuses_fewer_tests_than_references_tested():
    rng = np.random.default_rng(0)
    n = 12
    ref = _reference(rng.uniform(0, 300, (n, 2)), np.zeros(n), np.full(n, 10.0))
    m = logo.Matches(np.zeros(n, np.int64), np.arange(n), np.arange(n), np.zeros(n, np.float32))
    with pytest.raises(ValueError, match="`tests` must count at least the 1 references"):
        logo.verify(_gallery(ref), m, _scene(rng.uniform(0, 300, (n, 2)), np.zeros(n), np.full(n, 10.0)), SCENE,
                    tests=0)


def _card(seed: int, size: int = 200) -> np.ndarray:
    """A made-up mark: random polygons and a ring on a white card, gray."""
    rng = np.random.default_rng(seed)
    img = np.full((size, size), 255, np.uint8)
    for _ in range(7):
        pts = rng.integers(10, size - 10, (int(rng.integers(3, 6)), 2)).astype(np.int32)
        cv2.fillPoly(img, [pts], int(rng.integers(0, 200)))
    cv2.circle(img, (size // 2, size // 2), size // 3, int(rng.integers(0, 160)), 6)
    return img


@pytest.fixture(scope="module")
def fused_case():
    cards = {f"brand{i}": _card(10 + i) for i in range(3)}
    galleries = {d: logo.build_gallery([logo.Reference(b, b, detect(c, d), (200, 200)) for b, c in cards.items()])
                 for d in logo.method_detectors("fused")}
    src = np.array([[0, 0], [199, 0], [199, 199], [0, 199]], np.float32)
    H = cv2.getPerspectiveTransform(src, np.float32([[250, 120], [420, 140], [410, 330], [240, 300]]))
    rng = np.random.default_rng(5)
    scene = np.clip(rng.normal(128, 20, (480, 640)), 0, 255).astype(np.uint8)
    warped = cv2.warpPerspective(cards["brand1"], H, (640, 480))
    inside = cv2.warpPerspective(np.full((200, 200), 255, np.uint8), H, (640, 480)) > 0
    scene[inside] = warped[inside]
    return galleries, scene, H.astype(np.float64)


def test_fused_scores_count_every_detectors_tests(fused_case):
    # one a-contrario decision: a hypothesis' NFA is multiplied by the references tested by every detector, so its
    # score is its single-detector score minus log10(all tests / its detector's tests), exactly (same inliers)
    galleries, scene, _ = fused_case
    scenes = {d: detect(scene, d) for d in galleries}
    matches = {d: logo.match_scene(galleries[d], scenes[d]) for d in galleries}
    tests = {d: logo.tested_references(matches[d]) for d in galleries}
    total = sum(tests.values())
    fused = logo.verify_fused(galleries, matches, scenes, (640, 480), rng=0)
    assert {h.detector for h in fused} == {d for d in galleries if tests[d]}
    for d in galleries:
        alone = {h.reference: h for h in logo.verify(galleries[d], matches[d], scenes[d], (640, 480), rng=0)}
        for h in (h for h in fused if h.detector == d):
            # seeded alike, each detector finds the same fits as alone
            a = alone[h.reference]
            assert (h.inliers, h.reason) == (a.inliers, a.reason)
            if h.plausible:
                assert h.score == pytest.approx(a.score - np.log10(total / tests[d]), abs=1e-9)


def test_fused_finds_the_mark_where_it_is(fused_case):
    galleries, scene, H = fused_case
    det = logo.recognize_fused(galleries, {d: detect(scene, d) for d in galleries}, (640, 480), rng=0)
    assert det.brand == "brand1" and det.best.detector in galleries
    truth = cv2.perspectiveTransform(np.float32([[[0, 0]], [[199, 0]], [[199, 199]], [[0, 199]]]), H).reshape(4, 2)
    # keypoints of the coarsest detector (ORB, AKAZE) localise within ~1-2 px on a 200 px card: 4 px at the corners
    assert logo.quad_error(det.quad, truth) < 4.0


def test_unknown_method_lists_the_choices():
    with pytest.raises(ValueError, match=r"`method` must be one of \['akaze', 'brisk', 'fused', 'orb', 'sift'\]"):
        logo.method_detectors("surf")


def test_missed_record_names_the_true_brands_best_rejected_fit():
    sq = np.array([[0, 0], [100, 0], [100, 100], [0, 100]], float)
    none = np.zeros((0, 2), np.int64)
    hyps = [logo.Hypothesis("a", 0, 30, 20, 12.0, np.eye(3), sq, none, "", detector="sift"),
            logo.Hypothesis("b", 1, 18, 3, -np.inf, np.eye(3), sq, none, "3 inliers < 5", detector="orb"),
            logo.Hypothesis("b", 2, 9, 6, -np.inf, np.eye(3), sq + 5, none, "anisotropy 7.0 > 6.0",
                            detector="akaze")]
    det = logo.decide(hyps)
    rec = logo.missed_record(det, "b", {"sift": ["s0"], "orb": ["o0", "o1"], "akaze": ["k0", "k1", "k2"]})
    # neither is plausible: the one with more inliers is the better rejected fit
    assert (rec["reference"], rec["detector"], rec["inliers"], rec["reason"]) == ("k2", "akaze", 6,
                                                                                  "anisotropy 7.0 > 6.0")
    assert logo.missed_record(det, "c", {}) is None  # no reference of the brand was tried
    strip = logo.draw_missed([np.zeros((120, 160), np.uint8)] * 5,
                             [{"scene": f"s{i}", "truth": "b", "brand": "a", "missed": rec} for i in range(5)],
                             height=100, per_row=4)
    assert strip.ndim == 3 and strip.shape[0] == 2 * (100 + 36)  # two rows of thumbnails with their captions


ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


def _stage(module: str, cwd, *args: str):
    import os
    import subprocess
    import sys

    from conftest import default_params_path

    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    p = subprocess.run([sys.executable, "-m", f"stages.{module}", *args, "--params", str(default_params_path())],
                       cwd=cwd, env=env, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p


@pytest.mark.slow
def test_verify_stage_runs_the_fused_method(tmp_path, fused_case):
    import json

    _, scene, H = fused_case
    d = tmp_path / "mine"
    (d / "gallery").mkdir(parents=True)
    (d / "scenes").mkdir()
    for i in range(3):
        cv2.imwrite(str(d / "gallery" / f"brand{i}.png"), _card(10 + i))
    cv2.imwrite(str(d / "scenes" / "shop.png"), scene)
    cv2.imwrite(str(d / "scenes" / "empty.png"), np.full((480, 640), 128, np.uint8))
    # labelled as showing brand2, which it does not: a missed scene for the report's strip
    (d / "truth.json").write_text(json.dumps({"scenes": [{"file": "shop.png", "brand": "brand1", "quad": None},
                                                         {"file": "empty.png", "brand": "brand2", "quad": None}]}))
    for det in logo.method_detectors("fused"):
        _stage("features", tmp_path, "--images", "mine", "--out", f"features/{det}", "--section", "logo.features",
               "--detector", det, "--scenes", "scenes")
        _stage("logo_match", tmp_path, "--images", "mine", "--features", f"features/{det}", "--detector", det,
               "--out", f"matches/{det}")
    _stage("logo_verify", tmp_path, "--images", "mine", "--features", "features", "--matches", "matches",
           "--detector", "fused", "--out", "verify/fused", "--metrics", "metrics_fused.json", "--pr", "pr.json")
    recs = {r["scene"]: r for r in json.loads((tmp_path / "verify/fused/decisions.json").read_text())["scenes"]}
    assert recs["shop"]["brand"] == "brand1" and recs["empty"]["brand"] is None
    assert recs["shop"]["reference"] == "gallery/brand1.png"
    _stage("logo_report", tmp_path, "--images", "mine", "--verify", "verify", "--methods", "fused",
           "--out", "report", "--summary", "summary.json", "--found", "found.json")
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["tables"][0]["rows"][0][:3] == ["fused", 2, 1]
    tables = {t["title"].split(" (")[0]: t for t in summary["tables"]}
    assert tables["Recall per brand"]["rows"] == [["brand1", "1 / 1"], ["brand2", "0 / 1"]]
    assert "missed" in recs["empty"] and (tmp_path / "report" / "missed_fused.png").is_file()


def test_bench_per_brand_counts_the_answer_at_the_threshold(capsys):
    from cvpipe.bench.logo import _print_per_brand, per_brand

    answers = [{"truth": "a", "best_brand": "a", "score": 3.0}, {"truth": "a", "best_brand": "a", "score": -1.0},
               {"truth": "b", "best_brand": "a", "score": 9.0}, {"truth": None, "best_brand": "b", "score": 9.0}]
    got = per_brand(answers, 0.0)
    # the second "a" is below the threshold; the unknown-brand scene counts for no brand
    assert got == {"a": {"scenes": 2, "found": 1, "recall": 0.5}, "b": {"scenes": 1, "found": 0, "recall": 0.0}}
    _print_per_brand({"methods": {"fused": {"per_brand": got}}})
    assert "fused       a 1/2, b 0/1" in capsys.readouterr().out
