"""Threshold, morphology and connected components of a difference map: defect regions and the verdict."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..params import DefectRegionParams
from ._util import check_homography, disc
from .diff import Difference
from .register import ProbeRegistration

VERDICTS = ("perfect", "faulty")


@dataclass(frozen=True)
class Inspection:
    """Result of :func:`find_regions` / :func:`inspect`.

    Attributes
    ----------
    verdict : {"perfect", "faulty"}
    score : float
        Evidence of the strongest region: the sum of its difference over pixels divided by the threshold, i.e. its
        area in "pixels at threshold contrast"; 0 when there is no region.
    regions : (K, 4) float64
        Boxes ``[x1, y1, x2, y2]`` in reference pixels (pixel-edge coordinates), strongest first.
    probe_regions : (K, 4) float64
        The same boxes mapped into probe pixels (axis-aligned bounds of the mapped corners) and padded by ``pad``.
    region_scores : (K,) float64
    threshold : float
        Low (extent) threshold used, grey levels.
    registration : ProbeRegistration or None
    difference : Difference or None
    """

    verdict: str
    score: float
    regions: np.ndarray
    probe_regions: np.ndarray
    region_scores: np.ndarray
    threshold: float
    registration: ProbeRegistration | None = None
    difference: Difference | None = None


def map_boxes(boxes: np.ndarray, H: np.ndarray) -> np.ndarray:
    """Axis-aligned bounds of boxes ``[x1, y1, x2, y2]`` (K, 4) after mapping their corners by ``H``.

    Examples
    --------
    >>> import numpy as np
    >>> map_boxes([[0, 0, 10, 10]], np.diag([2.0, 2.0, 1.0])).tolist()
    [[0.0, 0.0, 20.0, 20.0]]
    """
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    if len(boxes) == 0:
        return boxes.copy()
    H = check_homography(H)
    x1, y1, x2, y2 = boxes.T
    corners = np.stack([np.stack([x1, y1], -1), np.stack([x2, y1], -1), np.stack([x2, y2], -1),
                        np.stack([x1, y2], -1)], 1)  # (K, 4, 2)
    pts = np.concatenate([corners, np.ones(corners.shape[:2] + (1,))], -1) @ H.T
    xy = pts[..., :2] / pts[..., 2:]
    return np.concatenate([xy.min(1), xy.max(1)], 1)


def merge_boxes(boxes: np.ndarray, scores: np.ndarray, distance: float) -> tuple[np.ndarray, np.ndarray]:
    """Merge boxes closer than ``distance`` pixels (gap along both axes) into their union, summing the scores.

    Parameters
    ----------
    boxes : (K, 4) float
        ``[x1, y1, x2, y2]``.
    scores : (K,) float
    distance : float
        Largest gap, in pixels, between two boxes that are merged; 0 merges only overlapping or touching boxes,
        a negative value merges nothing.

    Examples
    --------
    >>> boxes, scores = merge_boxes([[0, 0, 10, 10], [12, 0, 20, 10], [50, 50, 60, 60]], [1.0, 2.0, 4.0], 5.0)
    >>> boxes.tolist(), scores.tolist()  # the first two are 2 px apart: one box
    ([[50.0, 50.0, 60.0, 60.0], [0.0, 0.0, 20.0, 10.0]], [4.0, 3.0])
    """
    boxes, scores = np.array(boxes, np.float64).reshape(-1, 4), np.array(scores, np.float64).reshape(-1)
    if distance < 0:
        return boxes, scores
    merged = True
    while merged and len(boxes) > 1:
        merged = False
        for i in range(len(boxes)):
            gap_x = np.maximum(boxes[:, 0], boxes[i, 0]) - np.minimum(boxes[:, 2], boxes[i, 2])
            gap_y = np.maximum(boxes[:, 1], boxes[i, 1]) - np.minimum(boxes[:, 3], boxes[i, 3])
            near = (gap_x <= distance) & (gap_y <= distance)
            near[i] = False
            if near.any():
                group = near.copy()
                group[i] = True
                union = np.r_[boxes[group, :2].min(0), boxes[group, 2:].max(0)]
                boxes = np.vstack([boxes[~group], union])
                scores = np.r_[scores[~group], scores[group].sum()]
                merged = True
                break
    return boxes, scores


def find_regions(diff: Difference, H: np.ndarray, probe_shape: tuple[int, int],
                 params: DefectRegionParams | None = None) -> Inspection:
    """Threshold the difference, clean it, and turn connected components into defect regions and a verdict.

    The extent threshold is ``threshold`` times the reference contrast, raised to ``noise_factor`` noise standard
    deviations when the probe is noisier; a component is kept when some pixel in it reaches ``seed_threshold``
    times the contrast (hysteresis) and it has at least ``min_area`` pixels after opening and closing.

    Parameters
    ----------
    diff : Difference
    H : (3, 3)
        Reference -> probe, to map the regions into the probe.
    probe_shape : (h, w)
        Probe size; mapped boxes are clipped to it.
    params : DefectRegionParams, optional

    Examples
    --------
    >>> import numpy as np
    >>> diff = np.zeros((100, 100), np.float32)
    >>> diff[40:50, 20:35] = 80  # grey levels, against a contrast of 200: thresholds 30 (extent) and 60 (seed)
    >>> d = Difference(diff, np.ones(diff.shape, bool), gain=1.0, bias=0.0, noise=1.0, contrast=200.0)
    >>> r = find_regions(d, np.eye(3), (100, 100))
    >>> r.verdict, r.regions.tolist()
    ('faulty', [[20.0, 40.0, 35.0, 50.0]])
    """
    p = params or DefectRegionParams()
    H = check_homography(H)
    contrast = max(diff.contrast, 1.0)
    t_low = max(p.threshold * contrast, p.noise_factor * diff.noise)
    t_high = max(p.seed_threshold * contrast, t_low)
    mask = (diff.diff > t_low).astype(np.uint8)
    if p.open_radius > 0:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, disc(p.open_radius))
    if p.close_radius > 0:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, disc(p.close_radius))
    mask &= diff.valid.astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    boxes, scores = [], []
    if n > 1:
        on = mask.astype(bool)
        mass = np.bincount(labels[on], weights=diff.diff[on], minlength=n)
        seeded = np.zeros(n, bool)
        core = (diff.diff >= t_high).astype(np.uint8)
        if p.seed_radius > 0:  # misregistered edges leave thin slivers; real defects have a solid core
            core = cv2.morphologyEx(core, cv2.MORPH_OPEN, disc(p.seed_radius))
        seeded[labels[on & core.astype(bool)]] = True
        for i in range(1, n):
            x, y, w, h, area = stats[i]
            if area < p.min_area or not seeded[i]:
                continue
            boxes.append([x, y, x + w, y + h])
            scores.append(mass[i] / t_low)
    boxes_a, scores_a = merge_boxes(np.array(boxes, np.float64).reshape(-1, 4), np.array(scores, np.float64),
                                    p.merge_distance)
    order = np.argsort(scores_a, kind="stable")[::-1]
    boxes_a, scores_a = boxes_a[order], scores_a[order]
    probe_boxes = map_boxes(boxes_a, H)
    if len(probe_boxes):
        ph, pw = probe_shape[:2]
        probe_boxes[:, :2] -= p.pad
        probe_boxes[:, 2:] += p.pad
        probe_boxes[:, [0, 2]] = probe_boxes[:, [0, 2]].clip(0, pw)
        probe_boxes[:, [1, 3]] = probe_boxes[:, [1, 3]].clip(0, ph)
    score = float(scores_a[0]) if len(scores_a) else 0.0
    return Inspection("faulty" if len(boxes_a) else "perfect", score, boxes_a, probe_boxes, scores_a, float(t_low),
                      None, diff)


def choose(first: Inspection, alternative: Inspection | None) -> Inspection:
    """The inspection to keep: ``first``, unless it is faulty and the ``alternative`` leaves a lower score.

    Parameters
    ----------
    first : Inspection
        The comparison after :func:`register_probe`'s registration.
    alternative : Inspection or None
        The comparison after :func:`register_direct`'s registration, when :func:`wants_alternative` and it
        succeeded.

    Examples
    --------
    >>> import numpy as np
    >>> def result(verdict, score):
    ...     return Inspection(verdict, score, np.zeros((0, 4)), np.zeros((0, 4)), np.zeros(0), 10.0)
    >>> first, alternative = result("faulty", 40.0), result("perfect", 0.0)
    >>> choose(first, alternative) is alternative, choose(first, None) is first
    (True, True)
    """
    if alternative is not None and first.verdict == "faulty" and alternative.score < first.score:
        return alternative
    return first


def regions_item(item: tuple, p: DefectRegionParams) -> tuple[dict, float]:
    """Regions and verdict of one probe from its difference maps: the per-probe work of the ``defect_regions``
    stage, an item of :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    item : tuple
        ``(arrays, registration)``: the probe's ``defect_diff`` arrays (``alt_``-prefixed ones for the direct
        alternative, when there is one) and its ``registration.json`` record (``file``, ``probe_shape``,
        ``primary`` and ``alternative`` with their ``H`` and ``method``).
    p : DefectRegionParams

    Returns
    -------
    (dict, float)
        The probe's ``results.json`` record, for the registration :func:`choose` keeps, and the seconds it took.

    Examples
    --------
    >>> import cv2
    >>> from cvpipe.defect import difference_item
    >>> from cvpipe.params import DefectDiffParams, DefectRegionParams
    >>> ref = cv2.GaussianBlur(np.random.default_rng(0).integers(0, 255, (96, 96)).astype(np.uint8), (0, 0), 2)
    >>> probe = ref.copy(); probe[40:52, 40:52] = 255   # a bright square where the reference has texture
    >>> arrays, _, _ = difference_item((probe, np.ones(ref.shape, bool), None), (ref, DefectDiffParams()))
    >>> primary = {"H": np.eye(3).tolist(), "method": "features"}
    >>> reg = {"file": "probe.png", "probe_shape": ref.shape, "primary": primary}
    >>> record, _ = regions_item((arrays, reg), DefectRegionParams())
    >>> record["verdict"], record["regions"].tolist()
    ('faulty', [[38.0, 38.0, 53.0, 53.0]])
    """
    import time

    arrays, reg = item
    t0 = time.perf_counter()
    first = find_regions(Difference.from_arrays(arrays), reg["primary"]["H"], reg["probe_shape"], p)
    alt = (find_regions(Difference.from_arrays(arrays, "alt_"), reg["alternative"]["H"], reg["probe_shape"], p)
           if "alt_diff" in arrays else None)
    seconds = time.perf_counter() - t0
    chosen = "alternative" if choose(first, alt) is alt else "primary"
    r = alt if chosen == "alternative" else first
    return {"probe": reg["file"], "verdict": r.verdict, "score": r.score, "regions": r.probe_regions,
            "reference_regions": r.regions, "region_scores": r.region_scores, "threshold": r.threshold,
            "H": reg[chosen]["H"], "registration": chosen, "method": reg[chosen]["method"]}, seconds
