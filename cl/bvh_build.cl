/* bvh_build.cl — the visibility stage's BVH built on the device: Karras's radix tree over
 * sorted Morton keys, then its boxes refit bottom-up around the eye-space triangles.
 * Reads keys, order (host: clrays.bvh.sorted_morton_keys) and tri_vertices; writes
 * node_children, the parent links (leaf_parent by key, not triangle) and node_bounds in
 * the layout of clrays/bvh.py: the same tree, the same boxes or a rounding step wider
 * (docs/design.md §4.6). */
#include "common.h"

/* Leading bits keys a and b share (keys are unique, so < 64); -1 for b outside [0, n). */
inline int common_prefix(global const ulong* keys, int n, int a, int b)
{
    if (b < 0 || b >= n) return -1;
    return (int)clz(keys[a] ^ keys[b]);
}

/* One work-item per internal node i of n - 1 (Karras 2012, §4): the key range the node
 * covers, one end at i, and its split, as clrays.bvh.bvh_topology finds them. Leaves are
 * -(triangle + 1); node_parent[0] (the root) and nothing else is left to the host's -1. */
kernel void bvh_build_tree(global const ulong* keys, global const int* order, int n, global int2* node_children,
                           global int* node_parent, global int* leaf_parent)
{
    int i = get_global_id(0);
    if (i >= n - 1) return;
    /* Towards the neighbour sharing the longer prefix; the other one's prefix is the
     * least the range's keys share. */
    int direction = common_prefix(keys, n, i, i + 1) > common_prefix(keys, n, i, i - 1) ? 1 : -1;
    int prefix_min = common_prefix(keys, n, i, i - direction);
    int length_max = 2;
    while (common_prefix(keys, n, i, i + length_max * direction) > prefix_min) length_max *= 2;
    int length = 0;
    for (int step = length_max / 2; step >= 1; step /= 2)
        if (common_prefix(keys, n, i, i + (length + step) * direction) > prefix_min) length += step;
    int j = i + length * direction;
    /* The split: the last key sharing more leading bits with key i than key j does. */
    int prefix_node = common_prefix(keys, n, i, j);
    int split = 0;
    for (int divisor = 2;; divisor *= 2) {
        int step = (length + divisor - 1) / divisor;
        if (common_prefix(keys, n, i, i + (split + step) * direction) > prefix_node) split += step;
        if (step <= 1) break;
    }
    int gamma = i + split * direction + min(direction, 0);
    int first = min(i, j), last = max(i, j);
    int left, right;
    if (first == gamma) {
        left = -(order[gamma] + 1);
        leaf_parent[gamma] = i;
    } else {
        left = gamma;
        node_parent[gamma] = i;
    }
    if (last == gamma + 1) {
        right = -(order[gamma + 1] + 1);
        leaf_parent[gamma + 1] = i;
    } else {
        right = gamma + 1;
        node_parent[gamma + 1] = i;
    }
    node_children[i] = (int2)(left, right);
}

/* A child's box, padded: a triangle's from its float32 vertices, each side moved out by
 * `pad` and rounded outwards once more; a node's as the refit wrote it. Padding and
 * rounding are monotone, so a node's box, the union of its padded children's, is its
 * unpadded box padded: the boxes of clrays.bvh.refit_bvh (its pad rounded up to float32). */
inline void child_box(int child, global const float4* tri_vertices, float pad, volatile global float4* node_bounds,
                      float4* lo, float4* hi)
{
    if (child < 0) {
        int tri = -child - 1;
        float3 a = tri_vertices[3 * tri].xyz, b = tri_vertices[3 * tri + 1].xyz, c = tri_vertices[3 * tri + 2].xyz;
        *lo = (float4)(nextafter(fmin(fmin(a, b), c) - pad, (float3)(-INFINITY)), 0.0f);
        *hi = (float4)(nextafter(fmax(fmax(a, b), c) + pad, (float3)(INFINITY)), 0.0f);
    } else {
        *lo = node_bounds[2 * child];
        *hi = node_bounds[2 * child + 1];
    }
}

/* One work-item per leaf, in key order (neighbouring items share their nodes): up from
 * the leaf, the second of two siblings to arrive at a node (an atomic count per node,
 * zeroed by the host) boxes it and goes on; the first stops. Min and max are exact, so
 * the boxes are those of a refit in any order. */
kernel void bvh_build_refit(global const float4* tri_vertices, global const int2* node_children,
                            global const int* node_parent, global const int* leaf_parent, int n, float pad,
                            volatile global int* arrivals, volatile global float4* node_bounds)
{
    int leaf = get_global_id(0);
    if (leaf >= n) return;
    int node = leaf_parent[leaf];
    while (node >= 0) {
        /* This work-item's box (written last time round) before its arrival is counted. */
        mem_fence(CLK_GLOBAL_MEM_FENCE);
        if (atomic_inc(&arrivals[node]) == 0) return;
        mem_fence(CLK_GLOBAL_MEM_FENCE);
        int2 children = node_children[node];
        float4 left_lo, left_hi, right_lo, right_hi;
        child_box(children.x, tri_vertices, pad, node_bounds, &left_lo, &left_hi);
        child_box(children.y, tri_vertices, pad, node_bounds, &right_lo, &right_hi);
        node_bounds[2 * node] = fmin(left_lo, right_lo);
        node_bounds[2 * node + 1] = fmax(left_hi, right_hi);
        node = node_parent[node];
    }
}
