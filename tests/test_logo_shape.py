"""The shape cue for smooth marks (cvpipe.logo.shape): silhouettes recovered under scale and translation, plain blobs
and chance-level templates refused, the decision and the benchmark row that uses it."""

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from cvpipe.logo import shape

YELLOW = (0, 200, 255)  # BGR: hue 23 of OpenCV's 180


def _arches(w: int, h: int, thickness: int) -> np.ndarray:
    """An "M" of two yellow arches on white, (h, w, 3)."""
    img = np.full((h, w, 3), 255, np.uint8)
    for cx in (w // 4, 3 * w // 4):
        cv2.ellipse(img, (cx, h - 1), (w // 4 - thickness // 2, h - thickness // 2 - 1), 0, 180, 360, YELLOW,
                    thickness)
    return img


def _scene(rng, arches_at: tuple[int, int], scale: float) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """Grey clutter with a yellow rectangle, a yellow disc and the arches scaled by ``scale`` at ``arches_at``."""
    scene = cv2.GaussianBlur(rng.integers(60, 200, (300, 400, 1)).astype(np.uint8), (0, 0), 3)
    scene = cv2.cvtColor(scene, cv2.COLOR_GRAY2BGR)
    cv2.rectangle(scene, (20, 20), (120, 80), YELLOW, -1)
    cv2.circle(scene, (330, 240), 35, YELLOW, -1)
    small = cv2.resize(_arches(160, 120, 18), None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    x, y = arches_at
    h, w = small.shape[:2]
    region = scene[y:y + h, x:x + w]
    yellow = np.abs(small.astype(int) - YELLOW).sum(2) < 120
    region[yellow] = small[yellow]
    return scene, (x, y, w, h)


def test_arches_silhouette_is_found_at_another_scale_and_place_and_not_on_plain_blobs():
    t = shape.shape_template(_arches(160, 120, 18), "Arches", "ref.png")
    assert t is not None and t.fill < shape.MAX_FILL  # an M covers well under half of its box
    rng = np.random.default_rng(0)
    for scale, at in ((0.6, (180, 40)), (1.2, (60, 130))):
        scene, (x, y, w, h) = _scene(rng, at, scale)
        score, box = shape.shape_score(t, shape.scene_regions(scene))
        # resampling the thin arches costs a few percent of overlap; a blob of the same hue reaches far less
        assert score > 0.75, score
        bx, by, bw, bh = box
        assert abs(bx - x) <= 3 and abs(by - y) <= 3 and abs(bw - w) <= 4 and abs(bh - h) <= 4, (box, (x, y, w, h))
    # the same scene without the arches: the rectangle and the disc are the only yellow regions
    plain = cv2.GaussianBlur(rng.integers(60, 200, (300, 400, 1)).astype(np.uint8), (0, 0), 3)
    plain = cv2.cvtColor(plain, cv2.COLOR_GRAY2BGR)
    cv2.rectangle(plain, (20, 20), (120, 80), YELLOW, -1)
    cv2.circle(plain, (330, 240), 35, YELLOW, -1)
    # a filled box holds the whole silhouette: its overlap is the template's fill, the most a blob can reach
    # (hence templates that fill over MAX_FILL of their box are refused)
    assert shape.shape_score(t, shape.scene_regions(plain))[0] <= t.fill + 1e-9


def test_templates_of_grey_marks_and_regions_of_grey_images_are_refused():
    grey = np.full((50, 50, 3), 128, np.uint8)
    assert shape.shape_template(grey, "Grey", "g.png") is None  # no chromatic pixel: no hue to segment
    with pytest.raises(ValueError, match="`image`"):
        shape.scene_regions(grey[..., 0])


def _template(brand: str, fill: float, source=None) -> shape.ShapeTemplate:
    mask = np.zeros((shape.SIDE, shape.SIDE), bool)
    mask.flat[:int(round(fill * mask.size))] = True
    return shape.ShapeTemplate(brand, f"{brand}.png", source, 2, mask, 1.0)


def test_calibration_keeps_a_template_only_above_its_chance_level_and_refuses_blobs():
    templates = [_template("A", 0.3, source="a1"), _template("B", 0.3), _template("C", 0.9)]
    photos = ["a1", "a2", "b1", "c1", "none"]
    brands = [{"A"}, {"A"}, {"B"}, {"C"}, set()]
    scores = np.array([[0.99, 0.70, 0.35, 0.30, 0.20],   # A: its own photo (a1) does not count; a2 clears 0.35
                       [0.40, 0.45, 0.50, 0.30, 0.42],   # B: finds b1 at 0.50, only 0.05 above its chance 0.45
                       [0.10, 0.10, 0.10, 0.95, 0.10]])  # C: a plain blob (fill 0.9)
    th = shape.calibrate_shapes(templates, scores, photos, brands)
    assert th[0] == pytest.approx(0.35) and np.isnan(th[1]) and np.isnan(th[2])
    # a margin of 0.04 keeps B
    assert shape.calibrate_shapes(templates, scores, photos, brands, margin=0.04)[1] == pytest.approx(0.45)
    with pytest.raises(ValueError, match="`scores`"):
        shape.calibrate_shapes(templates, scores[:, :3], photos, brands)
    kept, levels = shape.kept_shapes(templates, th)
    assert [t.brand for t in kept] == ["A"] and levels.tolist() == pytest.approx([0.35])
    with pytest.raises(ValueError, match="`thresholds`"):
        shape.kept_shapes(templates, th[:2])


def test_decision_takes_the_largest_margin_above_the_minimum():
    templates = [_template("A", 0.3), _template("B", 0.3), _template("C", 0.3)]
    th = np.array([0.3, 0.2, np.nan])
    assert shape.decide_shape(templates, th, [0.35, 0.25, 0.99]) is None  # margins 0.05, 0.05; C not kept
    brand, margin, i = shape.decide_shape(templates, th, [0.45, 0.6, 0.99])
    assert (brand, i) == ("B", 1) and margin == pytest.approx(0.4)


def test_benchmark_row_adds_the_cue_only_where_the_fused_method_named_no_brand():
    from cvpipe.bench.logo import with_shape

    fused = {"brand": "A", "best_brand": "A", "score": 12.0, "inliers": 20, "detector": "sift",
             "found": [["A", 12.0]]}
    assert with_shape(fused, ("B", 0.2, 3)) == fused
    silent = {**fused, "brand": None, "best_brand": "C", "score": -1.0, "found": []}
    got = with_shape(silent, ("B", 0.2, 3))
    assert (got["brand"], got["best_brand"], got["score"], got["detector"], got["found"]) == \
        ("B", "B", 0.2, "shape", [["B", 0.2]])
    assert with_shape(silent, None) == silent


@pytest.mark.skipif(not (Path(os.environ.get("CVPIPE_DATA", "/nonexistent")) / "flickrlogos27_subset").is_dir(),
                    reason="CVPIPE_DATA with flickrlogos27_subset not available")
def test_gallery_arches_find_the_boxed_arches_of_a_photo():
    from cvpipe import io

    root = Path(os.environ["CVPIPE_DATA"]) / "flickrlogos27_subset"
    t = shape.shape_template(io.read_image(root / "gallery" / "McDonalds.png"), "McDonalds", "gallery")
    score, (x, y, w, h) = shape.shape_score(t, shape.scene_regions(io.read_image(root / "scenes/3858957735.jpg")))
    x0, y0, x1, y1 = 202, 85, 327, 185  # the photo's box in scenes.csv
    inter = max(0, min(x + w, x1) - max(x, x0)) * max(0, min(y + h, y1) - max(y, y0))
    iou = inter / (w * h + (x1 - x0) * (y1 - y0) - inter)
    # the silhouette lies inside the annotated box, which has a margin round the arches
    assert iou > 0.6 and score > 0.5, (iou, score)


def _cli_gallery(tmp_path, rng) -> Path:
    """A gallery of one brand, "Arches": the M of arches above a grey textured strip that gives SIFT keypoints."""
    g = tmp_path / "gallery"
    g.mkdir()
    ref = np.full((200, 160, 3), 255, np.uint8)
    ref[:120] = _arches(160, 120, 18)
    strip = cv2.GaussianBlur(rng.integers(0, 256, (80, 160, 1)).astype(np.uint8), (0, 0), 1.5)
    ref[120:] = cv2.cvtColor(strip, cv2.COLOR_GRAY2BGR)
    cv2.imwrite(str(g / "Arches.png"), ref)
    return g


def _clutter(rng) -> np.ndarray:
    return cv2.cvtColor(cv2.GaussianBlur(rng.integers(60, 200, (300, 400, 1)).astype(np.uint8), (0, 0), 3),
                        cv2.COLOR_GRAY2BGR)


def _shape_photos(tmp_path, rng) -> Path:
    """Two photos of the arches (other scales and places) and two without them but with yellow blobs."""
    d = tmp_path / "photos"
    (d / "Arches").mkdir(parents=True)
    (d / "none").mkdir()
    for k, (scale, at) in enumerate(((0.8, (150, 110)), (1.0, (130, 90)))):  # clear of _scene's blobs
        cv2.imwrite(str(d / "Arches" / f"{k}.png"), _scene(rng, at, scale)[0])
    for k in range(2):
        img = _clutter(rng)
        cv2.rectangle(img, (30 + 40 * k, 40), (200, 120 + 30 * k), YELLOW, -1)
        cv2.circle(img, (300, 200), 40 - 10 * k, YELLOW, -1)
        cv2.imwrite(str(d / "none" / f"{k}.png"), img)
    return d


def test_command_names_the_smooth_mark_that_keypoints_miss_with_shape_photos(tmp_path, capsys):
    import json

    from cvpipe import cli

    rng = np.random.default_rng(3)
    gallery, photos = _cli_gallery(tmp_path, rng), _shape_photos(tmp_path, rng)
    scene, (x, y, w, h) = _scene(rng, (120, 90), 0.7)  # the arches alone: the textured strip is not in the scene
    cv2.imwrite(str(tmp_path / "scene.png"), scene)
    plain = _clutter(rng)
    cv2.rectangle(plain, (20, 20), (160, 100), YELLOW, -1)  # yellow, but no arches
    cv2.imwrite(str(tmp_path / "plain.png"), plain)
    argv = ["logo", str(tmp_path / "scene.png"), str(tmp_path / "plain.png"), "--gallery", str(gallery), "--json"]
    assert cli.main(argv) == 0
    assert [r["brand"] for r in json.loads(capsys.readouterr().out)] == [None, None]  # no keypoint fit either way
    assert cli.main([*argv, "--shape-photos", str(photos)]) == 0
    out = capsys.readouterr()
    found, none = json.loads(out.out)
    assert "shape cue: 1 of 1 gallery silhouettes kept (Arches)" in out.err
    assert (found["brand"], found["cue"]) == ("Arches", "shape") and found["shape_margin"] > 0.3
    (x0, y0), (x1, y1) = found["quad"][0], found["quad"][2]
    assert abs(x0 - x) <= 3 and abs(y0 - y) <= 3 and abs(x1 - (x + w)) <= 4 and abs(y1 - (y + h)) <= 4
    assert none["brand"] is None and "cue" not in none


def test_command_refuses_shape_photos_it_cannot_use(tmp_path, capsys):
    from cvpipe import cli

    rng = np.random.default_rng(4)
    gallery = _cli_gallery(tmp_path, rng)
    cv2.imwrite(str(tmp_path / "scene.png"), _clutter(rng))
    argv = ["logo", str(tmp_path / "scene.png"), "--gallery", str(gallery), "--shape-photos"]
    assert cli.main([*argv, str(tmp_path / "nope")]) == 2
    assert "nope: --shape-photos folder does not exist" in capsys.readouterr().err
    (tmp_path / "photos" / "Unknown").mkdir(parents=True)
    assert cli.main([*argv, str(tmp_path / "photos")]) == 2
    err = capsys.readouterr().err
    assert "Unknown: --shape-photos subfolders must be gallery brands or 'none'; the gallery has Arches" in err
    (tmp_path / "empty" / "none").mkdir(parents=True)
    assert cli.main([*argv, str(tmp_path / "empty")]) == 2
    assert "empty: no photos; expected" in capsys.readouterr().err
