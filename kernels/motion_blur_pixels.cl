/* motion_blur's per-pixel math, written once for CLP_W pixels of a row (the width-generic macros
 * of clpost/codegen.py: CLP_F float or float16, CLP_FN(name) name or name_w16). The stage
 * instantiates this file twice before kernels/motion_blur.cl: at one pixel (plain names: a GPU's
 * one pixel per work-item, and the row edges of the CPU form) and at 16 (explicit float16 rows, a
 * CPU's SIMD lanes: PoCL vectorises neither the one-pixel prep nor the gather). Both widths run
 * the same float operations in the same order (FP_CONTRACT OFF), so they give the same image bit
 * for bit (tests/test_motion_blur.py). Formulas: clpost/stages/motion_blur.py (its reference() is
 * the oracle); buffers and defines: kernels/motion_blur.cl.
 */
#pragma OPENCL FP_CONTRACT OFF
/* FP_CONTRACT OFF: no a*b+c fusion, so tap positions round exactly as in the numpy reference. */

/* The model's constants come from the stage's defines() (clpost/stages/motion_blur.py, one place):
 * MOTION_BLUR_SOFT_Z, FOOT, AGREE0, AGREE1, DIFFER2, DIR, LINE, FRINGE2 and the jitter's R2X, R2Y. */
#ifndef MOTION_BLUR_RINT_MAGIC
#define MOTION_BLUR_RINT_MAGIC 12582912.0f   /* 1.5 * 2^23: x + this rounds x (|x| < 2^22) to an integer */
#endif

/* a row of CLP_W floats at buf + i (i the first pixel's index) */
#if CLP_W == 1
#define MB_LOAD(buf, i) ((buf)[i])
#define MB_STORE(v, buf, i) ((buf)[i] = (v))
#else
#define MB_LOAD(buf, i) vload16(0, (buf) + (i))
#define MB_STORE(v, buf, i) vstore16((v), 0, (buf) + (i))
#endif

inline CLP_F CLP_FN(motion_blur_len2)(const CLP_F x, const CLP_F y) {
    const CLP_F a = x * x;
    const CLP_F b = y * y;
    return a + b;
}

/* j in [-0.5, 0.5) at column xf of row y: a per-frame offset from the counter hash of (seed, frame)
 * of kernels/random.cl (CONVENTIONS "Randomness"; 24 high bits, exact in float) plus the R2 lattice
 * frac(x a1 + y a2): neighbouring pixels take well-spread strata (blue-noise-like), so the few
 * taps' noise is fine-grained; each fraction taken before the sum keeps float32 exact enough */
inline CLP_F CLP_FN(motion_blur_jitter)(const uint seed, const uint frame, const CLP_F xf, const int y) {
    const float j0 = (float)(rnd_hash4(seed, frame, 0u, 0u) >> 8) * (1.0f / 16777216.0f);
    const CLP_F a = xf * MOTION_BLUR_R2X;
    const float b = (float)y * MOTION_BLUR_R2Y;
    const CLP_F v = (a - floor(a)) + (b - floor(b)) + j0;
    return v - floor(v) - 0.5f;
}

/* What a tap reads of Y, one word (tap_records in the .py): l = max(|h|, 0.5) in the low 16 bits as a
 * float with a 10-bit mantissa (its bits from 0.5 up, rounded half up: relative step 2^-10, l <= K
 * = 20 px fits), h's unit direction (ex, ey) in the high two bytes, each a signed count of 1/127
 * (x, then y; rounded to nearest even as numpy's rint, by adding 1.5 * 2^23: PoCL expands
 * convert_int16_rte lane by lane, docs/motion_blur.md). l decodes with two integer operations and
 * no square root; the direction only places X against Y's motion line, where 1/127 is < 0.2 px at 21 px. */
inline CLP_U CLP_FN(motion_blur_pack)(const CLP_F l, const CLP_F ex, const CLP_F ey) {
    const CLP_U lw = (CLP_AS_U(l) + 0x1000u - 0x3f000000u) >> 13;
    const CLP_I qx = CLP_AS_I(ex * MOTION_BLUR_DIR + MOTION_BLUR_RINT_MAGIC) - as_int(MOTION_BLUR_RINT_MAGIC);
    const CLP_I qy = CLP_AS_I(ey * MOTION_BLUR_DIR + MOTION_BLUR_RINT_MAGIC) - as_int(MOTION_BLUR_RINT_MAGIC);
    return lw | ((CLP_AS_U(qx) & 0xffu) << 16) | (CLP_AS_U(qy) << 24);
}

inline CLP_F CLP_FN(motion_blur_unpack_len)(const CLP_U w) {
    return CLP_AS_F(((w << 16) >> 3) + 0x3f000000u);
}

/* 1 within a streak of half-length len, ramping to 0 over len -/+ half a pixel (a surface pixel
 * swept over +-len overlaps X's pixel partly up to half a pixel beyond): 1 - smoothstep(len - 1/2,
 * len + 1/2, dist), its unit width written out (no division) */
inline CLP_F CLP_FN(motion_blur_cylinder)(const CLP_F dist, const CLP_F len) {
    const CLP_F t = clamp(dist - len + MOTION_BLUR_FOOT, 0.0f, 1.0f);
    return 1.0f - t * t * (3.0f - 2.0f * t);
}

/* Taps per pixel from the length of v_N (its tile's neighbour max; <= K, so no int overflow): the
 * S strata of the path 2|v_N| are 2|v_N|/S px apart, so more than 2 ceil(DENSITY |v_N|) + 1 of them
 * only resample the same pixels. Odd, at most cap (the frame's, motion_blur_budget). */
inline CLP_I CLP_FN(motion_blur_taps)(const CLP_F ln, const int cap) {
    return min((CLP_I)cap, 2 * CLP_TO_I(ceil(MOTION_BLUR_DENSITY * ln)) + 1);
}

/* The prep of pixels x0 .. x0 + CLP_W - 1 of row y (the gather, below, needs): half-vector
 * h = v * k (k = shutter fraction / 2), clamped to |h| <= K keeping its direction, its unclamped
 * length (the key TileMax ranks by), the tap record (motion_blur_pack), and the inverse depth for
 * the soft depth test (0 for the sky, so no inf - inf).
 * Fringe rule first: renderers average the vector over the pixel filter but point-sample depth, so
 * an anti-aliased edge pixel carries a fraction of the moving surface's velocity. A pixel whose
 * speed is > MOTION_BLUR_FRINGE times the fastest of its 3 x 3 neighbours (first in scan order on
 * ties) takes that neighbour's velocity and depth: its colour is (partly) that surface's.
 * Neighbours clamp to the image; at 16 pixels the caller keeps the row inside (x0 - 1 >= 0,
 * x0 + 16 < width): neighbours are row loads at offsets -1, 0, +1 (velocity interleaved: the
 * even/odd lanes of 32 floats). */
inline void CLP_FN(motion_blur_prep_pixels)(__global const float *restrict velocity,
                                     __global const float *restrict depth,
                                     __global float *restrict hv, __global float *restrict iz,
                                     const int x0, const int y, const int width, const int height, const float k)
{
    const size_t n = (size_t)width * (size_t)height;
    const size_t i0 = (size_t)y * (size_t)width + (size_t)x0;
#if CLP_W == 1
#define MB_VEL(j, c) (velocity[2 * (j) + (c)])
#define MB_COL(dx) clamp(x0 + (dx), 0, width - 1)
#else
#define MB_VEL(j, c) ((c) ? (float16)(vload16(0, velocity + 2 * (j)).odd, vload16(1, velocity + 2 * (j)).odd) \
                          : (float16)(vload16(0, velocity + 2 * (j)).even, vload16(1, velocity + 2 * (j)).even))
#define MB_COL(dx) (x0 + (dx))
#endif
    CLP_F vx = MB_VEL(i0, 0), vy = MB_VEL(i0, 1);
    CLP_F z = MB_LOAD(depth, i0);
    const CLP_F own2 = CLP_FN(motion_blur_len2)(vx, vy);
    CLP_F best2 = own2, bx = vx, by = vy, bz = z;
    for (int dy = -1; dy <= 1; ++dy) {
        const int sy = clamp(y + dy, 0, height - 1);
        for (int dx = -1; dx <= 1; ++dx) {
            const size_t j = (size_t)sy * (size_t)width + (size_t)MB_COL(dx);
            const CLP_F nx = MB_VEL(j, 0), ny = MB_VEL(j, 1);
            const CLP_F s2 = CLP_FN(motion_blur_len2)(nx, ny);
            const CLP_I m = s2 > best2;
            best2 = m ? s2 : best2;
            bx = m ? nx : bx;
            by = m ? ny : by;
            bz = m ? MB_LOAD(depth, j) : bz;
        }
    }
#undef MB_VEL
#undef MB_COL
    const CLP_I take = own2 > 0.0f && own2 > MOTION_BLUR_FRINGE2 * best2;
    vx = take ? bx : vx;
    vy = take ? by : vy;
    z = take ? bz : z;
    /* scale by the inf-norm first: |v| up to FLT_MAX never overflows to inf */
    const CLP_F m = fmax(fabs(vx), fabs(vy));
    const CLP_I moving = m > 0.0f;
    const CLP_F ux = vx / m, uy = vy / m;                    /* inf-norm 1 */
    const CLP_F lu = sqrt(CLP_FN(motion_blur_len2)(ux, uy));
    const CLP_F len = lu * m * k;                            /* unclamped |h| (inf only beyond FLT_MAX) */
    const CLP_F r = fmin(len, (float)MOTION_BLUR_TILE);
    const CLP_F rlu = 1.0f / lu;
    const CLP_F ex = moving ? ux * rlu : 0.0f, ey = moving ? uy * rlu : 0.0f;   /* h's direction */
    MB_STORE(moving ? ex * r : 0.0f, hv, i0);
    MB_STORE(moving ? ey * r : 0.0f, hv + n, i0);
    MB_STORE(moving ? len : 0.0f, hv + 2 * n, i0);
    /* a tap loads Y's length and direction at once */
    MB_STORE(CLP_FN(motion_blur_pack)(fmax(moving ? r : 0.0f, 0.5f), ex, ey), (__global uint *)(hv + 3 * n), i0);
    MB_STORE(isinf(z) ? 0.0f : 1.0f / z, iz, i0);
}

/* One tap s of the gather on the pixels where TAP (a CLP_I, or 1) is true; uses and updates the
 * locals of motion_blur_gather. SPLIT (a constant): the odd taps' front sums apart (cfo, sfo*) and
 * the front set weights wfo, wfe, for runs where a pixel has a second direction; else every tap's in
 * cf, sf*, weighted by agree, agree2 (what wfo, wfe are without one, exactly: the loop keeps two
 * float16 fewer live, which spilled on the common path). */
#define MB_TAP(s, TAP, SPLIT) do { \
        const int odd = (s) & 1; \
        const CLP_F dx = odd ? dvx : dnx, dy = odd ? dvy : dny; \
        const CLP_F u = ((float)(s) + 0.5f + j) * inv_s;   /* S strata covering the whole path */ \
        const CLP_F tt = 2.0f * u - 1.0f; \
        const CLP_F ox = dx * tt; \
        const CLP_F oy = dy * tt; \
        /* the nearest pixel, floor(p + 1/2) clamped to the image, as truncation: the same for p + 1/2 >= 0, \
         * and every p + 1/2 < 0 clamps to 0 either way (PoCL expands floor() to a dozen operations) */ \
        const CLP_I sx = clamp(CLP_TO_I(xf + ox + 0.5f), 0, width - 1); \
        const CLP_I sy = clamp(CLP_TO_I(yf + oy + 0.5f), 0, height - 1); \
        const CLP_I k = sy * width + sx; \
        const CLP_F ddx = CLP_TO_F(sx - xs), ddy = CLP_TO_F(sy - y); \
        const CLP_F d2 = ddx * ddx + ddy * ddy; \
        const CLP_F dist = sqrt(d2); \
        const CLP_U rec = CLP_GATHERU((__global const uint *)(hv + 3 * n), k);   /* Y's record */ \
        const CLP_F ly = CLP_FN(motion_blur_unpack_len)(rec);   /* max(|h_Y|, 0.5) */ \
        const CLP_F eyx = CLP_TO_F(CLP_AS_I(rec << 8) >> 24), eyy = CLP_TO_F(CLP_AS_I(rec) >> 24); \
        const CLP_F wy = CLP_GATHER(iz, k); \
        /* soft depth test: f = Y in front of X, b = X in front of Y (1 when nearer or equal, 0 when \
         * farther by more than MOTION_BLUR_SOFT_Z relative); one division for the three per-tap \
         * quotients (depth test, 1/|h_Y|, 1/max(d, 1)^2) */ \
        const CLP_F zden = MOTION_BLUR_SOFT_Z * (wy > wx0 ? wy : wx0);   /* fmax(wx0, wy): wx0 is never NaN */ \
        const CLP_F md2 = fmax(d2, 1.0f); \
        const CLP_F lm = ly * md2; \
        const CLP_F q = 1.0f / (zden * lm); \
        const CLP_F r = (wx - wy) * (lm * q); \
        const CLP_F f = clamp(1.0f - r, 0.0f, 1.0f); \
        const CLP_F b = clamp(1.0f + r, 0.0f, 1.0f); \
        /* Y's surface passes over X for (path length per tap) / (Y's streak 2 |h_Y|) of the shutter; \
         * where the tap sets split, odd taps carry X's own surface and even taps what is in front. \
         * Background estimate (ab): surfaces behind X, or level with it whose streak misses X, \
         * weighted by 1 / max(d, 1)^2 (what is hidden behind X looks most like what is next to it) */ \
        const CLP_F cly = CLP_FN(motion_blur_cylinder)(dist, ly); \
        const CLP_F rly = (zden * md2) * q; \
        const CLP_F a = cly * (odd ? hdv : hdn) * rly; \
        const CLP_F clx = CLP_FN(motion_blur_cylinder)(dist, lx); \
        const CLP_F own = b * clx;   /* level with X and on X's path */ \
        /* a surface in front reaches X only along its own motion line, give or take its footprint \
         * and a spinning object's spread of directions: |d x e_Y| (e_Y = h_Y / |h_Y|) within LINE +- 1/2 px */ \
        const CLP_F line = clamp(MOTION_BLUR_LINE + 0.5f - fabs(ddx * eyy - ddy * eyx) * (1.0f / MOTION_BLUR_DIR), 0.0f, 1.0f); \
        const CLP_F af0 = line * f * (1.0f - own) * a * ((SPLIT) ? (odd ? wfo : wfe) : (odd ? agree : agree2)); \
        const CLP_F ao0 = f * own * a * (odd ? agree2 : agree); \
        const CLP_F aa0 = clx * clx * (odd ? kav : kan);   /* ao0 if Y were X (f = b = 1) */ \
        const CLP_F ab0 = b * ((1.0f - f) + f * (1.0f - cly)) * clx * ((zden * ly) * q); \
        const CLP_I tap = (TAP);   /* pixels past their own S or at their centre: nothing */ \
        const CLP_F af = tap ? af0 : 0.0f, ao = tap ? ao0 : 0.0f, ab = tap ? ab0 : 0.0f, aa = tap ? aa0 : 0.0f; \
        const CLP_F cr = CLP_GATHER(src, k), cg = CLP_GATHER(src + n, k), cb = CLP_GATHER(src + 2 * n, k); \
        /* the layer sums by fused multiply-adds (FP_CONTRACT is off for the tap positions): one \
         * instruction each, the same rounding at every width */ \
        if ((SPLIT) && odd) { cfo += af; sfor = fma(af, cr, sfor); sfog = fma(af, cg, sfog); sfob = fma(af, cb, sfob); } \
        else { cf += af; sfr = fma(af, cr, sfr); sfg = fma(af, cg, sfg); sfb = fma(af, cb, sfb); } \
        co += ao; sor = fma(ao, cr, sor); sog = fma(ao, cg, sog); sob = fma(ao, cb, sob); \
        ca += aa; \
        wb += ab; sbr = fma(ab, cr, sbr); sbg = fma(ab, cg, sbg); sbb = fma(ab, cb, sbb); \
    } while (0)

#if CLP_W == 16
/* the 16-pixel gather's taps 0 .. N - 1 (N its lanes' largest S): masks only where the lanes' S differ */
#define MB_LOOP16S(N, SPLIT) do { \
        if (smin == (N)) { \
            for (int s = 0; s < (N); ++s) { \
                if (s == (N) / 2) continue;   /* the centre stratum is X itself */ \
                MB_TAP(s, (int16)(-1), SPLIT); \
            } \
        } else { \
            for (int s = 0; s < (N); ++s) MB_TAP(s, (int16)s < ns && (int16)s != nc, SPLIT); \
        } \
    } while (0)
#define MB_LOOP16(N) do { if (split) MB_LOOP16S(N, 1); else MB_LOOP16S(N, 0); } while (0)
#endif

/* The gather of pixels x0 .. x0 + CLP_W - 1 of row y (x0 + CLP_W <= width), from motion_blur_gather
 * below: the pixels' second direction (v2x, v2y; 0 where none) and where they take it (use2); two,
 * a constant where it is inlined: 1 where a pixel of the run takes it (split sums, composite), 0
 * elsewhere (v2 and use2 then 0), which compiles the second direction's masks, weights and sums
 * out of the common path. Always inlined, into callers whose pointers are restrict (its own are not:
 * inlining restrict parameters leaves noalias scope intrinsics that Oclgrind 21.10 cannot run). */
inline __attribute__((always_inline)) void CLP_FN(motion_blur_gather_two)(
        __global const float *src, __global float *dst, __global const float *hv, __global const float *iz,
        __global const float *nmax, const int cap, const int x0, const int y,
        const int width, const int height, const int tw, const int th,
        const uint seed, const uint frame, const CLP_F v2x, const CLP_F v2y, const CLP_I use2, const int two)
{
    const size_t n = (size_t)width * (size_t)height;
    const size_t i0 = (size_t)y * (size_t)width + (size_t)x0;
    const size_t tn = (size_t)tw * (size_t)th;
#if CLP_W == 1
    const int xs = x0;
    const size_t t = (size_t)(y / MOTION_BLUR_TILE) * (size_t)tw + (size_t)(x0 / MOTION_BLUR_TILE);
    const float vnx = nmax[t], vny = nmax[tn + t];
    const float near2 = two ? nmax[4 * tn + t] : 0.0f;
#else
    const int16 xs = (int16)(x0) + convert_int16(CLP_ULANES16);
    /* v_N: the 16 pixels span at most two tiles, t0 (lane 0's) and t0 + 1: two scalar loads each, not gathers */
    const int t0 = (y / MOTION_BLUR_TILE) * tw + x0 / MOTION_BLUR_TILE;
    const int16 second = xs / MOTION_BLUR_TILE != (int16)(x0 / MOTION_BLUR_TILE);
    const int t1 = min(t0 + 1, (y / MOTION_BLUR_TILE) * tw + (x0 + 15) / MOTION_BLUR_TILE);
    const float16 vnx = second ? (float16)nmax[t1] : (float16)nmax[t0];
    const float16 vny = second ? (float16)nmax[tn + t1] : (float16)nmax[tn + t0];
    const float16 near2 = two ? (second ? (float16)nmax[4 * tn + t1] : (float16)nmax[4 * tn + t0]) : (float16)0.0f;
#endif
    const CLP_F cxr = MB_LOAD(src, i0), cxg = MB_LOAD(src + n, i0), cxb = MB_LOAD(src + 2 * n, i0);
    const CLP_F l2n = CLP_FN(motion_blur_len2)(vnx, vny);
    const CLP_I still = l2n <= 0.25f;             /* nothing in reach moves by half a pixel */
    if (!CLP_ANY(!still)) {
        MB_STORE(cxr, dst, i0); MB_STORE(cxg, dst + n, i0); MB_STORE(cxb, dst + 2 * n, i0);
        return;
    }
    const CLP_F hx = MB_LOAD(hv, i0), hy = MB_LOAD(hv + n, i0);
    const CLP_F lhx = sqrt(CLP_FN(motion_blur_len2)(hx, hy));
    const CLP_F lx = fmax(lhx, 0.5f);
    const CLP_I own_dir = lhx > 0.5f;
    const int split = two;   /* a pixel of the run has two directions: split sums, composite */
    const CLP_F vxx = own_dir ? hx : (use2 ? v2x : vnx), vxy = own_dir ? hy : (use2 ? v2y : vny);   /* odd taps follow X's own motion */
    const CLP_F ln = sqrt(l2n);
    const CLP_F lv = sqrt(CLP_FN(motion_blur_len2)(vxx, vxy));
    /* where X's own motion leaves v_N's direction, the tap sets split the work: odd taps (on X's
     * path) carry X's own surface, even taps (on v_N) the surfaces in front of X */
    const CLP_F rln = 1.0f / fmax(ln, 1e-30f), rlv = 1.0f / fmax(lv, 1e-30f);
    const CLP_F cosang = (vnx * vxx + vny * vxy) * (rln * rlv);
    const CLP_F agree0 = clamp((cosang - MOTION_BLUR_AGREE0) / (MOTION_BLUR_AGREE1 - MOTION_BLUR_AGREE0), 0.0f, 1.0f);
    /* two directions of a still X: no own path to split (agree 1). Written as arithmetic on u2 = 1 or 0:
     * Oclgrind 21.10 evaluates a vector select of a constant as inf */
    const CLP_F u2 = fabs(CLP_TO_F(use2));
    const CLP_F agree = two ? agree0 + u2 * (1.0f - agree0) : agree0;   /* the same where u2 = 0 */
    const CLP_F wx = MB_LOAD(iz, i0);
    const CLP_F wx0 = fmax(wx, 1e-30f);   /* fmax(fmax(wx, wy), 1e-30) = fmax(wx0, wy) */
    const CLP_F xf = CLP_TO_F(xs), yf = (CLP_F)((float)y);
    const CLP_F j = CLP_FN(motion_blur_jitter)(seed, frame, xf, y);
    /* taps of each pixel (motion_blur_taps), strata <= 1 / MOTION_BLUR_DENSITY px apart */
    const CLP_I ns = CLP_FN(motion_blur_taps)(ln, cap);
    const CLP_I nc = ns / 2;
    const CLP_F inv_s = 1.0f / CLP_TO_F(ns);
    /* the tap paths reach half a pixel beyond |v| (the swept pixel's footprint, see the cylinder) */
    const CLP_F pn = ln + MOTION_BLUR_FOOT, pv = lv + MOTION_BLUR_FOOT;
    const CLP_F sn = pn * rln, sv = pv * rlv;
    const CLP_F dnx = vnx * sn, dny = vny * sn, dvx = vxx * sv, dvy = vxy * sv;
    /* three layers: surfaces in front of X (coverage cf), X's own surface smeared along its path
     * (coverage co, X itself weighted wc), the background behind X (revealed as X moves away) */
    const CLP_F hdn = pn * inv_s, hdv = pv * inv_s;   /* half the path length per tap, per set */
    /* X's own point covers X for (its footprint: the centre stratum's path, at least the pixel)
     * over its streak 2 |h_X|: a static pixel (|h_X| <= 0.5) is its own surface all the time */
    const CLP_F wc = fmax(hdn + (own_dir ? hdv : hdn), 1.0f) / (2.0f * lx);
    CLP_F cf = 0.0f, co = wc, wb = 1e-3f;
    /* ca: what co would be if every tap were X's own surface (Y = X); the own layer's coverage is
     * the share co / ca of X's path (the taps' rounding cancels), per tap cyl(d, |h_X|)^2 times: */
    CLP_F ca = wc;
    const CLP_F rlx = 1.0f / lx;
    /* a set's weight where the sets split: agree + (1 - agree) 2 on the set that carries the layer,
     * agree (+ (1 - agree) 0, exactly) on the other */
    const CLP_F agree2 = agree + (1.0f - agree) * 2.0f;
    const CLP_F kan = hdn * agree * rlx, kav = hdv * agree2 * rlx;
    /* the front layer's set weights: with two directions each set alone estimates what reaches X
     * along its direction (weight 2 on both; composited nearer over farther below) */
    const CLP_F wfo = agree + u2 * (2.0f - agree), wfe = agree2 + u2 * (2.0f - agree2);
    CLP_F sfr = 0.0f, sfg = 0.0f, sfb = 0.0f;   /* front sums: even taps (cf, sf*), odd taps (cfo, sfo*) */
    CLP_F cfo = 0.0f, sfor = 0.0f, sfog = 0.0f, sfob = 0.0f;
    CLP_F sor = cxr * wc, sog = cxg * wc, sob = cxb * wc;
    CLP_F sbr = cxr * wb, sbg = cxg * wb, sbb = cxb * wb;
#if CLP_W == 1
    if (split) {
        for (int s = 0; s < ns; ++s) {
            if (s == nc) continue;   /* the centre stratum is X itself */
            MB_TAP(s, 1, 1);
        }
    } else {
        for (int s = 0; s < ns; ++s) {
            if (s == nc) continue;
            MB_TAP(s, 1, 0);
        }
    }
#else
    /* the loop runs to the largest S of the 16 pixels (a row of 16 spans at most two tiles), in
     * loops of a constant length (unrolled, odd/even and the centre resolved at compile time);
     * lanes past their own S or at their own centre stratum add nothing (unmasked when every lane
     * takes that S) */
    const int8 m8 = max(ns.lo, ns.hi);
    const int4 m4 = max(m8.lo, m8.hi);
    const int2 m2 = max(m4.lo, m4.hi);
    const int smax = max(m2.x, m2.y);
    const int8 n8 = min(ns.lo, ns.hi);
    const int4 n4 = min(n8.lo, n8.hi);
    const int2 n2 = min(n4.lo, n4.hi);
    const int smin = min(n2.x, n2.y);
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
#endif
    /* out = cf' F + (1 - cf') [co' O + (1 - co') B], cf' = min(cf, 1), co' = min(co / ca, 1), layer
     * colours normalised (co' O = so min(1/ca, 1/co); one reciprocal per layer) */
    /* the front layer: both sets' sums, or with two directions the nearer set's surface over the
     * farther's, c = c_n + (1 - c_n) c_f and c F = c_n F_n + (1 - c_n) c_f F_f (c_n, c_f clamped to 1;
     * only where some pixel of the run has a second direction) */
    /* (cfo, sfo* 0 unless split: + 0 leaves the sums, which start at +0, as they are) */
    CLP_F ct = two ? cf + cfo : cf, str = two ? sfr + sfor : sfr, stg = two ? sfg + sfog : sfg, stb = two ? sfb + sfob : sfb;
    if (split) {
        const CLP_I onear = near2 > 0.5f;
        const CLP_F cn = onear ? cfo : cf, cr_ = onear ? cf : cfo;
        const CLP_F cnc = fmin(cn, 1.0f), crc = fmin(cr_, 1.0f);
        const CLP_F rn = cnc * (1.0f / fmax(cn, 1e-30f)), rr = (1.0f - cnc) * crc * (1.0f / fmax(cr_, 1e-30f));
        const CLP_F s2r = (onear ? sfor : sfr) * rn + (onear ? sfr : sfor) * rr;
        const CLP_F s2g = (onear ? sfog : sfg) * rn + (onear ? sfg : sfog) * rr;
        const CLP_F s2b = (onear ? sfob : sfb) * rn + (onear ? sfb : sfob) * rr;
        ct = use2 ? cnc + (1.0f - cnc) * crc : ct;
        str = use2 ? s2r : str;
        stg = use2 ? s2g : stg;
        stb = use2 ? s2b : stb;
    }
    const CLP_F cfc = fmin(ct, 1.0f);
    const CLP_I front = ct > 0.0f;
    const CLP_F ao = fmin(1.0f / ca, 1.0f / co), ab = (1.0f - co * ao) * (1.0f / wb), af = 1.0f / ct;
    const CLP_F our = sor * ao + sbr * ab, oug = sog * ao + sbg * ab, oub = sob * ao + sbb * ab;
    const CLP_F frr = front ? str * af : cxr, frg = front ? stg * af : cxg, frb = front ? stb * af : cxb;
    MB_STORE(still ? cxr : cfc * frr + (1.0f - cfc) * our, dst, i0);
    MB_STORE(still ? cxg : cfc * frg + (1.0f - cfc) * oug, dst + n, i0);
    MB_STORE(still ? cxb : cfc * frb + (1.0f - cfc) * oub, dst + 2 * n, i0);
}

/* The gather of a run where a pixel takes a second direction (few runs of a frame): at 16 pixels a
 * call, not inlined, so the common path's code and registers stay as without it (docs/motion_blur.md,
 * "The second direction at the old cost") */
#if CLP_W == 16
__attribute__((noinline))
#else
inline
#endif
void CLP_FN(motion_blur_gather_split)(
        __global const float *restrict src, __global float *restrict dst,
        __global const float *restrict hv, __global const float *restrict iz,
        __global const float *restrict nmax, const int cap, const int x0, const int y,
        const int width, const int height, const int tw, const int th,
        const uint seed, const uint frame, const CLP_F v2x, const CLP_F v2y, const CLP_I use2)
{
    CLP_FN(motion_blur_gather_two)(src, dst, hv, iz, nmax, cap, x0, y, width, height, tw, th, seed, frame,
                                   v2x, v2y, use2, 1);
}

/* The gather of pixels x0 .. x0 + CLP_W - 1 of row y (x0 + CLP_W <= width). A still X (|h_X| <= 1/2)
 * whose neighbourhood holds a second surface moving another way (NeighborMax's planes 2, 3; the 16
 * pixels span tiles t0 and t1) sends its odd taps along that: no tap would look along it otherwise.
 * Runs where no pixel does (nearly all) take the gather without the second direction's work. */
inline void CLP_FN(motion_blur_gather)(__global const float *restrict src, __global float *restrict dst,
                                       __global const float *restrict hv, __global const float *restrict iz,
                                       __global const float *restrict nmax, const int cap, const int x0, const int y,
                                       const int width, const int height, const int tw, const int th,
                                       const uint seed, const uint frame)
{
    const size_t n = (size_t)width * (size_t)height;
    const size_t tn = (size_t)tw * (size_t)th;
    const int t0 = (y / MOTION_BLUR_TILE) * tw + x0 / MOTION_BLUR_TILE;
    const int t1 = (y / MOTION_BLUR_TILE) * tw + (x0 + CLP_W - 1) / MOTION_BLUR_TILE;
    CLP_F v2x = 0.0f, v2y = 0.0f;
    CLP_I use2 = 0;
    if (nmax[2 * tn + t0] != 0.0f || nmax[3 * tn + t0] != 0.0f || nmax[2 * tn + t1] != 0.0f || nmax[3 * tn + t1] != 0.0f) {
#if CLP_W == 1
        v2x = nmax[2 * tn + t0];
        v2y = nmax[3 * tn + t0];
#else
        const int16 second = ((int16)(x0) + convert_int16(CLP_ULANES16)) / MOTION_BLUR_TILE != (int16)(x0 / MOTION_BLUR_TILE);
        v2x = second ? (float16)nmax[2 * tn + t1] : (float16)nmax[2 * tn + t0];
        v2y = second ? (float16)nmax[3 * tn + t1] : (float16)nmax[3 * tn + t0];
#endif
        const size_t i0 = (size_t)y * (size_t)width + (size_t)x0;
        const CLP_F hx = MB_LOAD(hv, i0), hy = MB_LOAD(hv + n, i0);
        use2 = (sqrt(CLP_FN(motion_blur_len2)(hx, hy)) <= 0.5f) & (CLP_FN(motion_blur_len2)(v2x, v2y) > 0.0f);
    }
    if (CLP_ANY(use2))
        CLP_FN(motion_blur_gather_split)(src, dst, hv, iz, nmax, cap, x0, y, width, height, tw, th, seed, frame,
                                         v2x, v2y, use2);
    else
        CLP_FN(motion_blur_gather_two)(src, dst, hv, iz, nmax, cap, x0, y, width, height, tw, th, seed, frame,
                                       (CLP_F)0.0f, (CLP_F)0.0f, (CLP_I)0, 0);
}

#undef MB_LOAD
#undef MB_STORE
#undef MB_TAP
#undef MB_LOOP16
#undef MB_LOOP16S
