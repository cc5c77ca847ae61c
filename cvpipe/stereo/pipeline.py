"""The stereo pipeline's per-pair rectify step: rectify -> disparity -> depth -> report.

:func:`rectify_pair` decides how a pair is rectified (calibrated, uncalibrated, or not at all when it already
looks rectified) and returns the record that ``stereo_rectify`` writes as ``rect.json``; the metrics, pictures and
report summary of the stages are in :mod:`cvpipe.stereo.report`. Pure functions: no disk access (the stage scripts
in ``stages/`` read and write).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .. import geometry, io
from ..errors import InputError
from ..params import StereoRectifyParams
from . import rectify
from .calibration import Calibration

#: the kinds of rectification (``rect.json`` ``kind``)
KINDS = ("none", "calibrated", "uncalibrated")
#: the ``stereo.rectify`` defaults: the one declaration of the keyword defaults below
_RECTIFY = StereoRectifyParams()


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


def feature_matches(left: np.ndarray, right: np.ndarray, detector: str = _RECTIFY.detector,
                    max_features: int = _RECTIFY.max_features, ratio: float = _RECTIFY.ratio,
                    seed: int = _RECTIFY.seed) -> tuple[np.ndarray, np.ndarray]:
    """Putative matches left -> right (:func:`cvpipe.homography.correspondences`), the same on every run: FLANN's
    randomized KD-trees draw from OpenCV's global generator, which is seeded with ``seed`` first."""
    from ..homography import correspondences

    cv2.setRNGSeed(int(seed))
    return correspondences(io.to_gray(left), io.to_gray(right), detector, max_features, ratio)


def rectify_pair(left: np.ndarray, right: np.ndarray, pts1: np.ndarray, pts2: np.ndarray,
                 calib: Calibration | None, *, threshold: float = _RECTIFY.threshold,
                 margin: float = _RECTIFY.margin, seed: int = _RECTIFY.seed,
                 rectified_max_dy: float = _RECTIFY.rectified_max_dy,
                 rectified_share: float = _RECTIFY.rectified_share) -> RectifiedPair:
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
        q1, q2 = geometry.apply_homography(rect.H_left, p1), geometry.apply_homography(rect.H_right, p2)
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
        q1 = geometry.apply_homography(rect.H_left, p1[rect.fit.inliers])
        q2 = geometry.apply_homography(rect.H_right, p2[rect.fit.inliers])
        record.update(kind="uncalibrated", inliers=int(rect.fit.num_inliers))
        _vertical(record, rect.vertical_error, "inlier matches of the fundamental matrix")
    record.update(H_left=rect.H_left.tolist(), H_right=rect.H_right.tolist(), shift_px=float(rect.shift),
                  depth=_geometry(rect.depth))
    if len(rect.vertical_error):  # max_disp was estimated from the matches (else it is a default)
        record.update(max_disp=int(rect.max_disp), disparity_range_px=[float(v) for v in rect.disparity_range])
    lw, rw = rectify.warp_pair(left, right, rect)
    return RectifiedPair(lw, rw, record, q1, q2)


def rectify_item(item: tuple, p) -> tuple[RectifiedPair, float]:
    """Rectify one pair from its data: the per-pair work of the ``stereo_rectify`` stage, an item of
    :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    item : tuple
        ``(left, right, calibration text or None, its file name for messages or None)``; the images BGR uint8.
    p : StereoRectifyParams
        The ``stereo.rectify`` section (sent once per worker).

    Returns
    -------
    (RectifiedPair, float)
        The pair and the seconds its matching and rectification took.

    Raises
    ------
    InputError
        A bad calibration file or image (a ``ValueError`` becomes one, so the stage drops the pair).
    EstimationError
        The pair cannot be rectified (the message says ``cannot be rectified: ...``).
    """
    import time

    from ..errors import EstimationError
    from .calibration import parse_calibration

    left, right, calib_text, calib_name = item
    try:
        calib = None if calib_text is None else parse_calibration(calib_text, calib_name)
        t0 = time.perf_counter()
        p1, p2 = feature_matches(left, right, p.detector, p.max_features, p.ratio, p.seed)
        got = rectify_pair(left, right, p1, p2, calib, threshold=p.threshold, margin=p.margin, seed=p.seed,
                           rectified_max_dy=p.rectified_max_dy, rectified_share=p.rectified_share)
    except EstimationError as exc:
        raise EstimationError(f"cannot be rectified: {exc}") from None
    except InputError:
        raise
    except ValueError as exc:
        raise InputError(str(exc)) from None
    return got, time.perf_counter() - t0


#: rows of a worker's first pair run once before its timed call (the first call's one-off costs: imports, thread start)
WARMUP_ROWS = 16
_warm: set[str] = set()  # the methods this process has warmed up


def disparity_item(item: tuple, shared: tuple) -> tuple[np.ndarray, dict[str, float]]:
    """The disparity of one rectified pair: the per-pair work of the ``stereo_disparity`` stage, an item of
    :func:`cvpipe.compute.map_items` (data in, data out).

    Parameters
    ----------
    item : tuple
        ``(left, right, max_disp)``: the rectified images and the pair's disparity range.
    shared : tuple
        ``(method, section)``: a key of :data:`cvpipe.stereo.METHODS` and its ``stereo.<method>`` section
        (:func:`~cvpipe.stereo.methods.disparity_with`).

    Returns
    -------
    (ndarray, dict)
        The float32 disparity (NaN = none) and this item's wall times: ``disparity`` and, on the first pair a
        process computes with ``method``, ``warmup`` (a run on the first :data:`WARMUP_ROWS` rows, so that the
        timed call excludes the first call's one-off costs).

    Raises
    ------
    InputError
        The pair or the options do not fit the method (a ``ValueError`` becomes one, so the stage drops the pair).
    """
    import time

    from .methods import disparity_with

    left, right, max_disp = item
    method, params = shared
    seconds = {}
    try:
        if method not in _warm:
            t0 = time.perf_counter()
            disparity_with(left[:WARMUP_ROWS], right[:WARMUP_ROWS], max_disp, params, method)
            seconds["warmup"] = time.perf_counter() - t0
            _warm.add(method)
        t0 = time.perf_counter()
        disp = disparity_with(left, right, max_disp, params, method)
    except InputError:
        raise
    except ValueError as exc:
        raise InputError(str(exc)) from None
    seconds["disparity"] = time.perf_counter() - t0
    return disp, seconds
