/* vignetting: multiply by the relative illumination RI(r) at the pixel's image height r (mm).
 *
 * r is measured on the sensor from the principal point: pitch = sensor_w_mm / width (the image
 * spans the sensor width), principal point = image centre + (off_x_mm, off_y_mm). RI is a table of
 * VIGNETTING_LUT_SIZE samples over r in [0, r_max_mm], built once per camera on the host
 * (cos^4 theta of the thin lens, a lens's curve or a manufacturer table: clpost/stages/vignetting.py),
 * interpolated linearly; beyond r_max_mm the last value holds.
 */
#ifndef VIGNETTING_LUT_SIZE
#define VIGNETTING_LUT_SIZE 1024
#endif

inline float3 vignetting_apply(const float3 c, const PixelCtx p, const float sensor_w_mm,
                               const float off_x_mm, const float off_y_mm, const float r_max_mm,
                               __global const float *lut) {
    const float pitch = sensor_w_mm / (float)p.width;
    const float dx = ((float)p.x - 0.5f * (float)(p.width - 1)) * pitch - off_x_mm;
    const float dy = ((float)p.y - 0.5f * (float)(p.height - 1)) * pitch - off_y_mm;
    const float r2 = dx * dx + dy * dy;
    /* no sqrt/fmin/min library calls: with them vignetting+exposure took 12.2 ms at 1080p on
     * PoCL, 3.7 ms with native_sqrt and selects (same run); the index needs no correct rounding */
    const float rr = native_sqrt(r2);
    float t = rr * ((float)(VIGNETTING_LUT_SIZE - 1) / r_max_mm);
    t = t < (float)(VIGNETTING_LUT_SIZE - 1) ? t : (float)(VIGNETTING_LUT_SIZE - 1);
    int k = (int)t;
    k = k < VIGNETTING_LUT_SIZE - 2 ? k : VIGNETTING_LUT_SIZE - 2;
    const float f = t - (float)k;
    const float ri = lut[k] * (1.0f - f) + lut[k + 1] * f;
    /* per channel: float3 arithmetic stops PoCL's vectorisation of the fused kernel */
    return (float3)(c.x * ri, c.y * ri, c.z * ri);
}

/* the same for 16 pixels of a row, bit for bit (same operations per lane) */
inline void vignetting_apply16(float16 *r, float16 *g, float16 *b, const PixelCtx16 p,
                               const float sensor_w_mm, const float off_x_mm, const float off_y_mm,
                               const float r_max_mm, __global const float *lut) {
    const float pitch = sensor_w_mm / (float)p.width;
    const float16 dx = ((float)p.x0 + CLP_LANES16 - 0.5f * (float)(p.width - 1)) * pitch - off_x_mm;
    const float dy = ((float)p.y - 0.5f * (float)(p.height - 1)) * pitch - off_y_mm;
    const float16 t = fmin(native_sqrt(dx * dx + dy * dy) * ((float)(VIGNETTING_LUT_SIZE - 1) / r_max_mm),
                           (float)(VIGNETTING_LUT_SIZE - 1));
    const int16 k = min(convert_int16(t), VIGNETTING_LUT_SIZE - 2);
    const float16 f = t - convert_float16(k);
    const float16 ri = CLP_GATHER16(lut, k) * (1.0f - f) + CLP_GATHER16(lut, k + 1) * f;
    *r *= ri;
    *g *= ri;
    *b *= ri;
}
