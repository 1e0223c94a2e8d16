/* astigmatism: field curvature + astigmatism as a per-pixel elliptical gather.
 * clpost/stages/astigmatism.py documents the formulas; its reference() is the oracle.
 *
 * Buffers: colour planar (c*n + i); padded = colour as float4 (RGB_) with ASTIGMATISM_PAD px of
 * edge values on every side (so taps never clamp; one float4 load per bilinear corner instead of
 * three planar loads: the taps' addresses vary per pixel, so nothing vectorises across pixels); depth planar metres (+inf sky); lut = 2 planes of
 * ASTIGMATISM_LUT_SIZE focal offsets (sagittal, tangential; mm) over image height [0, r_max];
 * taps = ASTIGMATISM_TAPS points of a Vogel spiral over the unit disc (uniform weights).
 * axes = per padded pixel the ellipse semi-axes (a_s, a_t) in px of the pixel it continues, so a
 * tap can ask whether its *source* pixel's blur reaches the target (scatter-as-gather weights).
 * Defines: ASTIGMATISM_TAPS, ASTIGMATISM_PAD, ASTIGMATISM_LUT_SIZE.
 */
#define ASTIGMATISM_MAX_SEMI ((float)(ASTIGMATISM_PAD - 1))
#define ASTIGMATISM_MIN_SEMI 1e-3f
#define ASTIGMATISM_MIN_DEPTH_MM 1e-3f

inline float astigmatism_semi(float e0, float g, float d, float c0, float aperture, float half_inv_pitch)
{
    /* semi-axis (px) of this stage's ellipse: sqrt(max(c^2 - c0^2, 0)) / 2p, capped */
    const float den = 1.0f + d * g;
    if (!(den > 1e-6f)) return ASTIGMATISM_MAX_SEMI;
    const float c = aperture * fabs(e0 + d * g) / den;
    const float q = (c - c0) * (c + c0);
    const float a = sqrt(fmax(q, 0.0f)) * half_inv_pitch;
    return isfinite(a) ? fmin(a, ASTIGMATISM_MAX_SEMI) : ASTIGMATISM_MAX_SEMI;
}

__kernel void astigmatism_pad(__global const float *restrict src, __global const float *restrict depth,
                              __global const float *restrict lut, __global float4 *restrict padded,
                              __global float2 *restrict axes, const int width, const int height,
                              const float cx, const float cy, const float pitch_mm, const float lut_scale,
                              const float aperture_mm, const float v_mm, const float inv_f_mm)
{
    const int x = get_global_id(0), y = get_global_id(1);
    const int pw = width + 2 * ASTIGMATISM_PAD, ph = height + 2 * ASTIGMATISM_PAD;
    if (x >= pw || y >= ph) return;
    const int sx = clamp(x - ASTIGMATISM_PAD, 0, width - 1), sy = clamp(y - ASTIGMATISM_PAD, 0, height - 1);
    const size_t n = (size_t)width * height;
    const size_t i = (size_t)sy * width + sx, j = (size_t)y * pw + x;
    padded[j] = (float4)(src[i], src[n + i], src[2 * n + i], 0.0f);

    const float dx = (float)sx - cx, dy = (float)sy - cy;
    const float r = sqrt(dx * dx + dy * dy);
    /* focal offsets at this image height (linear LUT) */
    const float t = fmin(r * pitch_mm * lut_scale, (float)(ASTIGMATISM_LUT_SIZE - 1));
    const int k0 = min((int)t, ASTIGMATISM_LUT_SIZE - 2);
    const float ft = t - (float)k0;
    const float ds = mix(lut[k0], lut[k0 + 1], ft);
    const float dt = mix(lut[ASTIGMATISM_LUT_SIZE + k0], lut[ASTIGMATISM_LUT_SIZE + k0 + 1], ft);
    /* thin-lens defocus terms: g = 1/f - 1/z, e0 = 1 - v g = (1 - v/f) + v/z */
    const float zmm = fmax(depth[i] * 1000.0f, ASTIGMATISM_MIN_DEPTH_MM);
    const float inv_z = isinf(zmm) ? 0.0f : 1.0f / zmm;
    const float g = inv_f_mm - inv_z;
    const float e0 = (1.0f - v_mm * inv_f_mm) + v_mm * inv_z;
    const float c0 = aperture_mm * fabs(e0);
    const float hip = 0.5f / pitch_mm;
    axes[j] = (float2)(astigmatism_semi(e0, g, ds, c0, aperture_mm, hip),
                       astigmatism_semi(e0, g, dt, c0, aperture_mm, hip));
}

__kernel void astigmatism(__global const float4 *restrict padded, __global const float2 *restrict axes,
                          __global float *restrict dst, __constant float2 *taps,
                          const int width, const int height, const float cx, const float cy)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * height;
    const size_t i = (size_t)y * width + x;
    const int pw = width + 2 * ASTIGMATISM_PAD;
    const int jc = (y + ASTIGMATISM_PAD) * pw + (x + ASTIGMATISM_PAD);
    const float2 a = axes[jc];
    if (a.x < ASTIGMATISM_MIN_SEMI && a.y < ASTIGMATISM_MIN_SEMI) {
        const float4 v = padded[jc];
        dst[i] = v.x;
        dst[n + i] = v.y;
        dst[2 * n + i] = v.z;
        return;
    }
    const float dx = (float)x - cx, dy = (float)y - cy;
    const float r = sqrt(dx * dx + dy * dy);
    const float ex = r > 0.0f ? dx / r : 1.0f, ey = r > 0.0f ? dy / r : 0.0f;
    /* tap k: a_s*u.x along e_s = (-ey, ex), a_t*u.y along e_t = (ex, ey) */
    const float2 ax_s = (float2)(-ey, ex) * a.x, ax_t = (float2)(ex, ey) * a.y;
    const float bx = (float)(x + ASTIGMATISM_PAD), by = (float)(y + ASTIGMATISM_PAD);
    float4 acc = (float4)(0.0f);
    float wsum = 0.0f;
    for (int k = 0; k < ASTIGMATISM_TAPS; ++k) {
        const float2 u = taps[k];
        const float px = bx + ax_s.x * u.x + ax_t.x * u.y;
        const float py = by + ax_s.y * u.x + ax_t.y * u.y;
        /* does the source pixel's own ellipse (+ half a pixel) reach back to the target? */
        const float2 as = axes[(int)floor(py + 0.5f) * pw + (int)floor(px + 0.5f)];
        const float qs = a.x * u.x / (as.x + 0.5f), qt = a.y * u.y / (as.y + 0.5f);
        const float w = clamp(5.0f - 4.0f * sqrt(qs * qs + qt * qt), 0.0f, 1.0f);
        const float fx0 = floor(px), fy0 = floor(py);
        const float fx = px - fx0, fy = py - fy0;
        const int j = (int)fy0 * pw + (int)fx0;
        const float4 top = mix(padded[j], padded[j + 1], fx);
        const float4 bot = mix(padded[j + pw], padded[j + pw + 1], fx);
        acc += mix(top, bot, fy) * w;
        wsum += w;
    }
    const float4 own = padded[jc];
    const float4 out = wsum > 0.0f ? acc / wsum : own;
    dst[i] = out.x;
    dst[n + i] = out.y;
    dst[2 * n + i] = out.z;
}
