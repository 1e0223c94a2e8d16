/* ibl_warp: one projection of the image-based lens model (Heidrich, Slusallek & Seidel 1997,
 * sec. 3.5) mapped onto the film and accumulated.
 *
 * The projection's render `src` (planar R, G, B; src_w x src_h) is texture-mapped onto a regular
 * grid of film nodes (gx_n x gy_n, float4 per node: u, v = render pixel coordinates of the ray's
 * image-plane intersection, w = the weight W(x') = cos t' cos t'' / |x'' - x'|^2, 0 where the
 * ray is vignetted). Each output pixel of the cell's box (launched with the box's origin
 * px0, py0 so every work-item owns one pixel) interpolates its node values bilinearly, samples
 * the render bilinearly at (u, v) and adds w * colour to the planar accumulator `acc`.
 * Node i of the grid is at output pixel x = node_x0 + i / inv_sx (likewise y).
 * Cells of one pupil sample do not overlap and launches are serialised on the in-order queue,
 * so the read-modify-write of `acc` needs no atomics.
 */
__kernel void ibl_warp(__global const float *src, const int src_w, const int src_h,
                       __global const float4 *nodes, const int gx_n, const int gy_n,
                       const float node_x0, const float node_y0, const float inv_sx, const float inv_sy,
                       __global float *acc, const int out_w, const int out_h,
                       const int px0, const int py0)
{
    const int x = px0 + (int)get_global_id(0);
    const int y = py0 + (int)get_global_id(1);
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
        return;
    /* the render has a margin around the frustum; the clamp keeps rounding inside the image */
    const float u = clamp(n.x, 0.0f, (float)(src_w - 1));
    const float v = clamp(n.y, 0.0f, (float)(src_h - 1));
    const int iu = min((int)u, src_w - 2);
    const int iv = min((int)v, src_h - 2);
    const float fu = u - (float)iu;
    const float fv = v - (float)iv;
    const int plane = src_w * src_h;
    const int out_plane = out_w * out_h;
    const int o = y * out_w + x;
    for (int c = 0; c < 3; ++c) {
        __global const float *s = src + c * plane + iv * src_w + iu;
        const float val = mix(mix(s[0], s[1], fu), mix(s[src_w], s[src_w + 1], fu), fv);
        acc[c * out_plane + o] += n.z * val;
    }
}
