/* grain: dye-layer grain on planar densities (src/dst: channel c of pixel i at c*n + i).
 * params = [dmin0 dmin1 dmin2 dmax0 dmax1 dmax2]. Model, formulas and references:
 * clpost/stages/grain.py and clpost/grain_model.py. Coordinates: pixel x covers [x, x+1).
 */
#define GRAIN_LN10 2.302585093f
#if !GRAIN_BOOLEAN && GRAIN_TAPS != 1 && GRAIN_ROWS != 6
#error "grain_gaussian16 packs the 2 x (GRAIN_ROWS + 2) edge normals in one float16: GRAIN_ROWS must be 6"
#endif

inline float grain_to_density(const float t, const float dmin, const float dmax) {
    /* clear fraction -> density, clamped to the stock's [D_min, D_max] (t = 0 would be +inf) */
    return clamp(dmin - 0.30102999566f * clp_log2(fmax(t, 1e-30f)), dmin, dmax);  /* log10, vectorising */
}

/* draft/preview, and final with unresolved grains: Gaussian clear fraction with the model's
 * pixel variance (LUT over image density) and lag-1 correlation (separable [a, b, a]).
 * One pixel (the row's last 1-15 pixels of grain_gaussian16, below). */
inline void grain_gaussian_px(__global const float *restrict src, __global float *restrict dst,
                              const int x, const int y, const int width, const int height,
                              __global const float *params, __global const float *sigma_lut,
                              const float lut_scale, const float a, const float b, const float amount,
                              const uint seed, const uint frame) {
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
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
        /* counters are pixel coordinates (+1 so the border neighbours are >= 0); separable, in
         * the order grain_gaussian16 sums: rows filtered [a, b, a], then the three rows */
        float hr[3];
        for (int j = 0; j < 3; ++j) {
            float nq[3];
            for (int q = 0; q < 3; ++q) {
                const uint hh = rnd_hash4(seed, frame, (uint)(x + q), ((uint)(y + j) << 2) | c);
                nq[q] = rnd_normal(hh, rnd_mix(hh ^ 0x68e31da4u));
            }
            hr[j] = a * nq[0] + b * nq[1] + a * nq[2];
        }
        const float g = a * hr[0] + b * hr[1] + a * hr[2];
#endif
        dst[c * n + i] = grain_to_density(clp_exp2(-3.32192809f * d_img) + amount * sigma * g, dmin, dmax);  /* 10^-d */
    }
}

/* The normal of counter (X, Y) = pixel (X - 1, Y - 1) of layer c; 16 lanes from X = x0. */
inline float16 grain_normal16(const uint seed, const uint frame, const int x0, const int yc, const uint c) {
    const uint16 hh = rnd_hash4_w16(seed, frame, (uint16)((uint)x0) + CLP_ULANES16, (uint16)(((uint)yc << 2) | c));
    return rnd_normal_w16(hh, rnd_mix_w16(hh ^ 0x68e31da4u));
}

/* The 2 x (GRAIN_ROWS + 2) normals right of 16 lanes from x0: lane 2r + k is counter
 * (x0 + 16 + k, y0 + r). */
inline float16 grain_normal16x(const uint seed, const uint frame, const int x0, const int y0, const uint c) {
    const uint16 xs = (uint16)((uint)x0 + 16u) + (CLP_ULANES16 & 1u);
    const uint16 ys = (uint16)((uint)y0) + (CLP_ULANES16 >> 1);
    const uint16 hh = rnd_hash4_w16(seed, frame, xs, (ys << 2) | c);
    return rnd_normal_w16(hh, rnd_mix_w16(hh ^ 0x68e31da4u));
}

/* [a, b, a] along the row of counters from x0: 16 normals and the next two (e0, e1) per row
 * instead of 16 x 3 */
inline float16 grain_hrow16(const uint seed, const uint frame, const int x0, const int yc, const uint c,
                            const float a, const float b, const float e0, const float e1) {
    const float16 n0 = grain_normal16(seed, frame, x0, yc, c);
    const float16 n1 = (float16)(n0.s1234, n0.s5678, n0.s9abc, n0.sdef, e0);
    const float16 n2 = (float16)(n0.s2345, n0.s6789, n0.sabcd, n0.sef, e0, e1);
    return a * n0 + b * n1 + a * n2;
}

/* 16 pixels of GRAIN_ROWS rows per work-item (x0 = 16 gid0, y0 = GRAIN_ROWS gid1): the separable
 * filter reuses each filtered row for three output rows, so a pixel costs (1 + 2/GRAIN_ROWS) x 18/16
 * normals per layer instead of 9, all in float16 lanes (kernels/random.cl at width 16): the two
 * normals past each row's 16 (counters x0 + 16, x0 + 17 of the GRAIN_ROWS + 2 rows) are one more
 * float16 per layer (GRAIN_ROWS = 6: 2 x 8 = 16 lanes). */
inline void grain_gaussian16(__global const float *restrict src, __global float *restrict dst,
                             const int width, const int height, __global const float *params,
                             __global const float *sigma_lut, const float lut_scale,
                             const float a, const float b, const float amount, const uint seed,
                             const uint frame) {
    const int x0 = get_global_id(0) * 16;
    const int y0 = get_global_id(1) * GRAIN_ROWS;
    if (x0 >= width || y0 >= height) return;
    if (x0 + 16 > width) {   /* the row's last 1-15 pixels, one by one */
        const int y1 = min(y0 + GRAIN_ROWS, height);
        for (int y = y0; y < y1; ++y)
            for (int x = x0; x < width; ++x)
                grain_gaussian_px(src, dst, x, y, width, height, params, sigma_lut, lut_scale, a, b,
                                  amount, seed, frame);
        return;
    }
    const size_t n = (size_t)width * (size_t)height;
    for (uint c = 0; c < 3; ++c) {
        const float dmin = params[c], dmax = params[3 + c];
#if GRAIN_TAPS != 1
        float ex[16];   /* lane 2r + k: counter (x0 + 16 + k, y0 + r) */
        vstore16(grain_normal16x(seed, frame, x0, y0, c), 0, ex);
        float16 h0 = grain_hrow16(seed, frame, x0, y0, c, a, b, ex[0], ex[1]);
        float16 h1 = grain_hrow16(seed, frame, x0, y0 + 1, c, a, b, ex[2], ex[3]);
#endif
        for (int r = 0; r < GRAIN_ROWS; ++r) {
            const int y = y0 + r;
#if GRAIN_TAPS == 1
            const float16 g = grain_normal16(seed, frame, x0 + 1, y + 1, c);
#else
            const float16 h2 = grain_hrow16(seed, frame, x0, y + 2, c, a, b, ex[2 * r + 4], ex[2 * r + 5]);
            const float16 g = a * h0 + b * h1 + a * h2;
            h0 = h1;
            h1 = h2;
#endif
            if (y >= height) break;
            const size_t i = (size_t)y * (size_t)width + (size_t)x0;
            const float16 d_img = fmax(vload16(0, src + c * n + i) - dmin, 0.0f);
            const float16 u = fmin(d_img * lut_scale, (float)(GRAIN_LUT_SIZE - 1));
            const int16 k = min(convert_int16(u), GRAIN_LUT_SIZE - 2);
            const float16 sigma = mix(CLP_GATHER16(sigma_lut, k), CLP_GATHER16(sigma_lut, k + 1),
                                      u - convert_float16(k));
            const float16 t = clp_exp2_w16(-3.32192809f * d_img) + amount * sigma * g;  /* 10^-d */
            /* grain_to_density in lanes */
            vstore16(clamp(dmin - 0.30102999566f * clp_log2_w16(fmax(t, 1e-30f)), dmin, dmax), 0,
                     dst + c * n + i);
        }
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
    grain_gaussian16(src, dst, width, height, params, sigma_lut, lut_scale, a, b, amount, seed, frame);
#endif
}
