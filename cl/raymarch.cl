/* raymarch — the brute-force reference: in-scattered radiance per camera sample by
 * `steps` samples per light from the eye to the surface (for a spot light, over the part
 * of the ray inside its cone), equiangular about a point or spot light or uniform
 * (STEP_SPACING, docs/design.md §4.8), optionally jittered, with a shadow-map lookup per
 * sample.
 * Reads frame, views, lights, shadow_depth, camera_depth, offsets, light_textures,
 * texels (a light's texture multiplies it per sample, docs/light-textures.md), with
 * translucent objects the translucency stage's layers (translucency.h), and in a bounded or
 * heterogeneous medium its density and optical depths (medium.h, docs/media.md); writes
 * scatter (one float4 per camera sample, rgb radiance). */
#include "light_texture.h"
#include "translucency.h"
#include "medium.h"

/* MBOIT's one march (transparency_walk.cl's, docs/design.md, the camera side): built with
 * TRANSPARENCY_WEIGHTED_WALK, the kernel marches only the samples with translucent films, up
 * to the farthest, each step weighted by T(t) − T(D) (mboit.h), into scatter. */
#ifdef TRANSPARENCY_WEIGHTED_WALK
#include "mboit.h"
#define WEIGHTED_WALK_ARGS , global const int* walk_samples, int walk_count, int slots, global const uint* film_depth, \
                           global const int* film_tri, global const float4* tri_opacity, float2 depth_range,       \
                           float moment_bias
#else
#define WEIGHTED_WALK_ARGS
#endif
#ifndef STEP_SPACING
#define STEP_SPACING STEP_SPACING_EQUIANGULAR
#endif

/* A per-ray number in [0, 1): jitter that is repeatable from run to run. */
inline float hash_unit(uint a)
{
    a ^= a >> 16; a *= 0x7feb352du; a ^= a >> 15; a *= 0x846ca68bu; a ^= a >> 16;
    return (float)(a >> 8) * (1.0f / 16777216.0f);
}

/* tan θ from (sin θ, cos θ); past ±π/2 (cos ≤ 0, the rotation's drift) ±∞, which the
 * caller clamps to the marched interval. */
inline float tan_of(float sin_theta, float cos_theta)
{
    return cos_theta > 0.0f ? sin_theta / cos_theta : copysign(INFINITY, sin_theta);
}

/* s + d(s) at s = t0 + x on a ray passing at distance h from the light: the light's path
 * from the eye through the medium (docs/design.md §1), d = √(h² + x²). */
inline float light_path(float t0, float h, float x)
{
    return t0 + x + sqrt(h * h + x * x);
}

/* ∫ e^{-k·v} dv over a step of length dt, per channel: (1 - e^{-k·dt})/k, → dt as k → 0.
 * Below k·dt = 1e-6 the limit is exact to 5e-7 and avoids 0/0 where k·dt underflows. */
inline float3 step_integral(float3 k, float dt)
{
    float3 kdt = k * dt;
    return select((float3)(dt), -expm1(-kdt) / k, isgreater(kdt, (float3)(1e-6f)));
}

kernel void raymarch(global const frame_t* frame, global const view_t* views,
                     global const light_t* lights, global const uint* shadow_depth,
                     global const uint* camera_depth, global const float2* offsets,
                     global const light_texture_t* light_textures, global const float4* texels,
                     global float4* scatter TRANSLUCENCY_ARGS MEDIUM_ARGS WEIGHTED_WALK_ARGS)
{
#ifdef TRANSPARENCY_WEIGHTED_WALK
    if ((int)get_global_id(0) >= walk_count) return;
    int sample = walk_samples[get_global_id(0)];
#else
    int sample = get_global_id(0);
#endif
    int pixel = sample / frame->spp;
    if (pixel >= frame->width * frame->height) return;
    int x = pixel % frame->width, y = pixel / frame->width;
    float3 origin, dir;
    view_ray(views, view_screen(views, x, y, offsets[sample % frame->spp]), &origin, &dir);
    float distance = fmin(as_float(camera_depth[sample]), frame->far);
#ifdef TRANSPARENCY_WEIGHTED_WALK /* behind the farthest film the fog's weight is 0 */
    film_moments_t films = film_moments(slots, frame->width * frame->height * frame->spp, sample, film_depth,
                                        film_tri, tri_opacity, depth_range);
    distance = films.farthest;
#endif

    float3 sigma_t = frame->sigma_t.xyz;
    float u = frame->jitter ? hash_unit((uint)sample * 0x9e3779b9u + 0x85ebca6bu) : 0.5f;
    float3 radiance = (float3)(0.0f);
    for (int l = 0; l < frame->light_count; ++l) {
#ifdef ONLY_LIGHT /* a render pass of one light's in-scattering (clrays/passes.py) */
        if (l != ONLY_LIGHT) continue;
#endif
        global const light_t* light = lights + l;
        /* A spot light is marched only inside its cone: the hard edge is then exact and
         * no step is spent where the light does not reach. */
        float begin = 0.0f, end = distance;
        if (light->type == LIGHT_SPOT && !spot_interval(light, dir, distance, &begin, &end)) continue;
        /* camera.near: the ray starts at t0 (lighting.h's camera_ray_start); shade scales what
         * it gathers by e^{σt·t0}. */
        if (frame->near_plane.w > 0.0f) {
            begin = fmax(begin, camera_ray_start(frame, dir));
            if (!(end > begin)) continue;
        }
#ifdef MEDIUM_VARYING /* and only where it meets medium: the box, the grid's bounds */
        if (!medium_extent(medium, origin, dir, &begin, &end)) continue;
#endif
        float dt = (end - begin) / (float)frame->steps;
        int directional = light->type == LIGHT_DIRECTIONAL;
        int unshadowed = eye_in_lamp(light, frame->lamp_radius);
#if STEP_SPACING == STEP_SPACING_EQUIANGULAR
        /* Equiangular steps (docs/design.md §4.8): with t0 the ray's closest point to the
         * light and h its distance, t = t0 + h·tan θ at equal steps Δθ over [begin, end],
         * so a step is d²/h · Δθ long (d² = h² + (t - t0)²): the 1/d² peak of a ray that
         * passes near the light is spread over many steps, each carrying about as much
         * light. h is at least the lamp's radius: no medium lies closer, and a ray through
         * the light stays finite. */
        float3 to_light_ws = light->position.xyz - origin;
        float t0 = dot(to_light_ws, dir);
        float h = fmax(length(to_light_ws - t0 * dir), frame->lamp_radius);
        /* The angle the interval subtends at the light, from the cross and dot products of
         * (h, begin - t0) and (h, end - t0): well conditioned where a difference of two atans
         * near ±π/2 is not (a ray looking away from the light, h ≪ |s - t0|). */
        float x_begin = begin - t0, x_end = end - t0;
        float theta_step = atan2(h * (end - begin), h * h + x_begin * x_end) / (float)frame->steps;
        /* (An interval too short for float θ to resolve is marched uniformly.) */
        int equiangular = !directional && h > 0.0f && theta_step > 0.0f;
        /* θ advances by rotating (cos θ, sin θ), not by a tan per step (which made the demo's
         * frame 15 % dearer on the CPU device); tan = sin/cos does not see the pair's norm
         * drift. `edge_*`: the step's start, from (h, begin - t0) itself; the sample lies
         * u·Δθ past it. */
        float step_cos, step_sin = sincos(theta_step, &step_cos);
        float jitter_cos, jitter_sin = sincos(u * theta_step, &jitter_cos);
        float edge_norm = 1.0f / hypot(h, x_begin);
        float edge_cos = h * edge_norm, edge_sin = x_begin * edge_norm;
        float path_end = light_path(t0, h, x_begin), path_begin, x;
#endif
#ifdef MEDIUM_VARYING
        /* The eye's optical depth ∫ρ to the sample: closed form for box and height fog; in a
         * grid, summed along the march (trapezoids between samples) from its value at `begin`. */
        float eye_depth = segment_depth(medium, density_grid, origin, dir, 0.0f, begin);
        float t_before = begin, rho_before = medium_density(medium, density_grid, origin + begin * dir);
#endif
        for (int i = 0; i < frame->steps; ++i) {
            float t = begin + ((float)i + u) * dt;
#if STEP_SPACING == STEP_SPACING_EQUIANGULAR
            if (equiangular) {
                t = clamp(t0 + h * tan_of(edge_sin * jitter_cos + edge_cos * jitter_sin,
                                          edge_cos * jitter_cos - edge_sin * jitter_sin), begin, end);
                x = t - t0;
                float next_cos = edge_cos * step_cos - edge_sin * step_sin;
                edge_sin = edge_sin * step_cos + edge_cos * step_sin;
                edge_cos = next_cos;
                /* The step's light path s + d at both ends, the last step's end exactly `end`. */
                path_begin = path_end;
                path_end = light_path(t0, h, i + 1 == frame->steps ? x_end
                                                 : clamp(h * tan_of(edge_sin, edge_cos), x_begin, x_end));
            }
#endif
            float3 p = origin + t * dir;
#ifdef MEDIUM_VARYING
            float rho = medium_density(medium, density_grid, p);
#ifdef MEDIUM_GRID
            eye_depth += 0.5f * (rho_before + rho) * (t - t_before);
            t_before = t;
            rho_before = rho;
#endif
            if (rho == 0.0f) continue;
#endif
            float d = directional ? 0.0f : length(p - light->position.xyz);
            if (!directional && d < frame->lamp_radius) continue; /* no medium in the lamp */
            float3 to_light;
            /* Unattenuated here: both exponentials are integrated over the step below. */
            float3 incident = light_incident(light, (float3)(0.0f), p, &to_light)
                              * light_texture(light_textures + l, texels, light, p);
            if (incident.x + incident.y + incident.z == 0.0f) continue;
            /* No depth bias: a sample in the medium is on no surface, so it cannot shadow
             * itself, and a bias would light a texel-thick layer behind every occluder. */
            float visible = unshadowed ? 1.0f : shadow_visibility(light, views, shadow_depth, p, 0.0f, 0);
            if (visible == 0.0f) continue;
#ifdef TRANSLUCENT_LAYERS /* through the translucent surfaces nearer the light (translucency.h) */
            incident *= light_transmittance(light, views, layer_depth, layer_clear, layer_stride, p, 0.0f);
#endif
            /* The light's path e^{-σt·(s + d(s))}, d the distance to the light (0 for a
             * directional light), is linear in s across the step to first order, with slope
             * σt·(1 + d'), d' = -to_light·dir: integrated exactly over [start, start + dt],
             * so a step longer than the mean free path (dense fog) still weighs right. */
            float3 weight;
#ifdef MEDIUM_VARYING
            /* In a varying medium, the midpoint rule: ρ·e^{-σt·(eye depth + light depth)} times the
             * step's length at the sample (ds/dθ·Δθ for an equiangular step). */
            float step_length = dt;
#if STEP_SPACING == STEP_SPACING_EQUIANGULAR
            if (equiangular) step_length = (h * h + x * x) / h * theta_step;
#endif
#ifndef MEDIUM_GRID
            eye_depth = segment_depth(medium, density_grid, origin, dir, 0.0f, t);
#endif
            weight = exp(-sigma_t * (eye_depth + light_path_depth(medium, density_grid, light_depth_grid, light, l, p)))
                     * (rho * step_length);
#else
#if STEP_SPACING == STEP_SPACING_EQUIANGULAR
            /* An equiangular step: ∫ e^{-σt·(s + d)} ds over it is (h² + x²)/h · ∫ e^{-σt·path(θ)} dθ
             * (ds/dθ; not d²/h, which differs where h was raised to the lamp's radius), the path
             * taken as linear in θ between its true values at the step's ends. Not the tangent
             * at the sample, as below: near θ = ±π/2 a step's length changes many times across
             * it, and the tangent's extrapolation would overflow. */
            if (equiangular) {
                weight = ((h * h + x * x) / h) * exp(-sigma_t * path_begin)
                         * step_integral(sigma_t * ((path_end - path_begin) / theta_step), theta_step);
            } else
#endif
            {
                float d_rate = directional ? 0.0f : -dot(to_light, dir);
                float path = t + d - (1.0f + d_rate) * u * dt;
                weight = exp(-sigma_t * path) * step_integral(sigma_t * (1.0f + d_rate), dt);
            }
#endif /* MEDIUM_VARYING */
#ifdef TRANSPARENCY_WEIGHTED_WALK
            weight *= fog_weight(&films, t, depth_range, moment_bias);
#endif
            /* cos θ = (light → p)·(p → eye) = to_light·dir */
            radiance += incident * weight * (visible * phase_function(frame, dot(to_light, dir)));
        }
    }
    scatter[sample] = (float4)(radiance * frame->sigma_s.xyz, 0.0f);
}
