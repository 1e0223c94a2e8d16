/* dof: definitions shared by the dof kernels (prepended to each dof program). */

/* padded extent of the working buffers: the image rounded up to whole tiles plus `pad` on each
 * side, so every work-item of an edge tile reads inside the buffer without a clamp */
/* planes per level of `lv`: R, G, B, signed CoC (working px) and 1 / max(|CoC|, 1/2) (the
 * gather's weights need 1/r per tap: a load instead of two divisions) */
#define DOF_PLANES 5
#define DOF_INV_R(c) (1.0f / fmax(fabs(c), 0.5f))

#define DOF_PW(n, pad) (DOF_TILE * (((n) + DOF_TILE - 1) / DOF_TILE) + 2 * (pad))
