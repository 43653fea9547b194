/* light_texture.h — a light's texture on the device (docs/light-textures.md): the bilinear
 * texel of the light ray through a point (raymarch, shade, light_texture_prefix), and the
 * radiance of a lit run of a textured light from the rectified prefix sums (traverse).
 * clrays/reference/light_texture.py is the same lookup on the host. */
#ifndef CLRAYS_LIGHT_TEXTURE_H
#define CLRAYS_LIGHT_TEXTURE_H
#include "gamma_texels.h"
#include "integrand.h"

/* The texels a and b = a + 1 along a side of n texels either side of the integer-valued
 * coordinate x0, wrapped (repeat) or clamped. The wrap is float arithmetic, exact while
 * |x0| < 2^24 (and in range beyond), and only for x0 outside [0, n): an integer division
 * per texel (four per lookup) made the rectified texture's lookups several times slower on
 * PoCL, and the float wrap of every lookup was still 30 % of light_texture_prefix's time. */
inline void texel_pair(float x0, int n, int wrap, int* a, int* b)
{
    if (wrap == TEXTURE_WRAP_REPEAT) {
        float side = (float)n;
        if (x0 < 0.0f || x0 >= side) { /* (coordinates wrapped once per γ cell skip this) */
            x0 -= side * floor(x0 * (1.0f / side)); /* (a reciprocal, hoisted out of a loop of lookups) */
            x0 = x0 < 0.0f ? x0 + side : (x0 >= side ? x0 - side : x0); /* the quotient rounded up or down */
        }
        *a = clamp((int)x0, 0, n - 1);
        *b = *a + 1 < n ? *a + 1 : 0;
    } else {
        int i = (int)x0;
        *a = clamp(i, 0, n - 1);
        *b = clamp(i + 1, 0, n - 1);
    }
}

/* Bilinear between the texel centres of the w × h texels t at texel coordinates (fx, fy)
 * (texel i's centre at i), wrapped or clamped at the sides. */
inline float3 texture_bilinear(global const float4* t, int w, int h, int wrap, float fx, float fy)
{
    /* Clamped so that the int conversion below stays defined far outside the image. */
    fx = clamp(fx, -1e9f, 1e9f);
    fy = clamp(fy, -1e9f, 1e9f);
    float x0 = floor(fx), y0 = floor(fy);
    float tx = fx - x0, ty = fy - y0;
    int xa, xb, ya, yb;
    texel_pair(x0, w, wrap, &xa, &xb);
    texel_pair(y0, h, wrap, &ya, &yb);
    float3 top = mix(t[ya * w + xa].xyz, t[ya * w + xb].xyz, tx);
    float3 bottom = mix(t[yb * w + xa].xyz, t[yb * w + xb].xyz, tx);
    return mix(top, bottom, ty);
}

/* The texture's factor on the light that reaches p (eye space): 1 for an untextured light,
 * 0 behind a spot light. Texel centres at i + ½, bilinear between them (within a cube
 * face, clamped at its edges). */
inline float3 light_texture(global const light_texture_t* texture, global const float4* texels,
                            global const light_t* light, float3 p)
{
    if (!texture->textured) return (float3)(1.0f);
    float sx, sy;
    int w = texture->width, h = texture->height;
    global const float4* t = texels + texture->first_texel;
    if (light->type == LIGHT_POINT) {
        /* A cube: the face of the major axis (as light_view_index), seen from the light along
         * F with up U and right F × U (+x, -x, +y, -y, +z, -z as the cube shadow map's faces);
         * six faces of w × w stacked in rows. */
        float3 d = p - light->position.xyz, a = fabs(d);
        int axis = (a.x >= a.y && a.x >= a.z) ? 0 : (a.y >= a.z ? 1 : 2);
        float major = axis == 0 ? d.x : (axis == 1 ? d.y : d.z);
        int face = 2 * axis + (major < 0.0f ? 1 : 0);
        float3 forward = (float3)(axis == 0, axis == 1, axis == 2) * (major < 0.0f ? -1.0f : 1.0f);
        float3 up = axis == 1 ? (float3)(0.0f, 0.0f, 1.0f) : (float3)(0.0f, 1.0f, 0.0f);
        float along = dot(d, forward);
        if (!(along > 0.0f)) return (float3)(0.0f);
        sx = dot(d, cross(forward, up)) / along;
        sy = dot(d, up) / along;
        h = w;
        t += face * w * w;
    } else if (light->type == LIGHT_DIRECTIONAL) {
        float3 q = p - texture->origin.xyz;
        sx = 2.0f * dot(q, texture->right.xyz) * texture->scale_x;
        sy = 2.0f * dot(q, texture->up.xyz) * texture->scale_y;
    } else {
        float3 w = p - light->position.xyz;
        float along = dot(w, light->direction.xyz);
        if (!(along > 0.0f)) return (float3)(0.0f);
        sx = dot(w, texture->right.xyz) * texture->scale_x / along;
        sy = dot(w, texture->up.xyz) * texture->scale_y / along;
    }
    return texture_bilinear(t, w, h, texture->wrap, (sx + 1.0f) * 0.5f * (float)w - 0.5f,
                            (1.0f - sy) * 0.5f * (float)h - 0.5f);
}

/* One row's prefix sum at texel coordinate `cell` (gamma_texels.h): values at the cell
 * boundaries (n + 1 of them, `stride` floats apart), linear in between. */
inline float prefix_at(global const float* prefix, int stride, int n, float cell)
{
    int k = clamp((int)floor(cell), 0, n - 1);
    float f = clamp(cell - (float)k, 0.0f, 1.0f);
    return mix(prefix[(size_t)k * stride], prefix[(size_t)(k + 1) * stride], f);
}

/* Radiance of the lit run [gamma0, gamma1) of ray `ray` along one slice of a textured light
 * (docs/light-textures.md, minmax): with T̄ the texture's mean over the run,
 *
 *   L = T̄·L_untextured + (1/sinβ)·Σ_i B_i(β)·[∫T·Γ_i - T̄·∫Γ_i]
 *
 * L_untextured is the integrand stage's segment (any mode); the sum is the low-rank SVD's
 * estimate of ∫(T - T̄)·I, which vanishes for a constant texture, so the SVD's own error
 * only enters multiplied by the texture's variation within the run. row_prefix holds the
 * slice's prefix sums (cl/light_texture.cl): a record per cell boundary of
 * [channel][0..rank], term 0 of T alone, term i + 1 of T·Γ_i, so that a run's ends read
 * four records; basis holds B[channel][rank][n_beta], then ∫Γ as P[channel][rank][n + 1]. */
inline float3 textured_run_radiance(global const textured_integrand_t* ti, global const float* basis,
                                    global const float* row_prefix, gamma_texels_t texels, const integrand_row_t* ray,
                                    float3 untextured, float gamma0, float gamma1)
{
    int n = ti->gamma_samples, rank = ti->rank, record = 3 * (rank + 1);
    float c0 = gamma_texel_coord(texels, gamma0), c1 = gamma_texel_coord(texels, gamma1);
    float span = ti->beta_max - ti->beta_min;
    float row_t = 0.0f;
    int j = 0;
    if (span > 0.0f) {
        float lo = inline_sqrt(inline_clamp(ray->beta - ti->beta_min, 0.0f, span));
        float hi = inline_sqrt(inline_clamp(ti->beta_max - ray->beta, 0.0f, span));
        j = grid_split(M_2_PI_F * atan2_approx(lo, hi) * (float)(ti->n_beta - 1), ti->n_beta, &row_t);
    }
    size_t row_length = (size_t)(n + 1);
    float radiance[3];
    float base[3] = {untextured.x, untextured.y, untextured.z};
    for (int c = 0; c < 3; ++c) {
        global const float* q = row_prefix + (size_t)c * (rank + 1);
        /* The mean over the run; a run shorter than 1e-3 of a cell takes its cell's value. */
        int cell = clamp((int)c0, 0, n - 1);
        float mean = c1 - c0 > 1e-3f ? (prefix_at(q, record, n, c1) - prefix_at(q, record, n, c0)) / (gamma1 - gamma0)
                                     : (q[(size_t)(cell + 1) * record] - q[(size_t)cell * record])
                                           / gamma_texel_width(texels, cell);
        float correction = 0.0f;
        for (int i = 0; i < rank; ++i) {
            global const float* b = basis + ((size_t)c * rank + i) * ti->n_beta;
            global const float* p = basis + (size_t)3 * rank * ti->n_beta + ((size_t)c * rank + i) * row_length;
            global const float* qi = q + i + 1;
            float b_i = mix(b[j], b[j + 1], row_t);
            correction += b_i * ((prefix_at(qi, record, n, c1) - prefix_at(qi, record, n, c0))
                                 - mean * (prefix_at(p, 1, n, c1) - prefix_at(p, 1, n, c0)));
        }
        radiance[c] = mean * base[c] + correction / ray->sin_beta;
    }
    return (float3)(radiance[0], radiance[1], radiance[2]);
}

#endif
