/* sensor: normalised signal -> raw digital recording (shot noise, full well, read noise, ISO gain,
 * black level, quantisation), renormalised so 1.0 = clipping. Formulas: clpost/stages/sensor.py.
 * Random numbers: counters (seed, frame, pixel, 4*channel + k), k = 0 and 3, kernels/random.cl.
 * Width-generic (clpost/codegen.py): CLP_W pixels of a row per call; the shot noise is
 * rnd_poisson (kernels/random.cl), its two branches selected per lane.
 */

/* Per channel ch: the shot noise's uniform (exact Poisson) of counter (i, 4 ch); one Box-Muller
 * draw of counter (i, 4 ch + 3) — its second uniform a re-mix of the first hash (a constant XOR
 * alone would leave the two normals correlated) — gives the read noise its cosine branch and the
 * shot noise's normal approximation its sine branch (two independent normals for one log, one
 * square root and two hashes). */
inline CLP_F CLP_FN(sensor_channel)(const CLP_F s, const uint ch, const CLP_U i, const float e_sat,
                                    const float full_well, const float read_noise, const float black,
                                    const float white, const uint seed, const uint frame) {
    const CLP_F mean = fmin(fmax(s, 0.0f) * e_sat, 2.0f * full_well);
    const CLP_U h3 = CLP_FN(rnd_hash4)(seed, frame, i, (CLP_U)(4u * ch + 3u));
    CLP_F g_shot;
    const CLP_F g_read = CLP_FN(rnd_normal_pair)(h3, CLP_FN(rnd_mix)(h3 ^ 0x5bd1e995u), &g_shot);
    const CLP_F e = fmin(CLP_FN(rnd_poisson)(mean, g_shot, seed, frame, i, 4u * ch), full_well) + read_noise * g_read;
    const CLP_F dn = clamp(rint(black + e * ((white - black) / e_sat)), 0.0f, white);
    return (dn - black) / (white - black);
}

inline void sensor_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, const float e_sat,
                         const float full_well, const float read_noise, const float black,
                         const float white, const uint seed, const uint frame) {
    const CLP_U i = CLP_INDEX(p);
    *r = CLP_FN(sensor_channel)(*r, 0u, i, e_sat, full_well, read_noise, black, white, seed, frame);
    *g = CLP_FN(sensor_channel)(*g, 1u, i, e_sat, full_well, read_noise, black, white, seed, frame);
    *b = CLP_FN(sensor_channel)(*b, 2u, i, e_sat, full_well, read_noise, black, white, seed, frame);
}
