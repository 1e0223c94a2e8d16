/* ibl_warp: projections of the image-based lens model (Heidrich, Slusallek & Seidel 1997,
 * sec. 3.5) mapped onto the film and accumulated.
 *
 * A projection's render `src` (src_w x src_h; ibl_warp: planar R, G, B; ibl_warp_cells: RGBA pixels,
 * rows bottom-up as OpenGL reads them back) is texture-mapped onto a regular grid of film nodes (gx_n x gy_n, float4 per node: u, v =
 * render pixel coordinates of the ray's image-plane intersection, w = the weight
 * W(x') = cos t' cos t'' / |x'' - x'|^2, 0 where the ray is vignetted). Each output pixel of the cell's box interpolates its node values
 * bilinearly, samples the render bilinearly at (u, v) and adds w * colour to the planar
 * accumulator `acc`. Node i of the grid is at output pixel x = node_x0 + i / inv_sx (likewise y).
 *
 * ibl_warp: one projection per launch (launched with the box's origin px0, py0 so every
 * work-item owns one pixel of the box). Cells of one pupil sample do not overlap and launches
 * are serialised on the in-order queue, so the read-modify-write of `acc` needs no atomics.
 * ibl_warp_cells: all projections of a frame in one launch over the output; each pixel loops
 * over the cells in order and adds those whose box holds it (one launch instead of one per
 * projection: the launches, not the arithmetic, were the warp's cost).
 */
/* One texel of a render; with `sky` (ibl_warp_cells, RGBA renders) a texel of alpha 0 — no surface
 * drawn there — is the sky of its direction instead, the formula of pyvista_renderer._sky:
 * d = R (x, y, 1) with x = (iu - cx) / f, y = (iv - cy) / f (iv counted from the image's top row),
 * t = sqrt(clamp(d_z / |d|, 0, 1)), colour = mix(horizon, zenith, t). sky_r0..2: the rows of the
 * camera-to-world rotation R, with w = 1 / f, cx, cy. */
static float3 texel(__global const float *s, const int ch_stride, const int sky, const int iu, const int iv,
                    const float4 sky_r0, const float4 sky_r1, const float4 sky_r2, const float3 horizon,
                    const float3 zenith)
{
    if (sky && !(s[3 * ch_stride] > 0.0f)) {
        const float3 ray = (float3)(((float)iu - sky_r1.w) * sky_r0.w, ((float)iv - sky_r2.w) * sky_r0.w, 1.0f);
        const float3 d = (float3)(dot(sky_r0.xyz, ray), dot(sky_r1.xyz, ray), dot(sky_r2.xyz, ray));
        return mix(horizon, zenith, sqrt(clamp(d.z / length(d), 0.0f, 1.0f)));
    }
    return (float3)(s[0], s[ch_stride], s[2 * ch_stride]);
}

static float3 warp_sample(__global const float *src, const int src_w, const int src_h,
                          const int px_stride, const int row_stride, const int ch_stride,
                          __global const float4 *nodes, const int gx_n, const int gy_n,
                          const float node_x0, const float node_y0, const float inv_sx, const float inv_sy,
                          const int x, const int y, const int sky, const float4 sky_r0, const float4 sky_r1,
                          const float4 sky_r2, const float3 horizon, const float3 zenith)
{
    /* the box lies inside the node grid up to rounding: clamp only absorbs that */
    const float gx = clamp(((float)x - node_x0) * inv_sx, 0.0f, (float)(gx_n - 1));
    const float gy = clamp(((float)y - node_y0) * inv_sy, 0.0f, (float)(gy_n - 1));
    const int ix = min((int)gx, gx_n - 2);
    const int iy = min((int)gy, gy_n - 2);
    const float fx = gx - (float)ix;
    const float fy = gy - (float)iy;
    const int k = iy * gx_n + ix;
    const float4 n = mix(mix(nodes[k], nodes[k + 1], fx), mix(nodes[k + gx_n], nodes[k + gx_n + 1], fx), fy);
    if (!(n.z > 0.0f))
        return (float3)(0.0f);
    /* the render has a margin around the frustum; the clamp keeps rounding inside the image */
    const float u = clamp(n.x, 0.0f, (float)(src_w - 1));
    const float v = clamp(n.y, 0.0f, (float)(src_h - 1));
    const int iu = min((int)u, src_w - 2);
    const int iv = min((int)v, src_h - 2);
    const float fu = u - (float)iu;
    const float fv = v - (float)iv;
    __global const float *s = src + iv * row_stride + iu * px_stride;
    const float3 t00 = texel(s, ch_stride, sky, iu, iv, sky_r0, sky_r1, sky_r2, horizon, zenith);
    const float3 t10 = texel(s + px_stride, ch_stride, sky, iu + 1, iv, sky_r0, sky_r1, sky_r2, horizon, zenith);
    const float3 t01 = texel(s + row_stride, ch_stride, sky, iu, iv + 1, sky_r0, sky_r1, sky_r2, horizon, zenith);
    const float3 t11 = texel(s + row_stride + px_stride, ch_stride, sky, iu + 1, iv + 1, sky_r0, sky_r1, sky_r2,
                             horizon, zenith);
    return n.z * mix(mix(t00, t10, fu), mix(t01, t11, fu), fv);
}

__kernel void ibl_warp(__global const float *src, const int src_w, const int src_h,
                       __global const float4 *nodes, const int gx_n, const int gy_n,
                       const float node_x0, const float node_y0, const float inv_sx, const float inv_sy,
                       __global float *acc, const int out_w, const int out_h,
                       const int px0, const int py0)
{
    const int x = px0 + (int)get_global_id(0);
    const int y = py0 + (int)get_global_id(1);
    const float3 v = warp_sample(src, src_w, src_h, 1, src_w, src_w * src_h, nodes, gx_n, gy_n,
                                 node_x0, node_y0, inv_sx, inv_sy, x, y, 0, (float4)(0.0f), (float4)(0.0f),
                                 (float4)(0.0f), (float3)(0.0f), (float3)(0.0f));
    const int out_plane = out_w * out_h;
    const int o = y * out_w + x;
    acc[o] += v.x;
    acc[out_plane + o] += v.y;
    acc[2 * out_plane + o] += v.z;
}

/* cell_i: 11 ints per cell: box i0, i1, j0, j1; src offset (floats) of the render's first (bottom)
 * row, src_w, src_h; node offset (float4s), gx_n, gy_n; src row stride (pixels: src_w for a render
 * stored alone, the page's width for one tile of a page of renders). cell_f: per cell (node_x0,
 * node_y0, inv_sx, inv_sy). sky != 0: cell_sky holds 3 float4 per cell (texel()'s sky_r0..2) and
 * texels of alpha 0 are the sky (texel()); sky == 0: cell_sky is not read. */
__kernel void ibl_warp_cells(__global const float *src, __global const float4 *nodes,
                             __global const int *cell_i, __global const float4 *cell_f, const int n_cells,
                             __global float *acc, const int out_w, const int out_h,
                             __global const float4 *cell_sky, const int sky, const float4 horizon,
                             const float4 zenith)
{
    const int x = (int)get_global_id(0);
    const int y = (int)get_global_id(1);
    if (x >= out_w || y >= out_h)
        return;
    float3 sum = (float3)(0.0f);
    for (int c = 0; c < n_cells; ++c) {
        __global const int *ci = cell_i + 11 * c;
        if (x < ci[0] || x >= ci[1] || y < ci[2] || y >= ci[3])
            continue;
        const float4 cf = cell_f[c];
        /* RGBA rows bottom-up (OpenGL's order, as read back): row 0 of the image is the last */
        __global const float *top = src + ci[4] + 4 * (ci[6] - 1) * ci[10];
        const float4 r0 = sky ? cell_sky[3 * c] : (float4)(0.0f);
        const float4 r1 = sky ? cell_sky[3 * c + 1] : (float4)(0.0f);
        const float4 r2 = sky ? cell_sky[3 * c + 2] : (float4)(0.0f);
        sum += warp_sample(top, ci[5], ci[6], 4, -4 * ci[10], 1, nodes + ci[7], ci[8], ci[9], cf.x, cf.y, cf.z, cf.w,
                           x, y, sky, r0, r1, r2, horizon.xyz, zenith.xyz);
    }
    const int out_plane = out_w * out_h;
    const int o = y * out_w + x;
    acc[o] += sum.x;
    acc[out_plane + o] += sum.y;
    acc[2 * out_plane + o] += sum.z;
}
