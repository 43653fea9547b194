/* lighting.h — device functions shared by the stages: view rays and projections,
 * incident light, phase function, shadow-map visibility. Radiometry as in
 * docs/design.md §1: Lin = I·exp(-σt·d)/d² (point, spot inside its cone), Lin = E (directional). */
#ifndef CLRAYS_LIGHTING_H
#define CLRAYS_LIGHTING_H
#include "common.h"
#include "inline_math.h"
#include "atan2_approx.h"

#define INV_FOUR_PI 0.0795774715459476679f

/* A point or spot light is a lamp: a ball of radius frame_t.lamp_radius around it holds no
 * medium, which keeps a ray through the light and the eye at the light finite
 * (docs/design.md §1, the lamp; the radius follows the scene's size, never camera.far, and is
 * clrays/reference/radiometry.py lamp_radius, so the host reference uses the same value). */

/* The eye (eye space's origin) is inside a point or spot light's lamp, d_el → 0: then every
 * point the eye sees, the light sees too, and nothing visible is shadowed (docs/design.md §6). A
 * shadow-map test there would only add its texel-wide errors along every silhouette. */
ALWAYS_INLINE int eye_in_lamp(global const light_t* light, float lamp_radius)
{
    return light->type != LIGHT_DIRECTIONAL && exact_length(light->position.xyz) < lamp_radius;
}

/* Screen coordinates of sample (x + ox, y + oy) in [-1, 1], y up. */
inline float2 view_screen(global const view_t* view, int x, int y, float2 offset)
{
    return (float2)(2.0f * ((float)x + offset.x) / (float)view->width - 1.0f,
                    1.0f - 2.0f * ((float)y + offset.y) / (float)view->height);
}

/* The ray of a view sample: origin and unit direction. A perspective direction's squared
 * length is at least 1 (forward is a unit vector orthogonal to right and up), the plain
 * path of inline_normalize, which is the library's there (the same bits on PoCL, without
 * a call: docs/design.md §4.5, "Cost on PoCL"). */
ALWAYS_INLINE void view_ray(global const view_t* view, float2 s, float3* origin, float3* dir)
{
    float3 right = view->right.xyz * (s.x * view->scale_x);
    float3 up = view->up.xyz * (s.y * view->scale_y);
    if (view->projection == PROJECTION_PERSPECTIVE) {
        *origin = view->origin.xyz;
        *dir = inline_normalize(view->forward.xyz + right + up);
    } else {
        *origin = view->origin.xyz + right + up;
        *dir = view->forward.xyz;
    }
}

/* Where the camera ray along unit dir starts (camera.near, docs/scene-format.md): at the plane
 * near in front of the eye along its view axis, t0 = near / cos θ, as Cycles' Clip Start. The
 * walks clip their lit runs to [t0, D] and shade measures the eye's transmittance from t0,
 * only when near > 0: with near = 0 no kernel computes it, and the images keep their bits. */
ALWAYS_INLINE float camera_ray_start(global const frame_t* frame, float3 dir)
{
    return frame->near_plane.w / inline_dot(dir, frame->near_plane.xyz);
}

/* A camera sample's surface point p, its ray direction and its normal turned to face the
 * camera (surfaces are two-sided, as shade has them). Returns 0 where the sample sees no
 * surface (no triangle, or beyond far). */
ALWAYS_INLINE int camera_surface_point(global const frame_t* frame, global const view_t* views,
                                global const uint* camera_depth, global const int* tri_id,
                                global const float4* tri_normal, global const float2* offsets, int sample,
                                float3* p, float3* dir, float3* n)
{
    int pixel = sample / frame->spp;
    int x = pixel % frame->width, y = pixel / frame->width;
    float distance = as_float(camera_depth[sample]);
    int tri = tri_id[sample];
    if (tri < 0 || distance > frame->far) return 0;
    float3 origin;
    view_ray(views, view_screen(views, x, y, offsets[sample % frame->spp]), &origin, dir);
    *p = origin + distance * *dir;
    *n = tri_normal[tri].xyz;
    if (inline_dot(*n, *dir) > 0.0f) *n = -*n;
    return 1;
}

/* Project p into a view: continuous texel coordinates and depth (distance from the
 * origin for perspective views, along forward for orthographic ones). Returns 0
 * when p is behind a perspective view. */
ALWAYS_INLINE int view_project(global const view_t* view, float3 p, float2* texel, float* depth)
{
    float3 q = p - view->origin.xyz;
    float x = inline_dot(q, view->right.xyz), y = inline_dot(q, view->up.xyz), z = inline_dot(q, view->forward.xyz);
    float sx, sy;
    if (view->projection == PROJECTION_PERSPECTIVE) {
        if (z <= 0.0f) return 0;
        *depth = inline_length(q);
        sx = x / (z * view->scale_x);
        sy = y / (z * view->scale_y);
    } else {
        *depth = z;
        sx = x / view->scale_x;
        sy = y / view->scale_y;
    }
    *texel = (float2)((sx + 1.0f) * 0.5f * (float)view->width, (1.0f - sy) * 0.5f * (float)view->height);
    return 1;
}

/* Henyey-Greenstein (or isotropic) phase function of cos θ, θ between the light's
 * propagation direction and the direction towards the eye. */
inline float phase_function(global const frame_t* frame, float cos_theta)
{
    if (frame->phase_type == PHASE_ISOTROPIC) return INV_FOUR_PI;
    float g = frame->phase_g;
    float denom = 1.0f + g * g - 2.0f * g * cos_theta;
    return INV_FOUR_PI * (1.0f - g * g) / (denom * sqrt(denom));
}

/* Incident radiance-carrying quantity at p (docs/design.md §1) and the unit direction from p
 * towards the light. */
inline float3 light_incident(global const light_t* light, float3 sigma_t, float3 p, float3* to_light)
{
    if (light->type == LIGHT_DIRECTIONAL) {
        *to_light = -light->direction.xyz;
        return light->power.xyz;
    }
    float3 w = p - light->position.xyz;
    float d2 = dot(w, w);
    float d = sqrt(d2);
    *to_light = d > 0.0f ? -w / d : (float3)(0.0f, 1.0f, 0.0f);
    if (light->type == LIGHT_SPOT && dot(w, light->direction.xyz) < light->cos_cone * d)
        return (float3)(0.0f);
    /* d2 is clamped only where it underflows; the 1/d² peak itself is physical. */
    return light->power.xyz * exp(-sigma_t * d) / fmax(d2, 1e-30f);
}

/* A spot light's cone in a half-plane through the eye and the light (docs/design.md §4.5,
 * "A spot light's cone as a wedge"). The cone's apex is the light, which lies in every
 * such half-plane. With side s (unit, normal to the axis a from the eye to the light), the
 * light's ray at angle γ from the ray back to the eye, turned towards s, lies inside the
 * cone where cos γ·x + sin γ·y ≥ c: (x, y) = (-a·k, s·k) is the cone's axis k seen in the
 * half-plane and c its cos_cone. Those are the γ within δ of φ = atan2(y, x), with
 * cos δ = c/r, r = |(x, y)|: one wedge (φ - δ, φ + δ), empty (δ = 0) where r < c. x, y and
 * c scaled by one positive factor give the same wedge. c is taken as at least 0 (a
 * half-angle of at most 90°, as the loader allows), so δ ≤ π/2 and the wedge is at most a
 * half-turn: lit_sweep's one turn of it is all that meets a ray.
 * A camera ray's lit part is then [0, γ_end] within the wedge, with no cuts along the ray:
 * where a ray passes near the apex the cone's quadric has two nearly equal roots, which
 * float32 finds far apart (spot_interval: up to a third of a pixel's in-scattering off
 * next to the bunny's lamp), while φ and δ do not depend on the ray's t at all. */
ALWAYS_INLINE float2 lit_wedge(float x, float y, float c)
{
    c = inline_fmax(c, 0.0f);
    float phi = atan2_approx(y, x), delta = atan2_approx(inline_sqrt(inline_fmax(x * x + y * y - c * c, 0.0f)), c);
    return (float2)(phi - delta, phi + delta);
}

/* The lit part [begin, end] of a ray's sweep [0, γ_end] (empty where end ≤ begin): within
 * the wedge, or within the wedge a turn later. A wedge is at most a half-turn wide around a
 * φ in [-π, π], so no other turn meets [0, π), and the two never both do. */
ALWAYS_INLINE float2 lit_sweep(float gamma_end, float2 wedge)
{
    if (!(inline_fmin(gamma_end, wedge.y) > inline_fmax(wedge.x, 0.0f))) wedge += 2.0f * M_PI_F;
    return (float2)(inline_fmax(wedge.x, 0.0f), inline_fmin(gamma_end, wedge.y));
}

/* Below this sin β a ray's own half-plane is lost in the rounding of its float32 direction
 * (about 1e-7 rad): the ray passes the light within a lamp's radius or so. */
#define WEDGE_SIN_BETA_MIN 1e-6f

/* The lit wedge of the half-plane of the ray along dir (unit; sin β = |dir × a|, not
 * clamped). Its side is (dir - cos β·a)/sin β, so x and c are taken times sin β, and y as
 * dir·k⊥ = sin β·(s·k), with k⊥ = k - (a·k)·a the cone axis's part normal to a: no
 * division. Either way y carries the float32 direction's own rounding, about 1e-7 absolute:
 * φ is good to about 1e-7/sin β, a thousandth of a radian a ten-thousandth of a radian from
 * the light. A ray on the axis itself (below WEDGE_SIN_BETA_MIN) lies in every half-plane,
 * and its points are at γ = 0 or π, whose test does not depend on the side: the half-plane
 * of `normal`, any unit vector normal to the axis, stands for it. */
ALWAYS_INLINE float2 ray_wedge(global const light_t* light, float3 axis, float3 normal, float3 dir, float sin_beta)
{
    float3 k = light->direction.xyz;
    float axis_along = inline_dot(axis, k);
    float3 k_normal = k - axis_along * axis;
    if (!(sin_beta > WEDGE_SIN_BETA_MIN)) return lit_wedge(-axis_along, inline_dot(normal, k_normal), light->cos_cone);
    return lit_wedge(-axis_along * sin_beta, inline_dot(dir, k_normal), light->cos_cone * sin_beta);
}

/* The part [s0, s1] of the eye ray s·dir, s ∈ [0, far], inside a spot light's cone
 * (|angle to the axis| ≤ cone, on the light's side), for raymarch's steps, which are in
 * s. For a half-angle ≤ 90° the cone is convex, so this is one interval; returns 0 when
 * the ray misses it. The candidate
 * ends are the roots of (w·k)² = cos²·|w|² (w = p - l), the apex plane and the ray's
 * ends; the pieces between them are tested at their midpoints. */
ALWAYS_INLINE int spot_interval(global const light_t* light, float3 dir, float far, float* s0, float* s1)
{
    float3 l = light->position.xyz, k = light->direction.xyz;
    float c2 = light->cos_cone * light->cos_cone;
    float a1 = inline_dot(dir, k), a0 = -inline_dot(l, k), vl = inline_dot(dir, l);
    float qa = a1 * a1 - c2, qb = 2.0f * (a1 * a0 + c2 * vl), qc = a0 * a0 - c2 * inline_dot(l, l);
    float cut[5] = {0.0f, far, 0.0f, 0.0f, 0.0f};
    int count = 2;
    float disc = qb * qb - 4.0f * qa * qc;
    if (disc >= 0.0f && qa != 0.0f) {
        /* numerically stable pair of roots */
        float q = -0.5f * (qb + inline_copysign(inline_sqrt(disc), qb));
        cut[count++] = q / qa;
        if (q != 0.0f) cut[count++] = qc / q;
    } else if (qa == 0.0f && qb != 0.0f) {
        cut[count++] = -qc / qb;
    }
    if (a1 != 0.0f) cut[count++] = -a0 / a1;
    for (int i = 0; i < count; ++i) cut[i] = inline_clamp(cut[i], 0.0f, far);
    for (int i = 1; i < count; ++i) /* insertion sort of at most 5 values */
        for (int j = i; j > 0 && cut[j] < cut[j - 1]; --j) {
            float t = cut[j]; cut[j] = cut[j - 1]; cut[j - 1] = t;
        }
    int found = 0;
    for (int i = 0; i + 1 < count; ++i) {
        if (!(cut[i + 1] > cut[i])) continue;
        float3 w = 0.5f * (cut[i] + cut[i + 1]) * dir - l;
        if (inline_dot(w, k) >= light->cos_cone * inline_length(w)) {
            if (!found) *s0 = cut[i];
            *s1 = cut[i + 1];
            found = 1;
        }
    }
    return found;
}

/* The shadow-map view of a light that holds p: the cube face of p's major axis
 * (faces ordered +x, -x, +y, -y, +z, -z), or the single view. */
ALWAYS_INLINE int light_view_index(global const light_t* light, float3 p)
{
    if (light->view_count == 1) return light->first_view;
    float3 w = p - light->position.xyz;
    float3 a = (float3)(inline_fabs(w.x), inline_fabs(w.y), inline_fabs(w.z));
    int axis = (a.x >= a.y && a.x >= a.z) ? 0 : (a.y >= a.z ? 1 : 2);
    float component = axis == 0 ? w.x : (axis == 1 ? w.y : w.z);
    return light->first_view + 2 * axis + (component < 0.0f ? 1 : 0);
}

/* A 64-bit shadow-map key (raster.cl raster_nearest: the depth's bits above the triangle)
 * read as two uints: the one that holds the depth. */
#ifdef __ENDIAN_LITTLE__
#define KEY_DEPTH_WORD 1
#else
#define KEY_DEPTH_WORD 0
#endif

/* Where texel i's depth lies in the shadow depths: with SHADOW_DEPTH_IN_KEYS they are the
 * maps' keys (clrays/stages/raster.py depth_in_keys), whose depth word is read, else one
 * uint a texel. */
#if SHADOW_DEPTH_IN_KEYS
#define SHADOW_DEPTH_AT(i) (2 * (i) + KEY_DEPTH_WORD)
#else
#define SHADOW_DEPTH_AT(i) (i)
#endif

/* Stored blocker depth at integer texel (tx, ty) of a view, clamped to the map. */
ALWAYS_INLINE float shadow_texel(global const view_t* view, global const uint* shadow_depth, int tx, int ty)
{
    tx = inline_clamp_int(tx, 0, view->width - 1);
    ty = inline_clamp_int(ty, 0, view->height - 1);
    return as_float(shadow_depth[SHADOW_DEPTH_AT(view->depth_offset + ty * view->width + tx)]);
}

/* World size of one shadow-map texel at depth d: the scale of the depth bias. */
inline float shadow_texel_size(global const light_t* light, float depth)
{
    return light->type == LIGHT_DIRECTIONAL ? light->texel_angle : depth * light->texel_angle;
}

/* The point where a surface point p with unit normal n (turned to the light's side) looks
 * up the light's shadow map: p moved along n by a texel of the map at p's distance, which
 * keeps a lit surface from shadowing itself. One offset for every stage that looks a
 * surface up (shade, visibility, transparency, translucency, shadow_filter); exact_length
 * is the built-in length's bits, on every path. */
ALWAYS_INLINE float3 shadow_lookup(global const light_t* light, float3 p, float3 n)
{
    return p + n * shadow_texel_size(light, exact_length(p - light->position.xyz));
}

/* How far along its own ray a shadow ray's start may move to leave its surface: up to
 * 1 / SHADOW_RAY_ALONG_MIN of the height it leaves by. */
#define SHADOW_RAY_ALONG_MIN 0.05f

/* Where the shadow ray leaves: `push` = SHADOW_RAY_OFFSET_REL·(|p| + distance to the light)
 * above the surface, on the light's side (float32 rounding puts p up to a few ulps off its
 * plane, and a ray from below would meet the plane's other triangles), reached by moving
 * along the ray towards the light, push / cos θ: the ray's line still passes through p, as
 * exact's (float64) does. Moved along the normal instead, the line passed push off p, and a
 * point within push of a shadow's edge took the other side's answer: one floor pixel
 * 6e-6 below the window's top edge in sun.yaml at 200×150, 9e-6 inside a slat's corner in
 * grate.yaml at 128×72 (docs/stability.md, "A pixel on a hard shadow's edge"). Where the
 * light grazes the surface (cos θ < SHADOW_RAY_ALONG_MIN) the start moves push /
 * SHADOW_RAY_ALONG_MIN along the ray and the rest of the height along the normal, so it
 * stays within 20·push of p. One start for every shadow ray (visibility's rays and
 * lit tests, translucency's and the films' transmittance). */
ALWAYS_INLINE float3 shadow_ray_start(global const light_t* light, float3 p, float3 n, float3 to_light)
{
    float to_light_distance = light->type == LIGHT_DIRECTIONAL ? 0.0f : exact_length(light->position.xyz - p);
    float facing = inline_dot(n, to_light);
    float3 side = facing >= 0.0f ? n : -n;
    float cosine = inline_fabs(facing);
    float push = SHADOW_RAY_OFFSET_REL * (exact_length(p) + to_light_distance);
    float along = push / inline_fmax(cosine, SHADOW_RAY_ALONG_MIN);
    float lift = push - along * cosine;
    return p + to_light * along + side * lift;
}

/* 1 where p sees the light through the shadow map, else 0; averaged over a
 * (2·pcf + 1)² texel footprint when pcf > 0. Points outside the map are lit: a
 * map covers every occluder (cube, cone, or the scene bounds). bias is in texels. */
inline float shadow_visibility(global const light_t* light, global const view_t* views,
                               global const uint* shadow_depth, float3 p, float bias, int pcf)
{
    global const view_t* view = views + light_view_index(light, p);
    float2 texel;
    float depth;
    if (!view_project(view, p, &texel, &depth)) return 1.0f;
    if (texel.x < 0.0f || texel.y < 0.0f || texel.x >= (float)view->width || texel.y >= (float)view->height)
        return 1.0f;
    float tolerance = bias * shadow_texel_size(light, depth);
    int tx = (int)texel.x, ty = (int)texel.y;
    float lit = 0.0f;
    for (int j = -pcf; j <= pcf; ++j)
        for (int i = -pcf; i <= pcf; ++i)
            lit += depth <= shadow_texel(view, shadow_depth, tx + i, ty + j) + tolerance ? 1.0f : 0.0f;
    return lit / (float)((2 * pcf + 1) * (2 * pcf + 1));
}

#endif
