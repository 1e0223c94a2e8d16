/* exposure: scene luminance -> normalised sensor signal (1.0 = saturation).
 * gain = luminance_scale * pi*T / (4 N_w^2) * t * S / 78, computed once per frame on the host
 * in float64 (clpost/stages/exposure.py documents the formula and its sources).
 */
inline float3 exposure_apply(const float3 c, const PixelCtx p, const float gain) {
    /* per channel: float3 arithmetic stops PoCL's vectorisation of the fused kernel */
    return (float3)(c.x * gain, c.y * gain, c.z * gain);
}

inline void exposure_apply16(float16 *r, float16 *g, float16 *b, const PixelCtx16 p, const float gain) {
    *r *= gain;
    *g *= gain;
    *b *= gain;
}
