/* light_texture — each row's prefix sums of a textured light's texture T and of T·Γ_i,
 * rectified beside its shadow map (docs/light-textures.md, minmax).
 * Reads lights, epipolar, light_textures, texels, textured, gamma_basis (Γ_i per γ cell); writes
 * prefix, which traverse reads.
 *
 *   prefix, one slice: n + 1 records, one per cell boundary (0 first), each
 *                      | channel r: term 0 (∫T), term 1 (∫T·Γ_0), ..., term rank | channel g: ... | b: ... |
 *   gamma_basis:       Γ[cell][channel][rank]
 *
 * A run's ends read two records each, whatever the rank (cl/light_texture.h). */
#include "light_texture.h"

/* TEXTURE_RANK (-D, the stage's): the terms' sums are private, in registers where they fit. */
#define TEXTURE_TERMS (TEXTURE_RANK + 1)

/* One work-item per slice. T of a cell is its mean along the slice's light rays, from
 * `cell_samples` evenly spaced points of the cell (in its texel coordinate): a texture
 * finer than a cell (a directional light's tiled pattern seen far from the eye's line)
 * is averaged over the cell, as a run integrates it, where the cell's centre alone
 * aliases it. The sums along the row are compensated (Kahan) so that 16384 cells keep
 * float32's precision. */
kernel void light_texture_prefix(global const light_t* lights, global const epipolar_t* epipolar,
                                 global const light_texture_t* light_textures, global const float4* texels,
                                 global const textured_integrand_t* textured, global const float* gamma_basis,
                                 int cell_samples, global float* prefix)
{
    int slice = get_global_id(0);
    global const epipolar_t* ep = epipolar;
    int n = textured->gamma_samples;
    if (slice >= textured->slices) return;
    global const light_t* light = lights + ep->light_index;
    global const light_texture_t* texture = light_textures + ep->light_index;
    gamma_texels_t cells = gamma_texels_of(ep);
    float alpha = ep->alpha_min + ((float)slice + 0.5f) * ep->alpha_step;
    float3 r = ep->u.xyz * cos(alpha) + ep->w.xyz * sin(alpha);
    int directional = light->type == LIGHT_DIRECTIONAL;
    /* A directional light's texel coordinates are affine in γ along the row (light_texture's
     * directional case at γ·r): (fx, fy) = start + γ·step. */
    float3 q0 = -texture->origin.xyz;
    int w = texture->width, h = texture->height;
    float fx0 = (2.0f * dot(q0, texture->right.xyz) * texture->scale_x + 1.0f) * 0.5f * (float)w - 0.5f;
    float fy0 = (1.0f - 2.0f * dot(q0, texture->up.xyz) * texture->scale_y) * 0.5f * (float)h - 0.5f;
    float fx_step = dot(r, texture->right.xyz) * texture->scale_x * (float)w;
    float fy_step = -dot(r, texture->up.xyz) * texture->scale_y * (float)h;
    global const float4* image = texels + texture->first_texel;
    float inverse_samples = 1.0f / (float)cell_samples;

    global float* record = prefix + (size_t)slice * 3 * TEXTURE_TERMS * (n + 1);
    float sum[3 * TEXTURE_TERMS], compensation[3 * TEXTURE_TERMS];
    for (int i = 0; i < 3 * TEXTURE_TERMS; ++i) {
        sum[i] = compensation[i] = 0.0f;
        record[i] = 0.0f;
    }
    for (int k = 0; k < n; ++k) {
        float3 mean = (float3)(0.0f);
        if (directional) {
            /* The cell's start wrapped once into the tile (repeat), its points offset from it:
             * texel_pair then wraps only the points past the tile's edge. */
            float start = gamma_at_texel(cells, (float)k), length = gamma_texel_width(cells, k);
            float x = fx0 + start * fx_step, y = fy0 + start * fy_step;
            if (texture->wrap == TEXTURE_WRAP_REPEAT) {
                x -= (float)w * floor(x / (float)w);
                y -= (float)h * floor(y / (float)h);
            }
            for (int j = 0; j < cell_samples; ++j) {
                float along = ((float)j + 0.5f) * inverse_samples * length;
                mean += texture_bilinear(image, w, h, texture->wrap, x + along * fx_step, y + along * fy_step);
            }
        } else {
            for (int j = 0; j < cell_samples; ++j) {
                float gamma = gamma_at_texel(cells, (float)k + ((float)j + 0.5f) * inverse_samples);
                mean += light_texture(texture, texels, light,
                                      light->position.xyz - ep->axis.xyz * cos(gamma) + r * sin(gamma));
            }
        }
        mean *= inverse_samples * gamma_texel_width(cells, k); /* ∫T over the cell */
        global const float* gamma = gamma_basis + (size_t)k * 3 * TEXTURE_RANK;
        record += 3 * TEXTURE_TERMS;
        for (int channel = 0; channel < 3; ++channel) {
            float t = channel == 0 ? mean.x : (channel == 1 ? mean.y : mean.z);
            for (int term = 0; term < TEXTURE_TERMS; ++term) {
                int i = channel * TEXTURE_TERMS + term;
                float value = (term == 0 ? t : t * gamma[channel * TEXTURE_RANK + term - 1]) - compensation[i];
                float next = sum[i] + value;
                compensation[i] = (next - sum[i]) - value;
                sum[i] = next;
                record[i] = next;
            }
        }
    }
}
