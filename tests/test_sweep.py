"""The bad-input sweep as a table: input class x command -> exit status and a fragment of the one error line.

Every run checks the whole contract of README's "Errors" section: the exit status, exactly one ``cvpipe: error:``
line on stderr (none on success) and no traceback, exactly one JSON document on stdout (``{"error", "file",
"exit"}`` on failure), and the files left behind (the output only on success, with the umask's mode, and never a
temporary). A new command joins by adding its argv to ``COMMANDS`` and its column to ``EXPECTED``.
"""

from __future__ import annotations

import json
import os
import resource
import stat
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from cvpipe import cli

sys.path.insert(0, str(Path(__file__).parent))
from sweep_inputs import make, texture  # noqa: E402

CLASSES = ["missing", "folder", "empty", "not_an_image", "truncated", "1x1", "blank", "16bit", "alpha", "grey",
           "exif_rotated", "over_limit"]
COMMANDS = ["logo", "hough", "inspect", "homography", "stereo", "stitch"]

#: (exit, fragment of the error line) per class; per-command exceptions in _EXCEPT. Exit 0 = a result.
_BY_CLASS = {
    "missing": (2, "no such file"),
    "folder": (2, "is a folder"),
    "empty": (2, "file is empty"),
    "not_an_image": (2, "not a readable image"),
    "truncated": (2, "truncated image file"),
    "1x1": (2, "too small"),
    "over_limit": (2, "exceeds the limit of 100000000 pixels"),
    # a blank photo has no keypoints and no edges: no lines, no logo, no disparity are answers; registration
    # cannot be done, which is "no result" (exit 1) and says why
    "blank": (0, None),
    # valid images in other layouts: every command reads them like the 8-bit colour original
    "16bit": (0, None),
    "alpha": (0, None),
    "grey": (0, None),
    "exif_rotated": (0, None),
}
_EXCEPT = {
    ("blank", "inspect"): (1, "the probe is blank"),
    ("blank", "homography"): (1, "only 0 matches"),
    ("blank", "stitch"): (1, "no two images share enough features"),
}
EXPECTED = {(k, c): _EXCEPT.get((k, c), _BY_CLASS[k]) for k in CLASSES for c in COMMANDS}


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """Good inputs: views A and B of one textured scene (B shifted 100 px: homography and stitch), a stereo right
    view R (shifted 8 px: disparity 8), and a gallery whose one brand is a crop of B."""
    root = tmp_path_factory.mktemp("sweep")
    t = texture(240, 440, seed=1)
    views = {"a": t[:, :320].copy(), "b": t[:, 100:420].copy(), "r": t[:, 8:328].copy()}
    good = {k: make("good", v, root / "good", k) for k, v in views.items()}
    gallery = root / "gallery"
    gallery.mkdir()
    cv2.imwrite(str(gallery / "brand.png"), views["b"][60:200, 120:260])
    return {"root": root, "views": views, "good": good, "gallery": gallery}


def argv_for(command: str, bad: dict[str, Path], world: dict, out: Path) -> tuple[list[str], Path | None]:
    """The command line with the input under test in its first image slot, and the output file it writes."""
    g = world["good"]
    table = {
        "logo": (["logo", bad["a"], "--gallery", world["gallery"], "--json"], None),
        "hough": (["hough", bad["a"], "--json"], None),
        "inspect": (["inspect", g["a"], bad["a"], "--out", out, "--json"], None),
        "homography": (["homography", bad["a"], g["b"], "--json"], None),
        "stereo": (["stereo", bad["a"], bad["r"], "--max-disp", "16", "-o", out / "disp.npy", "--json"],
                   out / "disp.npy"),
        "stitch": (["stitch", bad["a"], bad["b"], "-o", out / "pano.png", "--json"], out / "pano.png"),
    }
    argv, product = table[command]
    return [str(a) for a in argv], product


def check_contract(code, out_text, err_text, expected, bad_path, out_dir, product):
    """The assertions shared by the in-process and the subprocess sweep."""
    exit_code, fragment = expected
    assert code == exit_code, (code, err_text)
    assert "Traceback" not in err_text
    errors = [ln for ln in err_text.splitlines() if ln.startswith("cvpipe: error:")]
    # our own lines only: errors and notes
    others = [ln for ln in err_text.splitlines() if ln.strip() and not ln.startswith(("cvpipe: error:",
                                                                                        "cvpipe: note:"))]
    assert not others, others
    doc = json.loads(out_text)  # exactly one JSON document (json.loads refuses trailing data)
    if exit_code == 0:
        assert not errors
    else:
        assert len(errors) == 1 and fragment in errors[0], errors
        if isinstance(doc, dict) and "error" in doc:
            assert doc["exit"] == exit_code and fragment in doc["error"]
            assert set(doc) == {"error", "file", "exit"}
            if doc["file"] is not None:
                assert Path(doc["file"]).name == Path(bad_path).name or Path(doc["file"]).exists()
        else:  # logo reports per scene: one list, the failed scene's record carries the error
            assert any(fragment in r.get("error", "") for r in doc)
    left = sorted(p.name for p in out_dir.rglob("*")) if out_dir.exists() else []
    assert not [n for n in left if ".cvpipe-tmp-" in n or ".tmp" in n], left
    if product is not None:
        if exit_code == 0:
            assert product.is_file()
            assert stat.S_IMODE(product.stat().st_mode) == 0o644  # umask 022 in these tests
        else:
            assert not product.exists()


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


@pytest.mark.parametrize("kind", CLASSES)
@pytest.mark.parametrize("command", COMMANDS)
def test_sweep(kind, command, world, tmp_path, capsys, umask_022):
    bad = {k: make(kind, v, tmp_path / "in" / k, k) for k, v in world["views"].items()}
    out = tmp_path / "out"
    argv, product = argv_for(command, bad, world, out)
    code = cli.main(argv)
    captured = capsys.readouterr()
    check_contract(code, captured.out, captured.err, EXPECTED[(kind, command)], bad["a"], out, product)


def test_sweep_exif_rotated_stereo_pair_is_read_upright(world, tmp_path, capsys):
    """A pair stored sideways with EXIF orientation 6: the disparity map has the upright size and the true 8 px."""
    bad = {k: make("exif_rotated", v, tmp_path / "in", k) for k, v in world["views"].items()}
    out = tmp_path / "out"
    argv, product = argv_for("stereo", bad, world, out)
    code = cli.main(argv)
    captured = capsys.readouterr()
    check_contract(code, captured.out, captured.err, (0, None), bad["a"], out, product)
    disp = np.load(product)
    assert disp.shape == world["views"]["a"].shape[:2]
    valid = disp[np.isfinite(disp)]
    # the views differ by a shift of 8 px; JPEG noise and the borders leave a few stray pixels: 90 % within 1 px
    assert valid.size > 0.5 * disp.size and np.mean(np.abs(valid - 8.0) <= 1.0) > 0.9


def test_sweep_blank_stereo_pair_has_no_valid_disparity(world, tmp_path, capsys):
    """A uniform grey pair: nothing to match, so the answer is a map without a valid pixel (not a full one)."""
    bad = {k: make("blank", v, tmp_path / "in", k) for k, v in world["views"].items()}
    out = tmp_path / "out"
    argv, product = argv_for("stereo", bad, world, out)
    code = cli.main(argv)
    captured = capsys.readouterr()
    check_contract(code, captured.out, captured.err, (0, None), bad["a"], out, product)
    assert json.loads(captured.out)["valid_fraction"] == 0.0
    assert np.isnan(np.load(product)).all()


# ------------------------------------------------------------------------------------------- 81 megapixels

#: an 81 MP photo (9000 x 9000) is under the 100 MP limit, so every command must handle it within the memory
#: budget: work at a smaller size and say so, or refuse naming what to change
BIG_EXPECTED = {
    "hough": (0, None),
    "logo": (0, None),  # detection at a reduced size (a "cvpipe: note:" line)
    "inspect": (2, "differ by a factor"),  # the 320x240 reference and the 9000x9000 probe cannot be one part
    "homography": (1, "chance level"),  # the big texture is unrelated to view B
    "stereo": (2, "over the memory budget"),  # 9000 x 9000 x 16 disparities: names --max-disp
    "stitch": (0, None),  # the same pixels under two names stitch to themselves, composed at a reduced size (a note)
}
#: address-space cap of each 81 MP run: the 4 GB budget plus the decoded images, OpenMP's and OpenCV's threads
BIG_CAP_BYTES = 12 * 1024**3


@pytest.fixture(scope="module")
def big_image(tmp_path_factory):
    """A 9000 x 9000 grey texture with straight edges (written once, PNG level 1: ~25 MB)."""
    path = tmp_path_factory.mktemp("big") / "big81.png"
    rng = np.random.default_rng(0)
    img = cv2.resize(rng.integers(0, 256, (300, 300), dtype=np.uint8), (9000, 9000), interpolation=cv2.INTER_LINEAR)
    for _ in range(40):
        x, y = (int(v) for v in rng.integers(0, 8000, 2))
        cv2.rectangle(img, (x, y), (x + 900, y + 600), int(rng.integers(0, 256)), 9)
    cv2.imwrite(str(path), img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    return path


def _cap():
    resource.setrlimit(resource.RLIMIT_AS, (BIG_CAP_BYTES, BIG_CAP_BYTES))
    os.umask(0o022)


@pytest.mark.slow
@pytest.mark.parametrize("command", COMMANDS)
def test_sweep_81_megapixels(command, big_image, world, tmp_path):
    # a second name for the same bytes (a hard link): stitch refuses one path given twice
    twin = tmp_path / "big81_b.png"
    os.link(big_image, twin)
    bad = {"a": big_image, "b": twin, "r": big_image}
    out = tmp_path / "out"
    argv, product = argv_for(command, bad, world, out)
    env = dict(os.environ, CVPIPE_MEMORY_BUDGET_GB="4")
    proc = subprocess.run([sys.executable, "-m", "cvpipe.cli", *argv], capture_output=True, text=True, env=env,
                          preexec_fn=_cap, timeout=1800)
    check_contract(proc.returncode, proc.stdout, proc.stderr, BIG_EXPECTED[command], big_image, out, product)
    if command in ("logo", "stitch"):  # work done at a smaller size says so
        assert "cvpipe: note:" in proc.stderr and "memory budget" in proc.stderr


# ------------------------------------------------------------------------------------------- calibration files


def middlebury(**change: str) -> str:
    """A Middlebury calib.txt of the sweep's 320x240 stereo views (disparity 8 px), with some values changed."""
    values = {"cam0": "[400 0 160; 0 400 120; 0 0 1]", "cam1": "[400 0 168; 0 400 120; 0 0 1]", "doffs": "8",
              "baseline": "100", "width": "320", "height": "240", "ndisp": "16"}
    values.update(change)
    return "".join(f"{k}={v}\n" for k, v in values.items())


def opencv_yaml(**extra: str) -> str:
    """An OpenCV stereo YAML of a rectified rig for the 320x240 views; ``extra`` keys replace or add lines."""
    m = "!!opencv-matrix\n   rows: {r}\n   cols: {c}\n   dt: d\n   data: [ {d} ]\n"
    lines = {"image_width": "320\n", "image_height": "240\n",
             "K1": m.format(r=3, c=3, d="400., 0., 160., 0., 400., 120., 0., 0., 1."),
             "D1": m.format(r=1, c=5, d="0., 0., 0., 0., 0."),
             "K2": m.format(r=3, c=3, d="400., 0., 168., 0., 400., 120., 0., 0., 1."),
             "D2": m.format(r=1, c=5, d="0., 0., 0., 0., 0."),
             "R": m.format(r=3, c=3, d="1., 0., 0., 0., 1., 0., 0., 0., 1."),
             "T": m.format(r=3, c=1, d="-100., 0., 0.")}
    lines.update(extra)
    return "%YAML:1.0\n---\n" + "".join(f"{k}: {v}" for k, v in lines.items())


#: calibration file -> (its text, exit status, fragment of the error line: the key and what is allowed).
#: The ``depth_*`` rows are valid files whose magnitudes give no usable depth (all +inf, all 0 or all undefined).
CALIBRATIONS = {
    "good": (middlebury(), 0, None),
    "good_yaml": (opencv_yaml(), 0, None),
    "width_1e400": (middlebury(width="1e400"), 2, "`width` must be an integer in [2, 1000000], got '1e400'"),
    "width_fraction": (middlebury(width="384.7"), 2, "`width` must be an integer in [2, 1000000], got '384.7'"),
    "ndisp_1e400": (middlebury(ndisp="1e400"), 2, "`ndisp` must be an integer in [1, 320], got '1e400'"),
    "ndisp_0": (middlebury(ndisp="0"), 2, "`ndisp` must be an integer in [1, 320], got '0'"),
    "cx_1e300": (middlebury(cam0="[400 0 1e300; 0 400 120; 0 0 1]"), 2,
                 "`cam0` principal point cx = 1e+300 must be in [-160, 480]"),
    "fy_negative": (middlebury(cam0="[400 0 160; 0 -400 120; 0 0 1]"), 2, "`cam0` focal length fy = -400 must be > 0"),
    "K22_zero": (middlebury(cam1="[400 0 168; 0 400 120; 0 0 0]"), 2, "`cam1`[2, 2] must be 1"),
    "K_all_zero": (middlebury(cam0="[0 0 0; 0 0 0; 0 0 0]"), 2, "`cam0` focal length fx = 0 must be > 0"),
    "doffs_beyond_width": (middlebury(doffs="-1e9"), 2, "`doffs` must be in [-640, 640]"),
    "size_mismatch": (middlebury(width="640"), 2, "`width` says 640x240 but the images are 320x240"),
    "K1_list": (opencv_yaml(K1="[1, 2, 3]\n"), 2, "`K1` must be a 3x3 matrix"),
    "image_width_inf": (opencv_yaml(image_width=".inf\n"), 2, "`image_width` must be an integer in [2, 1000000]"),
    "yaml_fy_negative": (opencv_yaml(K2="!!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 400., 0., "
                                        "168., 0., -400., 120., 0., 0., 1. ]\n"), 2, "`K2` focal length fy"),
    "over_1MB": ("# padding\n" * 110_000 + middlebury(), 2, "larger than the limit of 1000000 bytes"),
    "depth_huge_focal": (middlebury(cam0="[1e300 0 160; 0 1e300 120; 0 0 1]"), 2, "no pixel has a usable depth"),
    "depth_huge_baseline": (middlebury(baseline="1e300"), 2, "no pixel has a usable depth"),
    "depth_tiny_baseline": (middlebury(baseline="1e-300"), 2, "no pixel has a usable depth"),
    "depth_negative_doffs": (middlebury(doffs="-600"), 2, "no pixel has a usable depth"),
}


def calibration_argv(world: dict, calib: Path, out: Path) -> list[str]:
    g = world["good"]
    return [str(a) for a in ("stereo", g["a"], g["r"], "--max-disp", "16", "--method", "opencv-sgbm", "--calib",
                             calib, "-o", out / "disp.npy", "--depth", out / "z.npy", "--json")]


def check_calibration_run(code, out_text, err_text, expected, calib, out):
    """The sweep's contract plus: the error names the calibration file (line and JSON ``file``), and no depth."""
    check_contract(code, out_text, err_text, expected, calib, out, out / "disp.npy")
    if expected[0] != 0:
        doc = json.loads(out_text)
        assert doc["file"] == str(calib) and err_text.startswith(f"cvpipe: error: {calib}: ")
        assert not (out / "z.npy").exists()


@pytest.mark.parametrize("kind", sorted(CALIBRATIONS))
def test_sweep_calibration(kind, world, tmp_path, capsys, umask_022):
    text, code_expected, fragment = CALIBRATIONS[kind]
    calib = tmp_path / ("calib.yml" if text.startswith("%YAML") else "calib.txt")
    calib.write_text(text)
    out = tmp_path / "out"
    code = cli.main(calibration_argv(world, calib, out))
    captured = capsys.readouterr()
    check_calibration_run(code, captured.out, captured.err, (code_expected, fragment), calib, out)


#: 40,000 nested brackets or elements (about 80 KB): OpenCV's recursive parsers overflow the stack on these
NESTED = {
    "yaml": "%YAML:1.0\nK1: " + "[" * 40_000 + "]" * 40_000 + "\n",
    "yaml_blocks": "%YAML:1.0\nK1:\n  " + "- " * 40_000 + "1\n",
    "xml": '<?xml version="1.0"?>\n<opencv_storage>' + "<a>" * 40_000 + "</a>" * 40_000 + "</opencv_storage>\n",
}
#: address-space cap of a calibration run in a subprocess: far below what reading /dev/zero to its end would take
CALIB_CAP_BYTES = 3 * 1024**3


def _cap_calibration_run():
    resource.setrlimit(resource.RLIMIT_AS, (CALIB_CAP_BYTES, CALIB_CAP_BYTES))
    os.umask(0o022)


def _run_calibration_subprocess(world, calib, out):
    """The command in a child process (a crash or a runaway read must not take pytest with it)."""
    proc = subprocess.run([sys.executable, "-m", "cvpipe.cli", *calibration_argv(world, calib, out)],
                          capture_output=True, text=True, preexec_fn=_cap_calibration_run, timeout=120)
    return proc.returncode, proc.stdout, proc.stderr


@pytest.mark.parametrize("kind", sorted(NESTED))
def test_sweep_calibration_nested_brackets(kind, world, tmp_path):
    calib = tmp_path / ("deep.xml" if kind == "xml" else "deep.yml")
    calib.write_text(NESTED[kind])
    out = tmp_path / "out"
    code, out_text, err_text = _run_calibration_subprocess(world, calib, out)
    check_calibration_run(code, out_text, err_text, (2, "nested about"), calib, out)
    assert "over the limit of 64" in err_text


@pytest.mark.parametrize("kind", ["dev_zero", "sparse_1GB"])
def test_sweep_calibration_unbounded_size(kind, world, tmp_path):
    if kind == "dev_zero":
        calib = Path("/dev/zero")
        if not calib.exists():
            pytest.skip("no /dev/zero")
    else:
        calib = tmp_path / "huge.yml"
        with open(calib, "wb") as fh:  # sparse: 1 GB of zeros that take no disk space
            fh.truncate(1024**3)
    out = tmp_path / "out"
    code, out_text, err_text = _run_calibration_subprocess(world, calib, out)
    check_calibration_run(code, out_text, err_text, (2, "larger than the limit of 1000000 bytes"), calib, out)
