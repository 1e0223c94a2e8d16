/* Elementary functions for hot per-pixel code, width-generic (see clpost/codegen.py "Width-generic
 * code"): written once in terms of CLP_F / CLP_I / CLP_U and CLP_FN(name), instantiated by the
 * generator at one pixel (names clp_log2, ... for gathers: codegen.library(); clp_log2_w1 in fused
 * pointwise kernels) and at 16 pixels (clp_log2_w16, float16 lanes).
 *
 * PoCL 3.0's log/log2/log10 and cospi do not vectorise across work-items and cost many times a
 * copy of the frame; these are built from integer bit operations, fma and short polynomials and
 * do vectorise (measurements: docs/measurements.md#kernel-forms-on-pocl). Every select
 * costs: the domains are restricted to what the callers pass, and the callers clamp first.
 * Accuracy (tests/test_fastmath.py, against float64):
 *   clp_log2(x), x normal and finite (FLT_MIN <= x <= FLT_MAX): |error| <= max(2e-7, 2 ulp);
 *   clp_exp2(x), any non-NaN x: <= 2 ulp (exp2(-inf) = 0, exp2(x >= 128) = +inf);
 *   clp_exp2_bounded(x), |x| <= 126: <= 4 ulp;
 *   clp_cos2pi(u) = cos(2 pi u), finite u: |error| < 2.5e-7;
 *   clp_cossin2pi_half(v) = cos(2 pi v), sin(2 pi v), |v| <= 1/2: |error| < 2.5e-7.
 * Selects are written `c ? a : b` (per lane for vectors) and integer flags never added: a vector
 * comparison is -1 where true, a scalar one 1.
 */

/* log2 x = e + log2 m with x = m 2^e, m in [sqrt(1/2), sqrt(2)); log2 m = u Q(u), u = m - 1 (exact),
 * Q of degree 8 fitted to log2(1 + u)/u at Chebyshev nodes on [sqrt(1/2) - 1, sqrt(2) - 1]
 * (weighted by |u|: |u Q(u) - log2(1 + u)| < 6.4e-8 in float32). No division: a vector divide
 * costs a CPU ~20 fma's issue slots (the film and grain kernels measured x0.9 without it). */
inline CLP_F CLP_FN(clp_log2)(const CLP_F x) {
    const CLP_U bits = CLP_AS_U(x);
    CLP_I e = CLP_AS_I((bits >> 23) & 0xffu) - 127;
    CLP_F m = CLP_AS_F((bits & 0x007fffffu) | 0x3f800000u);   /* [1, 2) */
    const CLP_I big = m > 1.41421356f;
    m = big ? 0.5f * m : m;
    e = big ? e + 1 : e;
    const CLP_F u = m - 1.0f, u2 = u * u, u4 = u2 * u2;
    /* Q by Estrin's scheme (pairs, then powers u^2, u^4): 5 dependent operations instead of
     * Horner's 8, for grain's and film's long per-pixel chains (docs/benchmarks.md) */
    const CLP_F q01 = fma(u, -7.213473797e-1f, 1.442694855f), q23 = fma(u, -3.607062060e-1f, 4.809235176e-1f);
    const CLP_F q45 = fma(u, -2.387827314e-1f, 2.876248107e-1f), q67 = fma(u, -2.088673073e-1f, 2.178854908e-1f);
    const CLP_F q03 = fma(u2, q23, q01), q47 = fma(u2, q67, q45);
    const CLP_F p = fma(u4, fma(u4, 1.224903415e-1f, q47), q03);
    return fma(u, p, CLP_TO_F(e));
}

/* 2^x = 2^k 2^f, k = round(x), |f| <= 1/2; 2^f = e^(f ln 2) by Taylor to degree 7 (< 5e-9
 * relative); 2^k applied in two halves so subnormal results and k = 128 come out right.
 * floor(x + 0.5) rather than rint: rint does not vectorise on PoCL. */
inline CLP_F CLP_FN(clp_exp2)(const CLP_F x) {
    const CLP_F xc = clamp(x, -151.0f, 129.0f);
    const CLP_F k = floor(xc + 0.5f);
    const CLP_F f = (xc - k) * 0.69314718f;
    CLP_F p = fma(f, 1.98412698e-4f, 1.38888889e-3f);    /* 1/7!, 1/6! */
    p = fma(f, p, 8.33333333e-3f);
    p = fma(f, p, 4.16666667e-2f);
    p = fma(f, p, 0.16666667f);
    p = fma(f, p, 0.5f);
    p = fma(f, p, 1.0f);
    p = fma(f, p, 1.0f);
    const CLP_I ki = CLP_TO_I(k);
    const CLP_I k1 = ki >> 1, k2 = ki - k1;               /* each in [-76, 65]: normal scales */
    return p * CLP_AS_F(CLP_AS_U(k1 + 127) << 23) * CLP_AS_F(CLP_AS_U(k2 + 127) << 23);
}

/* 2^x for |x| <= 126 (callers clamp; a normal result, one scale): Taylor to degree 6
 * (< 1.3e-7 relative), ~2/3 the operations of clp_exp2. */
inline CLP_F CLP_FN(clp_exp2_bounded)(const CLP_F x) {
    const CLP_F k = floor(x + 0.5f);
    const CLP_F f = (x - k) * 0.69314718f;
    CLP_F p = fma(f, 1.38888889e-3f, 8.33333333e-3f);    /* 1/6!, 1/5! */
    p = fma(f, p, 4.16666667e-2f);
    p = fma(f, p, 0.16666667f);
    p = fma(f, p, 0.5f);
    p = fma(f, p, 1.0f);
    p = fma(f, p, 1.0f);
    return p * CLP_AS_F(CLP_AS_U(CLP_TO_I(k) + 127) << 23);
}

/* sin z for |z| <= pi/2: odd Taylor series to z^13 (truncation < 1e-9). */
inline CLP_F CLP_FN(clp_sin_core)(const CLP_F z) {
    const CLP_F z2 = z * z;
    CLP_F p = fma(z2, -1.60590438e-10f, 2.50521084e-8f);   /* -1/13!, 1/11! */
    p = fma(z2, p, -2.75573192e-6f);
    p = fma(z2, p, 1.98412698e-4f);
    p = fma(z2, p, -8.33333333e-3f);
    p = fma(z2, p, 0.16666667f);
    return fma(-z * z2, p, z);
}

/* cos(2 pi u): r = u - round(u), cos 2 pi r = sin(2 pi (1/4 - |r|)) with the argument in
 * [-pi/2, pi/2]. */
inline CLP_F CLP_FN(clp_cos2pi)(const CLP_F u) {
    const CLP_F r = u - floor(u + 0.5f);
    return CLP_FN(clp_sin_core)((0.25f - fabs(r)) * 6.28318531f);
}

/* cos(2 pi v), returned, and sin(2 pi v), in *s, for |v| <= 1/2 (the callers' domain: no range
 * reduction, which costs clp_cos2pi's floor): cos 2 pi v = sin(2 pi (1/4 - |v|)),
 * sin 2 pi v = sgn(v) sin(2 pi (1/4 - ||v| - 1/4|)), both arguments in [-pi/2, pi/2]. */
inline CLP_F CLP_FN(clp_cossin2pi_half)(const CLP_F v, CLP_F *s) {
    const CLP_F a = fabs(v), w = 0.25f - fabs(a - 0.25f);
    *s = CLP_FN(clp_sin_core)((v < 0.0f ? -w : w) * 6.28318531f);
    return CLP_FN(clp_sin_core)((0.25f - a) * 6.28318531f);
}
