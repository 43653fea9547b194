/* minmax — one level of the 1D min-max mipmap of every rectified row, by parallel
 * reduction: node i of level k is (min, max) of nodes 2i and 2i + 1 of level k - 1.
 * Reads epipolar; reads and writes tree (layout in minmax.h); one launch per level. */
#include "common.h"
#include "minmax.h"

kernel void minmax_reduce(global const epipolar_t* epipolar, int level, global float2* tree)
{
    int node = get_global_id(0), slice = get_global_id(1);
    int n = epipolar->gamma_samples;
    if (node >= (n >> level) || slice >= epipolar->slices) return;
    global float2* row = tree + (size_t)slice * 2 * n;
    float2 a = row[level_offset(n, level - 1) + 2 * node];
    float2 b = row[level_offset(n, level - 1) + 2 * node + 1];
    row[level_offset(n, level) + node] = (float2)(fmin(a.x, b.x), fmax(a.y, b.y));
}
