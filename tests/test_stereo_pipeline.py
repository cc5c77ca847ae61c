"""The stereo stages rectify -> disparity -> depth -> report, run in process on a small folder: an already rectified
pair with truth, an unrectified pair with its Middlebury calib.txt, and a pair that cannot be rectified (a planar
scene). Accuracy is checked against the known geometry of the samples."""

import runpy
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from cvpipe import geometry, io, samples
from cvpipe.stereo import depth
from cvpipe.report import validate_summary


def _stage(module: str, *argv: str) -> None:
    """Run ``python -m <module> <argv>`` in this process (the runner ends with sys.exit: status 0 expected)."""
    old = sys.argv
    sys.argv = [module, *argv]
    try:
        with pytest.raises(SystemExit) as done:
            runpy.run_module(module, run_name="__main__")
    finally:
        sys.argv = old
    assert done.value.code == 0, f"{module} exited with {done.value.code}"


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _rig():
    """Left and right camera matrices of the motorcycle rig and a rotation of its right camera (1.5, 1, -1 deg)."""
    c = samples.MOTORCYCLE_CALIB
    K1 = np.array([[c["focal"], 0, c["cx"]], [0, c["focal"], c["cy"]], [0, 0, 1.0]])
    K2 = K1.copy()
    K2[0, 2] += c["doffs"]
    Rr = cv2.Rodrigues(np.radians([1.5, 1.0, -1.0]))[0]
    return K1, K2, Rr


def _true_depth(truth: np.ndarray) -> np.ndarray:
    """Z = f B / (d + doffs) of the original left pixels (NaN where the disparity is unknown)."""
    c = samples.MOTORCYCLE_CALIB
    return (c["focal"] * c["baseline"] / (truth + c["doffs"])).astype(np.float32)


def _depth_error(z: np.ndarray, z_true: np.ndarray, H_left) -> np.ndarray:
    """Relative error of the depth map ``z`` (rectified frame) against ``z_true`` moved into that frame."""
    moved = cv2.warpPerspective(np.nan_to_num(z_true, nan=0.0), np.asarray(H_left, float), z.shape[::-1],
                                flags=cv2.INTER_NEAREST)
    both = np.isfinite(z) & (moved > 0)
    return np.abs(z[both] - moved[both]) / moved[both]


@pytest.fixture(scope="module")
def pipeline(tmp_path_factory, repo_root):
    """The folder, the params.yaml copy and one run of every stage (cwd = the folder, as dvc runs them)."""
    root = tmp_path_factory.mktemp("stereo_pipeline")
    pairs = root / "pairs"
    rect = samples.make_stereo()
    for name, img in rect.images.items():
        io.save_image(pairs / "bike" / name, img)
    io.save_npz(pairs / "bike" / "truth.npz", **rect.arrays["truth.npz"])
    io.save_json(pairs / "bike" / "truth.json", rect.truth)
    unrect, texts = samples.make_stereo_unrectified(np.random.default_rng(3), name="tilted")
    for name, img in unrect.images.items():
        io.save_image(pairs / name, img)
    io.save_npz(pairs / "tilted" / "truth.npz", **unrect.arrays["tilted/truth.npz"])
    for name, text in texts.items():
        (pairs / name).write_text(text)
    # a calibrated rig: the motorcycle's right camera turned about all three axes, with an OpenCV calibration file
    # that holds the pose (X_right = R X_left + T)
    K1, K2, Rr = _rig()
    io.save_image(pairs / "rig" / "left.png", rect.images["left.png"])
    h, w = rect.images["left.png"].shape[:2]
    io.save_image(pairs / "rig" / "right.png", cv2.warpPerspective(rect.images["right.png"], K2 @ Rr @ np.linalg.inv(K2),
                                                                   (w, h), flags=cv2.INTER_CUBIC))
    fs = cv2.FileStorage(".yml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    for key, value in (("K1", K1), ("D1", np.zeros((1, 5))), ("K2", K2), ("D2", np.zeros((1, 5))), ("R", Rr),
                       ("T", (-Rr @ [samples.MOTORCYCLE_CALIB["baseline"], 0.0, 0.0]).reshape(3, 1))):
        fs.write(key, np.asarray(value, np.float64))
    fs.write("image_width", w)
    fs.write("image_height", h)
    (pairs / "rig" / "calib.yml").write_text(fs.releaseAndGetString())
    # a planar scene: the second view is a homography of the first, so there is no epipolar geometry to find
    wall = samples.fit(samples.photo("astronaut"), 480, 360)
    H = np.array([[0.97, 0.05, 12.0], [-0.04, 0.98, 9.0], [1e-5, 2e-5, 1.0]])
    io.save_image(pairs / "wall" / "left.png", wall)
    io.save_image(pairs / "wall" / "right.png", cv2.warpPerspective(wall, H, (480, 360)))
    (root / "params.yaml").write_text((repo_root / "params.yaml").read_text())
    old = Path.cwd()
    import os

    os.chdir(root)
    try:
        _stage("stages.stereo_rectify", "--pairs", "pairs", "--out", "out/rectified", "--metrics", "metrics_rect.json")
        first = _tree(root / "out/rectified")
        _stage("stages.stereo_rectify", "--pairs", "pairs", "--out", "out/rectified", "--metrics", "metrics_rect.json")
        for method in ("opencv_sgbm", "opencv_bm"):
            _stage("stages.stereo_disparity", "--pairs", "pairs", "--rectified", "out/rectified", "--method", method,
                   "--out", f"out/{method}", "--metrics", f"metrics_{method}.json")
        _stage("stages.stereo_depth", "--rectified", "out/rectified", "--disparities", "out/opencv_sgbm", "--out",
               "out/depth", "--metrics", "metrics_depth.json")
        depth_first = _tree(root / "out/depth")
        _stage("stages.stereo_depth", "--rectified", "out/rectified", "--disparities", "out/opencv_sgbm", "--out",
               "out/depth", "--metrics", "metrics_depth.json")
        _stage("stages.stereo_report", "--pairs", "pairs", "--rectified", "out/rectified", "--disparities",
               "out/opencv_sgbm", "out/opencv_bm", "--depth", "out/depth", "--out", "out/report", "--summary",
               "summary.json", "--plots", "plots")
    finally:
        os.chdir(old)
    return {"root": root, "unrect": unrect, "first": first, "depth_first": depth_first}


def test_rectify_kinds_and_the_dropped_pair(pipeline):
    root = pipeline["root"]
    run = io.load_json(root / "out/rectified/run.json")
    assert run["pairs"]["bike"]["kind"] == "none"  # already rectified: a no-op, identity homographies
    assert np.array_equal(np.array(run["pairs"]["bike"]["H_left"]), np.eye(3))
    same = io.read_image(root / "out/rectified/bike/left.png"), io.read_image(root / "pairs/bike/left.png")
    assert np.array_equal(*same)
    assert run["pairs"]["tilted"]["kind"] == "uncalibrated"  # calib.txt of a rectified rig holds no pose
    assert [d["item"] for d in run["dropped"]] == ["wall"]
    assert "cannot be rectified" in run["dropped"][0]["reason"] and "planar" in run["dropped"][0]["reason"]
    m = io.load_json(root / "details_rect.json")["stereo"]["rectify"]
    # the rectification's targets: median vertical error <= 0.3 px and p95 <= 1 px on the inlier matches
    assert m["tilted"]["vertical_error_median_px"] <= 0.3 and m["tilted"]["vertical_error_p95_px"] <= 1.0
    assert m["tilted"]["rectified"] == 1 and m["bike"]["rectified"] == 0 and "wall" not in m
    assert m["rig"]["calibrated"] == 1 and m["tilted"]["calibrated"] == 0


def test_rectification_undoes_the_known_transform(pipeline):
    """Carried through the truth, a left pixel and its true right match land on the same rectified row."""
    root = pipeline["root"]
    rec = io.load_json(root / "out/rectified/tilted/rect.json")
    arrays = pipeline["unrect"].arrays["tilted/truth.npz"]
    disp, H_un = arrays["disparity"], arrays["H_unrectify"]
    ys, xs = np.nonzero(np.isfinite(disp))
    pick = np.random.default_rng(0).choice(len(xs), 2000, replace=False)
    x, y = xs[pick].astype(float), ys[pick].astype(float)
    right = geometry.apply_homography(H_un, np.column_stack([x - disp[ys[pick], xs[pick]], y]))
    ql = geometry.apply_homography(np.array(rec["H_left"]), np.column_stack([x, y]))
    qr = geometry.apply_homography(np.array(rec["H_right"]), right)
    dy = np.abs(ql[:, 1] - qr[:, 1])
    # true correspondences (not just the matches the fit used): same 0.3 / 1 px targets as the benchmark
    assert np.median(dy) <= 0.3 and np.percentile(dy, 95) <= 1.0
    d = ql[:, 0] - qr[:, 0]
    assert np.percentile(d, 1) >= 0 and np.percentile(d, 99) < rec["max_disp"]  # the search range covers it


def test_disparity_uses_truth_only_in_its_own_frame(pipeline):
    root = pipeline["root"]
    m = io.load_json(root / "details_opencv_sgbm.json")["stereo"]["opencv_sgbm"]
    assert m["bike"]["truth"] == 1 and "bad_2" in m["bike"]
    assert m["tilted"]["truth"] == 0 and "bad_2" not in m["tilted"]  # its truth.npz is in the original frame
    run = io.load_json(root / "out/opencv_sgbm/run.json")
    # bike: its truth.json max_disp; tilted: its calib.txt ndisp (the pair's own value wins over the estimate)
    assert run["max_disp_from"] == {"bike": "pair", "rig": "rectification", "tilted": "pair"}
    # measured 0.18 for OpenCV SGBM on the bundled motorcycle pair: 0.3 leaves room, a broken frame gives > 0.6
    assert m["bike"]["bad_2"] < 0.3


def test_depth_and_point_cloud(pipeline):
    root = pipeline["root"]
    run = io.load_json(root / "out/depth/run.json")
    assert run["disparity_only"] == ["bike"] and set(run["pairs"]) == {"rig", "tilted"}  # bike: no calibration
    z = np.load(root / "out/depth/tilted/depth.npy", allow_pickle=False)
    assert z.dtype == np.float32 and np.isfinite(z).mean() > 0.5
    # the true depth of the original left pixels moved into the rectified frame: SGBM's disparity is good to ~1 px
    # at d + doffs ~ 60-90 px (1-2 %), and the estimated rectification's focal length and doffs add a few %:
    # median relative error under 5 %
    truth = pipeline["unrect"].arrays["tilted/truth.npz"]["disparity"]
    H_left = io.load_json(root / "out/rectified/tilted/rect.json")["H_left"]
    assert np.median(_depth_error(z, _true_depth(truth), H_left)) < 0.05
    header, pts = depth.parse_ply((root / "out/depth/tilted/cloud.ply").read_bytes())
    assert len(pts) == np.isfinite(z).sum() and any("mm" in h for h in header)
    assert np.allclose(np.sort(pts["z"]), np.sort(z[np.isfinite(z)]))
    left = io.read_image(root / "out/rectified/tilted/left.png")
    v, u = np.nonzero(np.isfinite(z))
    assert np.array_equal(pts["red"], left[v, u, 2]) and np.array_equal(pts["blue"], left[v, u, 0])
    pic = io.read_image(root / "out/depth/tilted/depth.png")
    assert pic.shape[0] == z.shape[0] and pic.shape[1] > z.shape[1]  # the colour bar is beside the map


def test_calibrated_rig(pipeline):
    """An OpenCV calibration with the pose: calibrated rectification, rows aligned, metric depth against the truth."""
    root = pipeline["root"]
    rec = io.load_json(root / "out/rectified/rig/rect.json")
    assert rec["kind"] == "calibrated" and rec["depth"]["exact"] is True
    assert rec["vertical_error_median_px"] <= 0.3  # the matches (p95: stray matches within 2 px of a row count)
    # the true correspondences (left (x, y) <-> original right (x - d, y), turned by the rig's rotation) land on
    # one rectified row: the pose is exact, so the 0.3 / 1 px targets hold
    K1, K2, Rr = _rig()
    truth = io.load_npz(root / "pairs/bike/truth.npz")["disparity"]
    ys, xs = np.nonzero(np.isfinite(truth))
    pick = np.random.default_rng(0).choice(len(xs), 2000, replace=False)
    x, y = xs[pick].astype(float), ys[pick].astype(float)
    right = geometry.apply_homography(K2 @ Rr @ np.linalg.inv(K2), np.column_stack([x - truth[ys[pick], xs[pick]], y]))
    dy = np.abs(geometry.apply_homography(np.array(rec["H_left"]), np.column_stack([x, y]))[:, 1]
                - geometry.apply_homography(np.array(rec["H_right"]), right)[:, 1])
    assert np.median(dy) <= 0.3 and np.percentile(dy, 95) <= 1.0
    assert io.load_json(root / "out/opencv_sgbm/run.json")["max_disp_from"]["rig"] == "rectification"
    z = np.load(root / "out/depth/rig/depth.npy", allow_pickle=False)
    truth = io.load_npz(root / "pairs/bike/truth.npz")["disparity"]
    # the rectified left camera is turned by about half the right camera's rotation (~1 deg): its Z differs from
    # the original camera's by well under 2 % in the image; with SGBM's ~1-2 %, the median stays under 5 %
    assert np.median(_depth_error(z, _true_depth(truth), rec["H_left"])) < 0.05


def test_reruns_are_byte_identical(pipeline):
    root = pipeline["root"]
    assert _tree(root / "out/rectified") == pipeline["first"]
    assert _tree(root / "out/depth") == pipeline["depth_first"]


def test_report_summary(pipeline):
    root = pipeline["root"]
    summary = validate_summary(io.load_json(root / "summary.json"))
    dropped = next(t for t in summary["tables"] if t["title"] == "Not processed")["rows"]
    assert [r[0] for r in dropped] == ["wall"]
    assert "disparity only for bike" in summary["description"]
    assert "bad-2.0 is reported only for pairs that needed no rectification" in summary["description"]
    per_pair = next(t for t in summary["tables"] if t["title"] == "Per pair")["rows"]
    assert all("truth not in the rectified frame" in row for row in per_pair if row[0] == "tilted")
    for pic in summary["pictures"]:
        assert (root / pic["path"]).is_file(), pic
    names = {Path(p["path"]).name for p in summary["pictures"]}
    assert {"tilted_rectified.png", "tilted_depth.png", "bike_rectified.png", "bike.png", "tilted.png"} <= names
    assert "tilted_depth.png" in names and "bike_depth.png" not in names
    assert {r["pair"] for r in io.load_json(root / "plots/vertical_error.json")} == {"bike", "rig", "tilted"}


def _middlebury_text(**change: str) -> str:
    """The motorcycle rig's Middlebury calib.txt (741x500), with some values changed."""
    c = samples.MOTORCYCLE_CALIB
    values = {"cam0": f"[{c['focal']} 0 {c['cx']}; 0 {c['focal']} {c['cy']}; 0 0 1]",
              "cam1": f"[{c['focal']} 0 {c['cx'] + c['doffs']}; 0 {c['focal']} {c['cy']}; 0 0 1]",
              "doffs": str(c["doffs"]), "baseline": str(c["baseline"]), "width": "741", "height": "500", "ndisp": "64"}
    values.update(change)
    return "".join(f"{k}={v}\n" for k, v in values.items())


def test_bad_calibrations_drop_their_pair_and_the_others_go_on(tmp_path, repo_root):
    """stereo_rectify drops a pair whose calibration file is refused (too big, nested 40,000 levels deep, a value
    out of range), naming the file and the key; stereo_depth drops a pair whose calibration gives no usable depth.
    stereo_rectify runs in a child process: a parser crash there must not take pytest with it."""
    import os
    import subprocess

    rect = samples.make_stereo()
    calibs = {
        "good": ("calib.txt", _middlebury_text()),
        "absurd": ("calib.txt", _middlebury_text(cam0="[1e300 0 311.193; 0 1e300 254.877; 0 0 1]")),
        "wide": ("calib.txt", _middlebury_text(width="1e400")),
        "k1list": ("calib.yml", "%YAML:1.0\nK1: [1, 2, 3]\n"),
        "deep": ("calib.yml", "%YAML:1.0\nK1: " + "[" * 40_000 + "]" * 40_000 + "\n"),
        "huge": ("calib.txt", "# padding\n" * 200_000 + _middlebury_text()),
    }
    for pair, (name, text) in calibs.items():
        for side in ("left.png", "right.png"):
            io.save_image(tmp_path / "pairs" / pair / side, rect.images[side])
        (tmp_path / "pairs" / pair / name).write_text(text)
    (tmp_path / "params.yaml").write_text((repo_root / "params.yaml").read_text())
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(repo_root), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-m", "stages.stereo_rectify", "--pairs", "pairs", "--out",
                           "out/rectified", "--metrics", "metrics_rect.json"], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    run = io.load_json(tmp_path / "out/rectified/run.json")
    assert set(run["pairs"]) == {"good", "absurd"}
    reasons = {d["item"]: d["reason"] for d in run["dropped"]}
    assert set(reasons) == {"wide", "k1list", "deep", "huge"}
    for pair, fragment in (("wide", "`width` must be an integer in [2, 1000000], got '1e400'"),
                           ("k1list", "`K1` must be a 3x3 matrix"), ("deep", "over the limit of 64"),
                           ("huge", "larger than the limit of 1000000 bytes")):
        assert calibs[pair][0] in reasons[pair] and pair in reasons[pair] and fragment in reasons[pair], reasons
        assert "\n" not in reasons[pair]
        assert not (tmp_path / "out/rectified" / pair).exists()
    old = Path.cwd()
    os.chdir(tmp_path)
    try:
        _stage("stages.stereo_disparity", "--pairs", "pairs", "--rectified", "out/rectified", "--method",
               "opencv_bm", "--out", "out/opencv_bm", "--metrics", "metrics_bm.json")
        _stage("stages.stereo_depth", "--rectified", "out/rectified", "--disparities", "out/opencv_bm", "--out",
               "out/depth", "--metrics", "metrics_depth.json")
    finally:
        os.chdir(old)
    run = io.load_json(tmp_path / "out/depth/run.json")
    assert set(run["pairs"]) == {"good"}
    (dropped,) = run["dropped"]
    assert dropped["item"] == "absurd"
    assert "absurd/calib.txt: no pixel has a usable depth: `focal` 1e+300" in dropped["reason"]
    assert not (tmp_path / "out/depth/absurd").exists()
