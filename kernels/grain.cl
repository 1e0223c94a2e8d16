/* grain: dye-layer grain on planar densities (src/dst: channel c of pixel i at c*n + i).
 * params = [dmin0 dmin1 dmin2 dmax0 dmax1 dmax2]. Model, formulas and references:
 * clpost/stages/grain.py and clpost/grain_model.py. Coordinates: pixel x covers [x, x+1).
 */
#define GRAIN_LN10 2.302585093f

inline float grain_to_density(const float t, const float dmin, const float dmax) {
    /* clear fraction -> density, clamped to the stock's [D_min, D_max] (t = 0 would be +inf) */
    return clamp(dmin - 0.30102999566f * clp_log2(fmax(t, 1e-30f)), dmin, dmax);  /* log10, vectorising */
}

/* draft/preview, and final with unresolved grains: Gaussian clear fraction with the model's
 * pixel variance (LUT over image density) and lag-1 correlation (separable [a, b, a]). */
inline void grain_gaussian(__global const float *restrict src, __global float *restrict dst,
                             const int width, const int height, __global const float *params,
                             __global const float *sigma_lut, const float lut_scale,
                             const float a, const float b, const float amount, const uint seed,
                             const uint frame) {
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
#if GRAIN_TAPS != 1
    const float w3[3] = {a, b, a};
#endif
    for (uint c = 0; c < 3; ++c) {
        const float dmin = params[c], dmax = params[3 + c];
        const float d_img = fmax(src[c * n + i] - dmin, 0.0f);
        const float u = fmin(d_img * lut_scale, (float)(GRAIN_LUT_SIZE - 1));
        const int k = min((int)u, GRAIN_LUT_SIZE - 2);
        const float sigma = mix(sigma_lut[k], sigma_lut[k + 1], u - (float)k);
#if GRAIN_TAPS == 1
        const uint h0 = rnd_hash4(seed, frame, (uint)(x + 1), ((uint)(y + 1) << 2) | c);
        const float g = rnd_normal(h0, rnd_mix(h0 ^ 0x68e31da4u));
#else
        float g = 0.0f;
        for (int j = 0; j < 3; ++j) {
            for (int q = 0; q < 3; ++q) {
                /* counters are pixel coordinates (+1 so the border neighbours are >= 0) */
                const uint hh = rnd_hash4(seed, frame, (uint)(x + q), ((uint)(y + j) << 2) | c);
                g += w3[j] * w3[q] * rnd_normal(hh, rnd_mix(hh ^ 0x68e31da4u));
            }
        }
#endif
        dst[c * n + i] = grain_to_density(clp_exp2(-3.32192809f * d_img) + amount * sigma * g, dmin, dmax);  /* 10^-d */
    }
}

/* final, resolved grains: the Boolean model (Newson et al. 2017). GRAIN_CELLS^2 cells per pixel,
 * each cell's grains a pure function of (seed, frame, cell, layer); GRAIN_NS^2 jittered samples. */
inline void grain_boolean(__global const float *restrict src, __global float *restrict dst,
                            const int width, const int height, __global const float *params,
                            const float r, const float amount, const uint seed, const uint frame) {
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
    const int K = GRAIN_CELLS;
    const int NS2 = GRAIN_NS * GRAIN_NS;
    float su[GRAIN_NS * GRAIN_NS], sv[GRAIN_NS * GRAIN_NS];
    for (int s = 0; s < NS2; ++s) {
        const uint hs = rnd_hash4(seed, frame, (uint)i, (uint)s | 0x80000000u);
        su[s] = (float)x + ((float)(s % GRAIN_NS) + rnd_uniform(hs)) / (float)GRAIN_NS;
        sv[s] = (float)y + ((float)(s / GRAIN_NS) + rnd_uniform(rnd_mix(hs ^ 0x85ebca6bu))) / (float)GRAIN_NS;
    }
    const float r2 = r * r;
    const float lam_per_d = GRAIN_LN10 / (M_PI_F * r2) / (float)(K * K);
    const int cx0 = (int)floor(((float)x - r) * (float)K), cx1 = (int)floor(((float)x + 1.0f + r) * (float)K);
    const int cy0 = (int)floor(((float)y - r) * (float)K), cy1 = (int)floor(((float)y + 1.0f + r) * (float)K);
    for (uint c = 0; c < 3; ++c) {
        const float dmin = params[c], dmax = params[3 + c];
        ulong covered = 0;
        for (int cy = cy0; cy <= cy1; ++cy) {
            const int py = clamp((cy >= 0 ? cy : cy - K + 1) / K, 0, height - 1);
            for (int cx = cx0; cx <= cx1; ++cx) {
                const int px = clamp((cx >= 0 ? cx : cx - K + 1) / K, 0, width - 1);
                const float d_img = fmax(src[c * n + (size_t)py * width + px] - dmin, 0.0f);
                const uint hc = rnd_hash4(seed, frame, (uint)(cx + 64), ((uint)(cy + 64) << 2) | c);
                const int count = (int)rnd_poisson_inversion(d_img * lam_per_d, rnd_uniform(hc));
                for (int g = 0; g < count; ++g) {
                    const uint hk = rnd_mix(hc + 0x9e3779b9u * (uint)(g + 1));
                    const float gx = ((float)cx + rnd_uniform(hk)) / (float)K;
                    const float gy = ((float)cy + rnd_uniform(rnd_mix(hk ^ 0x85ebca6bu))) / (float)K;
                    for (int s = 0; s < NS2; ++s) {
                        const float dx = gx - su[s], dy = gy - sv[s];
                        if (dx * dx + dy * dy <= r2) covered |= (ulong)1 << s;
                    }
                }
            }
        }
        const float clear = (float)(NS2 - (int)popcount(covered)) / (float)NS2;
        /* amount scales the deviation from the pixel's mean clear fraction 10^-D_img (1 = the model) */
        const float mean = clp_exp2(-3.32192809f * fmax(src[c * n + i] - dmin, 0.0f));
        dst[c * n + i] = grain_to_density(mean + amount * (clear - mean), dmin, dmax);
    }
}

/* The stage's one entry point; GRAIN_BOOLEAN (a #define, part of the program key) picks the model. */
__kernel void grain(__global const float *restrict src, __global float *restrict dst,
                    const int width, const int height, __global const float *params,
                    __global const float *sigma_lut, const float lut_scale, const float a,
                    const float b, const float r, const float amount, const uint seed, const uint frame) {
#if GRAIN_BOOLEAN
    (void)sigma_lut; (void)lut_scale; (void)a; (void)b;
    grain_boolean(src, dst, width, height, params, r, amount, seed, frame);
#else
    (void)r;
    grain_gaussian(src, dst, width, height, params, sigma_lut, lut_scale, a, b, amount, seed, frame);
#endif
}
