/* grain's Gaussian path, per pixel: the density with its grain and the counters' normals.
 * Width-generic (clpost/codegen.py "Width-generic code"): instantiated at one pixel and at 16 lanes
 * both in the grain gather's program (kernels/grain.cl: grain_pixel, grain_normal;
 * grain_pixel_w16, grain_block_w16) and in a fused pointwise kernel with white grain
 * (kernels/grain_white.cl). Model and formulas: clpost/stages/grain.py. Needs GRAIN_POLY_DEG.
 *
 * Gaussian clear fraction T + amount sigma_T G with the model's pixel standard deviation in closed
 * form, sigma_T = T sqrt(t + 1) R(t), R the GRAIN_POLY_DEG polynomial in t = min(d, span)
 * inv_half_span - 1 (inv_half_span = 2/span) of clpost/stages/grain.py gaussian_tables
 * (poly[0..GRAIN_POLY_DEG], constant term first), and G the pixel's unit normal (white, or
 * filtered by the gather). */
inline CLP_F CLP_FN(grain_pixel)(const CLP_F d, const float dmin, const float dmax, const CLP_F g,
                                 __global const float *poly, const float inv_half_span, const float amount) {
    const CLP_F d_img = fmax(d - dmin, 0.0f);
    const CLP_F t1 = fmin(d_img * inv_half_span, 2.0f);   /* t + 1, exact near D = 0 */
    const CLP_F t = t1 - 1.0f;
    /* R(t) as a polynomial in t^2 of the pairs poly[k] + poly[k + 1] t (half the dependent fma's
     * of Horner's on the pixel's one long chain), sqrt(t + 1) beside it, not after it */
    const CLP_F t2 = t * t;
#if GRAIN_POLY_DEG % 2
    CLP_F p = fma(poly[GRAIN_POLY_DEG], t, poly[GRAIN_POLY_DEG - 1]);
#else
    CLP_F p = (CLP_F)(poly[GRAIN_POLY_DEG]);
#endif
    for (int k = GRAIN_POLY_DEG - 2 - GRAIN_POLY_DEG % 2; k >= 0; k -= 2)
        p = fma(p, t2, fma(poly[k + 1], t, poly[k]));
    const CLP_F s = sqrt(t1) * p;   /* sigma_T / T */
    /* dmin - log10(T + amount sigma_T g) with T = 10^-d_img factored out: no exp2 (<= 0 -> D_max) */
    return clamp(dmin + d_img - 0.30102999566f * CLP_FN(clp_log2)(fmax(fma(amount * s, g, 1.0f), 1e-30f)), dmin, dmax);
}

/* Normals: counters come in blocks of 32 per row; in block X >> 5 of row Y, layer c, the 16
 * Box-Muller draws (rnd_normal_pair) of hashes (seed, frame, 16 (X >> 5) + k, Y << 2 | c),
 * k = 0..15, give counter 32 (X >> 5) + k its cosine and 32 (X >> 5) + 16 + k its sine branch —
 * so a float16 of draws is 32 consecutive normals with no shuffling (clpost/stages/grain.py
 * grain_normals is the numpy twin). */
#if CLP_W == 1
/* The normal of counter (X, Y) of layer c (counters of the pixels left of and above the image
 * wrap around as uint: any fixed mapping keeps the noise a function of the counters). */
inline float CLP_FN(grain_normal)(const uint seed, const uint frame, const int X, const int Y, const uint c) {
    const uint ux = (uint)X, block = (uint)((X + 32) >> 5) - 1u;   /* floor(X / 32), X >= -1 */
    const uint hh = CLP_FN(rnd_hash4)(seed, frame, (block << 4) | (ux & 15u), ((uint)Y << 2) | c);
    float sine;
    const float cosine = CLP_FN(rnd_normal_pair)(hh, CLP_FN(rnd_mix)(hh ^ 0x68e31da4u), &sine);
    return (ux & 16u) ? sine : cosine;
}
#else
/* The 32 normals of block B of row Y: counters 32 B .. 32 B + 15 (returned), + 16 .. + 31 (*hi). */
inline float16 CLP_FN(grain_block)(const uint seed, const uint frame, const uint B, const int Y, const uint c,
                                   float16 *hi) {
    const uint16 hh = CLP_FN(rnd_hash4)(seed, frame, (uint16)(B << 4) + CLP_ULANES16, (uint16)(((uint)Y << 2) | c));
    return CLP_FN(rnd_normal_pair)(hh, CLP_FN(rnd_mix)(hh ^ 0x68e31da4u), hi);
}
#endif
