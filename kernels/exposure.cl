/* exposure: scene luminance -> normalised sensor signal (1.0 = saturation).
 * gain = luminance_scale * pi*T / (4 N_w^2) * t * S / 78, computed once per frame on the host
 * in float64 (clpost/stages/exposure.py documents the formula and its sources).
 * Width-generic (clpost/codegen.py): CLP_W pixels of a row per call.
 */
inline void exposure_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, const float gain) {
    *r *= gain;
    *g *= gain;
    *b *= gain;
}
