"""The logo DVC stages (features, logo_match, logo_verify, logo_report) run as DVC would on a user's folder, with
and without truth, and the metrics and input discovery they rely on."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from cvpipe import logo
from cvpipe.geometry import apply_homography, image_corners

from test_logos import PERSP, _region_error, _scene, _view, marks  # noqa: F401 - fixtures used below
from conftest import default_params_path


# ----------------------------------------------------------------------------------- the DVC stages (runner)

ROOT = Path(__file__).resolve().parents[1]


def _stage(module: str, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    """Run ``python -m stages.<module>`` as DVC would (this checkout first on the path), in ``cwd``."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", f"stages.{module}", *args, "--params", str(default_params_path())],
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
    return decisions, json.loads((out / "details_sift.json").read_text())


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


def test_pick_method_chooses_the_most_accurate_detector():
    # scene c has no gallery logo (truth None); accuracy counts a right brand or a right "none": sift 1/3, orb 3/3,
    # brisk 2/3, so the best is neither the first detector nor the default
    a, b_missed, b, c_wrong, c = (_record("a", "nike", 9.0, "nike"), _record("b", None, -np.inf, "puma"),
                                  _record("b", "puma", 8.0, "puma"), _record("c", "nike", 5.0, None),
                                  _record("c", None, -np.inf, None))
    decisions = {"sift": [a, b_missed, c_wrong], "orb": [a, b, c], "brisk": [a, b, c_wrong]}
    assert [logo.evaluate_records(r, 0.0)["accuracy"] for r in decisions.values()] == [1 / 3, 1.0, 2 / 3]
    assert logo.pick_method(decisions, 0.0, "sift") == "orb"
    # equal accuracy (2/3): more right brands wins (brisk 2 against 1), then the earlier detector
    tie = {"sift": [a, b_missed, c], "brisk": [a, b, c_wrong]}
    assert logo.pick_method(tie, 0.0, "sift") == "brisk"
    assert logo.pick_method({"akaze": decisions["brisk"], "brisk": decisions["brisk"]}, 0.0, "brisk") == "akaze"
    # without ground truth: the default when it ran, else the first detector
    blind = [_record("a", "nike", 9.0)]
    assert logo.pick_method({"orb": blind, "sift": blind}, 0.0, "sift") == "sift"
    assert logo.pick_method({"orb": blind, "brisk": blind}, 0.0, "sift") == "orb"


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


def test_the_stages_say_why_a_gallery_image_and_its_brand_are_not_used(tmp_path, marks):
    from cvpipe import datasets, features, io
    from cvpipe.logo.cached import load_gallery
    from cvpipe.params import LogoFeaturesParams, LogoMatchParams

    root, feats = tmp_path / "mine", tmp_path / "features"
    flat = {level: np.full((64, 64, 3), level, np.uint8) for level in (200, 255)}
    images = {"gallery/brand0.png": marks["brand0"], "gallery/blank.png": flat[200],
              "gallery/brand1/front.png": marks["brand1"], "gallery/brand1/white.png": flat[255],
              "scenes/s.png": marks["brand0"]}
    for rel, img in images.items():
        io.save_image(root / rel, img)
        arrays, _ = features.detect_item((cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), False), LogoFeaturesParams())
        io.save_npz((feats / rel).with_suffix(".npz"), **arrays)
    inputs, _ = datasets.find_logo(root)
    gallery, dropped = load_gallery(inputs, root, feats, LogoMatchParams())
    assert gallery.brands == ("brand0", "brand1")
    # a blank image is named so; the brand it was the only image of is named as not used
    assert dropped == [
        {"item": "gallery/blank.png", "reason": "blank (one grey level, 200); brand 'blank' is not used"},
        {"item": "gallery/brand1/white.png", "reason": "blank (one grey level, 255)"}]
