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

/* Chebyshev's one-sided bound (VSM): the lit fraction is at most σ² / (σ² + (z − μ)²). */
inline float vsm_visibility(float4 b, float z, float min_variance)
{
    float variance = fmax(b.y - b.x * b.x, min_variance);
    float excess = z - b.x;
    return excess <= 0.0f ? 1.0f : variance / (variance + excess * excess);
}

/* Weight at z of the three-point distribution on {z, other1, other2} with moments (1, b.x, b.y):
 * E[ℓ(X)], ℓ the Lagrange polynomial that is 1 at z and 0 at the others. */
inline float three_point_weight(float4 b, float z, float other1, float other2)
{
    return (b.y - (other1 + other2) * b.x + other1 * other2) / ((z - other1) * (z - other2));
}

/* The other two support points z1 ≤ z2 of the distribution with moments (1, b) that has a
 * point at z: the roots of c0 + c1·x + c2·x², B·c = (1, z, z²), B the Hankel matrix of
 * (1, b1, b2 | b1, b2, b3 | b2, b3, b4) through its L·D·Lᵀ factors (docs/design.md §9). */
inline void three_point_support(float4 b, float z, float* z1, float* z2)
{
    float d11 = b.y - b.x * b.x;
    float l21 = (b.z - b.x * b.y) / d11;
    float d22 = (b.w - b.y * b.y) - l21 * l21 * d11;
    float y1 = z - b.x;
    float y2 = z * z - b.y - l21 * y1;
    float c2 = y2 / d22;
    float c1 = y1 / d11 - l21 * c2;
    float c0 = 1.0f - b.x * c1 - b.y * c2;
    float half_p = c1 / (2.0f * c2), q = c0 / c2;
    float root = sqrt(fmax(half_p * half_p - q, 0.0f));
    *z1 = -half_p - root;
    *z2 = -half_p + root;
}

/* Shadow of the three-point support: the weight of its points nearer than z. */
inline float three_point_shadow(float4 b, float z, float z1, float z2)
{
    if (z <= z1) return 0.0f;
    if (z <= z2) return three_point_weight(b, z1, z, z2);
    return 1.0f - three_point_weight(b, z, z1, z2);
}

/* The moments pulled towards those of depth 0.5 (the moment bias, docs/design.md §9). */
inline float4 biased_moments(float4 b, float moment_bias)
{
    return mix(b, (float4)(0.5f), moment_bias);
}

/* 4MSM on ℝ: 1 − the sharpest lower bound of the shadow P(depth < z). */
inline float msm_hamburger_visibility(float4 moments, float z, float moment_bias)
{
    float4 b = biased_moments(moments, moment_bias);
    float z1, z2;
    three_point_support(b, z, &z1, &z2);
    return 1.0f - clamp(three_point_shadow(b, z, z1, z2), 0.0f, 1.0f);
}

/* 4MSM on [0, 1]: as on ℝ while the support stays in [0, 1], else the four-point support
 * {0, z, z_free, 1} whose moments match (E[X(X − 1)(X − z)(X − z_free)] = 0). */
inline float msm_hausdorff_visibility(float4 moments, float z, float moment_bias)
{
    float4 b = biased_moments(moments, moment_bias);
    float z1, z2;
    three_point_support(b, z, &z1, &z2);
    float shadow;
    if (z1 >= 0.0f && z2 <= 1.0f) {
        shadow = three_point_shadow(b, z, z1, z2);
    } else {
        float z_free = (b.w - b.z - z * (b.z - b.y)) / (b.z - b.y - z * (b.y - b.x));
        /* Weights at 0 and at z_free of the distribution on {0, z, z_free, 1}: E[ℓ(X)]. */
        float at_zero = (b.z - (1.0f + z + z_free) * b.y + (z + z_free + z * z_free) * b.x - z * z_free)
                        / (-z * z_free);
        float at_free = (b.z - (1.0f + z) * b.y + z * b.x) / (z_free * (z_free - 1.0f) * (z_free - z));
        shadow = at_zero + (z_free < z ? at_free : 0.0f);
    }
    return 1.0f - clamp(shadow, 0.0f, 1.0f);
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
        for (int i = -radius; i <= radius; ++i)
            lit += depth <= as_float(shadow_depth[cube_texel(light, views, view_needed, view, tx + i, ty + j)]) + tolerance
                       ? 1.0f : 0.0f;
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
                                     global const int* view_needed, global const light_t* lights, global const uint* shadow_depth,
                                     global const float4* moments, global const float2* depth_range,
                                     global const uint* camera_depth, global const int* tri_id,
                                     global const float4* tri_normal, global const float2* offsets, int radius,
                                     float depth_bias, float moment_bias, global float* visible)
{
    int sample = get_global_id(0);
    if (sample >= frame->width * frame->height * frame->spp) return;
    int pixel = sample / frame->spp;
    int x = pixel % frame->width, y = pixel / frame->width;
    global float* out = visible + sample * frame->light_count;
    for (int l = 0; l < frame->light_count; ++l) out[l] = 1.0f;
    float distance = as_float(camera_depth[sample]);
    int tri = tri_id[sample];
    if (tri < 0 || distance > frame->far) return;
    float3 origin, dir;
    view_ray(views, view_screen(views, x, y, offsets[sample % frame->spp]), &origin, &dir);
    float3 p = origin + distance * dir;
    float3 n = tri_normal[tri].xyz;
    if (dot(n, dir) > 0.0f) n = -n; /* two-sided: face the camera, as shade does */
    for (int l = 0; l < frame->light_count; ++l) {
        global const light_t* light = lights + l;
        if (eye_in_lamp(light, frame->lamp_radius)) continue;
        float3 to_light;
        light_incident(light, frame->sigma_t.xyz, p, &to_light);
        float cosine = fabs(dot(n, to_light));
        float slope = fmin(sqrt(fmax(1.0f - cosine * cosine, 0.0f)) / cosine, MAX_BIAS_SLOPE);
        /* The normal offset by a texel of shade's own map test. */
        float3 lookup = p + n * shadow_texel_size(light, length(p - light->position.xyz));
        out[l] = filtered_visibility(light, views, view_needed, shadow_depth, moments, depth_range[l], lookup, slope,
                                     radius, depth_bias, moment_bias);
    }
}
