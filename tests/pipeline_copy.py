"""Helpers for tests that run DVC on a throw-away copy of this repository."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path


def tracked_files(repo: Path) -> list[str]:
    """Files git tracks plus untracked ones it does not ignore (the working tree as a fresh clone would see it)."""
    out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"], cwd=repo,
                         check=True, capture_output=True).stdout.decode()
    return [f for f in out.split("\0") if f and (repo / f).is_file()]


def copy_repo(repo: Path, dest: Path) -> Path:
    """Copy the working tree into ``dest`` as a new git repository with one commit."""
    for rel in tracked_files(repo):
        target = dest / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(repo / rel, target)
    env = dict(os.environ, GIT_AUTHOR_NAME="t", GIT_AUTHOR_EMAIL="t@t", GIT_COMMITTER_NAME="t",
               GIT_COMMITTER_EMAIL="t@t")
    for cmd in (["git", "init", "-q"], ["git", "add", "-A"], ["git", "commit", "-qm", "fresh clone"]):
        subprocess.run(cmd, cwd=dest, check=True, env=env, capture_output=True)
    return dest


def run_env() -> dict[str, str]:
    """Environment in which `python` and `dvc` are this interpreter's (the venv under test)."""
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["DVC_NO_ANALYTICS"] = "1"
    return env


def dvc(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """Run ``dvc ARGS`` in ``cwd``; raise with its output when it fails."""
    proc = subprocess.run([sys.executable, "-m", "dvc", *args], cwd=cwd, env=run_env(), capture_output=True,
                          text=True)
    if proc.returncode != 0:
        raise AssertionError(f"dvc {' '.join(args)} failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return proc
