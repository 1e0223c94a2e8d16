/* film: normalised signal -> dye density per layer via a LUT uniform in log10 exposure.
 * lut: 3 x FILM_LUT_SIZE densities (layer-major); x = log10(signal) + log10(78/S) is log10 H in
 * lux*s; indices outside the table clamp to its ends (D_min / D_max). clpost/stages/film.py has
 * the formula and sources.
 */
inline float film_lookup(__global const float *lut, const int layer, const float x,
                         const float lo, const float inv_step) {
    /* fmax/fmin also map -inf (signal 0) to the first entry without NaN. */
    const float u = fmin(fmax((x - lo) * inv_step, 0.0f), (float)(FILM_LUT_SIZE - 1));
    const int i = min((int)u, FILM_LUT_SIZE - 2);
    const float f = u - (float)i;
    __global const float *t = lut + layer * FILM_LUT_SIZE;
    return mad(f, t[i + 1] - t[i], t[i]);
}

inline float3 film_apply(const float3 c, const PixelCtx p, __global const float *lut,
                         const float log_offset, const float lo, const float inv_step) {
    /* log10 = log2 * log10(2) with the vectorising clp_log2 (kernels/common.cl), per channel in
     * scalar code: on PoCL, PoCL's log10 and float3 arithmetic both stop the vectorisation across
     * work-items. fmax keeps the argument a normal float (clp_log2's domain). */
    return (float3)(film_lookup(lut, 0, mad(clp_log2(fmax(c.x, 1e-37f)), 0.30102999566f, log_offset), lo, inv_step),
                    film_lookup(lut, 1, mad(clp_log2(fmax(c.y, 1e-37f)), 0.30102999566f, log_offset), lo, inv_step),
                    film_lookup(lut, 2, mad(clp_log2(fmax(c.z, 1e-37f)), 0.30102999566f, log_offset), lo, inv_step));
}
