"""Synthetic task summaries with real pictures on disk, for the report tests (builder, stage and browser)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from cvpipe import io

#: text that breaks a page when it is not escaped
NASTY = "<script>alert('x')</script> & \"quoted\" <b>bold</b>"


def picture(path: Path, width: int, height: int, seed: int) -> None:
    """A small PNG/JPEG with a few shapes, so it decodes to a real image of known size."""
    rng = np.random.default_rng(seed)
    img = np.full((height, width, 3), 255, np.uint8)
    for _ in range(5):
        x1, x2 = sorted(rng.integers(0, width, 2))
        y1, y2 = sorted(rng.integers(0, height, 2))
        cv2.rectangle(img, (int(x1), int(y1)), (int(x2), int(y2)), rng.integers(0, 255, 3).tolist(), 2)
    io.save_image(path, img)


def summary(task: str, pictures: list[str], nasty: bool = False) -> dict:
    """A summary in the schema of cvpipe.report with the given repo-relative picture paths."""
    title = f"{task} results" + (f" {NASTY}" if nasty else "")
    return {
        "task": task,
        "title": title,
        "description": f"Synthetic {task} summary for the report tests." + (f" {NASTY}" if nasty else ""),
        "pictures": [{"path": p, "caption": f"{Path(p).name}" + (f" {NASTY}" if nasty else "")} for p in pictures],
        "tables": [{"title": "accuracy" + (f" {NASTY}" if nasty else ""),
                    "columns": ["method", "error px", "recall", "ok"],
                    "rows": [["ours", 0.123456, 0.98, True], ["opencv", 12345.6, None, False]]}],
    }


def make_outputs(root: Path, tasks: tuple[str, ...] = ("hough", "stereo"), nasty: bool = True) -> list[dict]:
    """Write ``root/outputs/<task>/summary.json`` and its pictures (PNG and JPEG, one name with a space and a #)."""
    made = []
    for k, task in enumerate(tasks):
        rel = [f"outputs/{task}/result.png", f"outputs/{task}/input #{k} a.jpg"]
        picture(root / rel[0], 320, 200, seed=k)
        picture(root / rel[1], 160, 240, seed=10 + k)
        s = summary(task, rel, nasty)
        io.save_json(root / "outputs" / task / "summary.json", s)
        made.append(s)
    return made


def make_timings(root: Path) -> list[dict]:
    """Write two stage runner timing files into ``root/outputs/timings`` (as the runner does) and return them."""
    made = [{"stage": "hough_lines@ours", "seconds": {"total": 0.5, "first_call": 0.4}, "load_average": 1.0},
            {"stage": "hough_edges", "seconds": {"total": 0.25}, "load_average": None}]
    for t in made:
        io.save_json(root / "outputs" / "timings" / f"{t['stage']}.json", t)
    return made
