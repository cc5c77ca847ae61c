"""``cvpipe bench pipeline``: how long a `dvc repro` takes when nothing changed (the cache check itself)."""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

HELP = "time a no-op `dvc repro` in a repository whose pipeline is up to date"
EXAMPLE = "cvpipe bench pipeline --repo . --repeat 3"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repo", default=".", help="repository root (default: current folder)")
    parser.add_argument("--repeat", type=int, default=3, help="number of timed no-op runs (default 3)")
    parser.add_argument("--data", help="unused; accepted for symmetry with the other benchmarks")


def _repro(repo: Path) -> tuple[float, str]:
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "dvc", "repro"], cwd=repo, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"dvc repro failed in {repo}: {proc.stderr.strip().splitlines()[-1:]}")
    return time.perf_counter() - t0, proc.stdout


def run(args: argparse.Namespace) -> int:
    if args.repeat < 1:
        raise ValueError(f"`--repeat` must be at least 1, got {args.repeat}")
    repo = Path(args.repo)
    if not (repo / "dvc.yaml").is_file():
        raise ValueError(f"{repo}: no dvc.yaml here, expected the repository root")
    warm, out = _repro(repo)  # brings the pipeline up to date if it was not
    times = []
    for _ in range(args.repeat):
        t, out = _repro(repo)
        if "Running stage" in out:
            raise RuntimeError("a stage ran during a no-op repro: the pipeline is not reproducible as cached")
        times.append(t)
    print(f"first repro (brings outputs up to date): {warm:.2f} s")
    print(f"no-op dvc repro, median of {len(times)}: {statistics.median(times):.2f} s "
          f"(min {min(times):.2f}, max {max(times):.2f})")
    return 0
