/* distortion: resample the undistorted (pinhole) render into the distorted image.
 *
 * map holds, for every output pixel i, the source position in the render (planar: x at map[i],
 * y at map[n + i], render pixel centres at integers). It is computed once per (camera, size) on
 * the host in float64 by the exact Newton inverse of the OpenCV model (clpost/calibration.py);
 * a pixel with no preimage (outside the render, beyond the fold, no convergence) has x = -1e30
 * and gets color 0 (its alpha, written on the host, is 0).
 *
 * DISTORTION_FILTER 1: bilinear (4 taps, draft/preview). 3: cubic convolution, a = -3/4 (16 taps,
 * final; OpenCV's INTER_CUBIC), clamped below at 0 so HDR edges cannot ring to negative values.
 * a = -3/4 and no range clamp because they keep edges where they are: checkerboard corners
 * detected on the output are 0.038 px RMS from the true model (the detector's floor on the
 * undistorted render) vs 0.055 px with a = -1/2 clamped to the 4 nearest samples
 * (docs/distortion_calibration.md). Taps outside the render repeat its edge (index clamp): the map is arbitrary, so tap
 * offsets are not uniform and padding would not make addresses affine anyway.
 */
#ifndef DISTORTION_FILTER
#define DISTORTION_FILTER 1
#endif

inline float distortion_tap(__global const float *src, const size_t plane, int x, int y,
                            const int sw, const int sh) {
    x = clamp(x, 0, sw - 1);
    y = clamp(y, 0, sh - 1);
    return src[plane + (size_t)y * (size_t)sw + (size_t)x];
}

/* Keys (1981) cubic convolution kernel, a = -3/4:
 * (a+2)|t|^3 - (a+3)|t|^2 + 1 on [0, 1], a(|t|^3 - 5|t|^2 + 8|t| - 4) on [1, 2) */
inline float distortion_keys(float t) {
    t = fabs(t);
    if (t <= 1.0f) return (1.25f * t - 2.25f) * t * t + 1.0f;
    if (t < 2.0f) return ((-0.75f * t + 3.75f) * t - 6.0f) * t + 3.0f;
    return 0.0f;
}

__kernel void distortion(__global const float *restrict src, __global float *restrict dst,
                         __global const float *restrict map, const int src_w, const int src_h,
                         const int width, const int height)
{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * (size_t)height;
    const size_t sn = (size_t)src_w * (size_t)src_h;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
    const float sx = map[i];
    const float sy = map[n + i];
    if (!(sx > -1.0e29f)) {
        dst[i] = 0.0f;
        dst[n + i] = 0.0f;
        dst[2 * n + i] = 0.0f;
        return;
    }
    const float fx0 = floor(sx), fy0 = floor(sy);
    const int x0 = (int)fx0, y0 = (int)fy0;
    const float tx = sx - fx0, ty = sy - fy0;
    for (int c = 0; c < 3; ++c) {
        const size_t plane = (size_t)c * sn;
        const float a = distortion_tap(src, plane, x0, y0, src_w, src_h);
        const float b = distortion_tap(src, plane, x0 + 1, y0, src_w, src_h);
        const float d = distortion_tap(src, plane, x0, y0 + 1, src_w, src_h);
        const float e = distortion_tap(src, plane, x0 + 1, y0 + 1, src_w, src_h);
#if DISTORTION_FILTER == 1
        const float v = (a * (1.0f - tx) + b * tx) * (1.0f - ty) + (d * (1.0f - tx) + e * tx) * ty;
#else
        float wx[4], wy[4];
        for (int k = 0; k < 4; ++k) {
            wx[k] = distortion_keys(tx - (float)(k - 1));
            wy[k] = distortion_keys(ty - (float)(k - 1));
        }
        float acc = 0.0f;
        for (int m = 0; m < 4; ++m) {
            float row = 0.0f;
            for (int k = 0; k < 4; ++k)
                row += wx[k] * distortion_tap(src, plane, x0 + k - 1, y0 + m - 1, src_w, src_h);
            acc += wy[m] * row;
        }
        const float v = fmax(acc, 0.0f);
#endif
        dst[(size_t)c * n + i] = v;
    }
}

/* The bicubic resampling (final) from a per-pixel tap table built once per map on the host
 * (clpost/stages/distortion.py, tap_table): base[i] is the index of the top-left tap of the 4×4
 * window in a source plane (-1: no preimage, colour 0) and wts holds the 4 horizontal then 4
 * vertical weights (planes of n), computed in float64 with the edge repeat folded in (the window
 * is moved inside the source and the weight of a tap beyond the edge is added to the edge tap).
 * The loop has no floor, no clamp and no filter polynomial: 2.0× faster than `distortion` at
 * 1080p (45 vs 108 ms, best of 10, same run, loaded machine). Bilinear stays in `distortion`:
 * its table version was not faster (24.5 vs 17.5 ms). Needs a source of at least 4×4 px. */
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
