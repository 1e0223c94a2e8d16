/* vignetting: multiply by the relative illumination RI at the pixel.
 *
 * ri is a plane of W x H factors built once per curve, principal point and size on the device
 * (kernels/vignetting_plane.cl; clpost/stages/vignetting.py, Vignetting.values: RI(r) at the pixel's image height r in mm
 * from the principal point; cos^4 theta of the thin lens, a lens's traced curve or a
 * manufacturer table). One contiguous load per pixel: PoCL does not vectorise data-dependent
 * loads, so a per-pixel LUT lookup here would cost more than the rest of the stage
 * (docs/measurements.md#kernel-forms-on-pocl).
 * Width-generic (clpost/codegen.py): CLP_W pixels of a row per call.
 */
inline void vignetting_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, __global const float *ri) {
    const CLP_F v = CLP_PLANE(ri, p);
    *r *= v;
    *g *= v;
    *b *= v;
}
