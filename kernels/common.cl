/* Shared definitions for every clpost kernel (prepended to each program by clpost.pipeline).
 *
 * Layout: images are float32. "Interleaved" is the host layout (H, W, 3) — pixel i's channels at
 * 3i, 3i+1, 3i+2. "Planar" is the device layout for gathers — channel c of pixel i at c*n + i,
 * with n = W*H — because PoCL vectorises across work-items when addresses are affine in the id.
 * Global size is (W, H): get_global_id(0) is x, row 0 is the top row (CONVENTIONS.md).
 */

/* Where a pointwise function is evaluated. */
typedef struct {
    int x;        /* column, pixel centre at x */
    int y;        /* row, 0 at the top */
    int width;
    int height;
    size_t i;     /* y * width + x: index into depth[], and velocity[2i], velocity[2i+1] */
} PixelCtx;

/* 16 consecutive pixels of one row (pixel k at x0 + k, index i0 + k): the context of the
 * 16-pixel instantiation of a pointwise stage's width-generic <name>_apply (clpost/codegen.py). */
typedef struct {
    int x0;
    int y;
    int width;
    int height;
    size_t i0;
} PixelCtx16;

#define CLP_LANES16 ((float16)(0.0f, 1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 6.0f, 7.0f, \
                               8.0f, 9.0f, 10.0f, 11.0f, 12.0f, 13.0f, 14.0f, 15.0f))

#define CLP_ULANES16 ((uint16)(0u, 1u, 2u, 3u, 4u, 5u, 6u, 7u, 8u, 9u, 10u, 11u, 12u, 13u, 14u, 15u))

/* any lane of a comparison's int16 true: an OR tree, which LLVM reduces in 4 vector steps —
 * PoCL's any() tests the 16 lanes one by one with a branch each (≈ 40 instructions; the Poisson
 * search's loop test, kernels/random.cl CLP_ANY). */
inline int clp_any16(const int16 c) {
    const int8 a = c.lo | c.hi;
    const int4 b = a.lo | a.hi;
    const int2 d = b.lo | b.hi;
    return (d.x | d.y) < 0;
}

/* table[idx] per lane (a data-dependent gather has no vector builtin) */
#define CLP_GATHER16(table, idx) ((float16)( \
    (table)[(idx).s0], (table)[(idx).s1], (table)[(idx).s2], (table)[(idx).s3], \
    (table)[(idx).s4], (table)[(idx).s5], (table)[(idx).s6], (table)[(idx).s7], \
    (table)[(idx).s8], (table)[(idx).s9], (table)[(idx).sa], (table)[(idx).sb], \
    (table)[(idx).sc], (table)[(idx).sd], (table)[(idx).se], (table)[(idx).sf]))

/* the same for a uint table */
#define CLP_GATHER16U(table, idx) ((uint16)( \
    (table)[(idx).s0], (table)[(idx).s1], (table)[(idx).s2], (table)[(idx).s3], \
    (table)[(idx).s4], (table)[(idx).s5], (table)[(idx).s6], (table)[(idx).s7], \
    (table)[(idx).s8], (table)[(idx).s9], (table)[(idx).sa], (table)[(idx).sb], \
    (table)[(idx).sc], (table)[(idx).sd], (table)[(idx).se], (table)[(idx).sf]))

/* The tile of a tiled gather (astigmatism, coma; clpost/stages/_field.py "Tiles"): work-group g
 * takes tile `tile_id` (from its list); a work-item does `lanes` consecutive pixels of a tile row
 * from (x, y). The padded planes hold whole tiles plus `pad` on every side: row pitch pw, plane
 * size pn, and pixel (x, y) at index jc. */
typedef struct {
    int id, tx, ty;
    int x, y;
    int pw;
    size_t pn;
    int jc;
} ClpTile;

inline ClpTile clp_tile(const int tile_id, const int tiles_x, const int tiles_y, const int tile_w,
                        const int tile_h, const int pad, const int lanes)
{
    ClpTile t;
    t.id = tile_id;
    t.tx = tile_id % tiles_x;
    t.ty = tile_id / tiles_x;
    t.x = t.tx * tile_w + lanes * (int)get_local_id(0);
    t.y = t.ty * tile_h + (int)get_local_id(1);
    t.pw = tiles_x * tile_w + 2 * pad;
    t.pn = (size_t)t.pw * (size_t)(tiles_y * tile_h + 2 * pad);
    t.jc = (t.y + pad) * t.pw + t.x + pad;
    return t;
}

/* 16 pixels of a row (x .. x + 15) into a planar RGB image. `whole` (a compile-time constant at
 * the call site): the frame is whole tiles, every vector lies inside; otherwise rows below the
 * frame and pixels right of it are computed by the caller but not stored. */
inline void clp_store16_planar(__global float *restrict dst, const float16 r, const float16 g,
                               const float16 b, const int x, const int y, const int width,
                               const int height, const int whole)
{
    const size_t n = (size_t)width * height;
    const size_t i = (size_t)y * width + x;
    if (whole) {
        vstore16(r, 0, dst + i);
        vstore16(g, 0, dst + n + i);
        vstore16(b, 0, dst + 2 * n + i);
        return;
    }
    if (y >= height) return;
    float rr[16], gg[16], bb[16];
    vstore16(r, 0, rr);
    vstore16(g, 0, gg);
    vstore16(b, 0, bb);
    for (int e = 0; e < 16 && x + e < width; ++e) {
        dst[i + e] = rr[e];
        dst[n + i + e] = gg[e];
        dst[2 * n + i + e] = bb[e];
    }
}

/* Scalar loads and stores, not vload3/vstore3: on PoCL 3.0 a vload3/vstore3 stops the
 * vectorisation across work-items of the whole kernel (docs/measurements.md#kernel-forms-on-pocl). */
inline float3 load_interleaved(__global const float *buf, const size_t i) {
    return (float3)(buf[3 * i], buf[3 * i + 1], buf[3 * i + 2]);
}

inline void store_interleaved(__global float *buf, const size_t i, const float3 c) {
    buf[3 * i] = c.x;
    buf[3 * i + 1] = c.y;
    buf[3 * i + 2] = c.z;
}

inline float3 load_planar(__global const float *buf, const size_t i, const size_t n) {
    return (float3)(buf[i], buf[n + i], buf[2 * n + i]);
}

inline void store_planar(__global float *buf, const size_t i, const size_t n, const float3 c) {
    buf[i] = c.x;
    buf[n + i] = c.y;
    buf[2 * n + i] = c.z;
}
