/* vignetting: multiply by the relative illumination RI at the pixel.
 *
 * ri is a plane of W x H factors built once per curve, principal point and size on the host
 * (clpost/stages/vignetting.py, Vignetting.ri_plane: RI(r) at the pixel's image height r in mm
 * from the principal point; cos^4 theta of the thin lens, a lens's traced curve or a
 * manufacturer table). One contiguous load per pixel: a per-pixel LUT lookup here cost 2 of the
 * 3 ms of vignetting+exposure at 1080p (PoCL does not vectorise data-dependent loads).
 */
inline float3 vignetting_apply(const float3 c, const PixelCtx p, __global const float *ri) {
    const float v = ri[p.i];
    return (float3)(c.x * v, c.y * v, c.z * v);
}

inline void vignetting_apply16(float16 *r, float16 *g, float16 *b, const PixelCtx16 p,
                               __global const float *ri) {
    const float16 v = vload16(0, ri + p.i0);
    *r *= v;
    *g *= v;
    *b *= v;
}
