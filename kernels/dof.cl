/* dof (the stage's main kernel, `dof`): scatter-as-gather on a per-tile lattice of stride
 * s = 2^l over the tent-prefiltered level l (dof_levels.cl), near/far layers, bladed + textured +
 * cat's-eye bokeh; and the half-resolution composite. Every formula is in clpost/stages/dof.py
 * (the float64 reference mirrors this line by line).
 * Structural: DOF_TILE (tile = work-group of DOF_TILE/DOF_VEC x DOF_TILE work-items), DOF_VEC,
 * DOF_RMAX, DOF_SCALE, DOF_BUDGET, DOF_LEVELS, DOF_VIGNETTING,
 * DOF_LIGHTS (lights' 1/4-px ramp at stride 1, LIGHT_RAMP_PX: the full-resolution gather only, and not
 * with DOF_VIGNETTING or DOF_PROFILE),
 * DOF_TEXTURE (spherical aberration's texture on: σ ≠ 0; with DOF_SCALE > 1 also DOF_TEX_PLANE, the
 * levels' sixth plane: dof_common.cl),
 * DOF_PROFILE (a traced lens's per-channel texture, the pencil map: clpost/optics/pencil.py; with
 * DOF_PROF_ND rows, DOF_PROF_NR bins over [0, DOF_PROF_TMAX], DOF_PROF_RK = output px -> row
 * units (1 / the largest CoC radius); DOF_REACH = DOF_PROF_TMAX, the bokeh's reach over its CoC radius, else 1).
 * The tap count and stride are uniform per work-group (one tile), tap offsets uniform across
 * work-items, and borders are padded, so no tap is clamped.
 */

/* DOF_FRONT_MARGIN: FRONT_MARGIN_PX of clpost/stages/dof.py (the host passes it) */
/* DOF_VEC pixels of a row per work-item in explicit vectors (PoCL does not vectorise across
 * work-items around a tap loop whose trip count is only known per tile): 16 where the device's
 * native float vector is 16 wide (AVX-512; docs/measurements.md#kernel-forms-on-pocl), else 8; the
 * host passes it (clpost/stages/dof_cl.py, gather_vector_width) */
#ifndef DOF_VEC
#define DOF_VEC 8
#endif
#ifndef DOF_PROFILE
#define DOF_PROFILE 0
#endif
#if DOF_PROFILE
#define DOF_TMAX DOF_PROF_TMAX
#else
#define DOF_TMAX 1.0f
#endif
#if DOF_VEC == 16
#define DOF_F float16
#define DOF_I int16
#define DOF_CONVERT_I convert_int16
#define DOF_LOAD(p) vload16(0, (p))
#define DOF_STORE(v, p) vstore16((v), 0, (p))
#define DOF_LANES ((float16)(0.0f, 1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 6.0f, 7.0f, 8.0f, 9.0f, 10.0f, 11.0f, 12.0f, 13.0f, 14.0f, 15.0f))
#elif DOF_VEC == 8
#define DOF_F float8
#define DOF_I int8
#define DOF_CONVERT_I convert_int8
#define DOF_LOAD(p) vload8(0, (p))
#define DOF_STORE(v, p) vstore8((v), 0, (p))
#define DOF_LANES ((float8)(0.0f, 1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 6.0f, 7.0f))
#elif DOF_VEC == 1
/* one pixel per work-item (a GPU's form: a warp's loads coalesce across work-items, and the
 * accumulators fit its registers); scalar comparisons give 1, not -1, so DOF_ANY tests != 0 */
#define DOF_F float
#define DOF_I int
#define DOF_CONVERT_I convert_int
#define DOF_LOAD(p) (*(p))
#define DOF_STORE(v, p) (*(p) = (v))
#define DOF_LANES 0.0f
#else
#error "DOF_VEC must be 1, 8 or 16"
#endif
#if DOF_VEC == 1
#define DOF_ANY(m) ((m) != 0)
#else
#define DOF_ANY(m) any(m)
#endif

/* wf, wb: the layers' weights (red's with DOF_PROFILE, whose weights differ per channel: wfg,
 * wfb, wbg, wbb for green and blue) */
typedef struct { DOF_F r, g, b, wf, fr, fg, fb, wb;
#if DOF_PROFILE
                 DOF_F wfg, wfb, wbg, wbb;
#endif
                 /* the background hidden behind p (gather_reference's H, Hk, Wh, dmin): the
                  * estimate's colour sums and weight, the behind taps' colour weight (wh, and
                  * whg, whb per channel with DOF_PROFILE), the nearest behind tap's distance
                  * + half the ramp (-1: none yet) */
                 DOF_F hr, hg, hb, hk, wh, dh;
#if DOF_PROFILE
                 DOF_F whg, whb;
#endif
} DofAccV;

#if DOF_PROFILE
/* The traced texture (profile_at in clpost/optics/pencil.py): bilinear in (defocus row, radial
 * bin centre), ends clamped; the table is float4 (R, G, B, 0) per (row, bin). Per lane: the
 * rows differ per source. */
inline void dof_profile(__global const float4 *restrict prof, const DOF_F rq, const DOF_F t,
                        DOF_F *pr, DOF_F *pg, DOF_F *pb)
{
    const DOF_F fj = clamp((rq * (DOF_SCALE * DOF_PROF_RK) + 1.0f) * (0.5f * (DOF_PROF_ND - 1)), 0.0f,
                           (float)(DOF_PROF_ND - 1));
    const DOF_F fi = clamp(t * ((float)DOF_PROF_NR / DOF_PROF_TMAX) - 0.5f, 0.0f, (float)(DOF_PROF_NR - 1));
    const DOF_F j0 = fmin(floor(fj), (float)(DOF_PROF_ND - 2)), i0 = fmin(floor(fi), (float)(DOF_PROF_NR - 2));
    float aj[DOF_VEC], ai[DOF_VEC], vr[DOF_VEC], vg[DOF_VEC], vb[DOF_VEC];
    int at[DOF_VEC];
    DOF_STORE(fj - j0, aj);
    DOF_STORE(fi - i0, ai);
    DOF_STORE(DOF_CONVERT_I(j0) * DOF_PROF_NR + DOF_CONVERT_I(i0), at);
    for (int l = 0; l < DOF_VEC; ++l) {
        __global const float4 *q = prof + at[l];
        const float4 a = q[0] + (q[1] - q[0]) * ai[l];
        const float4 b = q[DOF_PROF_NR] + (q[DOF_PROF_NR + 1] - q[DOF_PROF_NR]) * ai[l];
        const float4 v = a + (b - a) * aj[l];
        vr[l] = v.x; vg[l] = v.y; vb[l] = v.z;
    }
    *pr = DOF_LOAD(vr); *pg = DOF_LOAD(vg); *pb = DOF_LOAD(vb);
}
#endif

/* a light tap's lattice sums (light_sums / light_sum_at in clpost/stages/dof.py): rows of
 * DOF_LIGHT_N, N₁(r) and N_¼(r) of a far light, then of a near one; linear in r, ends clamped;
 * per lane */
inline void dof_light_sums(__global const float *restrict lsum, const DOF_F r, const DOF_I far, DOF_F *n1,
                           DOF_F *n4)
{
    const DOF_F f = clamp((r - DOF_LIGHT_R0) * DOF_LIGHT_K, 0.0f, (float)(DOF_LIGHT_N - 1));
    const DOF_F i0 = fmin(floor(f), (float)(DOF_LIGHT_N - 2));
    float a[DOF_VEC], v1[DOF_VEC], v4[DOF_VEC];
    int at[DOF_VEC];
    DOF_STORE(f - i0, a);
    DOF_STORE(DOF_CONVERT_I(i0) + select((DOF_I)(2 * DOF_LIGHT_N), (DOF_I)(0), far), at);
    for (int l = 0; l < DOF_VEC; ++l) {
        __global const float *q = lsum + at[l];
        v1[l] = q[0] + (q[1] - q[0]) * a[l];
        v4[l] = q[DOF_LIGHT_N] + (q[DOF_LIGHT_N + 1] - q[DOF_LIGHT_N]) * a[l];
    }
    *n1 = DOF_LOAD(v1); *n4 = DOF_LOAD(v4);
}

/* a tap behind p and sharper than p (by DOF_HIDDEN_MARGIN px) feeds the estimate of the
 * background hidden behind p (gather_reference in clpost/stages/dof.py): weight
 * clamp((R - |o|) / ramp + 1/2, 0, 1) with R the behind surface's own radius, widened to the nearest behind tap's distance + half the ramp (taps come in
 * distance order; dh < 0: none yet) */
inline void dof_hidden(DofAccV *acc, const DOF_F cr, const DOF_F cg, const DOF_F cb, const DOF_F rq,
                       const DOF_I hid, const float dist, const float inv_ramp)
{
    acc->dh = select(acc->dh, (DOF_F)(dist + 0.5f / inv_ramp), hid & (acc->dh < 0.0f));
    const DOF_F rh = fmax(fmax(fabs(rq), 0.5f), acc->dh);
    const DOF_F kh = select((DOF_F)(0.0f), clamp((rh - dist) * inv_ramp + 0.5f, 0.0f, 1.0f), hid);
    acc->hr += kh * cr; acc->hg += kh * cg; acc->hb += kh * cb; acc->hk += kh;
}

/* any(m) as a tree of ORs over the vector's halves: the same answer as OpenCL's any() (lanes are 0
 * or -1). For the hidden background's per-tap test PoCL's any() cost thin's final gather ~10 %,
 * this ~0 (docs/fidelity.md, "The background hidden behind a blurred foreground's edge"); the
 * lights' test keeps any(), which measured no slower there */
inline int dof_any(const DOF_I m)
{
#if DOF_VEC == 1
    return DOF_ANY(m);
#else
#if DOF_VEC == 16
    const int8 m8 = m.lo | m.hi;
#else
    const int8 m8 = m;
#endif
    const int4 m4 = m8.lo | m8.hi;
    const int2 m2 = m4.lo | m4.hi;
    return (m2.x | m2.y) != 0;
#endif
}

/* one source tap for 8 neighbouring target pixels: colours (cr, cg, cb), signed CoC rq and
 * iq = 1/max(|rq|, 1/2) at offset (dx, dy) px, |o| = dist px; the tap's constants (ρ and 1/ρ
 * of both layers) are uniform scalars. Selects and DOF_F arithmetic only: no branch, no
 * division (1/r comes from the level's fifth plane, 1/ρ from the tap table). */
inline void dof_tapv(DofAccV *acc, const DOF_F cr, const DOF_F cg, const DOF_F cb, const DOF_F rq,
                     const DOF_F iq, const DOF_F rp, const DOF_F arp, const DOF_F iarp,
                     const float dist, const float rhof, const float rhon, const float irhof,
                     const float irhon, const float inv_ramp, const float cell, const float sa,
                     const DOF_F hx, const DOF_F hy, const int dx, const int dy, const DOF_F pvq,
                     const float vig, __global const float4 *restrict prof, const int lights, const int hidden,
                     __global const float *restrict lsum, const DOF_F tq, const DOF_F tp)
{
    const DOF_I front = rq < rp - DOF_FRONT_MARGIN;
    const DOF_I behind = rq > rp + DOF_FRONT_MARGIN;
    const DOF_I far = rq >= 0.0f;
    /* r = max(|rp|, 1/2) behind p (background clamp), else max(|rq|, 1/2) */
    const DOF_F r = select(fmax(fabs(rq), 0.5f), arp, behind);
    const DOF_F ir = select(iq, iarp, behind);
    const DOF_F rr = r * select((DOF_F)(rhon), (DOF_F)(rhof), far);
    const DOF_F cov = clamp((rr * DOF_TMAX - dist) * inv_ramp + 0.5f, 0.0f, 1.0f);
    /* a light at stride 1 (LIGHT_LUMA in clpost/stages/dof.py): its colour weight on the ¼-px
     * ramp × N₁/N_¼ (in front 1/N_¼; r ≥ DOF_LIGHT_RMAX: the 1-px ramp, in front 1/N₁); `cov`
     * stays the normalising weight. `lights`: a compile-time 1 in the tap loop of a level-0 tile
     * near a light (the kernel's DOF_TAPS), 0 in every other; there only work-items that see a
     * light pay for it */
    DOF_F covc = cov, wsmall = (DOF_F)(0.0f);
    DOF_I small = (DOF_I)(0);
    if (DOF_LIGHTS && lights) {  /* stride 1, a light near the tile; not with cat's-eye bokeh or a traced profile */
        const DOF_I bright = DOF_LIGHT_Y0 * cr + DOF_LIGHT_Y1 * cg + DOF_LIGHT_Y2 * cb > DOF_LIGHT_LUMA;
        if (DOF_ANY(bright)) {
            DOF_F n1, n4;
            dof_light_sums(lsum, r, far, &n1, &n4);
            /* (a texture of |sa| = 1 can zero a small disc's sums: such a light keeps the 1-px ramp) */
            const DOF_I light = bright & (r < DOF_LIGHT_RMAX) & (n4 > 0.0f);
            const DOF_F cl = clamp((rr * DOF_TMAX - dist) * DOF_LIGHT_INV_RAMP + 0.5f, 0.0f, 1.0f);
            covc = select(select(cov, cov / select((DOF_F)(1.0f), n1, n1 > 0.0f), bright & front),
                          cl * select(n1, (DOF_F)(1.0f), front) / select((DOF_F)(1.0f), n4, n4 > 0.0f), light);
            /* LIGHT_SMALL_PX: the 3x3's separable weight, the whole colour weight (texture-free) */
            small = light & (r >= DOF_LIGHT_SMALL_LO) & (r < DOF_LIGHT_SMALL_HI);
            if (abs(dx) <= 1 && abs(dy) <= 1) {
                const DOF_F aw = DOF_LOCAL_A(r);
                wsmall = (dx ? aw : 1.0f - 2.0f * aw) * (dy ? aw : 1.0f - 2.0f * aw) * select(n1, (DOF_F)(1.0f), front);
            }
        }
    }
    DOF_F w = cell * ir * ir;  /* every factor but the coverage: applied to both weights */
#if DOF_TEXTURE
    {
        /* a tap behind p (clamped to p's radius) takes p's layer's texture */
        const DOF_I texfar = select(far, rp >= 0.0f, behind);
        const DOF_F t = fmin(dist * ir * select((DOF_F)(irhon), (DOF_F)(irhof), far), 1.0f);
        const DOF_F a = select((DOF_F)(sa), (DOF_F)(-sa), texfar);
        w *= 1.0f + a * (2.0f * t * t - 1.0f);
#if DOF_TEX_PLANE
        /* half resolution: the texture keeps the disc's untextured lattice sum, N(r/s; 0)/N(r/s; a)
         * (texture_sums in clpost/stages/dof.py): the source's own from its level's plane, p's
         * behind p (r and the texture's sign are p's there) */
        w *= select(tq, tp, behind);
#endif
    }
#endif
#if DOF_VIGNETTING
    {
        const DOF_F sir = select(-ir, ir, far);  /* 1 / (r sgn) */
        /* front and rear barrel circles at ±vig h / 2 (h: the midpoint of p and q, pvq: the mean
         * of their 1/area fraction), so w(p, q) = w(q, p): the clipped bokeh keeps its energy */
        const DOF_F ax = -(float)dx * sir, ay = -(float)dy * sir;
        const DOF_F bx = 0.5f * vig * hx, by = 0.5f * vig * hy;
        const DOF_F e = sqrt(fmax((ax - bx) * (ax - bx) + (ay - by) * (ay - by),
                                  (ax + bx) * (ax + bx) + (ay + by) * (ay + by)));
        w *= clamp((1.0f - e) * r + 0.5f, 0.0f, 1.0f) * pvq;
    }
#endif
    /* wn: the normalising (1-px) weight of the background pool, 0 in front */
    const DOF_F wn = select(w * cov, (DOF_F)(0.0f), front);
    w = select(w * covc, wsmall, small);
#if DOF_PROFILE
    DOF_F pr, pg, pb;
    dof_profile(prof, rq, dist * ir * select((DOF_F)(irhon), (DOF_F)(irhof), far), &pr, &pg, &pb);
    const DOF_F wr = w * pr, wg = w * pg, wb3 = w * pb;
    const DOF_F fwr = select((DOF_F)(0.0f), wr, front), fwg = select((DOF_F)(0.0f), wg, front);
    const DOF_F fwb = select((DOF_F)(0.0f), wb3, front);
    /* behind p and sharper: the weight goes to the hidden background's estimate (dof_hidden) */
    const DOF_I hid = behind & (fabs(rq) < arp - DOF_HIDDEN_MARGIN);
    const DOF_F hwr = select((DOF_F)(0.0f), wr, hid), hwg = select((DOF_F)(0.0f), wg, hid);
    const DOF_F hwb = select((DOF_F)(0.0f), wb3, hid);
    acc->fr += fwr * cr; acc->fg += fwg * cg; acc->fb += fwb * cb;
    acc->wf += fwr; acc->wfg += fwg; acc->wfb += fwb;
    acc->r += (wr - fwr - hwr) * cr; acc->g += (wg - fwg - hwg) * cg; acc->b += (wb3 - fwb - hwb) * cb;
    acc->wh += hwr; acc->whg += hwg; acc->whb += hwb;
    dof_hidden(acc, cr, cg, cb, rq, hid, dist, inv_ramp);
    acc->wb += wn * pr; acc->wbg += wn * pg; acc->wbb += wn * pb;
#else
    const DOF_F wfr = select((DOF_F)(0.0f), w, front);
    DOF_F wbk = w - wfr;
    /* `hidden`: a compile-time 0 in the tap loop of 8 or 16 pixels none of which is in front of
     * the focus by DOF_HIDDEN_MARGIN (no tap can be behind and sharper there) */
    const DOF_I hid = hidden ? behind & (fabs(rq) < arp - DOF_HIDDEN_MARGIN) : (DOF_I)(0);
    if (hidden && dof_any(hid)) {
        /* behind p and sharper: the weight goes to the hidden background's estimate (dof_hidden) */
        const DOF_F whk = select((DOF_F)(0.0f), w, hid);
        wbk -= whk;
        acc->wh += whk;
        dof_hidden(acc, cr, cg, cb, rq, hid, dist, inv_ramp);
    }
    acc->fr += wfr * cr; acc->fg += wfr * cg; acc->fb += wfr * cb; acc->wf += wfr;
    acc->r += wbk * cr; acc->g += wbk * cg; acc->b += wbk * cb; acc->wb += wn;
#endif
}

#if DOF_PROFILE
/* one channel of the composite: front layer over background, each normalised by its own weight
 * (clpost/stages/dof.py); *alpha = the front layer's coverage */
inline DOF_F dof_out(const DOF_F f, const DOF_F b, const DOF_F wf, const DOF_F wb, const DOF_F own, DOF_F *alpha)
{
    const DOF_F a = fmin(1.0f, wf);
    const DOF_F inv_wf = select((DOF_F)(0.0f), 1.0f / wf, wf > 0.0f);
    const DOF_F inv_wb = select((DOF_F)(0.0f), 1.0f / wb, wb > 0.0f);
    *alpha = a;
    return a * inv_wf * f + (1.0f - a) * select(own, b * inv_wb, wb > 0.0f);
}
#endif

/* launched with local size (DOF_TILE / DOF_VEC, DOF_TILE): one work-group per tile, each
 * work-item 8 pixels of a row */
__kernel void dof(__global const float *restrict lv, __global const float *restrict pv,
                  __global const int *restrict tn,
                  __constant const int *restrict tap_dx, __constant const int *restrict tap_dy,
                  __constant const float *restrict tap_dist, __constant const float *restrict rho_far,
                  __constant const float *restrict rho_near, __constant const float *restrict inv_rho_far,
                  __constant const float *restrict inv_rho_near,
                  __global float *restrict out, __global float *restrict alpha_out,
                  const int ww, const int hw, const int pad, const int tw,
                  const float inv_area, const float sa, const float vig,
                  const float cx, const float cy, const float inv_half,
                  __global const float4 *restrict prof, __global const float *restrict lsum)
{
    const int x = DOF_VEC * get_global_id(0), y = get_global_id(1);
    /* per work-group (= tile) values from the group id: uniform, so the tap loop's trip count
     * and offsets are the same for every work-item; edge-tile work-items beyond the image read
     * the padding (DOF_PW) and only skip the final write */
    const int packed = tn[get_group_id(1) * tw + get_group_id(0)];
    const int count = packed & 0xffffff, lvl = (packed >> 24) & 15;  /* bits 28+: dof_tile_mix's */
    /* count 0: a tile whose output nobody reads (final's mixed resolution, dof_tile_mix) */
    if (count == 0) return;
    const int s = 1 << lvl;
    const float fs = (float)s, inv_s = 1.0f / fs, cell = fs * fs * inv_area;
    /* the disc-edge coverage ramp: max(s/2, 1) px wide (clpost/stages/dof.py) */
    const float inv_ramp = 1.0f / fmax(0.5f * fs, 1.0f);
    const int pw = DOF_PW(ww, pad);
    const size_t pn = (size_t)pw * DOF_PW(hw, pad);
    const size_t c0 = (size_t)(y + pad) * pw + (x + pad);
    __global const float *L = lv + (size_t)DOF_PLANES * lvl * pn;
    const DOF_F rp = DOF_LOAD(lv + 3 * pn + c0);
    const DOF_F arp = fmax(fabs(rp), 0.5f), iarp = 1.0f / arp;
    const DOF_F lane = DOF_LANES;
    const DOF_F hx0 = ((float)x + lane - cx) * inv_half;
    const float hy0 = ((float)y - cy) * inv_half;
    DofAccV acc = {(DOF_F)(0.0f), (DOF_F)(0.0f), (DOF_F)(0.0f), (DOF_F)(0.0f),
                   (DOF_F)(0.0f), (DOF_F)(0.0f), (DOF_F)(0.0f), (DOF_F)(0.0f),
#if DOF_PROFILE
                   (DOF_F)(0.0f), (DOF_F)(0.0f), (DOF_F)(0.0f), (DOF_F)(0.0f)
#endif
                   };
    acc.hr = acc.hg = acc.hb = acc.hk = acc.wh = (DOF_F)(0.0f);
    acc.dh = (DOF_F)(-1.0f);
#if DOF_PROFILE
    acc.whg = acc.whb = (DOF_F)(0.0f);
#endif
    const DOF_F pvp = DOF_VIGNETTING ? DOF_LOAD(pv + c0) : (DOF_F)(1.0f);
    /* p's own texture rescale (DOF_TEX_PLANE): its centre tap's and every tap's behind it */
    DOF_F tp = (DOF_F)(1.0f);
#if DOF_TEX_PLANE
    {
        DOF_F t1, th;
        dof_light_sums(lsum, arp * inv_s, rp >= 0.0f, &t1, &th);
        tp = lvl > 0 ? th : t1;
    }
#endif
    /* the taps; the light path (dof_tapv's `lights`) only in a level-0 tile that dof_tile_dilate
     * found within one tile of a light (bit 31 of its packed plan): the same loop without it
     * elsewhere, so a frame without lights runs the plain tap loop */
#define DOF_TAPS(LIGHT, HIDDEN) { \
    {\
        /* centre tap: own colour, blended toward the level's as p's own bokeh outgrows the\
         * lattice spacing (a point light's centre must not stay a one-pixel spike) */\
        const DOF_F beta = clamp(fabs(rp) * inv_s, 0.0f, 1.0f);\
        const DOF_F ob = 1.0f - beta;\
        dof_tapv(&acc, DOF_LOAD(lv + c0) * ob + DOF_LOAD(L + c0) * beta,\
                 DOF_LOAD(lv + pn + c0) * ob + DOF_LOAD(L + pn + c0) * beta,\
                 DOF_LOAD(lv + 2 * pn + c0) * ob + DOF_LOAD(L + 2 * pn + c0) * beta,\
                 rp, iarp, rp, arp, iarp, 0.0f, rho_far[0], rho_near[0], inv_rho_far[0], inv_rho_near[0],\
                 inv_ramp, cell, sa, hx0, (DOF_F)(hy0), 0, 0,\
                 pvp, vig, prof, (LIGHT), (HIDDEN), lsum, tp, tp);\
    }\
    for (int k = 1; k < count; ++k) {\
        const int dx = s * tap_dx[k], dy = s * tap_dy[k];\
        const size_t q = (size_t)((long)c0 + (long)dy * pw + dx);\
        dof_tapv(&acc, DOF_LOAD(L + q), DOF_LOAD(L + pn + q), DOF_LOAD(L + 2 * pn + q),\
                 DOF_LOAD(L + 3 * pn + q), DOF_LOAD(L + 4 * pn + q), rp, arp, iarp, fs * tap_dist[k],\
                 rho_far[k], rho_near[k], inv_rho_far[k], inv_rho_near[k], inv_ramp, cell, sa,\
                 ((float)x + 0.5f * (float)dx + lane - cx) * inv_half,\
                 (DOF_F)(((float)y + 0.5f * (float)dy - cy) * inv_half),\
                 dx, dy, DOF_VIGNETTING ? 0.5f * (pvp + DOF_LOAD(pv + q)) : (DOF_F)(1.0f), vig, prof,\
                 (LIGHT), (HIDDEN), lsum, DOF_TEX_PLANE ? DOF_LOAD(L + 5 * pn + q) : (DOF_F)(1.0f), tp);\
    } }
    /* the hidden background's taps (dof_hidden) only where a pixel is in front of the focus */
    const int hidden = DOF_ANY(rp < -DOF_HIDDEN_MARGIN);
    if (DOF_LIGHTS && lvl == 0 && packed < 0) {
        if (hidden)
            DOF_TAPS(1, 1)
        else
            DOF_TAPS(1, 0)
    } else if (hidden)
        DOF_TAPS(0, 1)
    else
        DOF_TAPS(0, 0)
#undef DOF_TAPS
    /* the behind taps' weight takes the hidden background's estimate as its colour */
    {
        const DOF_F ihk = select((DOF_F)(0.0f), 1.0f / acc.hk, acc.hk > 0.0f);
#if DOF_PROFILE
        acc.r += acc.wh * acc.hr * ihk; acc.g += acc.whg * acc.hg * ihk; acc.b += acc.whb * acc.hb * ihk;
#else
        acc.r += acc.wh * acc.hr * ihk; acc.g += acc.wh * acc.hg * ihk; acc.b += acc.wh * acc.hb * ihk;
#endif
    }
    /* per channel (one weight for all three without DOF_PROFILE); alpha_out: green's coverage.
     * No background weight (a strong SA texture zeroes the centre tap and every other tap is in
     * front): the background is the pixel's own colour, never 0/0 */
#if DOF_PROFILE
    /* per channel (the traced weights differ per colour); alpha_out: green's coverage */
    DOF_F alpha, a_r, a_b;
    DOF_F o_r = dof_out(acc.fr, acc.r, acc.wf, acc.wb, DOF_LOAD(lv + c0), &a_r);
    DOF_F o_g = dof_out(acc.fg, acc.g, acc.wfg, acc.wbg, DOF_LOAD(lv + pn + c0), &alpha);
    DOF_F o_b = dof_out(acc.fb, acc.b, acc.wfb, acc.wbb, DOF_LOAD(lv + 2 * pn + c0), &a_b);
#else
    const DOF_F alpha = fmin(1.0f, acc.wf);
    const DOF_F inv_wf = select((DOF_F)(0.0f), 1.0f / acc.wf, acc.wf > 0.0f);
    /* no background weight (a strong SA texture zeroes the centre tap and every other tap is in
     * front): the background is the pixel's own colour, never 0/0 */
    const DOF_F inv_wb = select((DOF_F)(0.0f), 1.0f / acc.wb, acc.wb > 0.0f);
    const DOF_F ob = 1.0f - alpha, af = alpha * inv_wf;
    DOF_F o_r = af * acc.fr + ob * select(DOF_LOAD(lv + c0), acc.r * inv_wb, acc.wb > 0.0f);
    DOF_F o_g = af * acc.fg + ob * select(DOF_LOAD(lv + pn + c0), acc.g * inv_wb, acc.wb > 0.0f);
    DOF_F o_b = af * acc.fb + ob * select(DOF_LOAD(lv + 2 * pn + c0), acc.b * inv_wb, acc.wb > 0.0f);
#endif
#if DOF_SCALE == 1
    /* small CoCs (final; _full_small in clpost/stages/dof.py): lerp(3x3 blur, gather, b),
     * b = clamp((|r| - DOF_SMALL_LO) DOF_SMALL_K, 0, 1), 1 where alpha > 0; the 3x3 blur as
     * dof_local_px, on level 0 of the padded buffers (their border replicates the edge, as its
     * clamp does) */
    const DOF_F bl = select(clamp((fabs(rp) - DOF_SMALL_LO) * DOF_SMALL_K, 0.0f, 1.0f), (DOF_F)(1.0f), alpha > 0.0f);
    if (count > 1 && DOF_ANY(bl < 1.0f)) {  /* one-tap tiles: kept as gathered (_full_small's one_tap) */
        const DOF_F ap = DOF_LOCAL_A(rp);
        DOF_I need = fabs(rp) >= DOF_LOCAL_MIN;
        DOF_F lr = (DOF_F)(0.0f), lg = (DOF_F)(0.0f), lb = (DOF_F)(0.0f), lw = (DOF_F)(0.0f);
        for (int b = -1; b <= 1; ++b)
            for (int a = -1; a <= 1; ++a) {
                const size_t q = (size_t)((long)c0 + (long)b * pw + a);
                const DOF_F rq = DOF_LOAD(lv + 3 * pn + q);
                const DOF_I front = rq < rp - DOF_FRONT_MARGIN;
                need |= front & (fabs(rq) >= DOF_LOCAL_MIN);
                const DOF_F aq = select(fmin(DOF_LOCAL_A(rq), ap), DOF_LOCAL_A(rq), front);
                const DOF_F wq = (b ? aq : 1.0f - 2.0f * aq) * (a ? aq : 1.0f - 2.0f * aq);
                lr += wq * DOF_LOAD(lv + q); lg += wq * DOF_LOAD(lv + pn + q); lb += wq * DOF_LOAD(lv + 2 * pn + q);
                lw += wq;
            }
        const DOF_F il = 1.0f / lw;
        const DOF_F nr = select(DOF_LOAD(lv + c0), lr * il, need);
        const DOF_F ng = select(DOF_LOAD(lv + pn + c0), lg * il, need);
        const DOF_F nb = select(DOF_LOAD(lv + 2 * pn + c0), lb * il, need);
        o_r = select(nr + (o_r - nr) * bl, o_r, bl >= 1.0f);
        o_g = select(ng + (o_g - ng) * bl, o_g, bl >= 1.0f);
        o_b = select(nb + (o_b - nb) * bl, o_b, bl >= 1.0f);
    }
#endif
    if (y >= hw || x >= ww) return;
    const size_t n = (size_t)ww * hw, i = (size_t)y * ww + x;
    if (x + DOF_VEC <= ww) {
        DOF_STORE(o_r, out + i); DOF_STORE(o_g, out + n + i); DOF_STORE(o_b, out + 2 * n + i);
        DOF_STORE(alpha, alpha_out + i);
    } else {
        /* the image's last, partial group of 8 */
        float tr[DOF_VEC], tg[DOF_VEC], tb[DOF_VEC], ta[DOF_VEC];
        DOF_STORE(o_r, tr); DOF_STORE(o_g, tg); DOF_STORE(o_b, tb); DOF_STORE(alpha, ta);
        for (int j = 0; j < ww - x; ++j) {
            out[i + j] = tr[j]; out[n + i + j] = tg[j]; out[2 * n + i + j] = tb[j];
            alpha_out[i + j] = ta[j];
        }
    }
}

/* Half-resolution levels: small CoCs take the full-resolution 3x3 blur (dof_local_px), mixed with
 * the upsampled blur where the full-resolution CoC (DOF_HALF_B) or the front layer's coverage says so. Upsampling is bilinear
 * weighted by CoC similarity g = 1/(DOF_UP_TOL + (r - m_i)^2) (UPSAMPLE_COC_TOL_PX2), r the full-resolution CoC and m_i the min of
 * the full-resolution CoC over corner i's DOF_SCALE^2 block: the original CoC, not the
 * variance-matched one the working pixels were gathered with, which is 0 for every |r| < 2.31 px
 * (see _upsample and _half_composite in clpost/stages/dof.py).
 * One output pixel (the edge groups of dof_upsample). */
inline float dof_block_min(__global const float *coc, const int xs, const int ys, const int width, const int height)
{
    float m = INFINITY;
    for (int b = 0; b < DOF_SCALE; ++b)
        for (int a = 0; a < DOF_SCALE; ++a)
            m = fmin(m, coc[(size_t)min(DOF_SCALE * ys + b, height - 1) * width + min(DOF_SCALE * xs + a, width - 1)]);
    return m;
}

/* The full-resolution 3x3 blur of small CoCs (local_blur in clpost/stages/dof.py): neighbour q
 * weighs w(ox) w(oy), w(0) = 1 - 2a, w(+-1) = a, a = DOF_LOCAL_A of q's CoC when q is nearer than p
 * by more than DOF_FRONT_MARGIN (px here), else of the smaller of the two; normalised. Edges clamped. */
inline float3 dof_local_px(__global const float *src, __global const float *coc, const int x, const int y,
                           const int width, const int height)
{
    const size_t n = (size_t)width * height, i = (size_t)y * width + x;
    const float r = coc[i], ap = DOF_LOCAL_A(r);
    /* every side weight under DOF_LOCAL_A(DOF_LOCAL_MIN): p's own |r| and every nearer neighbour's
     * under DOF_LOCAL_MIN (the others weigh at most p's) */
    int need = fabs(r) >= DOF_LOCAL_MIN;
    for (int b = -1; b <= 1; ++b)
        for (int a = -1; a <= 1; ++a) {
            const float rq = coc[(size_t)clamp(y + b, 0, height - 1) * width + clamp(x + a, 0, width - 1)];
            need |= rq < r - DOF_FRONT_MARGIN && fabs(rq) >= DOF_LOCAL_MIN;
        }
    if (!need)
        return (float3)(src[i], src[n + i], src[2 * n + i]);
    float3 acc = (float3)(0.0f);
    float wsum = 0.0f;
    for (int b = -1; b <= 1; ++b)
        for (int a = -1; a <= 1; ++a) {
            const size_t j = (size_t)clamp(y + b, 0, height - 1) * width + clamp(x + a, 0, width - 1);
            const float rq = coc[j];
            const float aq = rq < r - DOF_FRONT_MARGIN ? DOF_LOCAL_A(rq) : fmin(DOF_LOCAL_A(rq), ap);
            const float wq = (b ? aq : 1.0f - 2.0f * aq) * (a ? aq : 1.0f - 2.0f * aq);
            acc += wq * (float3)(src[j], src[n + j], src[2 * n + j]);
            wsum += wq;
        }
    return acc / wsum;
}

inline float3 dof_upsample_px(__global const float *src, __global const float *coc, __global const float *blur,
                              __global const float *alpha, const int x, const int y,
                              const int width, const int height, const int ww, const int hw)
{
    const float sx = ((float)x + 0.5f) / DOF_SCALE - 0.5f, sy = ((float)y + 0.5f) / DOF_SCALE - 0.5f;
    const int x0 = clamp((int)floor(sx), 0, ww - 1), y0 = clamp((int)floor(sy), 0, hw - 1);
    const float fx = clamp(sx - (float)x0, 0.0f, 1.0f), fy = clamp(sy - (float)y0, 0.0f, 1.0f);
    const int x1 = min(x0 + 1, ww - 1), y1 = min(y0 + 1, hw - 1);
    const size_t n = (size_t)width * height, i = (size_t)y * width + x, nw = (size_t)ww * hw;
    const float r = coc[i];
    const int xs[4] = {x0, x1, x0, x1}, ys[4] = {y0, y0, y1, y1};
    const float bw[4] = {(1.0f - fx) * (1.0f - fy), fx * (1.0f - fy), (1.0f - fx) * fy, fx * fy};
    float dr[4];
    int same = 0;
    for (int c = 0; c < 4; ++c) {
        dr[c] = fabs(r - dof_block_min(coc, xs[c], ys[c], width, height));
        same |= bw[c] > 0.0f && dr[c] <= DOF_UP_SAME;
    }
    float4 acc = (float4)(0.0f);
    float wsum = 0.0f;
    for (int c = 0; c < 4; ++c) {
        const size_t j = (size_t)ys[c] * ww + xs[c];
        const float g = same && dr[c] > DOF_UP_SAME ? 0.0f : bw[c] / (DOF_UP_TOL + dr[c] * dr[c]);
        acc += g * (float4)(blur[j], blur[nw + j], blur[2 * nw + j], alpha[j]);
        wsum += g;
    }
    acc /= wsum;
    const float b = fmax(DOF_HALF_B(r), acc.w);
    if (b >= 1.0f)
        return acc.xyz;  /* exact at b = 1 even for 1e8 highlights */
    const float3 c = dof_local_px(src, coc, x, y, width, height);
    return c + (acc.xyz - c) * b;
}

#if DOF_SCALE == 2
/* working pixels m-1 .. m+14 of a row (one vload16) -> the left (x0) and right (x1 = x0 + 1)
 * bilinear corners of output pixels 2m .. 2m+15: x0 = m-1, m, m, m+1, m+1, ..., m+7 with
 * fx = 3/4, 1/4, 3/4, ... */
#define DOF_LEFT(v) ((float16)((v).s0, (v).s1, (v).s1, (v).s2, (v).s2, (v).s3, (v).s3, (v).s4, \
                               (v).s4, (v).s5, (v).s5, (v).s6, (v).s6, (v).s7, (v).s7, (v).s8))
#define DOF_RIGHT(v) ((float16)((v).s1, (v).s2, (v).s2, (v).s3, (v).s3, (v).s4, (v).s4, (v).s5, \
                                (v).s5, (v).s6, (v).s6, (v).s7, (v).s7, (v).s8, (v).s8, (v).s9))
#endif

/* The 16-lane upsampling's shared steps (dof_upsample16 at the row ends, dof_upsample inside;
 * macros, not functions: a shared function was measured slower, docs/fidelity.md):
 * p's own surface among the 2x2 working corners (the others are left out, UPSAMPLE_SAME_PX), and
 * one row of corners' weighted colour and alpha, read through DOF_UP_LOAD(plane, row offset),
 * which each caller defines (clamped per lane at the ends, whole-row loads inside). */
#define DOF_UP_OWN_SURFACE (((wl0 > 0.0f) & (dl0 <= DOF_UP_SAME)) | ((wr0 > 0.0f) & (dr0 <= DOF_UP_SAME)) \
                            | ((wl1 > 0.0f) & (dl1 <= DOF_UP_SAME)) | ((wr1 > 0.0f) & (dr1 <= DOF_UP_SAME)))
#define DOF_UP_ROW(YS, DL, DR, WL, WR) { \
        const size_t j = (size_t)(YS) * ww; \
        const float16 vr = DOF_UP_LOAD(blur, j), vg = DOF_UP_LOAD(blur + nw, j); \
        const float16 vb = DOF_UP_LOAD(blur + 2 * nw, j), va = DOF_UP_LOAD(alpha, j); \
        const float16 gl = select((WL) / (DOF_UP_TOL + (DL) * (DL)), (float16)(0.0f), same & ((DL) > DOF_UP_SAME)); \
        const float16 gr = select((WR) / (DOF_UP_TOL + (DR) * (DR)), (float16)(0.0f), same & ((DR) > DOF_UP_SAME)); \
        ar += gl * DOF_LEFT(vr); ag += gl * DOF_LEFT(vg); ab += gl * DOF_LEFT(vb); aa += gl * DOF_LEFT(va); \
        wsum += gl; \
        ar += gr * DOF_RIGHT(vr); ag += gr * DOF_RIGHT(vg); ab += gr * DOF_RIGHT(vb); aa += gr * DOF_RIGHT(va); \
        wsum += gr; }

/* The corners' weighted colour (ar, ag, ab) and alpha (ua) of the 16 pixels, the half-resolution
 * blend b and `near` (DOF_NARROW_NEAR): declared in the caller's scope from its r, fx, fy, y0, y1, m,
 * with DOF_UP_LOAD defined by the caller and EDGE its dof_block_min16 clamp (0 inside the image). */
#define DOF_UP_CORNERS(EDGE) \
    float16 ar = (float16)(0.0f), ag = ar, ab = ar, aa = ar, wsum = ar; \
    const float16 vc0 = dof_block_min16(coc, x, y0, width, height, ww, (EDGE)); \
    const float16 vc1 = dof_block_min16(coc, x, y1, width, height, ww, (EDGE)); \
    const float16 dl0 = fabs(r - DOF_LEFT(vc0)), dr0 = fabs(r - DOF_RIGHT(vc0)); \
    const float16 dl1 = fabs(r - DOF_LEFT(vc1)), dr1 = fabs(r - DOF_RIGHT(vc1)); \
    const float16 wl0 = (1.0f - fx) * (1.0f - fy), wr0 = fx * (1.0f - fy), wl1 = (1.0f - fx) * fy, wr1 = fx * fy; \
    const int16 same = DOF_UP_OWN_SURFACE; \
    DOF_UP_ROW(y0, dl0, dr0, wl0, wr0) \
    DOF_UP_ROW(y1, dl1, dr1, wl1, wr1) \
    const float16 inv = 1.0f / wsum; \
    const float16 b = fmax(DOF_HALF_B(r), aa * inv); \
    ar *= inv; ag *= inv; ab *= inv; \
    const int near = DOF_NARROW_NEAR; \
    const float16 ua = aa * inv;

/* The narrow-source layer (dof_narrow.cl, prepended to this program): its arguments, and its
 * light added to the 16 pixels after the composite is stored (nothing without DOF_NARROW). */
#define DOF_NARROW_PARAMS __global const int *restrict ncount, __global const float8 *restrict nrec, \
    __global const int *restrict ntile, \
    const int ncx, const int ncy, __global const float2 *restrict normals, const int nblades, const float kpoly, \
    const float roundness, const float nsa, const float ninv_area
#define DOF_NARROW_ARGS ncount, nrec, ntile, ncx, ncy, normals, nblades, kpoly, roundness, nsa, ninv_area
#if DOF_NARROW
/* after the 16 pixels are stored: where a source's disc reaches the 16-px tile (`ntile`) and one of its
 * discs reaches these pixels, add the layer to them (read back, add, store; NL lanes inside the image) */
#define DOF_NARROW_NEAR ntile[(y / 16) * ((width + 15) / 16) + x / 16]
#define DOF_NARROW_APPLY(UA, KW, NL) if (near) { \
        float16 l3[3] = {(float16)(0.0f), (float16)(0.0f), (float16)(0.0f)}; \
        if (dof_narrow16(ncount, nrec, ncx, ncy, x, y, r, (UA), (KW), normals, nblades, kpoly, roundness, nsa, \
                         ninv_area, &l3[0], &l3[1], &l3[2])) \
            for (int c = 0; c < 3; ++c) { \
                if ((NL) == 16) { \
                    vstore16(vload16(0, dst + c * n + i) + l3[c], 0, dst + c * n + i); \
                } else { \
                    float t[16]; \
                    vstore16(l3[c], 0, t); \
                    for (int l = 0; l < (NL); ++l) dst[c * n + i + l] += t[l]; \
                } \
            } \
    }
#else
#define DOF_NARROW_NEAR 0
#define DOF_NARROW_APPLY(UA, KW, NL)
#endif

#if DOF_SCALE == 2
/* 16 floats of row `row` from column `col` on: one vload16 inside the row (edge 0), else per lane
 * with the column clamped to [0, lim - 1] (edge 1: the groups at the image's left/right end, the
 * per-pixel formulas' clamps) */
inline float16 dof_row16(__global const float *p, const size_t row, const int col, const int lim, const int edge)
{
    if (!edge)
        return vload16(0, p + row + col);
    float t[16];
    for (int l = 0; l < 16; ++l)
        t[l] = p[row + clamp(col + l, 0, lim - 1)];
    return vload16(0, t);
}

/* The min CoC of the 2x2 blocks of working pixels m-1 .. m+14 (m = x / 2) in working row ys
 * (dof_block_min: working columns clamped to [0, ww - 1], the block's second column and row to the
 * image). */
inline float16 dof_block_min16(__global const float *coc, const int x, const int ys, const int width, const int height,
                               const int ww, const int edge)
{
    const size_t k0 = (size_t)(2 * ys) * width;
    const size_t k1 = (size_t)min(2 * ys + 1, height - 1) * width;
    if (!edge) {
        const float16 a0 = vload16(0, coc + k0 + x - 2), a1 = vload16(1, coc + k0 + x - 2);
        const float16 b0 = vload16(0, coc + k1 + x - 2), b1 = vload16(1, coc + k1 + x - 2);
        return (float16)(fmin(fmin(a0.even, a0.odd), fmin(b0.even, b0.odd)),
                         fmin(fmin(a1.even, a1.odd), fmin(b1.even, b1.odd)));
    }
    float t[16];
    for (int l = 0; l < 16; ++l) {
        const int c0 = 2 * clamp(x / 2 - 1 + l, 0, ww - 1), c1 = min(c0 + 1, width - 1);
        t[l] = fmin(fmin(coc[k0 + c0], coc[k0 + c1]), fmin(coc[k1 + c0], coc[k1 + c1]));
    }
    return vload16(0, t);
}

/* 16 floats to dst + i: the lanes inside the image (the last group of a row may be partial) */
inline void dof_store16(const float16 v, __global float *dst, const size_t i, const int nlanes)
{
    if (nlanes >= 16) {
        vstore16(v, 0, dst + i);
        return;
    }
    float t[16];
    vstore16(v, 0, t);
    for (int l = 0; l < nlanes; ++l)
        dst[i + l] = t[l];
}

/* The vector form of dof_upsample_px (its formulas lane-wise) for output pixels x .. x + 15 of row
 * y, with edge = 1: the groups at the image's left/right end, whose loads leave the rows
 * (dof_row16, dof_block_min16 clamp per lane as the per-pixel form does). The interior groups run
 * the same formulas inline in dof_upsample with whole-row loads, without the per-lane clamps
 * (docs/fidelity.md has the measurements behind the split). */
inline void dof_upsample16(__global const float *restrict src, __global const float *restrict coc,
                           __global const float *restrict blur, __global const float *restrict alpha,
                           __global float *restrict dst, const int x, const int y,
                           const int width, const int height, const int ww, const int hw, const int edge,
                           DOF_NARROW_PARAMS)
{
    const size_t n = (size_t)width * height, i = (size_t)y * width + x, nw = (size_t)ww * hw;
    const int nlanes = min(16, width - x);
    const int m = x / 2;
    const float sy = ((float)y + 0.5f) / DOF_SCALE - 0.5f;
    const int y0 = clamp((int)floor(sy), 0, hw - 1), y1 = min(y0 + 1, hw - 1);
    const float fy = clamp(sy - (float)y0, 0.0f, 1.0f);
    const float16 fx = (float16)(0.75f, 0.25f, 0.75f, 0.25f, 0.75f, 0.25f, 0.75f, 0.25f,
                                  0.75f, 0.25f, 0.75f, 0.25f, 0.75f, 0.25f, 0.75f, 0.25f);
    const size_t row = (size_t)y * width;
    const float16 r = dof_row16(coc, row, x, width, edge);
#define DOF_UP_LOAD(P, J) dof_row16((P), (J), m - 1, ww, edge)
    DOF_UP_CORNERS(edge)
#undef DOF_UP_LOAD
    const int16 whole = b >= 1.0f;
    if (all(whole)) {  /* every pixel takes the half-resolution blur whole (r >= 2 px) */
        dof_store16(ar, dst, i, nlanes); dof_store16(ag, dst + n, i, nlanes); dof_store16(ab, dst + 2 * n, i, nlanes);
        DOF_NARROW_APPLY(ua, (float16)(0.0f), nlanes)
        return;
    }
    /* the full-resolution 3x3 blur (dof_local_px), lane-wise; rows clamped to the image */
    const size_t rows[3] = {(size_t)max(y - 1, 0) * width, row, (size_t)min(y + 1, height - 1) * width};
    const float16 ap = DOF_LOCAL_A(r);
    int16 need = fabs(r) >= DOF_LOCAL_MIN;  /* dof_local_px's test */
#pragma unroll
    for (int bb = 0; bb < 3; ++bb)
#pragma unroll
        for (int a = -1; a <= 1; ++a) {
            const float16 rq = dof_row16(coc, rows[bb], x + a, width, edge);
            need |= (rq < r - DOF_FRONT_MARGIN) & (fabs(rq) >= DOF_LOCAL_MIN);
        }
    const int16 sharp = !need;
    const float16 sr = dof_row16(src, row, x, width, edge), sg = dof_row16(src + n, row, x, width, edge);
    const float16 sb = dof_row16(src + 2 * n, row, x, width, edge);
    float16 cr = sr, cg = sg, cb = sb, kw = (float16)(0.0f);  /* kw: DOF_NARROW_APPLY's */
    if (!all(sharp | whole)) {  /* some pixel needs the 3x3's taps */
        float16 tr = (float16)(0.0f), tg = tr, tb = tr, cw = tr;
#pragma unroll
        for (int bb = 0; bb < 3; ++bb)
#pragma unroll
            for (int a = -1; a <= 1; ++a) {
                const float16 rq = dof_row16(coc, rows[bb], x + a, width, edge);
                const float16 aq = select(fmin(DOF_LOCAL_A(rq), ap), DOF_LOCAL_A(rq), rq < r - DOF_FRONT_MARGIN);
                const float16 wq = (bb != 1 ? aq : 1.0f - 2.0f * aq) * (a ? aq : 1.0f - 2.0f * aq);
                tr += wq * dof_row16(src, rows[bb], x + a, width, edge);
                tg += wq * dof_row16(src + n, rows[bb], x + a, width, edge);
                tb += wq * dof_row16(src + 2 * n, rows[bb], x + a, width, edge);
                cw += wq;
            }
        const float16 ic = 1.0f / cw;
        cr = select(tr * ic, sr, sharp);
        cg = select(tg * ic, sg, sharp);
        cb = select(tb * ic, sb, sharp);
        kw = select((1.0f - b) * ic, (float16)(0.0f), sharp | whole);
    }
    dof_store16(select(cr + (ar - cr) * b, ar, whole), dst, i, nlanes);
    dof_store16(select(cg + (ag - cg) * b, ag, whole), dst + n, i, nlanes);
    dof_store16(select(cb + (ab - cb) * b, ab, whole), dst + 2 * n, i, nlanes);
    DOF_NARROW_APPLY(ua, kw, nlanes)
}
#endif

/* 16 output pixels of a row per work-item, float16 (PoCL does not vectorise the per-pixel form;
 * docs/measurements.md#kernel-forms-on-pocl); groups of 16 at the image's left/right end (where the
 * row load would leave the working row) per pixel. Launched over (ceil(width / 16), height). */
__kernel void dof_upsample(__global const float *restrict src, __global const float *restrict coc,
                           __global const float *restrict blur, __global const float *restrict alpha,
                           __global float *restrict dst,
                           const int width, const int height, const int ww, const int hw,
                           __global const int *restrict tn_mix, const int tw_mix, DOF_NARROW_PARAMS)
{
    const int x = 16 * get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
#if DOF_MIXED
    /* final's mixed resolution: only the pixels of big working tiles (`tn_mix` = dof_tile_mix's
     * `mix`) take the
     * half-resolution blur; the rest keep the full-resolution gather already in dst. The 16
     * pixels lie in one working tile (x is a multiple of 16, a working tile 2 * DOF_TILE px). */
    if (!tn_mix[(y / (DOF_SCALE * DOF_TILE)) * tw_mix + x / (DOF_SCALE * DOF_TILE)])
        return;
#endif
    const size_t n = (size_t)width * height, i = (size_t)y * width + x, nw = (size_t)ww * hw;
#if DOF_SCALE == 2
    const int m = x / 2;
    /* x + 30 <= width: the corners' 2x2 blocks (columns 2m - 2 .. 2m + 29) lie in the image */
    if (m >= 1 && m + 14 <= ww - 1 && x + 30 <= width) {
        const float sy = ((float)y + 0.5f) / DOF_SCALE - 0.5f;
        const int y0 = clamp((int)floor(sy), 0, hw - 1), y1 = min(y0 + 1, hw - 1);
        const float fy = clamp(sy - (float)y0, 0.0f, 1.0f);
        const float16 fx = (float16)(0.75f, 0.25f, 0.75f, 0.25f, 0.75f, 0.25f, 0.75f, 0.25f,
                                      0.75f, 0.25f, 0.75f, 0.25f, 0.75f, 0.25f, 0.75f, 0.25f);
        const float16 r = vload16(0, coc + i);
#define DOF_UP_LOAD(P, J) vload16(0, (P) + (J) + m - 1)
        DOF_UP_CORNERS(0)
#undef DOF_UP_LOAD
        const int16 whole_ = b >= 1.0f;
        if (all(whole_)) {  /* every pixel takes the half-resolution blur whole (r >= 2 px) */
            vstore16(ar, 0, dst + i); vstore16(ag, 0, dst + n + i); vstore16(ab, 0, dst + 2 * n + i);
            DOF_NARROW_APPLY(ua, (float16)(0.0f), 16)
            return;
        }
        /* the full-resolution 3x3 blur (dof_local_px), lane-wise; columns x - 1 .. x + 16 lie in
         * the image (x >= 2, x + 30 <= width) */
        const float16 ap = DOF_LOCAL_A(r);
        int16 need = fabs(r) >= DOF_LOCAL_MIN;  /* dof_local_px's test */
#pragma unroll
        for (int bb = -1; bb <= 1; ++bb) {
            const size_t row = (size_t)clamp(y + bb, 0, height - 1) * width + x;
#pragma unroll
            for (int a = -1; a <= 1; ++a) {
                const float16 rq = vload16(0, coc + row + a);
                need |= (rq < r - DOF_FRONT_MARGIN) & (fabs(rq) >= DOF_LOCAL_MIN);
            }
        }
        const int16 sharp = !need;
        if (all(sharp | whole_)) {  /* no pixel needs the 3x3's taps: its colour is the source's */
            const float16 sr = vload16(0, src + i), sg = vload16(0, src + n + i), sb = vload16(0, src + 2 * n + i);
            vstore16(select(sr + (ar - sr) * b, ar, whole_), 0, dst + i);
            vstore16(select(sg + (ag - sg) * b, ag, whole_), 0, dst + n + i);
            vstore16(select(sb + (ab - sb) * b, ab, whole_), 0, dst + 2 * n + i);
            DOF_NARROW_APPLY(ua, (float16)(0.0f), 16)
            return;
        }
        float16 cr = (float16)(0.0f), cg = cr, cb = cr, cw = cr;
#pragma unroll
        for (int bb = -1; bb <= 1; ++bb) {
            const size_t row = (size_t)clamp(y + bb, 0, height - 1) * width + x;
#pragma unroll
            for (int a = -1; a <= 1; ++a) {
                const float16 rq = vload16(0, coc + row + a);
                const float16 aq = select(fmin(DOF_LOCAL_A(rq), ap), DOF_LOCAL_A(rq), rq < r - DOF_FRONT_MARGIN);
                const float16 wq = (bb ? aq : 1.0f - 2.0f * aq) * (a ? aq : 1.0f - 2.0f * aq);
                cr += wq * vload16(0, src + row + a);
                cg += wq * vload16(0, src + n + row + a);
                cb += wq * vload16(0, src + 2 * n + row + a);
                cw += wq;
            }
        }
        const float16 ic = 1.0f / cw;
        const int16 whole = whole_;
        cr = select(cr * ic, vload16(0, src + i), sharp);
        cg = select(cg * ic, vload16(0, src + n + i), sharp);
        cb = select(cb * ic, vload16(0, src + 2 * n + i), sharp);
        vstore16(select(cr + (ar - cr) * b, ar, whole), 0, dst + i);
        vstore16(select(cg + (ag - cg) * b, ag, whole), 0, dst + n + i);
        vstore16(select(cb + (ab - cb) * b, ab, whole), 0, dst + 2 * n + i);
        DOF_NARROW_APPLY(ua, select((1.0f - b) * ic, (float16)(0.0f), sharp | whole), 16)
        return;
    }
    /* the groups at the image's left/right end: the same formulas, loads clamped per lane */
    dof_upsample16(src, coc, blur, alpha, dst, x, y, width, height, ww, hw, 1, DOF_NARROW_ARGS);
#else
    for (int xi = x; xi < min(x + 16, width); ++xi) {
        const float3 o = dof_upsample_px(src, coc, blur, alpha, xi, y, width, height, ww, hw);
        const size_t ii = (size_t)y * width + xi;
        dst[ii] = o.x; dst[n + ii] = o.y; dst[2 * n + ii] = o.z;
    }
#endif
}
