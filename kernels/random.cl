/* Counter-based random numbers (CONVENTIONS.md "Randomness"): every value is a pure function of
 * (seed, frame, pixel, sample), so results are identical on any device and any work-group size,
 * and frames are independent. Hash: Chris Wellons' "lowbias32" integer finaliser (bias 0.17),
 * chained over the counter words. clpost/random.py is the bit-exact numpy twin.
 * Included by several stages; the guard lets a fused program contain it once.
 */
#ifndef CLPOST_RANDOM_CL
#define CLPOST_RANDOM_CL

inline uint rnd_mix(uint x) {
    x ^= x >> 16; x *= 0x7feb352du;
    x ^= x >> 15; x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

/* Hash of the counter (seed, frame, a, b): a, b are e.g. pixel index and sample number. */
inline uint rnd_hash4(const uint seed, const uint frame, const uint a, const uint b) {
    uint h = rnd_mix(seed ^ 0x9e3779b9u);
    h = rnd_mix(h ^ frame);
    h = rnd_mix(h ^ a);
    return rnd_mix(h ^ b);
}

/* Uniform in (0, 1): 24 high bits, centred in their bin, never 0 or 1 (log() safe). */
inline float rnd_uniform(const uint h) {
    return ((float)(h >> 8) + 0.5f) * (1.0f / 16777216.0f);
}

/* Standard normal from two hashes (Box-Muller, cosine branch). ln and cos through clp_log2 and
 * clp_cos2pi (kernels/common.cl, which every program that includes this file starts with):
 * PoCL's log and cospi do not vectorise and made Box-Muller ~30 ns a normal. u1 >= 2^-25 is a
 * normal float, inside clp_log2's domain. */
inline float rnd_normal(const uint h1, const uint h2) {
    const float u1 = rnd_uniform(h1);
    const float u2 = rnd_uniform(h2);
    return sqrt(-1.38629436f * clp_log2(u1)) * clp_cos2pi(u2);
}

/* Poisson(mean) by inversion with uniform u: the smallest n with u <= F(n; mean), by the
 * sequential search over the pmf (at most 128 steps; for small means — callers switch to a
 * normal approximation above theirs). clpost/random.py poisson_inversion is the numpy twin. */
inline float rnd_poisson_inversion(const float mean, const float u) {
    float prob = exp(-mean), cdf = prob, n = 0.0f;
    for (int k = 1; k <= 128 && u > cdf; ++k) {
        prob *= mean / (float)k;
        cdf += prob;
        n = (float)k;
    }
    return n;
}

#endif
