"""The stereo task's results: disparity accuracy against the truth, the per-stage metrics, the pictures and the
report summary. Pure functions: no disk access (the stage scripts in ``stages/`` read and write).
"""

from __future__ import annotations

import cv2
import numpy as np

from .. import geometry, io, metrics
from ..params import StereoReportParams
from . import depth as depth_mod

#: bad-pixel thresholds in pixels used by the stages and the benchmark (Middlebury's bad-1.0 and bad-2.0)
BAD_THRESHOLDS = (1.0, 2.0)
#: the ``stereo.report`` defaults: the one declaration of the ``error_clip`` / ``clip`` defaults below
_REPORT = StereoReportParams()


def evaluate(disp: np.ndarray, truth: np.ndarray, thresholds: tuple[float, ...] = BAD_THRESHOLDS,
             mask: np.ndarray | None = None) -> dict[str, float]:
    """Accuracy of a disparity map against the truth, over the pixels with known truth.

    Parameters
    ----------
    disp, truth : ndarray, (H, W) float
        Estimated and true disparity in pixels; NaN = no estimate / unknown truth.
    thresholds : tuple of float
        Bad-pixel thresholds in pixels; each gives a key ``bad_<t>`` (e.g. ``bad_2.0``).
    mask : ndarray, (H, W) bool, optional
        Restrict the evaluation to these pixels.

    Returns
    -------
    dict
        ``bad_<t>`` (missing or off by more than t, share of known pixels), ``mean_error`` (pixels, over pixels
        with both an estimate and truth) and ``density`` (share of known pixels with an estimate).
    """
    out = {f"bad_{float(t):.1f}": metrics.bad_pixel_rate(disp, truth, float(t), mask) for t in thresholds}
    out["mean_error"] = metrics.mean_abs_error(disp, truth, mask)
    out["density"] = metrics.density(disp, truth, mask)
    return out


def to_png16(disp: np.ndarray) -> np.ndarray:
    """(H, W) uint16 image of ``round(256 * disparity)``, 0 where NaN (the KITTI convention; exact to 1/256 px).

    Raises ``ValueError`` for negative disparities or disparities of 256 px or more, which the format cannot hold.
    """
    finite = np.isfinite(disp)
    if finite.any() and (disp[finite].min() < 0 or disp[finite].max() >= 256):
        raise ValueError("`disp` must lie in [0, 256) pixels to be stored as a 16-bit PNG")
    out = np.zeros(disp.shape, np.uint16)
    out[finite] = np.clip(np.round(disp[finite] * 256.0), 1, 65535).astype(np.uint16)
    return out


def colorize_disparity(disp: np.ndarray, max_disp: float) -> np.ndarray:
    """(H, W, 3) uint8 BGR picture of a disparity map: turbo colour map over [0, max_disp], black where NaN."""
    if not max_disp > 0:
        raise ValueError(f"`max_disp` must be > 0, got {max_disp}")
    finite = np.isfinite(disp)
    scaled = np.zeros(disp.shape, np.uint8)
    scaled[finite] = np.clip(disp[finite] / float(max_disp) * 255.0, 0, 255).astype(np.uint8)
    pic = cv2.applyColorMap(scaled, cv2.COLORMAP_TURBO)
    pic[~finite] = 0
    return pic


def error_picture(disp: np.ndarray, truth: np.ndarray, clip: float = _REPORT.error_clip) -> np.ndarray:
    """(H, W, 3) uint8 BGR map of |disp - truth|: black (0) to white (>= ``clip`` px) on a hot scale; missing
    estimates with known truth in blue, unknown truth in mid grey."""
    if disp.shape != truth.shape:
        raise ValueError(f"`disp` must have the shape of `truth` {truth.shape}, got {disp.shape}")
    if not clip > 0:
        raise ValueError(f"`clip` must be > 0, got {clip}")
    known = np.isfinite(truth)
    both = known & np.isfinite(disp)
    scaled = np.zeros(disp.shape, np.uint8)
    scaled[both] = np.clip(np.abs(disp[both] - truth[both]) / clip * 255.0, 0, 255).astype(np.uint8)
    pic = cv2.applyColorMap(scaled, cv2.COLORMAP_HOT)
    pic[known & ~both] = (255, 80, 0)
    pic[~known] = (128, 128, 128)
    return pic


# ------------------------------------------------------------------------------- pipeline results and report


def metric_key(name: str) -> str:
    """A pair name as a metrics key: no dots (DVC joins nested keys with dots) and never ``all``."""
    key = str(name).replace(".", "_")
    return "pair_all" if key == "all" else key


def pair_result(disp: np.ndarray, max_disp: int, truth: np.ndarray | None = None) -> dict:
    """The numbers of one disparity map: ``max_disp``, ``valid_fraction`` (share of all pixels with an estimate)
    and, with ``truth``, ``bad_1`` / ``bad_2`` (see :func:`evaluate`), ``density`` and ``mean_error_px``; a value
    that does not exist (no known truth pixel) is left out rather than NaN."""
    out: dict = {"max_disp": int(max_disp), "valid_fraction": float(np.isfinite(disp).mean())}
    if truth is not None:
        ev = evaluate(disp, truth)
        named = {f"bad_{t:g}": ev[f"bad_{float(t):.1f}"] for t in BAD_THRESHOLDS}
        named.update(density=ev["density"], mean_error_px=ev["mean_error"])
        out.update({k: float(v) for k, v in named.items() if np.isfinite(v)})
    return out


#: per-pair keys that need the truth, averaged over the pairs with truth in ``all``
TRUTH_KEYS = tuple(f"bad_{t:g}" for t in BAD_THRESHOLDS) + ("density", "mean_error_px")


def metrics_of(run: dict) -> dict:
    """``{"stereo": {method: {"all": {...}, pair: {...}}}}`` from one ``stereo_disparity`` result ``{"method",
    "pairs": {name: pair_result(...) + {"truth": bool}}}``; ``all`` holds ``pairs``, the mean ``valid_fraction``
    and, over the pairs with truth, ``truth_pairs`` and the mean of each truth key."""
    pairs = run["pairs"]
    summary: dict = {"pairs": len(pairs)}
    if pairs:
        summary["valid_fraction"] = float(np.mean([r["valid_fraction"] for r in pairs.values()]))
    with_truth = [r for r in pairs.values() if r["truth"]]
    if with_truth:
        summary["truth_pairs"] = len(with_truth)
        for k in TRUTH_KEYS:
            vals = [r[k] for r in with_truth if k in r]
            if vals:
                summary[k] = float(np.mean(vals))
    per_pair = {metric_key(n): {k: (int(v) if isinstance(v, bool) else v) for k, v in r.items()}
                for n, r in pairs.items()}
    return {"stereo": {run["method"]: {"all": summary, **per_pair}}}


def merge_dropped(runs: dict) -> list[dict]:
    """The ``dropped`` lists of the methods' runs as one: an (item, reason) that every method dropped is listed
    once, one that only some dropped names them (``"pair (opencv_bm)"``)."""
    seen: dict[tuple[str, str], list[str]] = {}
    for method, run in runs.items():
        for d in run["dropped"]:
            seen.setdefault((d["item"], d["reason"]), []).append(method)
    return [{"item": item if len(ms) == len(runs) else f"{item} ({', '.join(ms)})", "reason": reason}
            for (item, reason), ms in seen.items()]


def _labelled(pic: np.ndarray, label: str, width: int) -> np.ndarray:
    h = max(1, int(round(pic.shape[0] * width / pic.shape[1])))
    bar = np.full((24, width, 3), 255, np.uint8)
    cv2.putText(bar, label, (4, 17), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([bar, cv2.resize(pic, (width, h), interpolation=cv2.INTER_AREA)])


def comparison_picture(left: np.ndarray, disparities: dict, max_disp: int, truth: np.ndarray | None = None,
                       error_clip: float = _REPORT.error_clip, width: int = 320) -> np.ndarray:
    """One pair's methods side by side: the left image and each method's colour-mapped disparity; with ``truth`` a
    second row with the true disparity and each method's error map (:func:`error_picture`).

    Parameters
    ----------
    left : (H, W) or (H, W, 3) uint8
        The left image.
    disparities : dict
        Label -> (H, W) float disparity (NaN = none), or None for a method that failed (a grey panel).
    max_disp : int
        The top of the colour scale (the pair's search range).
    truth : (H, W) float, optional
        True disparity (NaN = unknown).
    error_clip : float
        Absolute error (pixels) at which the error maps saturate.
    width : int
        Width of each panel in pixels.

    Returns
    -------
    (rows * (h + 24), width * (1 + len(disparities)), 3) uint8 BGR
    """
    grey = np.full(left.shape[:2] + (3,), 96, np.uint8)
    top = [_labelled(cv2.cvtColor(left, cv2.COLOR_GRAY2BGR) if left.ndim == 2 else left, "left image", width)]
    for label, d in disparities.items():
        top.append(_labelled(grey if d is None else colorize_disparity(d, max_disp), f"{label}" +
                             (": failed" if d is None else ""), width))
    rows = [np.hstack(top)]
    if truth is not None:
        bottom = [_labelled(colorize_disparity(truth, max_disp), "true disparity", width)]
        for label, d in disparities.items():
            bottom.append(_labelled(grey if d is None else error_picture(d, truth, error_clip),
                                    f"{label} |error|", width))
        rows.append(np.hstack(bottom))
    return np.vstack(rows)


def report_summary(runs: dict, pictures: list[dict], dropped: list[dict], error_clip: float) -> dict:
    """The report page's summary of the stereo task (schema in ``cvpipe.report``).

    Parameters
    ----------
    runs : dict
        Method -> ``stereo_disparity`` result (``{"method", "pairs": {name: {...}}, "dropped"}``).
    pictures : list of dict
        ``{"path", "caption"}`` per pair picture, repo-relative paths.
    dropped : list of dict
        ``{"item", "reason"}`` for every input that was not processed (:func:`merge_dropped`).
    error_clip : float
        The saturation of the error maps (pixels), for the description.
    """
    none = "no ground truth"
    names = list(dict.fromkeys(n for run in runs.values() for n in run["pairs"]))
    truth_pairs = sorted({n for run in runs.values() for n, r in run["pairs"].items() if r["truth"]})

    def pct(v):
        return None if v is None else round(100.0 * v, 2)

    per_method = []
    for method, run in runs.items():
        s = metrics_of(run)["stereo"][method]["all"]
        acc = ([pct(s.get("bad_1")), pct(s.get("bad_2")), None if "mean_error_px" not in s else
                round(s["mean_error_px"], 3), pct(s.get("density"))] if truth_pairs else [none] * 4)
        per_method.append([method, f"{len(run['pairs'])} / {len(names)}", pct(s.get("valid_fraction")), *acc])
    per_pair = []
    for name in names:
        for method, run in runs.items():
            r = run["pairs"].get(name)
            if r is None:
                per_pair.append([name, method, None, "failed", "failed", "failed"])
                continue
            per_pair.append([name, method, r["max_disp"], pct(r["valid_fraction"]),
                             pct(r.get("bad_2")) if r["truth"] else none,
                             (round(r["mean_error_px"], 3) if "mean_error_px" in r else None) if r["truth"] else none])
    tables = [
        {"title": "Per method (means over the pairs)",
         "columns": ["method", "pairs", "valid %", "bad-1.0 %", "bad-2.0 %", "mean error px", "density %"],
         "rows": per_method},
        {"title": "Per pair", "columns": ["pair", "method", "max_disp", "valid %", "bad-2.0 %", "mean error px"],
         "rows": per_pair},
    ]
    tables += metrics.not_processed_table(dropped)
    if truth_pairs:
        truth_note = (f"{len(truth_pairs)} of {len(names)} pairs have a true disparity ({', '.join(truth_pairs)}). "
                      "A pixel is bad when its estimate is missing or off by more than the threshold, over all pixels "
                      "with known truth; mean error is over pixels with an estimate; density is the share of known "
                      f"pixels with an estimate. Error maps: white at {error_clip:g} px or more, blue = missing, "
                      "grey = unknown truth.")
    else:
        truth_note = ("These pairs have no ground truth: the tables give the share of pixels with a (trusted) "
                      "estimate, and the pictures show each method's disparity.")
    return {
        "task": "stereo",
        "title": "Disparity of rectified pairs: our semi-global matching vs OpenCV BM / SGBM",
        "description": (f"Every method searches the pair's disparity range (max_disp). {truth_note} Disparity "
                        "pictures: turbo colour map from 0 to max_disp, black = no estimate. Times: `dvc plots "
                        "show` (outputs/timings) and `cvpipe bench stereo`."),
        "pictures": pictures,
        "tables": tables,
    }


def quality_plots(runs: dict) -> dict[str, list[dict]]:
    """``dvc plots`` rows per file: ``bad_2`` (pairs with truth) and ``valid_fraction`` (every pair), each row
    ``{"pair", "method", "label", <value>}``."""
    bad, valid = [], []
    for method, run in runs.items():
        for name, r in run["pairs"].items():
            base = {"pair": name, "method": method, "label": f"{name} {method}"}
            valid.append({**base, "valid_fraction": r["valid_fraction"]})
            if "bad_2" in r:
                bad.append({**base, "bad_2": r["bad_2"]})
    return {"bad_2": bad, "valid_fraction": valid}


# ------------------------------------------------------------------------------------------------ metrics


def rectify_metrics(records: dict) -> dict:
    """``{"stereo": {"rectify": {"all": {...}, <pair>: {...}}}}``: numbers only (``calibrated`` / ``rectified``
    as 0/1, the vertical error, matches, inliers, max_disp when estimated)."""
    per = {}
    for name, r in records.items():
        m = {"matches": r["matches"], "rectified": int(r["kind"] != "none"), "calibrated": int(r["kind"] ==
                                                                                                 "calibrated")}
        for k in ("vertical_error_median_px", "vertical_error_p95_px", "inliers", "max_disp"):
            if k in r:
                m[k] = r[k]
        per[metric_key(name)] = m
    summary: dict = {"pairs": len(records), "rectified": sum(r["kind"] != "none" for r in records.values())}
    med = [r["vertical_error_median_px"] for r in records.values() if "vertical_error_median_px" in r]
    if med:
        summary["vertical_error_median_px_worst"] = float(np.max(med))  # of the worst pair
    return {"stereo": {"rectify": {"all": summary, **per}}}


def depth_result(z: np.ndarray, points: int, geometry: dict) -> dict:
    """Numbers of one depth map: valid fraction, median / 5th / 95th percentile depth (in the geometry's unit),
    the number of points of the cloud, and whether the geometry was exact (1) or from an estimated rectification."""
    finite = z[np.isfinite(z)]
    out = {"valid_fraction": float(np.isfinite(z).mean()), "points": int(points), "exact": int(geometry["exact"])}
    if len(finite):
        out.update(depth_median=float(np.median(finite)), depth_p5=float(np.percentile(finite, 5)),
                   depth_p95=float(np.percentile(finite, 95)))
    return out


def depth_metrics(results: dict) -> dict:
    """``{"stereo": {"depth": {"all": {"pairs", "depth_pairs"}, <pair>: depth_result(...)}}}``."""
    per = {metric_key(n): r for n, r in results.items()}
    return {"stereo": {"depth": {"all": {"depth_pairs": len(results)}, **per}}}


# ----------------------------------------------------------------------------------------------- pictures


_COLOURS = [tuple(int(c) for c in cv2.applyColorMap(np.uint8([[v]]), cv2.COLORMAP_HSV)[0, 0])
            for v in np.linspace(0, 230, 12)]


def _pair_with_lines(left: np.ndarray, right: np.ndarray, p1: np.ndarray, p2: np.ndarray, rows: np.ndarray,
                     label: str) -> np.ndarray:
    canvas = np.hstack([io.to_bgr(left), io.to_bgr(right)])
    w = left.shape[1]
    for i, k in enumerate(rows):
        c = _COLOURS[i % len(_COLOURS)]
        y = float(p1[k, 1])
        cv2.line(canvas, (0, int(round(y))), (2 * w - 1, int(round(y))), c, 1, cv2.LINE_AA)
        cv2.circle(canvas, (int(round(p1[k, 0])), int(round(p1[k, 1]))), 4, c, 2, cv2.LINE_AA)
        cv2.circle(canvas, (int(round(p2[k, 0])) + w, int(round(p2[k, 1]))), 4, c, 2, cv2.LINE_AA)
    bar = np.full((24, canvas.shape[1], 3), 255, np.uint8)
    cv2.putText(bar, label, (4, 17), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([bar, canvas])


def rectification_picture(left: np.ndarray, right: np.ndarray, rect_left: np.ndarray, rect_right: np.ndarray,
                          H_left, H_right, points_left: np.ndarray, points_right: np.ndarray,
                          lines: int = 12, width: int = 960) -> np.ndarray:
    """The pair before (top) and after (bottom) rectification with the epipolar lines of a few matches.

    In the rectified frame the epipolar line of a left point is its row, drawn across both images through the
    left point; a correctly rectified match has its right point (same colour) on that line. The top row shows
    the same matches in the original images (each line through the left point's original row), where the right
    points are off their lines by the vertical misalignment.

    Parameters
    ----------
    left, right : (H, W[, 3]) uint8
        The original pair.
    rect_left, rect_right : (H, W[, 3]) uint8
        The rectified pair.
    H_left, H_right : (3, 3)
        Original -> rectified pixels.
    points_left, points_right : (N, 2)
        Matches in rectified pixels.
    lines : int
        How many matches (spread over the rows) get a line.
    width : int
        Width of the picture.

    Returns
    -------
    (h, width, 3) uint8 BGR
    """
    q1 = np.asarray(points_left, np.float64).reshape(-1, 2)
    q2 = np.asarray(points_right, np.float64).reshape(-1, 2)
    rows = np.array([], int)
    if len(q1):
        order = np.argsort(q1[:, 1], kind="stable")
        rows = order[np.unique(np.linspace(0, len(order) - 1, min(lines, len(order))).round().astype(int))]
    o1 = geometry.apply_homography(np.linalg.inv(np.asarray(H_left, float)), q1) if len(q1) else q1
    o2 = geometry.apply_homography(np.linalg.inv(np.asarray(H_right, float)), q2) if len(q2) else q2
    top = _pair_with_lines(left, right, o1, o2, rows, "original pair: lines through the left points' rows")
    bottom = _pair_with_lines(rect_left, rect_right, q1, q2, rows,
                              "rectified pair: each line is the epipolar line of the left point (same row)")
    pic = np.vstack([top, bottom])
    h = max(1, int(round(pic.shape[0] * width / pic.shape[1])))
    return cv2.resize(pic, (width, h), interpolation=cv2.INTER_AREA)


def depth_picture(left: np.ndarray, depth: np.ndarray, unit: str, width: int = 960) -> np.ndarray:
    """The rectified left image beside its colour-mapped depth with a colour bar in ``unit``."""
    col = depth_mod.colorize(depth, unit=unit, label="depth")
    lft = io.to_bgr(left)
    pic = np.hstack([lft, col])
    h = max(1, int(round(pic.shape[0] * width / pic.shape[1])))
    return cv2.resize(pic, (width, h), interpolation=cv2.INTER_AREA)


# ------------------------------------------------------------------------------------------------ summary


def extend_summary(summary: dict, rect_records: dict, depth_run: dict, pictures: list[dict],
                   frame_truth: tuple = ()) -> dict:
    """Add the rectification and depth tables, pictures and wording to the disparity summary of
    :func:`cvpipe.stereo.report_summary` (a new dict); ``frame_truth`` names the pairs that have a truth.npz (used
    only when the pair needed no rectification)."""
    def num(v, nd=3):
        return None if v is None else round(float(v), nd)

    rect_rows = []
    for name, r in rect_records.items():
        rect_rows.append([name, r["kind"], r["matches"], r.get("inliers"), num(r.get("vertical_error_median_px")),
                          num(r.get("vertical_error_p95_px")), r.get("max_disp"), r["vertical_error_over"]])
    depth_rows = []
    for name in rect_records:
        res = depth_run["pairs"].get(name)
        if res is None:
            why = "disparity only (no calibration)" if name in depth_run["disparity_only"] else "no disparity"
            depth_rows.append([name, why, None, None, None, None])
            continue
        unit = depth_run["units"][name]
        depth_rows.append([name, f"depth in {unit}" + ("" if res["exact"] else " (estimated rectification)"),
                           num(100 * res["valid_fraction"], 2), num(res.get("depth_median"), 1),
                           f"{num(res.get('depth_p5'), 1)} .. {num(res.get('depth_p95'), 1)}", res["points"]])
    tables = [dict(t) for t in summary["tables"]]
    elsewhere = {n for n in frame_truth if rect_records.get(n, {}).get("kind", "none") != "none"}
    for t in tables:  # a truth.npz that exists but is in the original frame is not "no ground truth"
        if t["title"] == "Per pair":
            t["rows"] = [[("truth not in the rectified frame" if c == "no ground truth" and row[0] in elsewhere
                           else c) for c in row] for row in t["rows"]]
    at = next((i for i, t in enumerate(tables) if t["title"] == "Not processed"), len(tables))
    tables[at:at] = [
        {"title": "Rectification (stereo_rectify)",
         "columns": ["pair", "kind", "matches", "inliers", "vertical error median px", "vertical error p95 px",
                     "estimated max_disp", "measured over"], "rows": rect_rows},
        {"title": f"Depth (stereo_depth, from {depth_run['method']})",
         "columns": ["pair", "output", "valid %", "median depth", "depth p5 .. p95", "points in the PLY"],
         "rows": depth_rows},
    ]
    rectified = [n for n, r in rect_records.items() if r["kind"] != "none"]
    only = depth_run["disparity_only"]
    text = ("Each pair is first rectified (calibrated from an OpenCV calibration that holds the rig's pose, kept as "
            "it is when its feature matches already lie on the same rows, else uncalibrated from the fundamental "
            "matrix of its matches: Hartley + Loop-Zhang); the vertical error is |y_left - y_right| of the "
            "matches after rectification. ")
    if rectified:
        text += (f"Rectified pairs ({', '.join(rectified)}): their disparity is in the rectified frame, where a "
                 "truth.npz of the original frame does not apply, so bad-2.0 is reported only for pairs that needed "
                 "no rectification. ")
    text += ("Depth Z = f * baseline / (d + doffs) and a coloured binary PLY point cloud are written for pairs "
             "with a calibration (calib.txt or calib.yml)" + (f"; disparity only for {', '.join(only)}. " if only
                                                             else ". "))
    return {**summary, "description": text + summary["description"], "pictures": pictures + summary["pictures"],
            "tables": tables}


def vertical_error_plot(rect_records: dict) -> list[dict]:
    """``dvc plots`` rows ``{"pair", "kind", "label", "vertical_error_median_px"}``."""
    return [{"pair": n, "kind": r["kind"], "label": f"{n} ({r['kind']})",
             "vertical_error_median_px": r["vertical_error_median_px"]}
            for n, r in rect_records.items() if "vertical_error_median_px" in r]
