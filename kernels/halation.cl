/* halation: the film base's halo, x' = (1 - s_c) x + s_c up(K * down(x)) per channel (formula,
 * derivation and the numpy oracle halation_reference: clpost/stages/halation.py). Three passes
 * on planar buffers: f x f box mean to the working grid, direct 2-D gather of the cell-integrated
 * radial kernel K (zero outside the frame), bilinear upsampling + mix.
 * Structural: HAL_F (working-resolution factor f), HAL_R (kernel radius in working px).
 */
#ifndef HAL_F
#error "HAL_F (working-resolution factor) must be defined"
#endif
#ifndef HAL_R
#error "HAL_R (kernel radius, working px) must be defined"
#endif

/* one working pixel: the mean of the full-resolution pixels of its f x f cell (fewer at the
 * right/bottom edge) */
__kernel void halation_down(__global const float *restrict src, __global float *restrict down,
                            const int w, const int h, const int ww, const int hw)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= ww || y >= hw) return;
    const size_t n = (size_t)w * h, nw = (size_t)ww * hw;
    float3 acc = (float3)(0.0f);
    int cnt = 0;
    for (int j = y * HAL_F; j < min((y + 1) * HAL_F, h); ++j)
        for (int i = x * HAL_F; i < min((x + 1) * HAL_F, w); ++i) {
            const size_t q = (size_t)j * w + i;
            acc += (float3)(src[q], src[n + q], src[2 * n + q]);
            ++cnt;
        }
    acc /= (float)cnt;
    const size_t o = (size_t)y * ww + x;
    down[o] = acc.x; down[nw + o] = acc.y; down[2 * nw + o] = acc.z;
}

/* K * down on the working grid; taps outside the frame read 0 (the light leaves the frame) */
__kernel void halation_conv(__global const float *restrict down, __global float *restrict conv,
                            __constant const float *restrict k, const int ww, const int hw)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= ww || y >= hw) return;
    const size_t nw = (size_t)ww * hw;
    float3 acc = (float3)(0.0f);
    for (int dy = max(-HAL_R, -y); dy <= min(HAL_R, hw - 1 - y); ++dy)
        for (int dx = max(-HAL_R, -x); dx <= min(HAL_R, ww - 1 - x); ++dx) {
            const float kv = k[(dy + HAL_R) * (2 * HAL_R + 1) + dx + HAL_R];
            const size_t q = (size_t)(y + dy) * ww + x + dx;
            acc += kv * (float3)(down[q], down[nw + q], down[2 * nw + q]);
        }
    const size_t o = (size_t)y * ww + x;
    conv[o] = acc.x; conv[nw + o] = acc.y; conv[2 * nw + o] = acc.z;
}

/* bilinear sample of the working halo at the pixel centre (edges clamped) and the mix */
__kernel void halation(__global const float *restrict src, __global const float *restrict conv,
                       __global float *restrict dst, const int w, const int h, const int ww,
                       const int hw, const float sr, const float sg, const float sb)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    const float sx = ((float)x + 0.5f) / HAL_F - 0.5f, sy = ((float)y + 0.5f) / HAL_F - 0.5f;
    const int x0 = clamp((int)floor(sx), 0, ww - 1), y0 = clamp((int)floor(sy), 0, hw - 1);
    const float fx = clamp(sx - (float)x0, 0.0f, 1.0f), fy = clamp(sy - (float)y0, 0.0f, 1.0f);
    const int x1 = min(x0 + 1, ww - 1), y1 = min(y0 + 1, hw - 1);
    const size_t n = (size_t)w * h, nw = (size_t)ww * hw, i = (size_t)y * w + x;
    const float s[3] = {sr, sg, sb};
    for (int c = 0; c < 3; ++c) {
        __global const float *p = conv + c * nw;
        const float a = p[(size_t)y0 * ww + x0] * (1.0f - fx) + p[(size_t)y0 * ww + x1] * fx;
        const float b = p[(size_t)y1 * ww + x0] * (1.0f - fx) + p[(size_t)y1 * ww + x1] * fx;
        const float halo = a * (1.0f - fy) + b * fy;
        const float v = src[c * n + i];
        dst[c * n + i] = (1.0f - s[c]) * v + s[c] * halo;
    }
}
