/* dof: per-tile max |CoC| and its dilation by the reach of neighbouring tiles (Jimenez 2014).
 * Structural: DOF_TILE (tile edge, working px), DOF_RMAX (max CoC radius, working px),
 * DOF_BUDGET (lattice radius R_b), DOF_LEVELS, DOF_REACH (a bokeh's reach over its CoC radius: a
 * traced profile's T_MAX, else 1; DOF_RMAX is then the largest reach).
 * Output per tile: the lattice level l (stride s = 2^l, the smallest with
 * k = ceil(R/s - 0.5) <= R_b) and the number of taps ntaps[k] of the distance-sorted unit lattice
 * table that covers every source whose bokeh can reach a pixel of the tile, packed as
 * taps | l << 24 (see tile_plan in clpost/stages/dof.py).
 */

__kernel void dof_tile_max(__global const float *restrict lv, __global float *restrict tmax,
                           const int ww, const int hw, const int pad, const int tw, const int th)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    const int pw = DOF_PW(ww, pad);
    __global const float *pr = lv + (size_t)3 * pw * DOF_PW(hw, pad);  /* level 0 CoC */
    float m = 0.0f;
#if DOF_TILE == 16
    if ((tx + 1) * DOF_TILE <= ww && (ty + 1) * DOF_TILE <= hw) {
        /* a whole tile: one row per vload16 (max is exact in any order) */
        float16 v = (float16)(0.0f);
        for (int y = ty * DOF_TILE; y < (ty + 1) * DOF_TILE; ++y)
            v = fmax(v, fabs(vload16(0, pr + (size_t)(y + pad) * pw + tx * DOF_TILE + pad)));
        const float8 a = fmax(v.lo, v.hi);
        const float4 b = fmax(a.lo, a.hi);
        const float2 c = fmax(b.lo, b.hi);
        tmax[ty * tw + tx] = fmax(c.x, c.y) * DOF_REACH;
        return;
    }
#endif
    for (int y = ty * DOF_TILE; y < min((ty + 1) * DOF_TILE, hw); ++y)
        for (int x = tx * DOF_TILE; x < min((tx + 1) * DOF_TILE, ww); ++x)
            m = fmax(m, fabs(pr[(size_t)(y + pad) * pw + x + pad]));
    tmax[ty * tw + tx] = m * DOF_REACH;
}

/* The border replicates edge pixels, so an edge tile's own max also stands for the padding. */
__kernel void dof_tile_dilate(__global const float *restrict tmax, __global int *restrict tn,
                              __global const int *restrict ntaps, const int tw, const int th)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tw || ty >= th) return;
    const int reach = (DOF_RMAX + DOF_TILE) / DOF_TILE;
    float r = 0.5f;
    for (int ny = max(ty - reach, 0); ny <= min(ty + reach, th - 1); ++ny)
        for (int nx = max(tx - reach, 0); nx <= min(tx + reach, tw - 1); ++nx) {
            /* smallest pixel distance between the two tiles */
            const float gx = (float)max(0, (int)abs(nx - tx) * DOF_TILE - (DOF_TILE - 1));
            const float gy = (float)max(0, (int)abs(ny - ty) * DOF_TILE - (DOF_TILE - 1));
            const float m = tmax[ny * tw + nx];
            if (m + 0.5f > sqrt(gx * gx + gy * gy)) r = fmax(r, m);
        }
    int lvl = 0;
    while (lvl < DOF_LEVELS && (int)ceil(r / (float)(1 << lvl) - 0.5f) > DOF_BUDGET) ++lvl;
    const int k = clamp((int)ceil(r / (float)(1 << lvl) - 0.5f), 0, DOF_BUDGET);
    tn[ty * tw + tx] = ntaps[k] | (lvl << 24);
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
    int big = (tn_h[ty * twh + tx] >> 24) >= DOF_MIX_LEVEL;
    for (int cy = 2 * ty; cy <= min(2 * ty + 1, th - 1); ++cy)
        for (int cx = 2 * tx; cx <= min(2 * tx + 1, tw - 1); ++cx)
            big |= (tn_full[cy * tw + cx] >> 24) > DOF_MIX_FULL_LEVELS;
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
