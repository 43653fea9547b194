/* traverse — in-scattered radiance per camera sample, `render.sampling: pixel`: walk
 * the min-max tree rows of the two slices nearest the sample's α over its γ extent,
 * integrate the lit runs with the integrand tables, blend the two slices
 * (docs/design.md §4.5 "traverse"; the walk itself is in walk.h).
 * Reads frame, views, lights, epipolar, tree, integrand, tables, camera_depth, offsets,
 * and the walk's features (walk_features.h: a light texture, translucent layers); adds
 * into scatter (float4 per camera sample). */
#include "walk.h"

NOT_ACROSS_WORK_ITEMS
kernel void traverse(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                     global const epipolar_t* epipolar, global const float2* tree,
                     global const integrand_t* integrand, global const float* tables,
                     global const uint* camera_depth, global const float2* offsets,
                     global float4* scatter WALK_FEATURE_ARGS)
{
    int sample = get_global_id(0);
    if (sample >= frame->width * frame->height * frame->spp) return;
    global const epipolar_t* ep = epipolar;
    float3 dir = camera_ray(frame, views, offsets, sample);
    float distance = fmin(as_float(camera_depth[sample]), frame->far);
    ray_span_t span;
    if (!ray_span(ep, lights + ep->light_index, frame, integrand, dir, distance, &span)) return;
    int i0, i1;
    float t;
    nearest_slices(ep, dir, &i0, &i1, &t);
    walk_features_t features;
    ATTACH_WALK_FEATURES(features) /* a light texture, translucent layers (walk_features.h) */
    float3 near0 = row_radiance(ep, tree, i0, &span, integrand, tables, frame, &features);
    float3 near1 = row_radiance(ep, tree, i1, &span, integrand, tables, frame, &features);
    scatter[sample] += (float4)(mix(near0, near1, t), 0.0f);
}
