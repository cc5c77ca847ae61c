"""``cvpipe bench stereo --rectify``: our uncalibrated rectification against OpenCV's, on unrectified Middlebury pairs.

Each rectified pair (the five Middlebury pairs and scikit-image's motorcycle) is unrectified by a seeded random
homography of the right view: a rotation of up to ``MAX_ROTATION_DEG`` about each camera axis through the principal
point (``K R K^-1``, with the image centre as principal point and ``FOCAL_PER_WIDTH * width`` as focal length unless
the pair's calibration is known), a scale change of up to ``MAX_SCALE`` about the principal point and a vertical
shift of up to ``MAX_SHIFT_PX``. SIFT matches of (left, unrectified right) go to both methods:

- ours: :func:`cvpipe.stereo.rectify.rectify_uncalibrated` (7-point RANSAC, Hartley + Loop-Zhang homographies, disparity
  shift and ``max_disp``);
- OpenCV: ``cv2.findFundamentalMat`` (USAC_MAGSAC, same threshold) + ``cv2.stereoRectifyUncalibrated``.

True correspondences come from the true disparity of the original pair: the left pixel (x, y) with disparity d
matches (x - d, y) in the original right view, i.e. ``H_u (x - d, y)`` in the unrectified one. Reported per pair:
median and 95th percentile of their vertical error after rectification (px) for ours, OpenCV's, and a reference
that no method can have, the noise floor of these matches: the Sampson least-squares F of exactly the matches that
the true F calls inliers, rectified as ours (``truth_ls``); the distortion of the left image
(aspect change and skew of its mid-lines, see :func:`cvpipe.stereo.rectify.distortion`), the rectification time (given
the matches; wall and CPU seconds, median of ``--repeats`` interleaved calls after a warm-up), and bad-2.0 of our SGM on the rectified
pair against the true disparity carried into the rectified frame, next to bad-2.0 on the original pair (both with
the smallest multiple of 16 above the largest true disparity as range). The unrectifying warp itself pushes part
of the right view out of the frame (a 3 degree turn moves it by ~30 px), which no rectification can bring back: so
bad-2.0 is compared over the same scene points, those whose true match is still inside the unrectified right view
(``bad_2.0_original_visible``); the plain ``bad_2.0_original`` over all pixels is reported too. OpenCV's
rectification leaves negative disparities, so SGM (0 .. max_disp - 1) is run on ours only.
"""

from __future__ import annotations

import argparse
import os
import time

import cv2
import numpy as np
from tqdm import tqdm

from .. import geometry, io, stereo
from ..homography import correspondences
from ..stereo import rectify
from .stereo_pairs import disparity_range

#: unrectifying transform bounds (the benchmark's protocol)
MAX_ROTATION_DEG = 3.0
MAX_SHIFT_PX = 8.0
MAX_SCALE = 0.02
#: focal length assumed for pairs without a calibration, in units of the image width (a ~45 degree field of view)
FOCAL_PER_WIDTH = 1.2
#: known calibration of scikit-image's motorcycle pair (its docstring): focal length, principal point of the right
MOTORCYCLE_K_RIGHT = (994.978, 311.193 + 31.086, 254.877)
#: truth pixels sampled on a grid with this step
_STEP = 2
#: inlier threshold (Sampson / reprojection, px) of both methods
THRESHOLD = 1.0
#: what a rectification is held to: vertical error median and p95 (px), bad-2.0 rise (points), seconds per pair
TARGETS = {"median_px": 0.3, "p95_px": 1.0, "bad2_points": 2.0, "seconds": 0.2}


def _rotation(ax: float, ay: float, az: float) -> np.ndarray:
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def unrectifying_homography(rng: np.random.Generator, size: tuple[int, int], K: np.ndarray | None = None,
                            max_rotation_deg: float = MAX_ROTATION_DEG, max_shift: float = MAX_SHIFT_PX,
                            max_scale: float = MAX_SCALE) -> tuple[np.ndarray, dict]:
    """A random homography (original right -> unrectified right) and its parameters.

    Rotation about each axis uniform in +-``max_rotation_deg`` (through the principal point), scale uniform in
    1 +- ``max_scale`` about it, vertical shift uniform in +-``max_shift`` px.
    """
    w, h = size
    if K is None:
        f = FOCAL_PER_WIDTH * w
        K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
    ang = np.radians(rng.uniform(-max_rotation_deg, max_rotation_deg, 3))
    s = 1.0 + rng.uniform(-max_scale, max_scale)
    ty = rng.uniform(-max_shift, max_shift)
    cx, cy = K[0, 2], K[1, 2]
    scale = np.array([[s, 0, (1 - s) * cx], [0, s, (1 - s) * cy], [0, 0, 1.0]])
    shift = np.array([[1, 0, 0], [0, 1, ty], [0, 0, 1.0]])
    H = shift @ scale @ K @ _rotation(*ang) @ np.linalg.inv(K)
    return H / H[2, 2], {"rotation_deg": np.degrees(ang).tolist(), "scale": s, "shift_y_px": ty}


def true_correspondences(truth: np.ndarray, H_u: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Left pixels with known disparity (on a grid) and their true match in the unrectified right view."""
    w, h = size
    yy, xx = np.mgrid[0:h:_STEP, 0:w:_STEP]
    d = truth[::_STEP, ::_STEP]
    ok = np.isfinite(d)
    pl = np.column_stack([xx[ok], yy[ok]]).astype(np.float64)
    pr = geometry.apply_homography(H_u, pl - np.column_stack([d[ok], np.zeros(ok.sum())]))
    inside = (pr[:, 0] >= 0) & (pr[:, 0] <= w - 1) & (pr[:, 1] >= 0) & (pr[:, 1] <= h - 1)
    return pl[inside], pr[inside]


def truth_in_rectified_frame(truth: np.ndarray, H_u: np.ndarray, H_left: np.ndarray, H_right: np.ndarray,
                             size: tuple[int, int]) -> np.ndarray:
    """The true disparity of the rectified left image: each rectified pixel goes back to the original left
    (nearest truth pixel, so that depth edges stay sharp), to its true match in the original right, through the
    unrectification and the right rectifying homography; the disparity is the difference of the columns."""
    w, h = size
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    prect = np.column_stack([xx.ravel(), yy.ravel()])
    porig = geometry.apply_homography(np.linalg.inv(H_left), prect)
    xi, yi = np.round(porig[:, 0]).astype(int), np.round(porig[:, 1]).astype(int)
    ok = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
    d = np.full(len(prect), np.nan)
    d[ok] = truth[yi[ok], xi[ok]]
    ok &= np.isfinite(d)
    out = np.full(len(prect), np.nan)
    pr = geometry.apply_homography(H_right @ H_u, np.column_stack([porig[ok, 0] - d[ok], porig[ok, 1]]))
    out[ok] = prect[ok, 0] - pr[:, 0]
    return out.reshape(h, w).astype(np.float32)


def visible_truth(truth: np.ndarray, H_u: np.ndarray, H_left: np.ndarray) -> np.ndarray:
    """The true disparity of the original pair restricted to the pixels whose true match is still inside the
    unrectified right view and which stay inside the rectified left frame (NaN elsewhere): the scene points that
    the unrectified pair can match at all, so that bad-2.0 before and after compares the same points."""
    h, w = truth.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    p = np.column_stack([xx.ravel(), yy.ravel()])
    d = truth.ravel().astype(np.float64)
    ok = np.isfinite(d)
    q = np.full_like(p, -1.0)
    q[ok] = geometry.apply_homography(H_u, np.column_stack([p[ok, 0] - d[ok], p[ok, 1]]))
    r = geometry.apply_homography(H_left, p)
    inside = ((q[:, 0] >= 0) & (q[:, 0] <= w - 1) & (q[:, 1] >= 0) & (q[:, 1] <= h - 1)
              & (r[:, 0] >= 0) & (r[:, 0] <= w - 1) & (r[:, 1] >= 0) & (r[:, 1] <= h - 1))
    return np.where((ok & inside).reshape(h, w), truth, np.nan).astype(np.float32)


def _vertical(H_left, H_right, pl, pr) -> np.ndarray:
    return np.abs(geometry.apply_homography(H_left, pl)[:, 1] - geometry.apply_homography(H_right, pr)[:, 1])


def true_fundamental(H_u: np.ndarray) -> np.ndarray:
    """The exact F of (left, unrectified right): the original pair is rectified (``y_right = y_left``, i.e.
    ``F0 = [e_x]_x``), and the right view was mapped by ``H_u``."""
    F0 = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    return np.linalg.inv(H_u).T @ F0


def run_rectify(args: argparse.Namespace, pairs: dict) -> int:
    """The rectification benchmark over ``pairs`` (name -> (left BGR, right BGR, true disparity))."""
    if args.repeats < 1:
        from ..errors import InputError

        raise InputError(f"`--repeats` must be >= 1, got {args.repeats}")
    n_seeds = getattr(args, "seeds", 1)
    if n_seeds < 1:
        from ..errors import InputError

        raise InputError(f"`--seeds` must be >= 1, got {n_seeds}")
    # one unrectifying transform per pair and seed; seed args.seed alone gives the single-run protocol's transforms
    jobs = [(s, name, data, seq) for s in range(args.seed, args.seed + n_seeds)
            for (name, data), seq in zip(pairs.items(), np.random.SeedSequence(s).spawn(len(pairs)))]
    rows = []
    warm = None
    for unrect_seed, name, (left, right, truth), seed in tqdm(jobs, desc="bench stereo --rectify", disable=None):
        rng = np.random.default_rng(seed)
        h, w = left.shape[:2]
        K = None
        if name == "motorcycle":
            f, cx, cy = MOTORCYCLE_K_RIGHT
            K = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
        H_u, params = unrectifying_homography(rng, (w, h), K)
        right_u = cv2.warpPerspective(right, H_u, (w, h), flags=cv2.INTER_LINEAR)
        # FLANN's randomized KD-trees draw from OpenCV's global RNG: seed it per pair, so that a row's matches (and
        # with them both methods' results) are the same whichever pairs and seeds run before it
        cv2.setRNGSeed(int(rng.integers(2 ** 31 - 1)))
        t0 = time.perf_counter()
        p1, p2 = correspondences(io.to_gray(left), io.to_gray(right_u))
        t_match = time.perf_counter() - t0
        if warm is None:  # the first call of the process, timed apart: it warms OpenCV and the allocations
            t0 = time.perf_counter()
            rectify.rectify_uncalibrated(p1, p2, (w, h), threshold=THRESHOLD, rng=0)
            warm = time.perf_counter() - t0
        ours_t, cv_t, ours_c, cv_c = [], [], [], []
        for k in range(args.repeats):  # interleaved, so that load from other processes hits both alike
            t0, c0 = time.perf_counter(), time.process_time()
            ours = rectify.rectify_uncalibrated(p1, p2, (w, h), threshold=THRESHOLD, rng=k)
            ours_t.append(time.perf_counter() - t0)
            ours_c.append(time.process_time() - c0)
            t0, c0 = time.perf_counter(), time.process_time()
            H1, H2, _, cv_inl = rectify.opencv_uncalibrated(p1, p2, (w, h), threshold=THRESHOLD)
            cv_t.append(time.perf_counter() - t0)
            cv_c.append(time.process_time() - c0)
        pl, pr = true_correspondences(truth, H_u, (w, h))
        ev_ours = _vertical(ours.H_left, ours.H_right, pl, pr)
        ev_cv = _vertical(H1, H2, pl, pr)
        # the noise floor: least squares on exactly the matches that the truth calls inliers, rectified as ours
        true_inl = stereo.sampson_distance(true_fundamental(H_u), p1, p2) <= THRESHOLD
        F_ls = stereo.sampson_least_squares(p1[true_inl], p2[true_inl])
        H1_ls, H2_ls, *_ = rectify.rectifying_homographies(F_ls, p1[true_inl], p2[true_inl], (w, h))
        ev_ls = _vertical(H1_ls, H2_ls, pl, pr)
        dist_ours = rectify.distortion(ours.H_left, (w, h))
        dist_cv = rectify.distortion(H1, (w, h))
        # SGM on the original pair and on our rectified pair, each against its own truth
        nd0 = disparity_range(truth)
        disp0 = stereo.disparity_sgm(left, right, nd0)
        bad_orig = stereo.evaluate(disp0, truth, (2.0,))["bad_2.0"]
        vis = visible_truth(truth, H_u, ours.H_left)
        bad_orig_vis = stereo.evaluate(disp0, vis, (2.0,))["bad_2.0"]
        lr, rr = rectify.warp_pair(left, right_u, ours)
        truth_r = truth_in_rectified_frame(vis, H_u, ours.H_left, ours.H_right, (w, h))
        nd1 = disparity_range(truth_r)
        bad_rect = stereo.evaluate(stereo.disparity_sgm(lr, rr, nd1), truth_r, (2.0,))["bad_2.0"]
        finite = truth_r[np.isfinite(truth_r)]
        rows.append({
            "pair": name, "seed": unrect_seed, "size": [w, h], "unrectify": params, "matches": int(len(p1)),
            "inliers_ours": ours.fit.num_inliers, "inliers_opencv": int(cv_inl.sum()),
            "vertical_median_px_ours": float(np.median(ev_ours)),
            "vertical_p95_px_ours": float(np.percentile(ev_ours, 95)),
            "vertical_median_px_opencv": float(np.median(ev_cv)),
            "vertical_p95_px_opencv": float(np.percentile(ev_cv, 95)),
            "vertical_median_px_truth_ls": float(np.median(ev_ls)),
            "vertical_p95_px_truth_ls": float(np.percentile(ev_ls, 95)), "true_inliers": int(true_inl.sum()),
            "aspect_change_ours": dist_ours["aspect_change"], "skew_deg_ours": dist_ours["skew_deg"],
            "aspect_change_opencv": dist_cv["aspect_change"], "skew_deg_opencv": dist_cv["skew_deg"],
            "bad_2.0_original": bad_orig, "bad_2.0_original_visible": bad_orig_vis, "bad_2.0_rectified": bad_rect,
            "max_disp_original": nd0,
            "max_disp_rectified": nd1, "max_disp_auto": ours.max_disp,
            "true_disparity_range_rectified": [float(np.percentile(finite, 0.5)), float(np.percentile(finite, 99.5))],
            "share_true_disparity_in_auto_range": float(((finite >= 0) & (finite < ours.max_disp)).mean()),
            "seconds_ours": float(np.median(ours_t)), "seconds_opencv": float(np.median(cv_t)),
            "cpu_seconds_ours": float(np.median(ours_c)), "cpu_seconds_opencv": float(np.median(cv_c)),
            "seconds_matching": t_match,
        })
    def key(r: dict) -> str:
        return r["pair"] if n_seeds == 1 else f"{r['pair']}@{r['seed']}"

    summary = {
        "pairs": [key(r) for r in rows], "seed": args.seed, "seeds": n_seeds, "repeats": args.repeats,
        "threshold_px": THRESHOLD,
        "first_call_s": warm, "targets": TARGETS, "load_average_1min": os.getloadavg()[0],
        "median_ok": {key(r): r["vertical_median_px_ours"] <= TARGETS["median_px"] for r in rows},
        "p95_ok": {key(r): r["vertical_p95_px_ours"] <= TARGETS["p95_px"] for r in rows},
        "not_worse_than_opencv": {key(r): bool(r["vertical_median_px_ours"] <= r["vertical_median_px_opencv"]
                                                  and r["vertical_p95_px_ours"] <= r["vertical_p95_px_opencv"])
                                  for r in rows},
        "bad2_within": {key(r): bool(100 * (r["bad_2.0_rectified"] - r["bad_2.0_original_visible"])
                                        <= TARGETS["bad2_points"]) for r in rows},
        "time_ok": {key(r): r["seconds_ours"] < TARGETS["seconds"] for r in rows},
        "median_not_worse": {key(r): bool(r["vertical_median_px_ours"] <= r["vertical_median_px_opencv"])
                             for r in rows},
        "p95_not_worse": {key(r): bool(r["vertical_p95_px_ours"] <= r["vertical_p95_px_opencv"]) for r in rows},
        "truth_ls_not_worse_than_opencv": {key(r): bool(r["vertical_median_px_truth_ls"] <= r["vertical_median_px_opencv"]
                                                    and r["vertical_p95_px_truth_ls"] <= r["vertical_p95_px_opencv"])
                                           for r in rows},
        "mean_vertical_median_px": {m: float(np.mean([r[f"vertical_median_px_{m}"] for r in rows]))
                                    for m in ("ours", "opencv", "truth_ls")},
        "mean_vertical_p95_px": {m: float(np.mean([r[f"vertical_p95_px_{m}"] for r in rows]))
                                 for m in ("ours", "opencv", "truth_ls")},
    }
    if args.json:
        print(io.dumps_json({"summary": summary, "rows": rows}))
        return 0
    print(f"{'pair':<14} {'vert med':>8} {'(cv)':>6} {'vert p95':>8} {'(cv)':>6} {'aspect%':>7} {'(cv)':>6} "
          f"{'skew deg':>8} {'(cv)':>6} {'bad2 orig':>9} {'(visible)':>9} {'bad2 rect':>9} {'auto nd':>7} "
          f"{'covered':>7} {'ours ms':>7} {'cv ms':>6} {'ours cpu':>8} {'cv cpu':>6}")
    for r in rows:
        print(f"{key(r):<14} {r['vertical_median_px_ours']:8.3f} {r['vertical_median_px_opencv']:6.3f} "
              f"{r['vertical_p95_px_ours']:8.3f} {r['vertical_p95_px_opencv']:6.3f} "
              f"{100 * r['aspect_change_ours']:7.2f} {100 * r['aspect_change_opencv']:6.2f} "
              f"{r['skew_deg_ours']:8.2f} {r['skew_deg_opencv']:6.2f} {100 * r['bad_2.0_original']:8.2f}% "
              f"{100 * r['bad_2.0_original_visible']:8.2f}% "
              f"{100 * r['bad_2.0_rectified']:8.2f}% {r['max_disp_auto']:7d} "
              f"{100 * r['share_true_disparity_in_auto_range']:6.1f}% {1000 * r['seconds_ours']:7.1f} "
              f"{1000 * r['seconds_opencv']:6.1f} {1000 * r['cpu_seconds_ours']:8.1f} "
              f"{1000 * r['cpu_seconds_opencv']:6.1f}")
    ok = {k: sum(v.values()) for k, v in summary.items() if k.endswith(("_ok", "_not_worse"))
          or k in ("not_worse_than_opencv", "bad2_within", "truth_ls_not_worse_than_opencv")}
    print("targets met (pairs of", len(rows), "):", ", ".join(f"{k} {v}" for k, v in ok.items()),
          f"; first call {warm:.2f} s; load average {summary['load_average_1min']:.1f}")
    med, p95 = summary["mean_vertical_median_px"], summary["mean_vertical_p95_px"]
    print(f"mean over the rows: vertical median {med['ours']:.3f} px (OpenCV {med['opencv']:.3f}, least squares on "
          f"the true inliers {med['truth_ls']:.3f}), p95 {p95['ours']:.3f} px (OpenCV {p95['opencv']:.3f}, "
          f"{p95['truth_ls']:.3f})")
    return 0
