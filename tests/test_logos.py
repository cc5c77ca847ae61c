"""Logo recognition: synthetic scenes with a known mark pasted by a known homography, validation, the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from cvpipe import cli, errors, logo
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


def test_the_same_picture_under_two_brands_is_refused_naming_both(marks):
    """A copy under another name would tie every other-brand ratio test: neither brand could ever be found."""
    feats = detect(cv2.cvtColor(marks["brand0"], cv2.COLOR_BGR2GRAY), "sift")
    refs = [logo.Reference("brand0", "brand0.png", feats, (200, 200)),
            logo.Reference("brand0_copy", "brand0_copy.png", feats, (200, 200))]
    with pytest.raises(InputError, match=r"brand0_copy\.png: the same picture as brand0\.png, under another brand"):
        logo.build_gallery(refs)
    same_brand = [refs[0], logo.Reference("brand0", "brand0_copy.png", feats, (200, 200))]
    assert logo.build_gallery(same_brand).brands == ("brand0",)


def test_a_copy_inside_its_own_brand_still_finds_the_brand(marks):
    """Duplicate gallery images of one brand never cancel it: the ratio test weighs a brand's nearest descriptor
    against other brands only, so the copy's identical descriptors are no rival, and the brand is found with as
    many verified matches as without the copy (a copy can split the matches between the two references: at least
    90 % of them stay with the one that wins)."""
    gray = {b: cv2.cvtColor(m, cv2.COLOR_BGR2GRAY) for b, m in marks.items()}
    refs = [logo.Reference(b, f"{b}.png", detect(g, "sift"), (200, 200)) for b, g in gray.items()]
    copy = logo.Reference("brand0", "brand0_copy.png", refs[0].features, (200, 200))
    scene = detect(_scene(marks["brand0"], _view((300, 240), 0.8, 0, PERSP)), "sift")
    alone = logo.recognize(logo.build_gallery(refs), scene, (640, 480), rng=0)
    doubled = logo.recognize(logo.build_gallery(refs + [copy]), scene, (640, 480), rng=0)
    assert alone.brand == doubled.brand == "brand0"
    assert doubled.best.matches >= 0.9 * alone.best.matches >= LogoVerifyParams().min_matches


def test_gallery_over_the_memory_budget_is_refused_naming_what_to_change(marks, monkeypatch):
    refs = [logo.Reference(b, f"{b}.png", detect(cv2.cvtColor(m, cv2.COLOR_BGR2GRAY), "sift"), (200, 200))
            for b, m in marks.items()]
    held = sum(logo.gallery.features_nbytes(r.features) for r in refs)
    # a budget just under what the three references need (5 bytes per byte of keypoints), then just over it
    monkeypatch.setenv("CVPIPE_MEMORY_BUDGET_GB", str(0.9 * 5 * held / 1e9))
    with pytest.raises(errors.BudgetError, match=r"the gallery of 3 reference images .*`--max-features`"):
        logo.build_gallery(refs)
    monkeypatch.setenv("CVPIPE_MEMORY_BUDGET_GB", str(1.1 * 5 * held / 1e9))
    assert logo.build_gallery(refs).brands == tuple(sorted(marks))


def _gallery_and_scene(marks, tmp_path) -> tuple[Path, Path]:
    """A gallery folder with one file per mark and a scene showing the first mark."""
    gallery = tmp_path / "gallery"
    gallery.mkdir()
    for b, m in marks.items():
        cv2.imwrite(str(gallery / f"{b}.png"), m)
    scene = tmp_path / "scene.png"
    cv2.imwrite(str(scene), _scene(marks["brand0"], _view((300, 240), 0.8, 0, PERSP)))
    return gallery, scene


def test_logo_command_refuses_a_gallery_over_the_budget_while_reading_it(marks, tmp_path, monkeypatch, capsys):
    gallery, scene = _gallery_and_scene(marks, tmp_path)
    # a budget that holds the detection of every image (0.1 GB), and a gallery that costs 10,000 bytes per byte of
    # keypoints: the first reference (about 70 KB of them) is already over, so the command stops at it
    monkeypatch.setenv("CVPIPE_MEMORY_BUDGET_GB", "0.1")
    monkeypatch.setattr(logo.gallery, "GALLERY_BYTES_PER_FEATURE_BYTE", 1e4)
    assert cli.main(["logo", "--gallery", str(gallery), str(scene)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the gallery of 1 reference images" in err[0] and "CVPIPE_MEMORY_BUDGET_GB" in err[0]


def test_logo_command_checks_the_budget_with_every_detectors_keypoints_and_counts_images(marks, tmp_path,
                                                                                         monkeypatch):
    # fused holds three galleries at once: the bytes checked grow with each detector's keypoints, while the number
    # of reference images the message names is the number of files read
    gallery, scene = _gallery_and_scene(marks, tmp_path)
    seen = []
    monkeypatch.setattr(logo.gallery, "check_gallery_memory", lambda held, images: seen.append((held, images)))
    assert cli.main(["logo", "--gallery", str(gallery), str(scene), "--method", "fused"]) == 0
    detectors = len(logo.method_detectors("fused"))
    reading = seen[:len(marks) * detectors]  # then build_gallery checks each detector's gallery on its own
    assert [n for _, n in reading] == [k for k in range(1, len(marks) + 1) for _ in range(detectors)]
    assert all(b[0] > a[0] for a, b in zip(reading, reading[1:]))
    assert [n for _, n in seen[len(reading):]] == [len(marks)] * detectors


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
    ({"max_features": 7}, r"`max_features` must be an integer >= 8 \(`min_features`\), got 7"),
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


def test_cli_notes_each_gallery_brand_and_image_it_does_not_use(tmp_path, gallery_dir, marks, capsys):
    cv2.imwrite(str(gallery_dir / "blank.png"), np.full((64, 64), 200, np.uint8))
    cv2.imwrite(str(gallery_dir / "brand1" / "white.png"), np.full((64, 64), 255, np.uint8))
    (gallery_dir / "vacant").mkdir()
    scene = tmp_path / "s.jpg"
    cv2.imwrite(str(scene), _scene(marks["brand1"], _view((320, 240), 0.8, 10, PERSP)))
    argv = ["logo", str(scene), "--gallery", str(gallery_dir), "--json"]
    assert cli.main(argv) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)[0]["brand"] == "brand1"
    assert err.splitlines() == [
        f"cvpipe: note: gallery brand 'vacant' is not used: its folder {gallery_dir / 'vacant'} holds no images",
        f"cvpipe: note: gallery brand 'blank' is not used: {gallery_dir / 'blank.png'}: blank (one grey level, 200)",
        (f"cvpipe: note: gallery image {gallery_dir / 'brand1' / 'white.png'} of brand 'brand1' is not used: "
         "blank (one grey level, 255)")]
    assert cli.main(["-q", *argv]) == 0  # -q silences the notes, not the answer
    out, err = capsys.readouterr()
    assert err == "" and json.loads(out)[0]["brand"] == "brand1"


@pytest.mark.parametrize("method", ["fused", "sift"])
def test_cli_notes_an_image_no_detector_can_use_once_with_each_detectors_count(tmp_path, gallery_dir, marks, capsys,
                                                                                method):
    # a smooth ramp is not blank (many grey levels) but gives no detector a keypoint; the default method (fused)
    # reads each image once and notes it once, with the count of every detector it ran
    ramp = np.tile(np.linspace(60, 200, 64).astype(np.uint8), (64, 1))
    cv2.imwrite(str(gallery_dir / "brand1" / "ramp.png"), ramp)
    scene = tmp_path / "s.jpg"
    cv2.imwrite(str(scene), _scene(marks["brand1"], _view((320, 240), 0.8, 10, PERSP)))
    assert cli.main(["logo", str(scene), "--gallery", str(gallery_dir), "--json", "--method", method]) == 0
    out, err = capsys.readouterr()
    counts = ", ".join(f"0 keypoints with {d}" for d in logo.method_detectors(method))
    assert json.loads(out)[0]["brand"] == "brand1"
    assert err.splitlines() == [f"cvpipe: note: gallery image {gallery_dir / 'brand1' / 'ramp.png'} of brand "
                                f"'brand1' is not used: {counts}, fewer than the 8 needed"]


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
    assert "`--max-features` must be in [1, 1000000], got 0" in capsys.readouterr().err


def test_cli_missing_gallery_folder(tmp_path, capsys):
    assert cli.main(["logo", "x.jpg", "--gallery", str(tmp_path / "nope")]) == 2
    assert "gallery folder does not exist" in capsys.readouterr().err


def _loo_subset(tmp_path, marks) -> None:
    """A five-photo subset in ``tmp_path`` (scenes.csv, scenes/, gallery/): two photos each of brand0 and brand1,
    one of brand2, and a reference image of brand1."""
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


def test_leave_one_out_protocol(tmp_path, marks):
    """Each boxed training photo is a scene twice: its brand must be found with the other photos of the brand in the
    gallery, and none when its brand is left out of the gallery entirely."""
    from cvpipe.bench.logo import run_leave_one_out
    from cvpipe.params import LogoFeaturesParams

    _loo_subset(tmp_path, marks)
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


def test_leave_one_out_shape_row_follows_the_fused_answers(tmp_path, marks):
    """The fused+shape row answers as fused wherever fused names a brand, and is calibrated without the photo."""
    from cvpipe.bench.logo import SHAPE_ROW, run_leave_one_out
    from cvpipe.params import LogoFeaturesParams

    _loo_subset(tmp_path, marks)
    res = run_leave_one_out(tmp_path, ["fused"], LogoFeaturesParams(), LogoMatchParams(), LogoVerifyParams())
    fused, cue = res["methods"]["fused"]["scenes_detail"], res["methods"][SHAPE_ROW]["scenes_detail"]
    assert [(d["scene"], d["truth"]) for d in fused] == [(d["scene"], d["truth"]) for d in cue]
    assert all(c == f for f, c in zip(fused, cue) if f["brand"] is not None)
    assert all(c["detector"] == "shape" for f, c in zip(fused, cue) if c != f)
    assert res["protocol"]["shape"]["templates"] >= 0


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
