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

inline float3 load_interleaved(__global const float *buf, const size_t i) {
    return vload3(i, buf);
}

inline void store_interleaved(__global float *buf, const size_t i, const float3 c) {
    vstore3(c, i, buf);
}

inline float3 load_planar(__global const float *buf, const size_t i, const size_t n) {
    return (float3)(buf[i], buf[n + i], buf[2 * n + i]);
}

inline void store_planar(__global float *buf, const size_t i, const size_t n, const float3 c) {
    buf[i] = c.x;
    buf[n + i] = c.y;
    buf[2 * n + i] = c.z;
}
