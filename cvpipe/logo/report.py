"""Evaluation against ground truth, the stage records and metrics, the report's summary and pictures."""

from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

import cv2
import numpy as np

from ..io import to_bgr

if TYPE_CHECKING:
    from .detect import Detection


def evaluate(truth: Sequence[str | None], predicted: Sequence[str | None], scores: Sequence[float],
             threshold: float) -> dict:
    """Precision, recall and accuracy of brand decisions, and the precision-recall curve over the threshold.

    Parameters
    ----------
    truth : sequence of str or None
        True brand per scene (None = no gallery logo).
    predicted : sequence of str or None
        Brand of the best plausible hypothesis per scene, *before* thresholding (None when there is none).
    scores : sequence of float
        Its score (``-inf`` when there is none).
    threshold : float
        The decision threshold (``score_threshold``).

    Returns
    -------
    dict
        ``precision`` (correct brand / scenes answered with a brand; 1.0 when nothing is answered), ``recall``
        (correct brand / scenes with a logo), ``accuracy`` (correct brand or correct none / all scenes), the counts,
        and ``curve``: a list of ``{"threshold", "precision", "recall"}`` at every distinct score.

    Examples
    --------
    >>> ev = evaluate(["a", "b", None], ["a", "c", "a"], [9.0, 5.0, 1.0], threshold=2.0)
    >>> ev["precision"], ev["recall"], ev["accuracy"]
    (0.5, 0.5, 0.6666666666666666)
    """
    if not (len(truth) == len(predicted) == len(scores)):
        raise ValueError(f"`truth`, `predicted` and `scores` must have equal lengths, got "
                         f"{len(truth)}, {len(predicted)}, {len(scores)}")
    s = np.asarray(scores, np.float64)
    correct = np.array([p is not None and p == t for p, t in zip(predicted, truth)])
    has = np.array([p is not None for p in predicted])
    positives = int(sum(t is not None for t in truth))
    negatives_truth = np.array([t is None for t in truth])

    def at(th: float) -> dict:
        answered = has & (s >= th)
        tp = int(np.sum(answered & correct))
        n_ans = int(answered.sum())
        right_none = int(np.sum(~answered & negatives_truth))
        return {"threshold": float(th), "answered": n_ans, "correct": tp,
                "precision": tp / n_ans if n_ans else 1.0,
                "recall": tp / positives if positives else 0.0,
                "accuracy": (tp + right_none) / len(truth) if len(truth) else 0.0}

    finite = sorted({float(v) for v in s[np.isfinite(s)]}, reverse=True)
    curve = [{k: v for k, v in at(t).items() if k in ("threshold", "precision", "recall")} for t in finite]
    result = at(threshold)
    result.update({"scenes": len(truth), "positives": positives, "curve": curve})
    return result


def quad_error(quad: np.ndarray | None, truth: np.ndarray | Sequence | None, cyclic: bool = False) -> float | None:
    """Mean distance in pixels between corresponding corners of two (4, 2) quads (None when either is None).

    With ``cyclic`` the smallest error over the four starting corners of ``quad``: the outline of a mark with
    rotational symmetry (or of a gallery view stored rotated) may legitimately start at another corner.
    """
    if quad is None or truth is None:
        return None
    q, t = np.asarray(quad, np.float64), np.asarray(truth, np.float64)
    if q.shape != (4, 2) or t.shape != (4, 2):
        raise ValueError(f"quads must be (4, 2), got {q.shape} and {t.shape}")
    shifts = range(4) if cyclic else range(1)
    return float(min(np.linalg.norm(np.roll(q, i, axis=0) - t, axis=1).mean() for i in shifts))


# --------------------------------------------------------------------------------------------------- pictures


def confusion(truth: Sequence[str | None], predicted: Sequence[str | None],
              labels: Sequence[str]) -> np.ndarray:
    """(L+1, L+1) int counts, rows = truth, columns = decision, over ``labels`` plus a last "none" class."""
    index = {b: i for i, b in enumerate(labels)}
    none = len(labels)
    m = np.zeros((none + 1, none + 1), np.int64)
    for t, p in zip(truth, predicted):
        m[index.get(t, none) if t is not None else none, index.get(p, none) if p is not None else none] += 1
    return m


def draw_confusion(matrix: np.ndarray, labels: Sequence[str], title: str, cell: int = 34) -> np.ndarray:
    """A confusion matrix as a BGR picture: rows = truth, columns = decision, darker = more scenes."""
    names = list(labels) + ["none"]
    n = len(names)
    if matrix.shape != (n, n):
        raise ValueError(f"`matrix` must be ({n}, {n}) for {n - 1} labels plus none, got {matrix.shape}")
    left, top = 120, 130
    img = np.full((top + n * cell + 10, left + n * cell + 10, 3), 255, np.uint8)
    font = cv2.FONT_HERSHEY_SIMPLEX
    cv2.putText(img, title, (8, 20), font, 0.55, (0, 0, 0), 1, cv2.LINE_AA)
    row_sum = np.maximum(matrix.sum(axis=1, keepdims=True), 1)
    for i in range(n):
        cv2.putText(img, names[i][:14], (6, top + i * cell + cell // 2 + 5), font, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
        label = np.full((cell, top - 30, 3), 255, np.uint8)
        cv2.putText(label, names[i][:14], (2, cell // 2 + 5), font, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
        rot = cv2.rotate(label, cv2.ROTATE_90_COUNTERCLOCKWISE)
        img[30:30 + rot.shape[0], left + i * cell:left + i * cell + rot.shape[1]] = rot
        for j in range(n):
            v = int(matrix[i, j])
            shade = int(255 - 200 * v / row_sum[i, 0])
            color = (shade, 255, shade) if i == j else (shade, shade, 255)
            x0, y0 = left + j * cell, top + i * cell
            cv2.rectangle(img, (x0, y0), (x0 + cell - 1, y0 + cell - 1), color, -1)
            cv2.rectangle(img, (x0, y0), (x0 + cell - 1, y0 + cell - 1), (200, 200, 200), 1)
            if v:
                cv2.putText(img, str(v), (x0 + 6, y0 + cell // 2 + 5), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    return img


def draw_detection(scene: np.ndarray, reference: np.ndarray, quad: np.ndarray | None,
                   gallery_xy: np.ndarray, scene_xy: np.ndarray, truth_quad: np.ndarray | None = None,
                   caption: str = "", height: int = 360) -> np.ndarray:
    """Reference beside scene (both scaled to ``height`` px): inlier matches as lines, the found outline in green,
    the true outline (when given) in blue, ``caption`` on top. BGR uint8 in, BGR uint8 out."""
    scene, reference = to_bgr(scene), to_bgr(reference)
    sr, ss = height / reference.shape[0], height / scene.shape[0]
    ref_s = cv2.resize(reference, (max(1, int(round(reference.shape[1] * sr))), height))
    sc_s = cv2.resize(scene, (max(1, int(round(scene.shape[1] * ss))), height))
    canvas = np.full((height + 26, ref_s.shape[1] + sc_s.shape[1] + 6, 3), 255, np.uint8)
    canvas[26:, :ref_s.shape[1]] = ref_s
    off = ref_s.shape[1] + 6
    canvas[26:, off:] = sc_s
    for (gx, gy), (sx, sy) in zip(np.asarray(gallery_xy), np.asarray(scene_xy)):
        p1 = (int(round(gx * sr)), int(round(gy * sr)) + 26)
        p2 = (int(round(sx * ss)) + off, int(round(sy * ss)) + 26)
        cv2.line(canvas, p1, p2, (0, 200, 255), 1, cv2.LINE_AA)
        cv2.circle(canvas, p2, 2, (0, 200, 255), -1, cv2.LINE_AA)
    for q, color in ((truth_quad, (255, 80, 0)), (quad, (0, 200, 0))):
        if q is not None:
            pts = np.round(np.asarray(q, np.float64) * ss + [off, 26]).astype(np.int32)
            cv2.polylines(canvas, [pts], True, color, 2, cv2.LINE_AA)
    cv2.putText(canvas, caption, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    return canvas


# ------------------------------------------------------------------------------------ pipeline results (pure)

#: what an accuracy cell says when no scene of the run has ground truth
NO_TRUTH = "no ground truth"


def scene_record(scene: str, det: Detection, reference: str | None, truth: tuple[str | None, np.ndarray | None]
                 | None = None, reference_names: Mapping[str, Sequence[str]] | None = None) -> dict:
    """The JSON record of one scene's decision as the ``logo_verify`` stage stores it.

    Parameters
    ----------
    scene : str
        The scene's name (file stem).
    det : Detection
        From :func:`decide`.
    reference : str or None
        Name of the reference image of ``det.best`` (None when no hypothesis was plausible).
    truth : (brand, quad) or None
        The scene's ground truth (brand None = no gallery logo, quad (4, 2) or None); None when it has none.
    reference_names : mapping detector -> sequence of str, optional
        The reference names of each gallery the hypotheses come from; with them a labelled scene whose true brand
        was missed gets ``missed``: why the true brand's best hypothesis was not the answer.

    Returns
    -------
    dict
        ``scene``, ``brand`` (after the threshold), ``score`` (of the best plausible hypothesis, None when there is
        none), ``inliers``, ``quad``, ``best_brand`` (before the threshold), ``reference``, ``labelled`` and, for a
        labelled scene, ``truth``, ``truth_quad`` and ``quad_error_px`` (when the brand is right), and ``missed``
        (see :func:`missed_record`) when the true brand was not the answer.
    """
    best = det.best
    rec = {"scene": scene, "brand": det.brand, "inliers": int(det.inliers),
           "score": float(det.score) if np.isfinite(det.score) else None,
           "quad": None if det.quad is None else np.asarray(det.quad, np.float64).tolist(),
           "best_brand": best.brand if best is not None else None, "reference": reference,
           "labelled": truth is not None}
    if truth is not None:
        brand, quad = truth
        rec.update(truth=brand, truth_quad=None if quad is None else np.asarray(quad, np.float64).tolist(),
                   quad_error_px=(quad_error(det.quad, quad, cyclic=True)
                                  if det.brand is not None and det.brand == brand else None))
        if brand is not None and det.brand != brand and reference_names is not None:
            rec["missed"] = missed_record(det, brand, reference_names)
    return rec


def missed_record(det: Detection, brand: str, reference_names: Mapping[str, Sequence[str]]) -> dict | None:
    """Why ``brand`` was not the answer of a scene: its best hypothesis (plausible ones first, then by score and
    inliers) with ``reference``, ``detector``, ``matches``, ``inliers``, ``score`` (None when rejected), ``reason``
    (the failed check, or "below the threshold" / "a better brand won") and ``quad`` (None when the fit had none);
    None when no reference of the brand had enough matches to be tried."""
    mine = [h for h in det.hypotheses if h.brand == brand]
    if not mine:
        return None
    h = max(mine, key=lambda h: (h.plausible, h.score, h.inliers, h.matches))
    reason = h.reason or ("a better brand won" if det.brand is not None else "below the threshold")
    return {"reference": reference_names[h.detector][h.reference], "detector": h.detector, "matches": int(h.matches),
            "inliers": int(h.inliers), "score": float(h.score) if np.isfinite(h.score) else None, "reason": reason,
            "quad": None if h.quad is None else np.asarray(h.quad, np.float64).round(2).tolist()}


def draw_missed(scenes: Sequence[np.ndarray], records: Sequence[dict], height: int = 200,
                per_row: int = 4) -> np.ndarray:
    """A strip of missed scenes: each scene scaled to ``height`` px with the true outline in blue and the outline of
    the true brand's best rejected hypothesis in red (``record["missed"]["quad"]``), captioned with the scene, the
    true brand and why it was missed. BGR uint8 in, BGR uint8 out; ``per_row`` thumbnails a row."""
    tiles = []
    width = 0
    for img, r in zip(scenes, records):
        img = to_bgr(img)
        s = height / img.shape[0]
        tile = cv2.resize(img, (max(1, int(round(img.shape[1] * s))), height), interpolation=cv2.INTER_AREA)
        m = r.get("missed")
        for q, color in ((r.get("truth_quad"), (255, 80, 0)), (m and m.get("quad"), (0, 0, 230))):
            if q is not None:
                cv2.polylines(tile, [np.round(np.asarray(q, np.float64) * s).astype(np.int32)], True, color, 2,
                              cv2.LINE_AA)
        lines = [f"{r['scene']}: {r.get('truth')} -> {r.get('brand') or 'none'}"]
        lines.append("no reference matched" if m is None else
                     f"{m['detector']} {m['inliers']}/{m['matches']}: {m['reason']}"[:48])
        cap = np.full((36, tile.shape[1], 3), 255, np.uint8)
        for k, text in enumerate(lines):
            cv2.putText(cap, text, (3, 14 + 16 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
        tiles.append(np.vstack([tile, cap]))
        width = max(width, tile.shape[1])
    rows = []
    for i in range(0, len(tiles), per_row):
        row = [np.pad(t, ((0, 0), (0, width - t.shape[1] + 4), (0, 0)), constant_values=255)
               for t in tiles[i:i + per_row]]
        row += [np.full_like(row[0], 255)] * (per_row - len(row))
        rows.append(np.hstack(row))
    return np.vstack(rows) if rows else np.full((height, height, 3), 255, np.uint8)


def evaluate_records(records: Sequence[dict], threshold: float) -> dict | None:
    """:func:`evaluate` over the labelled scene records of :func:`scene_record`, plus ``quad_error_px_median``
    (over the scenes whose brand is right, when any); None when no record is labelled."""
    lab = [r for r in records if r["labelled"]]
    if not lab:
        return None
    ev = evaluate([r["truth"] for r in lab], [r["best_brand"] for r in lab],
                  [r["score"] if r["score"] is not None else -np.inf for r in lab], threshold)
    errs = [r["quad_error_px"] for r in lab if r.get("quad_error_px") is not None]
    if errs:
        ev["quad_error_px_median"] = float(np.median(errs))
    return ev


def brand_recall(records: Sequence[dict]) -> dict[str, tuple[int, int]]:
    """``brand -> (found, scenes)`` over the labelled scene records (:func:`scene_record`) whose true brand is that
    brand: how many got it as their answer.

    Examples
    --------
    >>> recs = [{"labelled": True, "truth": "a", "brand": "a"}, {"labelled": True, "truth": "a", "brand": None},
    ...         {"labelled": True, "truth": None, "brand": "b"}, {"labelled": False, "brand": "a"}]
    >>> brand_recall(recs)
    {'a': (1, 2)}
    """
    out: dict[str, tuple[int, int]] = {}
    for r in records:
        if r.get("labelled") and r.get("truth") is not None:
            found, n = out.get(r["truth"], (0, 0))
            out[r["truth"]] = (found + (r["brand"] == r["truth"]), n + 1)
    return dict(sorted(out.items()))


def metric_key(name: str) -> str:
    """``name`` usable as one DVC metric key (DVC joins nested keys with dots)."""
    return name.replace(".", "_")


def found_counts(records: Sequence[dict], brands: Sequence[str]) -> dict[str, int]:
    """Scenes answered with each brand (every brand listed, 0 when never found)."""
    return {b: sum(r["brand"] == b for r in records) for b in brands}


def metrics_of(records: Sequence[dict], brands: Sequence[str], detector: str, threshold: float) -> dict:
    """The numeric metrics of one detector's run, ``{"logo": {detector: {"all": {...}, "found": {brand: n}}}}``.

    ``all`` always has the counts ``scenes`` and ``answered`` (scenes given a brand) and ``labelled`` (scenes with
    ground truth); with ground truth also ``precision``, ``recall``, ``accuracy``, ``correct``, ``positives`` (over
    the labelled scenes) and ``quad_error_px_median`` when some brand was right. No strings, no NaN.
    """
    summary = {"scenes": len(records), "answered": sum(r["brand"] is not None for r in records),
               "labelled": sum(bool(r["labelled"]) for r in records)}
    ev = evaluate_records(records, threshold)
    if ev is not None:
        summary.update({k: ev[k] for k in ("precision", "recall", "accuracy", "correct", "positives",
                                           "quad_error_px_median") if k in ev})
    found = {metric_key(b): n for b, n in found_counts(records, brands).items()}
    return {"logo": {metric_key(detector): {"all": summary, "found": found}}}


def pr_rows(records: Sequence[dict], detector: str, threshold: float) -> list[dict]:
    """``dvc plots`` rows ``{"threshold", "precision", "recall", "method"}`` of the precision-recall curve over the
    labelled scenes; empty without ground truth (an empty plot file is valid for ``dvc plots``)."""
    ev = evaluate_records(records, threshold)
    return [] if ev is None else [dict(c, method=detector) for c in ev["curve"]]


def found_plot(decisions: dict[str, Sequence[dict]], brands: Sequence[str]) -> list[dict]:
    """``dvc plots`` rows ``{"label", "brand", "method", "found"}``: scenes answered with each brand per detector
    (the quality plot that needs no ground truth)."""
    return [{"label": f"{b} ({m})", "brand": b, "method": m, "found": n}
            for m, recs in decisions.items() for b, n in found_counts(recs, brands).items()]


def pick_method(decisions: dict[str, Sequence[dict]], threshold: float, default: str) -> str:
    """The method whose results the overlays show: the most accurate one with ground truth (ties: more correct
    answers, then the earlier one), else ``default`` (``logo.report.method``) when it ran, else the first."""
    scored = {m: evaluate_records(r, threshold) for m, r in decisions.items()}
    if any(v is not None for v in scored.values()):
        return max((m for m in decisions if scored[m] is not None),
                   key=lambda m: (scored[m]["accuracy"], scored[m]["correct"], -list(decisions).index(m)))
    return default if default in decisions else next(iter(decisions))


def merge_dropped(dropped: dict[str, Sequence[dict]]) -> list[dict]:
    """Per-detector ``{"item", "reason"}`` lists merged into one, each item and reason once with the detectors that
    dropped it (``{"item", "reason", "methods"}``), in first-seen order."""
    merged: dict[tuple[str, str], list[str]] = {}
    for m, items in dropped.items():
        for d in items:
            merged.setdefault((d["item"], d["reason"]), [])
            if m not in merged[(d["item"], d["reason"])]:
                merged[(d["item"], d["reason"])].append(m)
    return [{"item": i, "reason": r, "methods": ms} for (i, r), ms in merged.items()]


def report_summary(decisions: dict[str, Sequence[dict]], brands: Sequence[str], references: int,
                   threshold: float, pictures: list[dict], dropped: list[dict]) -> dict:
    """The report page's summary of the logo task (schema in ``cvpipe.report``).

    Parameters
    ----------
    decisions : dict
        Detector -> its scene records (:func:`scene_record`), every detector over the same scenes.
    brands : sequence of str
        The gallery's brands.
    references : int
        Number of gallery images.
    threshold : float
        The decision threshold the records were made with (``logo.verify.score_threshold``).
    pictures : list of dict
        ``{"path", "caption"}``, repo-relative paths.
    dropped : list of dict
        From :func:`merge_dropped`: every input that was not processed, with the detectors and the reason.
    """
    methods = list(decisions)
    scenes = sorted({r["scene"] for recs in decisions.values() for r in recs})
    first = decisions[methods[0]] if methods else []
    labelled = sum(bool(r["labelled"]) for r in first)
    rows = []
    for m in methods:
        ev = evaluate_records(decisions[m], threshold)
        acc = [NO_TRUTH] * 4 if ev is None else [
            round(ev["accuracy"], 3), round(ev["precision"], 3), round(ev["recall"], 3),
            round(ev["quad_error_px_median"], 2) if "quad_error_px_median" in ev else None]
        rows.append([m, len(decisions[m]), sum(r["brand"] is not None for r in decisions[m]), *acc])
    by_scene = {m: {r["scene"]: r for r in recs} for m, recs in decisions.items()}
    scene_rows = []
    for s in scenes:
        truth = next((r for m in methods for r in [by_scene[m].get(s)] if r is not None), None)
        row = [s, (truth.get("truth") or "none") if truth is not None and truth["labelled"] else NO_TRUTH]
        for m in methods:
            r = by_scene[m].get(s)
            row += (["not processed", None, None] if r is None else
                    [r["brand"] or "none", None if r["score"] is None else round(r["score"], 2), r["inliers"]])
        scene_rows.append(row)
    counts = {m: found_counts(decisions[m], brands) for m in methods}
    recall = {m: brand_recall(decisions[m]) for m in methods}
    truth_brands = sorted({b for m in methods for b in recall[m]})
    tables = [
        {"title": "Per detector",
         "columns": ["detector", "scenes", "brand found", "accuracy", "precision", "recall",
                     "outline error median (px)"], "rows": rows},
        {"title": "Found per brand (scenes answered with it)", "columns": ["brand", *methods],
         "rows": [[b, *(counts[m][b] for m in methods)] for b in brands]},
        *([{"title": "Recall per brand (scenes with ground truth whose brand was found, of those with it)",
            "columns": ["brand", *methods],
            "rows": [[b, *(f"{recall[m][b][0]} / {recall[m][b][1]}" if b in recall[m] else "-" for m in methods)]
                     for b in truth_brands]}] if truth_brands else []),
        {"title": "Per scene: brand found, score (-log10 NFA) and inliers per detector",
         "columns": ["scene", "true brand", *(f"{m} {c}" for m in methods for c in ("brand", "score", "inliers"))],
         "rows": scene_rows},
    ]
    if dropped:
        tables.append({"title": "Not processed", "columns": ["input", "reason"],
                       "rows": [[d["item"], f"{', '.join(d['methods'])}: {d['reason']}"] for d in dropped]})
    if labelled == len(first) and first:
        truth_note = f"All {labelled} scenes have ground truth."
    elif labelled:
        truth_note = (f"{labelled} of {len(first)} scenes have ground truth; accuracy, precision and recall count "
                      f"those only.")
    else:
        truth_note = "The scenes have no ground truth: the tables show what each detector found."
    return {
        "task": "logo", "title": "Logo recognition: which brand is in the scene and where",
        "description": (
            f"Every scene's features are matched against the gallery ({len(brands)} brands, {references} reference "
            f"images) in one index; each reference's best homography is verified (RANSAC plus shape checks) and "
            f"scored by its a-contrario significance (-log10 NFA); below {threshold:g} the answer is none. "
            f"{truth_note} Overlays: found outline in green, {'true outline in blue, ' if labelled else ''}"
            "inlier matches in orange. "
            "Times: `dvc plots show` (outputs/timings)."),
        "pictures": pictures,
        "tables": tables,
    }
