"""cvpipe.stereo.epipolar: the 8-point and 7-point solvers and the RANSAC on synthetic scenes seen by two known cameras,
and the degeneracy / validation branches."""

import numpy as np
import pytest

from cvpipe.stereo import epipolar
from cvpipe.errors import EstimationError, InputError

from cameras import project, rotation

K = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])


def true_F(R, t):
    """F of cameras K[I|0] and K[R|t]: K^-T [t]x R K^-1, unit norm."""
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    Ki = np.linalg.inv(K)
    F = Ki.T @ tx @ R @ Ki
    return F / np.linalg.norm(F)


def scene(n=200, seed=0, R=None, t=None):
    """Points spread over 4-10 m of depth seen by a left camera and a right one 0.5 m to the side, turned a little."""
    rng = np.random.default_rng(seed)
    X = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-1.5, 1.5, n), rng.uniform(4, 10, n)])
    R = rotation(0.02, -0.03, 0.01) if R is None else R
    t = np.array([-0.5, 0.02, 0.03]) if t is None else t
    return project(X, K), project(X, K, R, t), (true_F(R, t) if np.any(t) else None)


def same_up_to_sign(F, G):
    return min(np.linalg.norm(F - G), np.linalg.norm(F + G))


class TestSolvers:
    def test_eight_point_is_exact_on_noise_free_points(self):
        x1, x2, F = scene()
        est = epipolar.eight_point(x1, x2)
        # exact data: only rounding separates the estimate from the truth (unit-norm matrices)
        assert same_up_to_sign(est, F) < 1e-8
        assert np.linalg.matrix_rank(est, tol=1e-10) == 2

    def test_seven_point_contains_the_true_matrix(self):
        x1, x2, F = scene(n=7, seed=3)
        sols = epipolar.seven_point(x1, x2)
        assert 1 <= len(sols) <= 3
        for G in sols:  # each solution passes through all 7 correspondences and has rank 2
            assert epipolar.sampson_distance(G, x1, x2).max() < 1e-8
            assert abs(np.linalg.det(G)) < 1e-10
        assert min(same_up_to_sign(G, F) for G in sols) < 1e-7

    def test_sampson_distance_of_a_point_moved_off_its_epipolar_line(self):
        x1, x2, F = scene(n=20)
        # moving the right point by 1 px along its epipolar line's normal gives a Sampson distance just under
        # 1 px (the distance is shared between the two points; with the left point fixed it is 1 / sqrt(1 + r),
        # r = |F^T x2|^2 / |F x1|^2 restricted to the first two components)
        l2 = np.column_stack([x1, np.ones(20)]) @ F.T
        n = l2[:, :2] / np.linalg.norm(l2[:, :2], axis=1, keepdims=True)
        d = epipolar.sampson_distance(F, x1, x2 + n)
        assert np.all((d > 0.5) & (d <= 1.0 + 1e-9))
        assert epipolar.sampson_distance(F, x1, x2).max() < 1e-9


class TestRansac:
    def test_recovers_F_with_noise_and_outliers(self):
        x1, x2, F = scene(n=300, seed=1)
        rng = np.random.default_rng(5)
        n1 = x1 + rng.normal(0, 0.3, x1.shape)
        n2 = x2 + rng.normal(0, 0.3, x2.shape)
        out = rng.random(300) < 0.3
        n2[out] = rng.uniform([0, 0], [640, 480], (out.sum(), 2))
        fit = epipolar.find_fundamental(n1, n2, threshold=1.0, rng=0)
        # 0.3 px noise on ~200 inliers: the noise-free correspondences lie within a few hundredths of a pixel of the
        # estimated geometry (measured 0.04 px median); 0.1 px leaves room for other seeds
        assert np.median(epipolar.sampson_distance(fit.F, x1[~out], x2[~out])) < 0.1
        assert np.linalg.matrix_rank(fit.F, tol=1e-9) == 2
        # nearly every true inlier is found (0.3 px noise: a Sampson distance over 1 px is a > 3 sigma event) and
        # a random outlier falls within 1 px of its epipolar line only by chance (~1 px band of a ~600 px image)
        assert fit.inliers[~out].mean() > 0.95
        assert fit.inliers[out].mean() < 0.05
        assert fit.rms < 1.0

    def test_seeded_rng_reproduces_the_result(self):
        x1, x2, _ = scene(n=120, seed=2)
        noisy = x2 + np.random.default_rng(0).normal(0, 0.5, x2.shape)
        a = epipolar.find_fundamental(x1, noisy, rng=7)
        b = epipolar.find_fundamental(x1, noisy, rng=7)
        assert np.array_equal(a.F, b.F) and np.array_equal(a.inliers, b.inliers)

    def test_pure_rotation_has_no_baseline(self):
        x1, x2, _ = scene(n=150, R=rotation(0.02, 0.05, 0.01), t=np.zeros(3))
        with pytest.raises(EstimationError, match="no baseline"):
            epipolar.find_fundamental(x1, x2 + np.random.default_rng(0).normal(0, 0.2, x2.shape), rng=0)

    def test_planar_scene_is_refused(self):
        rng = np.random.default_rng(4)
        X = np.column_stack([rng.uniform(-2, 2, 150), rng.uniform(-1.5, 1.5, 150), np.full(150, 6.0)])
        R, t = rotation(0.02, -0.03, 0.01), np.array([-0.5, 0.02, 0.03])
        with pytest.raises(EstimationError, match="planar"):
            epipolar.find_fundamental(project(X, K), project(X, K, R, t), rng=0)

    def test_too_few_and_collinear(self):
        x1, x2, _ = scene(n=7)
        with pytest.raises(EstimationError, match="at least 8 correspondences"):
            epipolar.find_fundamental(x1, x2)
        line = np.column_stack([np.linspace(0, 600, 30), np.linspace(10, 400, 30)])
        with pytest.raises(EstimationError, match="collinear"):
            epipolar.find_fundamental(line, line + 3.0)

    def test_too_few_inliers(self):
        rng = np.random.default_rng(0)
        a, b = rng.uniform(0, 640, (40, 2)), rng.uniform(0, 640, (40, 2))
        with pytest.raises(EstimationError, match="share too little"):
            epipolar.find_fundamental(a, b, threshold=0.05, min_inliers=30, rng=0)

    @pytest.mark.parametrize("kwargs, message", [
        ({"threshold": 0}, "`threshold` must be"),
        ({"confidence": 1.0}, "`confidence` must be"),
        ({"max_iters": 0}, "`max_iters` must be"),
        ({"min_inliers": 7}, "`min_inliers` must be"),
    ])
    def test_parameter_validation(self, kwargs, message):
        x1, x2, _ = scene(n=20)
        with pytest.raises(InputError, match=message):
            epipolar.find_fundamental(x1, x2, **kwargs)

    def test_shape_validation(self):
        with pytest.raises(InputError, match="shape"):
            epipolar.find_fundamental(np.zeros((10, 3)), np.zeros((10, 3)))
        with pytest.raises(InputError, match="same number"):
            epipolar.find_fundamental(np.zeros((10, 2)), np.zeros((9, 2)))
        with pytest.raises(InputError, match="NaN"):
            epipolar.eight_point(np.full((10, 2), np.nan), np.zeros((10, 2)))
        with pytest.raises(InputError, match="exactly 7"):
            epipolar.seven_point(np.zeros((8, 2)), np.zeros((8, 2)))


def test_final_refit_cut_off_follows_the_noise_scale():
    """The final Tukey refit cuts off at 4.685 sigma of the inliers' Sampson distances (sigma from their median),
    kept within [0.05, 2] x the threshold."""
    from cvpipe.stereo.epipolar import _noise_cutoff

    rng = np.random.default_rng(0)
    d = np.abs(rng.normal(0.0, 0.1, 20_000))  # Sampson distances of Gaussian noise, sigma 0.1 px
    # the median of |N(0, s)| is 0.6745 s: with 20 000 samples the estimate is within ~1.5 % (3 standard errors)
    assert _noise_cutoff(d, 1.0) == pytest.approx(4.685 * 0.1, rel=0.03)
    # outliers beyond the threshold do not move it (only the inliers' median counts)
    assert _noise_cutoff(np.concatenate([d, rng.uniform(5, 50, 5000)]), 1.0) == pytest.approx(4.685 * 0.1, rel=0.03)
    assert _noise_cutoff(np.zeros(100), 1.0) == pytest.approx(0.05)  # exact data: the floor, not 0
    assert _noise_cutoff(np.abs(rng.normal(0.0, 0.8, 1000)), 1.0) == pytest.approx(2.0)  # the cap


def test_sampson_least_squares_refuses_bad_rounds_and_too_few_points():
    p = np.random.default_rng(1).uniform(0, 100, (10, 2))
    with pytest.raises(InputError, match="`rounds`"):
        epipolar.sampson_least_squares(p, p + 1.0, rounds=-1)
    with pytest.raises(EstimationError, match="at least 8"):
        epipolar.sampson_least_squares(p[:7], p[:7] + 1.0)
