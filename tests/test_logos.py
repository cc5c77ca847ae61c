"""Logo recognition: synthetic scenes with a known mark pasted by a known homography, validation, the CLI."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from cvpipe import cli, logo
from cvpipe.geometry import apply_homography, image_corners
from cvpipe.errors import EstimationError, InputError
from cvpipe.features import detect
from cvpipe.params import LogoMatchParams, LogoVerifyParams
from cvpipe.samples import fit, paste, photo

WORDS = ("KAPPA", "ZULU", "ORBIT")


def _mark(seed: int, size: int = 200) -> np.ndarray:
    """A made-up brand mark: a word, a ring and random polygons in saturated colours on a white card."""
    rng = np.random.default_rng(seed)
    img = np.full((size, size, 3), 255, np.uint8)
    for _ in range(6):
        pts = rng.integers(10, size - 10, (int(rng.integers(3, 6)), 2)).astype(np.int32)
        cv2.fillPoly(img, [pts], tuple(int(c) for c in rng.integers(0, 200, 3)))
    cv2.circle(img, (size // 2, size // 2), size // 3, tuple(int(c) for c in rng.integers(0, 160, 3)), 6)
    cv2.putText(img, WORDS[seed % len(WORDS)], (12, size - 24), cv2.FONT_HERSHEY_DUPLEX, 1.3, (20, 20, 20), 3)
    return img


@pytest.fixture(scope="module")
def marks() -> dict[str, np.ndarray]:
    return {f"brand{i}": _mark(i) for i in range(3)}


@pytest.fixture(scope="module")
def gallery(marks) -> logo.Gallery:
    refs = [logo.Reference(b, f"{b}.png", detect(cv2.cvtColor(m, cv2.COLOR_BGR2GRAY), "sift"), (200, 200))
            for b, m in marks.items()]
    return logo.build_gallery(refs)


def _view(center, scale, angle_deg, persp, size=200) -> np.ndarray:
    """Homography mapping the size x size card onto a rotated, scaled, slightly perspective quad at ``center``."""
    src = image_corners(size, size).astype(np.float32)
    c = src.mean(0)
    t = np.deg2rad(angle_deg)
    R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    dst = (src - c) @ R.T * scale + np.asarray(center)
    dst += np.asarray(persp, np.float64) * size * scale
    return cv2.getPerspectiveTransform(src, dst.astype(np.float32)).astype(np.float64)


def _scene(mark: np.ndarray | None, H: np.ndarray | None, background: str = "coffee") -> np.ndarray:
    bg = fit(photo(background), 640, 480)
    if mark is not None:
        bg = paste(bg, mark, H)
    noisy = bg.astype(np.float32) + np.random.default_rng(1).normal(0, 3, bg.shape)
    return cv2.cvtColor(np.clip(noisy, 0, 255).astype(np.uint8), cv2.COLOR_BGR2GRAY)


def _region_error(quad, truth) -> float:
    """Mean corner distance up to the order of the corners: a mark with rotational symmetry (the python logo) or a
    gallery view stored rotated legitimately starts its outline at another corner of the same region."""
    q = np.asarray(quad, np.float64)
    return min(logo.quad_error(np.roll(q, i, axis=0), truth) for i in range(4))


PERSP = [[0.03, -0.02], [-0.04, 0.02], [0.02, 0.05], [-0.01, -0.03]]


@pytest.mark.parametrize("brand, center, scale, angle", [
    ("brand0", (300, 220), 0.8, 20), ("brand1", (420, 300), 0.6, -35), ("brand2", (200, 250), 1.0, 5),
])
def test_recovers_brand_and_quad(gallery, marks, brand, center, scale, angle):
    H = _view(center, scale, angle, PERSP)
    gray = _scene(marks[brand], H)
    det = logo.recognize(gallery, detect(gray, "sift"), (640, 480), rng=0)
    assert det.brand == brand
    truth = apply_homography(H, image_corners(200, 200))
    # SIFT keypoints sit within ~0.5 px; extrapolating the fit from the inliers to the card corners and the
    # 3-level noise add a little: 2.5 px mean corner error is ~2% of a 120-200 px logo side
    assert logo.quad_error(det.quad, truth) < 2.5
    assert det.inliers >= LogoVerifyParams().min_inliers and det.score >= LogoVerifyParams().score_threshold


@pytest.mark.parametrize("background", ["coffee", "astronaut", "chelsea"])
def test_no_logo_gives_none(gallery, background):
    det = logo.recognize(gallery, detect(_scene(None, None, background), "sift"), (640, 480), rng=0)
    assert det.brand is None and det.quad is None


def test_unknown_mark_gives_none(gallery):
    # a mark that is not in the gallery must not be forced onto the nearest brand
    H = _view((320, 240), 0.9, 10, PERSP)
    det = logo.recognize(gallery, detect(_scene(_mark(7), H), "sift"), (640, 480), rng=0)
    assert det.brand is None


@pytest.mark.parametrize("method", ["orb", "brisk", "akaze"])
def test_binary_detectors_recover_brand(marks, method):
    refs = [logo.Reference(b, b, detect(cv2.cvtColor(m, cv2.COLOR_BGR2GRAY), method), (200, 200))
            for b, m in marks.items()]
    g = logo.build_gallery(refs)
    H = _view((320, 240), 1.0, 15, PERSP)
    det = logo.recognize(g, detect(_scene(marks["brand1"], H), method), (640, 480), rng=0)
    assert det.brand == "brand1"
    # binary detectors localise on a coarser pyramid than SIFT: 4 px is ~2% of the 200 px card side
    assert logo.quad_error(det.quad, apply_homography(H, image_corners(200, 200))) < 4.0


def test_several_references_per_brand_do_not_cancel(marks):
    """Two views of one brand in the gallery: the ratio test compares brands, so the brand is still found."""
    gray = cv2.cvtColor(marks["brand0"], cv2.COLOR_BGR2GRAY)
    rotated = cv2.rotate(gray, cv2.ROTATE_90_CLOCKWISE)
    refs = [logo.Reference("brand0", "a", detect(gray, "sift"), (200, 200)),
            logo.Reference("brand0", "b", detect(rotated, "sift"), (200, 200)),
            logo.Reference("brand1", "c", detect(cv2.cvtColor(marks["brand1"], cv2.COLOR_BGR2GRAY), "sift"),
                            (200, 200))]
    g = logo.build_gallery(refs)
    det = logo.recognize(g, detect(_scene(marks["brand0"], _view((300, 240), 0.8, 0, PERSP)), "sift"),
                          (640, 480), rng=0)
    assert det.brand == "brand0"
    assert det.best.matches >= LogoVerifyParams().min_matches


def test_boxed_reference_projects_its_box(marks):
    """A reference that is a whole photo with the logo boxed: the quad is the box's outline in the scene."""
    canvas = fit(photo("chelsea"), 400, 300)
    canvas[50:250, 100:300] = marks["brand2"]
    gray = cv2.cvtColor(canvas, cv2.COLOR_BGR2GRAY)
    mask = np.zeros_like(gray)
    mask[50:250, 100:300] = 255
    ref = logo.Reference("brand2", "photo", detect(gray, "sift", mask=mask), (400, 300), (100, 50, 299, 249))
    g = logo.build_gallery([ref])
    H = _view((320, 240), 0.7, -20, PERSP)
    det = logo.recognize(g, detect(_scene(marks["brand2"], H), "sift"), (640, 480), rng=0)
    assert det.brand == "brand2"
    # same 2.5 px tolerance as for whole-image references (the box is the same 200 px card)
    assert logo.quad_error(det.quad, apply_homography(H, image_corners(200, 200))) < 2.5


def test_bundled_style_samples():
    """A small set made by the sample generator: every mark is found with the right brand and no-logo scenes
    get none."""
    pytest.importorskip("resvg_py")
    from cvpipe.samples import make_logo

    s = make_logo(np.random.default_rng(5), n_scenes=10, n_negatives=4)
    refs = [logo.Reference(Path(k).stem, k, detect(cv2.cvtColor(v, cv2.COLOR_BGR2GRAY), "sift"),
                            (v.shape[1], v.shape[0])) for k, v in s.images.items() if k.startswith("gallery/")]
    g = logo.build_gallery(refs)
    for sc in s.truth["scenes"]:
        img = s.images[f"scenes/{sc['file']}"]
        det = logo.recognize(g, detect(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), "sift"), (640, 480), rng=0)
        assert det.brand == sc["brand"], sc["file"]
        if det.brand:
            # the generator degrades with blur, noise and JPEG: 4 px is ~2-4% of a 100-220 px logo
            assert _region_error(det.quad, sc["quad"]) < 4.0, sc["file"]


# ------------------------------------------------------------------------------------------- score and checks


def test_significance_penalises_many_matches_and_rewards_inliers():
    base = logo.significance(12, 40, 4.0, 300 * 300, 10)
    assert logo.significance(20, 40, 4.0, 300 * 300, 10) > base  # more inliers, same matches
    assert logo.significance(12, 400, 4.0, 300 * 300, 10) < base  # same inliers among far more matches
    assert logo.significance(12, 40, 4.0, 300 * 300, 100) < base  # more references tested
    assert logo.significance(4, 40, 4.0, 300 * 300, 10) == -np.inf


@pytest.mark.parametrize("H, reason", [
    (np.diag([-1.0, 1.0, 1.0]) @ np.array([[1, 0, -300], [0, 1, 0], [0, 0, 1.0]]), "mirrored"),
    (np.diag([0.05, 0.05, 1.0]), "covers"),
    (np.diag([3.0, 0.3, 1.0]), "anisotropy"),
    (np.array([[1, 0, 0], [0, 1, 0], [0.0125, 0, 1.0]]), "perspective"),
    (np.array([[1, 0, 0], [0, 1, 0], [-0.01, 0, 1.0]]), "horizon"),
])
def test_shape_problems(H, reason):
    assert reason in logo.shape_problem(H, image_corners(200, 200), (640, 480))


def test_plain_view_has_no_shape_problem():
    assert logo.shape_problem(_view((320, 240), 1.0, 30, PERSP), image_corners(200, 200), (640, 480)) == ""


def test_evaluate_counts_wrong_brand_as_false_positive():
    truth = ["a", "b", None, "a"]
    pred = ["a", "a", "b", None]
    ev = logo.evaluate(truth, pred, [9.0, 5.0, 1.0, -np.inf], threshold=2.0)
    # answered: scenes 0 and 1; right: scene 0 only; scene 2 (no logo, score below threshold) is a right "none"
    assert (ev["answered"], ev["correct"]) == (2, 1)
    assert ev["precision"] == pytest.approx(0.5) and ev["recall"] == pytest.approx(1 / 3)
    assert ev["accuracy"] == pytest.approx(2 / 4)
    assert [c["threshold"] for c in ev["curve"]] == [9.0, 5.0, 1.0]


def test_gallery_keeps_strongest_keypoints(gallery):
    g = logo.build_gallery(gallery.references, max_features=40)
    for full, capped in zip(gallery.references, g.references):
        assert len(capped.features) == 40
        # the 40 kept are exactly the 40 of highest response
        assert np.sort(capped.features.response).min() >= np.sort(full.features.response)[-40]
    assert len(g.ref_of) == 40 * len(g.references)


def test_affine_ransac_recovers_map_among_outliers():
    rng = np.random.default_rng(3)
    A = np.array([[0.8, -0.3, 40.0], [0.25, 0.9, -12.0], [0.0, 0.0, 1.0]])
    src = rng.uniform(0, 200, (40, 2))
    dst = src @ A[:2, :2].T + A[:2, 2] + rng.normal(0, 0.5, (40, 2))
    bad = rng.permutation(40)[:28]  # 70 % outliers, as on a busy photo
    dst[bad] = rng.uniform(0, 300, (28, 2))
    fit, inl = logo.affine_ransac(src, dst, threshold=3.0, hypotheses=2000, rng=0)
    good = np.setdiff1d(np.arange(40), bad)
    # 0.5 px noise: every true match lies within 3 px; a random point does so with probability ~3e-4
    assert set(np.flatnonzero(inl)) == set(good)
    corners = image_corners(200, 200)
    assert logo.quad_error(apply_homography(fit, corners), apply_homography(A, corners)) < 1.0


def test_affine_ransac_degenerate():
    with pytest.raises(EstimationError, match="needs 3 correspondences"):
        logo.affine_ransac(np.zeros((2, 2)), np.zeros((2, 2)), 3.0)
    line = np.c_[np.arange(10.0), 2 * np.arange(10.0)]
    with pytest.raises(EstimationError, match="collinear"):
        logo.affine_ransac(line, line, 3.0)


@pytest.mark.parametrize("model", ["homography", "affine_homography"])
def test_models_recover_perspective_view(gallery, marks, model):
    # the affine-first model must still end with the homography when the view has perspective
    H = _view((320, 240), 0.9, 25, PERSP)
    det = logo.recognize(gallery, detect(_scene(marks["brand0"], H), "sift"), (640, 480),
                          verify_params=LogoVerifyParams(model=model), rng=0)
    assert det.brand == "brand0"
    assert logo.quad_error(det.quad, apply_homography(H, image_corners(200, 200))) < 2.5


# --------------------------------------------------------------------------------------------- validation


def test_empty_gallery():
    with pytest.raises(InputError, match="gallery is empty"):
        logo.build_gallery([])


def test_gallery_without_features_names_files():
    blank = detect(np.full((64, 64), 128, np.uint8), "sift")
    refs = [logo.Reference("x", "x.png", blank, (64, 64)), logo.Reference("y", "y.png", blank, (64, 64))]
    with pytest.raises(InputError, match=r"x\.png \(0\).*y\.png \(0\)"):
        logo.build_gallery(refs)


def test_gallery_mixed_detectors(marks):
    g = cv2.cvtColor(marks["brand0"], cv2.COLOR_BGR2GRAY)
    refs = [logo.Reference("a", "a", detect(g, "sift"), (200, 200)),
            logo.Reference("b", "b", detect(g, "orb"), (200, 200))]
    with pytest.raises(ValueError, match="share one detector"):
        logo.build_gallery(refs)


@pytest.mark.parametrize("kwargs, match", [
    ({"min_features": 3}, "`min_features` must be an integer >= 4"),
    ({"max_features": 7}, r"`max_features` must be an integer >= `min_features` \(8\)"),
])
def test_gallery_min_features(gallery, kwargs, match):
    with pytest.raises(ValueError, match=match):
        logo.build_gallery(gallery.references, **kwargs)


@pytest.mark.parametrize("size, box, match", [
    ((0, 10), None, "`size` of reference r"),
    ((100, 100), (10, 10, 100, 50), "`box` of reference r"),
    ((100, 100), (50, 10, 40, 50), "`box` of reference r"),
])
def test_reference_geometry(gallery, size, box, match):
    feats = gallery.references[0].features
    with pytest.raises(ValueError, match=match):
        logo.build_gallery([logo.Reference("b", "r", feats, size, box)])


def test_scene_detector_mismatch(gallery, marks):
    orb = detect(cv2.cvtColor(marks["brand0"], cv2.COLOR_BGR2GRAY), "orb")
    with pytest.raises(ValueError, match="scene features come from 'orb'"):
        logo.match_scene(gallery, orb)


def test_scene_size_validated(gallery, marks):
    feats = detect(cv2.cvtColor(marks["brand0"], cv2.COLOR_BGR2GRAY), "sift")
    with pytest.raises(ValueError, match="`scene_size` must be"):
        logo.recognize(gallery, feats, (0, 480))


def test_evaluate_lengths():
    with pytest.raises(ValueError, match="equal lengths"):
        logo.evaluate(["a"], ["a", None], [1.0], 0.0)


def test_quad_error_cyclic():
    q = image_corners(100, 50)
    assert logo.quad_error(np.roll(q, 2, axis=0), q) > 50  # corner i compared with corner i + 2
    assert logo.quad_error(np.roll(q, 2, axis=0), q, cyclic=True) == 0.0


def test_quad_error_shape():
    with pytest.raises(ValueError, match=r"quads must be \(4, 2\)"):
        logo.quad_error(np.zeros((3, 2)), np.zeros((4, 2)))


def test_draw_confusion_shape():
    with pytest.raises(ValueError, match=r"`matrix` must be \(3, 3\)"):
        logo.draw_confusion(np.zeros((2, 2), np.int64), ["a", "b"], "t")


@pytest.mark.parametrize("cls, kwargs, match", [
    (LogoMatchParams, {"ratio": 0.0}, "`ratio` must be in"),
    (LogoMatchParams, {"k": 1}, "`k` must be in"),
    (LogoMatchParams, {"per_reference": 9}, "`per_reference` must be in"),
    (LogoMatchParams, {"min_features": 2}, "`min_features` must be in"),
    (LogoMatchParams, {"reference_features": 7}, "`reference_features` must be in"),
    (LogoVerifyParams, {"model": "similarity"}, "`model` must be one of"),
    (LogoVerifyParams, {"binary_model": "affine"}, "`binary_model` must be one of"),
    (LogoVerifyParams, {"affine_samples": 0}, "`affine_samples` must be in"),
    (LogoVerifyParams, {"ransac_threshold": 0.0}, "`ransac_threshold` must be in"),
    (LogoVerifyParams, {"max_iters": 0}, "`max_iters` must be in"),
    (LogoVerifyParams, {"max_models": 0}, "`max_models` must be in"),
    (LogoVerifyParams, {"min_matches": 3}, "`min_matches` must be in"),
    (LogoVerifyParams, {"min_inliers": 3}, "`min_inliers` must be in"),
    (LogoVerifyParams, {"min_area": 0.0}, "`min_area` must be in"),
    (LogoVerifyParams, {"min_area": 0.1, "max_area": 0.05}, "`max_area` must be in"),
    (LogoVerifyParams, {"max_anisotropy": 0.5}, "`max_anisotropy` must be in"),
    (LogoVerifyParams, {"max_perspective": 0.5}, "`max_perspective` must be in"),
    (LogoVerifyParams, {"min_spread": 1.5}, "`min_spread` must be in"),
    (LogoVerifyParams, {"angle_tolerance": 0.0}, "`angle_tolerance` must be in"),
    (LogoVerifyParams, {"scale_tolerance": 1.0}, "`scale_tolerance` must be in"),
])
def test_params_validation(cls, kwargs, match):
    with pytest.raises(ValueError, match=match):
        cls(**kwargs)


# ---------------------------------------------------------------------------------------------------- CLI


@pytest.fixture
def gallery_dir(tmp_path, marks) -> Path:
    d = tmp_path / "gallery"
    d.mkdir()
    cv2.imwrite(str(d / "brand0.png"), marks["brand0"])
    (d / "brand1").mkdir()  # the folder layout: several references of one brand
    cv2.imwrite(str(d / "brand1" / "front.png"), marks["brand1"])
    cv2.imwrite(str(d / "brand1" / "turned.png"), cv2.rotate(marks["brand1"], cv2.ROTATE_90_CLOCKWISE))
    return d


def test_cli_bad_scene_among_good(tmp_path, gallery_dir, marks, capsys):
    H = _view((320, 240), 0.8, 10, PERSP)
    good = tmp_path / "good.jpg"
    cv2.imwrite(str(good), _scene(marks["brand1"], H))
    empty = tmp_path / "none.jpg"
    cv2.imwrite(str(empty), _scene(None, None))
    broken = tmp_path / "broken.jpg"
    broken.write_bytes(b"not an image at all")
    code = cli.main(["logo", str(good), str(broken), str(empty), "--gallery", str(gallery_dir), "--json"])
    out, err = capsys.readouterr()
    assert code == 2  # bad input for one scene
    records = json.loads(out)
    assert [r["scene"] for r in records] == [str(good), str(broken), str(empty)]
    assert records[0]["brand"] == "brand1" and len(records[0]["quad"]) == 4
    assert _region_error(records[0]["quad"], apply_homography(H, image_corners(200, 200))) < 2.5
    assert "error" in records[1] and "broken.jpg" in records[1]["error"] and records[1]["brand"] is None
    assert records[2]["brand"] is None and records[2]["quad"] is None and "error" not in records[2]
    assert err.count("cvpipe: error:") == 1 and "broken.jpg" in err


def test_cli_empty_gallery(tmp_path, capsys):
    (tmp_path / "g").mkdir()
    (tmp_path / "s.png").write_bytes(b"")
    assert cli.main(["logo", str(tmp_path / "s.png"), "--gallery", str(tmp_path / "g")]) == 2
    assert "the gallery is empty" in capsys.readouterr().err


def test_cli_gallery_without_features(tmp_path, capsys):
    g = tmp_path / "g"
    g.mkdir()
    cv2.imwrite(str(g / "flat.png"), np.full((64, 64), 200, np.uint8))
    assert cli.main(["logo", str(g / "flat.png"), "--gallery", str(g)]) == 2
    assert "flat.png (0)" in capsys.readouterr().err


def test_cli_bad_ratio(tmp_path, gallery_dir, capsys):
    assert cli.main(["logo", "x.jpg", "--gallery", str(gallery_dir), "--ratio", "1.5"]) == 2
    assert "`--ratio` must be in" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------------ benchmark


def test_flickrlogos_protocol(data_root):
    """The benchmark's split follows SOURCE.txt: 50 query photos + 20 no-logo photos, gallery = boxes + crops."""
    from cvpipe.bench.logo import SUBSET, load_subset

    if not (data_root / SUBSET).is_dir():
        pytest.skip(f"{SUBSET} not in {data_root}")
    gallery, tests = load_subset(data_root / SUBSET)
    assert len(tests) == 70 and sum(b is None for _, b in tests) == 20
    assert len({b for _, b in tests if b}) == 10
    training = {n.split("[")[0] for _, n, _, box in gallery if box is not None}
    assert not training & {f for f, _ in tests}  # no test photo is in the gallery
    assert {b for b, _, _, box in gallery if box is None} == {b for _, b in tests if b}  # one crop per brand


def test_bench_refuses_wrong_root(tmp_path, capsys):
    assert cli.main(["bench", "logo", "--data", str(tmp_path)]) == 2
    assert "scenes.csv: no such file" in capsys.readouterr().err


def test_bench_min_box_validated(tmp_path, capsys):
    assert cli.main(["bench", "logo", "--data", str(tmp_path), "--min-box", "0"]) == 2
    assert "`--min-box` must be a positive number" in capsys.readouterr().err


def test_bench_needs_a_data_root(monkeypatch, capsys):
    monkeypatch.delenv("CVPIPE_DATA", raising=False)
    assert cli.main(["bench", "logo"]) == 2
    assert "no data root" in capsys.readouterr().err


def test_cli_bad_max_features(gallery_dir, capsys):
    assert cli.main(["logo", "x.jpg", "--gallery", str(gallery_dir), "--max-features", "0"]) == 2
    assert "`--max-features` must be a positive integer" in capsys.readouterr().err


def test_cli_missing_gallery_folder(tmp_path, capsys):
    assert cli.main(["logo", "x.jpg", "--gallery", str(tmp_path / "nope")]) == 2
    assert "gallery folder does not exist" in capsys.readouterr().err


def test_leave_one_out_protocol(tmp_path, marks):
    """Each boxed training photo is a scene twice: its brand must be found with the other photos of the brand in the
    gallery, and none when its brand is left out of the gallery entirely."""
    from cvpipe.bench.logo import run_leave_one_out
    from cvpipe.params import LogoFeaturesParams

    (tmp_path / "scenes").mkdir()
    (tmp_path / "gallery").mkdir()
    rows = ["image,brand,gt_kind,x1,y1,x2,y2,img_w,img_h"]
    # a different photo behind every mark: the boxes include some background, which must not tie photos together
    for i, (brand, angle, bg) in enumerate([("brand0", 10, "coffee"), ("brand0", -15, "astronaut"),
                                             ("brand1", 5, "chelsea"), ("brand1", -20, "rocket"),
                                             ("brand2", 0, "camera")]):
        H = _view((320, 240), 0.9, angle, PERSP)
        q = apply_homography(H, image_corners(200, 200))
        (x1, y1), (x2, y2) = np.floor(q.min(0)).astype(int), np.ceil(q.max(0)).astype(int)
        cv2.imwrite(str(tmp_path / "scenes" / f"{i}.jpg"), _scene(marks[brand], H, bg))
        rows.append(f"scenes/{i}.jpg,{brand},bbox,{x1},{y1},{x2},{y2},640,480")
    (tmp_path / "scenes.csv").write_text("\n".join(rows) + "\n")
    cv2.imwrite(str(tmp_path / "gallery" / "brand1.png"), marks["brand1"])
    res = run_leave_one_out(tmp_path, ["sift"], LogoFeaturesParams(), LogoMatchParams(), LogoVerifyParams())
    ev = res["methods"]["sift"]
    assert res["protocol"]["photos"] == 5 and ev["scenes"] == 10 and ev["positives"] == 5
    detail = ev["scenes_detail"]
    # clean synthetic views of a mark with 200+ keypoints: every positive is found; brand2's only reference is its
    # own photo, so finding it would mean the photo leaked into its own gallery
    assert [d["brand"] for d in detail if d["truth"]] == ["brand0", "brand0", "brand1", "brand1", None]
    # the negative pass leaves the photo's whole brand out: its own brand (found with scores in the hundreds above)
    # must never come back; a chance fit of another brand near the threshold is the recogniser's business, not the
    # protocol's
    own = {d["scene"]: d["truth"] for d in detail if d["truth"]}
    assert all(d["best_brand"] != own[d["scene"]] for d in detail if d["truth"] is None)


def test_fitter_follows_descriptor_kind(gallery, marks, monkeypatch):
    """`model` serves SIFT and `binary_model` the binary detectors."""
    used = []
    for name, fitter in list(logo.MODELS.items()):
        monkeypatch.setitem(logo.MODELS, name, lambda *a, _n=name, _f=fitter: used.append(_n) or _f(*a))
    H = _view((320, 240), 1.0, 15, PERSP)
    gray = _scene(marks["brand1"], H)
    vp = LogoVerifyParams(model="affine_homography", binary_model="homography")
    assert logo.recognize(gallery, detect(gray, "sift"), (640, 480), verify_params=vp, rng=0).brand == "brand1"
    assert set(used) == {"affine_homography"}
    used.clear()
    refs = [logo.Reference(b, b, detect(cv2.cvtColor(m, cv2.COLOR_BGR2GRAY), "orb"), (200, 200))
            for b, m in marks.items()]
    det = logo.recognize(logo.build_gallery(refs), detect(gray, "orb"), (640, 480), verify_params=vp, rng=0)
    assert det.brand == "brand1" and set(used) == {"homography"}


# ------------------------------------------------------------------------------------------ keypoint poses


def test_map_poses_follows_detector_angles(marks):
    """Orientation and size predicted through a known rotation + scale agree with what SIFT measures (OpenCV's
    angle is in image axes, y down): median errors below 2 degrees and 3 %."""
    gray = cv2.cvtColor(marks["brand2"], cv2.COLOR_BGR2GRAY)
    M = cv2.getRotationMatrix2D((100, 100), 35, 1.3)
    M[:, 2] += 30
    moved = cv2.warpAffine(gray, M, (320, 320), borderValue=255)
    a, b = detect(gray, "sift"), detect(moved, "sift")
    m = cv2.BFMatcher(cv2.NORM_L2, crossCheck=True).match(a.descriptors, b.descriptors)
    ia, ib = np.array([x.queryIdx for x in m]), np.array([x.trainIdx for x in m])
    H = np.r_[M, [[0, 0, 1]]]
    ok = np.linalg.norm(apply_homography(H, a.xy[ia]) - b.xy[ib], axis=1) < 1.5
    assert ok.sum() >= 20
    pose = np.c_[a.angle[ia[ok]], np.log(a.size[ia[ok]])].astype(np.float64)
    pred = logo.map_poses(H, a.xy[ia[ok]], pose)
    d_angle = np.abs((pred[:, 0] - b.angle[ib[ok]] + 180) % 360 - 180)
    assert np.median(d_angle) < 2.0
    assert np.median(np.abs(pred[:, 1] - np.log(b.size[ib[ok]]))) < np.log(1.03)
    assert logo.pose_agrees(pred, np.c_[b.angle[ib[ok]], np.log(b.size[ib[ok]])], 30.0, 2.0).mean() > 0.9


def test_pose_agreement_strengthens_the_score():
    """Agreement in orientation and scale is evidence: the same counts score higher, and 4 inliers can count."""
    p = logo.pose_probability(30.0, 2.0)
    assert 0 < p < 0.1
    assert logo.pose_probability(180.0, 16.0) == 1.0
    assert logo.significance(8, 40, 4.0, 300 * 300, 10, p) > logo.significance(8, 40, 4.0, 300 * 300, 10)
    assert logo.significance(4, 40, 4.0, 300 * 300, 10) == -np.inf
    assert np.isfinite(logo.significance(4, 40, 4.0, 300 * 300, 10, p))


def test_affine_ransac_rejects_pose_contradictions():
    """Points that fit the map in position but not in orientation are not inliers when poses are given."""
    rng = np.random.default_rng(3)
    src = rng.uniform(0, 200, (30, 2))
    A = np.array([[0.8, -0.3, 50.0], [0.3, 0.8, 20.0], [0, 0, 1]])
    dst = apply_homography(A, src)
    src_pose = np.c_[rng.uniform(0, 360, 30), np.zeros(30)]
    dst_pose = logo.map_poses(A, src, src_pose)
    dst_pose[:10, 0] += 90.0  # the first 10 keypoints point elsewhere
    _, inl = logo.affine_ransac(src, dst, 3.0, rng=0)
    assert inl.all()
    _, inl = logo.affine_ransac(src, dst, 3.0, rng=0, src_pose=src_pose, dst_pose=dst_pose, angle_tolerance=30.0,
                                 scale_tolerance=2.0)
    assert not inl[:10].any() and inl[10:].all()


def test_bench_scene_scale_validated(tmp_path, capsys):
    assert cli.main(["bench", "logo", "--data", str(tmp_path), "--scene-scale", "2"]) != 0
    assert "`--scene-scale` must be in" in capsys.readouterr().err


def test_cli_min_long_side_validated(gallery_dir, capsys):
    assert cli.main(["logo", str(gallery_dir / "brand0.png"), "--gallery", str(gallery_dir),
                     "--min-long-side", "-5"]) != 0
    assert "`--min-long-side` must be" in capsys.readouterr().err


def test_gallery_index_does_not_depend_on_call_order(marks):
    """The FLANN kd-trees are randomised: building the same gallery twice, with other random work in between, must
    give the same matches (the index is seeded)."""
    refs = [logo.Reference(b, b, detect(cv2.cvtColor(m, cv2.COLOR_BGR2GRAY), "sift"), (200, 200))
            for b, m in marks.items()]
    scene = detect(_scene(marks["brand1"], _view((320, 240), 0.7, 10, PERSP)), "sift")
    first = logo.match_scene(logo.build_gallery(refs), scene)
    cv2.randu(np.zeros((50, 50), np.uint8), 0, 255)  # advance OpenCV's global generator
    second = logo.match_scene(logo.build_gallery(refs), scene)
    for a, b in zip(first.to_arrays().values(), second.to_arrays().values()):
        np.testing.assert_array_equal(a, b)


# ----------------------------------------------------------------------------------- the DVC stages (runner)

ROOT = Path(__file__).resolve().parents[1]


def _stage(module: str, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    """Run ``python -m stages.<module>`` as DVC would (this checkout first on the path), in ``cwd``."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", f"stages.{module}", *args, "--params", str(ROOT / "params.yaml")],
                          cwd=cwd, env=env, capture_output=True, text=True)


def _leaves(tree) -> list:
    return [v for x in tree.values() for v in (_leaves(x) if isinstance(x, dict) else [x])]


@pytest.fixture(scope="module")
def user_folder(tmp_path_factory, marks):
    """A user's logo folder without truth: a brand file, a brand subfolder of two references, a gallery image without
    keypoints, two scenes with a logo, one without, features from the real features stage; then a scene that the
    features stage never saw (as if it could not read it)."""
    top = tmp_path_factory.mktemp("logo_stages")
    d = top / "mine"
    (d / "gallery" / "brand1").mkdir(parents=True)
    (d / "scenes").mkdir()
    cv2.imwrite(str(d / "gallery" / "brand0.png"), marks["brand0"])
    cv2.imwrite(str(d / "gallery" / "brand1" / "front.PNG"), marks["brand1"])
    cv2.imwrite(str(d / "gallery" / "brand1" / "turned.jpg"), cv2.rotate(marks["brand1"], cv2.ROTATE_90_CLOCKWISE))
    cv2.imwrite(str(d / "gallery" / "flat.png"), np.full((64, 64, 3), 200, np.uint8))
    views = {"shop": ("brand1", _view((330, 250), 0.7, -15, PERSP)), "street": ("brand0", _view((300, 220), 0.8, 20,
                                                                                                 PERSP))}
    for name, (brand, H) in views.items():
        cv2.imwrite(str(d / "scenes" / f"{name}.jpg"), _scene(marks[brand], H))
    cv2.imwrite(str(d / "scenes" / "empty.png"), _scene(None, None))
    p = _stage("features", top, "--images", "mine", "--out", "features", "--section", "logo.features",
               "--detector", "sift", "--scenes", "scenes")
    assert p.returncode == 0, p.stderr
    (d / "scenes" / "broken.jpg").write_bytes(b"not an image")
    return top, d, views


def _run_logo_stages(top: Path) -> tuple[dict, dict]:
    """logo_match, logo_verify and logo_report on ``top/mine`` with SIFT, paths relative to ``top`` as in dvc.yaml."""
    p = _stage("logo_match", top, "--images", "mine", "--features", "features", "--detector", "sift",
               "--out", "out/matches")
    assert p.returncode == 0, p.stderr
    # one summary line, naming what was left out and why
    assert "dropped 2" in p.stdout and "scenes/broken.jpg" in p.stdout and "gallery/flat.png" in p.stdout
    p = _stage("logo_verify", top, "--images", "mine", "--features", "features", "--matches", "out/matches",
               "--detector", "sift", "--out", "out/verify/sift", "--metrics", "out/metrics_sift.json",
               "--pr", "out/plots/pr_sift.json")
    assert p.returncode == 0, p.stderr
    p = _stage("logo_report", top, "--images", "mine", "--verify", "out/verify", "--methods", "sift",
               "--out", "out/report", "--summary", "out/summary.json", "--found", "out/plots/found.json")
    assert p.returncode == 0, p.stderr
    out = top / "out"
    decisions = {r["scene"]: r for r in json.loads((out / "verify" / "sift" / "decisions.json").read_text())["scenes"]}
    return decisions, json.loads((out / "metrics_sift.json").read_text())


@pytest.mark.slow
def test_stages_on_a_folder_without_truth(user_folder):
    from cvpipe import report

    top, d, views = user_folder
    decisions, metrics = _run_logo_stages(top)
    out = top / "out"
    assert sorted(decisions) == ["empty", "shop", "street"]  # broken.jpg is dropped, not fatal
    for name, (brand, H) in views.items():
        r = decisions[name]
        assert r["brand"] == brand and not r["labelled"] and "truth" not in r
        # the reference that won is a file of the brand's own subfolder (or its single file)
        assert r["reference"].startswith(f"gallery/{brand}")
        # 2.5 px: the corners of a 200 px card seen at 0.7-0.8 scale, as in test_recovers_brand_and_quad
        assert _region_error(r["quad"], apply_homography(H, image_corners(200, 200))) < 2.5
    assert decisions["empty"]["brand"] is None
    assert metrics["logo"]["sift"]["all"] == {"scenes": 3, "answered": 2, "labelled": 0}
    # every gallery brand is counted, also one whose only image gave no usable reference (stable metric keys)
    assert metrics["logo"]["sift"]["found"] == {"brand0": 1, "brand1": 1, "flat": 0}
    assert all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in _leaves(metrics))
    assert json.loads((out / "plots" / "pr_sift.json").read_text()) == []
    summary = report.validate_summary(json.loads((out / "summary.json").read_text()))
    tables = {t["title"]: t for t in summary["tables"]}
    assert tables["Per detector"]["rows"][0][3:] == ["no ground truth"] * 4
    assert {r[0] for r in tables["Not processed"]["rows"]} == {"scenes/broken.jpg", "gallery/flat.png"}
    assert all((top / p["path"]).is_file() for p in summary["pictures"]) and len(summary["pictures"]) == 2
    assert "no ground truth" in summary["description"] and "timings" not in summary
    found = json.loads((out / "plots" / "found.json").read_text())
    assert {(r["brand"], r["found"]) for r in found} == {("brand0", 1), ("brand1", 1), ("flat", 0)}


@pytest.mark.slow
def test_stages_with_truth_score_the_decisions(user_folder):
    top, d, views = user_folder
    truth = [{"file": f"{n}.jpg", "brand": b, "quad": apply_homography(H, image_corners(200, 200)).tolist()}
             for n, (b, H) in views.items()] + [{"file": "empty.png", "brand": None, "quad": None}]
    (d / "truth.json").write_text(json.dumps({"scenes": truth}))
    try:
        decisions, metrics = _run_logo_stages(top)
    finally:
        (d / "truth.json").unlink()
    m = metrics["logo"]["sift"]["all"]
    assert (m["labelled"], m["positives"], m["correct"]) == (3, 2, 2)
    assert m["precision"] == 1.0 and m["recall"] == 1.0 and m["accuracy"] == 1.0
    assert m["quad_error_px_median"] < 2.5  # as above
    pr = json.loads((top / "out" / "plots" / "pr_sift.json").read_text())
    assert pr and all(0.0 <= r["precision"] <= 1.0 and 0.0 <= r["recall"] <= 1.0 for r in pr)
    assert all(decisions[n]["truth"] == b for n, (b, _) in views.items())


def _record(scene, brand, score, truth="unlabelled"):
    det = logo.Detection(brand, score, 10 if brand else 0, None, None, [])
    if brand is not None:  # a plausible best hypothesis of that brand
        det = logo.Detection(brand, score, 10, None, logo.Hypothesis(brand, 0, 20, 10, score, None, None,
                                                                       np.zeros((0, 2), np.int64)), [])
    return logo.scene_record(scene, det, "gallery/x.png" if brand else None,
                              None if truth == "unlabelled" else (truth, None))


def test_metrics_count_only_the_scenes_with_truth():
    recs = [_record("a", "nike", 9.0, "nike"), _record("b", "nike", 4.0, None), _record("c", None, -np.inf, "puma"),
            _record("d", "puma", 7.0)]  # d has no truth: counted as answered, not in precision/recall
    m = logo.metrics_of(recs, ["nike", "puma", "co.op"], "sift", 0.0)["logo"]["sift"]
    assert m["all"]["scenes"] == 4 and m["all"]["answered"] == 3 and m["all"]["labelled"] == 3
    # labelled: a right, b a false positive (truth none), c missed -> precision 1/2, recall 1/2 (a of a, c)
    assert m["all"]["precision"] == 0.5 and m["all"]["recall"] == 0.5 and m["all"]["positives"] == 2
    assert m["found"] == {"nike": 2, "puma": 1, "co_op": 0}  # no dots in metric keys (DVC joins keys with dots)
    assert "quad_error_px_median" not in m["all"]  # no outline truth given: no key rather than NaN
    assert logo.metrics_of(recs[3:], ["puma"], "orb", 0.0)["logo"]["orb"]["all"] == {
        "scenes": 1, "answered": 1, "labelled": 0}
    assert logo.pr_rows(recs[3:], "orb", 0.0) == []
    assert [r["recall"] for r in logo.pr_rows(recs, "sift", 0.0)] == [0.5, 0.5]  # at scores 9 then 4


def test_merge_dropped_lists_each_input_once_with_its_detectors():
    got = logo.merge_dropped({"sift": [{"item": "scenes/x.jpg", "reason": "unreadable"}],
                               "orb": [{"item": "scenes/x.jpg", "reason": "unreadable"},
                                       {"item": "gallery/y.png", "reason": "fewer than 8 keypoints"}]})
    assert got == [{"item": "scenes/x.jpg", "reason": "unreadable", "methods": ["sift", "orb"]},
                   {"item": "gallery/y.png", "reason": "fewer than 8 keypoints", "methods": ["orb"]}]


def test_find_logo_maps_files_to_brands_and_drops_name_clashes(tmp_path, marks):
    from cvpipe import datasets

    (tmp_path / "gallery" / "brand1").mkdir(parents=True)
    (tmp_path / "scenes").mkdir()
    for rel in ("gallery/brand0.png", "gallery/brand0.jpg", "gallery/brand1/a.png", "gallery/brand1/b.webp",
                "scenes/s.jpg"):
        cv2.imwrite(str(tmp_path / rel), marks["brand0"])
    (tmp_path / "gallery" / "empty").mkdir()
    inputs, dropped = datasets.find_logo(tmp_path)
    assert {b: [f.relative_to(tmp_path).as_posix() for f in fs] for b, fs in inputs.gallery.items()} == {
        "brand0": ["gallery/brand0.jpg"], "brand1": ["gallery/brand1/a.png", "gallery/brand1/b.webp"]}
    # brand0.png would write the same features file as brand0.jpg; an empty brand folder is listed too
    assert [d["item"] for d in dropped] == ["gallery/brand0.png", "gallery/empty"]
    assert inputs.scenes[0].name == "s" and not inputs.scenes[0].labelled


# ------------------------------------------------------------------------------------- several logos per photo


def test_every_logo_finds_two_gallery_brands_in_one_photo(gallery, marks):
    """A composite photo with two gallery marks at known places: every_logo reports both brands, each outline where
    the mark was pasted, and no third brand."""
    H0, H2 = _view((170, 240), 0.8, 10, PERSP), _view((470, 240), 0.8, -15, PERSP)
    bg = paste(paste(fit(photo("coffee"), 640, 480), marks["brand0"], H0), marks["brand2"], H2)
    gray = cv2.cvtColor(bg, cv2.COLOR_BGR2GRAY)
    det = logo.recognize(gallery, detect(gray, "sift"), (640, 480), rng=0)
    vp = LogoVerifyParams()
    found = logo.every_logo(det, vp.score_threshold)
    assert sorted(h.brand for h in found) == ["brand0", "brand2"]
    assert found[0].brand == det.brand  # the one-brand answer is the best of the list
    truth = {"brand0": H0, "brand2": H2}
    for h in found:
        # 2.5 px mean corner error: ~2 % of the 160 px pasted mark (the tolerance of test_recovers_brand_and_quad)
        assert logo.quad_error(h.quad, apply_homography(truth[h.brand], image_corners(200, 200))) < 2.5, h.brand
    # a stricter rule for further logos keeps the best one only once it exceeds the second's score
    assert [h.brand for h in logo.every_logo(det, vp.score_threshold, extra_score=found[1].score + 1)] == [det.brand]


def test_overlapping_outlines_keep_only_the_best():
    """Non-maximum suppression on outline IoU; implausible and sub-threshold hypotheses are never reported."""
    sq = np.array([[0, 0], [100, 0], [100, 100], [0, 100]], float)
    assert logo.quad_iou(sq, sq) == pytest.approx(1.0)
    assert logo.quad_iou(sq, sq + [200, 0]) == 0.0
    assert logo.quad_iou(sq, sq + [50, 0]) == pytest.approx(50 * 100 / (2 * 100 * 100 - 50 * 100))  # 1/3

    def hyp(brand, score, quad, reason=""):
        return logo.Hypothesis(brand, 0, 30, 20, score, np.eye(3), quad, np.zeros((0, 2), np.int64), reason)

    det = logo.Detection("a", 50.0, 20, sq, None, [
        hyp("a", 50.0, sq), hyp("b", 40.0, sq + [10, 10]),  # b overlaps a (IoU 0.68): suppressed
        hyp("c", 30.0, sq + [300, 0]),  # elsewhere: kept
        hyp("d", 90.0, sq + [600, 0], reason="outline not convex or mirrored"),  # implausible: never reported
        hyp("e", -1.0, sq + [900, 0])])  # below the threshold 0
    assert [h.brand for h in logo.every_logo(det, 0.0)] == ["a", "c"]
    assert [h.brand for h in logo.every_logo(det, 0.0, max_overlap=0.9)] == ["a", "b", "c"]
    assert [h.brand for h in logo.every_logo(det, 0.0, extra_score=30.0)] == ["a", "c"]  # c reaches it
    assert [h.brand for h in logo.every_logo(det, 0.0, extra_score=30.5)] == ["a"]


def test_extra_labels_are_documented_and_name_subset_brands():
    """Every correction of the benchmark's labels names a photo, one of the subset's brands and a reason."""
    from cvpipe.bench.logo import load_extra_labels

    extra = load_extra_labels()
    brands = {"Adidas", "BMW", "Cocacola", "DHL", "Fedex", "Ferrari", "Google", "Heineken", "McDonalds", "Starbucks"}
    assert extra and all(k.startswith("scenes/") and k.endswith(".jpg") for k in extra)
    assert set().union(*extra.values()) <= brands


def test_extra_labels_refuse_a_row_without_reason(tmp_path):
    from cvpipe.bench.logo import load_extra_labels

    bad = tmp_path / "extra.csv"
    bad.write_text("image,brand,reason\nscenes/1.jpg,Google,\n")
    with pytest.raises(InputError, match=r"extra.csv:2: image, brand and reason"):
        load_extra_labels(bad)
    bad.write_text("image,brand\nscenes/1.jpg,Google\n")
    with pytest.raises(InputError, match="missing column"):
        load_extra_labels(bad)


def test_multi_evaluate_counts_every_true_brand():
    """Several-brands precision/recall by hand: scene 1 holds a and b (finds a, then b at 5), scene 2 holds c and
    finds d (wrong), scene 3 holds nothing and finds nothing."""
    from cvpipe.bench.logo import multi_evaluate

    rows = [{"truth_all": ["a", "b"], "found": [["a", 40.0], ["b", 5.0]]},
            {"truth_all": ["c"], "found": [["d", 3.0]]},
            {"truth_all": [], "found": []}]
    ev = multi_evaluate(rows, extra_score=0.0)
    assert (ev["correct"], ev["answered"], ev["positives"]) == (2, 3, 3)
    ev = multi_evaluate(rows, extra_score=10.0)  # b's 5 is not enough for a second logo; d is a first logo
    assert (ev["correct"], ev["answered"], ev["positives"]) == (1, 2, 3)
    # one brand: a is right in scene 1, d wrong in scene 2; 1 right of the 2 photos that hold a logo
    assert ev["one_brand_precision"] == 0.5 and ev["one_brand_recall"] == 0.5


def test_extra_labels_name_photos_of_the_subset_and_new_brands(data_root):
    """Each correction names a photo of the subset and a brand its own label does not already give."""
    import csv

    from cvpipe.bench.logo import SUBSET, load_extra_labels

    if not (data_root / SUBSET).is_dir():
        pytest.skip(f"{SUBSET} not in {data_root}")
    with (data_root / SUBSET / "scenes.csv").open(newline="") as fh:
        labels = {r["image"]: r["brand"] for r in csv.DictReader(fh)}
    for image, brands in load_extra_labels().items():
        assert image in labels, image
        assert labels[image] not in brands, image
