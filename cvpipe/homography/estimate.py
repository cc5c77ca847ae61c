"""Robust homography estimation: :func:`find_homography` (LO-RANSAC + Levenberg-Marquardt), the OpenCV baselines
behind the same interface, the method registry :func:`estimate`, and the a-contrario test against chance
(:func:`check_significant`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import EstimationError, InputError, check_int
from ..geometry import as_points
from ..params import HomographyEstimateParams, section_or_default
from ..robust import log10_nfa, new_state, run
from ._chance import bounding_box as _bounding_box, chance_hits as _chance_hits, densest_cell as _densest_cell
from ._chance import distinct_rows as _distinct_rows
from ._dlt import finalize as _finalize, normalize, sq_errors as _sq_errors
from ._ransac import collapsed as _collapsed, ransac_chunk as _ransac_chunk, rows_in_order as _rows_in_order
from .dlt import _ALL_COLLINEAR_EPS, _check_pair, _unit_h22

#: the ``homography.estimate`` defaults: the one declaration of the keyword defaults of the estimators here
_EST = HomographyEstimateParams()
#: default iteration cap of :func:`find_homography` (10 000: enough for ~85 % outliers at confidence 0.999)
DEFAULT_MAX_ITERS = _EST.max_iters
#: initial SPRT guesses: inlier ratio of a good model and consistent fraction of a bad one (both re-estimated)
_SPRT_EPS0 = 0.05
_SPRT_DELTA0 = 0.01
#: the SPRT's time of one hypothesis (sample, checks, solve) in units of one point verification
_SPRT_TM = 200.0
#: final refinement: IRLS rounds and the cut-off of its Tukey weights (see ``_dlt.finalize``) relative to the threshold. The threshold bounds the noise of an inlier, but real matches (SIFT under viewpoint change) have
#: heavier tails: a smooth redescending weight over 3x the threshold (weight 0.79 at the threshold, 0.31 at twice
#: it) gave lower corner errors on the Oxford/CMP pairs than hard inliers (see docs/notes/homography.md), like
#: MAGSAC++'s marginalisation over the noise scale; the returned inlier mask still uses the threshold itself.
_FINAL_ROUNDS = 2
_FINAL_WSCALE = 3.0
#: a model is accepted only when its number of false alarms is below this (a-contrario, Moisan & Stival's ORSA: an
#: NFA < 1 means fewer than one model this good is expected from matches that are pure chance)
MAX_NFA = 1.0


@dataclass(frozen=True, eq=False)
class HomographyFit:
    """The result of :func:`find_homography`.

    Attributes
    ----------
    H : (3, 3) float64
        Maps ``src`` to ``dst`` (homogeneous column vectors), scaled so that ``H[2, 2] = 1``.
    inliers : (N,) bool
        Correspondences whose reprojection error under ``H`` is at most ``threshold`` pixels.
    iterations : int
        Samples drawn, degenerate ones included (what the adaptive bound counts; ``cv2.findHomography`` counts the
        same way).
    rms : float
        Root-mean-square reprojection error of the inliers under ``H``, in pixels of ``dst``.
    log10_nfa : float
        ``log10`` of the number of false alarms of the inlier count (see :func:`log10_nfa`); negative = significant.
        Far from chance it is the upper bound that decided (from :func:`chance_bound`), not the exact value.
    """

    H: np.ndarray
    inliers: np.ndarray
    iterations: int
    rms: float
    log10_nfa: float = float("nan")

    @property
    def num_inliers(self) -> int:
        """Number of inliers."""
        return int(self.inliers.sum())


# ------------------------------------------------------------------------------------ significance vs chance


#: at most this many source points enter the permutation estimate of :func:`chance_probability` (O(rows x N))
_CHANCE_ROWS = 2000


def chance_probability(H: np.ndarray, src: np.ndarray, dst: np.ndarray, threshold: float,
                       area: float | None = None) -> float:
    """Chance that an unrelated match is an inlier of ``H``: the larger of two null models.

    - uniform: the destination point falls anywhere in ``area`` (px^2; default the bounding box of ``dst``), so
      ``p = pi threshold^2 / area``;
    - permutation: the pairing is random, the points are the observed ones, so ``p`` is the fraction of pairs
      ``(src_i, dst_j)``, ``i != j``, within ``threshold`` under ``H``. It accounts for clustered keypoints and
      for strongly perspective models that squeeze many sources into the densest part of ``dst`` (how chance
      models of unrelated photos collect their "inliers").
    """
    s = np.ascontiguousarray(src, np.float64)
    d = np.ascontiguousarray(dst, np.float64)
    n = len(s)
    p_uniform = _uniform_chance(d, threshold, area)
    if n < 2:
        return p_uniform
    rows = np.arange(n, dtype=np.int64)
    if n > _CHANCE_ROWS:  # evenly spread rows: deterministic and unbiased for the caller's order
        rows = np.linspace(0, n - 1, _CHANCE_ROWS).round().astype(np.int64)
    hits = _chance_hits(s, d, np.ascontiguousarray(H, np.float64), float(threshold) ** 2, rows)
    return max(p_uniform, hits / (len(rows) * (n - 1.0)))


def _uniform_chance(dst: np.ndarray, threshold: float, area: float | None) -> float:
    """The uniform null model of :func:`chance_probability`: ``pi threshold^2 / area``, at most 1."""
    a = points_area(dst) if area is None else float(area)
    return min(1.0, math.pi * float(threshold) ** 2 / max(a, 1.0))


def chance_bound(dst: np.ndarray, threshold: float, area: float | None = None) -> float:
    """An upper bound of :func:`chance_probability` that does not depend on the model, in O(N).

    Under the permutation model a source point is an inlier of the pair ``(src_i, dst_j)`` when ``H src_i`` lies
    within ``threshold`` of ``dst_j``; a disc of that radius meets at most 3 x 3 cells of a square grid of side
    ``threshold`` (4 x 4 allowing for the rounding of the cell indices), so at most 16 times the count of the
    densest cell of ``dst`` fall within it, whatever ``H`` is: ``p <= 16 max_cell / (N - 1)``.
    """
    d = np.ascontiguousarray(dst, np.float64)
    p_uniform = _uniform_chance(d, threshold, area)
    if len(d) < 2:
        return p_uniform
    return max(p_uniform, min(1.0, 16.0 * _densest_cell(d, float(threshold)) / (len(d) - 1.0)))


def points_area(pts: np.ndarray) -> float:
    """Area in px^2 of the axis-aligned bounding box of ``pts`` (N, 2), at least 1 px on each side."""
    p = np.ascontiguousarray(pts, np.float64).reshape(-1, 2)
    if len(p) == 0:
        return 1.0
    x0, y0, x1, y1 = _bounding_box(p)
    return float((x1 - x0 + 1.0) * (y1 - y0 + 1.0))


def _check_area(area) -> None:
    if area is not None and not (isinstance(area, (int, float, np.integer, np.floating)) and math.isfinite(area)
                                 and area > 0):
        raise InputError(f"`area` must be a finite number of px^2 > 0, got {area!r}")


def _significant(fit: HomographyFit, src: np.ndarray, dst: np.ndarray, threshold: float,
                 area: float | None) -> HomographyFit:
    """:func:`check_significant` for more than 4 correspondences (a minimal set is fitted exactly: nothing to test)."""
    if len(dst) <= 4:
        return fit
    return _nfa_test(fit, src, dst, threshold, area)


def _nfa_test(fit: HomographyFit, src: np.ndarray, dst: np.ndarray, threshold: float,
              area: float | None) -> HomographyFit:
    """:func:`check_significant` of validated (N, 2) float64 points."""
    inl = np.ascontiguousarray(fit.inliers, bool)
    # evidence counts distinct points: many matches to one keypoint (or SIFT's copies of a keypoint with several
    # orientations) are one observation, and a model that squeezes a row of sources onto one point gains nothing
    n_src, k_src = _distinct_rows(src, inl)
    n_dst, k_dst = _distinct_rows(dst, inl)
    k, n = min(k_src, k_dst), min(n_src, n_dst)
    # far from chance a bound of p that costs O(N) decides (the NFA grows with p); the O(rows x N) estimate of p
    # only near the boundary
    lnfa = log10_nfa(k, n, chance_bound(dst, threshold, area))
    if lnfa < math.log10(MAX_NFA):
        return HomographyFit(H=fit.H, inliers=fit.inliers, iterations=fit.iterations, rms=fit.rms, log10_nfa=lnfa)
    p = chance_probability(fit.H, src, dst, threshold, area)
    lnfa = log10_nfa(k, n, p)
    if not lnfa < math.log10(MAX_NFA):
        raise EstimationError(
            f"the best homography has {k} distinct inliers of {n} distinct matches ({fit.num_inliers} of {len(src)} "
            f"in all) within {float(threshold):g} px, which is chance "
            f"level (an unrelated match is an inlier with probability {p:.2g}; NFA 10^{lnfa:.1f} >= {MAX_NFA:g}): "
            "the images do not seem to show the same plane; check that they overlap, or try another --detector "
            "or more features"
        )
    return HomographyFit(H=fit.H, inliers=fit.inliers, iterations=fit.iterations, rms=fit.rms, log10_nfa=lnfa)


def check_significant(fit: HomographyFit, src, dst, threshold: float, area: float | None = None) -> HomographyFit:
    """``fit`` with its ``log10_nfa`` filled in, or :class:`EstimationError` when its inliers are chance-level.

    Parameters
    ----------
    fit : HomographyFit
        A model estimated from ``src`` -> ``dst``.
    src, dst : (N, 2) array_like
        The putative matches it was estimated from.
    threshold : float
        The inlier threshold in pixels.
    area : float, optional
        Destination image area in px^2 (see :func:`chance_probability`).

    Raises
    ------
    EstimationError
        ``NFA >= MAX_NFA``: as many inliers are expected from unrelated matches; the message has the counts.

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.homography import check_significant, find_homography
    >>> src = np.random.default_rng(2).uniform(0, 500, (50, 2))
    >>> fit = find_homography(src, src + 7.0, rng=0)  # a translation: every match is an inlier
    >>> bool(check_significant(fit, src, src + 7.0, threshold=3.0).log10_nfa < 0)
    True
    """
    return _nfa_test(fit, as_points("src", src), as_points("dst", dst), threshold, area)


# ----------------------------------------------------------------------------------------------- public API


def find_homography(
    src,
    dst,
    threshold: float = _EST.threshold,
    confidence: float = _EST.confidence,
    max_iters: int = _EST.max_iters,
    rng=None,
    *,
    local_optimization: bool = True,
    refine: bool = True,
    lo_multiplier: float = 2.0,
    lo_steps: int = 2,
    area: float | None = None,
) -> HomographyFit:
    """Robust homography from putative correspondences (LO-RANSAC + Levenberg-Marquardt), like cv2.findHomography.

    Parameters
    ----------
    src, dst : (N, 2) array_like
        Corresponding points in pixels (x = column, y = row); OpenCV's (N, 1, 2) layout is accepted. N >= 4.
    threshold : float
        Maximum one-sided reprojection error ``|| dehom(H src_i) - dst_i ||`` of an inlier, in pixels of ``dst``.
    confidence : float
        Probability in (0, 1) that at least one all-inlier sample was drawn when the adaptive bound stops RANSAC.
    max_iters : int
        Upper bound on the number of samples drawn (degenerate ones included).
    rng : None, int or numpy.random.Generator
        Seed or generator for the sampling (``np.random.default_rng(rng)``).
    local_optimization : bool
        Re-estimate every so-far-best model from its inliers (LO-RANSAC).
    refine : bool
        Finish with iteratively reweighted Levenberg-Marquardt (Tukey weights) on the reprojection error.
    lo_multiplier, lo_steps : float, int
        The LO threshold shrinks from ``lo_multiplier * threshold`` to ``threshold`` in ``lo_steps`` refits.
    area : float, optional
        Area of the destination image in px^2 for the test against chance (:func:`log10_nfa`); default the bounding
        box of ``dst`` (stricter). With more than 4 correspondences a model whose inlier count is chance-level is
        refused; 4 correspondences are fitted exactly and cannot be tested.

    Returns
    -------
    HomographyFit
        ``H`` (src -> dst, ``H[2, 2] = 1``), ``inliers`` (N,) bool, ``iterations``, ``rms``.

    Raises
    ------
    InputError (a ValueError)
        Shapes differ or are not (N, 2), fewer than 4 correspondences, NaN/inf, parameters out of range.
    EstimationError
        All points collinear, every sample degenerate, no model with at least 4 inliers, or an inlier count that
        chance explains (NFA >= 1); raise ``threshold`` or ``max_iters``, or supply better matches.

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.homography import find_homography, transform_points
    >>> H_true = np.array([[1.1, 0.02, 5.0], [-0.03, 0.95, -2.0], [1e-4, 2e-4, 1.0]])
    >>> src = np.random.default_rng(0).uniform(0, 500, (40, 2))
    >>> dst = transform_points(H_true, src)
    >>> dst[:5] += 60.0  # five outliers
    >>> fit = find_homography(src, dst, rng=0)
    >>> fit.num_inliers, bool(np.allclose(fit.H, H_true, atol=1e-6))
    (35, True)
    """
    s, d = _check_pair(src, dst)
    _check_area(area)
    if not (isinstance(threshold, (int, float, np.floating, np.integer)) and math.isfinite(threshold)
            and threshold > 0):
        raise InputError(f"`threshold` must be a finite number > 0 pixels, got {threshold!r}")
    if not (isinstance(confidence, (int, float, np.floating)) and 0.0 < confidence < 1.0):
        raise InputError(f"`confidence` must be in (0, 1), got {confidence!r}")
    check_int("max_iters", max_iters, 1)
    if not (isinstance(lo_multiplier, (int, float)) and lo_multiplier >= 1.0):
        raise InputError(f"`lo_multiplier` must be >= 1, got {lo_multiplier!r}")
    check_int("lo_steps", lo_steps, 1)
    gen = np.random.default_rng(rng)
    n = len(s)
    thr2 = float(threshold) ** 2
    Ts, sn, ok_s = normalize(s, _ALL_COLLINEAR_EPS)
    Td, dn, ok_d = normalize(d, _ALL_COLLINEAR_EPS)
    for name, ok in (("src", ok_s), ("dst", ok_d)):
        if not ok:
            raise EstimationError(
                f"all `{name}` points are collinear or coincident, so the homography is undetermined; "
                "supply correspondences spread over a 2-D region"
            )
    Tdi = np.linalg.inv(Td)
    Tsi = np.linalg.inv(Ts)
    best_H = np.zeros((3, 3))
    state = new_state(int(max_iters), _SPRT_EPS0, _SPRT_DELTA0, _SPRT_TM)
    log1mconf = math.log1p(-float(confidence))
    # the SPRT assumes the points are verified in random order; the caller's order may be sorted by quality
    perm = gen.permutation(n)
    pts = _rows_in_order(perm, s, d, sn, dn)  # (4, n, 2): src, dst, normalized src, normalized dst
    lo, lo_mult, lo_n, max_it = bool(local_optimization), float(lo_multiplier), int(lo_steps), int(max_iters)

    def step(u):
        return _ransac_chunk(pts, Ts, Tdi, Tsi, Td, u, thr2, log1mconf, max_it, lo, lo_mult, lo_n, best_H, state)

    run(step, gen, 4, state, max_iters=int(max_iters), first_chunk=256, largest_chunk=8192)
    iterations = int(state["iterations"][0])
    if iterations == int(state["degenerate"][0]):
        raise EstimationError(
            f"all {int(state['attempts'][0])} sampled 4-point sets were degenerate (collinear or "
            "orientation-flipping); the correspondences are nearly collinear or inconsistent"
        )
    H, mask, e2 = _finalize(s, d, best_H, thr2, bool(refine), _FINAL_ROUNDS, thr2 * _FINAL_WSCALE ** 2)
    if refine and _collapsed(Td @ H @ Tsi):  # the refinement drifted to a degenerate model: keep RANSAC's
        H, mask, e2 = _finalize(s, d, best_H, thr2, False, 0, thr2)
    if mask.sum() < 4:
        raise EstimationError(
            f"no homography with at least 4 inliers within {threshold} px after {iterations} iterations; "
            "raise `threshold` or `max_iters`, or supply better matches"
        )
    if _collapsed(Td @ H @ Tsi):
        raise EstimationError(
            "the best homography is nearly singular (it collapses the image onto a line or a point): the matches "
            "are dominated by many-to-one correspondences; use a cross check or a stricter ratio test"
        )
    H = _unit_h22(H)
    rms = float(np.sqrt(e2[mask].mean()))
    inl = mask.copy()
    H.setflags(write=False)
    inl.setflags(write=False)
    fit = HomographyFit(H=H, inliers=inl, iterations=iterations, rms=rms)
    return _significant(fit, s, d, threshold, area)


# --------------------------------------------------------------------------------------- method registry


def _opencv(method_flag_name: str) -> Callable[..., HomographyFit]:
    def estimate(src, dst, threshold=_EST.threshold, confidence=_EST.confidence, max_iters=_EST.max_iters, rng=None,
                 area=None):
        import cv2

        s, d = _check_pair(src, dst)
        _check_area(area)
        if not (math.isfinite(threshold) and threshold > 0):
            raise InputError(f"`threshold` must be a finite number > 0 pixels, got {threshold!r}")
        # ``rng`` is accepted for the common signature and ignored: cv2.findHomography's RANSAC and USAC samplers
        # start from a fixed internal state (the result does not change with cv2.setRNGSeed), so they are
        # deterministic for given points
        H, mask = cv2.findHomography(s, d, getattr(cv2, method_flag_name), float(threshold),
                                     maxIters=int(max_iters), confidence=float(confidence))
        if H is None or mask is None:
            raise EstimationError(f"cv2.findHomography ({method_flag_name}) found no homography; "
                                  "raise `threshold` or supply better matches")
        inl = mask.ravel().astype(bool)
        H = _unit_h22(np.asarray(H, dtype=np.float64))
        e2 = _sq_errors(s, d, H, np.empty(len(s)))
        if inl.sum() < 4:
            raise EstimationError(f"cv2.findHomography ({method_flag_name}) found no homography with at least 4 "
                                  "inliers; raise `threshold` or supply better matches")
        rms = float(np.sqrt(e2[inl].mean()))
        return _significant(HomographyFit(H=H, inliers=inl, iterations=-1, rms=rms), s, d, threshold, area)

    estimate.__name__ = f"opencv_{method_flag_name.lower()}"
    estimate.__doc__ = (f"``cv2.findHomography`` with ``cv2.{method_flag_name}`` behind the find_homography interface "
                        "(deterministic: ``rng`` is ignored).")
    return estimate


#: method name -> estimator with the :func:`find_homography` signature (src, dst, threshold, confidence,
#: max_iters, rng); ``iterations`` is -1 for OpenCV, which does not report it
METHODS: dict[str, Callable[..., HomographyFit]] = {
    "ours": find_homography,
    "opencv_ransac": _opencv("RANSAC"),
    "opencv_magsac": _opencv("USAC_MAGSAC"),
}


def estimate(method: str, src, dst, **kwargs) -> HomographyFit:
    """Run the estimator registered as ``method`` in :data:`METHODS` (keyword arguments as find_homography).

    This is the path of the ``cvpipe homography`` command and the pipeline's estimate stage: every method's model
    must be significant against chance (:func:`check_significant`, with ``area`` or the bounding box of ``dst``),
    and 4 matches, which any homography fits exactly, are not enough to tell (EstimationError).

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.homography import estimate, transform_points
    >>> src = np.random.default_rng(1).uniform(0, 500, (30, 2))
    >>> dst = transform_points([[1.0, 0.1, 3.0], [0.0, 1.2, -4.0], [0.0, 1e-4, 1.0]], src)
    >>> estimate("opencv_ransac", src, dst).num_inliers
    30
    >>> estimate("ours", src[:4], dst[:4])
    Traceback (most recent call last):
    ...
    cvpipe.errors.EstimationError: only 4 matches: a homography fits any 4 exactly, so this one cannot be told from chance; supply more matches (more features, a larger ratio)
    """
    try:
        fn = METHODS[method]
    except KeyError:
        raise InputError(f"`method` must be one of {sorted(METHODS)}, got {method!r}") from None
    fit = fn(src, dst, **kwargs)
    n = len(fit.inliers)
    if n <= 4:
        raise EstimationError(f"only {n} matches: a homography fits any 4 exactly, so this one cannot be told "
                              "from chance; supply more matches (more features, a larger ratio)")
    return fit


def estimate_with(src, dst, params: HomographyEstimateParams | None, method: str) -> HomographyFit:
    """:func:`estimate` with the ``homography.estimate`` section: its ``threshold`` (pixels), ``confidence``,
    ``max_iters`` and ``seed`` (the RANSAC ``rng``; OpenCV's methods ignore it).

    Parameters
    ----------
    src, dst : array_like, shape (N, 2)
        Matched points, ``dst ~ H src``.
    params : HomographyEstimateParams or None
        The ``homography.estimate`` section (None: its defaults).
    method : str
        A key of :data:`METHODS`.

    Returns
    -------
    HomographyFit

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.homography import transform_points
    >>> from cvpipe.params import HomographyEstimateParams
    >>> src = np.random.default_rng(1).uniform(0, 500, (30, 2))
    >>> dst = transform_points([[1.0, 0.1, 3.0], [0.0, 1.2, -4.0], [0.0, 1e-4, 1.0]], src)
    >>> estimate_with(src, dst, HomographyEstimateParams(threshold=2.0), "ours").num_inliers
    30
    """
    p = section_or_default(params, HomographyEstimateParams, "homography.estimate")
    return estimate(method, src, dst, threshold=p.threshold, confidence=p.confidence, max_iters=p.max_iters,
                    rng=p.seed)


def estimate_item(item: tuple, shared: tuple) -> tuple[HomographyFit, float]:
    """One pair's homography: the per-pair work of the ``homography_estimate`` stage, an item of
    :func:`cvpipe.compute.map_items` (it may run on another machine: data in, data out).

    Parameters
    ----------
    item : tuple
        ``(src, dst)``: the pair's (N, 2) matched points.
    shared : tuple
        ``(method, HomographyEstimateParams)``: a key of :data:`METHODS` and the ``homography.estimate`` section
        (:func:`estimate_with`).

    Returns
    -------
    (HomographyFit, float)
        The fit and the seconds it took.

    Raises
    ------
    EstimationError, InputError
        As :func:`estimate_with`, the message prefixed with the number of matches (``"12 matches: ..."``).
    """
    import time

    src, dst = item
    method, params = shared
    t0 = time.perf_counter()
    try:
        fit = estimate_with(src, dst, params, method)
    except (EstimationError, InputError) as exc:
        raise type(exc)(f"{len(src)} matches: {exc}") from None
    return fit, time.perf_counter() - t0
