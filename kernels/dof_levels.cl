/* dof: prefiltered lattice levels of the padded working buffers (clpost/stages/dof.py,
 * prefiltered_levels). Level l+1 = level l convolved with (1, 2, 1)/4 at spacing s = 2^l along x
 * then y (tent of half-width 2s), CoC = min over the offsets -s, 0, s (min over the (4s-1)^2
 * window). Layout of `lv`: level l, channel c (R, G, B, CoC) of padded pixel o at (4 l + c) pn + o.
 * Reads beyond the padded buffer clamp (the reference does the same).
 */

/* x pass: level `lv_in` of lv -> tmp (4 planes) */
__kernel void dof_levels_x(__global const float *restrict lv, __global float *restrict tmp,
                           const int pw, const int ph, const int s, const int lv_in)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= pw || y >= ph) return;
    const size_t pn = (size_t)pw * ph, row = (size_t)y * pw;
    const size_t o = row + x, a = row + max(x - s, 0), b = row + min(x + s, pw - 1);
    __global const float *src = lv + (size_t)4 * lv_in * pn;
    for (int c = 0; c < 3; ++c)
        tmp[c * pn + o] = 0.25f * (src[c * pn + a] + 2.0f * src[c * pn + o] + src[c * pn + b]);
    tmp[3 * pn + o] = fmin(fmin(src[3 * pn + a], src[3 * pn + o]), src[3 * pn + b]);
}

/* y pass: tmp -> level `lv_out` of lv */
__kernel void dof_levels_y(__global const float *restrict tmp, __global float *restrict lv,
                           const int pw, const int ph, const int s, const int lv_out)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= pw || y >= ph) return;
    const size_t pn = (size_t)pw * ph;
    const size_t o = (size_t)y * pw + x, a = (size_t)max(y - s, 0) * pw + x;
    const size_t b = (size_t)min(y + s, ph - 1) * pw + x;
    __global float *dst = lv + (size_t)4 * lv_out * pn;
    for (int c = 0; c < 3; ++c)
        dst[c * pn + o] = 0.25f * (tmp[c * pn + a] + 2.0f * tmp[c * pn + o] + tmp[c * pn + b]);
    dst[3 * pn + o] = fmin(fmin(tmp[3 * pn + a], tmp[3 * pn + o]), tmp[3 * pn + b]);
}
