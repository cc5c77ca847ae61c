# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The robust core's steps as inline C (compiled into each module that cimports them): minimal samples from
uniforms, the search state of a run and the stopping rules (the bound and the SPRT).

Types: the uniforms ``u`` are float64 (rows, sample size) C-contiguous (``gen.random``); ``pick`` and ``chosen``
int64 (``long long[::1]``); the state is the (1,) array of :data:`cvpipe.robust.STATE`, and ``state_view`` gives its
``State*`` for the stopping rules (a ``State[::1]`` memoryview works too, ``&view[0]``, but its format check costs
about 1 us a call). Counts (``n``, ``consistent``, ``seen``, inlier counts) are integers; ``max_iters`` is a double
(the cap of the bound, compared with doubles).
"""

from cpython.buffer cimport PyBUF_SIMPLE, PyBUF_WRITABLE, PyBuffer_Release, PyObject_GetBuffer
from libc.math cimport fabs, log, log1p, INFINITY


ctypedef struct State:
    # the fields and their order of cvpipe.robust.state.STATE (all 8 bytes: no padding)
    double best_cost
    long long best_inliers
    double bound
    long long iterations
    long long attempts
    long long degenerate
    long long lo_runs
    double sprt_eps
    double sprt_delta
    double sprt_a
    double sprt_tm
    long long bad_consistent
    long long bad_seen
    long long bad_models


cdef inline State* state_view(object state, Py_buffer* view) except NULL:
    """The ``State`` of the (1,) :data:`cvpipe.robust.STATE` array ``state``, through a writable buffer ``view``
    that the caller releases (``PyBuffer_Release(view)``) when done. Only the size is checked (a ``State[::1]``
    memoryview would parse the record's format, about 1 us a call)."""
    PyObject_GetBuffer(state, view, PyBUF_SIMPLE | PyBUF_WRITABLE)
    if view.len != sizeof(State):
        PyBuffer_Release(view)
        raise ValueError(f"the state must be a (1,) array of cvpipe.robust.STATE ({sizeof(State)} bytes), "
                         f"got {view.len} bytes")
    return <State*>view.buf


cdef inline void sample_distinct(const double[:, ::1] u, Py_ssize_t row, Py_ssize_t n, long long[::1] pick,
                                 long long[::1] chosen) noexcept nogil:
    """``len(pick)`` distinct indices in [0, n) into ``pick`` from as many uniforms ``u[row]`` in [0, 1).

    ``chosen`` is scratch of the same length (the indices chosen so far, kept sorted). ``n >= len(pick)``.
    """
    cdef Py_ssize_t j, t, i
    cdef long long r, top
    for j in range(pick.shape[0]):
        r = <long long>(u[row, j] * <double>(n - j))
        top = n - j - 1
        if top < r:
            r = top
        t = 0
        while t < j and r >= chosen[t]:
            r += 1
            t += 1
        for i in range(j, t, -1):
            chosen[i] = chosen[i - 1]
        chosen[t] = r
        pick[j] = r


cdef inline (long long, long long, long long, long long) sample4(const double[:, ::1] u, Py_ssize_t row,
                                                                 Py_ssize_t n) noexcept nogil:
    """Four distinct indices in [0, n) from the uniforms ``u[row, :4]``: :func:`sample_distinct` for a sample of
    4. ``n >= 4``."""
    cdef long long a = <long long>(u[row, 0] * <double>n)
    cdef long long b = <long long>(u[row, 1] * <double>(n - 1))
    cdef long long c = <long long>(u[row, 2] * <double>(n - 2))
    cdef long long d = <long long>(u[row, 3] * <double>(n - 3))
    cdef long long lo, hi, x0, x1, x2
    if a > n - 1:
        a = n - 1
    if b > n - 2:
        b = n - 2
    if c > n - 3:
        c = n - 3
    if d > n - 4:
        d = n - 4
    if b >= a:
        b += 1
    lo = a if a < b else b
    hi = b if a < b else a
    if c >= lo:
        c += 1
    if c >= hi:
        c += 1
    x0 = lo if lo < c else c
    x2 = c if hi < c else hi
    x1 = lo + hi + c - x0 - x2
    if d >= x0:
        d += 1
    if d >= x1:
        d += 1
    if d >= x2:
        d += 1
    return a, b, c, d


cdef inline double iterations_needed(double inliers, double n, Py_ssize_t sample_size, double log1mconf,
                                     double max_iters, double sprt_a) noexcept nogil:
    """Iterations needed to draw, and accept, one all-inlier sample with confidence ``1 - exp(log1mconf)``.

    An all-inlier sample is drawn with probability ``w^sample_size`` (``w = inliers / n``) and survives the SPRT with
    probability about ``1 - 1/sprt_a`` (``sprt_a = inf``: no SPRT). At most ``max_iters``; not rounded.
    """
    cdef double w = inliers / n
    cdef double p = 1.0, den, k
    cdef Py_ssize_t i
    for i in range(sample_size):
        p *= w
    p *= 1.0 - 1.0 / sprt_a
    if p >= 1.0:
        return 1.0
    if p <= 0.0:
        return max_iters
    den = log1p(-p)
    if den >= 0.0:
        return max_iters
    k = log1mconf / den
    if k >= max_iters:
        return max_iters
    return k


cdef inline double sprt_threshold(double eps, double delta, double tm) noexcept nogil:
    """Decision threshold A of the SPRT (Chum & Matas 2008, eq. 2), ``A = K + log A`` by iteration; ``inf`` (no
    SPRT) unless ``0 < delta < eps < 1``. One model per minimal sample."""
    cdef double c, k, a
    cdef int i
    if not (0.0 < delta and delta < eps and eps < 1.0):
        return INFINITY
    c = (1.0 - delta) * log((1.0 - delta) / (1.0 - eps)) + delta * log(delta / eps)
    k = tm * c / 1.0 + 1.0
    a = k
    for i in range(20):
        a = k + log(a)
    return a


cdef inline void start(State* s, double max_iters, double sprt_eps, double sprt_delta, double sprt_tm) noexcept nogil:
    """The state before the first hypothesis (see :func:`cvpipe.robust.new_state`)."""
    s.best_cost = INFINITY
    s.best_inliers = 0
    s.bound = max_iters
    s.iterations = 0
    s.attempts = 0
    s.degenerate = 0
    s.lo_runs = 0
    s.sprt_eps = sprt_eps
    s.sprt_delta = sprt_delta
    s.sprt_tm = sprt_tm
    s.sprt_a = sprt_threshold(sprt_eps, sprt_delta, sprt_tm)
    s.bad_consistent = 0
    s.bad_seen = 0
    s.bad_models = 0


cdef inline void on_rejected(State* s, long long consistent, long long seen, Py_ssize_t n, Py_ssize_t sample_size,
                             double log1mconf, double max_iters) noexcept nogil:
    """Record a model the SPRT rejected after ``seen`` points, ``consistent`` of them consistent with it.

    The consistent share of the rejected models estimates ``sprt_delta``; once 20 of them are in and it drifted by
    more than 10 %, the test is redesigned and the bound recomputed.
    """
    cdef double d
    s.bad_consistent += consistent
    s.bad_seen += seen
    s.bad_models += 1
    if s.bad_models >= 20 and s.bad_seen > 0:
        # max(), min() as Python's: the first argument unless the second is strictly greater (smaller)
        d = <double>s.bad_consistent / <double>s.bad_seen
        if 1e-4 > d:
            d = 1e-4
        if fabs(d - s.sprt_delta) > 0.1 * s.sprt_delta:
            s.sprt_delta = 0.5 * s.sprt_eps if 0.5 * s.sprt_eps < d else d
            s.sprt_a = sprt_threshold(s.sprt_eps, s.sprt_delta, s.sprt_tm)
            s.bound = iterations_needed(<double>s.best_inliers, <double>n, sample_size, log1mconf, max_iters,
                                        s.sprt_a)


cdef inline void on_new_best(State* s, double cost, long long inliers, long long raw_inliers, Py_ssize_t n,
                             Py_ssize_t sample_size, double log1mconf, double max_iters) noexcept nogil:
    """Record a new so-far-best model: its ``cost``, its ``inliers`` (after local optimization) and ``raw_inliers``
    (of the minimal model, which estimates ``sprt_eps``); the bound follows the most inliers seen."""
    cdef double eps = <double>raw_inliers / <double>n
    s.best_cost = cost
    if eps > s.sprt_eps and s.sprt_a < INFINITY:
        s.sprt_eps = eps
        if 0.5 * s.sprt_eps < s.sprt_delta:
            s.sprt_delta = 0.5 * s.sprt_eps
        s.sprt_a = sprt_threshold(s.sprt_eps, s.sprt_delta, s.sprt_tm)
    if inliers > s.best_inliers:
        s.best_inliers = inliers
    s.bound = iterations_needed(<double>s.best_inliers, <double>n, sample_size, log1mconf, max_iters, s.sprt_a)
