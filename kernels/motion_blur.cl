/* motion_blur: velocity-buffer motion blur (McGuire, Hennessy, Bukowski, Osman 2012, "A
 * Reconstruction Filter for Plausible Motion Blur") and a rolling-shutter warp.
 * clpost/stages/motion_blur.py documents the formulas; its reference() is the oracle.
 *
 * Buffers: colour planar (c*n + i); velocity interleaved (2i, 2i+1) px per frame, forward,
 * +x right, +y down; depth planar metres (+inf sky). Scratch: hv = clamped half-vectors and
 * their unclamped length and what a tap reads of Y packed in one word (4 planes: x, y, key, record),
 * iz = 1/depth (0 for sky), tile and
 * neighbour-max (3 planes each). Maxima are ranked by the unclamped length: clamped vectors all
 * have length K, and ranking them by a rounding-level difference would not be reproducible.
 *
 * Defines: MOTION_BLUR_TILE (tile size K = the largest blur half-length in px),
 * MOTION_BLUR_SAMPLES (S_q, odd; the centre tap is the pixel itself), MOTION_BLUR_SAMPLES_MAX (odd:
 * the most taps a frame whose motion covers few tiles may take, motion_blur_budget),
 * MOTION_BLUR_DENSITY (taps per px of half-path: S = min(C, 2 ceil(DENSITY |v_N|) + 1), C the frame's cap).
 */
#pragma OPENCL FP_CONTRACT OFF
/* FP_CONTRACT OFF: no a*b+c fusion, so tap positions round exactly as in the numpy reference. */

/* MOTION_BLUR_LANES: pixels per work-item of the prep and the gather, 16 (explicit float16 rows, for
 * CPUs: PoCL vectorises neither one-pixel form) or 1 (one pixel per work-item, for GPUs, where a
 * 16-wide work-item makes uncoalesced loads and few work-items); the stage sets it from
 * Runtime.wide. The one-pixel functions below are the spec either way (the 16-wide ones do the
 * same operations lane for lane). */
#ifndef MOTION_BLUR_LANES
#define MOTION_BLUR_LANES 16
#endif
#if MOTION_BLUR_LANES != 16 && MOTION_BLUR_LANES != 1
#error "MOTION_BLUR_LANES must be 16 or 1"
#endif

#define MOTION_BLUR_SOFT_Z 0.05f   /* relative depth difference over which fore/background blend */
#define MOTION_BLUR_FOOT 0.5f      /* half a pixel: a swept pixel's footprint reaches this beyond |h| (FOOT in the .py) */
#define MOTION_BLUR_AGREE0 0.8f    /* cos(v_N, h_X) below which the tap sets split (AGREE0/1 in the .py) */
#define MOTION_BLUR_AGREE1 0.95f
#define MOTION_BLUR_DIR 127.0f    /* steps of the tap record's unit direction (DIR in the .py) */
#define MOTION_BLUR_LINE 2.0f      /* a front surface reaches X within this of its motion line, +- 1/2 px (LINE in the .py) */

#define MOTION_BLUR_R2X 0.7548776662f   /* the R2 lattice's steps per pixel in x and y (JITTER_R2 in the .py) */
#define MOTION_BLUR_R2Y 0.5698402910f
inline float motion_blur_jitter(uint seed, uint frame, int x, int y) {
    /* j in [-0.5, 0.5): a per-frame offset from the counter hash of (seed, frame) of kernels/random.cl
     * (CONVENTIONS "Randomness"; 24 high bits, exact in float) plus the R2 lattice
     * frac(x a1 + y a2): neighbouring pixels take well-spread strata (blue-noise-like), so the few
     * taps' noise is fine-grained; each fraction taken before the sum keeps float32 exact enough */
    const float j0 = (float)(rnd_hash4(seed, frame, 0u, 0u) >> 8) * (1.0f / 16777216.0f);
    const float a = (float)x * MOTION_BLUR_R2X;
    const float b = (float)y * MOTION_BLUR_R2Y;
    const float v = (a - floor(a)) + (b - floor(b)) + j0;
    return v - floor(v) - 0.5f;
}

/* What a tap reads of Y, one word (tap_records in the .py): l = max(|h|, 0.5) in the low 16 bits as a
 * float with a 10-bit mantissa (its bits from 0.5 up, rounded half up: relative step 2^-10, l <= K
 * = 20 px fits), h's unit direction in the high two bytes, each a signed count of 1/127 (x, then y;
 * rounded to nearest even as numpy's rint, by adding 1.5 * 2^23: PoCL expands convert_int16_rte
 * lane by lane, docs/motion_blur.md). l decodes with two integer operations and no square root;
 * the direction only places X against Y's motion line, where 1/127 is < 0.2 px at 21 px. */
#define MOTION_BLUR_RINT_MAGIC 12582912.0f   /* 1.5 * 2^23: x + this rounds x (|x| < 2^22) to an integer */
inline uint motion_blur_pack(float l, float2 e) {
    const uint lw = (as_uint(l) + 0x1000u - 0x3f000000u) >> 13;
    const int qx = as_int(e.x * MOTION_BLUR_DIR + MOTION_BLUR_RINT_MAGIC) - as_int(MOTION_BLUR_RINT_MAGIC);
    const int qy = as_int(e.y * MOTION_BLUR_DIR + MOTION_BLUR_RINT_MAGIC) - as_int(MOTION_BLUR_RINT_MAGIC);
    return lw | (((uint)qx & 0xffu) << 16) | ((uint)qy << 24);
}

inline float motion_blur_unpack_len(uint w) {
    return as_float(((w << 16) >> 3) + 0x3f000000u);
}

inline float motion_blur_len2(float2 v) {
    float a = v.x * v.x;
    float b = v.y * v.y;
    return a + b;
}

/* motion_blur (the gather, below) needs: half-vector h = v * k (k = shutter fraction / 2), clamped to |h| <= K keeping its direction;
 * inverse depth for the soft depth test (0 for the sky, so no inf - inf).
 * Fringe rule first: renderers average the vector over the pixel filter but point-sample depth, so
 * an anti-aliased edge pixel carries a fraction of the moving surface's velocity. A pixel whose
 * speed is > MOTION_BLUR_FRINGE times the fastest of its 3 x 3 neighbours (first in scan order on
 * ties) takes that neighbour's velocity and depth: its colour is (partly) that surface's. */
#define MOTION_BLUR_FRINGE2 0.01f  /* MOTION_BLUR_FRINGE = 0.1, squared */
inline void motion_blur_prep_px(__global const float *restrict velocity,
                                __global const float *restrict depth,
                                __global float *restrict hv, __global float *restrict iz,
                                const int x, const int y, const int width, const int height, const float k)
{
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
    float2 v = (float2)(velocity[2 * i], velocity[2 * i + 1]);
    const float own2 = motion_blur_len2(v);
    float best2 = own2;
    size_t bi = i;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            const int sx = clamp(x + dx, 0, width - 1), sy = clamp(y + dy, 0, height - 1);
            const size_t j = (size_t)sy * (size_t)width + (size_t)sx;
            const float s2 = motion_blur_len2((float2)(velocity[2 * j], velocity[2 * j + 1]));
            if (s2 > best2) { best2 = s2; bi = j; }
        }
    }
    float z = depth[i];
    if (own2 > 0.0f && own2 > MOTION_BLUR_FRINGE2 * best2) {
        v = (float2)(velocity[2 * bi], velocity[2 * bi + 1]);
        z = depth[bi];
    }
    /* scale by the inf-norm first: |v| up to FLT_MAX never overflows to inf */
    const float m = fmax(fabs(v.x), fabs(v.y));
    float2 h = (float2)(0.0f, 0.0f), e = (float2)(0.0f, 0.0f);
    float len = 0.0f, r = 0.0f;
    if (m > 0.0f) {
        const float2 u = v / m;                     /* inf-norm 1 */
        const float lu = sqrt(motion_blur_len2(u));
        len = lu * m * k;                           /* unclamped |h| (inf only beyond FLT_MAX) */
        r = fmin(len, (float)MOTION_BLUR_TILE);
        e = u * (1.0f / lu);                        /* h's direction */
        h = e * r;
    }
    hv[i] = h.x;
    hv[n + i] = h.y;
    hv[2 * n + i] = len;
    /* a tap loads Y's length and direction at once */
    ((__global uint *)(hv + 3 * n))[i] = motion_blur_pack(fmax(r, 0.5f), e);
    iz[i] = isinf(z) ? 0.0f : 1.0f / z;
}

#if MOTION_BLUR_LANES == 16

/* motion_blur_prep_px on 16 pixels of a row (x0 - 1 >= 0 and x0 + 16 < width: no column clamp),
 * lane for lane the same operations; neighbours are row loads at offsets -1, 0, +1 (velocity
 * interleaved: even/odd lanes of 32 floats). */
inline void motion_blur_prep_16(__global const float *restrict velocity,
                                __global const float *restrict depth,
                                __global float *restrict hv, __global float *restrict iz,
                                const int x0, const int y, const int width, const int height, const float k)
{
    const size_t n = (size_t)width * (size_t)height;
    const size_t i0 = (size_t)y * (size_t)width + (size_t)x0;
    float16 vx = (float16)(vload16(0, velocity + 2 * i0).even, vload16(1, velocity + 2 * i0).even);
    float16 vy = (float16)(vload16(0, velocity + 2 * i0).odd, vload16(1, velocity + 2 * i0).odd);
    float16 z = vload16(0, depth + i0);
    const float16 own2 = vx * vx + vy * vy;
    float16 best2 = own2, bx = vx, by = vy, bz = z;
    for (int dy = -1; dy <= 1; ++dy) {
        const int sy = clamp(y + dy, 0, height - 1);
        for (int dx = -1; dx <= 1; ++dx) {
            const size_t j = (size_t)sy * (size_t)width + (size_t)(x0 + dx);
            const float16 a = vload16(0, velocity + 2 * j), b = vload16(1, velocity + 2 * j);
            const float16 nx = (float16)(a.even, b.even), ny = (float16)(a.odd, b.odd);
            const float16 s2 = nx * nx + ny * ny;
            const int16 m = s2 > best2;
            best2 = m ? s2 : best2;
            bx = m ? nx : bx;
            by = m ? ny : by;
            bz = m ? vload16(0, depth + j) : bz;
        }
    }
    const int16 take = own2 > 0.0f && own2 > MOTION_BLUR_FRINGE2 * best2;
    vx = take ? bx : vx;
    vy = take ? by : vy;
    z = take ? bz : z;
    const float16 m = fmax(fabs(vx), fabs(vy));
    const int16 moving = m > 0.0f;
    const float16 ux = vx / m, uy = vy / m;
    const float16 lu = sqrt(ux * ux + uy * uy);
    const float16 len = lu * m * k;
    const float16 r = fmin(len, (float)MOTION_BLUR_TILE);
    const float16 rlu = 1.0f / lu;
    const float16 ex = ux * rlu, ey = uy * rlu;   /* h's direction */
    const float16 hx = ex * r, hy = ey * r;
    const float16 hx0 = moving ? hx : 0.0f, hy0 = moving ? hy : 0.0f;
    vstore16(hx0, 0, hv + i0);
    vstore16(hy0, 0, hv + n + i0);
    vstore16(moving ? len : 0.0f, 0, hv + 2 * n + i0);
    const float16 l = fmax(moving ? r : 0.0f, 0.5f);
    const uint16 lw = (as_uint16(l) + 0x1000u - 0x3f000000u) >> 13;
    const int16 qx = as_int16((moving ? ex : 0.0f) * MOTION_BLUR_DIR + MOTION_BLUR_RINT_MAGIC) - as_int(MOTION_BLUR_RINT_MAGIC);
    const int16 qy = as_int16((moving ? ey : 0.0f) * MOTION_BLUR_DIR + MOTION_BLUR_RINT_MAGIC) - as_int(MOTION_BLUR_RINT_MAGIC);
    vstore16(lw | ((as_uint16(qx) & 0xffu) << 16) | (as_uint16(qy) << 24), 0,
             (__global uint *)(hv + 3 * n) + i0);   /* motion_blur_pack */
    vstore16(isinf(z) ? 0.0f : 1.0f / z, 0, iz + i0);
}

#endif /* MOTION_BLUR_LANES == 16 */

/* h, |h| key and 1/depth per pixel: 16 pixels of a row per work-item (x0 = 16 gid0; groups that
 * touch the left or right edge one pixel at a time: their neighbours clamp), or one (LANES 1) */
__kernel void motion_blur_prep(__global const float *restrict velocity,
                               __global const float *restrict depth,
                               __global float *restrict hv, __global float *restrict iz,
                               const int width, const int height, const float k)
{
#if MOTION_BLUR_LANES == 16
    const int x0 = get_global_id(0) * 16, y = get_global_id(1);
    if (x0 >= width || y >= height) return;
    if (x0 >= 1 && x0 + 16 < width) {
        motion_blur_prep_16(velocity, depth, hv, iz, x0, y, width, height, k);
    } else {
        for (int x = x0; x < min(x0 + 16, width); ++x)
            motion_blur_prep_px(velocity, depth, hv, iz, x, y, width, height, k);
    }
#else
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    motion_blur_prep_px(velocity, depth, hv, iz, x, y, width, height, k);
#endif
}

/* largest half-vector (by length; first in scan order on ties) of each K x K tile */
__kernel void motion_blur_tilemax(__global const float *restrict hv, __global float *restrict tile,
                                  const int width, const int height, const int tw, const int th)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    const size_t n = (size_t)width * (size_t)height;
    float2 best = (float2)(0.0f, 0.0f);
    float best2 = 0.0f;   /* the unclamped length of best */
    const int y1 = min(ty * MOTION_BLUR_TILE + MOTION_BLUR_TILE, height);
    const int x1 = min(tx * MOTION_BLUR_TILE + MOTION_BLUR_TILE, width);
    for (int y = ty * MOTION_BLUR_TILE; y < y1; ++y) {
        for (int x = tx * MOTION_BLUR_TILE; x < x1; ++x) {
            const size_t i = (size_t)y * (size_t)width + (size_t)x;
            const float l = hv[2 * n + i];
            if (l > best2) { best2 = l; best = (float2)(hv[i], hv[n + i]); }
        }
    }
    const size_t t = (size_t)ty * (size_t)tw + (size_t)tx;
    const size_t tn = (size_t)tw * (size_t)th;
    tile[t] = best.x;
    tile[tn + t] = best.y;
    tile[2 * tn + t] = best2;
}

/* largest tile half-vector in the 3 x 3 tile neighbourhood (scan order on ties) */
__kernel void motion_blur_neighbormax(__global const float *restrict tile, __global float *restrict nmax,
                                      const int tw, const int th)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    const size_t tn = (size_t)tw * (size_t)th;
    float2 best = (float2)(0.0f, 0.0f);
    float best2 = 0.0f;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            const int sx = tx + dx, sy = ty + dy;
            if (sx < 0 || sy < 0 || sx >= tw || sy >= th) continue;
            const size_t t = (size_t)sy * (size_t)tw + (size_t)sx;
            const float l = tile[2 * tn + t];
            if (l > best2) { best2 = l; best = (float2)(tile[t], tile[tn + t]); }
        }
    }
    const size_t t = (size_t)ty * (size_t)tw + (size_t)tx;
    nmax[t] = best.x;
    nmax[tn + t] = best.y;
}

/* 1 within a streak of half-length len, ramping to 0 over len -/+ half a pixel (a surface pixel
 * swept over +-len overlaps X's pixel partly up to half a pixel beyond): 1 - smoothstep(len - 1/2,
 * len + 1/2, dist), its unit width written out (no division) */
inline float motion_blur_cylinder(float dist, float len) {
    const float t = clamp(dist - len + MOTION_BLUR_FOOT, 0.0f, 1.0f);
    return 1.0f - t * t * (3.0f - 2.0f * t);
}

/* weight that a surface of inverse depth wa is in front of one of inverse depth wb:
 * 1 when nearer or equal, 0 when farther by more than MOTION_BLUR_SOFT_Z (relative) */
inline float motion_blur_front(float wa, float wb) {
    const float m = fmax(fmax(wa, wb), 1e-30f);
    return clamp(1.0f - (wb - wa) / (MOTION_BLUR_SOFT_Z * m), 0.0f, 1.0f);
}

/* Taps per pixel from the length of v_N (its tile's neighbour max; <= K, so no int overflow): the
 * S strata of the path 2|v_N| are 2|v_N|/S px apart, so more than 2 ceil(DENSITY |v_N|) + 1 of them
 * only resample the same pixels. Odd, at most MOTION_BLUR_SAMPLES (the quality's S_q); the same
 * integer in the float16 form. */
inline int motion_blur_taps(const float ln, const int cap) {
    return min(cap, 2 * (int)ceil(MOTION_BLUR_DENSITY * ln) + 1);
}

/* The frame's tap cap (one work-item): the quality's S_q times the share of tiles that run the
 * gather at all (|v_N| > 0.5 px), rounded down to odd, within [S_q, MOTION_BLUR_SAMPLES_MAX]: a frame
 * whose motion covers few tiles spends the taps its still tiles leave on its moving ones, bounded
 * by what a frame moving everywhere costs at S_q. */
__kernel void motion_blur_budget(__global const float *restrict nmax, __global int *restrict cap,
                                 const int tw, const int th)
{
    if (get_global_id(0) != 0) return;
    const int tn = tw * th;
    int moving = 0;
    for (int t = 0; t < tn; ++t)
        moving += motion_blur_len2((float2)(nmax[t], nmax[tn + t])) > 0.25f ? 1 : 0;
    int c = moving > 0 ? (MOTION_BLUR_SAMPLES * tn) / moving : MOTION_BLUR_SAMPLES;
    c = clamp(c, MOTION_BLUR_SAMPLES, MOTION_BLUR_SAMPLES_MAX);
    cap[0] = c - (1 - (c & 1));   /* odd (S_q and the maximum are odd) */
}

/* One pixel (every pixel with MOTION_BLUR_LANES 1, else the row's last 1-15 of the kernel below); motion_blur_16 is the same
 * arithmetic in 16 lanes. */
inline void motion_blur_px(__global const float *restrict src, __global float *restrict dst,
                           __global const float *restrict hv, __global const float *restrict iz,
                           __global const float *restrict nmax, const int cap, const int x, const int y,
                           const int width, const int height, const int tw, const int th,
                           const uint seed, const uint frame)
{
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
    const size_t tn = (size_t)tw * (size_t)th;
    const size_t t = (size_t)(y / MOTION_BLUR_TILE) * (size_t)tw + (size_t)(x / MOTION_BLUR_TILE);
    const float2 vn = (float2)(nmax[t], nmax[tn + t]);
    const float3 cx = load_planar(src, i, n);
    if (motion_blur_len2(vn) <= 0.25f) {          /* nothing in reach moves by half a pixel */
        store_planar(dst, i, n, cx);
        return;
    }
    const float2 hx = (float2)(hv[i], hv[n + i]);
    const float lhx = sqrt(motion_blur_len2(hx));
    const float lx = fmax(lhx, 0.5f);
    const float2 vx = lhx > 0.5f ? hx : vn;        /* odd taps follow X's own motion */
    const float ln = sqrt(motion_blur_len2(vn));
    const float lv = sqrt(motion_blur_len2(vx));
    /* where X's own motion leaves v_N's direction, the tap sets split the work: odd taps (on X's
     * path) carry X's own surface, even taps (on v_N) the surfaces in front of X */
    const float rln = 1.0f / fmax(ln, 1e-30f), rlv = 1.0f / fmax(lv, 1e-30f);
    const float cosang = (vn.x * vx.x + vn.y * vx.y) * (rln * rlv);
    const float agree = clamp((cosang - MOTION_BLUR_AGREE0) / (MOTION_BLUR_AGREE1 - MOTION_BLUR_AGREE0), 0.0f, 1.0f);
    const float wx = iz[i];
    const float wx0 = fmax(wx, 1e-30f);   /* fmax(fmax(wx, wy), 1e-30) = fmax(wx0, wy) */
    const float j = motion_blur_jitter(seed, frame, x, y);
    /* taps of this pixel (motion_blur_taps), strata <= 1 / MOTION_BLUR_DENSITY px apart */
    const int ns = motion_blur_taps(ln, cap);
    const float inv_s = 1.0f / (float)ns;
    /* the tap paths reach half a pixel beyond |v| (the swept pixel's footprint, see the cylinder) */
    const float pn = ln + MOTION_BLUR_FOOT, pv = lv + MOTION_BLUR_FOOT;
    const float2 dn = vn * (pn * rln), dv = vx * (pv * rlv);
    /* three layers: surfaces in front of X (coverage cf), X's own surface smeared along its path
     * (coverage co, X itself weighted wc), the background behind X (revealed as X moves away) */
    const float hdn = pn * inv_s, hdv = pv * inv_s;   /* half the path length per tap, per set */
    /* X's own point covers X for (its footprint: the centre stratum's path, at least the pixel)
     * over its streak 2 |h_X|: a static pixel (|h_X| <= 0.5) is its own surface all the time */
    const float wc = fmax(hdn + hdv, 1.0f) / (2.0f * lx);
    float cf = 0.0f, co = wc, wb = 1e-3f;
    float3 sf = (float3)(0.0f), so = cx * wc, sb = cx * wb;
    for (int s = 0; s < ns; ++s) {
        if (s == ns / 2) continue;   /* the centre stratum is X itself */
        const float2 dir = (s & 1) ? dv : dn;
        const float u = ((float)s + 0.5f + j) * inv_s;   /* S strata covering the whole path */
        const float tt = 2.0f * u - 1.0f;
        const float ox = dir.x * tt;
        const float oy = dir.y * tt;
        const int sx = clamp((int)floor((float)x + ox + 0.5f), 0, width - 1);
        const int sy = clamp((int)floor((float)y + oy + 0.5f), 0, height - 1);
        const size_t k = (size_t)sy * (size_t)width + (size_t)sx;
        const float ddx = (float)(sx - x), ddy = (float)(sy - y);
        const float d2 = ddx * ddx + ddy * ddy;
        const float dist = sqrt(d2);
        const uint rec = ((__global const uint *)(hv + 3 * n))[k];   /* Y's record: motion_blur_pack */
        const float ly = motion_blur_unpack_len(rec);   /* max(|h_Y|, 0.5) */
        const float wy = iz[k];
        /* soft depth test: f = Y in front of X, b = X in front of Y (motion_blur_front, one division) */
        /* one division for the three per-tap quotients (depth test, 1/|h_Y|, 1/max(d, 1)^2) */
        const float zden = MOTION_BLUR_SOFT_Z * fmax(wx0, wy);
        const float md2 = fmax(d2, 1.0f);
        const float lm = ly * md2;
        const float q = 1.0f / (zden * lm);
        const float r = (wx - wy) * (lm * q);
        const float f = clamp(1.0f - r, 0.0f, 1.0f);
        const float b = clamp(1.0f + r, 0.0f, 1.0f);
        /* Y's surface passes over X for (path length per tap) / (Y's streak 2 |h_Y|) of the shutter;
         * where the tap sets split, odd taps carry X's own surface and even taps what is in front.
         * Background estimate (ab): surfaces behind X, or level with it whose streak misses X,
         * weighted by 1 / max(d, 1)^2 (what is hidden behind X looks most like what is next to it) */
        const float cly = motion_blur_cylinder(dist, ly);
        const float rly = (zden * md2) * q;
        const float a = cly * ((s & 1) ? hdv : hdn) * rly;
        const float own = b * motion_blur_cylinder(dist, lx);   /* level with X and on X's path */
        /* a surface in front reaches X only along its own motion line, give or take its footprint
         * and a spinning object's spread of directions: |d x e_Y| (e_Y = h_Y / |h_Y|) within LINE +- 1/2 px */
        const float eyx = (float)(as_int(rec << 8) >> 24), eyy = (float)(as_int(rec) >> 24);
        const float line = clamp(MOTION_BLUR_LINE + 0.5f - fabs(ddx * eyy - ddy * eyx) * (1.0f / MOTION_BLUR_DIR), 0.0f, 1.0f);
        const float af = line * f * (1.0f - own) * a * (agree + (1.0f - agree) * ((s & 1) ? 0.0f : 2.0f));
        const float ao = f * own * a * (agree + (1.0f - agree) * ((s & 1) ? 2.0f : 0.0f));
        const float ab = b * ((1.0f - f) + f * (1.0f - cly)) * motion_blur_cylinder(dist, lx) * ((zden * ly) * q);
        const float3 cy = load_planar(src, k, n);
        /* the layer sums by fused multiply-adds (FP_CONTRACT is off for the tap positions): one
         * instruction each, and the same rounding in the 16-lane form */
        cf += af;
        sf = fma((float3)(af), cy, sf);
        co += ao;
        so = fma((float3)(ao), cy, so);
        wb += ab;
        sb = fma((float3)(ab), cy, sb);
    }
    /* out = cf' F + (1 - cf') [co' O + (1 - co') B], coverages clamped to 1, layer colours normalised
     * (co' O = so min(1/co, 1); one reciprocal per layer) */
    const float cfc = fmin(cf, 1.0f), ico = 1.0f / co;
    const float3 own = so * fmin(ico, 1.0f) + sb * ((1.0f - fmin(co, 1.0f)) * (1.0f / wb));
    const float3 fr = cf > 0.0f ? sf * (1.0f / cf) : cx;
    store_planar(dst, i, n, cfc * fr + (1.0f - cfc) * own);
}


#if MOTION_BLUR_LANES == 16
/* The gather on 16 consecutive pixels of a row (x0 .. x0 + 15), every lane the arithmetic of
 * motion_blur_px operation for operation (FP_CONTRACT OFF; the same roundings, so the same tap
 * positions): PoCL does not vectorise the one-pixel form (float3, sqrt, smoothstep, data-dependent
 * loads), explicit float16 compiles to 16-lane vector code. Taps are per-lane gathers. */
#define MB_GATHER(buf, k) CLP_GATHER16(buf, k)
inline float16 motion_blur_cyl16(const float16 dist, const float16 len) {
    const float16 t = clamp(dist - len + MOTION_BLUR_FOOT, 0.0f, 1.0f);
    return 1.0f - t * t * (3.0f - 2.0f * t);
}

/* motion_blur_px's line weight: |d x e_Y| from Y's record */
#define MB_LINE16 clamp(MOTION_BLUR_LINE + 0.5f - fabs(ddx * eyy - ddy * eyx) * (1.0f / MOTION_BLUR_DIR), 0.0f, 1.0f) *
/* one tap s of motion_blur_16 on all lanes where TAP (int16) is true; uses and updates its locals */
#define MB_TAP16(s, TAP) do { \
        const int odd = (s) & 1; \
        const float16 dx = odd ? dvx : dnx, dy = odd ? dvy : dny; \
        const float16 u = ((float)(s) + 0.5f + j) * inv_s; \
        const float16 tt = 2.0f * u - 1.0f; \
        const float16 ox = dx * tt; \
        const float16 oy = dy * tt; \
        const int16 sx = clamp(convert_int16(floor(xf + ox + 0.5f)), 0, width - 1); \
        const int16 sy = clamp(convert_int16(floor(yf + oy + 0.5f)), 0, height - 1); \
        const int16 k = sy * width + sx; \
        const float16 ddx = convert_float16(sx - xs), ddy = convert_float16(sy - y); \
        const float16 d2 = ddx * ddx + ddy * ddy; \
        const float16 dist = sqrt(d2); \
        const uint16 rec = CLP_GATHER16U((__global const uint *)(hv + 3 * n), k);   /* Y's record */ \
        const float16 ly = as_float16(((rec << 16) >> 3) + 0x3f000000u);   /* motion_blur_unpack_len */ \
        const float16 eyx = convert_float16(as_int16(rec << 8) >> 24), eyy = convert_float16(as_int16(rec) >> 24); \
        const float16 wy = MB_GATHER(iz, k); \
        const float16 zden = MOTION_BLUR_SOFT_Z * fmax(wx0, wy); \
        const float16 md2 = fmax(d2, 1.0f); \
        const float16 lm = ly * md2; \
        const float16 q = 1.0f / (zden * lm); \
        const float16 r = (wx - wy) * (lm * q); \
        const float16 f = clamp(1.0f - r, 0.0f, 1.0f); \
        const float16 b = clamp(1.0f + r, 0.0f, 1.0f); \
        const float16 cly = motion_blur_cyl16(dist, ly); \
        const float16 rly = (zden * md2) * q; \
        const float16 a = cly * (odd ? hdv : hdn) * rly; \
        const float16 clx = motion_blur_cyl16(dist, lx); \
        const float16 own = b * clx; \
        const float16 af0 = MB_LINE16 f * (1.0f - own) * a * (agree + (1.0f - agree) * (odd ? 0.0f : 2.0f)); \
        const float16 ao0 = f * own * a * (agree + (1.0f - agree) * (odd ? 2.0f : 0.0f)); \
        const float16 ab0 = b * ((1.0f - f) + f * (1.0f - cly)) * clx * ((zden * ly) * q); \
        const int16 tap = (TAP);   /* lanes past their own S or at their centre: nothing */ \
        const float16 af = tap ? af0 : 0.0f, ao = tap ? ao0 : 0.0f, ab = tap ? ab0 : 0.0f; \
        const float16 cr = MB_GATHER(src, k), cg = MB_GATHER(src + n, k), cb = MB_GATHER(src + 2 * n, k); \
        cf += af; sfr = fma(af, cr, sfr); sfg = fma(af, cg, sfg); sfb = fma(af, cb, sfb); \
        co += ao; sor = fma(ao, cr, sor); sog = fma(ao, cg, sog); sob = fma(ao, cb, sob); \
        wb += ab; sbr = fma(ab, cr, sbr); sbg = fma(ab, cg, sbg); sbb = fma(ab, cb, sbb); \
    } while (0)

/* motion_blur_16's taps 0 .. N - 1 (N its lanes' largest S): masks only where the lanes' S differ */
#define MB_LOOP16(N) do { \
        if (smin == (N)) { \
            for (int s = 0; s < (N); ++s) { \
                if (s == (N) / 2) continue;   /* the centre stratum is X itself */ \
                MB_TAP16(s, (int16)(-1)); \
            } \
        } else { \
            for (int s = 0; s < (N); ++s) MB_TAP16(s, (int16)s < ns && (int16)s != nc); \
        } \
    } while (0)

inline void motion_blur_16(__global const float *restrict src, __global float *restrict dst,
                           __global const float *restrict hv, __global const float *restrict iz,
                           __global const float *restrict nmax, const int cap, const int x0, const int y,
                           const int width, const int height, const int tw, const int th,
                           const uint seed, const uint frame)
{
    const size_t n = (size_t)width * (size_t)height;
    const size_t i0 = (size_t)y * (size_t)width + (size_t)x0;
    const size_t tn = (size_t)tw * (size_t)th;
    const int16 xs = (int16)(x0) + convert_int16(CLP_ULANES16);
    /* v_N: the 16 pixels span at most two tiles, t0 (lane 0's) and t0 + 1: two scalar loads each, not gathers */
    const int t0 = (y / MOTION_BLUR_TILE) * tw + x0 / MOTION_BLUR_TILE;
    const int16 second = xs / MOTION_BLUR_TILE != (int16)(x0 / MOTION_BLUR_TILE);
    const int t1 = min(t0 + 1, (y / MOTION_BLUR_TILE) * tw + (x0 + 15) / MOTION_BLUR_TILE);
    const float16 vnx = second ? (float16)nmax[t1] : (float16)nmax[t0];
    const float16 vny = second ? (float16)nmax[tn + t1] : (float16)nmax[tn + t0];
    const float16 cxr = vload16(0, src + i0), cxg = vload16(0, src + n + i0), cxb = vload16(0, src + 2 * n + i0);
    const float16 l2n = vnx * vnx + vny * vny;
    const int16 still = l2n <= 0.25f;             /* nothing in reach moves by half a pixel */
    if (all(still)) {
        vstore16(cxr, 0, dst + i0); vstore16(cxg, 0, dst + n + i0); vstore16(cxb, 0, dst + 2 * n + i0);
        return;
    }
    const float16 hx = vload16(0, hv + i0), hy = vload16(0, hv + n + i0);
    const float16 lhx = sqrt(hx * hx + hy * hy);
    const float16 lx = fmax(lhx, 0.5f);
    const int16 own_dir = lhx > 0.5f;
    const float16 vxx = own_dir ? hx : vnx, vxy = own_dir ? hy : vny;   /* odd taps follow X's own motion */
    const float16 ln = sqrt(l2n);
    const float16 lv = sqrt(vxx * vxx + vxy * vxy);
    const float16 rln = 1.0f / fmax(ln, 1e-30f), rlv = 1.0f / fmax(lv, 1e-30f);
    const float16 cosang = (vnx * vxx + vny * vxy) * (rln * rlv);
    const float16 agree = clamp((cosang - MOTION_BLUR_AGREE0) / (MOTION_BLUR_AGREE1 - MOTION_BLUR_AGREE0), 0.0f, 1.0f);
    const float16 wx = vload16(0, iz + i0);
    const float16 wx0 = fmax(wx, 1e-30f);   /* fmax(fmax(wx, wy), 1e-30) = fmax(wx0, wy) */
    /* motion_blur_jitter */
    const float j0 = (float)(rnd_hash4(seed, frame, 0u, 0u) >> 8) * (1.0f / 16777216.0f);
    const float16 ja = convert_float16(xs) * MOTION_BLUR_R2X;
    const float jb = (float)y * MOTION_BLUR_R2Y;
    const float16 jv = (ja - floor(ja)) + (jb - floor(jb)) + j0;
    const float16 j = jv - floor(jv) - 0.5f;
    /* motion_blur_taps per lane; the loop runs to the largest (a 16-pixel row spans at most two
     * tiles), lanes past their own S or at their own centre stratum add nothing */
    const int16 ns = min((int16)cap, 2 * convert_int16(ceil(MOTION_BLUR_DENSITY * ln)) + 1);
    const int16 nc = ns / 2;
    const float16 inv_s = 1.0f / convert_float16(ns);
    const int8 m8 = max(ns.lo, ns.hi);
    const int4 m4 = max(m8.lo, m8.hi);
    const int2 m2 = max(m4.lo, m4.hi);
    const int smax = max(m2.x, m2.y);
    const int8 n8 = min(ns.lo, ns.hi);
    const int4 n4 = min(n8.lo, n8.hi);
    const int2 n2 = min(n4.lo, n4.hi);
    const int smin = min(n2.x, n2.y);
    const float16 pn = ln + MOTION_BLUR_FOOT, pv = lv + MOTION_BLUR_FOOT;   /* paths reach half a pixel beyond |v| */
    const float16 sn = pn * rln, sv = pv * rlv;
    const float16 dnx = vnx * sn, dny = vny * sn, dvx = vxx * sv, dvy = vxy * sv;
    const float16 hdn = pn * inv_s, hdv = pv * inv_s;
    const float16 wc = fmax(hdn + hdv, 1.0f) / (2.0f * lx);
    const float16 xf = convert_float16(xs), yf = (float16)((float)y);
    float16 cf = 0.0f, co = wc, wb = 1e-3f;
    float16 sfr = 0.0f, sfg = 0.0f, sfb = 0.0f;
    float16 sor = cxr * wc, sog = cxg * wc, sob = cxb * wc;
    float16 sbr = cxr * wb, sbg = cxg * wb, sbb = cxb * wb;
    /* loops of a constant length (unrolled, odd/even and the centre resolved at compile time): the
     * group's largest S; unmasked when every lane takes that S */
    switch (smax) {
#if MOTION_BLUR_SAMPLES_MAX >= 3
    case 3: MB_LOOP16(3); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 5
    case 5: MB_LOOP16(5); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 7
    case 7: MB_LOOP16(7); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 9
    case 9: MB_LOOP16(9); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 11
    case 11: MB_LOOP16(11); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 13
    case 13: MB_LOOP16(13); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 15
    case 15: MB_LOOP16(15); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 17
    case 17: MB_LOOP16(17); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 19
    case 19: MB_LOOP16(19); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 21
    case 21: MB_LOOP16(21); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 23
    case 23: MB_LOOP16(23); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 25
    case 25: MB_LOOP16(25); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 27
    case 27: MB_LOOP16(27); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 29
    case 29: MB_LOOP16(29); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 31
    case 31: MB_LOOP16(31); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 33
    case 33: MB_LOOP16(33); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 35
    case 35: MB_LOOP16(35); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 37
    case 37: MB_LOOP16(37); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 39
    case 39: MB_LOOP16(39); break;
#endif
#if MOTION_BLUR_SAMPLES_MAX >= 41
    case 41: MB_LOOP16(41); break;
#endif
    default: break;   /* S = 1: the centre only (|v_N| = 0, a still pixel) */
    }
    const float16 cfc = fmin(cf, 1.0f), ico = 1.0f / co;
    const int16 front = cf > 0.0f;
    const float16 ao = fmin(ico, 1.0f), ab = (1.0f - fmin(co, 1.0f)) * (1.0f / wb), af = 1.0f / cf;
    const float16 our = sor * ao + sbr * ab, oug = sog * ao + sbg * ab, oub = sob * ao + sbb * ab;
    const float16 frr = front ? sfr * af : cxr, frg = front ? sfg * af : cxg, frb = front ? sfb * af : cxb;
    vstore16(still ? cxr : cfc * frr + (1.0f - cfc) * our, 0, dst + i0);
    vstore16(still ? cxg : cfc * frg + (1.0f - cfc) * oug, 0, dst + n + i0);
    vstore16(still ? cxb : cfc * frb + (1.0f - cfc) * oub, 0, dst + 2 * n + i0);
}

#endif /* MOTION_BLUR_LANES == 16 */

/* 16 pixels of a row per work-item (x0 = 16 gid0; the row's last 1-15 one by one), or one (LANES 1) */
__kernel void motion_blur(__global const float *restrict src, __global float *restrict dst,
                          __global const float *restrict hv, __global const float *restrict iz,
                          __global const float *restrict nmax, __global const int *restrict caps,
                          const int width, const int height, const int tw, const int th,
                          const uint seed, const uint frame)
{
    const int cap = caps[0];   /* motion_blur_budget */
#if MOTION_BLUR_LANES == 16
    const int x0 = get_global_id(0) * 16, y = get_global_id(1);
    if (x0 >= width || y >= height) return;
    if (x0 + 16 <= width) {
        motion_blur_16(src, dst, hv, iz, nmax, cap, x0, y, width, height, tw, th, seed, frame);
    } else {
        for (int x = x0; x < width; ++x)
            motion_blur_px(src, dst, hv, iz, nmax, cap, x, y, width, height, tw, th, seed, frame);
    }
#else
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    motion_blur_px(src, dst, hv, iz, nmax, cap, x, y, width, height, tw, th, seed, frame);
#endif
}

/* rolling shutter: row y is exposed tau_y = r (y/(H-1) - 1/2) frames after the frame time, so it
 * shows the surface that moved there: q = p - v(q) tau_y (3 fixed-point steps, v at the nearest
 * pixel), bilinear with clamp to edge. */
__kernel void motion_blur_rolling(__global const float *restrict src, __global float *restrict dst,
                                  __global const float *restrict velocity,
                                  const int width, const int height, const float r)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * (size_t)height;
    const size_t i = (size_t)y * (size_t)width + (size_t)x;
    const float tau = height > 1 ? r * ((float)y / (float)(height - 1) - 0.5f) : 0.0f;
    float qx = (float)x, qy = (float)y;
    for (int it = 0; it < 3; ++it) {
        const int nx = clamp((int)floor(qx + 0.5f), 0, width - 1);
        const int ny = clamp((int)floor(qy + 0.5f), 0, height - 1);
        const size_t k = (size_t)ny * (size_t)width + (size_t)nx;
        const float dx = velocity[2 * k] * tau;
        const float dy = velocity[2 * k + 1] * tau;
        qx = clamp((float)x - dx, 0.0f, (float)(width - 1));
        qy = clamp((float)y - dy, 0.0f, (float)(height - 1));
    }
    const int x0 = min((int)floor(qx), width - 1), y0 = min((int)floor(qy), height - 1);
    const int x1 = min(x0 + 1, width - 1), y1 = min(y0 + 1, height - 1);
    const float fx = qx - (float)x0, fy = qy - (float)y0;
    const float3 c00 = load_planar(src, (size_t)y0 * width + x0, n);
    const float3 c10 = load_planar(src, (size_t)y0 * width + x1, n);
    const float3 c01 = load_planar(src, (size_t)y1 * width + x0, n);
    const float3 c11 = load_planar(src, (size_t)y1 * width + x1, n);
    const float3 top = c00 * (1.0f - fx) + c10 * fx;
    const float3 bot = c01 * (1.0f - fx) + c11 * fx;
    store_planar(dst, i, n, top * (1.0f - fy) + bot * fy);
}
