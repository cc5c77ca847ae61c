"""cvpipe in a user's own DVC repository, as a user gets it: the wheel built from this checkout, installed with its
`pipeline` extra into a new venv, run from a folder outside this repository (nothing of it on the path).

`cvpipe init` in a new git repository, a folder of the user's images tracked with `dvc add`, then: `dvc repro`
succeeds; a queued sweep of two experiments succeeds (DVC's temporary copies see the tracked folder) and
`dvc exp show --only-changed` with the README's `--drop` pattern fits 120 columns, as does `dvc metrics show`; an
untracked folder in an experiment fails with the one line that says how to track it; a teammate's clone gets the
results with `dvc pull` through a remote, after which `dvc repro` runs nothing.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from conftest import ROOT

pytestmark = [pytest.mark.slow, pytest.mark.timeout(1800)]

#: the `--drop` pattern the README gives for `dvc exp show --only-changed` (a test checks the README says it)
DROP = "outputs/|data/|Created|State|Executor"
#: the widest table a terminal of the usual size shows without wrapping
MAX_COLUMNS = 120


def _run(cmd: list[str], cwd: Path, env: dict, check: bool = True, timeout: float = 900) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    if check and proc.returncode != 0:
        raise AssertionError(f"{' '.join(map(str, cmd))} (exit {proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return proc


@pytest.fixture(scope="module")
def user(tmp_path_factory):
    """A new venv with the wheel and its `pipeline` extra, and the environment to run it outside this repository."""
    work = tmp_path_factory.mktemp("own")
    build_env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-build-isolation", "--no-deps", "-w", str(work / "dist"),
          str(ROOT)], work, build_env)
    wheel = next((work / "dist").glob("cvpipe-*.whl"))
    _run([sys.executable, "-m", "venv", str(work / "venv")], work, build_env)
    py = work / "venv" / "bin" / "python"
    _run([str(py), "-m", "pip", "install", "-q", f"cvpipe[pipeline] @ {wheel.as_uri()}"], work, build_env)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{py.parent}{os.pathsep}/usr/bin:/bin"
    env["COLUMNS"] = "1000"  # DVC's tables at their natural width (they shrink to a narrower terminal)
    return work, env


def _lines_images(folder: Path, n: int = 3) -> None:
    """Small images of straight lines (what `cvpipe hough` looks for)."""
    folder.mkdir(parents=True)
    rng = np.random.default_rng(7)
    for i in range(n):
        img = np.full((240, 320), 30, np.uint8)
        for _ in range(6):
            p, q = rng.integers(0, 320, 2), rng.integers(0, 240, 2)
            cv2.line(img, (int(p[0]), int(q[0])), (int(p[1]), int(q[1])), 230, 2)
        cv2.imwrite(str(folder / f"lines_{i}.png"), img)


def _width(text: str) -> int:
    return max((len(line.rstrip()) for line in text.splitlines()), default=0)


def test_init_repro_sweep_and_pull_in_a_users_repository(user):
    work, env = user
    repo = work / "repo"
    _lines_images(repo / "data" / "lines")
    # nothing of this checkout on the path: the package, its stages and the template come from the wheel
    where = _run(["python", "-c", "import cvpipe.stages, cvpipe; print(cvpipe.stages.__file__)"], work, env)
    assert str(ROOT) not in where.stdout and "site-packages" in where.stdout

    out = _run(["cvpipe", "init", "repo", "--tasks", "hough", "--data", "hough=data/lines"], work, env).stdout
    assert "dvc add data/lines" in out
    _run(["git", "config", "user.email", "user@example.invalid"], repo, env)
    _run(["git", "config", "user.name", "user"], repo, env)
    _run(["dvc", "add", "-q", "data/lines"], repo, env)
    _run(["git", "add", "-A"], repo, env)
    _run(["git", "commit", "-qm", "cvpipe pipeline"], repo, env)

    _run(["dvc", "repro"], repo, env)
    metrics = json.loads((repo / "outputs" / "hough" / "metrics.json").read_text())
    base = metrics["hough"]["all"]["lines_ours"]
    assert base > 0 and metrics["hough"]["all"]["lines_opencv"] == base
    _run(["git", "add", "-A"], repo, env)
    _run(["git", "commit", "-qm", "results"], repo, env)

    # a queued sweep of two: DVC's temporary copies get data/lines from its cache
    for t in (60, 100):
        _run(["dvc", "exp", "run", "--queue", "-S", f"hough.lines.threshold={t}"], repo, env)
    _run(["dvc", "queue", "start", "-j", "1"], repo, env)
    deadline = time.monotonic() + 900
    while time.monotonic() < deadline:
        status = _run(["dvc", "queue", "status"], repo, env).stdout
        if not re.search(r"\b(Queued|Running)\b", status):
            break
        time.sleep(3)
    assert status.count("Success") == 2, status
    shown = json.loads(_run(["dvc", "exp", "show", "--json"], repo, env).stdout)
    found, names = {}, {}
    for rev in shown:
        for exp in (rev.get("experiments") or []):
            for run in exp.get("revs", []):
                data = run["data"]
                t = data["params"]["params.yaml"]["data"]["hough"]["lines"]["threshold"]
                found[t] = data["metrics"]["outputs/hough/metrics.json"]["data"]["hough"]["all"]["lines_ours"]
                names[t] = run["name"]
    assert set(found) == {60, 100} and found[60] > found[100] > 0  # a lower threshold finds more lines

    table = _run(["dvc", "exp", "show", "--only-changed", "--drop", DROP], repo, env).stdout
    assert "hough.lines.threshold" in table and _width(table) <= MAX_COLUMNS, table
    metrics_table = _run(["dvc", "metrics", "show"], repo, env).stdout
    assert "lines_ours" in metrics_table and _width(metrics_table) <= MAX_COLUMNS, metrics_table

    # the two experiments' pictures side by side, on a page that loads nothing from the network
    _run(["dvc", "plots", "diff", names[60], names[100], "-o", "plots"], repo, env)
    page = (repo / "plots" / "index.html").read_text(encoding="utf-8")
    assert not re.search(r"""(src|href)\s*=\s*["']?https?:""", page), "the page loads something from the network"
    for name in (names[60], names[100]):
        pictures = [m for m in re.findall(r'<img src="([^"]+)"', page) if name in m]
        assert pictures and all((repo / "plots" / p).is_file() for p in pictures), name

    # a folder that neither git nor DVC tracks is not in an experiment's copy: one line says how to fix it
    _lines_images(repo / "data" / "untracked", n=1)
    failed = _run(["dvc", "exp", "run", "--temp", "-S", "hough.data=data/untracked"], repo, env, check=False)
    assert failed.returncode != 0
    said = [line for line in (failed.stdout + failed.stderr).splitlines() if "experiment's copy" in line]
    assert said and "dvc add data/untracked" in said[0], failed.stdout + failed.stderr

    # a teammate: clone, pull the results through a remote, and nothing is left to run
    _run(["dvc", "remote", "add", "-d", "local", str(work / "remote")], repo, env)
    _run(["git", "commit", "-qam", "remote"], repo, env)
    _run(["dvc", "push", "-q"], repo, env)
    mate = work / "mate"
    _run(["git", "clone", "-q", str(repo), str(mate)], work, env)
    _run(["dvc", "pull", "-q"], mate, env)
    assert (mate / "outputs" / "hough" / "overlays").is_dir()
    rerun = _run(["dvc", "repro"], mate, env).stdout
    assert "Running stage" not in rerun, rerun
    assert "up to date" in _run(["dvc", "status"], mate, env).stdout


def test_readme_gives_the_drop_pattern_this_test_checks():
    assert f"--drop '{DROP}'" in (ROOT / "README.md").read_text(encoding="utf-8")
