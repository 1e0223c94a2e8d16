/* dof: definitions shared by the dof kernels (prepended to each dof program). */

/* padded extent of the working buffers: the image rounded up to whole tiles plus `pad` on each
 * side, so every work-item of an edge tile reads inside the buffer without a clamp */
/* planes per level of `lv`: R, G, B, signed CoC (working px) and 1 / max(|CoC|, 1/2) (the
 * gather's weights need 1/r per tap: a load instead of two divisions); at half resolution with
 * the spherical-aberration texture a sixth, the texture's rescale N(r/s; 0)/N(r/s; a) of the
 * level's own CoC (texture_sums in clpost/stages/dof.py; dof_texture_plane), so the gather's taps
 * read it instead of looking a table up per tap */
#define DOF_TEX_PLANE (DOF_TEXTURE && DOF_SCALE > 1)
#if DOF_TEX_PLANE
#define DOF_PLANES 6
#else
#define DOF_PLANES 5
#endif
#define DOF_INV_R(c) (1.0f / fmax(fabs(c), 0.5f))

#define DOF_PW(n, pad) (DOF_TILE * (((n) + DOF_TILE - 1) / DOF_TILE) + 2 * (pad))

/* The half-resolution path's variance-matched radius and composite weight (half_radius and
 * half_blend in clpost/stages/dof.py): r' = sgn(r) sqrt(max(r^2 - DOF_HALF_SHRINK, 0)) and
 * b = clamp((r^2/4 - DOF_LOCAL_VAR) DOF_HALF_BLEND, 0, 1); the 3x3 blur's side weight
 * a = min(r^2/4, DOF_LOCAL_VAR)/2 (local_weight); scalar or vector r (generic built-ins only). */
#define DOF_HALF_R(r) copysign(sqrt(fmax((r) * (r) - DOF_HALF_SHRINK, 0.0f)), (r))
#define DOF_HALF_B(r) clamp(((r) * (r) * 0.25f - DOF_LOCAL_VAR) * DOF_HALF_BLEND, 0.0f, 1.0f)
#define DOF_LOCAL_A(r) (0.5f * fmin((r) * (r) * 0.25f, DOF_LOCAL_VAR))
