# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The robust core's steps for Python callers (compute only; :mod:`cvpipe.robust.sampling`,
:mod:`cvpipe.robust.stopping` and :mod:`cvpipe.robust.state` document and check): the compiled recipes cimport
the same inline steps from ``_core.pxd``."""

import numpy as np

from cpython.buffer cimport PyBuffer_Release

from . cimport _core
from ._core cimport State, state_view


def sample_distinct(const double[:, ::1] u, Py_ssize_t row, Py_ssize_t n, long long[::1] pick,
                    long long[::1] chosen):
    """``len(pick)`` distinct indices in [0, n) into ``pick`` from the uniforms ``u[row]``."""
    _core.sample_distinct(u, row, n, pick, chosen)


def sample4(const double[:, ::1] u, Py_ssize_t row, Py_ssize_t n):
    """Four distinct indices in [0, n) from the uniforms ``u[row, :4]``, as a tuple."""
    return _core.sample4(u, row, n)


def draw_samples(const double[:, ::1] u, Py_ssize_t n):
    """One sample of ``u.shape[1]`` distinct indices in [0, n) per row of ``u``: (rows, k) int64."""
    cdef Py_ssize_t k = u.shape[1], i
    out_arr = np.empty((u.shape[0], k), np.int64)
    cdef long long[:, ::1] out = out_arr
    cdef long long[::1] chosen = np.empty(k, np.int64)
    with nogil:
        for i in range(u.shape[0]):
            _core.sample_distinct(u, i, n, out[i], chosen)
    return out_arr


def iterations_needed(double inliers, double n, Py_ssize_t sample_size, double log1mconf, double max_iters,
                      double sprt_a):
    """Iterations needed to draw, and accept, one all-inlier sample with confidence ``1 - exp(log1mconf)``."""
    return _core.iterations_needed(inliers, n, sample_size, log1mconf, max_iters, sprt_a)


def sprt_threshold(double eps, double delta, double tm):
    """Decision threshold A of the SPRT; ``inf`` unless ``0 < delta < eps < 1``."""
    return _core.sprt_threshold(eps, delta, tm)


def start(state, double max_iters, double sprt_eps, double sprt_delta, double sprt_tm):
    """Fill the (1,) state array as the state before the first hypothesis."""
    cdef Py_buffer view
    _core.start(state_view(state, &view), max_iters, sprt_eps, sprt_delta, sprt_tm)
    PyBuffer_Release(&view)


def on_rejected(state, long long consistent, long long seen, Py_ssize_t n, Py_ssize_t sample_size, double log1mconf,
                double max_iters):
    """Record a model the SPRT rejected after ``seen`` points, ``consistent`` of them consistent with it."""
    cdef Py_buffer view
    _core.on_rejected(state_view(state, &view), consistent, seen, n, sample_size, log1mconf, max_iters)
    PyBuffer_Release(&view)


def on_new_best(state, double cost, long long inliers, long long raw_inliers, Py_ssize_t n, Py_ssize_t sample_size,
                double log1mconf, double max_iters):
    """Record a new so-far-best model."""
    cdef Py_buffer view
    _core.on_new_best(state_view(state, &view), cost, inliers, raw_inliers, n, sample_size, log1mconf, max_iters)
    PyBuffer_Release(&view)
