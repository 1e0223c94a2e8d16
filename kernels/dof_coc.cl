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
    float nearest = d, brightest_same = 0.0f;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            const size_t j = (size_t)clamp(y + dy, 0, height - 1) * width + clamp(x + dx, 0, width - 1);
            const float dq = depth[j];
            nearest = fmin(nearest, dq);
            if ((dx != 0 || dy != 0) && dq >= DOF_MIXED_SAME_DEPTH * d)
                brightest_same = fmax(brightest_same, dof_luma(src, j, n));
        }
    const float s = (lum > DOF_MIXED_BRIGHTER * brightest_same && nearest < d) ? nearest : d;
    const float inv_s = isinf(s) ? 0.0f : 1.0f / s;
    coc[i] = clamp(k * (inv_u - inv_s), -limit, limit);
}

/* Padded working buffers: colour = mean of the DOF_SCALE^2 block, CoC = nearest (min signed) of
 * the block in working px; the border of width `pad` replicates the edge (no clamp per tap). */
__kernel void dof_prepare(__global const float *restrict src, __global const float *restrict coc,
                          __global float *restrict pc, __global float *restrict pr,
                          const int width, const int height, const int ww, const int hw, const int pad)
{
    const int gx = get_global_id(0), gy = get_global_id(1);
    const int pw = ww + 2 * pad, ph = hw + 2 * pad;
    if (gx >= pw || gy >= ph) return;
    const int xw = clamp(gx - pad, 0, ww - 1), yw = clamp(gy - pad, 0, hw - 1);
    const size_t n = (size_t)width * height, pn = (size_t)pw * ph, o = (size_t)gy * pw + gx;
    float3 acc = (float3)(0.0f);
    float r = INFINITY;
    for (int sy = 0; sy < DOF_SCALE; ++sy)
        for (int sx = 0; sx < DOF_SCALE; ++sx) {
            const size_t j = (size_t)min(yw * DOF_SCALE + sy, height - 1) * width
                             + min(xw * DOF_SCALE + sx, width - 1);
            acc += (float3)(src[j], src[n + j], src[2 * n + j]);
            r = fmin(r, coc[j]);
        }
    acc *= 1.0f / (DOF_SCALE * DOF_SCALE);
    pc[o] = acc.x; pc[pn + o] = acc.y; pc[2 * pn + o] = acc.z;
    pr[o] = r / DOF_SCALE;
}
