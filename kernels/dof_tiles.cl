/* dof: per-tile max |CoC| and its dilation by the reach of neighbouring tiles (Jimenez 2014).
 * Structural: DOF_TILE (tile edge, working px), DOF_RMAX (max CoC radius, working px),
 * DOF_BUDGET (lattice radius R_b), DOF_LEVELS.
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
    for (int y = ty * DOF_TILE; y < min((ty + 1) * DOF_TILE, hw); ++y)
        for (int x = tx * DOF_TILE; x < min((tx + 1) * DOF_TILE, ww); ++x)
            m = fmax(m, fabs(pr[(size_t)(y + pad) * pw + x + pad]));
    tmax[ty * tw + tx] = m;
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
