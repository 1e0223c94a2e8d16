/* grain, white Gaussian path (grain radius too small for a measurable lag-1 correlation,
 * clpost/stages/grain.py RHO_WHITE) as a pointwise stage fused with film and print: the pixel's
 * density is all it reads, so the frame is read and written once for all three. Width-generic
 * (clpost/codegen.py), after kernels/grain_pixel.cl; the same counters, normals and arithmetic as
 * the gather's white path (kernels/grain.cl), so the image is the same bit for bit.
 * params = [dmin0 dmin1 dmin2 dmax0 dmax1 dmax2].
 *
 * State (PointwiseStage.state): a float16 of Box-Muller draws is the normals of 32 consecutive
 * counters, cosines for the first 16 and sines for the next; the generated kernel runs 32 pixels
 * per work-item as two 16-pixel calls in order (x0 a multiple of 32, then x0 + 16), so the first
 * call draws and keeps the sines for the second: half a draw per pixel and layer. The one-pixel
 * form draws its counter's pair and keeps one branch. */
typedef struct { CLP_F hi[3]; } CLP_FN(grain_state);

inline CLP_F CLP_FN(grain_white)(const CLP_CTX p, CLP_FN(grain_state) *st, const uint c,
                                 const uint seed, const uint frame) {
#if CLP_W == 1
    (void)st;
    return CLP_FN(grain_normal)(seed, frame, p.x, p.y, c);
#else
    if ((p.x0 & 16) == 0)
        return CLP_FN(grain_block)(seed, frame, (uint)p.x0 >> 5, p.y, c, &st->hi[c]);
    return st->hi[c];
#endif
}

inline void grain_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, CLP_FN(grain_state) *st,
                        __global const float *params, __global const float *poly, const float inv_half_span,
                        const float amount, const uint seed, const uint frame) {
    *r = CLP_FN(grain_pixel)(*r, params[0], params[3], CLP_FN(grain_white)(p, st, 0u, seed, frame), poly,
                             inv_half_span, amount);
    *g = CLP_FN(grain_pixel)(*g, params[1], params[4], CLP_FN(grain_white)(p, st, 1u, seed, frame), poly,
                             inv_half_span, amount);
    *b = CLP_FN(grain_pixel)(*b, params[2], params[5], CLP_FN(grain_white)(p, st, 2u, seed, frame), poly,
                             inv_half_span, amount);
}
