/* front_layer: a foreground layer (premultiplied R, G, B, coverage, depth; interleaved, 5 floats a
 * pixel) spread over each pixel's thin-lens disc and composited over the image (formula, tables
 * and the numpy oracle front_reference: clpost/stages/front_layer.py).
 * Structural: FRONT_TILE (tile side, px), FRONT_REACH (half-size of the rho table's window),
 * FRONT_NORM_STEPS (N(r) table entries per px).
 */
#ifndef FRONT_TILE
#error "FRONT_TILE must be defined"
#endif
#ifndef FRONT_REACH
#error "FRONT_REACH must be defined"
#endif
#ifndef FRONT_NORM_STEPS
#error "FRONT_NORM_STEPS must be defined"
#endif

/* CoC radius (px, >= 0, at most rlim) of depth d: k |1/S - 1/d| (k = 0: depth of field off) */
inline float front_radius(const float d, const float k, const float inv_u, const float rlim)
{
    const float inv_d = isinf(d) ? 0.0f : 1.0f / d;
    return fmin(fabs(k * (inv_u - inv_d)), rlim);
}

/* each tile's largest radius among its covered pixels, -1 where none is covered */
__kernel void front_layer_tiles(__global const float *restrict front, __global float *restrict tiles,
                                const int w, const int h, const int tw, const int th,
                                const float k, const float inv_u, const float rlim)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    float m = -1.0f;
    for (int y = ty * FRONT_TILE; y < min((ty + 1) * FRONT_TILE, h); ++y)
        for (int x = tx * FRONT_TILE; x < min((tx + 1) * FRONT_TILE, w); ++x) {
            __global const float *f = front + 5 * ((size_t)y * w + x);
            if (f[3] > 0.0f) m = fmax(m, front_radius(f[4], k, inv_u, rlim));
        }
    tiles[(size_t)ty * tw + tx] = m;
}

/* out = F_rgb + (1 - F_a) src, F the gathered front layer; beyond the frame the layer continues
 * as its edge pixels, so a tile index outside the frame reads the edge tile's radius */
__kernel void front_layer(__global const float *restrict src, __global const float *restrict front,
                          __global const float *restrict tiles, __global const float *restrict rho,
                          __global const float *restrict norm, __global float *restrict dst,
                          const int w, const int h, const int tw, const int th,
                          const float k, const float inv_u, const float rlim)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    const size_t n = (size_t)w * h, p = (size_t)y * w + x;
    /* the taps' reach: the largest radius of the tiles (or their copies beyond the frame) whose
     * rectangle lies within that radius and the ramp's half pixel of p */
    const int rt = (int)ceil((rlim + 0.5f) / FRONT_TILE) + 1;
    const int ptx = x / FRONT_TILE, pty = y / FRONT_TILE;
    float reach = -1.0f;
    for (int j = pty - rt; j <= pty + rt; ++j)
        for (int i = ptx - rt; i <= ptx + rt; ++i) {
            const float r = tiles[(size_t)clamp(j, 0, th - 1) * tw + clamp(i, 0, tw - 1)];
            if (r < 0.0f) continue;
            const float gx = fmax(0.0f, fmax((float)(i * FRONT_TILE - x), (float)(x - (i + 1) * FRONT_TILE + 1)));
            const float gy = fmax(0.0f, fmax((float)(j * FRONT_TILE - y), (float)(y - (j + 1) * FRONT_TILE + 1)));
            if (gx * gx + gy * gy < (r + 0.5f) * (r + 0.5f)) reach = fmax(reach, r);
        }
    float3 c = (float3)(src[p], src[n + p], src[2 * n + p]);
    if (reach >= 0.0f) {
        const int R = min((int)ceil(reach + 0.5f), FRONT_REACH);
        float4 acc = (float4)(0.0f);
        for (int dy = -R; dy <= R; ++dy) {
            const int qy = clamp(y - dy, 0, h - 1);
            for (int dx = -R; dx <= R; ++dx) {
                __global const float *f = front + 5 * ((size_t)qy * w + clamp(x - dx, 0, w - 1));
                if (!(f[3] > 0.0f)) continue;
                const float r = front_radius(f[4], k, inv_u, rlim);
                const float dist = sqrt((float)(dx * dx + dy * dy));
                const float wt = clamp(r * rho[(dy + FRONT_REACH) * (2 * FRONT_REACH + 1) + dx + FRONT_REACH] - dist + 0.5f,
                                       0.0f, 1.0f);
                if (wt <= 0.0f) continue;
                const float t = r * FRONT_NORM_STEPS;
                const int i0 = (int)t;
                const float nr = mix(norm[i0], norm[i0 + 1], t - (float)i0);
                acc += (wt / nr) * (float4)(f[0], f[1], f[2], f[3]);
            }
        }
        c = acc.xyz + (1.0f - acc.w) * c;
    }
    dst[p] = c.x;
    dst[n + p] = c.y;
    dst[2 * n + p] = c.z;
}
