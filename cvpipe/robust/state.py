"""The search state of one RANSAC run: a numpy record with named fields, created here and updated in place by the
compiled kernels (as the C struct ``State`` of ``_core.pxd``, same fields in the same order) and by the driver
:func:`cvpipe.robust.run`."""

from __future__ import annotations

import numpy as np

from . import _search

#: The fields of the state:
#:
#: - ``best_cost``: the score of the best model so far (MSAC cost: lower is better); ``best_inliers``: its inlier
#:   count (after local optimization);
#: - ``bound``: the iterations the adaptive bound asks for; ``iterations``: what the recipe counts against it
#:   (the homography: samples drawn, degenerate ones included; the fundamental matrix: regular samples);
#:   ``attempts``: samples drawn, degenerate ones included; ``degenerate``: samples rejected before scoring;
#:   ``lo_runs``: local optimizations run;
#: - ``sprt_eps``, ``sprt_delta``: the SPRT's inlier share of a good and of a bad model; ``sprt_a``: its decision
#:   threshold (``inf``: no SPRT); ``sprt_tm``: the time of one hypothesis in point verifications;
#: - ``bad_consistent``, ``bad_seen``, ``bad_models``: consistent points and points verified in the models the SPRT
#:   rejected, and how many (they re-estimate ``sprt_delta``).
STATE = np.dtype([
    ("best_cost", np.float64), ("best_inliers", np.int64), ("bound", np.float64), ("iterations", np.int64),
    ("attempts", np.int64), ("degenerate", np.int64), ("lo_runs", np.int64), ("sprt_eps", np.float64),
    ("sprt_delta", np.float64), ("sprt_a", np.float64), ("sprt_tm", np.float64), ("bad_consistent", np.int64),
    ("bad_seen", np.int64), ("bad_models", np.int64),
], align=True)


def new_state(max_iters: int, sprt_eps: float = 0.0, sprt_delta: float = 0.0, sprt_tm: float = 0.0) -> np.ndarray:
    """The state before the first hypothesis: no model, the bound at ``max_iters``.

    Parameters
    ----------
    max_iters : int
        The cap of the bound.
    sprt_eps, sprt_delta : float
        The SPRT's initial inlier share of a good and of a bad model; the default (0, 0) runs no SPRT
        (``sprt_a = inf``: every hypothesis is scored on every point).
    sprt_tm : float
        The time of one hypothesis (sampling, checks, solving) in units of one point verification.

    Returns
    -------
    (1,) array of dtype :data:`STATE`
        Pass it whole to the kernels and to :func:`on_new_best`, :func:`on_rejected`; read a field as
        ``state["iterations"][0]``.
    """
    state = np.empty(1, STATE)
    # one compiled call fills the record (Python field writes cost several microseconds, a noticeable share of a
    # homography's half millisecond)
    _search.start(state, float(max_iters), float(sprt_eps), float(sprt_delta), float(sprt_tm))
    return state
