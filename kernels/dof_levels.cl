/* dof: prefiltered lattice levels of the padded working buffers (clpost/stages/dof.py,
 * prefiltered_levels). Level l+1 = level l convolved with (1, 2, 1)/4 at spacing s = 2^l along x
 * then y (tent of half-width 2s), CoC = min over the offsets -s, 0, s (min over the (4s-1)^2
 * window). Layout of `lv`: level l, channel c (R, G, B, CoC, 1/max(|CoC|, 1/2)) of padded pixel o
 * at (DOF_PLANES l + c) pn + o. Reads beyond the padded buffer clamp (the reference does the same).
 *
 * One pass per level: the x filter of the three rows y - s, y, y + s, then the y filter, in the
 * same float operations as two separate passes (bit-identical), without writing and re-reading
 * an intermediate level. Each work-item does DOF_LVEC pixels of a row in float16 (PoCL does not
 * vectorise the per-pixel form; both choices: docs/measurements.md#kernel-forms-on-pocl); the
 * groups that touch the buffer's left/right end (where the clamp matters) or its partial last
 * group go pixel by pixel.
 */
#define DOF_LVEC 16

/* the x filter of one row at x .. x+15 (inside: no clamp) */
#define DOF_XF(row) (0.25f * (vload16(0, (row) - s) + 2.0f * vload16(0, (row)) + vload16(0, (row) + s)))
#define DOF_XM(row) fmin(fmin(vload16(0, (row) - s), vload16(0, (row))), vload16(0, (row) + s))

__kernel void dof_levels(__global float *restrict lv, const int pw, const int ph, const int s, const int lv_in)
{
    const int x = DOF_LVEC * get_global_id(0), y = get_global_id(1);
    if (x >= pw || y >= ph) return;
    const size_t pn = (size_t)pw * ph;
    const size_t ra = (size_t)max(y - s, 0) * pw, ro = (size_t)y * pw, rb = (size_t)min(y + s, ph - 1) * pw;
    __global const float *src = lv + (size_t)DOF_PLANES * lv_in * pn;
    __global float *dst = lv + (size_t)DOF_PLANES * (lv_in + 1) * pn;
    if (x - s >= 0 && x + DOF_LVEC - 1 + s <= pw - 1) {
        for (int c = 0; c < 3; ++c) {
            __global const float *p = src + c * pn + x;
            vstore16(0.25f * (DOF_XF(p + ra) + 2.0f * DOF_XF(p + ro) + DOF_XF(p + rb)), 0, dst + c * pn + ro + x);
        }
        __global const float *p = src + 3 * pn + x;
        const float16 r = fmin(fmin(DOF_XM(p + ra), DOF_XM(p + ro)), DOF_XM(p + rb));
        vstore16(r, 0, dst + 3 * pn + ro + x);
        vstore16(DOF_INV_R(r), 0, dst + 4 * pn + ro + x);
        return;
    }
    for (int xi = x; xi < min(x + DOF_LVEC, pw); ++xi) {
        const int xa = max(xi - s, 0), xb = min(xi + s, pw - 1);
        for (int c = 0; c < 3; ++c) {
            __global const float *p = src + c * pn;
            const float ta = 0.25f * (p[ra + xa] + 2.0f * p[ra + xi] + p[ra + xb]);
            const float to = 0.25f * (p[ro + xa] + 2.0f * p[ro + xi] + p[ro + xb]);
            const float tb = 0.25f * (p[rb + xa] + 2.0f * p[rb + xi] + p[rb + xb]);
            dst[c * pn + ro + xi] = 0.25f * (ta + 2.0f * to + tb);
        }
        __global const float *p = src + 3 * pn;
        const float r = fmin(fmin(fmin(fmin(p[ra + xa], p[ra + xi]), p[ra + xb]),
                                  fmin(fmin(p[ro + xa], p[ro + xi]), p[ro + xb])),
                             fmin(fmin(p[rb + xa], p[rb + xi]), p[rb + xb]));
        dst[3 * pn + ro + xi] = r;
        dst[4 * pn + ro + xi] = DOF_INV_R(r);
    }
}
#undef DOF_XF
#undef DOF_XM

#if DOF_TEX_PLANE
/* the texture's rescale plane (DOF_PLANES) of every level l = 0 .. nlev (stride s = 2^l), one
 * launch for all of them: N(r/s; 0)/N(r/s; a) of r = max(|CoC|, 1/2) and the CoC's sign, from the
 * table `tsum` (texture_sums in clpost/stages/dof.py: rows far ramp 1, far ramp 1/2, near ramp 1,
 * near ramp 1/2 of DOF_LIGHT_N, linear in r/s, ends clamped; ramp 1 at stride 1, else ramp 1/2) */
__kernel void dof_texture_plane(__global float *restrict lv, __global const float *restrict tsum, const int pw,
                                const int ph, const int nlev)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= pw || y >= ph) return;
    const size_t pn = (size_t)pw * ph, o = (size_t)y * pw + x;
    for (int lvl = 0; lvl <= nlev; ++lvl) {
        __global float *L = lv + (size_t)DOF_PLANES * lvl * pn;
        const float c = L[3 * pn + o];
        const float f = clamp((fmax(fabs(c), 0.5f) / (float)(1 << lvl) - DOF_LIGHT_R0) * DOF_LIGHT_K, 0.0f,
                              (float)(DOF_LIGHT_N - 1));
        const float i0 = fmin(floor(f), (float)(DOF_LIGHT_N - 2));
        __global const float *q = tsum + (int)i0 + (c >= 0.0f ? 0 : 2 * DOF_LIGHT_N) + (lvl > 0 ? DOF_LIGHT_N : 0);
        L[5 * pn + o] = q[0] + (q[1] - q[0]) * (f - i0);
    }
}
#endif
