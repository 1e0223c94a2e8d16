/* grain: dye-layer grain on planar densities (src/dst: channel c of pixel i at c*n + i).
 * params = [dmin0 dmin1 dmin2 dmax0 dmax1 dmax2]. Model, formulas and references:
 * clpost/stages/grain.py and clpost/grain_model.py. Coordinates: pixel x covers [x, x+1).
 */
#define GRAIN_LN10 2.302585093f
#if !GRAIN_BOOLEAN && (GRAIN_ROWS % 2 != 0 || GRAIN_ROWS > 14)
#error "grain_gaussian16 draws its rows in pairs and the edge normals of GRAIN_ROWS + 2 rows in one float16"
#endif

inline float grain_to_density(const float t, const float dmin, const float dmax) {
    /* clear fraction -> density, clamped to the stock's [D_min, D_max] (t = 0 would be +inf) */
    return clamp(dmin - 0.30102999566f * clp_log2(fmax(t, 1e-30f)), dmin, dmax);  /* log10, vectorising */
}

/* draft/preview, and final with unresolved grains: Gaussian clear fraction T + amount sigma_T G
 * with the model's pixel standard deviation in closed form, sigma_T = T sqrt((t + 1) P(t)), P the
 * GRAIN_POLY_DEG polynomial in t = min(d, span) inv_half_span - 1 (inv_half_span = 2/span) of
 * clpost/stages/grain.py sigma_polynomial (poly[0..GRAIN_POLY_DEG], constant term first), and G
 * the unit normals filtered by the separable [a, b, a] (a = 0, b = 1: white).
 *
 * Normals: counter (X, Y) of layer c is pixel (X - 1, Y - 1)'s; the Box-Muller draw of hash
 * (seed, frame, X >> 1, Y << 2 | c) gives X even its cosine and X odd its sine branch
 * (rnd_normal_pair). The same numbers in both forms below, summed in the same order. */
inline float grain_pixel(const float d, const float dmin, const float dmax, const float g,
                         __global const float *poly, const float inv_half_span, const float amount) {
    const float d_img = fmax(d - dmin, 0.0f);
    const float t = fmin(d_img * inv_half_span, 2.0f) - 1.0f;
    float p = poly[GRAIN_POLY_DEG];
    for (int k = GRAIN_POLY_DEG - 1; k >= 0; --k)
        p = fma(p, t, poly[k]);
    const float mean = clp_exp2(-3.32192809f * d_img);   /* 10^-d */
    const float sigma = mean * sqrt(fmax((t + 1.0f) * p, 0.0f));
    return grain_to_density(mean + amount * sigma * g, dmin, dmax);
}

/* The lane form of grain_pixel. */
inline float16 grain_pixel16(const float16 d, const float dmin, const float dmax, const float16 g,
                             __global const float *poly, const float inv_half_span, const float amount) {
    const float16 d_img = fmax(d - dmin, 0.0f);
    const float16 t = fmin(d_img * inv_half_span, 2.0f) - 1.0f;
    float16 p = (float16)(poly[GRAIN_POLY_DEG]);
    for (int k = GRAIN_POLY_DEG - 1; k >= 0; --k)
        p = fma(p, t, poly[k]);
    const float16 mean = clp_exp2_w16(-3.32192809f * d_img);
    const float16 sigma = mean * sqrt(fmax((t + 1.0f) * p, 0.0f));
    return clamp(dmin - 0.30102999566f * clp_log2_w16(fmax(mean + amount * sigma * g, 1e-30f)), dmin, dmax);
}

/* The four normals of counters 2 (X >> 1) .. 2 (X >> 1) + 3 in row Y: two Box-Muller draws. */
inline void grain_normals4(const uint seed, const uint frame, const int X, const int Y, const uint c,
                           float n[4]) {
    for (int q = 0; q < 2; ++q) {
        const uint hh = rnd_hash4(seed, frame, (uint)(X >> 1) + (uint)q, ((uint)Y << 2) | c);
        n[2 * q] = rnd_normal_pair(hh, rnd_mix(hh ^ 0x68e31da4u), &n[2 * q + 1]);
    }
}

/* One pixel (a GPU's form, GRAIN_LANES 1, and the last 1-15 pixels of a row in the lane form). */
inline void grain_gaussian_px(__global const float *restrict src, __global float *restrict dst,
                              const int x, const int y, const int width, const int height,
                              __global const float *params, __global const float *poly,
                              const float inv_half_span, const float a, const float b,
                              const float amount, const uint seed, const uint frame) {
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
    const int o = x & 1;   /* counter x is lane o of its pair */
    for (uint c = 0; c < 3; ++c) {
        float hr[3];
        for (int j = 0; j < 3; ++j) {
            float nq[4];
            grain_normals4(seed, frame, x, y + j, c, nq);
            hr[j] = a * nq[o] + b * nq[o + 1] + a * nq[o + 2];
        }
        const float g = a * hr[0] + b * hr[1] + a * hr[2];
        dst[c * n + i] = grain_pixel(src[c * n + i], params[c], params[3 + c], g, poly, inv_half_span, amount);
    }
}

/* [a, b, a] along two rows of counters from x0 (even): the Box-Muller draws of pairs x0/2 + 0..7
 * of rows Y (lanes 0-7) and Y + 1 (lanes 8-15) interleaved into each row's 16 normals, and the
 * row's next two normals e0, e1 (counters x0 + 16, x0 + 17). */
inline void grain_hrows16(const uint seed, const uint frame, const int x0, const int Y, const uint c,
                          const float a, const float b, const float *ce, const float *se,
                          float16 *h0, float16 *h1) {
    const uint16 lane = CLP_ULANES16;
    const uint16 hh = rnd_hash4_w16(seed, frame, (uint16)((uint)x0 >> 1) + (lane & 7u),
                                    (((uint16)((uint)Y) + (lane >> 3)) << 2) | c);
    float16 s;
    const float16 k = rnd_normal_pair_w16(hh, rnd_mix_w16(hh ^ 0x68e31da4u), &s);
    for (int r = 0; r < 2; ++r) {
        const float8 kc = r ? k.hi : k.lo, sc = r ? s.hi : s.lo;
        const float16 n0 = (float16)(kc.s0, sc.s0, kc.s1, sc.s1, kc.s2, sc.s2, kc.s3, sc.s3,
                                     kc.s4, sc.s4, kc.s5, sc.s5, kc.s6, sc.s6, kc.s7, sc.s7);
        const float e0 = ce[r], e1 = se[r];
        const float16 n1 = (float16)(n0.s1234, n0.s5678, n0.s9abc, n0.sdef, e0);
        const float16 n2 = (float16)(n0.s2345, n0.s6789, n0.sabcd, n0.sef, e0, e1);
        const float16 h = a * n0 + b * n1 + a * n2;
        if (r) *h1 = h; else *h0 = h;
    }
}

/* 16 pixels of GRAIN_ROWS rows per work-item (x0 = 16 gid0, y0 = GRAIN_ROWS gid1): the separable
 * filter reuses each filtered row for three output rows and each Box-Muller draw gives two
 * normals, so a pixel and layer costs (GRAIN_ROWS + 2) x 9 / (16 GRAIN_ROWS) draws (0.64 at 14
 * rows; 9 normals each of its own draw before), all in float16 lanes (kernels/random.cl at width
 * 16): the draws of pair x0/2 + 8 (the two normals past each row's 16) of the GRAIN_ROWS + 2 rows
 * are one more float16 per layer. */
inline void grain_gaussian16(__global const float *restrict src, __global float *restrict dst,
                             const int width, const int height, __global const float *params,
                             __global const float *poly, const float inv_half_span,
                             const float a, const float b, const float amount, const uint seed,
                             const uint frame) {
    const int x0 = get_global_id(0) * 16;
    const int y0 = get_global_id(1) * GRAIN_ROWS;
    if (x0 >= width || y0 >= height) return;
    if (x0 + 16 > width) {   /* the row's last 1-15 pixels, one by one */
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
        /* lane r: the draw of pair x0/2 + 8 in row y0 + r: counters x0 + 16 (cosine), x0 + 17 (sine) */
        float ce[16], se[16];
        {
            const uint16 hh = rnd_hash4_w16(seed, frame, (uint16)(((uint)x0 >> 1) + 8u),
                                            (((uint16)((uint)y0) + CLP_ULANES16) << 2) | c);
            float16 s;
            vstore16(rnd_normal_pair_w16(hh, rnd_mix_w16(hh ^ 0x68e31da4u), &s), 0, ce);
            vstore16(s, 0, se);
        }
        float16 h0, h1, h2, h3;
        grain_hrows16(seed, frame, x0, y0, c, a, b, ce, se, &h0, &h1);
        for (int r = 0; r < GRAIN_ROWS; r += 2) {
            grain_hrows16(seed, frame, x0, y0 + r + 2, c, a, b, ce + r + 2, se + r + 2, &h2, &h3);
            const float16 g0 = a * h0 + b * h1 + a * h2;
            const float16 g1 = a * h1 + b * h2 + a * h3;
            h0 = h2;
            h1 = h3;
            const int y = y0 + r;
            if (y >= height) break;
            const size_t i = (size_t)y * (size_t)width + (size_t)x0;
            vstore16(grain_pixel16(vload16(0, src + c * n + i), dmin, dmax, g0, poly, inv_half_span, amount),
                     0, dst + c * n + i);
            if (y + 1 >= height) break;
            vstore16(grain_pixel16(vload16(0, src + c * n + i + width), dmin, dmax, g1, poly, inv_half_span,
                                   amount), 0, dst + c * n + i + width);
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
 * GRAIN_LANES the Gaussian path's form: 16 pixels x GRAIN_ROWS rows per work-item (a CPU's SIMD
 * lanes) or one pixel (a GPU's: a warp's loads and stores coalesce). */
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
    grain_gaussian16(src, dst, width, height, params, poly, inv_half_span, a, b, amount, seed, frame);
#endif
}
