/* shaft_edges — each triangle's side towards one light, for the walks that follow a
 * blocker's surface to its silhouette (shaft_edges.h, surface_turns).
 * Reads epipolar_t (the light: at d_el along the axis from the eye, or the axis itself for
 * a directional light), the frame's triangles (eye space) and their edges' windings;
 * writes sides[t] = windings[t] | FACES_LIGHT where (v1 − v0) × (v2 − v0) points to the
 * light's side of the triangle's plane. */
#include "common.h"
#include "inline_math.h"
#include "walk_features.h"

kernel void shaft_edge_sides(global const epipolar_t* ep, global const float4* vertices, int count,
                             global const uchar* windings, global uchar* sides)
{
    int tri = get_global_id(0);
    if (tri >= count) return;
    float3 v0 = vertices[3 * tri].xyz, v1 = vertices[3 * tri + 1].xyz, v2 = vertices[3 * tri + 2].xyz;
    float3 normal = inline_cross(v1 - v0, v2 - v0);
    float3 to_light = ep->d_el == 0.0f ? ep->axis.xyz : ep->d_el * ep->axis.xyz - v0;
    sides[tri] = windings[tri] | (inline_dot(normal, to_light) > 0.0f ? FACES_LIGHT : 0u);
}
