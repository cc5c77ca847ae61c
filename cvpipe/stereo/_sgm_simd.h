/* AVX2 helpers of the semi-global matching kernels (cvpipe/stereo/_sgm.pyx).
 *
 * A pixel's disparities are padded to DP, a multiple of 16: path costs are int16, 16 disparities per vector, NV =
 * DP / 16 vectors per pixel. Path costs stay <= 255 + P2 <= 4351 and lanes past the last disparity hold SGM_BIG, so
 * signed and unsigned 16-bit minima agree and nothing overflows. Sums of path costs are uint16 (at most 8 * 4351).
 * Disparity indices are int16 lanes too (at most 32767 disparities). Every function is inlined into its caller,
 * where NV is a compile-time constant for 16, 32 and 64 disparities.
 */
#ifndef CVPIPE_SGM_SIMD_H
#define CVPIPE_SGM_SIMD_H

#include <immintrin.h>
#include <stdint.h>
#include <stdlib.h>

#define SGM_INLINE static inline __attribute__((always_inline))
#define SGM_BIG 16000

/* specialisation tags of the sweep: 1, 2 or 4 vectors per pixel, or any number */
typedef struct { char unused; } sgm_nv1;
typedef struct { char unused; } sgm_nv2;
typedef struct { char unused; } sgm_nv4;
typedef struct { char unused; } sgm_nvn;

SGM_INLINE void *sgm_alloc(size_t bytes) { return aligned_alloc(64, (bytes + 63) / 64 * 64); }

SGM_INLINE int sgm_load_acquire(const int32_t *p) { return __atomic_load_n(p, __ATOMIC_ACQUIRE); }
SGM_INLINE void sgm_store_release(int32_t *p, int32_t v) { __atomic_store_n(p, v, __ATOMIC_RELEASE); }
SGM_INLINE int sgm_fetch_add(int32_t *p, int32_t v) { return __atomic_fetch_add(p, v, __ATOMIC_ACQ_REL); }
SGM_INLINE int sgm_cas(int32_t *p, int32_t expected, int32_t desired)
{
    return __atomic_compare_exchange_n(p, &expected, desired, 0, __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE);
}

SGM_INLINE __m256i sgm_loadu(const void *p) { return _mm256_loadu_si256((const __m256i *)p); }

/* lane i <- cur[i - 1], lane 0 <- prev[15] */
SGM_INLINE __m256i sgm_shift_up(__m256i cur, __m256i prev)
{
    return _mm256_alignr_epi8(cur, _mm256_permute2x128_si256(prev, cur, 0x21), 14);
}

/* lane i <- cur[i + 1], lane 15 <- next[0] */
SGM_INLINE __m256i sgm_shift_down(__m256i cur, __m256i next)
{
    return _mm256_alignr_epi8(_mm256_permute2x128_si256(cur, next, 0x21), cur, 2);
}

/* the unsigned minimum of the 16 lanes, in every lane */
SGM_INLINE __m256i sgm_hmin(__m256i m)
{
    __m128i t = _mm_min_epu16(_mm256_castsi256_si128(m), _mm256_extracti128_si256(m, 1));
    return _mm256_broadcastw_epi16(_mm_minpos_epu16(t));
}

/* the unsigned minimum of the 16 lanes */
SGM_INLINE int16_t sgm_hmin_scalar(__m256i m)
{
    __m128i t = _mm_min_epu16(_mm256_castsi256_si128(m), _mm256_extracti128_si256(m, 1));
    return (int16_t)_mm_cvtsi128_si32(_mm_minpos_epu16(t));
}

/* the pixel's matching costs as int16 */
SGM_INLINE void sgm_load_cost(int nv, const uint8_t *c, __m256i *cv)
{
    for (int k = 0; k < nv; k++)
        cv[k] = _mm256_cvtepu8_epi16(_mm_loadu_si128((const __m128i *)(c + 16 * k)));
}

/* one step of a path from the previous pixel's costs ``prev`` (memory, SGM_BIG at prev[-1] and prev[DP]) to ``cur``:
 * L(d) = C(d) + min(Lp(d), Lp(d - 1) + P1, Lp(d + 1) + P1, jump) - mprev, jump = mprev + P2'. Adds L to ``sum``
 * (sets it when ``first``); returns min_d L */
SGM_INLINE int16_t sgm_step_mem(int nv, const int16_t *prev, __m256i mprev, __m256i jump, const __m256i *cv,
                                __m256i p1, __m256i padbig, int16_t *cur, __m256i *sum, int first)
{
    __m256i mn = _mm256_setzero_si256();
    for (int k = 0; k < nv; k++) {
        __m256i a = _mm256_loadu_si256((const __m256i *)(prev + 16 * k - 1));
        __m256i b = _mm256_load_si256((const __m256i *)(prev + 16 * k));
        __m256i c = _mm256_loadu_si256((const __m256i *)(prev + 16 * k + 1));
        __m256i v = _mm256_min_epi16(_mm256_add_epi16(_mm256_min_epi16(a, c), p1), b);
        __m256i L = _mm256_sub_epi16(_mm256_add_epi16(cv[k], _mm256_min_epi16(v, jump)), mprev);
        if (k == nv - 1)
            L = _mm256_max_epi16(L, padbig);
        _mm256_store_si256((__m256i *)(cur + 16 * k), L);
        sum[k] = first ? L : _mm256_add_epi16(sum[k], L);
        mn = k ? _mm256_min_epi16(mn, L) : L;
    }
    return sgm_hmin_scalar(mn);
}

/* the same step with the path's costs in ``h`` (updated in place; neighbours shifted in registers) */
SGM_INLINE __m256i sgm_step_reg(int nv, __m256i *h, __m256i mprev, __m256i jump, const __m256i *cv, __m256i p1,
                                __m256i padbig, __m256i *sum, int first)
{
    const __m256i big = _mm256_set1_epi16(SGM_BIG);
    __m256i before = big, mn = _mm256_setzero_si256();
    for (int k = 0; k < nv; k++) {
        __m256i b = h[k];
        __m256i a = sgm_shift_up(b, before);
        __m256i c = sgm_shift_down(b, k + 1 < nv ? h[k + 1] : big);
        before = b;
        __m256i v = _mm256_min_epi16(_mm256_add_epi16(_mm256_min_epi16(a, c), p1), b);
        __m256i L = _mm256_sub_epi16(_mm256_add_epi16(cv[k], _mm256_min_epi16(v, jump)), mprev);
        if (k == nv - 1)
            L = _mm256_max_epi16(L, padbig);
        h[k] = L;
        sum[k] = first ? L : _mm256_add_epi16(sum[k], L);
        mn = k ? _mm256_min_epi16(mn, L) : L;
    }
    return sgm_hmin(mn);
}

SGM_INLINE void sgm_store_sum(int nv, const __m256i *sum, uint16_t *out)
{
    for (int k = 0; k < nv; k++)
        _mm256_storeu_si256((__m256i *)(out + 16 * k), sum[k]);
}

/* the cache lines of a pixel's DP uint16 sums */
SGM_INLINE void sgm_prefetch(int nv, const void *p)
{
    for (int k = 0; k < nv; k += 2)
        _mm_prefetch((const char *)p + 32 * k, _MM_HINT_T0);
}

SGM_INLINE void sgm_add_sum(int nv, __m256i *sum, const uint16_t *other)
{
    for (int k = 0; k < nv; k++)
        sum[k] = _mm256_add_epi16(sum[k], _mm256_loadu_si256((const __m256i *)(other + 16 * k)));
}

/* Winner of a pixel from its aggregated costs ``s``: 65535 written past the ``n`` candidates (into ``s`` itself),
 * returns the first least-cost disparity and its cost in ``*m`` */
SGM_INLINE int sgm_argmin(int nv, __m256i *s, int n, int *m)
{
    const __m256i iota = _mm256_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const __m256i last = _mm256_set1_epi16((int16_t)(n - 1));
    __m256i mn = _mm256_setzero_si256();
    for (int k = 0; k < nv; k++) {
        __m256i past = _mm256_cmpgt_epi16(_mm256_add_epi16(iota, _mm256_set1_epi16((int16_t)(16 * k))), last);
        s[k] = _mm256_or_si256(s[k], past);
        mn = k ? _mm256_min_epu16(mn, s[k]) : s[k];
    }
    __m256i mb = sgm_hmin(mn);
    *m = _mm256_cvtsi256_si32(mb) & 0xFFFF;
    /* 2 mask bits per lane, 32 lanes per 64-bit word: the first set bit without a branch for up to 64 lanes */
    uint64_t lo = (uint32_t)_mm256_movemask_epi8(_mm256_cmpeq_epi16(s[0], mb));
    if (nv == 1)
        return __builtin_ctzll(lo) >> 1;
    lo |= (uint64_t)(uint32_t)_mm256_movemask_epi8(_mm256_cmpeq_epi16(s[1], mb)) << 32;
    if (nv == 2)
        return __builtin_ctzll(lo) >> 1;
    if (nv == 4) {
        uint64_t hi = (uint32_t)_mm256_movemask_epi8(_mm256_cmpeq_epi16(s[2], mb));
        hi |= (uint64_t)(uint32_t)_mm256_movemask_epi8(_mm256_cmpeq_epi16(s[3], mb)) << 32;
        int a = __builtin_ctzll(lo | (1ULL << 63)) >> 1, b = 32 + (__builtin_ctzll(hi | (1ULL << 63)) >> 1);
        return lo ? a : b;
    }
    for (int k = 0; k < nv; k++) {
        unsigned bits = (unsigned)_mm256_movemask_epi8(_mm256_cmpeq_epi16(s[k], mb));
        if (bits)
            return 16 * k + (__builtin_ctz(bits) >> 1);
    }
    return 0;
}

/* disp[x] for x < n: the winner bd[x], or bd + (0.5 (cm - cp)) / (cm - 2 m + cp) in double precision (the vertex
 * of the parabola through the winner's cost m and its neighbours' cm, cp) when 0 < bd < min(nd, x + 1) - 1 and
 * the denominator is positive */
SGM_INLINE void sgm_subpixel(float *disp, const int32_t *bd, const int32_t *m, const int32_t *cm, const int32_t *cp,
                             long n, int nd)
{
    const __m256d two = _mm256_set1_pd(2.0), half = _mm256_set1_pd(0.5), zero = _mm256_setzero_pd();
    long x = 0;
    for (; x + 4 <= n; x += 4) {
        __m128i b = _mm_loadu_si128((const __m128i *)(bd + x));
        __m128i lim = _mm_min_epi32(_mm_set1_epi32(nd - 1), _mm_add_epi32(_mm_set1_epi32((int)x),
                                                                            _mm_setr_epi32(0, 1, 2, 3)));
        __m128i okb = _mm_and_si128(_mm_cmpgt_epi32(b, _mm_setzero_si128()), _mm_cmpgt_epi32(lim, b));
        __m256d db = _mm256_cvtepi32_pd(b);
        __m256d dm = _mm256_cvtepi32_pd(_mm_loadu_si128((const __m128i *)(m + x)));
        __m256d dcm = _mm256_cvtepi32_pd(_mm_loadu_si128((const __m128i *)(cm + x)));
        __m256d dcp = _mm256_cvtepi32_pd(_mm_loadu_si128((const __m128i *)(cp + x)));
        __m256d den = _mm256_add_pd(_mm256_sub_pd(dcm, _mm256_mul_pd(two, dm)), dcp);
        __m256d v = _mm256_add_pd(db, _mm256_div_pd(_mm256_mul_pd(half, _mm256_sub_pd(dcm, dcp)), den));
        __m256d ok = _mm256_and_pd(_mm256_castsi256_pd(_mm256_cvtepi32_epi64(okb)),
                                   _mm256_cmp_pd(den, zero, _CMP_GT_OQ));
        _mm_storeu_ps(disp + x, _mm256_cvtpd_ps(_mm256_blendv_pd(db, v, ok)));
    }
    for (; x < n; x++) {
        int lim = nd - 1 < x ? nd - 1 : (int)x;
        double den = ((double)cm[x] - 2.0 * (double)m[x]) + (double)cp[x];
        if (bd[x] > 0 && bd[x] < lim && den > 0)
            disp[x] = (float)((double)bd[x] + 0.5 * ((double)cm[x] - (double)cp[x]) / den);
        else
            disp[x] = (float)bd[x];
    }
}

/* Right image's winners over a window of right pixels xr = x - j in lane j (``best`` biased by 0x8000 for signed
 * compares, ``arg`` their disparities), updated with the masked costs ``s`` of left pixel x. Left to right the
 * first (smallest) disparity of a tie is kept (strict <); right to left (``ltr`` 0) the last (<=). */
SGM_INLINE void sgm_right_update(int nv, __m256i *best, __m256i *arg, const __m256i *s, int ltr)
{
    const __m256i iota = _mm256_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const __m256i bias = _mm256_set1_epi16((int16_t)0x8000);
    for (int k = 0; k < nv; k++) {
        __m256i d = _mm256_add_epi16(iota, _mm256_set1_epi16((int16_t)(16 * k)));
        __m256i v = _mm256_xor_si256(s[k], bias);
        if (ltr)
            arg[k] = _mm256_blendv_epi8(arg[k], d, _mm256_cmpgt_epi16(best[k], v));
        else
            arg[k] = _mm256_blendv_epi8(d, arg[k], _mm256_cmpgt_epi16(v, best[k]));
        best[k] = _mm256_min_epi16(best[k], v);
    }
}

SGM_INLINE void sgm_right_reset(int nv, __m256i *best, __m256i *arg)
{
    for (int k = 0; k < nv; k++) {
        best[k] = _mm256_set1_epi16(0x7FFF);
        arg[k] = _mm256_setzero_si256();
    }
}

/* left to right: returns the disparity of lane DP - 1 (finished) and shifts the window up for the next pixel */
SGM_INLINE int sgm_right_shift_up(int nv, __m256i *best, __m256i *arg)
{
    int out = _mm256_extract_epi16(arg[nv - 1], 15);
    for (int k = nv - 1; k >= 0; k--) {
        best[k] = sgm_shift_up(best[k], k ? best[k - 1] : _mm256_set1_epi16(0x7FFF));
        arg[k] = sgm_shift_up(arg[k], k ? arg[k - 1] : _mm256_setzero_si256());
    }
    return out;
}

/* right to left: returns the disparity of lane 0 (finished) and shifts the window down for the next pixel */
SGM_INLINE int sgm_right_shift_down(int nv, __m256i *best, __m256i *arg)
{
    int out = _mm256_extract_epi16(arg[0], 0);
    for (int k = 0; k < nv; k++) {
        best[k] = sgm_shift_down(best[k], k + 1 < nv ? best[k + 1] : _mm256_set1_epi16(0x7FFF));
        arg[k] = sgm_shift_down(arg[k], k + 1 < nv ? arg[k + 1] : _mm256_setzero_si256());
    }
    return out;
}

/* dst[i] = src[n - 1 - i] for i < n */
SGM_INLINE void sgm_reverse(uint8_t *dst, const uint8_t *src, long n)
{
    const __m256i rev = _mm256_setr_epi8(15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0,
                                         15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0);
    long i = 0;
    for (; i + 32 <= n; i += 32) {
        __m256i v = _mm256_shuffle_epi8(_mm256_loadu_si256((const __m256i *)(src + n - 32 - i)), rev);
        _mm256_storeu_si256((__m256i *)(dst + i), _mm256_permute4x64_epi64(v, 0x4E));
    }
    for (; i < n; i++)
        dst[i] = src[n - 1 - i];
}

/* planes[c * ps + i] = row[3 * i + c] for the pixels i < n of a 3-channel row */
SGM_INLINE void sgm_deinterleave3(uint8_t *planes, long ps, const uint8_t *row, long n)
{
    const __m128i m[3][3] = {
        {_mm_setr_epi8(0, 3, 6, 9, 12, 15, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1),
         _mm_setr_epi8(-1, -1, -1, -1, -1, -1, 2, 5, 8, 11, 14, -1, -1, -1, -1, -1),
         _mm_setr_epi8(-1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, 1, 4, 7, 10, 13)},
        {_mm_setr_epi8(1, 4, 7, 10, 13, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1),
         _mm_setr_epi8(-1, -1, -1, -1, -1, 0, 3, 6, 9, 12, 15, -1, -1, -1, -1, -1),
         _mm_setr_epi8(-1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, 2, 5, 8, 11, 14)},
        {_mm_setr_epi8(2, 5, 8, 11, 14, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1),
         _mm_setr_epi8(-1, -1, -1, -1, -1, 1, 4, 7, 10, 13, -1, -1, -1, -1, -1, -1),
         _mm_setr_epi8(-1, -1, -1, -1, -1, -1, -1, -1, -1, -1, 0, 3, 6, 9, 12, 15)}};
    long i = 0;
    for (; i + 16 <= n; i += 16) {
        __m128i a = _mm_loadu_si128((const __m128i *)(row + 3 * i));
        __m128i b = _mm_loadu_si128((const __m128i *)(row + 3 * i + 16));
        __m128i c = _mm_loadu_si128((const __m128i *)(row + 3 * i + 32));
        for (int k = 0; k < 3; k++)
            _mm_storeu_si128((__m128i *)(planes + k * ps + i),
                             _mm_or_si128(_mm_or_si128(_mm_shuffle_epi8(a, m[k][0]), _mm_shuffle_epi8(b, m[k][1])),
                                          _mm_shuffle_epi8(c, m[k][2])));
    }
    for (; i < n; i++)
        for (int k = 0; k < 3; k++)
            planes[k * ps + i] = row[3 * i + k];
}

/* One census nibble plane of a row: out[x] = sum_q [nb_q[x] < centre[x]] << sh_q over ``cnt`` (<= 4) neighbours */
SGM_INLINE void sgm_census_plane(uint8_t *out, const uint8_t *centre, const uint8_t *const *nb, const int *sh, int cnt,
                                 long w)
{
    long x = 0;
    for (; x + 32 <= w; x += 32) {
        __m256i c = _mm256_loadu_si256((const __m256i *)(centre + x)), acc = _mm256_setzero_si256();
        for (int q = 0; q < cnt; q++) {
            __m256i v = _mm256_loadu_si256((const __m256i *)(nb[q] + x));
            __m256i ge = _mm256_cmpeq_epi8(_mm256_max_epu8(v, c), v);
            acc = _mm256_or_si256(acc, _mm256_andnot_si256(ge, _mm256_set1_epi8((char)(1 << sh[q]))));
        }
        _mm256_storeu_si256((__m256i *)(out + x), acc);
    }
    for (; x < w; x++) {
        int v = 0;
        for (int q = 0; q < cnt; q++)
            v |= (nb[q][x] < centre[x]) << sh[q];
        out[x] = (uint8_t)v;
    }
}

/* The left-right check of a row: disp[x] >= 0 becomes -1 unless the right disparity at x - lo or x - hi (lo, hi
 * the floor and ceil of disp[x]) is within ``t`` (an integer: the differences are integers) of lo or hi */
SGM_INLINE void sgm_lr_check(float *disp, const int32_t *disp_r, long w, int t)
{
    const __m256i last = _mm256_set1_epi32((int)w - 1), zero = _mm256_setzero_si256(), tv = _mm256_set1_epi32(t);
    const __m256i iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    long x = 0;
    for (; x + 8 <= w; x += 8) {
        __m256 d = _mm256_loadu_ps(disp + x);
        __m256i lo = _mm256_cvttps_epi32(d);
        __m256i hi = _mm256_sub_epi32(lo, _mm256_castps_si256(_mm256_cmp_ps(d, _mm256_cvtepi32_ps(lo), _CMP_GT_OQ)));
        __m256i xs = _mm256_add_epi32(_mm256_set1_epi32((int)x), iota);
        __m256i ilo = _mm256_sub_epi32(xs, lo), ihi = _mm256_sub_epi32(xs, hi);
        __m256i rlo = _mm256_i32gather_epi32((const int *)disp_r,
                                             _mm256_min_epi32(_mm256_max_epi32(ilo, zero), last), 4);
        __m256i rhi = _mm256_i32gather_epi32((const int *)disp_r,
                                             _mm256_min_epi32(_mm256_max_epi32(ihi, zero), last), 4);
        /* a candidate fails when its pixel is left of the image or its difference exceeds t */
        __m256i bad_lo = _mm256_or_si256(_mm256_cmpgt_epi32(zero, ilo),
                                         _mm256_cmpgt_epi32(_mm256_abs_epi32(_mm256_sub_epi32(lo, rlo)), tv));
        __m256i bad_hi = _mm256_or_si256(_mm256_cmpgt_epi32(zero, ihi),
                                         _mm256_cmpgt_epi32(_mm256_abs_epi32(_mm256_sub_epi32(hi, rhi)), tv));
        __m256 reject = _mm256_and_ps(_mm256_castsi256_ps(_mm256_and_si256(bad_lo, bad_hi)),
                                      _mm256_cmp_ps(d, _mm256_setzero_ps(), _CMP_GE_OQ));
        _mm256_storeu_ps(disp + x, _mm256_blendv_ps(d, _mm256_set1_ps(-1.0f), reject));
    }
    for (; x < w; x++) {
        float d = disp[x];
        if (d < 0)
            continue;
        long lo = (long)d, hi = lo + (d > (float)lo);
        int ok_lo = x - lo >= 0 && labs(lo - disp_r[x - lo]) <= t;
        int ok_hi = x - hi >= 0 && labs(hi - disp_r[x - hi]) <= t;
        if (!(ok_lo || ok_hi))
            disp[x] = -1.0f;
    }
}

/* Matching costs of one pixel for its DP disparities (``dp``: 32 at a time, a last 16 stored as 16): census
 * Hamming distance from nibble planes (plane p of the left pixel at lnib[p * ls], of the right candidates x - d at
 * rnib[p * rs + d]) plus, when ``ad``, (min(sum_c |L_c - R_c|, cap) * mult) >> 16 from the colour values (left at
 * lpx[c], right candidates at rad[c * as + d]); needs cap <= 255 and mult < 65536. */
SGM_INLINE void sgm_cost_px(int dp, int npl, const uint8_t *lnib, long ls, const uint8_t *rnib, long rs, int ad,
                            int nch, const uint8_t *lpx, const uint8_t *rad, long as, __m256i capv, __m256i multv,
                            uint8_t *out)
{
    const __m256i lut = _mm256_setr_epi8(0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4,
                                         0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4);
    const __m256i zero = _mm256_setzero_si256();
    int nb = (dp + 31) / 32;
    for (int b0 = 0; b0 < nb; b0 += 4) {
        int n = nb - b0 < 4 ? nb - b0 : 4;
        __m256i acc[4], s[4];
        for (int b = 0; b < n; b++) {
            acc[b] = zero;
            s[b] = zero;
        }
        for (int p = 0; p < npl; p++) {
            __m256i l = _mm256_set1_epi8((char)lnib[p * ls]);
            const uint8_t *r = rnib + p * rs + 32 * b0;
            for (int b = 0; b < n; b++)
                acc[b] = _mm256_add_epi8(acc[b], _mm256_shuffle_epi8(lut, _mm256_xor_si256(
                    _mm256_loadu_si256((const __m256i *)(r + 32 * b)), l)));
        }
        if (ad) {
            for (int c = 0; c < nch; c++) {
                __m256i l = _mm256_set1_epi8((char)lpx[c]);
                const uint8_t *r = rad + c * as + 32 * b0;
                for (int b = 0; b < n; b++) {
                    __m256i v = _mm256_loadu_si256((const __m256i *)(r + 32 * b));
                    s[b] = _mm256_adds_epu8(s[b], _mm256_or_si256(_mm256_subs_epu8(l, v), _mm256_subs_epu8(v, l)));
                }
            }
            for (int b = 0; b < n; b++) {
                __m256i t = _mm256_min_epu8(s[b], capv);
                __m256i lo = _mm256_mulhi_epu16(_mm256_unpacklo_epi8(t, zero), multv);
                __m256i hi = _mm256_mulhi_epu16(_mm256_unpackhi_epi8(t, zero), multv);
                acc[b] = _mm256_add_epi8(acc[b], _mm256_packus_epi16(lo, hi));
            }
        }
        for (int b = 0; b < n; b++) {
            int d = 32 * (b0 + b);
            if (d + 32 <= dp)
                _mm256_storeu_si256((__m256i *)(out + d), acc[b]);
            else
                _mm_storeu_si128((__m128i *)(out + d), _mm256_castsi256_si128(acc[b]));
        }
    }
}

/* sgm_cost_px for 16 disparities and two pixels at once, x (candidates at rnib, rad) and x + 1 (one byte before):
 * its 32 costs are the 16 of x then the 16 of x + 1 */
SGM_INLINE void sgm_cost_2px16(int npl, const uint8_t *lnib, long ls, const uint8_t *rnib, long rs, int ad, int nch,
                               const uint8_t *lpx, const uint8_t *rad, long as, __m256i capv, __m256i multv,
                               uint8_t *out)
{
    const __m256i lut = _mm256_setr_epi8(0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4,
                                         0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4);
    const __m256i sel = _mm256_setr_epi8(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                                         1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1);
    const __m256i zero = _mm256_setzero_si256();
    __m256i acc = zero;
    for (int p = 0; p < npl; p++) {
        const uint8_t *r = rnib + p * rs;
        __m256i v = _mm256_inserti128_si256(_mm256_castsi128_si256(_mm_loadu_si128((const __m128i *)r)),
                                            _mm_loadu_si128((const __m128i *)(r - 1)), 1);
        __m256i l = _mm256_shuffle_epi8(_mm256_set1_epi16((int16_t)(lnib[p * ls] | (lnib[p * ls + 1] << 8))), sel);
        acc = _mm256_add_epi8(acc, _mm256_shuffle_epi8(lut, _mm256_xor_si256(v, l)));
    }
    if (ad) {
        __m256i s = zero;
        for (int c = 0; c < nch; c++) {
            const uint8_t *r = rad + c * as;
            __m256i v = _mm256_inserti128_si256(_mm256_castsi128_si256(_mm_loadu_si128((const __m128i *)r)),
                                                _mm_loadu_si128((const __m128i *)(r - 1)), 1);
            __m256i l = _mm256_shuffle_epi8(_mm256_set1_epi16((int16_t)(lpx[c] | (lpx[nch + c] << 8))), sel);
            s = _mm256_adds_epu8(s, _mm256_or_si256(_mm256_subs_epu8(l, v), _mm256_subs_epu8(v, l)));
        }
        s = _mm256_min_epu8(s, capv);
        __m256i lo = _mm256_mulhi_epu16(_mm256_unpacklo_epi8(s, zero), multv);
        __m256i hi = _mm256_mulhi_epu16(_mm256_unpackhi_epi8(s, zero), multv);
        acc = _mm256_add_epi8(acc, _mm256_packus_epi16(lo, hi));
    }
    _mm256_storeu_si256((__m256i *)out, acc);
}

#endif
