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
from cvpipe.homography import alignment_checkerboard, alignment_panel, summarize_methods, transform_points
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
    assert "`threshold` must be a finite number > 0" in capsys.readouterr().err
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


def test_summarize_methods():
    truth = [{"name": "p1", "H": np.eye(3).tolist(), "size_a": [100, 50]},
             {"name": "p2", "H": np.eye(3).tolist(), "size_a": [100, 50]}]
    off = [[1, 0, 4.0], [0, 1, 3.0], [0, 0, 1]]  # every corner 5 px away
    runs = {"m": {"p1": {"H": np.eye(3), "inliers": 10, "matches": 12, "time_ms": 1.0},
                  "p2": {"H": off, "inliers": 6, "matches": 9, "time_ms": 3.0}},
            "f": {"p1": {"H": None, "inliers": 0, "matches": 3}, "p2": {"H": np.eye(3), "inliers": 7, "matches": 9,
                                                                        "time_ms": 2.0}}}
    metrics, per_pair = summarize_methods(truth, runs, success_px=3.0)
    assert metrics["m"]["median_corner_error_px"] == pytest.approx(2.5)
    assert metrics["m"]["pairs_within"] == 1 and metrics["m"]["success_rate"] == 0.5
    assert metrics["m"]["median_time_ms"] == 2.0 and metrics["m"]["median_inliers"] == 8.0
    assert metrics["f"]["failures"] == 1 and metrics["f"]["pairs_within"] == 1
    assert per_pair["p1"]["f"]["corner_error_px"] is None
    assert per_pair["p2"]["m"]["corner_error_px"] == pytest.approx(5.0)


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


def test_estimate_and_report_stages(tmp_path, pair_files):
    """The two stage scripts end to end on one pair laid out like data/samples/homography."""
    from cvpipe.homography import correspondences

    a, b, (w, h) = pair_files
    images = tmp_path / "images"
    images.mkdir()
    (images / "p_a.png").write_bytes(a.read_bytes())
    (images / "p_b.png").write_bytes(b.read_bytes())
    truth = tmp_path / "truth.json"
    io.save_json(truth, {"pairs": [{"name": "p", "a": "p_a.png", "b": "p_b.png", "H": H_AB, "size_a": [w, h]}]})
    src, dst = correspondences(io.read_image(a, "gray"), io.read_image(b, "gray"))
    io.save_npz(tmp_path / "matches" / "p.npz", src=src, dst=dst)
    (tmp_path / "params.yaml").write_text((ROOT / "params.yaml").read_text())
    # run from tmp_path with relative paths, as dvc runs them from the repository root
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = [sys.executable, "-m"]
    for method in ("ours", "opencv_magsac"):
        subprocess.run(run + ["stages.homography_estimate", "--truth", "truth.json", "--matches", "matches",
                              "--method", method, "--out", f"est/{method}"], check=True, cwd=tmp_path, env=env)
    subprocess.run(run + ["stages.homography_report", "--truth", "truth.json", "--images", "images",
                          "--estimates", "est/ours", "est/opencv_magsac", "--metrics", "metrics.json",
                          "--out", "report", "--summary", "summary.json"], check=True, cwd=tmp_path, env=env)
    metrics = io.load_json(tmp_path / "metrics.json")
    assert set(metrics) == {"ours", "opencv_magsac"}
    # same 1 px tolerance as the CLI test: an easy synthetic warp
    assert metrics["ours"]["median_corner_error_px"] < 1.0 and metrics["ours"]["pairs_within"] == 1
    pic = io.read_image(tmp_path / "report" / "p.png")
    assert pic.shape[1] == 3 * 400  # truth + two methods
    from cvpipe.report import validate_summary

    summary = validate_summary(io.load_json(tmp_path / "summary.json"))
    assert summary["task"] == "homography" and set(summary["timings"]) == {"ours", "opencv_magsac"}


def test_cli_and_bench_argument_checks(pair_files, capsys):
    a, b, _ = pair_files
    assert cli.main(["homography", str(a), str(b), "--max-features", "0"]) == 2
    assert "`--max-features` must be >= 1" in capsys.readouterr().err
    assert cli.main(["homography", str(a), str(b), "--ratio", "1.5"]) == 2
    assert "`--ratio` must be in (0, 1]" in capsys.readouterr().err
    assert cli.main(["bench", "homography", "--no-real", "--repeats", "0"]) == 2
    assert "`--repeats` must be >= 1" in capsys.readouterr().err
    assert cli.main(["bench", "homography", "--no-real", "--synthetic-trials", "0"]) == 2
    assert "`--synthetic-trials` must be >= 1" in capsys.readouterr().err


@pytest.mark.parametrize("cls, mapping, message", [
    ("HomographyEstimateParams", {"threshold": 0.0}, r"`threshold` must be in \(0\.0, inf\]"),
    ("HomographyEstimateParams", {"confidence": 1.0}, r"`confidence` must be in \(0, 1\), got 1\.0"),
    ("HomographyEstimateParams", {"max_iters": 0}, r"`max_iters` must be in \[1, 10000000\]"),
    ("HomographyReportParams", {"success_px": -1.0}, r"`success_px` must be in \(0\.0, inf\]"),
    ("HomographyReportParams", {"checker_tiles": 0}, r"`checker_tiles` must be in \[1, 256\]"),
])
def test_homography_params_ranges(cls, mapping, message):
    from cvpipe import params

    with pytest.raises(InputError, match=message):
        params.from_mapping(getattr(params, cls), mapping, "homography.x")
