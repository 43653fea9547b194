/* fill — a buffer set to one 4- or 8-byte pattern, repeated in `pattern`, by every core
 * (Device.fill on a CPU device, where the driver's own fill runs on one thread). One
 * work-item per FILL_VECTORS vectors of 16 bytes; the host fills the tail past the last
 * whole vector. */
kernel void fill_vectors(global uint4* out, uint4 pattern, int vectors)
{
    int first = get_global_id(0) * FILL_VECTORS;
    int last = min(first + FILL_VECTORS, vectors);
    for (int i = first; i < last; ++i) out[i] = pattern;
}
