/* bvh.h — shadow rays against the scene's BVH (layout: clrays/bvh.py): is the segment
 * from a point to a light blocked by any triangle? Any hit ends the walk.
 * Reads node_bounds (lo, hi float4 per internal node), node_children (int2 per node:
 * ≥ 0 a node, < 0 the leaf of triangle -(child + 1)) and tri_vertices. */
#ifndef CLRAYS_BVH_H
#define CLRAYS_BVH_H
#include "common.h"
#include "inline_math.h"

/* Deep enough for any LBVH of 30-bit Morton codes plus 32 tie-break bits. */
#define BVH_STACK 96

/* Whether the ray origin + t·dir, t ∈ [0, t_max], meets the box [lo, hi]
 * (inv_dir = 1/dir, ±inf on a zero component). */
inline int ray_meets_box(float3 origin, float3 inv_dir, float t_max, float4 lo, float4 hi)
{
    float3 t0 = (lo.xyz - origin) * inv_dir, t1 = (hi.xyz - origin) * inv_dir;
    /* fmax/fmin drop a NaN (origin on a slab of a flat box with dir parallel to it); written
     * out (inline_math.h), as the library's are calls in the walk's innermost loop. */
    float near_x = inline_fmin(t0.x, t1.x), near_y = inline_fmin(t0.y, t1.y), near_z = inline_fmin(t0.z, t1.z);
    float far_x = inline_fmax(t0.x, t1.x), far_y = inline_fmax(t0.y, t1.y), far_z = inline_fmax(t0.z, t1.z);
    float near = inline_fmax(inline_fmax(near_x, near_y), inline_fmax(near_z, 0.0f));
    float far = inline_fmin(inline_fmin(far_x, far_y), inline_fmin(far_z, t_max));
    return near <= far;
}

/* Möller–Trumbore, two-sided, edges inclusive: whether the ray meets the triangle at
 * t ∈ (t_min, t_max). */
inline int ray_meets_triangle(float3 origin, float3 dir, float t_min, float t_max, float3 v0, float3 v1, float3 v2)
{
    float3 e1 = v1 - v0, e2 = v2 - v0;
    float3 pv = cross(dir, e2);
    float det = dot(e1, pv);
    if (det == 0.0f) return 0;
    float inv = 1.0f / det;
    float3 tv = origin - v0;
    float u = dot(tv, pv) * inv;
    if (u < 0.0f || u > 1.0f) return 0;
    float3 qv = cross(tv, e1);
    float v = dot(dir, qv) * inv;
    if (v < 0.0f || u + v > 1.0f) return 0;
    float t = dot(e2, qv) * inv;
    return t > t_min && t < t_max;
}

/* Whether any triangle but `skip` (the surface the ray leaves; -1: none) crosses
 * origin + t·dir, t ∈ (t_min, t_max). root: 0, or the single leaf of a one-triangle scene. */
inline int bvh_occluded(global const float4* node_bounds, global const int2* node_children, int root,
                        global const float4* tri_vertices, float3 origin, float3 dir, float t_min, float t_max,
                        int skip)
{
    float3 inv_dir = 1.0f / dir;
    int stack[BVH_STACK];
    int top = 0;
    stack[top++] = root;
    while (top > 0) {
        int node = stack[--top];
        if (node < 0) {
            int tri = -node - 1;
            if (tri != skip
                && ray_meets_triangle(origin, dir, t_min, t_max, tri_vertices[3 * tri].xyz,
                                      tri_vertices[3 * tri + 1].xyz, tri_vertices[3 * tri + 2].xyz))
                return 1;
            continue;
        }
        if (!ray_meets_box(origin, inv_dir, t_max, node_bounds[2 * node], node_bounds[2 * node + 1])) continue;
        int2 children = node_children[node];
        if (top + 2 > BVH_STACK) return 1; /* cannot happen for an LBVH; blocked is the safe answer */
        stack[top++] = children.y;
        stack[top++] = children.x;
    }
    return 0;
}

#endif
