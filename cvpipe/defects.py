"""Defect inspection against a golden reference.

The chain is: register the probe to the reference (keypoint matches, our RANSAC homography, then ECC refinement on
a small pyramid), warp the probe into the reference frame, fit gain and bias between the two on their overlap, take a
difference that tolerates the last pixel or so of misregistration (the probe is compared against the min/max of the
reference over a small disc and vice versa), threshold it with hysteresis, clean it with morphology and turn the
connected components into regions, in reference and probe pixels. A probe with at least one region is ``faulty``.
Each step is a function of its own (:func:`register`, :func:`register_direct`, :func:`warp_probe`,
:func:`difference`, :func:`find_regions`, :func:`choose`): :func:`inspect` runs them all, each DVC stage one.

Every homography here maps reference pixels to probe pixels (x = column, y = row).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from .errors import EstimationError, InputError
from .features import Features, detect
from .homography import find_homography
from .matching import match
from .params import (DefectDiffParams, DefectFeaturesParams, DefectRegionParams, DefectRegisterParams, FeaturesParams,
                     MatchParams)

VERDICTS = ("perfect", "faulty")


@dataclass(frozen=True)
class InspectParams:
    """Every parameter of :func:`inspect`, one frozen dataclass per pipeline stage."""

    features: FeaturesParams = field(default_factory=DefectFeaturesParams)
    match: MatchParams = field(default_factory=MatchParams)
    register: DefectRegisterParams = field(default_factory=DefectRegisterParams)
    diff: DefectDiffParams = field(default_factory=DefectDiffParams)
    regions: DefectRegionParams = field(default_factory=DefectRegionParams)


def load_inspect_params(path="params.yaml") -> InspectParams:
    """The ``defect.*`` sections of ``params.yaml`` as one :class:`InspectParams`."""
    from .params import load_section

    return InspectParams(load_section(DefectFeaturesParams, "defect.features", path),
                         load_section(MatchParams, "defect.match", path),
                         load_section(DefectRegisterParams, "defect.register", path),
                         load_section(DefectDiffParams, "defect.diff", path),
                         load_section(DefectRegionParams, "defect.regions", path))


@dataclass(frozen=True)
class Registration:
    """Result of :func:`register`.

    Attributes
    ----------
    H : (3, 3) float64
        Refined homography, reference pixels -> probe pixels, ``H[2, 2] == 1``.
    H_features : (3, 3) float64
        The RANSAC homography before ECC refinement.
    matches, inliers : int
        Putative matches and RANSAC inliers.
    correlation : float
        Zero-mean normalised correlation of the aligned images (ECC's criterion), in [-1, 1]; NaN when ECC is off.
    method : {"features", "direct"}
        "direct" when the keypoints could not support a homography and ECC started from a phase-correlation shift.
    """

    H: np.ndarray
    H_features: np.ndarray
    matches: int
    inliers: int
    correlation: float
    method: str = "features"


@dataclass(frozen=True)
class Difference:
    """Result of :func:`difference`.

    Attributes
    ----------
    diff : (H, W) float32
        Tolerant absolute difference in grey levels of the reference, 0 outside ``valid``.
    valid : (H, W) bool
        Reference pixels that the probe covers (minus a border margin).
    gain, bias : float
        Photometric model ``probe ~= gain * reference + bias`` fitted on the overlap.
    noise : float
        Robust standard deviation of the corrected residual, grey levels.
    contrast : float
        Dynamic range of the reference (99th - 1st percentile), grey levels.
    """

    diff: np.ndarray
    valid: np.ndarray
    gain: float
    bias: float
    noise: float
    contrast: float

    def to_arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Named arrays for ``io.save_npz``, each name prefixed by ``prefix``."""
        return {prefix + k: np.asarray(getattr(self, k)) for k in ("diff", "valid", "gain", "bias", "noise",
                                                                     "contrast")}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], prefix: str = "") -> "Difference":
        """Inverse of :meth:`to_arrays`."""
        return cls(np.asarray(arrays[prefix + "diff"], np.float32), np.asarray(arrays[prefix + "valid"], bool),
                   *(float(arrays[prefix + k]) for k in ("gain", "bias", "noise", "contrast")))

    def photometry(self) -> dict[str, float]:
        """The scalar fields (photometric fit, noise, contrast), for a JSON record."""
        return {k: getattr(self, k) for k in ("gain", "bias", "noise", "contrast")}


@dataclass(frozen=True)
class Inspection:
    """Result of :func:`find_regions` / :func:`inspect`.

    Attributes
    ----------
    verdict : {"perfect", "faulty"}
    score : float
        Evidence of the strongest region: the sum of its difference over pixels divided by the threshold, i.e. its
        area in "pixels at threshold contrast"; 0 when there is no region.
    regions : (K, 4) float64
        Boxes ``[x1, y1, x2, y2]`` in reference pixels (pixel-edge coordinates), strongest first.
    probe_regions : (K, 4) float64
        The same boxes mapped into probe pixels (axis-aligned bounds of the mapped corners) and padded by ``pad``.
    region_scores : (K,) float64
    threshold : float
        Low (extent) threshold used, grey levels.
    registration : Registration or None
    difference : Difference or None
    """

    verdict: str
    score: float
    regions: np.ndarray
    probe_regions: np.ndarray
    region_scores: np.ndarray
    threshold: float
    registration: Registration | None = None
    difference: Difference | None = None


# --------------------------------------------------------------------------------------------------- checks


def _check_gray(name: str, img: np.ndarray) -> np.ndarray:
    img = np.asarray(img)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if img.ndim != 2 or img.dtype != np.uint8:
        raise InputError(f"`{name}` must be a (H, W) or (H, W, 3) uint8 image, got shape {img.shape} "
                         f"dtype {img.dtype}")
    if min(img.shape) < 16:
        raise InputError(f"`{name}` must be at least 16x16 pixels, got {img.shape[1]}x{img.shape[0]}")
    return img


def _check_homography(H: np.ndarray) -> np.ndarray:
    H = np.asarray(H, np.float64)
    if H.shape != (3, 3) or not np.all(np.isfinite(H)) or abs(np.linalg.det(H)) < 1e-12:
        raise InputError(f"`H` must be a finite invertible 3x3 matrix, got {H.tolist()}")
    return H / H[2, 2]


def _scaled(H: np.ndarray, s: float) -> np.ndarray:
    """The homography ``H`` (full resolution) expressed for images scaled by ``s`` (pixel-edge convention)."""
    S = np.array([[s, 0, 0.5 * s - 0.5], [0, s, 0.5 * s - 0.5], [0, 0, 1.0]])
    out = S @ H @ np.linalg.inv(S)
    return out / out[2, 2]


def _local_scale(H: np.ndarray, x: float, y: float) -> float:
    """sqrt(|det J|) of ``H`` at (x, y): how much the homography magnifies areas there."""
    p = H @ np.array([x, y, 1.0])
    w = p[2]
    J = (H[:2, :2] * w - np.outer(p[:2], H[2, :2])) / (w * w)
    return float(np.sqrt(abs(np.linalg.det(J))))


# --------------------------------------------------------------------------------------------------- registration


def _ecc_refine(reference: np.ndarray, probe: np.ndarray, H: np.ndarray, p: DefectRegisterParams,
                levels: int) -> tuple[np.ndarray, float]:
    """ECC (``MOTION_HOMOGRAPHY``) coarse to fine over ``levels`` octaves ending at ``ecc_scale``.

    A coarse level that does not converge (too little structure left at that scale) is skipped; only a failure at
    the finest level is an error.
    """
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, p.ecc_iterations, p.ecc_eps)
    rho = float("nan")
    for level in range(levels - 1, -1, -1):
        s = p.ecc_scale * 0.5 ** level
        ref_l = cv2.resize(reference, None, fx=s, fy=s, interpolation=cv2.INTER_AREA) if s != 1 else reference
        prb_l = cv2.resize(probe, None, fx=s, fy=s, interpolation=cv2.INTER_AREA) if s != 1 else probe
        start = _scaled(H, s).astype(np.float32)
        try:
            rho, warp = cv2.findTransformECC(ref_l, prb_l, start.copy(), cv2.MOTION_HOMOGRAPHY, criteria, None, 3)
        except cv2.error as exc:
            if level > 0:
                continue
            warp = None
            for motion in (cv2.MOTION_AFFINE, cv2.MOTION_EUCLIDEAN):  # too little structure for 8 parameters
                affine = (start[:2] / start[2, 2]).astype(np.float32)
                if motion == cv2.MOTION_EUCLIDEAN:
                    u, _, vt = np.linalg.svd(affine[:, :2])
                    affine[:, :2] = u @ vt
                try:
                    rho, affine = cv2.findTransformECC(ref_l, prb_l, affine, motion, criteria, None, 3)
                except cv2.error:
                    continue
                warp = np.vstack([affine, [0, 0, 1]])
                break
            if warp is None:
                raise EstimationError(f"registration failed: ECC refinement did not converge at scale {s:g}; the "
                                      f"probe may not show the reference part, or lower `ecc_levels`") from exc
        H = _scaled(warp.astype(np.float64), 1.0 / s)
    return H, float(rho)


def register(reference: np.ndarray, probe: np.ndarray, params: DefectRegisterParams | None = None, *,
             reference_features: Features | None = None, probe_features: Features | None = None,
             matches: np.ndarray | None = None, features: FeaturesParams | None = None,
             matching: MatchParams | None = None) -> Registration:
    """Homography from reference pixels to probe pixels.

    Parameters
    ----------
    reference, probe : (H, W) or (H, W, 3) uint8
        Golden reference and probe images (sizes may differ).
    params : DefectRegisterParams, optional
    reference_features, probe_features : Features, optional
        Precomputed keypoints (e.g. the reference's, shared by many probes); detected with ``features`` if absent.
    matches : (M, 2) int, optional
        Precomputed index pairs ``[i_reference, i_probe]``; matched with ``matching`` if absent.

    Returns
    -------
    Registration

    Raises
    ------
    InputError
        Bad image arrays, or sizes so different (more than ``max_scale_change`` per side) that the probe cannot
        show the same part at the same scale.
    EstimationError
        Registration failed: too few keypoints (blank probe), too few consistent matches (unrelated scene), a
        homography that shrinks/magnifies beyond ``max_scale_change`` or barely overlaps, or an alignment whose
        correlation stays below ``min_correlation``. The message says which and what to tune.
    """
    p = params or DefectRegisterParams()
    fp, mp = features or DefectFeaturesParams(), matching or MatchParams()
    reference, probe = _check_gray("reference", reference), _check_gray("probe", probe)
    (rh, rw), (ph, pw) = reference.shape, probe.shape
    side_ratio = max(rh / ph, ph / rh, rw / pw, pw / rw)
    if side_ratio > p.max_scale_change:
        raise InputError(f"registration failed: probe is {pw}x{ph} but reference is {rw}x{rh}, sides differ by a "
                         f"factor {side_ratio:.2f} > `max_scale_change` = {p.max_scale_change:g}")
    if float(probe.std()) < 2.0:
        raise EstimationError(f"registration failed: the probe is blank (grey-level std {probe.std():.2f})")
    n_matches = n_in = 0
    try:
        H0, n_matches, n_in = _feature_homography(reference, probe, p, fp, mp, reference_features, probe_features,
                                                  matches)
        reg = _align(reference, probe, H0, "features", p, n_matches, n_in, "")
    except EstimationError as exc:
        if not p.direct_fallback:
            raise
        return _align(reference, probe, _translation_init(reference, probe), "direct", p, n_matches, n_in,
                      f"{exc}; then direct alignment (ECC from a phase-correlation shift): ")
    if p.direct_fallback and np.isfinite(reg.correlation) and reg.correlation < p.retry_correlation:
        # keypoints on repetitive layouts can agree on a wrong homography that ECC cannot leave: try the direct
        # start as well and keep whichever aligns better
        try:
            other = _align(reference, probe, _translation_init(reference, probe), "direct", p, n_matches, n_in, "")
        except EstimationError:
            return reg
        if other.correlation > reg.correlation:
            return other
    return reg


def _align(reference: np.ndarray, probe: np.ndarray, H0: np.ndarray, method: str, p: DefectRegisterParams,
           n_matches: int, n_in: int, why: str) -> Registration:
    """ECC refinement of ``H0`` and the checks on its result; ``why`` prefixes error messages."""
    extra = 1 if method == "direct" else 0  # the direct start is rougher: one more, coarser ECC level
    H, rho = H0, float("nan")
    if p.ecc_levels + extra > 0:  # always true on the direct path
        try:
            H, rho = _ecc_refine(reference, probe, H0, p, p.ecc_levels + extra)
        except EstimationError as exc:
            raise EstimationError(why + _reason(exc) if why else str(exc)) from exc
        if not np.all(np.isfinite(H)):
            raise EstimationError((why or "registration failed: ") + "ECC refinement diverged; lower `ecc_levels`")
    try:
        _check_geometry(H, reference.shape, probe.shape, p)
    except EstimationError as exc:
        raise EstimationError(why + _reason(exc) if why else str(exc)) from exc
    threshold = p.min_correlation if method == "features" else max(p.min_correlation, p.direct_min_correlation)
    if np.isfinite(rho) and rho < threshold:
        raise EstimationError(f"{why or 'registration failed: '}aligned images correlate at only {rho:.2f} "
                              f"(< {threshold:g}); is the probe the reference part?")
    return Registration(H, H0, n_matches, n_in, rho, method)


def _reason(exc: Exception) -> str:
    """The message of a registration error without its leading "registration failed: "."""
    return str(exc).removeprefix("registration failed: ")


def _feature_homography(reference, probe, p, fp, mp, fr, fq, matches) -> tuple[np.ndarray, int, int]:
    """RANSAC homography from keypoint matches; EstimationError (saying why) when they do not support one."""
    fr = fr if fr is not None else detect(reference, fp.detector, fp.max_features)
    fq = fq if fq is not None else detect(probe, fp.detector, fp.max_features)
    if len(fr) < p.min_inliers or len(fq) < p.min_inliers:
        raise EstimationError(f"registration failed: only {len(fr)} reference and {len(fq)} probe keypoints "
                              f"(need {p.min_inliers}); is the probe blank or featureless?")
    if matches is None:
        matches = match(fr.descriptors, fq.descriptors, mp.ratio, mp.cross_check, fr.binary)
    matches = np.asarray(matches, np.int64).reshape(-1, 2)
    if len(matches) < p.min_inliers:
        raise EstimationError(f"registration failed: only {len(matches)} descriptor matches (need "
                              f"{p.min_inliers}); the probe does not seem to show the reference part")
    src, dst = fr.xy[matches[:, 0]].astype(np.float64), fq.xy[matches[:, 1]].astype(np.float64)
    try:
        fit = find_homography(src, dst, threshold=p.ransac_threshold, rng=np.random.default_rng(p.seed))
    except (ZeroDivisionError, FloatingPointError, np.linalg.LinAlgError) as exc:
        # numerical failure inside the estimator on degenerate match sets: same meaning as its EstimationError
        raise EstimationError(f"registration failed: the homography estimate from {len(matches)} matches broke "
                              f"down numerically ({type(exc).__name__})") from exc
    except EstimationError as exc:  # e.g. a chance-level model (cvpipe.homography.check_significant)
        raise EstimationError(f"registration failed: {exc}") from exc
    n_in = int(np.count_nonzero(fit.inliers))
    if n_in < p.min_inliers or n_in < p.min_inlier_ratio * len(matches):
        raise EstimationError(
            f"registration failed: only {n_in} of {len(matches)} matches agree on one homography (need "
            f"{p.min_inliers} and {p.min_inlier_ratio:.0%}); the probe does not seem to show the reference part")
    H0 = fit.H / fit.H[2, 2]
    _check_geometry(H0, reference.shape, probe.shape, p)
    return H0, len(matches), n_in


def _translation_init(reference: np.ndarray, probe: np.ndarray, scale: float = 0.25) -> np.ndarray:
    """A pure translation (reference -> probe) from phase correlation of quarter-resolution images."""
    r = cv2.resize(reference, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA).astype(np.float32)
    q = cv2.resize(probe, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA).astype(np.float32)
    h, w = max(r.shape[0], q.shape[0]), max(r.shape[1], q.shape[1])
    r = cv2.copyMakeBorder(r, 0, h - r.shape[0], 0, w - r.shape[1], cv2.BORDER_REPLICATE)
    q = cv2.copyMakeBorder(q, 0, h - q.shape[0], 0, w - q.shape[1], cv2.BORDER_REPLICATE)
    win = cv2.createHanningWindow((w, h), cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(r, q, win)
    return np.array([[1.0, 0, dx / scale], [0, 1.0, dy / scale], [0, 0, 1.0]])


def _check_geometry(H: np.ndarray, ref_shape: tuple, probe_shape: tuple, p: DefectRegisterParams) -> None:
    rh, rw = ref_shape
    scale = _local_scale(H, (rw - 1) / 2, (rh - 1) / 2)
    if not 1 / p.max_scale_change <= scale <= p.max_scale_change:
        raise EstimationError(f"registration failed: the homography scales the reference by {scale:.2f} "
                              f"(allowed 1/{p.max_scale_change:g} .. {p.max_scale_change:g}); matches are wrong")
    overlap = float(_coverage(H, ref_shape, probe_shape, 0, step=8).mean())
    if overlap < p.min_overlap:
        raise EstimationError(f"registration failed: the probe covers only {overlap:.0%} of the reference "
                              f"(< `min_overlap` = {p.min_overlap:.0%})")


def _coverage(H: np.ndarray, ref_shape: tuple, probe_shape: tuple, margin: float, step: int = 1) -> np.ndarray:
    """Bool grid over reference pixels (every ``step``-th) that ``H`` maps inside the probe, ``margin`` px in."""
    rh, rw = ref_shape
    ph, pw = probe_shape
    ys, xs = np.mgrid[0:rh:step, 0:rw:step].astype(np.float64)
    w = H[2, 0] * xs + H[2, 1] * ys + H[2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (H[0, 0] * xs + H[0, 1] * ys + H[0, 2]) / w
        v = (H[1, 0] * xs + H[1, 1] * ys + H[1, 2]) / w
    return (w > 0) & (u >= margin) & (u <= pw - 1 - margin) & (v >= margin) & (v <= ph - 1 - margin)


def warp_to_reference(probe: np.ndarray, H: np.ndarray, reference_shape: tuple[int, int]) -> np.ndarray:
    """Resample ``probe`` on the reference pixel grid: ``out(x) = probe(H x)``, bilinear, 0 outside.

    Parameters
    ----------
    probe : (h, w) or (h, w, 3) uint8
    H : (3, 3)
        Reference -> probe.
    reference_shape : (H, W)
    """
    H = _check_homography(H)
    rh, rw = reference_shape[:2]
    return cv2.warpPerspective(probe, H, (rw, rh), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0)


# --------------------------------------------------------------------------------------------------- difference


def _disc(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def fit_gain_bias(reference: np.ndarray, warped: np.ndarray, valid: np.ndarray, trim: float = 3.0,
                  iterations: int = 4, max_samples: int = 40_000) -> tuple[float, float, float]:
    """Robust fit of ``warped ~= gain * reference + bias`` over ``valid`` pixels.

    Least squares repeated on the pixels whose residual lies within ``trim`` robust standard deviations (MAD), so
    defects and misregistered edges do not pull the fit. At most about ``max_samples`` pixels on a regular grid
    are used.

    Parameters
    ----------
    reference, warped : (H, W) array
        Grey levels.
    valid : (H, W) bool

    Returns
    -------
    gain, bias, sigma : float
        ``sigma`` is the robust residual standard deviation in grey levels (plus 0.5 for quantisation).
    """
    step = max(1, int(np.sqrt(valid.size / max_samples)))
    v = valid[::step, ::step]
    r = reference[::step, ::step][v].astype(np.float64)
    w = warped[::step, ::step][v].astype(np.float64)
    if len(r) < 100:
        raise EstimationError(f"registration failed: only {int(valid.sum())} overlapping pixels to compare")
    keep = np.ones(len(r), bool)
    gain, bias, sigma = 1.0, 0.0, 0.0
    for _ in range(iterations):
        rk, wk = r[keep], w[keep]
        var = rk.var()
        if var < 1e-6:
            raise EstimationError("the reference is flat over the overlap: nothing to compare")
        gain = float(((rk - rk.mean()) * (wk - wk.mean())).mean() / var)
        bias = float(wk.mean() - gain * rk.mean())
        res = w - (gain * r + bias)
        sigma = float(1.4826 * np.median(np.abs(res - np.median(res)))) + 0.5
        keep = np.abs(res) <= trim * sigma
        if keep.sum() < 100:
            break
    if gain < 0.2:
        raise EstimationError(f"registration failed: the aligned probe has gain {gain:.2f} against the reference "
                              f"(inverted or washed-out image?)")
    return gain, bias, sigma


def difference(reference: np.ndarray, warped: np.ndarray, valid: np.ndarray,
               params: DefectDiffParams | None = None) -> Difference:
    """Misregistration-tolerant difference between the reference and the probe warped onto it.

    The probe is first corrected by the fitted gain and bias. A pixel differs by how far the probe lies outside
    the [min, max] of the reference over a disc of ``tolerance_radius``, or the reference outside the probe's
    [min, max] over that disc, whichever is larger: a shift of up to the radius produces no difference, while
    extra or missing material of any width does.

    Parameters
    ----------
    reference : (H, W) uint8
    warped : (H, W) uint8
        Probe resampled on the reference grid (:func:`warp_to_reference`).
    valid : (H, W) bool
        Reference pixels covered by the probe.
    params : DefectDiffParams, optional
    """
    p = params or DefectDiffParams()
    reference, warped = _check_gray("reference", reference), _check_gray("warped", warped)
    valid = np.asarray(valid, bool)
    if reference.shape != warped.shape or valid.shape != reference.shape:
        raise InputError(f"`reference`, `warped` and `valid` must have one shape, got {reference.shape}, "
                         f"{warped.shape}, {valid.shape}")
    if p.border_margin > 0:  # also away from the reference's own frame: scans are often ragged at their edges
        valid = cv2.erode(valid.astype(np.uint8), _disc(p.border_margin), borderType=cv2.BORDER_CONSTANT,
                          borderValue=0).astype(bool)
    ref = reference.astype(np.float32)
    prb = warped.astype(np.float32)
    if p.smooth_sigma > 0:
        ref = cv2.GaussianBlur(ref, (0, 0), p.smooth_sigma)
        prb = cv2.GaussianBlur(prb, (0, 0), p.smooth_sigma)
    gain, bias, sigma = fit_gain_bias(ref, prb, valid, p.fit_trim)
    prb = (prb - bias) / gain
    if p.tolerance_radius > 0:
        k = _disc(p.tolerance_radius)
        ref_lo, ref_hi = cv2.erode(ref, k), cv2.dilate(ref, k)
        prb_lo, prb_hi = cv2.erode(prb, k), cv2.dilate(prb, k)
        d = np.maximum(np.maximum(prb - ref_hi, ref_lo - prb), np.maximum(ref - prb_hi, prb_lo - ref))
    else:
        d = np.abs(prb - ref)
    d = np.maximum(d, 0.0)
    d[~valid] = 0.0
    lo, hi = np.percentile(ref[valid][::7], [1, 99])
    return Difference(d.astype(np.float32), valid, gain, bias, sigma / gain, float(hi - lo))


# --------------------------------------------------------------------------------------------------- regions


def map_boxes(boxes: np.ndarray, H: np.ndarray) -> np.ndarray:
    """Axis-aligned bounds of boxes ``[x1, y1, x2, y2]`` (K, 4) after mapping their corners by ``H``."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    if len(boxes) == 0:
        return boxes.copy()
    H = _check_homography(H)
    x1, y1, x2, y2 = boxes.T
    corners = np.stack([np.stack([x1, y1], -1), np.stack([x2, y1], -1), np.stack([x2, y2], -1),
                        np.stack([x1, y2], -1)], 1)  # (K, 4, 2)
    pts = np.concatenate([corners, np.ones(corners.shape[:2] + (1,))], -1) @ H.T
    xy = pts[..., :2] / pts[..., 2:]
    return np.concatenate([xy.min(1), xy.max(1)], 1)


def merge_boxes(boxes: np.ndarray, scores: np.ndarray, distance: float) -> tuple[np.ndarray, np.ndarray]:
    """Merge boxes closer than ``distance`` pixels (gap along both axes) into their union, summing the scores.

    Parameters
    ----------
    boxes : (K, 4) float
        ``[x1, y1, x2, y2]``.
    scores : (K,) float
    distance : float
        Largest gap, in pixels, between two boxes that are merged; 0 merges only overlapping or touching boxes,
        a negative value merges nothing.
    """
    boxes, scores = np.array(boxes, np.float64).reshape(-1, 4), np.array(scores, np.float64).reshape(-1)
    if distance < 0:
        return boxes, scores
    merged = True
    while merged and len(boxes) > 1:
        merged = False
        for i in range(len(boxes)):
            gap_x = np.maximum(boxes[:, 0], boxes[i, 0]) - np.minimum(boxes[:, 2], boxes[i, 2])
            gap_y = np.maximum(boxes[:, 1], boxes[i, 1]) - np.minimum(boxes[:, 3], boxes[i, 3])
            near = (gap_x <= distance) & (gap_y <= distance)
            near[i] = False
            if near.any():
                group = near.copy()
                group[i] = True
                union = np.r_[boxes[group, :2].min(0), boxes[group, 2:].max(0)]
                boxes = np.vstack([boxes[~group], union])
                scores = np.r_[scores[~group], scores[group].sum()]
                merged = True
                break
    return boxes, scores


def find_regions(diff: Difference, H: np.ndarray, probe_shape: tuple[int, int],
                 params: DefectRegionParams | None = None) -> Inspection:
    """Threshold the difference, clean it, and turn connected components into defect regions and a verdict.

    The extent threshold is ``threshold`` times the reference contrast, raised to ``noise_factor`` noise standard
    deviations when the probe is noisier; a component is kept when some pixel in it reaches ``seed_threshold``
    times the contrast (hysteresis) and it has at least ``min_area`` pixels after opening and closing.

    Parameters
    ----------
    diff : Difference
    H : (3, 3)
        Reference -> probe, to map the regions into the probe.
    probe_shape : (h, w)
        Probe size; mapped boxes are clipped to it.
    params : DefectRegionParams, optional
    """
    p = params or DefectRegionParams()
    H = _check_homography(H)
    contrast = max(diff.contrast, 1.0)
    t_low = max(p.threshold * contrast, p.noise_factor * diff.noise)
    t_high = max(p.seed_threshold * contrast, t_low)
    mask = (diff.diff > t_low).astype(np.uint8)
    if p.open_radius > 0:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, _disc(p.open_radius))
    if p.close_radius > 0:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, _disc(p.close_radius))
    mask &= diff.valid.astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    boxes, scores = [], []
    if n > 1:
        on = mask.astype(bool)
        mass = np.bincount(labels[on], weights=diff.diff[on], minlength=n)
        seeded = np.zeros(n, bool)
        core = (diff.diff >= t_high).astype(np.uint8)
        if p.seed_radius > 0:  # misregistered edges leave thin slivers; real defects have a solid core
            core = cv2.morphologyEx(core, cv2.MORPH_OPEN, _disc(p.seed_radius))
        seeded[labels[on & core.astype(bool)]] = True
        for i in range(1, n):
            x, y, w, h, area = stats[i]
            if area < p.min_area or not seeded[i]:
                continue
            boxes.append([x, y, x + w, y + h])
            scores.append(mass[i] / t_low)
    boxes_a, scores_a = merge_boxes(np.array(boxes, np.float64).reshape(-1, 4), np.array(scores, np.float64),
                                    p.merge_distance)
    order = np.argsort(scores_a, kind="stable")[::-1]
    boxes_a, scores_a = boxes_a[order], scores_a[order]
    probe_boxes = map_boxes(boxes_a, H)
    if len(probe_boxes):
        ph, pw = probe_shape[:2]
        probe_boxes[:, :2] -= p.pad
        probe_boxes[:, 2:] += p.pad
        probe_boxes[:, [0, 2]] = probe_boxes[:, [0, 2]].clip(0, pw)
        probe_boxes[:, [1, 3]] = probe_boxes[:, [1, 3]].clip(0, ph)
    score = float(scores_a[0]) if len(scores_a) else 0.0
    return Inspection("faulty" if len(boxes_a) else "perfect", score, boxes_a, probe_boxes, scores_a, float(t_low),
                      None, diff)


# --------------------------------------------------------------------------------------------------- all at once


def register_direct(reference: np.ndarray, probe: np.ndarray, params: DefectRegisterParams | None = None, *,
                    matches: int = 0, inliers: int = 0) -> Registration:
    """The direct registration: ECC started from a phase-correlation shift, without keypoints.

    :func:`register` falls back to it when the keypoints fail; :func:`inspect` also asks for it when a keypoint
    registration makes the probe faulty (see :func:`choose`).

    Parameters
    ----------
    reference, probe : (H, W) or (H, W, 3) uint8
    params : DefectRegisterParams, optional
    matches, inliers : int
        The keypoint counts to carry into the result (those of the registration it is an alternative to).

    Returns
    -------
    Registration
        With ``method == "direct"``.

    Raises
    ------
    EstimationError
        ECC did not converge or its result fails the geometry or correlation checks of :func:`register`.
    """
    p = params or DefectRegisterParams()
    ref, prb = _check_gray("reference", reference), _check_gray("probe", probe)
    return _align(ref, prb, _translation_init(ref, prb), "direct", p, matches, inliers, "")


def wants_alternative(registration: Registration, params: DefectRegisterParams | None = None) -> bool:
    """Whether a direct registration may replace ``registration`` (it came from keypoints, ``direct_fallback`` on).

    On sparse boards the keypoints can lock ECC onto an alignment that is right where most of the copper is and off
    elsewhere; before such a probe is called faulty, the direct alignment is compared as well (:func:`choose`).
    """
    return registration.method == "features" and (params or DefectRegisterParams()).direct_fallback


def choose(first: Inspection, alternative: Inspection | None) -> Inspection:
    """The inspection to keep: ``first``, unless it is faulty and the ``alternative`` leaves a lower score.

    Parameters
    ----------
    first : Inspection
        The comparison after :func:`register`'s registration.
    alternative : Inspection or None
        The comparison after :func:`register_direct`'s registration, when :func:`wants_alternative` and it
        succeeded.
    """
    if alternative is not None and first.verdict == "faulty" and alternative.score < first.score:
        return alternative
    return first


def warp_probe(probe: np.ndarray, H: np.ndarray, reference_shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The probe on the reference grid and the reference pixels it covers.

    Parameters
    ----------
    probe : (h, w) uint8
    H : (3, 3)
        Reference -> probe.
    reference_shape : (H, W)

    Returns
    -------
    warped : (H, W) uint8
        :func:`warp_to_reference` of the probe.
    valid : (H, W) bool
        Reference pixels whose whole bilinear footprint lies inside the probe.
    """
    probe = np.asarray(probe)
    warped = warp_to_reference(probe, H, reference_shape)
    valid = warp_to_reference(np.full(probe.shape[:2], 255, np.uint8), H, reference_shape) == 255
    return warped, valid


def compare(reference: np.ndarray, warped: np.ndarray, valid: np.ndarray, registration: Registration,
            probe_shape: tuple[int, int], diff: DefectDiffParams | None = None,
            regions: DefectRegionParams | None = None) -> Inspection:
    """:func:`difference` then :func:`find_regions` for one registration: the verdict it leads to.

    Parameters
    ----------
    reference : (H, W) uint8
    warped, valid : (H, W)
        :func:`warp_probe` of the probe by ``registration.H``.
    registration : Registration
    probe_shape : (h, w)
    diff, regions : DefectDiffParams, DefectRegionParams, optional

    Returns
    -------
    Inspection
        With ``registration`` and ``difference`` filled in.
    """
    d = difference(reference, warped, valid, diff)
    return replace(find_regions(d, registration.H, probe_shape, regions), registration=registration)


def inspect(reference: np.ndarray, probe: np.ndarray, params: InspectParams | None = None, *,
            reference_features: Features | None = None) -> Inspection:
    """Register ``probe`` to ``reference``, compare them and judge the probe.

    The steps, each a function of its own (the DVC stages run them one by one): :func:`register`,
    :func:`warp_probe`, :func:`compare` (:func:`difference` and :func:`find_regions`), and for a faulty probe
    registered by keypoints the same with :func:`register_direct`, keeping the result :func:`choose` picks.

    Parameters
    ----------
    reference, probe : (H, W) or (H, W, 3) uint8
    params : InspectParams, optional
    reference_features : Features, optional
        The reference's keypoints when inspecting many probes against one reference.

    Returns
    -------
    Inspection
        With ``registration`` and ``difference`` filled in.

    Raises
    ------
    InputError, EstimationError
        When the probe cannot be registered (see :func:`register`); no verdict is given then.
    """
    p = params or InspectParams()
    ref, prb = _check_gray("reference", reference), _check_gray("probe", probe)
    reg = register(ref, prb, p.register, reference_features=reference_features, features=p.features,
                   matching=p.match)
    result = compare(ref, *warp_probe(prb, reg.H, ref.shape), reg, prb.shape, p.diff, p.regions)
    if result.verdict != "faulty" or not wants_alternative(reg, p.register):
        return result
    try:
        alt = register_direct(ref, prb, p.register, matches=reg.matches, inliers=reg.inliers)
        other = compare(ref, *warp_probe(prb, alt.H, ref.shape), alt, prb.shape, p.diff, p.regions)
    except EstimationError:  # the alternative is only a second opinion: the first result stands
        return result
    return choose(result, other)


# --------------------------------------------------------------------------------------------------- pictures


def draw_regions(image: np.ndarray, regions: np.ndarray, truth: np.ndarray | None = None,
                 thickness: int = 2) -> np.ndarray:
    """A BGR copy of ``image`` with ``regions`` outlined in red and optional ``truth`` boxes in green.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) uint8
    regions, truth : (K, 4)
        Boxes ``[x1, y1, x2, y2]`` in the image's pixels.
    """
    img = np.asarray(image)
    out = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img[..., :3].copy()
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
    """
    scale = 255.0 / max(2.0 * float(threshold), 1e-6)
    return cv2.applyColorMap(np.clip(np.asarray(diff, np.float32) * scale, 0, 255).astype(np.uint8),
                             cv2.COLORMAP_INFERNO)


# --------------------------------------------------------------------------------------------------- evaluation


def evaluate(results: list[dict], truth: list[dict], iou: float = 0.33) -> dict:
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
    """
    from .metrics import DetectionCounts, match_boxes

    by_name = {Path(r["probe"]).name: r for r in results}
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
