/* distortion: resample the undistorted (pinhole) render into the distorted image.
 *
 * map holds, for every output pixel i, the source position in the render (planar: x at map[i],
 * y at map[n + i], render pixel centres at integers). It is computed once per (camera, size) on
 * the host in float64 by the exact Newton inverse of the OpenCV model (clpost/calibration/model.py);
 * a pixel with no preimage (outside the render, beyond the fold, no convergence) has x = -1e30
 * and gets color 0 (its alpha, written on the host, is 0).
 *
 * Both filters live in one program (no define selects them); the quality picks the kernels.
 * Draft/preview: bilinear (4 taps), kernels `distortion_tiles` and `distortion_rest` (`distortion`:
 * the same per pixel over the whole map).
 * Final: cubic B-spline interpolation: the B-spline coefficients of the
 * source (`distortion_fir_rows` then `_cols`: the prefilter of Unser 1999 as a separable FIR,
 * |k| <= DISTORTION_FIR_K) and 16 taps with B-spline weights (`distortion_bspline_tiles` on the
 * tiles whose taps fit a tile-uniform window, `distortion_table` elsewhere), made HDR-safe by
 * clamping to the least and largest of the position's 2x2 samples and handing over to bilinear
 * where the local contrast is high (`distortion_dering` writes the hand-over weight; formula and
 * source: resample and hdr_weight in clpost/stages/distortion.py).
 * Why not
 * Keys' cubic convolution (OpenCV's INTER_CUBIC): it is only first-order and moves an edge by up
 * to ~0.03 px depending on its sub-pixel phase, which cost 5-8 % in the recovered k2/p2 of the
 * checkerboard calibration; the B-spline is exact for cubics and keeps every parameter within 1 %
 * (docs/distortion_calibration.md). Taps outside the render repeat its edge (the coefficients are
 * those of the edge-extended source, as scipy's map_coordinates(order=3, mode="nearest"), the
 * reference, computes them), stored with DISTORTION_PAD pixels around the render.
 * The final filter's multiply-adds are fma, not mad: PoCL compiles mad as a multiply and an add
 * (two instructions, two roundings), fma as one vfmadd with one rounding; 7-9 % off the final
 * filter's four kernels at 1080p (docs/benchmarks.md, "Distortion's final filter, fifth pass").
 * Where a factor is a power of two (4, 1/2, 1/512) both are exact and give the same bits.
 */

/* Bilinear. One output pixel of the map: taps beyond the render repeat its edge, no preimage ->
 * colour 0. No floor/clamp calls and a select instead of an early return: both keep PoCL's
 * vectoriser going (docs/measurements.md#kernel-forms-on-pocl). */
inline void distortion_pixel(__global const float *restrict src, __global float *restrict dst,
                             __global const float *restrict map, const int src_w, const int src_h,
                             const size_t n, const size_t i)
{
    const size_t sn = (size_t)src_w * src_h;
    const float sx = map[i], sy = map[n + i];
    const int ok = sx > -1.0e29f;
    const float cx = ok ? sx : 0.0f, cy = ok ? sy : 0.0f;
    /* floor for valid positions (>= -1/2): truncation of a positive number */
    const int x0 = (int)(cx + 1.0f) - 1, y0 = (int)(cy + 1.0f) - 1;
    const float tx = cx - (float)x0, ty = cy - (float)y0;
    const int xa = x0 < 0 ? 0 : x0, ya = y0 < 0 ? 0 : y0;
    const int xb = x0 + 1 > src_w - 1 ? src_w - 1 : x0 + 1, yb = y0 + 1 > src_h - 1 ? src_h - 1 : y0 + 1;
    for (int c = 0; c < 3; ++c) {
        __global const float *p = src + c * sn;
        const float a = p[ya * src_w + xa], b = p[ya * src_w + xb];
        const float d = p[yb * src_w + xa], e = p[yb * src_w + xb];
        const float v = (a * (1.0f - tx) + b * tx) * (1.0f - ty) + (d * (1.0f - tx) + e * tx) * ty;
        dst[c * n + i] = ok ? v : 0.0f;
    }
}

__kernel void distortion(__global const float *restrict src, __global float *restrict dst,
                         __global const float *restrict map, const int src_w, const int src_h,
                         const int width, const int height)
{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= width || y >= height) return;
    distortion_pixel(src, dst, map, src_w, src_h, (size_t)width * height, (size_t)y * width + x);
}

/* Bilinear on the tiles of DISTORTION_TILE x DISTORTION_TILE output pixels where the map's
 * integer displacement floor(s) - x takes at most two neighbouring values (host:
 * clpost/stages/distortion.py, bilinear_tiles): the 2x2 taps of every pixel of a tile row lie in
 * the 3x3 window at (x + ox, y + oy), so the loads are vload16 at addresses affine in the lane,
 * and bilinear weights are tent weights max(0, 1 - |f - k|) on that window. One work-item: one
 * row of one tile; a work-group: one row of TILE_GROUP consecutive tiles (as
 * distortion_bspline_tiles, which says why). tiles: (x0, y0, ox, oy) per tile. */
#define DISTORTION_TILE 16
__kernel void distortion_tiles(__global const float *restrict src, __global float *restrict dst,
                               __global const float *restrict map, __global const int *restrict tiles,
                               const int src_w, const int src_h, const int width, const int height,
                               const int ntiles)
{
    const int row = get_global_id(0), tile = get_global_id(1);
    if (tile >= ntiles) return;  /* the tile count rounded up to whole work-groups (host) */
    const int4 t = vload4(tile, tiles);
    const int y = t.y + row;
    const size_t n = (size_t)width * height, sn = (size_t)src_w * src_h;
    const size_t i = (size_t)y * width + t.x;
    const float16 fx = vload16(0, map + i) - ((float)(t.x + t.z) + CLP_LANES16);
    const float16 fy = vload16(0, map + n + i) - (float)(y + t.w);
    const float16 wx0 = fmax(1.0f - fx, 0.0f), wx2 = fmax(fx - 1.0f, 0.0f), wx1 = 1.0f - wx0 - wx2;
    const float16 wy0 = fmax(1.0f - fy, 0.0f), wy2 = fmax(fy - 1.0f, 0.0f), wy1 = 1.0f - wy0 - wy2;
    const size_t base = (size_t)(y + t.w) * src_w + (size_t)(t.x + t.z);
    for (int c = 0; c < 3; ++c) {
        __global const float *p = src + c * sn + base;
        float16 acc = (float16)(0.0f);
        for (int m = 0; m < 3; ++m) {
            __global const float *q = p + (size_t)m * src_w;
            const float16 rowv = wx0 * vload16(0, q) + wx1 * vload16(0, q + 1) + wx2 * vload16(0, q + 2);
            acc += (m == 0 ? wy0 : (m == 1 ? wy1 : wy2)) * rowv;
        }
        vstore16(acc, 0, dst + c * n + i);
    }
}

/* the other tiles (a listed tile x0, y0 per work-group of DISTORTION_TILE^2), one pixel each */
__kernel void distortion_rest(__global const float *restrict src, __global float *restrict dst,
                              __global const float *restrict map, __global const int *restrict tiles,
                              const int src_w, const int src_h, const int width, const int height)
{
    const int2 t = vload2(get_global_id(2), tiles);
    const int x = t.x + get_global_id(0), y = t.y + get_global_id(1);
    if (x >= width || y >= height) return;
    distortion_pixel(src, dst, map, src_w, src_h, (size_t)width * height, (size_t)y * width + x);
}

/* Cubic B-spline prefilter as a separable FIR (formula, derivation and error bound: the docstring
 * of clpost/stages/distortion.py, fir_taps). The coefficient plane (DISTORTION_PAD edge pixels
 * around the source, row pitch a multiple of 16) is
 *     C = h (*) (h (*) f)^T,   h_k = -6z/(1 - z^2) z^|k| = sqrt(3) z^|k|,  z = sqrt(3) - 2,  |k| <= K
 * on the source f extended by edge repeat, i.e. scipy's map_coordinates(order=3, mode="nearest")
 * prefilter up to the truncation (sum_{|k|>K} |h_k| = 1.7e-7 at K = 12).
 * Why not the recursion (Unser 1999, as scipy): a causal + anticausal sweep is one sequential
 * chain per row/column: along rows neighbouring work-items walk different rows (no vectorisation),
 * along columns it is latency-bound (30+ ms at 1080p). The FIR gives every work-item 16
 * neighbouring pixels and loads at offsets uniform across lanes, on buffers padded so no tap is
 * clamped. */
#define DISTORTION_PAD 20
#define DISTORTION_FIR_K 12
/* The coefficient planes hold the coefficients / DISTORTION_COEF_SCALE, so huge finite colour stays
 * finite: the prefilter's gain is sum |h| = 3 per pass (9 in all), its pair sums twice a sample, and
 * the gathers' 1-4-1 sums of the cell's samples reach 36 x the largest coefficient: 324 x max|f|
 * unscaled, which overflowed float from max|f| ~ 1e36. / 512 keeps every one below max|f|; the
 * gathers multiply their result back. A power of two, so (no underflow: |f| > 1e-35) the scaled
 * arithmetic is exact and the output the same bits as unscaled. */
#define DISTORTION_COEF_SCALE 512.0f
/* h_0 ... h_K in float64 printed to float precision (tests/test_distortion.py checks them against
 * fir_taps and the impulse response of scipy.ndimage.spline_filter1d) */
__constant float distortion_fir[DISTORTION_FIR_K + 1] = {
    1.732050807568878f, -0.464101615137755f, 0.1243556529821412f, -0.03332099679080968f,
    0.008928334181097489f, -0.002392339933580263f, 0.0006410255532235573f, -0.00017176227931396592f,
    4.6023564032306114e-05f, -1.2331976815258494e-05f, 3.304343228727843e-06f, -8.853960996528744e-07f,
    2.3724116988365365e-07f};

/* Row pass. Work-item (g, r, ch): tmp row r, padded columns 16g ... 16g + 15, the source row
 * clamp(r - PAD - K) (rows repeat the edge, so the column pass needs no clamp either); source
 * column of padded column p: p - PAD. The window x0 ... x0 + 47 (16 + 2K = 40 used) is three
 * vload16 and the 2K + 1 shifted copies are DISTORTION_SHIFT with literal lanes (one permute each),
 * not 25 unaligned vload16, which split cache lines (same output;
 * docs/measurements.md#kernel-forms-on-pocl). Work-items whose window leaves the row (5 of 123
 * per row at 1080p) copy it with clamped indices to a private array first. tmp: 3 planes of th =
 * coefficient rows + 2K rows of pitch. The taps are written out for K = 12. */
#if DISTORTION_FIR_K != 12
#error "distortion_fir_rows is unrolled for DISTORTION_FIR_K = 12"
#endif
/* lanes s ... s + 15 of the 32-lane a:b (s a literal 1 ... 15). Where the compiler has it, clang's
 * __builtin_shufflevector with literal indices: one LLVM shufflevector, which every backend lowers
 * to its permutes. shuffle2 with a constant mask means the same, but PoCL 5.0 (LLVM 16) does not
 * fold it into one permute, which made distortion_fir_rows and distortion_dering many times slower
 * there (PoCL 3.1 folds it; docs/benchmarks.md, "Distortion's final filter on 16 cores"). Same
 * lanes, same sums: the output is the same bits either way (tests/test_distortion.py). */
#if defined(__has_builtin) && !defined(DISTORTION_SHUFFLE2)  /* -DDISTORTION_SHUFFLE2: the fallback (tests) */
#if __has_builtin(__builtin_shufflevector)
#define DISTORTION_HAVE_SHUFFLEVECTOR 1
#endif
#endif
#ifdef DISTORTION_HAVE_SHUFFLEVECTOR
#define DISTORTION_SHIFT(a, b, s) __builtin_shufflevector((a), (b), (s), (s) + 1, (s) + 2, (s) + 3, (s) + 4, \
    (s) + 5, (s) + 6, (s) + 7, (s) + 8, (s) + 9, (s) + 10, (s) + 11, (s) + 12, (s) + 13, (s) + 14, (s) + 15)
#else
#define DISTORTION_SHIFT(a, b, s) shuffle2((a), (b), (uint16)(s) + \
    (uint16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15))
#endif
__kernel void distortion_fir_rows(__global const float *restrict src, __global float *restrict tmp,
                                  const int src_w, const int src_h, const int pitch, const int th)
{
    const int g = get_global_id(0), r = get_global_id(1), ch = get_global_id(2);
    const int sy = clamp(r - DISTORTION_PAD - DISTORTION_FIR_K, 0, src_h - 1);
    __global const float *s = src + ((size_t)ch * src_h + sy) * src_w;
    const int x0 = 16 * g - DISTORTION_PAD - DISTORTION_FIR_K;
    float16 a, b, c;
    if (x0 >= 0 && x0 + 47 <= src_w - 1) {
        a = vload16(0, s + x0);
        b = vload16(1, s + x0);
        c = vload16(2, s + x0);
    } else {
        float win[48];
        for (int i = 0; i < 48; ++i) win[i] = s[clamp(x0 + i, 0, src_w - 1)];
        a = vload16(0, win);
        b = vload16(1, win);
        c = vload16(2, win);
    }
    a *= 1.0f / DISTORTION_COEF_SCALE;
    b *= 1.0f / DISTORTION_COEF_SCALE;
    c *= 1.0f / DISTORTION_COEF_SCALE;
    /* output lane l, tap k reads window offset K + l + k; the pairs k, -k share a multiply;
     * smallest taps first and the centre last: with the column pass ordered alike, the rounding
     * error of the coefficients fell from 1.4e-6 to 0.64e-6 of max|f| (1e8 spikes, 300x200) */
    float16 acc = distortion_fir[12] * (a + DISTORTION_SHIFT(b, c, 8));
    acc = fma(distortion_fir[11], DISTORTION_SHIFT(a, b, 1) + DISTORTION_SHIFT(b, c, 7), acc);
    acc = fma(distortion_fir[10], DISTORTION_SHIFT(a, b, 2) + DISTORTION_SHIFT(b, c, 6), acc);
    acc = fma(distortion_fir[9], DISTORTION_SHIFT(a, b, 3) + DISTORTION_SHIFT(b, c, 5), acc);
    acc = fma(distortion_fir[8], DISTORTION_SHIFT(a, b, 4) + DISTORTION_SHIFT(b, c, 4), acc);
    acc = fma(distortion_fir[7], DISTORTION_SHIFT(a, b, 5) + DISTORTION_SHIFT(b, c, 3), acc);
    acc = fma(distortion_fir[6], DISTORTION_SHIFT(a, b, 6) + DISTORTION_SHIFT(b, c, 2), acc);
    acc = fma(distortion_fir[5], DISTORTION_SHIFT(a, b, 7) + DISTORTION_SHIFT(b, c, 1), acc);
    acc = fma(distortion_fir[4], DISTORTION_SHIFT(a, b, 8) + b, acc);
    acc = fma(distortion_fir[3], DISTORTION_SHIFT(a, b, 9) + DISTORTION_SHIFT(a, b, 15), acc);
    acc = fma(distortion_fir[2], DISTORTION_SHIFT(a, b, 10) + DISTORTION_SHIFT(a, b, 14), acc);
    acc = fma(distortion_fir[1], DISTORTION_SHIFT(a, b, 11) + DISTORTION_SHIFT(a, b, 13), acc);
    acc = fma(distortion_fir[0], DISTORTION_SHIFT(a, b, 12), acc);
    vstore16(acc, 0, tmp + ((size_t)ch * th + r) * pitch + 16 * g);
}

/* Column pass. Work-item (g, q0, ch): coefficient rows q = DISTORTION_FIR_ROWS q0 + o (source
 * row q - PAD), columns 16g ... 16g + 15, from tmp rows q ... q + 2K: the ROWS outputs share their
 * loads (ROWS + 2K vload16 instead of ROWS (2K + 1); docs/measurements.md#kernel-forms-on-pocl);
 * each sums its smallest taps first, as the row pass (same speed as summing in row order, half the
 * rounding error). coef: 3 planes of ch_rows (a multiple of ROWS) rows of pitch. */
#define DISTORTION_FIR_ROWS 4
__kernel void distortion_fir_cols(__global const float *restrict tmp, __global float *restrict coef,
                                  const int pitch, const int th, const int ch_rows)
{
    const int g = get_global_id(0), q = DISTORTION_FIR_ROWS * get_global_id(1), ch = get_global_id(2);
    __global const float *t = tmp + ((size_t)ch * th + q) * pitch + 16 * g;
    float16 v[DISTORTION_FIR_ROWS + 2 * DISTORTION_FIR_K], acc[DISTORTION_FIR_ROWS];
#pragma unroll
    for (int j = 0; j < DISTORTION_FIR_ROWS + 2 * DISTORTION_FIR_K; ++j) v[j] = vload16(0, t + (size_t)j * pitch);
#pragma unroll
    for (int o = 0; o < DISTORTION_FIR_ROWS; ++o) {
        acc[o] = distortion_fir[DISTORTION_FIR_K] * (v[o] + v[o + 2 * DISTORTION_FIR_K]);
#pragma unroll
        for (int k = DISTORTION_FIR_K - 1; k >= 1; --k)
            acc[o] = fma(distortion_fir[k], v[o + DISTORTION_FIR_K - k] + v[o + DISTORTION_FIR_K + k], acc[o]);
        acc[o] = fma(distortion_fir[0], v[o + DISTORTION_FIR_K], acc[o]);
    }
#pragma unroll
    for (int o = 0; o < DISTORTION_FIR_ROWS; ++o)
        vstore16(acc[o], 0, coef + ((size_t)ch * ch_rows + q + o) * pitch + 16 * g);
}

/* One channel's output value v (type T: float or float16) from its B-spline sum acc and the 2x2
 * cell's samples tl tr (top) bl br (bottom): acc clamped to the cell's least and largest sample,
 * handed over to the cell's bilinear value by the weight th (HDR-safe: resample and hdr_weight in
 * clpost/stages/distortion.py). mix(x, y, t) written as fma(y - x, t, x): PoCL compiles mix as a
 * subtract, a multiply and an add (docs/benchmarks.md, "fifth pass"). */
#define DISTORTION_HANDOVER(T, v, acc, tl, tr, bl, br, tx, ty, th) do { \
        const T lo_ = min(min(tl, tr), min(bl, br)), hi_ = max(max(tl, tr), max(bl, br)); \
        const T top_ = fma((tr) - (tl), tx, tl), bottom_ = fma((br) - (bl), tx, bl); \
        const T lin_ = fma(bottom_ - top_, ty, top_), cl_ = clamp(acc, lo_, hi_); \
        v = fma(lin_ - cl_, th, cl_); \
    } while (0)

/* The 16-tap gather of the final filter, on the tiles that `distortion_bspline_tiles` does not
 * take, from a per-pixel tap table built once per map on the host (clpost/stages/distortion.py,
 * tap_table): base[i] is the index of the top-left tap of the 4x4 window in a coefficient plane
 * (-1: no preimage, colour 0) and wts holds the 4 horizontal then 4 vertical B-spline weights
 * (planes of n), computed in float64. No floor, clamp or polynomial per tap (a table is faster
 * than computing the weights per pixel; docs/measurements.md#kernel-forms-on-pocl). One work-group
 * of DISTORTION_TILE^2 per listed tile (x0, y0). */
__kernel void distortion_table(__global const float *restrict src, __global float *restrict dst,
                               __global const int *restrict base, __global const float *restrict wts,
                               __global const int *restrict tiles, __global const float *restrict hdr,
                               const int src_w, const int src_h, const int width, const int height)
{
    const int2 t = vload2(get_global_id(2), tiles);
    const int x = t.x + get_global_id(0), y = t.y + get_global_id(1);
    if (x >= width || y >= height) return;
    const int n = width * height, sn = src_w * src_h;
    const int i = y * width + x;
    const int b0 = base[i];
    if (b0 < 0) {  /* no preimage: colour 0 (whole tiles of them are listed here) */
        for (int c = 0; c < 3; ++c) dst[c * n + i] = 0.0f;
        return;
    }
    const int b = b0;
    float wx[4], wy[4];
    for (int k = 0; k < 4; ++k) {
        wx[k] = wts[k * n + i];
        wy[k] = wts[(4 + k) * n + i];
    }
    /* the 2x2 cell: samples at window (1, 1) ... (2, 2) of the 4x4 taps, from the coefficients
     * (36 f = (1 4 1) (x) (1 4 1) c, the B-spline at the knots) */
    const float tx = wts[8 * n + i], ty = wts[9 * n + i];
    const int cell = b + src_w + 1;
    const float th = mix(mix(hdr[cell], hdr[cell + 1], tx), mix(hdr[cell + src_w], hdr[cell + src_w + 1], tx), ty);
    for (int c = 0; c < 3; ++c) {
        const int plane = c * sn + b;
        float acc = 0.0f, h1[4], h2[4];
        for (int m = 0; m < 4; ++m) {
            float row = 0.0f, cm[4];
            for (int k = 0; k < 4; ++k) {
                cm[k] = src[plane + m * src_w + k];
                row += wx[k] * cm[k];
            }
            acc += wy[m] * row;
            h1[m] = cm[0] + 4.0f * cm[1] + cm[2];
            h2[m] = cm[1] + 4.0f * cm[2] + cm[3];
        }
        const float a = (h1[0] + 4.0f * h1[1] + h1[2]) * (1.0f / 36.0f), e = (h2[0] + 4.0f * h2[1] + h2[2]) * (1.0f / 36.0f);
        const float d = (h1[1] + 4.0f * h1[2] + h1[3]) * (1.0f / 36.0f), f = (h2[1] + 4.0f * h2[2] + h2[3]) * (1.0f / 36.0f);
        float v;
        DISTORTION_HANDOVER(float, v, acc, a, e, d, f, tx, ty, th);
        dst[c * n + i] = v * DISTORTION_COEF_SCALE;
    }
}

/* The cubic B-spline weights of the taps at floor - 1 ... floor + 2 for the fraction t in [0, 1)
 * (the host's bspline3, which the tap table uses; the third as 1 minus the others, the weights
 * summing to 1 by construction). */
#define DISTORTION_BSPLINE4_BODY(T) { \
        const T s = 1.0f - t, t2 = t * t, t3 = t2 * t; \
        w[0] = s * s * s * (1.0f / 6.0f); \
        w[1] = fma(0.5f, t3, (T)(2.0f / 3.0f) - t2); \
        w[3] = t3 * (1.0f / 6.0f); \
        w[2] = 1.0f - w[0] - w[1] - w[3]; \
    }
inline void distortion_bspline4(const float16 t, float16 *w) DISTORTION_BSPLINE4_BODY(float16)
inline void distortion_bspline4_1(const float t, float *w) DISTORTION_BSPLINE4_BODY(float)

/* The final filter on the tiles of DISTORTION_TILE x DISTORTION_TILE output pixels whose integer
 * displacement floor(s) - x takes at most two neighbouring values where there is a preimage (the
 * others get colour 0; host: bspline_tiles), as the
 * bilinear distortion_tiles: the 4x4 windows of a tile row lie in the 5x5 window of coefficients
 * at (x + ox - 1, y + oy - 1), read by vload16 at addresses affine in the lane; a lane whose
 * fraction f = s - (x + ox) in [0, 2) is >= 1 takes window columns 1-4, the others 0-3 (one select
 * per column), with the 4 B-spline weights of its fraction f - floor(f) (computed here in float32
 * from the float32 map; the table's are float64-derived float32; both within a few ulps). Rows
 * likewise: the 5 row sums weighted by the 4 weights placed on rows 0-3 or 1-4. One work-item:
 * one row of one tile; tiles: (x0, y0, ox, oy); coef planes of pitch x ch_rows with
 * DISTORTION_PAD pixels around the render. A work-group is one row of TILE_GROUP consecutive
 * tiles (clpost/stages/distortion.py; local size (1, TILE_GROUP)), not one tile's 16 rows: its
 * work-items read the same 5 coefficient rows of each plane 64 bytes further on each, a few
 * sequential streams, where a tile's 16 rows in turn opened ~160 (docs/benchmarks.md, "Worst
 * final, third pass").
 * Where all 16 lanes of a work-item take the same window columns (rows), the work-item reads only
 * those 4 (a branch per work-item, not per lane): 4 x 4 loads and no selects where both agree
 * (most work-items of a moderate distortion), 4 rows of 5 columns where only the rows do, the
 * 5 x 5 window with selects in the rest. The sums are the same operations in
 * the same order as the 5 x 5 form, whose extra row enters with weight 0 (docs/benchmarks.md,
 * "Worst final, third pass"). */
/* One channel: the lane's B-spline sum acc over NR rows of the window at p (5: rows 0-3 or 1-4 by
 * down; 4: the rows chosen), columns 0-3 or 1-4 by right where SEL (else the 4 at p), and the
 * cell's samples a b (top) d e (bottom) from the same loads (6 f = d0 + 4 d1 + d2, the B-spline at
 * the knots). NR and SEL are constants at every use, so each form compiles without the other's
 * selects. */
inline __attribute__((always_inline)) void distortion_bspline_ch(
    __global const float *p, const size_t pitch, const int NR, const int SEL, const int16 right,
    const int16 down, const float16 *wx, const float16 *wy, float16 *acc_, float16 *a_, float16 *b_,
    float16 *d_, float16 *e_)
{
    float16 acc = (float16)(0.0f), hl[5], hr[5];
    /* the rows written out (a loop over NR rows was not unrolled: "loop not unrolled") */
#define DISTORTION_BSPLINE_ROW(r) do { \
        __global const float *q = p + (size_t)(r) * pitch; \
        float16 d0, d1, d2, d3; \
        if (SEL) { \
            const float16 c1 = vload16(0, q + 1), c2 = vload16(0, q + 2), c3 = vload16(0, q + 3); \
            d0 = select(vload16(0, q), c1, right); \
            d1 = select(c1, c2, right); \
            d2 = select(c2, c3, right); \
            d3 = select(c3, vload16(0, q + 4), right); \
        } else { \
            d0 = vload16(0, q); \
            d1 = vload16(0, q + 1); \
            d2 = vload16(0, q + 2); \
            d3 = vload16(0, q + 3); \
        } \
        float16 rowv = wx[0] * d0; \
        rowv = fma(wx[1], d1, rowv); \
        rowv = fma(wx[2], d2, rowv); \
        rowv = fma(wx[3], d3, rowv); \
        acc = fma(wy[r], rowv, acc); \
        hl[r] = fma(4.0f, d1, d0 + d2); \
        hr[r] = fma(4.0f, d2, d1 + d3); \
    } while (0)
    DISTORTION_BSPLINE_ROW(0);
    DISTORTION_BSPLINE_ROW(1);
    DISTORTION_BSPLINE_ROW(2);
    DISTORTION_BSPLINE_ROW(3);
    if (NR == 5) DISTORTION_BSPLINE_ROW(4);
#undef DISTORTION_BSPLINE_ROW
    float16 l0, l1, l2, l3, r0, r1, r2, r3;
    if (NR == 5) {  /* the cell's rows: window rows 0-3 (fy < 1) or 1-4 */
        l0 = select(hl[0], hl[1], down); l1 = select(hl[1], hl[2], down);
        l2 = select(hl[2], hl[3], down); l3 = select(hl[3], hl[4], down);
        r0 = select(hr[0], hr[1], down); r1 = select(hr[1], hr[2], down);
        r2 = select(hr[2], hr[3], down); r3 = select(hr[3], hr[4], down);
    } else {
        l0 = hl[0]; l1 = hl[1]; l2 = hl[2]; l3 = hl[3];
        r0 = hr[0]; r1 = hr[1]; r2 = hr[2]; r3 = hr[3];
    }
    *acc_ = acc;
    *a_ = fma(4.0f, l1, l0 + l2) * (1.0f / 36.0f);
    *b_ = fma(4.0f, r1, r0 + r2) * (1.0f / 36.0f);
    *d_ = fma(4.0f, l2, l1 + l3) * (1.0f / 36.0f);
    *e_ = fma(4.0f, r2, r1 + r3) * (1.0f / 36.0f);
}

/* the output of one channel (DISTORTION_HANDOVER), colour 0 without a preimage */
#define DISTORTION_BSPLINE_STORE(acc, a, b, d, e, c) do { \
        float16 v; \
        DISTORTION_HANDOVER(float16, v, acc, a, b, d, e, tx, ty, th); \
        vstore16(select((float16)(0.0f), v * DISTORTION_COEF_SCALE, ok), 0, dst + (c) * n + i); \
    } while (0)
#define DISTORTION_BSPLINE_CHANNELS(off, NR, SEL, wyv) do { \
        for (int c = 0; c < 3; ++c) { \
            float16 acc, a, b, d, e; \
            distortion_bspline_ch(coef + c * sn + base + (off), pitch, NR, SEL, right, down, wx, wyv, \
                                  &acc, &a, &b, &d, &e); \
            DISTORTION_BSPLINE_STORE(acc, a, b, d, e, c); \
        } \
    } while (0)

__kernel void distortion_bspline_tiles(__global const float *restrict coef, __global float *restrict dst,
                                       __global const float *restrict map, __global const int *restrict tiles,
                                       __global const float *restrict hdr,
                                       const int pitch, const int ch_rows, const int width, const int height,
                                       const int ntiles)
{
    const int row = get_global_id(0), tile = get_global_id(1);
    if (tile >= ntiles) return;  /* the tile count rounded up to whole work-groups (host) */
    const int4 t = vload4(tile, tiles);
    const int y = t.y + row;
    if (y >= height) return;  /* a tile across the bottom edge (whole in x: host) */
    const size_t n = (size_t)width * height, sn = (size_t)pitch * ch_rows;
    const size_t i = (size_t)y * width + t.x;
    const float16 sx = vload16(0, map + i);
    const int16 ok = sx > -1.0e29f;  /* no preimage (-1e30): colour 0 */
    const float16 fx = select((float16)(0.0f), sx - ((float)(t.x + t.z) + CLP_LANES16), ok);
    const float16 fy = select((float16)(0.0f), vload16(0, map + n + i) - (float)(y + t.w), ok);
    const int16 right = fx >= 1.0f, down = fy >= 1.0f;
    const float16 tx = select(fx, fx - 1.0f, right), ty = select(fy, fy - 1.0f, down);
    float16 wx[4], v4[4], wy[5];
    distortion_bspline4(tx, wx);
    distortion_bspline4(ty, v4);
    /* the hand-over weight, bilinear over the lane's 2x2 cell at (x + ox, y + oy) + (right, down):
     * tent weights on the 3x3 samples there, one of the three 0 (as distortion_tiles) */
    const float16 bx0 = max(1.0f - fx, 0.0f), bx2 = max(fx - 1.0f, 0.0f), bx1 = 1.0f - bx0 - bx2;
    const float16 by0 = max(1.0f - fy, 0.0f), by2 = max(fy - 1.0f, 0.0f), by1 = 1.0f - by0 - by2;
    const size_t base = (size_t)(y + t.w - 1 + DISTORTION_PAD) * pitch + (size_t)(t.x + t.z - 1 + DISTORTION_PAD);
    const size_t cell = base + pitch + 1;
    float16 th = (float16)(0.0f);
#pragma unroll
    for (int r = 0; r < 3; ++r) {
        __global const float *q = hdr + cell + (size_t)r * pitch;
        th = fma(r == 0 ? by0 : (r == 1 ? by1 : by2),
                 bx0 * vload16(0, q) + bx1 * vload16(0, q + 1) + bx2 * vload16(0, q + 2), th);
    }
    /* one window for every lane? (all() / any() of a vector: one test per work-item) */
    const int allr = all(right), onex = allr || !any(right);
    const int alld = all(down), oney = alld || !any(down);
    if (onex && oney) {
        DISTORTION_BSPLINE_CHANNELS((size_t)allr + (size_t)alld * pitch, 4, 0, v4);
    } else if (oney) {
        DISTORTION_BSPLINE_CHANNELS((size_t)alld * pitch, 4, 1, v4);
    } else {
        wy[0] = select(v4[0], (float16)(0.0f), down);
        wy[1] = select(v4[1], v4[0], down);
        wy[2] = select(v4[2], v4[1], down);
        wy[3] = select(v4[3], v4[2], down);
        wy[4] = select((float16)(0.0f), v4[3], down);
        DISTORTION_BSPLINE_CHANNELS(0, 5, 1, wy);
    }
}

/* HDR-safe final filter, preparation (clpost/stages/distortion.py: resample, hdr_weight): for every
 * position of the coefficient planes (pitch x ch_rows, DISTORTION_PAD pixels around the render,
 * so the gathers address it as they address coefficients), hdr = the hand-over weight there: over
 * the 5x5 neighbourhood of the edge-extended source's channel sum R + G + B, with its least lo and
 * largest hi, clamp((hi - R1 lo) / ((R2 - R1) lo), 0, 1) for lo > 0, 1 where lo <= 0 < hi - lo
 * (one plane for all channels: a third of the work of a per-channel weight). One work-item: 16
 * positions of DISTORTION_FIR_ROWS rows, the 5-wide row min/max by constant shuffles of a 32-wide
 * window (vector loads, or a private copy with clamped indices at the row's ends). The gathers take the 2x2
 * cell's samples from the coefficients they load anyway (36 f = (1 4 1) (x) (1 4 1) c): no loads. */
#define DISTORTION_R1 32.0f
#define DISTORTION_R2 128.0f
/* The channel sum / DISTORTION_HDR_SCALE: R + G + B reaches 3 max|f| and the weight's (R2 - R1) lo
 * 96 x that, which overflowed float (inf - inf: NaN weights) from max|f| ~ 1e36; / 512 keeps both
 * below max|f|. The weight is a ratio, so (a power of two, no underflow: |f| > 1e-35) the same up to
 * native_divide's rounding. Each channel is scaled before the sum, summed in the order (R + G) + B as
 * before (an fma each: one more operation). */
#define DISTORTION_HDR_SCALE 512.0f
#define DISTORTION_SUM3(r, g, b) \
    fma((b), 1.0f / DISTORTION_HDR_SCALE, fma((g), 1.0f / DISTORTION_HDR_SCALE, (r) * (1.0f / DISTORTION_HDR_SCALE)))
/* clamp((hi - R1 lo) / ((R2 - R1) lo), 0, 1), for lo > 0. native_divide: PoCL's correctly rounded
 * float16 division is not vectorised (half the kernel's time); a weight needs no last ulp */
#define DISTORTION_HDR_RATIO(lo, hi) \
    clamp(native_divide((hi) - DISTORTION_R1 * (lo), (DISTORTION_R2 - DISTORTION_R1) * (lo)), 0.0f, 1.0f)
inline float16 distortion_hdr_t(const float16 lo, const float16 hi)
{
    const float16 r = DISTORTION_HDR_RATIO(lo, hi);
    return select(select((float16)(0.0f), (float16)(1.0f), hi > lo), r, lo > 0.0f);
}
/* lo, hi (float16) take the least and largest of the 5 values at lanes l ... l + 4 of a:b */
#define DISTORTION_MINMAX5(a, b, lo, hi) do { \
        const float16 v1 = DISTORTION_SHIFT(a, b, 1), v2 = DISTORTION_SHIFT(a, b, 2); \
        const float16 v3 = DISTORTION_SHIFT(a, b, 3), v4 = DISTORTION_SHIFT(a, b, 4); \
        lo = min(lo, min(min(a, v1), min(min(v2, v3), v4))); \
        hi = max(hi, max(max(a, v1), max(max(v2, v3), v4))); \
    } while (0)
__kernel void distortion_dering(__global const float *restrict src, __global float *restrict hdr,
                                const int src_w, const int src_h,
                                const int pitch, const int ch_rows)
{
    const int g = get_global_id(0), q0 = DISTORTION_FIR_ROWS * get_global_id(1);
    const size_t sn = (size_t)src_w * src_h;
    const int sy = q0 - DISTORTION_PAD;      /* source row of the first row (before the edge repeat) */
    const int x0 = 16 * g - DISTORTION_PAD;  /* source column of lane 0 */
    const int inside = x0 - 2 >= 0 && x0 + 29 <= src_w - 1;
    /* the ROWS output rows share their 4 + ROWS input rows' 5-wide min/max (as distortion_fir_cols) */
    float16 rlo[DISTORTION_FIR_ROWS + 4], rhi[DISTORTION_FIR_ROWS + 4];
    if (inside) {  /* the loops twice, so the branch is not taken per row */
        for (int j = 0; j < DISTORTION_FIR_ROWS + 4; ++j) {
            __global const float *s = src + (size_t)clamp(sy - 2 + j, 0, src_h - 1) * src_w + x0 - 2;
            const float16 a = DISTORTION_SUM3(vload16(0, s), vload16(0, s + sn), vload16(0, s + 2 * sn));
            const float16 b = DISTORTION_SUM3(vload16(1, s), vload16(1, s + sn), vload16(1, s + 2 * sn));
            rlo[j] = (float16)(INFINITY);
            rhi[j] = (float16)(-INFINITY);
            DISTORTION_MINMAX5(a, b, rlo[j], rhi[j]);
        }
    } else {  /* the row's edge repeated: a private copy (as distortion_fir_rows) */
        for (int j = 0; j < DISTORTION_FIR_ROWS + 4; ++j) {
            __global const float *s = src + (size_t)clamp(sy - 2 + j, 0, src_h - 1) * src_w;
            float win[32];
            for (int k = 0; k < 32; ++k) {
                const int x = clamp(x0 - 2 + k, 0, src_w - 1);
                win[k] = DISTORTION_SUM3(s[x], s[sn + x], s[2 * sn + x]);
            }
            const float16 a = vload16(0, win), b = vload16(1, win);
            rlo[j] = (float16)(INFINITY);
            rhi[j] = (float16)(-INFINITY);
            DISTORTION_MINMAX5(a, b, rlo[j], rhi[j]);
        }
    }
#pragma unroll
    for (int o = 0; o < DISTORTION_FIR_ROWS; ++o) {
        const float16 lo = min(min(min(rlo[o], rlo[o + 1]), min(rlo[o + 2], rlo[o + 3])), rlo[o + 4]);
        const float16 hi = max(max(max(rhi[o], rhi[o + 1]), max(rhi[o + 2], rhi[o + 3])), rhi[o + 4]);
        vstore16(distortion_hdr_t(lo, hi), 0, hdr + (size_t)(q0 + o) * pitch + 16 * g);
    }
}

/* The final filter's one-pixel (GPU) forms: `distortion_fir_rows1`, `_fir_cols1`, `_dering1` and
 * `_bspline_tiles1` do per work-item, for one output position, the operations the 16-lane kernels
 * above do per lane, in the same order (so PoCL gives the same bits; tests/test_distortion.py), with
 * consecutive work-items on consecutive x: a warp's loads coalesce, and no work-item holds 16-wide
 * windows (`distortion_fir_cols` keeps 28 float16 rows in flight, which a GPU spills). Chosen where
 * `Runtime.wide` is false (clpost/stages/distortion.py). */
__kernel void distortion_fir_rows1(__global const float *restrict src, __global float *restrict tmp,
                                   const int src_w, const int src_h, const int pitch, const int th)
{
    const int x = get_global_id(0), r = get_global_id(1), ch = get_global_id(2);
    if (x >= pitch || r >= th) return;
    const int sy = clamp(r - DISTORTION_PAD - DISTORTION_FIR_K, 0, src_h - 1);
    __global const float *s = src + ((size_t)ch * src_h + sy) * src_w;
    const int x0 = x - DISTORTION_PAD - DISTORTION_FIR_K;  /* window element j: column x0 + j */
#define DISTORTION_W(j) (s[clamp(x0 + (j), 0, src_w - 1)] * (1.0f / DISTORTION_COEF_SCALE))
    float acc = distortion_fir[12] * (DISTORTION_W(0) + DISTORTION_W(24));
#pragma unroll
    for (int k = 11; k >= 1; --k)
        acc = fma(distortion_fir[k], DISTORTION_W(12 - k) + DISTORTION_W(12 + k), acc);
    acc = fma(distortion_fir[0], DISTORTION_W(12), acc);
#undef DISTORTION_W
    tmp[((size_t)ch * th + r) * pitch + x] = acc;
}

__kernel void distortion_fir_cols1(__global const float *restrict tmp, __global float *restrict coef,
                                   const int pitch, const int th, const int ch_rows)
{
    const int x = get_global_id(0), q = get_global_id(1), ch = get_global_id(2);
    if (x >= pitch || q >= ch_rows) return;
    __global const float *t = tmp + ((size_t)ch * th + q) * pitch + x;
    float acc = distortion_fir[DISTORTION_FIR_K] * (t[0] + t[(size_t)2 * DISTORTION_FIR_K * pitch]);
#pragma unroll
    for (int k = DISTORTION_FIR_K - 1; k >= 1; --k)
        acc = fma(distortion_fir[k], t[(size_t)(DISTORTION_FIR_K - k) * pitch] + t[(size_t)(DISTORTION_FIR_K + k) * pitch],
                  acc);
    acc = fma(distortion_fir[0], t[(size_t)DISTORTION_FIR_K * pitch], acc);
    coef[((size_t)ch * ch_rows + q) * pitch + x] = acc;
}

__kernel void distortion_dering1(__global const float *restrict src, __global float *restrict hdr,
                                 const int src_w, const int src_h, const int pitch, const int ch_rows)
{
    const int x = get_global_id(0), q = get_global_id(1);
    if (x >= pitch || q >= ch_rows) return;
    const size_t sn = (size_t)src_w * src_h;
    int cols[5];
    for (int k = 0; k < 5; ++k) cols[k] = clamp(x - DISTORTION_PAD - 2 + k, 0, src_w - 1);
    float rlo[5], rhi[5];
    for (int j = 0; j < 5; ++j) {
        __global const float *s = src + (size_t)clamp(q - DISTORTION_PAD - 2 + j, 0, src_h - 1) * src_w;
        float v[5];
        for (int k = 0; k < 5; ++k) v[k] = DISTORTION_SUM3(s[cols[k]], s[sn + cols[k]], s[2 * sn + cols[k]]);
        rlo[j] = min((float)INFINITY, min(min(v[0], v[1]), min(min(v[2], v[3]), v[4])));
        rhi[j] = max((float)-INFINITY, max(max(v[0], v[1]), max(max(v[2], v[3]), v[4])));
    }
    const float lo = min(min(min(rlo[0], rlo[1]), min(rlo[2], rlo[3])), rlo[4]);
    const float hi = max(max(max(rhi[0], rhi[1]), max(rhi[2], rhi[3])), rhi[4]);
    hdr[(size_t)q * pitch + x] = lo > 0.0f ? DISTORTION_HDR_RATIO(lo, hi) : (hi > lo ? 1.0f : 0.0f);
}

/* distortion_bspline_tiles for one pixel: lane `get_global_id(0)` of the tile row; its own 4x4
 * window (the 16-lane form's 5x5 and selects reduce to it, the extra row and column entering with
 * weight 0). One work-group per tile (TILE x TILE work-items). */
__kernel void distortion_bspline_tiles1(__global const float *restrict coef, __global float *restrict dst,
                                        __global const float *restrict map, __global const int *restrict tiles,
                                        __global const float *restrict hdr,
                                        const int pitch, const int ch_rows, const int width, const int height,
                                        const int ntiles)
{
    const int lane = get_global_id(0), row = get_global_id(1), tile = get_global_id(2);
    if (tile >= ntiles) return;
    const int4 t = vload4(tile, tiles);
    const int y = t.y + row;
    if (y >= height) return;
    const size_t n = (size_t)width * height, sn = (size_t)pitch * ch_rows;
    const size_t i = (size_t)y * width + t.x + lane;
    const float sx = map[i];
    const int ok = sx > -1.0e29f;
    const float fx = ok ? sx - ((float)(t.x + t.z) + (float)lane) : 0.0f;
    const float fy = ok ? map[n + i] - (float)(y + t.w) : 0.0f;
    const int right = fx >= 1.0f, down = fy >= 1.0f;
    const float tx = right ? fx - 1.0f : fx, ty = down ? fy - 1.0f : fy;
    float wx[4], wy[4];
    distortion_bspline4_1(tx, wx);
    distortion_bspline4_1(ty, wy);
    const float bx0 = max(1.0f - fx, 0.0f), bx2 = max(fx - 1.0f, 0.0f), bx1 = 1.0f - bx0 - bx2;
    const float by0 = max(1.0f - fy, 0.0f), by2 = max(fy - 1.0f, 0.0f), by1 = 1.0f - by0 - by2;
    const size_t base = (size_t)(y + t.w - 1 + DISTORTION_PAD) * pitch + (size_t)(t.x + t.z - 1 + DISTORTION_PAD)
        + (size_t)lane;
    const size_t cell = base + pitch + 1;
    float th = 0.0f;
#pragma unroll
    for (int r = 0; r < 3; ++r) {
        __global const float *h = hdr + cell + (size_t)r * pitch;
        th = fma(r == 0 ? by0 : (r == 1 ? by1 : by2), bx0 * h[0] + bx1 * h[1] + bx2 * h[2], th);
    }
    const size_t off = base + (size_t)right + (size_t)down * pitch;
    for (int c = 0; c < 3; ++c) {
        __global const float *p = coef + c * sn + off;
        float acc = 0.0f, hl[4], hr[4];
#pragma unroll
        for (int r = 0; r < 4; ++r) {
            __global const float *q = p + (size_t)r * pitch;
            const float d0 = q[0], d1 = q[1], d2 = q[2], d3 = q[3];
            float rowv = wx[0] * d0;
            rowv = fma(wx[1], d1, rowv);
            rowv = fma(wx[2], d2, rowv);
            rowv = fma(wx[3], d3, rowv);
            acc = fma(wy[r], rowv, acc);
            hl[r] = fma(4.0f, d1, d0 + d2);
            hr[r] = fma(4.0f, d2, d1 + d3);
        }
        const float a = fma(4.0f, hl[1], hl[0] + hl[2]) * (1.0f / 36.0f);
        const float b = fma(4.0f, hr[1], hr[0] + hr[2]) * (1.0f / 36.0f);
        const float d = fma(4.0f, hl[2], hl[1] + hl[3]) * (1.0f / 36.0f);
        const float e = fma(4.0f, hr[2], hr[1] + hr[3]) * (1.0f / 36.0f);
        float v;
        DISTORTION_HANDOVER(float, v, acc, a, b, d, e, tx, ty, th);
        dst[c * n + i] = ok ? v * DISTORTION_COEF_SCALE : 0.0f;
    }
}

/* The distorted image's depth and velocity (the colour kernels' companions, so the host does no
 * per-pixel work): nearest source pixel `flat[i]` (-1: no preimage -> depth +inf, velocity 0);
 * velocities are displacements in the render, so they map to the output by the inverse of the
 * map's Jacobian (`jinv`, 4 planes: a b; c d), exactly as Distortion.host_buffers computes them.
 * One output pixel per work-item; global size rounded up to the work-group (hence the guard). */
__kernel void distortion_aux(__global const float *restrict depth_in, __global const float *restrict vel_in,
                             __global const int *restrict flat, __global const float *restrict jinv,
                             __global float *restrict depth_out, __global float *restrict vel_out,
                             const int n, const int has_depth, const int has_velocity)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const int s = flat[i];
    if (has_depth)
        depth_out[i] = s < 0 ? INFINITY : depth_in[s];
    if (has_velocity) {
        const size_t m = (size_t)n;
        const float vx = s < 0 ? 0.0f : vel_in[2 * (size_t)s], vy = s < 0 ? 0.0f : vel_in[2 * (size_t)s + 1];
        vel_out[2 * (size_t)i] = jinv[i] * vx + jinv[m + i] * vy;
        vel_out[2 * (size_t)i + 1] = jinv[2 * m + i] * vx + jinv[3 * m + i] * vy;
    }
}
