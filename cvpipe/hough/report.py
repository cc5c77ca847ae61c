"""Pictures and the report page of the hough task: lines and segments drawn on an image, summary, plot rows."""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..metrics import not_processed_table
from ..overlays import to_bgr
from .evaluate import _as_lines

__all__ = ["draw_lines", "draw_segments", "report_summary", "quality_plot"]


def draw_lines(image: np.ndarray, lines: np.ndarray, color: tuple[int, int, int] = (0, 0, 255),
               thickness: int = 1) -> np.ndarray:
    """A BGR copy of ``image`` with the infinite lines ``[rho, theta, ...]`` drawn across it.

    Examples
    --------
    >>> import numpy as np
    >>> out = draw_lines(np.zeros((60, 80), np.uint8), [[20.0, np.pi / 2, 80]])  # red across the row y = 20
    >>> out.shape, int(out[20, 40].argmax()), int(out[40, 40].max())  # anti-aliased: red dominates on the row
    ((60, 80, 3), 2, 0)
    """
    out = to_bgr(image)
    reach = 2 * (out.shape[0] + out.shape[1])
    for rho, theta in _as_lines(lines)[:, :2]:
        c, s = math.cos(theta), math.sin(theta)
        x0, y0 = rho * c, rho * s
        p1 = (int(round(x0 - reach * s)), int(round(y0 + reach * c)))
        p2 = (int(round(x0 + reach * s)), int(round(y0 - reach * c)))
        cv2.line(out, p1, p2, color, thickness, cv2.LINE_AA)
    return out


def draw_segments(image: np.ndarray, segments: np.ndarray, color: tuple[int, int, int] = (0, 255, 0),
                  thickness: int = 1) -> np.ndarray:
    """A BGR copy of ``image`` with the segments ``[x1, y1, x2, y2]`` drawn on it.

    Examples
    --------
    >>> import numpy as np
    >>> out = draw_segments(np.zeros((60, 80), np.uint8), [[10, 20, 60, 20]])
    >>> int(out[20, 30].argmax()), int(out[20, 70].max())  # green on the segment, nothing past its end
    (1, 0)
    """
    out = to_bgr(image)
    for x1, y1, x2, y2 in np.asarray(segments, np.int64).reshape(-1, 4):
        cv2.line(out, (int(x1), int(y1)), (int(x2), int(y2)), color, thickness, cv2.LINE_AA)
    return out


def report_summary(metrics: dict, ours: dict, opencv: dict, pictures: list[dict], dropped: list[dict]) -> dict:
    """The report page's summary of the hough task (schema in ``cvpipe.report``), from ``compare_runs`` output.

    Parameters
    ----------
    metrics : dict
        ``compare_runs(ours, opencv, truth)``.
    ours, opencv : dict
        The two ``hough_lines`` stage results (for the parameters).
    pictures : list of dict
        ``{"path", "caption"}`` overlays, repo-relative paths.
    dropped : list of dict
        ``{"item", "reason"}`` for every input image that was not processed.

    Examples
    --------
    >>> import numpy as np
    >>> run = {"rho": 1.0, "theta": np.pi / 180, "threshold": 60,
    ...        "images": [{"file": "a.png", "lines": [[20.0, np.pi / 2, 80]]}]}
    >>> from cvpipe.hough.evaluate import compare_runs
    >>> compared = compare_runs(run, run, {"a": [[20.0, np.pi / 2], [5.0, 0.0]]})
    >>> page = report_summary(compared, run, run, pictures=[], dropped=[])
    >>> page["task"], [t["title"] for t in page["tables"]]
    ('hough', ['Per method', 'Per image'])
    """
    rows = metrics["per_image"]
    has_truth = metrics["truth_images"] > 0
    methods = []
    for key in ("ours", "opencv"):
        recall = metrics.get(f"recall_{key}")
        methods.append([key, int(sum(r["our_lines" if key == "ours" else "ref_lines"] for r in rows)),
                        metrics["parity_min"] if key == "ours" else 1.0,
                        "no ground truth" if recall is None else round(recall, 4)])
    none = "no ground truth"
    per_image = [[r["file"], r["ref_lines"], r["reproduced"], r["identical"], r.get("truth_found_ours", none),
                  r.get("truth_found_opencv", none), r.get("truth_lines", none)] for r in rows]
    truth_note = (f"{metrics['truth_images']} of {metrics['images']} images have true lines." if has_truth else
                  "These images have no ground truth: the table compares the two implementations only.")
    tables = [
        {"title": "Per method",
         "columns": ["method", "lines", "share of OpenCV's lines reproduced (min over images)",
                     "recall of true lines"],
         "rows": methods},
        {"title": "Per image",
         "columns": ["image", "OpenCV lines", "reproduced by ours", "identical output", "true lines found (ours)",
                     "true lines found (OpenCV)", "true lines"],
         "rows": per_image},
    ]
    tables += not_processed_table(dropped)
    return {
        "task": "hough",
        "title": "Our standard Hough transform against cv2.HoughLines at identical parameters",
        "description": (
            f"Canny edges of each image, then both transforms with rho {ours['rho']:g} px, theta "
            f"{math.degrees(ours['theta']):g} deg, threshold {ours['threshold']}. Ours reproduces "
            f"{metrics['identical_images']} of {metrics['images']} images exactly (same cells, votes and order). "
            f"{truth_note} Overlays: ours in red (left), OpenCV's in green (right). Times: `dvc plots show` "
            "(outputs/timings) and `cvpipe bench hough`."),
        "pictures": pictures,
        "tables": tables,
    }


def quality_plot(metrics: dict) -> list[dict]:
    """``dvc plots`` rows ``{"image", "method", "lines", "true_found"}``: what each implementation found per image.

    Examples
    --------
    >>> compared = {"per_image": [{"file": "a", "our_lines": 3, "ref_lines": 2, "truth_found_ours": 1}]}  # no truth
    >>> for row in quality_plot(compared):                                            # for OpenCV's lines here
    ...     print(row)
    {'image': 'a', 'method': 'ours', 'lines': 3, 'true_found': 1}
    {'image': 'a', 'method': 'opencv', 'lines': 2, 'true_found': None}
    """
    rows = []
    for r in metrics["per_image"]:
        for key, count in (("ours", r["our_lines"]), ("opencv", r["ref_lines"])):
            rows.append({"image": r["file"], "method": key, "lines": int(count),
                         "true_found": r.get(f"truth_found_{key}")})
    return rows
