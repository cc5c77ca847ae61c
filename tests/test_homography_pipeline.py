"""The homography task around the estimator: CLI command, pictures, report summary, benchmark data, stages."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from cvpipe import cli, io
from cvpipe.bench import homography as bench
from cvpipe.errors import InputError
from cvpipe.homography import (alignment_checkerboard, alignment_panel, compare_methods, metrics_of, quality_plots,
                               transform_points)
from cvpipe.report import validate_summary
from cvpipe.metrics import corner_error

H_AB = np.array([[0.95, 0.08, 20.0], [-0.06, 0.97, 15.0], [1.2e-4, -6e-5, 1.0]])
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def pair_files(tmp_path_factory, textured_image):
    d = tmp_path_factory.mktemp("hpair")
    h, w = textured_image.shape
    # B(x') = A(H^-1 x'): warpPerspective with H maps A's pixels to B's
    b = cv2.warpPerspective(textured_image, H_AB, (w, h))
    io.save_image(d / "a.png", textured_image)
    io.save_image(d / "b.png", b)
    return d / "a.png", d / "b.png", (w, h)


@pytest.mark.parametrize("method", ["ours", "opencv-ransac", "opencv-magsac"])
def test_cli_homography_json(pair_files, method, capsys):
    a, b, (w, h) = pair_files
    assert cli.main(["homography", str(a), str(b), "--method", method, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"H", "matches", "inliers"}
    assert 4 <= out["inliers"] <= out["matches"]
    # a synthetic warp of a textured photo: SIFT + any robust estimator lands within 1 px at the corners
    assert corner_error(np.array(out["H"]), H_AB, w, h) < 1.0


def test_cli_homography_errors(pair_files, tmp_path, capsys):
    a, b, _ = pair_files
    assert cli.main(["homography", str(tmp_path / "missing.png"), str(b)]) == 2
    assert "missing.png" in capsys.readouterr().err
    assert cli.main(["homography", str(a), str(b), "--threshold", "0"]) == 2
    assert "`--threshold` must be in (0.0, 100.0], got 0.0" in capsys.readouterr().err
    blank = tmp_path / "blank.png"
    io.save_image(blank, np.full((100, 100), 128, np.uint8))
    # no features on a flat image: the algorithm cannot succeed -> exit 1 with advice
    assert cli.main(["homography", str(blank), str(b)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("cvpipe: error: only 0 matches") and "--detector" in err


def test_checkerboard_shows_b_only_where_it_covers_a():
    a = np.full((40, 60), 50, np.uint8)
    b = np.full((40, 60), 200, np.uint8)
    shift = np.array([[1.0, 0, 30.0], [0, 1.0, 0], [0, 0, 1.0]])  # A's x maps to x + 30 in B
    pic = alignment_checkerboard(a, b, shift, tiles=6)
    assert pic.shape == (40, 60, 3) and pic.dtype == np.uint8
    # columns x >= 30 sample B outside its frame: uncovered, drawn as darkened A (50 // 3)
    assert (pic[:, 31:, 0] == 50 // 3).all()
    # the covered half alternates A and B squares
    left = pic[:, :29, 0]
    assert (left == 50).any() and (left == 200).any()
    panel = alignment_panel(a, b, {"good": np.eye(3), "none": None}, tiles=4, width=30)
    assert panel.shape == (24 + 20, 60, 3)
    with pytest.raises(InputError, match="`tiles` must be an integer >= 1"):
        alignment_checkerboard(a, b, shift, tiles=0)
    with pytest.raises(InputError, match=r"`H_ab` must be a finite \(3, 3\) array"):
        alignment_checkerboard(a, b, np.eye(2))


def test_compare_methods_scores_truth_pairs_and_counts_failures():
    pairs = [{"name": "p1", "matches": 12, "size_a": [100, 50], "H": np.eye(3)},
             {"name": "p2", "matches": 9, "size_a": [100, 50], "H": np.eye(3)},
             {"name": "p.3", "matches": 20, "size_a": [100, 50], "H": None}]
    off = [[1, 0, 4.0], [0, 1, 3.0], [0, 0, 1]]  # every corner 5 px away
    runs = {"m": {"pairs": {"p1": {"H": np.eye(3), "inliers": 10}, "p2": {"H": off, "inliers": 6},
                            "p.3": {"H": np.eye(3), "inliers": 15}}, "dropped": []},
            "f": {"pairs": {"p2": {"H": np.eye(3), "inliers": 7}}, "dropped": [{"item": "p1", "reason": "x"}]}}
    c = compare_methods(pairs, runs, success_px=3.0)
    assert c["pairs"] == 3 and c["truth_pairs"] == 2
    m, f = c["all"]["m"], c["all"]["f"]
    # errors 0 and 5 px over the two truth pairs: median 2.5, one within 3 px
    assert m["median_corner_error_px"] == pytest.approx(2.5) and m["pairs_within"] == 1 and m["success_rate"] == 0.5
    assert m["mean_corner_error_px"] == pytest.approx(0.0) and m["median_inliers"] == 10.0 and m["failures"] == 0
    # a failure counts as an infinite error: the median of (inf, 0) is inf, so the key is left out (no NaN/inf)
    assert f["failures"] == 2 and f["pairs_within"] == 1 and "median_corner_error_px" not in f
    assert "corner_error_px" not in c["per_pair"]["p1"]["f"] and c["per_pair"]["p1"]["f"]["within"] == 0
    assert c["per_pair"]["p2"]["m"]["corner_error_px"] == pytest.approx(5.0)
    # the pair without truth has inliers but no accuracy keys
    assert set(c["per_pair"]["p.3"]["m"]) == {"inliers", "estimated"}
    metrics = metrics_of(c)["homography"]
    assert set(metrics["m"]) == {"all", "p1", "p2", "p_3"}  # no dots in the keys (DVC joins with dots)
    leaves = [v for meth in metrics.values() for item in meth.values() for v in item.values()]
    assert all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in leaves)
    plots = quality_plots(c)
    assert len(plots["inliers"]) == 6 and len(plots["corner_error"]) == 3  # f failed p1; p.3 has no truth
    no_truth = compare_methods([dict(q, H=None) for q in pairs], runs)
    assert all(set(s) == {"pairs", "estimated", "failures", "median_inliers"} for s in no_truth["all"].values())


def test_synthetic_scene_has_the_requested_outliers():
    rng = np.random.default_rng(0)
    H, src, dst = bench.synthetic_scene(rng, 500, 0.8, noise=1.0)
    err = np.linalg.norm(transform_points(H, src) - dst, axis=1)
    # 100 inliers with 1 px noise (2-D: 99.99 % within 4.3 px); uniform outliers land within 4.3 px only by chance
    assert 95 <= (err < 4.3).sum() <= 110


def test_bench_ground_truth_directions(data_root):
    pairs = bench.real_pairs(data_root)
    assert {p["set"] for p in pairs} == {"oxford", "cmp"}
    assert sum(p["set"] == "oxford" for p in pairs) == 23 and sum(p["set"] == "cmp" for p in pairs) == 16
    cmp_root = data_root / "cmp_homogr"
    for p in pairs:
        if p["set"] != "cmp":
            continue
        v = np.loadtxt(cmp_root / "derived" / f"{p['name']}_vpts.txt")
        # the hand-clicked validation points (xA yA xB yB) must map A -> B under the H the bench uses
        assert np.abs(transform_points(p["H"], v[:, :2]) - v[:, 2:]).max() < 1e-3, p["name"]


def test_bench_synthetic_smoke(capsys):
    assert cli.main(["bench", "homography", "--no-real", "--synthetic-points", "200", "--synthetic-trials", "2",
                     "--outliers", "0.5", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    row = out["synthetic"][0]
    assert row["outliers"] == 0.5 and set(row["methods"]) == {"ours", "opencv_ransac", "opencv_magsac"}
    # 1 px noise and 100 inliers: every method is sub-pixel at the corners of a 640x480 image
    assert all(m["median_corner_error_px"] < 1.0 for m in row["methods"].values())
    assert row["ratio_ours_magsac_wall"] > 0


def test_bench_rejects_bad_arguments(capsys):
    assert cli.main(["bench", "homography", "--no-real", "--outliers", "1.0"]) == 2
    assert "`--outliers` values must be in [0, 1)" in capsys.readouterr().err
    assert cli.main(["bench", "homography", "--data", "/nonexistent/x", "--no-synthetic"]) == 2


def _stage(tmp_path, *args):
    """Run ``python -m stages.<args>`` from ``tmp_path`` with relative paths, as dvc runs it from the repo root."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", *args], cwd=tmp_path, env=env, capture_output=True, text=True,
                          check=True)


def test_stages_end_to_end_with_and_without_truth(tmp_path, pair_files):
    """features -> match -> estimate -> report on a folder with a NAME_a/NAME_b pair that has truth, a subfolder
    pair without truth, an unreadable image and a half pair; then the report again with no truth file at all."""
    a, b, (w, h) = pair_files
    images = tmp_path / "images"
    (images / "sub").mkdir(parents=True)
    (images / "p_a.png").write_bytes(a.read_bytes())
    (images / "p_b.png").write_bytes(b.read_bytes())
    (images / "sub" / "one.png").write_bytes(a.read_bytes())
    (images / "sub" / "two.png").write_bytes(b.read_bytes())
    (images / "broken_a.png").write_bytes(b"not an image")
    (images / "broken_b.png").write_bytes(b.read_bytes())
    (images / "alone_a.png").write_bytes(a.read_bytes())
    io.save_json(images / "truth.json", {"pairs": [{"name": "p", "H": H_AB}]})
    (tmp_path / "params.yaml").write_text((ROOT / "params.yaml").read_text())
    _stage(tmp_path, "stages.features", "--images", "images", "--out", "feats", "--section", "homography.features")
    assert io.load_json(tmp_path / "feats" / "dropped.json")[0]["item"] == "broken_a.png"
    log = _stage(tmp_path, "stages.homography_match", "--images", "images", "--features", "feats", "--out", "m").stdout
    assert "dropped 2" in log and "alone_a.png" in log and "not a readable image" in log
    assert sorted(f.name for f in (tmp_path / "m").glob("*.npz")) == ["p.npz", "sub.npz"]
    for method in ("ours", "opencv_magsac"):
        _stage(tmp_path, "stages.homography_estimate", "--matches", "m", "--method", method, "--out", f"est/{method}")
    first = (tmp_path / "est/ours/estimates.json").read_bytes()
    _stage(tmp_path, "stages.homography_estimate", "--matches", "m", "--method", "ours", "--out", "est/ours")
    assert (tmp_path / "est/ours/estimates.json").read_bytes() == first  # seeded: a rerun is byte-identical
    assert b"time" not in first and b"seconds" not in first  # times only in the uncached timings
    assert io.load_json(tmp_path / "outputs/timings/homography_estimate@ours.json")["seconds"]["total"] > 0

    def report():
        _stage(tmp_path, "stages.homography_report", "--images", "images", "--matches", "m", "--estimates",
               "est/ours", "est/opencv_magsac", "--out", "report", "--metrics", "metrics.json", "--summary",
               "summary.json", "--plots", "plots")
        return (io.load_json(tmp_path / "details.json")["homography"],
                validate_summary(io.load_json(tmp_path / "summary.json")))

    metrics, summary = report()
    assert set(metrics) == {"ours", "opencv_magsac"}
    for method in metrics:
        # same 1 px tolerance as the CLI test: an easy synthetic warp
        assert metrics[method]["p"]["corner_error_px"] < 1.0 and metrics[method]["all"]["pairs_within"] == 1
        assert "corner_error_px" not in metrics[method]["sub"] and metrics[method]["sub"]["inliers"] >= 4
    assert io.read_image(tmp_path / "report" / "p.png").shape[1] == 3 * 400  # truth + two methods
    assert io.read_image(tmp_path / "report" / "sub.png").shape[1] == 2 * 400  # no truth: the methods only
    not_processed = next(t for t in summary["tables"] if t["title"] == "Not processed")
    assert {r[0] for r in not_processed["rows"]} == {"alone_a.png", "broken"}
    assert {r["pair"] for r in io.load_json(tmp_path / "plots" / "corner_error.json")} == {"p"}
    assert "1 of 2 pairs have a true homography" in summary["description"]
    assert "Without ground truth (inliers only): sub." in summary["description"]

    (images / "truth.json").unlink()
    metrics, summary = report()
    assert all("success_rate" not in m["all"] and "corner_error_px" not in m["p"] for m in metrics.values())
    assert "no ground truth" in summary["description"] and io.load_json(tmp_path / "plots" / "corner_error.json") == []
    assert io.read_image(tmp_path / "report" / "p.png").shape[1] == 2 * 400


def _stage_in_process(monkeypatch, cwd, module, *args):
    """Run ``python -m stages.<module> ARGS`` in this process from ``cwd``; return its exit status."""
    import runpy

    (cwd / "params.yaml").write_text((ROOT / "params.yaml").read_text())
    monkeypatch.chdir(cwd)
    monkeypatch.setattr(sys, "argv", [f"stages.{module}", *args])
    with pytest.raises(SystemExit) as exc:
        runpy.run_module(f"stages.{module}", run_name="__main__")
    return exc.value.code


def test_a_cut_off_cached_npz_fails_the_stage_with_one_line_naming_it(tmp_path, monkeypatch, capsys):
    io.save_npz(tmp_path / "m" / "p.npz", src=np.zeros((8, 2)), dst=np.zeros((8, 2)))
    data = (tmp_path / "m" / "p.npz").read_bytes()
    (tmp_path / "m" / "p.npz").write_bytes(data[:len(data) // 2])  # a copy or a disk cut short
    assert _stage_in_process(monkeypatch, tmp_path, "homography_estimate", "--matches", "m", "--method", "ours",
                             "--out", "est") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("homography_estimate@ours: error: m/p.npz: not a readable .npz archive")
    assert err[0].endswith("; expected an .npz holding `src`, `dst`")
    assert not (tmp_path / "est" / "estimates.json").exists()


def test_cached_features_without_an_expected_array_fail_the_stage_naming_it(tmp_path, monkeypatch, capsys,
                                                                            textured_image):
    from cvpipe.features import NPZ_ARRAYS, detect_item
    from cvpipe.params import FeaturesParams

    arrays, _ = detect_item((textured_image, False), FeaturesParams())
    (tmp_path / "images").mkdir()
    for side in ("a", "b"):
        cv2.imwrite(str(tmp_path / "images" / f"p_{side}.png"), textured_image)
        io.save_npz(tmp_path / "feats" / f"p_{side}.npz", **arrays)
    io.save_json(tmp_path / "feats" / "dropped.json", [])
    io.save_npz(tmp_path / "feats" / "p_b.npz", **{k: v for k, v in arrays.items() if k != "detector"})
    assert _stage_in_process(monkeypatch, tmp_path, "homography_match", "--images", "images", "--features", "feats",
                             "--out", "m") == 2
    err = capsys.readouterr().err.strip().splitlines()
    expected = ", ".join(f"`{k}`" for k in NPZ_ARRAYS)
    assert err == [f"homography_match: error: feats/p_b.npz: missing array(s) `detector`; expected an .npz holding "
                   f"{expected}"]
    assert not (tmp_path / "m").exists()


def test_cli_and_bench_argument_checks(pair_files, capsys):
    a, b, _ = pair_files
    assert cli.main(["homography", str(a), str(b), "--max-features", "0"]) == 2
    assert "`--max-features` must be in [1, 1000000], got 0" in capsys.readouterr().err
    assert cli.main(["homography", str(a), str(b), "--ratio", "1.5"]) == 2
    assert "`--ratio` must be in (0.0, 1.0], got 1.5" in capsys.readouterr().err
    assert cli.main(["bench", "homography", "--no-real", "--repeats", "0"]) == 2
    assert "`--repeats` must be >= 1" in capsys.readouterr().err
    assert cli.main(["bench", "homography", "--no-real", "--synthetic-trials", "0"]) == 2
    assert "`--synthetic-trials` must be >= 1" in capsys.readouterr().err


@pytest.mark.parametrize("cls, mapping, message", [
    ("HomographyEstimateParams", {"threshold": 0.0}, r"`homography\.x\.threshold` must be in \(0\.0, 100\.0\]"),
    ("HomographyEstimateParams", {"confidence": 1.0},
     r"`homography\.x\.confidence` must be in \(0\.0, 1\.0\), got 1\.0"),
    ("HomographyEstimateParams", {"max_iters": 0}, r"`homography\.x\.max_iters` must be in \[1, 10000000\]"),
    ("HomographyReportParams", {"success_px": -1.0}, r"`homography\.x\.success_px` must be in \(0\.0, inf\)"),
    ("HomographyReportParams", {"checker_tiles": 0}, r"`homography\.x\.checker_tiles` must be in \[1, 256\]"),
])
def test_homography_params_ranges(cls, mapping, message):
    from cvpipe import params

    with pytest.raises(InputError, match=message):
        params.from_mapping(getattr(params, cls), mapping, "homography.x")
