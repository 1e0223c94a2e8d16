/* vignetting_plane: the relative-illumination plane the vignetting kernel multiplies by, built on
 * the device when the RI curve changes (a focus pull moves the exit pupil: every frame), so the
 * host's per-frame work is the LUT, not a pass over the pixels (clpost/stages/vignetting.py,
 * Vignetting.values; its host form, Vignetting.ri_plane, is what tests compare it with).
 *
 * plane[i] = the LUT interpolated linearly at radius[i] (the pixel's image height in mm, uploaded
 * once per principal point and size), lut sampled uniformly on [0, r_max]: position
 * t = radius * (n - 1) / r_max, clamped to the table's ends as numpy.interp does.
 */
__kernel void vignetting_plane(__global const float *lut, __global const float *radius,
                               __global float *plane, const int count, const int n, const float scale) {
    const int i = get_global_id(0);
    if (i >= count) return;
    const float t = clamp(radius[i] * scale, 0.0f, (float)(n - 1));
    const int k = min((int)t, n - 2);
    const float f = t - (float)k;
    plane[i] = fma(f, lut[k + 1] - lut[k], lut[k]);
}
