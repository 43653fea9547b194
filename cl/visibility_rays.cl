/* visibility_rays — the shadow rays of the entries the maps leave (visibility.h).
 * visibility_rays reads ray_entries, ray_count, tri_vertices, node_bounds, node_children,
 * and visibility_rays_listed those, map_read and a light's lists of the triangles touching
 * each texel; both write their visible from a shadow ray. */
#include "visibility.h"

/* A listed entry's shadow ray: from the point moved off the surface on the light's side,
 * to the light (t in (0, t_max)); its sample's own triangle is skipped. */
inline void listed_shadow_ray(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                              global const uint* camera_depth, global const int* tri_id,
                              global const float4* tri_normal, global const float2* offsets, int entry,
                              float3* start, float3* ray, float* t_max)
{
    int sample = entry / frame->light_count;
    global const light_t* light = lights + entry % frame->light_count;
    float3 p, dir, n;
    camera_surface_point(frame, views, camera_depth, tri_id, tri_normal, offsets, sample, &p, &dir, &n);
    float3 to_light;
    light_reaches(light, frame->sigma_t.xyz, p, &to_light);
    *start = shadow_ray_start(light, p, n, to_light);
    *ray = light->type == LIGHT_DIRECTIONAL ? to_light : light->position.xyz - *start;
    *t_max = light->type == LIGHT_DIRECTIONAL ? INFINITY : 1.0f;
}

/* The shadow rays of the entries visibility listed, through the BVH: the list's length
 * (ray_count[0]) read here, each work-item a run of it (LIST_RUN), and nothing done unless
 * the route is the BVH's (ROUTE_ARGS; VISIBILITY_ROUTE_ANY where the host has read it).
 * Each entry's answer depends on it alone, so the list's order (atomics) changes nothing. */
kernel void visibility_rays(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                            global const uint* camera_depth, global const int* tri_id,
                            global const float4* tri_vertices, global const float4* tri_normal,
                            global const float2* offsets, global const float4* node_bounds,
                            global const int2* node_children, int root, global const int* ray_entries,
                            global const int* ray_count, global float* visible, ROUTE_ARGS)
{
    RETURN_UNLESS_ROUTED
    LIST_RUN(ray_count[0], begin, end)
    for (int item = begin; item < end; ++item) {
        int entry = ray_entries[item];
        float3 start, ray;
        float t_max;
        listed_shadow_ray(frame, views, lights, camera_depth, tri_id, tri_normal, offsets, entry, &start, &ray,
                          &t_max);
        visible[entry] = bvh_occluded(node_bounds, node_children, root, tri_vertices, start, ray, 0.0f, t_max,
                                      tri_id[entry / frame->light_count]) ? 0.0f : 1.0f;
    }
}

/* The same rays of one light's entries (`light`), each against the triangles that touch
 * its texel (note_touching: the light's lists, texel addresses less `first`, the frame's
 * address of the light's texel 0) instead of the BVH's: the same triangles that can meet
 * the segment, tested by the same ray test, so the same answer (docs/design.md §4.6).
 * Enqueued before the device knows the route (ROUTE_ARGS) or the entries' count
 * (ray_count[0], read here; each work-item takes a run of the entries). */
kernel void visibility_rays_listed(global const frame_t* frame, global const view_t* views,
                                   global const light_t* lights, global const uint* camera_depth,
                                   global const int* tri_id, global const float4* tri_vertices,
                                   global const float4* tri_normal, global const float2* offsets,
                                   global const int2* map_read, int light, int first,
                                   global const int* touching_head, global const int2* touching,
                                   global const int* ray_entries, global const int* ray_count, global float* visible,
                                   ROUTE_ARGS)
{
    RETURN_UNLESS_ROUTED
    LIST_RUN(ray_count[0], begin, end)
    for (int item = begin; item < end; ++item) {
        int entry = ray_entries[item];
        if (entry % frame->light_count != light) continue;
        float3 start, ray;
        float t_max;
        listed_shadow_ray(frame, views, lights, camera_depth, tri_id, tri_normal, offsets, entry, &start, &ray,
                          &t_max);
        int skip = tri_id[entry / frame->light_count], occluded = 0;
        test_ray_t tested = test_ray(start, ray);
        for (int node = touching_head[map_read[entry].x - first]; node >= 0 && !occluded; node = touching[node].y) {
            int tri = touching[node].x;
            occluded = tri != skip && ray_meets_triangle(&tested, 0.0f, t_max, tri_vertices[3 * tri].xyz,
                                                         tri_vertices[3 * tri + 1].xyz, tri_vertices[3 * tri + 2].xyz);
        }
        visible[entry] = occluded ? 0.0f : 1.0f;
    }
}
