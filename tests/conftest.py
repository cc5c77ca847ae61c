"""Shared fixtures: the repository root, the real data root (skip when absent), and small synthetic images."""

from __future__ import annotations

# first, before numpy and OpenCV load: the tests run with the code paths the stages pin (stages/__init__.py), so that
# a result computed in a test's own process is the same, bit for bit, as the one a stage wrote
import stages  # noqa: F401,I001

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

ROOT = Path(__file__).resolve().parents[1]

# the property tests draw the same examples on every run (a fixed seed), so that CI sees what a developer saw;
# HYPOTHESIS_PROFILE=explore draws fresh random examples each run (to hunt for new failing inputs)
settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


@pytest.fixture(scope="session", autouse=True)
def numba_kernels_compiled(tmp_path_factory):
    """Every task's numba kernels compiled and cached before the first test (tests/compile_kernels.py says why).

    In a subprocess with this session's environment (its NUMBA_CACHE_DIR); the pytest-xdist workers share a lock file
    in the session's temporary folder, so one compiles (about a minute on a cold cache) while the others wait, then
    find the cache warm (a few seconds).
    """
    import fcntl
    import subprocess
    import sys

    shared = tmp_path_factory.getbasetemp().parent
    with open(shared / "numba-kernels.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        proc = subprocess.run([sys.executable, str(ROOT / "tests" / "compile_kernels.py")], cwd=ROOT,
                              capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def data_root() -> Path:
    """The real benchmark data (``$CVPIPE_DATA``, else ``../shared/data``); tests using it skip when absent."""
    env = os.environ.get("CVPIPE_DATA")
    root = Path(env) if env else ROOT.parent / "shared" / "data"
    if not root.is_dir():
        pytest.skip("real data not available (set CVPIPE_DATA)")
    return root


@pytest.fixture(scope="session")
def textured_image() -> np.ndarray:
    """A 480x640 grayscale photo (scikit-image astronaut) with plenty of texture for feature detectors."""
    from cvpipe.samples import fit, photo

    import cv2

    return cv2.cvtColor(fit(photo("astronaut"), 640, 480), cv2.COLOR_BGR2GRAY)
