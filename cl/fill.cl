/* fill — a buffer set to one 4- or 8-byte pattern, repeated in `pattern`, by every core
 * (Device.fill on a CPU device, where the driver's own fill runs on one thread). One
 * work-item per FILL_VECTORS vectors of 16 bytes; the host fills the tail past the last
 * whole vector.
 *
 * The stores are non-temporal where the compiler has them: a frame's cube map (25 MB at
 * 1280×720) is far larger than a core's cache, so a plain store would first read each line
 * it writes. The fill took 0.36–0.54 of its time, and the raster passes that then read the
 * map lost less than that (docs/design.md §4.5, "Cost on PoCL"). */
#if defined(__has_builtin)
#if __has_builtin(__builtin_nontemporal_store)
#define STREAM_STORE(value, pointer) __builtin_nontemporal_store(value, pointer)
#endif
#endif
#ifndef STREAM_STORE
#define STREAM_STORE(value, pointer) (*(pointer) = (value))
#endif
/* Streaming stores are weakly ordered on x86: a fence after them, before the kernels that
 * read the buffer next (with atomics, on other cores) can see it. */
#define STREAM_FENCE()
#if defined(__has_builtin)
#if __has_builtin(__builtin_nontemporal_store) && __has_builtin(__builtin_ia32_sfence)
#undef STREAM_FENCE
#define STREAM_FENCE() __builtin_ia32_sfence()
#endif
#endif

kernel void fill_vectors(global uint4* out, uint4 pattern, int vectors)
{
    int first = get_global_id(0) * FILL_VECTORS;
    int last = min(first + FILL_VECTORS, vectors);
    for (int i = first; i < last; ++i) STREAM_STORE(pattern, out + i);
    STREAM_FENCE();
}
