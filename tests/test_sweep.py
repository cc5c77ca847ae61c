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
           "over_limit"]
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
    # our own lines only: errors, notes, and the README's "compiling ... once" line of a cold numba cache (which
    # line appears depends on the cache, not on the input)
    others = [ln for ln in err_text.splitlines() if ln.strip() and not ln.startswith(("cvpipe: error:",
                                                                                        "cvpipe: note:",
                                                                                        "cvpipe: compiling the "))]
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


# ------------------------------------------------------------------------------------------- 81 megapixels

#: an 81 MP photo (9000 x 9000) is under the 100 MP limit, so every command must handle it within the memory
#: budget: work at a smaller size and say so, or refuse naming what to change
BIG_EXPECTED = {
    "hough": (0, None),
    "logo": (0, None),  # detection at a reduced size (a "cvpipe: note:" line)
    "inspect": (2, "differ by a factor"),  # the 320x240 reference and the 9000x9000 probe cannot be one part
    "homography": (1, "chance level"),  # the big texture is unrelated to view B
    "stereo": (2, "over the memory budget"),  # 9000 x 9000 x 16 disparities: names --max-disp
    "stitch": (0, None),  # the same photo twice stitches to itself, composed at a reduced size (a note)
}
#: address-space cap of each 81 MP run: the 4 GB budget plus the decoded images, numba and OpenCV's threads
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
    bad = {"a": big_image, "b": big_image, "r": big_image}
    out = tmp_path / "out"
    argv, product = argv_for(command, bad, world, out)
    env = dict(os.environ, CVPIPE_MEMORY_BUDGET_GB="4")
    proc = subprocess.run([sys.executable, "-m", "cvpipe.cli", *argv], capture_output=True, text=True, env=env,
                          preexec_fn=_cap, timeout=1800)
    check_contract(proc.returncode, proc.stdout, proc.stderr, BIG_EXPECTED[command], big_image, out, product)
    if command in ("logo", "stitch"):  # work done at a smaller size says so
        assert "cvpipe: note:" in proc.stderr and "memory budget" in proc.stderr
