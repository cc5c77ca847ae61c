"""A stage whose items the memory budget refuses: the refused ones are dropped with their reason, and when the budget
refused every item the stage fails with one line instead of reporting "0 lines in 0 images" with exit 0."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _edges(path: Path, side: int) -> None:
    e = np.zeros((side, side), np.uint8)
    e[side // 2, :] = 255  # one horizontal line of `side` votes
    cv2.imwrite(str(path), e)


def _hough_lines(cwd: Path, budget_gb: float) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "CVPIPE_MEMORY_BUDGET_GB": str(budget_gb)}
    return subprocess.run([sys.executable, "-m", "stages.hough_lines", "--edges", "edges", "--out", "lines.json",
                           "--method", "ours"], cwd=cwd, env=env, capture_output=True, text=True)


def test_every_item_over_the_budget_fails_the_stage_with_one_line(tmp_path):
    (tmp_path / "edges").mkdir()
    (tmp_path / "params.yaml").write_text((ROOT / "params.yaml").read_text())
    for name in ("a.png", "b.png"):
        _edges(tmp_path / "edges" / name, 1500)  # accumulator: 181 x 6001 int32 = 4.3 MB
    proc = _hough_lines(tmp_path, 0.001)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "every item (2) was refused by the memory budget" in lines[0] and "a.png" in lines[0]
    assert "CVPIPE_MEMORY_BUDGET_GB" in lines[0]
    assert not (tmp_path / "lines.json").exists()


def test_items_within_the_budget_go_on_and_the_refused_one_is_named(tmp_path):
    (tmp_path / "edges").mkdir()
    (tmp_path / "params.yaml").write_text((ROOT / "params.yaml").read_text())
    _edges(tmp_path / "edges" / "big.png", 1500)  # 4.3 MB accumulator: over 0.002 GB
    _edges(tmp_path / "edges" / "small.png", 400)  # 181 x 1133 int32 = 0.8 MB: within it
    proc = _hough_lines(tmp_path, 0.002)
    assert proc.returncode == 0, proc.stderr
    assert "dropped 1: big.png (" in proc.stdout + proc.stderr
    got = json.loads((tmp_path / "lines.json").read_text())
    assert [i["file"] for i in got["images"]] == ["small.png"] and got["images"][0]["lines"]
