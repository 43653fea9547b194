/* bvh_build.cl — the visibility stage's BVH built on the device: Karras's radix tree over
 * sorted Morton keys, then its boxes refit bottom-up around the eye-space triangles.
 * Reads keys, order (host: clrays.bvh.sorted_morton_keys) and tri_vertices; writes
 * node_children and node_bounds in the layout of clrays/bvh.py (the same tree; the same
 * boxes or a rounding step wider: docs/design.md §4.6), and for the refit the tree by key
 * (node_keys, leaves as -(key + 1)), the parent links and the leaves' boxes by key. */
#include "common.h"

/* Leading bits keys a and b share (keys are unique, so < 64); -1 for b outside [0, n). */
inline int common_prefix(global const ulong* keys, int n, int a, int b)
{
    if (b < 0 || b >= n) return -1;
    return (int)clz(keys[a] ^ keys[b]);
}

/* One work-item per internal node i of n - 1 (Karras 2012, §4): the key range the node
 * covers, one end at i, and its split, as clrays.bvh.bvh_topology finds them. Leaves are
 * -(triangle + 1) in node_children, -(key + 1) in node_keys; node_parent[0] (the root)
 * and nothing else is left to the host's -1. */
kernel void bvh_build_tree(global const ulong* keys, global const int* order, int n, global int2* node_children,
                           global int2* node_keys, global int* node_parent, global int* leaf_parent)
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
    int left_is_leaf = min(i, j) == gamma, right_is_leaf = max(i, j) == gamma + 1;
    node_keys[i] = (int2)(left_is_leaf ? -(gamma + 1) : gamma, right_is_leaf ? -(gamma + 2) : gamma + 1);
    node_children[i] = (int2)(left_is_leaf ? -(order[gamma] + 1) : gamma,
                              right_is_leaf ? -(order[gamma + 1] + 1) : gamma + 1);
    if (left_is_leaf) leaf_parent[gamma] = i;
    else node_parent[gamma] = i;
    if (right_is_leaf) leaf_parent[gamma + 1] = i;
    else node_parent[gamma + 1] = i;
}

/* Each side moved out by `pad` and rounded outwards once more. Padding and rounding are
 * monotone, so a node's box, the union of its padded children's, is its unpadded box
 * padded: the boxes of clrays.bvh.refit_bvh (its pad rounded up to float32). */
inline float4 padded_lo(float3 lo, float pad) { return (float4)(nextafter(lo - pad, (float3)(-INFINITY)), 0.0f); }
inline float4 padded_hi(float3 hi, float pad) { return (float4)(nextafter(hi + pad, (float3)(INFINITY)), 0.0f); }

/* One work-item per key: the padded box of its triangle. A pass of its own, without the
 * refit's atomics, so that a CPU overlaps the scattered vertex reads. */
kernel void bvh_build_leaves(global const float4* tri_vertices, global const int* order, int n, float pad,
                             global float4* leaf_bounds)
{
    int leaf = get_global_id(0);
    if (leaf >= n) return;
    int tri = order[leaf];
    float3 a = tri_vertices[3 * tri].xyz, b = tri_vertices[3 * tri + 1].xyz, c = tri_vertices[3 * tri + 2].xyz;
    leaf_bounds[2 * leaf] = padded_lo(fmin(fmin(a, b), c), pad);
    leaf_bounds[2 * leaf + 1] = padded_hi(fmax(fmax(a, b), c), pad);
}

/* One work-item per key: up from its leaf, the second of two siblings to arrive at a
 * node (an atomic count per node, zeroed by the host) boxes it, from its own box and the
 * sibling's, and goes on; the first stops. Min and max are exact, so the boxes are those
 * of a refit in any order. The sibling's box may come from another work-group: OpenCL
 * 1.2 orders nothing between work-groups but atomics, so the box is written before a
 * fence and the count, and read through a volatile pointer after it, as Karras's and
 * Apetrei's builds do on GPUs (on a CPU device the caches are coherent anyway). */
kernel void bvh_build_refit(global const int2* node_keys, global const int* node_parent,
                            global const int* leaf_parent, global const float4* leaf_bounds, int n,
                            volatile global int* arrivals, volatile global float4* node_bounds)
{
    int leaf = get_global_id(0);
    if (leaf >= n) return;
    float4 lo = leaf_bounds[2 * leaf], hi = leaf_bounds[2 * leaf + 1];
    int child = -(leaf + 1);
    int node = leaf_parent[leaf];
    while (node >= 0) {
        /* This work-item's box (written last time round) before its arrival is counted. */
        mem_fence(CLK_GLOBAL_MEM_FENCE);
        if (atomic_inc(&arrivals[node]) == 0) return;
        mem_fence(CLK_GLOBAL_MEM_FENCE);
        int2 children = node_keys[node];
        int sibling = children.x == child ? children.y : children.x;
        if (sibling < 0) {
            lo = fmin(lo, leaf_bounds[2 * (-sibling - 1)]);
            hi = fmax(hi, leaf_bounds[2 * (-sibling - 1) + 1]);
        } else {
            lo = fmin(lo, node_bounds[2 * sibling]);
            hi = fmax(hi, node_bounds[2 * sibling + 1]);
        }
        node_bounds[2 * node] = lo;
        node_bounds[2 * node + 1] = hi;
        child = node;
        node = node_parent[node];
    }
}
