/* motion_blur: velocity-buffer motion blur (McGuire, Hennessy, Bukowski, Osman 2012, "A
 * Reconstruction Filter for Plausible Motion Blur") and a rolling-shutter warp.
 * clpost/stages/motion_blur.py documents the formulas; its reference() is the oracle.
 *
 * Buffers: colour planar (c*n + i); velocity interleaved (2i, 2i+1) px per frame, forward,
 * +x right, +y down; depth planar metres (+inf sky). Scratch: hv = clamped half-vectors and
 * their unclamped length and what a tap reads of Y packed in one word (4 planes: x, y, key, record),
 * iz = 1/depth (0 for sky), tile max (4 planes) and
 * neighbour max (5 planes). Maxima are ranked by the unclamped length: clamped vectors all
 * have length K, and ranking them by a rounding-level difference would not be reproducible.
 *
 * Defines: MOTION_BLUR_TILE (tile size K = the largest blur half-length in px),
 * MOTION_BLUR_SAMPLES (S_q, odd; the centre tap is the pixel itself), MOTION_BLUR_SAMPLES_MAX (odd:
 * the most taps a frame whose motion covers few tiles may take, motion_blur_budget),
 * MOTION_BLUR_DENSITY (taps per px of half-path: S = min(C, 2 ceil(DENSITY |v_N|) + 1), C the frame's cap),
 * MOTION_BLUR_LANES (below); the filter's constants (MOTION_BLUR_SOFT_Z, FOOT, AGREE0/1, DIFFER2, DIR,
 * LINE, FRINGE2, R2X/R2Y) from the same defines() (motion_blur.py's _model_defines, the one place).
 *
 * The per-pixel math of the prep and the gather (and the constants) is kernels/motion_blur_pixels.cl,
 * instantiated before this file at one pixel (plain names) and at 16 (_w16).
 */
#pragma OPENCL FP_CONTRACT OFF

/* MOTION_BLUR_LANES: pixels per work-item of the prep and the gather, 16 (explicit float16 rows, for
 * CPUs: PoCL vectorises neither one-pixel form) or 1 (one pixel per work-item, for GPUs, where a
 * 16-wide work-item makes uncoalesced loads and few work-items); the stage sets it from
 * Runtime.wide. */
#ifndef MOTION_BLUR_LANES
#define MOTION_BLUR_LANES 16
#endif
#if MOTION_BLUR_LANES != 16 && MOTION_BLUR_LANES != 1
#error "MOTION_BLUR_LANES must be 16 or 1"
#endif

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
        motion_blur_prep_pixels_w16(velocity, depth, hv, iz, x0, y, width, height, k);
    } else {
        for (int x = x0; x < min(x0 + 16, width); ++x)
            motion_blur_prep_pixels(velocity, depth, hv, iz, x, y, width, height, k);
    }
#else
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    motion_blur_prep_pixels(velocity, depth, hv, iz, x, y, width, height, k);
#endif
}

/* 1 where direction a differs from b by more than acos(MOTION_BLUR_AGREE0) (a . b < 0.8 |a| |b|, in
 * squares; a zero vector differs from nothing) */
inline int motion_blur_differs(const float ax, const float ay, const float bx, const float by) {
    const float d = ax * bx + ay * by;
    const float la = ax * ax + ay * ay, lb = bx * bx + by * by;
    return d < 0.0f || d * d < MOTION_BLUR_DIFFER2 * (la * lb);
}

/* Each K x K tile's largest half-vector (by the unclamped length; first in scan order on ties) and
 * the inverse depth of its pixel: planes x, y, key, 1/z */
__kernel void motion_blur_tilemax(__global const float *restrict hv, __global const float *restrict iz,
                                  __global float *restrict tile,
                                  const int width, const int height, const int tw, const int th)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    const size_t n = (size_t)width * (size_t)height;
    float2 best = (float2)(0.0f, 0.0f);
    float best2 = 0.0f;   /* the unclamped length of best */
    size_t bi = 0;        /* its pixel (its 1/z is read once, after the scan) */
    int found = 0;
    const int y1 = min(ty * MOTION_BLUR_TILE + MOTION_BLUR_TILE, height);
    const int x1 = min(tx * MOTION_BLUR_TILE + MOTION_BLUR_TILE, width);
    for (int y = ty * MOTION_BLUR_TILE; y < y1; ++y) {
        for (int x = tx * MOTION_BLUR_TILE; x < x1; ++x) {
            const size_t i = (size_t)y * (size_t)width + (size_t)x;
            const float l = hv[2 * n + i];
            if (l > best2) { best2 = l; best = (float2)(hv[i], hv[n + i]); bi = i; found = 1; }
        }
    }
    const size_t t = (size_t)ty * (size_t)tw + (size_t)tx;
    const size_t tn = (size_t)tw * (size_t)th;
    tile[t] = best.x;
    tile[tn + t] = best.y;
    tile[2 * tn + t] = best2;
    tile[3 * tn + t] = found ? iz[bi] : 0.0f;
}

/* v_N: the largest tile half-vector in the 3 x 3 tile neighbourhood (scan order on ties); and the
 * neighbourhood's second direction: the largest of those tile maxima whose direction differs from
 * v_N, kept only where it is faster than half a pixel and its surface is not level with v_N's (1/z
 * apart by more than half the soft depth test's ramp): another surface moving another way.
 * Planes x, y (v_N), x2, y2 (the second direction, 0 where none), and 1 where the second
 * direction's surface is the nearer. */
__kernel void motion_blur_neighbormax(__global const float *restrict tile, __global float *restrict nmax,
                                      const int tw, const int th)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    const size_t tn = (size_t)tw * (size_t)th;
    /* the 3x3 tiles once (row by row; a tile beyond the frame has length 0, which neither
     * selection below takes), then v_N and the second direction from the same values (the loops
     * unrolled, so the arrays stay in registers) */
    float cx[9], cy[9], cl[9], cz[9];
#pragma unroll
    for (int k = 0; k < 9; ++k) {
        const int sx = tx + k % 3 - 1, sy = ty + k / 3 - 1;
        const int in = sx >= 0 && sy >= 0 && sx < tw && sy < th;
        const size_t t = in ? (size_t)sy * (size_t)tw + (size_t)sx : 0;
        cx[k] = in ? tile[t] : 0.0f;
        cy[k] = in ? tile[tn + t] : 0.0f;
        cl[k] = in ? tile[2 * tn + t] : 0.0f;
        cz[k] = in ? tile[3 * tn + t] : 0.0f;
    }
    float2 best = (float2)(0.0f, 0.0f);
    float best2 = 0.0f, bz = 0.0f;
#pragma unroll
    for (int k = 0; k < 9; ++k)
        if (cl[k] > best2) { best2 = cl[k]; best = (float2)(cx[k], cy[k]); bz = cz[k]; }
    float2 sec = (float2)(0.0f, 0.0f);
    float sec2 = 0.0f, sz = 0.0f;
#pragma unroll
    for (int k = 0; k < 9; ++k)
        if (cl[k] > sec2 && motion_blur_differs(cx[k], cy[k], best.x, best.y)) {
            sec2 = cl[k]; sec = (float2)(cx[k], cy[k]); sz = cz[k];
        }
    const int other = sec2 > 0.5f && fabs(sz - bz) > 0.5f * MOTION_BLUR_SOFT_Z * fmax(fmax(sz, bz), 1e-30f);
    const size_t t = (size_t)ty * (size_t)tw + (size_t)tx;
    nmax[t] = best.x;
    nmax[tn + t] = best.y;
    nmax[2 * tn + t] = other ? sec.x : 0.0f;
    nmax[3 * tn + t] = other ? sec.y : 0.0f;
    nmax[4 * tn + t] = other && sz > bz ? 1.0f : 0.0f;
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
        moving += motion_blur_len2(nmax[t], nmax[tn + t]) > 0.25f ? 1 : 0;
    int c = moving > 0 ? (MOTION_BLUR_SAMPLES * tn) / moving : MOTION_BLUR_SAMPLES;
    c = clamp(c, MOTION_BLUR_SAMPLES, MOTION_BLUR_SAMPLES_MAX);
    cap[0] = c - (1 - (c & 1));   /* odd (S_q and the maximum are odd) */
}

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
        motion_blur_gather_w16(src, dst, hv, iz, nmax, cap, x0, y, width, height, tw, th, seed, frame);
    } else {
        for (int x = x0; x < width; ++x)
            motion_blur_gather(src, dst, hv, iz, nmax, cap, x, y, width, height, tw, th, seed, frame);
    }
#else
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    motion_blur_gather(src, dst, hv, iz, nmax, cap, x, y, width, height, tw, th, seed, frame);
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
