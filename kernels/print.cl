/* print: developed densities -> paper print (PRINT_MODE 0, display-referred) or re-linearised
 * scene-linear (PRINT_MODE 1). params = [a0 a1 a2 b0 b1 b2 k range scale]; formulas and sources
 * in clpost/stages/print.py.
 */
/* One channel. exp and exp10 through clp_exp2 (kernels/common.cl), in scalar code: PoCL's exp10
 * and float3 arithmetic stop the vectorisation across work-items (measured at 1080p: 90-120 ms
 * as float3, 24 ms per channel). */
inline float print_channel(const float d, __global const float *params, const int ch) {
#if PRINT_MODE == 0
    /* e^(-k x) overflows to +inf for very thin negatives: 1/(1+inf) = 0 -> paper white, no NaN. */
    const float dp = params[7] / (1.0f + clp_exp2(-params[6] * 1.44269504f * (params[ch] - d)));
    return clp_exp2(-3.32192809f * dp);
#else
    return clp_exp2(3.32192809f * ((d - params[ch]) * params[3 + ch])) * params[8];
#endif
}

inline float3 print_apply(const float3 c, const PixelCtx p, __global const float *params) {
    return (float3)(print_channel(c.x, params, 0), print_channel(c.y, params, 1),
                    print_channel(c.z, params, 2));
}
