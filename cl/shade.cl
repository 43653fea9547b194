/* shade — surface radiance at each camera sample (two-sided Lambertian, shadow-map
 * test with optional PCF), attenuated to the eye, plus the in-scattered radiance,
 * averaged over the pixel's samples.
 * Reads frame, views, lights, shadow_depth, camera_depth, tri_id, tri_vertices,
 * tri_normal, tri_vertex_normals, tri_albedo, offsets, scatter, visible (the visibility
 * stage's answer per sample and light, with surface_shadows exact; the shadow_filter stage's
 * with surface_shadows filtered), light_textures and texels (a light's texture,
 * docs/light-textures.md), and with translucent objects the translucency stage's layers
 * (translucency.h); writes image (one
 * float4 per pixel, linear rgb). */
#include "light_texture.h"
#include "translucency.h"

#define SURFACE_BIAS_TEXELS 1.5f /* depth tolerance of the surface shadow test */

/* A scene with translucent objects builds shade with SHADE_TRANSPARENCY: the transparency stage's
 * T(D) and the light of the layers in front of each sample (docs/design.md, translucent surfaces:
 * the camera side) come as two more buffers. Opaque-only scenes build it without, and their
 * images are unchanged. */
#ifdef SHADE_TRANSPARENCY
#define TRANSPARENCY_ARGS , global const float4* transmittance, global const float4* in_front
#else
#define TRANSPARENCY_ARGS
#endif

/* The shading normal of a smooth triangle where the sample ray meets it: its three vertex
 * normals weighted by the barycentric coordinates of the hit (Möller–Trumbore on the ray,
 * clamped to the triangle, as a sample by an edge may land just outside), normalised.
 * `flat` where that is undefined: a ray in the triangle's plane, or normals that cancel. */
inline float3 smooth_normal(global const float4* tri_vertices, global const float4* tri_vertex_normals,
                            int tri, float3 origin, float3 dir, float3 flat)
{
    float3 v0 = tri_vertices[3 * tri].xyz;
    float3 edge1 = tri_vertices[3 * tri + 1].xyz - v0, edge2 = tri_vertices[3 * tri + 2].xyz - v0;
    float3 p = cross(dir, edge2);
    float det = dot(edge1, p);
    if (det == 0.0f) return flat;
    float3 t = origin - v0;
    float u = clamp(dot(t, p) / det, 0.0f, 1.0f);
    float v = clamp(dot(dir, cross(t, edge1)) / det, 0.0f, 1.0f);
    if (u + v > 1.0f) {
        float sum = u + v;
        u /= sum;
        v /= sum;
    }
    float3 n = (1.0f - u - v) * tri_vertex_normals[3 * tri].xyz + u * tri_vertex_normals[3 * tri + 1].xyz
               + v * tri_vertex_normals[3 * tri + 2].xyz;
    float n_length = length(n);
    return n_length > 0.0f ? n / n_length : flat;
}

kernel void shade(global const frame_t* frame, global const view_t* views,
                  global const light_t* lights, global const uint* shadow_depth,
                  global const uint* camera_depth, global const int* tri_id,
                  global const float4* tri_vertices, global const float4* tri_normal,
                  global const float4* tri_vertex_normals, global const float4* tri_albedo,
                  global const float2* offsets, global const float4* scatter,
                  global const float* visible_exact, global const light_texture_t* light_textures,
                  global const float4* texels, global float4* image TRANSLUCENCY_ARGS SURFACE_THROUGH_ARGS
                  TRANSPARENCY_ARGS)
{
    int pixel = get_global_id(0);
    if (pixel >= frame->width * frame->height) return;
    int x = pixel % frame->width, y = pixel / frame->width;
    float3 sigma_t = frame->sigma_t.xyz;
    float3 total = (float3)(0.0f);
    for (int s = 0; s < frame->spp; ++s) {
        int sample = pixel * frame->spp + s;
        float3 origin, dir;
        view_ray(views, view_screen(views, x, y, offsets[s]), &origin, &dir);
        float distance = as_float(camera_depth[sample]);
        int tri = tri_id[sample];
        float3 surface;
        if (tri < 0 || distance > frame->far) {
            distance = frame->far;
            surface = frame->background.xyz;
        } else {
            float3 p = origin + distance * dir;
            /* n, the triangle's own normal, picks the side and offsets the shadow lookup;
             * the shading normal (n itself unless the triangle is smooth) weighs the light. */
            float3 n = tri_normal[tri].xyz;
            float3 shading = tri_normal[tri].w != 0.0f
                                 ? smooth_normal(tri_vertices, tri_vertex_normals, tri, origin, dir, n)
                                 : n;
            if (dot(n, dir) > 0.0f) { /* two-sided: face the camera */
                n = -n;
                shading = -shading;
            }
            float3 irradiance = (float3)(0.0f);
            for (int l = 0; l < frame->light_count; ++l) {
                float3 to_light;
                float3 incident = light_incident(lights + l, sigma_t, p, &to_light)
                                  * light_texture(light_textures + l, texels, lights + l, p);
                float cosine = dot(shading, to_light);
                if (cosine <= 0.0f || incident.x + incident.y + incident.z == 0.0f) continue;
                /* Normal offset by a texel keeps a lit surface from shadowing itself. */
                float3 lookup = p + n * shadow_texel_size(lights + l, length(p - lights[l].position.xyz));
                float visible;
                if (eye_in_lamp(lights + l, frame->lamp_radius))
                    visible = 1.0f;
                else if (frame->surface_shadows == SURFACE_SHADOWS_EXACT
                         || frame->surface_shadows == SURFACE_SHADOWS_FILTERED)
                    visible = visible_exact[sample * frame->light_count + l];
                else
                    visible = shadow_visibility(lights + l, views, shadow_depth, lookup, SURFACE_BIAS_TEXELS,
                                                frame->pcf);
#ifdef TRANSLUCENT_LAYERS /* through the translucent surfaces nearer the light (translucency.h) */
                if (visible > 0.0f)
                    incident *= has_surface_through
                                    ? surface_through[sample * frame->light_count + l].xyz
                                    : light_transmittance(lights + l, views, layer_depth, layer_clear, layer_stride,
                                                          lookup, SURFACE_BIAS_TEXELS);
#endif
                irradiance += incident * (cosine * visible);
            }
            surface = tri_albedo[tri].xyz * irradiance * M_1_PI_F;
        }
#ifdef SHADE_TRANSPARENCY
        total += transmittance[sample].xyz * (surface * exp(-sigma_t * distance) + scatter[sample].xyz)
                 + in_front[sample].xyz;
#else
        total += surface * exp(-sigma_t * distance) + scatter[sample].xyz;
#endif
    }
    image[pixel] = (float4)(total / (float)frame->spp, 1.0f);
}
