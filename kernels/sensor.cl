/* sensor: normalised signal -> raw digital recording (shot noise, full well, read noise, ISO gain,
 * black level, quantisation), renormalised so 1.0 = clipping. Formulas: clpost/stages/sensor.py.
 * Random numbers: counter (seed, frame, pixel, 4*channel + k), kernels/random.cl.
 */
#define SENSOR_POISSON_EXACT_MAX 32.0f

/* The read-noise normal has its own counter; its second uniform is a re-mix of the first hash
 * (a constant XOR alone would leave the two normals correlated). */
inline float sensor_read_normal(const uint h3) {
    return rnd_normal(h3, rnd_mix(h3 ^ 0x5bd1e995u));
}

inline float sensor_channel(const float s, const uint ch, const PixelCtx p, const float e_sat,
                            const float full_well, const float read_noise, const float black,
                            const float white, const uint seed, const uint frame) {
    const uint i = (uint)p.i;
    const float mean = fmin(fmax(s, 0.0f) * e_sat, 2.0f * full_well);
    const uint h2 = rnd_hash4(seed, frame, i, 4u * ch + 2u);
    float e;
    if (mean > SENSOR_POISSON_EXACT_MAX) {
        const float g = rnd_normal(rnd_hash4(seed, frame, i, 4u * ch + 1u), h2);
        e = fmax(rint(mean + sqrt(mean) * g), 0.0f);
    } else {
        e = rnd_poisson_inversion(mean, rnd_uniform(rnd_hash4(seed, frame, i, 4u * ch)));
    }
    e = fmin(e, full_well) + read_noise * sensor_read_normal(rnd_hash4(seed, frame, i, 4u * ch + 3u));
    const float dn = clamp(rint(black + e * ((white - black) / e_sat)), 0.0f, white);
    return (dn - black) / (white - black);
}

inline float3 sensor_apply(const float3 c, const PixelCtx p, const float e_sat, const float full_well,
                           const float read_noise, const float black, const float white,
                           const uint seed, const uint frame) {
    return (float3)(sensor_channel(c.x, 0u, p, e_sat, full_well, read_noise, black, white, seed, frame),
                    sensor_channel(c.y, 1u, p, e_sat, full_well, read_noise, black, white, seed, frame),
                    sensor_channel(c.z, 2u, p, e_sat, full_well, read_noise, black, white, seed, frame));
}
