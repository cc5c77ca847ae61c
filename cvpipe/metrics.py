"""Accuracy metrics against ground truth (small, generic, shared by the tasks' reports and benchmarks), and the one
summary table every task's report has (:func:`not_processed_table`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from .errors import InputError, check_int


def _homography(name: str, H) -> np.ndarray:
    a = np.asarray(H, dtype=np.float64)
    if a.shape != (3, 3):
        raise InputError(f"`{name}` must have shape (3, 3), got {a.shape}")
    if not np.isfinite(a).all():
        raise InputError(f"`{name}` contains NaN or inf")
    return a


def image_corners(width: int, height: int) -> np.ndarray:
    """(4, 2) float64 corners of a width x height image in pixel-centre coordinates: (0, 0), (w-1, 0), (w-1, h-1),
    (0, h-1), clockwise from the top-left (x = column, y = row)."""
    check_int("width", width, 1)
    check_int("height", height, 1)
    w, h = float(width - 1), float(height - 1)
    return np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]])


def corner_error(H_est, H_true, width: int, height: int) -> float:
    """Mean distance in pixels between the four image corners mapped by ``H_est`` and by ``H_true``.

    Parameters
    ----------
    H_est, H_true : (3, 3) array_like
        Homographies from the image of size ``width`` x ``height`` (the source) to another image.
    width, height : int
        Size of the source image in pixels; the corners are those of :func:`image_corners`.

    Returns
    -------
    float
        The mean corner distance in pixels of the target image; ``inf`` if ``H_est`` sends a corner to infinity or
        to the other side of the horizon (a sign flip of the homogeneous coordinate relative to ``H_true``).
    """
    He = _homography("H_est", H_est)
    Ht = _homography("H_true", H_true)
    c = np.hstack([image_corners(width, height), np.ones((4, 1))])
    pe = c @ He.T
    pt = c @ Ht.T
    # each H has an arbitrary scale, so only a corner-to-corner change of sign of w_est / w_true reveals a corner
    # sent across the horizon
    if np.any(pe[:, 2] == 0) or np.any(pt[:, 2] == 0) or len(set(np.sign(pe[:, 2] * pt[:, 2]))) != 1:
        return float("inf")
    d = pe[:, :2] / pe[:, 2:3] - pt[:, :2] / pt[:, 2:3]
    return float(np.sqrt((d**2).sum(axis=1)).mean())


def _as_boxes(name: str, boxes) -> np.ndarray:
    b = np.asarray(boxes, np.float64)
    if b.size == 0:
        return np.zeros((0, 4))
    if b.ndim != 2 or b.shape[1] != 4:
        raise ValueError(f"`{name}` must be an (N, 4) array of [x1, y1, x2, y2] boxes, got shape {b.shape}")
    if not np.all(np.isfinite(b)):
        raise ValueError(f"`{name}` contains non-finite coordinates")
    if np.any(b[:, 2] < b[:, 0]) or np.any(b[:, 3] < b[:, 1]):
        raise ValueError(f"`{name}` has a box with x2 < x1 or y2 < y1")
    return b


def box_iou(a, b) -> np.ndarray:
    """Intersection over union of every box in ``a`` with every box in ``b``.

    Parameters
    ----------
    a : (N, 4) array_like
        Boxes ``[x1, y1, x2, y2]`` in pixels (edge coordinates, so the width is ``x2 - x1``).
    b : (M, 4) array_like

    Returns
    -------
    (N, M) float64
        IoU in [0, 1]; 0 where both boxes are empty.
    """
    a, b = _as_boxes("a", a), _as_boxes("b", b)
    ix = np.clip(np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    iy = np.clip(np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    inter = ix * iy
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    union = area_a[:, None] + area_b[None, :] - inter
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(union > 0, inter / union, 0.0)


@dataclass(frozen=True)
class DetectionCounts:
    """True positives, false positives and false negatives of a detection-vs-truth matching."""

    tp: int
    fp: int
    fn: int

    def __add__(self, other: "DetectionCounts") -> "DetectionCounts":
        return DetectionCounts(self.tp + other.tp, self.fp + other.fp, self.fn + other.fn)

    @property
    def precision(self) -> float:
        """TP / (TP + FP); 1.0 when nothing was detected (no false claim was made)."""
        return self.tp / (self.tp + self.fp) if self.tp + self.fp else 1.0

    @property
    def recall(self) -> float:
        """TP / (TP + FN); 1.0 when there was nothing to find."""
        return self.tp / (self.tp + self.fn) if self.tp + self.fn else 1.0

    @property
    def f1(self) -> float:
        """Harmonic mean of precision and recall (0 when both are 0)."""
        p, r = self.precision, self.recall
        return 2 * p * r / (p + r) if p + r else 0.0


def match_boxes(pred, truth, iou_threshold: float = 0.5) -> tuple[DetectionCounts, np.ndarray]:
    """One-to-one greedy matching of predicted to true boxes by decreasing IoU.

    A pair counts when its IoU is at least ``iou_threshold``; each box is used at most once.

    Parameters
    ----------
    pred : (N, 4) array_like
        Predicted boxes ``[x1, y1, x2, y2]``.
    truth : (M, 4) array_like
        Ground-truth boxes.
    iou_threshold : float in (0, 1]

    Returns
    -------
    counts : DetectionCounts
    pairs : (K, 2) int
        Matched ``[i_pred, i_truth]`` index pairs.
    """
    if not 0.0 < float(iou_threshold) <= 1.0:
        raise ValueError(f"`iou_threshold` must be in (0, 1], got {iou_threshold}")
    iou = box_iou(pred, truth)
    n, m = iou.shape
    pairs = []
    if n and m:
        cand = np.argwhere(iou >= iou_threshold)
        order = np.argsort(-iou[cand[:, 0], cand[:, 1]], kind="stable")
        used_p, used_t = np.zeros(n, bool), np.zeros(m, bool)
        for i, j in cand[order]:
            if not used_p[i] and not used_t[j]:
                used_p[i] = used_t[j] = True
                pairs.append((i, j))
    k = len(pairs)
    return DetectionCounts(k, n - k, m - k), np.array(pairs, np.int64).reshape(-1, 2)


# ---- dense maps (stereo disparity): NaN = missing estimate / unknown truth ----


def _known(truth: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """Boolean map of pixels whose truth is known (finite) and, if given, inside ``mask``."""
    known = np.isfinite(truth)
    if mask is not None:
        if mask.shape != truth.shape:
            raise InputError(f"`mask` must have the shape of `truth` {truth.shape}, got {mask.shape}")
        known &= mask.astype(bool)
    return known


def _check_maps(estimate: np.ndarray, truth: np.ndarray) -> None:
    if estimate.shape != truth.shape:
        raise InputError(f"`estimate` must have the shape of `truth` {truth.shape}, got {estimate.shape}")


def bad_pixel_rate(estimate: np.ndarray, truth: np.ndarray, threshold: float, mask: np.ndarray | None = None) -> float:
    """Share of pixels with known truth whose estimate is missing (NaN) or off by more than ``threshold``.

    Parameters
    ----------
    estimate, truth : ndarray, (H, W) float
        Estimated and true values (e.g. disparity in pixels); NaN marks a missing estimate / unknown truth.
    threshold : float
        Largest accepted absolute error (e.g. 1.0 or 2.0 pixels for Middlebury's bad-1.0 / bad-2.0), >= 0.
    mask : ndarray, (H, W) bool, optional
        Restrict the evaluation to these pixels (e.g. non-occluded).

    Returns
    -------
    float
        In [0, 1]; NaN when no pixel has known truth.
    """
    _check_maps(estimate, truth)
    if not threshold >= 0:
        raise InputError(f"`threshold` must be >= 0, got {threshold}")
    known = _known(truth, mask)
    n = int(known.sum())
    if n == 0:
        return float("nan")
    err = np.abs(estimate[known].astype(np.float64) - truth[known])
    good = np.isfinite(err) & (err <= threshold)
    return float(1.0 - good.sum() / n)


def mean_abs_error(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Mean absolute error over pixels where both the estimate and the truth exist (NaN if there are none)."""
    _check_maps(estimate, truth)
    both = _known(truth, mask) & np.isfinite(estimate)
    if not both.any():
        return float("nan")
    return float(np.mean(np.abs(estimate[both].astype(np.float64) - truth[both])))


def density(estimate: np.ndarray, truth: np.ndarray | None = None, mask: np.ndarray | None = None) -> float:
    """Share of pixels with an estimate (finite), over the pixels with known truth when ``truth`` is given."""
    if truth is None:
        known = np.ones(estimate.shape, bool) if mask is None else mask.astype(bool)
    else:
        _check_maps(estimate, truth)
        known = _known(truth, mask)
    n = int(known.sum())
    return float("nan") if n == 0 else float(np.isfinite(estimate[known]).sum() / n)


def not_processed_table(dropped: Sequence[Mapping[str, Any]]) -> list[dict]:
    """The "Not processed" table of a report summary: a row ``[input, reason]`` per ``{"item", "reason"}`` that a
    stage could not use; an empty list when it used everything (so that ``tables += not_processed_table(dropped)``).

    Here rather than in :mod:`cvpipe.report`: every stage imports its task's report module, and the page builder's
    edits must not rerun them.

    Examples
    --------
    >>> not_processed_table([{"item": "b.jpg", "reason": "not a readable image"}])
    [{'title': 'Not processed', 'columns': ['input', 'reason'], 'rows': [['b.jpg', 'not a readable image']]}]
    >>> not_processed_table([])
    []
    """
    rows = [[d["item"], d["reason"]] for d in dropped]
    return [{"title": "Not processed", "columns": ["input", "reason"], "rows": rows}] if rows else []


#: the figures that a task's tracked metrics file keeps: its ``all`` rows, the few numbers that ``dvc exp show`` and
#: ``dvc metrics diff`` compare across experiments (everything per item goes to the stage's details file)
HEADLINE = {
    "hough": ("lines_ours", "lines_opencv", "parity_mean", "recall_ours", "recall_opencv"),
    "homography": ("median_corner_error_px", "success_rate", "median_inliers"),
    "defect": ("faulty", "perfect", "f1", "false_alarms"),
    "logo": ("precision", "recall", "answered"),
    "stereo": ("bad_2", "valid_fraction", "rectified", "vertical_error_median_px_worst", "depth_pairs"),
    "panorama": ("used_images", "ok_sets", "median_corner_error_px"),
}
#: decimals of the figures in a metrics file: pixel errors to 1e-4 px, rates and shares to 1e-4, so that noise below
#: that never shows as a change
METRIC_DECIMALS = 4


def headline(metrics: Mapping[str, Any]) -> dict:
    """The headline of a stage's metrics ``{task: {...}}``: the ``all`` figures named in :data:`HEADLINE` for the
    task, at any depth (``{"logo": {"sift": {"all": {...}}}}``), floats rounded to :data:`METRIC_DECIMALS`.

    Examples
    --------
    >>> headline({"logo": {"sift": {"all": {"precision": 0.912345678, "scenes": 40}, "nike": {"precision": 1.0}}}})
    {'logo': {'sift': {'all': {'precision': 0.9123}}}}
    """

    def keep(node: Mapping[str, Any], names: tuple) -> dict:
        out: dict = {}
        for key, value in node.items():
            if key == "all" and isinstance(value, Mapping):
                row = {k: round(v, METRIC_DECIMALS) if isinstance(v, float) else v
                       for k, v in value.items() if k in names}
                if row:
                    out[key] = row
            elif isinstance(value, Mapping):
                sub = keep(value, names)
                if sub:
                    out[key] = sub
        return out

    return {task: keep(body, HEADLINE.get(task, ())) for task, body in metrics.items() if isinstance(body, Mapping)}


def rounded(rows: Any) -> Any:
    """``rows`` (JSON-like: dicts, lists, numbers) with every float rounded to :data:`METRIC_DECIMALS`: plot rows
    are written at the precision they carry, so that noise below it never shows as a change."""
    if isinstance(rows, float):
        return round(rows, METRIC_DECIMALS)
    if isinstance(rows, Mapping):
        return {k: rounded(v) for k, v in rows.items()}
    if isinstance(rows, (list, tuple)):
        return [rounded(v) for v in rows]
    return rows

