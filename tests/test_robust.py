"""The robust-estimation core (cvpipe.robust): its sampler, bound, SPRT, state, driver and test against chance,
each checked against its definition; the recipes built on it are tested in test_homography, test_epipolar and
test_logos."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cvpipe import robust
from cvpipe.robust.stopping import on_new_best, on_rejected

_uniform = st.floats(0.0, 1.0, exclude_max=True, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(n=st.integers(4, 10_000), u=st.lists(_uniform, min_size=4, max_size=4))
def test_sample4_draws_the_same_distinct_indices_as_the_general_sampler(n, u):
    uu = np.array([u])
    pick, chosen = np.empty(4, np.int64), np.empty(4, np.int64)
    robust.sample_distinct(uu, 0, n, pick, chosen)
    four = robust.sample4(uu, 0, n)
    assert tuple(int(i) for i in pick) == tuple(int(i) for i in four)
    assert len(set(four)) == 4 and all(0 <= i < n for i in four)


@settings(max_examples=200, deadline=None)
@given(k=st.integers(1, 9), extra=st.integers(0, 50), seed=st.integers(0, 2**32 - 1))
def test_samples_are_distinct_and_in_range(k, extra, seed):
    n = k + extra
    u = np.random.default_rng(seed).random((20, k))
    u[0] = np.nextafter(1.0, 0.0)  # the largest uniform still gives an index below n
    idx = robust.draw_samples(u, n)
    assert idx.shape == (20, k) and idx.min() >= 0 and idx.max() < n
    assert all(len(set(row)) == k for row in idx.tolist())


def test_every_subset_is_equally_likely():
    # 6 choose 3 = 20 subsets, 200 000 samples: 10 000 expected each, standard deviation about 97; 6 deviations
    # (580) fail a sampler that favours any subset by 6 % or more and pass a uniform one except once in 10^8
    idx = robust.draw_samples(np.random.default_rng(0).random((200_000, 3)), 6)
    keys = np.sort(idx, axis=1) @ np.array([36, 6, 1])
    _, counts = np.unique(keys, return_counts=True)
    assert len(counts) == 20
    assert np.abs(counts - 10_000).max() < 580


def test_the_bound_is_the_textbook_number_of_samples():
    # w = 0.5, 4-point samples, confidence 0.99: log(0.01) / log(1 - 0.5^4) = 71.35
    k = robust.iterations_needed(50, 100, 4, math.log1p(-0.99), 10_000, np.inf)
    assert k == pytest.approx(math.log(0.01) / math.log(1 - 0.5 ** 4), rel=1e-12)
    # the SPRT's false rejections (1/A) ask for more samples; all inliers: one; none: the cap
    assert robust.iterations_needed(50, 100, 4, math.log1p(-0.99), 10_000, 10.0) > k
    assert robust.iterations_needed(100, 100, 7, math.log1p(-0.99), 10_000, np.inf) == 1.0
    assert robust.iterations_needed(0, 100, 7, math.log1p(-0.99), 10_000, np.inf) == 10_000.0
    assert robust.iterations_needed(3, 100, 7, math.log1p(-0.99), 10_000, np.inf) == 10_000.0  # capped


def test_the_sprt_threshold_solves_its_equation():
    eps, delta, tm = 0.3, 0.02, 200.0
    a = robust.sprt_threshold(eps, delta, tm)
    c = (1 - delta) * math.log((1 - delta) / (1 - eps)) + delta * math.log(delta / eps)
    assert a == pytest.approx(tm * c + 1 + math.log(a), rel=1e-9)  # A = K + log A, Chum & Matas eq. 2
    assert robust.sprt_threshold(0.0, 0.0, tm) == np.inf  # no SPRT without a good model's share above a bad one's
    assert robust.sprt_threshold(0.1, 0.2, tm) == np.inf


def test_new_state_names_its_fields():
    s = robust.new_state(500, 0.05, 0.01, 200.0)
    assert s.dtype == robust.STATE and s.shape == (1,)
    assert s["bound"][0] == 500 and s["best_cost"][0] == np.inf and s["iterations"][0] == 0
    assert s["sprt_a"][0] == robust.sprt_threshold(0.05, 0.01, 200.0)
    assert robust.new_state(500)["sprt_a"][0] == np.inf


def test_sprt_updates_follow_the_models_seen():
    n, log1mconf = 1000, math.log1p(-0.99)
    s = robust.new_state(10_000, 0.05, 0.01, 200.0)
    # a new best with 300 raw inliers of 1000: the good model's share becomes 0.3, the bound follows 300 inliers
    on_new_best(s, 5.0, 320, 300, n, 4, log1mconf, 10_000)
    assert s["sprt_eps"][0] == 0.3 and s["best_inliers"][0] == 320 and s["best_cost"][0] == 5.0
    assert s["bound"][0] == robust.iterations_needed(320, n, 4, log1mconf, 10_000, s["sprt_a"][0])
    # 20 rejected models with 10 % consistent points: delta is re-estimated and the test redesigned
    for _ in range(20):
        on_rejected(s, 5, 50, n, 4, log1mconf, 10_000)
    assert s["bad_models"][0] == 20 and s["sprt_delta"][0] == pytest.approx(0.1)
    assert s["sprt_a"][0] == robust.sprt_threshold(0.3, 0.1, 200.0)
    # without an SPRT (the default state) a new best leaves it off
    t = robust.new_state(10_000)
    on_new_best(t, 1.0, 500, 500, n, 7, log1mconf, 10_000)
    assert t["sprt_a"][0] == np.inf and t["sprt_eps"][0] == 0.0


def _step_that_counts(state, per_row, bound):
    def step(u):
        state["iterations"] += per_row * len(u)
        state["bound"] = bound
        return len(u)
    return step


def test_run_stops_at_the_bound_and_at_the_attempt_cap():
    s = robust.new_state(1000)
    robust.run(_step_that_counts(s, 1, 300), np.random.default_rng(0), 4, s, max_iters=1000, first_chunk=64,
               largest_chunk=128)
    assert s["iterations"][0] == 320 and s["attempts"][0] == 320  # chunks of 64, 128, 128: stops once >= 300
    # every sample degenerate: no iteration counts, the run ends after 10 * max_iters + 100 samples
    d = robust.new_state(50)
    robust.run(_step_that_counts(d, 0, 50), np.random.default_rng(0), 7, d, max_iters=50, first_chunk=64,
               largest_chunk=64)
    assert d["iterations"][0] == 0 and d["attempts"][0] == 600
    # at least min_iterations, whatever the bound says
    m = robust.new_state(1000)
    robust.run(_step_that_counts(m, 1, 1), np.random.default_rng(0), 7, m, max_iters=1000, first_chunk=64,
               largest_chunk=64, min_iterations=256)
    assert m["iterations"][0] == 256


def _nfa_exact(k, n, p, s):
    """log10 of C(n, s) P[Binomial(n - s, p) >= k - s], in exact rational arithmetic."""
    p = Fraction(p)
    tail = sum(math.comb(n - s, i) * p ** i * (1 - p) ** (n - s - i) for i in range(k - s, n - s + 1))
    exact = math.comb(n, s) * tail
    return math.log10(exact.numerator) - math.log10(exact.denominator)  # exact even far below float's range


@pytest.mark.parametrize("k, n, p, s", [(12, 40, 0.01, 4), (6, 100, 0.01, 4), (30, 60, 0.2, 4), (20, 50, 0.05, 7),
                                        (5, 5, 0.5, 4)])
def test_log10_nfa_is_the_binomial_tail_of_orsa(k, n, p, s):
    assert robust.log10_nfa(k, n, p, s) == pytest.approx(_nfa_exact(k, n, p, s), abs=1e-9)


def test_log10_nfa_bounds_an_underflowing_tail_from_below_by_its_first_term():
    # P = 1e-783 is below float's range: the first term of the tail stands for it; the next terms add a share of
    # about (n - k) / k * p = 3.4e-4 of it, so the bound is within log10(1 + 4e-4) = 1.7e-4 below the exact value
    exact = _nfa_exact(300, 400, 0.001, 4)
    assert exact - 1.8e-4 < robust.log10_nfa(300, 400, 0.001, 4) <= exact


def test_log10_nfa_edges():
    assert robust.log10_nfa(3, 40, 0.1) == np.inf  # fewer inliers than a sample
    assert robust.log10_nfa(4, 40, 0.1) == pytest.approx(math.log10(math.comb(40, 4)))  # the sample alone
    assert robust.log10_nfa(41, 40, 0.1) == -np.inf  # more inliers than matches: no chance model does that
    assert robust.log10_nfa(4000, 5000, 1e-6) < -1000  # the tail underflows: its first term, finite in logs
