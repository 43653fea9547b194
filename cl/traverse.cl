/* traverse — in-scattered radiance per camera sample: walk the min-max tree of the
 * two slices nearest the sample's α over [0, γ_D), integrate the lit runs with the
 * integrand tables, blend the two slices (docs/design.md §4 "traverse").
 * Reads frame, views, lights, epipolar, tree, integrand, tables, camera_depth,
 * offsets, and for a textured light textured, texture_basis, texture_prefix
 * (docs/light-textures.md); adds into scatter (float4 per camera sample).
 *
 * TRAVERSAL_TREE walks the tree without a stack: a node whose min > β is wholly lit,
 * one whose max ≤ β wholly shadowed, else descend; after a node, move to the next
 * one and climb while its index is even. TRAVERSAL_SCAN reads every texel. */
#include "integrand.h"
#include "light_texture.h"
#include "minmax.h"

/* TRAVERSAL_TREE and TRAVERSAL_SCAN come from clrays/structs.py (-D). */
#ifndef TRAVERSAL
#define TRAVERSAL TRAVERSAL_TREE
#endif

/* A lit run's radiance: the integrand tables' segment, times the light's texture along
 * this row when it has one (light_texture.h). */
inline float3 run_radiance(global const integrand_t* in, global const float* tables, global const frame_t* frame,
                           const integrand_row_t* ray, global const textured_integrand_t* textured,
                           global const float* texture_basis, global const float* row_prefix, float gamma_step,
                           float gamma0, float gamma1)
{
    float3 untextured = segment_radiance(in, tables, frame, ray, gamma0, gamma1);
    if (!textured->textured || !(gamma1 > gamma0)) return untextured;
    return textured_run_radiance(textured, texture_basis, row_prefix, gamma_step, ray, untextured, gamma0, gamma1);
}

/* Radiance of the lit part of [gamma_begin, gamma_end) of ray beta along one row.
 * Adjacent lit nodes merge into one run, so the integrand is evaluated once per run.
 * row_prefix: this row's texture prefix sums (unread for an untextured light). */
inline float3 walk_row(global const epipolar_t* ep, global const float2* row, const integrand_row_t* ray,
                       float gamma_begin, float gamma_end, global const integrand_t* in,
                       global const float* tables, global const frame_t* frame,
                       global const textured_integrand_t* textured, global const float* texture_basis,
                       global const float* row_prefix)
{
    float beta = ray->beta;
    int n = ep->gamma_samples;
    int end = min(n, (int)ceil(gamma_end / ep->gamma_step));
    float3 radiance = (float3)(0.0f);
    int run_start = -1, run_end = 0;
    int position = clamp((int)floor(gamma_begin / ep->gamma_step), 0, n);
    while (position < end) {
        int size;
        int lit;
#if TRAVERSAL == TRAVERSAL_TREE
        /* The largest node starting at position: climb while the index is even. */
        int level = position == 0 ? ep->levels : min(ep->levels, 31 - clz(position & -position));
        for (;;) {
            float2 node = row[level_offset(n, level) + (position >> level)];
            if (node.x > beta) { lit = 1; break; }
            if (node.y <= beta) { lit = 0; break; }
            --level; /* mixed: descend to the left child */
        }
        size = 1 << level;
#else
        lit = row[position].x > beta;
        size = 1;
#endif
        if (lit) {
            if (run_start < 0) run_start = position;
            run_end = position + size;
        } else if (run_start >= 0) {
            radiance += run_radiance(in, tables, frame, ray, textured, texture_basis, row_prefix, ep->gamma_step,
                                     fmax(run_start * ep->gamma_step, gamma_begin),
                                     fmin(run_end * ep->gamma_step, gamma_end));
            run_start = -1;
        }
        position += size;
    }
    if (run_start >= 0)
        radiance += run_radiance(in, tables, frame, ray, textured, texture_basis, row_prefix, ep->gamma_step,
                                 fmax(run_start * ep->gamma_step, gamma_begin), fmin(run_end * ep->gamma_step, gamma_end));
    return radiance;
}

kernel void traverse(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                     global const epipolar_t* epipolar, global const float2* tree,
                     global const integrand_t* integrand, global const float* tables,
                     global const uint* camera_depth, global const float2* offsets,
                     global const textured_integrand_t* textured, global const float* texture_basis,
                     global const float* texture_prefix, global float4* scatter)
{
    int sample = get_global_id(0);
    if (sample >= frame->width * frame->height * frame->spp) return;
    global const epipolar_t* ep = epipolar;
    int pixel = sample / frame->spp;
    float3 origin, dir;
    view_ray(views, view_screen(views, pixel % frame->width, pixel / frame->width, offsets[sample % frame->spp]),
             &origin, &dir);
    float distance = fmin(as_float(camera_depth[sample]), frame->far);
    int light_type = lights[ep->light_index].type;

    float cos_beta = dot(dir, ep->axis.xyz);
    /* Clamped, not tested: a ray through a point light (β = 0) or straight away from a
     * light (β = π) has a finite integral, and the clamp gives it a γ extent of
     * SIN_BETA_MIN·s that the row coordinates resolve. β stays below float32(π), the S of
     * an unblocked light ray, so that the ray away from the light sees those as lit. */
    float sin_beta = fmax(length(cross(dir, ep->axis.xyz)), SIN_BETA_MIN);
    float beta = fmin(atan2(sin_beta, cos_beta), nextafter(M_PI_F, 0.0f));
    float begin = 0.0f, end = distance;
    if (light_type == LIGHT_SPOT && !spot_interval(lights + ep->light_index, dir, distance, &begin, &end))
        return; /* the ray never enters the cone */
    float gamma_begin = light_type == LIGHT_DIRECTIONAL ? begin * sin_beta
                                                        : atan2(begin * sin_beta, ep->d_el - begin * cos_beta);
    float gamma_end = light_type == LIGHT_DIRECTIONAL ? end * sin_beta
                                                      : atan2(end * sin_beta, ep->d_el - end * cos_beta);
    if (!(gamma_end > gamma_begin)) return; /* no extent in γ */
    /* The lamp (lighting.h): a ray that passes within its radius of a point or spot light
     * leaves out the chord inside it, [gamma_lamp0, gamma_lamp1), as exact does; this keeps
     * a ray through the light finite. For every other ray the chord is empty. */
    float gamma_lamp0 = gamma_end, gamma_lamp1 = gamma_end;
    float radius = frame->lamp_radius, miss = ep->d_el * sin_beta;
    if (light_type != LIGHT_DIRECTIONAL && miss < radius) {
        float closest = ep->d_el * cos_beta, half_chord = sqrt(radius * radius - miss * miss);
        float s0 = clamp(closest - half_chord, begin, end), s1 = clamp(closest + half_chord, begin, end);
        gamma_lamp0 = atan2(s0 * sin_beta, ep->d_el - s0 * cos_beta);
        gamma_lamp1 = atan2(s1 * sin_beta, ep->d_el - s1 * cos_beta);
    }

    /* Position between slice centres; wrap around when the slices close the circle. */
    float alpha = atan2(dot(dir, ep->w.xyz), dot(dir, ep->u.xyz));
    float offset = alpha - ep->alpha_min;
    offset -= 2.0f * M_PI_F * floor(offset / (2.0f * M_PI_F));
    /* A partial fan: angles in the gap before alpha_min count as negative offsets. */
    if (!ep->full_circle && offset > M_PI_F + 0.5f * ep->alpha_step * (float)ep->slices)
        offset -= 2.0f * M_PI_F;
    float f = offset / ep->alpha_step - 0.5f;
    int i0 = (int)floor(f);
    float t = f - (float)i0;
    int i1 = i0 + 1;
    if (ep->full_circle) {
        i0 = (i0 + ep->slices) % ep->slices;
        i1 = i1 % ep->slices;
    } else {
        i0 = clamp(i0, 0, ep->slices - 1);
        i1 = clamp(i1, 0, ep->slices - 1);
    }
    size_t stride = 2 * (size_t)ep->gamma_samples;
    integrand_row_t ray = integrand_row(integrand, beta, sin_beta, cos_beta);
    /* A textured light's prefix sums, one block per slice (light_texture.cl). */
    size_t prefix_stride = textured->textured ? (size_t)3 * (textured->rank + 1) * (ep->gamma_samples + 1) : 0;
    global const float* prefix0 = texture_prefix + i0 * prefix_stride;
    global const float* prefix1 = texture_prefix + i1 * prefix_stride;
    float3 near0 = walk_row(ep, tree + i0 * stride, &ray, gamma_begin, gamma_lamp0, integrand, tables, frame,
                            textured, texture_basis, prefix0);
    float3 near1 = walk_row(ep, tree + i1 * stride, &ray, gamma_begin, gamma_lamp0, integrand, tables, frame,
                            textured, texture_basis, prefix1);
    if (gamma_lamp1 < gamma_end) {
        near0 += walk_row(ep, tree + i0 * stride, &ray, gamma_lamp1, gamma_end, integrand, tables, frame,
                          textured, texture_basis, prefix0);
        near1 += walk_row(ep, tree + i1 * stride, &ray, gamma_lamp1, gamma_end, integrand, tables, frame,
                          textured, texture_basis, prefix1);
    }
    scatter[sample] += (float4)(mix(near0, near1, t), 0.0f);
}
