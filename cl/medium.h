/* medium.h — a medium that is not homogeneous (docs/media.md): where it is (a box) and how
 * dense (exp(-(y - base)/H), y up), and the closed forms that follow for a straight path:
 * its optical depth, so the transmittance towards the eye (T_e) and from a light (T_l).
 * Reads medium_t (common.h, eye space). Kernels include it only when built with MEDIUM_FIELD.
 *
 * The walk's per-ray prefix (medium_ray_t): in-scattering G(γ) at MEDIUM_NODES nodes evenly
 * spaced in the ray's γ over its part inside the box, the integrand exponential between nodes
 * (linear where a node's is 0), and a lit run [γ0, γ1) is G(γ1) − G(γ0). */
#ifndef CLRAYS_MEDIUM_H
#define CLRAYS_MEDIUM_H
#include "common.h"
#include "lighting.h"

/* Nodes of a ray's prefix (docs/media.md, "Precision"). */
#ifndef MEDIUM_NODES
#define MEDIUM_NODES 64
#endif

/* The height density's exponent is capped: e^80 stays finite in float32, so density·T is
 * never ∞·0 far below the base (T is 0 there anyway). */
#define MEDIUM_EXPONENT_MAX 80.0f

/* A ray's prefix ends where the least attenuated channel's optical depth from the eye reaches
 * this: beyond, what scatters towards the eye is under e^-12 = 6e-6 of what it would be
 * unattenuated, and the nodes go where the light still is (docs/media.md, "Precision"). */
#define MEDIUM_DEPTH_MAX 12.0f

/* The density factor at eye-space height y, box not tested. */
inline float medium_height_density(global const medium_t* m, float y)
{
    if (!(m->inv_scale_height > 0.0f)) return 1.0f;
    return exp(fmin(-(y - m->height_base) * m->inv_scale_height, MEDIUM_EXPONENT_MAX));
}

/* The density factor at eye-space p: 0 outside the box. */
inline float medium_density(global const medium_t* m, float3 p)
{
    if (m->bounded && (any(isless(p, m->box_min.xyz)) || any(isgreater(p, m->box_max.xyz)))) return 0.0f;
    return medium_height_density(m, p.y);
}

/* [*t0, *t1] narrowed to the part of o + t·d inside the box (slabs); 0 where nothing is left.
 * An axis the ray runs parallel to keeps or empties the whole interval. */
inline int medium_clip(global const medium_t* m, float3 o, float3 d, float* t0, float* t1)
{
    if (!m->bounded) return *t1 > *t0;
    float lo = *t0, hi = *t1;
    float origin[3] = {o.x, o.y, o.z}, dir[3] = {d.x, d.y, d.z};
    float box_lo[3] = {m->box_min.x, m->box_min.y, m->box_min.z};
    float box_hi[3] = {m->box_max.x, m->box_max.y, m->box_max.z};
    for (int axis = 0; axis < 3; ++axis) {
        if (dir[axis] == 0.0f) {
            if (origin[axis] < box_lo[axis] || origin[axis] > box_hi[axis]) return 0;
            continue;
        }
        float inverse = 1.0f / dir[axis];
        float a = (box_lo[axis] - origin[axis]) * inverse, b = (box_hi[axis] - origin[axis]) * inverse;
        lo = fmax(lo, fmin(a, b));
        hi = fmin(hi, fmax(a, b));
    }
    *t0 = lo;
    *t1 = hi;
    return hi > lo;
}

/* Which faces of the box the ray from the eye along unit d up to `distance` enters and leaves
 * by (6: it starts or ends inside), as one code; -1 where it misses the box. Where two rays'
 * codes differ, an edge of the box's silhouette, or of its faces, lies between them: the
 * in-scattering has a kink there that interpolation between the rays would cut. */
inline int medium_faces(global const medium_t* m, float3 d, float distance)
{
    if (!m->bounded) return 0;
    float near = 0.0f, far = distance;
    int enter = 6, leave = 6;
    float dir[3] = {d.x, d.y, d.z};
    float box_lo[3] = {m->box_min.x, m->box_min.y, m->box_min.z};
    float box_hi[3] = {m->box_max.x, m->box_max.y, m->box_max.z};
    for (int axis = 0; axis < 3; ++axis) {
        if (dir[axis] == 0.0f) {
            if (box_lo[axis] > 0.0f || box_hi[axis] < 0.0f) return -1;
            continue;
        }
        float a = box_lo[axis] / dir[axis], b = box_hi[axis] / dir[axis];
        float lo = fmin(a, b), hi = fmax(a, b);
        if (lo > near) { near = lo; enter = 2 * axis + (dir[axis] < 0.0f); }
        if (hi < far) { far = hi; leave = 2 * axis + (dir[axis] > 0.0f); }
    }
    return far > near ? enter * 7 + leave : -1;
}

/* (1 − e^{−x})/x, → 1 as x → 0: the mean of e^{−x·u} over u ∈ [0, 1]. */
inline float medium_mean_exp(float x)
{
    return fabs(x) < 1e-4f ? 1.0f - 0.5f * x : -expm1(-x) / x;
}

/* ∫ density(o + t·d) dt over t ∈ [t0, t1] (d unit; t1 may be +∞): the optical depth per unit
 * σt. Exact for the box and the height density: with ρ(y) = e^{−(y − base)/H} and y = o_y + t·d_y,
 * the integral over a clipped [a, b] is ρ(y(a))·(b − a)·(1 − e^{−x})/x, x = (b − a)·d_y/H. An
 * unbounded path that does not climb out of the height density (d_y ≤ 0) has infinite depth;
 * one through a medium without density or bounds has none (a light at infinity in a
 * homogeneous medium is not attenuated: docs/design.md §1). */
inline float medium_depth(global const medium_t* m, float3 o, float3 d, float t0, float t1)
{
    if (!medium_clip(m, o, d, &t0, &t1)) return 0.0f;
    float k = m->inv_scale_height;
    if (isinf(t1)) {
        if (!(k > 0.0f)) return 0.0f;
        return d.y > 0.0f ? medium_height_density(m, o.y + t0 * d.y) / (d.y * k) : INFINITY;
    }
    float length = t1 - t0;
    if (!(k > 0.0f)) return length;
    return medium_height_density(m, o.y + t0 * d.y) * length * medium_mean_exp(length * d.y * k);
}

/* T_l at eye-space p of a light at eye-space `source` (point, spot) or towards unit `source`
 * (directional), per channel. */
inline float3 medium_light_transmittance(global const medium_t* m, int directional, float3 source, float3 sigma_t,
                                         float3 p)
{
    if (directional) return exp(-sigma_t * medium_depth(m, p, source, 0.0f, INFINITY));
    float3 w = source - p;
    float d = length(w);
    return d > 0.0f ? exp(-sigma_t * medium_depth(m, p, w / d, 0.0f, d)) : (float3)(1.0f);
}

/* medium_light_transmittance of a light_t (shade). */
inline float3 medium_light_through(global const medium_t* m, global const light_t* light, float3 sigma_t, float3 p)
{
    int directional = light->type == LIGHT_DIRECTIONAL;
    return medium_light_transmittance(m, directional, directional ? -light->direction.xyz : light->position.xyz,
                                      sigma_t, p);
}

/* T_e: the transmittance from the eye-space origin o along unit d to distance t. */
inline float3 medium_eye_transmittance(global const medium_t* m, float3 sigma_t, float3 o, float3 d, float t)
{
    return exp(-sigma_t * medium_depth(m, o, d, 0.0f, t));
}

/* ∫_0^t of the integrand between nodes of values a and b, in units of the step: a·(b/a)^u
 * integrated, a·t·(e^{qt} − 1)/(qt) with q = ln(b/a), exact where the integrand is exponential
 * (attenuation: docs/media.md); linear where either is 0. t = 1 gives the whole interval. */
inline float3 medium_interval_part(float3 a, float3 b, float t)
{
    int3 positive = isgreater(a, (float3)(0.0f)) & isgreater(b, (float3)(0.0f));
    float3 qt = select((float3)(0.0f), log(b / a) * t, positive);
    float3 ratio = select(expm1(qt) / qt, 1.0f + 0.5f * qt, isless(fabs(qt), (float3)(1e-4f)));
    float3 linear = t * (a + (0.5f * t) * (b - a));
    return select(linear, a * t * ratio, positive);
}

/* One camera ray's in-scattering prefix in its light's γ (docs/media.md, "The walk"):
 * f the integrand per unit γ at the nodes, g = G its prefix, nodes evenly spaced over
 * [gamma_in, gamma_out], the γ of the ray's part inside the box. */
typedef struct {
    float gamma_in;
    float gamma_out;
    float step;       /* (gamma_out − gamma_in)/(MEDIUM_NODES − 1), 0: an empty ray */
    float inv_step;
    float3 f[MEDIUM_NODES];
    float3 g[MEDIUM_NODES];
    /* A sun over height fog that fills all space: runs in closed form (medium_sun_segment),
     * no nodes. */
    int sun_closed_form;
    global const medium_t* medium;
    float3 dir;
    float3 sigma_t;
    float3 sun_scale; /* σs·E·ρ(cosβ) */
    float sun_slope;  /* c = 1 − d_y/ℓ_y: d(τ_e + τ_l)/ds = density·c */
    float sin_beta;
    float3 medium_light; /* ℓ, the unit direction towards the sun */
} medium_ray_t;

/* (1 − e^{−x})/x per channel, → 1 as x → 0. */
inline float3 medium_mean_exp3(float3 x)
{
    return select(-expm1(-x) / x, 1.0f - 0.5f * x, isless(fabs(x), (float3)(1e-4f)));
}

/* A run [s0, s1] of a sun's ray through height fog that fills all space (docs/media.md, "A
 * sun over height fog"): with Φ = τ_e + τ_l, dΦ/ds = density·c, so ∫ σs·E·ρ·density·e^{−σt·Φ} ds
 * = σs·E·ρ·e^{−σt·Φ(s0)}·Δτ·(1 − e^{−σt·c·Δτ})/(σt·c·Δτ), Δτ the density's integral over the
 * run: the α·ℓ_y/(ℓ_y − d_y)·[T_eT_l(s0) − T_eT_l(s1)] of the closed form, finite as d_y → ℓ_y. */
inline float3 medium_sun_segment(const medium_ray_t* ray, float gamma0, float gamma1)
{
    global const medium_t* m = ray->medium;
    float s0 = fmax(gamma0, 0.0f) / ray->sin_beta, s1 = fmax(gamma1, 0.0f) / ray->sin_beta;
    float3 x0 = s0 * ray->dir;
    float phi0 = medium_depth(m, (float3)(0.0f), ray->dir, 0.0f, s0) + medium_depth(m, x0, ray->medium_light, 0.0f, INFINITY);
    float run = medium_depth(m, (float3)(0.0f), ray->dir, s0, s1);
    return ray->sun_scale * exp(-ray->sigma_t * phi0) * run * medium_mean_exp3(ray->sigma_t * (ray->sun_slope * run));
}

/* Distance along the ray of angle β (sin, cos) to the eye–light axis at light angle γ:
 * s = d_el·sinγ/sin(β + γ) (point, spot; docs/design.md §2), s = γ/sinβ (directional). */
inline float medium_ray_distance(int directional, float d_el, float sin_beta, float cos_beta, float gamma)
{
    if (directional) return gamma / sin_beta;
    float sin_gamma = sin(gamma), cos_gamma = cos(gamma);
    float sin_sum = sin_beta * cos_gamma + cos_beta * sin_gamma;
    return sin_sum > 0.0f ? d_el * sin_gamma / sin_sum : INFINITY;
}

inline float medium_ray_gamma(int directional, float d_el, float sin_beta, float cos_beta, float s)
{
    return directional ? s * sin_beta : atan2(s * sin_beta, d_el - s * cos_beta);
}

/* Build the prefix of the camera ray along unit dir (eye space, from the eye at the origin)
 * up to `distance`, for the light of epipolar frame ep (at ep->axis·d_el, or towards ep->axis
 * for a directional light). amplitude: σs·I or σs·E (integrand_t).
 * The integrand per unit γ is the homogeneous one (docs/integrand.md) with e^{−σt(s + r)}
 * replaced by density·T_e·T_l:
 *   point/spot   σs·I·ρ(cos(β+γ))·density·T_e·T_l / (d_el·sinβ)
 *   directional  σs·E·ρ(cosβ)·density·T_e·T_l / sinβ */
inline void medium_ray_build(global const medium_t* m, global const frame_t* frame, global const epipolar_t* ep,
                             int directional, float3 amplitude, float3 dir, float distance, float sin_beta,
                             float cos_beta, medium_ray_t* ray)
{
    float s_in = 0.0f, s_out = distance;
    float3 sigma_t = frame->sigma_t.xyz;
    ray->step = 0.0f;
    ray->gamma_in = ray->gamma_out = 0.0f;
    ray->sun_closed_form = directional && !m->bounded && m->inv_scale_height > 0.0f;
    if (ray->sun_closed_form) {
        ray->medium = m;
        ray->dir = dir;
        ray->sigma_t = sigma_t;
        ray->sin_beta = sin_beta;
        ray->medium_light = ep->axis.xyz;
        /* a sun at or below the horizon reaches no fog that fills the space below it */
        ray->sun_scale = ep->axis.y > 0.0f ? amplitude * phase_function(frame, cos_beta) : (float3)(0.0f);
        ray->sun_slope = ep->axis.y > 0.0f ? 1.0f - dir.y / ep->axis.y : 0.0f;
        return;
    }
    if (!medium_clip(m, (float3)(0.0f), dir, &s_in, &s_out)) return;
    float sigma_least = fmin(fmin(sigma_t.x, sigma_t.y), sigma_t.z);
    if (sigma_least * medium_depth(m, (float3)(0.0f), dir, 0.0f, s_out) > MEDIUM_DEPTH_MAX) {
        float lo = s_in, hi = s_out; /* bisection: the depth grows with s */
        for (int i = 0; i < 24; ++i) {
            float mid = 0.5f * (lo + hi);
            if (sigma_least * medium_depth(m, (float3)(0.0f), dir, 0.0f, mid) > MEDIUM_DEPTH_MAX) hi = mid;
            else lo = mid;
        }
        s_out = hi;
    }
    float d_el = ep->d_el;
    float3 source = directional ? ep->axis.xyz : ep->axis.xyz * d_el;
    ray->gamma_in = medium_ray_gamma(directional, d_el, sin_beta, cos_beta, s_in);
    ray->gamma_out = medium_ray_gamma(directional, d_el, sin_beta, cos_beta, s_out);
    if (!(ray->gamma_out > ray->gamma_in)) return;
    ray->step = (ray->gamma_out - ray->gamma_in) / (float)(MEDIUM_NODES - 1);
    ray->inv_step = 1.0f / ray->step;
    float3 scale = amplitude / (directional ? sin_beta : d_el * sin_beta);
    float3 previous = (float3)(0.0f);
    for (int k = 0; k < MEDIUM_NODES; ++k) {
        float gamma = k == MEDIUM_NODES - 1 ? ray->gamma_out : ray->gamma_in + (float)k * ray->step;
        float s = k == 0 ? s_in : (k == MEDIUM_NODES - 1 ? s_out
                                   : clamp(medium_ray_distance(directional, d_el, sin_beta, cos_beta, gamma), s_in, s_out));
        float3 x = s * dir;
        /* cosθ between the light's propagation and the way to the eye (docs/integrand.md) */
        float cos_theta = directional ? cos_beta : cos_beta * cos(gamma) - sin_beta * sin(gamma);
        float3 through = medium_eye_transmittance(m, sigma_t, (float3)(0.0f), dir, s)
                       * medium_light_transmittance(m, directional, source, sigma_t, x);
        /* nodes lie in the box by construction: its faces are not tested again */
        float3 f = scale * (phase_function(frame, cos_theta) * medium_height_density(m, x.y)) * through;
        ray->f[k] = f;
        ray->g[k] = k == 0 ? (float3)(0.0f) : ray->g[k - 1] + ray->step * medium_interval_part(previous, f, 1.0f);
        previous = f;
    }
}

/* G(γ): 0 before the box, the whole ray's after it, medium_interval_part between nodes. */
inline float3 medium_ray_prefix(const medium_ray_t* ray, float gamma)
{
    if (!(gamma > ray->gamma_in)) return (float3)(0.0f);
    if (!(gamma < ray->gamma_out)) return ray->g[MEDIUM_NODES - 1];
    float u = (gamma - ray->gamma_in) * ray->inv_step;
    int k = min((int)u, MEDIUM_NODES - 2);
    return ray->g[k] + ray->step * medium_interval_part(ray->f[k], ray->f[k + 1], u - (float)k);
}

/* A lit run's in-scattering, [γ0, γ1) of the ray. */
inline float3 medium_ray_segment(const medium_ray_t* ray, float gamma0, float gamma1)
{
    if (!(gamma1 > gamma0)) return (float3)(0.0f);
    if (ray->sun_closed_form) return medium_sun_segment(ray, gamma0, gamma1);
    if (!(ray->step > 0.0f)) return (float3)(0.0f);
    return medium_ray_prefix(ray, gamma1) - medium_ray_prefix(ray, gamma0);
}

#endif
