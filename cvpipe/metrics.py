"""Evaluation metrics shared by the tasks' tests and benchmarks (generic: no task-specific logic here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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


def corner_error(H_est, H_true, width: int, height: int) -> float:
    """Mean distance in pixels between the image corners mapped by ``H_est`` and by ``H_true``.

    Parameters
    ----------
    H_est, H_true : (3, 3) array_like
        Homographies of the same direction.
    width, height : int
        Size of the image whose corners ``(0, 0), (w-1, 0), (w-1, h-1), (0, h-1)`` are mapped.
    """
    corners = np.array([[0, 0, 1], [width - 1, 0, 1], [width - 1, height - 1, 1], [0, height - 1, 1]], float)
    out = []
    for H in (H_est, H_true):
        H = np.asarray(H, np.float64)
        if H.shape != (3, 3) or not np.all(np.isfinite(H)):
            raise ValueError(f"homographies must be finite 3x3 matrices, got shape {H.shape}")
        p = corners @ H.T
        out.append(p[:, :2] / p[:, 2:])
    return float(np.linalg.norm(out[0] - out[1], axis=1).mean())
