/* coma: third-order coma as a gather with the comet PSF of the pixel's field height.
 * clpost/stages/coma.py documents the formulas; its reference() is the oracle.
 *
 * Vectorisation: work-groups are tiles of COMA_TILE_W × COMA_TILE_H pixels (over lists of
 * tiles), each work-item computes 16 consecutive pixels of a tile row as explicit float16 vectors
 * (PoCL's own vectoriser across work-items needs fully unrolled, carefully written scalar code;
 * explicit vectors are as fast or faster and build in a second). Each tap reads a 3 × 3 window at
 * an integer offset b_k that is the same for the whole tile (the tile centre's landing point,
 * rounded), and interpolates inside it with tent weights at the pixel's *own* landing point:
 * exactly the bilinear tap of the per-pixel comet while that point lies within 1 px of b_k (the
 * comet changes by < 0.5 px across a tile for the lenses and coefficients in the tests and
 * benchmarks: Coma.shape_error_px), clamped to the window beyond (the reference does the same).
 * Tiles where the comet changes by at most Coma.UNIFORM_PX take the tile centre's comet, whose taps
 * collapse into a per-tile stencil of integer offsets (coma_s<S>, below).
 *
 * Buffers: colour planar (c*n + i); padded = 3 planes of pw × ph, pw = tiles_x * COMA_TILE_W +
 * 2 COMA_PAD (ph likewise), edge values repeated, so no tap clamps and the rounded-up work-items
 * read inside the buffer; shape = 4 planes of (tiles_y * COMA_TILE_H) × (tiles_x * COMA_TILE_W),
 * per pixel C e_r (x, y) in px, C' = dC/dr and C/r (written by coma_shape from the LUT, once per camera and frame size); lut = 2 planes of COMA_LUT_SIZE values over image height [0, r_max]:
 * C (mm) and dC/dr; tiles = per tile (row-major) the tile centre's -C e_s, -C e_r (px; from the
 * host, float64 exact C); coma_taps = COMA_TAPS landing offsets (sagittal, radial) in units of C
 * of a Vogel spiral over the pupil, a program-scope __constant table that Coma prepends to this
 * source.
 * Defines: COMA_TAPS, COMA_PAD, COMA_LUT_SIZE, COMA_TILE_W, COMA_TILE_H, COMA_WHOLE_TILES (the
 * frame is a whole number of tiles, so every work-item stores without a branch).
 */
#if COMA_TILE_W % 16
#error "the gathers read rows of a tile as float16: COMA_TILE_W must be a multiple of 16"
#endif
#define COMA_MAX_C ((float)(COMA_PAD - 1) / 3.0f)

/* the padded copy of the colour planes (edge values repeated). One work-item = 16 consecutive
 * pixels of a padded row (pw is a multiple of 16): whole vectors where the row's 16 source
 * pixels lie inside the frame, per pixel with a clamp only in the vectors that touch a side
 * (a scalar clamp on every pixel ran at half the memory bandwidth) */
__kernel void coma_pad(__global const float *restrict src, __global float *restrict padded,
                       const int width, const int height, const int pw, const int ph,
                       const int skip_x0, const int skip_x1, const int skip_y0, const int skip_y1)
{
    const int x0 = 16 * (int)get_global_id(0), y = get_global_id(1);
    if (x0 >= pw || y >= ph) return;
    /* [skip_x0, skip_x1) x [skip_y0, skip_y1) (padded coordinates; empty when the window kernel
     * runs): no tile reads the padded copy there (the inner tiles read the source) */
    if (x0 >= skip_x0 && x0 + 16 <= skip_x1 && y >= skip_y0 && y < skip_y1) return;
    const int sy = clamp(y - COMA_PAD, 0, height - 1);
    const size_t n = (size_t)width * height, pn = (size_t)pw * ph;
    __global const float *s = src + (size_t)sy * width;
    __global float *d = padded + (size_t)y * pw + x0;
    const int sx0 = x0 - COMA_PAD;
    if (sx0 >= 0 && sx0 + 16 <= width) {
        vstore16(vload16(0, s + sx0), 0, d);
        vstore16(vload16(0, s + n + sx0), 0, d + pn);
        vstore16(vload16(0, s + 2 * n + sx0), 0, d + 2 * pn);
    } else {
        for (int e = 0; e < 16; ++e) {
            const int sx = clamp(sx0 + e, 0, width - 1);
            d[e] = s[sx];
            d[pn + e] = s[n + sx];
            d[2 * pn + e] = s[2 * n + sx];
        }
    }
}

/* the comet of output pixel (x, y) of the rounded-up frame (ow x oh), from the LUT; it depends
 * on the camera and the frame size only, so Coma runs this once per camera and size */
__kernel void coma_shape(__global float *restrict shape, __global const float *restrict lut,
                         const int ow, const int oh, const float cx, const float cy,
                         const float pitch_mm, const float lut_scale)
{
    const int ox = get_global_id(0), oy = get_global_id(1);
    if (ox >= ow || oy >= oh) return;
    const float dx = (float)ox - cx, dy = (float)oy - cy;
    const float r = sqrt(dx * dx + dy * dy);
    const float ex = r > 0.0f ? dx / r : 1.0f, ey = r > 0.0f ? dy / r : 0.0f;
    const float t = fmin(r * pitch_mm * lut_scale, (float)(COMA_LUT_SIZE - 1));
    const int k0 = min((int)t, COMA_LUT_SIZE - 2);
    const float craw = mix(lut[k0], lut[k0 + 1], t - (float)k0) / pitch_mm;
    const float c = clamp(craw, -COMA_MAX_C, COMA_MAX_C);
    /* C' = dC/dr (0 where the comet is capped) and C/r (-> C'(0) on the axis): the Jacobian of
     * each tap's map, so a point's light is conserved although the PSF changes with r */
    const float dc = fabs(craw) > COMA_MAX_C ? 0.0f
                   : mix(lut[COMA_LUT_SIZE + k0], lut[COMA_LUT_SIZE + k0 + 1], t - (float)k0);
    const size_t on = (size_t)ow * oh, o = (size_t)oy * ow + ox;
    shape[o] = c * ex;
    shape[on + o] = c * ey;
    shape[2 * on + o] = dc;
    shape[3 * on + o] = r > 0.0f ? c / r : dc;
}

#define COMA_ABS16(v) as_float16(as_uint16(v) & (uint16)0x7fffffffu)
#define COMA_CLAMP116(v) (0.5f * (COMA_ABS16((v) + 1.0f) - COMA_ABS16((v) - 1.0f)))

/* One work-item = 16 consecutive pixels of a tile row as explicit float16 vectors (a work-group
 * = a tile = COMA_TILE_W / 16 x COMA_TILE_H work-items; work-group g = tile list[g], the tiles
 * whose comet varies too much for the stencils, coma_s<S>). Each tap reads a 3 x 3 window at the tile-uniform
 * offset b and weights it with tent weights at each pixel's own landing point. */
__kernel void coma(__global const float *restrict padded, __global const float *restrict shape,
          __global float *restrict dst, __global const float *restrict tiles,
          __global const int *restrict list, const int tiles_x, const int tiles_y,
          const int width, const int height)
{
    const ClpTile t = clp_tile(list[get_group_id(0)], tiles_x, tiles_y, COMA_TILE_W, COMA_TILE_H, COMA_PAD, 16);
    const int tile_id = t.id, x = t.x, y = t.y, pw = t.pw;
    const int ow = tiles_x * COMA_TILE_W, oh = tiles_y * COMA_TILE_H;
    const size_t pn = t.pn, on = (size_t)ow * oh;
    const int o = y * ow + x;
    const float16 cex = vload16(0, shape + o), cey = vload16(0, shape + on + o);
    const float16 dc = vload16(0, shape + 2 * on + o), q = vload16(0, shape + 3 * on + o);
    /* the tile centre's comet (group-uniform): each tap's window offset */
    __global const float *tile = tiles + 4 * tile_id;
    const float tsxx = tile[0], tsxy = tile[1], trxx = tile[2], trxy = tile[3];
    const int base = t.jc;
    float16 ar = 0.0f, ag = 0.0f, ab = 0.0f;
    /* unrolled by 4: as fast as fully unrolled with explicit vectors, and builds in a second */
#pragma unroll 4
    for (int k = 0; k < COMA_TAPS; ++k) {
        const float ux = coma_taps[2 * k], uy = coma_taps[2 * k + 1];
        /* window centre b: round(tile offset), by truncating a positive number (|offset| < PAD) */
        const int bx = (int)(tsxx * ux + trxx * uy + ((float)COMA_PAD + 0.5f)) - COMA_PAD;
        const int by = (int)(tsxy * ux + trxy * uy + ((float)COMA_PAD + 0.5f)) - COMA_PAD;
        /* the pixels' own landing points: -C (ux e_s + uy e_r), e_s = (-ey, ex), e_r = (ex, ey),
         * clamped to the window */
        const float16 fx = COMA_CLAMP116(cey * ux - cex * uy - (float)bx);
        const float16 fy = COMA_CLAMP116(-(cex * ux + cey * uy) - (float)by);
        /* tent weights of the window samples at -1, 0, 1 */
        const float16 hm = 0.5f * (COMA_ABS16(fx) - fx), hp = 0.5f * (COMA_ABS16(fx) + fx);
        const float16 h0 = 1.0f - COMA_ABS16(fx);
        float16 jac = (1.0f - dc * uy) * (1.0f - q * uy) + q * dc * (ux * ux);
        /* max(jac, 0), scaled by 1/COMA_TAPS here rather than the sums at the end: summed
         * unscaled, COMA_TAPS colours near FLT_MAX overflowed to inf (COMA_TAPS is a power of two,
         * so the scaling is exact and the result the same bits) */
        jac = (0.5f / (float)COMA_TAPS) * (jac + COMA_ABS16(jac));
        const float16 wm = jac * (0.5f * (COMA_ABS16(fy) - fy)), w0 = jac * (1.0f - COMA_ABS16(fy));
        const float16 wp = jac * (0.5f * (COMA_ABS16(fy) + fy));
        __global const float *p = padded + base + by * pw + bx;
#define COMA_ROW16(p) (hm * vload16(0, (p) - 1) + h0 * vload16(0, (p)) + hp * vload16(0, (p) + 1))
#define COMA_WIN16(p) (wm * COMA_ROW16((p) - pw) + w0 * COMA_ROW16(p) + wp * COMA_ROW16((p) + pw))
        ar += COMA_WIN16(p);
        p += pn;
        ag += COMA_WIN16(p);
        p += pn;
        ab += COMA_WIN16(p);
#undef COMA_WIN16
#undef COMA_ROW16
    }
    const size_t n = (size_t)width * height;
    const size_t i = (size_t)y * width + x;
#if COMA_WHOLE_TILES
    vstore16(ar, 0, dst + i);
    vstore16(ag, 0, dst + n + i);
    vstore16(ab, 0, dst + 2 * n + i);
#else
    /* frames that are not whole tiles: the rounded-up pixels are computed but not stored */
    if (y >= height) return;
    float rr[16], gg[16], bb[16];
    vstore16(ar, 0, rr);
    vstore16(ag, 0, gg);
    vstore16(ab, 0, bb);
    for (int e = 0; e < 16 && x + e < width; ++e) {
        dst[i + e] = rr[e];
        dst[n + i + e] = gg[e];
        dst[2 * n + i + e] = bb[e];
    }
#endif
}

/* 16 pixels of a tile row into the planar output (kernels/common.cl; partial tiles: per pixel) */
#define coma_store16(dst, r, g, b, x, y, width, height) \
    clp_store16_planar(dst, r, g, b, x, y, width, height, COMA_WHOLE_TILES)

/* The uniform tiles (Coma.tile_uniform): every pixel of the tile takes the tile centre's comet,
 * so the N bilinear taps land on the same integer offsets for all its pixels and collapse into a
 * stencil (Coma.uniform_stencils, built once per camera and frame size on the host): per distinct
 * offset s the sums over the taps of their bilinear weights c times (1, t_r, t_r^2 + t_s^2) / N.
 * The pixel's own Jacobian J_k = 1 - (C' + C/r) t_r + C' C/r (t_r^2 + t_s^2) is linear in
 * those three, so sum_k J_k c_k = W0 - a W1 + b W2 with a = C' + C/r, b = C' C/r per pixel:
 * the same sum as tap by tap (the clamp of J at 0 never acts on these tiles), but 3 reads per
 * offset instead of 12 per tap, and the count of offsets follows the comet's area (4 for a
 * comet that stays inside one pixel cell) rather than N.
 * One work-item = 16 consecutive pixels of a tile row (float16); work-group g = tile list[g],
 * its stencil at offs/wts + g * S (offsets (dx, dy); weights W0, W1, W2, 0, the unused entries
 * of a shorter stencil zero). Tiles whose reads (|d| <= COMA_PAD) stay inside the frame
 * (inner[g]) read the source planes directly, so coma_pad only fills the ring the others read.
 * S is a compile-time constant per kernel (coma_s<S>): a run-time count makes such loops slower
 * (docs/measurements.md#kernel-forms-on-pocl). */
inline void coma_stencil(__global const float *restrict padded, __global const float *restrict src,
                         __global const float *restrict shape, __global float *restrict dst,
                         __global const int *restrict list, __global const int *restrict inner,
                         __global const int2 *restrict offs, __global const float4 *restrict wts,
                         const int tiles_x, const int tiles_y, const int width, const int height, const int S,
                         const int jac_px)
{
    const int g = (int)get_group_id(0);
    const ClpTile t = clp_tile(list[g], tiles_x, tiles_y, COMA_TILE_W, COMA_TILE_H, COMA_PAD, 16);
    const int x = t.x, y = t.y, pw = t.pw;
    const int ow = tiles_x * COMA_TILE_W, oh = tiles_y * COMA_TILE_H;
    const size_t pn = t.pn, on = (size_t)ow * oh;
    const int o = y * ow + x;
    /* jac_px (compile-time after inlining): each pixel's own Jacobian from its C' and C/r;
     * otherwise the tile's one Jacobian is folded into W0 (coma_c<S>: no shape reads) */
    float16 a = 0.0f, b = 0.0f;
    if (jac_px) {
        const float16 dc = vload16(0, shape + 2 * on + o), q = vload16(0, shape + 3 * on + o);
        a = dc + q;
        b = dc * q;
    }
    /* group-uniform choice of the planes read: the source (inner tiles) or the padded copy */
    const int in = inner[g];
    __global const float *base = in ? src + (size_t)y * width + x : padded + t.jc;
    const int pitch = in ? width : pw;
    const size_t plane = in ? (size_t)width * height : pn;
    __global const int2 *so = offs + g * S;
    __global const float4 *sw = wts + g * S;
    float16 ar = 0.0f, ag = 0.0f, ab = 0.0f;
    /* unrolled by 4 by hand (a constant 4-trip inner loop; every S is a multiple of 4) */
    for (int s4 = 0; s4 < S; s4 += 4)
#pragma unroll
    for (int s = s4; s < s4 + 4; ++s) {
        const float4 wv = sw[s];
        const int2 d = so[s];
        __global const float *p = base + d.y * pitch + d.x;
        if (jac_px) {
            const float16 wgt = wv.x - a * wv.y + b * wv.z;
            ar += wgt * vload16(0, p);
            ag += wgt * vload16(0, p + plane);
            ab += wgt * vload16(0, p + 2 * plane);
        } else {
            ar += wv.x * vload16(0, p);
            ag += wv.x * vload16(0, p + plane);
            ab += wv.x * vload16(0, p + 2 * plane);
        }
    }
    coma_store16(dst, ar, ag, ab, x, y, width, height);
}

#define COMA_STENCIL_ARGS __global const float *restrict padded, __global const float *restrict src, \
    __global const float *restrict shape, __global float *restrict dst, __global const int *restrict list, \
    __global const int *restrict inner, __global const int2 *restrict offs, __global const float4 *restrict wts, \
    const int tiles_x, const int tiles_y, const int width, const int height
#define COMA_STENCIL_CALL(S, J) \
    coma_stencil(padded, src, shape, dst, list, inner, offs, wts, tiles_x, tiles_y, width, height, S, J)
/* one kernel per stencil size class (Coma.STENCIL_SIZES; N taps of 4 bilinear corners reach at
 * most 4 N <= 256 offsets): coma_s<S> with each pixel's Jacobian, coma_c<S> with the tile's one
 * (Coma.tile_jacobian) */
/* coma_s<S> and coma_c<S> for every S of Coma.STENCIL_SIZES are generated after this file
 * (clpost/stages/coma.py, program_source) */
