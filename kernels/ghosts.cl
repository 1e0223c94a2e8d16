// ghosts: two-reflection ghosts of the frame's sources (clpost/stages/ghosts.py).
// Planar float32 colour (channel c of pixel i at c*W*H + i). sources: n_src records of 12 floats
// (x, y, flux R, G, B, tile x0, y0, share kept R, G, B, 0, 0); table: n_src × n_ghost records of
// 12 floats, source-major (per channel: centre factor, signed radius px, irradiance per unit flux;
// float 11 of a source's first record: how many of its records to draw).

inline float ghosts_rho(float ox, float oy, float rot, float roundness)
{
#if GHOSTS_BLADES > 0
    const float seg = 2.0f * M_PI_F / GHOSTS_BLADES;
    const float phi0 = -0.5f * M_PI_F - rot;
    float t = atan2(oy, ox) - phi0;
    t = t - seg * floor(t / seg) - 0.5f * seg;
    const float poly = cos(M_PI_F / GHOSTS_BLADES) / cos(t);
    return (1.0f - roundness) * poly + roundness;
#else
    return 1.0f;
#endif
}

__kernel void ghosts(__global const float *src, __global float *dst, __global const float *sources,
                     const int n_src, __global const float *table, const int n_ghost, const int w, const int h,
                     const float cx, const float cy, const float threshold, const float rot, const float roundness)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    const int i = y * w + x, n = w * h;
    float v[3] = {src[i], src[n + i], src[2 * n + i]};
    float keep[3] = {1.0f, 1.0f, 1.0f};
    const float px = (float)x, py = (float)y;
    const bool over = fmax(v[0], fmax(v[1], v[2])) > threshold;
    float add[3] = {0.0f, 0.0f, 0.0f};
    int mine = 0;
    for (int k = 0; k < n_src; ++k) {
        __global const float *s = sources + 12 * k;
        if (px >= s[5] && px < s[5] + 16.0f && py >= s[6] && py < s[6] + 16.0f) {
            mine = 1;
            keep[0] = s[7]; keep[1] = s[8]; keep[2] = s[9];
        }
        const int drawn = n_ghost > 0 ? (int)table[12 * k * n_ghost + 11] : 0;  // the source's ghosts above the floor come first
        for (int g = 0; g < drawn; ++g) {
            __global const float *t = table + 12 * (k * n_ghost + g);
            for (int c = 0; c < 3; ++c) {
                const float f = t[3 * c], e = t[3 * c + 2];
                float r = t[3 * c + 1];
                float ox = px - (cx + (s[0] - cx) * f), oy = py - (cy + (s[1] - cy) * f);
                if (r < 0.0f) { ox = -ox; oy = -oy; r = -r; }
                const float d = sqrt(ox * ox + oy * oy);
                if (d > r + 0.5f) continue;  // outside the shape (corners on the unit circle: ρ ≤ 1)
                const float cov = clamp(r * ghosts_rho(ox, oy, rot, roundness) - d + 0.5f, 0.0f, 1.0f);
                add[c] += s[2 + c] * e * cov;
            }
        }
    }
    for (int c = 0; c < 3; ++c)
        dst[c * n + i] = ((mine && over) ? v[c] * keep[c] : v[c]) + add[c];
}
