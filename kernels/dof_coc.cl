/* dof: signed circle of confusion and the padded working-resolution buffers of the gather.
 * Formula, constants and the edge rule are documented in clpost/stages/dof.py:
 *   r_px = k (1/u - 1/S), clamped to +-limit; +inf depth -> 1/S = 0 (finite far limit).
 * Structural: DOF_SCALE (working-resolution divisor). Constants of the colour/depth rules from the stage:
 * DOF_FRINGE_STEP (FRINGE_STEP), DOF_SAME_SOURCE (SAME_SOURCE), DOF_LIGHT_FRINGE (LIGHT_FRINGE).
 */

#define DOF_MIXED_SAME_DEPTH 0.8f

inline float dof_luma(__global const float *src, const size_t i, const size_t n) {
    return DOF_LUMA_R * src[i] + DOF_LUMA_G * src[n + i] + DOF_LUMA_B * src[2 * n + i];
}

/* the light clause of the rules below: p's near neighbour of luma bright_n is a light above
 * DOF_SAME_SOURCE x p whose 1 - DOF_FRINGE_STEP share is above own_min (clamped to 0) and that covers
 * at most DOF_LIGHT_FRINGE of p (sb = bright_n - own_min, pb = lum - own_min); one definition for the
 * one-pixel and the 16-lane forms (scalar 0/1, vector 0/-1) */
#define DOF_LIGHT_CLAUSE(lum, bright_n, own_min, sb, pb)                                              \
    (((bright_n) > DOF_SAME_SOURCE * (lum)) & ((1.0f - DOF_FRINGE_STEP) * (bright_n) > fmax((own_min), 0.0f)) \
     & ((pb) <= DOF_LIGHT_FRINGE * (sb)))
/* the light's tail (dof_coc_tail): the light clause where p's own share also holds, and p stands
 * above DOF_SAME_SOURCE x its surface's third-brightest other pixel hi3 */
#define DOF_TAIL_TAKE(lum, bright_n, own_min, sb, pb, hi3)                                             \
    (((sb) > 0.0f) & (2.0f * (pb) * (bright_n) >= (lum) * (sb)) & DOF_LIGHT_CLAUSE(lum, bright_n, own_min, sb, pb) \
     & ((lum) > DOF_SAME_SOURCE * (hi3)))

/* The fringe rule (effective_depth in clpost/stages/dof.py): p, a mix of a near and a far surface
 * Y_p = a Y_n + (1 - a) Y_f, takes the nearest depth of its 3x3 when the near surface (brightest near
 * neighbour) covers half of p or brings half its light (Y_f: the darkest of p's own surface), or when
 * the near surface (darkest near neighbour) covers half of p (Y_f: the brightest of p's own surface);
 * either only when that near surface is brighter (darker) than every other pixel of p's own surface
 * by more than 1 - DOF_FRINGE_STEP (other_min/other_max: p's own surface without p) or, the bright
 * one, is a light for p (DOF_LIGHT_CLAUSE; an own pixel as bright is that light's twin).
 * Both tests without a division; `span > 0` also rejects "no near neighbour" (+-inf). Returns 2 when
 * the bright hypothesis takes the nearest depth, 1 when only the dark one does, 0 when neither. */
inline int dof_fringe_take(const float lum, const float bright_n, const float dark_n, const float other_min,
                           const float other_max)
{
    const float own_min = fmin(other_min, lum), own_max = fmax(other_max, lum);
    const float sb = bright_n - own_min, pb = lum - own_min;
    const float sd = own_max - dark_n, pd = own_max - lum;
    if (sb > 0.0f && (2.0f * pb >= sb || 2.0f * pb * bright_n >= lum * sb)
        && (DOF_FRINGE_STEP * bright_n > other_max
            || DOF_LIGHT_CLAUSE(lum, bright_n, own_min, sb, pb)))
        return 2;
    return sd > 0.0f && 2.0f * pd >= sd && dark_n < DOF_FRINGE_STEP * other_min;
}

inline float16 dof_luma16(__global const float *p, const size_t n) {
    return DOF_LUMA_R * vload16(0, p) + DOF_LUMA_G * vload16(0, p + n) + DOF_LUMA_B * vload16(0, p + 2 * n);
}

#define DOF_SPECKLE_MAX_SAME 3
/* one exchange of the median network, on v[] of floats or float16s (generic fmin/fmax) */
#define DOF_SORT2(a, b) { const __typeof__(v[0]) t_ = fmin(v[a], v[b]); v[b] = fmax(v[a], v[b]); v[a] = t_; }

/* Stochastic-depth speckle (despeckle_depth in clpost/stages/dof.py): p is a candidate when at most
 * DOF_SPECKLE_MAX_SAME of its 8 neighbours share its depth (within 0.8x either way) and they are not one
 * arc of the ring (an object's corner: DOF_CANDIDATE below). A candidate whose
 * luminance lies within its other-depth neighbours' robust range (lo2 .. hi2: the second-darkest to the
 * second-brightest, so one bright twin of a 1-px lamp cannot explain it; DOF_FRINGE_STEP's 5 % outside
 * it allowed) takes the median depth of its 3x3; one
 * not on a one-pixel line, brighter than all of them but within DOF_SAME_SOURCE x the brightest (the
 * same source) and above DOF_SAME_SOURCE x the dimmest (a source above its surround), whose depth
 * class is seen on a speckle (dof_speckle_px) of its 5x5 dimmer than lum / DOF_SAME_SOURCE and than
 * DOF_SAME_SOURCE x the dimmest (one showing the surround, not a lamp's own dimmer pixel), takes that
 * brightest neighbour's depth (a light seen through a pane). Neighbours clamped to the image; the median by
 * the 19-exchange network for 9 values (Paeth, Graphics Gems 1990). */
inline int dof_same_depth(const float dq, const float d) {
    return dq >= DOF_MIXED_SAME_DEPTH * d && d >= DOF_MIXED_SAME_DEPTH * dq;
}

/* dof_same_depth lane-wise (true lanes are -1); lim = DOF_MIXED_SAME_DEPTH * d */
inline int16 dof_same_depth16(const float16 dq, const float16 d, const float16 lim) {
    return (dq >= lim) & (d >= DOF_MIXED_SAME_DEPTH * dq);
}

/* Position of neighbour (a, b) on the ring of 8 around p, clockwise from the top left. */
inline int dof_ring_pos(const int a, const int b) {
    return b < 0 ? a + 1 : b > 0 ? 5 - a : (a > 0 ? 3 : 7);
}

/* A speckle candidate: at most DOF_SPECKLE_MAX_SAME same-depth neighbours, unless exactly that many
 * form one arc of the ring (an object's corner). `ring`: bit dof_ring_pos set per same-depth
 * neighbour; works lane-wise on int16 as on int. */
#define DOF_CANDIDATE(same, ring) (((same) <= DOF_SPECKLE_MAX_SAME) & \
    !(((same) == DOF_SPECKLE_MAX_SAME) & (popcount((ring) ^ ((((ring) >> 1) | ((ring) << 7)) & 255)) == 2)))

/* A candidate not on a one-pixel line (no two opposite same-depth neighbours: a wire, a pole): a
 * speckle, for the light-behind-a-pane test (speckle_candidates(lines=False)). */
inline int dof_speckle_px(__global const float *depth, const int x, const int y, const int width, const int height)
{
    const float d = depth[(size_t)y * width + x];
    int same = 0, ring = 0;
    for (int b = -1; b <= 1; ++b)
        for (int a = -1; a <= 1; ++a)
            if ((a != 0 || b != 0)
                && dof_same_depth(depth[(size_t)clamp(y + b, 0, height - 1) * width + clamp(x + a, 0, width - 1)], d)) {
                ++same;
                ring |= 1 << dof_ring_pos(a, b);
            }
    return DOF_CANDIDATE(same, ring) && !(ring & (ring >> 4) & 15);
}

inline float dof_despeckle_px(__global const float *src, __global const float *depth, const int x, const int y,
                              const int width, const int height)
{
    const size_t n = (size_t)width * height, i = (size_t)y * width + x;
    const float d = depth[i];
    float v[9];
    int same = 0, ring = 0, k = 0;
    for (int b = -1; b <= 1; ++b)
        for (int a = -1; a <= 1; ++a) {
            const float dq = depth[(size_t)clamp(y + b, 0, height - 1) * width + clamp(x + a, 0, width - 1)];
            v[k++] = dq;
            if ((a != 0 || b != 0) && dof_same_depth(dq, d)) {
                ++same;
                ring |= 1 << dof_ring_pos(a, b);
            }
        }
    if (!DOF_CANDIDATE(same, ring))  /* most pixels: depth alone decides, no luminance loads */
        return d;
    const float lum = dof_luma(src, i, n);
    float lo = INFINITY, hi = -INFINITY, hi_d = d, lo2 = INFINITY, hi2 = -INFINITY;
    for (int b = -1; b <= 1; ++b)
        for (int a = -1; a <= 1; ++a) {
            const size_t j = (size_t)clamp(y + b, 0, height - 1) * width + clamp(x + a, 0, width - 1);
            const float dq = depth[j];
            if ((a == 0 && b == 0) || dof_same_depth(dq, d)) continue;
            const float lq = dof_luma(src, j, n);
            lo2 = fmin(lo2, fmax(lo, lq));
            hi2 = fmax(hi2, fmin(hi, lq));
            lo = fmin(lo, lq);
            if (lq > hi) { hi = lq; hi_d = dq; }
        }
    if (lum < DOF_FRINGE_STEP * lo)
        return d;
    if (lum > hi && lum <= DOF_SAME_SOURCE * hi && lum > DOF_SAME_SOURCE * lo && !(ring & (ring >> 4) & 15)) {
        for (int b = -2; b <= 2; ++b)
            for (int a = -2; a <= 2; ++a) {
                const int xq = clamp(x + a, 0, width - 1), yq = clamp(y + b, 0, height - 1);
                const size_t j = (size_t)yq * width + xq;
                const float lq = dof_luma(src, j, n);
                if (dof_same_depth(depth[j], d) && DOF_SAME_SOURCE * lq < lum && lq <= DOF_SAME_SOURCE * lo
                    && dof_speckle_px(depth, xq, yq, width, height))
                    return hi_d;
            }
    }
    if (DOF_FRINGE_STEP * lum > hi2 || lum < DOF_FRINGE_STEP * lo2)
        return d;
    DOF_SORT2(1, 2) DOF_SORT2(4, 5) DOF_SORT2(7, 8) DOF_SORT2(0, 1) DOF_SORT2(3, 4) DOF_SORT2(6, 7)
    DOF_SORT2(1, 2) DOF_SORT2(4, 5) DOF_SORT2(7, 8) DOF_SORT2(0, 3) DOF_SORT2(5, 8) DOF_SORT2(4, 7)
    DOF_SORT2(3, 6) DOF_SORT2(1, 4) DOF_SORT2(2, 5) DOF_SORT2(4, 7) DOF_SORT2(4, 2) DOF_SORT2(6, 4)
    DOF_SORT2(4, 2)
    return v[4];
}

/* 16 pixels of a row per work-item: the same-depth count in float16 (9 row loads); a group with
 * no candidate (every lane has more than DOF_SPECKLE_MAX_SAME same-depth neighbours: most of an
 * image) copies its depth, the others take the luminance test and the median lane-wise; the
 * groups at the left/right edge go per pixel.
 * Launched over (ceil(width / 16), height). */
__kernel void dof_despeckle(__global const float *restrict src, __global const float *restrict depth,
                            __global float *restrict out, const int width, const int height)
{
    const int x = 16 * get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t i = (size_t)y * width + x;
    if (x >= 1 && x + 16 <= width - 1) {
        const float16 d = vload16(0, depth + i);
        const float16 lim = DOF_MIXED_SAME_DEPTH * d;
        const size_t rows[3] = {(size_t)max(y - 1, 0) * width + x, i, (size_t)min(y + 1, height - 1) * width + x};
        int16 same = (int16)(0), ring = (int16)(0);
#pragma unroll
        for (int b = 0; b < 3; ++b)
#pragma unroll
            for (int a = -1; a <= 1; ++a) {
                if (a == 0 && b == 1) continue;
                const float16 dq = vload16(0, depth + rows[b] + a);
                same -= dof_same_depth16(dq, d, lim);  /* true lanes are -1 */
            }
        /* most groups: no lane has few enough same-depth neighbours (the count alone, as
         * DOF_CANDIDATE needs `same` <= DOF_SPECKLE_MAX_SAME) */
        if (!any(same <= DOF_SPECKLE_MAX_SAME)) {
            vstore16(d, 0, out + i);
            return;
        }
#pragma unroll
        for (int b = 0; b < 3; ++b)
#pragma unroll
            for (int a = -1; a <= 1; ++a) {
                if (a == 0 && b == 1) continue;
                const float16 dq = vload16(0, depth + rows[b] + a);
                ring |= (dof_same_depth16(dq, d, lim) & 1) << dof_ring_pos(a, b - 1);
            }
        const int16 cand = DOF_CANDIDATE(same, ring);
        if (!any(cand)) {
            vstore16(d, 0, out + i);
            return;
        }
        /* candidates: the luminance test and the 9-value median, lane-wise */
        const size_t n = (size_t)width * height;
        const float16 lum = dof_luma16(src + i, n);
        float16 lo = (float16)(INFINITY), hi = (float16)(-INFINITY), lo2 = lo, hi2 = hi;
        float16 v[9];
        int k = 0;
#pragma unroll
        for (int b = 0; b < 3; ++b)
#pragma unroll
            for (int a = -1; a <= 1; ++a) {
                const float16 dq = vload16(0, depth + rows[b] + a);
                v[k++] = dq;
                if (a == 0 && b == 1) continue;
                const int16 sm = dof_same_depth16(dq, d, lim);
                const float16 lq = dof_luma16(src + rows[b] + a, n);
                lo2 = select(fmin(lo2, fmax(lo, lq)), lo2, sm);
                hi2 = select(fmax(hi2, fmin(hi, lq)), hi2, sm);
                lo = select(fmin(lo, lq), lo, sm);
                hi = select(fmax(hi, lq), hi, sm);
            }
        DOF_SORT2(1, 2) DOF_SORT2(4, 5) DOF_SORT2(7, 8) DOF_SORT2(0, 1) DOF_SORT2(3, 4) DOF_SORT2(6, 7)
        DOF_SORT2(1, 2) DOF_SORT2(4, 5) DOF_SORT2(7, 8) DOF_SORT2(0, 3) DOF_SORT2(5, 8) DOF_SORT2(4, 7)
        DOF_SORT2(3, 6) DOF_SORT2(1, 4) DOF_SORT2(2, 5) DOF_SORT2(4, 7) DOF_SORT2(4, 2) DOF_SORT2(6, 4)
        DOF_SORT2(4, 2)
        /* a light seen through a pane (lum above hi but within DOF_SAME_SOURCE x it) is rare:
         * the group goes per pixel (the 5x5 test) */
        if (!any(cand & (lum > hi) & (lum <= DOF_SAME_SOURCE * hi) & (lum > DOF_SAME_SOURCE * lo)
                 & ((ring & (ring >> 4) & 15) == 0))) {
            vstore16(select(d, v[4], cand & (lum >= DOF_FRINGE_STEP * lo2) & (DOF_FRINGE_STEP * lum <= hi2)),
                     0, out + i);
            return;
        }
    }
    for (int xi = x; xi < min(x + 16, width); ++xi)
        out[(size_t)y * width + xi] = dof_despeckle_px(src, depth, xi, y, width, height);
}
#undef DOF_SORT2

/* The effective depth of one pixel by the fringe rule above (effective_depth's 3x3 rule); *bright:
 * whether its bright hypothesis moved it. Neighbour rows/columns clamped to the image. */
inline float dof_fringe_px(__global const float *src, __global const float *depth, const int x, const int y,
                           const int width, const int height, int *bright)
{
    const size_t n = (size_t)width * height, i = (size_t)y * width + x;
    const float d = depth[i];
    const float lum = dof_luma(src, i, n);
    float nearest = d, bright_n = -INFINITY, dark_n = INFINITY, other_min = INFINITY, other_max = -INFINITY;
    for (int b = -1; b <= 1; ++b)
        for (int a = -1; a <= 1; ++a) {
            if (a == 0 && b == 0) continue;
            const size_t j = (size_t)clamp(y + b, 0, height - 1) * width + clamp(x + a, 0, width - 1);
            const float dq = depth[j], lq = dof_luma(src, j, n);
            nearest = fmin(nearest, dq);
            if (dq < DOF_MIXED_SAME_DEPTH * d) {
                bright_n = fmax(bright_n, lq);
                dark_n = fmin(dark_n, lq);
            } else {
                other_min = fmin(other_min, lq);
                other_max = fmax(other_max, lq);
            }
        }
    const int take = dof_fringe_take(lum, bright_n, dark_n, other_min, other_max);
    *bright = take == 2;
    return take ? nearest : d;
}

inline float dof_coc_of(const float s, const float k, const float inv_u, const float limit) {
    const float inv_s = isinf(s) ? 0.0f : 1.0f / s;
    return clamp(k * (inv_u - inv_s), -limit, limit);
}

/* 16 pixels of a row per work-item in explicit float16 (PoCL does not vectorise the per-pixel form;
 * docs/measurements.md#kernel-forms-on-pocl); groups of 16 touching the left/right edge or the
 * image's end take the per-pixel path (same formula). Launched over (ceil(width / 16), height).
 * moved[y * ceil(width / 16) + group]: bit l, the rule's bright hypothesis moved pixel x + l; bit
 * 16 + l, the rule moved it; e1: the depths after the rule, written in the groups it moved a pixel of
 * (dof_coc_tail). */
__kernel void dof_coc(__global const float *restrict src, __global const float *restrict depth,
                      __global float *restrict e1, __global float *restrict coc, __global uint *restrict moved,
                      const int width, const int height, const float k, const float inv_u, const float limit)
{
    const int x = 16 * get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    const size_t n = (size_t)width * height, i = (size_t)y * width + x;
    const size_t flag = (size_t)y * ((width + 15) / 16) + get_global_id(0);
    if (x >= 1 && x + 16 <= width - 1) {
        const float16 d = vload16(0, depth + i);
        const float16 near_lim = DOF_MIXED_SAME_DEPTH * d;
        const size_t rows[3] = {(size_t)max(y - 1, 0) * width + x, i, (size_t)min(y + 1, height - 1) * width + x};
        float16 nearest = d;
#pragma unroll
        for (int b = 0; b < 3; ++b)
#pragma unroll
            for (int a = -1; a <= 1; ++a)
                nearest = fmin(nearest, vload16(0, depth + rows[b] + a));
        float16 s = d;
        uint any_take = 0;
        /* no depth step in any of the 16 neighbourhoods (most of an image): no colour test */
        if (any(nearest < near_lim)) {
            const float16 lum = dof_luma16(src + i, n);
            float16 bright_n = (float16)(-INFINITY), dark_n = (float16)(INFINITY);
            float16 other_min = (float16)(INFINITY), other_max = (float16)(-INFINITY);
    #pragma unroll
            for (int b = 0; b < 3; ++b)
    #pragma unroll
                for (int a = -1; a <= 1; ++a) {
                    if (a == 0 && b == 1) continue;
                    const float16 dq = vload16(0, depth + rows[b] + a);
                    const float16 lq = dof_luma16(src + rows[b] + a, n);
                    const int16 near = dq < near_lim;
                    bright_n = fmax(bright_n, select((float16)(-INFINITY), lq, near));
                    dark_n = fmin(dark_n, select((float16)(INFINITY), lq, near));
                    other_min = fmin(other_min, select(lq, (float16)(INFINITY), near));
                    other_max = fmax(other_max, select(lq, (float16)(-INFINITY), near));
                }
            const float16 own_min = fmin(other_min, lum), own_max = fmax(other_max, lum);
            const float16 sb = bright_n - own_min, pb = lum - own_min;
            const float16 sd = own_max - dark_n, pd = own_max - lum;
            const int16 take_b = (sb > 0.0f) & ((2.0f * pb >= sb) | (2.0f * pb * bright_n >= lum * sb))
                                 & ((DOF_FRINGE_STEP * bright_n > other_max)
                                    | DOF_LIGHT_CLAUSE(lum, bright_n, own_min, sb, pb));
            const int16 take_d = (sd > 0.0f) & (2.0f * pd >= sd) & (dark_n < DOF_FRINGE_STEP * other_min);
            s = select(d, nearest, take_b | take_d);
            /* bit l: lane l moved by the bright hypothesis; bit 16 + l: moved at all */
            const int16 pow2 = (int16)(1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096, 8192, 16384, 32768);
            const uint16 bit = convert_uint16(take_b & pow2) | convert_uint16((take_b | take_d) & pow2) << 16;
            const uint8 b8 = bit.lo | bit.hi;
            const uint4 b4 = b8.lo | b8.hi;
            const uint2 b2 = b4.lo | b4.hi;
            any_take = b2.x | b2.y;
            if (any_take)
                vstore16(s, 0, e1 + i);
        }
        moved[flag] = any_take;
        const float16 inv_s = select(1.0f / s, (float16)(0.0f), isinf(s));
        vstore16(clamp(k * (inv_u - inv_s), -limit, limit), 0, coc + i);
        return;
    }
    uint any_take = 0;
    for (int xi = x; xi < min(x + 16, width); ++xi) {
        int bright;
        const float s = dof_fringe_px(src, depth, xi, y, width, height, &bright);
        any_take |= (uint)bright << (xi - x) | (uint)(s != depth[(size_t)y * width + xi]) << (16 + xi - x);
        e1[(size_t)y * width + xi] = s;
        coc[(size_t)y * width + xi] = dof_coc_of(s, k, inv_u, limit);
    }
    moved[flag] = any_take;
}

/* The light's tail (effective_depth's second clause): p, left at its own depth by the rule above,
 * takes the nearest depth of its 3x3 after that rule's bright hypothesis when a neighbour at a near
 * depth after it is a light for p by the rule's light clause (more than DOF_SAME_SOURCE x p, its
 * 1 - DOF_FRINGE_STEP share above own_min clamped to 0, p at most DOF_LIGHT_FRINGE of it), brings
 * half of p's light, and p stands DOF_SAME_SOURCE x above every other pixel of its own surface but
 * two (tail samples beside it along the light's edge). Returns the depth (p's own when not). */
inline float dof_tail_px(__global const float *src, __global const float *depth, __global const float *e1,
                         __global const uint *moved, const int x, const int y, const int width, const int height)
{
    const size_t n = (size_t)width * height, i = (size_t)y * width + x;
    const float d = depth[i];
    const int gw = (width + 15) / 16;
    if (moved[(size_t)y * gw + x / 16] >> (16 + (x & 15)) & 1)
        return d;  /* moved by the 3x3 rule: its CoC stands (the caller keeps it) */
    /* a neighbour's depth after the bright hypothesis: e1 where it moved the pixel, depth elsewhere */
#define DOF_E1B(xq, yq) ((moved[(size_t)(yq) * gw + (xq) / 16] >> ((xq) & 15) & 1) \
                         ? e1[(size_t)(yq) * width + (xq)] : depth[(size_t)(yq) * width + (xq)])
    int moved_near = 0;  /* a neighbour it moved to a depth near for p (else the light clause again) */
    for (int b = -1; b <= 1; ++b)
        for (int a = -1; a <= 1; ++a) {
            const int xq = clamp(x + a, 0, width - 1), yq = clamp(y + b, 0, height - 1);
            const size_t j = (size_t)yq * width + xq;
            moved_near |= DOF_E1B(xq, yq) < DOF_MIXED_SAME_DEPTH * d && DOF_E1B(xq, yq) != depth[j];
        }
    if (!moved_near)
        return d;
    const float lum = dof_luma(src, i, n);
    float nearest = d, bright_n = -INFINITY, own_min = lum, hi = -INFINITY, hi2 = -INFINITY, hi3 = -INFINITY;
    for (int b = -1; b <= 1; ++b)
        for (int a = -1; a <= 1; ++a) {
            if (a == 0 && b == 0) continue;
            const int xq = clamp(x + a, 0, width - 1), yq = clamp(y + b, 0, height - 1);
            const float e = DOF_E1B(xq, yq);
            const float lq = dof_luma(src, (size_t)yq * width + xq, n);
            nearest = fmin(nearest, e);
            if (e < DOF_MIXED_SAME_DEPTH * d) {
                bright_n = fmax(bright_n, lq);
            } else {
                own_min = fmin(own_min, lq);
                hi3 = fmax(hi3, fmin(hi2, lq));
                hi2 = fmax(hi2, fmin(hi, lq));
                hi = fmax(hi, lq);
            }
        }
    const float sb = bright_n - own_min, pb = lum - own_min;
    const int take = DOF_TAIL_TAKE(lum, bright_n, own_min, sb, pb, hi3);
    return take ? nearest : d;
#undef DOF_E1B
}

/* After dof_coc, per 16 x DOF_TAIL_ROWS block (from dof_cl.TAIL_ROWS), from the masks of the lanes
 * the rule's bright hypothesis moved in its own and neighbouring groups (3 x 3): a pixel with no such
 * neighbour is skipped — without one the test is the rule's light clause on the raw depths, which
 * left it (a dark-moved neighbour counts at its own depth: a dark near surface is no light). In a
 * group inside the image the 18 columns x - 1 .. x + 16 of the three rows' masks, dilated by one
 * column, are each lane's moved neighbours: rows with none (nearly all) load nothing else; the
 * others take the light's-tail test in float16, first on depths alone (a neighbour moved to a depth
 * near for the lane), then on luminance. The groups at the left/right edge go per pixel when their
 * 3 x 3 groups have a moved pixel. Launched over (ceil(width / 16), ceil(height / DOF_TAIL_ROWS)). */
__kernel void dof_coc_tail(__global const float *restrict src, __global const float *restrict depth,
                           __global const float *restrict e1, __global float *restrict coc,
                           __global const uint *restrict moved, const int width, const int height,
                           const float k, const float inv_u, const float limit)
{
    const int g = get_global_id(0), y0 = DOF_TAIL_ROWS * get_global_id(1), gw = (width + 15) / 16;
    const int x = 16 * g;
    if (x >= width || y0 >= height) return;
    const int ga = max(g - 1, 0), gb = min(g + 1, gw - 1), y1 = min(y0 + DOF_TAIL_ROWS, height);
    const int inner = x >= 1 && x + 16 <= width - 1;
    const size_t n = (size_t)width * height;
    /* row r's moved columns x - 1 .. x + 16 as bits 0 .. 17 (the groups beside exist in an inner group) */
#define DOF_ROW_MOVED(r) ((moved[(size_t)(r) * gw + ga] >> 15 & 1) | (moved[(size_t)(r) * gw + g] & 0xffff) << 1 \
                          | (moved[(size_t)(r) * gw + gb] & 1) << 17)
    uint prev = DOF_ROW_MOVED(max(y0 - 1, 0)), cur = DOF_ROW_MOVED(y0);
    for (int y = y0; y < y1; ++y) {
        const uint next = DOF_ROW_MOVED(min(y + 1, height - 1));
        const uint w3 = prev | cur | next, lanes = (w3 | w3 >> 1 | w3 >> 2) & 0xffff;
        const int wr[3] = {(int)prev, (int)cur, (int)next};
        prev = cur;
        cur = next;
        if (!(inner ? lanes : w3))
            continue;
        const size_t i = (size_t)y * width + x;
        if (x >= 1 && x + 16 <= width - 1) {
            const float16 d = vload16(0, depth + i), lim = DOF_MIXED_SAME_DEPTH * d;
            const size_t rows[3] = {(size_t)max(y - 1, 0) * width + x, i, (size_t)min(y + 1, height - 1) * width + x};
            const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
            /* left at its depth by the rule */
            const int16 keep = (((int16)((int)(moved[(size_t)y * gw + g] >> 16)) >> lane) & 1) == 0;
            /* neighbour (a, b - 1)'s lanes the bright hypothesis moved (mb, true = -1) and their depths
             * after it (e: e1 there, depth elsewhere) */
#define DOF_TAIL_E16(b, a) \
    const int16 mb = -(((int16)(wr[b] >> (1 + (a))) >> lane) & 1); \
    const float16 e = select(vload16(0, depth + rows[b] + (a)), vload16(0, e1 + rows[b] + (a)), mb)
            float16 nearest = d;
            int16 near_any = (int16)(0);
#pragma unroll
            for (int b = 0; b < 3; ++b)
#pragma unroll
                for (int a = -1; a <= 1; ++a) {
                    if (a == 0 && b == 1) continue;
                    DOF_TAIL_E16(b, a);
                    nearest = fmin(nearest, e);
                    near_any |= mb & (e < lim);
                }
            if (!any(keep & near_any))
                continue;
            const float16 lum = dof_luma16(src + i, n);
            float16 bright_n = (float16)(-INFINITY), own_min = lum, hi = (float16)(-INFINITY), hi2 = hi, hi3 = hi;
#pragma unroll
            for (int b = 0; b < 3; ++b)
#pragma unroll
                for (int a = -1; a <= 1; ++a) {
                    if (a == 0 && b == 1) continue;
                    DOF_TAIL_E16(b, a);
                    const float16 lq = dof_luma16(src + rows[b] + a, n);
                    const int16 near = e < lim;
                    bright_n = select(bright_n, fmax(bright_n, lq), near);
                    own_min = select(fmin(own_min, lq), own_min, near);
                    hi3 = select(fmax(hi3, fmin(hi2, lq)), hi3, near);
                    hi2 = select(fmax(hi2, fmin(hi, lq)), hi2, near);
                    hi = select(fmax(hi, lq), hi, near);
                }
            const float16 sb = bright_n - own_min, pb = lum - own_min;
            const int16 take = keep & DOF_TAIL_TAKE(lum, bright_n, own_min, sb, pb, hi3);
#undef DOF_TAIL_E16
            if (any(take)) {
                const float16 inv_s = select(1.0f / nearest, (float16)(0.0f), isinf(nearest));
                vstore16(select(vload16(0, coc + i), clamp(k * (inv_u - inv_s), -limit, limit), take), 0, coc + i);
            }
            continue;
        }
        for (int xi = x; xi < min(x + 16, width); ++xi) {
            const float d = depth[(size_t)y * width + xi], s = dof_tail_px(src, depth, e1, moved, xi, y, width, height);
            if (s != d)
                coc[(size_t)y * width + xi] = dof_coc_of(s, k, inv_u, limit);
        }
    }
#undef DOF_ROW_MOVED
}

/* Padded working buffers (level 0 of `lv`, see dof_levels.cl): colour = mean of the DOF_SCALE^2 block, CoC = nearest (min signed) of
 * the block in working px, at half resolution the variance-matched radius DOF_HALF_R of it; the border of width `pad` replicates the edge (no clamp per tap).
 * Returns (R, G, B, CoC) of padded pixel (gx, gy). */
inline float4 dof_prepare_px(__global const float *src, __global const float *coc, const int gx, const int gy,
                             const int width, const int height, const int ww, const int hw, const int pad)
{
    const int xw = clamp(gx - pad, 0, ww - 1), yw = clamp(gy - pad, 0, hw - 1);
    const size_t n = (size_t)width * height;
#if DOF_SCALE == 1
    const size_t j = (size_t)yw * width + xw;
    const float3 acc = (float3)(src[j], src[n + j], src[2 * n + j]);
    const float r = coc[j];
#elif DOF_SCALE == 2
    const int x0 = 2 * xw, y0 = 2 * yw, x1 = min(x0 + 1, width - 1), y1 = min(y0 + 1, height - 1);
    const size_t j00 = (size_t)y0 * width + x0, j01 = (size_t)y0 * width + x1;
    const size_t j10 = (size_t)y1 * width + x0, j11 = (size_t)y1 * width + x1;
    const float3 acc = 0.25f * ((float3)(src[j00], src[n + j00], src[2 * n + j00])
                                + (float3)(src[j01], src[n + j01], src[2 * n + j01])
                                + (float3)(src[j10], src[n + j10], src[2 * n + j10])
                                + (float3)(src[j11], src[n + j11], src[2 * n + j11]));
    const float r = DOF_HALF_R(fmin(fmin(coc[j00], coc[j01]), fmin(coc[j10], coc[j11])));
#else
#error "DOF_SCALE must be 1 or 2"
#endif
    return (float4)(acc, r / DOF_SCALE);
}

/* 16 padded pixels of a row per work-item: the groups of 16 whose source is inside the image go
 * in float16 (at half resolution two vload16 per row, summed even + odd), the rest (border, odd
 * last column) per pixel. Launched over (ceil(pw / 16), ph). */
__kernel void dof_prepare(__global const float *restrict src, __global const float *restrict coc,
                          __global float *restrict lv, __global float *restrict pv,
                          const int width, const int height, const int ww, const int hw, const int pad,
                          const float vig, const float cx, const float cy, const float inv_half)
{
    const int gx = 16 * get_global_id(0), gy = get_global_id(1);
    const int pw = DOF_PW(ww, pad), ph = DOF_PW(hw, pad);
    if (gx >= pw || gy >= ph) return;
    const size_t pn = (size_t)pw * ph, o = (size_t)gy * pw + gx;
    const int xw = gx - pad, yw = clamp(gy - pad, 0, hw - 1);
    if (xw >= 0 && DOF_SCALE * (xw + 16) <= width && gx + 16 <= pw) {
        const size_t n = (size_t)width * height;
#if DOF_SCALE == 1
        const size_t j = (size_t)yw * width + xw;
        vstore16(vload16(0, src + j), 0, lv + o);
        vstore16(vload16(0, src + n + j), 0, lv + pn + o);
        vstore16(vload16(0, src + 2 * n + j), 0, lv + 2 * pn + o);
        const float16 r = vload16(0, coc + j);
#else
        const size_t j0 = (size_t)(2 * yw) * width + 2 * xw;
        const size_t j1 = (size_t)min(2 * yw + 1, height - 1) * width + 2 * xw;
        for (int c = 0; c < 3; ++c) {
            /* the 2x2 mean in the per-pixel form's order, ((p00 + p01) + p10) + p11: rows j0, j1
             * as 32 floats each (two vload16), even = left column, odd = right column */
            const float16 a0 = vload16(0, src + c * n + j0), a1 = vload16(1, src + c * n + j0);
            const float16 b0 = vload16(0, src + c * n + j1), b1 = vload16(1, src + c * n + j1);
            const float8 lo = ((a0.even + a0.odd) + b0.even) + b0.odd;
            const float8 hi = ((a1.even + a1.odd) + b1.even) + b1.odd;
            vstore16(0.25f * (float16)(lo, hi), 0, lv + c * pn + o);
        }
        const float16 a0 = vload16(0, coc + j0), b0 = vload16(0, coc + j1);
        const float16 a1 = vload16(1, coc + j0), b1 = vload16(1, coc + j1);
        const float16 r = DOF_HALF_R((float16)(fmin(fmin(a0.even, a0.odd), fmin(b0.even, b0.odd)),
                                               fmin(fmin(a1.even, a1.odd), fmin(b1.even, b1.odd)))) / DOF_SCALE;
#endif
        vstore16(r, 0, lv + 3 * pn + o);
        vstore16(DOF_INV_R(r), 0, lv + 4 * pn + o);
    } else {
        for (int xi = gx; xi < min(gx + 16, pw); ++xi) {
            const float4 v = dof_prepare_px(src, coc, xi, gy, width, height, ww, hw, pad);
            const size_t oi = (size_t)gy * pw + xi;
            lv[oi] = v.x; lv[pn + oi] = v.y; lv[2 * pn + oi] = v.z; lv[3 * pn + oi] = v.w;
            lv[4 * pn + oi] = DOF_INV_R(v.w);
        }
    }
#if DOF_VIGNETTING
    /* 1 / pupil area fraction of a source here (two-disc lens area, |h| capped at the corner):
     * once per pixel instead of an acos per tap */
    for (int xi = gx; xi < min(gx + 16, pw); ++xi) {
        const float hx = ((float)(xi - pad) - cx) * inv_half, hy = ((float)(gy - pad) - cy) * inv_half;
        const float d = vig * fmin(sqrt(hx * hx + hy * hy), 1.0f);
        pv[(size_t)gy * pw + xi] = M_PI_F / (2.0f * acos(0.5f * d) - 0.5f * d * sqrt(4.0f - d * d));
    }
#endif
}
