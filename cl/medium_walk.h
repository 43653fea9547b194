/* medium_walk.h — the walk's lit runs in a bounded or heterogeneous medium (docs/media.md,
 * "The walk"): each camera ray gets its own prefix of in-scattering G(γ) in its light's γ, at
 * MEDIUM_NODES nodes evenly spaced over its part that meets the medium (medium_extent: the box,
 * the grid's bounds), the integrand exponential between nodes (linear where a node's is 0);
 * a lit run [γ0, γ1) is G(γ1) − G(γ0). Density and optical depths come from medium.h; a sun
 * over height fog that fills all space needs no nodes (medium_sun_segment).
 * Reads the medium (MEDIUM_ARGS) through the walk's features; built with MEDIUM_VARYING only. */
#ifndef CLRAYS_MEDIUM_WALK_H
#define CLRAYS_MEDIUM_WALK_H
#include "medium.h"
#include "lighting.h"

/* Nodes of a ray's prefix (docs/media.md, "Precision"); a grid's follow its voxels, set by the
 * host (clrays.stages.medium.walk_nodes). */
#ifndef MEDIUM_NODES
#define MEDIUM_NODES 32
#endif

/* A ray's prefix ends where the least attenuated channel's optical depth from the eye reaches
 * this: beyond, what scatters towards the eye is under e^-12 = 6e-6 of what it would be
 * unattenuated, and the nodes go where the light still is (docs/media.md, "Precision"). */
#define WALK_DEPTH_END 12.0f

/* The medium as a walk reads it (walk_features.h attaches it). */
typedef struct {
    global const medium_t* medium;
    global const float* density_grid;
    global const float* light_depth_grid;
    global const light_t* lights; /* the frame's lights: the walk's is ep->light_index */
} walk_medium_t;

/* ρ at a node, which lies in the medium's extent by construction: moved onto it first, so that
 * rounding does not put a node on a face of the box or the grid outside it (ρ = 0 there). */
inline float walk_density(const walk_medium_t* w, float3 x)
{
#ifdef MEDIUM_BOUNDED
    x = clamp(x, w->medium->box_min.xyz, w->medium->box_max.xyz);
#endif
#ifdef MEDIUM_GRID
    x = clamp(x, w->medium->grid_min.xyz, w->medium->grid_max.xyz);
#endif
    return medium_density(w->medium, w->density_grid, x);
}

/* Which faces of the box [lo, hi] the ray from the eye along unit d up to `distance` enters
 * and leaves by (6: it starts or ends inside), as one code; -1 where it misses the box. */
inline int box_faces(float3 box_lo, float3 box_hi, float3 d, float distance)
{
    float near = 0.0f, far = distance;
    int enter = 6, leave = 6;
    float dir[3] = {d.x, d.y, d.z}, lo[3] = {box_lo.x, box_lo.y, box_lo.z}, hi[3] = {box_hi.x, box_hi.y, box_hi.z};
    for (int axis = 0; axis < 3; ++axis) {
        if (dir[axis] == 0.0f) {
            if (lo[axis] > 0.0f || hi[axis] < 0.0f) return -1;
            continue;
        }
        float a = lo[axis] / dir[axis], b = hi[axis] / dir[axis];
        if (fmin(a, b) > near) { near = fmin(a, b); enter = 2 * axis + (dir[axis] < 0.0f); }
        if (fmax(a, b) < far) { far = fmax(a, b); leave = 2 * axis + (dir[axis] > 0.0f); }
    }
    return far > near ? enter * 7 + leave : -1;
}

/* The faces of the box and of the grid's bounds a ray crosses (box_faces), as one code. Where
 * two rays' codes differ an edge of a silhouette, or of a face, lies between them: the density
 * breaks there, and the in-scattering has a kink that interpolating between the rays would cut. */
inline int medium_faces(global const medium_t* m, float3 d, float distance)
{
    int code = 0;
#ifdef MEDIUM_BOUNDED
    code = box_faces(m->box_min.xyz, m->box_max.xyz, d, distance) + 1;
#endif
#ifdef MEDIUM_GRID
    code = code * 64 + box_faces(m->grid_min.xyz, m->grid_max.xyz, d, distance) + 1;
#endif
    return code;
}

/* (1 − e^{−x})/x per channel, → 1 as x → 0. */
inline float3 mean_exp3(float3 x)
{
    return select(-expm1(-x) / x, 1.0f - 0.5f * x, isless(fabs(x), (float3)(1e-4f)));
}

/* ∫_0^t of the integrand between nodes of values a and b, in units of the step: a·(b/a)^u
 * integrated, a·t·(e^{qt} − 1)/(qt) with q = ln(b/a), exact where the integrand is exponential
 * (attenuation: docs/media.md); linear where either is 0. t = 1 gives the whole interval.
 * `grey`: the channels are in proportion, and share one ratio (their sums'). */
inline float3 medium_interval_part(float3 a, float3 b, float t, int grey)
{
    if (grey) { /* the channels in proportion (one σt): one ratio b/a for all three */
        float a_sum = a.x + a.y + a.z, b_sum = b.x + b.y + b.z;
        if (!(a_sum > 0.0f && b_sum > 0.0f)) return t * (a + (0.5f * t) * (b - a));
        float qt = log(b_sum / a_sum) * t;
        return a * (t * (fabs(qt) < 1e-4f ? 1.0f + 0.5f * qt : expm1(qt) / qt));
    }
    int3 positive = isgreater(a, (float3)(0.0f)) & isgreater(b, (float3)(0.0f));
    float3 qt = select((float3)(0.0f), log(b / a) * t, positive);
    float3 ratio = select(expm1(qt) / qt, 1.0f + 0.5f * qt, isless(fabs(qt), (float3)(1e-4f)));
    float3 linear = t * (a + (0.5f * t) * (b - a));
    return select(linear, a * t * ratio, positive);
}

/* One camera ray's in-scattering prefix in its light's γ: at rising nodes gamma[k] over the
 * γ of the ray's part that meets the medium (up to WALK_DEPTH_END), f the integrand per unit
 * γ and g = G its prefix. */
/* What a ray's prefix is built from: kept until its first lit run asks for it, so that a ray
 * in shadow all along builds none. */
typedef struct {
    walk_medium_t where;
    global const frame_t* frame;
    global const epipolar_t* ep;
    int directional;
    float3 amplitude;
    float3 dir;
    float distance;
    float sin_beta;
    float cos_beta;
} medium_ray_source_t;

typedef struct {
    int built; /* 0: only `source` is set */
    medium_ray_source_t source;
    int nodes; /* MEDIUM_NODES, or 0: the ray meets no medium */
    int grey;  /* one σt in every channel: the nodes' f in proportion, one exponential for T */
    float gamma[MEDIUM_NODES];
    float3 f[MEDIUM_NODES];
    float3 g[MEDIUM_NODES];
#if defined(MEDIUM_HEIGHT) && !defined(MEDIUM_BOUNDED) && !defined(MEDIUM_GRID)
    /* A sun over height fog that fills all space: runs in closed form (medium_sun_segment). */
    int sun_closed_form;
    global const medium_t* medium;
    float3 dir;
    float3 towards_sun; /* ℓ */
    float3 sigma_t;
    float3 sun_scale;   /* σs·E·ρ(cosβ), 0 for a sun at or below the horizon */
    float sun_slope;    /* c = 1 − d_y/ℓ_y: d(τ_e + τ_l)/ds = density·c */
    float sin_beta;
#define WALK_SUN_CLOSED_FORM 1
#endif
} medium_ray_t;

#ifdef WALK_SUN_CLOSED_FORM
/* A run of a sun's ray through height fog that fills all space (docs/media.md, "A sun over
 * height fog"): with Φ = τ_e + τ_l, dΦ/ds = density·c, so over [s0, s1]
 *   ∫ σs·E·ρ·density·e^{−σt·Φ} ds = σs·E·ρ·e^{−σt·Φ(s0)}·Δτ·(1 − e^{−σt·c·Δτ})/(σt·c·Δτ),
 * Δτ the density's integral over the run: the α·ℓ_y/(ℓ_y − d_y)·[T_eT_l(s0) − T_eT_l(s1)] of the
 * closed form, and finite as d_y → ℓ_y (c → 0). */
inline float3 medium_sun_segment(const medium_ray_t* ray, float gamma0, float gamma1)
{
    global const medium_t* m = ray->medium;
    float s0 = fmax(gamma0, 0.0f) / ray->sin_beta, s1 = fmax(gamma1, 0.0f) / ray->sin_beta;
    float phi0 = segment_depth(m, 0, (float3)(0.0f), ray->dir, 0.0f, s0)
               + segment_depth(m, 0, s0 * ray->dir, ray->towards_sun, 0.0f, INFINITY);
    float run = segment_depth(m, 0, (float3)(0.0f), ray->dir, s0, s1);
    return ray->sun_scale * exp(-ray->sigma_t * phi0) * run * mean_exp3(ray->sigma_t * (ray->sun_slope * run));
}
#endif

/* Distance along the ray of angle β (sin, cos) to the eye–light axis at light angle γ:
 * s = d_el·sinγ/sin(β + γ) (point, spot; docs/design.md §2), s = γ/sinβ (directional). */
inline float walk_distance(int directional, float d_el, float sin_beta, float cos_beta, float gamma)
{
    if (directional) return gamma / sin_beta;
    float cos_gamma, sin_gamma = sincos(gamma, &cos_gamma);
    float sin_sum = sin_beta * cos_gamma + cos_beta * sin_gamma;
    return sin_sum > 0.0f ? d_el * sin_gamma / sin_sum : INFINITY;
}

/* γ of distance s along that ray: walk.h's ray_span. */
inline float walk_gamma(int directional, float d_el, float sin_beta, float cos_beta, float s)
{
    return directional ? s * sin_beta : atan2(s * sin_beta, d_el - s * cos_beta);
}

/* Build the prefix of the camera ray along unit dir (eye space, from the eye at the origin)
 * up to `distance`, for the light of epipolar frame ep. amplitude: σs·I or σs·E (integrand_t).
 * The integrand per unit γ is the homogeneous one (docs/integrand.md) with e^{−σt(s + r)}
 * replaced by density·T_e·T_l:
 *   point/spot   σs·I·ρ(cos(β+γ))·density·T_e·T_l / (d_el·sinβ)
 *   directional  σs·E·ρ(cosβ)·density·T_e·T_l / sinβ
 * The nodes of a point or spot light's ray: half evenly spaced in γ, which follow the light's
 * falloff and phase near it, half in distance, which follow the density and the attenuation
 * where the ray runs away from the light (γ squeezes that part), merged in order; a
 * directional light's γ is the distance (times sinβ), so all of them evenly spaced.
 * T_e sums the optical depth node to node (in a grid, a lookup in the eye's optical-depth
 * grid); T_l is medium.h's light_path_depth (closed form, or the light's optical-depth grid). */
inline void medium_ray_build(const walk_medium_t* w, global const frame_t* frame, global const epipolar_t* ep,
                             int directional, float3 amplitude, float3 dir, float distance, float sin_beta,
                             float cos_beta, medium_ray_t* ray)
{
    global const medium_t* m = w->medium;
    float s_in = 0.0f, s_out = distance;
    float3 sigma_t = frame->sigma_t.xyz;
    ray->nodes = 0;
    ray->grey = sigma_t.x == sigma_t.y && sigma_t.x == sigma_t.z;
#ifdef WALK_SUN_CLOSED_FORM
    ray->sun_closed_form = directional;
    if (directional) {
        ray->medium = m;
        ray->dir = dir;
        ray->towards_sun = ep->axis.xyz;
        ray->sigma_t = sigma_t;
        ray->sin_beta = sin_beta;
        int above = ep->axis.y > 0.0f; /* a sun at or below the horizon reaches no fog below it */
        ray->sun_scale = above ? amplitude * phase_function(frame, cos_beta) : (float3)(0.0f);
        ray->sun_slope = above ? 1.0f - dir.y / ep->axis.y : 0.0f;
        return;
    }
#endif
    if (!medium_extent(m, (float3)(0.0f), dir, &s_in, &s_out)) return;
    float sigma_least = fmin(fmin(sigma_t.x, sigma_t.y), sigma_t.z);
#ifndef MEDIUM_GRID /* (a grid's depth is a march: its rays keep their whole extent) */
    if (sigma_least * segment_depth(m, w->density_grid, (float3)(0.0f), dir, s_in, s_out) > WALK_DEPTH_END) {
        float lo = s_in, hi = s_out; /* bisection: the depth grows with s */
        for (int i = 0; i < 24; ++i) {
            float mid = 0.5f * (lo + hi);
            if (sigma_least * segment_depth(m, w->density_grid, (float3)(0.0f), dir, s_in, mid) > WALK_DEPTH_END)
                hi = mid;
            else
                lo = mid;
        }
        s_out = hi;
    }
#endif
    float d_el = ep->d_el;
    float gamma_in = walk_gamma(directional, d_el, sin_beta, cos_beta, s_in);
    float gamma_out = walk_gamma(directional, d_el, sin_beta, cos_beta, s_out);
    if (!(gamma_out > gamma_in)) return;
    ray->nodes = MEDIUM_NODES;
    int even_gamma = directional ? MEDIUM_NODES : MEDIUM_NODES / 2 + 1; /* with both ends */
    int even_s = MEDIUM_NODES - even_gamma;                               /* between the ends */
    float gamma_step = (gamma_out - gamma_in) / (float)(even_gamma - 1);
    float s_step = (s_out - s_in) / (float)(even_s + 1);
    float3 scale = amplitude / (directional ? sin_beta : d_el * sin_beta);
    float eye_depth = segment_depth(m, w->density_grid, (float3)(0.0f), dir, 0.0f, s_in), s_before = s_in;
    int next_gamma = 1, next_s = 1; /* the first node is the entry: (gamma_in, s_in) */
    float gamma = gamma_in, s = s_in;
    for (int k = 0; k < MEDIUM_NODES; ++k) {
        if (k > 0) { /* the nearer of the next node evenly spaced in γ and the next in s */
            float gamma_a = next_gamma == even_gamma - 1 ? gamma_out : gamma_in + (float)next_gamma * gamma_step;
            float s_a = next_gamma == even_gamma - 1 ? s_out : walk_distance(directional, d_el, sin_beta, cos_beta, gamma_a);
            float s_b = next_s <= even_s ? s_in + (float)next_s * s_step : INFINITY;
            if (s_b < s_a) {
                s = s_b;
                gamma = walk_gamma(directional, d_el, sin_beta, cos_beta, s_b);
                ++next_s;
            } else {
                s = s_a;
                gamma = gamma_a;
                ++next_gamma;
            }
            s = clamp(s, s_before, s_out);
            gamma = clamp(gamma, ray->gamma[k - 1], gamma_out); /* rising, whatever the rounding */
        }
#ifdef MEDIUM_GRID /* one lookup in the eye's optical-depth grid, not a march node to node */
        eye_depth = eye_path_depth(m, w->density_grid, w->light_depth_grid, (float3)(0.0f), dir, s);
#else
        eye_depth += segment_depth(m, w->density_grid, (float3)(0.0f), dir, s_before, s);
#endif
        s_before = s;
        float3 x = s * dir;
        float density = walk_density(w, x);
        float3 f = (float3)(0.0f);
        if (density > 0.0f) {
            /* cosθ between the light's propagation and the way to the eye (docs/integrand.md) */
            float cos_gamma, sin_gamma = sincos(gamma, &cos_gamma);
            float cos_theta = directional ? cos_beta : cos_beta * cos_gamma - sin_beta * sin_gamma;
            float light_depth = light_path_depth(w->medium, w->density_grid, w->light_depth_grid,
                                                 w->lights + ep->light_index, ep->light_index, x);
            float depth = eye_depth + light_depth;
            float3 through = ray->grey ? (float3)(exp(-sigma_t.x * depth)) : exp(-sigma_t * depth);
            f = scale * (phase_function(frame, cos_theta) * density) * through;
        }
        ray->gamma[k] = gamma;
        ray->f[k] = f;
        ray->g[k] = k == 0 ? (float3)(0.0f)
                           : ray->g[k - 1] + (gamma - ray->gamma[k - 1]) * medium_interval_part(ray->f[k - 1], f, 1.0f, ray->grey);
    }
}

/* G(γ): 0 before the medium, the whole ray's after it, medium_interval_part between the nodes
 * around γ (a bisection). */
inline float3 medium_ray_prefix(const medium_ray_t* ray, float gamma)
{
    if (!(gamma > ray->gamma[0])) return (float3)(0.0f);
    if (!(gamma < ray->gamma[MEDIUM_NODES - 1])) return ray->g[MEDIUM_NODES - 1];
    int lo = 0, hi = MEDIUM_NODES - 1; /* gamma[lo] ≤ γ < gamma[hi] */
    while (hi - lo > 1) {
        int mid = (lo + hi) >> 1;
        if (ray->gamma[mid] <= gamma) lo = mid;
        else hi = mid;
    }
    float width = ray->gamma[hi] - ray->gamma[lo];
    float t = width > 0.0f ? (gamma - ray->gamma[lo]) / width : 0.0f;
    return ray->g[lo] + width * medium_interval_part(ray->f[lo], ray->f[hi], t, ray->grey);
}

/* A lit run's in-scattering, [γ0, γ1) of the ray; its first builds the ray's prefix. */
inline float3 medium_ray_segment(medium_ray_t* ray, float gamma0, float gamma1)
{
    if (!(gamma1 > gamma0)) return (float3)(0.0f);
    if (!ray->built) {
        const medium_ray_source_t* from = &ray->source;
        medium_ray_build(&from->where, from->frame, from->ep, from->directional, from->amplitude, from->dir,
                         from->distance, from->sin_beta, from->cos_beta, ray);
        ray->built = 1;
    }
#ifdef WALK_SUN_CLOSED_FORM
    if (ray->sun_closed_form) return medium_sun_segment(ray, gamma0, gamma1);
#endif
    if (!ray->nodes) return (float3)(0.0f);
    return medium_ray_prefix(ray, gamma1) - medium_ray_prefix(ray, gamma0);
}

#endif
