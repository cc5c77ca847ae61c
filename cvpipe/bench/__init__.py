"""Benchmarks on the real data sets (``cvpipe bench <task> --data DIR``).

Each module has the same interface as the subcommand modules in ``cvpipe.commands``. Benchmarks print ratios
against the baseline measured in the same process; they never assert on time.
"""

import os as _os
import subprocess as _subprocess
import sys as _sys
import tempfile as _tempfile
from pathlib import Path as _Path


def fresh_cache_output(snippet: str) -> list[str]:
    """Run ``snippet`` in a fresh interpreter with an empty numba cache and return its whitespace-split stdout.

    Benchmarks use it to measure one-off numba compile times apart from the run times.
    """
    with _tempfile.TemporaryDirectory() as cache:
        env = dict(_os.environ, NUMBA_CACHE_DIR=cache)
        root = str(_Path(__file__).resolve().parents[1].parent)
        env["PYTHONPATH"] = _os.pathsep.join([root, env.get("PYTHONPATH", "")])
        return _subprocess.run([_sys.executable, "-c", snippet], env=env, capture_output=True, text=True,
                               check=True).stdout.split()
