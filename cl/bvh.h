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

/* A ray set up for the watertight triangle test (Woop, Benthin and Wald, "Watertight
 * Ray/Triangle Intersection", JCGT 2013): its direction's largest component names the
 * test's z axis, and a shear takes the ray to that axis, so each edge of a triangle is
 * tested in 2D by an edge function of its two ends alone. */
typedef struct {
    float3 origin;
    int axis;       /* the largest |component| of the direction: 0, 1 or 2 */
    float shear_x;  /* the direction's other two components over that one, */
    float shear_y;  /* in the rotated order (ray_axes) */
    float scale_z;  /* 1 over that component: t along origin + t·dir */
} test_ray_t;

/* v's components in the ray's rotated order, the test's z last. */
ALWAYS_INLINE float3 ray_axes(float3 v, int axis)
{
    return axis == 0 ? v.yzx : (axis == 1 ? v.zxy : v);
}

ALWAYS_INLINE test_ray_t test_ray(float3 origin, float3 dir)
{
    float3 size = (float3)(inline_fabs(dir.x), inline_fabs(dir.y), inline_fabs(dir.z));
    test_ray_t ray;
    ray.origin = origin;
    ray.axis = size.x > size.y ? (size.x > size.z ? 0 : 2) : (size.y > size.z ? 1 : 2);
    float3 d = ray_axes(dir, ray.axis);
    ray.shear_x = d.x / d.z;
    ray.shear_y = d.y / d.z;
    ray.scale_z = 1.0f / d.z;
    return ray;
}

/* Whether the ray meets the triangle at t ∈ (t_min, t_max), either side, edges inclusive.
 * Each edge function is computed from the edge's two ends alone, unfused, so two triangles
 * that share an edge compute it alike (one the other's negative): a ray through the edge
 * meets one of them or both, never neither. Möller–Trumbore's barycentrics, each from a
 * whole triangle, let a ray slip between two: one floor pixel of the bunny at 1280×720 saw
 * its spot through the shared edge of two of the mesh's faces towards the light, the faces
 * away from it left out of the texel's list (visibility_rays_listed; docs/design.md §4.6). */
inline int ray_meets_triangle(const test_ray_t* ray, float t_min, float t_max, float3 v0, float3 v1, float3 v2)
{
#pragma OPENCL FP_CONTRACT OFF
    float3 a = ray_axes(v0 - ray->origin, ray->axis), b = ray_axes(v1 - ray->origin, ray->axis),
           c = ray_axes(v2 - ray->origin, ray->axis);
    float ax = a.x - ray->shear_x * a.z, ay = a.y - ray->shear_y * a.z;
    float bx = b.x - ray->shear_x * b.z, by = b.y - ray->shear_y * b.z;
    float cx = c.x - ray->shear_x * c.z, cy = c.y - ray->shear_y * c.z;
    float u = cx * by - cy * bx, v = ax * cy - ay * cx, w = bx * ay - by * ax;
    if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return 0;
    float det = u + v + w;
    if (det == 0.0f) return 0;
    float t = ((u * a.z + v * b.z) + w * c.z) * ray->scale_z / det;
    return t > t_min && t < t_max;
}

/* Whether any triangle but `skip` (the surface the ray leaves; -1: none) crosses
 * origin + t·dir, t ∈ (t_min, t_max). root: 0, or the single leaf of a one-triangle scene. */
inline int bvh_occluded(global const float4* node_bounds, global const int2* node_children, int root,
                        global const float4* tri_vertices, float3 origin, float3 dir, float t_min, float t_max,
                        int skip)
{
    float3 inv_dir = 1.0f / dir;
    test_ray_t ray = test_ray(origin, dir);
    int stack[BVH_STACK];
    int top = 0;
    stack[top++] = root;
    while (top > 0) {
        int node = stack[--top];
        if (node < 0) {
            int tri = -node - 1;
            if (tri != skip
                && ray_meets_triangle(&ray, t_min, t_max, tri_vertices[3 * tri].xyz, tri_vertices[3 * tri + 1].xyz,
                                      tri_vertices[3 * tri + 2].xyz))
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
