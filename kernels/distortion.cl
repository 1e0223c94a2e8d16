/* distortion: resample the undistorted (pinhole) render into the distorted image.
 *
 * map holds, for every output pixel i, the source position in the render (planar: x at map[i],
 * y at map[n + i], render pixel centres at integers). It is computed once per (camera, size) on
 * the host in float64 by the exact Newton inverse of the OpenCV model (clpost/calibration.py);
 * a pixel with no preimage (outside the render, beyond the fold, no convergence) has x = -1e30
 * and gets color 0 (its alpha, written on the host, is 0).
 *
 * DISTORTION_FILTER 1: bilinear (4 taps, draft/preview), kernel `distortion`.
 * DISTORTION_FILTER 3: cubic B-spline interpolation (final): the B-spline coefficients of the
 * source (`distortion_bspline_rows` then `_cols`, Unser 1999) and 16 taps with B-spline weights
 * from a per-pixel table (`distortion_table`), clamped below at 0 so HDR edges cannot ring to
 * negative values. Why not Keys' cubic convolution (OpenCV's INTER_CUBIC): it is only first-order
 * and moves an edge by up to ~0.03 px depending on its sub-pixel phase, which cost 5-8 % in the
 * recovered k2/p2 of the checkerboard calibration; the B-spline is exact for cubics and keeps
 * every parameter within 1 % (docs/distortion_calibration.md). Taps outside the render repeat its
 * edge (the coefficients are computed on a copy padded by DISTORTION_PAD edge pixels, as scipy's
 * map_coordinates(order=3, mode="nearest") does, which is the reference).
 */

/* Bilinear. One output pixel of the map: taps beyond the render repeat its edge, no preimage ->
 * colour 0. No floor/clamp calls and a select instead of an early return (8.4 vs 11.0 ms at
 * 1080p, one pixel per work-item, same run). */
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
 * row of one tile. tiles: (x0, y0, ox, oy) per tile. */
#define DISTORTION_TILE 16
__kernel void distortion_tiles(__global const float *restrict src, __global float *restrict dst,
                               __global const float *restrict map, __global const int *restrict tiles,
                               const int src_w, const int src_h, const int width, const int height)
{
    const int row = get_global_id(0), tile = get_global_id(1);
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

/* Cubic B-spline prefilter (Unser, "Splines: a perfect fit for signal and image processing",
 * IEEE SPM 1999): gain (1 - z)(1 - 1/z) = 6, then a causal and an anticausal first-order recursion
 * with the pole z = sqrt(3) - 2, mirror-boundary initialisations as scipy.ndimage (ni_splines.c).
 * The causal sum is truncated after DISTORTION_HORIZON terms (|z|^32 < 1e-18; exact for n <= 33). */
#define DISTORTION_PAD 12
#define DISTORTION_HORIZON 32
#define DISTORTION_POLE (-0.267949192431122706f)

/* c[0], c[stride], ... <- the B-spline coefficients of 6 * (the values there): two sweeps, the
 * gain folded into the causal one */
inline void distortion_bspline_line(__global float *c, const int n, const int stride)
{
    const float z = DISTORTION_POLE;
    const float zn1 = pown(z, n - 1);
    const int m = n - 1 < DISTORTION_HORIZON ? n - 1 : DISTORTION_HORIZON;
    float c0 = c[0] + zn1 * c[(n - 1) * stride], zi = z;
    for (int i = 1; i < m; ++i) {
        c0 += zi * (c[i * stride] + zn1 * c[(n - 1 - i) * stride]);
        zi *= z;
    }
    float prev = 6.0f * c0 / (1.0f - zn1 * zn1);
    c[0] = prev;
    for (int i = 1; i < n; ++i) {
        prev = mad(z, prev, 6.0f * c[i * stride]);
        c[i * stride] = prev;
    }
    prev = (z * c[(n - 2) * stride] + prev) * z / (z * z - 1.0f);
    c[(n - 1) * stride] = prev;
    for (int i = n - 2; i >= 0; --i) {
        prev = z * (prev - c[i * stride]);
        c[i * stride] = prev;
    }
}

/* one work-item per (padded row, channel): copy the row with DISTORTION_PAD edge pixels on each
 * side (edge repeat), then filter it along x */
__kernel void distortion_bspline_rows(__global const float *restrict src, __global float *restrict coef,
                                      const int src_w, const int src_h, const int pw, const int ph)
{
    const int j = get_global_id(0), ch = get_global_id(1);
    if (j >= ph) return;
    const int sy = clamp(j - DISTORTION_PAD, 0, src_h - 1);
    __global const float *s = src + (size_t)ch * src_w * src_h + (size_t)sy * src_w;
    __global float *c = coef + (size_t)ch * pw * ph + (size_t)j * pw;
    for (int i = 0; i < DISTORTION_PAD; ++i) {
        c[i] = s[0];
        c[pw - 1 - i] = s[src_w - 1];
    }
    for (int i = 0; i < src_w; ++i) c[DISTORTION_PAD + i] = s[i];
    distortion_bspline_line(c, pw, 1);
}

/* one work-item per (padded column, channel): filter along y (neighbouring work-items walk
 * neighbouring columns, so PoCL can vectorise across them) */
__kernel void distortion_bspline_cols(__global float *restrict coef, const int pw, const int ph)
{
    const int i = get_global_id(0), ch = get_global_id(1);
    if (i >= pw) return;
    distortion_bspline_line(coef + (size_t)ch * pw * ph + i, ph, pw);
}

/* The 16-tap gather of the final filter from a per-pixel tap table built once per map on the host
 * (clpost/stages/distortion.py, tap_table): base[i] is the index of the top-left tap of the 4x4
 * window in a coefficient plane (-1: no preimage, colour 0) and wts holds the 4 horizontal then
 * 4 vertical B-spline weights (planes of n), computed in float64. No floor, clamp or polynomial
 * per tap (a table was 2x faster than computing Keys weights per pixel at 1080p; bilinear computes
 * its taps: its table version was not faster). */
__kernel void distortion_table(__global const float *restrict src, __global float *restrict dst,
                               __global const int *restrict base, __global const float *restrict wts,
                               const int src_w, const int src_h, const int width, const int height)
{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= width || y >= height) return;
    const int n = width * height, sn = src_w * src_h;
    const int i = y * width + x;
    const int b0 = base[i];
    const int b = b0 < 0 ? 0 : b0;
    float wx[4], wy[4];
    for (int k = 0; k < 4; ++k) {
        wx[k] = wts[k * n + i];
        wy[k] = wts[(4 + k) * n + i];
    }
    for (int c = 0; c < 3; ++c) {
        const int plane = c * sn + b;
        float acc = 0.0f;
        for (int m = 0; m < 4; ++m) {
            float row = 0.0f;
            for (int k = 0; k < 4; ++k)
                row += wx[k] * src[plane + m * src_w + k];
            acc += wy[m] * row;
        }
        acc = acc > 0.0f ? acc : 0.0f;
        dst[c * n + i] = b0 < 0 ? 0.0f : acc;
    }
}
