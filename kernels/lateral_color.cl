/* lateral_color: per-channel radial resampling (chromatic difference of magnification).
 * clpost/stages/lateral_color.py documents the formulas; its reference() is the oracle.
 *
 * Buffers: colour planar (c*n + i); lut = 6 planes of LATERAL_COLOR_LUT_SIZE values over the
 * output image height: r/rho for R, G, B, then the flux Jacobian for R, G, B. A gather of three
 * bilinear taps per pixel: cheap enough that clamping at the border costs nothing measurable.
 * Defines: LATERAL_COLOR_LUT_SIZE.
 */
__kernel void lateral_color(__global const float *restrict src, __global float *restrict dst,
                            __global const float *restrict lut, const int width, const int height,
                            const float cx, const float cy, const float lut_per_px)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * height;
    const size_t i = (size_t)y * width + x;
    const float dx = (float)x - cx, dy = (float)y - cy;
    const float t = fmin(sqrt(dx * dx + dy * dy) * lut_per_px, (float)(LATERAL_COLOR_LUT_SIZE - 1));
    const int k0 = min((int)t, LATERAL_COLOR_LUT_SIZE - 2);
    const float ft = t - (float)k0;
    for (int c = 0; c < 3; ++c) {
        const float s = mix(lut[c * LATERAL_COLOR_LUT_SIZE + k0], lut[c * LATERAL_COLOR_LUT_SIZE + k0 + 1], ft);
        const float jac = mix(lut[(3 + c) * LATERAL_COLOR_LUT_SIZE + k0], lut[(3 + c) * LATERAL_COLOR_LUT_SIZE + k0 + 1], ft);
        const float px = clamp(cx + dx * s, 0.0f, (float)(width - 1));
        const float py = clamp(cy + dy * s, 0.0f, (float)(height - 1));
        const int x0 = (int)px, y0 = (int)py;
        const int x1 = min(x0 + 1, width - 1), y1 = min(y0 + 1, height - 1);
        const float fx = px - (float)x0, fy = py - (float)y0;
        __global const float *p = src + c * n;
        const float top = mix(p[y0 * width + x0], p[y0 * width + x1], fx);
        const float bot = mix(p[y1 * width + x0], p[y1 * width + x1], fx);
        dst[c * n + i] = mix(top, bot, fy) * jac;
    }
}
