"""The defect task's pictures and report: the regions and heat-map pictures, scores of inspection records against
ground truth, metrics, ``dvc plots`` rows and the report page's summary, from the records of the ``defect_regions``
stage (one per probe, as ``cvpipe inspect --json`` prints them) and the optional truth.

Pure functions: records and arrays in, dicts and images out (the ``defect_report`` stage reads and writes).
A record with ``verdict`` None is a probe that was not inspected (``error`` says why). ``truth`` maps a probe's file
name to ``{"verdict", "boxes" (K, 4) in probe pixels, "H" (3, 3) reference -> probe or None}``, only for the probes
that have ground truth.
"""

from __future__ import annotations

import statistics
from pathlib import PurePath
from typing import Any, Mapping

import cv2
import numpy as np

from ..errors import InputError
from ..io import to_bgr
from ..metrics import DetectionCounts, box_iou, corner_error, match_boxes, not_processed_table

#: a region matches a true box at this IoU (DeepPCB's criterion, also used by ``cvpipe bench defect``)
IOU = 0.33
NO_TRUTH = "no ground truth"
NOT_INSPECTED = "not inspected"


def draw_regions(image: np.ndarray, regions: np.ndarray, truth: np.ndarray | None = None,
                 thickness: int = 2) -> np.ndarray:
    """A BGR copy of ``image`` with ``regions`` outlined in red and optional ``truth`` boxes in green.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) uint8
    regions, truth : (K, 4)
        Boxes ``[x1, y1, x2, y2]`` in the image's pixels.

    Examples
    --------
    >>> import numpy as np
    >>> out = draw_regions(np.zeros((40, 40), np.uint8), [[5, 5, 20, 20]])
    >>> out.shape, out[5, 10].tolist()  # on the box's top edge: red (BGR)
    ((40, 40, 3), [0, 0, 255])
    """
    out = to_bgr(np.asarray(image)).copy()  # drawn on: never the caller's array
    for boxes, color in ((truth, (0, 200, 0)), (regions, (0, 0, 255))):
        if boxes is None:
            continue
        for x1, y1, x2, y2 in np.asarray(boxes, np.float64).reshape(-1, 4):
            cv2.rectangle(out, (int(round(x1)), int(round(y1))), (int(round(x2)), int(round(y2))), color,
                          thickness)
    return out


def heat_map(diff: np.ndarray, threshold: float) -> np.ndarray:
    """BGR heat map of a difference image; the colour scale saturates at twice ``threshold``.

    Parameters
    ----------
    diff : (H, W) float
        Difference in grey levels (:attr:`Difference.diff`).
    threshold : float
        The extent threshold (:attr:`Inspection.threshold`), which lands in the middle of the scale.

    Examples
    --------
    >>> import numpy as np
    >>> heat_map(np.array([[0.0, 10.0, 40.0]], np.float32), threshold=10.0).shape
    (1, 3, 3)
    """
    scale = 255.0 / max(2.0 * float(threshold), 1e-6)
    return cv2.applyColorMap(np.clip(np.asarray(diff, np.float32) * scale, 0, 255).astype(np.uint8),
                             cv2.COLORMAP_INFERNO)


def evaluate(results: list[dict], truth: list[dict], iou: float = IOU) -> dict:
    """Image- and defect-level scores of inspection records against ground truth.

    Parameters
    ----------
    results : list of dict
        Records as ``cvpipe inspect --json`` prints them (``probe``, ``verdict`` or None with ``error``,
        ``regions`` in probe pixels), matched to ``truth`` by the file name of ``probe``.
    truth : list of dict
        ``{"file", "verdict", "boxes"}`` per probe (the samples' truth.json layout).
    iou : float
        A region matches a true box at IoU >= ``iou`` (one-to-one, greedy).

    Returns
    -------
    dict
        ``accuracy`` (errors count as wrong), ``faulty_flagged``, ``false_alarm_rate`` (perfect probes judged
        faulty or not registered), ``errors``, defect-level ``precision``, ``recall``, ``f1`` and the counts.

    Examples
    --------
    >>> results = [{"probe": "in/a.png", "verdict": "faulty", "regions": [[10, 10, 20, 20]]},
    ...            {"probe": "in/b.png", "verdict": "perfect", "regions": []}]
    >>> truth = [{"file": "a.png", "verdict": "faulty", "boxes": [[11, 10, 20, 21]]},
    ...          {"file": "b.png", "verdict": "perfect", "boxes": []}]
    >>> m = evaluate(results, truth)
    >>> m["accuracy"], m["recall"], m["false_alarm_rate"]
    (1.0, 1.0, 0.0)
    """
    by_name = {PurePath(r["probe"]).name: r for r in results}
    counts, right, flagged, alarms, errors = DetectionCounts(0, 0, 0), 0, [], [], 0
    for t in truth:
        r = by_name.get(t["file"])
        if r is None:
            raise InputError(f"no inspection result for probe {t['file']}")
        verdict = r.get("verdict")
        errors += verdict is None
        right += verdict == t["verdict"]
        (flagged if t["verdict"] == "faulty" else alarms).append(
            verdict == "faulty" if t["verdict"] == "faulty" else verdict != "perfect")
        regions = r.get("regions")
        counts += match_boxes(np.asarray([] if regions is None else regions, float).reshape(-1, 4),
                              np.asarray(t["boxes"], float).reshape(-1, 4), iou)[0]
    n = len(truth)
    return {"probes": n, "accuracy": right / n if n else None, "errors": errors,
            "faulty_flagged": float(np.mean(flagged)) if flagged else None,
            "false_alarm_rate": float(np.mean(alarms)) if alarms else None,
            "precision": counts.precision, "recall": counts.recall, "f1": counts.f1,
            "tp": counts.tp, "fp": counts.fp, "fn": counts.fn, "iou": iou}


def _key(file: str) -> str:
    """A probe's metrics key: its file stem, dots replaced (DVC splits metric keys at dots)."""
    return PurePath(file).stem.replace(".", "_")


def probe_truth_scores(record: Mapping[str, Any], truth: Mapping[str, Any], reference_size: tuple[int, int]) -> dict:
    """Per-probe agreement with the truth: ``correct``, ``box_iou`` and ``registration_corner_error_px``.

    Parameters
    ----------
    record : dict
        One ``defect_regions`` record.
    truth : dict
        That probe's truth (``verdict``, ``boxes``, ``H`` or None).
    reference_size : (width, height)
        Of the reference image: the corner error is measured at its corners.

    Returns
    -------
    dict
        ``correct`` (bool); ``box_iou`` (mean over the true boxes of the best IoU of a found region, when the probe
        has true boxes); ``registration_corner_error_px`` (when both the truth and the record have ``H``).
    """
    out: dict[str, Any] = {"correct": record.get("verdict") == truth["verdict"]}
    boxes = np.asarray(truth["boxes"], float).reshape(-1, 4)
    if len(boxes):
        found = np.asarray(record.get("regions") or [], float).reshape(-1, 4)
        out["box_iou"] = float(box_iou(found, boxes).max(0).mean()) if len(found) else 0.0
    if truth.get("H") is not None and record.get("H") is not None:
        out["registration_corner_error_px"] = corner_error(record["H"], truth["H"], *reference_size)
    return out


def evaluate_records(records: list[dict], truth: Mapping[str, Mapping[str, Any]],
                     reference_size: tuple[int, int]) -> dict:
    """Counts, and scores against the truth where there is some.

    Returns
    -------
    dict
        ``probes``, ``inspected``, ``faulty``, ``perfect``, ``direct_registrations``, ``truth_probes``;
        ``per_probe`` (file -> :func:`probe_truth_scores`, probes with truth only); with truth also ``overall``:
        :func:`evaluate` at IoU :data:`IOU` over the probes with truth (a probe not inspected counts
        as wrong) plus the median registration corner error.

    Examples
    --------
    >>> records = [{"probe": "in/a.png", "verdict": "faulty", "score": 12.5, "regions": [[10, 10, 20, 20]]}]
    >>> truth = {"a.png": {"verdict": "faulty", "boxes": [[10, 10, 20, 20]], "H": None}}
    >>> ev = evaluate_records(records, truth, (64, 64))
    >>> ev["faulty"], ev["overall"]["accuracy"], ev["per_probe"]["a.png"]["box_iou"]
    (1, 1.0, 1.0)
    """
    inspected = [r for r in records if r.get("verdict") is not None]
    out = {"probes": len(records), "inspected": len(inspected),
           "faulty": sum(r["verdict"] == "faulty" for r in inspected),
           "perfect": sum(r["verdict"] == "perfect" for r in inspected),
           "direct_registrations": sum(r.get("method") == "direct" for r in inspected),
           "truth_probes": 0, "per_probe": {}}
    labelled = [r for r in records if PurePath(r["probe"]).name in truth]
    if not labelled:
        return out
    out["truth_probes"] = len(labelled)
    names = [PurePath(r["probe"]).name for r in labelled]
    out["per_probe"] = {n: probe_truth_scores(r, truth[n], reference_size) for n, r in zip(names, labelled)}
    overall = evaluate(labelled, [{"file": n, "verdict": truth[n]["verdict"], "boxes": truth[n]["boxes"]}
                                  for n in names], IOU)
    errors = [s["registration_corner_error_px"] for s in out["per_probe"].values()
              if "registration_corner_error_px" in s]
    if errors:
        overall["registration_corner_error_px"] = statistics.median(errors)
    out["overall"] = overall
    return out


def metrics_of(records: list[dict], evaluated: dict) -> dict:
    """The flat numeric metrics: ``{"defect": {"all": {...}, "<probe stem>": {...}}}`` (no strings, no None).

    Parameters
    ----------
    records : list of dict
        The ``defect_regions`` records.
    evaluated : dict
        :func:`evaluate_records` of them.

    Examples
    --------
    >>> records = [{"probe": "in/a.png", "verdict": "faulty", "score": 12.5, "regions": [[10, 10, 20, 20]]}]
    >>> metrics_of(records, evaluate_records(records, {}, (64, 64)))["defect"]["a"]
    {'inspected': 1, 'score': 12.5, 'faulty': 1, 'regions': 1}
    """
    every = {k: evaluated[k] for k in ("probes", "inspected", "faulty", "perfect", "direct_registrations",
                                      "truth_probes")}
    overall = evaluated.get("overall")
    if overall:
        every.update({"accuracy": overall["accuracy"], "precision": overall["precision"],
                      "recall": overall["recall"], "f1": overall["f1"], "false_alarms": overall["false_alarm_rate"],
                      "faulty_flagged": overall["faulty_flagged"],
                      "registration_corner_error_px": overall.get("registration_corner_error_px")})
    out: dict[str, Any] = {"all": {k: v for k, v in every.items() if v is not None}}
    for r in records:
        m: dict[str, Any] = {"inspected": int(r.get("verdict") is not None)}
        if r.get("verdict") is not None:
            m.update(score=float(r["score"]), faulty=int(r["verdict"] == "faulty"), regions=len(r["regions"]))
        for k, v in evaluated["per_probe"].get(PurePath(r["probe"]).name, {}).items():
            m[k] = int(v) if isinstance(v, bool) else v
        out[_key(r["probe"])] = m
    return {"defect": out}


def confusion_rows(records: list[dict], truth: Mapping[str, Mapping[str, Any]]) -> list[dict]:
    """``dvc plots`` rows ``{"probe", "actual", "predicted"}`` (DVC's ``confusion`` template), probes with truth."""
    return [{"probe": PurePath(r["probe"]).name, "actual": truth[PurePath(r["probe"]).name]["verdict"],
             "predicted": r.get("verdict") or NOT_INSPECTED}
            for r in records if PurePath(r["probe"]).name in truth]


def score_rows(records: list[dict]) -> list[dict]:
    """``dvc plots`` rows ``{"probe", "score", "verdict"}`` for the inspected probes (score 0 = perfect)."""
    return [{"probe": PurePath(r["probe"]).name, "score": float(r["score"]), "verdict": r["verdict"]}
            for r in records if r.get("verdict") is not None]


def overlay(probe: np.ndarray, record: Mapping[str, Any], truth: Mapping[str, Any] | None) -> np.ndarray:
    """The probe (BGR) with the found regions in red, the true boxes in green and a caption line."""
    out = draw_regions(probe, np.asarray(record.get("regions") or [], float).reshape(-1, 4),
                       None if truth is None else truth["boxes"])
    text = f"{PurePath(record['probe']).name}: {record.get('verdict') or NOT_INSPECTED}"
    if truth is not None:
        text += f" (truth {truth['verdict']})"
    return caption(out, text)


def caption(image: np.ndarray, text: str) -> np.ndarray:
    """``image`` (BGR, drawn on in place and returned) with ``text`` in white on a dark outline, top left."""
    cv2.putText(image, text, (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 0, 0), 4, cv2.LINE_AA)
    cv2.putText(image, text, (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2, cv2.LINE_AA)
    return image


def montage(images: list[np.ndarray], cols: int, width: int = 1200) -> np.ndarray:
    """BGR tiles in a grid ``width`` pixels wide, each image scaled to fit its square tile (black padding).

    Parameters
    ----------
    images : list of (H, W, 3) uint8
        At least one.
    cols : int
        Tiles per row (fewer when there are fewer images).

    Examples
    --------
    >>> import numpy as np
    >>> montage([np.zeros((10, 20, 3), np.uint8)] * 3, cols=2, width=100).shape  # two rows of two 50 px tiles
    (100, 100, 3)
    """
    if not images:
        raise ValueError("`images` must hold at least one image")
    cols = max(1, min(cols, len(images)))
    side = width // cols
    tiles = []
    for im in images:
        h, w = im.shape[:2]
        s = side / max(h, w)
        small = cv2.resize(im, (max(1, round(w * s)), max(1, round(h * s))), interpolation=cv2.INTER_AREA)
        tile = np.zeros((side, side, 3), np.uint8)
        tile[:small.shape[0], :small.shape[1]] = small
        tiles.append(tile)
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % cols)
    return np.vstack([np.hstack(tiles[i:i + cols]) for i in range(0, len(tiles), cols)])


def _num(v: Any, digits: int = 3) -> Any:
    return round(float(v), digits) if v is not None else None


def report_summary(records: list[dict], registration: Mapping[str, Any], evaluated: dict, pictures: list[dict],
                   dropped: list[dict]) -> dict:
    """The report page's summary of the defect task (schema in ``cvpipe.report``).

    Parameters
    ----------
    records : list of dict
        The ``defect_regions`` records.
    registration : dict
        ``defect_register``'s registration.json ``probes`` (stem -> record), for the registration quality.
    evaluated : dict
        :func:`evaluate_records` of the records.
    pictures : list of dict
        ``{"path", "caption"}``, repo-relative paths.
    dropped : list of dict
        ``{"item", "reason"}`` for every probe that was not inspected.
    """
    by_file = {rec["file"]: rec for rec in registration.values()}
    rows = []
    for r in records:
        name = PurePath(r["probe"]).name
        t = evaluated["per_probe"].get(name)
        reg = by_file.get(name, {}).get(r.get("registration") or "primary") or {}
        rows.append([name, r.get("verdict") or NOT_INSPECTED, _num(r.get("score"), 1), len(r.get("regions") or []),
                     r.get("method"), _num(reg.get("correlation")),
                     NO_TRUTH if t is None else t["correct"],
                     NO_TRUTH if t is None else _num(t.get("box_iou")),
                     NO_TRUTH if t is None else _num(t.get("registration_corner_error_px"), 2)])
    tables = [{"title": "Per probe", "columns": ["probe", "verdict", "score", "regions", "registration",
                                                 "ECC correlation", "verdict correct", "box IoU (mean best)",
                                                 "registration corner error, px"], "rows": rows}]
    overall = evaluated.get("overall")
    if overall:
        tables.insert(0, {"title": f"Probes with ground truth ({evaluated['truth_probes']}), defect-level scores at "
                                   f"IoU >= {IOU}",
                          "columns": ["accuracy", "faulty flagged", "false alarms", "precision", "recall", "F1",
                                      "not inspected", "median registration corner error, px"],
                          "rows": [[_num(overall["accuracy"]), _num(overall["faulty_flagged"]),
                                    _num(overall["false_alarm_rate"]), _num(overall["precision"]),
                                    _num(overall["recall"]), _num(overall["f1"]), overall["errors"],
                                    _num(overall.get("registration_corner_error_px"), 2)]]})
    tables += not_processed_table(dropped)
    n, k = evaluated["probes"], evaluated["truth_probes"]
    truth_note = (f"{k} of {n} probes have ground truth (green boxes)." if k else
                  "These probes have no ground truth: the verdicts and regions are shown without accuracy.")
    return {
        "task": "defect",
        "title": "Defect inspection against a golden reference",
        "description": (
            f"{evaluated['inspected']} of {n} probes inspected: {evaluated['faulty']} faulty, "
            f"{evaluated['perfect']} perfect. Each probe is registered to the reference (keypoint matches, RANSAC "
            "homography, ECC refinement; directly by phase correlation + ECC when that aligns better), corrected "
            "for gain and bias and compared with a difference that tolerates a few pixels of misregistration. "
            f"{truth_note} Red boxes are found defects. Comparison with the seed's plain difference: "
            "`cvpipe bench defect`; times: `dvc plots show` (outputs/timings)."),
        "pictures": pictures,
        "tables": tables,
    }
