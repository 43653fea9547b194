/* rectify — the shadow map resampled into epipolar coordinates: for each slice α and
 * light angle γ, the view angle β of the light ray's blocker, S[α, γ] (docs/design.md §2, §3).
 * Reads views, lights, shadow_depth, epipolar, slice_sides, texel_angles; writes level 0
 * of the min-max tree (float2 (S, S) per texel). rectify_bounds reads camera_depth and reduces the
 * β and γ ranges the visible rays need (as pseudo-angles, see pseudo_angle).
 *
 *   tree row α: | level 0: N texels | level 1: N/2 | level 2: N/4 | ... | 1 | (float2 min, max)
 *               0                   N            3N/2                    2N-1 */
#include "lighting.h"
#include "atan2_approx.h"

#define PI_F 3.14159265358979f

/* Camera samples per rectify_bounds work-item (clrays/stages/rectify.py BOUNDS_CHUNK). */
#ifndef BOUNDS_CHUNK
#define BOUNDS_CHUNK 16
#endif

/* A stand-in for the angle θ ∈ [0, π] of (x, y), y ≥ 0, that rises with it: tan(θ/2) up to
 * π/2, 2 - cot(θ/2) above. rectify_bounds reduces it instead of θ and the host takes the arc
 * tangent of the extremes only (clrays/stages/rectify.py angle_of_pseudo): PoCL's atan2 cost
 * more than the rest of the kernel, twice per camera sample. */
inline float pseudo_angle(float x, float y)
{
    float r = sqrt(x * x + y * y);
    return x >= 0.0f ? (r + x > 0.0f ? y / (r + x) : 0.0f) : 2.0f - y / (r - x);
}

/* One work-item per BOUNDS_CHUNK camera samples: it reduces their β and γ in registers and
 * then updates the three bounds, so the atomics do not serialize every sample on them. */
kernel void rectify_bounds(global const frame_t* frame, global const view_t* views,
                           global const light_t* lights, global const epipolar_t* epipolar,
                           global const uint* camera_depth, global const float2* offsets,
                           global uint* bounds)
{
    int samples = frame->width * frame->height * frame->spp;
    int first = get_global_id(0) * BOUNDS_CHUNK, last = min(first + BOUNDS_CHUNK, samples);
    if (first >= samples) return;
    int directional = lights[epipolar->light_index].type == LIGHT_DIRECTIONAL;
    float q_beta_min = INFINITY, q_beta_max = 0.0f, gamma_max = 0.0f;
    /* The chunk's pixel (x, y) and sample within it advance by counting: three integer divisions
     * per sample cost PoCL 6 % of the kernel (bench/RESULTS.md, host stages). */
    int spp = frame->spp, width = frame->width;
    int pixel = first / spp, sub = first - pixel * spp;
    int x = pixel % width, y = pixel / width;
    for (int sample = first; sample < last; ++sample) {
        float3 origin, dir;
        view_ray(views, view_screen(views, x, y, offsets[sub]), &origin, &dir);
        if (++sub == spp) {
            sub = 0;
            if (++x == width) {
                x = 0;
                ++y;
            }
        }
        float s = fmin(as_float(camera_depth[sample]), frame->far);
        float cos_beta = dot(dir, epipolar->axis.xyz), sin_beta = length(cross(dir, epipolar->axis.xyz));
        float q_beta = pseudo_angle(cos_beta, sin_beta);
        /* γ (docs/design.md §3): s·sin β for a directional light, else the angle at the light. */
        float gamma = directional ? s * sin_beta : pseudo_angle(epipolar->d_el - s * cos_beta, s * sin_beta);
        q_beta_min = fmin(q_beta_min, q_beta);
        q_beta_max = fmax(q_beta_max, q_beta);
        gamma_max = fmax(gamma_max, gamma);
    }
    /* Non-negative floats order like their bit patterns, so uint atomics reduce them. */
    atomic_min(bounds + 0, as_uint(q_beta_min));
    atomic_max(bounds + 1, as_uint(q_beta_max));
    atomic_max(bounds + 2, as_uint(gamma_max));
}

/* slice_sides[α] = u·cos α + w·sin α at the slice's centre and texel_angles[γ] = (γ, cos γ,
 * sin γ) come from the host (clrays/stages/rectify.py slice_sides, texel_angles): the same for every
 * texel of a row or column, they cost the kernel no trigonometry. Texel centres, except
 * texel 0 at γ = 0: the eye's own light ray (through the eye, the same for every slice). A
 * ray straight away from the light (β → π) spans only γ < SIN_BETA_MIN·s, far less than
 * half a texel, and its visibility is that ray's. */
kernel void rectify(global const view_t* views, global const light_t* lights,
                    global const uint* shadow_depth, global const epipolar_t* epipolar,
                    global const float4* slice_sides, global const float4* texel_angles, global float2* tree)
{
    int texel = get_global_id(0), slice = get_global_id(1);
    global const epipolar_t* ep = epipolar;
    if (texel >= ep->gamma_samples || slice >= ep->slices) return;
    global const light_t* light = lights + ep->light_index;
    float4 angle = texel_angles[texel];
    float gamma = angle.x, cos_gamma = angle.y, sin_gamma = angle.z;
    float3 r = slice_sides[slice].xyz;
    float blocker_beta;
    if (light->type == LIGHT_DIRECTIONAL) {
        /* Light ray: γ·r + t·ω. The orthographic map stores depth along -ω from its
         * origin o, so the blocker sits at t_b = -(depth + o·(-ω)); S = atan2(γ, t_b). */
        global const view_t* view = views + light->first_view;
        float2 texel_xy;
        float unused;
        view_project(view, gamma * r, &texel_xy, &unused);
        float stored = INFINITY;
        if (texel_xy.x >= 0.0f && texel_xy.y >= 0.0f && texel_xy.x < (float)view->width && texel_xy.y < (float)view->height)
            stored = shadow_texel(view, shadow_depth, (int)texel_xy.x, (int)texel_xy.y);
        float t_blocker = -(stored + dot(view->origin.xyz, view->forward.xyz));
        blocker_beta = stored == INFINITY ? PI_F : atan2_approx(gamma, t_blocker);
    } else {
        /* Light ray from l at angle γ to l → e, in slice α. */
        float3 dir = -ep->axis.xyz * cos_gamma + r * sin_gamma;
        {
            /* Spot lights: outside the cone the map has no texel and the ray counts as
             * unblocked; traverse clips each eye ray to the cone analytically, so the
             * cone's edge is exact rather than a texel wide. */
            float3 probe = light->position.xyz + dir;
            global const view_t* view = views + light_view_index(light, probe);
            float2 texel_xy;
            float unused;
            float stored = INFINITY;
            if (view_project(view, probe, &texel_xy, &unused))
                stored = shadow_texel(view, shadow_depth, (int)texel_xy.x, (int)texel_xy.y);
            blocker_beta = stored == INFINITY ? PI_F
                                              : atan2_approx(stored * sin_gamma, ep->d_el - stored * cos_gamma);
        }
    }
    tree[(size_t)slice * 2 * ep->gamma_samples + texel] = (float2)(blocker_beta, blocker_beta);
}
