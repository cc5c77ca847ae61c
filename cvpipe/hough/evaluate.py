"""How well detected lines agree: with OpenCV's cell for cell, and with ground-truth lines and segments."""

from __future__ import annotations

import math
import time

import numpy as np

from ..errors import InputError
from ..params import HoughLinesParams, HoughReportParams

__all__ = ["line_cells", "cell_agreement", "line_segment_matches", "segment_segment_matches", "truth_matches",
           "compare_runs", "metrics_of", "median_seconds"]

#: the ``hough.lines`` / ``hough.report`` defaults: the one declaration of the keyword defaults below (the angles in
#: radians, converted once here)
_LINES, _REPORT = HoughLinesParams(), HoughReportParams()
_THETA, _THETA_TOL = math.radians(_LINES.theta_deg), np.deg2rad(_REPORT.theta_tol_deg)


def _as_lines(lines: np.ndarray) -> np.ndarray:
    """``lines`` as a float64 (N, k) array with k >= 2 (an empty input becomes (0, 3))."""
    arr = np.asarray(lines, np.float64)
    if arr.size == 0:
        return np.zeros((0, 3), np.float64)
    if arr.ndim != 2 or arr.shape[1] < 2:
        raise InputError(f"`lines` must have shape (N, 2) or (N, 3), got {arr.shape}")
    return arr


def _as_segments(segments: np.ndarray) -> np.ndarray:
    """``segments`` as a float64 (M, 4) array ``[x1, y1, x2, y2]``."""
    return np.asarray(segments, np.float64).reshape(-1, 4)


def line_cells(lines: np.ndarray, rho: float = _LINES.rho, theta: float = _THETA, min_theta: float = 0.0
               ) -> np.ndarray:
    """Accumulator cell (angle index, rho index relative to rho = 0) of each line, shape (N, 2) int64.

    Examples
    --------
    >>> import numpy as np
    >>> line_cells([[20.0, np.pi / 2, 80], [-3.0, 0.0, 51]]).tolist()
    [[90, 20], [0, -3]]
    """
    lines = _as_lines(lines)
    rho32, theta32 = float(np.float32(rho)), float(np.float32(theta))
    n = np.rint((lines[:, 1] - float(np.float32(min_theta))) / theta32).astype(np.int64)
    r = np.rint(lines[:, 0] / rho32).astype(np.int64)
    return np.stack([n, r], axis=1)


def cell_agreement(ours: np.ndarray, ref: np.ndarray, rho: float = _LINES.rho, theta: float = _THETA,
                   min_theta: float = 0.0) -> dict:
    """How many of the reference lines ``ref`` appear in the same accumulator cell in ``ours``.

    Returns
    -------
    dict
        ``reproduced`` (count), ``ref_lines``, ``our_lines``, ``parity`` (reproduced / ref_lines; 1.0 when both are
        empty), ``same_votes`` (reproduced lines whose votes agree too), ``same_order`` (identical cell sequence).

    Examples
    --------
    >>> import numpy as np
    >>> ours = [[20.0, np.pi / 2, 80], [-3.0, 0.0, 51]]
    >>> agree = cell_agreement(ours, [[20.0, np.pi / 2, 80]])
    >>> agree["reproduced"], agree["parity"], agree["same_order"]
    (1, 1.0, False)
    """
    ours, ref = _as_lines(ours), _as_lines(ref)
    a = line_cells(ours, rho, theta, min_theta)
    b = line_cells(ref, rho, theta, min_theta)
    ours_map = {tuple(c): i for i, c in enumerate(a.tolist())}
    votes = ours.shape[1] > 2 and ref.shape[1] > 2
    reproduced = same_votes = 0
    for j, c in enumerate(b.tolist()):
        i = ours_map.get(tuple(c))
        if i is not None:
            reproduced += 1
            same_votes += int(votes and ours[i, 2] == ref[j, 2])
    parity = reproduced / len(b) if len(b) else (1.0 if len(a) == 0 else 0.0)
    return {"reproduced": reproduced, "ref_lines": len(b), "our_lines": len(a), "parity": parity,
            "same_votes": same_votes, "same_order": bool(len(a) == len(b) and np.array_equal(a, b))}


def _undirected_angle_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = np.abs(a - b) % np.pi
    return np.minimum(d, np.pi - d)


def _along(normal_x: np.ndarray, normal_y: np.ndarray, offset: np.ndarray, direction: np.ndarray,
           segments: np.ndarray, dist_px: float, angle_deg: float) -> np.ndarray:
    """(N, M) bool: segment m lies along line n, i.e. both of its end points are within ``dist_px`` of the line
    ``normal . p = offset`` (unit normals, each argument (N, 1)) and its direction within ``angle_deg`` of
    ``direction`` (radians)."""
    d1 = np.abs(segments[:, 0] * normal_x + segments[:, 1] * normal_y - offset)
    d2 = np.abs(segments[:, 2] * normal_x + segments[:, 3] * normal_y - offset)
    seg_dir = np.arctan2(segments[:, 3] - segments[:, 1], segments[:, 2] - segments[:, 0])
    ang = _undirected_angle_diff(direction, seg_dir[None, :])
    return (d1 <= dist_px) & (d2 <= dist_px) & (ang <= np.deg2rad(angle_deg))


def line_segment_matches(lines: np.ndarray, segments: np.ndarray, dist_px: float = 2.0,
                         angle_deg: float = 1.0) -> np.ndarray:
    """Which ground-truth segments some (infinite) Hough line passes along.

    A segment is found when a line makes an angle of at most ``angle_deg`` with it and both of its end points lie
    within ``dist_px`` of the line.

    Parameters
    ----------
    lines : ndarray, shape (N, >=2)
        ``[rho, theta, ...]`` in cv2.HoughLines conventions.
    segments : ndarray, shape (M, 4)
        ``[x1, y1, x2, y2]`` in 0-based pixel coordinates.

    Returns
    -------
    ndarray, shape (M,), bool
        True where some line passes along the segment.

    Examples
    --------
    >>> import numpy as np
    >>> line_segment_matches([[20.0, np.pi / 2]], [[0, 20, 79, 20], [5, 0, 5, 59]]).tolist()  # the row y = 20
    [True, False]
    """
    lines, segments = _as_lines(lines), _as_segments(segments)
    rho, th = lines[:, 0][:, None], lines[:, 1][:, None]
    return _along(np.cos(th), np.sin(th), rho, th + np.pi / 2, segments, dist_px, angle_deg).any(axis=0)


def segment_segment_matches(found: np.ndarray, segments: np.ndarray, dist_px: float = 2.0, angle_deg: float = 1.0,
                            min_overlap: float = 0.5) -> np.ndarray:
    """Which ground-truth segments a detected segment covers.

    A ground-truth segment is found when a detected segment makes an angle of at most ``angle_deg`` with it, both
    ground-truth end points lie within ``dist_px`` of the detected segment's line, and the detected segment, projected
    onto the ground-truth segment, covers at least ``min_overlap`` of its length.

    Parameters
    ----------
    found, segments : ndarray, shape (N, 4) and (M, 4)
        ``[x1, y1, x2, y2]`` in 0-based pixel coordinates.

    Returns
    -------
    ndarray, shape (M,), bool
        True where some detected segment covers the ground-truth segment.

    Examples
    --------
    >>> segment_segment_matches([[0, 20, 79, 20]], [[10, 20, 60, 20], [5, 0, 5, 59]]).tolist()
    [True, False]
    """
    found, segments = _as_segments(found), _as_segments(segments)
    fdx, fdy = found[:, 2] - found[:, 0], found[:, 3] - found[:, 1]
    flen = np.hypot(fdx, fdy)
    flen = np.where(flen > 0, flen, 1.0)
    nx, ny = (-fdy / flen)[:, None], (fdx / flen)[:, None]
    off = (found[:, 0] * nx[:, 0] + found[:, 1] * ny[:, 0])[:, None]
    along = _along(nx, ny, off, np.arctan2(fdy, fdx)[:, None], segments, dist_px, angle_deg)
    gdx, gdy = segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1]
    glen = np.hypot(gdx, gdy)
    gl = np.where(glen > 0, glen, 1.0)
    ux, uy = gdx / gl, gdy / gl
    t1 = (found[:, 0][:, None] - segments[:, 0]) * ux + (found[:, 1][:, None] - segments[:, 1]) * uy
    t2 = (found[:, 2][:, None] - segments[:, 0]) * ux + (found[:, 3][:, None] - segments[:, 1]) * uy
    lo, hi = np.maximum(np.minimum(t1, t2), 0.0), np.minimum(np.maximum(t1, t2), glen)
    cover = np.clip(hi - lo, 0.0, None) >= min_overlap * glen
    return (along & cover).any(axis=0)


def truth_matches(lines: np.ndarray, truth: np.ndarray, rho_tol: float = _REPORT.rho_tol,
                  theta_tol: float = _THETA_TOL) -> np.ndarray:
    """Which true lines ``truth`` (M, 2) ``[rho, theta]`` a detected line (N, >=2) lies within tolerance of.

    (rho, theta) and (-rho, theta - pi) are the same line, so lines near theta = 0 and theta = pi are compared both
    ways. Returns (M,) bool.

    Examples
    --------
    >>> import numpy as np
    >>> lines = [[20.0, np.pi / 2, 80], [-10.0, np.pi - 0.01, 60]]
    >>> truth_matches(lines, [[20.5, np.pi / 2], [10.0, 0.0], [40.0, 1.0]]).tolist()  # (10, 0) is (-10, pi)
    [True, True, False]
    """
    truth = np.asarray(truth, np.float64).reshape(-1, 2)
    lines = np.asarray(lines, np.float64)
    if len(lines) == 0 or len(truth) == 0:
        return np.zeros(len(truth), bool)
    r, t = lines[:, 0][:, None], lines[:, 1][:, None]
    dt = np.abs(t - truth[:, 1])
    direct = (dt <= theta_tol) & (np.abs(r - truth[:, 0]) <= rho_tol)
    flipped = (np.abs(dt - np.pi) <= theta_tol) & (np.abs(r + truth[:, 0]) <= rho_tol)
    return (direct | flipped).any(axis=0)


def median_seconds(fn, repeats: int = _LINES.repeats, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` over ``repeats`` calls after ``warmup`` untimed calls, in seconds.

    Examples
    --------
    >>> median_seconds(lambda: sum(range(100)), repeats=3) >= 0
    True
    """
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def compare_runs(ours: dict, opencv: dict, truth: dict | None = None, params: HoughReportParams | None = None
                 ) -> dict:
    """Agreement and truth recall of two ``hough_lines`` stage results (see ``stages/hough_lines.py``).

    Parameters
    ----------
    ours, opencv : dict
        ``{"rho", "theta", "images": [{"file", "lines": [[rho, theta, votes]]}]}`` per implementation.
    truth : dict or None
        Image stem -> (N, 2) true ``[rho, theta]`` lines, for the images that have truth.
    params : HoughReportParams or None
        The ``hough.report`` section: a true line is found by a detected one within ``rho_tol`` pixels and
        ``theta_tol_deg`` degrees (:func:`truth_matches`); None: its defaults.

    Returns
    -------
    dict
        ``per_image`` entries and the summary: ``parity_min``/``parity_mean`` (share of OpenCV's lines in the same
        cell), ``identical_images`` (same lines, votes and order), ``lines_ours``/``lines_opencv`` (lines found
        over all images) and, when any image has truth,
        ``recall_ours``/``recall_opencv`` (true lines found within the tolerances) and ``truth_images``.

    Examples
    --------
    >>> import numpy as np
    >>> run = {"rho": 1.0, "theta": np.pi / 180, "threshold": 60,
    ...        "images": [{"file": "a.png", "lines": [[20.0, np.pi / 2, 80]]}]}
    >>> compared = compare_runs(run, run, {"a": [[20.0, np.pi / 2], [5.0, 0.0]]})
    >>> compared["parity_min"], compared["identical_images"], compared["recall_ours"]
    (1.0, 1, 0.5)
    """
    from pathlib import PurePath

    p = HoughReportParams() if params is None else params
    rho_tol, theta_tol = p.rho_tol, math.radians(p.theta_tol_deg)
    stem = lambda name: PurePath(name).stem  # noqa: E731 - edge maps are PNGs of the same stem as the inputs
    ref = {stem(i["file"]): i for i in opencv["images"]}
    true = truth or {}
    rows, found = [], {"ours": [], "opencv": []}
    for mine in ours["images"]:
        name = stem(mine["file"])
        if name not in ref:
            raise InputError(f"image {name!r} is in ours but not in the opencv run")
        a, b = _as_lines(mine["lines"]), _as_lines(ref[name]["lines"])
        agree = cell_agreement(a, b, ours["rho"], ours["theta"])
        row = {"file": name, **agree, "identical": bool(a.shape == b.shape and np.array_equal(a, b))}
        if name in true:
            for key, lines in (("ours", a), ("opencv", b)):
                hit = truth_matches(lines, np.asarray(true[name], dtype=float).reshape(-1, 2), rho_tol, theta_tol)
                row[f"truth_found_{key}"] = int(hit.sum())
                found[key].append(hit)
            row["truth_lines"] = len(true[name])
        rows.append(row)
    parity = [r["parity"] for r in rows]
    out = {"images": len(rows), "parity_min": min(parity, default=1.0), "parity_mean": float(np.mean(parity or [1.0])),
           "identical_images": sum(r["identical"] for r in rows), "truth_images": len(found["ours"]),
           "lines_ours": sum(r["our_lines"] for r in rows), "lines_opencv": sum(r["ref_lines"] for r in rows),
           "per_image": rows}
    for key, hits in found.items():
        if hits:
            out[f"recall_{key}"] = float(np.concatenate(hits).mean()) if sum(map(len, hits)) else 1.0
    return out


def metrics_of(compared: dict) -> dict:
    """The flat numeric metrics of :func:`compare_runs` output, namespaced by image (``{"hough": {...}}``).

    Examples
    --------
    >>> compared = {"images": 1, "parity_min": 1.0, "per_image": [{"file": "a", "parity": 1.0, "identical": True}]}
    >>> metrics_of(compared)  # the summary under "all", each image under its name, booleans as 0/1
    {'hough': {'all': {'images': 1, 'parity_min': 1.0}, 'a': {'parity': 1.0, 'identical': 1}}}
    """
    summary = {k: v for k, v in compared.items() if k != "per_image"}
    per_image = {r["file"]: {k: (int(v) if isinstance(v, bool) else v) for k, v in r.items() if k != "file"}
                 for r in compared["per_image"]}
    return {"hough": {"all": summary, **per_image}}


def lines_item(edges: np.ndarray, shared: tuple) -> tuple[np.ndarray, float, float]:
    """The lines of one edge map and their times: the per-image work of the ``hough_lines`` stage, an item of
    :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    edges : (H, W) uint8
        The edge map.
    shared : tuple
        ``(method, HoughLinesParams)``: a key of :data:`cvpipe.hough.IMPLEMENTATIONS` and the ``hough.lines``
        section (``rho``, ``theta_deg``, ``threshold``, ``refine`` for ours, ``repeats``).

    Returns
    -------
    (lines, first, median)
        The (N, 3) ``[rho, theta, votes]`` rows, the seconds of the first call (a fresh worker's one-off costs
        included) and the median seconds over ``repeats`` further calls (:func:`median_seconds`).
    """
    from .transform import detect_lines

    method, p = shared
    t0 = time.perf_counter()
    lines = detect_lines(edges, p, method)
    first = time.perf_counter() - t0
    return lines, first, median_seconds(lambda: detect_lines(edges, p, method), p.repeats)
