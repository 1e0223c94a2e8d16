/* film: normalised signal -> dye density per layer via a table uniform in log10 exposure.
 * lut: 3 x FILM_LUT_SIZE packed entries (layer-major), entry i = v << 12 | dv: the density at
 * grid point i, v * dec[3 + layer] + dec[layer] (20 bits), and the step to point i + 1,
 * dv * dec[6 + layer] (12 bits) — one load per lane and layer for the linear interpolation
 * (clpost/stages/film.py packed_lut). x = log10(signal) + log10(78/S) is log10 H in lux*s;
 * indices outside the table clamp to its ends (D_min / D_max). clpost/stages/film.py has the
 * formula and sources. Width-generic (clpost/codegen.py): CLP_W pixels of a row per call; the
 * table is read per lane (CLP_GATHERU).
 */
inline CLP_F CLP_FN(film_lookup)(__global const uint *lut, __global const float *dec, const int layer,
                                 const CLP_F x, const float lo, const float inv_step) {
    /* fmax/fmin also map -inf (signal 0) to the first entry without NaN. */
    const CLP_F u = fmin(fmax((x - lo) * inv_step, 0.0f), (float)(FILM_LUT_SIZE - 1));
    const CLP_I i = min(CLP_TO_I(u), FILM_LUT_SIZE - 2);
    const CLP_F f = u - CLP_TO_F(i);
    const CLP_U e = CLP_GATHERU(lut + layer * FILM_LUT_SIZE, i);
    const CLP_F v = mad(CLP_TO_F(e >> 12), dec[3 + layer], dec[layer]);
    return mad(f, CLP_TO_F(e & 0xfffu) * dec[6 + layer], v);
}

/* log10 = log2 * log10(2) with the vectorising clp_log2 (kernels/fastmath.cl): PoCL's log10 does
 * not vectorise. fmax keeps the argument a normal float (clp_log2's domain). */
inline CLP_F CLP_FN(film_layer)(const CLP_F s, __global const uint *lut, __global const float *dec,
                                const int layer, const float log_offset, const float lo, const float inv_step) {
    return CLP_FN(film_lookup)(lut, dec, layer, mad(CLP_FN(clp_log2)(fmax(s, 1e-37f)), 0.30102999566f, log_offset),
                               lo, inv_step);
}

inline void film_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, __global const uint *lut,
                       __global const float *dec, const float log_offset, const float lo, const float inv_step) {
    *r = CLP_FN(film_layer)(*r, lut, dec, 0, log_offset, lo, inv_step);
    *g = CLP_FN(film_layer)(*g, lut, dec, 1, log_offset, lo, inv_step);
    *b = CLP_FN(film_layer)(*b, lut, dec, 2, log_offset, lo, inv_step);
}
