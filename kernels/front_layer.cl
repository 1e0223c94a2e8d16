/* front_layer: a foreground layer (premultiplied R, G, B, coverage, depth; interleaved, 5 floats a
 * pixel) spread over each pixel's thin-lens disc at the level of a pyramid where that disc is
 * FRONT_RB ... 2 FRONT_RB level pixels, and composited over the image (formula, levels and the
 * numpy oracle front_reference: clpost/stages/front_layer.py).
 * A level's planes: 5 planes of wl x hl (premultiplied R, G, B, coverage, each over N(r); radius
 * in level px, -1 where nothing spreads). Spread levels >= 1 sit one after another in `spread`
 * (4 planes each); `levels` holds (wl, hl, offset) of each.
 * Structural: FRONT_TILE (tile side), FRONT_REACH (half-size of the rho window), FRONT_NORM_STEPS
 * (N(r) table entries per px), FRONT_RB (R, float), FRONT_LEVELS (number of levels).
 */
#ifndef FRONT_TILE
#error "FRONT_TILE must be defined"
#endif
#ifndef FRONT_REACH
#error "FRONT_REACH must be defined"
#endif
#ifndef FRONT_NORM_STEPS
#error "FRONT_NORM_STEPS must be defined"
#endif
#ifndef FRONT_RB
#error "FRONT_RB must be defined"
#endif
#ifndef FRONT_LEVELS
#error "FRONT_LEVELS must be defined"
#endif

/* CoC radius (px, >= 0, at most rlim) of depth d: k |1/S - 1/d| (k = 0: depth of field off) */
inline float front_radius(const float d, const float k, const float inv_u, const float rlim)
{
    const float inv_d = isinf(d) ? 0.0f : 1.0f / d;
    return fmin(fabs(k * (inv_u - inv_d)), rlim);
}

/* the level radius r (full-resolution px) spreads at: 0 below 2R, else the largest L with r >= R 2^L */
inline int front_level(const float r)
{
    int L = 0;
    while (L + 1 < FRONT_LEVELS && r >= FRONT_RB * (float)(2 << L)) ++L;
    return L;
}

/* 1 / N(r), N from its table (linear) */
inline float front_inv_norm(__global const float *restrict norm, const float r)
{
    const float t = r * FRONT_NORM_STEPS;
    const int i0 = (int)t;
    return 1.0f / mix(norm[i0], norm[i0 + 1], t - (float)i0);
}

/* level 0's planes: the pixels spreading at full resolution */
__kernel void front_layer_prep(__global const float *restrict front, __global const float *restrict norm,
                               __global float *restrict planes, const int w, const int h,
                               const float k, const float inv_u, const float rlim)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    const size_t n = (size_t)w * h, p = (size_t)y * w + x;
    __global const float *f = front + 5 * p;
    const float r = front_radius(f[4], k, inv_u, rlim);
    const int mine = f[3] > 0.0f && front_level(r) == 0;
    const float s = mine ? front_inv_norm(norm, r) : 0.0f;
    for (int c = 0; c < 4; ++c) planes[c * n + p] = s * f[c];
    planes[4 * n + p] = mine ? r : -1.0f;
}

/* level L >= 1's planes: per 2^L block, the mean of its level-L pixels (the block's pixels inside
 * the frame count) at their alpha-weighted mean radius / 2^L */
__kernel void front_layer_down(__global const float *restrict front, __global const float *restrict norm,
                               __global float *restrict planes, const int w, const int h, const int wl,
                               const int hl, const int L, const float k, const float inv_u, const float rlim)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= wl || y >= hl) return;
    const int f = 1 << L;
    float4 s = (float4)(0.0f);
    float sa = 0.0f, sar = 0.0f;
    int cnt = 0;
    for (int j = y * f; j < min((y + 1) * f, h); ++j)
        for (int i = x * f; i < min((x + 1) * f, w); ++i) {
            ++cnt;
            __global const float *q = front + 5 * ((size_t)j * w + i);
            if (!(q[3] > 0.0f)) continue;
            const float r = front_radius(q[4], k, inv_u, rlim);
            if (front_level(r) != L) continue;
            s += (float4)(q[0], q[1], q[2], q[3]);
            sa += q[3];
            sar += q[3] * r;
        }
    const size_t n = (size_t)wl * hl, p = (size_t)y * wl + x;
    const float rm = sar / sa / (float)f;
    const float rl = sa > 0.0f ? sqrt(fmax(rm * rm - FRONT_SHRINK, 0.0f)) : -1.0f;
    const float4 v = sa > 0.0f ? s * (front_inv_norm(norm, rl) / (float)cnt) : (float4)(0.0f);
    planes[p] = v.x; planes[n + p] = v.y; planes[2 * n + p] = v.z; planes[3 * n + p] = v.w;
    planes[4 * n + p] = rl;
}

/* each tile's largest radius, -1 where no pixel spreads */
__kernel void front_layer_tiles(__global const float *restrict planes, __global float *restrict tiles,
                                const int w, const int h, const int tw, const int th)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    __global const float *rad = planes + 4 * (size_t)w * h;
    float m = -1.0f;
    for (int y = ty * FRONT_TILE; y < min((ty + 1) * FRONT_TILE, h); ++y)
        for (int x = tx * FRONT_TILE; x < min((tx + 1) * FRONT_TILE, w); ++x)
            m = fmax(m, rad[(size_t)y * w + x]);
    tiles[(size_t)ty * tw + tx] = m;
}

/* each tile's reach: the largest radius of the tiles (or their copies beyond the frame: the
 * layer continues as its edge pixels) that lie within that radius and the ramp's half pixel of
 * some pixel of it; -1 where nothing spreads onto it */
__kernel void front_layer_reach(__global const float *restrict tiles, __global float *restrict reach,
                                const int tw, const int th, const int roff)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    const int rt = (int)ceil((2.0f * FRONT_RB + 0.5f) / FRONT_TILE) + 1;
    float m = -1.0f;
    for (int j = ty - rt; j <= ty + rt; ++j)
        for (int i = tx - rt; i <= tx + rt; ++i) {
            const float r = tiles[(size_t)clamp(j, 0, th - 1) * tw + clamp(i, 0, tw - 1)];
            if (r < 0.0f) continue;
            const int ax = (int)abs(i - tx), ay = (int)abs(j - ty);
            const float gx = (float)max(0, (ax - 1) * FRONT_TILE + 1);
            const float gy = (float)max(0, (ay - 1) * FRONT_TILE + 1);
            if (gx * gx + gy * gy < (r + 0.5f) * (r + 0.5f)) m = fmax(m, r);
        }
    reach[roff + (size_t)ty * tw + tx] = m;
}

/* Σ_q k_{r_q}(p - q) P_q at pixel (x, y) of a level, q clamped to the level (the layer continues
 * as its edge pixels), within its tile's reach */
inline float4 front_spread(__global const float *restrict planes, __global const float *restrict reach_tiles,
                           __global const float *restrict rho, const int x, const int y, const int w,
                           const int h, const int tw)
{
    const float reach = reach_tiles[(size_t)(y / FRONT_TILE) * tw + x / FRONT_TILE];
    float4 acc = (float4)(0.0f);
    if (reach < 0.0f) return acc;
    const size_t n = (size_t)w * h;
    const int R = min((int)ceil(reach + 0.5f), FRONT_REACH);
    for (int dy = -R; dy <= R; ++dy) {
        const size_t row = (size_t)clamp(y - dy, 0, h - 1) * w;
        for (int dx = -R; dx <= R; ++dx) {
            const size_t q = row + clamp(x - dx, 0, w - 1);
            const float r = planes[4 * n + q];
            if (r < 0.0f) continue;
            const float wt = clamp(r * rho[(dy + FRONT_REACH) * (2 * FRONT_REACH + 1) + dx + FRONT_REACH]
                                   - sqrt((float)(dx * dx + dy * dy)) + 0.5f, 0.0f, 1.0f);
            acc += wt * (float4)(planes[q], planes[n + q], planes[2 * n + q], planes[3 * n + q]);
        }
    }
    return acc;
}

/* a level >= 1 spread, into its place in `spread` */
__kernel void front_layer_gather(__global const float *restrict planes, __global const float *restrict reach,
                                 __global const float *restrict rho, __global float *restrict spread,
                                 const int w, const int h, const int tw, const int offset, const int roff)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    const float4 v = front_spread(planes, reach + roff, rho, x, y, w, h, tw);
    const size_t n = (size_t)w * h, p = (size_t)y * w + x;
    __global float *o = spread + offset;
    o[p] = v.x; o[n + p] = v.y; o[2 * n + p] = v.z; o[3 * n + p] = v.w;
}

/* per full-resolution tile: whether any level >= 1 has spread something under the bilinear
 * corners of one of its pixels (else the composite skips the levels there) */
__kernel void front_layer_active(__global const float *restrict reach, __global const int *restrict levels,
                                 __global int *restrict active, const int tw, const int th)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    int any = 0;
    for (int L = 1; L < FRONT_LEVELS && !any; ++L) {
        __global const int *lv = levels + 5 * (L - 1);
        const int wl = lv[0], hl = lv[1], twl = lv[3], thl = (hl + FRONT_TILE - 1) / FRONT_TILE;
        /* level pixels under the tile's pixels' corners: floor((x + 0.5) / 2^L - 0.5) ... + 1 */
        const int x0 = clamp(((tx * FRONT_TILE) >> L) - 1, 0, wl - 1), x1 = clamp((((tx + 1) * FRONT_TILE - 1) >> L) + 1, 0, wl - 1);
        const int y0 = clamp(((ty * FRONT_TILE) >> L) - 1, 0, hl - 1), y1 = clamp((((ty + 1) * FRONT_TILE - 1) >> L) + 1, 0, hl - 1);
        __global const float *rl = reach + lv[4];
        for (int j = y0 / FRONT_TILE; j <= min(y1 / FRONT_TILE, thl - 1); ++j)
            for (int i = x0 / FRONT_TILE; i <= min(x1 / FRONT_TILE, twl - 1); ++i)
                any |= rl[j * twl + i] >= 0.0f;
    }
    active[(size_t)ty * tw + tx] = any;
}

/* pixel (x, y)'s output from its level-0 spread acc: + each level >= 1 upsampled (bilinear,
 * pixel centres aligned, edges clamped) where its tiles under the four corners reach anything
 * (on: the pixel's tile has any), then out = F_rgb + (1 - F_a) src.
 * levels[5 (L - 1) ...]: level L's wl, hl, offset in `spread`, tiles across, offset in `reach` */
inline void front_finish(float4 acc, const int x, const int y, const int w, const int h, const int on,
                         __global const float *restrict src, __global const float *restrict reach,
                         __global const float *restrict spread, __global const int *restrict levels,
                         __global float *restrict dst)
{
#pragma unroll
    for (int L = 1; L < FRONT_LEVELS; ++L) {
        if (!on) break;
        __global const int *lv = levels + 5 * (L - 1);
        const int wl = lv[0], hl = lv[1], twl = lv[3];
        const float f = (float)(1 << L);
        const float sx = ((float)x + 0.5f) / f - 0.5f, sy = ((float)y + 0.5f) / f - 0.5f;
        const int x0 = clamp((int)floor(sx), 0, wl - 1), y0 = clamp((int)floor(sy), 0, hl - 1);
        const int x1 = min(x0 + 1, wl - 1), y1 = min(y0 + 1, hl - 1);
        __global const float *rl = reach + lv[4];
        const int tx0 = x0 / FRONT_TILE, tx1 = x1 / FRONT_TILE, ty0 = y0 / FRONT_TILE, ty1 = y1 / FRONT_TILE;
        if (fmax(fmax(rl[ty0 * twl + tx0], rl[ty0 * twl + tx1]), fmax(rl[ty1 * twl + tx0], rl[ty1 * twl + tx1])) < 0.0f)
            continue;  /* nothing spread there at this level: its planes are 0 */
        const float fx = clamp(sx - (float)x0, 0.0f, 1.0f), fy = clamp(sy - (float)y0, 0.0f, 1.0f);
        const size_t nl = (size_t)wl * hl;
        const size_t i00 = (size_t)y0 * wl + x0, i01 = (size_t)y0 * wl + x1;
        const size_t i10 = (size_t)y1 * wl + x0, i11 = (size_t)y1 * wl + x1;
        __global const float *s = spread + lv[2];
        float v[4];
        for (int c = 0; c < 4; ++c) {
            __global const float *p = s + c * nl;
            v[c] = (p[i00] * (1.0f - fx) + p[i01] * fx) * (1.0f - fy) + (p[i10] * (1.0f - fx) + p[i11] * fx) * fy;
        }
        acc += (float4)(v[0], v[1], v[2], v[3]);
    }
    const size_t n = (size_t)w * h, p = (size_t)y * w + x;
    const float3 c = acc.xyz + (1.0f - acc.w) * (float3)(src[p], src[n + p], src[2 * n + p]);
    dst[p] = c.x;
    dst[n + p] = c.y;
    dst[2 * n + p] = c.z;
}

/* the composite, one pixel per work-item (GPUs) */
__kernel void front_layer(__global const float *restrict src, __global const float *restrict planes,
                          __global const float *restrict reach, __global const float *restrict rho,
                          __global const float *restrict spread, __global const int *restrict levels,
                          __global const int *restrict active, __global float *restrict dst, const int w,
                          const int h, const int tw)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    const float4 acc = front_spread(planes, reach, rho, x, y, w, h, tw);
    front_finish(acc, x, y, w, h, active[(size_t)(y / FRONT_TILE) * tw + x / FRONT_TILE], src, reach, spread,
                 levels, dst);
}

/* ---- 16-pixel forms (CPUs: one work-item spreads 16 consecutive pixels of a row as the lanes of
 * float16 vectors; the same taps in the same order as front_spread, lane by lane) ---- */

/* 16 consecutive values of a level plane at row offset `row`, columns qx ... qx + 15 clamped */
inline float16 front_row16(__global const float *restrict p, const size_t row, const int qx, const int w)
{
    if (qx >= 0 && qx + 15 < w) return vload16(0, p + row + qx);
    float t[16];
    for (int l = 0; l < 16; ++l) t[l] = p[row + clamp(qx + l, 0, w - 1)];
    return vload16(0, t);
}

/* the largest reach of the tiles under pixels x0 ... x0 + 15 of row y */
inline float front_reach16(__global const float *restrict reach_tiles, const int x0, const int y, const int w,
                           const int tw)
{
    const size_t trow = (size_t)(y / FRONT_TILE) * tw;
    float reach = -1.0f;
    for (int t = x0 / FRONT_TILE; t <= min(x0 + 15, w - 1) / FRONT_TILE; ++t) reach = fmax(reach, reach_tiles[trow + t]);
    return reach;
}

/* front_spread of pixels x0 ... x0 + 15 of row y (lanes past the frame's edge: clamped sources,
 * not stored) within `reach` (front_reach16) */
inline void front_spread16(__global const float *restrict planes, const float reach,
                           __global const float *restrict rho, const int x0, const int y, const int w,
                           const int h, float16 *ar, float16 *ag, float16 *ab, float16 *aa)
{
    *ar = *ag = *ab = *aa = (float16)(0.0f);
    if (reach < 0.0f) return;
    const size_t n = (size_t)w * h;
    const int R = min((int)ceil(reach + 0.5f), FRONT_REACH);
    for (int dy = -R; dy <= R; ++dy) {
        const size_t row = (size_t)clamp(y - dy, 0, h - 1) * w;
        for (int dx = -R; dx <= R; ++dx) {
            const float rh = rho[(dy + FRONT_REACH) * (2 * FRONT_REACH + 1) + dx + FRONT_REACH];
            const float dist = sqrt((float)(dx * dx + dy * dy));
            const int qx = x0 - dx;
            /* a source without a radius (-1) weighs 0 (r rho - dist + 1/2 <= 0) and its planes are 0 */
            const float16 wt = clamp(front_row16(planes + 4 * n, row, qx, w) * rh - dist + 0.5f, 0.0f, 1.0f);
            if (!any(wt > 0.0f)) continue;
            *ar += wt * front_row16(planes, row, qx, w);
            *ag += wt * front_row16(planes + n, row, qx, w);
            *ab += wt * front_row16(planes + 2 * n, row, qx, w);
            *aa += wt * front_row16(planes + 3 * n, row, qx, w);
        }
    }
}

/* a spread, 16 pixels per work-item, into its place in `spread`; where nothing reaches, zeros
 * (zeros = 1: a level >= 1, whose bilinear corners the composite may read there) or nothing
 * (level 0: the composite reads a pixel's own spread only where its tile's reach says some) */
__kernel void front_layer_gather16(__global const float *restrict planes, __global const float *restrict reach,
                                   __global const float *restrict rho, __global float *restrict spread,
                                   const int w, const int h, const int tw, const int offset, const int roff,
                                   const int zeros)
{
    const int x0 = get_global_id(0) * 16, y = get_global_id(1);
    if (x0 >= w || y >= h) return;
    const float r = front_reach16(reach + roff, x0, y, w, tw);
    if (r < 0.0f && !zeros) return;
    float16 v[4];
    front_spread16(planes, r, rho, x0, y, w, h, &v[0], &v[1], &v[2], &v[3]);
    const size_t n = (size_t)w * h, p = (size_t)y * w + x0;
    __global float *o = spread + offset;
    for (int c = 0; c < 4; ++c) {
        if (x0 + 15 < w) {
            vstore16(v[c], 0, o + c * n + p);
        } else {
            float t[16];
            vstore16(v[c], 0, t);
            for (int l = 0; x0 + l < w; ++l) o[c * n + p + l] = t[l];
        }
    }
}

/* the composite after front_layer_gather16 spread level 0 into `spread0` (4 planes, full
 * resolution): one pixel per work-item, the levels as in front_layer */
__kernel void front_layer_add(__global const float *restrict src, __global const float *restrict spread0,
                              __global const float *restrict reach, __global const float *restrict spread,
                              __global const int *restrict levels, __global const int *restrict active,
                              __global float *restrict dst, const int w, const int h, const int tw)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    const size_t n = (size_t)w * h, p = (size_t)y * w + x, t = (size_t)(y / FRONT_TILE) * tw + x / FRONT_TILE;
    const float4 acc = reach[t] >= 0.0f ? (float4)(spread0[p], spread0[n + p], spread0[2 * n + p], spread0[3 * n + p])
                                        : (float4)(0.0f);
    front_finish(acc, x, y, w, h, active[t], src, reach, spread, levels, dst);
}
