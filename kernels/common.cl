/* Shared definitions for every clpost kernel (prepended to each program by clpost.pipeline).
 *
 * Layout: images are float32. "Interleaved" is the host layout (H, W, 3) — pixel i's channels at
 * 3i, 3i+1, 3i+2. "Planar" is the device layout for gathers — channel c of pixel i at c*n + i,
 * with n = W*H — because PoCL vectorises across work-items when addresses are affine in the id.
 * Global size is (W, H): get_global_id(0) is x, row 0 is the top row (CONVENTIONS.md).
 */

/* Where a pointwise function is evaluated. */
typedef struct {
    int x;        /* column, pixel centre at x */
    int y;        /* row, 0 at the top */
    int width;
    int height;
    size_t i;     /* y * width + x: index into depth[], and velocity[2i], velocity[2i+1] */
} PixelCtx;

/* 16 consecutive pixels of one row (pixel k at x0 + k, index i0 + k): the context of the
 * explicit-vector form <name>_apply16 of a pointwise stage (clpost/pipeline.py, VECTOR_PIXELS). */
typedef struct {
    int x0;
    int y;
    int width;
    int height;
    size_t i0;
} PixelCtx16;

#define CLP_LANES16 ((float16)(0.0f, 1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 6.0f, 7.0f, \
                               8.0f, 9.0f, 10.0f, 11.0f, 12.0f, 13.0f, 14.0f, 15.0f))

/* table[idx] per lane (a data-dependent gather has no vector builtin) */
#define CLP_GATHER16(table, idx) ((float16)( \
    (table)[(idx).s0], (table)[(idx).s1], (table)[(idx).s2], (table)[(idx).s3], \
    (table)[(idx).s4], (table)[(idx).s5], (table)[(idx).s6], (table)[(idx).s7], \
    (table)[(idx).s8], (table)[(idx).s9], (table)[(idx).sa], (table)[(idx).sb], \
    (table)[(idx).sc], (table)[(idx).sd], (table)[(idx).se], (table)[(idx).sf]))

/* 16 pixels of a row (x .. x + 15) into a planar RGB image. `whole` (a compile-time constant at
 * the call site): the frame is whole tiles, every vector lies inside; otherwise rows below the
 * frame and pixels right of it are computed by the caller but not stored. */
inline void clp_store16_planar(__global float *restrict dst, const float16 r, const float16 g,
                               const float16 b, const int x, const int y, const int width,
                               const int height, const int whole)
{
    const size_t n = (size_t)width * height;
    const size_t i = (size_t)y * width + x;
    if (whole) {
        vstore16(r, 0, dst + i);
        vstore16(g, 0, dst + n + i);
        vstore16(b, 0, dst + 2 * n + i);
        return;
    }
    if (y >= height) return;
    float rr[16], gg[16], bb[16];
    vstore16(r, 0, rr);
    vstore16(g, 0, gg);
    vstore16(b, 0, bb);
    for (int e = 0; e < 16 && x + e < width; ++e) {
        dst[i + e] = rr[e];
        dst[n + i + e] = gg[e];
        dst[2 * n + i + e] = bb[e];
    }
}

/* Scalar loads and stores, not vload3/vstore3: on PoCL 3.0 a vload3/vstore3 stops the
 * vectorisation across work-items of the whole kernel (measured at 1080p: an exp2 per channel
 * 25 ms with vload3/vstore3, 13.6 ms with these, 7.2 ms planar). */
inline float3 load_interleaved(__global const float *buf, const size_t i) {
    return (float3)(buf[3 * i], buf[3 * i + 1], buf[3 * i + 2]);
}

inline void store_interleaved(__global float *buf, const size_t i, const float3 c) {
    buf[3 * i] = c.x;
    buf[3 * i + 1] = c.y;
    buf[3 * i + 2] = c.z;
}

inline float3 load_planar(__global const float *buf, const size_t i, const size_t n) {
    return (float3)(buf[i], buf[n + i], buf[2 * n + i]);
}

inline void store_planar(__global float *buf, const size_t i, const size_t n, const float3 c) {
    buf[i] = c.x;
    buf[n + i] = c.y;
    buf[2 * n + i] = c.z;
}

/* Elementary functions for hot per-pixel code (issue "performance"). PoCL 3.0's log/log2/log10
 * and cospi cost 10-20 ns per call on these CPUs (measured on a 1080p RGB frame: log 124 ms,
 * cospi 54 ms, exp 6-8 ms, a copy 1.5 ms) because they do not vectorise; these are built from
 * integer bit operations, fma and short polynomials and vectorise across work-items
 * (clp_log2 5 ms, clp_exp2 8 ms, clp_cos2pi 6 ms on the same frame). Every select costs: the
 * domains are restricted to what the callers pass, and the callers clamp first.
 * Accuracy (tests/test_fastmath.py, against float64):
 *   clp_log2(x), x normal and finite (FLT_MIN <= x <= FLT_MAX): |error| <= max(2e-7, 2 ulp);
 *   clp_exp2(x), any non-NaN x: <= 2 ulp (exp2(-inf) = 0, exp2(x >= 128) = +inf);
 *   clp_cos2pi(u) = cos(2 pi u), finite u: |error| < 2.5e-7.
 */
#ifndef CLPOST_FASTMATH_CL
#define CLPOST_FASTMATH_CL

/* log2 x = e + log2 m with x = m 2^e, m in [sqrt(1/2), sqrt(2)); ln m = 2 atanh t,
 * t = (m - 1)/(m + 1), |t| <= 0.1716, series to t^11 (truncation < 3e-10). */
inline float clp_log2(const float x) {
    const uint bits = as_uint(x);
    int e = (int)((bits >> 23) & 0xffu) - 127;
    float m = as_float((bits & 0x007fffffu) | 0x3f800000u);   /* [1, 2) */
    const int big = m > 1.41421356f;
    m = big ? 0.5f * m : m;
    e += big;
    const float t = (m - 1.0f) / (m + 1.0f);
    const float t2 = t * t;
    float p = fma(t2, 0.18181818f, 0.22222222f);          /* 2/11, 2/9 */
    p = fma(t2, p, 0.28571429f);                          /* 2/7 */
    p = fma(t2, p, 0.4f);
    p = fma(t2, p, 0.66666667f);
    p = fma(t2, p, 2.0f);
    return fma(t * p, 1.44269504f, (float)e);             /* ln m / ln 2 + e */
}

inline float3 clp_log2_3(const float3 x) {
    return (float3)(clp_log2(x.x), clp_log2(x.y), clp_log2(x.z));
}

/* 2^x = 2^k 2^f, k = round(x), |f| <= 1/2; 2^f = e^(f ln 2) by Taylor to degree 7 (< 5e-9
 * relative); 2^k applied in two halves so subnormal results and k = 128 come out right.
 * floor(x + 0.5) rather than rint: rint does not vectorise on PoCL (7 ms vs 4 ms a frame). */
inline float clp_exp2(const float x) {
    const float xc = clamp(x, -151.0f, 129.0f);
    const float k = floor(xc + 0.5f);
    const float f = (xc - k) * 0.69314718f;
    float p = fma(f, 1.98412698e-4f, 1.38888889e-3f);    /* 1/7!, 1/6! */
    p = fma(f, p, 8.33333333e-3f);
    p = fma(f, p, 4.16666667e-2f);
    p = fma(f, p, 0.16666667f);
    p = fma(f, p, 0.5f);
    p = fma(f, p, 1.0f);
    p = fma(f, p, 1.0f);
    const int ki = (int)k;
    const int k1 = ki >> 1, k2 = ki - k1;                 /* each in [-76, 65]: normal scales */
    return p * as_float((uint)(k1 + 127) << 23) * as_float((uint)(k2 + 127) << 23);
}

inline float3 clp_exp2_3(const float3 x) {
    return (float3)(clp_exp2(x.x), clp_exp2(x.y), clp_exp2(x.z));
}

/* cos(2 pi u): r = u - round(u), cos 2 pi r = sin(2 pi (1/4 - |r|)) with the argument in
 * [-pi/2, pi/2]; odd Taylor series to z^13 (truncation < 1e-9). */
inline float clp_cos2pi(const float u) {
    const float r = u - floor(u + 0.5f);
    const float z = (0.25f - fabs(r)) * 6.28318531f;
    const float z2 = z * z;
    float p = fma(z2, -1.60590438e-10f, 2.50521084e-8f);   /* -1/13!, 1/11! */
    p = fma(z2, p, -2.75573192e-6f);
    p = fma(z2, p, 1.98412698e-4f);
    p = fma(z2, p, -8.33333333e-3f);
    p = fma(z2, p, 0.16666667f);
    return fma(-z * z2, p, z);
}

#endif
