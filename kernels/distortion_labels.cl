/* distortion_labels: the distorted image's label planes (ids, segmentation, normals, any AOV),
 * never blended. numpy oracle: clpost.labels.channels.nearest_labels.
 *
 * Output pixel i of plane l takes the 32-bit word of the source pixel nearest to its source
 * position (flat[i], the same index table distortion_aux uses for depth; -1: no preimage ->
 * LABEL_FILL = 0). Words are copied, not converted: float, int32 and uint32 planes (and
 * Cryptomatte's float-coded hashes) come out bit for bit.
 *
 * Buffers: src (planes, n_src words each), dst (planes, n words each), flat (n ints).
 * Global size (n rounded up to the work-group, planes); hence the guard. */
__kernel void distortion_labels(__global const uint *restrict src, __global uint *restrict dst,
                                __global const int *restrict flat, const int n, const int n_src)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const size_t l = get_global_id(1);
    const int s = flat[i];
    dst[l * (size_t)n + i] = s < 0 ? 0u : src[l * (size_t)n_src + s];
}
