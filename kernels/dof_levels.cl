/* dof: prefiltered lattice levels of the padded working buffers (clpost/stages/dof.py,
 * prefiltered_levels). Level l+1 = level l convolved with (1, 2, 1)/4 at spacing s = 2^l along x
 * then y (tent of half-width 2s), CoC = min over the offsets -s, 0, s (min over the (4s-1)^2
 * window). Layout of `lv`: level l, channel c (R, G, B, CoC, 1/max(|CoC|, 1/2)) of padded pixel o
 * at (DOF_PLANES l + c) pn + o; `tmp` has the first four.
 * Reads beyond the padded buffer clamp (the reference does the same).
 * Each work-item does DOF_LVEC pixels of a row in explicit float16 (PoCL did not vectorise the
 * per-pixel form: 25 ms per pass at 1080p, measured); the few groups of 8 that touch the
 * buffer's left/right end (where the clamp matters) or its partial last group go pixel by pixel.
 */
#define DOF_LVEC 16

/* x pass: level `lv_in` of lv -> tmp (4 planes) */
__kernel void dof_levels_x(__global const float *restrict lv, __global float *restrict tmp,
                           const int pw, const int ph, const int s, const int lv_in)
{
    const int x = DOF_LVEC * get_global_id(0), y = get_global_id(1);
    if (x >= pw || y >= ph) return;
    const size_t pn = (size_t)pw * ph, row = (size_t)y * pw;
    __global const float *src = lv + (size_t)DOF_PLANES * lv_in * pn;
    if (x - s >= 0 && x + DOF_LVEC - 1 + s <= pw - 1) {
        const size_t o = row + x;
        for (int c = 0; c < 3; ++c) {
            __global const float *p = src + c * pn + o;
            vstore16(0.25f * (vload16(0, p - s) + 2.0f * vload16(0, p) + vload16(0, p + s)), 0, tmp + c * pn + o);
        }
        __global const float *p = src + 3 * pn + o;
        vstore16(fmin(fmin(vload16(0, p - s), vload16(0, p)), vload16(0, p + s)), 0, tmp + 3 * pn + o);
        return;
    }
    for (int xi = x; xi < min(x + DOF_LVEC, pw); ++xi) {
        const size_t o = row + xi, a = row + max(xi - s, 0), b = row + min(xi + s, pw - 1);
        for (int c = 0; c < 3; ++c)
            tmp[c * pn + o] = 0.25f * (src[c * pn + a] + 2.0f * src[c * pn + o] + src[c * pn + b]);
        tmp[3 * pn + o] = fmin(fmin(src[3 * pn + a], src[3 * pn + o]), src[3 * pn + b]);
    }
}

/* y pass: tmp -> level `lv_out` of lv */
__kernel void dof_levels_y(__global const float *restrict tmp, __global float *restrict lv,
                           const int pw, const int ph, const int s, const int lv_out)
{
    const int x = DOF_LVEC * get_global_id(0), y = get_global_id(1);
    if (x >= pw || y >= ph) return;
    const size_t pn = (size_t)pw * ph;
    const size_t o = (size_t)y * pw + x, a = (size_t)max(y - s, 0) * pw + x;
    const size_t b = (size_t)min(y + s, ph - 1) * pw + x;
    __global float *dst = lv + (size_t)DOF_PLANES * lv_out * pn;
    if (x + DOF_LVEC <= pw) {
        for (int c = 0; c < 3; ++c)
            vstore16(0.25f * (vload16(0, tmp + c * pn + a) + 2.0f * vload16(0, tmp + c * pn + o)
                             + vload16(0, tmp + c * pn + b)), 0, dst + c * pn + o);
        const float16 r = fmin(fmin(vload16(0, tmp + 3 * pn + a), vload16(0, tmp + 3 * pn + o)),
                              vload16(0, tmp + 3 * pn + b));
        vstore16(r, 0, dst + 3 * pn + o);
        vstore16(DOF_INV_R(r), 0, dst + 4 * pn + o);
        return;
    }
    for (int j = 0; j < pw - x; ++j) {
        for (int c = 0; c < 3; ++c)
            dst[c * pn + o + j] = 0.25f * (tmp[c * pn + a + j] + 2.0f * tmp[c * pn + o + j] + tmp[c * pn + b + j]);
        const float r = fmin(fmin(tmp[3 * pn + a + j], tmp[3 * pn + o + j]), tmp[3 * pn + b + j]);
        dst[3 * pn + o + j] = r;
        dst[4 * pn + o + j] = DOF_INV_R(r);
    }
}
