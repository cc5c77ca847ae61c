"""Geometric verification of each reference's matches: RANSAC model, plausibility checks, a-contrario score."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ..errors import EstimationError
from ..features import Features
from ..geometry import apply_homography as _map_points
from ..homography import find_homography
from ..params import LogoVerifyParams
from ..robust import draw_samples, log10_nfa

#: the ``logo.verify`` defaults: the one declaration of :func:`affine_ransac`'s ``hypotheses``
_VERIFY = LogoVerifyParams()

if TYPE_CHECKING:
    from .gallery import Gallery, Reference
    from .match import Matches


def _mapped(H, pts):
    """``pts`` mapped by ``H``; a point sent to infinity means the fit is implausible (EstimationError)."""
    out = _map_points(H, pts)
    if not np.isfinite(out).all():
        raise EstimationError("a point maps to infinity")
    return out


@dataclass(frozen=True)
class Hypothesis:
    """The verified (or rejected) homography of one reference in one scene.

    Attributes
    ----------
    brand : str
    reference : int
        Index into ``Gallery.references``.
    matches : int
        Tentative matches of this reference (after one-to-one filtering).
    inliers : int
        RANSAC inliers (0 when no homography could be fitted).
    score : float
        ``-log10`` NFA (see the module docstring); ``-inf`` when rejected.
    H : (3, 3) float64 or None
        Reference pixels -> scene pixels.
    quad : (4, 2) float64 or None
        Reference outline (corner pixel centres, clockwise from top-left) in scene pixels.
    pairs : (K, 2) int64
        Inlier ``[reference keypoint, scene keypoint]`` index pairs.
    reason : str
        Why the hypothesis was rejected, empty when it passed every check.
    reference_xy : (K, 2) float64
        The inliers' reference keypoints in the pixels of ``reference``.
    detector : str
        Detector of the gallery the hypothesis comes from (the fused method weighs several).
    """

    brand: str
    reference: int
    matches: int
    inliers: int
    score: float
    H: np.ndarray | None
    quad: np.ndarray | None
    pairs: np.ndarray
    reason: str = ""
    reference_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    detector: str = ""

    @property
    def plausible(self) -> bool:
        return not self.reason


def _polygon_area(q: np.ndarray) -> float:
    x, y = q[:, 0], q[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _hull_area(pts: np.ndarray) -> float:
    if len(pts) < 3:
        return 0.0
    return float(cv2.contourArea(cv2.convexHull(np.asarray(pts, np.float32))))


def shape_problem(H: np.ndarray, corners: np.ndarray, scene_size: tuple[int, int],
                  params: LogoVerifyParams | None = None) -> str:
    """Why the homography is not a plausible view of a flat logo, or ``""`` when it is.

    Parameters
    ----------
    H : (3, 3)
        Reference pixels -> scene pixels.
    corners : (4, 2)
        Logo outline in reference pixels, clockwise from the top-left (``Reference.outline``).
    scene_size : (width, height)
        Scene size in pixels.
    params : LogoVerifyParams, optional
        ``min_area``, ``max_area`` (outline area / scene area), ``max_anisotropy`` (ratio of the singular values
        of the local affine map at the reference centre: shear plus aspect change), ``max_perspective`` (ratio of
        the largest to the smallest local area scale over the four corners).
    """
    p = params or LogoVerifyParams()
    corners = np.asarray(corners, np.float64)
    w = np.c_[corners, np.ones(4)] @ np.asarray(H, np.float64)[2]
    if np.any(w <= 1e-9):
        return "outline crosses the horizon"
    quad = _mapped(H, corners)
    edges = np.roll(quad, -1, axis=0) - quad
    cross = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
    # the reference outline turns clockwise on screen (y down) = positive cross products; negative means mirrored
    if not np.all(cross > 0):
        return "outline not convex or mirrored"
    frac = _polygon_area(quad) / float(scene_size[0] * scene_size[1])
    if not p.min_area <= frac <= p.max_area:
        return f"outline covers {frac:.4f} of the scene, outside [{p.min_area}, {p.max_area}]"
    c = corners.mean(axis=0)
    hc = H @ np.r_[c, 1.0]
    J = (H[:2, :2] * hc[2] - np.outer(hc[:2], H[2, :2])) / hc[2] ** 2
    s = np.linalg.svd(J, compute_uv=False)
    if s[1] <= 0 or s[0] / s[1] > p.max_anisotropy:
        return f"anisotropy {s[0] / max(s[1], 1e-12):.1f} > {p.max_anisotropy}"
    # local area scale of a homography is det(H) / w^3
    persp = float((w.max() / w.min()) ** 3)
    if persp > p.max_perspective:
        return f"perspective area ratio {persp:.1f} > {p.max_perspective}"
    return ""


def fit_affine(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares affine map (3, 3), last row ``[0, 0, 1]``, from (N, 2) ``src`` to (N, 2) ``dst``, N >= 3."""
    X = np.c_[np.asarray(src, np.float64), np.ones(len(src))]
    M, *_ = np.linalg.lstsq(X, np.asarray(dst, np.float64), rcond=None)
    return np.r_[M.T, [[0.0, 0.0, 1.0]]]


def map_poses(H: np.ndarray, xy: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Keypoint orientations and scales carried through the homography ``H``.

    Parameters
    ----------
    H : (3, 3)
    xy : (N, 2)
        Keypoint positions before the mapping.
    pose : (N, 2)
        ``[angle in degrees, natural log of the keypoint size]`` (OpenCV's angle: image axes, y down).

    Returns
    -------
    (N, 2) poses after the mapping: the direction vector of each angle is mapped by the local Jacobian of ``H``,
    and the log size grows by the log of the Jacobian's area scale, halved (a length scale).
    """
    H = np.asarray(H, np.float64)
    xy = np.asarray(xy, np.float64)
    w = xy @ H[2, :2] + H[2, 2]
    hx = xy @ H[:2, :2].T + H[:2, 2]
    J = (H[None, :2, :2] * w[:, None, None] - hx[:, :, None] * H[None, 2:3, :2]) / (w * w)[:, None, None]
    return _apply_jacobians(J, pose)


def _apply_jacobians(J: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Poses mapped by local linear maps ``J`` (..., 2, 2) that broadcast against ``pose`` (N, 2)."""
    a = np.deg2rad(pose[:, 0])
    ux = J[..., 0, 0] * np.cos(a) + J[..., 0, 1] * np.sin(a)
    uy = J[..., 1, 0] * np.cos(a) + J[..., 1, 1] * np.sin(a)
    det = np.abs(J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0])
    return np.stack([np.rad2deg(np.arctan2(uy, ux)), pose[:, 1] + 0.5 * np.log(np.maximum(det, 1e-300))], axis=-1)


def pose_agrees(predicted: np.ndarray, observed: np.ndarray, angle_tolerance: float,
                scale_tolerance: float) -> np.ndarray:
    """Whether predicted and observed ``[angle deg, log size]`` agree within the tolerances (degrees, ratio)."""
    d = np.abs((predicted[..., 0] - observed[..., 0] + 180.0) % 360.0 - 180.0)
    return (d <= angle_tolerance) & (np.abs(predicted[..., 1] - observed[..., 1]) <= np.log(scale_tolerance))


def pose_probability(angle_tolerance: float, scale_tolerance: float) -> float:
    """Chance that an unrelated match agrees in pose: orientation uniform over 360 degrees, log size ratio uniform
    over a factor of 4 either way (``ln 16``); 1 when the tolerances switch the check off."""
    return min(1.0, angle_tolerance / 180.0) * min(1.0, 2.0 * np.log(scale_tolerance) / np.log(16.0))


def affine_ransac(src: np.ndarray, dst: np.ndarray, threshold: float, hypotheses: int = _VERIFY.affine_samples,
                  rng=None, src_pose: np.ndarray | None = None, dst_pose: np.ndarray | None = None,
                  angle_tolerance: float = 180.0, scale_tolerance: float = 1e9) -> tuple[np.ndarray, np.ndarray]:
    """Robust affine map from putative correspondences: RANSAC over 3-point samples, evaluated all at once.

    A logo that covers a small part of the scene is seen almost affinely, and an affine map cannot fold the
    outline over the horizon, so it finds the right model among few, noisy matches where a free homography fits a
    chance configuration with a couple more inliers.

    Parameters
    ----------
    src, dst : (N, 2) float
        Reference and scene points, pixels; N >= 3.
    threshold : float
        Inlier distance in scene pixels.
    hypotheses : int
        3-point samples drawn (all triples when there are fewer).
    rng : None, int or Generator
    src_pose, dst_pose : (N, 2) float, optional
        ``[angle deg, log size]`` of the keypoints; when given, an inlier must also agree in orientation and scale
        with the model's prediction within ``angle_tolerance`` degrees and a ``scale_tolerance`` size ratio.

    Returns
    -------
    A : (3, 3) float64
        Reference -> scene, refitted by least squares on the inliers (a few rounds).
    inliers : (N,) bool

    Raises
    ------
    EstimationError
        Fewer than 3 correspondences or every sample degenerate (collinear).
    """
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    n = len(src)
    if n < 3:
        raise EstimationError(f"an affine map needs 3 correspondences, got {n}")
    rng = np.random.default_rng(rng)
    if n * (n - 1) * (n - 2) // 6 <= hypotheses:
        idx = np.array(list(itertools.combinations(range(n), 3)), np.int64)
    else:  # the robust core's sampler: distinct triples, uniform, reproducible from the seed
        idx = draw_samples(rng.random((hypotheses, 3)), n)
    # the linear part L of each sample maps the edge vectors of the source triangle onto the target's: L = E D^-1
    d1, d2 = src[idx[:, 1]] - src[idx[:, 0]], src[idx[:, 2]] - src[idx[:, 0]]
    e1, e2 = dst[idx[:, 1]] - dst[idx[:, 0]], dst[idx[:, 2]] - dst[idx[:, 0]]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    ok = np.abs(det) > 1e-6 * (np.abs(np.c_[d1, d2]).max(axis=1) ** 2 + 1e-12)
    if not ok.any():
        raise EstimationError("every 3-point sample is collinear")
    d1, d2, e1, e2, det, idx = d1[ok], d2[ok], e1[ok], e2[ok], det[ok], idx[ok]
    L = np.empty((len(det), 2, 2))
    L[:, :, 0] = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / det[:, None]
    L[:, :, 1] = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) / det[:, None]
    t = dst[idx[:, 0]] - np.einsum("tij,tj->ti", L, src[idx[:, 0]])
    ex = L[:, 0, 0:1] * src[:, 0] + L[:, 0, 1:2] * src[:, 1] + t[:, 0:1] - dst[:, 0]  # (T, n)
    ey = L[:, 1, 0:1] * src[:, 0] + L[:, 1, 1:2] * src[:, 1] + t[:, 1:2] - dst[:, 1]
    err2 = ex * ex + ey * ey
    th2 = threshold * threshold
    inl = err2 < th2
    use_pose = src_pose is not None and dst_pose is not None
    if use_pose:
        inl &= pose_agrees(_apply_jacobians(L[:, None], src_pose), dst_pose[None], angle_tolerance, scale_tolerance)
    # most inliers; among equals the smallest truncated squared error (MSAC)
    best = int(np.argmax(inl.sum(axis=1) - np.minimum(err2, th2).sum(axis=1) / (th2 * n + 1.0)))
    inliers = inl[best]
    A = np.r_[np.c_[L[best], t[best]], [[0.0, 0.0, 1.0]]]
    for _ in range(3):  # local optimisation: refit on the inliers while that does not lose any
        if inliers.sum() < 3:
            break
        A2 = fit_affine(src[inliers], dst[inliers])
        in2 = np.linalg.norm(src @ A2[:2, :2].T + A2[:2, 2] - dst, axis=1) < threshold
        if use_pose:
            in2 &= pose_agrees(_apply_jacobians(A2[None, :2, :2], src_pose), dst_pose, angle_tolerance,
                               scale_tolerance)
        if in2.sum() < inliers.sum():
            break
        A, same, inliers = A2, np.array_equal(in2, inliers), in2
        if same:
            break
    return A, inliers


def significance(inliers: int, matches: int, threshold: float, area: float, n_refs: int,
                 pose_prob: float = 1.0) -> float:
    """``-log10`` of the number of false alarms of a homography with ``inliers`` among ``matches``.

    Parameters
    ----------
    inliers, matches : int
        Inlier and tentative match counts of one reference.
    threshold : float
        RANSAC reprojection threshold, scene pixels.
    area : float
        Scene area (px^2) over which chance matches spread.
    n_refs : int
        Number of references tested in this scene (multiple tests).
    pose_prob : float
        Chance that an unrelated match also agrees with the model in orientation and scale
        (:func:`pose_probability`; 1 when inliers are judged by position only). The 4 matches of the minimal sample
        fix the model's position but not the orientations and scales of their keypoints, so they count too.

    Examples
    --------
    12 of 40 matches within 4 px in a 300 x 300 scene, 10 references tried: far from chance.

    >>> round(significance(12, 40, 4.0, 300 * 300, 10), 1)
    12.6
    >>> significance(4, 40, 4.0, 300 * 300, 10)  # a minimal sample alone proves nothing
    -inf
    """
    if matches < 5 or inliers < (5 if pose_prob >= 1.0 else 4):
        return -np.inf
    prob = min(1.0, np.pi * threshold ** 2 / max(area, 1.0)) * pose_prob
    # NFA of the model (robust core) times the references tried; the 4 sample matches agree in pose by chance too
    return float(-(log10_nfa(inliers, matches, prob) + 4 * np.log10(pose_prob) + np.log10(max(n_refs, 1))))


def _check(brand: str, r: int, ref: Reference, H: np.ndarray, inl: np.ndarray, src: np.ndarray, dst: np.ndarray,
           g_idx: np.ndarray, s_idx: np.ndarray, scene_size: tuple[int, int], n_tested: int,
           p: LogoVerifyParams, pose_prob: float = 1.0, detector: str = "") -> Hypothesis:
    """Plausibility checks and score of one fitted model (see :func:`verify`)."""
    # one inlier per scene keypoint: with `per_reference` > 1 a scene keypoint may match both twins of a symmetric
    # mark, and both may agree with the model
    _, first = np.unique(np.where(inl, s_idx, -1), return_index=True)
    keep = np.zeros(len(inl), bool)
    keep[first] = True
    keep &= inl
    n_in = int(keep.sum())
    n_matches = len(np.unique(s_idx))
    pairs = np.c_[g_idx[keep], s_idx[keep]]
    reason = shape_problem(H, ref.outline, scene_size, p)
    quad = None if reason.startswith("outline crosses") else _mapped(H, ref.outline)
    if not reason and n_in < p.min_inliers:
        reason = f"{n_in} inliers < {p.min_inliers}"
    if not reason:
        spread = _hull_area(src[keep]) / ref.area
        if spread < p.min_spread:
            reason = f"inliers cover {spread:.3f} of the reference < {p.min_spread}"
    score = -np.inf
    if not reason:
        area = float(scene_size[0] * scene_size[1])
        score = significance(n_in, n_matches, p.ransac_threshold, area, n_tested, pose_prob)
    return Hypothesis(brand, r, n_matches, n_in, score, H, quad, pairs, reason, src[keep], detector)


def _reprojection_inliers(H: np.ndarray, src: np.ndarray, dst: np.ndarray, threshold: float,
                          poses: tuple | None = None, p: LogoVerifyParams | None = None) -> np.ndarray:
    """(N,) bool: ``src`` mapped by ``H`` lands within ``threshold`` pixels of ``dst`` (in front of the camera), and
    agrees in orientation and scale when ``poses = (src_pose, dst_pose)`` is given."""
    q = np.c_[src, np.ones(len(src))] @ H.T
    ok = q[:, 2] > 1e-9
    err = np.full(len(src), np.inf)
    err[ok] = np.linalg.norm(q[ok, :2] / q[ok, 2:3] - dst[ok], axis=1)
    inl = err < threshold
    if poses is not None and inl.any():
        agree = np.zeros(len(src), bool)
        agree[inl] = pose_agrees(map_poses(H, src[inl], poses[0][inl]), poses[1][inl], p.angle_tolerance,
                                 p.scale_tolerance)
        inl &= agree
    return inl


def _fit_homography(src: np.ndarray, dst: np.ndarray, ref: Reference, scene_size: tuple[int, int],
                    p: LogoVerifyParams, rng: np.random.Generator,
                    poses: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    fit = find_homography(src, dst, threshold=p.ransac_threshold, confidence=0.999, max_iters=p.max_iters, rng=rng)
    inl = np.asarray(fit.inliers, bool)
    if poses is not None:
        inl = _reprojection_inliers(fit.H, src, dst, p.ransac_threshold, poses, p)
    return fit.H, inl


def _fit_affine_homography(src: np.ndarray, dst: np.ndarray, ref: Reference, scene_size: tuple[int, int],
                           p: LogoVerifyParams, rng: np.random.Generator,
                           poses: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    # the affine RANSAC picks the consistent matches; a homography refitted on them replaces the affine map when it
    # is plausible and explains about as many of all the matches (within 10 %: the affine inlier band of a
    # perspective view is not the homography's, and a few matches near the band edge may swap sides)
    sp, dp = poses if poses is not None else (None, None)
    A, inl = affine_ransac(src, dst, p.ransac_threshold, p.affine_samples, rng, sp, dp, p.angle_tolerance,
                           p.scale_tolerance)
    if inl.sum() < 5:
        return A, inl
    try:
        fit = find_homography(src[inl], dst[inl], threshold=p.ransac_threshold, confidence=0.999,
                              max_iters=p.max_iters, rng=rng)
    except EstimationError:
        return A, inl
    h_inl = _reprojection_inliers(fit.H, src, dst, p.ransac_threshold, poses, p)
    if h_inl.sum() >= max(0.9 * inl.sum(), 5) and not shape_problem(fit.H, ref.outline, scene_size, p):
        return fit.H, h_inl
    return A, inl


#: ``logo.verify.model`` -> fitter(src, dst, reference, scene_size, params, rng, poses) -> (H (3, 3), inliers (N,) bool)
MODELS = {"homography": _fit_homography, "affine_homography": _fit_affine_homography}


def _scene_counts(matches: Matches) -> dict[int, int]:
    """Reference index -> distinct scene keypoints matched to it (one matched to several keypoints counts once)."""
    return {int(r): len(np.unique(matches.scene_idx[matches.ref == r])) for r in np.unique(matches.ref)}


def tested_references(matches: Matches, params: LogoVerifyParams | None = None) -> int:
    """References that :func:`verify` tests in a scene: those with at least ``min_matches`` matched scene
    keypoints."""
    p = params or LogoVerifyParams()
    return sum(c >= p.min_matches for c in _scene_counts(matches).values())


def verify(gallery: Gallery, matches: Matches, scene: Features | np.ndarray, scene_size: tuple[int, int],
           params: LogoVerifyParams | None = None, rng=None, tests: int | None = None) -> list[Hypothesis]:
    """Fit and check one model per gallery reference that has at least ``min_matches`` tentatively matched scene
    keypoints.

    The fitter is ``params.model`` for float descriptors (SIFT) and ``params.binary_model`` for the binary ones (see
    :data:`MODELS`): binary detectors put their keypoints in dense clusters on texture, where 3-point affine samples
    find chance fits more easily than 4-point homographies. An inlier must land within ``ransac_threshold`` of its
    predicted position and, when the scene's keypoint orientations and sizes are given, agree with the model's
    predicted orientation (``angle_tolerance``) and scale (``scale_tolerance``); the score then counts that
    agreement as evidence (:func:`significance`). When the best RANSAC fit fails the checks, its inliers are set
    aside and the remaining matches are fitted again (at most ``max_models`` fits per reference); the number of fits
    enters the score's multiple-test count.

    Parameters
    ----------
    gallery : Gallery
    matches : Matches
        From :func:`match_scene`.
    scene : Features or (N, 2) float
        Scene keypoints; with bare positions (pixels) inliers are judged by position only.
    scene_size : (width, height)
        Scene size in pixels.
    params : LogoVerifyParams, optional
    rng : None, int or Generator
        Seeds RANSAC.
    tests : int, optional
        References tested in this scene by every method weighed in one decision (:func:`tested_references` of each
        gallery, summed: the fused method); the score's multiple-test count. Default: this gallery's alone.

    Returns
    -------
    list of Hypothesis
        One per tested reference, sorted by score (best first).
    """
    p = params or LogoVerifyParams()
    rng = np.random.default_rng(rng)
    use_pose = isinstance(scene, Features) and (p.angle_tolerance < 180.0 or p.scale_tolerance < 16.0)
    scene_xy = np.asarray(scene.xy if isinstance(scene, Features) else scene, np.float64)
    scene_pose = (np.c_[scene.angle, np.log(np.maximum(scene.size, 1e-6))].astype(np.float64) if use_pose
                  else None)
    pose_prob = pose_probability(p.angle_tolerance, p.scale_tolerance) if use_pose else 1.0
    counts = _scene_counts(matches)
    tested = [r for r, c in counts.items() if c >= p.min_matches]
    if tests is None:
        tests = len(tested)
    elif tests < len(tested):
        raise ValueError(f"`tests` must count at least the {len(tested)} references tested here, got {tests}")
    fitter = MODELS[p.binary_model if gallery.binary else p.model]
    out = []
    for r in tested:
        ref = gallery.references[r]
        sel = matches.ref == r
        g_idx, s_idx = matches.gallery_idx[sel], matches.scene_idx[sel]
        kf = ref.features
        src = kf.xy[g_idx].astype(np.float64)
        src_pose = (np.c_[kf.angle[g_idx], np.log(np.maximum(kf.size[g_idx], 1e-6))].astype(np.float64) if use_pose
                    else None)
        dst = scene_xy[s_idx]
        dst_pose = scene_pose[s_idx] if use_pose else None
        brand = ref.brand
        none = np.zeros((0, 2), np.int64)
        hyp, left = None, np.ones(len(src), bool)
        # sequential RANSAC: an implausible best fit (a chance fit, or a fold made by the twin matches of a
        # symmetric mark) gives its inliers up and the rest is fitted again, up to `max_models` times
        for attempt in range(1, p.max_models + 1):
            if left.sum() < p.min_matches:
                break
            try:
                H, fit_inl = fitter(src[left], dst[left], ref, scene_size, p, rng,
                                    (src_pose[left], dst_pose[left]) if use_pose else None)
            except EstimationError as exc:
                if hyp is None:
                    hyp = Hypothesis(brand, r, counts[r], 0, -np.inf, None, None, none, f"no homography: {exc}",
                                     np.zeros((0, 2)), gallery.detector)
                break
            inl = np.zeros(len(src), bool)
            inl[np.flatnonzero(left)[fit_inl]] = True
            cand = _check(brand, r, ref, H, inl, src, dst, g_idx, s_idx, scene_size,
                          tests * attempt, p, pose_prob, gallery.detector)
            if hyp is None or (hyp.reason and not cand.reason):
                hyp = cand
            if not cand.reason:
                break
            left &= ~inl
        out.append(hyp)
    out.sort(key=lambda h: (h.score, h.inliers), reverse=True)
    return out
