"""Several logos per photo: every_logo and its outline suppression, the benchmark's extra labels and the
several-brands evaluation."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cvpipe import logo
from cvpipe.errors import InputError
from cvpipe.features import detect
from cvpipe.geometry import apply_homography, image_corners
from cvpipe.params import LogoVerifyParams
from cvpipe.samples import fit, paste, photo

from test_logos import PERSP, _view, gallery, marks  # noqa: F401 - fixtures used below


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
