/* Counter-based random numbers (CONVENTIONS.md "Randomness"): every value is a pure function of
 * (seed, frame, pixel, sample), so results are identical on any device and any work-group size,
 * and frames are independent. Hash: Chris Wellons' "lowbias32" integer finaliser (bias 0.17),
 * chained over the counter words. clpost/random.py is the bit-exact numpy twin.
 *
 * Width-generic (clpost/codegen.py "Width-generic code"), after kernels/fastmath.cl: one pixel
 * (rnd_hash4, ... in gathers through codegen.library()) or 16 lanes (rnd_hash4_w16 on uint16
 * counters) in fused pointwise kernels; the counter words that vary per pixel are CLP_U.
 */

inline CLP_U CLP_FN(rnd_mix)(CLP_U x) {
    x ^= x >> 16; x *= 0x7feb352du;
    x ^= x >> 15; x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

/* rnd_mix of one uint: the (seed, frame) words are the same in every lane, hashed once. */
inline uint CLP_FN(rnd_mix1)(uint x) {
    x ^= x >> 16; x *= 0x7feb352du;
    x ^= x >> 15; x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

/* Hash of the counter (seed, frame, a, b): a, b are e.g. pixel index and sample number. */
inline CLP_U CLP_FN(rnd_hash4)(const uint seed, const uint frame, const CLP_U a, const CLP_U b) {
    const uint h = CLP_FN(rnd_mix1)(CLP_FN(rnd_mix1)(seed ^ 0x9e3779b9u) ^ frame);
    return CLP_FN(rnd_mix)(CLP_FN(rnd_mix)((CLP_U)h ^ a) ^ b);
}

/* Uniform in (0, 1]: 24 high bits, centred in their bin, never 0 (log() safe); the top bin's centre,
 * 1 - 2^-25, rounds to 1.0f (rnd_poisson_inversion stops where its float32 sum does). */
inline CLP_F CLP_FN(rnd_uniform)(const CLP_U h) {
    return (CLP_TO_F(h >> 8) + 0.5f) * (1.0f / 16777216.0f);
}

/* Standard normal from two hashes (Box-Muller, cosine branch). ln through clp_log2
 * (kernels/fastmath.cl): PoCL's log does not vectorise. u1 >= 2^-25 is a normal float, inside
 * clp_log2's domain. cos 2 pi u2 = -cos 2 pi v with v = u2 - 1/2 (exact, |v| <= 1/2, v = 1/2 for
 * the top uniform 1.0f: clp_cossin2pi_half, no range reduction). */
inline CLP_F CLP_FN(rnd_normal)(const CLP_U h1, const CLP_U h2) {
    CLP_F unused;
    const CLP_F c = CLP_FN(clp_cossin2pi_half)(CLP_FN(rnd_uniform)(h2) - 0.5f, &unused);
    return -sqrt(-1.38629436f * CLP_FN(clp_log2)(CLP_FN(rnd_uniform)(h1))) * c;
}

/* Both normals of one Box-Muller draw: returns the cosine branch (= rnd_normal(h1, h2)) and
 * stores the sine branch, sin 2 pi u2 = -sin 2 pi (u2 - 1/2), in *other; the two are independent
 * standard normals for one log, one square root and two hashes. clpost/random.py normal_pair. */
inline CLP_F CLP_FN(rnd_normal_pair)(const CLP_U h1, const CLP_U h2, CLP_F *other) {
    const CLP_F nrad = -sqrt(-1.38629436f * CLP_FN(clp_log2)(CLP_FN(rnd_uniform)(h1)));
    CLP_F s;
    const CLP_F c = CLP_FN(clp_cossin2pi_half)(CLP_FN(rnd_uniform)(h2) - 0.5f, &s);
    *other = nrad * s;
    return nrad * c;
}

/* Poisson(mean) by inversion with uniform u: the smallest n with u <= F(n; mean) — the number of
 * k >= 0 with F(k) < u, F non-decreasing — by the sequential search over the pmf, eight terms per
 * iteration, all from p_k: p_{k+j} = p_k mean^j c_j, c_j = 1/((k+1)...(k+j)) (scalar, from the
 * table of 1/k), F(k+j) = F(k) + (p_{k+1} + ... + p_{k+j}). The loop-carried work is one multiply
 * and one add per eight steps, the lane test (any u > F(k)) once per eight, and there is no
 * vector division (why eight: docs/benchmarks.md, "Grain's Gaussian path and sensor, second
 * pass"). At most 128 steps; for small means — callers switch to a normal
 * approximation above theirs, and pass 0 for those lanes so they stop at once (the search needs
 * e^-mean > 0 in float32: mean < ~87, ~103 where subnormals are kept; beyond, it returns 8).
 * clpost/random.py poisson_inversion is the numpy twin (float64, one term per step: the same n
 * but where u lies within float32 rounding of an F(n); tests/test_poisson_sampler.py). */
#ifndef RND_INV_DEFINED   /* this file is instantiated once per width */
#define RND_INV_DEFINED
__constant float rnd_inv[129] = {   /* 1/k, k = 0 (unused) .. 128 */
    0.0f, 1.000000000e+00f, 5.000000000e-01f, 3.333333333e-01f, 2.500000000e-01f, 2.000000000e-01f,
    1.666666667e-01f, 1.428571429e-01f, 1.250000000e-01f, 1.111111111e-01f, 1.000000000e-01f, 9.090909091e-02f,
    8.333333333e-02f, 7.692307692e-02f, 7.142857143e-02f, 6.666666667e-02f, 6.250000000e-02f, 5.882352941e-02f,
    5.555555556e-02f, 5.263157895e-02f, 5.000000000e-02f, 4.761904762e-02f, 4.545454545e-02f, 4.347826087e-02f,
    4.166666667e-02f, 4.000000000e-02f, 3.846153846e-02f, 3.703703704e-02f, 3.571428571e-02f, 3.448275862e-02f,
    3.333333333e-02f, 3.225806452e-02f, 3.125000000e-02f, 3.030303030e-02f, 2.941176471e-02f, 2.857142857e-02f,
    2.777777778e-02f, 2.702702703e-02f, 2.631578947e-02f, 2.564102564e-02f, 2.500000000e-02f, 2.439024390e-02f,
    2.380952381e-02f, 2.325581395e-02f, 2.272727273e-02f, 2.222222222e-02f, 2.173913043e-02f, 2.127659574e-02f,
    2.083333333e-02f, 2.040816327e-02f, 2.000000000e-02f, 1.960784314e-02f, 1.923076923e-02f, 1.886792453e-02f,
    1.851851852e-02f, 1.818181818e-02f, 1.785714286e-02f, 1.754385965e-02f, 1.724137931e-02f, 1.694915254e-02f,
    1.666666667e-02f, 1.639344262e-02f, 1.612903226e-02f, 1.587301587e-02f, 1.562500000e-02f, 1.538461538e-02f,
    1.515151515e-02f, 1.492537313e-02f, 1.470588235e-02f, 1.449275362e-02f, 1.428571429e-02f, 1.408450704e-02f,
    1.388888889e-02f, 1.369863014e-02f, 1.351351351e-02f, 1.333333333e-02f, 1.315789474e-02f, 1.298701299e-02f,
    1.282051282e-02f, 1.265822785e-02f, 1.250000000e-02f, 1.234567901e-02f, 1.219512195e-02f, 1.204819277e-02f,
    1.190476190e-02f, 1.176470588e-02f, 1.162790698e-02f, 1.149425287e-02f, 1.136363636e-02f, 1.123595506e-02f,
    1.111111111e-02f, 1.098901099e-02f, 1.086956522e-02f, 1.075268817e-02f, 1.063829787e-02f, 1.052631579e-02f,
    1.041666667e-02f, 1.030927835e-02f, 1.020408163e-02f, 1.010101010e-02f, 1.000000000e-02f, 9.900990099e-03f,
    9.803921569e-03f, 9.708737864e-03f, 9.615384615e-03f, 9.523809524e-03f, 9.433962264e-03f, 9.345794393e-03f,
    9.259259259e-03f, 9.174311927e-03f, 9.090909091e-03f, 9.009009009e-03f, 8.928571429e-03f, 8.849557522e-03f,
    8.771929825e-03f, 8.695652174e-03f, 8.620689655e-03f, 8.547008547e-03f, 8.474576271e-03f, 8.403361345e-03f,
    8.333333333e-03f, 8.264462810e-03f, 8.196721311e-03f, 8.130081301e-03f, 8.064516129e-03f, 8.000000000e-03f,
    7.936507937e-03f, 7.874015748e-03f, 7.812500000e-03f
};
#endif
inline CLP_F CLP_FN(rnd_poisson_inversion)(const CLP_F mean, CLP_F u) {
    CLP_F mp[8];   /* mean^(j + 1) */
    mp[0] = mean;
    for (int j = 1; j < 8; ++j)
        mp[j] = mp[j - 1] * mean;
    CLP_F prob = exp(-mean), cdf = prob, n = 0.0f;
    for (int k = 0; k < 128; k += 8) {
        if (!CLP_ANY(u > cdf)) break;
        float c = 1.0f;                 /* c_{j+1} */
        CLP_F s = 0.0f, pj = 0.0f;      /* p_{k+1} + ... + p_{k+j+1}, p_{k+j+1} */
        n = u > cdf ? (CLP_F)((float)(k + 1)) : n;
        for (int j = 0; j < 8; ++j) {
            c *= rnd_inv[k + j + 1];
            pj = prob * (mp[j] * c);
            s += pj;
            if (j < 7)
                n = u > cdf + s ? (CLP_F)((float)(k + j + 2)) : n;
        }
        prob = pj;
        /* where the float32 sum has stopped moving (the tail's terms below its rounding) before
         * reaching u — u rounds to 1.0f for the top 24-bit value, and cdf may end an ulp or two
         * short of it — no later F(k) reaches u: the lane is done, with n the end of the block in
         * which its sum stopped (within -8 .. +16 of the float64 quantile of 1 - 2^-25, not 128;
         * tests/test_poisson_sampler.py) */
        u = cdf + s == cdf ? (CLP_F)(0.0f) : u;
        cdf += s;
    }
    return n;
}

/* Photon shot noise: Poisson(mean) exactly by inversion up to RND_POISSON_EXACT_MAX, with the
 * uniform of counter (a, b); above it the normal approximation round(mean + sqrt(mean) g) >= 0
 * with the Poisson variance (standard normal g). Per lane; the search (and its hash) runs only
 * where a lane needs it, with mean 0 (no step) in the lanes of the normal approximation.
 * clpost/random.py poisson is the numpy twin. */
#define RND_POISSON_EXACT_MAX 32.0f
inline CLP_F CLP_FN(rnd_poisson)(const CLP_F mean, const CLP_F g, const uint seed, const uint frame,
                                 const CLP_U a, const uint b) {
    const CLP_I normal = mean > RND_POISSON_EXACT_MAX;
    CLP_F e = fmax(rint(mean + sqrt(mean) * g), 0.0f);
    if (CLP_ANY(!normal)) {
        const CLP_F u = CLP_FN(rnd_uniform)(CLP_FN(rnd_hash4)(seed, frame, a, (CLP_U)(b)));
        e = normal ? e : CLP_FN(rnd_poisson_inversion)(normal ? (CLP_F)(0.0f) : mean, u);
    }
    return e;
}
