// glare: the highlights split off (kernel glare), the spectrum product and the sum (clpost/stages/glare.py).
// Planar float32 colour (channel c of pixel i at c*W*H + i); hi and conv: (3, hf, wf) grids
// with the frame at their top-left corner and zeros elsewhere.

__kernel void glare(__global const float *src, __global float *dst, __global float *hi,
                          const int w, const int h, const int wf, const int hf, const float threshold)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= wf || y >= hf) return;
    const int j = y * wf + x, nf = wf * hf;
    if (x >= w || y >= h) {
        hi[j] = 0.0f; hi[nf + j] = 0.0f; hi[2 * nf + j] = 0.0f;
        return;
    }
    const int i = y * w + x, n = w * h;
    for (int c = 0; c < 3; ++c) {
        const float v = src[c * n + i];
        const float e = fmax(v - threshold, 0.0f);
        hi[c * nf + j] = e;
        dst[c * n + i] = v - e;
    }
}

__kernel void glare_multiply(__global float2 *spec, __global const float2 *kern, const int n)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const float2 a = spec[i], b = kern[i];
    spec[i] = (float2)(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

__kernel void glare_add(__global float *dst, __global const float *conv, const int w, const int h,
                        const int wf, const int hf)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    const int i = y * w + x, n = w * h, j = y * wf + x, nf = wf * hf;
    for (int c = 0; c < 3; ++c)
        dst[c * n + i] += conv[c * nf + j];
}
