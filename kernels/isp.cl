/* isp: raw mosaic (planar channel 0, the raw stage's output) -> display-encoded sRGB: Malvar-He-Cutler
 * demosaic, white balance, colour matrix, tone curve, sRGB encoding. Formulas, filter weights and
 * sources: clpost/stages/isp.py (its reference() is the numpy oracle; colour-demosaicing's
 * demosaicing_CFA_Bayer_Malvar2004 the demosaic's).
 * One work-item per pixel: 21 mosaic reads (the 5x5 cross-and-diamond the filters use), borders
 * mirrored about the edge photosite (keeps the pattern's parity); frames are at least 3x3.
 * Buffers: src planar (only channel 0 read), dst planar RGB; table: WB gains (3), colour matrix
 * rows (9). Defines: ISP_CFA_00 .. ISP_CFA_11, the Bayer channel (0 R, 1 G, 2 B) at (y mod 2, x mod 2).
 */
#if !defined(ISP_CFA_00) || !defined(ISP_CFA_01) || !defined(ISP_CFA_10) || !defined(ISP_CFA_11)
#error "isp.cl needs ISP_CFA_00 .. ISP_CFA_11 (clpost/stages/isp.py defines())"
#endif

/* Mirror about the edge photosite (i in [-2, n + 1], n >= 3). The reflection below 0 goes through
 * float fabs: the integer form compiles to llvm.abs, which Oclgrind 21.10 cannot run. */
inline int isp_mirror(int i, const int n) {
    i = (int)fabs((float)i);
    return i >= n ? 2 * (n - 1) - i : i;
}

inline float isp_at(__global const float *src, const int x, const int y, const int dx, const int dy,
                    const int w, const int h) {
    return src[isp_mirror(y + dy, h) * w + isp_mirror(x + dx, w)];
}

inline int isp_channel(const int x, const int y) {
    const int xo = x & 1, yo = y & 1;
    return yo ? (xo ? ISP_CFA_11 : ISP_CFA_10) : (xo ? ISP_CFA_01 : ISP_CFA_00);
}

inline float isp_encode(const float v, const float tone_white) {
    float y = fmax(v, 0.0f);
    if (tone_white > 0.0f) y = y * (1.0f + y / (tone_white * tone_white)) / (1.0f + y);
    y = clamp(y, 0.0f, 1.0f);
    /* y^(1/2.4) through kernels/fastmath.cl: PoCL does not vectorise pow */
    return y <= 0.0031308f ? 12.92f * y : 1.055f * clp_exp2(clp_log2(fmax(y, 0.0031308f)) * (1.0f / 2.4f)) - 0.055f;
}

__kernel void isp(__global const float *restrict src, __global float *restrict dst, const int width,
                  const int height, const int phase_x, const int phase_y, __constant float *table,
                  const float tone_white) {
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
#define M(dx, dy) isp_at(src, x, y, dx, dy, width, height)
    const float c = M(0, 0);
    const float axial_h = M(-1, 0) + M(1, 0), axial_v = M(0, -1) + M(0, 1);
    const float far_h = M(-2, 0) + M(2, 0), far_v = M(0, -2) + M(0, 2);
    const float diag = M(-1, -1) + M(1, -1) + M(-1, 1) + M(1, 1);
#undef M
    /* the four Malvar-He-Cutler filters (clpost/stages/isp.py MHC_FILTERS), /8 */
    const float g_at_rb = (4.0f * c + 2.0f * (axial_h + axial_v) - (far_h + far_v)) * 0.125f;
    const float rb_at_g_row = (5.0f * c + 4.0f * axial_h - far_h - diag + 0.5f * far_v) * 0.125f;
    const float rb_at_g_col = (5.0f * c + 4.0f * axial_v - far_v - diag + 0.5f * far_h) * 0.125f;
    const float rb_at_br = (6.0f * c + 2.0f * diag - 1.5f * (far_h + far_v)) * 0.125f;

    /* the pattern starts at the display window's top-left: phase = its offset's parity */
    const int site = isp_channel(x + phase_x, y + phase_y);
    const int red_row = isp_channel(0, y + phase_y) == 0 || isp_channel(1, y + phase_y) == 0;
    float r, g, b;
    if (site == 0) { r = c; g = g_at_rb; b = rb_at_br; }
    else if (site == 2) { r = rb_at_br; g = g_at_rb; b = c; }
    else if (red_row) { r = rb_at_g_row; g = c; b = rb_at_g_col; }
    else { r = rb_at_g_col; g = c; b = rb_at_g_row; }
    r *= table[0]; g *= table[1]; b *= table[2];
    const int n = width * height, i = y * width + x;
    dst[i] = isp_encode(table[3] * r + table[4] * g + table[5] * b, tone_white);
    dst[n + i] = isp_encode(table[6] * r + table[7] * g + table[8] * b, tone_white);
    dst[2 * n + i] = isp_encode(table[9] * r + table[10] * g + table[11] * b, tone_white);
}
