# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernel of :mod:`cvpipe.logo.match` (compute only; the Python module validates and documents)."""

import numpy as np

from cython.parallel cimport prange


cdef extern from *:
    int __builtin_popcountll(unsigned long long) nogil


cdef inline void _insert(int d, int j, int k, int* od, int* oi) noexcept nogil:
    """Put train row ``j`` at distance ``d`` into the sorted ``k`` nearest (an equal distance stays behind)."""
    cdef int s = k - 2
    while s >= 0 and od[s] > d:
        od[s + 1] = od[s]
        oi[s + 1] = oi[s]
        s = s - 1
    od[s + 1] = d
    oi[s + 1] = j


cdef void _nearest(const unsigned long long* q, const unsigned long long* train, Py_ssize_t m, Py_ssize_t words,
                   int k, int* od, int* oi) noexcept nogil:
    """The ``k`` nearest of the ``m`` train rows (``words`` words each) to the query row ``q`` into ``od``, ``oi``
    (sorted by distance; an equal distance never displaces an earlier row)."""
    cdef Py_ssize_t j, w
    cdef int d, s
    cdef const unsigned long long* t = train
    cdef unsigned long long q0, q1, q2, q3, q4, q5, q6, q7
    for s in range(k):
        od[s] = 1 << 30
        oi[s] = -1
    if words == 4:  # ORB: 32 bytes
        q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
        for j in range(m):
            d = (__builtin_popcountll(q0 ^ t[0]) + __builtin_popcountll(q1 ^ t[1])
                 + __builtin_popcountll(q2 ^ t[2]) + __builtin_popcountll(q3 ^ t[3]))
            t += 4
            if d < od[k - 1]:
                _insert(d, <int>j, k, od, oi)
    elif words == 8:  # AKAZE (61 bytes, padded) and BRISK: 64 bytes
        q0, q1, q2, q3, q4, q5, q6, q7 = q[0], q[1], q[2], q[3], q[4], q[5], q[6], q[7]
        for j in range(m):
            d = (__builtin_popcountll(q0 ^ t[0]) + __builtin_popcountll(q1 ^ t[1])
                 + __builtin_popcountll(q2 ^ t[2]) + __builtin_popcountll(q3 ^ t[3])
                 + __builtin_popcountll(q4 ^ t[4]) + __builtin_popcountll(q5 ^ t[5])
                 + __builtin_popcountll(q6 ^ t[6]) + __builtin_popcountll(q7 ^ t[7]))
            t += 8
            if d < od[k - 1]:
                _insert(d, <int>j, k, od, oi)
    else:
        for j in range(m):
            d = 0
            for w in range(words):
                d = d + __builtin_popcountll(q[w] ^ t[w])
            t += words
            if d < od[k - 1]:
                _insert(d, <int>j, k, od, oi)


def hamming_k_nearest(const unsigned long long[:, ::1] query, const unsigned long long[:, ::1] train, int k,
                      int num_threads):
    """``(dist, idx)``, (n, k) int32 each: the Hamming distances and indices of every query row's ``k`` nearest
    train rows in increasing distance, train order deciding ties (the earlier row first), by exact brute force
    over rows of 8-byte words; ``idx`` -1 (and ``dist`` 2**30) where the train has fewer than ``k`` rows. The
    queries are split over ``num_threads`` OpenMP threads."""
    cdef Py_ssize_t n = query.shape[0], i
    if query.shape[1] != train.shape[1] or k < 1:
        raise ValueError("hamming_k_nearest needs rows of the same width and k >= 1")
    dist = np.empty((n, k), np.int32)
    idx = np.empty((n, k), np.int32)
    cdef int[:, ::1] od = dist
    cdef int[:, ::1] oi = idx
    cdef Py_ssize_t m = train.shape[0], words = train.shape[1]
    if n == 0 or m == 0:
        dist[:] = 1 << 30
        idx[:] = -1
        return dist, idx
    for i in prange(n, nogil=True, num_threads=max(num_threads, 1), schedule="static"):
        _nearest(&query[i, 0], &train[0, 0], m, words, k, &od[i, 0], &oi[i, 0])
    return dist, idx
