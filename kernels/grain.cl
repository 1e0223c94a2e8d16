/* grain: dye-layer grain on planar densities (src/dst: channel c of pixel i at c*n + i).
 * params = [dmin0 dmin1 dmin2 dmax0 dmax1 dmax2]. Model, formulas and references:
 * clpost/stages/grain.py and clpost/grain_model.py. Coordinates: pixel x covers [x, x+1).
 */
#define GRAIN_LN10 2.302585093f
#if !GRAIN_BOOLEAN && GRAIN_ROWS > 14
#error "grain_gaussian32 draws the edge normals of GRAIN_ROWS + 2 rows in one float16 each: GRAIN_ROWS <= 14"
#endif

inline float grain_to_density(const float t, const float dmin, const float dmax) {
    /* clear fraction -> density, clamped to the stock's [D_min, D_max] (t = 0 would be +inf) */
    return clamp(dmin - 0.30102999566f * clp_log2(fmax(t, 1e-30f)), dmin, dmax);  /* log10, vectorising */
}

/* draft/preview, and final with unresolved grains, correlated: the Gaussian path, grain_pixel of
 * kernels/grain_pixel.cl on the normals of counters (x + i, y + j), i, j in {-1, 0, 1}, filtered by
 * the separable [a, b, a]. (White noise, a = 0, is per pixel: the plan fuses it with film and print,
 * kernels/grain_white.cl.) The same numbers in both forms below, summed in the same order. */

/* One pixel (a GPU's form, GRAIN_LANES 1, and the last 1-31 pixels of a row in the lane form). */
inline void grain_gaussian_px(__global const float *restrict src, __global float *restrict dst,
                              const int x, const int y, const int width, const int height,
                              __global const float *params, __global const float *poly,
                              const float inv_half_span, const float a, const float b,
                              const float amount, const uint seed, const uint frame) {
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
    for (uint c = 0; c < 3; ++c) {
        float hr[3];
        for (int j = 0; j < 3; ++j)
            hr[j] = a * grain_normal(seed, frame, x - 1, y + j - 1, c) + b * grain_normal(seed, frame, x, y + j - 1, c)
                  + a * grain_normal(seed, frame, x + 1, y + j - 1, c);
        const float g = a * hr[0] + b * hr[1] + a * hr[2];
        dst[c * n + i] = grain_pixel(src[c * n + i], params[c], params[3 + c], g, poly, inv_half_span, amount);
    }
}

/* Row Y's normals of pixels x0 .. x0 + 31 filtered [a, b, a] along the row: block x0/32 and the
 * normals left (counter x0 - 1) and right (x0 + 32) of it. */
inline void grain_hrow32(const uint seed, const uint frame, const int x0, const int Y, const uint c,
                         const float a, const float b, const float left, const float right,
                         float16 *h0, float16 *h1) {
    float16 s;
    const float16 k = grain_block_w16(seed, frame, (uint)x0 >> 5, Y, c, &s);
    *h0 = a * (float16)(left, k.s0123, k.s456789ab, k.scde) + b * k + a * (float16)(k.s123, k.s456789ab, k.scdef, s.s0);
    *h1 = a * (float16)(k.sf, s.s0123, s.s456789ab, s.scde) + b * s + a * (float16)(s.s123, s.s456789ab, s.scdef, right);
}

/* 32 pixels of GRAIN_ROWS rows per work-item (x0 = 32 gid0, y0 = GRAIN_ROWS gid1), in float16
 * lanes (kernels/random.cl at width 16): one float16 of draws is a row's 32 normals; the [a, b, a]
 * filter reuses each filtered row for three
 * output rows and takes the normals left and right of the block (counters x0 - 1, x0 + 32) of the
 * GRAIN_ROWS + 2 rows from two float16 of draws, (GRAIN_ROWS + 4) x 16 / (32 GRAIN_ROWS) draws
 * per pixel and layer (9/14 at 14 rows, clpost/stages/grain.py GAUSSIAN_ROWS). */
inline void grain_gaussian32(__global const float *restrict src, __global float *restrict dst,
                             const int width, const int height, __global const float *params,
                             __global const float *poly, const float inv_half_span,
                             const float a, const float b, const float amount, const uint seed,
                             const uint frame) {
    const int x0 = get_global_id(0) * 32;
    const int y0 = get_global_id(1) * GRAIN_ROWS;
    if (x0 >= width || y0 >= height) return;
    if (x0 + 32 > width) {   /* the row's last 1-31 pixels, one by one */
        const int y1 = min(y0 + GRAIN_ROWS, height);
        for (int y = y0; y < y1; ++y)
            for (int x = x0; x < width; ++x)
                grain_gaussian_px(src, dst, x, y, width, height, params, poly, inv_half_span, a, b,
                                  amount, seed, frame);
        return;
    }
    const size_t n = (size_t)width * (size_t)height;
    for (uint c = 0; c < 3; ++c) {
        const float dmin = params[c], dmax = params[3 + c];
        /* lane r: row y0 - 1 + r; left: the sine of draw 15 of block x0/32 - 1, right: the
         * cosine of draw 0 of block x0/32 + 1 */
        float le[16], ri[16];
        {
            const uint16 rows = ((uint16)((uint)(y0 - 1)) + CLP_ULANES16) << 2 | c;
            const uint16 hl = rnd_hash4_w16(seed, frame, (uint16)(((((uint)x0 >> 5) - 1u) << 4) | 15u), rows);
            const uint16 hr = rnd_hash4_w16(seed, frame, (uint16)((((uint)x0 >> 5) + 1u) << 4), rows);
            float16 s, unused;
            (void)rnd_normal_pair_w16(hl, rnd_mix_w16(hl ^ 0x68e31da4u), &s);
            vstore16(s, 0, le);
            vstore16(rnd_normal_pair_w16(hr, rnd_mix_w16(hr ^ 0x68e31da4u), &unused), 0, ri);
        }
        float16 a0, a1, b0, b1;   /* filtered rows y - 1 and y, each as two 16-pixel halves */
        grain_hrow32(seed, frame, x0, y0 - 1, c, a, b, le[0], ri[0], &a0, &a1);
        grain_hrow32(seed, frame, x0, y0, c, a, b, le[1], ri[1], &b0, &b1);
        for (int r = 0; r < GRAIN_ROWS; ++r) {
            const int y = y0 + r;
            float16 c0, c1;
            grain_hrow32(seed, frame, x0, y + 1, c, a, b, le[r + 2], ri[r + 2], &c0, &c1);
            const float16 g0 = a * a0 + b * b0 + a * c0;
            const float16 g1 = a * a1 + b * b1 + a * c1;
            a0 = b0; a1 = b1;
            b0 = c0; b1 = c1;
            if (y >= height) break;
            const size_t i = (size_t)y * (size_t)width + (size_t)x0;
            vstore16(grain_pixel_w16(vload16(0, src + c * n + i), dmin, dmax, g0, poly, inv_half_span, amount),
                     0, dst + c * n + i);
            vstore16(grain_pixel_w16(vload16(0, src + c * n + i + 16), dmin, dmax, g1, poly, inv_half_span, amount),
                     0, dst + c * n + i + 16);
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

/* The stage's one entry point; GRAIN_BOOLEAN (a #define, part of the program key) picks the model,
 * GRAIN_LANES the Gaussian path's form: 32 pixels x GRAIN_ROWS rows per work-item in float16 (a
 * CPU's SIMD lanes) or one pixel (a GPU's: a warp's loads and stores coalesce). */
__kernel void grain(__global const float *restrict src, __global float *restrict dst,
                    const int width, const int height, __global const float *params,
                    __global const float *poly, const float inv_half_span, const float a,
                    const float b, const float r, const float amount, const uint seed, const uint frame) {
#if GRAIN_BOOLEAN
    (void)poly; (void)inv_half_span; (void)a; (void)b;
    grain_boolean(src, dst, width, height, params, r, amount, seed, frame);
#elif GRAIN_LANES == 1
    (void)r;
    const int x = get_global_id(0), y = get_global_id(1);
    if (x < width && y < height)
        grain_gaussian_px(src, dst, x, y, width, height, params, poly, inv_half_span, a, b, amount, seed, frame);
#else
    (void)r;
    grain_gaussian32(src, dst, width, height, params, poly, inv_half_span, a, b, amount, seed, frame);
#endif
}
