/* raw: normalised signal -> one colour-filter-array photosite per pixel with the calibrated noise
 * model (photon shot noise, PRNU, full well, DSNU, read, row and column noise, black level,
 * quantisation), renormalised so 1.0 = the white level; the value goes to all three channels.
 * Formulas and sources: clpost/stages/raw.py (its reference() is the numpy oracle).
 * Random numbers: kernels/random.cl, counters listed in clpost/stages/raw.py.
 * Width-generic (clpost/codegen.py): CLP_W pixels of a row per call; the filter's channel varies
 * per lane (x parity), so all four channel responses (R, G, B, clear: 12 uniform coefficients) are
 * computed and the photosite's is selected per lane.
 * Defines: RAW_CFA_00, RAW_CFA_01, RAW_CFA_10, RAW_CFA_11 — the channel (0 R, 1 G, 2 B, 3 C) at
 * (y mod 2, x mod 2).
 */
#if !defined(RAW_CFA_00) || !defined(RAW_CFA_01) || !defined(RAW_CFA_10) || !defined(RAW_CFA_11)
#error "raw.cl needs RAW_CFA_00, RAW_CFA_01, RAW_CFA_10, RAW_CFA_11 (clpost/stages/raw.py defines())"
#endif
#define RAW_FIXED_FRAME 0xffffffffu

inline CLP_F CLP_FN(raw_normal)(const uint seed, const uint frame, const CLP_U a, const uint b) {
    return CLP_FN(rnd_normal)(CLP_FN(rnd_hash4)(seed, frame, a, (CLP_U)(b)),
                              CLP_FN(rnd_hash4)(seed, frame, a, (CLP_U)(b + 1u)));
}

inline void raw_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, const float e_sat,
                      const float full_well, const float gain, const float read_noise,
                      const float row_noise, const float col_noise, const float dsnu, const float prnu,
                      const float black, const float white, __global const float *matrix,
                      const uint phase_x, const uint phase_y, const uint seed, const uint frame) {
    const CLP_U i = CLP_INDEX(p);
    const CLP_U x = CLP_TO_U(CLP_X(p)), y = CLP_TO_U(CLP_Y(p));
    /* the pattern starts at the display window's top-left: phase = its offset's parity */
    const CLP_I xo = CLP_TO_I((x + phase_x) & 1u) != 0, yo = CLP_TO_I((y + phase_y) & 1u) != 0;
    const CLP_I ch = yo ? (xo ? (CLP_I)(RAW_CFA_11) : (CLP_I)(RAW_CFA_10))
                        : (xo ? (CLP_I)(RAW_CFA_01) : (CLP_I)(RAW_CFA_00));
    const CLP_F rr = *r, gg = *g, bb = *b;
    const CLP_F s_r = matrix[0] * rr + matrix[1] * gg + matrix[2] * bb;
    const CLP_F s_g = matrix[3] * rr + matrix[4] * gg + matrix[5] * bb;
    const CLP_F s_b = matrix[6] * rr + matrix[7] * gg + matrix[8] * bb;
    const CLP_F s_c = matrix[9] * rr + matrix[10] * gg + matrix[11] * bb;
    const CLP_F s = ch == 0 ? s_r : (ch == 1 ? s_g : (ch == 2 ? s_b : s_c));

    const CLP_F n_prnu = CLP_FN(raw_normal)(seed, RAW_FIXED_FRAME, i, 14u);
    CLP_F mean = fmax(fmax(s, 0.0f) * e_sat * (1.0f + prnu * n_prnu), 0.0f);
    mean = fmin(mean, 2.0f * full_well);
    const CLP_F e = CLP_FN(rnd_poisson)(mean, CLP_FN(raw_normal)(seed, frame, i, 1u), seed, frame, i, 0u);
    const CLP_U h3 = CLP_FN(rnd_hash4)(seed, frame, i, (CLP_U)(3u));
    const CLP_F dn = black + gain * fmin(e, full_well)
                     + dsnu * CLP_FN(raw_normal)(seed, RAW_FIXED_FRAME, i, 12u)
                     + read_noise * CLP_FN(rnd_normal)(h3, CLP_FN(rnd_mix)(h3 ^ 0x5bd1e995u))
                     + row_noise * CLP_FN(raw_normal)(seed, frame, y, 8u)
                     + col_noise * CLP_FN(raw_normal)(seed, frame, x, 10u);
    const CLP_F out = (clamp(rint(dn), 0.0f, white) - black) / (white - black);
    *r = out; *g = out; *b = out;
}
