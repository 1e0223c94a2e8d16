/* coma: third-order coma as a gather with the comet PSF of the pixel's field height.
 * clpost/stages/coma.py documents the formulas; its reference() is the oracle.
 *
 * Buffers: colour planar (c*n + i); padded = colour as float4 (RGB_) with COMA_PAD px of edge
 * values on every side (one float4 load per bilinear corner: tap addresses vary per pixel, so
 * nothing vectorises across pixels); lut = 2 planes of COMA_LUT_SIZE values over image height
 * [0, r_max]: C (mm) and dC/dr; taps = COMA_TAPS landing offsets (sagittal, radial) in units of
 * C of a Vogel spiral over the pupil.
 * Defines: COMA_TAPS, COMA_PAD, COMA_LUT_SIZE.
 */
#define COMA_MAX_C ((float)(COMA_PAD - 1) / 3.0f)

__kernel void coma_pad(__global const float *restrict src, __global float4 *restrict padded,
                       const int width, const int height)
{
    const int x = get_global_id(0), y = get_global_id(1);
    const int pw = width + 2 * COMA_PAD, ph = height + 2 * COMA_PAD;
    if (x >= pw || y >= ph) return;
    const int sx = clamp(x - COMA_PAD, 0, width - 1), sy = clamp(y - COMA_PAD, 0, height - 1);
    const size_t n = (size_t)width * height;
    const size_t i = (size_t)sy * width + sx, j = (size_t)y * pw + x;
    padded[j] = (float4)(src[i], src[n + i], src[2 * n + i], 0.0f);
}

__kernel void coma(__global const float4 *restrict padded, __global float *restrict dst,
                   __global const float *restrict lut, __constant float2 *taps,
                   const int width, const int height, const float cx, const float cy,
                   const float pitch_mm, const float lut_scale)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * height;
    const size_t i = (size_t)y * width + x;
    const int pw = width + 2 * COMA_PAD;

    const float dx = (float)x - cx, dy = (float)y - cy;
    const float r = sqrt(dx * dx + dy * dy);
    const float ex = r > 0.0f ? dx / r : 1.0f, ey = r > 0.0f ? dy / r : 0.0f;
    const float t = fmin(r * pitch_mm * lut_scale, (float)(COMA_LUT_SIZE - 1));
    const int k0 = min((int)t, COMA_LUT_SIZE - 2);
    const float craw = mix(lut[k0], lut[k0 + 1], t - (float)k0) / pitch_mm;
    const float c = clamp(craw, -COMA_MAX_C, COMA_MAX_C);
    /* C' = dC/dr (0 where the comet is capped) and C/r (-> C'(0) on the axis): the Jacobian of
     * each tap's map, so a point's light is conserved although the PSF changes with r */
    const float dc = fabs(craw) > COMA_MAX_C ? 0.0f
                   : mix(lut[COMA_LUT_SIZE + k0], lut[COMA_LUT_SIZE + k0 + 1], t - (float)k0);
    const float q = r > 0.0f ? c / r : dc;
    /* gather from x - C (ts * e_s + tr * e_r), e_s = (-ey, ex), e_r = (ex, ey) */
    const float2 ax_s = (float2)(ey, -ex) * c, ax_r = (float2)(-ex, -ey) * c;
    const float bx = (float)(x + COMA_PAD), by = (float)(y + COMA_PAD);
    float4 acc = (float4)(0.0f);
    for (int k = 0; k < COMA_TAPS; ++k) {
        const float2 u = taps[k];
        const float jac = fmax((1.0f - dc * u.y) * (1.0f - q * u.y) + q * dc * u.x * u.x, 0.0f);
        const float px = bx + ax_s.x * u.x + ax_r.x * u.y;
        const float py = by + ax_s.y * u.x + ax_r.y * u.y;
        const float fx0 = floor(px), fy0 = floor(py);
        const float fx = px - fx0, fy = py - fy0;
        const int j = (int)fy0 * pw + (int)fx0;
        const float4 top = mix(padded[j], padded[j + 1], fx);
        const float4 bot = mix(padded[j + pw], padded[j + pw + 1], fx);
        acc += mix(top, bot, fy) * jac;
    }
    const float inv = 1.0f / (float)COMA_TAPS;
    dst[i] = acc.x * inv;
    dst[n + i] = acc.y * inv;
    dst[2 * n + i] = acc.z * inv;
}
