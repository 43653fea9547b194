/* shadow_filter — filtered surface shadows (render.shadow_filter, docs/design.md §9): per
 * camera sample and light, the lit fraction of a filter footprint around its shadow-map texel.
 * shadow_filter_moments reads shadow_depth; writes moments (float4 (z, z², z³, z⁴) per texel,
 *   z the depth normalised to the light's [near, far]).
 * shadow_filter_blur reads moments; writes one view's rows (axis 0) or columns (axis 1) box-blurred.
 * shadow_filter_visibility reads frame, views, lights, shadow_depth or the blurred moments,
 *   camera_depth, tri_id, tri_normal, offsets; writes visible (float per sample and light),
 *   which shade reads as it reads the visibility stage's.
 *
 *   a cube map's faces, unfolded around +z:      a texel past a face's edge is the texel of
 *            +-----+                             the neighbouring face that sees the same
 *            | +y  |                             direction (cube_texel), so the blur and PCF
 *      +-----+-----+-----+-----+                 run across the seams; a single view clamps
 *      | -x  | +z  | +x  | -z  |                 to its edge, as the map's own test does.
 *      +-----+-----+-----+-----+
 *            | -y  |
 *            +-----+                                                                        */
#include "lighting.h"
#include "moments.h"

#ifndef SHADOW_FILTER
#define SHADOW_FILTER SHADOW_FILTER_MSM_HAMBURGER
#endif

/* The receiver's slope is counted up to this (about 83°): beyond, its bias would lift
 * whole shadows off grazing surfaces. */
#define MAX_BIAS_SLOPE 8.0f

/* Index in the light's depth (or moment) atlas of texel (tx, ty) of `view`, which may lie
 * past the view's edges (docs/design.md §9, cube seams). A neighbouring face that raster
 * left empty (the frame reads none of it: view_needed 0) is not read; the texel clamps to
 * `view`'s edge instead, as on a single view. */
inline int cube_texel(global const light_t* light, global const view_t* views, global const int* view_needed,
                      global const view_t* view, int tx, int ty)
{
    if (light->view_count == 6 && (tx < 0 || ty < 0 || tx >= view->width || ty >= view->height)) {
        float sx = 2.0f * ((float)tx + 0.5f) / (float)view->width - 1.0f;
        float sy = 1.0f - 2.0f * ((float)ty + 0.5f) / (float)view->height;
        float3 p = view->origin.xyz + view->forward.xyz + sx * view->scale_x * view->right.xyz
                   + sy * view->scale_y * view->up.xyz;
        int neighbour = light_view_index(light, p);
        if (view_needed[neighbour]) {
            view = views + neighbour;
            float2 texel;
            float depth;
            view_project(view, p, &texel, &depth);
            tx = (int)floor(texel.x);
            ty = (int)floor(texel.y);
        }
    }
    tx = clamp(tx, 0, view->width - 1);
    ty = clamp(ty, 0, view->height - 1);
    return view->depth_offset + ty * view->width + tx;
}

/* The moment vector of one texel of one light. Empty texels (nothing rasterized) sit at
 * the far end, z = 1, behind every receiver. */
kernel void shadow_filter_moments(global const uint* shadow_depth, int first_texel, int texels, float near,
                                  float inverse_range, global float4* moments)
{
    int i = get_global_id(0);
    if (i >= texels) return;
    float depth = as_float(shadow_depth[first_texel + i]);
    float z = isinf(depth) ? 1.0f : clamp((depth - near) * inverse_range, 0.0f, 1.0f);
    float z2 = z * z;
    moments[first_texel + i] = (float4)(z, z2, z2 * z, z2 * z2);
}

/* One pass of the separable (2·radius + 1)-texel box blur over one view of a light. */
kernel void shadow_filter_blur(global const view_t* views, global const light_t* lights,
                               global const int* view_needed, int light_index, int view_index, int radius, int axis,
                               global const float4* source, global float4* target)
{
    global const light_t* light = lights + light_index;
    global const view_t* view = views + view_index;
    int i = get_global_id(0);
    if (i >= view->width * view->height) return;
    int tx = i % view->width, ty = i / view->width;
    int step = axis == 0 ? 1 : view->width;
    int along = axis == 0 ? tx : ty, extent = axis == 0 ? view->width : view->height;
    float4 sum = (float4)(0.0f);
    if (along >= radius && along + radius < extent) { /* inside the view: no seam, no clamp */
        global const float4* centre = source + view->depth_offset + i;
        for (int k = -radius; k <= radius; ++k) sum += centre[k * step];
    } else {
        for (int k = -radius; k <= radius; ++k)
            sum += source[cube_texel(light, views, view_needed, view, tx + (axis == 0 ? k : 0),
                                     ty + (axis == 1 ? k : 0))];
    }
    target[view->depth_offset + i] = sum / (float)(2 * radius + 1);
}

/* The reconstruction SHADOW_FILTER of one filtered moment vector. */
inline float moment_visibility(float4 moments, float z, float moment_bias)
{
#if SHADOW_FILTER == SHADOW_FILTER_VSM
    return vsm_visibility(moments, z, moment_bias);
#elif SHADOW_FILTER == SHADOW_FILTER_MSM_HAUSDORFF
    return msm_hausdorff_visibility(moments, z, moment_bias);
#else
    return msm_hamburger_visibility(moments, z, moment_bias);
#endif
}

/* The reconstruction alone, on given moments and normalised depths (the tests' entry). */
kernel void shadow_filter_reconstruct(global const float4* moments, global const float* depth, int count,
                                      float moment_bias, global float* visible)
{
    int i = get_global_id(0);
    if (i < count) visible[i] = moment_visibility(moments[i], depth[i], moment_bias);
}

/* The lit fraction of p for one light: 1 outside its map, as the map's own test. `slope`
 * is tan of the angle between the receiver's normal and the light: across a footprint of
 * `radius` texels the receiver's own depth moves by up to radius·slope texels, which the
 * tolerance takes in, or a sloped receiver would shadow itself (docs/design.md §9, bias). */
inline float filtered_visibility(global const light_t* light, global const view_t* views,
                                 global const int* view_needed,
                                 global const uint* shadow_depth, global const float4* moments, float2 depth_range,
                                 float3 p, float slope, int radius, float depth_bias, float moment_bias)
{
#if SHADOW_FILTER == SHADOW_FILTER_HARD
    return shadow_visibility(light, views, shadow_depth, p, depth_bias, 0);
#else
    global const view_t* view = views + light_view_index(light, p);
    float2 texel;
    float depth;
    if (!view_project(view, p, &texel, &depth)) return 1.0f;
    if (texel.x < 0.0f || texel.y < 0.0f || texel.x >= (float)view->width || texel.y >= (float)view->height)
        return 1.0f;
    float tolerance = (depth_bias + (float)radius * slope) * shadow_texel_size(light, depth);
    int tx = (int)texel.x, ty = (int)texel.y;
#if SHADOW_FILTER == SHADOW_FILTER_PCF
    float lit = 0.0f;
    for (int j = -radius; j <= radius; ++j)
        for (int i = -radius; i <= radius; ++i) {
            float blocker = as_float(shadow_depth[cube_texel(light, views, view_needed, view, tx + i, ty + j)]);
            lit += depth <= blocker + tolerance ? 1.0f : 0.0f;
        }
    return lit / (float)((2 * radius + 1) * (2 * radius + 1));
#else
    /* The blurred map holds the box mean of the moments around this texel: the same
     * footprint PCF averages its tests over. */
    float z = (depth - tolerance - depth_range.x) * depth_range.y;
    return moment_visibility(moments[view->depth_offset + ty * view->width + tx], z, moment_bias);
#endif
#endif
}

kernel void shadow_filter_visibility(global const frame_t* frame, global const view_t* views,
                                     global const int* view_needed, global const light_t* lights,
                                     global const uint* shadow_depth,
                                     global const float4* moments, global const float2* depth_range,
                                     global const uint* camera_depth, global const int* tri_id,
                                     global const float4* tri_normal, global const float2* offsets, int radius,
                                     float depth_bias, float moment_bias, global float* visible)
{
    int sample = get_global_id(0);
    if (sample >= frame->width * frame->height * frame->spp) return;
    global float* out = visible + sample * frame->light_count;
    for (int l = 0; l < frame->light_count; ++l) out[l] = 1.0f;
    float3 p, dir, n;
    if (!camera_surface_point(frame, views, camera_depth, tri_id, tri_normal, offsets, sample, &p, &dir, &n)) return;
    for (int l = 0; l < frame->light_count; ++l) {
        global const light_t* light = lights + l;
        if (eye_in_lamp(light, frame->lamp_radius)) continue;
        float3 to_light;
        light_incident(light, frame->sigma_t.xyz, p, &to_light);
        float cosine = fabs(dot(n, to_light));
        float slope = fmin(sqrt(fmax(1.0f - cosine * cosine, 0.0f)) / cosine, MAX_BIAS_SLOPE);
        /* The normal offset by a texel of shade's own map test. */
        float3 lookup = shadow_lookup(light, p, n);
        out[l] = filtered_visibility(light, views, view_needed, shadow_depth, moments, depth_range[l], lookup, slope,
                                     radius, depth_bias, moment_bias);
    }
}
