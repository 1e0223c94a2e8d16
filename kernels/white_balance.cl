/* white_balance: c' = M c with the 3x3 CAT02 white-balance matrix, computed once per camera on the
 * host in float64 (clpost/stages/white_balance.py documents the formula and its sources).
 * Width-generic (clpost/codegen.py): CLP_W pixels of a row per call.
 */
inline void white_balance_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p,
                                const float m00, const float m01, const float m02,
                                const float m10, const float m11, const float m12,
                                const float m20, const float m21, const float m22) {
    const CLP_F r0 = *r, g0 = *g, b0 = *b;
    *r = m00 * r0 + m01 * g0 + m02 * b0;
    *g = m10 * r0 + m11 * g0 + m12 * b0;
    *b = m20 * r0 + m21 * g0 + m22 * b0;
}
