/* print: developed densities -> paper print (PRINT_MODE 0, display-referred) or re-linearised
 * scene-linear (PRINT_MODE 1). params = [a0 a1 a2 b0 b1 b2 k range scale]; formulas and sources
 * in clpost/stages/print.py. Width-generic (clpost/codegen.py): CLP_W pixels of a row per call.
 */
/* One channel. exp and exp10 through clp_exp2(_bounded) (kernels/fastmath.cl): PoCL's exp10 does not
 * vectorise (measurements: docs/measurements.md#kernel-forms-on-pocl). */
inline CLP_F CLP_FN(print_channel)(const CLP_F d, __global const float *params, const int ch) {
#if PRINT_MODE == 0
    /* e^(-k x) clamped to 2^+-126: 1/(1 + 2^126) < 1e-38 is paper white, 2^-126 the full range
     * (both within float rounding of the limits), no NaN for any input; dp in [0, range] keeps the
     * second exponent bounded too. */
    const CLP_F z = clamp(-params[6] * 1.44269504f * (params[ch] - d), -126.0f, 126.0f);
    const CLP_F dp = params[7] / (1.0f + CLP_FN(clp_exp2_bounded)(z));
    return CLP_FN(clp_exp2_bounded)(-3.32192809f * dp);
#else
    return CLP_FN(clp_exp2)(3.32192809f * ((d - params[ch]) * params[3 + ch])) * params[8];
#endif
}

inline void print_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, __global const float *params) {
    *r = CLP_FN(print_channel)(*r, params, 0);
    *g = CLP_FN(print_channel)(*g, params, 1);
    *b = CLP_FN(print_channel)(*b, params, 2);
}
