# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernels of semi-global matching (:func:`cvpipe.stereo.sgm.disparity_sgm` validates, documents and calls
them): the disparity of the left image (census cost, path aggregation, winner-take-all, left-right check), speckle
removal and the background fill. They only compute: the checks live in the public functions.

Layout of :func:`disparity`. Two sweeps run at once, one per thread: the downward sweep visits the rows top to
bottom and each row left to right, the upward sweep bottom to top and right to left. Each carries the path costs
of its row-to-row directions (three, or the vertical one with 4 paths) in two row buffers and the horizontal path
of its column order in registers, so that a pixel's four (two) paths are summed as they are computed. A row's
matching costs are computed by the first sweep that needs them and kept in the cost volume for the other. The
first sweep to finish a row stores its sum of paths; the second adds its own to it and takes the winner-take-all
of the row at once (the left image's disparity, the right image's in a sliding window of registers, then the
left-right check): the aggregated cost is never stored whole, and every row is finished by one sweep. Memory: the
cost volume (1 byte per pixel and disparity) and the stored sums (2 bytes, about half of each sweep's volume).
Neither sweep ever waits for the other (a row whose costs the other is computing is computed again), so one thread
runs both sweeps one after the other with the same result.

Path costs are int16 in the SIMD helpers of ``_sgm_simd.h`` (16 disparities per AVX2 vector, padded to DP, a
multiple of 16); 16, 32 and 64 disparities have specialised sweeps (fused types) with the vector count a
compile-time constant.
"""

import numpy as np

cimport openmp
from cython.parallel cimport prange
from libc.stdint cimport int16_t, int32_t, uint8_t, uint16_t, uint64_t
from libc.stdlib cimport free, malloc
from libc.string cimport memset, memcpy
from libc.math cimport NAN, fabsf


cdef extern from "_sgm_simd.h" nogil:
    ctypedef struct __m256i:
        pass
    ctypedef struct sgm_nv1:
        pass
    ctypedef struct sgm_nv2:
        pass
    ctypedef struct sgm_nv4:
        pass
    ctypedef struct sgm_nvn:
        pass
    int SGM_BIG
    __m256i _mm256_set1_epi16(int16_t)
    __m256i _mm256_set1_epi8(char)
    __m256i _mm256_add_epi16(__m256i, __m256i)
    __m256i sgm_loadu(const void*)
    void* sgm_alloc(size_t)
    int sgm_load_acquire(const int32_t*)
    void sgm_store_release(int32_t*, int32_t)
    int sgm_fetch_add(int32_t*, int32_t)
    bint sgm_cas(int32_t*, int32_t, int32_t)
    void sgm_load_cost(int nv, const uint8_t* c, __m256i* cv)
    int16_t sgm_step_mem(int nv, const int16_t* prev, __m256i mprev, __m256i jump, const __m256i* cv, __m256i p1,
                         __m256i padbig, int16_t* cur, __m256i* sum, int first)
    __m256i sgm_step_reg(int nv, __m256i* h, __m256i mprev, __m256i jump, const __m256i* cv, __m256i p1,
                         __m256i padbig, __m256i* sum, int first)
    void sgm_store_sum(int nv, const __m256i* sum, uint16_t* out)
    void sgm_prefetch(int nv, const void* p)
    void sgm_add_sum(int nv, __m256i* sum, const uint16_t* other)
    int sgm_argmin(int nv, __m256i* s, int n, int* m)
    void sgm_subpixel(float* disp, const int32_t* bd, const int32_t* m, const int32_t* cm, const int32_t* cp, long n,
                      int nd)
    void sgm_right_update(int nv, __m256i* best, __m256i* arg, const __m256i* s, int ltr)
    void sgm_right_reset(int nv, __m256i* best, __m256i* arg)
    int sgm_right_shift_up(int nv, __m256i* best, __m256i* arg)
    int sgm_right_shift_down(int nv, __m256i* best, __m256i* arg)
    void sgm_reverse(uint8_t* dst, const uint8_t* src, long n)
    void sgm_cost_2px16(int npl, const uint8_t* lnib, long ls, const uint8_t* rnib, long rs, int ad, int nch,
                        const uint8_t* lpx, const uint8_t* rad, long as_, __m256i capv, __m256i multv, uint8_t* out)
    void sgm_census_plane(uint8_t* out, const uint8_t* centre, const uint8_t* const* nb, const int* sh, int cnt, long w)
    void sgm_lr_check(float* disp, const int32_t* disp_r, long w, int t)
    void sgm_deinterleave3(uint8_t* planes, long ps, const uint8_t* row, long n)
    void sgm_cost_px(int dp, int npl, const uint8_t* lnib, long ls, const uint8_t* rnib, long rs, int ad, int nch,
                     const uint8_t* lpx, const uint8_t* rad, long as_, __m256i capv, __m256i multv, uint8_t* out)

ctypedef fused nv_t:
    sgm_nv1
    sgm_nv2
    sgm_nv4
    sgm_nvn


cdef inline int32_t _iabs(int32_t v) noexcept nogil:
    return -v if v < 0 else v


cdef inline int _threads(Py_ssize_t n) noexcept nogil:
    """Threads for ``n`` independent items: OpenMP's count (OMP_NUM_THREADS), at most ``n``."""
    return <int>max(1, min(<Py_ssize_t>openmp.omp_get_max_threads(), n))


# ----------------------------------------------------------------------------------------------- census and cost


cdef void _census_planes(const uint8_t* padded, Py_ssize_t pw, Py_ssize_t y, int ry, int rx, int bits, Py_ssize_t w,
                         uint8_t* planes, Py_ssize_t ps) noexcept nogil:
    """Census signatures of row ``y`` of an image padded by (ry, rx) (row stride ``pw``) as nibble planes: plane p
    (at ``planes + p * ps``, w bytes) holds bits 4p .. 4p + 3. A bit is set where the neighbour is darker than the
    centre, the neighbours in row-major order without the centre, the first in the highest bit (``bits`` - 1)."""
    cdef const uint8_t* centre = padded + (y + ry) * pw + rx
    cdef const uint8_t* nb[4]
    cdef int sh[4]
    cdef int dy, dx, b = bits, cnt = 0
    for dy in range(2 * ry + 1):
        for dx in range(2 * rx + 1):
            if dy == ry and dx == rx:
                continue
            b -= 1
            nb[cnt] = padded + (y + dy) * pw + dx
            sh[cnt] = b & 3
            cnt += 1
            if b & 3 == 0:  # the plane's lowest bit: its neighbours are complete
                sgm_census_plane(planes + (b >> 2) * ps, centre, nb, sh, cnt, w)
                cnt = 0


def census_row(const uint8_t[:, ::1] padded, Py_ssize_t y, int ry, int rx, uint64_t[::1] row):
    """Census signatures (uint64) of row ``y`` of ``padded`` (padded by ``ry``, ``rx``) into ``row``."""
    cdef Py_ssize_t w = row.shape[0], x
    cdef int bits = (2 * ry + 1) * (2 * rx + 1) - 1, p, npl = (bits + 3) // 4
    cdef uint8_t* planes = <uint8_t*>malloc(max(npl, 1) * w)
    if planes == NULL:
        raise MemoryError()
    with nogil:
        _census_planes(&padded[0, 0], padded.shape[1], y, ry, rx, bits, w, planes, w)
        for x in range(w):
            row[x] = 0
            for p in range(npl):
                row[x] |= (<uint64_t>planes[p * w + x]) << (4 * p)
    free(planes)


cdef struct Shared:
    # inputs
    const uint8_t* gray         # (H, W) left grey levels (P2 adaptation)
    const uint8_t* pad_l        # grey images padded by (ry, rx) for the census
    const uint8_t* pad_r
    Py_ssize_t pw
    int ry, rx, bits, npl
    const uint8_t* col_l        # (H, W, nch) images for the absolute-difference term
    const uint8_t* col_r
    int nch
    int ad                      # 0: census only, 1: AD term in SIMD, 2: AD term scalar
    int32_t ad_cap, ad_mult
    uint8_t invalid
    Py_ssize_t h, w, nd, dp
    int nk
    int16_t p1
    const int16_t* p2_lut
    double uniqueness
    bint subpixel
    double lr_max_diff
    bint deferred
    int32_t failed              # set when a thread's buffers could not be allocated
    # shared state
    uint8_t* cost               # (H, W, DP) matching costs
    int32_t* cost_state         # per row: 0 not computed, 1 being computed, 2 in ``cost``
    uint16_t* part0             # (H, W, DP) sums of the downward sweep's paths, rows it finished first
    uint16_t* part1             # ... of the upward sweep's
    int32_t* part_count         # per row: sweeps that stored their sum
    const uint8_t* flat         # (H, W) non-zero where the left census window is flat: rejected
    float* disp                 # (H, W) left disparity, -1 = rejected


cdef struct Local:
    char* block
    int16_t* rows               # 2 x 3 (W + 2) pixels x RS path costs (previous and current row)
    int16_t* mins               # 2 x 3 (W + 2) minima
    uint8_t* gray               # 2 x (W + 2) grey levels (current and previous row)
    uint8_t* crow               # (W, DP) costs of a row computed for this sweep only
    uint8_t* lnib               # census nibble planes of the left row (npl x W)
    uint8_t* rfwd               # ... of the right row, or its colour planes (max(npl, 3) x W)
    uint8_t* rnib               # ... of the right row, reversed (npl x RW)
    uint8_t* rad                # colour planes of the right row, reversed (nch x RW)
    int32_t* disp_r             # (W,) right disparities of the row being finished
    uint16_t* srow              # (W, DP) its aggregated costs (for the parabola and the uniqueness test)
    int32_t* wta                # (4, W) its winners, their costs and their neighbours' costs
    uint16_t* sbuf              # (DP,) the right window's disparities
    __m256i* vecs               # 5 x NV vectors when NV is not a compile-time constant


cdef inline Py_ssize_t _rw(const Shared* sh) noexcept nogil:
    """Row length of the reversed right planes: reads run up to DP + 31 past a pixel."""
    return sh.w + sh.dp + 32


cdef bint _local_init(const Shared* sh, Local* lc) noexcept nogil:
    cdef Py_ssize_t w = sh.w, dp = sh.dp, rs = dp + 16, rw = _rw(sh), n, i
    cdef size_t o_rows = 0
    cdef size_t o_mins = o_rows + _up64(2 * 3 * (w + 2) * rs * sizeof(int16_t))
    cdef size_t o_gray = o_mins + _up64(2 * 3 * (w + 2) * sizeof(int16_t))
    cdef size_t o_crow = o_gray + _up64(2 * (w + 2))
    cdef size_t o_lnib = o_crow + _up64(w * dp)
    cdef size_t o_rfwd = o_lnib + _up64(max(sh.npl, 1) * w)
    cdef size_t o_rnib = o_rfwd + _up64(max(sh.npl, 3) * w)
    cdef size_t o_rad = o_rnib + _up64(max(sh.npl, 1) * rw)
    cdef size_t o_dr = o_rad + _up64(sh.nch * rw)
    cdef size_t o_sr = o_dr + _up64(w * sizeof(int32_t))
    cdef size_t o_wta = o_sr + _up64(w * dp * sizeof(uint16_t))
    cdef size_t o_sb = o_wta + _up64(4 * w * sizeof(int32_t))
    cdef size_t o_vec = o_sb + _up64(dp * sizeof(uint16_t))
    cdef size_t total = o_vec + _up64(5 * (dp // 16) * 32)
    lc.block = <char*>sgm_alloc(total)
    if lc.block == NULL:
        return False
    lc.rows = <int16_t*>(lc.block + o_rows)
    lc.mins = <int16_t*>(lc.block + o_mins)
    lc.gray = <uint8_t*>(lc.block + o_gray)
    lc.crow = <uint8_t*>(lc.block + o_crow)
    lc.lnib = <uint8_t*>(lc.block + o_lnib)
    lc.rfwd = <uint8_t*>(lc.block + o_rfwd)
    lc.rnib = <uint8_t*>(lc.block + o_rnib)
    lc.rad = <uint8_t*>(lc.block + o_rad)
    lc.disp_r = <int32_t*>(lc.block + o_dr)
    lc.srow = <uint16_t*>(lc.block + o_sr)
    lc.wta = <int32_t*>(lc.block + o_wta)
    lc.sbuf = <uint16_t*>(lc.block + o_sb)
    lc.vecs = <__m256i*>(lc.block + o_vec)
    n = 2 * 3 * (w + 2) * rs
    for i in range(n):
        lc.rows[i] = SGM_BIG
    memset(lc.rnib, 0, max(sh.npl, 1) * rw)
    memset(lc.rad, 0, sh.nch * rw)
    return True


cdef inline size_t _up64(size_t n) noexcept nogil:
    return (n + 63) // 64 * 64


cdef inline int _nv(nv_t* tag, const Shared* sh) noexcept nogil:
    if nv_t is sgm_nv1:
        return 1
    elif nv_t is sgm_nv2:
        return 2
    elif nv_t is sgm_nv4:
        return 4
    else:
        return <int>(sh.dp // 16)


cdef void _cost_row(nv_t* tag, const Shared* sh, Local* lc, Py_ssize_t y, uint8_t* out) noexcept nogil:
    """Matching costs of row ``y`` into ``out`` (W, DP): census Hamming distance + (min(sum_c |L_c - R_c|, ad_cap)
    * ad_mult) >> 16, and ``invalid`` where x - d < 0. The right row's planes are reversed, so that the candidates
    x - d, d = 0, 1, ... of a pixel are consecutive forward."""
    cdef Py_ssize_t w = sh.w, dp = sh.dp, nd = sh.nd, rw = _rw(sh), x, i, d, base
    cdef int npl = sh.npl, nch = sh.nch, c, p
    cdef uint8_t* fwd = lc.rfwd
    cdef const uint8_t* cr = sh.col_r + y * w * nch
    cdef const uint8_t* cl
    cdef uint8_t* o
    cdef int32_t ad
    cdef __m256i capv = _mm256_set1_epi8(<char>min(sh.ad_cap, 255))
    cdef __m256i multv = _mm256_set1_epi16(<int16_t>sh.ad_mult)
    _census_planes(sh.pad_l, sh.pw, y, sh.ry, sh.rx, sh.bits, w, lc.lnib, w)
    _census_planes(sh.pad_r, sh.pw, y, sh.ry, sh.rx, sh.bits, w, fwd, w)
    for p in range(npl):
        sgm_reverse(lc.rnib + p * rw, fwd + p * w, w)
    if sh.ad and nch == 3:
        sgm_deinterleave3(fwd, w, cr, w)
        for c in range(3):
            sgm_reverse(lc.rad + c * rw, fwd + c * w, w)
    elif sh.ad:
        sgm_reverse(lc.rad, cr, w)
    cdef int dpc = 16 * _nv(tag, sh)
    x = 0
    if dpc == 16:  # two pixels per vector
        while x + 1 < w:
            base = w - 1 - x
            sgm_cost_2px16(npl, lc.lnib + x, w, lc.rnib + base, rw, sh.ad == 1, nch, sh.col_l + (y * w + x) * nch,
                           lc.rad + base, rw, capv, multv, out + x * dp)
            x += 2
    while x < w:
        base = w - 1 - x
        sgm_cost_px(dpc, npl, lc.lnib + x, w, lc.rnib + base, rw, sh.ad == 1, nch,
                    sh.col_l + (y * w + x) * nch, lc.rad + base, rw, capv, multv, out + x * dp)
        x += 1
    if sh.ad == 2:
        for x in range(w):
            base = w - 1 - x
            cl = sh.col_l + (y * w + x) * nch
            o = out + x * dp
            for d in range(min(nd, x + 1)):
                ad = 0
                for c in range(nch):
                    ad = ad + _iabs(<int32_t>cl[c] - <int32_t>lc.rad[c * rw + base + d])
                o[d] = <uint8_t>(o[d] + <uint8_t>((min(ad, sh.ad_cap) * sh.ad_mult) >> 16))
    for x in range(min(w, nd - 1)):
        memset(out + x * dp + x + 1, sh.invalid, nd - 1 - x)


cdef const uint8_t* _costs_of_row(nv_t* tag, const Shared* sh, Local* lc, Py_ssize_t y) noexcept nogil:
    """Row ``y``'s matching costs: from the cost volume, computed into it when no sweep has claimed the row yet, or
    into the sweep's private row while the other sweep is computing them (no waiting)."""
    cdef uint8_t* row = sh.cost + y * sh.w * sh.dp
    cdef int32_t* state = sh.cost_state + y
    if sgm_load_acquire(state) == 2:
        return row
    if sgm_cas(state, 0, 1):
        _cost_row(tag, sh, lc, y, row)
        sgm_store_release(state, 2)
        return row
    if sgm_load_acquire(state) == 2:
        return row
    _cost_row(tag, sh, lc, y, lc.crow)
    return lc.crow


cdef void _lr_check_row(float* disp, const int32_t* disp_r, Py_ssize_t w, double max_diff) noexcept nogil:
    """Reject (-1) the left disparities of a row that the right image's disparity does not confirm within
    ``max_diff``: the floor and the ceil of the disparity are both tried, and either may agree. The differences
    are integers, so the test is against floor(max_diff)."""
    sgm_lr_check(disp, disp_r, w, <int>min(max_diff, 2147483647.0))


cdef __m256i _padbig(const Shared* sh, int nv) noexcept nogil:
    """SGM_BIG in the lanes of the last vector past the last disparity, 0 elsewhere."""
    cdef int16_t lanes[16]
    cdef int i
    for i in range(16):
        lanes[i] = SGM_BIG if (nv - 1) * 16 + i >= sh.nd else 0
    return sgm_loadu(lanes)


cdef void _finish_stored_row(nv_t* tag, const Shared* sh, Local* lc, Py_ssize_t y) noexcept nogil:
    """Winner-take-all and left-right check of row ``y`` from the two sweeps' stored sums (both sweeps stored it)."""
    cdef int nv = _nv(tag, sh)
    cdef Py_ssize_t w = sh.w, dp = sh.dp, x, j
    cdef __m256i sum_a[4]
    cdef __m256i best_a[4]
    cdef __m256i arg_a[4]
    cdef __m256i* sm = sum_a
    cdef __m256i* best = best_a
    cdef __m256i* arg = arg_a
    cdef const uint16_t* pa = sh.part0 + y * w * dp
    cdef const uint16_t* pb = sh.part1 + y * w * dp
    if nv_t is sgm_nvn:
        sm = lc.vecs
        best = lc.vecs + nv
        arg = lc.vecs + 2 * nv
    sgm_right_reset(nv, best, arg)
    for x in range(w):
        for j in range(nv):
            sm[j] = _mm256_add_epi16(sgm_loadu(pa + x * dp + 16 * j), sgm_loadu(pb + x * dp + 16 * j))
        _finish_px(nv, sh, lc, x, 1, x == w - 1, sm, best, arg)
    _finish_row(nv, sh, lc, y, 1, arg)


cdef inline void _finish_px(int nv, const Shared* sh, Local* lc, Py_ssize_t x, int ltr, bint last, __m256i* s,
                            __m256i* best, __m256i* arg) noexcept nogil:
    """Winner-take-all of pixel x from its aggregated costs ``s``: its winner and cost (the left disparity follows in
    :func:`_finish_row`), and its offers to the right pixels x - d in the window ``best``/``arg`` (pixels visited
    left to right when ``ltr``)."""
    cdef int m, e
    cdef Py_ssize_t xr, w = sh.w
    lc.wta[x] = sgm_argmin(nv, s, <int>min(sh.nd, x + 1), &m)
    lc.wta[w + x] = m
    sgm_right_update(nv, best, arg, s, ltr)
    if ltr:
        if not last:
            e = sgm_right_shift_up(nv, best, arg)
            xr = x - (sh.dp - 1)
            if xr >= 0:
                lc.disp_r[xr] = e
    else:
        lc.disp_r[x] = sgm_right_shift_down(nv, best, arg)
    if sh.subpixel or sh.uniqueness > 0:
        sgm_store_sum(nv, s, lc.srow + x * sh.dp)


cdef void _finish_row(int nv, const Shared* sh, Local* lc, Py_ssize_t y, int ltr, __m256i* arg) noexcept nogil:
    """The row's left disparities from its winners (the uniqueness test, the parabola), the right disparities left
    in the window after a row visited left to right, then the row's left-right check."""
    cdef Py_ssize_t w = sh.w, dp = sh.dp, x, j, bd
    cdef int32_t* wbd = lc.wta
    cdef int32_t* wm = lc.wta + w
    cdef int32_t* wcm = lc.wta + 2 * w
    cdef int32_t* wcp = lc.wta + 3 * w
    cdef float* disp = sh.disp + y * w
    cdef const uint8_t* flat
    cdef const uint16_t* sx
    cdef double limit
    if ltr:
        sgm_store_sum(nv, arg, lc.sbuf)
        for j in range(min(dp, w)):
            lc.disp_r[w - 1 - j] = lc.sbuf[j]
    if sh.subpixel:
        for x in range(w):
            sx = lc.srow + x * dp
            bd = wbd[x]
            wcm[x] = sx[max(bd - 1, 0)]
            wcp[x] = sx[min(bd + 1, dp - 1)]
        sgm_subpixel(disp, wbd, wm, wcm, wcp, w, <int>sh.nd)
    else:
        for x in range(w):
            disp[x] = <float>wbd[x]
    if sh.uniqueness > 0:
        # rejected when a disparity more than one step from the winner costs less than (1 + uniqueness) times it
        for x in range(w):
            sx = lc.srow + x * dp
            bd = wbd[x]
            limit = wm[x] * (1.0 + sh.uniqueness)
            for j in range(min(sh.nd, x + 1)):
                if (j < bd - 1 or j > bd + 1) and sx[j] < limit:
                    disp[x] = -1.0
                    break
    if sh.lr_max_diff >= 0:
        _lr_check_row(disp, lc.disp_r, w, sh.lr_max_diff)
    flat = sh.flat + y * w
    for x in range(w):
        disp[x] = -1.0 if flat[x] else disp[x]


cdef void _sweep(nv_t* tag, Shared* sh, int side) noexcept nogil:
    """The downward (``side`` 0: rows top to bottom, columns left to right) or upward (1: bottom to top, right to
    left) sweep: row-to-row paths (three directions, or the vertical one when ``nk`` = 1) and the horizontal path in
    the sweep's column order; each row's sum is stored, or added to the other sweep's stored sum and finished.

    A path's first pixel is a step from a virtual pixel whose costs and minimum are 0 (it gives L = C): the row
    buffers hold such a pixel beyond both ends of the row and start as zeros, and so do the horizontal path's
    registers at the start of a row, so that no pixel needs a test."""
    cdef int nv = _nv(tag, sh)
    cdef Py_ssize_t h = sh.h, w = sh.w, dp = sh.dp, rs = dp + 16, ws = w + 2, nbuf = 3 * ws * rs
    cdef Py_ssize_t s, y, j, x, x0, k
    cdef int nk = sh.nk, ltr = side == 0, dx = 1 if side == 0 else -1
    cdef Local lc
    cdef __m256i cv_a[4]
    cdef __m256i sum_a[4]
    cdef __m256i h_a[4]
    cdef __m256i best_a[4]
    cdef __m256i arg_a[4]
    cdef __m256i* cv = cv_a
    cdef __m256i* sm = sum_a
    cdef __m256i* hv = h_a
    cdef __m256i* best = best_a
    cdef __m256i* arg = arg_a
    cdef __m256i p1v = _mm256_set1_epi16(sh.p1), padbig = _padbig(sh, nv), hm
    cdef const uint8_t* crow
    cdef uint8_t* gcur        # the row's grey levels at 1 .. W (0 and W + 1: any value)
    cdef uint8_t* gprev       # ... of the previous row of the sweep
    cdef uint8_t* gtmp
    cdef int16_t* prev        # 3 directions x (W + 2) pixels x RS path costs, pixel x at x + 1
    cdef int16_t* cur
    cdef int16_t* mprev       # 3 directions x (W + 2) minima
    cdef int16_t* mcur
    cdef uint16_t* own
    cdef const uint16_t* other
    cdef const int16_t* p2 = sh.p2_lut
    cdef int32_t g
    cdef int16_t mp
    cdef bint fin
    if not _local_init(sh, &lc):
        sgm_store_release(&sh.failed, 1)
        return
    if nv_t is sgm_nvn:
        cv = lc.vecs
        sm = lc.vecs + nv
        hv = lc.vecs + 2 * nv
        best = lc.vecs + 3 * nv
        arg = lc.vecs + 4 * nv
    for j in range(2 * 3 * ws):
        memset(lc.rows + j * rs + 16, 0, dp * sizeof(int16_t))
    memset(lc.mins, 0, 2 * 3 * ws * sizeof(int16_t))
    gcur = lc.gray
    gprev = lc.gray + ws
    memset(lc.gray, 0, 2 * ws)
    x0 = 0 if ltr else w - 1
    for s in range(h):
        y = s if side == 0 else h - 1 - s
        crow = _costs_of_row(tag, sh, &lc, y)
        fin = not sh.deferred and sgm_load_acquire(sh.part_count + y) == 1
        own = (sh.part0 if side == 0 else sh.part1) + y * w * dp
        other = (sh.part1 if side == 0 else sh.part0) + y * w * dp
        prev = lc.rows + (s & 1) * nbuf
        cur = lc.rows + (1 - (s & 1)) * nbuf
        mprev = lc.mins + (s & 1) * 3 * ws
        mcur = lc.mins + (1 - (s & 1)) * 3 * ws
        gtmp = gprev
        gprev = gcur
        gcur = gtmp
        memcpy(gcur + 1, sh.gray + y * w, w)
        if fin:
            sgm_right_reset(nv, best, arg)
        for k in range(nv):
            hv[k] = _mm256_set1_epi16(0)
        hm = _mm256_set1_epi16(0)
        for j in range(w):
            x = x0 + dx * j
            sgm_load_cost(nv, crow + x * dp, cv)
            g = gcur[x + 1]
            if nk == 3:
                # from (x + 1, y - dy), (x, y - dy) and (x - 1, y - dy)
                mp = mprev[x + 2]
                mcur[x + 1] = sgm_step_mem(
                    nv, prev + (x + 2) * rs + 16, _mm256_set1_epi16(mp),
                    _mm256_set1_epi16(<int16_t>(mp + p2[_iabs(g - gprev[x + 2])])), cv, p1v, padbig,
                    cur + (x + 1) * rs + 16, sm, 1)
                mp = mprev[ws + x + 1]
                mcur[ws + x + 1] = sgm_step_mem(
                    nv, prev + (ws + x + 1) * rs + 16, _mm256_set1_epi16(mp),
                    _mm256_set1_epi16(<int16_t>(mp + p2[_iabs(g - gprev[x + 1])])), cv, p1v, padbig,
                    cur + (ws + x + 1) * rs + 16, sm, 0)
                mp = mprev[2 * ws + x]
                mcur[2 * ws + x + 1] = sgm_step_mem(
                    nv, prev + (2 * ws + x) * rs + 16, _mm256_set1_epi16(mp),
                    _mm256_set1_epi16(<int16_t>(mp + p2[_iabs(g - gprev[x])])), cv, p1v, padbig,
                    cur + (2 * ws + x + 1) * rs + 16, sm, 0)
            else:
                mp = mprev[x + 1]
                mcur[x + 1] = sgm_step_mem(
                    nv, prev + (x + 1) * rs + 16, _mm256_set1_epi16(mp),
                    _mm256_set1_epi16(<int16_t>(mp + p2[_iabs(g - gprev[x + 1])])), cv, p1v, padbig,
                    cur + (x + 1) * rs + 16, sm, 1)
            # the horizontal path, from the previous pixel of the row in this sweep's order
            hm = sgm_step_reg(nv, hv, hm, _mm256_add_epi16(hm, _mm256_set1_epi16(p2[_iabs(g - gcur[x + 1 - dx])])),
                              cv, p1v, padbig, sm, 0)
            if fin:
                # the other sweep's sums were stored long ago: fetched 32 pixels ahead
                if j + 32 < w:
                    sgm_prefetch(nv, other + (x + 32 * dx) * dp)
                sgm_add_sum(nv, sm, other + x * dp)
                _finish_px(nv, sh, &lc, x, ltr, j == w - 1, sm, best, arg)
            else:
                sgm_store_sum(nv, sm, own + x * dp)
        if fin:
            _finish_row(nv, sh, &lc, y, ltr, arg)
        elif not sh.deferred and sgm_fetch_add(sh.part_count + y, 1) == 1:
            _finish_stored_row(tag, sh, &lc, y)
    free(lc.block)


cdef void _run_sweep(Shared* sh, int side) noexcept nogil:
    if sh.dp == 16:
        _sweep(<sgm_nv1*>NULL, sh, side)
    elif sh.dp == 32:
        _sweep(<sgm_nv2*>NULL, sh, side)
    elif sh.dp == 64:
        _sweep(<sgm_nv4*>NULL, sh, side)
    else:
        _sweep(<sgm_nvn*>NULL, sh, side)


cdef void _finish_deferred(Shared* sh, Py_ssize_t y0, Py_ssize_t y1) noexcept nogil:
    cdef Local lc
    cdef Py_ssize_t y
    if not _local_init(sh, &lc):
        sgm_store_release(&sh.failed, 1)
        return
    for y in range(y0, y1):
        if sh.dp == 16:
            _finish_stored_row(<sgm_nv1*>NULL, sh, &lc, y)
        elif sh.dp == 32:
            _finish_stored_row(<sgm_nv2*>NULL, sh, &lc, y)
        elif sh.dp == 64:
            _finish_stored_row(<sgm_nv4*>NULL, sh, &lc, y)
        else:
            _finish_stored_row(<sgm_nvn*>NULL, sh, &lc, y)
    free(lc.block)


def disparity(const uint8_t[:, ::1] gray_l, const uint8_t[:, ::1] pad_l, const uint8_t[:, ::1] pad_r, int ry, int rx,
              const uint8_t[:, :, ::1] col_l, const uint8_t[:, :, ::1] col_r, int32_t ad_cap, int32_t ad_mult,
              uint8_t invalid_cost, Py_ssize_t max_disp, int nk, int16_t p1, const int16_t[::1] p2_lut,
              double uniqueness, bint subpixel, double lr_max_diff, const uint8_t[:, ::1] flat, bint deferred=False):
    """Left disparity (H, W) float32, -1 = rejected, of semi-global matching with ``max_disp`` disparities.

    Matching cost: census Hamming distance (``pad_*``: the grey images padded by (ry, rx)) + (min(sum_c |L_c -
    R_c|, ad_cap) * ad_mult) >> 16 over the (H, W, C) images ``col_*`` (``ad_mult`` = 0: none), ``invalid_cost``
    where x - d < 0. Paths: ``nk`` = 3 row-to-row directions per sweep (8 paths) or 1 (4 paths), penalties ``p1``
    and ``p2_lut[|dI|]`` (grey step along the path on ``gray_l``). Then the winner-take-all with the ``uniqueness``
    test, the parabola when ``subpixel``, the left-right check (``lr_max_diff`` < 0: none), and -1 where ``flat``
    (H, W) is non-zero. ``deferred`` stores both sweeps' sums of every row and finishes the rows afterwards (the
    same result; for tests).
    """
    cdef Shared sh
    cdef Py_ssize_t h = gray_l.shape[0], w = gray_l.shape[1], dp = (max_disp + 15) // 16 * 16
    cdef int nch = col_l.shape[2], i, nt
    cost = np.empty(h * w * dp + 64, np.uint8)
    parts = np.empty(2 * h * w * dp + 32, np.uint16)
    states = np.zeros(2 * h, np.int32)
    disp = np.empty((h, w), np.float32)
    cdef uint8_t[::1] cost_v = cost
    cdef uint16_t[::1] parts_v = parts
    cdef int32_t[::1] states_v = states
    cdef float[:, ::1] disp_v = disp
    sh.gray = &gray_l[0, 0]
    sh.pad_l = &pad_l[0, 0]
    sh.pad_r = &pad_r[0, 0]
    sh.pw = pad_l.shape[1]
    sh.ry = ry
    sh.rx = rx
    sh.bits = (2 * ry + 1) * (2 * rx + 1) - 1
    sh.npl = (sh.bits + 3) // 4
    sh.col_l = &col_l[0, 0, 0]
    sh.col_r = &col_r[0, 0, 0]
    sh.nch = nch
    sh.ad = 0 if ad_mult <= 0 else (1 if ad_cap <= 255 and ad_mult < 65536 else 2)
    sh.ad_cap = ad_cap
    sh.ad_mult = ad_mult
    sh.invalid = invalid_cost
    sh.h = h
    sh.w = w
    sh.nd = max_disp
    sh.dp = dp
    sh.nk = nk
    sh.p1 = p1
    sh.p2_lut = &p2_lut[0]
    sh.uniqueness = uniqueness
    sh.subpixel = subpixel
    sh.lr_max_diff = lr_max_diff
    sh.deferred = deferred
    sh.failed = 0
    sh.cost = &cost_v[0]
    sh.cost_state = &states_v[0]
    sh.part0 = &parts_v[0]
    sh.part1 = &parts_v[h * w * dp]
    sh.part_count = &states_v[h]
    sh.flat = &flat[0, 0]
    sh.disp = &disp_v[0, 0]
    nt = _threads(2)
    with nogil:
        for i in prange(2, num_threads=nt, schedule="static", chunksize=1):
            _run_sweep(&sh, i)
        if deferred:
            _finish_deferred(&sh, 0, h)
    if sh.failed:
        raise MemoryError("semi-global matching: no memory for a thread's row buffers")
    return disp


# ----------------------------------------------------------------------------------------------- post-processing


cdef inline int32_t _find_root(int32_t* parent, int32_t i) noexcept nogil:
    """Root of ``i`` in the union-find forest ``parent``, compressing the path on the way."""
    cdef int32_t root = i, nxt
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


def remove_speckles(float[:, ::1] disp, Py_ssize_t max_size, double max_jump, bint nan=False):
    """Reject (-1) 4-connected regions (neighbours within ``max_jump`` px of each other) smaller than ``max_size``
    px, in place; with ``nan``, every rejected pixel (these and the negative ones) becomes NaN instead.

    One pass over the rows labels runs (consecutive accepted pixels of a row, each within ``max_jump`` of its left
    neighbour) and joins each run to the runs above it that it touches within ``max_jump``, in a union-find forest
    whose roots count their regions' pixels; a second pass rejects the pixels of small regions (the regions of a
    flood fill)."""
    cdef Py_ssize_t h = disp.shape[0], w = disp.shape[1], y, x
    run_a = np.empty((h, w), np.int32)
    forest_a = np.empty(2 * max(h * w, 1), np.int32)
    small_a = np.empty(max(h * w, 1), np.uint8)
    cdef int32_t[:, ::1] run_v = run_a
    cdef int32_t[::1] forest_v = forest_a
    cdef uint8_t[::1] small_v = small_a
    cdef int32_t* parent = &forest_v[0]
    cdef int32_t* size = &forest_v[h * w]  # pixels of a region, valid at its root
    cdef uint8_t* small = &small_v[0]
    cdef int32_t* run
    cdef float* row
    cdef int32_t n = 0, r, root, last_r, last_b, b, rb, i, cnt
    cdef float d, left
    with nogil:
        for y in range(h):
            row = &disp[y, 0]
            run = &run_v[y, 0]
            r = -1  # the current run, -1 after a rejected pixel
            root = -1  # its root: only this row's joins of this run can change it while the run lasts
            cnt = 0  # pixels of the run not yet added to its root's size
            left = -1.0
            last_r = -1  # the last pair of runs joined on this row: a run touches the same run above over many pixels
            last_b = -1
            for x in range(w):
                d = row[x]
                if d < 0:
                    run[x] = -1
                    if cnt:
                        size[root] += cnt
                        cnt = 0
                    r = -1
                    left = d
                    continue
                if r < 0 or fabsf(d - left) > max_jump:
                    if cnt:
                        size[root] += cnt
                        cnt = 0
                    r = n
                    root = n
                    parent[n] = n
                    size[n] = 0
                    n += 1
                cnt += 1
                run[x] = r
                left = d
                if y > 0:
                    b = run[x - w]
                    if b >= 0 and not (r == last_r and b == last_b) and fabsf(d - row[x - w]) <= max_jump:
                        last_r = r
                        last_b = b
                        size[root] += cnt
                        cnt = 0
                        rb = _find_root(parent, b)
                        if rb > root:
                            parent[rb] = root
                            size[root] += size[rb]
                        elif rb < root:
                            parent[root] = rb
                            size[rb] += size[root]
                            root = rb
            if cnt:
                size[root] += cnt
        for i in range(n):
            small[i] = size[_find_root(parent, i)] < max_size
        for y in range(h):
            row = &disp[y, 0]
            run = &run_v[y, 0]
            if nan:
                for x in range(w):
                    r = run[x]
                    if r < 0 or small[r]:
                        row[x] = NAN
            else:
                for x in range(w):
                    r = run[x]
                    if r >= 0 and small[r]:
                        row[x] = -1.0


def fill_background(const float[:, ::1] disp):
    """Fill rejected (< 0) pixels from the nearest accepted pixels left and right on the row, taking the smaller
    (background) disparity; returns a filled copy."""
    cdef Py_ssize_t h = disp.shape[0], w = disp.shape[1], y, x, xx
    out_a = np.array(disp, dtype=np.float32, copy=True)
    cdef float[:, ::1] out = out_a
    cdef float left, right
    cdef int nt = _threads(h)
    with nogil:
        for y in prange(h, num_threads=nt, schedule="static"):
            for x in range(w):
                if disp[y, x] >= 0:
                    continue
                left = -1.0
                xx = x - 1
                while xx >= 0:
                    if disp[y, xx] >= 0:
                        left = disp[y, xx]
                        break
                    xx = xx - 1
                right = -1.0
                xx = x + 1
                while xx < w:
                    if disp[y, xx] >= 0:
                        right = disp[y, xx]
                        break
                    xx = xx + 1
                if left >= 0 and right >= 0:
                    out[y, x] = min(left, right)
                elif left >= 0:
                    out[y, x] = left
                elif right >= 0:
                    out[y, x] = right
    return out_a
