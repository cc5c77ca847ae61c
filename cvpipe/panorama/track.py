"""Refinement of an accepted pair's homography by tracking (a step of the match graph, after the acceptance test;
:func:`cvpipe.panorama.match.match_graph`).

Binary features (ORB) are found on an image pyramid and placed to about a pixel of the level they come from, and
they cluster on the textured parts, so a homography fitted to their matches extrapolates poorly outside the
overlap. :func:`track_pair` takes the corners of image i (:func:`corners`, Shi-Tomasi, found once per image) that
the homography sends inside image j, follows each with pyramidal Lucas-Kanade (``cv2.calcOpticalFlowPyrLK``,
started at the homography's prediction), and fits the homography again to those sub-pixel tracks
(:func:`cvpipe.homography.find_homography`, RANSAC + LM, at ``threshold``, which also drops the tracks that slipped;
a backward check of each track changed nothing measurable on the Adobe sets and doubled the cost, so there is none).
Choices: :data:`PAIR_REFINE_CHOICES`.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..errors import EstimationError
from ..homography import find_homography

#: ``panorama.match.pair_refine``: "none" keeps the fit of the matches, "lk" fits tracks (:func:`track_pair`)
PAIR_REFINE_CHOICES = ("none", "lk")
DEFAULT_PAIR_REFINE = "none"
#: Lucas-Kanade window (pixels, square; 15 was as accurate as 21 on the Adobe sets) and pyramid levels above the
#: base: the homography's prediction is within a few pixels, which level 2 (a quarter of the resolution) absorbs
LK_WINDOW = 15
LK_LEVELS = 2
#: Lucas-Kanade stops after this many iterations per level or a step below this many pixels
LK_ITERATIONS = 30
LK_EPS = 0.01
#: inlier threshold of the fit to the tracks, pixels: tracks are sub-pixel, so a tight threshold keeps the precise ones
TRACK_THRESHOLD = 1.0
#: Shi-Tomasi corners per image (:func:`corners`), their quality relative to the best and their spacing in pixels
CORNERS = 500
CORNER_QUALITY = 0.01
CORNER_SPACING = 8
#: images larger than this (pixels) find their corners at half size (:func:`corners`)
HALF_SIZE_PIXELS = 250_000


def corners(gray: np.ndarray, n: int = CORNERS) -> np.ndarray:
    """(M, 2) float64, M <= ``n``: the image's strongest Shi-Tomasi corners (``cv2.goodFeaturesToTrack``), about
    :data:`CORNER_SPACING` px apart, in ``gray``'s pixels.

    Above :data:`HALF_SIZE_PIXELS` they are found on the half-size image (20x cheaper than at full size: 1.9 against
    36 ms on a 0.6 MP photo) and scaled back: a point only picks the patch that Lucas-Kanade then follows to a
    fraction of a pixel, so it need not sit on the corner exactly; a small image keeps all its corners.
    """
    if gray.size <= HALF_SIZE_PIXELS:
        c = cv2.goodFeaturesToTrack(gray, n, CORNER_QUALITY, CORNER_SPACING, blockSize=7)
        return np.zeros((0, 2)) if c is None else c.reshape(-1, 2).astype(np.float64)
    half = cv2.resize(gray, ((gray.shape[1] + 1) // 2, (gray.shape[0] + 1) // 2), interpolation=cv2.INTER_AREA)
    c = cv2.goodFeaturesToTrack(half, n, CORNER_QUALITY, CORNER_SPACING / 2, blockSize=5)
    if c is None:
        return np.zeros((0, 2))
    sx, sy = gray.shape[1] / half.shape[1], gray.shape[0] / half.shape[0]
    c = c.reshape(-1, 2).astype(np.float64)
    return np.column_stack([(c[:, 0] + 0.5) * sx - 0.5, (c[:, 1] + 0.5) * sy - 0.5])


def track_pair(gray_i: np.ndarray, gray_j: np.ndarray, H: np.ndarray, points: np.ndarray, min_inliers: int,
               threshold: float = TRACK_THRESHOLD, rng=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int] | None:
    """The homography of an accepted pair fitted again to Lucas-Kanade tracks of points of image i.

    Parameters
    ----------
    gray_i, gray_j : (H, W) uint8
        The pair's images at the registration resolution.
    H : (3, 3)
        The accepted homography, image i -> j.
    points : (N, 2) float
        Points of image i to track (:func:`corners`); those that ``H`` sends outside image j (less half a window)
        are left out.
    min_inliers : int
        Fewest tracks the new fit must keep (otherwise None).
    threshold : float
        Inlier threshold of the fit to the tracks, pixels.
    rng : seed or Generator
        For RANSAC.

    Returns
    -------
    (H, src, dst, tracked) or None
        The new homography, the tracks it keeps (its inliers) and the number of points tracked, or None when too
        few points track (the caller keeps ``H``).
    """
    h, w = gray_j.shape
    points = np.asarray(points, np.float64).reshape(-1, 2)
    if len(points) < min_inliers:
        return None
    guess = cv2.perspectiveTransform(points.reshape(-1, 1, 2), H).reshape(-1, 2)
    m = LK_WINDOW // 2
    inside = (guess[:, 0] >= m) & (guess[:, 0] <= w - 1 - m) & (guess[:, 1] >= m) & (guess[:, 1] <= h - 1 - m)
    if inside.sum() < min_inliers:
        return None
    if gray_i.shape != gray_j.shape:  # Lucas-Kanade wants one size: pad both (right, bottom) to the larger
        hh, ww = max(gray_i.shape[0], h), max(gray_i.shape[1], w)
        gray_i = cv2.copyMakeBorder(gray_i, 0, hh - gray_i.shape[0], 0, ww - gray_i.shape[1], cv2.BORDER_REPLICATE)
        gray_j = cv2.copyMakeBorder(gray_j, 0, hh - h, 0, ww - w, cv2.BORDER_REPLICATE)
    p0 = np.ascontiguousarray(points[inside], np.float32).reshape(-1, 1, 2)
    guess = np.ascontiguousarray(guess[inside], np.float32).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, LK_ITERATIONS, LK_EPS)
    win = (LK_WINDOW, LK_WINDOW)
    p1, ok, _ = cv2.calcOpticalFlowPyrLK(gray_i, gray_j, p0, guess, winSize=win, maxLevel=LK_LEVELS,
                                         criteria=crit, flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
    q = p1.reshape(-1, 2)
    good = (ok.ravel() == 1) & (q[:, 0] >= 0) & (q[:, 0] <= w - 1) & (q[:, 1] >= 0) & (q[:, 1] <= h - 1)
    if good.sum() < min_inliers:
        return None
    a, b = p0.reshape(-1, 2)[good].astype(np.float64), q[good].astype(np.float64)
    try:
        fit = find_homography(a, b, threshold=threshold, rng=rng)
    except EstimationError:
        return None
    if int(fit.inliers.sum()) < min_inliers:
        return None
    return fit.H, a[fit.inliers], b[fit.inliers], len(a)
