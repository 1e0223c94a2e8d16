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

/* Uniform in (0, 1): 24 high bits, centred in their bin, never 0 or 1 (log() safe). */
inline CLP_F CLP_FN(rnd_uniform)(const CLP_U h) {
    return (CLP_TO_F(h >> 8) + 0.5f) * (1.0f / 16777216.0f);
}

/* Standard normal from two hashes (Box-Muller, cosine branch). ln and cos through clp_log2 and
 * clp_cos2pi (kernels/fastmath.cl): PoCL's log and cospi do not vectorise. u1 >= 2^-25 is a normal
 * float, inside clp_log2's domain. */
inline CLP_F CLP_FN(rnd_normal)(const CLP_U h1, const CLP_U h2) {
    const CLP_F u1 = CLP_FN(rnd_uniform)(h1);
    const CLP_F u2 = CLP_FN(rnd_uniform)(h2);
    return sqrt(-1.38629436f * CLP_FN(clp_log2)(u1)) * CLP_FN(clp_cos2pi)(u2);
}

/* Both normals of one Box-Muller draw: returns the cosine branch (= rnd_normal(h1, h2)) and
 * stores the sine branch, sin 2 pi u2 = cos 2 pi (u2 - 1/4), in *other; the two are independent
 * standard normals for one log, one square root and two hashes. clpost/random.py normal_pair. */
inline CLP_F CLP_FN(rnd_normal_pair)(const CLP_U h1, const CLP_U h2, CLP_F *other) {
    const CLP_F rad = sqrt(-1.38629436f * CLP_FN(clp_log2)(CLP_FN(rnd_uniform)(h1)));
    const CLP_F u2 = CLP_FN(rnd_uniform)(h2);
    *other = rad * CLP_FN(clp_cos2pi)(u2 - 0.25f);
    return rad * CLP_FN(clp_cos2pi)(u2);
}

/* Poisson(mean) by inversion with uniform u: the smallest n with u <= F(n; mean), by the
 * sequential search over the pmf (at most 128 steps; for small means — callers switch to a
 * normal approximation above theirs, and pass 0 for those lanes so they stop at once).
 * clpost/random.py poisson_inversion is the numpy twin. */
inline CLP_F CLP_FN(rnd_poisson_inversion)(const CLP_F mean, const CLP_F u) {
    CLP_F prob = exp(-mean), cdf = prob, n = 0.0f;
    for (int k = 1; k <= 128; ++k) {
        const CLP_I more = u > cdf;
        if (!CLP_ANY(more)) break;
        prob *= mean / (float)k;
        cdf += prob;
        n = more ? (CLP_F)((float)k) : n;
    }
    return n;
}

/* Photon shot noise: Poisson(mean) exactly by inversion (uniform u) up to RND_POISSON_EXACT_MAX,
 * above it the normal approximation round(mean + sqrt(mean) g) >= 0 with the Poisson variance
 * (standard normal g); both branches are evaluated and selected per lane, the search getting
 * mean 0 (one step) where the normal one is taken. clpost/random.py poisson is the numpy twin. */
#define RND_POISSON_EXACT_MAX 32.0f
inline CLP_F CLP_FN(rnd_poisson)(const CLP_F mean, const CLP_F u, const CLP_F g) {
    const CLP_I normal = mean > RND_POISSON_EXACT_MAX;
    const CLP_F e_normal = fmax(rint(mean + sqrt(mean) * g), 0.0f);
    const CLP_F e_exact = CLP_FN(rnd_poisson_inversion)(normal ? (CLP_F)(0.0f) : mean, u);
    return normal ? e_normal : e_exact;
}
