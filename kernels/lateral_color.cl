/* lateral_color: per-channel radial resampling (chromatic difference of magnification).
 * clpost/stages/lateral_color.py documents the formulas and the tile model; its reference() is
 * the oracle.
 *
 * Two kernels over lists of 16 x 8 tiles (work-group = tile, group g -> tile list[g]):
 *
 * lateral_color_tiles - the tiles where, per channel, the source displacement is affine across
 *   the tile (to LATERAL_COLOR's tolerance) and its bilinear cell is the same integer offset
 *   (bx, by) for every pixel: addresses are affine in the work-item id and the body has no
 *   library call, select or branch, so PoCL vectorises the implicit work-item loop
 *   (docs/measurements.md#gather-layouts-on-pocl). The record of a tile (LATERAL_COLOR_REC floats,
 *   from the host):
 *   [0] tile origin index y0*width + x0 (int bits), then per channel c (10 floats at 1 + 10c):
 *   the cell offset by*width + bx (int bits), the bilinear fraction fx = a0 + ax lx + ay ly (3),
 *   fy likewise (3), the flux Jacobian likewise (3), with (lx, ly) the pixel within the tile.
 * lateral_color - the per-pixel map (LUT over image height, clamped at the border) for the other
 *   tiles (borders, partial tiles, strong lateral colour, cells that straddle an integer).
 *
 * Buffers: colour planar (c*n + i); lut = 6 planes of LATERAL_COLOR_LUT_SIZE values over the
 * output image height: r/rho for R, G, B, then the flux Jacobian for R, G, B.
 * Defines: LATERAL_COLOR_LUT_SIZE, LATERAL_COLOR_TILE_W, LATERAL_COLOR_TILE_H, LATERAL_COLOR_REC.
 */
__kernel void lateral_color_tiles(__global const float *restrict src, __global float *restrict dst,
                                  __global const float *restrict rec, const int width, const int height)
{
    __global const float *t = rec + (size_t)get_group_id(0) * LATERAL_COLOR_REC;
    const int lx = (int)get_local_id(0), ly = (int)get_local_id(1);
    const float fl = (float)lx, fm = (float)ly;
    const size_t n = (size_t)width * height;
    const int i = as_int(t[0]) + ly * width + lx;
    /* unrolled: PoCL vectorises the implicit work-item loop only when it is the innermost loop */
#pragma unroll
    for (int c = 0; c < 3; ++c) {
        __global const float *r = t + 1 + 10 * c;
        const float fx = r[1] + r[2] * fl + r[3] * fm;
        const float fy = r[4] + r[5] * fl + r[6] * fm;
        const float jac = r[7] + r[8] * fl + r[9] * fm;
        __global const float *p = src + c * n + i + as_int(r[0]);
        const float top = p[0] + fx * (p[1] - p[0]);
        const float bot = p[width] + fx * (p[width + 1] - p[width]);
        dst[c * n + i] = (top + fy * (bot - top)) * jac;
    }
}

__kernel void lateral_color(__global const float *restrict src, __global float *restrict dst,
                            __global const float *restrict lut, __global const int *restrict tiles,
                            const int width, const int height,
                            const float cx, const float cy, const float lut_per_px)
{
    const int tile = tiles[get_group_id(0)];
    const int tiles_x = (width + LATERAL_COLOR_TILE_W - 1) / LATERAL_COLOR_TILE_W;
    const int x = (tile % tiles_x) * LATERAL_COLOR_TILE_W + (int)get_local_id(0);
    const int y = (tile / tiles_x) * LATERAL_COLOR_TILE_H + (int)get_local_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * height;
    const size_t i = (size_t)y * width + x;
    const float dx = (float)x - cx, dy = (float)y - cy;
    const float t = fmin(sqrt(dx * dx + dy * dy) * lut_per_px, (float)(LATERAL_COLOR_LUT_SIZE - 1));
    const int k0 = min((int)t, LATERAL_COLOR_LUT_SIZE - 2);
    const float ft = t - (float)k0;
    for (int c = 0; c < 3; ++c) {
        const float s = mix(lut[c * LATERAL_COLOR_LUT_SIZE + k0], lut[c * LATERAL_COLOR_LUT_SIZE + k0 + 1], ft);
        const float jac = mix(lut[(3 + c) * LATERAL_COLOR_LUT_SIZE + k0], lut[(3 + c) * LATERAL_COLOR_LUT_SIZE + k0 + 1], ft);
        const float px = clamp(cx + dx * s, 0.0f, (float)(width - 1));
        const float py = clamp(cy + dy * s, 0.0f, (float)(height - 1));
        const int x0 = (int)px, y0 = (int)py;
        const int x1 = min(x0 + 1, width - 1), y1 = min(y0 + 1, height - 1);
        const float fx = px - (float)x0, fy = py - (float)y0;
        __global const float *p = src + c * n;
        const float top = mix(p[y0 * width + x0], p[y0 * width + x1], fx);
        const float bot = mix(p[y1 * width + x0], p[y1 * width + x1], fx);
        dst[c * n + i] = mix(top, bot, fy) * jac;
    }
}
