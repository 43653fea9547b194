/* shade — surface radiance at each camera sample (two-sided Lambertian, shadow-map
 * test with optional PCF), attenuated to the eye, plus the in-scattered radiance,
 * averaged over the pixel's samples.
 * Reads frame, views, lights, shadow_depth, camera_depth, tri_id, tri_normal,
 * tri_albedo, offsets, scatter; writes image (one float4 per pixel, linear rgb). */
#include "lighting.h"

#define SURFACE_BIAS_TEXELS 1.5f /* depth tolerance of the surface shadow test */

kernel void shade(global const frame_t* frame, global const view_t* views,
                  global const light_t* lights, global const uint* shadow_depth,
                  global const uint* camera_depth, global const int* tri_id,
                  global const float4* tri_normal, global const float4* tri_albedo,
                  global const float2* offsets, global const float4* scatter,
                  global float4* image)
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
            float3 n = tri_normal[tri].xyz;
            if (dot(n, dir) > 0.0f) n = -n; /* two-sided: face the camera */
            float3 irradiance = (float3)(0.0f);
            for (int l = 0; l < frame->light_count; ++l) {
                float3 to_light;
                float3 incident = light_incident(lights + l, sigma_t, p, &to_light);
                float cosine = dot(n, to_light);
                if (cosine <= 0.0f || incident.x + incident.y + incident.z == 0.0f) continue;
                /* Normal offset by a texel keeps a lit surface from shadowing itself. */
                float3 lookup = p + n * shadow_texel_size(lights + l, length(p - lights[l].position.xyz));
                float visible = eye_in_lamp(lights + l, frame->far)
                                    ? 1.0f
                                    : shadow_visibility(lights + l, views, shadow_depth, lookup,
                                                        SURFACE_BIAS_TEXELS, frame->pcf);
                irradiance += incident * (cosine * visible);
            }
            surface = tri_albedo[tri].xyz * irradiance * M_1_PI_F;
        }
        total += surface * exp(-sigma_t * distance) + scatter[sample].xyz;
    }
    image[pixel] = (float4)(total / (float)frame->spp, 1.0f);
}
