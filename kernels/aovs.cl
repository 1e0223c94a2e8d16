/* aovs: diagnostic passes of an output frame, one pixel per work-item (a side output of a few
 * loads and one store per plane; not a colour stage, so not part of the fused pointwise kernels).
 * Formulas, units and sign are documented once in clpost/aovs.py (numpy oracle: aovs.reference):
 *   coc   c = k2 (1/u - 1/S)       signed CoC diameter in px (far > 0, near < 0), dof's thin-lens
 *                                  formula (clpost/stages/dof.py), +inf depth -> 1/S = 0
 *   focus m = clamp(2 - |c| / c_lim, 0, 1)   1 inside the depth of field, 0 beyond 2 c_lim
 *   blur  b = s |v|                motion-blur streak length in px over the shutter fraction s
 * Buffers: depth W*H float (+inf sky), velocity W*H*2 interleaved px/frame, out 3 planes of W*H.
 * Structural: AOVS_COC, AOVS_BLUR (0/1: which inputs exist).
 */
#if !defined(AOVS_COC) || !defined(AOVS_BLUR)
#error "AOVS_COC and AOVS_BLUR must be defined (0 or 1)"
#endif

__kernel void aovs(__global const float *restrict depth, __global const float *restrict velocity,
                   __global float *restrict out, const int n, const float k2, const float inv_u,
                   const float inv_lim, const float s)
{
    const int i = get_global_id(0);
    if (i >= n) return;
#if AOVS_COC
    const float d = depth[i];
    const float inv_s = isinf(d) ? 0.0f : 1.0f / d;
    const float c = k2 * (inv_u - inv_s);
    out[i] = c;
    out[n + i] = clamp(2.0f - fabs(c) * inv_lim, 0.0f, 1.0f);
#endif
#if AOVS_BLUR
    const float vx = velocity[2 * i], vy = velocity[2 * i + 1];
    out[2 * n + i] = s * hypot(vx, vy);
#endif
}
