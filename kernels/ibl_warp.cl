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
static float3 warp_sample(__global const float *src, const int src_w, const int src_h,
                          const int px_stride, const int row_stride, const int ch_stride,
                          __global const float4 *nodes, const int gx_n, const int gy_n,
                          const float node_x0, const float node_y0, const float inv_sx, const float inv_sy,
                          const int x, const int y)
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
    float val[3];
    for (int c = 0; c < 3; ++c) {
        __global const float *s = src + c * ch_stride + iv * row_stride + iu * px_stride;
        val[c] = n.z * mix(mix(s[0], s[px_stride], fu), mix(s[row_stride], s[row_stride + px_stride], fu), fv);
    }
    return (float3)(val[0], val[1], val[2]);
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
                                 node_x0, node_y0, inv_sx, inv_sy, x, y);
    const int out_plane = out_w * out_h;
    const int o = y * out_w + x;
    acc[o] += v.x;
    acc[out_plane + o] += v.y;
    acc[2 * out_plane + o] += v.z;
}

/* cell_i: 11 ints per cell: box i0, i1, j0, j1; src offset (floats) of the render's first (bottom)
 * row, src_w, src_h; node offset (float4s), gx_n, gy_n; src row stride (pixels: src_w for a render
 * stored alone, the page's width for one tile of a page of renders). cell_f: per cell (node_x0,
 * node_y0, inv_sx, inv_sy). */
__kernel void ibl_warp_cells(__global const float *src, __global const float4 *nodes,
                             __global const int *cell_i, __global const float4 *cell_f, const int n_cells,
                             __global float *acc, const int out_w, const int out_h)
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
        sum += warp_sample(top, ci[5], ci[6], 4, -4 * ci[10], 1, nodes + ci[7], ci[8], ci[9], cf.x, cf.y, cf.z, cf.w,
                           x, y);
    }
    const int out_plane = out_w * out_h;
    const int o = y * out_w + x;
    acc[o] += sum.x;
    acc[out_plane + o] += sum.y;
    acc[2 * out_plane + o] += sum.z;
}
