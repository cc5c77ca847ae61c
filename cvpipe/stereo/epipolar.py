"""The fundamental matrix of two views: normalized 8-point and 7-point solvers inside RANSAC.

:func:`find_fundamental` has the semantics of ``cv2.findFundamentalMat(pts1, pts2, cv2.FM_RANSAC, threshold)``:
``F`` satisfies ``x2^T F x1 = 0`` for corresponding homogeneous pixels ``x1`` (first view) and ``x2`` (second view),
has rank 2, and a correspondence is an inlier when its Sampson distance (the first-order geometric distance of the
pair to the epipolar variety, in pixels) is at most ``threshold``. The pipeline is

1. Hartley normalization of both point sets (``cvpipe.geometry.hartley_normalization``);
2. RANSAC over minimal 7-point samples, solved in batches: the 2-D null space of the 7x9 epipolar system, then the
   one to three real roots of the cubic ``det(a F1 + (1 - a) F2) = 0``; samples whose system has rank below 7
   (repeated or collinear points) are skipped. Hypotheses are scored by MSAC (truncated squared Sampson distance)
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

Everything is vectorized numpy (a batch of samples is solved and scored at once): a numba kernel did not pay, as the
work per hypothesis is a handful of small SVDs and one pass over the points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import EstimationError, InputError, check_int
from ..geometry import as_points, collinear, hartley_normalization
from ..params import StereoRectifyParams

#: default iteration cap of :func:`find_fundamental` (7-point samples; ~65 % outliers at confidence 0.999)
DEFAULT_MAX_ITERS = 5_000
#: samples solved and scored together
_BATCH = 64
#: the ``stereo.rectify`` defaults: the one declaration of :func:`find_fundamental`'s ``threshold``
_RECTIFY = StereoRectifyParams()
#: smallest sigma_7 / sigma_1 of a 7-point system in normalized coordinates for the sample to count as regular
_RANK_EPS = 1e-9
#: relative size of the smaller principal axis below which a whole point set counts as collinear
_ALL_COLLINEAR_EPS = 1e-6
#: rounds of Sampson-reweighted 8-point refitting of the final model
_REFINE_ROUNDS = 10
#: the final refit weighs every correspondence by Tukey's biweight with at most this cut-off (in units of the
#: threshold), as the homography's final refinement does: real matches have heavier tails than the threshold assumes
_FINAL_WSCALE = 2.0
#: ...and within it the cut-off is Tukey's 4.685 sigma (95 % efficiency under Gaussian noise) of the inliers' noise
#: scale, ``sigma = 1.4826 * median`` of their Sampson distances. SIFT matches are heavy-tailed (on the Middlebury
#: pairs the 90th percentile of the true residuals is 4 sigma, not 1.6), so a cut-off at the noise scale rather
#: than at the threshold takes the tail's pull off the fit. ``_MIN_C`` keeps it from collapsing on exact data
_TUKEY_C = 4.685
_MAD_TO_SIGMA = 1.4826
_MIN_C = 0.05
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


def _check_pair(pts1, pts2, minimum: int) -> tuple[np.ndarray, np.ndarray]:
    p1, p2 = as_points("pts1", pts1), as_points("pts2", pts2)
    if len(p1) != len(p2):
        raise InputError(f"`pts1` and `pts2` must have the same number of points, got {len(p1)} and {len(p2)}")
    if len(p1) < minimum:
        raise EstimationError(
            f"a fundamental matrix needs at least {minimum} correspondences, got {len(p1)}: the views share too "
            "little (more overlap, more features or a looser ratio test)")
    for name, p in (("pts1", p1), ("pts2", p2)):
        if collinear(p, _ALL_COLLINEAR_EPS):
            raise EstimationError(
                f"all `{name}` points are collinear or coincident, so the fundamental matrix is undetermined; "
                "supply correspondences spread over the image")
    return p1, p2


# ------------------------------------------------------------------------------------------------ solvers


def _hom(p: np.ndarray) -> np.ndarray:
    return np.column_stack([p, np.ones(len(p))])


def _design(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Rows of the linear system ``A f = 0`` for ``x2^T F x1 = 0`` (F row-major); works on (..., N, 2) arrays."""
    u, v = x1[..., 0], x1[..., 1]
    up, vp = x2[..., 0], x2[..., 1]
    one = np.ones_like(u)
    return np.stack([up * u, up * v, up, vp * u, vp * v, vp, u, v, one], axis=-1)


def enforce_rank2(F: np.ndarray) -> np.ndarray:
    """The closest rank-2 matrix to ``F`` in Frobenius norm (smallest singular value set to 0)."""
    U, s, Vt = np.linalg.svd(F)
    return (U * np.array([s[0], s[1], 0.0])) @ Vt


def _unit(F: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(F)
    F = F / n
    # a fixed sign for a reproducible representative: the largest entry positive
    k = np.argmax(np.abs(F))
    return F if F.flat[k] >= 0 else -F


def _eight_point_normalized(x1n: np.ndarray, x2n: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    A = _design(x1n, x2n)
    if len(A) < 8:
        raise EstimationError("the 8-point system needs at least 8 correspondences")
    if w is not None:
        A = A * w[:, None]
    # the null vector of A from the 9x9 normal matrix (Hartley normalization keeps it well conditioned): an
    # eigen-decomposition of 9x9 instead of an SVD of N x 9, ~10x faster for a thousand points
    ev, V = np.linalg.eigh(A.T @ A)
    if ev[1] <= 1e-24 * max(ev[-1], 1e-300):
        raise EstimationError("the 8-point system is rank-deficient (degenerate configuration); "
                              "supply more correspondences spread over the image and over depth")
    return enforce_rank2(V[:, 0].reshape(3, 3))


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
    p1, p2 = _check_pair(pts1, pts2, 8)
    w = None
    if weights is not None:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (len(p1),) or not np.isfinite(w).all() or (w < 0).any():
            raise InputError(f"`weights` must be {len(p1)} finite non-negative numbers")
    T1, T2 = hartley_normalization(p1), hartley_normalization(p2)
    Fn = _eight_point_normalized(_apply(T1, p1), _apply(T2, p2), w)
    return _unit(T2.T @ Fn @ T1)


def sampson_least_squares(pts1, pts2, rounds: int = _REFINE_ROUNDS) -> np.ndarray:
    """The rank-2 F that minimizes the Sampson distances of correspondences that are all inliers.

    The normalized 8-point algorithm, reweighted ``rounds`` times so that the algebraic error becomes the Sampson
    distance (the refit that :func:`find_fundamental` applies to its inliers, without RANSAC or robust weights).
    ``pts1``, ``pts2``, the result and the errors are those of :func:`eight_point` (the points must hold no
    outliers); ``rounds`` (>= 0, else InputError) is the number of reweighting rounds.
    """
    check_int("rounds", rounds, 0)
    p1, p2 = _check_pair(pts1, pts2, 8)
    T1, T2 = hartley_normalization(p1), hartley_normalization(p2)
    return _refit(_apply(T1, p1), _apply(T2, p2), p1, p2, T1, T2, np.ones(len(p1), bool), int(rounds))


def _apply(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:2, :2].T + T[:2, 2]


def _seven_point_batch(x1n: np.ndarray, x2n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fundamental matrices of a batch of 7-point samples.

    Parameters
    ----------
    x1n, x2n : (B, 7, 2) float64
        Normalized points of each sample.

    Returns
    -------
    F : (M, 3, 3) float64
        Every real solution of every regular sample (1 or 3 per sample).
    owner : (M,) int
        The sample each solution comes from.
    """
    A = _design(x1n, x2n)  # (B, 7, 9)
    _, sv, vt = np.linalg.svd(A, full_matrices=True)
    regular = sv[:, 6] > _RANK_EPS * sv[:, 0]
    F1 = vt[regular, 7].reshape(-1, 3, 3)
    F2 = vt[regular, 8].reshape(-1, 3, 3)
    idx = np.flatnonzero(regular)
    if len(idx) == 0:
        return np.empty((0, 3, 3)), np.empty(0, dtype=np.int64)
    # det(a F1 + (1 - a) F2) is a cubic in a: fit it exactly through 4 values
    a_s = np.array([0.0, 1.0, -1.0, 2.0])
    dets = np.stack([np.linalg.det(a * F1 + (1 - a) * F2) for a in a_s], axis=1)  # (B', 4)
    V = np.vander(a_s, 4)  # columns a^3, a^2, a, 1
    coef = np.linalg.solve(V, dets.T).T  # (B', 4): c3, c2, c1, c0
    # roots of the cubics as eigenvalues of their companion matrices, all samples at once; a sample whose cubic
    # degenerates (c3 ~ 0: F2 itself is a solution) is rare and simply skipped
    scale = np.abs(coef).max(axis=1)
    good = (scale > 0) & (np.abs(coef[:, 0]) > 1e-10 * np.where(scale > 0, scale, 1.0))
    c = coef[good] / coef[good, :1]
    comp = np.zeros((len(c), 3, 3))
    comp[:, 0, :] = -c[:, 1:]
    comp[:, 1, 0] = comp[:, 2, 1] = 1.0
    roots = np.linalg.eigvals(comp)  # (B'', 3)
    real = np.abs(roots.imag) <= 1e-8 * np.maximum(1.0, np.abs(roots))
    si, ri = np.nonzero(real)
    if len(si) == 0:
        return np.empty((0, 3, 3)), np.empty(0, dtype=np.int64)
    a = roots.real[si, ri][:, None, None]
    gi = np.flatnonzero(good)[si]
    return a * F1[gi] + (1 - a) * F2[gi], idx[gi]


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
    F, _ = _seven_point_batch(_apply(T1, p1)[None], _apply(T2, p2)[None])
    if len(F) == 0:
        raise EstimationError("the 7-point sample is degenerate (repeated or collinear points); draw another")
    return [_unit(T2.T @ f @ T1) for f in F]


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
    Fs = F.reshape(-1, 3, 3)
    p1 = np.asarray(pts1, dtype=np.float64).reshape(-1, 2)
    p2 = np.asarray(pts2, dtype=np.float64).reshape(-1, 2)
    x1, x2 = _hom(p1), _hom(p2)
    # plain 2-D products, (N, 3) @ (3, M), one per needed row / column of F: BLAS instead of stacked temporaries
    num = _design(p1, p2) @ Fs.reshape(-1, 9).T  # (N, M): x2^T F x1
    a0, a1 = x1 @ Fs[:, 0, :].T, x1 @ Fs[:, 1, :].T  # rows 1, 2 of F x1
    b0, b1 = x2 @ Fs[:, :, 0].T, x2 @ Fs[:, :, 1].T  # rows 1, 2 of F^T x2
    den = a0 * a0 + a1 * a1 + b0 * b0 + b1 * b1
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.abs(num) / np.sqrt(den)
    d = np.where(den > 0, d, np.inf).T  # (M, N)
    return d[0] if single else d


def epipoles(F) -> tuple[np.ndarray, np.ndarray]:
    """Unit homogeneous epipoles ``e1`` (``F e1 = 0``, first view) and ``e2`` (``F^T e2 = 0``, second view)."""
    U, _, Vt = np.linalg.svd(np.asarray(F, dtype=np.float64))
    return Vt[-1], U[:, -1]


# ------------------------------------------------------------------------------------------------- RANSAC


def _msac_cost(d: np.ndarray, thr2: float) -> np.ndarray:
    return np.minimum(d * d, thr2).sum(axis=-1)


def _refit(x1n, x2n, p1, p2, T1, T2, mask, rounds):
    """Sampson-reweighted normalized 8-point on ``mask``; returns F in pixel coordinates (unit norm)."""
    Fn = _eight_point_normalized(x1n[mask], x2n[mask])
    for _ in range(rounds):
        F = T2.T @ Fn @ T1
        h1, h2 = _hom(p1[mask]), _hom(p2[mask])
        Fx1, Ftx2 = h1 @ F.T, h2 @ F
        den = Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2
        # algebraic residual / its gradient norm = Sampson distance; the normalization changes the algebraic
        # scale by a constant factor only
        w = 1.0 / np.sqrt(np.maximum(den, 1e-300))
        Fn = _eight_point_normalized(x1n[mask], x2n[mask], w / w.mean())
    return _unit(T2.T @ Fn @ T1)


def _noise_cutoff(d: np.ndarray, threshold: float) -> float:
    """Tukey's cut-off ``_TUKEY_C * sigma`` for Sampson distances ``d``, with the noise scale ``sigma`` estimated
    robustly from the inliers (``1.4826 * median`` of the distances within ``threshold``), kept within
    ``[_MIN_C, _FINAL_WSCALE] * threshold``."""
    inl = d[d <= threshold]
    sigma = _MAD_TO_SIGMA * float(np.median(inl)) if len(inl) else threshold
    return min(_FINAL_WSCALE * threshold, max(_TUKEY_C * sigma, _MIN_C * threshold))


def _refit_robust(x1n, x2n, p1, p2, T1, T2, F, threshold, rounds):
    """Iteratively reweighted 8-point over every correspondence with Sampson weights times Tukey's biweight of the
    Sampson distance, so the result depends smoothly on the inlier set; the cut-off follows the noise scale of the
    inliers, re-estimated each round (:func:`_noise_cutoff`)."""
    for _ in range(rounds):
        h1, h2 = _hom(p1), _hom(p2)
        Fx1, Ftx2 = h1 @ F.T, h2 @ F
        den = np.maximum(Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2, 1e-300)
        d = np.abs((Fx1 * h2).sum(axis=1)) / np.sqrt(den)
        c = _noise_cutoff(d, threshold)
        use = d < c
        if use.sum() < 8:
            break
        w = (1.0 - (d[use] / c) ** 2) ** 2 / np.sqrt(den[use])
        F = _unit(T2.T @ _eight_point_normalized(x1n[use], x2n[use], w / w.mean()) @ T1)
    return F


def _finish(x1n, x2n, p1, p2, T1, T2, F, threshold, min_inliers):
    """The final refinement of one RANSAC model: 8-point refits with inlier re-selection, then the robust refit."""
    mask = sampson_distance(F, p1, p2) <= threshold
    for _ in range(2):  # refit, re-select inliers, refit (the inlier set settles in one or two rounds)
        F = _refit(x1n, x2n, p1, p2, T1, T2, mask, _REFINE_ROUNDS)
        new = sampson_distance(F, p1, p2) <= threshold
        if new.sum() < min_inliers or np.array_equal(new, mask):
            break
        mask = new
    if _FINAL_WSCALE > 0:
        F = _refit_robust(x1n, x2n, p1, p2, T1, T2, F, threshold, _REFINE_ROUNDS)
    return F


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
    p1, p2 = _check_pair(pts1, pts2, 8)
    gen = np.random.default_rng(rng)
    n = len(p1)
    thr2 = float(threshold) ** 2
    T1, T2 = hartley_normalization(p1), hartley_normalization(p2)
    x1n, x2n = _apply(T1, p1), _apply(T2, p2)
    log1mconf = math.log1p(-float(confidence))

    best_F, best_cost, best_count, history, pool = None, np.inf, 0, [], []
    bound, iterations, attempts = float(max_iters), 0, 0
    while (iterations < bound or iterations < min(_MIN_SAMPLES, max_iters)) and attempts < 10 * max_iters + 100:
        k = _BATCH
        # 7 distinct indices per sample: argpartition of uniforms is exact sampling without replacement
        samples = np.argpartition(gen.random((k, n)), 7, axis=1)[:, :7] if n > 7 else np.tile(np.arange(7), (k, 1))
        attempts += k
        Fn, owner = _seven_point_batch(x1n[samples], x2n[samples])
        iterations += len(np.unique(owner))
        if len(Fn) == 0:
            continue
        Fpx = np.einsum("ji,mjk,kl->mil", T2, Fn, T1)
        d = sampson_distance(Fpx, p1, p2)
        cost = _msac_cost(d, thr2)
        for i in np.argsort(cost)[:_POOL_PER_BATCH]:
            pool.append((float(cost[i]), Fpx[i]))
        j = int(np.argmin(cost))
        if cost[j] < best_cost:
            best_cost, best_F = float(cost[j]), Fpx[j]
            history.append(best_F)
            mask = d[j] <= threshold
            if mask.sum() >= 8:  # local optimization: the least-squares model of the new best's inliers
                try:
                    F_lo = _refit(x1n, x2n, p1, p2, T1, T2, mask, 0)
                    c_lo = float(_msac_cost(sampson_distance(F_lo, p1, p2), thr2))
                    if c_lo < best_cost:
                        best_cost, best_F = c_lo, F_lo
                        history.append(best_F)
                except EstimationError:
                    pass
            count = int((sampson_distance(best_F, p1, p2) <= threshold).sum())
            if count > best_count:
                best_count = count
                w = count / n
                denom = math.log1p(-min(w ** 7, 1 - 1e-16))
                bound = min(float(max_iters), log1mconf / denom if denom < 0 else float(max_iters))
    if best_F is None:
        if check_planar and _homography_share(p1, p2, threshold, gen) >= _PLANAR_SHARE:
            raise EstimationError(_PLANAR_MESSAGE)
        raise EstimationError(f"all {attempts} sampled 7-point sets were degenerate; the correspondences are "
                              "nearly collinear or repeated")
    mask = sampson_distance(best_F, p1, p2) <= threshold
    if mask.sum() < min_inliers:
        raise EstimationError(
            f"only {int(mask.sum())} correspondences fit one epipolar geometry within {threshold} px (need "
            f"{min_inliers}): the views share too little; supply more overlap or raise `threshold`")
    # several starts for the final refinement (see _FINAL_STARTS): keep the lowest final cost
    F, final_cost = None, np.inf
    # the starts compete on the MSAC cost truncated at the noise cut-off of the RANSAC model, not at the threshold:
    # with the threshold 5-10x the noise, the tail would decide between nearly equal models
    sel2 = _noise_cutoff(sampson_distance(best_F, p1, p2), float(threshold)) ** 2
    starts = history[-_FINAL_STARTS:] + [f for _, f in sorted(pool, key=lambda t: t[0])[:_FINAL_STARTS]]
    # a cheap look at each start (two robust rounds), then the full refinement of the two most promising
    quick = []
    for start in starts:
        try:
            q = _refit_robust(x1n, x2n, p1, p2, T1, T2, start, float(threshold), 2)
        except EstimationError:
            continue
        quick.append((float(_msac_cost(sampson_distance(q, p1, p2), sel2)), q))
    for _, start in sorted(quick, key=lambda t: t[0])[:2]:
        try:
            cand = _finish(x1n, x2n, p1, p2, T1, T2, start, float(threshold), min_inliers)
        except EstimationError:
            continue
        c = float(_msac_cost(sampson_distance(cand, p1, p2), sel2))
        if c < final_cost:
            F, final_cost = cand, c
    if F is None:
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
