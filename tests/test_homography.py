"""cvpipe.homography: recovery of known homographies, degenerate input, and the method registry."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from cvpipe.errors import EstimationError, InputError
from cvpipe.homography import (
    METHODS,
    HomographyFit,
    dlt,
    estimate,
    find_homography,
    hartley_normalization,
    transform_points,
)
from cvpipe.homography._dlt import null_vector as _null_vector
from cvpipe.homography._ransac import minimal_solve as _minimal_solve
from cvpipe.metrics import corner_error, image_corners

W, H_IMG = 640, 480
#: a perspective view change: rotation, scale, shear and a visible projective part
H_TRUE = np.array([[0.92, 0.12, 25.0], [-0.08, 1.05, -14.0], [2.2e-4, -1.4e-4, 1.0]])


def scene(n=300, outlier_frac=0.5, noise=0.5, seed=0, H=H_TRUE):
    """Correspondences src -> dst under H with Gaussian noise on dst and known gross outliers.

    Outliers are replaced by uniform points at least 20 px away from their true image, so the ground-truth inlier
    set is unambiguous at a 3 px threshold.
    """
    r = np.random.default_rng(seed)
    src = r.uniform([0, 0], [W - 1, H_IMG - 1], size=(n, 2))
    dst = transform_points(H, src) + r.normal(0.0, noise, size=(n, 2))
    k = int(round(outlier_frac * n))
    out = r.choice(n, size=k, replace=False)
    true_dst = transform_points(H, src[out])
    for j, i in enumerate(out):
        while True:
            p = r.uniform([0, 0], [W - 1, H_IMG - 1])
            if np.linalg.norm(p - true_dst[j]) > 20.0:
                dst[i] = p
                break
    is_out = np.zeros(n, bool)
    is_out[out] = True
    return src, dst, is_out


# --------------------------------------------------------------------------------------------- recovery


@pytest.mark.parametrize("outlier_frac", [0.0, 0.5, 0.8])
def test_recovers_known_h_with_known_outliers(outlier_frac):
    src, dst, is_out = scene(outlier_frac=outlier_frac, seed=1)
    fit = find_homography(src, dst, threshold=3.0, rng=0)
    assert isinstance(fit, HomographyFit)
    assert fit.H.shape == (3, 3) and fit.H.dtype == np.float64 and fit.H[2, 2] == 1.0
    assert fit.inliers.shape == (len(src),) and fit.inliers.dtype == bool
    # 0.5 px noise on >= 60 inliers: the least-squares corners are good to ~0.1-0.3 px; 1 px leaves margin
    assert corner_error(fit.H, H_TRUE, W, H_IMG) < 1.0
    # every planted outlier is > 20 px off, far beyond the 3 px threshold
    assert not fit.inliers[is_out].any()
    # a true inlier exceeds 3 px = 6 sigma only with probability exp(-18): all of them must be found
    assert fit.inliers[~is_out].all()
    assert fit.num_inliers == (~is_out).sum()
    # rms of the inliers is the noise level (2-D, sigma 0.5 -> sqrt(2) * 0.5 = 0.71 px), within sampling error
    assert 0.5 < fit.rms < 0.9


def test_noise_free_is_exact():
    src, dst, is_out = scene(noise=0.0, outlier_frac=0.3, seed=2)
    fit = find_homography(src, dst, rng=3)
    # only floating-point error remains after LSQ + LM on exact data
    assert corner_error(fit.H, H_TRUE, W, H_IMG) < 1e-6
    assert np.array_equal(fit.inliers, ~is_out)


def test_four_points_give_the_exact_homography():
    src = np.array([[10.0, 20.0], [600.0, 30.0], [580.0, 450.0], [40.0, 400.0]])
    dst = transform_points(H_TRUE, src)
    fit = find_homography(src, dst)
    assert np.allclose(transform_points(fit.H, src), dst, atol=1e-8)
    assert fit.inliers.all()


def test_mirror_homography_is_allowed():
    # a global orientation flip (x -> -x) is a valid homography: only *inconsistent* flips are degenerate
    M = np.array([[-1.0, 0.0, 700.0], [0.0, 1.0, 5.0], [0.0, 0.0, 1.0]]) @ H_TRUE
    src, dst, is_out = scene(H=M, outlier_frac=0.4, seed=4)
    fit = find_homography(src, dst, rng=5)
    assert corner_error(fit.H, M, W, H_IMG) < 1.0
    assert not fit.inliers[is_out].any()


def test_opencv_point_layout_and_caller_order_are_accepted():
    src, dst, _ = scene(seed=6)
    # inliers first, as a quality-sorted match list would be: the SPRT must not be fooled by the order
    order = np.argsort(np.linalg.norm(transform_points(H_TRUE, src) - dst, axis=1))
    fit = find_homography(src[order].reshape(-1, 1, 2), dst[order].reshape(-1, 1, 2), rng=0)
    assert corner_error(fit.H, H_TRUE, W, H_IMG) < 1.0


def test_seeded_runs_are_reproducible():
    src, dst, _ = scene(outlier_frac=0.7, seed=7)
    a = find_homography(src, dst, rng=42)
    b = find_homography(src, dst, rng=np.random.default_rng(42))
    assert np.array_equal(a.H, b.H) and np.array_equal(a.inliers, b.inliers) and a.iterations == b.iterations


def test_adaptive_bound_stops_early_on_clean_data():
    # with no outliers the first non-degenerate sample already gives w = 1, so the bound is 1 iteration
    src, dst, _ = scene(outlier_frac=0.0, noise=0.0, seed=8)
    assert find_homography(src, dst, rng=0, max_iters=5000).iterations <= 3
    # at 80 % outliers it needs thousands (log(0.001) / log(1 - 0.2^4) ~ 4300)
    src, dst, _ = scene(outlier_frac=0.8, seed=8)
    assert find_homography(src, dst, rng=0, max_iters=50_000).iterations > 1000


def test_the_bound_counts_degenerate_draws():
    # 290 of 300 noise-free matches on one line, 10 off it: most 4-point draws hold a collinear triple. Every match is
    # an inlier, so the first regular sample sets the bound to 1 draw; the draws before it count (a draw is
    # all-inlier with probability w^4 whether or not it is degenerate), so the run reports all of them
    rng = np.random.default_rng(3)
    t = rng.uniform(0, 600, 290)
    src = np.concatenate([np.stack([t, 0.5 * t + 40], axis=1), rng.uniform([0, 0], [W - 1, H_IMG - 1], (10, 2))])
    dst = transform_points(H_TRUE, src)
    # P(regular) = P(at most 2 of the 4 on the line) ~ 0.9%, so the first regular draw is rarely the first one
    iterations = [find_homography(src, dst, rng=seed, refine=False).iterations for seed in range(10)]
    assert np.median(iterations) > 10
    fit = find_homography(src, dst, rng=0)
    assert np.allclose(fit.H, H_TRUE / H_TRUE[2, 2], atol=1e-6)


@pytest.mark.parametrize("seed", range(20))
def test_null_vector_matches_a_full_eigendecomposition(seed):
    # a DLT-like 9x9 normal matrix: a small smallest eigenvalue, the others spread over 8 orders of magnitude
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.normal(size=(9, 9)))
    w = np.concatenate([[10.0 ** rng.uniform(-12, -3)], 10.0 ** np.sort(rng.uniform(-2, 6, 8))])
    M = (Q * w) @ Q.T
    h = np.empty(9)
    assert _null_vector(M, h)
    # |cos| of the angle to the exact eigenvector: inverse iteration stops at a step below 1e-13, and the
    # eigenvector itself is determined to about eps * w_max / (w_1 - w_0) <= 1e-8 here
    assert abs(h @ Q[:, 0]) > 1.0 - 1e-12
    assert abs(np.linalg.norm(h) - 1.0) < 1e-12


def test_null_vector_leaves_a_double_null_space_to_the_caller():
    # two zero eigenvalues (e.g. all inliers on a line): the iterates do not settle, the caller decides with Jacobi
    rng = np.random.default_rng(0)
    Q, _ = np.linalg.qr(rng.normal(size=(9, 9)))
    M = (Q * np.array([0.0, 0.0, 1, 2, 3, 4, 5, 6, 7])) @ Q.T
    assert not _null_vector(M, np.empty(9))


def test_lo_and_refinement_do_not_hurt_accuracy():
    # averaged over seeds, the full pipeline is at least as accurate as plain RANSAC + DLT on inliers
    full, plain = [], []
    for seed in range(5):
        src, dst, _ = scene(outlier_frac=0.6, noise=1.0, seed=100 + seed)
        full.append(corner_error(find_homography(src, dst, rng=seed).H, H_TRUE, W, H_IMG))
        p = find_homography(src, dst, rng=seed, local_optimization=False, refine=False)
        plain.append(corner_error(dlt(src[p.inliers], dst[p.inliers]), H_TRUE, W, H_IMG))
    assert np.mean(full) <= np.mean(plain) * 1.05


# -------------------------------------------------------------------------------------------- components


def test_dlt_exact_and_weighted():
    src, dst, _ = scene(outlier_frac=0.0, noise=0.0, seed=9)
    assert corner_error(dlt(src, dst), H_TRUE, W, H_IMG) < 1e-8
    # zero weight removes a corrupted correspondence completely
    dst2 = dst.copy()
    dst2[0] += 100.0
    w = np.ones(len(src))
    w[0] = 0.0
    assert corner_error(dlt(src, dst2, weights=w), H_TRUE, W, H_IMG) < 1e-8


def test_hartley_normalization():
    pts = np.random.default_rng(0).uniform(0, 1000, (50, 2))
    T = hartley_normalization(pts)
    q = pts @ T[:2, :2].T + T[:2, 2]
    assert np.allclose(q.mean(axis=0), 0.0, atol=1e-12)
    assert np.isclose(np.linalg.norm(q, axis=1).mean(), np.sqrt(2.0))


def test_transform_points_round_trip_and_horizon():
    pts = np.random.default_rng(1).uniform(0, 600, (20, 2))
    back = transform_points(np.linalg.inv(H_TRUE), transform_points(H_TRUE, pts))
    assert np.allclose(back, pts, atol=1e-9)
    # a point on the line sent to infinity (w = 0) maps to inf, not NaN
    P = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, -5.0]])
    assert np.isinf(transform_points(P, [[5.0, 1.0]])).all()


def _pts(*xy):
    return np.array(xy, dtype=np.float64)


def test_minimal_sample_degeneracy_checks():
    Hn = np.empty((3, 3))
    square = _pts([-1, -1], [1, -1], [1, 1], [-1, 1])
    assert _minimal_solve(square, square * 2.0, 0, 1, 2, 3, Hn)
    # three collinear points in src
    assert not _minimal_solve(_pts([-1, -1], [0, 0], [1, 1], [-1, 1]), square, 0, 1, 2, 3, Hn)
    # three collinear points in dst
    assert not _minimal_solve(square, _pts([-1, -1], [0, 0], [1, 1], [-1, 1]), 0, 1, 2, 3, Hn)
    # one point moved across the diagonal: the orientations of the triangles disagree (a "twisted" quadrilateral)
    assert not _minimal_solve(square, _pts([-1, -1], [1, -1], [-1, 1], [1, 1]), 0, 1, 2, 3, Hn)
    # a global mirror keeps all orientations consistently flipped: allowed
    assert _minimal_solve(square, square * np.array([-1.0, 1.0]), 0, 1, 2, 3, Hn)


def test_corner_error_metric():
    assert corner_error(H_TRUE, H_TRUE, W, H_IMG) == 0.0
    shifted = np.array([[1.0, 0, 3.0], [0, 1.0, 4.0], [0, 0, 1.0]]) @ H_TRUE
    # a 3-4-5 translation after H moves every mapped corner by exactly 5 px
    assert np.isclose(corner_error(shifted, H_TRUE, W, H_IMG), 5.0)
    assert np.isclose(corner_error(-2.0 * H_TRUE, H_TRUE, W, H_IMG), 0.0)  # scale-invariant
    assert image_corners(3, 2).tolist() == [[0, 0], [2, 0], [2, 1], [0, 1]]
    with pytest.raises(InputError, match="`H_est` must have shape"):
        corner_error(np.eye(2), H_TRUE, W, H_IMG)
    with pytest.raises(InputError, match="`width` must be an integer"):
        corner_error(H_TRUE, H_TRUE, 0, H_IMG)


# ------------------------------------------------------------------------------------------- bad input


@pytest.fixture
def good():
    src, dst, _ = scene(n=20, outlier_frac=0.0, seed=11)
    return src, dst


def test_too_few_points(good):
    src, dst = good
    with pytest.raises(InputError, match="at least 4 correspondences, got 3"):
        find_homography(src[:3], dst[:3])
    with pytest.raises(InputError, match="at least 4 correspondences, got 3"):
        dlt(src[:3], dst[:3])


def test_mismatched_and_bad_shapes(good):
    src, dst = good
    with pytest.raises(InputError, match="same number of points, got 20 and 19"):
        find_homography(src, dst[:19])
    with pytest.raises(InputError, match=r"`src` must have shape \(N, 2\)"):
        find_homography(np.hstack([src, src[:, :1]]), dst)
    with pytest.raises(InputError, match=r"`dst` must have shape \(N, 2\)"):
        find_homography(src, dst.ravel())
    with pytest.raises(InputError, match="`src` must be a numeric"):
        find_homography([["a", "b"]] * 5, dst[:5])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_points(good, bad):
    src, dst = good
    d = dst.copy()
    d[7, 1] = bad
    with pytest.raises(InputError, match=r"`dst` contains NaN or inf \(first at row 7\)"):
        find_homography(src, d)
    s = src.copy()
    s[2, 0] = bad
    with pytest.raises(InputError, match=r"`src` contains NaN or inf \(first at row 2\)"):
        find_homography(s, dst)


def test_all_collinear_points(good):
    src, dst = good
    t = np.linspace(0, 100, 20)
    line = np.stack([t, 2 * t + 1], axis=1)
    with pytest.raises(EstimationError, match="all `src` points are collinear"):
        find_homography(line, dst)
    with pytest.raises(EstimationError, match="all `dst` points are collinear"):
        find_homography(src, line)
    with pytest.raises(EstimationError, match="all `src` points are collinear or coincident"):
        find_homography(np.ones((6, 2)), dst[:6])
    with pytest.raises(EstimationError, match="collinear"):
        dlt(line, dst)


def test_nearly_collinear_points_make_every_sample_degenerate(good):
    src, dst = good
    t = np.linspace(0, 100, 20)
    # 1e-4 px off a line: not rank-deficient as a whole, but every sampled triple is collinear
    line = np.stack([t, 2 * t + 1 + 1e-4 * np.sin(t)], axis=1)
    with pytest.raises(EstimationError, match="degenerate"):
        find_homography(line, dst, max_iters=50)


def test_no_consensus_raises():
    r = np.random.default_rng(12)
    src, dst = r.uniform(0, 500, (400, 2)), r.uniform(0, 500, (400, 2))
    # unrelated point sets: no hypothesis earns support beyond its own 4 points, so nothing is accepted
    with pytest.raises(EstimationError, match="no homography with at least 4 inliers"):
        find_homography(src, dst, threshold=0.5, max_iters=500, rng=0)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"threshold": 0.0}, "`threshold` must be a finite number > 0"),
        ({"threshold": -1.0}, "`threshold` must be a finite number > 0"),
        ({"threshold": float("nan")}, "`threshold` must be a finite number > 0"),
        ({"confidence": 1.0}, r"`confidence` must be in \(0, 1\)"),
        ({"confidence": 0.0}, r"`confidence` must be in \(0, 1\)"),
        ({"max_iters": 0}, "`max_iters` must be an integer >= 1"),
        ({"max_iters": 2.5}, "`max_iters` must be an integer >= 1"),
        ({"lo_multiplier": 0.5}, "`lo_multiplier` must be >= 1"),
        ({"lo_steps": 0}, "`lo_steps` must be an integer >= 1"),
    ],
)
def test_bad_parameters(good, kwargs, message):
    src, dst = good
    with pytest.raises(InputError, match=message):
        find_homography(src, dst, **kwargs)


def test_dlt_bad_weights(good):
    src, dst = good
    with pytest.raises(InputError, match=r"`weights` must have shape \(20,\)"):
        dlt(src, dst, weights=np.ones(3))
    with pytest.raises(InputError, match="`weights` must be finite and non-negative"):
        dlt(src, dst, weights=-np.ones(20))


def test_transform_points_bad_input():
    with pytest.raises(InputError, match=r"`H` must have shape \(3, 3\)"):
        transform_points(np.eye(2), [[0.0, 0.0]])
    with pytest.raises(InputError, match="`H` contains NaN or inf"):
        transform_points(np.full((3, 3), np.nan), [[0.0, 0.0]])
    with pytest.raises(InputError, match=r"`pts` must have shape \(N, 2\)"):
        transform_points(np.eye(3), [1.0, 2.0, 3.0])


# ----------------------------------------------------------------------------------------------- registry


@pytest.mark.parametrize("method", sorted(METHODS))
def test_every_method_recovers_h(method):
    src, dst, is_out = scene(outlier_frac=0.5, seed=13)
    fit = estimate(method, src, dst, threshold=3.0, rng=0)
    # same tolerance as above; every registered estimator must meet it on an easy scene
    assert corner_error(fit.H, H_TRUE, W, H_IMG) < 1.0
    assert fit.H[2, 2] == 1.0 and fit.inliers.dtype == bool
    assert not fit.inliers[is_out].any()


def test_unknown_method():
    with pytest.raises(InputError, match=r"`method` must be one of \['opencv_magsac', 'opencv_ransac', 'ours'\]"):
        estimate("lmeds", np.zeros((4, 2)), np.zeros((4, 2)))


# --------------------------------------------------------------------------------------------- real data


def _data_root() -> Path:
    root = os.environ.get("CVPIPE_DATA")
    if not root or not (Path(root) / "oxford_affine" / "boat" / "H1to2p").exists():
        pytest.skip("real data not available (set CVPIPE_DATA)")
    return Path(root)


def test_oxford_boat_pair_with_sift():
    import cv2

    root = _data_root() / "oxford_affine" / "boat"
    a = cv2.imread(str(root / "img1.pgm"), cv2.IMREAD_GRAYSCALE)
    b = cv2.imread(str(root / "img2.pgm"), cv2.IMREAD_GRAYSCALE)
    H_gt = np.loadtxt(root / "H1to2p")
    sift = cv2.SIFT_create(nfeatures=2000)
    ka, da = sift.detectAndCompute(a, None)
    kb, db = sift.detectAndCompute(b, None)
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(da, db, k=2)
    good = [m for m, n in knn if m.distance < 0.8 * n.distance]
    src = np.float64([ka[m.queryIdx].pt for m in good])
    dst = np.float64([kb[m.trainIdx].pt for m in good])
    fit = find_homography(src, dst, threshold=3.0, rng=0)
    h, w = a.shape
    # the Oxford ground truth is itself good to about 1 px (pixel-origin conventions); 2 px is a clear success
    assert corner_error(fit.H, H_gt, w, h) < 2.0


def test_opencv_methods_are_deterministic_and_ignore_rng():
    # documented in the registry: OpenCV's samplers start from a fixed state, so benchmark repeats differ only in time
    src, dst, _ = scene(outlier_frac=0.6, seed=14)
    for method in ("opencv_ransac", "opencv_magsac"):
        assert np.array_equal(estimate(method, src, dst, rng=0).H, estimate(method, src, dst, rng=123).H)


def test_dlt_rank_deficient_minimal_set():
    # 4 points with 3 collinear: not collinear as a whole, but the homography through them is not unique
    src = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [0.0, 5.0]])
    dst = src * 2.0 + 1.0
    with pytest.raises(EstimationError, match="rank-deficient"):
        dlt(src, dst)


def test_corner_error_more_bad_input():
    with pytest.raises(InputError, match="`H_true` contains NaN or inf"):
        corner_error(H_TRUE, np.full((3, 3), np.inf), W, H_IMG)
    with pytest.raises(InputError, match="`height` must be an integer >= 1"):
        corner_error(H_TRUE, H_TRUE, W, 2.5)
    # a corner sent across the horizon by one H but not the other cannot be compared: inf, not a number
    flip = np.array([[1.0, 0, 0], [0, 1.0, 0], [-2.0 / W, 0, 1.0]])
    assert corner_error(flip, H_TRUE, W, H_IMG) == float("inf")


def test_dlt_exact_on_four_points():
    src = np.array([[10.0, 20.0], [600.0, 30.0], [580.0, 450.0], [40.0, 400.0]])
    dst = transform_points(H_TRUE, src)
    # 8 equations, 8 unknowns: exact up to rounding
    assert np.allclose(transform_points(dlt(src, dst), src), dst, atol=1e-8)


@pytest.mark.parametrize("seed", range(4))
def test_many_to_one_cluster_does_not_win_with_a_collapsed_model(seed):
    """Repetitive texture can match many source points to one destination point (seen with ORB on PCBs). A nearly
    singular H maps them all onto that point with zero error and wins the MSAC cost unless collapsed models are
    rejected; the true H must be found instead (3 px: the inliers carry 1 px noise)."""
    from cvpipe.metrics import corner_error

    rng = np.random.default_rng(seed)
    H_true = np.array([[0.95, -0.04, 40.0], [0.08, 0.98, 35.0], [-4e-5, 1e-5, 1.0]])
    good = rng.uniform(0, 600, (30, 2))
    good_dst = transform_points(H_true, good) + rng.normal(0, 1.0, (30, 2))
    line = np.c_[rng.uniform(50, 600, 24), np.full(24, 53.3)]  # collinear sources across the image ...
    point = np.tile([[524.2, 47.5]], (24, 1))                   # ... all matched to one destination point
    junk = rng.uniform(0, 600, (35, 2)), rng.uniform(0, 600, (35, 2))
    src = np.r_[good, line, junk[0]]
    dst = np.r_[good_dst, point, junk[1]]
    fit = find_homography(src, dst, 3.0, rng=seed)
    assert corner_error(fit.H, H_true, 640, 480) < 3.0
    assert not fit.inliers[30:54].any()


@pytest.mark.parametrize("name", ["cvpipe.geometry", "cvpipe.homography.dlt", "cvpipe.homography.estimate",
                                  "cvpipe.homography.match", "cvpipe.homography.report", "cvpipe.linalg"])
def test_examples_in_docstrings_run(name):
    """The Examples sections of the public homography modules (and the shared geometry) are true."""
    import doctest
    import importlib

    # import_module, not attribute access: cvpipe.homography.estimate is also the name of the function
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0, result


def test_enormous_scale_keeps_h22_one():
    # the unit square onto a square 1e12 wide: H[2, 2] is 7e-13 of |H| in the solver's output, and H / H[2, 2]
    # (diag(1e12, 1e12, 1) plus a shift of 3) is finite, so it is the answer
    src = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [1.0, 1.0]])
    fit = find_homography(src, src * 1e12 + 3.0, threshold=3.0, rng=0, max_iters=500)
    assert fit.H[2, 2] == 1.0
    # the shift of 3 sits beside entries of 1e12, where doubles are 1.2e-4 apart: 1e-3 is a few of those steps
    np.testing.assert_allclose(fit.H, [[1e12, 0, 3], [0, 1e12, 3], [0, 0, 1]], rtol=1e-9, atol=1e-3)
