# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernels of the Hough transforms: they only compute; the functions of :mod:`cvpipe.hough.transform` and
:mod:`cvpipe.hough.probabilistic` validate the input and document the results.

Rho bins are computed in float32 (``x * tab_cos[n] + y * tab_sin[n]``, products and sum rounded to float32, no fused
multiply-add) and rounded half to even, as OpenCV's ``cvRound`` does.
"""

cimport openmp
from cython.parallel cimport prange
from libc.math cimport atan2, cos, fabs, fabsf, floor, fmod, rintf, sin, M_PI
from libc.stdint cimport uint64_t
from libc.stdlib cimport calloc, free, malloc, realloc
from libc.string cimport memcpy, memset

import numpy as np


cdef inline Py_ssize_t floor_div(Py_ssize_t a, Py_ssize_t b) noexcept nogil:
    """``a // b`` rounded toward minus infinity (b > 0)."""
    cdef Py_ssize_t q = a / b
    if q * b > a:
        q -= 1
    return q


cdef Py_ssize_t count_nonzero(const unsigned char* pixels, Py_ssize_t size) noexcept nogil:
    """Number of nonzero bytes, counted in blocks of up to 65535 into a 16-bit counter (a loop that vectorises into
    16-bit lanes)."""
    cdef Py_ssize_t i, start = 0, stop, count = 0
    cdef unsigned short block_count
    while start < size:
        stop = min(size, start + 65535)
        block_count = 0
        for i in range(start, stop):
            block_count += pixels[i] != 0
        count += block_count
        start = stop
    return count


# ------------------------------------------------------------------------------------------------- edge points


def edge_points(const unsigned char[:, ::1] edges):
    """Coordinates (float32 x, float32 y) of the nonzero pixels of ``edges``, in row-major order."""
    cdef Py_ssize_t h = edges.shape[0], w = edges.shape[1], size = h * w
    cdef Py_ssize_t j, x, y, k = 0, count
    cdef const unsigned char* flat = &edges[0, 0]
    cdef const unsigned char* row
    cdef uint64_t word
    cdef float fy
    with nogil:
        count = count_nonzero(flat, size)
    # one spare element: the branch-free scan below writes one element past the last edge pixel at most
    xs = np.empty(count + 1, np.float32)
    ys = np.empty(count + 1, np.float32)
    cdef float[::1] xv = xs, yv = ys
    cdef float* px = &xv[0]
    cdef float* py = &yv[0]
    with nogil:
        for y in range(h):
            row = flat + y * w
            fy = <float>y
            # eight pixels at a time; a word that holds an edge pixel writes all eight and advances past the edge
            # pixels only (no branch per pixel: the edge pixels of a word follow no pattern)
            x = 0
            while x + 8 <= w:
                memcpy(&word, row + x, 8)
                if word != 0:
                    for j in range(8):
                        px[k] = <float>(x + j)
                        py[k] = fy
                        k += row[x + j] != 0
                x += 8
            while x < w:
                if row[x] != 0:
                    px[k] = <float>x
                    py[k] = fy
                    k += 1
                x += 1
    return xs[:count], ys[:count]


# ------------------------------------------------------------------------------------------------- standard vote
#
# The vote counts, per angle, the rho bins of all edge pixels; the increments of the histogram cells (a load and a
# store each) bound it. Most edge pixels have an 8-neighbour, and the bins of two neighbours differ by at most 2: the
# exact values differ by at most |cos| + |sin| (of the table, per rho step), float32 rounding moves each by less
# than 0.19 on images under 2^20 px a side, and rounding to a bin adds less than 1; so with |cos| + |sin| <= 1.5
# (rho >= ~0.95 px) the difference is under 2.9. The pixels are then voted in pairs of neighbours where possible: a
# pair is one increment, in one of three histograms by the difference d of its bins (d = 0: both in bin b; d = 1:
# bins b and b + 1; d = 2: bins b and b + 2, b the smaller), and the pixels left single go to a fourth. The
# accumulator row is summed from them: the same counts for about half the increments.
#
# Each histogram has two copies used alternately: neighbouring pixels hit the same bin, and with a single copy every
# increment would wait for the previous one.


cdef struct VotePoints:
    const float* xa      # first pixel of each pair (x, y)
    const float* ya
    const float* xb      # second pixel of each pair
    const float* yb
    Py_ssize_t npairs
    const float* xs      # single pixels
    const float* ys
    Py_ssize_t nsingles
    float xmin, xmax, ymin, ymax    # bounding box of all pixels


cdef inline int rho_bin(float x, float y, float c, float s) noexcept nogil:
    """OpenCV's rho bin (before the offset) of the pixel (x, y) at the angle with table entries ``c``, ``s``:
    float32 products and sum, rounded half to even (``cvRound(j * tabCos[n] + i * tabSin[n])``)."""
    return <int>rintf(x * c + y * s)


cdef void vote_rows(const VotePoints* p, const float* tab_cos, const float* tab_sin, int* acc, Py_ssize_t width,
                    Py_ssize_t n_start, Py_ssize_t n_stop, int* pair_keys, int* single_keys,
                    int* hist) noexcept nogil:
    """Fill accumulator rows ``n_start + 1 .. n_stop`` (angles ``n_start .. n_stop - 1``) of ``acc``, ``width``
    cells a row (numrho + 2, with the zero border).

    Scratch: ``pair_keys`` (npairs), ``single_keys`` (nsingles), ``hist`` (8 * (width + 4), zero on entry and left
    zero): two copies of the pair histograms (d = 0, 1, 2, each width + 4 cells), then two of the single one.
    """
    cdef Py_ssize_t stride = width + 4, n, k, r, lo, hi, full
    # the bin offset into the row, and into the histograms, which keep two zero cells below bin 0
    cdef int off = <int>(floor_div(width - 3, 2) + 1), key_off = off + 2, key_stride = <int>stride
    cdef int a, b, b0, b1, b2, b3
    cdef float c, s
    cdef const float* xa = p.xa
    cdef const float* ya = p.ya
    cdef const float* xb = p.xb
    cdef const float* yb = p.yb
    cdef const float* xs = p.xs
    cdef const float* ys = p.ys
    cdef Py_ssize_t npairs = p.npairs, nsingles = p.nsingles
    cdef int* pairs0 = hist
    cdef int* pairs1 = hist + 3 * stride
    cdef int* singles0 = hist + 6 * stride
    cdef int* singles1 = hist + 7 * stride
    cdef int* row
    for n in range(n_start, n_stop):
        c = tab_cos[n]
        s = tab_sin[n]
        # the keys: bin + offset, in the histogram of the pair's bin difference (these loops vectorise)
        for k in range(npairs):
            a = rho_bin(xa[k], ya[k], c, s)
            b = rho_bin(xb[k], yb[k], c, s)
            pair_keys[k] = min(a, b) + key_off + abs(a - b) * key_stride
        for k in range(nsingles):
            single_keys[k] = rho_bin(xs[k], ys[k], c, s) + key_off
        full = npairs - npairs % 2
        for k in range(0, full, 2):
            pairs0[pair_keys[k]] += 1
            pairs1[pair_keys[k + 1]] += 1
        if full < npairs:
            pairs0[pair_keys[full]] += 1
        full = nsingles - nsingles % 2
        for k in range(0, full, 2):
            singles0[single_keys[k]] += 1
            singles1[single_keys[k + 1]] += 1
        if full < nsingles:
            singles0[single_keys[full]] += 1
        # the bins lo .. hi - 1 that the pixels can reach: float32 rounding is monotonic, so those of the corners of
        # their bounding box bound them (on a drawing or a photo, a third of the row or less)
        lo = 0
        hi = 0
        if npairs or nsingles:
            b0 = rho_bin(p.xmin, p.ymin, c, s)
            b1 = rho_bin(p.xmax, p.ymin, c, s)
            b2 = rho_bin(p.xmin, p.ymax, c, s)
            b3 = rho_bin(p.xmax, p.ymax, c, s)
            lo = max(0, min(min(b0, b1), min(b2, b3)) + off)
            hi = min(width, max(max(b0, b1), max(b2, b3)) + off + 1)
            hi = max(lo, hi)
        row = acc + (n + 1) * width
        memset(row, 0, lo * sizeof(int))
        # bin r (histogram cell r + 2) counts the singles in r, twice the d = 0 pairs in r, the d = 1 pairs in r and
        # r - 1, the d = 2 pairs in r and r - 2
        if npairs:
            for r in range(lo, hi):
                row[r] = ((singles0[r + 2] + singles1[r + 2]) + 2 * (pairs0[r + 2] + pairs1[r + 2])
                          + (pairs0[stride + r + 2] + pairs1[stride + r + 2])
                          + (pairs0[stride + r + 1] + pairs1[stride + r + 1])
                          + (pairs0[2 * stride + r + 2] + pairs1[2 * stride + r + 2])
                          + (pairs0[2 * stride + r] + pairs1[2 * stride + r]))
            for k in range(6):
                memset(hist + k * stride + lo + 2, 0, (hi - lo) * sizeof(int))
        else:
            for r in range(lo, hi):
                row[r] = singles0[r + 2] + singles1[r + 2]
        memset(row + hi, 0, (width - hi) * sizeof(int))
        memset(singles0 + lo + 2, 0, (hi - lo) * sizeof(int))
        memset(singles1 + lo + 2, 0, (hi - lo) * sizeof(int))


cdef Py_ssize_t strip_points(const unsigned char* edges, Py_ssize_t h, Py_ssize_t w, float* xs, float* ys,
                             float* box) noexcept nogil:
    """The nonzero pixels of the (h, w) map ``edges`` in strips of two rows, column by column (x, then y within the
    strip): consecutive pixels of this order are often 8-neighbours. ``xs``, ``ys`` need one spare element. Returns
    the number of pixels; ``box`` gets xmin, xmax, ymin, ymax bounds of them (to the word of 8 columns and the
    strip), or zeros when there are none."""
    cdef Py_ssize_t x, y, j, k = 0, xlo = w, xhi = -1, ylo = h, yhi = -1
    cdef const unsigned char* row0
    cdef const unsigned char* row1
    cdef uint64_t word0, word1
    cdef float fy0, fy1
    cdef bint two_rows
    for y in range(0, h, 2):
        row0 = edges + y * w
        # a last strip of one row reads that row twice and keeps none of the copy
        two_rows = y + 1 < h
        row1 = row0 + w if two_rows else row0
        fy0 = <float>y
        fy1 = <float>(y + 1)
        x = 0
        # eight columns at a time; a word pair that holds an edge pixel writes all sixteen and advances past the edge
        # pixels only (no branch per pixel)
        while x + 8 <= w:
            memcpy(&word0, row0 + x, 8)
            memcpy(&word1, row1 + x, 8)
            if (word0 | word1) != 0:
                xlo = min(xlo, x)
                xhi = max(xhi, x + 7)
                ylo = min(ylo, y)
                yhi = max(yhi, y + two_rows)
                for j in range(8):
                    xs[k] = <float>(x + j)
                    ys[k] = fy0
                    k += row0[x + j] != 0
                    xs[k] = <float>(x + j)
                    ys[k] = fy1
                    k += (row1[x + j] != 0) & two_rows
            x += 8
        while x < w:
            if row0[x] != 0 or row1[x] != 0:
                xlo = min(xlo, x)
                xhi = max(xhi, x)
                ylo = min(ylo, y)
                yhi = max(yhi, y + two_rows)
            xs[k] = <float>x
            ys[k] = fy0
            k += row0[x] != 0
            xs[k] = <float>x
            ys[k] = fy1
            k += (row1[x] != 0) & two_rows
            x += 1
    if k == 0:
        xlo = xhi = ylo = yhi = 0
    box[0] = <float>xlo
    box[1] = <float>min(xhi, w - 1)
    box[2] = <float>ylo
    box[3] = <float>min(yhi, h - 1)
    return k


cdef inline unsigned char neighbours(const float* xs, const float* ys, Py_ssize_t k) noexcept nogil:
    """Whether pixels k and k + 1 are 8-neighbours."""
    return (fabsf(xs[k + 1] - xs[k]) <= 1.0) & (fabsf(ys[k + 1] - ys[k]) <= 1.0)


cdef void pair_points(float* xs, float* ys, Py_ssize_t count, float* xa, float* ya, float* xb, float* yb,
                      Py_ssize_t* npairs, Py_ssize_t* nsingles) noexcept nogil:
    """Pair consecutive 8-neighbours of ``xs``, ``ys`` into ``xa``, ``ya``, ``xb``, ``yb``; the pixels left single
    are moved to the front of ``xs``, ``ys``, which hold three spare elements.

    Two rounds at fixed places, so that no step waits for the previous one: pixels 2i and 2i + 1 when they are
    neighbours, then 2i + 1 and 2i + 2 when both are still single (on the samples and York Urban, 79-99 % of the
    pixels end up paired, against 82-99 % for a greedy pass in order).
    """
    cdef Py_ssize_t k, np_ = 0, ns = 0
    # adj_k: pixels k and k + 1 are neighbours (and adj_before, adj_before2 for k - 1 and k - 2)
    cdef unsigned char adj_before2 = 0, adj_before = 0, adj_k, adj_next, adj_next2, first, second, before, after
    # beyond the last pixel, three that are neither its neighbours nor each other's
    xs[count] = -10.0
    xs[count + 1] = -20.0
    xs[count + 2] = -30.0
    ys[count] = ys[count + 1] = ys[count + 2] = 0.0
    adj_k = neighbours(xs, ys, 0)
    # no branch: every candidate is written and only the counts of those kept advance; a single is written at or
    # before the last pixel read (the next steps read from k + 2 on), so in place
    for k in range(0, count, 2):
        adj_next = neighbours(xs, ys, k + 1)
        adj_next2 = neighbours(xs, ys, k + 2)
        first = adj_k                                               # (k, k + 1), first round
        second = adj_next & (1 - adj_k) & (1 - adj_next2)           # (k + 1, k + 2), second round
        before = adj_before & (1 - adj_before2) & (1 - adj_k)       # (k - 1, k), second round
        xa[np_] = xs[k]
        ya[np_] = ys[k]
        xb[np_] = xs[k + 1]
        yb[np_] = ys[k + 1]
        np_ += first
        xa[np_] = xs[k + 1]
        ya[np_] = ys[k + 1]
        xb[np_] = xs[k + 2]
        yb[np_] = ys[k + 2]
        np_ += second
        # pixel k is single when in neither (k - 1, k) nor (k, k + 1); pixel k + 1 (if there is one) when in neither
        # (k, k + 1) nor (k + 1, k + 2)
        after = (1 - first) & (1 - second) & (k + 1 < count)
        xs[ns] = xs[k]
        ys[ns] = ys[k]
        ns += (1 - first) & (1 - before)
        xs[ns] = xs[k + 1]
        ys[ns] = ys[k + 1]
        ns += after
        adj_before2 = adj_k
        adj_before = adj_next
        adj_k = adj_next2
    npairs[0] = np_
    nsingles[0] = ns


def vote(const unsigned char[:, ::1] edges, const float[::1] tab_cos, const float[::1] tab_sin, Py_ssize_t numrho,
         int num_threads, long long min_parallel_votes):
    """Accumulator of the nonzero pixels of ``edges`` with OpenCV's one-cell zero border, shape
    (numangle + 2, numrho + 2), int32.

    With ``num_threads`` > 1 (0 or less: OpenMP's thread count) and at least ``min_parallel_votes`` votes (pixels x
    angles), blocks of angles are voted on that many threads, each block by the first thread free.
    """
    cdef Py_ssize_t h = edges.shape[0], w = edges.shape[1], numangle = tab_cos.shape[0], width = numrho + 2
    cdef Py_ssize_t count, n, chunk, stride = width + 4, half
    cdef int threads = num_threads if num_threads > 0 else openmp.omp_get_max_threads(), tid
    cdef const unsigned char* pixels = &edges[0, 0]
    cdef const float* pc = &tab_cos[0]
    cdef const float* ps = &tab_sin[0]
    cdef float* buffer
    cdef float* xs
    cdef float* ys
    cdef int* keys
    cdef int* hist
    cdef bint pair_up = max(h, w) < (1 << 20)
    cdef float box[4]
    cdef VotePoints points
    acc = np.empty((numangle + 2, width), np.int32)
    cdef int[:, ::1] av = acc
    cdef int* pacc = &av[0, 0]
    # every row between the borders is written whole by the vote
    memset(pacc, 0, width * sizeof(int))
    memset(pacc + (numangle + 1) * width, 0, width * sizeof(int))
    for n in range(numangle):
        pair_up = pair_up and fabsf(pc[n]) + fabsf(ps[n]) <= 1.5
    with nogil:
        count = count_nonzero(pixels, h * w)
    half = count // 2 + 1
    if count * numangle < min_parallel_votes or numangle < 2:
        threads = 1
    threads = max(1, threads)
    # the pixels in strip order (count + 3 each for x and y) and the pairs (4 x half); per thread, the keys and the
    # histograms
    buffer = <float*>malloc((2 * (count + 3) + 4 * half) * sizeof(float))
    keys = <int*>malloc(threads * (half + count + 1) * sizeof(int))
    hist = <int*>calloc(threads * 8 * stride, sizeof(int))
    if buffer == NULL or keys == NULL or hist == NULL:
        free(buffer)
        free(keys)
        free(hist)
        raise MemoryError("no memory for the Hough vote's scratch buffers")
    xs = buffer
    ys = buffer + count + 3
    points.xa = buffer + 2 * (count + 3)
    points.ya = points.xa + half
    points.xb = points.ya + half
    points.yb = points.xb + half
    with nogil:
        strip_points(pixels, h, w, xs, ys, box)
        points.xmin, points.xmax, points.ymin, points.ymax = box[0], box[1], box[2], box[3]
        points.xs = xs
        points.ys = ys
        if pair_up:
            pair_points(xs, ys, count, <float*>points.xa, <float*>points.ya, <float*>points.xb, <float*>points.yb,
                        &points.npairs, &points.nsingles)
        else:
            points.npairs = 0
            points.nsingles = count
    if threads == 1:
        with nogil:
            vote_rows(&points, pc, ps, pacc, width, 0, numangle, keys, keys + half, hist)
    else:
        # each block owns whole accumulator rows, so threads never write to the same cell; guided scheduling hands
        # out shrinking blocks, so a thread that starts late takes fewer and none waits long for another at the end
        for chunk in prange(numangle, nogil=True, num_threads=threads, schedule="guided"):
            tid = openmp.omp_get_thread_num()
            vote_rows(&points, pc, ps, pacc, width, chunk, chunk + 1, keys + tid * (half + count + 1),
                      keys + tid * (half + count + 1) + half, hist + tid * 8 * stride)
    free(buffer)
    free(keys)
    free(hist)
    return acc


# ------------------------------------------------------------------------------------------------- peaks


cdef inline bint is_peak(const int* acc, Py_ssize_t width, Py_ssize_t b) noexcept nogil:
    """OpenCV's line cell at flat index ``b`` (above the threshold): above the lower rho and angle neighbours, at
    least the higher ones."""
    cdef int v = acc[b]
    return v > acc[b - 1] and v >= acc[b + 1] and v > acc[b - width] and v >= acc[b + width]


cdef inline void sift_down(long long* keys, Py_ssize_t root, Py_ssize_t size) noexcept nogil:
    """Move ``keys[root]`` down the max-heap ``keys[:size]`` to its place."""
    cdef Py_ssize_t child
    cdef long long key = keys[root]
    while 2 * root + 1 < size:
        child = 2 * root + 1
        if child + 1 < size and keys[child + 1] > keys[child]:
            child += 1
        if keys[child] <= key:
            break
        keys[root] = keys[child]
        root = child
    keys[root] = key


cdef void heap_sort(long long* keys, Py_ssize_t size) noexcept nogil:
    """Sort ``keys[:size]`` in increasing order, in place."""
    cdef Py_ssize_t k
    cdef long long top
    for k in range(size // 2 - 1, -1, -1):
        sift_down(keys, k, size)
    for k in range(size - 1, 0, -1):
        top = keys[0]
        keys[0] = keys[k]
        keys[k] = top
        sift_down(keys, 0, k)


def peaks(const int[:, ::1] acc, long long threshold):
    """Angle index, rho index and votes (int64 each) of OpenCV's local maxima in ``acc`` (with its zero border),
    sorted like ``hough_cmp_gt``: more votes first, then the smaller flat index (angle-major)."""
    cdef Py_ssize_t na = acc.shape[0] - 2, nr = acc.shape[1] - 2, width = nr + 2
    cdef long long cells = <long long>(na + 2) * width
    cdef Py_ssize_t n, r, r0, r1, k, count = 0, capacity = 256
    cdef const int* a = &acc[0, 0]
    cdef const int* row
    cdef int top
    cdef long long vmax = 0, b
    cdef bint out_of_memory = False
    cdef long long* bases = <long long*>malloc(capacity * sizeof(long long))
    cdef long long* grown
    if bases == NULL:
        raise MemoryError("no memory for the Hough peaks")
    with nogil:
        for n in range(1, na + 1):
            row = a + n * width
            # most angles have no cell above the threshold, and most cells of the others are at or below it: the
            # maximum of the row, then of each block of 32 cells (loops that vectorise), rule them out before the
            # branchy scan of the cells
            top = 0
            for r in range(1, nr + 1):
                top = max(top, row[r])
            if top <= threshold:
                continue
            for r0 in range(1, nr + 1, 32):
                r1 = min(r0 + 32, nr + 1)
                top = 0
                for r in range(r0, r1):
                    top = max(top, row[r])
                if top <= threshold:
                    continue
                for r in range(r0, r1):
                    if row[r] > threshold and is_peak(a, width, n * width + r):
                        if count == capacity:
                            grown = <long long*>realloc(bases, 2 * capacity * sizeof(long long))
                            if grown == NULL:
                                out_of_memory = True
                                break
                            bases = grown
                            capacity *= 2
                        bases[count] = n * width + r
                        count += 1
                        vmax = max(vmax, <long long>row[r])
                if out_of_memory:
                    break
            if out_of_memory:
                break
    if out_of_memory:
        free(bases)
        raise MemoryError("no memory for the Hough peaks")
    out = np.empty((3, count), np.int64)
    cdef long long[:, ::1] ov = out
    with nogil:
        # one int64 key per peak: fewer votes first, then the flat index; the keys are distinct, so their sorted
        # order is unique
        for k in range(count):
            bases[k] = (vmax - a[bases[k]]) * cells + bases[k]
        heap_sort(bases, count)
        for k in range(count):
            b = bases[k] % cells
            ov[0, k] = b // width - 1
            ov[1, k] = b % width - 1
            ov[2, k] = a[b]
    free(bases)
    return out[0], out[1], out[2]


# ------------------------------------------------------------------------------------------------- refinement


cdef inline double py_mod(double x, double m) noexcept nogil:
    """Python's float ``x % m`` for ``m > 0``: the result has the sign of ``m``."""
    cdef double r = fmod(x, m)
    if r != 0.0:
        if r < 0.0:
            r += m
    else:
        r = 0.0
    return r


def refine_fit(const double[::1] xs, const double[::1] ys, const double[::1] rhos, const double[::1] thetas,
               double band, int iterations):
    """Total-least-squares line through the edge pixels within ``band`` px of each line; (rho, theta) float64."""
    cdef Py_ssize_t i, k, j, npts = xs.shape[0], nlines = rhos.shape[0], cnt
    cdef int it
    cdef double rho, theta, c, s, sx, sy, mx, my, cxx, cyy, cxy, dx, dy, phi, new_t, new_r
    cdef const double* px = &xs[0] if npts else NULL
    cdef const double* py = &ys[0] if npts else NULL
    # the indices of the pixels within the band of the current line, in increasing order
    cdef Py_ssize_t* near = <Py_ssize_t*>malloc((npts + 1) * sizeof(Py_ssize_t))
    if near == NULL:
        raise MemoryError("no memory for the line refinement")
    out_r = np.empty(nlines, np.float64)
    out_t = np.empty(nlines, np.float64)
    cdef double[::1] orv = out_r, otv = out_t
    with nogil:
        for i in range(nlines):
            rho = rhos[i]
            theta = thetas[i]
            for it in range(iterations):
                c = cos(theta)
                s = sin(theta)
                # no branch: every index is written, and the count advances past those within the band
                cnt = 0
                for k in range(npts):
                    near[cnt] = k
                    cnt += fabs(px[k] * c + py[k] * s - rho) <= band
                if cnt < 3:
                    break
                # the sums in increasing pixel order
                sx = 0.0
                sy = 0.0
                for j in range(cnt):
                    sx += px[near[j]]
                    sy += py[near[j]]
                mx = sx / <double>cnt
                my = sy / <double>cnt
                cxx = 0.0
                cyy = 0.0
                cxy = 0.0
                for j in range(cnt):
                    dx = px[near[j]] - mx
                    dy = py[near[j]] - my
                    cxx += dx * dx
                    cyy += dy * dy
                    cxy += dx * dy
                # the normal is the eigenvector of the smaller eigenvalue of the scatter matrix
                phi = 0.5 * atan2(2.0 * cxy, cxx - cyy)  # direction of the line
                new_t = phi + 0.5 * M_PI
                # keep the normal on the side of the detected one, then bring theta into [0, pi)
                if cos(new_t - theta) < 0:
                    new_t += M_PI
                new_r = mx * cos(new_t) + my * sin(new_t)
                new_t = py_mod(new_t, 2.0 * M_PI)
                if new_t >= M_PI:
                    new_t -= M_PI
                    new_r = -new_r
                rho = new_r
                theta = new_t
            orv[i] = rho
            otv[i] = theta
    free(near)
    return out_r, out_t


# ------------------------------------------------------------------------------------------------- probabilistic


cdef inline long long walk_coord(long long origin, double sgn, double step, long long t) noexcept nogil:
    """The pixel coordinate ``floor(origin + sgn * step * t + 0.5)`` of step ``t`` along a walk."""
    return <long long>floor(<double>origin + sgn * step * <double>t + 0.5)


def ppht(const unsigned char[:, ::1] edges, const long long[::1] order, const float[::1] tab_cos,
         const float[::1] tab_sin, Py_ssize_t numrho, long long threshold, double min_length, long long max_gap,
         Py_ssize_t max_lines):
    """Progressive probabilistic Hough transform; returns (K, 4) int32 segments x1, y1, x2, y2.

    ``order``: the visiting order, a permutation of the indices of the nonzero pixels of ``edges`` (row-major).
    """
    cdef Py_ssize_t h = edges.shape[0], w = edges.shape[1], numangle = tab_cos.shape[0]
    cdef Py_ssize_t i, j, k, n, q, side, nout = 0, npts = order.shape[0], count, cols
    cdef long long x, y, px, py, best, best_n, gap, t, t_first, v
    cdef long long off = floor_div(numrho - 1, 2), lo = 0, hi = numrho - 1
    cdef long long ends[2][2]
    cdef long long tend[2]
    cdef float fx, fy
    cdef double dx0, dy0, sx, sy, sgn
    cdef bint good
    cdef const unsigned char* pixels = &edges[0, 0]
    cdef const float* tc = &tab_cos[0]
    cdef const float* ts = &tab_sin[0]
    cdef uint64_t word
    # the rho bins of the image corners bound those of every pixel (float32 products and sums are monotonic): a
    # coarse rho can put a corner's bin outside 0 .. numrho - 1, and the accumulator then grows to hold it
    for n in range(numangle):
        for x in (0, w - 1):
            for y in (0, h - 1):
                v = <long long>rintf(<float>x * tc[n] + <float>y * ts[n]) + off
                lo = min(lo, v)
                hi = max(hi, v)
    off -= lo
    cols = hi - lo + 1
    with nogil:
        count = count_nonzero(pixels, h * w)
    acc_arr = np.zeros((numangle, cols), np.int32)
    mask_arr = np.empty((h, w), np.uint8)
    voted_arr = np.zeros((h, w), np.uint8)
    # one spare element each: the branch-free scan below writes one past the last pixel at most
    xs_arr = np.empty(count + 1, np.int64)
    ys_arr = np.empty(count + 1, np.int64)
    out_arr = np.empty((max_lines, 4), np.int32)
    # per angle, the flat index of the cell of rho bin 0 (with the offset), and the cells of the pixel being voted
    cells_arr = np.empty(2 * numangle, np.int64)
    cdef int[:, ::1] acc_view = acc_arr
    cdef unsigned char[:, ::1] mask_view = mask_arr, voted_view = voted_arr
    cdef long long[::1] xs_view = xs_arr, ys_view = ys_arr, cells_view = cells_arr
    cdef int[:, ::1] out = out_arr
    cdef int* acc = &acc_view[0, 0]
    cdef unsigned char* mask = &mask_view[0, 0]
    cdef unsigned char* voted = &voted_view[0, 0]
    cdef long long* xs = &xs_view[0]
    cdef long long* ys = &ys_view[0]
    cdef long long* row_cell = &cells_view[0]
    cdef long long* cells = row_cell + numangle
    with nogil:
        for n in range(numangle):
            row_cell[n] = n * cols + off
        for i in range(h * w):
            mask[i] = pixels[i] != 0
        # the edge pixels in row-major order: eight at a time, and a word that holds one writes all eight and
        # advances past the edge pixels only
        k = 0
        for i in range(h):
            j = 0
            while j + 8 <= w:
                memcpy(&word, pixels + i * w + j, 8)
                if word != 0:
                    for q in range(8):
                        xs[k] = j + q
                        ys[k] = i
                        k += mask[i * w + j + q]
                j += 8
            while j < w:
                xs[k] = j
                ys[k] = i
                k += mask[i * w + j]
                j += 1
        for q in range(npts):
            x = xs[order[q]]
            y = ys[order[q]]
            if mask[y * w + x] == 0:
                continue
            fx = <float>x
            fy = <float>y
            # the cells of the pixel (a loop that vectorises), then its votes
            for n in range(numangle):
                cells[n] = <long long>(<int>rintf(fx * tc[n] + fy * ts[n])) + row_cell[n]
            best = threshold - 1
            best_n = -1
            for n in range(numangle):
                v = acc[cells[n]] + 1
                acc[cells[n]] = <int>v
                if v > best:
                    best = v
                    best_n = n
            voted[y * w + x] = 1
            if best_n < 0:
                continue
            # direction along the line: perpendicular to the normal (cos, sin); step one pixel on the major axis
            dx0 = -<double>ts[best_n]
            dy0 = <double>tc[best_n]
            if fabs(dx0) >= fabs(dy0):
                sx = 1.0 if dx0 > 0 else -1.0
                sy = dy0 / fabs(dx0)
            else:
                sx = dx0 / fabs(dy0)
                sy = 1.0 if dy0 > 0 else -1.0
            for side in range(2):
                sgn = 1.0 if side == 0 else -1.0
                gap = 0
                ends[side][0] = x
                ends[side][1] = y
                tend[side] = 0
                t = 1
                while True:
                    px = walk_coord(x, sgn, sx, t)
                    py = walk_coord(y, sgn, sy, t)
                    if px < 0 or px >= w or py < 0 or py >= h:
                        break
                    if mask[py * w + px] != 0:
                        gap = 0
                        ends[side][0] = px
                        ends[side][1] = py
                        tend[side] = t
                    else:
                        gap += 1
                        if gap > max_gap:
                            break
                    t += 1
            good = max(abs(ends[1][0] - ends[0][0]), abs(ends[1][1] - ends[0][1])) >= min_length
            # clear the pixels of the walked segment; a kept segment also takes back their votes
            for side in range(2):
                sgn = 1.0 if side == 0 else -1.0
                t_first = 0 if side == 0 else 1
                for t in range(t_first, tend[side] + 1):
                    px = walk_coord(x, sgn, sx, t)
                    py = walk_coord(y, sgn, sy, t)
                    if mask[py * w + px] != 0:
                        if good and voted[py * w + px] != 0:
                            fx = <float>px
                            fy = <float>py
                            for n in range(numangle):
                                cells[n] = <long long>(<int>rintf(fx * tc[n] + fy * ts[n])) + row_cell[n]
                            for n in range(numangle):
                                acc[cells[n]] -= 1
                            voted[py * w + px] = 0
                        mask[py * w + px] = 0
            if good:
                out[nout, 0] = <int>ends[0][0]
                out[nout, 1] = <int>ends[0][1]
                out[nout, 2] = <int>ends[1][0]
                out[nout, 3] = <int>ends[1][1]
                nout += 1
                if nout == max_lines:
                    break
    return out_arr[:nout].copy()
