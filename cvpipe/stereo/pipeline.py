"""The stereo pipeline's per-pair steps and its results: rectify -> disparity -> depth -> report.

:func:`rectify_pair` decides how a pair is rectified (calibrated, uncalibrated, or not at all when it already
looks rectified) and returns the record that ``stereo_rectify`` writes as ``rect.json``; the other functions turn
the stages' results into metrics, pictures and the report summary. Pure functions: no disk access (the stage
scripts in ``stages/`` read and write).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .. import io
from ..errors import InputError
from . import depth as depth_mod
from . import rectify
from .calibration import Calibration

#: the kinds of rectification (``rect.json`` ``kind``)
KINDS = ("none", "calibrated", "uncalibrated")


@dataclass(frozen=True, eq=False)
class RectifiedPair:
    """One pair after :func:`rectify_pair`.

    Attributes
    ----------
    left, right : (H, W, 3) uint8
        The images in the rectified frame (the inputs themselves for ``kind == "none"``).
    record : dict
        JSON-ready: ``kind``, ``H_left``, ``H_right`` (original -> rectified pixels), ``matches``, ``max_disp``
        (only when estimated from the matches), ``shift_px``, ``disparity_range_px``, ``vertical_error_median_px``,
        ``vertical_error_p95_px``, ``vertical_error_over`` (which matches), ``inliers`` (uncalibrated), ``depth``
        (focal, cx, cy, baseline, doffs, unit, exact; or None without a calibration).
    points_left, points_right : (N, 2) float64
        The matches that the vertical error is measured on, in rectified pixels (for the picture).
    """

    left: np.ndarray
    right: np.ndarray
    record: dict
    points_left: np.ndarray
    points_right: np.ndarray


def _geometry(g: rectify.DepthGeometry | None) -> dict | None:
    if g is None:
        return None
    return {"focal": g.focal, "cx": g.cx, "cy": g.cy, "baseline": g.baseline, "doffs": g.doffs, "unit": g.unit,
            "exact": bool(g.exact)}


def _vertical(record: dict, dy: np.ndarray, over: str) -> None:
    if len(dy):
        record["vertical_error_median_px"] = float(np.median(dy))
        record["vertical_error_p95_px"] = float(np.percentile(dy, 95))
    record["vertical_error_over"] = f"{len(dy)} {over}"


def feature_matches(left: np.ndarray, right: np.ndarray, detector: str = "sift", max_features: int = 4000,
                    ratio: float = 0.8, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Putative matches left -> right (:func:`cvpipe.homography.correspondences`), the same on every run: FLANN's
    randomized KD-trees draw from OpenCV's global generator, which is seeded with ``seed`` first."""
    from ..homography import correspondences

    cv2.setRNGSeed(int(seed))
    return correspondences(io.to_gray(left), io.to_gray(right), detector, max_features, ratio)


def rectify_pair(left: np.ndarray, right: np.ndarray, pts1: np.ndarray, pts2: np.ndarray,
                 calib: Calibration | None, *, threshold: float = 1.0, margin: float = 1.0, seed: int = 0,
                 rectified_max_dy: float = 1.0, rectified_share: float = 0.75) -> RectifiedPair:
    """Rectify one pair the way the pipeline does.

    The rule: a calibration that holds the rig's pose (an OpenCV stereo file: K1 D1 K2 D2 R T) gives a calibrated
    rectification (``cv2.stereoRectify``); else a pair whose matches already lie on the same rows
    (:func:`cvpipe.stereo.rectify.looks_rectified`) is kept as it is (``kind = "none"``, identity homographies); else it
    is rectified from its matches (:func:`cvpipe.stereo.rectify.rectify_uncalibrated`, Hartley + Loop-Zhang), with a
    Middlebury ``calib.txt`` (a rectified rig: no pose) giving only the focal length and baseline for depth.

    Parameters
    ----------
    left, right : (H, W, 3) uint8
        The pair (BGR), same size.
    pts1, pts2 : (N, 2) float
        Putative feature matches, left and right pixels.
    calib : Calibration or None
        The pair's calibration.
    threshold, margin, seed
        As in :func:`cvpipe.stereo.rectify.rectify_uncalibrated` (``seed`` seeds the RANSAC).
    rectified_max_dy, rectified_share
        As ``max_dy`` / ``share`` of :func:`cvpipe.stereo.rectify.looks_rectified`.

    Returns
    -------
    RectifiedPair

    Raises
    ------
    InputError
        Images of different sizes, a calibration for another image size.
    EstimationError
        The pair cannot be rectified (too few matches, a planar scene or a pure rotation, epipole in the image).
    """
    if left.shape[:2] != right.shape[:2]:
        raise InputError(f"the right image is {right.shape[1]}x{right.shape[0]}, the left {left.shape[1]}x"
                         f"{left.shape[0]}")
    h, w = left.shape[:2]
    p1 = np.asarray(pts1, np.float64).reshape(-1, 2)
    p2 = np.asarray(pts2, np.float64).reshape(-1, 2)
    if calib is not None:
        calib.check_size((w, h))
    record: dict = {"matches": int(len(p1)), "calib": None if calib is None else calib.source}
    if calib is not None and not calib.rectified:
        rect = rectify.rectify_calibrated(calib, (w, h), p1, p2, margin=margin)
        q1, q2 = rectify.apply_h(rect.H_left, p1), rectify.apply_h(rect.H_right, p2)
        keep = np.abs(q1[:, 1] - q2[:, 1]) <= 2.0  # as rectify_calibrated (lens distortion left out here)
        q1, q2 = q1[keep], q2[keep]
        record["kind"] = "calibrated"
        _vertical(record, rect.vertical_error, "matches within 2 px of one row after rectification")
    elif rectify.looks_rectified(p1, p2, rectified_max_dy, rectified_share):
        record.update(kind="none", H_left=np.eye(3).tolist(), H_right=np.eye(3).tolist(), shift_px=0.0)
        dy = np.abs(p1[:, 1] - p2[:, 1])
        _vertical(record, dy[dy <= 2.0], "matches within 2 px of one row (no rectification)")
        record["depth"] = _geometry(None if calib is None else rectify.rectified_depth_geometry(calib))
        return RectifiedPair(left, right, record, p1, p2)
    else:
        rect = rectify.rectify_uncalibrated(p1, p2, (w, h), threshold=threshold, margin=margin, calibration=calib,
                                            rng=seed)
        q1 = rectify.apply_h(rect.H_left, p1[rect.fit.inliers])
        q2 = rectify.apply_h(rect.H_right, p2[rect.fit.inliers])
        record.update(kind="uncalibrated", inliers=int(rect.fit.num_inliers))
        _vertical(record, rect.vertical_error, "inlier matches of the fundamental matrix")
    record.update(H_left=rect.H_left.tolist(), H_right=rect.H_right.tolist(), shift_px=float(rect.shift),
                  depth=_geometry(rect.depth))
    if len(rect.vertical_error):  # max_disp was estimated from the matches (else it is a default)
        record.update(max_disp=int(rect.max_disp), disparity_range_px=[float(v) for v in rect.disparity_range])
    lw, rw = rectify.warp_pair(left, right, rect)
    return RectifiedPair(lw, rw, record, q1, q2)


# ------------------------------------------------------------------------------------------------ metrics


def _key(name: str) -> str:
    key = str(name).replace(".", "_")
    return "pair_all" if key == "all" else key


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
        per[_key(name)] = m
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
    per = {_key(n): r for n, r in results.items()}
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
    o1 = rectify.apply_h(np.linalg.inv(np.asarray(H_left, float)), q1) if len(q1) else q1
    o2 = rectify.apply_h(np.linalg.inv(np.asarray(H_right, float)), q2) if len(q2) else q2
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
