/* dof: definitions shared by the dof kernels (prepended to each dof program). */

/* padded extent of the working buffers: the image rounded up to whole tiles plus `pad` on each
 * side, so every work-item of an edge tile reads inside the buffer without a clamp */
#define DOF_PW(n, pad) (DOF_TILE * (((n) + DOF_TILE - 1) / DOF_TILE) + 2 * (pad))
