/* visibility.h — what the visibility kernels share (docs/design.md §4.6): exact hard shadows
 * on surfaces, per camera sample and light 1 when the segment to the light is clear, else 0.
 * The shadow map decides where its neighbourhood is unanimous; the other samples cast a
 * shadow ray through the BVH, or in a frame of few samples against the triangles touching
 * their texel. The kernels, by family, each in its own file:
 *   visibility_bound.cl    the bound and writer maps a light's lit tests read
 *   visibility_prepare.cl  per sample and light: turned away, unlit, or the texel to test
 *   visibility.cl          the maps' decision of the entries prepare left pending
 *   visibility_rays.cl     the shadow rays of the entries the maps leave */
#ifndef CLRAYS_VISIBILITY_H
#define CLRAYS_VISIBILITY_H

#include "lighting.h"
#include "bvh.h"
#include "lanes.h"
#include "solids.h"

/* SURFACE_BIAS_TEXELS, the map test's depth tolerance, and SHADOW_RAY_OFFSET_REL, how far
 * a shadow ray leaves its surface, come from clrays/structs.py (-D). */
/* Bounds are shrunk by this relative margin against float32 rounding of the bound itself. */
#define BOUND_MARGIN_REL 1e-5f

/* VISIBILITY_PENDING (clrays/structs.py): visible's value, between visibility_prepare and
 * visibility, of a sample and light that the maps or a ray decide (never left in it). */
/* map_read's texel, between the two: the address of the texel of the bound and writer
 * maps that decides the lit test, or one of these. */
#define MAP_TEXEL_OUTSIDE -1 /* the point projects outside the map: lit (a map covers every occluder) */
#define MAP_TEXEL_NONE -2    /* behind a perspective view: a ray decides */

/* A launch the host enqueues before the device knows whether the frame needs it: it returns
 * at once unless visibility's route (VISIBILITY_ROUTE_*, clrays/structs.py; written by
 * visibility_route) is `wanted`; VISIBILITY_ROUTE_ANY runs whatever the route. */
#define ROUTE_ARGS global const int* route, int wanted
#define RETURN_UNLESS_ROUTED if (wanted != VISIBILITY_ROUTE_ANY && *route != wanted) return;

/* The run of a list of `count` items (a length the device alone knows) that this work-item
 * takes: the list split evenly over the launch (clrays.device.Device.list_launch). */
#define LIST_RUN(count, begin, end)                                                         \
    int begin, end;                                                                         \
    {                                                                                       \
        int items_ = get_global_size(0), per_item_ = (count) / items_ + ((count) % items_ != 0); \
        begin = get_global_id(0) * per_item_;                                               \
        end = min(begin + per_item_, (count));                                              \
    }

/* Unit direction of the view ray through pixel coordinates (px, py) of a perspective view. */
inline float3 view_direction(global const view_t* view, float px, float py)
{
    float sx = 2.0f * px / (float)view->width - 1.0f, sy = 1.0f - 2.0f * py / (float)view->height;
    return inline_normalize(view->forward.xyz + view->right.xyz * (sx * view->scale_x) + view->up.xyz * (sy * view->scale_y));
}

/* The writer map beside the bound map: per texel, the one convex part whose triangles
 * touch it (WRITER_NONE: none yet), or WRITER_MANY once a second one does (both from
 * clrays/structs.py). A sample whose texel's only writer is its own convex part is lit:
 * no other triangle comes near its segment to the light, which projects into that texel,
 * and the part lies wholly on the far side of the sample's plane from the light (the
 * sample's face turns towards it), which the segment leaves at the sample. A part is a
 * label per triangle, the bits in w of its second vertex row (clrays.inputs.vertex_rows):
 * a plane's, a box's or a sphere's triangles share one, any other triangle has its own
 * (Geometry.convex_part). So the seams of a floor's triangles and a box's edges leave
 * their texels to no other test. A box's or a sphere's label has CONVEX_OUTSIDE_ONLY:
 * the argument holds for a point of its outside, which its winding faces; seen from
 * inside (a room, a dome) the sample's face turns towards a light beyond the far wall,
 * which the same part blocks. */
ALWAYS_INLINE int convex_part_of(global const float4* tri_vertices, int tri)
{
    return as_int(tri_vertices[3 * tri + 1].w);
}

/* Whether light_incident is non-zero at p (any light arrives), and as it, the unit
 * direction from p towards the light. Its three exp() only where they could decide it:
 * inside a spot's cone, some channel with power ≥ 1e-6, σt·d ≤ 30 and d² ≤ 1e10 is
 * ≥ 1e-29 for sure, a normal float, so non-zero. */
ALWAYS_INLINE int light_reaches(global const light_t* light, float3 sigma_t, float3 p, float3* to_light)
{
    if (light->type != LIGHT_DIRECTIONAL) {
        float3 w = p - light->position.xyz;
        float d2 = inline_dot(w, w);
        float d = inline_sqrt(d2);
        *to_light = d > 0.0f ? -w / d : (float3)(0.0f, 1.0f, 0.0f);
        if (light->type == LIGHT_SPOT && inline_dot(w, light->direction.xyz) < light->cos_cone * d) return 0;
        float3 power = light->power.xyz, attenuation = sigma_t * d;
        if (d2 <= 1e10f && ((power.x >= 1e-6f && attenuation.x <= 30.0f) || (power.y >= 1e-6f && attenuation.y <= 30.0f)
                            || (power.z >= 1e-6f && attenuation.z <= 30.0f)))
            return 1;
    }
    float3 incident = light_incident(light, sigma_t, p, to_light);
    return incident.x + incident.y + incident.z != 0.0f;
}


/* light_view_index, then view_project (lighting.h) on each lane: the view of p, its
 * continuous texel coordinates and its depth there; the lanes where p is behind a
 * perspective view come back 0 (their texel and depth unused). */
ALWAYS_INLINE int_lanes light_project_lanes(global const view_t* views, global const light_t* light, float_lanes px,
                                            float_lanes py, float_lanes pz, view_lanes_t* v, float_lanes* texel_x,
                                            float_lanes* texel_y, float_lanes* depth)
{
    *v = views_of_lanes(views, light_view_index_lanes(light, px, py, pz));
    float_lanes qx = px - v->origin_x, qy = py - v->origin_y, qz = pz - v->origin_z;
    float_lanes x = dot_lanes_of_lanes(qx, qy, qz, v->right_x, v->right_y, v->right_z);
    float_lanes y = dot_lanes_of_lanes(qx, qy, qz, v->up_x, v->up_y, v->up_z);
    float_lanes z = dot_lanes_of_lanes(qx, qy, qz, v->forward_x, v->forward_y, v->forward_z);
    int perspective = views[light->first_view].projection == PROJECTION_PERSPECTIVE;
    *depth = perspective ? length_lanes(qx, qy, qz) : z;
    float_lanes screen_x = perspective ? x / (z * v->scale_x) : x / v->scale_x;
    float_lanes screen_y = perspective ? y / (z * v->scale_y) : y / v->scale_y;
    *texel_x = (screen_x + 1.0f) * 0.5f * float_of_lanes(v->width);
    *texel_y = (1.0f - screen_y) * 0.5f * float_of_lanes(v->height);
    return perspective ? !(z <= 0.0f) : (int_lanes)(-1);
}

#endif
