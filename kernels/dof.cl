/* dof (the stage's main kernel, `dof`): scatter-as-gather on a per-tile lattice of stride
 * s = 2^l over the tent-prefiltered level l (dof_levels.cl), near/far layers, bladed + textured +
 * cat's-eye bokeh; and the half-resolution composite. Every formula is in clpost/stages/dof.py
 * (the float64 reference mirrors this line by line).
 * Structural: DOF_TILE (= local size), DOF_RMAX, DOF_SCALE, DOF_BUDGET, DOF_LEVELS, DOF_VIGNETTING.
 * The tap count and stride are uniform per work-group (one tile), tap offsets uniform across
 * work-items, and borders are padded, so no tap is clamped.
 */

#define DOF_FRONT_MARGIN 1.0f

typedef struct { float3 F, B; float wf, wb; } DofAcc;

/* one source tap: colour c, signed CoC rq at offset (dx, dy) px, |o| = dist px */
inline void dof_tap(DofAcc *acc, const float3 c, const float rq, const float rp, const float dist,
                    const float rhof, const float rhon, const float inv_s, const float cell,
                    const float sa, const int x, const int y, const int dx, const int dy,
                    const float pvq, const float vig, const float cx, const float cy, const float inv_half)
{
    const int front = rq < rp - DOF_FRONT_MARGIN;
    const int behind = rq > rp + DOF_FRONT_MARGIN;
    const float r = behind ? fmax(fabs(rp), 0.5f) : fmax(fabs(rq), 0.5f);
    const int far = rq >= 0.0f;
    const float rho = far ? rhof : rhon;
    const float rr = r * rho;
    const float cov = clamp((rr - dist) * inv_s + 0.5f, 0.0f, 1.0f);
    const float t = fmin(dist / rr, 1.0f);
    const float a = far ? -sa : sa;
    float w = cov * (1.0f + a * (2.0f * t * t - 1.0f)) * cell / (r * r);
#if DOF_VIGNETTING
    {
        const float hx = ((float)(x + dx) - cx) * inv_half, hy = ((float)(y + dy) - cy) * inv_half;
        const float sgn = far ? 1.0f : -1.0f;
        const float ax = -(float)dx / (r * sgn), ay = -(float)dy / (r * sgn);
        const float ex = ax - vig * hx, ey = ay - vig * hy;
        const float e = sqrt(ex * ex + ey * ey);
        /* per-source pupil area (pv = 1/area fraction): the clipped bokeh keeps its energy */
        w *= clamp((1.0f - e) * r + 0.5f, 0.0f, 1.0f) * pvq;
    }
#endif
    /* selects, not branches: PoCL vectorises the tap loop across work-items */
    const float wfr = front ? w : 0.0f, wbk = w - wfr;
    acc->F += wfr * c; acc->wf += wfr;
    acc->B += wbk * c; acc->wb += wbk;
}

/* launched with local size (DOF_TILE, DOF_TILE): one work-group per tile */
__kernel void dof(__global const float *restrict lv, __global const float *restrict pv,
                  __global const int *restrict tn,
                  __constant const int *restrict tap_dx, __constant const int *restrict tap_dy,
                  __constant const float *restrict tap_dist, __constant const float *restrict rho_far,
                  __constant const float *restrict rho_near,
                  __global float *restrict out, __global float *restrict alpha_out,
                  const int ww, const int hw, const int pad, const int tw,
                  const float inv_area, const float sa, const float vig,
                  const float cx, const float cy, const float inv_half)
{
    const int x = get_global_id(0), y = get_global_id(1);
    /* per work-group (= tile) values from the group id: provably uniform, so the tap loop's trip
     * count and offsets are the same for every work-item; edge-tile work-items beyond the image
     * read the padding (DOF_PW) and only skip the final write */
    const int packed = tn[get_group_id(1) * tw + get_group_id(0)];
    const int count = packed & 0xffffff, lvl = packed >> 24;
    const int s = 1 << lvl;
    const float fs = (float)s, inv_s = 1.0f / fs, cell = fs * fs * inv_area;
    const int pw = DOF_PW(ww, pad);
    const size_t pn = (size_t)pw * DOF_PW(hw, pad);
    const size_t c0 = (size_t)(y + pad) * pw + (x + pad);
    __global const float *L = lv + (size_t)4 * lvl * pn;
    const float rp = lv[3 * pn + c0];
    DofAcc acc = {(float3)(0.0f), (float3)(0.0f), 0.0f, 0.0f};
    {
        /* centre tap: own colour, blended toward the level's as p's own bokeh outgrows the
         * lattice spacing (a point light's centre must not stay a one-pixel spike) */
        const float beta = clamp(fabs(rp) * inv_s, 0.0f, 1.0f);
        const float3 own = (float3)(lv[c0], lv[pn + c0], lv[2 * pn + c0]);
        const float3 lc = (float3)(L[c0], L[pn + c0], L[2 * pn + c0]);
        dof_tap(&acc, own * (1.0f - beta) + lc * beta, rp, rp, 0.0f, rho_far[0], rho_near[0], inv_s, cell, sa,
                x, y, 0, 0, pv[DOF_VIGNETTING ? c0 : 0], vig, cx, cy, inv_half);
    }
    for (int k = 1; k < count; ++k) {
        const int dx = s * tap_dx[k], dy = s * tap_dy[k];
        const size_t q = (size_t)((long)c0 + (long)dy * pw + dx);
        const float3 c = (float3)(L[q], L[pn + q], L[2 * pn + q]);
        dof_tap(&acc, c, L[3 * pn + q], rp, fs * tap_dist[k], rho_far[k], rho_near[k], inv_s, cell, sa,
                x, y, dx, dy, pv[DOF_VIGNETTING ? q : 0], vig, cx, cy, inv_half);
    }
    const float alpha = fmin(1.0f, acc.wf);
    const float3 fr = acc.wf > 0.0f ? acc.F / acc.wf : (float3)(0.0f);
    const float3 res = alpha * fr + (1.0f - alpha) * (acc.B / acc.wb);
    if (x < ww && y < hw) {
        const size_t n = (size_t)ww * hw, i = (size_t)y * ww + x;
        out[i] = res.x; out[n + i] = res.y; out[2 * n + i] = res.z;
        alpha_out[i] = alpha;
    }
}

/* Half-resolution levels: keep in-focus pixels at full resolution, take the upsampled blur where
 * the full-resolution CoC or the front layer's coverage says so. Upsampling is bilinear weighted
 * by CoC similarity g = 1/(1/4 + (r - s r_i)^2) (see _upsample in clpost/stages/dof.py). */
__kernel void dof_upsample(__global const float *restrict src, __global const float *restrict coc,
                           __global const float *restrict blur, __global const float *restrict alpha,
                           __global const float *restrict lv, __global float *restrict dst,
                           const int width, const int height, const int ww, const int hw, const int pad)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    const float sx = ((float)x + 0.5f) / DOF_SCALE - 0.5f, sy = ((float)y + 0.5f) / DOF_SCALE - 0.5f;
    const int x0 = clamp((int)floor(sx), 0, ww - 1), y0 = clamp((int)floor(sy), 0, hw - 1);
    const float fx = clamp(sx - (float)x0, 0.0f, 1.0f), fy = clamp(sy - (float)y0, 0.0f, 1.0f);
    const int x1 = min(x0 + 1, ww - 1), y1 = min(y0 + 1, hw - 1);
    const size_t n = (size_t)width * height, i = (size_t)y * width + x, nw = (size_t)ww * hw;
    const int pw = DOF_PW(ww, pad);
    __global const float *pr = lv + (size_t)3 * pw * DOF_PW(hw, pad);  /* level 0 CoC */
    const float r = coc[i];
    /* the four corners written out instead of private arrays (13.5 -> 8 ms at 640x360, measured) */
#define DOF_CORNER(XS, YS, BW) { \
        const size_t j = (size_t)(YS) * ww + (XS); \
        const float dr = r - DOF_SCALE * pr[(size_t)((YS) + pad) * pw + (XS) + pad]; \
        const float g = (BW) / (0.25f + dr * dr); \
        acc += g * (float4)(blur[j], blur[nw + j], blur[2 * nw + j], alpha[j]); \
        wsum += g; }
    float4 acc = (float4)(0.0f);
    float wsum = 0.0f;
    DOF_CORNER(x0, y0, (1.0f - fx) * (1.0f - fy))
    DOF_CORNER(x1, y0, fx * (1.0f - fy))
    DOF_CORNER(x0, y1, (1.0f - fx) * fy)
    DOF_CORNER(x1, y1, fx * fy)
#undef DOF_CORNER
    acc /= wsum;
    const float b = fmax(clamp(fabs(r) - 0.5f, 0.0f, 1.0f), acc.w);
    const float3 c = (float3)(src[i], src[n + i], src[2 * n + i]);
    const float3 o = c * (1.0f - b) + acc.xyz * b;  /* exact at b = 1 even for 1e8 highlights */
    dst[i] = o.x; dst[n + i] = o.y; dst[2 * n + i] = o.z;
}
