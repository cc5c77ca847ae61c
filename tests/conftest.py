"""Shared fixtures: the repository root, the real data root (skip when absent), and small synthetic images."""

from __future__ import annotations

# first, before numpy and OpenCV load: the tests run with the code paths the stages pin (stages/__init__.py), so that
# a result computed in a test's own process is the same, bit for bit, as the one a stage wrote
import stages  # noqa: F401,I001

import functools
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

ROOT = Path(__file__).resolve().parents[1]


@functools.lru_cache(maxsize=None)
def default_params_path() -> Path:
    """A params.yaml with every parameter at its default, for tests that run stages: this repository's params.yaml
    is the workspace's, and after a user's `dvc exp apply` it holds their values."""
    import tempfile

    import yaml

    from cvpipe.init import default_params

    path = Path(tempfile.mkdtemp(prefix="cvpipe-defaults-")) / "params.yaml"
    path.write_text(yaml.safe_dump(default_params(), sort_keys=False), encoding="utf-8")
    return path

# the property tests draw the same examples on every run (a fixed seed), so that CI sees what a developer saw;
# HYPOTHESIS_PROFILE=explore draws fresh random examples each run (to hunt for new failing inputs)
settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


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



def pytest_unconfigure(config):
    """Tests that run a program in this process (a stage's ``run`` as ``python -m`` would) install
    :mod:`cvpipe.interrupt`, whose last ``atexit`` function leaves with that program's exit status: without this,
    a session with failures would end with the last such program's 0. pytest's own status must be the process's."""
    import atexit

    from cvpipe import interrupt

    atexit.unregister(interrupt._leave)  # noqa: SLF001 - our own module's function, not a dependency's
