"""Stereo rectification: uncalibrated (from the fundamental matrix) and calibrated (from a calibration file).

Uncalibrated: Hartley's method (Hartley 1999, "Theory and practice of projective rectification"), with the
shearing correction of Loop & Zhang (1999) on the right image. Hartley's method was chosen over the quasi-Euclidean
one because it is closed form and purely projective: the quasi-Euclidean model (Fusiello & Irsara) assumes both
views share one focal length and differ by a rotation, so a scale change or a shift of the principal point between
the photos (zoom, cropping, phone stabilisation) leaves vertical errors it cannot remove, and it needs a non-linear
solve. The steps:

1. the left homography ``H_left = T^-1 G R T``: translate the image centre to the origin (T), rotate the epipole
   onto the x axis (R, the smaller of the two rotations that do so, so the image is never turned upside down), and
   send it to infinity with ``G = [[1, 0, 0], [0, 1, 0], [-1/f, 0, 1]]``, which is the identity to first order at
   the centre: the projective transform closest to a rigid one there. A pair that is nearly rectified already
   (epipole near infinity on the x axis) gets a near-identity;
2. the right homography's second and third rows follow from ``F`` and ``H_left`` (the epipolar line of a right
   point must be the row ``y`` in the rectified left image): ``y_r = -(N_2 . x) / (N_1 . x)`` with
   ``N = H_left^-T F^T``;
3. its first row is free: it is chosen to keep the right image as undistorted as possible, by Loop & Zhang's
   shearing transform (the mid-lines of the image stay perpendicular and keep their length ratio, i.e. no skew
   and no aspect change), then translated so that the right principal point (by default the image centre) keeps
   its column;
4. a horizontal shift of the right image puts the smallest disparity of the inlier matches (robustly: isolated
   strays dropped, then their 0.5th percentile, see :func:`robust_disparity_range`) at ``margin`` pixels, so that a
   search over ``0 .. max_disp - 1`` covers the scene, and ``max_disp`` is the smallest multiple of 16 above their
   robust largest disparity plus a margin.

Calibrated: ``cv2.stereoRectify`` and ``cv2.initUndistortRectifyMap`` from the intrinsics, lens distortion and
relative pose of a Middlebury ``calib.txt`` or an OpenCV stereo YAML file (parsed by :mod:`.calibration`), with the
same disparity shift.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..errors import EstimationError, InputError
from ..geometry import apply_homography
from ..params import StereoRectifyParams
from .calibration import Calibration, _check_size
from .epipolar import FundamentalFit, epipoles, find_fundamental

#: robust extremes of the inlier disparities (percentiles): a few false matches along an epipolar line are inliers
#: of F with any disparity, so the plain min / max would follow them
DISPARITY_PERCENTILES = (0.5, 99.5)
#: the ``stereo.rectify`` defaults: the one declaration of the ``threshold`` / ``margin`` defaults below
_RECTIFY = StereoRectifyParams()
#: resampling of the rectified images: bicubic keeps the texture that the matching cost needs (bilinear is a
#: low-pass filter at half-pixel shifts); over 72 unrectified Middlebury draws bad-2.0 after rectification rose by
#: 0.44 points on average over the original pair's (at most 1.93) against 0.49 (at most 2.18) with bilinear, and
#: Lanczos-4 rang (0.57, at most 2.28 on seeds 0-3)
WARP_INTERPOLATION = cv2.INTER_CUBIC
#: ``max_disp`` headroom above the largest (robust) inlier disparity: a fraction of it, at least 4 px
_MAX_DISP_HEADROOM = (0.1, 4.0)


@dataclass(frozen=True, eq=False)
class DepthGeometry:
    """What turns a disparity of the rectified left image into depth and 3-D points.

    Attributes
    ----------
    focal : float
        Focal length of the rectified left image, pixels.
    cx, cy : float
        Its principal point, pixels.
    baseline : float
        Distance between the camera centres, in ``unit``.
    doffs : float
        Added to the disparity: ``Z = focal * baseline / (d + doffs)`` (the difference of the principal points'
        columns, right minus left, in the rectified frame).
    unit : str
        Unit of ``baseline`` and therefore of depth (e.g. ``"mm"``).
    exact : bool
        False when the rectification was estimated from the images (uncalibrated) and only the intrinsics and
        baseline come from the calibration: then ``doffs`` assumes the right view kept its principal column.
    """

    focal: float
    cx: float
    cy: float
    baseline: float
    doffs: float
    unit: str
    exact: bool = True


@dataclass(frozen=True, eq=False)
class Rectification:
    """The result of :func:`rectify_uncalibrated` or :func:`rectify_calibrated`.

    Attributes
    ----------
    H_left, H_right : (3, 3) float64
        Original -> rectified pixels of each image (without lens distortion in the calibrated case).
    size : (int, int)
        (width, height) of the rectified images (the input size).
    shift : float
        Horizontal shift applied to the right image, pixels (already inside ``H_right``).
    max_disp : int
        Disparities to search (0 .. max_disp - 1), a multiple of 16 covering the inlier matches.
    disparity_range : (float, float)
        Robust smallest and largest disparity of the inlier matches after rectification, pixels.
    vertical_error : (N,) float64
        ``|y_left - y_right|`` of the inlier matches after rectification, pixels (calibrated: of the matches that
        land within 2 px of the same row, empty without matches).
    fit : FundamentalFit or None
        The epipolar geometry (uncalibrated only).
    depth : DepthGeometry or None
        Present when a calibration was given.
    maps : tuple or None
        Calibrated only: ``(left_x, left_y, right_x, right_y)`` float32 remap tables (rectified -> original).
    """

    H_left: np.ndarray
    H_right: np.ndarray
    size: tuple
    shift: float
    max_disp: int
    disparity_range: tuple
    vertical_error: np.ndarray
    fit: FundamentalFit | None = None
    depth: DepthGeometry | None = None
    maps: tuple | None = field(default=None, repr=False)

    @property
    def vertical_error_median(self) -> float:
        """Median vertical error of the inlier matches, pixels."""
        return float(np.median(self.vertical_error)) if len(self.vertical_error) else float("nan")

    @property
    def vertical_error_p95(self) -> float:
        """95th percentile of the vertical error of the inlier matches, pixels."""
        return float(np.percentile(self.vertical_error, 95)) if len(self.vertical_error) else float("nan")


# ------------------------------------------------------------------------------------------- small helpers


def distortion(H, size) -> dict[str, float]:
    """Distortion of an image by a rectifying homography, from its mid-lines (Loop & Zhang's measures).

    Parameters
    ----------
    H : (3, 3) array_like
        Original -> rectified pixels.
    size : (int, int)
        (width, height) of the original image.

    Returns
    -------
    dict
        ``aspect_change``: |(length ratio of the mapped horizontal and vertical mid-lines) / (w / h) - 1|;
        ``skew_deg``: |90 - the angle between them| in degrees. Both 0 for a similarity.
    """
    w, h = _check_size(size)
    H = np.asarray(H, dtype=np.float64)
    a, b, c, d = apply_homography(H, np.array([[(w - 1) / 2, 0], [w - 1, (h - 1) / 2], [(w - 1) / 2, h - 1],
                                      [0, (h - 1) / 2]]))
    x, y = b - d, c - a
    cosang = abs(float(x @ y)) / (np.linalg.norm(x) * np.linalg.norm(y))
    return {"aspect_change": abs(float(np.linalg.norm(x) / np.linalg.norm(y)) / ((w - 1) / (h - 1)) - 1.0),
            "skew_deg": 90.0 - math.degrees(math.acos(min(1.0, cosang)))}


def _shear(Hp: np.ndarray, w: int, h: int) -> np.ndarray:
    """Loop & Zhang's shearing transform S = [[sa, sb, 0], [0, 1, 0], [0, 0, 1]] that makes the mapped mid-lines
    of a (w, h) image perpendicular with length ratio (w - 1) / (h - 1)."""
    a, b, c, d = apply_homography(Hp, np.array([[(w - 1) / 2, 0], [w - 1, (h - 1) / 2], [(w - 1) / 2, h - 1],
                                       [0, (h - 1) / 2]]))
    (xu, xv), (yu, yv) = b - d, c - a
    W, Hh = float(w - 1), float(h - 1)
    den = Hh * W * (xv * yu - xu * yv)
    if abs(den) < 1e-12:
        raise EstimationError("the right rectifying homography collapses the image onto a line; the epipolar "
                              "geometry is implausible (check the matches)")
    sa = (Hh ** 2 * xv ** 2 + W ** 2 * yv ** 2) / den
    sb = (Hh ** 2 * xu * xv + W ** 2 * yu * yv) / -den
    if sa < 0:
        sa, sb = -sa, -sb
    return np.array([[sa, sb, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def _max_disp(hi: float) -> int:
    top = hi + max(_MAX_DISP_HEADROOM[0] * hi, _MAX_DISP_HEADROOM[1])
    return int(max(16, math.ceil(top / 16.0) * 16))


def _strays_below(d: np.ndarray, budget: int) -> int:
    """How many of the lowest values of the sorted ``d`` (at most ``budget``) lie below the innermost gap of more
    than ``max(8, 25 % of the range above it)``: a lone stray or a group of them, far from the rest."""
    n = 0
    for k in range(1, min(budget, len(d) - 2) + 1):
        if d[k] - d[k - 1] > max(8.0, 0.25 * (d[-1] - d[k])):
            n = k
    return n


def robust_disparity_range(d) -> tuple[float, float]:
    """Smallest and largest disparity of inlier matches, ignoring stray ones.

    A false match along an epipolar line is an inlier of F with any disparity (e.g. two SIFT keypoints at one
    place matched to a repeated texture 400 px away). At each end, the points beyond the innermost gap of more than
    ``max(8 px, 25 % of the remaining range)`` among the outermost 2 % are dropped (a lone stray or a group of them,
    e.g. false matches at -6.5, -1.7 and 4.7 px below a scene at 20.6-31.7 px), then the nearest-rank percentiles
    of :data:`DISPARITY_PERCENTILES` are taken.
    """
    d = np.sort(np.asarray(d, dtype=np.float64).ravel())
    if len(d) == 0:
        raise EstimationError("no inlier matches to measure the disparity range")
    budget = max(1, int(0.02 * len(d)))
    d = d[:len(d) - _strays_below(-d[::-1], budget)]
    kept = d[_strays_below(d, budget):]
    lo = np.percentile(kept, DISPARITY_PERCENTILES[0], method="higher")
    hi = np.percentile(kept, DISPARITY_PERCENTILES[1], method="lower")
    return float(lo), float(hi)


def _disparity_shift(xl: np.ndarray, xr: np.ndarray, margin: float) -> tuple[float, float, float]:
    """(shift to add to the right x, robust low, robust high disparity after the shift)."""
    lo, hi = robust_disparity_range(xl - xr)
    shift = float(lo - margin)
    return shift, float(lo - shift), float(hi - shift)


# -------------------------------------------------------------------------------------------- uncalibrated


def rectifying_homographies(F, pts1, pts2, size, margin: float = _RECTIFY.margin, right_anchor=None) -> tuple:
    """Hartley / Loop-Zhang rectifying homographies of a pair with fundamental matrix ``F``.

    Parameters
    ----------
    F : (3, 3) array_like
        Rank-2 fundamental matrix, ``x_right^T F x_left = 0``.
    pts1, pts2 : (N, 2) array_like
        Inlier matches (left, right) that set the disparity shift; N >= 1.
    size : (int, int)
        (width, height) of both images.
    margin : float
        Where the smallest (robust) inlier disparity lands, pixels (>= 0).
    right_anchor : (float, float), optional
        The right image point whose column is kept before the disparity shift (default: the image centre; the
        right principal point when a calibration is known, so that its ``doffs`` still holds).

    Returns
    -------
    H_left, H_right : (3, 3) float64
        Original -> rectified pixels.
    shift : float
        Horizontal shift included in ``H_right``, pixels.
    lo, hi : float
        Robust smallest and largest inlier disparity after rectification.
    """
    w, h = _check_size(size)
    if not (math.isfinite(margin) and margin >= 0):
        raise InputError(f"`margin` must be a finite number >= 0 pixels, got {margin!r}")
    F = np.asarray(F, dtype=np.float64)
    p1 = np.asarray(pts1, dtype=np.float64).reshape(-1, 2)
    p2 = np.asarray(pts2, dtype=np.float64).reshape(-1, 2)
    if len(p1) == 0 or len(p1) != len(p2):
        raise InputError("`pts1` and `pts2` must hold the same number (>= 1) of inlier matches")
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    T = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [0.0, 0.0, 1.0]])
    e1, _ = epipoles(F)
    e = T @ e1
    if e[2] < 0:
        e = -e
    ang = math.atan2(e[1], e[0])
    # the smaller rotation that puts the epipole on the x axis (either direction): never turn the image over
    if ang > math.pi / 2:
        ang -= math.pi
    elif ang <= -math.pi / 2:
        ang += math.pi
    c, s = math.cos(ang), math.sin(ang)
    R = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    er = R @ e
    if abs(er[0]) < 1e-12:
        raise EstimationError("the epipole is at the image centre (the camera moved forward): such a pair "
                              "cannot be rectified by homographies; take the photos side by side")
    G = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-er[2] / er[0], 0.0, 1.0]])
    H_left = np.linalg.inv(T) @ G @ R @ T
    corners = np.array([[0.0, 0.0, 1.0], [w - 1, 0.0, 1.0], [0.0, h - 1, 1.0], [w - 1, h - 1, 1.0]])
    if ((corners @ H_left[2]) <= 0).any():
        raise EstimationError("the rectified left image would wrap through infinity (the epipole lies inside the "
                              "image, the camera moved forward): take the photos side by side")
    # rows 2 and 3 of the right homography are fixed by F and H_left
    N = np.linalg.inv(H_left).T @ F.T
    r2, r3 = -N[2], N[1]
    if np.mean(np.column_stack([p2, np.ones(len(p2))]) @ r3) < 0:
        r2, r3 = -r2, -r3
    # provisional first row: keep the columns of the right image (least squares over a grid), then shear
    gx, gy = np.meshgrid(np.linspace(0, w - 1, 9), np.linspace(0, h - 1, 9))
    g = np.column_stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
    wgt = g @ r3
    if (wgt <= 0).any():
        raise EstimationError("the rectified right image would wrap through infinity (the epipole lies inside "
                              "the image): such a pair cannot be rectified by homographies")
    r1, *_ = np.linalg.lstsq(g / wgt[:, None], g[:, 0], rcond=None)
    Hp = np.vstack([r1, r2, r3])
    H_right = _shear(Hp, w, h) @ Hp
    ax, ay = (cx, cy) if right_anchor is None else (float(right_anchor[0]), float(right_anchor[1]))
    x_anchor = apply_homography(H_right, np.array([[ax, ay]]))[0, 0]
    H_right = np.array([[1.0, 0.0, ax - x_anchor], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) @ H_right
    xl = apply_homography(H_left, p1)[:, 0]
    xr = apply_homography(H_right, p2)[:, 0]
    shift, lo, hi = _disparity_shift(xl, xr, margin)
    H_right = np.array([[1.0, 0.0, shift], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) @ H_right
    return H_left / H_left[2, 2], H_right / H_right[2, 2], shift, lo, hi


def rectify_uncalibrated(pts1, pts2, size, threshold: float = _RECTIFY.threshold, margin: float = _RECTIFY.margin,
                         calibration=None,
                         rng=None, fit: FundamentalFit | None = None) -> Rectification:
    """Rectify a pair from its point matches alone (the fundamental matrix), optionally with known intrinsics.

    Parameters
    ----------
    pts1, pts2 : (N, 2) array_like
        Putative matches, left and right pixels.
    size : (int, int)
        (width, height) of both images.
    threshold : float
        Sampson-distance inlier threshold of :func:`cvpipe.stereo.epipolar.find_fundamental`, pixels.
    margin : float
        Where the smallest (robust) inlier disparity lands, pixels.
    calibration : Calibration, optional
        A calibration of the rig without usable extrinsics (a Middlebury ``calib.txt`` describes the rectified
        rig): its focal length, baseline and ``doffs`` give the depth geometry (``exact=False``).
    rng : None, int or numpy.random.Generator
        Seed of the RANSAC sampling.
    fit : FundamentalFit, optional
        An epipolar geometry already estimated from these matches (skips the RANSAC).

    Returns
    -------
    Rectification

    Raises
    ------
    EstimationError
        Too few matches, a planar scene or a pure rotation (see ``find_fundamental``), or a geometry that
        homographies cannot rectify (epipole inside the image).
    """
    w, h = _check_size(size)
    if fit is None:
        fit = find_fundamental(pts1, pts2, threshold=threshold, rng=rng)
    p1 = np.asarray(pts1, dtype=np.float64).reshape(-1, 2)[fit.inliers]
    p2 = np.asarray(pts2, dtype=np.float64).reshape(-1, 2)[fit.inliers]
    anchor = None if calibration is None else (calibration.K2[0, 2], calibration.K2[1, 2])
    H_left, H_right, shift, lo, hi = rectifying_homographies(fit.F, p1, p2, (w, h), margin, anchor)
    vert = np.abs(apply_homography(H_left, p1)[:, 1] - apply_homography(H_right, p2)[:, 1])
    depth = None
    if calibration is not None:
        K1 = calibration.K1
        J = _jacobian(H_left, K1[0, 2], K1[1, 2])
        c0 = apply_homography(H_left, np.array([[K1[0, 2], K1[1, 2]]]))[0]
        depth = DepthGeometry(focal=float(K1[0, 0] * math.sqrt(abs(np.linalg.det(J)))), cx=float(c0[0]),
                              cy=float(c0[1]), baseline=calibration.baseline,
                              doffs=float(calibration.doffs + shift), unit=calibration.unit, exact=False)
    return Rectification(H_left=H_left, H_right=H_right, size=(w, h), shift=shift, max_disp=_max_disp(hi),
                         disparity_range=(lo, hi), vertical_error=vert, fit=fit, depth=depth)


def _jacobian(H: np.ndarray, x: float, y: float) -> np.ndarray:
    q = H @ np.array([x, y, 1.0])
    return (H[:2, :2] - np.outer(q[:2] / q[2], H[2, :2])) / q[2]


def opencv_uncalibrated(pts1, pts2, size, threshold: float = _RECTIFY.threshold
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV's uncalibrated rectification on the same matches: ``cv2.findFundamentalMat`` (USAC_MAGSAC) and
    ``cv2.stereoRectifyUncalibrated``.

    Returns
    -------
    H_left, H_right : (3, 3) float64
        Original -> rectified pixels.
    F : (3, 3) float64
    inliers : (N,) bool
    """
    w, h = _check_size(size)
    p1 = np.asarray(pts1, dtype=np.float64).reshape(-1, 2)
    p2 = np.asarray(pts2, dtype=np.float64).reshape(-1, 2)
    F, mask = cv2.findFundamentalMat(p1, p2, cv2.USAC_MAGSAC, float(threshold), 0.999, 10000)
    if F is None or F.shape != (3, 3) or mask is None:
        raise EstimationError("cv2.findFundamentalMat (USAC_MAGSAC) found no fundamental matrix")
    inl = mask.ravel().astype(bool)
    ok, H1, H2 = cv2.stereoRectifyUncalibrated(p1[inl], p2[inl], F, (w, h), threshold=5.0)
    if not ok:
        raise EstimationError("cv2.stereoRectifyUncalibrated failed")
    return np.asarray(H1, float), np.asarray(H2, float), np.asarray(F, float), inl


def rectify_calibrated(calib: Calibration, size, pts1=None, pts2=None, margin: float = _RECTIFY.margin
                       ) -> Rectification:
    """Calibrated rectification (``cv2.stereoRectify``, ``cv2.initUndistortRectifyMap``) with the disparity shift.

    Parameters
    ----------
    calib : Calibration
        Intrinsics, distortion and pose of the rig; its size must match ``size``.
    size : (int, int)
        (width, height) of both images.
    pts1, pts2 : (N, 2) array_like, optional
        Matches (original pixels); those that land on the same row (within 2 px) after rectification set the
        disparity shift and ``max_disp``. Without them the shift is 0 and ``max_disp`` comes from ``ndisp``
        (or 128).
    margin : float
        Where the smallest (robust) match disparity lands, pixels.

    Returns
    -------
    Rectification
        With ``maps`` (remap tables) and an exact ``depth`` geometry.

    Raises
    ------
    InputError
        The images are not the calibration's size, or ``cv2.stereoRectify`` gives no finite result for it (absurd
        magnitudes such as a focal length of 1e300).
    """
    w, h = _check_size(size)
    calib.check_size((w, h))
    R1, R2, P1, P2, _, _, _ = cv2.stereoRectify(calib.K1, calib.D1, calib.K2, calib.D2, (w, h), calib.R,
                                                calib.T.reshape(3, 1), flags=0, alpha=0)
    P1, P2 = np.asarray(P1, float), np.asarray(P2, float)
    if not all(np.isfinite(m).all() for m in (R1, R2, P1, P2)) or P1[0, 0] <= 0:
        raise InputError(f"{calib.source}: `K1`, `K2`, `R` and `T` give no finite rectification (cv2.stereoRectify); "
                         "check their magnitudes", file=calib.source)
    shift, lo, hi, vert = 0.0, 0.0, float(calib.ndisp or 128) - 16.0, np.empty(0)
    if pts1 is not None and pts2 is not None and len(pts1) > 0:
        p1 = np.asarray(pts1, np.float64).reshape(-1, 1, 2)
        p2 = np.asarray(pts2, np.float64).reshape(-1, 1, 2)
        q1 = cv2.undistortPoints(p1, calib.K1, calib.D1, R=R1, P=P1).reshape(-1, 2)
        q2 = cv2.undistortPoints(p2, calib.K2, calib.D2, R=R2, P=P2).reshape(-1, 2)
        dy = np.abs(q1[:, 1] - q2[:, 1])
        keep = dy <= 2.0
        if keep.sum() >= 8:
            vert = dy[keep]
            shift, lo, hi = _disparity_shift(q1[keep, 0], q2[keep, 0], margin)
    P2s = P2.copy()
    P2s[0] += shift * P2s[2]
    m1 = cv2.initUndistortRectifyMap(calib.K1, calib.D1, R1, P1[:, :3], (w, h), cv2.CV_32FC1)
    m2 = cv2.initUndistortRectifyMap(calib.K2, calib.D2, R2, P2s[:, :3], (w, h), cv2.CV_32FC1)
    H_left = P1[:, :3] @ R1 @ np.linalg.inv(calib.K1)
    H_right = P2s[:, :3] @ R2 @ np.linalg.inv(calib.K2)
    f = float(P1[0, 0])
    baseline = abs(float(P2[0, 3]) / float(P2[0, 0])) if P2[0, 3] != 0 else abs(float(P2[1, 3]) / float(P2[1, 1]))
    # columns of the principal points, right minus left (the shift moved the right one)
    depth = DepthGeometry(focal=f, cx=float(P1[0, 2]), cy=float(P1[1, 2]), baseline=baseline,
                          doffs=float(P2s[0, 2] - P1[0, 2]), unit=calib.unit, exact=True)
    return Rectification(H_left=H_left / H_left[2, 2], H_right=H_right / H_right[2, 2], size=(w, h),
                         shift=shift, max_disp=_max_disp(hi), disparity_range=(lo, hi), vertical_error=vert,
                         depth=depth, maps=(m1[0], m1[1], m2[0], m2[1]))


def rectified_depth_geometry(calib: Calibration) -> DepthGeometry:
    """Depth geometry of an already rectified pair described by ``calib`` (Middlebury: used as is).

    Raises
    ------
    InputError
        An OpenCV calibration whose cameras are not rectified (a rotation, lens distortion, different focal
        lengths or rows, or a baseline off the x axis): the pair needs rectifying first.
    """
    if not calib.rectified:
        K1, K2 = calib.K1, calib.K2
        off_axis = np.abs(calib.T[1:]).max() > 1e-6 * calib.baseline
        if (not np.allclose(calib.R, np.eye(3), atol=1e-9) or np.any(calib.D1) or np.any(calib.D2) or off_axis
                or not np.isclose(K1[0, 0], K2[0, 0]) or not np.isclose(K1[1, 2], K2[1, 2])):
            raise InputError(f"{calib.source}: the calibration describes cameras that are not rectified (R, D1/D2, "
                             "T or K1/K2); add --rectify")
    doffs = calib.doffs if calib.rectified else calib.K2[0, 2] - calib.K1[0, 2]
    return DepthGeometry(focal=float(calib.K1[0, 0]), cx=float(calib.K1[0, 2]), cy=float(calib.K1[1, 2]),
                         baseline=calib.baseline, doffs=float(doffs), unit=calib.unit, exact=True)


def warp_pair(left: np.ndarray, right: np.ndarray, rect: Rectification) -> tuple[np.ndarray, np.ndarray]:
    """Both images in the rectified frame (bicubic, :data:`WARP_INTERPOLATION`; outside the original: 0)."""
    w, h = rect.size
    if rect.maps is not None:
        lx, ly, rx, ry = rect.maps
        return (cv2.remap(left, lx, ly, WARP_INTERPOLATION, borderMode=cv2.BORDER_CONSTANT),
                cv2.remap(right, rx, ry, WARP_INTERPOLATION, borderMode=cv2.BORDER_CONSTANT))
    return (cv2.warpPerspective(left, rect.H_left, (w, h), flags=WARP_INTERPOLATION),
            cv2.warpPerspective(right, rect.H_right, (w, h), flags=WARP_INTERPOLATION))


def max_disp_from_matches(pts1, pts2, max_dy: float = 1.5) -> int:
    """``max_disp`` of an already rectified pair from its matches on the same row (within ``max_dy`` px).

    Raises
    ------
    EstimationError
        Fewer than 8 matches on the same row: the pair does not look rectified (use ``--rectify``).
    """
    p1 = np.asarray(pts1, dtype=np.float64).reshape(-1, 2)
    p2 = np.asarray(pts2, dtype=np.float64).reshape(-1, 2)
    keep = np.abs(p1[:, 1] - p2[:, 1]) <= max_dy
    d = p1[keep, 0] - p2[keep, 0]
    d = d[d >= 0]
    if len(d) < 8:
        raise EstimationError(f"only {len(d)} matches lie on the same row with a disparity >= 0: the pair does not "
                              "look rectified; pass `--rectify` or a number to `--max-disp`")
    return _max_disp(robust_disparity_range(d)[1])


def looks_rectified(pts1, pts2, max_dy: float = _RECTIFY.rectified_max_dy, share: float = 0.9) -> bool:
    """Whether a pair is already rectified: at least ``share`` of its matches lie within ``max_dy`` px of the same
    row (a stage can then skip rectification, which makes it a no-op for rectified pairs).

    Parameters
    ----------
    pts1, pts2 : (N, 2) array_like
        Putative matches (left, right); the ratio test leaves a few outliers, hence ``share`` < 1.
    max_dy : float
        Row tolerance, pixels (SIFT keypoints are good to a few tenths of a pixel).
    share : float
        Fraction in (0, 1].
    """
    if not (0 < share <= 1) or not max_dy > 0:
        raise InputError(f"`share` must be in (0, 1] and `max_dy` > 0, got {share!r} and {max_dy!r}")
    p1 = np.asarray(pts1, dtype=np.float64).reshape(-1, 2)
    p2 = np.asarray(pts2, dtype=np.float64).reshape(-1, 2)
    if len(p1) == 0 or len(p1) != len(p2):
        return False
    return bool(np.mean(np.abs(p1[:, 1] - p2[:, 1]) <= max_dy) >= share)
