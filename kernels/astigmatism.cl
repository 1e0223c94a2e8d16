/* astigmatism: field curvature + astigmatism as an elliptical gather on tiles.
 * clpost/stages/astigmatism.py documents the formulas; its reference() is the oracle.
 *
 * Vectorisation (docs/measurements.md#gather-layouts-on-pocl): work-groups are tiles of
 * ASTIGMATISM_TILE_W × ASTIGMATISM_TILE_H pixels and every tap offset is group-uniform — the tile's
 * bounding ellipse (largest semi-axes of its pixels, the tile centre's directions) sampled by the
 * Vogel spiral, a
 * program-scope literal table that Astigmatism prepends to this source — so each tap reads rows
 * of the tile at one offset. Each pixel keeps its own ellipse through the tap weights. The gather
 * computes 16 pixels per work-item as explicit float16 vectors: PoCL's vectoriser across
 * work-items (found with POCL_VECTORIZER_REMARKS and objdump) needed the offsets hoisted (a
 * per-tile table of tap records read from a buffer was not: every read became a vector gather)
 * and the taps' weights chained through a zero dependency on the running sum so the SLP pass
 * would not pack pairs of taps, which made the loop latency-bound. The explicit vectors need
 * neither.
 *
 * Buffers: colour planar (c*n + i); padded = 3 planes of pw × ph (pw = tiles_x * TILE_W +
 * 2 PAD, ph likewise), edge values repeated (no clamp per tap; the rounded-up work-items read
 * inside), filled only in the ring that the border tiles read: inner tiles (inner = one int per
 * tile, from the host) read the colour planes src directly; offs = 2 planes pw × ph, the focal
 * offsets (mm) of the pixel each padded pixel continues (per camera and size); axes = 4 planes pw × ph: the ellipse semi-axes (a_s, a_t) in px of the pixel each
 * padded pixel continues, and 1/(a_s + 1/2)^2, 1/(a_t + 1/2)^2 for the reach test; lut = 2 planes of ASTIGMATISM_LUT_SIZE focal offsets (sagittal,
 * tangential; mm) over image height [0, r_max]; tiles = per tile (row-major) the tile centre's
 * unit radial vector (e_x, e_y) from the host and the tile's largest (a_s, a_t) from
 * astigmatism_tiles.
 * Tile classes: astigmatism_tiles appends each tile to one list per class (copy, 4, 8, ...
 * ASTIGMATISM_TAPS taps, the point classes, exact); the host launches astigmatism_copy, the gather
 * kernels (astigmatism_t<n> and astigmatism for the full count, astigmatism_p<n> for the point
 * classes; one compile-time tap count each) and
 * astigmatism_exact with one work-group per tile of the frame — the most a list can hold, so the
 * host never reads the counts (no sync). With ASTIGMATISM_SPREAD (the 16-lane CPU form) a class's
 * count c of listed tiles is spread evenly over the launch's n work-groups (astigmatism_slot:
 * group g takes entry g c / n where that steps up), otherwise they are its first c groups; the
 * other groups return at once (a few ns each on PoCL). PoCL's CPU device hands each thread a run
 * of consecutive work-groups, so the first c groups ran on one or a few of its threads
 * (docs/benchmarks.md, "astigmatism: tile classes spread over the launch"); a GPU schedules its
 * groups as they free up, and keeps the packed order.
 * The tap table holds
 * the spirals of 4, 8, ..., ASTIGMATISM_TAPS points one after the other, then the point classes' spirals.
 * Defines: ASTIGMATISM_TAPS, ASTIGMATISM_PAD, ASTIGMATISM_LUT_SIZE, ASTIGMATISM_TILE_W,
 * ASTIGMATISM_TILE_H, ASTIGMATISM_WHOLE_TILES (whole tiles: stores without a branch),
 * ASTIGMATISM_CLASSES (copy, the tap classes, the point classes, exact), ASTIGMATISM_TAP_CLASSES
 * (how many tap classes: 4, 8, ... ASTIGMATISM_TAPS), ASTIGMATISM_COPY_PX, ASTIGMATISM_TAPS_PER_PX (FULL_AT_PX / TAPS),
 * ASTIGMATISM_FULL_TAP0 (table offset of the full spiral), ASTIGMATISM_LANES (16 or 1, below),
 * ASTIGMATISM_SPREAD (1: spread each class's tiles over its launch, astigmatism_slot).
 * Point classes (clpost/stages/astigmatism.py, "Point taps"): astigmatism_point_class (generated
 * before this file) maps a tile's smallest semi-axis to its point class or -1; those tiles'
 * gathers (astigmatism_p<n>) take one tap per channel from pre = 3 planes pw × ph, the colour
 * box-filtered over ASTIGMATISM_POINT_BOX² pixels (astigmatism_box, only where need[tile]: within
 * reach of a point tile), on the ellipses shrunk by ASTIGMATISM_POINT_SHRINK px² per axis.
 */
#if ASTIGMATISM_TILE_W % 16
#error "the gather reads rows of a tile as float16 (the tile pass as float8): ASTIGMATISM_TILE_W must be a multiple of 16"
#endif
#if ASTIGMATISM_PAD % ASTIGMATISM_TILE_W || ASTIGMATISM_PAD % ASTIGMATISM_TILE_H
#error "astigmatism_box maps a padded row's 16 pixels to one tile: ASTIGMATISM_PAD must be a multiple of the tile size"
#endif
#if ASTIGMATISM_POINT_BOX != 4
#error "astigmatism_box filters 4 x 4 pixels (ASTIGMATISM_POINT_BOX)"
#endif
#if ASTIGMATISM_TAPS % 4
#error "the gather's tap loop is unrolled by 4: ASTIGMATISM_TAPS must be a multiple of 4"
#endif
/* ASTIGMATISM_MAX_SEMI, _MIN_SEMI, _MIN_DEPTH_MM, _EXACT_PX, _MIXED: the Python constants of
 * clpost/stages/astigmatism.py, #defined before this file by clpost/stages/astigmatism_cl.py */
#ifndef ASTIGMATISM_MIXED
#error "build through clpost.stages.astigmatism_cl.program_source (it defines the stage's constants)"
#endif

/* semi-axis (px) of this stage's ellipse on 16 lanes: sqrt(max(c^2 - c0^2, 0)) / 2p, capped (the
 * cap also where the astigmatic focus is at or beyond infinity, den <= 1e-6, or a is not finite) */
inline float16 astigmatism_semi16(float16 e0, float16 g, float16 d, float16 c0, float aperture, float half_inv_pitch)
{
#pragma OPENCL FP_CONTRACT OFF
    const float16 den = 1.0f + d * g;
    const float16 c = aperture * fabs(e0 + d * g) / den;
    const float16 q = (c - c0) * (c + c0);
    const float16 a = sqrt(fmax(q, 0.0f)) * half_inv_pitch;
    const int16 ok = (den > 1e-6f) & isfinite(a);
    return select((float16)ASTIGMATISM_MAX_SEMI, fmin(a, ASTIGMATISM_MAX_SEMI), ok);
}


/* The padded copy of the colour planes (edge values repeated) and every padded pixel's ellipse
 * (that of the frame pixel it continues). One work-item = 16 consecutive pixels of a padded row
 * (pw is a multiple of 16) as float16 vectors: whole-vector loads where the row's 16 source
 * pixels lie inside the frame, per-lane clamped loads only in the vectors that touch a side
 * (a clamp on every pixel, one pixel per work-item, does not vectorise;
 * docs/measurements.md#kernel-forms-on-pocl); the axes are computed on the 16 lanes either way. */
/* Tile classes without ties: astigmatism_offsets, astigmatism_pad and astigmatism_semi16 turn
 * FP_CONTRACT off and use only correctly rounded operations (+ - * / sqrt on a CPU), so the
 * reference's float32 emulation of them (Astigmatism.semi_axes_px32) is bit-equal and classifies
 * every tile as astigmatism_tiles does, also at a threshold. */
/* The focal offsets (sagittal, tangential; mm) at every padded pixel's image height: 2 planes pw x
 * ph (those of the frame pixel it continues), from the LUT. They depend on the camera and frame
 * size only, so the host runs this once per camera and size, not per frame (the 64 per-lane LUT
 * loads of 16 pixels were most of astigmatism_pad's time). */
__kernel void astigmatism_offsets(__global const float *restrict lut, __global float *restrict offs,
                                  const int width, const int height, const int pw, const int ph,
                                  const float cx, const float cy, const float pitch_mm, const float lut_scale)
{
#pragma OPENCL FP_CONTRACT OFF
    const int x0 = 16 * (int)get_global_id(0), y = get_global_id(1);
    if (x0 >= pw || y >= ph) return;
    const int sy = clamp(y - ASTIGMATISM_PAD, 0, height - 1);
    const size_t j = (size_t)y * pw + x0, pn = (size_t)pw * ph;
    const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const int16 sx = clamp(x0 - ASTIGMATISM_PAD + lane, 0, width - 1);
    const float16 dx = convert_float16(sx) - cx;
    const float dy = (float)sy - cy;
    const float16 r = sqrt(dx * dx + dy * dy);
    /* linear LUT over image height */
    const float16 t = fmin(r * pitch_mm * lut_scale, (float)(ASTIGMATISM_LUT_SIZE - 1));
    const int16 k0 = min(convert_int16(t), ASTIGMATISM_LUT_SIZE - 2);
    const float16 ft = t - convert_float16(k0);
    const int16 k1 = k0 + 1;
    __global const float *lt = lut + ASTIGMATISM_LUT_SIZE;
    /* a + (b - a) t written out (mix's rounding is the library's) */
    const float16 s0 = CLP_GATHER16(lut, k0), t0 = CLP_GATHER16(lt, k0);
    vstore16(s0 + (CLP_GATHER16(lut, k1) - s0) * ft, 0, offs + j);
    vstore16(t0 + (CLP_GATHER16(lt, k1) - t0) * ft, 0, offs + pn + j);
}

__kernel void astigmatism_pad(__global const float *restrict src, __global const float *restrict depth,
                              __global const float *restrict offs, __global float *restrict padded,
                              __global float *restrict axes, const int width, const int height,
                              const int pw, const int ph, const float pitch_mm,
                              const float aperture_mm, const float v_mm, const float inv_f_mm,
                              const int ring_x0, const int ring_x1, const int ring_y0, const int ring_y1)
{
#pragma OPENCL FP_CONTRACT OFF
    const int x0 = 16 * (int)get_global_id(0), y = get_global_id(1);
    if (x0 >= pw || y >= ph) return;
    const int sy = clamp(y - ASTIGMATISM_PAD, 0, height - 1);
    const size_t n = (size_t)width * height, pn = (size_t)pw * ph;
    __global const float *s = src + (size_t)sy * width;
    __global const float *zs = depth + (size_t)sy * width;
    const size_t j = (size_t)y * pw + x0;
    const int sx0 = x0 - ASTIGMATISM_PAD;
    const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const int16 sx = clamp(sx0 + lane, 0, width - 1);
    float16 z;
    if (sx0 >= ring_x0 && sx0 + 16 <= ring_x1 && y - ASTIGMATISM_PAD >= ring_y0 && y - ASTIGMATISM_PAD < ring_y1) {
        /* read only by inner tiles, which read the source: no colour copy */
        z = vload16(0, zs + sx0);
    } else if (sx0 >= 0 && sx0 + 16 <= width) {
        vstore16(vload16(0, s + sx0), 0, padded + j);
        vstore16(vload16(0, s + n + sx0), 0, padded + pn + j);
        vstore16(vload16(0, s + 2 * n + sx0), 0, padded + 2 * pn + j);
        z = vload16(0, zs + sx0);
    } else {
        vstore16(CLP_GATHER16(s, sx), 0, padded + j);
        vstore16(CLP_GATHER16(s + n, sx), 0, padded + pn + j);
        vstore16(CLP_GATHER16(s + 2 * n, sx), 0, padded + 2 * pn + j);
        z = CLP_GATHER16(zs, sx);
    }

    /* focal offsets at this image height (astigmatism_offsets) */
    const float16 ds = vload16(0, offs + j), dt = vload16(0, offs + pn + j);
    /* thin-lens defocus terms: g = 1/f - 1/z, e0 = 1 - v g = (1 - v/f) + v/z */
    const float16 zmm = fmax(z * 1000.0f, ASTIGMATISM_MIN_DEPTH_MM);
    const float16 inv_z = select(1.0f / zmm, (float16)0.0f, isinf(zmm));
    const float16 g = inv_f_mm - inv_z;
    const float16 e0 = (1.0f - v_mm * inv_f_mm) + v_mm * inv_z;
    const float16 c0 = aperture_mm * fabs(e0);
    const float hip = 0.5f / pitch_mm;
    const float16 as = astigmatism_semi16(e0, g, ds, c0, aperture_mm, hip);
    const float16 at = astigmatism_semi16(e0, g, dt, c0, aperture_mm, hip);
    vstore16(as, 0, axes + j);
    vstore16(at, 0, axes + pn + j);
    /* 1/(a + 1/2)^2 for the reach test of the taps that land here (no division per tap) */
    vstore16(1.0f / ((as + 0.5f) * (as + 0.5f)), 0, axes + 2 * pn + j);
    vstore16(1.0f / ((at + 0.5f) * (at + 0.5f)), 0, axes + 3 * pn + j);
}

/* tile (tx, ty): the largest and smallest semi-axes of its pixels (inside the frame) into tiles
 * and tmin, its point flag, and its class (returned; astigmatism_tiles lists it) */
inline int astigmatism_tile_class(__global const float *restrict axes, __global float *restrict tiles,
                                  __global float *restrict tmin, __global int *restrict point,
                                  const int width, const int height, const int tiles_x, const int tiles_y,
                                  const int tx, const int ty)
{
    const int pw = tiles_x * ASTIGMATISM_TILE_W + 2 * ASTIGMATISM_PAD;
    const size_t pn = (size_t)pw * (tiles_y * ASTIGMATISM_TILE_H + 2 * ASTIGMATISM_PAD);
    const int x1 = min((tx + 1) * ASTIGMATISM_TILE_W, width), y1 = min((ty + 1) * ASTIGMATISM_TILE_H, height);
    float ms = 0.0f, mt = 0.0f, mn_s, mn_t;
    if (x1 - tx * ASTIGMATISM_TILE_W == ASTIGMATISM_TILE_W && y1 - ty * ASTIGMATISM_TILE_H == ASTIGMATISM_TILE_H) {
        /* a whole tile: rows as float8 vectors (the scalar loops below cost as much as the
         * gather's pad pass) */
        float8 vs = 0.0f, vt = 0.0f, ws = MAXFLOAT, wt = MAXFLOAT;
        for (int y = ty * ASTIGMATISM_TILE_H; y < y1; ++y)
            for (int x = tx * ASTIGMATISM_TILE_W; x < x1; x += 8) {
                const size_t j = (size_t)(y + ASTIGMATISM_PAD) * pw + x + ASTIGMATISM_PAD;
                const float8 a = vload8(0, axes + j), b = vload8(0, axes + pn + j);
                vs = fmax(vs, a);
                vt = fmax(vt, b);
                ws = fmin(ws, a);
                wt = fmin(wt, b);
            }
        float4 h4 = fmax(vs.lo, vs.hi);
        float2 h2 = fmax(h4.lo, h4.hi);
        ms = fmax(h2.lo, h2.hi);
        h4 = fmax(vt.lo, vt.hi);
        h2 = fmax(h4.lo, h4.hi);
        mt = fmax(h2.lo, h2.hi);
        h4 = fmin(ws.lo, ws.hi);
        h2 = fmin(h4.lo, h4.hi);
        mn_s = fmin(h2.lo, h2.hi);
        h4 = fmin(wt.lo, wt.hi);
        h2 = fmin(h4.lo, h4.hi);
        mn_t = fmin(h2.lo, h2.hi);
    } else {
        for (int y = ty * ASTIGMATISM_TILE_H; y < y1; ++y)
            for (int x = tx * ASTIGMATISM_TILE_W; x < x1; ++x) {
                const size_t j = (size_t)(y + ASTIGMATISM_PAD) * pw + x + ASTIGMATISM_PAD;
                ms = fmax(ms, axes[j]);
                mt = fmax(mt, axes[pn + j]);
            }
        mn_s = ms;
        mn_t = mt;
        for (int y = ty * ASTIGMATISM_TILE_H; y < y1; ++y)
            for (int x = tx * ASTIGMATISM_TILE_W; x < x1; ++x) {
                const size_t j = (size_t)(y + ASTIGMATISM_PAD) * pw + x + ASTIGMATISM_PAD;
                mn_s = fmin(mn_s, axes[j]);
                mn_t = fmin(mn_t, axes[pn + j]);
            }
    }
    /* exact (per-pixel) path for tiles where the shared ellipse would be wrong by more than
     * about half a pixel: the tile centre's direction is off by up to (half diagonal)/r rad, or
     * some pixel's ellipse is less than ASTIGMATISM_MIXED of the bound (a depth edge) */
    const float r = tiles[4 * (ty * tiles_x + tx) + 2];  /* the host put the tile centre's r here */
    const float half_diag = 0.5f * sqrt((float)(ASTIGMATISM_TILE_W * ASTIGMATISM_TILE_W + ASTIGMATISM_TILE_H * ASTIGMATISM_TILE_H));
    const bool turn = fmax(ms, mt) * half_diag > ASTIGMATISM_EXACT_PX * r;
    const bool mixed = (ms > ASTIGMATISM_EXACT_PX && mn_s < ASTIGMATISM_MIXED * ms)
                    || (mt > ASTIGMATISM_EXACT_PX && mn_t < ASTIGMATISM_MIXED * mt);
    tiles[4 * (ty * tiles_x + tx) + 2] = ms;
    tiles[4 * (ty * tiles_x + tx) + 3] = mt;
    tmin[2 * (ty * tiles_x + tx)] = mn_s;  /* for astigmatism_reach */
    tmin[2 * (ty * tiles_x + tx) + 1] = mn_t;
    /* class: the exact path; a point class where every pixel's smaller semi-axis is large enough
     * (astigmatism_point_class); copy below ASTIGMATISM_COPY_PX; else the fewest taps n = 4, 8, ...
     * ASTIGMATISM_TAPS with B <= n * ASTIGMATISM_TAPS_PER_PX (B the bounding semi-axis) */
    const float bound = fmax(ms, mt);
    const int pc = astigmatism_point_class(fmin(mn_s, mn_t));
    point[ty * tiles_x + tx] = !(turn || mixed) && pc >= 0;  /* for astigmatism_reach's need flags */
    int c;
    if (turn || mixed) {
        c = ASTIGMATISM_CLASSES - 1;
    } else if (pc >= 0) {
        c = pc;
    } else if (bound < ASTIGMATISM_COPY_PX) {
        c = 0;
    } else {
        c = 1;
        while (c < ASTIGMATISM_TAP_CLASSES && bound > (float)(2 << c) * ASTIGMATISM_TAPS_PER_PX) ++c;
    }
    return c;
}

/* one work-item per tile (astigmatism_tile_class), its class appended to that class's tile list
 * (lists: ASTIGMATISM_CLASSES rows of tiles_x * tiles_y tile indices; counts: one counter per
 * class, zeroed by the host). A work-group (TILES_GROUP tiles of a row, clpost/stages/astigmatism_cl.py; the host rounds
 * the global size up) counts its tiles per class in local memory and reserves each class's run
 * of the list with one global atomic_add instead of one atomic_inc per tile on the one cache line
 * of counts (docs/benchmarks.md, "astigmatism: tile classes spread over the launch"). The order within a
 * list depends on the atomics' order; the result does not (each tile is independent). */
__kernel void astigmatism_tiles(__global const float *restrict axes, __global float *restrict tiles,
                                __global float *restrict tmin, __global int *restrict point,
                                __global int *restrict counts, __global int *restrict lists,
                                const int width, const int height, const int tiles_x, const int tiles_y)
{
    __local int count[ASTIGMATISM_CLASSES], base[ASTIGMATISM_CLASSES];
    const int tx = get_global_id(0), ty = get_global_id(1), lid = get_local_id(0);
    const int valid = tx < tiles_x && ty < tiles_y;
    for (int k = lid; k < ASTIGMATISM_CLASSES; k += get_local_size(0))
        count[k] = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    int c = 0, slot = 0;
    if (valid) {
        c = astigmatism_tile_class(axes, tiles, tmin, point, width, height, tiles_x, tiles_y, tx, ty);
        slot = atomic_inc(count + c);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int k = lid; k < ASTIGMATISM_CLASSES; k += get_local_size(0))
        base[k] = count[k] ? atomic_add(counts + k, count[k]) : 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (valid)
        lists[c * tiles_x * tiles_y + base[c] + slot] = ty * tiles_x + tx;
}

/* one work-item per tile: does the gather need its reach test? A tap's reach weight is 1 when
 * q^2 = u_s^2/(a_s' + 1/2)^2 + u_t^2/(a_t' + 1/2)^2 <= 1 (a' the semi-axes of the pixel the tap
 * lands on); the taps have |u_s| <= B_s |v_x|, |u_t| <= B_t |v_y| with v a spiral point (|v| < 1)
 * and land within PAD px of the tile, in the tiles at most ASTIGMATISM_REACH_TX / _TY away (the
 * padded border repeats the edge tiles' pixels). So if every such pixel has a_s' + 1/2 >= B_s and
 * a_t' + 1/2 >= B_t, every weight is 1 and the test is skipped (reach[tile] = 0): most tiles of a
 * smooth depth map, whose ellipses vary by far less than half a pixel over 2 PAD px. */
#define ASTIGMATISM_REACH_TX ((ASTIGMATISM_PAD + ASTIGMATISM_TILE_W - 1) / ASTIGMATISM_TILE_W)
#define ASTIGMATISM_REACH_TY ((ASTIGMATISM_PAD + ASTIGMATISM_TILE_H - 1) / ASTIGMATISM_TILE_H)
/* The same neighbourhood gives need[tile]: some point tile reads this tile's pixels of pre (its taps
 * land within PAD px of it; the padded border belongs to the edge tiles), so astigmatism_box
 * filters only those. */
__kernel void astigmatism_reach(__global const float *restrict tiles, __global const float *restrict tmin,
                                __global const int *restrict point, __global int *restrict reach,
                                __global int *restrict need, const int tiles_x, const int tiles_y)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tiles_x || ty >= tiles_y) return;
    float ns = MAXFLOAT, nt = MAXFLOAT;
    int np = 0;
    for (int y = max(ty - ASTIGMATISM_REACH_TY, 0); y <= min(ty + ASTIGMATISM_REACH_TY, tiles_y - 1); ++y)
        for (int x = max(tx - ASTIGMATISM_REACH_TX, 0); x <= min(tx + ASTIGMATISM_REACH_TX, tiles_x - 1); ++x) {
            ns = fmin(ns, tmin[2 * (y * tiles_x + x)]);
            nt = fmin(nt, tmin[2 * (y * tiles_x + x) + 1]);
            np |= point[y * tiles_x + x];
        }
    const int id = ty * tiles_x + tx;
    /* a point tile's taps lie on its shrunk bound (astigmatism_gather) */
    const float shrink = point[id] ? ASTIGMATISM_POINT_SHRINK : 0.0f;
    const float bs = sqrt(fmax(tiles[4 * id + 2] * tiles[4 * id + 2] - shrink, 0.0f));
    const float bt = sqrt(fmax(tiles[4 * id + 3] * tiles[4 * id + 3] - shrink, 0.0f));
    reach[id] = !(ns + 0.5f >= bs && nt + 0.5f >= bt);
    need[id] = np;
}

/* pre: the colour box-filtered over 4 x 4 pixels, pre(p) = mean of C(p + (i, j)), i, j = -1 .. 2
 * (centre p + (1/2, 1/2); C edge-repeated like the padded copy), for every padded pixel of the
 * tiles that need it. One work-item = 16 pixels of a padded row (one tile column: PAD is a
 * multiple of the tile size; the padded border belongs to the edge tiles); whole-vector loads
 * where the 19 source columns lie inside the frame, clamped per-lane gathers at the sides. */
__kernel void astigmatism_box(__global const float *restrict src, __global const int *restrict need,
                              __global float *restrict pre, const int width, const int height,
                              const int pw, const int ph, const int tiles_x, const int tiles_y)
{
    const int x0 = 16 * (int)get_global_id(0), y = get_global_id(1);
    if (x0 >= pw || y >= ph) return;
    const int tx = clamp(x0 / ASTIGMATISM_TILE_W - ASTIGMATISM_PAD / ASTIGMATISM_TILE_W, 0, tiles_x - 1);
    const int ty = clamp(y / ASTIGMATISM_TILE_H - ASTIGMATISM_PAD / ASTIGMATISM_TILE_H, 0, tiles_y - 1);
    if (!need[ty * tiles_x + tx]) return;
    const size_t n = (size_t)width * height, pn = (size_t)pw * ph, j = (size_t)y * pw + x0;
    const int sx0 = x0 - ASTIGMATISM_PAD;
    const int inside = sx0 - 1 >= 0 && sx0 + 18 <= width;
    const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const int16 c0 = clamp(sx0 - 1 + lane, 0, width - 1), c1 = clamp(sx0 + lane, 0, width - 1);
    const int16 c2 = clamp(sx0 + 1 + lane, 0, width - 1), c3 = clamp(sx0 + 2 + lane, 0, width - 1);
    for (int c = 0; c < 3; ++c) {
        /* each term scaled before the sum: a mean of finite values stays finite (16 terms above
         * FLT_MAX / 16 summed first overflow) */
        const float16 k = 1.0f / 16.0f;
        float16 acc = 0.0f;
        for (int i = -1; i <= 2; ++i) {
            __global const float *s = src + c * n + (size_t)clamp(y - ASTIGMATISM_PAD + i, 0, height - 1) * width;
            if (inside) {
                acc = mad(k, vload16(0, s + sx0 - 1), acc);
                acc = mad(k, vload16(0, s + sx0), acc);
                acc = mad(k, vload16(0, s + sx0 + 1), acc);
                acc = mad(k, vload16(0, s + sx0 + 2), acc);
            } else {
                acc = mad(k, CLP_GATHER16(s, c0), acc);
                acc = mad(k, CLP_GATHER16(s, c1), acc);
                acc = mad(k, CLP_GATHER16(s, c2), acc);
                acc = mad(k, CLP_GATHER16(s, c3), acc);
            }
        }
        vstore16(acc, 0, pre + c * pn + j);
    }
}

#define ASTIGMATISM_ABS(v) as_float(as_uint(v) & 0x7fffffffu)
/* clamp(v, 0, 1) without a call or a select: m = min(v, 1) = (v + 1 - |v - 1|) / 2, then
 * max(m, 0) = (m + |m|) / 2 — two dependent steps, so the SLP pass finds no pair of |.| to pack
 * (exact while v - 1 is exact in float, |v| < 4e6) */
inline float astigmatism_sat(float v)
{
    const float m = 0.5f * (v + 1.0f - ASTIGMATISM_ABS(v - 1.0f));
    return 0.5f * (m + ASTIGMATISM_ABS(m));
}

/* clamp(v, 0, 1) for the explicit float16 form: the min/max builtins are one vector min and max
 * each there (the |.| form of astigmatism_sat is for the work-item vectoriser's scalar code; here
 * it cost 7 vector ops a weight, 2 per tap: the stage x1.05-1.08 at 1080p final, one process) */
inline float16 astigmatism_sat16(float16 v)
{
    return min(max(v, 0.0f), 1.0f);
}

/* clamp(v, 0, hi): the gather's membership weight scaled by hi = 1/ntaps (astigmatism_gather) */
inline float astigmatism_satn(float v, float hi)
{
    const float m = 0.5f * (v + hi - ASTIGMATISM_ABS(v - hi));
    return 0.5f * (m + ASTIGMATISM_ABS(m));
}
inline float16 astigmatism_satn16(float16 v, float hi)
{
    return min(max(v, 0.0f), hi);
}

/* 16 pixels of a tile row into the planar output (kernels/common.cl; partial tiles: per pixel) */
#define astigmatism_store16(dst, r, g, b, x, y, width, height) \
    clp_store16_planar(dst, r, g, b, x, y, width, height, ASTIGMATISM_WHOLE_TILES)

/* The gather and copy kernels' pixels per work-item: 16 (explicit float16 vectors, for CPUs — see
 * below) or 1 (a work-group = a tile of TILE_W x TILE_H work-items, for GPUs, where 16-wide
 * work-items make groups of 8 and uncoalesced loads); clpost/stages/astigmatism_cl.py defines it
 * from the device. AVEC / AVLOAD / ASAT / ASTORE are the width's type, load, clamp and store. */
#ifndef ASTIGMATISM_LANES
#define ASTIGMATISM_LANES 16
#endif
#if ASTIGMATISM_LANES == 16
#define AVEC float16
#define AIVEC int16
#define AVLOAD(p) vload16(0, (p))
#define ASAT(v) astigmatism_sat16(v)
#define ASATN(v, hi) astigmatism_satn16(v, hi)
#define ASTORE(dst, r, g, b, x, y, width, height) astigmatism_store16(dst, r, g, b, x, y, width, height)
#elif ASTIGMATISM_LANES == 1
#define AVEC float
#define AIVEC int
#define AVLOAD(p) (*(p))
#define ASAT(v) astigmatism_sat(v)
#define ASATN(v, hi) astigmatism_satn(v, hi)
inline void astigmatism_store1(__global float *restrict dst, const float r, const float g, const float b,
                               const int x, const int y, const int width, const int height)
{
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * height, i = (size_t)y * width + x;
    dst[i] = r;
    dst[n + i] = g;
    dst[2 * n + i] = b;
}
#define ASTORE(dst, r, g, b, x, y, width, height) astigmatism_store1(dst, r, g, b, x, y, width, height)
#else
#error "ASTIGMATISM_LANES must be 16 or 1"
#endif

/* On a CPU one work-item = 16 consecutive pixels of a row of the tile, as explicit float16 vectors
 * (a work-group = a tile = ASTIGMATISM_TILE_W / 16 x ASTIGMATISM_TILE_H work-items; on a GPU one
 * pixel, ASTIGMATISM_LANES above). Written with
 * vectors rather than left to PoCL's work-item-loop vectoriser because that one needs the taps'
 * weights chained through a zero dependency on the running sum (or the SLP pass packs pairs of
 * taps and it gives up), and that chain makes the loop latency-bound; here the taps' weights are
 * independent and overlap. float16 rather than float8 (faster at 64 taps, the same at 16;
 * docs/measurements.md#kernel-forms-on-pocl); the tap loop is unrolled by 4 (see below), not fully. */
inline void astigmatism_gather(__global const float *restrict padded, __global const float *restrict src,
                 __global const float *restrict pre, const int box, __global const int *restrict inner,
                 const int test_reach, __global const float *restrict axes,
                 __global float *restrict dst, __global const float *restrict tiles,
                 const int tile_of_group, const int tiles_x, const int tiles_y,
                 const int width, const int height, const int ntaps, const int tap0)
{
    /* this work-group's tile of the class's list (astigmatism_slot); ntaps spiral points from tap0
     * (both compile-time constants after inlining: a run-time count makes the loop slower;
     * docs/measurements.md#kernel-forms-on-pocl) */
    const ClpTile t = clp_tile(tile_of_group, tiles_x, tiles_y, ASTIGMATISM_TILE_W,
                               ASTIGMATISM_TILE_H, ASTIGMATISM_PAD, ASTIGMATISM_LANES);
    const int tile_id = t.id, x = t.x, y = t.y, pw = t.pw, jc = t.jc;
    const size_t pn = t.pn;
    /* colour: an inner tile (all its reads inside the frame) reads the source planes, the others
     * the padded copy (astigmatism_pad fills only the ring they read) */
    const int in = inner[tile_id];
    __global const float *col = in ? src + ((size_t)y * width + x) : padded + jc;
    const int stride = in ? width : pw;
    const size_t plane = in ? (size_t)width * height : pn;
    /* the pixels' own ellipses: 1/a^2 (a tap outside gets no weight). The 1e-3 px^2 keeps
     * a = 0 finite and the weights' argument below 4e6, where astigmatism_sat16 is exact in float */
    const AVEC as = AVLOAD(axes + jc), at = AVLOAD(axes + pn + jc);
    /* box (compile-time after inlining: a point class): the ellipses shrunk by
     * ASTIGMATISM_POINT_SHRINK px^2 per axis, a'^2 = max(a^2 - S, 0), for the box filter's and the
     * tap rounding's own variance (clpost/stages/astigmatism.py, "Point taps") */
    const float shrink = box ? ASTIGMATISM_POINT_SHRINK : 0.0f;
    const AVEC is2 = 1.0f / (fmax(as * as - shrink, 0.0f) + 1e-3f), it2 = 1.0f / (fmax(at * at - shrink, 0.0f) + 1e-3f);
    /* the tile's bounding ellipse and direction: the tap offsets are the same for all its pixels */
    __global const float *tile = tiles + 4 * tile_id;
    __constant const float *taps = astigmatism_taps + 2 * tap0;
    const float tex = tile[0], tey = tile[1];
    const float bs = box ? sqrt(fmax(tile[2] * tile[2] - shrink, 0.0f)) : tile[2];
    const float bt = box ? sqrt(fmax(tile[3] * tile[3] - shrink, 0.0f)) : tile[3];
    __global const float *pc = pre + jc;  /* a point class's taps: pre, padded layout */
    /* every weight scaled by kn = 1/ntaps (folded into the membership clamp, no extra operation),
     * so the running sums stay below the largest colour: unscaled, up to ntaps colours near
     * FLT_MAX overflowed to inf. The tap counts are powers of two, so the scaling is exact and
     * the result, sum / wsum, is the same bits as without it (but for weights below 1e-36) */
    const float kn = 1.0f / (float)ntaps;
    AVEC ar = 0.0f, ag = 0.0f, ab = 0.0f, wsum = 0.0f;
    /* unrolled by 4, not fully: a full unroll of 64 float16 taps takes tens of seconds to build
     * cold for about the same speed. By hand (a constant 4-trip inner loop): '#pragma unroll 4'
     * in this inlined function was refused for one of the kernels ("loop not unrolled").
     * Every tap count is a multiple of 4 (docs/measurements.md#kernel-forms-on-pocl). */
    for (int k4 = 0; k4 < ntaps; k4 += 4)
#pragma unroll
    for (int k = k4; k < k4 + 4; ++k) {
        const float us = bs * taps[2 * k], ut = bt * taps[2 * k + 1];
        const float ox = -tey * us + tex * ut, oy = tex * us + tey * ut;
        /* floor and round by truncating positive numbers (|offset| < PAD) */
        const int ix = (int)(ox + (float)ASTIGMATISM_PAD) - ASTIGMATISM_PAD;
        const int iy = (int)(oy + (float)ASTIGMATISM_PAD) - ASTIGMATISM_PAD;
        const int nx = (int)(ox + ((float)ASTIGMATISM_PAD + 0.5f)) - ASTIGMATISM_PAD;
        const int ny = (int)(oy + ((float)ASTIGMATISM_PAD + 0.5f)) - ASTIGMATISM_PAD;
        const float fx = ox - (float)ix, fy = oy - (float)iy;
        const float us2 = us * us, ut2 = ut * ut;
        /* does the source pixel's own ellipse (+ half a pixel) reach back to the target? weight 1
         * inside, 0 from 1.25 times its size (in q^2: 1 .. 1.5625). Is the tap inside the
         * target's own ellipse? weight 1 inside, 0 from q^2 = 1.125 */
        const AVEC own = ASATN(9.0f * kn - (8.0f * kn) * (us2 * is2 + ut2 * it2), kn);
        AVEC w = own;
        if (test_reach) {  /* compile-time after inlining: 1 on the tiles astigmatism_reach flags */
            __global const float *an = axes + jc + ny * pw + nx;
            const AVEC q2 = us2 * AVLOAD(an + 2 * pn) + ut2 * AVLOAD(an + 3 * pn);
            w *= ASAT((1.5625f - q2) * (1.0f / 0.5625f));
        }
        if (box) {  /* one load per channel: pre at floor(x + o), its box centred within 1/2 px of x + o */
            __global const float *p = pc + iy * pw + ix;
            ar = mad(w, AVLOAD(p), ar);
            ag = mad(w, AVLOAD(p + pn), ag);
            ab = mad(w, AVLOAD(p + 2 * pn), ab);
        } else {
            /* the bilinear weights are the tap's (scalars, the same for every lane): interpolate,
             * then weigh by the lane's w (no per-lane products of the four corner weights) */
            const float b00 = (1.0f - fx) * (1.0f - fy), b01 = fx * (1.0f - fy), b10 = (1.0f - fx) * fy, b11 = fx * fy;
            __global const float *p = col + iy * stride + ix;
            ar = mad(w, b00 * AVLOAD(p) + b01 * AVLOAD(p + 1) + b10 * AVLOAD(p + stride) + b11 * AVLOAD(p + stride + 1), ar);
            p += plane;
            ag = mad(w, b00 * AVLOAD(p) + b01 * AVLOAD(p + 1) + b10 * AVLOAD(p + stride) + b11 * AVLOAD(p + stride + 1), ag);
            p += plane;
            ab = mad(w, b00 * AVLOAD(p) + b01 * AVLOAD(p + 1) + b10 * AVLOAD(p + stride) + b11 * AVLOAD(p + stride + 1), ab);
        }
        wsum += w;
    }
    /* copy where both semi-axes are below 1e-3 px or no tap has weight */
    const AIVEC keep = ((as < ASTIGMATISM_MIN_SEMI) & (at < ASTIGMATISM_MIN_SEMI)) | !(wsum > 0.0f);
    const AVEC inv = 1.0f / select(wsum, (AVEC)1.0f, keep);
    const AVEC r = select(ar * inv, AVLOAD(col), keep);
    const AVEC g = select(ag * inv, AVLOAD(col + plane), keep);
    const AVEC b = select(ab * inv, AVLOAD(col + 2 * plane), keep);
    ASTORE(dst, r, g, b, x, y, width, height);
}

/* The entry of the class's list that this work-group takes, or -1 (it returns at once): the
 * launch has n = tiles_x × tiles_y groups, the class c <= n listed tiles (list0 = class × n: the
 * row of the class in lists, whose length astigmatism_tiles counted in counts[class]). Group g
 * takes entry floor(g c / n) where that steps up to the next group's, so the c busy groups lie
 * evenly among the n — each entry exactly once (the steps of floor(g c / n), g = 0 .. n, are 0 or
 * 1 and sum to c) — instead of as the first c, which PoCL ran on one thread's run of groups.
 * Without ASTIGMATISM_SPREAD: group g takes entry g if g < c. */
#ifndef ASTIGMATISM_SPREAD
#define ASTIGMATISM_SPREAD 1
#endif
inline int astigmatism_slot(__global const int *restrict counts, const int list0, const int tiles_x,
                            const int tiles_y)
{
    const long n = (long)tiles_x * tiles_y, g = get_group_id(0);
    const long c = counts[list0 / n];
#if ASTIGMATISM_SPREAD
    const long j = g * c / n;
    return (g + 1) * c / n > j ? (int)j : -1;
#else
    return g < c ? (int)g : -1;
#endif
}
/* `tile`: the tile id this work-group gathers; return when it takes none */
#define ASTIGMATISM_LISTED(tile, list, counts, list0, tiles_x, tiles_y) \
    const int tile##_slot = astigmatism_slot(counts, list0, tiles_x, tiles_y); \
    if (tile##_slot < 0) return; \
    const int tile = (list)[(list0) + tile##_slot]

#define ASTIGMATISM_GATHER_ARGS __global const float *restrict padded, __global const float *restrict src, \
    __global const float *restrict pre, __global const int *restrict inner, __global const int *restrict reach, \
    __global const float *restrict axes, \
    __global float *restrict dst, __global const float *restrict tiles, __global const int *restrict list, \
    __global const int *restrict counts, const int list0, const int tiles_x, const int tiles_y, const int width, \
    const int height
/* the reach test is group-uniform (one tile per work-group): two inlined copies of the loop */
#define ASTIGMATISM_GATHER_CALL(n, t0, box) \
    ASTIGMATISM_LISTED(tile, list, counts, list0, tiles_x, tiles_y); \
    if (reach[tile]) \
        astigmatism_gather(padded, src, pre, box, inner, 1, axes, dst, tiles, tile, tiles_x, tiles_y, width, \
                           height, n, t0); \
    else \
        astigmatism_gather(padded, src, pre, box, inner, 0, axes, dst, tiles, tile, tiles_x, tiles_y, width, \
                           height, n, t0)

/* the quality's ASTIGMATISM_TAPS (its spiral is the table's last) */
__kernel void astigmatism(ASTIGMATISM_GATHER_ARGS) { ASTIGMATISM_GATHER_CALL(ASTIGMATISM_TAPS, ASTIGMATISM_FULL_TAP0, 0); }
/* the smaller classes: astigmatism_t<n>, the spiral of n points at its table offset, and the point
 * classes astigmatism_p<n> — generated after this file from Astigmatism.tap_classes() and
 * POINT_CLASSES (clpost/stages/astigmatism_cl.py) */

/* the tiles whose bounding semi-axis is below ASTIGMATISM_COPY_PX: copied through (the gather's
 * geometry: ASTIGMATISM_LANES pixels per work-item) */
__kernel void astigmatism_copy(__global const float *restrict padded, __global const float *restrict src,
                               __global const int *restrict inner, __global float *restrict dst,
                               __global const int *restrict list, __global const int *restrict counts,
                               const int list0, const int tiles_x, const int tiles_y, const int width, const int height)
{
    ASTIGMATISM_LISTED(tile, list, counts, list0, tiles_x, tiles_y);
    const ClpTile t = clp_tile(tile, tiles_x, tiles_y, ASTIGMATISM_TILE_W,
                               ASTIGMATISM_TILE_H, ASTIGMATISM_PAD, ASTIGMATISM_LANES);
    const int tile_id = t.id, x = t.x, y = t.y, jc = t.jc;
    const size_t pn = t.pn;
    const int in = inner[tile_id];  /* see astigmatism_gather */
    __global const float *col = in ? src + ((size_t)y * width + x) : padded + jc;
    const size_t plane = in ? (size_t)width * height : pn;
    ASTORE(dst, AVLOAD(col), AVLOAD(col + plane), AVLOAD(col + 2 * plane), x, y, width, height);
}

/* the exact list's kernel, both forms: its arguments and its listed tile */
#define ASTIGMATISM_EXACT_HEAD                                                                          \
__kernel void astigmatism_exact(__global const float *restrict padded, __global const float *restrict src,   \
                       __global const int *restrict inner, __global const float *restrict axes,             \
                       __global float *restrict dst, __global const int *restrict list,                     \
                       __global const int *restrict counts, const int list0, const int tiles_x, const int tiles_y, \
                       const int width, const int height, const float cx, const float cy)                   \
{                                                                                                    \
    ASTIGMATISM_LISTED(tile, list, counts, list0, tiles_x, tiles_y);

/* the per-pixel model (each pixel's own ellipse and direction) for the tiles of the exact list
 * (one work-group per listed tile), all ASTIGMATISM_TAPS spiral points. The 16-lane form (a CPU)
 * is the one-pixel form's arithmetic on 16 pixels of a tile row, its per-pixel reads as per-lane
 * gathers (CLP_GATHER16): PoCL does not vectorise the one-pixel form across work-items
 * (data-dependent addresses; measured in docs/benchmarks.md). */
#if ASTIGMATISM_LANES == 16
ASTIGMATISM_EXACT_HEAD
    const ClpTile t = clp_tile(tile, tiles_x, tiles_y, ASTIGMATISM_TILE_W,
                               ASTIGMATISM_TILE_H, ASTIGMATISM_PAD, 16);
    const int tile_id = t.id, x = t.x, y = t.y, pw = t.pw, jc = t.jc;
    if (y >= height) return;  /* lanes right of the frame are computed, not stored */
    const size_t pn = t.pn;
    const size_t n = (size_t)width * height;
    /* colour as in the one-pixel form below */
    const int in = inner[tile_id];
    __global const float *col = in ? src : padded;
    const int stride = in ? width : pw, off = in ? ASTIGMATISM_PAD : 0;
    const size_t plane = in ? n : pn;
    const int jo = (y + ASTIGMATISM_PAD - off) * stride + (x + ASTIGMATISM_PAD - off);
    const int16 xs = x + (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const float16 as = vload16(0, axes + jc), at = vload16(0, axes + pn + jc);
    const float16 dx = convert_float16(xs) - cx;
    const float dy = (float)y - cy;
    const float16 r = sqrt(dx * dx + dy * dy);
    const int16 pos = r > 0.0f;
    const float16 ex = select((float16)1.0f, dx / r, pos), ey = select((float16)0.0f, dy / r, pos);
    const float16 bx = convert_float16(xs + ASTIGMATISM_PAD);
    const float by = (float)(y + ASTIGMATISM_PAD);
    float16 ar = 0.0f, ag = 0.0f, ab = 0.0f, wsum = 0.0f;
    for (int k = 0; k < ASTIGMATISM_TAPS; ++k) {
        const float ux = astigmatism_taps[2 * (ASTIGMATISM_FULL_TAP0 + k)];
        const float uy = astigmatism_taps[2 * (ASTIGMATISM_FULL_TAP0 + k) + 1];
        const float16 us = as * ux, ut = at * uy;
        const float16 px = bx - ey * us + ex * ut, py = by + ex * us + ey * ut;
        const int16 jn = convert_int16(floor(py + 0.5f)) * pw + convert_int16(floor(px + 0.5f));
        const float16 qs = us / (CLP_GATHER16(axes, jn) + 0.5f), qt = ut / (CLP_GATHER16(axes + pn, jn) + 0.5f);
        const float16 w = clamp((1.5625f - (qs * qs + qt * qt)) * (1.0f / 0.5625f), 0.0f, 1.0f) * (1.0f / ASTIGMATISM_TAPS);
        const float16 fx0 = floor(px), fy0 = floor(py);
        const float16 fx = px - fx0, fy = py - fy0;
        const int16 j = (convert_int16(fy0) - off) * stride + convert_int16(fx0) - off;
        const int16 j1 = j + 1, js = j + stride, js1 = j + stride + 1;
        __global const float *c = col;
        ar += w * mix(mix(CLP_GATHER16(c, j), CLP_GATHER16(c, j1), fx), mix(CLP_GATHER16(c, js), CLP_GATHER16(c, js1), fx), fy);
        c += plane;
        ag += w * mix(mix(CLP_GATHER16(c, j), CLP_GATHER16(c, j1), fx), mix(CLP_GATHER16(c, js), CLP_GATHER16(c, js1), fx), fy);
        c += plane;
        ab += w * mix(mix(CLP_GATHER16(c, j), CLP_GATHER16(c, j1), fx), mix(CLP_GATHER16(c, js), CLP_GATHER16(c, js1), fx), fy);
        wsum += w;
    }
    /* the one-pixel form copies where both semi-axes are below the minimum, or no tap has weight */
    const int16 keep = ((as < ASTIGMATISM_MIN_SEMI) & (at < ASTIGMATISM_MIN_SEMI)) | !(wsum > 0.0f);
    astigmatism_store16(dst, select(ar / wsum, vload16(0, col + jo), keep),
                        select(ag / wsum, vload16(0, col + plane + jo), keep),
                        select(ab / wsum, vload16(0, col + 2 * plane + jo), keep), x, y, width, height);
}
#else
/* the one-pixel form (a GPU: a tile per work-group of TILE_W × TILE_H work-items) */
ASTIGMATISM_EXACT_HEAD
    const ClpTile t = clp_tile(tile, tiles_x, tiles_y, ASTIGMATISM_TILE_W,
                               ASTIGMATISM_TILE_H, ASTIGMATISM_PAD, 1);
    const int tile_id = t.id, x = t.x, y = t.y, pw = t.pw, jc = t.jc;
    if (x >= width || y >= height) return;
    const size_t pn = t.pn;
    const size_t n = (size_t)width * height;
    const size_t i = (size_t)y * width + x;
    /* colour: an inner tile reads the source planes (see astigmatism_gather); padded coordinates
     * (px, py) map to col[(py - off) * stride + px - off] */
    const int in = inner[tile_id];
    __global const float *col = in ? src : padded;
    const int stride = in ? width : pw, off = in ? ASTIGMATISM_PAD : 0;
    const size_t plane = in ? n : pn;
    const int jo = (y + ASTIGMATISM_PAD - off) * stride + (x + ASTIGMATISM_PAD - off);
    const float as = axes[jc], at = axes[pn + jc];
    if (as < ASTIGMATISM_MIN_SEMI && at < ASTIGMATISM_MIN_SEMI) {
        dst[i] = col[jo];
        dst[n + i] = col[plane + jo];
        dst[2 * n + i] = col[2 * plane + jo];
        return;
    }
    const float dx = (float)x - cx, dy = (float)y - cy;
    const float r = sqrt(dx * dx + dy * dy);
    const float ex = r > 0.0f ? dx / r : 1.0f, ey = r > 0.0f ? dy / r : 0.0f;
    const float bx = (float)(x + ASTIGMATISM_PAD), by = (float)(y + ASTIGMATISM_PAD);
    float ar = 0.0f, ag = 0.0f, ab = 0.0f, wsum = 0.0f;
    for (int k = 0; k < ASTIGMATISM_TAPS; ++k) {
        const float ux = astigmatism_taps[2 * (ASTIGMATISM_FULL_TAP0 + k)];
        const float uy = astigmatism_taps[2 * (ASTIGMATISM_FULL_TAP0 + k) + 1];
        const float us = as * ux, ut = at * uy;
        const float px = bx - ey * us + ex * ut, py = by + ex * us + ey * ut;
        /* does the source pixel's own ellipse (+ half a pixel) reach back to the target? */
        const int jn = (int)floor(py + 0.5f) * pw + (int)floor(px + 0.5f);
        const float qs = us / (axes[jn] + 0.5f), qt = ut / (axes[pn + jn] + 0.5f);
        /* scaled by 1/ASTIGMATISM_TAPS (a power of two: exact), so the sums stay finite (see
         * astigmatism_gather) */
        const float w = clamp((1.5625f - (qs * qs + qt * qt)) * (1.0f / 0.5625f), 0.0f, 1.0f) * (1.0f / ASTIGMATISM_TAPS);
        const float fx0 = floor(px), fy0 = floor(py);
        const float fx = px - fx0, fy = py - fy0;
        const int j = ((int)fy0 - off) * stride + (int)fx0 - off;
        __global const float *c = col + j;
        ar += w * mix(mix(c[0], c[1], fx), mix(c[stride], c[stride + 1], fx), fy);
        c += plane;
        ag += w * mix(mix(c[0], c[1], fx), mix(c[stride], c[stride + 1], fx), fy);
        c += plane;
        ab += w * mix(mix(c[0], c[1], fx), mix(c[stride], c[stride + 1], fx), fy);
        wsum += w;
    }
    const bool keep = !(wsum > 0.0f);
    dst[i] = keep ? col[jo] : ar / wsum;
    dst[n + i] = keep ? col[plane + jo] : ag / wsum;
    dst[2 * n + i] = keep ? col[2 * plane + jo] : ab / wsum;
}
#endif
