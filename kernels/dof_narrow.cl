/* dof: the half-resolution path's narrow-source layer (narrow_sources, narrow_norm and
 * narrow_layer in clpost/stages/dof.py): small bright lights taken out of the working image and
 * spread at full resolution by dof_upsample (dof.cl, dof_narrow16).
 * Structural: DOF_SCALE, DOF_TILE, DOF_NARROW_CELL (cell edge, px), DOF_NARROW_MAX (sources per
 * cell), DOF_NARROW_RATIO, DOF_NARROW_CONTRAST, DOF_NARROW_EDGE (px), DOF_NARROW_MIN (px),
 * DOF_NARROW_SUM (px), DOF_NARROW_FOCUS (px), DOF_NARROW_FRONT_MAX, DOF_NARROW_SPREAD (px), DOF_NARROW_RAMP (px),
 * DOF_LUMA_R/G/B, DOF_TEXTURE.
 * Records: float8 (x, y, signed CoC px, e_R, e_G, e_B, 1 / the source's weight sum, kind) per
 * source and in-focus light, in scan order, DOF_NARROW_MAX per cell; `ncount` per cell (0 when the
 * cell had more than DOF_NARROW_MAX). Kind (DOF_NK_*): a source spread by the layer (narrow_sources'
 * `sources`), an in-focus light (|CoC| <= DOF_NARROW_FOCUS, at most DOF_NARROW_FRONT_MAX pixels of
 * the block's 5x5 working pixels nearer by DOF_FRONT_MARGIN) whose 3x3 share is added back where
 * the composite takes the half-resolution blur (|CoC| >= DOF_NARROW_SPREAD: `small`, small_layer),
 * or one that only leaves the working image.
 */
#define DOF_NK_SOURCE 0.0f
#define DOF_NK_SMALL 1.0f
#define DOF_NK_FOCUS 2.0f

/* luminance of 16 working pixels of level 0 from padded offset o */
#define DOF_NY16(o) (DOF_LUMA_R * vload16(0, lv + (o)) + DOF_LUMA_G * vload16(0, lv + pn + (o)) \
                     + DOF_LUMA_B * vload16(0, lv + 2 * pn + (o)))

/* Candidate blocks: per working pixel, the index (0..7) of the third brightest of its 8 working
 * neighbours at distance 2 (NARROW_RING: (-2,-2), (-2,0), (-2,2), (0,-2), (0,2), (2,-2), (2,0), (2,2)) when its luminance is above DOF_NARROW_RATIO x that neighbour's, else -1; -1 too
 * within 2 of the working image's edge; `gflag` per group of 16 (ceil(ww / 16) a row): whether
 * one of them is a candidate (`flag` is written only for the groups that have one, where
 * dof_narrow_list reads it). 16 working pixels of a row per work-item (the padding covers the
 * ring's reads); launched over (ceil(ww / 16), hw). */
__kernel void dof_narrow_flag(__global const float *restrict lv, __global int *restrict flag,
                              __global int *restrict gflag, const int ww, const int hw, const int pad)
{
    const int x = 16 * get_global_id(0), y = get_global_id(1);
    if (x >= ww || y >= hw) return;
    const int pw = DOF_PW(ww, pad);
    const size_t pn = (size_t)pw * DOF_PW(hw, pad);
    const size_t o = (size_t)(y + pad) * pw + x + pad;
    const int ngx = (ww + 15) / 16;
    const float16 yp = DOF_NY16(o);
    const int16 xs = (int16)(x) + (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const int16 inside = (xs >= 2) & (xs <= ww - 3) & (int16)(y >= 2 && y <= hw - 3 ? -1 : 0);
    /* the third brightest of the 8 is at least the dimmest of any 3 of them: when three are each
     * >= yp / DOF_NARROW_RATIO for every lane, no lane is a candidate (most of an image) */
    const float16 lim = yp * (1.0f / DOF_NARROW_RATIO);
    /* first on green alone: Y >= DOF_LUMA_G G (every weight and colour >= 0) */
    const float16 ga = vload16(0, lv + pn + o - 2 * pw), gb = vload16(0, lv + pn + o - 2);
    const float16 gc = vload16(0, lv + pn + o + 2);
    const float16 glim = lim * (1.0f / DOF_LUMA_G);
    if (!any(inside & (ga < glim | gb < glim | gc < glim))) {
        gflag[(size_t)y * ngx + x / 16] = 0;
        return;
    }
    const float16 ya = DOF_NY16(o - 2 * pw), yb = DOF_NY16(o - 2), yc = DOF_NY16(o + 2);
    if (!any(inside & (ya < lim | yb < lim | yc < lim))) {
        gflag[(size_t)y * ngx + x / 16] = 0;  /* `flag` is read only where `gflag` is set */
        return;
    }
    /* the three brightest (m1 >= m2 >= m3, an earlier one ranks above an equal later one) and
     * the third's index */
    float16 m1 = DOF_NY16(o - 2 * pw - 2), m2 = (float16)(-INFINITY), m3 = m2;
    int16 k1 = (int16)(0), k2 = (int16)(-1), k3 = k2;
#define DOF_RING(i, off) { const float16 v = DOF_NY16(o + (off)); \
        const int16 g1 = v > m1, g2 = v > m2, g3 = v > m3; \
        m3 = select(m3, select(v, m2, g2), g3); k3 = select(k3, select((int16)(i), k2, g2), g3); \
        m2 = select(m2, select(v, m1, g1), g2); k2 = select(k2, select((int16)(i), k1, g1), g2); \
        m1 = select(m1, v, g1); k1 = select(k1, (int16)(i), g1); }
    DOF_RING(1, -2 * (long)pw)
    DOF_RING(2, -2 * (long)pw + 2)
    DOF_RING(3, -2)
    DOF_RING(4, 2)
    DOF_RING(5, 2 * (long)pw - 2)
    DOF_RING(6, 2 * (long)pw)
    DOF_RING(7, 2 * (long)pw + 2)
#undef DOF_RING
    const int16 out = select((int16)(-1), k3, inside & (yp > DOF_NARROW_RATIO * m3));
    const int anyc = any(out >= 0);
    gflag[(size_t)y * ngx + x / 16] = anyc;
    if (!anyc)
        return;
    if (x + 16 <= ww) {
        vstore16(out, 0, flag + (size_t)y * ww + x);
    } else {
        int t[16];
        vstore16(out, 0, t);
        for (int l = 0; l < ww - x; ++l)
            flag[(size_t)y * ww + x + l] = t[l];
    }
}
#undef DOF_NY16

/* narrow_weight in clpost/stages/dof.py, for a source of signed CoC rq at offset o = (dx, dy) = q - p
 * spread with radius r (a coverage ramp DOF_NARROW_RAMP_OF(rq) px wide): rho of the N-gon (corners on the unit circle) in the direction of o is
 * cos(pi/N) |o| / max_i(o . n_i) over its edge normals n_i (`normals`, the host's table at
 * phi0 + (i + 1/2) 2 pi / N, phi0 = -pi/2 - rotation; `kpoly` = cos(pi/N)), blended with the circle
 * by the roundness; the direction is p - q for a far source (o's sign flipped). The same angle as
 * the reference's atan2 form, without a transcendental per lane. For scalars and vectors (DOF_NW_T). */
#define DOF_NARROW_RAMP_OF(rq) (fmax(fabs(rq), 0.5f) < DOF_NARROW_SUM ? DOF_NARROW_RAMP : 1.0f)
#define DOF_NARROW_W(DOF_NW_T, NAME) \
inline DOF_NW_T NAME(const DOF_NW_T dx, const float dy, const float rq, const DOF_NW_T r, const int blades, \
                     __global const float2 *normals, const float kpoly, const float roundness, const float sa, \
                     const float inv_area) \
{ \
    const float sg = rq >= 0.0f ? -1.0f : 1.0f; \
    const DOF_NW_T dist = sqrt(dx * dx + dy * dy); \
    DOF_NW_T rho = (DOF_NW_T)(1.0f); \
    if (blades > 0) { \
        DOF_NW_T m = (DOF_NW_T)(-INFINITY); \
        for (int i = 0; i < blades; ++i) \
            m = fmax(m, sg * (dx * normals[i].x + dy * normals[i].y)); \
        rho = (1.0f - roundness) * select(kpoly * dist / m, (DOF_NW_T)(1.0f), m <= 0.0f) + roundness; \
    } \
    const DOF_NW_T rr = r * rho; \
    DOF_NW_T w = clamp((rr - dist) / DOF_NARROW_RAMP_OF(rq) + 0.5f, 0.0f, 1.0f); \
    DOF_NW_TEXTURE \
    return w * inv_area / (r * r); \
}
#if DOF_TEXTURE
#define DOF_NW_TEXTURE w *= 1.0f + (sg < 0.0f ? -sa : sa) * (2.0f * fmin(dist / rr, 1.0f) * fmin(dist / rr, 1.0f) - 1.0f);
#else
#define DOF_NW_TEXTURE
#endif
DOF_NARROW_W(float, dof_narrow_w)
DOF_NARROW_W(float16, dof_narrow_w16)

/* One work-item per cell: the cell's sources in scan order (working rows, then the block's rows),
 * each with 1 / its weight sum (narrow_norm); then, unless there are more than DOF_NARROW_MAX,
 * each source block's working colour (level 0) recomputed from the colour with the sources'
 * excess taken out (dof_prepare's 2x2 mean, same order). */
__kernel void dof_narrow_list(__global const float *restrict src, __global const float *restrict coc,
                              __global float *restrict lv, __global const int *restrict flag,
                              __global const int *restrict gflag,
                              __global int *restrict ncount, __global float8 *restrict nrec,
                              const int width, const int height, const int ww, const int hw, const int pad,
                              const int ncx, const int ncy, __global const float2 *restrict normals,
                              const int blades, const float kpoly, const float roundness, const float sa,
                              const float inv_area)
{
    const int cx = get_global_id(0), cy = get_global_id(1);
    if (cx >= ncx || cy >= ncy) return;
    const int cw = DOF_NARROW_CELL / DOF_SCALE;
    const int pw = DOF_PW(ww, pad);
    const size_t pn = (size_t)pw * DOF_PW(hw, pad), n = (size_t)width * height;
    const int rdy[8] = {-2, -2, -2, 0, 0, 2, 2, 2}, rdx[8] = {-2, 0, 2, -2, 2, -2, 0, 2};
    __global float8 *rec = nrec + (size_t)(cy * ncx + cx) * DOF_NARROW_MAX;
    int count = 0;  /* records: sources and in-focus lights */
    float last_rq = NAN, last_norm = 0.0f;
    const int ngx = (ww + 15) / 16;
    for (int py = cy * cw; py < min((cy + 1) * cw, hw); ++py)
        for (int px = cx * cw; px < min((cx + 1) * cw, ww); ++px) {
            if (px % 16 == 0 && !gflag[(size_t)py * ngx + px / 16]) {  /* no candidate in these 16 */
                px += 15;
                continue;
            }
            const int k = flag[(size_t)py * ww + px];
            if (k < 0)
                continue;
            const size_t ob = (size_t)(py + rdy[k] + pad) * pw + px + rdx[k] + pad;
            const float3 bg = (float3)(lv[ob], lv[pn + ob], lv[2 * pn + ob]);
            const float bgy = DOF_LUMA_R * bg.x + DOF_LUMA_G * bg.y + DOF_LUMA_B * bg.z;
            int nfront[DOF_SCALE * DOF_SCALE], have_front = 0;
            for (int b = 0; b < DOF_SCALE; ++b)
                for (int a = 0; a < DOF_SCALE; ++a) {
                    const int y = DOF_SCALE * py + b, x = DOF_SCALE * px + a;
                    const size_t i = (size_t)y * width + x;
                    const float3 e = fmax((float3)(src[i], src[n + i], src[2 * n + i]) - bg, 0.0f);
                    const float ey = DOF_LUMA_R * e.x + DOF_LUMA_G * e.y + DOF_LUMA_B * e.z;
                    const float rq = coc[i];
                    /* not split behind a sharper pixel of its 3x3 (NARROW_MIN_PX; the block is >= 2
                     * working px from the edge: the 3x3 lies in the image) */
                    int split = fabs(rq) > DOF_NARROW_FOCUS;
                    for (int v = -1; v <= 1; ++v)
                        for (int u = -1; u <= 1; ++u) {
                            const float c = coc[i + (long)v * width + u];
                            split &= !(fabs(c) < DOF_NARROW_MIN && c < rq - DOF_FRONT_MARGIN);
                        }
                    int kept = fabs(rq) <= DOF_NARROW_FOCUS;
                    if (kept) {
                        if (!have_front) {  /* once per block, for each of its pixels: the pixels of
                                             * the 5x5 working pixels nearer than it (the block is
                                             * >= 2 working px from the edge; past the image's last
                                             * row/column a block has none) */
                            float t[DOF_SCALE * DOF_SCALE];
                            for (int m = 0; m < DOF_SCALE * DOF_SCALE; ++m) {
                                t[m] = coc[(size_t)(DOF_SCALE * py + m / DOF_SCALE) * width + DOF_SCALE * px
                                           + m % DOF_SCALE] - DOF_FRONT_MARGIN;
                                nfront[m] = 0;
                            }
                            for (int v = DOF_SCALE * (py - 2); v < min(DOF_SCALE * (py + 3), height); ++v)
                                for (int u = DOF_SCALE * (px - 2); u < min(DOF_SCALE * (px + 3), width); ++u) {
                                    const float c = coc[(size_t)v * width + u];
                                    for (int m = 0; m < DOF_SCALE * DOF_SCALE; ++m)
                                        nfront[m] += c < t[m];
                                }
                            have_front = 1;
                        }
                        kept = nfront[b * DOF_SCALE + a] <= DOF_NARROW_FRONT_MAX;
                    }
                    if (!((split || kept)
                          && ey > DOF_NARROW_CONTRAST * bgy * M_PI_F * rq * rq * fmax(1.0f, fabs(rq) / DOF_NARROW_EDGE)))
                        continue;
                    if (!split) {  /* in focus: its excess leaves the working image */
                        if (count < DOF_NARROW_MAX)
                            rec[count] = (float8)((float)x, (float)y, rq, e.x, e.y, e.z, 0.0f,
                                                  fabs(rq) >= DOF_NARROW_SPREAD ? DOF_NK_SMALL : DOF_NK_FOCUS);
                        ++count;
                        continue;
                    }
                    if (count < DOF_NARROW_MAX) {
                        if (rq != last_rq) {  /* a light's pixels mostly share one CoC: sum once */
                            const float r = fmax(fabs(rq), 0.5f);
                            float ws = 1.0f;  /* from DOF_NARROW_SUM px on the disc's own integral */
                            if (r < DOF_NARROW_SUM) {
                                const int kk = (int)ceil(r) + 1;
                                ws = 0.0f;
                                for (int v = -kk; v <= kk; ++v)
                                    for (int u = -kk; u <= kk; ++u)
                                        ws += dof_narrow_w((float)u, (float)v, rq, r, blades, normals, kpoly,
                                                           roundness, sa, inv_area);
                            }
                            last_rq = rq;
                            last_norm = 1.0f / ws;
                        }
                        rec[count] = (float8)((float)x, (float)y, rq, e.x, e.y, e.z, last_norm, DOF_NK_SOURCE);
                    }
                    ++count;
                }
        }
    if (count > DOF_NARROW_MAX) {
        ncount[cy * ncx + cx] = 0;
        return;
    }
    ncount[cy * ncx + cx] = count;
    /* the source blocks' and the in-focus lights' blocks' working colour without their excess; a
     * block's records are consecutive (scan order) */
    for (int jj = 0; jj < count; ) {
        const int px = (int)rec[jj].s0 / DOF_SCALE, py = (int)rec[jj].s1 / DOF_SCALE;
        float3 p[DOF_SCALE][DOF_SCALE];
        for (int b = 0; b < DOF_SCALE; ++b)
            for (int a = 0; a < DOF_SCALE; ++a) {
                const size_t i = (size_t)(DOF_SCALE * py + b) * width + DOF_SCALE * px + a;
                p[b][a] = (float3)(src[i], src[n + i], src[2 * n + i]);
            }
        for (; jj < count; ++jj) {
            const float8 s = rec[jj];
            if ((int)s.s0 / DOF_SCALE != px || (int)s.s1 / DOF_SCALE != py)
                break;
            p[(int)s.s1 - DOF_SCALE * py][(int)s.s0 - DOF_SCALE * px] -= (float3)(s.s3, s.s4, s.s5);
        }
        const size_t o = (size_t)(py + pad) * pw + px + pad;
#if DOF_SCALE == 2
        const float3 c = 0.25f * (((p[0][0] + p[0][1]) + p[1][0]) + p[1][1]);
#else
        const float3 c = p[0][0];
#endif
        lv[o] = c.x; lv[pn + o] = c.y; lv[2 * pn + o] = c.z;
    }
}

/* Per 16 x 16-px tile of the output, the number of listed sources whose disc (|r| + 1/2 px) reaches
 * it, in-focus lights with a 3x3 share (DOF_NK_SMALL) counted, the others not: the upsampling's
 * work-items of a tile with none skip the layer after one read. `ncount`: the cells' counts;
 * `ntile`: (ceil(h / 16), ceil(w / 16)). */
__kernel void dof_narrow_near(__global const int *restrict ncount, __global const float8 *restrict nrec,
                              __global int *restrict ntile, const int ncx, const int ncy, const int ntx,
                              const int nty)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= ntx || ty >= nty) return;
    const int reach = DOF_SCALE * DOF_RMAX + 1;
    const float x0 = (float)(16 * tx), y0 = (float)(16 * ty);
    const int cx0 = max(16 * tx - reach, 0) / DOF_NARROW_CELL, cx1 = min((16 * tx + 15 + reach) / DOF_NARROW_CELL, ncx - 1);
    const int cy0 = max(16 * ty - reach, 0) / DOF_NARROW_CELL, cy1 = min((16 * ty + 15 + reach) / DOF_NARROW_CELL, ncy - 1);
    int t = 0;
    for (int cy = cy0; cy <= cy1; ++cy)
        for (int cx = cx0; cx <= cx1; ++cx) {
            __global const float8 *rec = nrec + (size_t)(cy * ncx + cx) * DOF_NARROW_MAX;
            for (int j = 0; j < ncount[cy * ncx + cx]; ++j) {
                const float rs = fmax(fabs(rec[j].s2), 0.5f) + 0.5f;
                t += rec[j].s7 != DOF_NK_FOCUS && rec[j].s0 >= x0 - rs && rec[j].s0 <= x0 + 15.0f + rs && rec[j].s1 >= y0 - rs
                     && rec[j].s1 <= y0 + 15.0f + rs;
            }
        }
    ntile[ty * ntx + tx] = t;
}

/* The layer's light at output pixels x .. x + 15 of row y (narrow_layer): the sources of the
 * cells within the largest CoC (+1 px), each spread with its own radius over a pixel it is in
 * front of or on the surface of, with the smaller of its own and the pixel's radius times 1 - the
 * upsampled front coverage `ua` over a pixel in front of it; scaled by 1 / its weight sum; and
 * the in-focus lights' 3x3 share where the composite takes the half-resolution blur
 * (small_layer: the 3x3's weight times max(DOF_HALF_B(r) - ua, 0)), less each source's share of the
 * composite's 3x3 blur (`kw`: 1 - b over its weight sum where the composite uses it, else 0; the 3x3
 * reads the colour without the sources' excess in _half_composite); added to *o_r, *o_g, *o_b.
 * Returns whether a source's disc reached these pixels. */
inline int dof_narrow16(__global const int *restrict ncount, __global const float8 *restrict nrec,
                         const int ncx, const int ncy, const int x, const int y, const float16 r,
                         const float16 ua, const float16 kw, __global const float2 *restrict normals, const int blades,
                         const float kpoly, const float roundness, const float sa, const float inv_area,
                         float16 *o_r, float16 *o_g, float16 *o_b)
{
    const int reach = DOF_SCALE * DOF_RMAX + 1;
    const int cx0 = max(x - reach, 0) / DOF_NARROW_CELL, cx1 = min((x + 15 + reach) / DOF_NARROW_CELL, ncx - 1);
    const int cy0 = max(y - reach, 0) / DOF_NARROW_CELL, cy1 = min((y + reach) / DOF_NARROW_CELL, ncy - 1);
    const float16 xs = (float16)((float)x) + (float16)(0.0f, 1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 6.0f, 7.0f, 8.0f, 9.0f,
                                                      10.0f, 11.0f, 12.0f, 13.0f, 14.0f, 15.0f);
    int touched = 0;
    /* the aperture's smallest radius (the polygon's inscribed circle, blended by the roundness) */
    const float rho_min = blades > 0 ? (1.0f - roundness) * kpoly + roundness : 1.0f;
    for (int cy = cy0; cy <= cy1; ++cy)
        for (int cx = cx0; cx <= cx1; ++cx) {
            const int cn = ncount[cy * ncx + cx];
            __global const float8 *rec = nrec + (size_t)(cy * ncx + cx) * DOF_NARROW_MAX;
            for (int j = 0; j < cn; ++j) {
                const float8 s = rec[j];
                if (s.s7 != DOF_NK_SOURCE) {
                    if (s.s7 == DOF_NK_FOCUS || fabs(s.s1 - (float)y) > 1.0f || s.s0 < (float)x - 1.0f
                        || s.s0 > (float)x + 16.0f)
                        continue;
                    touched = 1;
                    /* small_layer: a = DOF_LOCAL_A of its CoC over a pixel behind it, else of the
                     * smaller |CoC| (the 3x3's rule); w(0) = 1 - 2a, w(+-1) = a per axis */
                    const float16 dx = fabs(s.s0 - xs);
                    const float16 a = select(fmin(DOF_LOCAL_A(s.s2), DOF_LOCAL_A(r)), (float16)(DOF_LOCAL_A(s.s2)),
                                             s.s2 < r - DOF_FRONT_MARGIN);
                    const float16 wx = select(select((float16)(0.0f), a, dx == 1.0f), 1.0f - 2.0f * a, dx == 0.0f);
                    const float16 wy = s.s1 == (float)y ? 1.0f - 2.0f * a : a;
                    const float16 wv = wx * wy * fmax(DOF_HALF_B(r) - ua, 0.0f);
                    *o_r += wv * s.s3; *o_g += wv * s.s4; *o_b += wv * s.s5;
                    continue;
                }
                const float rs = fmax(fabs(s.s2), 0.5f);
                /* a source reaches rs + 1/2 px (rho <= 1, the 1-px ramp) */
                if (fabs(s.s1 - (float)y) > rs + 0.5f || s.s0 < (float)x - rs - 0.5f || s.s0 > (float)x + 15.5f + rs)
                    continue;
                touched = 1;
                if (fabs(s.s1 - (float)y) <= 1.0f && s.s0 >= (float)x - 1.0f && s.s0 <= (float)x + 16.0f) {
                    /* the 3x3 share of its excess the composite took from the colour (kw: 1 - b over
                     * the 3x3's weight sum where it is used, else 0): the 3x3 reads the colour
                     * without the sources' excess (_half_composite), weights as small_layer's */
                    const float16 dx = fabs(s.s0 - xs);
                    const float16 a = select(fmin(DOF_LOCAL_A(s.s2), DOF_LOCAL_A(r)), (float16)(DOF_LOCAL_A(s.s2)),
                                             s.s2 < r - DOF_FRONT_MARGIN);
                    const float16 wx = select(select((float16)(0.0f), a, dx == 1.0f), 1.0f - 2.0f * a, dx == 0.0f);
                    const float16 wy = s.s1 == (float)y ? 1.0f - 2.0f * a : a;
                    const float16 wv = wx * wy * kw;
                    *o_r -= wv * s.s3; *o_g -= wv * s.s4; *o_b -= wv * s.s5;
                }
                const int16 behind = s.s2 > r + DOF_FRONT_MARGIN;
#if !DOF_TEXTURE
                /* every lane well inside the disc (|o| <= r rho_min - half the ramp: coverage 1 in
                 * any direction) and none behind: the weight is the disc's constant 1 / (a_K r^2) */
                const float dy = s.s1 - (float)y, rin = rs * rho_min - 0.5f * DOF_NARROW_RAMP_OF(s.s2);
                const float16 dx = s.s0 - xs;
                if (rin > 0.0f && !any(behind) && all(dx * dx + dy * dy <= rin * rin)) {
                    const float wc = inv_area / (rs * rs) * s.s6;
                    *o_r += wc * s.s3; *o_g += wc * s.s4; *o_b += wc * s.s5;
                    continue;
                }
#endif
                const float16 rs16 = (float16)(rs);
                const float16 rad = select(rs16, fmin(fmax(fabs(r), 0.5f), rs16), behind);
                const float16 w = dof_narrow_w16(s.s0 - xs, s.s1 - (float)y, s.s2, rad, blades, normals, kpoly,
                                                 roundness, sa, inv_area);
                const float16 wv = select(w, w * (1.0f - ua), behind) * s.s6;
                *o_r += wv * s.s3; *o_g += wv * s.s4; *o_b += wv * s.s5;
            }
        }
    return touched;
}
