/* grain, white Gaussian path (grain radius too small for a measurable lag-1 correlation,
 * clpost/stages/grain.py RHO_WHITE) as a pointwise stage fused with film and print: the pixel's
 * density is all it reads, so the frame is read and written once for all three. Width-generic
 * (clpost/codegen.py), after kernels/grain_pixel.cl; the same counters, normals and arithmetic as
 * the gather's white path had, so the image is the same bit for bit.
 * params = [dmin0 dmin1 dmin2 dmax0 dmax1 dmax2].
 *
 * State (PointwiseStage.state): a float16 of Box-Muller draws is the normals of 32 consecutive
 * counters, cosines for the first 16 and sines for the next; the generated kernel runs 32 pixels
 * per work-item as two 16-pixel calls, and grain_prepare (once, at x0 a multiple of 32) draws the
 * block of each layer into st[0] (cosines: pixels x0 .. x0 + 15) and st[1] (sines: x0 + 16 ..
 * x0 + 31) — half a draw per pixel and layer. The one-pixel form draws its counter's pair and
 * keeps the branch its counter takes. */
typedef struct { CLP_F n[3]; } CLP_FN(grain_state);   /* the call's normals, per layer */

inline void CLP_FN(grain_prepare)(const CLP_CTX p, CLP_FN(grain_state) *st, __global const float *params,
                                  __global const float *poly, const float inv_half_span, const float amount,
                                  const uint seed, const uint frame) {
    (void)params; (void)poly; (void)inv_half_span; (void)amount;
    for (uint c = 0; c < 3; ++c) {
#if CLP_W == 1
        st[0].n[c] = CLP_FN(grain_normal)(seed, frame, p.x, p.y, c);
#else
        st[0].n[c] = CLP_FN(grain_block)(seed, frame, (uint)p.x0 >> 5, p.y, c, &st[1].n[c]);
#endif
    }
}

inline void grain_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, const CLP_FN(grain_state) *st,
                        __global const float *params, __global const float *poly, const float inv_half_span,
                        const float amount, const uint seed, const uint frame) {
    (void)p; (void)seed; (void)frame;
    *r = CLP_FN(grain_pixel)(*r, params[0], params[3], st->n[0], poly, inv_half_span, amount);
    *g = CLP_FN(grain_pixel)(*g, params[1], params[4], st->n[1], poly, inv_half_span, amount);
    *b = CLP_FN(grain_pixel)(*b, params[2], params[5], st->n[2], poly, inv_half_span, amount);
}
