/* dof: per-tile signed CoC range and its dilation by the reach of neighbouring tiles (Jimenez 2014),
 * depth-aware (tile_plan in clpost/stages/dof.py).
 * Structural: DOF_TILE (tile edge, working px), DOF_RMAX (max CoC radius, working px),
 * DOF_BUDGET (lattice radius R_b), DOF_LEVELS, DOF_REACH (a bokeh's reach over its CoC radius: a
 * traced profile's T_MAX, else 1; DOF_RMAX is then the largest reach), DOF_FRONT_MARGIN.
 * Output per tile: the lattice level l (stride s = 2^l, the smallest with
 * k = ceil(R/s - 0.5) <= R_b) and the number of taps ntaps[k] of the distance-sorted unit lattice
 * table that covers every source whose bokeh can reach a pixel of the tile, and the routing level
 * m of final's mixed resolution (the same rule with every neighbour's |CoC|, depth order ignored:
 * dof_tile_mix keeps routing the tiles it routed before the dilation became depth-aware), packed
 * as taps | l << 24 | m << 28 (l, m <= 7; the gather reads l = (packed >> 24) & 15), and bit 31
 * (DOF_LIGHT_BIT: the packed int is negative) on a level-0 tile within one tile of a light
 * (`tlight`: a level-0 pixel whose luma is above DOF_LIGHT_LUMA; the gather runs its light path
 * only there, so every other tile keeps the plain tap loop).
 */
#define DOF_LIGHT_BIT ((int)0x80000000)
#if DOF_BUDGET > DOF_TILE
#error "the light bit assumes a level-0 tile's taps stay within the 3x3 tiles around it"
#endif

/* tmax[2 t], tmax[2 t + 1]: the signed CoC's min and max over tile t (level 0); tlight[t]: whether a
 * level-0 pixel of tile t is a light (DOF_LIGHTS; the light test of dof_tapv). One walk over the
 * tile reads the four planes (min, max and the light flag are exact in any order). */
#define DOF_IS_LIGHT(r, g, b) (DOF_LIGHT_Y0 * (r) + DOF_LIGHT_Y1 * (g) + DOF_LIGHT_Y2 * (b) > DOF_LIGHT_LUMA)
__kernel void dof_tile_max(__global const float *restrict lv, __global float *restrict tmax,
                           __global int *restrict tlight,
                           const int ww, const int hw, const int pad, const int tw, const int th)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    const int pw = DOF_PW(ww, pad);
    const size_t pn = (size_t)pw * DOF_PW(hw, pad);
    __global const float *pr = lv + 3 * pn;  /* level 0 CoC */
    const int t = ty * tw + tx;
#if DOF_TILE == 16
    if ((tx + 1) * DOF_TILE <= ww && (ty + 1) * DOF_TILE <= hw) {  /* a whole tile: one row per vload16 */
        const size_t o0 = (size_t)(ty * DOF_TILE + pad) * pw + tx * DOF_TILE + pad;
        float16 lo = vload16(0, pr + o0), hi = lo;
        int16 on = (int16)(0);
        for (int y = 0; y < DOF_TILE; ++y) {
            const size_t o = o0 + (size_t)y * pw;
            const float16 v = vload16(0, pr + o);
            lo = fmin(lo, v);
            hi = fmax(hi, v);
            if (DOF_LIGHTS)
                on |= DOF_IS_LIGHT(vload16(0, lv + o), vload16(0, lv + pn + o), vload16(0, lv + 2 * pn + o));
        }
        const float8 a = fmin(lo.lo, lo.hi), b = fmax(hi.lo, hi.hi);
        const float4 c = fmin(a.lo, a.hi), d = fmax(b.lo, b.hi);
        const float2 e = fmin(c.lo, c.hi), f = fmax(d.lo, d.hi);
        tmax[2 * t] = fmin(e.x, e.y);
        tmax[2 * t + 1] = fmax(f.x, f.y);
        tlight[t] = DOF_LIGHTS ? any(on) : 0;
        return;
    }
#endif
    float lo = INFINITY, hi = -INFINITY;
    int on = 0;
    for (int y = ty * DOF_TILE; y < min((ty + 1) * DOF_TILE, hw); ++y)
        for (int x = tx * DOF_TILE; x < min((tx + 1) * DOF_TILE, ww); ++x) {
            const size_t i = (size_t)(y + pad) * pw + x + pad;
            const float v = pr[i];
            lo = fmin(lo, v);
            hi = fmax(hi, v);
            if (DOF_LIGHTS)
                on |= DOF_IS_LIGHT(lv[i], lv[pn + i], lv[2 * pn + i]);
        }
    tmax[2 * t] = lo;
    tmax[2 * t + 1] = hi;
    tlight[t] = on;
}
#undef DOF_IS_LIGHT

/* The border replicates edge pixels, so an edge tile's own range also stands for the padding.
 * A neighbour's sources behind every pixel of the tile (CoC above the tile's max + the front
 * margin) are clamped to the pixel's own radius by the gather: they do not dilate. */
__kernel void dof_tile_dilate(__global const float *restrict tmax, __global const int *restrict tlight,
                              __global int *restrict tn, __global const int *restrict ntaps,
                              __constant const float *restrict tap_dist, const int tw, const int th)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    const int reach = (DOF_RMAX + DOF_TILE) / DOF_TILE;
    const float top = tmax[2 * (ty * tw + tx) + 1] + DOF_FRONT_MARGIN;
    float r = 0.5f, ra = 0.5f;
    for (int ny = max(ty - reach, 0); ny <= min(ty + reach, th - 1); ++ny)
        for (int nx = max(tx - reach, 0); nx <= min(tx + reach, tw - 1); ++nx) {
            const float lo = tmax[2 * (ny * tw + nx)], hi = tmax[2 * (ny * tw + nx) + 1];
            /* smallest pixel distance between the two tiles */
            const float gx = (float)max(0, (int)abs(nx - tx) * DOF_TILE - (DOF_TILE - 1));
            const float gy = (float)max(0, (int)abs(ny - ty) * DOF_TILE - (DOF_TILE - 1));
            const float g = sqrt(gx * gx + gy * gy);
            const float ma = fmax(fabs(lo), fabs(hi)) * DOF_REACH;
            if (ma + 0.5f > g) ra = fmax(ra, ma);
            if (lo > top) continue;
            const float m = fmax(fabs(lo), fabs(fmin(hi, top))) * DOF_REACH;
            if (m + 0.5f > g) r = fmax(r, m);
        }
    int lvl = 0, route = 0;
    while (lvl < DOF_LEVELS && (int)ceil(r / (float)(1 << lvl) - 0.5f) > DOF_BUDGET) ++lvl;
    while (route < DOF_LEVELS && (int)ceil(ra / (float)(1 << route) - 0.5f) > DOF_BUDGET) ++route;
    const int k = clamp((int)ceil(r / (float)(1 << lvl) - 0.5f), 0, DOF_BUDGET);
    /* only the taps nearer than R/s + DOF_TRIM (lattice units; TRIM_LATTICE in clpost/stages/dof.py):
     * ntaps[k] holds every tap nearer than k + 1 >= R/s + 1/2, and the ring between has coverage 0
     * for every source that dilated the tile; the 3x3 around p always (a light's LIGHT_SMALL_PX
     * weight) */
    int cnt = ntaps[k];
    const float bound = r / (float)(1 << lvl) + DOF_TRIM;
    while (cnt > 9 && tap_dist[cnt - 1] >= bound) --cnt;
    /* a level-0 tile's taps reach DOF_BUDGET <= DOF_TILE px: the 3x3 tiles around it hold them */
    int light = 0;
    if (DOF_LIGHTS && lvl == 0)
        for (int ny = max(ty - 1, 0); ny <= min(ty + 1, th - 1); ++ny)
            for (int nx = max(tx - 1, 0); nx <= min(tx + 1, tw - 1); ++nx)
                light |= tlight[ny * tw + nx];
    tn[ty * tw + tx] = cnt | (lvl << 24) | (route << 28) | (light ? DOF_LIGHT_BIT : 0);
}

/* Final's mixed resolution (clpost/stages/dof.py, mixed_mask): launched over the tiles of the
 * half-resolution plan `tn_h`. A half tile is "big" when its lattice level is >= DOF_MIX_LEVEL or
 * one of its 2x2 full-resolution child tiles would need a level above DOF_MIX_FULL_LEVELS (final
 * builds only those full-resolution levels). Big tiles take their pixels from the
 * half-resolution gather (`mix` = 1, read by dof_upsample), so their full-resolution children
 * skip the full-resolution gather (`tn_full_out` = 0: count 0, the gather returns at once). The
 * half-resolution gather is needed only in big tiles and their 8 neighbours (the upsampling's
 * bilinear corners reach one working pixel beyond a tile): the others get count 0 in `tn_h_out`.
 * Inputs and outputs are separate buffers, so no work-item reads what another writes. */
inline int dof_tile_big(__global const int *tn_h, __global const int *tn_full, const int tx, const int ty,
                        const int twh, const int tw, const int th)
{
    int big = ((tn_h[ty * twh + tx] >> 28) & 7) >= DOF_MIX_LEVEL;
    for (int cy = 2 * ty; cy <= min(2 * ty + 1, th - 1); ++cy)
        for (int cx = 2 * tx; cx <= min(2 * tx + 1, tw - 1); ++cx)
            big |= ((tn_full[cy * tw + cx] >> 28) & 7) > DOF_MIX_FULL_LEVELS;
    return big;
}

__kernel void dof_tile_mix(__global const int *restrict tn_h, __global const int *restrict tn_full,
                           __global int *restrict tn_h_out, __global int *restrict tn_full_out,
                           __global int *restrict mix, const int twh, const int thh, const int tw,
                           const int th)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= twh || ty >= thh) return;
    const int own = tn_h[ty * twh + tx];
    int needed = 0;
    for (int ny = max(ty - 1, 0); ny <= min(ty + 1, thh - 1); ++ny)
        for (int nx = max(tx - 1, 0); nx <= min(tx + 1, twh - 1); ++nx)
            needed |= dof_tile_big(tn_h, tn_full, nx, ny, twh, tw, th);
    const int big = dof_tile_big(tn_h, tn_full, tx, ty, twh, tw, th);
    tn_h_out[ty * twh + tx] = needed ? own : 0;
    mix[ty * twh + tx] = big;
    for (int cy = 2 * ty; cy <= min(2 * ty + 1, th - 1); ++cy)
        for (int cx = 2 * tx; cx <= min(2 * tx + 1, tw - 1); ++cx)
            tn_full_out[cy * tw + cx] = big ? 0 : tn_full[cy * tw + cx];
}
