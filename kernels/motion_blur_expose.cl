/* motion_blur_expose: one step of a long exposure, sum += w * E, with Neumaier's compensated
 * summation so the error stays ~1 ulp whatever the number of frames (clpost/expose.py).
 * Buffers: float32 arrays of n3 = W*H*3 values (any layout, element-wise).
 */
#pragma OPENCL FP_CONTRACT OFF
/* FP_CONTRACT OFF: the compensation term must see the rounding of each add, not a fused one. */

__kernel void motion_blur_expose(__global const float *restrict src, __global float *restrict sum,
                                 __global float *restrict comp, const float w, const int n3)
{
    const int i = get_global_id(0);
    if (i >= n3) return;
    const float x = w * src[i];
    const float s = sum[i];
    const float t = s + x;
    /* Neumaier (1974): keep the low-order part lost by t = s + x, whichever is larger */
    const float lost = fabs(s) >= fabs(x) ? (s - t) + x : (x - t) + s;
    comp[i] += lost;
    sum[i] = t;
}
