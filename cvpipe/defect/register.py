"""Registration of a probe to the golden reference, and the warp of the probe onto the reference grid.

Keypoint matches give a RANSAC homography (:func:`cvpipe.homography.find_homography`) that ECC refines on a small
pyramid; when the keypoints cannot support one, :func:`register_direct` starts ECC from a phase-correlation shift
instead. Every homography here maps reference pixels to probe pixels (x = column, y = row).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import EstimationError, InputError
from ..features import Features, detect_with
from ..homography import find_homography
from ..matching import match_with
from ..params import DefectFeaturesParams, DefectRegisterParams, FeaturesParams, MatchParams
from ._util import check_gray, check_homography


@dataclass(frozen=True)
class ProbeRegistration:
    """Result of :func:`register_probe`.

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


def register_probe(reference: np.ndarray, probe: np.ndarray, params: DefectRegisterParams | None = None, *,
                   reference_features: Features | None = None, probe_features: Features | None = None,
                   matches: np.ndarray | None = None, features: FeaturesParams | None = None,
                   matching: MatchParams | None = None) -> ProbeRegistration:
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
    ProbeRegistration

    Raises
    ------
    InputError
        Bad image arrays, or sizes so different (more than ``max_scale_change`` per side) that the probe cannot
        show the same part at the same scale.
    EstimationError
        ProbeRegistration failed: too few keypoints (blank probe), too few consistent matches (unrelated scene), a
        homography that shrinks/magnifies beyond ``max_scale_change`` or barely overlaps, or an alignment whose
        correlation stays below ``min_correlation``. The message says which and what to tune.

    Examples
    --------
    >>> from cvpipe.metrics import corner_error
    >>> from cvpipe.samples import make_defect
    >>> board = make_defect(np.random.default_rng(0), n_faulty=2, n_perfect=1, size=240)  # probe_02 is perfect
    >>> reg = register_probe(board.images["reference.png"], board.images["probes/probe_02.png"])
    >>> true_H = board.truth["probes"][2]["H"]
    >>> reg.method, bool(corner_error(reg.H, true_H, 240, 240) < 1.0)  # px, at the reference's corners
    ('features', True)
    """
    p = params or DefectRegisterParams()
    fp, mp = features or DefectFeaturesParams(), matching or MatchParams()
    reference, probe = check_gray("reference", reference), check_gray("probe", probe)
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
           n_matches: int, n_in: int, why: str) -> ProbeRegistration:
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
    return ProbeRegistration(H, H0, n_matches, n_in, rho, method)


def _reason(exc: Exception) -> str:
    """The message of a registration error without its leading "registration failed: "."""
    return str(exc).removeprefix("registration failed: ")


def _feature_homography(reference, probe, p, fp, mp, fr, fq, matches) -> tuple[np.ndarray, int, int]:
    """RANSAC homography from keypoint matches; EstimationError (saying why) when they do not support one."""
    fr = fr if fr is not None else detect_with(reference, fp)
    fq = fq if fq is not None else detect_with(probe, fp)
    if len(fr) < p.min_inliers or len(fq) < p.min_inliers:
        raise EstimationError(f"registration failed: only {len(fr)} reference and {len(fq)} probe keypoints "
                              f"(need {p.min_inliers}); is the probe blank or featureless?")
    if matches is None:
        matches = match_with(fr, fq, mp)
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

    Examples
    --------
    >>> import numpy as np
    >>> probe = np.tile(np.arange(20, dtype=np.uint8) * 10, (20, 1))  # grey level = 10 x column
    >>> H = np.array([[1.0, 0, 2], [0, 1, 0], [0, 0, 1]])  # reference (x, y) -> probe (x + 2, y)
    >>> warp_to_reference(probe, H, (20, 20))[0, [0, 1, 17, 18]].tolist()
    [20, 30, 190, 0]
    """
    H = check_homography(H)
    rh, rw = reference_shape[:2]
    return cv2.warpPerspective(probe, H, (rw, rh), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def register_direct(reference: np.ndarray, probe: np.ndarray, params: DefectRegisterParams | None = None, *,
                    matches: int = 0, inliers: int = 0) -> ProbeRegistration:
    """The direct registration: ECC started from a phase-correlation shift, without keypoints.

    :func:`register_probe` falls back to it when the keypoints fail; :func:`inspect` also asks for it when a keypoint
    registration makes the probe faulty (see :func:`choose`).

    Parameters
    ----------
    reference, probe : (H, W) or (H, W, 3) uint8
    params : DefectRegisterParams, optional
    matches, inliers : int
        The keypoint counts to carry into the result (those of the registration it is an alternative to).

    Returns
    -------
    ProbeRegistration
        With ``method == "direct"``.

    Raises
    ------
    EstimationError
        ECC did not converge or its result fails the geometry or correlation checks of :func:`register_probe`.

    Examples
    --------
    >>> from cvpipe.samples import make_defect
    >>> board = make_defect(np.random.default_rng(0), n_faulty=2, n_perfect=1, size=240).images
    >>> reg = register_direct(board["reference.png"], board["probes/probe_02.png"])
    >>> reg.method, bool(reg.correlation > 0.9)  # ECC's correlation of the aligned images
    ('direct', True)
    """
    p = params or DefectRegisterParams()
    ref, prb = check_gray("reference", reference), check_gray("probe", probe)
    return _align(ref, prb, _translation_init(ref, prb), "direct", p, matches, inliers, "")


def wants_alternative(registration: ProbeRegistration, params: DefectRegisterParams | None = None) -> bool:
    """Whether a direct registration may replace ``registration`` (it came from keypoints, ``direct_fallback`` on).

    On sparse boards the keypoints can lock ECC onto an alignment that is right where most of the copper is and off
    elsewhere; before such a probe is called faulty, the direct alignment is compared as well (:func:`choose`).

    Examples
    --------
    >>> import numpy as np
    >>> reg = ProbeRegistration(np.eye(3), np.eye(3), matches=50, inliers=40, correlation=0.99, method="features")
    >>> wants_alternative(reg)
    True
    """
    return registration.method == "features" and (params or DefectRegisterParams()).direct_fallback


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

    Examples
    --------
    >>> import numpy as np
    >>> probe = np.full((20, 20), 100, np.uint8)
    >>> warped, valid = warp_probe(probe, np.array([[1.0, 0, 2], [0, 1, 0], [0, 0, 1]]), (20, 20))
    >>> int(valid[0].sum())  # columns 18 and 19 of the reference fall outside the probe
    18
    """
    probe = np.asarray(probe)
    warped = warp_to_reference(probe, H, reference_shape)
    valid = warp_to_reference(np.full(probe.shape[:2], 255, np.uint8), H, reference_shape) == 255
    return warped, valid


def register_item(item: tuple, shared: tuple) -> dict:
    """Register one probe with its direct alternative and warp it: the per-probe work of the ``defect_register``
    stage, an item of :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    item : tuple
        ``(probe gray image, probe Features, (M,) match indices)``.
    shared : tuple
        ``(reference gray image, reference Features, DefectRegisterParams)``, sent once per worker.

    Returns
    -------
    dict
        ``probe_shape``, ``primary`` (:class:`ProbeRegistration`), ``alternative`` (one or None), ``alternative_error`` (str or
        None), ``arrays`` (``H``, ``warped``, ``valid`` and ``alt_*`` for the alternative) and ``seconds``
        (``register``, ``direct_alternative``: this item's wall times, for the stage's timings).

    Raises
    ------
    InputError, EstimationError
        As :func:`register_probe` (the stage drops the probe with the reason).

    Examples
    --------
    >>> from cvpipe.features import detect
    >>> from cvpipe.io import to_gray
    >>> from cvpipe.matching import match
    >>> from cvpipe.params import DefectRegisterParams
    >>> from cvpipe.samples import make_defect
    >>> board = make_defect(np.random.default_rng(0), n_faulty=2, n_perfect=1, size=240)
    >>> ref, prb = to_gray(board.images["reference.png"]), to_gray(board.images["probes/probe_02.png"])
    >>> fr, fq = detect(ref, "orb", 1000), detect(prb, "orb", 1000)
    >>> out = register_item((prb, fq, match(fr.descriptors, fq.descriptors, 0.8, False, fr.binary)),
    ...                     (ref, fr, DefectRegisterParams()))
    >>> out["primary"].method, out["arrays"]["warped"].shape == ref.shape
    ('features', True)
    """
    import time

    probe, features, matches = item
    reference, reference_features, p = shared
    t0 = time.perf_counter()
    reg = register_probe(reference, probe, p, reference_features=reference_features, probe_features=features,
                         matches=matches)
    seconds = {"register": time.perf_counter() - t0}
    warped, valid = warp_probe(probe, reg.H, reference.shape)
    out = {"probe_shape": probe.shape, "primary": reg, "alternative": None, "alternative_error": None,
           "seconds": seconds,
           "arrays": {"H": reg.H, "warped": warped, "valid": valid}}
    if wants_alternative(reg, p):
        t0 = time.perf_counter()
        try:
            alt = register_direct(reference, probe, p, matches=reg.matches, inliers=reg.inliers)
        except EstimationError as exc:
            out["alternative_error"] = str(exc)
        else:
            out["alternative"] = alt
            warped, valid = warp_probe(probe, alt.H, reference.shape)
            out["arrays"].update(alt_H=alt.H, alt_warped=warped, alt_valid=valid)
        seconds["direct_alternative"] = time.perf_counter() - t0
    return out
