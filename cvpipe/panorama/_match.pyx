# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernel of :mod:`cvpipe.panorama.match` (compute only; the Python module validates and documents)."""

import numpy as np

from libc.string cimport memcpy


cdef extern from *:
    int __builtin_popcountll(unsigned long long) nogil


cdef inline unsigned long long _word(const unsigned char* p) noexcept nogil:
    cdef unsigned long long v
    memcpy(&v, p, 8)  # an unaligned 8-byte load
    return v


def hamming_two_nearest(const unsigned char[:, ::1] query, const unsigned char[:, ::1] train):
    """``(dist, idx)``, (n, 2) int32 each: the Hamming distances and indices of every query row's two nearest train
    rows (train order decides ties: the earlier row first), by exact brute force over 32-byte rows (ORB's), each
    compared as four 8-byte words (``popcnt``). Needs 32-byte rows and at least 2 train rows."""
    cdef Py_ssize_t n = query.shape[0], m = train.shape[0], i, j
    cdef int d, d1, d2, i1, i2
    cdef unsigned long long q0, q1, q2, q3
    cdef const unsigned char* qp
    cdef const unsigned char* tp
    dist = np.empty((n, 2), np.int32)
    idx = np.empty((n, 2), np.int32)
    cdef int[:, ::1] od = dist
    cdef int[:, ::1] oi = idx
    if query.shape[1] != 32 or train.shape[1] != 32 or m < 2:
        raise ValueError("hamming_two_nearest needs 32-byte rows and at least 2 train rows")
    with nogil:
        for i in range(n):
            qp = &query[i, 0]
            q0, q1, q2, q3 = _word(qp), _word(qp + 8), _word(qp + 16), _word(qp + 24)
            d1 = d2 = 1 << 30
            i1 = i2 = -1
            tp = &train[0, 0]
            for j in range(m):
                d = (__builtin_popcountll(q0 ^ _word(tp)) + __builtin_popcountll(q1 ^ _word(tp + 8))
                     + __builtin_popcountll(q2 ^ _word(tp + 16)) + __builtin_popcountll(q3 ^ _word(tp + 24)))
                tp += 32
                if d < d2:
                    if d < d1:
                        d2, i2 = d1, i1
                        d1, i1 = d, j
                    else:
                        d2, i2 = d, j
            od[i, 0], od[i, 1], oi[i, 0], oi[i, 1] = d1, d2, i1, i2
    return dist, idx
