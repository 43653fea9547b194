/* light_texture — a textured light's texture rectified beside its shadow map, T[α, γ], and
 * each row's prefix sums of T and T·Γ_i (docs/light-textures.md, minmax).
 * Reads lights, epipolar, light_textures, texels, gamma_basis (Γ_i per γ cell); writes
 * rectified (float4 per slice and cell) and prefix, which traverse reads.
 *
 *   prefix, one slice:  | channel r: term 0 (T) | term 1 (T·Γ_0) | ... | term rank | channel g: ... | b: ... |
 *                       each term: n + 1 values at the cell boundaries, 0 first */
#include "light_texture.h"

/* The texture on the light ray of slice `slice` at the centre of γ cell `cell`: the ray
 * rectify samples the shadow map along (rectify.cl), at the cell's centre. */
kernel void light_texture_rectify(global const light_t* lights, global const epipolar_t* epipolar,
                                  global const light_texture_t* light_textures, global const float4* texels,
                                  global float4* rectified)
{
    int cell = get_global_id(0), slice = get_global_id(1);
    global const epipolar_t* ep = epipolar;
    if (cell >= ep->gamma_samples || slice >= ep->slices) return;
    global const light_t* light = lights + ep->light_index;
    float alpha = ep->alpha_min + ((float)slice + 0.5f) * ep->alpha_step;
    float gamma = gamma_at_texel(gamma_texels_of(ep), (float)cell + 0.5f);
    float3 r = ep->u.xyz * cos(alpha) + ep->w.xyz * sin(alpha);
    float3 on_ray = light->type == LIGHT_DIRECTIONAL ? gamma * r
                                                     : light->position.xyz - ep->axis.xyz * cos(gamma) + r * sin(gamma);
    float3 value = light_texture(light_textures + ep->light_index, texels, light, on_ray);
    rectified[(size_t)slice * ep->gamma_samples + cell] = (float4)(value, 0.0f);
}

/* One work-item per (channel, term) of a slice: the running sum along the row, compensated
 * (Kahan) so that 16384 cells keep float32's precision. Term 0 sums T, term i + 1 T·Γ_i. */
kernel void light_texture_prefix(global const epipolar_t* epipolar, global const textured_integrand_t* textured,
                                 global const float* gamma_basis, global const float4* rectified,
                                 global float* prefix)
{
    int item = get_global_id(0), slice = get_global_id(1);
    int rank = textured->rank, n = textured->gamma_samples;
    if (item >= 3 * (rank + 1) || slice >= textured->slices) return;
    int channel = item / (rank + 1), term = item % (rank + 1);
    gamma_texels_t texels = gamma_texels_of(epipolar);
    global const float4* row = rectified + (size_t)slice * n;
    global const float* gamma = gamma_basis + ((size_t)channel * rank + max(term - 1, 0)) * n;
    global float* out = prefix + (((size_t)slice * 3 + channel) * (rank + 1) + term) * (n + 1);
    float sum = 0.0f, compensation = 0.0f;
    out[0] = 0.0f;
    for (int k = 0; k < n; ++k) {
        float4 t = row[k];
        float texel = channel == 0 ? t.x : (channel == 1 ? t.y : t.z);
        float value = gamma_texel_width(texels, k) * texel * (term == 0 ? 1.0f : gamma[k]) - compensation;
        float next = sum + value;
        compensation = (next - sum) - value;
        sum = next;
        out[k + 1] = sum;
    }
}
