/* dof: signed circle of confusion and the padded working-resolution buffers of the gather.
 * Formula, constants and the edge rule are documented in clpost/stages/dof.py:
 *   r_px = k (1/u - 1/S), clamped to +-limit; +inf depth -> 1/S = 0 (finite far limit).
 * Structural: DOF_SCALE (working-resolution divisor).
 */

#define DOF_MIXED_BRIGHTER 1.5f
#define DOF_MIXED_SAME_DEPTH 0.8f

inline float dof_luma(__global const float *src, const size_t i, const size_t n) {
    return 0.2126f * src[i] + 0.7152f * src[n + i] + 0.0722f * src[2 * n + i];
}

/* Full-resolution signed CoC radius (px). A pixel brighter than 1.5x every same-depth neighbour
 * takes the nearest depth of its 3x3 neighbourhood (anti-aliased colour vs one-sample depth). */
__kernel void dof_coc(__global const float *restrict src, __global const float *restrict depth,
                      __global float *restrict coc, const int width, const int height,
                      const float k, const float inv_u, const float limit)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * height, i = (size_t)y * width + x;
    const float d = depth[i];
    const float lum = dof_luma(src, i, n);
    /* neighbour rows/columns clamped once per pixel, selects instead of branches (PoCL then
     * vectorises across work-items) */
    const int xs[3] = {max(x - 1, 0), x, min(x + 1, width - 1)};
    const int ys[3] = {max(y - 1, 0), y, min(y + 1, height - 1)};
    float nearest = d, brightest_same = 0.0f;
#pragma unroll
    for (int b = 0; b < 3; ++b)
#pragma unroll
        for (int a = 0; a < 3; ++a) {
            const size_t j = (size_t)ys[b] * width + xs[a];
            const float dq = depth[j];
            nearest = fmin(nearest, dq);
            const float lq = (a == 1 && b == 1) ? 0.0f : dof_luma(src, j, n);
            brightest_same = fmax(brightest_same, dq >= DOF_MIXED_SAME_DEPTH * d ? lq : 0.0f);
        }
    const float s = (lum > DOF_MIXED_BRIGHTER * brightest_same && nearest < d) ? nearest : d;
    const float inv_s = isinf(s) ? 0.0f : 1.0f / s;
    coc[i] = clamp(k * (inv_u - inv_s), -limit, limit);
}

/* Padded working buffers (level 0 of `lv`, see dof_levels.cl): colour = mean of the DOF_SCALE^2 block, CoC = nearest (min signed) of
 * the block in working px; the border of width `pad` replicates the edge (no clamp per tap). */
__kernel void dof_prepare(__global const float *restrict src, __global const float *restrict coc,
                          __global float *restrict lv, __global float *restrict pv,
                          const int width, const int height, const int ww, const int hw, const int pad,
                          const float vig, const float cx, const float cy, const float inv_half)
{
    const int gx = get_global_id(0), gy = get_global_id(1);
    const int pw = DOF_PW(ww, pad), ph = DOF_PW(hw, pad);
    if (gx >= pw || gy >= ph) return;
    const int xw = clamp(gx - pad, 0, ww - 1), yw = clamp(gy - pad, 0, hw - 1);
    const size_t n = (size_t)width * height, pn = (size_t)pw * ph, o = (size_t)gy * pw + gx;
#if DOF_SCALE == 1
    const size_t j = (size_t)yw * width + xw;
    const float3 acc = (float3)(src[j], src[n + j], src[2 * n + j]);
    const float r = coc[j];
#elif DOF_SCALE == 2
    /* written out: PoCL compiled the generic 2-D block loop ~40x slower (measured) */
    const int x0 = 2 * xw, y0 = 2 * yw, x1 = min(x0 + 1, width - 1), y1 = min(y0 + 1, height - 1);
    const size_t j00 = (size_t)y0 * width + x0, j01 = (size_t)y0 * width + x1;
    const size_t j10 = (size_t)y1 * width + x0, j11 = (size_t)y1 * width + x1;
    const float3 acc = 0.25f * ((float3)(src[j00], src[n + j00], src[2 * n + j00])
                                + (float3)(src[j01], src[n + j01], src[2 * n + j01])
                                + (float3)(src[j10], src[n + j10], src[2 * n + j10])
                                + (float3)(src[j11], src[n + j11], src[2 * n + j11]));
    const float r = fmin(fmin(coc[j00], coc[j01]), fmin(coc[j10], coc[j11]));
#else
#error "DOF_SCALE must be 1 or 2"
#endif
    lv[o] = acc.x; lv[pn + o] = acc.y; lv[2 * pn + o] = acc.z;
    lv[3 * pn + o] = r / DOF_SCALE;
#if DOF_VIGNETTING
    /* 1 / pupil area fraction of a source here (two-disc lens area, |h| capped at the corner):
     * once per pixel instead of an acos per tap */
    const float hx = ((float)(gx - pad) - cx) * inv_half, hy = ((float)(gy - pad) - cy) * inv_half;
    const float d = vig * fmin(sqrt(hx * hx + hy * hy), 1.0f);
    pv[o] = M_PI_F / (2.0f * acos(0.5f * d) - 0.5f * d * sqrt(4.0f - d * d));
#endif
}
