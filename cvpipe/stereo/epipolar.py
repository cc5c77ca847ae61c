"""The fundamental matrix of two views: normalized 8-point and 7-point solvers inside RANSAC.

:func:`find_fundamental` has the semantics of ``cv2.findFundamentalMat(pts1, pts2, cv2.FM_RANSAC, threshold)``:
``F`` satisfies ``x2^T F x1 = 0`` for corresponding homogeneous pixels ``x1`` (first view) and ``x2`` (second view),
has rank 2, and a correspondence is an inlier when its Sampson distance (the first-order geometric distance of the
pair to the epipolar variety, in pixels) is at most ``threshold``. The pipeline is

1. Hartley normalization of both point sets (as ``cvpipe.geometry.hartley_normalization``, in one pass with the
   test that they are not all on one line);
2. RANSAC (the robust core :mod:`cvpipe.robust`: its sampler, bound and driver) over minimal 7-point samples,
   solved in batches: the 2-D null space of the 7x9 epipolar system, then the one to three real roots of the cubic
   ``det(a F1 + (1 - a) F2) = 0``; samples whose system has rank below 7 (repeated or collinear points) are
   skipped. Hypotheses are scored by MSAC (truncated squared Sampson distance)
   and the number of samples follows the adaptive bound ``log(1 - confidence) / log(1 - w^7)``, with at least
   ``_MIN_SAMPLES``;
3. every so-far-best model is refitted by the normalized 8-point algorithm on its inliers (local optimization);
4. the final model is refitted on its inliers by iteratively reweighted 8-point least squares, whose weights
   turn the algebraic error into the Sampson distance, with the rank-2 constraint enforced by SVD after each round,
   then over every correspondence with Tukey weights whose cut-off is 4.685 times the inliers' noise scale (a
   robust estimate from the median Sampson distance, at most twice the threshold). With little depth variation the
   cost is nearly flat along the epipole's distance and this refinement has several basins, so it starts from
   several RANSAC models (the last so-far-best ones and the lowest-cost ones of the run) and keeps the lowest cost;
5. degeneracy checks: too few correspondences or inliers, every point on one line, and inliers that one
   homography explains as well as ``F`` (a planar scene, or a pure rotation with no baseline), where ``F`` is not
   determined; each raises :class:`cvpipe.errors.EstimationError` saying what to change.

The loops are compiled kernels (:mod:`cvpipe.stereo._epipolar`): the 7-point solve and MSAC scoring of a batch of
samples, the Sampson distances, the 8-point solve from the accumulated 9x9 normal matrix with the rank-2 projection,
and the reweighting rounds of the final refinement (with the median of the noise scale); this module draws the
samples, keeps the so-far-best models and the starts of the final refinement, and raises the errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import EstimationError, InputError, check_int
from ..geometry import as_points, hartley_normalization
from ..params import StereoRectifyParams
from ..robust import iterations_needed, new_state, run
from . import _epipolar as K
from ._epipolar import _FINAL_WSCALE, _MAD_TO_SIGMA, _MIN_C, _RANK_EPS, _REFINE_ROUNDS, _TUKEY_C  # noqa: F401

#: default iteration cap of :func:`find_fundamental` (7-point samples; ~65 % outliers at confidence 0.999)
DEFAULT_MAX_ITERS = 5_000
#: samples solved and scored together
_BATCH = 64
#: the ``stereo.rectify`` defaults: the one declaration of :func:`find_fundamental`'s ``threshold``
_RECTIFY = StereoRectifyParams()
#: relative size of the smaller principal axis below which a whole point set counts as collinear
_ALL_COLLINEAR_EPS = 1e-6
#: the rank test of a 7-point sample (``_RANK_EPS``), the rounds of the final refit (``_REFINE_ROUNDS``) and its
#: Tukey cut-off (``_FINAL_WSCALE``, ``_TUKEY_C``, ``_MAD_TO_SIGMA``, ``_MIN_C``) are declared beside the kernels
#: that use them, in :mod:`cvpipe.stereo._epipolar`
#: RANSAC models that each get the final refinement (the most recent so-far-best ones and the lowest-cost ones
#: of the whole run, a few per batch), the lowest final cost wins; and the fewest samples drawn. With little depth
#: variation the cost is flat along the epipole's distance and the refinement has several basins: on an
#: unrectified Adirondack pair, 64 samples and one start ended in a basin with p95 vertical error 1.7-5.7 px for
#: some seeds (cost 94.5 against 84.1)
_FINAL_STARTS = 6
_POOL_PER_BATCH = 4
_MIN_SAMPLES = 256
#: share of the F inliers that one homography may explain (within 2 x threshold) before the pair counts as
#: degenerate: a planar scene or a pure camera rotation, where every point fits F for a whole family of F
_PLANAR_SHARE = 0.95
_PLANAR_MESSAGE = (f"{_PLANAR_SHARE:.0%} or more of the matches fit one homography: the scene is planar or the camera "
                   "only rotated (no baseline), so the epipolar geometry is undetermined; move the camera sideways "
                   "between the two photos")


@dataclass(frozen=True, eq=False)
class FundamentalFit:
    """The result of :func:`find_fundamental`.

    Attributes
    ----------
    F : (3, 3) float64
        Rank-2 fundamental matrix with ``x2^T F x1 = 0``, scaled to unit Frobenius norm.
    inliers : (N,) bool
        Correspondences whose Sampson distance under ``F`` is at most ``threshold`` pixels.
    iterations : int
        7-point samples drawn (regular ones; samples with a rank-deficient system are not counted).
    rms : float
        Root-mean-square Sampson distance of the inliers, in pixels.
    """

    F: np.ndarray
    inliers: np.ndarray
    iterations: int
    rms: float

    @property
    def num_inliers(self) -> int:
        """Number of inliers."""
        return int(self.inliers.sum())


# ----------------------------------------------------------------------------------------------- validation


def _check_pair(pts1, pts2, minimum: int):
    """(p1, p2, T1, T2, x1n, x2n): the validated points, their Hartley normalizations and the normalized points."""
    p1, p2 = as_points("pts1", pts1), as_points("pts2", pts2)
    if len(p1) != len(p2):
        raise InputError(f"`pts1` and `pts2` must have the same number of points, got {len(p1)} and {len(p2)}")
    if len(p1) < minimum:
        raise EstimationError(
            f"a fundamental matrix needs at least {minimum} correspondences, got {len(p1)}: the views share too "
            "little (more overlap, more features or a looser ratio test)")
    normalized = []
    for name, p in (("pts1", p1), ("pts2", p2)):
        T, x = np.empty((3, 3)), np.empty_like(p)
        if not K.normalize_points(p, _ALL_COLLINEAR_EPS, T, x):
            raise EstimationError(
                f"all `{name}` points are collinear or coincident, so the fundamental matrix is undetermined; "
                "supply correspondences spread over the image")
        normalized.append((T, x))
    (T1, x1n), (T2, x2n) = normalized
    return p1, p2, T1, T2, x1n, x2n


# ------------------------------------------------------------------------------------------------ solvers


def enforce_rank2(F: np.ndarray) -> np.ndarray:
    """The closest rank-2 matrix to ``F`` in Frobenius norm (smallest singular value set to 0)."""
    U, s, Vt = np.linalg.svd(F)
    return (U * np.array([s[0], s[1], 0.0])) @ Vt


def _unit(F: np.ndarray) -> np.ndarray:
    """F scaled to unit Frobenius norm, a fixed sign for a reproducible representative: the largest entry positive."""
    F = np.array(F, dtype=np.float64)
    K.unit(F)
    return F


_SOLVE_ERRORS = {
    K.FM_TOO_FEW: "the 8-point system needs at least 8 correspondences",
    K.FM_RANK_DEFICIENT: ("the 8-point system is rank-deficient (degenerate configuration); supply more "
                          "correspondences spread over the image and over depth"),
}


def _products(x1n: np.ndarray, x2n: np.ndarray) -> np.ndarray:
    """The (N, 36) products of the 8-point system's monomials (:func:`cvpipe.stereo._epipolar.design_products`)."""
    P = np.empty((len(x1n), 36))
    K.design_products(x1n, x2n, P)
    return P


def _columns(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """(4, N) rows x1, y1, x2, y2 of the correspondences: the layout in which the kernels score them on SIMD
    lanes."""
    return np.ascontiguousarray(np.concatenate([p1.T, p2.T]))


def _eight_point_normalized(x1n: np.ndarray, x2n: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    # the null vector of A from the 9x9 normal matrix (Hartley normalization keeps it well conditioned): an
    # eigen-decomposition of 9x9 instead of an SVD of N x 9
    Fn = np.empty((3, 3))
    status = K.eight_point_solve(_products(x1n, x2n), np.ones(len(x1n)) if w is None else w * w, len(x1n), Fn,
                                 np.empty((9, 9)), False)
    if status != K.FM_OK:
        raise EstimationError(_SOLVE_ERRORS[status])
    return Fn


def eight_point(pts1, pts2, weights=None) -> np.ndarray:
    """Normalized 8-point algorithm: the least-squares rank-2 fundamental matrix of >= 8 correspondences.

    Minimizes the algebraic error ``sum_i w_i^2 (x2_i^T F x1_i)^2`` in Hartley-normalized coordinates, then sets the
    smallest singular value to 0 (Hartley & Zisserman, algorithm 11.1).

    Parameters
    ----------
    pts1, pts2 : (N, 2) array_like
        Corresponding pixels in the first and second view, N >= 8.
    weights : (N,) array_like, optional
        Non-negative weight per correspondence (default 1).

    Returns
    -------
    F : (3, 3) float64
        ``x2^T F x1 = 0``, rank 2, unit Frobenius norm.

    Raises
    ------
    InputError
        Bad shapes, NaN/inf, bad weights.
    EstimationError
        Fewer than 8 points, all points collinear, or a rank-deficient system.
    """
    p1, p2, T1, T2, x1n, x2n = _check_pair(pts1, pts2, 8)
    w = None
    if weights is not None:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (len(p1),) or not np.isfinite(w).all() or (w < 0).any():
            raise InputError(f"`weights` must be {len(p1)} finite non-negative numbers")
    Fn = _eight_point_normalized(x1n, x2n, w)
    return _unit(T2.T @ Fn @ T1)


def sampson_least_squares(pts1, pts2, rounds: int = _REFINE_ROUNDS) -> np.ndarray:
    """The rank-2 F that minimizes the Sampson distances of correspondences that are all inliers.

    The normalized 8-point algorithm, reweighted ``rounds`` times so that the algebraic error becomes the Sampson
    distance (the refit that :func:`find_fundamental` applies to its inliers, without RANSAC or robust weights).
    ``pts1``, ``pts2``, the result and the errors are those of :func:`eight_point` (the points must hold no
    outliers); ``rounds`` (>= 0, else InputError) is the number of reweighting rounds.
    """
    check_int("rounds", rounds, 0)
    p1, p2, T1, T2, x1n, x2n = _check_pair(pts1, pts2, 8)
    F = np.empty((3, 3))
    status = K.refit(_products(x1n, x2n), _columns(p1, p2), T1, T2, np.ones(len(p1), np.bool_), int(rounds),
                     np.empty(len(p1)), F, np.empty((9, 9)), False)
    if status != K.FM_OK:
        raise EstimationError(_SOLVE_ERRORS[status])
    return F


def _apply(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:2, :2].T + T[:2, 2]


def seven_point(pts1, pts2) -> list[np.ndarray]:
    """The one or three fundamental matrices through exactly 7 correspondences (the minimal solver).

    Parameters
    ----------
    pts1, pts2 : (7, 2) array_like
        Corresponding pixels.

    Returns
    -------
    list of (3, 3) float64
        Each rank 2 (up to rounding) with ``x2^T F x1 = 0`` for all 7 pairs, unit Frobenius norm.

    Raises
    ------
    InputError
        Not exactly 7 points, bad shapes or NaN/inf.
    EstimationError
        A degenerate sample (repeated or collinear points) with no regular solution.
    """
    p1, p2 = as_points("pts1", pts1), as_points("pts2", pts2)
    if p1.shape != (7, 2) or p2.shape != (7, 2):
        raise InputError(f"the 7-point solver needs exactly 7 correspondences, got {len(p1)} and {len(p2)}")
    T1, T2 = hartley_normalization(p1), hartley_normalization(p2)
    Fns = np.empty((3, 3, 3))
    count = K.seven_point(_apply(T1, p1), _apply(T2, p2), np.arange(7, dtype=np.int64), Fns)
    if count == 0:
        raise EstimationError("the 7-point sample is degenerate (repeated or collinear points); draw another")
    return [_unit(T2.T @ f @ T1) for f in Fns[:count]]


def sampson_distance(F, pts1, pts2) -> np.ndarray:
    """First-order geometric distance of each correspondence to the epipolar geometry ``F``, in pixels.

    ``|x2^T F x1| / sqrt((F x1)_1^2 + (F x1)_2^2 + (F^T x2)_1^2 + (F^T x2)_2^2)`` (Hartley & Zisserman, 11.4.3).

    Parameters
    ----------
    F : (3, 3) array_like or (M, 3, 3)
        Fundamental matrix (or a stack of them), ``x2^T F x1 = 0``.
    pts1, pts2 : (N, 2) array_like
        Corresponding pixels.

    Returns
    -------
    (N,) or (M, N) float64
    """
    F = np.asarray(F, dtype=np.float64)
    single = F.ndim == 2
    Fs = np.ascontiguousarray(F.reshape(-1, 3, 3))
    p1 = np.ascontiguousarray(np.asarray(pts1, dtype=np.float64).reshape(-1, 2))
    p2 = np.ascontiguousarray(np.asarray(pts2, dtype=np.float64).reshape(-1, 2))
    if len(p1) != len(p2):  # the broadcasting error of the former vectorized version
        raise ValueError(f"`pts1` and `pts2` must have the same number of points, got {len(p1)} and {len(p2)}")
    d = np.empty((len(Fs), len(p1)))
    K.sampson_distances(Fs, p1, p2, d)
    return d[0] if single else d


def epipoles(F) -> tuple[np.ndarray, np.ndarray]:
    """Unit homogeneous epipoles ``e1`` (``F e1 = 0``, first view) and ``e2`` (``F^T e2 = 0``, second view)."""
    U, _, Vt = np.linalg.svd(np.asarray(F, dtype=np.float64))
    return Vt[-1], U[:, -1]


# ------------------------------------------------------------------------------------------------- RANSAC


def _noise_cutoff(d: np.ndarray, threshold: float) -> float:
    """Tukey's cut-off ``_TUKEY_C * sigma`` for Sampson distances ``d``, with the noise scale ``sigma`` estimated
    robustly from the inliers (``1.4826 * median`` of the distances within ``threshold``), kept within
    ``[_MIN_C, _FINAL_WSCALE] * threshold`` (the kernel :func:`cvpipe.stereo._epipolar.noise_cutoff`)."""
    d = np.ascontiguousarray(d, dtype=np.float64)
    return float(K.noise_cutoff(d, float(threshold), np.empty(len(d)), False))


def _homography_share(p1: np.ndarray, p2: np.ndarray, threshold: float, rng: np.random.Generator) -> float:
    """Share of the correspondences that the best RANSAC homography maps within ``2 * threshold`` px."""
    from ..homography import find_homography

    try:
        fit = find_homography(p1, p2, threshold=2.0 * threshold, rng=rng, max_iters=2000)
    except EstimationError:
        return 0.0
    return fit.num_inliers / len(p1)


def find_fundamental(pts1, pts2, threshold: float = _RECTIFY.threshold, confidence: float = 0.999,
                     max_iters: int = DEFAULT_MAX_ITERS, min_inliers: int = 15, check_planar: bool = True,
                     rng=None) -> FundamentalFit:
    """Robust fundamental matrix of putative correspondences (7-point RANSAC, MSAC scoring, 8-point refits).

    Parameters
    ----------
    pts1, pts2 : (N, 2) array_like
        Putative corresponding pixels in the first and second view (x = column, y = row).
    threshold : float
        Largest Sampson distance of an inlier, in pixels.
    confidence : float
        Probability in (0, 1) that an all-inlier sample was drawn, which sets the adaptive number of samples.
    max_iters : int
        Cap on the number of 7-point samples.
    min_inliers : int
        Fewest inliers (>= 8) a result must have.
    check_planar : bool
        Refuse inliers that one homography explains (planar scene or pure rotation): ``F`` is undetermined there.
    rng : None, int or numpy.random.Generator
        Seed or generator of the sampling; a fixed seed reproduces the result exactly.

    Returns
    -------
    FundamentalFit

    Raises
    ------
    InputError
        Bad shapes, NaN/inf or parameters out of range.
    EstimationError
        Too few correspondences or inliers, collinear points, or a planar / pure-rotation configuration.
    """
    if not (isinstance(threshold, (int, float)) and math.isfinite(threshold) and threshold > 0):
        raise InputError(f"`threshold` must be a finite number > 0 pixels, got {threshold!r}")
    if not (isinstance(confidence, (int, float)) and 0.0 < confidence < 1.0):
        raise InputError(f"`confidence` must be in (0, 1), got {confidence!r}")
    check_int("max_iters", max_iters, 1)
    check_int("min_inliers", min_inliers, 8)
    p1, p2, T1, T2, x1n, x2n = _check_pair(pts1, pts2, 8)
    PT = _products(x1n, x2n)
    q = _columns(p1, p2)
    gen = np.random.default_rng(rng)
    n = len(p1)
    thr2 = float(threshold) ** 2
    log1mconf = math.log1p(-float(confidence))

    state = new_state(int(max_iters))
    best_F, history, pool = None, [], []
    models, costs, mask = np.empty((3 * _BATCH, 3, 3)), np.empty(3 * _BATCH), np.empty(n, np.bool_)

    def step(u):
        nonlocal best_F
        # the models of the batch in pixel coordinates with their MSAC costs (those that cannot be among the lowest
        # _POOL_PER_BATCH are left unfinished at cost inf)
        m, regular = K.ransac_batch(u, x1n, x2n, q, T1, T2, thr2, _POOL_PER_BATCH, models, costs)
        s = state[0]
        s["iterations"] += regular
        if m == 0:
            return len(u)
        cost = costs[:m]
        for i in np.argsort(cost)[:_POOL_PER_BATCH]:
            pool.append((float(cost[i]), models[i].copy()))
        j = int(np.argmin(cost))
        if cost[j] < s["best_cost"]:
            s["best_cost"], best_F = float(cost[j]), models[j].copy()
            history.append(best_F)
            # local optimization: the least-squares model of the new best's inliers
            F_lo = np.empty((3, 3))
            ok, c_lo = K.local_optimize(PT, q, T1, T2, best_F, thr2, F_lo)
            if ok and c_lo < s["best_cost"]:
                s["best_cost"], best_F = c_lo, F_lo
                history.append(best_F)
            count = K.count_within(best_F, q, thr2, mask)
            if count > s["best_inliers"]:
                s["best_inliers"] = count
                s["bound"] = iterations_needed(count, n, 7, log1mconf, int(max_iters), np.inf)
        return len(u)

    run(step, gen, 7, state, max_iters=int(max_iters), first_chunk=_BATCH, largest_chunk=_BATCH,
        min_iterations=min(_MIN_SAMPLES, int(max_iters)))
    iterations = int(state["iterations"][0])
    if best_F is None:
        if check_planar and _homography_share(p1, p2, threshold, gen) >= _PLANAR_SHARE:
            raise EstimationError(_PLANAR_MESSAGE)
        raise EstimationError(f"all {int(state['attempts'][0])} sampled 7-point sets were degenerate; the "
                              "correspondences are nearly collinear or repeated")
    d_best = sampson_distance(best_F, p1, p2)
    mask = d_best <= threshold
    if mask.sum() < min_inliers:
        raise EstimationError(
            f"only {int(mask.sum())} correspondences fit one epipolar geometry within {threshold} px (need "
            f"{min_inliers}): the views share too little; supply more overlap or raise `threshold`")
    # several starts for the final refinement (see _FINAL_STARTS): keep the lowest final cost
    # the starts compete on the MSAC cost truncated at the noise cut-off of the RANSAC model, not at the threshold:
    # with the threshold 5-10x the noise, the tail would decide between nearly equal models
    sel2 = _noise_cutoff(d_best, float(threshold)) ** 2
    starts = history[-_FINAL_STARTS:] + [f for _, f in sorted(pool, key=lambda t: t[0])[:_FINAL_STARTS]]
    # a cheap look at each start (two robust rounds), then the full refinement of the two most promising
    F = np.empty((3, 3))
    if not K.final_refinement(PT, q, T1, T2, np.array(starts), float(threshold), sel2, int(min_inliers),
                              2, 2, F):
        F = best_F
    d = sampson_distance(F, p1, p2)
    mask = d <= threshold
    if mask.sum() < min_inliers:
        raise EstimationError(
            f"only {int(mask.sum())} inliers after refitting (need {min_inliers}); supply better matches")
    if check_planar and _homography_share(p1[mask], p2[mask], threshold, gen) >= _PLANAR_SHARE:
        raise EstimationError(_PLANAR_MESSAGE)
    rms = float(np.sqrt(np.mean(d[mask] ** 2)))
    F = F.copy()
    F.setflags(write=False)
    mask.setflags(write=False)
    return FundamentalFit(F=F, inliers=mask, iterations=int(iterations), rms=rms)
