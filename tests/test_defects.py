"""cvpipe.defect: inserted defects are found where they were put, perfect probes stay perfect through
misalignment, lighting and noise, and probes that cannot be registered are errors, not verdicts."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from cvpipe import cli, defect, io
from cvpipe.errors import EstimationError, InputError
from cvpipe.metrics import DetectionCounts, box_iou, corner_error, match_boxes
from cvpipe.params import DefectDiffParams, DefectRegionParams, DefectRegisterParams, replace
from conftest import default_params_path

SIZE = 320


def board(seed: int, size: int = SIZE) -> np.ndarray:
    """A synthetic PCB: textured substrate, copper traces with pads, a few labels (BGR uint8)."""
    rng = np.random.default_rng(seed)
    img = np.empty((size, size, 3), np.uint8)
    img[:] = (40, 90, 30)
    tex = cv2.GaussianBlur(rng.normal(0, 6, (size, size)).astype(np.float32), (0, 0), 2)
    img = np.clip(img + tex[..., None], 0, 255).astype(np.uint8)
    for _ in range(18):
        pts = [rng.uniform(20, size - 20, 2)]
        for _ in range(3):
            d = [(1, 0), (0, 1), (1, 1), (1, -1)][int(rng.integers(4))]
            pts.append(np.clip(pts[-1] + np.array(d) * rng.uniform(-80, 80), 15, size - 15))
        cv2.polylines(img, [np.array(pts, np.int32)], False, (60, 150, 200), int(rng.integers(3, 7)), cv2.LINE_AA)
        for q in (pts[0], pts[-1]):
            cv2.circle(img, tuple(int(v) for v in q), 7, (60, 150, 200), -1, cv2.LINE_AA)
            cv2.circle(img, tuple(int(v) for v in q), 2, (20, 30, 20), -1, cv2.LINE_AA)
    for i in range(3):
        x, y = rng.integers(10, size - 80, 2)
        cv2.putText(img, f"R{i}{int(rng.integers(10, 99))}", (int(x), int(y)), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    (230, 230, 230), 1, cv2.LINE_AA)
    return img


def motion(rot_deg: float, scale: float, shift: tuple[float, float], persp=(0.0, 0.0)) -> np.ndarray:
    c = (SIZE - 1) / 2
    t = np.deg2rad(rot_deg)
    A = np.array([[scale * np.cos(t), -scale * np.sin(t), 0], [scale * np.sin(t), scale * np.cos(t), 0], [*persp, 1]])
    T = np.array([[1, 0, c + shift[0]], [0, 1, c + shift[1]], [0, 0, 1]])
    C = np.array([[1, 0, -c], [0, 1, -c], [0, 0, 1]])
    H = T @ A @ C
    return H / H[2, 2]


def make_probe(part: np.ndarray, H: np.ndarray, seed: int, gain=0.9, bias=12.0, noise=2.5) -> np.ndarray:
    """``part`` seen through ``H`` (reference -> probe) with a lighting change, slight blur and noise."""
    rng = np.random.default_rng(seed)
    warped = cv2.warpPerspective(part, H, (SIZE, SIZE), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    out = cv2.GaussianBlur(warped.astype(np.float32) * gain + bias, (0, 0), 0.6)
    return np.clip(out + rng.normal(0, noise, out.shape), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def reference() -> np.ndarray:
    return board(7)


def test_inserted_defect_is_found_where_it_was_put(reference):
    part = reference.copy()
    cv2.ellipse(part, (200, 120), (9, 6), 30, 0, 360, (25, 25, 35), -1, cv2.LINE_AA)  # a dark blob
    ref_box = np.array([[200 - 10, 120 - 9, 200 + 10, 120 + 9]], float)
    H = motion(2.5, 1.03, (6.0, -9.0), (1e-5, -1e-5))
    probe = make_probe(part, H, seed=1)
    r = defect.inspect(reference, probe)
    assert r.verdict == "faulty"
    assert len(r.regions) == 1, r.regions
    # The tolerant difference trims up to `tolerance_radius` (3 px) off each side of a ~20 px blob, so the region
    # is a shrunken copy of the truth: IoU >= 0.4 still means "the same place" (DeepPCB counts a hit at 0.33).
    assert box_iou(r.regions, ref_box)[0, 0] >= 0.4
    assert box_iou(r.probe_regions, defect.map_boxes(ref_box, H))[0, 0] >= 0.4
    # registration: ECC refinement lands well under the 3 px tolerance (corner error over the whole frame)
    assert corner_error(r.registration.H, H, SIZE, SIZE) < 0.5
    assert r.score > 0


def test_the_steps_one_by_one_give_what_inspect_gives(reference):
    """The DVC stages run register -> warp -> difference -> regions (and the direct alternative -> choose) one by
    one, storing arrays between them; the chain must give inspect()'s verdict, score, regions and H exactly."""
    part = reference.copy()
    cv2.circle(part, (90, 90), 7, (230, 230, 230), -1, cv2.LINE_AA)
    for probe in (make_probe(part, motion(-2.0, 1.02, (4.0, 7.0)), seed=9),
                  make_probe(reference, motion(1.0, 0.98, (-6.0, 3.0)), seed=10)):
        r = defect.inspect(reference, probe)
        ref, prb = io.to_gray(reference), io.to_gray(probe)
        reg = defect.register_probe(ref, prb)
        found = []
        for g in [reg] + ([defect.register_direct(ref, prb, matches=reg.matches, inliers=reg.inliers)]
                          if defect.wants_alternative(reg) else []):
            d = defect.difference(ref, *defect.warp_probe(prb, g.H, ref.shape))
            d = defect.Difference.from_arrays(d.to_arrays("alt_"), "alt_")  # as stored between the stages
            found.append(defect.find_regions(d, g.H, prb.shape))
        chosen = defect.choose(found[0], found[1] if len(found) > 1 else None)
        assert (chosen.verdict, chosen.score) == (r.verdict, r.score)
        assert np.array_equal(chosen.probe_regions, r.probe_regions)
        H = reg.H if chosen is found[0] else defect.register_direct(ref, prb).H
        assert np.array_equal(H, r.registration.H)


def test_choose_keeps_the_first_unless_a_faulty_one_has_a_lower_scoring_alternative():
    def result(verdict, score):
        return defect.Inspection(verdict, score, np.zeros((0, 4)), np.zeros((0, 4)), np.zeros(0), 10.0)

    faulty, lower, higher = result("faulty", 50.0), result("faulty", 20.0), result("faulty", 80.0)
    perfect = result("perfect", 0.0)
    assert defect.choose(faulty, lower) is lower and defect.choose(faulty, perfect) is perfect
    assert defect.choose(faulty, higher) is faulty and defect.choose(faulty, None) is faulty
    assert defect.choose(perfect, result("perfect", 0.0)) is perfect  # a perfect probe never asks
    reg = defect.ProbeRegistration(np.eye(3), np.eye(3), 50, 40, 0.99, "features")
    assert defect.wants_alternative(reg)
    assert not defect.wants_alternative(reg, DefectRegisterParams(direct_fallback=False))
    assert not defect.wants_alternative(replace(reg, method="direct"))


@pytest.mark.parametrize("seed, rot, shift, gain, bias", [
    (2, -3.5, (12.0, 8.0), 0.8, 20.0),
    (3, 1.0, (-14.0, 3.0), 1.15, -15.0),
    (4, 4.0, (0.0, -12.0), 1.0, 0.0),
])
def test_perfect_probe_with_misalignment_lighting_and_noise_is_perfect(reference, seed, rot, shift, gain, bias):
    H = motion(rot, 0.96 if seed % 2 else 1.04, shift, (2e-5, 1e-5))
    probe = make_probe(reference, H, seed, gain=gain, bias=bias, noise=3.0)
    r = defect.inspect(reference, probe)
    assert r.verdict == "perfect" and len(r.regions) == 0 and r.score == 0.0
    assert corner_error(r.registration.H, H, SIZE, SIZE) < 0.5
    # the fitted photometric model undoes the lighting change (blur and noise keep it from being exact)
    assert r.difference.gain == pytest.approx(gain, rel=0.05)


def test_difference_tolerates_a_shift_up_to_the_radius():
    ref = board(11)[..., 1]
    shifted = np.roll(ref, 2, axis=1)
    valid = np.ones(ref.shape, bool)
    tolerant = defect.difference(ref, shifted, valid, DefectDiffParams(tolerance_radius=3))
    plain = defect.difference(ref, shifted, valid, DefectDiffParams(tolerance_radius=0))
    # a 2 px shift of edges of ~90 grey levels: the plain difference sees them, the tolerant one (r = 3) does not
    # (a few grey levels remain from smoothing the rolled-in column)
    assert plain.diff.max() > 40
    assert np.percentile(tolerant.diff[tolerant.valid], 99.9) < 5


def test_gain_bias_fit_ignores_outliers():
    rng = np.random.default_rng(0)
    ref = rng.uniform(0, 255, (200, 200))
    warped = 0.7 * ref + 25 + rng.normal(0, 1, ref.shape)
    warped[50:90, 50:90] = 255  # a defect must not pull the fit
    gain, bias, sigma = defect.fit_gain_bias(ref, warped, np.ones(ref.shape, bool))
    assert gain == pytest.approx(0.7, abs=0.01) and bias == pytest.approx(25, abs=1.5) and sigma < 2.5


# --------------------------------------------------------------------------------------------- registration errors


def test_unrelated_probe_is_a_registration_error(reference):
    with pytest.raises(EstimationError, match="registration failed"):
        defect.inspect(reference, make_probe(board(99), np.eye(3), seed=5))


def test_blank_probe_is_a_registration_error(reference):
    with pytest.raises(EstimationError, match="registration failed: the probe is blank"):
        defect.inspect(reference, np.full((SIZE, SIZE), 128, np.uint8))


def test_wildly_different_size_is_an_input_error(reference):
    small = cv2.resize(reference, (SIZE // 4, SIZE // 4), interpolation=cv2.INTER_AREA)
    with pytest.raises(InputError, match=r"registration failed: probe is 80x80 .* factor 4\.00"):
        defect.inspect(reference, small)


def test_probe_barely_overlapping_is_a_registration_error(reference):
    p = DefectRegisterParams(min_overlap=0.99)
    probe = make_probe(reference, motion(0, 1.0, (60.0, 0.0)), seed=6)
    with pytest.raises(EstimationError, match=r"covers only \d+% of the reference"):
        defect.register_probe(reference, probe, p)


# --------------------------------------------------------------------------------------------- validation


@pytest.mark.parametrize("cls, kwargs, message", [
    (DefectRegionParams, {"threshold": 0.0}, r"`threshold` must be in \(0\.0, 1\.0\], got 0\.0"),
    (DefectRegionParams, {"seed_threshold": 0.1}, r"`seed_threshold` must be in \[0\.15, 1\.0\]"),
    (DefectRegionParams, {"min_area": 0}, r"`min_area` must be in \[1, "),
    (DefectRegionParams, {"pad": -1.0}, r"`pad` must be in \[0\.0, "),
    (DefectRegionParams, {"merge_distance": -2.0}, r"`merge_distance` must be in \[-1\.0, "),
    (DefectRegionParams, {"open_radius": -1}, r"`open_radius` must be in \[0, "),
    (DefectDiffParams, {"tolerance_radius": 21}, r"`tolerance_radius` must be in \[0, 20\]"),
    (DefectDiffParams, {"fit_trim": 0.0}, r"`fit_trim` must be in \(0\.0, "),
    (DefectDiffParams, {"smooth_sigma": -1.0}, r"`smooth_sigma` must be in \[0\.0, "),
    (DefectRegisterParams, {"min_inliers": 3}, r"`min_inliers` must be in \[4, "),
    (DefectRegisterParams, {"ecc_scale": 0.0}, r"`ecc_scale` must be in \(0\.0, 1\.0\]"),
    (DefectRegisterParams, {"max_scale_change": 0.5}, r"`max_scale_change` must be in \[1\.0, "),
    (DefectRegisterParams, {"min_overlap": 0.0}, r"`min_overlap` must be in \(0\.0, 1\.0\]"),
    (DefectRegisterParams, {"ecc_levels": 7}, r"`ecc_levels` must be in \[0, 6\]"),
])
def test_params_validation(cls, kwargs, message):
    with pytest.raises(ValueError, match=message):
        cls(**kwargs)


def test_image_validation(reference):
    with pytest.raises(InputError, match=r"`probe` must be a \(H, W\) or \(H, W, 3\) uint8 image.*float64"):
        defect.inspect(reference, np.zeros((64, 64)))
    with pytest.raises(InputError, match=r"`reference` must be at least 16x16 pixels, got 8x8"):
        defect.inspect(np.zeros((8, 8), np.uint8), reference)
    with pytest.raises(InputError, match="must have one shape"):
        defect.difference(reference[..., 0], reference[:100, :100, 0], np.ones((100, 100), bool))
    with pytest.raises(InputError, match="`H` must be a finite invertible 3x3 matrix"):
        defect.map_boxes([[0, 0, 1, 1]], np.zeros((3, 3)))


def test_gain_bias_fit_refuses_what_it_cannot_fit():
    flat = np.full((50, 50), 100.0)
    with pytest.raises(EstimationError, match="the reference is flat over the overlap"):
        defect.fit_gain_bias(flat, flat, np.ones(flat.shape, bool))
    ramp = np.tile(np.arange(50.0), (50, 1))
    with pytest.raises(EstimationError, match="gain -1.00 against the reference"):
        defect.fit_gain_bias(ramp, 255 - ramp, np.ones(ramp.shape, bool))
    with pytest.raises(EstimationError, match="only 4 overlapping pixels"):
        defect.fit_gain_bias(ramp, ramp, np.pad(np.ones((2, 2), bool), 24))


# --------------------------------------------------------------------------------------------- regions and metrics


def test_merge_boxes_joins_only_near_boxes():
    boxes = np.array([[0, 0, 10, 10], [14, 0, 20, 10], [60, 60, 70, 70]], float)
    merged, scores = defect.merge_boxes(boxes, np.array([1.0, 2.0, 4.0]), 5.0)
    order = np.argsort(merged[:, 0])
    assert merged[order].tolist() == [[0, 0, 20, 10], [60, 60, 70, 70]]
    assert scores[order].tolist() == [3.0, 4.0]
    assert len(defect.merge_boxes(boxes, np.ones(3), -1)[0]) == 3


def test_box_iou_and_matching():
    a = np.array([[0, 0, 10, 10], [20, 20, 30, 30]], float)
    b = np.array([[5, 0, 15, 10], [100, 100, 110, 110]], float)
    iou = box_iou(a, b)
    assert iou[0, 0] == pytest.approx(50 / 150) and iou[1].max() == 0.0
    counts, pairs = match_boxes(a, b, 0.33)
    assert counts == DetectionCounts(tp=1, fp=1, fn=1) and pairs.tolist() == [[0, 0]]
    assert match_boxes(a, b, 0.34)[0] == DetectionCounts(0, 2, 2)
    assert counts.precision == 0.5 and counts.recall == 0.5 and counts.f1 == 0.5
    with pytest.raises(ValueError, match=r"`iou_threshold` must be in \(0, 1\], got 0"):
        match_boxes(a, b, 0)
    with pytest.raises(ValueError, match=r"`a` must be an \(N, 4\) array"):
        box_iou([[1, 2, 3]], b)
    with pytest.raises(ValueError, match="x2 < x1"):
        box_iou([[5, 0, 1, 1]], b)


def test_evaluate_counts_errors_and_false_alarms():
    truth = [{"file": "a.png", "verdict": "faulty", "boxes": [[0, 0, 10, 10]]},
             {"file": "b.png", "verdict": "perfect", "boxes": []},
             {"file": "c.png", "verdict": "perfect", "boxes": []}]
    results = [{"probe": "x/a.png", "verdict": "faulty", "regions": [[1, 1, 10, 10]]},
               {"probe": "b.png", "verdict": "faulty", "regions": [[50, 50, 60, 60]]},
               {"probe": "c.png", "verdict": None, "regions": [], "error": "registration failed"}]
    m = defect.evaluate(results, truth)
    assert m["accuracy"] == pytest.approx(1 / 3) and m["errors"] == 1
    assert m["faulty_flagged"] == 1.0 and m["false_alarm_rate"] == 1.0
    assert (m["tp"], m["fp"], m["fn"]) == (1, 1, 0)
    with pytest.raises(InputError, match="no inspection result for probe d.png"):
        defect.evaluate(results, truth + [{"file": "d.png", "verdict": "perfect", "boxes": []}])


def test_report_metrics_are_numbers_per_probe_and_score_only_probes_with_truth():
    from cvpipe.defect import report as rep

    records = [{"probe": "a.png", "verdict": "faulty", "score": 40.0, "regions": [[10, 10, 30, 30]],
                "H": np.eye(3).tolist(), "method": "features"},
               {"probe": "b.v2.png", "verdict": "perfect", "score": 0.0, "regions": [], "H": np.eye(3).tolist(),
                "method": "direct"},
               {"probe": "c.png", "verdict": None, "score": None, "regions": [], "H": None, "error": "blank"}]
    shift = np.array([[1, 0, 2.0], [0, 1, 0], [0, 0, 1]])
    truth = {"a.png": {"verdict": "faulty", "boxes": np.array([[10.0, 10, 30, 30], [50, 50, 60, 60]]), "H": shift},
             "c.png": {"verdict": "perfect", "boxes": np.zeros((0, 4)), "H": None}}
    ev = rep.evaluate_records(records, truth, (100, 100))
    m = rep.metrics_of(records, ev)["defect"]
    assert set(m) == {"all", "a", "b_v2", "c"}  # stems, no dots: DVC splits metric keys at dots
    assert all(isinstance(v, (int, float)) and not isinstance(v, bool) for d in m.values() for v in d.values())
    # a: one of its two true boxes found exactly, the other missed -> mean best IoU 0.5; H off by 2 px everywhere
    assert m["a"]["correct"] == 1 and m["a"]["box_iou"] == pytest.approx(0.5)
    assert m["a"]["registration_corner_error_px"] == pytest.approx(2.0)
    assert "correct" not in m["b_v2"] and m["b_v2"]["faulty"] == 0  # no truth: nothing scored
    assert m["c"] == {"inspected": 0, "correct": 0}  # not inspected counts as wrong
    assert m["all"]["accuracy"] == 0.5 and m["all"]["truth_probes"] == 2 and m["all"]["direct_registrations"] == 1
    assert rep.confusion_rows(records, truth) == [{"probe": "a.png", "actual": "faulty", "predicted": "faulty"},
                                                  {"probe": "c.png", "actual": "perfect",
                                                   "predicted": "not inspected"}]
    assert [r["probe"] for r in rep.score_rows(records)] == ["a.png", "b.v2.png"]
    no_truth = rep.metrics_of(records, rep.evaluate_records(records, {}, (100, 100)))["defect"]
    assert "accuracy" not in no_truth["all"] and "correct" not in no_truth["a"]


def test_montage_keeps_each_picture_whole_in_its_tile():
    from cvpipe.defect import report as rep

    wide = np.full((50, 200, 3), 255, np.uint8)
    out = rep.montage([wide, wide, wide], cols=2, width=400)
    assert out.shape == (400, 400, 3)  # two rows of two 200 px tiles (the fourth empty)
    # the 4:1 picture fills its tile's width and a quarter of its height: not stretched
    assert out[:50, :200].min() == 255 and out[51:200, :200].max() == 0 and out[200:, 200:].max() == 0
    with pytest.raises(ValueError, match="`images` must hold at least one image"):
        rep.montage([], 3)


# --------------------------------------------------------------------------------------------- command line


def test_inspect_command_reports_failures_and_keeps_the_other_results(reference, tmp_path, capsys):
    part = reference.copy()
    cv2.circle(part, (100, 220), 8, (230, 230, 230), -1, cv2.LINE_AA)
    io.save_image(tmp_path / "ref.png", reference)
    io.save_image(tmp_path / "faulty.png", make_probe(part, motion(1.5, 1.0, (5.0, 5.0)), seed=8))
    io.save_image(tmp_path / "blank.png", np.full((SIZE, SIZE, 3), 90, np.uint8))
    out = tmp_path / "out"
    code = cli.main(["inspect", str(tmp_path / "ref.png"), str(tmp_path / "faulty.png"), str(tmp_path / "blank.png"),
                     "--out", str(out), "--json"])
    captured = capsys.readouterr()
    assert code == 1
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("cvpipe: error:") and "blank.png: registration failed" in err[0]
    records = json.loads(captured.out)
    assert [r["verdict"] for r in records] == ["faulty", None]
    assert set(records[0]) == {"probe", "verdict", "score", "regions", "H", "overlay"} and len(records[0]["regions"]) == 1
    assert records[0]["overlay"] == str(out / "faulty_regions.png")  # the JSON names the picture written
    assert "registration failed" in records[1]["error"]
    assert (out / "faulty_regions.png").is_file() and (out / "faulty_diff.png").is_file()
    assert json.loads((out / "inspect.json").read_text()) == records


def test_inspect_command_rejects_bad_options(tmp_path, capsys, reference):
    io.save_image(tmp_path / "ref.png", reference)
    code = cli.main(["inspect", str(tmp_path / "ref.png"), str(tmp_path / "ref.png"), "--threshold", "2"])
    assert code == 2 and "`--threshold` must be in (0.0, 1.0], got 2.0" in capsys.readouterr().err


def test_inspect_command_all_failing_and_unreadable_reference(tmp_path, capsys, reference):
    io.save_image(tmp_path / "ref.png", reference)
    io.save_image(tmp_path / "blank.png", np.zeros((SIZE, SIZE), np.uint8))
    assert cli.main(["inspect", str(tmp_path / "ref.png"), str(tmp_path / "blank.png")]) == 1
    # the one probe's own failure is the one line, naming the probe
    assert "blank.png: registration failed: the probe is blank" in capsys.readouterr().err
    assert cli.main(["inspect", str(tmp_path / "missing.png"), str(tmp_path / "blank.png")]) == 2
    assert "missing.png" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["--data", "{tmp}", "--limit", "-1"], r"`--limit` must be >= 0, got -1"),
    (["--data", "{tmp}", "--pad", "-2"], r"`--pad` must be >= 0, got -2"),
    (["--data", "{tmp}"], r"pairs.txt: not found; --data must be the folder that holds deeppcb/"),
])
def test_bench_defect_argument_errors(tmp_path, capsys, argv, message):
    import re

    assert cli.main(["bench", "defect", *[a.format(tmp=tmp_path) for a in argv]]) == 2
    assert re.search(message, capsys.readouterr().err)


# --------------------------------------------------------------------------------------------- real data


def test_deeppcb_pair_warped_both_ways(data_root):
    """One DeepPCB pair through the benchmark's synthesis: the test image is flagged, the template is not."""
    from cvpipe.bench.defect import load_pairs, make_probe as deeppcb_probe

    pair = load_pairs(data_root)[0]
    ref = io.read_image(pair["template"], "gray")
    rng = np.random.default_rng([20261122, 0])
    probe, H, boxes = deeppcb_probe(io.read_image(pair["test"], "gray"), pair["boxes"], rng)
    params = replace(defect.InspectParams(), regions=replace(DefectRegionParams(), pad=9.0))
    r = defect.inspect(ref, probe, params)
    assert r.verdict == "faulty"
    # this pair has 10 annotated defects; at DeepPCB's IoU 0.33 at least 8 must be found with at most 2 extras
    counts = match_boxes(r.probe_regions, boxes, 0.33)[0]
    assert counts.tp >= 0.8 * len(boxes) and counts.fp <= 2
    perfect, _, _ = deeppcb_probe(ref, np.zeros((0, 4)), rng)
    assert defect.inspect(ref, perfect, params).verdict == "perfect"


# --------------------------------------------------------------------------------------------- DVC stages


def _run_stages(root, folder, out, params):
    """The defect stages of dvc.yaml, in order, on ``folder`` (cwd ``out``: the runner's timings land there)."""
    import os
    import subprocess
    import sys

    from pathlib import Path

    o = Path("outputs", "defect")  # relative, as in dvc.yaml: the summary's picture paths must be
    steps = [
        ["stages.features", "--images", folder, "--out", o / "features", "--section", "defect.features"],
        ["stages.defect_match", "--images", folder, "--features", o / "features", "--out", o / "matches"],
        ["stages.defect_register", "--images", folder, "--features", o / "features", "--matches", o / "matches",
         "--out", o / "register"],
        ["stages.defect_diff", "--images", folder, "--registered", o / "register", "--out", o / "diff"],
        ["stages.defect_regions", "--diff", o / "diff", "--registration", o / "register" / "registration.json",
         "--out", o / "results.json"],
        ["stages.defect_report", "--images", folder, "--results", o / "results.json", "--registration",
         o / "register" / "registration.json", "--diff", o / "diff", "--out", o],
    ]
    env = dict(os.environ, PYTHONPATH=str(root))
    for module, *args in steps:
        subprocess.run([sys.executable, "-m", module, *map(str, args), "--params", str(params)], cwd=out, env=env,
                       check=True, capture_output=True, text=True)
    return out / o


@pytest.mark.slow
def test_stages_give_inspect_results_drop_the_unregistrable_probe_and_rerun_identically(reference, tmp_path):
    from pathlib import Path

    from cvpipe.report import validate_summary

    root = Path(__file__).resolve().parents[1]
    folder = tmp_path / "mine"
    part = reference.copy()
    cv2.ellipse(part, (200, 120), (9, 6), 30, 0, 360, (25, 25, 35), -1, cv2.LINE_AA)
    H_faulty, H_perfect = motion(2.5, 1.03, (6.0, -9.0)), motion(-1.5, 0.98, (-5.0, 4.0))
    probes = {"faulty.png": make_probe(part, H_faulty, seed=1), "perfect.png": make_probe(reference, H_perfect, 2),
              "blank.png": np.full((SIZE, SIZE, 3), 90, np.uint8)}
    io.save_image(folder / "reference.png", reference)
    for name, img in probes.items():
        io.save_image(folder / "probes" / name, img)
    true_box = defect.map_boxes([[190, 111, 210, 129]], H_faulty)
    io.save_json(folder / "truth.json", {"probes": [
        {"file": "faulty.png", "verdict": "faulty", "boxes": true_box, "H": H_faulty},
        {"file": "perfect.png", "verdict": "perfect", "boxes": [], "H": H_perfect}]})  # blank.png: no truth
    o = _run_stages(root, folder, tmp_path, default_params_path())

    params = defect.load_inspect_params(default_params_path())
    records = {r["probe"]: r for r in json.loads((o / "results.json").read_text())}
    for name in ("faulty.png", "perfect.png"):  # the stage chain is inspect(), step by step
        # read as the stages read them (the decoder's grey conversion can differ from cv2.cvtColor by 1 level)
        r = defect.inspect(io.read_image(folder / "reference.png", "gray"),
                            io.read_image(folder / "probes" / name, "gray"), params)
        rec = records[name]
        assert (rec["verdict"], rec["score"]) == (r.verdict, r.score)
        assert np.array_equal(np.reshape(rec["regions"], (-1, 4)), r.probe_regions)
        assert np.array_equal(rec["H"], r.registration.H)
    assert records["blank.png"]["verdict"] is None and "blank" in records["blank.png"]["error"]

    summary = validate_summary(json.loads((o / "summary.json").read_text()))
    not_processed = [t for t in summary["tables"] if t["title"] == "Not processed"]
    assert [row[0] for row in not_processed[0]["rows"]] == ["blank.png"]
    assert "2 of 3 probes have ground truth" in summary["description"]
    metrics = json.loads((o / "details.json").read_text())["defect"]
    leaves = [v for m in metrics.values() for v in m.values()]
    assert all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in leaves)
    assert metrics["faulty"]["faulty"] == 1 and metrics["perfect"]["faulty"] == 0
    assert metrics["blank"] == {"inspected": 0}
    assert metrics["all"]["accuracy"] == 1.0 and metrics["all"]["truth_probes"] == 2
    # the found blob is the inserted one (same tolerance as test_inserted_defect_is_found_where_it_was_put)
    assert metrics["faulty"]["box_iou"] >= 0.4
    # ECC registration lands well under a pixel over the frame (as in the unit tests)
    assert metrics["faulty"]["registration_corner_error_px"] < 0.5
    confusion = json.loads((o / "plots" / "confusion.json").read_text())
    assert confusion == [{"actual": "faulty", "predicted": "faulty", "probe": "faulty.png"},
                         {"actual": "perfect", "predicted": "perfect", "probe": "perfect.png"}]
    assert "timings" not in summary and (tmp_path / "outputs" / "timings" / "defect_register.json").is_file()

    # a rerun reproduces every cached output byte for byte (timings live apart, in outputs/timings)
    cached = [p for p in sorted(o.rglob("*")) if p.is_file()]
    before = {p: p.read_bytes() for p in cached}
    _run_stages(root, folder, tmp_path, root / "params.yaml")
    assert [p for p in cached if p.read_bytes() != before[p]] == []

    # without a truth file everything still runs; no accuracy anywhere, nothing to plot in the confusion matrix
    (folder / "truth.json").unlink()
    o = _run_stages(root, folder, tmp_path, root / "params.yaml")
    metrics = json.loads((o / "details.json").read_text())["defect"]
    assert "accuracy" not in metrics["all"] and "correct" not in metrics["faulty"]
    assert json.loads((o / "plots" / "confusion.json").read_text()) == []
    summary = json.loads((o / "summary.json").read_text())
    assert "no ground truth" in summary["description"]


def test_defect_is_an_alias_of_inspect():
    """`cvpipe defect` (the task's name) parses to the same options and runs the same function as `cvpipe inspect`."""
    from cvpipe.commands import inspect as command

    parser = cli.build_parser()
    a, b = (vars(parser.parse_args([verb, "ref.png", "p.png", "--tolerance", "2"])) for verb in ("inspect", "defect"))
    assert a.pop("_run") is b.pop("_run") is command.run
    assert (a.pop("command"), b.pop("command")) == ("inspect", "defect")
    assert a == b and a["tolerance"] == 2


PACKAGE_MODULES = ["cvpipe.defect", "cvpipe.defect.register", "cvpipe.defect.diff", "cvpipe.defect.regions",
                   "cvpipe.defect.report"]


@pytest.mark.parametrize("name", PACKAGE_MODULES)
def test_docstring_examples_run(name):
    """The Examples sections are doctests, and they hold (each is a small check on known input)."""
    import doctest
    import importlib

    failed, attempted = doctest.testmod(importlib.import_module(name), optionflags=doctest.NORMALIZE_WHITESPACE)
    assert attempted > 0 and failed == 0


def test_every_public_function_of_the_package_has_an_example():
    import inspect as pyinspect

    functions = [n for n in defect.__all__ if pyinspect.isfunction(getattr(defect, n))
                 and getattr(defect, n).__module__.startswith("cvpipe.defect")]
    assert "inspect" in functions and "register_probe" in functions
    assert [n for n in functions if "Examples\n" not in getattr(defect, n).__doc__] == []
