/* translucency — per light, the K translucent surfaces nearest the light in every
 * shadow-map texel, by depth peeling: pass k keeps the nearest depth beyond layer k − 1.
 * Reads tri_vertices (the translucent triangles only, anchored at the light), views,
 * triangle_clear (1 − opacity per triangle); writes peel depth and triangle per layer,
 * then layer_depth and layer_clear (cumulative transmittance) in cl/translucency.h's layout.
 *
 *   light ──▶ layer 0 ──▶ layer 1 ──▶ … ──▶ layer K−1        (one texel's ray)
 *             T0 = c0     T1 = c0·c1      T(K−1) = Π c_k     c = 1 − opacity */
#include "raster.cl"
#include "translucency.h"

/* A surface counts as a new layer only beyond the previous one by this many float ulps
 * (about 1e-5 relative): the two triangles of a pane meet the rays along their shared
 * edge at depths a few ulps apart, and are one surface there. */
#ifndef PEEL_GAP_ULPS
#define PEEL_GAP_ULPS 128u
#endif

#define PEEL_TARGET global uint* depth, global const uint* previous
RASTER_KERNELS(translucency_peel, PEEL_TARGET,
               if (as_uint(t) > previous[idx] + PEEL_GAP_ULPS) atomic_min(depth + idx, as_uint(t));)

/* Layer k of every texel into the light's atlas: its depth, and the product of (1 − α)
 * of layers 0 … k, packed unorm16 (rounded, so 1 stays exactly 1). */
kernel void translucency_pack(global const uint* peel_depth, global const int* peel_tri, int texels,
                              global const float4* triangle_clear, int layer, global const uint2* previous_clear,
                              global float* layer_depth, global uint2* layer_clear)
{
    int i = get_global_id(0);
    if (i >= texels) return;
    uint bits = peel_depth[i];
    float3 through = layer == 0 ? (float3)(1.0f) : (float3)(0.0f);
    if (layer > 0) {
        uint2 before = previous_clear[i];
        through = (float3)((float)(before.x & 0xffffu), (float)(before.x >> 16), (float)(before.y & 0xffffu))
                  * (1.0f / 65535.0f);
    }
    int tri = peel_tri[i];
    if (bits != DEPTH_EMPTY && tri >= 0) through *= triangle_clear[tri].xyz;
    uint3 q = convert_uint3_sat_rte(clamp(through, 0.0f, 1.0f) * 65535.0f);
    layer_depth[i] = as_float(bits);
    layer_clear[i] = (uint2)(q.x | (q.y << 16), q.z);
}

/* translucency_rectify — the layers resampled into one light's epipolar texture, as
 * rectify resamples its shadow map (docs/design.md §2, §3): per slice α and texel γ, the
 * β at which each layer sits on that light ray (π: no layer) and its transmittance, K per
 * texel, [slice][texel][k]; and per slice whether any of its texels has a layer, so the
 * walk of a row without one keeps the min-max tree (cl/translucent_walk.h).
 * Reads views, lights, layer_depth, layer_clear, epipolar; writes layer_beta,
 * rectified_clear, layer_rows (zeroed by the host). */
kernel void translucency_rectify(global const view_t* views, global const light_t* lights,
                                 global const float* layer_depth, global const uint2* layer_clear, int layer_stride,
                                 global const epipolar_t* epipolar, global float* layer_beta,
                                 global uint2* rectified_clear, global int* layer_rows)
{
    int texel = get_global_id(0), slice = get_global_id(1);
    global const epipolar_t* ep = epipolar;
    if (texel >= ep->gamma_samples || slice >= ep->slices) return;
    global const light_t* light = lights + ep->light_index;
    float alpha = ep->alpha_min + ((float)slice + 0.5f) * ep->alpha_step;
    float gamma = texel == 0 ? 0.0f : ((float)texel + 0.5f) * ep->gamma_step; /* rectify's texel centres */
    float3 r = ep->u.xyz * cos(alpha) + ep->w.xyz * sin(alpha);
    /* The light ray's texel in the shadow atlas, as rectify finds it. */
    global const view_t* view;
    float2 texel_xy;
    float unused;
    int on_map;
    if (light->type == LIGHT_DIRECTIONAL) {
        view = views + light->first_view;
        on_map = view_project(view, gamma * r, &texel_xy, &unused);
    } else {
        float3 probe = light->position.xyz - ep->axis.xyz * cos(gamma) + r * sin(gamma);
        view = views + light_view_index(light, probe);
        on_map = view_project(view, probe, &texel_xy, &unused);
    }
    on_map = on_map && texel_xy.x >= 0.0f && texel_xy.y >= 0.0f && texel_xy.x < (float)view->width
             && texel_xy.y < (float)view->height;
    int index = on_map ? view->depth_offset + (int)texel_xy.y * view->width + (int)texel_xy.x : 0;
    size_t out = ((size_t)slice * ep->gamma_samples + texel) * TRANSLUCENT_LAYERS;
    for (int k = 0; k < TRANSLUCENT_LAYERS; ++k) {
        float stored = on_map ? layer_depth[k * layer_stride + index] : INFINITY;
        float beta = M_PI_F;
        if (stored != INFINITY) {
            if (light->type == LIGHT_DIRECTIONAL)
                beta = atan2(gamma, -(stored + dot(view->origin.xyz, view->forward.xyz)));
            else
                beta = atan2(stored * sin(gamma), ep->d_el - stored * cos(gamma));
            if (k == 0) layer_rows[slice] = 1;
        }
        layer_beta[out + k] = beta;
        rectified_clear[out + k] = stored != INFINITY ? layer_clear[k * layer_stride + index] : (uint2)(0xffffffffu, 0xffffu);
    }
}
