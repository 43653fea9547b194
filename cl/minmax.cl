/* minmax — the 1D min-max mipmap of every rectified row: node i of level k is (min, max)
 * of nodes 2i and 2i + 1 of level k - 1. Reads epipolar; reads and writes tree (layout in
 * minmax.h); one launch for all levels. */
#include "common.h"
#include "inline_math.h"
#include "minmax.h"

/* One work-item per slice builds its row's levels 1..L in order: a row (2N float2, 16 KiB at
 * N = 1024) stays in cache from one level to the next, where a launch per level paid L
 * launches and a work-item per node, each calling PoCL's fmin and fmax (docs/design.md §4.5). */
kernel void minmax_reduce(global const epipolar_t* epipolar, global float2* tree)
{
    int slice = get_global_id(0);
    int n = epipolar->gamma_samples, levels = epipolar->levels;
    if (slice >= epipolar->slices) return;
    global float2* row = tree + (size_t)slice * 2 * n;
    for (int level = 1; level <= levels; ++level) {
        global const float2* below = row + level_offset(n, level - 1);
        global float2* here = row + level_offset(n, level);
        for (int node = 0; node < (n >> level); ++node) {
            float2 a = below[2 * node], b = below[2 * node + 1];
            here[node] = (float2)(inline_fmin(a.x, b.x), inline_fmax(a.y, b.y));
        }
    }
}
