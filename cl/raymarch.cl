/* raymarch — the brute-force reference: in-scattered radiance per camera sample by
 * `steps` uniform (optionally jittered) samples from the eye to the surface, with a
 * shadow-map lookup per sample and light.
 * Reads frame, views, lights, shadow_depth, camera_depth, offsets; writes scatter
 * (one float4 per camera sample, rgb radiance). */
#include "lighting.h"

/* A per-ray number in [0, 1): jitter that is repeatable from run to run. */
inline float hash_unit(uint a)
{
    a ^= a >> 16; a *= 0x7feb352du; a ^= a >> 15; a *= 0x846ca68bu; a ^= a >> 16;
    return (float)(a >> 8) * (1.0f / 16777216.0f);
}

kernel void raymarch(global const frame_t* frame, global const view_t* views,
                     global const light_t* lights, global const uint* shadow_depth,
                     global const uint* camera_depth, global const float2* offsets,
                     global float4* scatter)
{
    int sample = get_global_id(0);
    int pixel = sample / frame->spp;
    if (pixel >= frame->width * frame->height) return;
    int x = pixel % frame->width, y = pixel / frame->width;
    float3 origin, dir;
    view_ray(views, view_screen(views, x, y, offsets[sample % frame->spp]), &origin, &dir);
    float distance = fmin(as_float(camera_depth[sample]), frame->far);

    float3 sigma_s = frame->sigma_s.xyz, sigma_t = frame->sigma_t.xyz;
    float dt = distance / (float)frame->steps;
    float u = frame->jitter ? hash_unit((uint)sample * 0x9e3779b9u + 0x85ebca6bu) : 0.5f;
    float3 radiance = (float3)(0.0f);
    for (int i = 0; i < frame->steps; ++i) {
        float t = ((float)i + u) * dt;
        float3 p = origin + t * dir;
        float3 at_point = (float3)(0.0f);
        for (int l = 0; l < frame->light_count; ++l) {
            float3 to_light;
            float3 incident = light_incident(lights + l, sigma_t, p, &to_light);
            if (incident.x + incident.y + incident.z == 0.0f) continue;
            float visible = shadow_visibility(lights + l, views, shadow_depth, p, 1.0f, 0);
            /* cos θ = (light → p)·(p → eye) = to_light·dir */
            at_point += incident * (visible * phase_function(frame, dot(to_light, dir)));
        }
        radiance += at_point * exp(-sigma_t * t);
    }
    scatter[sample] = (float4)(radiance * sigma_s * dt, 0.0f);
}
