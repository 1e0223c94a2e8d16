/* print: developed densities -> paper print (PRINT_MODE 0, display-referred) or re-linearised
 * scene-linear (PRINT_MODE 1). params = [a0 a1 a2 b0 b1 b2 k range scale]; formulas and sources
 * in clpost/stages/print.py.
 */
inline float3 print_apply(const float3 c, const PixelCtx p, __global const float *params) {
    const float3 a = (float3)(params[0], params[1], params[2]);
#if PRINT_MODE == 0
    /* exp(-k x) overflows to +inf for very thin negatives: 1/(1+inf) = 0 -> paper white, no NaN. */
    const float3 dp = params[7] / (1.0f + exp(-params[6] * (a - c)));
    return exp10(-dp);
#else
    const float3 b = (float3)(params[3], params[4], params[5]);
    return exp10((c - a) * b) * params[8];
#endif
}
