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
#include "bvh.h"

/* A surface counts as a new layer only beyond the previous one by this many float ulps
 * (about 1e-5 relative): the two triangles of a pane meet the rays along their shared
 * edge at depths a few ulps apart, and are one surface there. */
#ifndef PEEL_GAP_ULPS
#define PEEL_GAP_ULPS 128u
#endif

#define PEEL_TARGET global uint* depth, global const uint* previous
RASTER_KERNELS(translucency_peel, PEEL_TARGET,
               if (as_uint(t) > previous[idx] + PEEL_GAP_ULPS) atomic_min(depth + idx, as_uint(t));,
               if (as_uint(t) > previous[idx] + PEEL_GAP_ULPS && as_uint(t) < depth[idx]) depth[idx] = as_uint(t);, )

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
    float gamma = texel == 0 ? 0.0f /* rectify's texel centres */
                             : gamma_at_texel(gamma_texels_of(ep), (float)texel + 0.5f);
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

/* translucency_surface — with `render.surface_shadows: exact`, the transmittance that
 * reaches each camera sample's surface from each light, as the exact reference computes
 * it: where the layers of the 5 × 5 texels around the sample's lookup agree, their
 * transmittance; elsewhere (the edges of a translucent shadow) a shadow ray through the
 * translucent triangles' own BVH, multiplying (1 − α) of every one it crosses.
 * Reads frame, views, lights, layers, camera_depth, tri_id, tri_normal, offsets, the
 * translucent triangles (eye space), their clear and BVH; writes surface_through
 * (float4 per sample and light). Opaque occluders are the visibility stage's. */
/* SHADOW_RAY_OFFSET_REL and SURFACE_BIAS_TEXELS: visibility.cl's and shade.cl's, from
 * clrays/structs.py (-D). */

/* The texels around the lookup whose layers must agree for their answer to stand: the lookup
 * lies up to a texel from the point along the normal (lighting.h's shadow_lookup), so 2 keeps
 * the 3 × 3 around the point's own texel inside the test; with 1, an edge a texel beyond it went
 * unseen (a floor pixel of scenes/glass_row.yaml at 640 × 360, lit in exact, took a pane's shadow). */
#define AGREE_RADIUS 2

/* The product of (1 − α) of every translucent triangle but `skip` that crosses
 * origin + t·dir, t ∈ (0, t_max): bvh_occluded's walk, visiting every hit. */
inline float3 bvh_transmittance(global const float4* node_bounds, global const int2* node_children, int root,
                                global const float4* vertices, global const float4* triangle_clear,
                                float3 origin, float3 dir, float t_max)
{
    float3 inv_dir = 1.0f / dir;
    test_ray_t ray = test_ray(origin, dir);
    float3 through = (float3)(1.0f);
    int stack[BVH_STACK];
    int top = 0;
    stack[top++] = root;
    while (top > 0) {
        int node = stack[--top];
        if (node < 0) {
            int tri = -node - 1;
            if (ray_meets_triangle(&ray, 0.0f, t_max, vertices[3 * tri].xyz, vertices[3 * tri + 1].xyz,
                                   vertices[3 * tri + 2].xyz))
                through *= triangle_clear[tri].xyz;
            continue;
        }
        if (!ray_meets_box(origin, inv_dir, t_max, node_bounds[2 * node], node_bounds[2 * node + 1])) continue;
        if (top + 2 > BVH_STACK) return (float3)(0.0f);
        int2 children = node_children[node];
        stack[top++] = children.y;
        stack[top++] = children.x;
    }
    return through;
}

/* Transmittance of the texel (tx, ty) of a view at `depth`, as light_transmittance reads it. */
inline float3 texel_layers(global const view_t* view, global const float* layer_depth,
                           global const uint2* layer_clear, int layer_stride, int tx, int ty, float depth)
{
    tx = clamp(tx, 0, view->width - 1);
    ty = clamp(ty, 0, view->height - 1);
    int index = view->depth_offset + ty * view->width + tx;
    float3 through = (float3)(1.0f);
    for (int k = 0; k < TRANSLUCENT_LAYERS; ++k) {
        if (!(layer_depth[k * layer_stride + index] < depth)) break;
        through = unpack_clear(layer_clear[k * layer_stride + index]);
    }
    return through;
}

kernel void translucency_surface(global const frame_t* frame, global const view_t* views,
                                 global const light_t* lights, global const uint* camera_depth,
                                 global const int* tri_id, global const float4* tri_normal,
                                 global const float2* offsets, global const float4* vertices,
                                 global const float4* triangle_clear, global const float4* node_bounds,
                                 global const int2* node_children, int root, global float4* surface_through
                                 TRANSLUCENCY_ARGS)
{
    int sample = get_global_id(0);
    if (sample >= frame->width * frame->height * frame->spp) return;
    int pixel = sample / frame->spp;
    global float4* out = surface_through + sample * frame->light_count;
    for (int l = 0; l < frame->light_count; ++l) out[l] = (float4)(1.0f);
    float distance = as_float(camera_depth[sample]);
    int tri = tri_id[sample];
    if (tri < 0 || distance > frame->far) return;
    float3 origin, dir;
    view_ray(views, view_screen(views, pixel % frame->width, pixel / frame->width, offsets[sample % frame->spp]),
             &origin, &dir);
    float3 p = origin + distance * dir;
    float3 n = tri_normal[tri].xyz;
    if (dot(n, dir) > 0.0f) n = -n;
    for (int l = 0; l < frame->light_count; ++l) {
        global const light_t* light = lights + l;
        float3 to_light;
        float3 incident = light_incident(light, frame->sigma_t.xyz, p, &to_light);
        if (incident.x + incident.y + incident.z == 0.0f || eye_in_lamp(light, frame->lamp_radius)) continue;
        /* The layers decide where the texels around the lookup agree (shade's lookup point). */
        float3 lookup = shadow_lookup(light, p, n);
        global const view_t* view = views + light_view_index(light, lookup);
        float2 texel;
        float depth;
        if (view_project(view, lookup, &texel, &depth)) {
            float reach = depth - SURFACE_BIAS_TEXELS * shadow_texel_size(light, depth);
            int tx = (int)texel.x, ty = (int)texel.y;
            float3 centre = texel_layers(view, layer_depth, layer_clear, layer_stride, tx, ty, reach);
            int agree = texel.x >= AGREE_RADIUS && texel.y >= AGREE_RADIUS
                        && texel.x < (float)(view->width - AGREE_RADIUS) && texel.y < (float)(view->height - AGREE_RADIUS);
            for (int j = -AGREE_RADIUS; j <= AGREE_RADIUS && agree; ++j)
                for (int i = -AGREE_RADIUS; i <= AGREE_RADIUS && agree; ++i)
                    agree = all(texel_layers(view, layer_depth, layer_clear, layer_stride, tx + i, ty + j, reach)
                                == centre);
            if (agree) {
                out[l] = (float4)(centre, 1.0f);
                continue;
            }
        }
        float3 start = shadow_ray_start(light, p, n, to_light);
        float3 ray = light->type == LIGHT_DIRECTIONAL ? to_light : light->position.xyz - start;
        float t_max = light->type == LIGHT_DIRECTIONAL ? INFINITY : 1.0f;
        out[l] = (float4)(bvh_transmittance(node_bounds, node_children, root, vertices, triangle_clear, start, ray,
                                            t_max), 1.0f);
    }
}
