"""The threading defaults that ``import cvpipe`` sets before numpy and OpenMP load (``cvpipe/__init__.py``): set when
the user has not, left alone when the user has, and in effect (OpenBLAS starts no thread of its own)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT

DEFAULTS = {"OMP_WAIT_POLICY": "PASSIVE", "OPENBLAS_NUM_THREADS": "1"}

PROBE = """
import json, os, sys
import cvpipe
import numpy as np
a = np.ones((300, 300))
a @ a  # OpenBLAS starts its threads at load; a product uses them
tasks = len(os.listdir("/proc/self/task")) if os.path.isdir("/proc/self/task") else -1
print(json.dumps({"env": {k: os.environ.get(k) for k in sys.argv[1:]}, "threads": tasks}))
"""


def _probe(**env_overrides: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in DEFAULTS}
    env.update(env_overrides)
    done = subprocess.run([sys.executable, "-c", PROBE, *DEFAULTS], cwd=ROOT, env=env, capture_output=True,
                          text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_import_sets_the_thread_defaults():
    assert _probe()["env"] == DEFAULTS


def test_the_users_settings_win():
    mine = {"OMP_WAIT_POLICY": "ACTIVE", "OPENBLAS_NUM_THREADS": "2"}
    assert _probe(**mine)["env"] == mine


@pytest.mark.skipif(not Path("/proc/self/task").is_dir() or (os.cpu_count() or 1) < 2,
                    reason="counts threads in /proc; needs 2 cores for OpenBLAS to start a thread of its own")
def test_openblas_starts_no_thread_of_its_own():
    # the same process with OpenBLAS allowed two threads has exactly one more: the default leaves numpy's products on
    # the calling thread, where no idle OpenBLAS thread spins beside cvpipe's own parallel work
    one, two = _probe()["threads"], _probe(OPENBLAS_NUM_THREADS="2")["threads"]
    assert two == one + 1
