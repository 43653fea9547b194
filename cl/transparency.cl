/* transparency — the translucent surfaces each camera ray meets in front of its opaque depth,
 * and their composite (docs/design.md, translucent surfaces: the camera side): layers found
 * by depth peeling (nearest first) or gathered in no order for MBOIT, then per sample the
 * transmittance T(D) of all of them and the light they add in front,
 * Σ_k α_k·T(z_k⁻)·(e^{-σt z_k}·S_k + L(0, z_k)).
 * Reads frame, views, offsets, camera_depth (the opaque depth), tri_vertices, translucent (the
 * translucent triangles' indices), and for the composite lights, shadow_depth, tri_normal,
 * tri_albedo, tri_opacity, light_textures, texels, film_scatter (L(0, z_k) per layer), and with
 * MBOIT's one walk walked_fog (transparency_walk.cl); writes film_depth, film_tri
 * ([slot][sample]), and transmittance, in_front (float4 per sample).
 *
 *   film buffers, slot-major:   | slot 0: sample 0 … S-1 | slot 1: sample 0 … S-1 | …
 *   so that one slot's depths are a camera-depth-shaped buffer the in-scatter stages read. */
#include "light_texture.h"
#include "mboit.h"
#include "translucency.h"

#ifndef TRANSPARENCY_MOMENTS
#define TRANSPARENCY_MOMENTS 0 /* 1: films gathered in no order (mboit, gathered), not peeled in order */
#endif
/* Hits closer than this (relative) are one surface: a ray through the edge two triangles of a
 * pane share meets both at the same depth, and the pane must count once. */
#define SAME_SURFACE_REL 1e-5f
/* MBOIT's fog weighted in one walk per sample (transparency_walk.cl, docs/design.md): the
 * composite adds walked_fog, ∫(T(s) − T(D)) dL(0, s), after its films' own light, and
 * film_scatter carries only the lights no walk covers (the eye in a lamp), zero otherwise. */
#ifdef TRANSPARENCY_WEIGHTED_WALK
#define WALKED_FOG_ARG , global const float4* walked_fog
#else
#define WALKED_FOG_ARG
#endif
/* SURFACE_BIAS_TEXELS: shade.cl's surface shadow test's, from clrays/structs.py (-D). */
#ifndef FILM_SHADOW_RAYS
/* 1 (`surface_shadows: exact`): a film's light through the translucent surfaces nearer the light
 * is a shadow ray's product over the translucent triangles, as exact computes it, not the
 * layers' lookup, whose coloured shadow edges are a texel wide. */
#define FILM_SHADOW_RAYS 0
#endif

/* Möller–Trumbore, two-sided, edges inclusive with EDGE_SLACK (common.h): the distance along
 * the ray, +inf for a miss. */
inline float hit_distance(float3 origin, float3 dir, global const float4* tri_vertices, int tri)
{
    float3 v0 = tri_vertices[3 * tri].xyz;
    float3 e1 = tri_vertices[3 * tri + 1].xyz - v0, e2 = tri_vertices[3 * tri + 2].xyz - v0;
    float3 pv = cross(dir, e2);
    float det = dot(e1, pv);
    if (det == 0.0f) return INFINITY;
    float inv = 1.0f / det;
    float3 tv = origin - v0;
    float u = dot(tv, pv) * inv;
    if (u < -EDGE_SLACK || u > 1.0f + EDGE_SLACK) return INFINITY;
    float3 qv = cross(tv, e1);
    float v = dot(dir, qv) * inv;
    if (v < -EDGE_SLACK || u + v > 1.0f + EDGE_SLACK) return INFINITY;
    float t = dot(e2, qv) * inv;
    return t > 0.0f ? t : INFINITY;
}

/* The sample's ray and the depth its translucent hits must be in front of: the opaque hit, or far. */
#define SAMPLE_RAY                                                                              \
    int sample = get_global_id(0);                                                              \
    int samples = frame->width * frame->height * frame->spp;                                    \
    if (sample >= samples) return;                                                              \
    int pixel = sample / frame->spp;                                                            \
    float3 origin, dir;                                                                         \
    view_ray(views, view_screen(views, pixel % frame->width, pixel / frame->width,              \
                                offsets[sample % frame->spp]), &origin, &dir);                  \
    float opaque = fmin(as_float(camera_depth[sample]), frame->far);

#define LAYER_ARGS global const frame_t* frame, global const view_t* views, global const float2* offsets, \
                   global const uint* camera_depth, global const float4* tri_vertices,                     \
                   global const int* translucent, int translucent_count

/* Depth peeling: `layers` passes, each the nearest hit beyond the previous layer, nearest first;
 * empty slots hold depth 0 (the in-scatter stages then add nothing) and triangle −1. `used` is
 * raised to the most layers any sample found, so the stages after run no empty slot. */
kernel void transparency_peel(LAYER_ARGS, int layers, global uint* film_depth, global int* film_tri,
                              global int* used)
{
    SAMPLE_RAY
    float previous = 0.0f;
    int found = 0;
    for (; found < layers; ++found) {
        float nearest = opaque;
        int nearest_tri = -1;
        float beyond = previous * (1.0f + SAME_SURFACE_REL);
        for (int i = 0; i < translucent_count; ++i) {
            int tri = translucent[i];
            float t = hit_distance(origin, dir, tri_vertices, tri);
            if (t > beyond && t < nearest) {
                nearest = t;
                nearest_tri = tri;
            }
        }
        if (nearest_tri < 0) break;
        film_depth[found * samples + sample] = as_uint(nearest);
        film_tri[found * samples + sample] = nearest_tri;
        previous = nearest;
    }
    for (int k = found; k < layers; ++k) {
        film_depth[k * samples + sample] = 0u;
        film_tri[k * samples + sample] = -1;
    }
    atomic_max(used, found);
}

/* MBOIT, first pass: how many hits the sample's ray has in front of its opaque depth (an upper
 * bound: the same surface met twice counts twice) into `counts`, and raised into `used`, the
 * slots to gather. */
kernel void transparency_count(LAYER_ARGS, global int* counts, global int* used)
{
    SAMPLE_RAY
    int count = 0;
    for (int i = 0; i < translucent_count; ++i)
        count += hit_distance(origin, dir, tri_vertices, translucent[i]) < opaque;
    counts[sample] = count;
    atomic_max(used, count);
}

/* MBOIT, second pass: every hit in front of the opaque depth, in the order of the triangle list
 * (no sorting), the same surface once; `slots` ≥ the count of the first pass. A sample stops at
 * its count of hits (most samples meet none, and pay for the first pass only). */
kernel void transparency_gather(LAYER_ARGS, global const int* counts, int slots, global uint* film_depth,
                                global int* film_tri)
{
    SAMPLE_RAY
    int found = 0, met = 0, count = counts[sample];
    for (int i = 0; i < translucent_count && met < count; ++i) {
        int tri = translucent[i];
        float t = hit_distance(origin, dir, tri_vertices, tri);
        if (!(t < opaque)) continue;
        ++met;
        int same = 0;
        for (int k = 0; k < found; ++k)
            same |= fabs(as_float(film_depth[k * samples + sample]) - t) <= SAME_SURFACE_REL * t;
        if (same) continue;
        film_depth[found * samples + sample] = as_uint(t);
        film_tri[found * samples + sample] = tri;
        ++found;
    }
    for (int k = found; k < slots; ++k) {
        film_depth[k * samples + sample] = 0u;
        film_tri[k * samples + sample] = -1;
    }
}

/* The product of (1 − α) of the translucent triangles that the shadow ray from a film at p
 * (normal n, facing the camera) to the light crosses: it leaves from the side facing the light,
 * offset as translucency_surface's ray (translucency.cl), so the film's own pane is behind it. */
inline float3 film_shadow_ray(global const light_t* light, float3 p, float3 n, float3 to_light,
                              global const float4* tri_vertices, global const float4* tri_opacity,
                              global const int* translucent, int translucent_count)
{
    float3 start = shadow_ray_start(light, p, n, to_light);
    float3 ray = light->type == LIGHT_DIRECTIONAL ? to_light : light->position.xyz - start;
    float t_max = light->type == LIGHT_DIRECTIONAL ? INFINITY : 1.0f;
    float3 through = (float3)(1.0f);
    for (int i = 0; i < translucent_count; ++i) {
        int tri = translucent[i];
        if (hit_distance(start, ray, tri_vertices, tri) < t_max) through *= 1.0f - tri_opacity[tri].xyz;
    }
    return through;
}

/* S_k: the light a surface of albedo `albedo` at p reflects towards the camera, as shade.cl's
 * two-sided Lambertian with the shadow-map test (its flat normal: smooth shading normals are
 * shade.cl's own), and through the translucent surfaces nearer the light when the light side's
 * layers are given: their lookup (translucency.h), or with FILM_SHADOW_RAYS a shadow ray.
 * Weighted by the layer's opacity by the caller. */
inline float3 surface_radiance(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                               global const uint* shadow_depth, global const light_texture_t* light_textures,
                               global const float4* texels, float3 p, float3 n, float3 dir, float3 albedo,
                               global const float4* tri_vertices, global const float4* tri_opacity,
                               global const int* translucent, int translucent_count TRANSLUCENCY_ARGS)
{
    if (dot(n, dir) > 0.0f) n = -n; /* two-sided: face the camera */
    float3 irradiance = (float3)(0.0f);
    for (int l = 0; l < frame->light_count; ++l) {
        float3 to_light;
        float3 incident = light_incident(lights + l, frame->sigma_t.xyz, p, &to_light)
                          * light_texture(light_textures + l, texels, lights + l, p);
        float cosine = dot(n, to_light);
        if (cosine <= 0.0f || incident.x + incident.y + incident.z == 0.0f) continue;
        float visible = 1.0f;
        if (!eye_in_lamp(lights + l, frame->lamp_radius)) {
            float3 lookup = shadow_lookup(lights + l, p, n);
            visible = shadow_visibility(lights + l, views, shadow_depth, lookup, SURFACE_BIAS_TEXELS, 0);
#ifdef TRANSLUCENT_LAYERS
#if FILM_SHADOW_RAYS
            if (visible > 0.0f)
                incident *= film_shadow_ray(lights + l, p, n, to_light, tri_vertices, tri_opacity, translucent,
                                            translucent_count);
#else
            if (visible > 0.0f)
                incident *= light_transmittance(lights + l, views, layer_depth, layer_clear, layer_stride, lookup,
                                                SURFACE_BIAS_TEXELS);
#endif
#endif
        }
        irradiance += incident * (cosine * visible);
    }
    return albedo * irradiance * M_1_PI_F;
}

/* Per sample: T(D) into transmittance, and the light of its layers in front, Σ_k α_k·T(z_k⁻)·C_k,
 * C_k = e^{-σt z_k}·S_k + L(0, z_k), into in_front. Depth peeling: T(z_k⁻) is the product of
 * the nearer layers' (1 − α). MBOIT: T(z_k⁻) = exp(−b0·F(z_k)), F the Hamburger bound on the
 * fraction of absorbance in front of z_k from the moments of all layers, then the weights
 * α_k·T(z_k⁻) scaled so that they sum to 1 − T(D), with T(D) = exp(−b0) exact per channel. */
kernel void transparency_composite(global const frame_t* frame, global const view_t* views,
                                   global const float2* offsets, global const light_t* lights,
                                   global const uint* shadow_depth, global const float4* tri_vertices,
                                   global const float4* tri_normal, global const float4* tri_albedo,
                                   global const float4* tri_opacity, global const light_texture_t* light_textures,
                                   global const float4* texels, int slots, global const uint* film_depth,
                                   global const int* film_tri, global const float4* film_scatter,
                                   float2 depth_range, float moment_bias, global const int* translucent,
                                   int translucent_count, global float4* transmittance,
                                   global float4* in_front TRANSLUCENCY_ARGS WALKED_FOG_ARG)
{
    int sample = get_global_id(0);
    int samples = frame->width * frame->height * frame->spp;
    if (sample >= samples) return;
    int pixel = sample / frame->spp;
    float3 origin, dir;
    view_ray(views, view_screen(views, pixel % frame->width, pixel / frame->width, offsets[sample % frame->spp]),
             &origin, &dir);
    float3 sigma_t = frame->sigma_t.xyz;
#if TRANSPARENCY_MOMENTS
    /* The moments of the absorbance over warped depth: b0 per channel, b1…b4 of the mean
     * absorbance, normalised (cl/moments.h takes the moments of a distribution). */
    film_moments_t moments = film_moments(slots, samples, sample, film_depth, film_tri, tri_opacity, depth_range);
    float3 b0 = moments.b0;
    float4 b = moments.b;
#endif
    float3 through = (float3)(1.0f), light = (float3)(0.0f), weights = (float3)(0.0f);
    for (int k = 0; k < slots; ++k) {
        int tri = film_tri[k * samples + sample];
        if (tri < 0) break;
        float z = as_float(film_depth[k * samples + sample]);
        float3 alpha = tri_opacity[tri].xyz;
        float3 surface = surface_radiance(frame, views, lights, shadow_depth, light_textures, texels, origin + z * dir,
                                          tri_normal[tri].xyz, dir, tri_albedo[tri].xyz, tri_vertices,
                                          tri_opacity, translucent, translucent_count TRANSLUCENCY_PASS);
        float3 radiance = surface * exp(-sigma_t * z) + film_scatter[k * samples + sample].xyz;
#if TRANSPARENCY_GATHERED
        float3 weight = alpha * estimated_transmittance(&moments, z, depth_range, moment_bias);
#elif TRANSPARENCY_MOMENTS
        float in_front_fraction = absorbance_in_front(b, warped_depth(z, depth_range), moment_bias);
        float3 weight = alpha * exp(-b0 * in_front_fraction);
#else
        float3 weight = alpha * through;
        through *= 1.0f - alpha;
#endif
        light += weight * radiance;
        weights += weight;
    }
#if TRANSPARENCY_MOMENTS
    through = moments.behind;
    light *= select((float3)(0.0f), (1.0f - through) / weights, isgreater(weights, (float3)(0.0f)));
#endif
#ifdef TRANSPARENCY_WEIGHTED_WALK
    light += walked_fog[sample].xyz;
#endif
    transmittance[sample] = (float4)(through, 0.0f);
    in_front[sample] = (float4)(light, 0.0f);
}
