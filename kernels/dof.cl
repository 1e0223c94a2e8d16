/* dof (the stage's main kernel, `dof`): scatter-as-gather over the distance-sorted taps of each tile, near/far layers, bladed +
 * textured + cat's-eye bokeh; and the half-resolution composite. Every formula is in
 * clpost/stages/dof.py (the float64 reference mirrors this line by line).
 * Structural: DOF_TILE (= local size), DOF_RMAX, DOF_SCALE, DOF_VIGNETTING (0/1).
 * The tap count is uniform per work-group (one tile), tap offsets uniform across work-items, and
 * borders are padded, so no tap is clamped.
 */

#define DOF_FRONT_MARGIN 1.0f

/* launched with local size (DOF_TILE, DOF_TILE): one work-group per tile */
__kernel void dof(__global const float *restrict pc, __global const float *restrict pr,
         __global const float *restrict pv,
                __global const int *restrict tn,
                __global const int *restrict tap_dx, __global const int *restrict tap_dy,
                __global const float *restrict tap_dist, __global const float *restrict rho_far,
                __global const float *restrict rho_near,
                __global float *restrict out, __global float *restrict alpha_out,
                const int ww, const int hw, const int pad, const int tw,
                const float inv_area, const float sa, const float vig,
                const float cx, const float cy, const float inv_half)
{
    const int x = get_global_id(0), y = get_global_id(1);
    const int count = tn[(y / DOF_TILE) * tw + x / DOF_TILE];
    if (x >= ww || y >= hw) return;
    const int pw = ww + 2 * pad;
    const size_t pn = (size_t)pw * (hw + 2 * pad);
    const size_t c0 = (size_t)(y + pad) * pw + (x + pad);
    const float rp = pr[c0];
    float3 F = (float3)(0.0f), B = (float3)(0.0f);
    float wf = 0.0f, wb = 0.0f;
    for (int k = 0; k < count; ++k) {
        const int dx = tap_dx[k], dy = tap_dy[k];
        const float dist = tap_dist[k];
        const size_t q = (size_t)((long)c0 + (long)dy * pw + dx);
        const float rq = pr[q];
        const int front = rq < rp - DOF_FRONT_MARGIN;
        const int behind = rq > rp + DOF_FRONT_MARGIN;
        const float r = behind ? fmax(fabs(rp), 0.5f) : fmax(fabs(rq), 0.5f);
        const int far = rq >= 0.0f;
        const float rho = far ? rho_far[k] : rho_near[k];
        const float rr = r * rho;
        const float cov = clamp(rr - dist + 0.5f, 0.0f, 1.0f);
        const float t = fmin(dist / rr, 1.0f);
        const float a = far ? -sa : sa;
        float w = cov * (1.0f + a * (2.0f * t * t - 1.0f)) * inv_area / (r * r);
#if DOF_VIGNETTING
        {
            const float hx = ((float)(x + dx) - cx) * inv_half, hy = ((float)(y + dy) - cy) * inv_half;
            const float sgn = far ? 1.0f : -1.0f;
            const float ax = -(float)dx / (r * sgn), ay = -(float)dy / (r * sgn);
            const float ex = ax - vig * hx, ey = ay - vig * hy;
            const float e = sqrt(ex * ex + ey * ey);
            /* per-source pupil area (pv = 1/area fraction): the clipped bokeh keeps its energy */
            w *= clamp((1.0f - e) * r + 0.5f, 0.0f, 1.0f) * pv[q];
        }
#endif
        const float3 c = (float3)(pc[q], pc[pn + q], pc[2 * pn + q]);
        if (front) { F += w * c; wf += w; } else { B += w * c; wb += w; }
    }
    const float alpha = fmin(1.0f, wf);
    const float3 fr = wf > 0.0f ? F / wf : (float3)(0.0f);
    const float3 res = alpha * fr + (1.0f - alpha) * (B / wb);
    const size_t n = (size_t)ww * hw, i = (size_t)y * ww + x;
    out[i] = res.x; out[n + i] = res.y; out[2 * n + i] = res.z;
    alpha_out[i] = alpha;
}

/* Half-resolution levels: keep in-focus pixels at full resolution, take the upsampled blur where
 * the full-resolution CoC or the front layer's coverage says so. Upsampling is bilinear weighted
 * by CoC similarity g = 1/(1/4 + (r - s r_i)^2) (see _upsample in clpost/stages/dof.py). */
__kernel void dof_upsample(__global const float *restrict src, __global const float *restrict coc,
                           __global const float *restrict blur, __global const float *restrict alpha,
                           __global const float *restrict pr, __global float *restrict dst,
                           const int width, const int height, const int ww, const int hw, const int pad)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    const float sx = ((float)x + 0.5f) / DOF_SCALE - 0.5f, sy = ((float)y + 0.5f) / DOF_SCALE - 0.5f;
    const int x0 = clamp((int)floor(sx), 0, ww - 1), y0 = clamp((int)floor(sy), 0, hw - 1);
    const float fx = clamp(sx - (float)x0, 0.0f, 1.0f), fy = clamp(sy - (float)y0, 0.0f, 1.0f);
    const int x1 = min(x0 + 1, ww - 1), y1 = min(y0 + 1, hw - 1);
    const size_t n = (size_t)width * height, i = (size_t)y * width + x, nw = (size_t)ww * hw;
    const int pw = ww + 2 * pad;
    const float r = coc[i];
    const int xs[4] = {x0, x1, x0, x1}, ys[4] = {y0, y0, y1, y1};
    const float bw[4] = {(1.0f - fx) * (1.0f - fy), fx * (1.0f - fy), (1.0f - fx) * fy, fx * fy};
    float4 acc = (float4)(0.0f);
    float wsum = 0.0f;
    for (int k = 0; k < 4; ++k) {
        const size_t j = (size_t)ys[k] * ww + xs[k];
        const float dr = r - DOF_SCALE * pr[(size_t)(ys[k] + pad) * pw + xs[k] + pad];
        const float g = bw[k] / (0.25f + dr * dr);
        acc += g * (float4)(blur[j], blur[nw + j], blur[2 * nw + j], alpha[j]);
        wsum += g;
    }
    acc /= wsum;
    const float b = fmax(clamp(fabs(r) - 0.5f, 0.0f, 1.0f), acc.w);
    const float3 c = (float3)(src[i], src[n + i], src[2 * n + i]);
    const float3 o = c + (acc.xyz - c) * b;
    dst[i] = o.x; dst[n + i] = o.y; dst[2 * n + i] = o.z;
}
