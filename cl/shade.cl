/* shade — surface radiance at each camera sample (two-sided Lambertian, shadow-map
 * test with optional PCF), attenuated to the eye, plus the in-scattered radiance,
 * averaged over the pixel's samples.
 * Reads frame, views, lights, shadow_depth, camera_depth, tri_id, tri_vertices,
 * tri_normal, tri_vertex_normals, tri_albedo, offsets, scatter, visible (the visibility
 * stage's answer per sample and light, with surface_shadows exact; the shadow_filter stage's
 * with surface_shadows filtered) and its feature groups (shade_features.h: the lights'
 * textures, the translucency stage's layers, the camera's films); writes image (one float4
 * per pixel, linear rgb) and, built with SHADE_PASSES, passes (the render passes' terms).
 * With one sample per pixel, image is scatter's own buffer (clrays/stages/shade.py): each
 * work-item reads its samples' in-scattering before it writes their pixels, and no other
 * reads them.
 *
 * Each work-item shades LANES (8) neighbouring pixels as float8 vectors (lanes.h), with the
 * built-ins written out (inline_math.h): PoCL would run one pixel at a time, each dot,
 * length or normalize a library call (docs/design.md §4.5, "Cost on PoCL"). Every lane does
 * the operations of the one-pixel code in the same order, so the image is the same bit for
 * bit; the rare paths (a textured light, the shadow map's test, translucent layers) call
 * the shared functions lane by lane. */
#include "shade_features.h"
#include "lanes.h"

/* SURFACE_BIAS_TEXELS, the surface shadow test's depth tolerance: clrays/structs.py (-D). */

/* A bounded or heterogeneous medium builds shade with MEDIUM_VARYING (medium.h): a surface's
 * light is attenuated along the light's path through it (T_l), and its radiance along the
 * camera ray (T_e), lane by lane; exp(-σt·d) otherwise, and those images are unchanged. */
#include "medium.h"

#ifdef MEDIUM_GRID
/* A surface's optical depth to light `source` through the grid, looked up in the light's
 * optical-depth grid: the density is 0 outside the grid's bounds, so a p outside them takes the
 * value where its path towards the light enters them (none: 0), and one on them that rounding
 * put outside (a grid fitted to the scene: its floor, its walls) is moved in, where
 * light_path_depth looks up instead of marching through the grid for every pixel. */
inline float grid_path_depth(global const medium_t* medium, global const float* density_grid,
                             global const float* depth_grid, global const light_t* source, int index, float3 p)
{
    float3 lo = medium->grid_min.xyz, hi = medium->grid_max.xyz;
    float3 towards;
    float reach = INFINITY;
    if (source->type == LIGHT_DIRECTIONAL) {
        towards = -source->direction.xyz;
    } else {
        float3 w = source->position.xyz - p;
        reach = length(w);
        if (!(reach > 0.0f)) return 0.0f;
        towards = w / reach;
    }
    float t0 = 0.0f, t1 = reach;
    if (!clip_to_box(lo, hi, p, towards, &t0, &t1)) return 0.0f;
    return light_path_depth(medium, density_grid, depth_grid, source, index, clamp(p + t0 * towards, lo, hi));
}
#define SURFACE_LIGHT_DEPTH(light, l, p) grid_path_depth(medium, density_grid, light_depth_grid, light, l, p)
#else
#define SURFACE_LIGHT_DEPTH(light, l, p) light_path_depth(medium, density_grid, light_depth_grid, light, l, p)
#endif

/* A vector quantity over the lanes: each component a float8. */
typedef struct {
    float_lanes x, y, z;
} vec_lanes;

ALWAYS_INLINE vec_lanes splat_lanes(float3 v)
{
    vec_lanes out = {(float_lanes)(v.x), (float_lanes)(v.y), (float_lanes)(v.z)};
    return out;
}

ALWAYS_INLINE float3 lane_of(vec_lanes v, int k) { return (float3)(v.x[k], v.y[k], v.z[k]); }

ALWAYS_INLINE vec_lanes select_lanes(int_lanes condition, vec_lanes a, vec_lanes b)
{
    vec_lanes out = {condition ? a.x : b.x, condition ? a.y : b.y, condition ? a.z : b.z};
    return out;
}

/* array[index].xyz and .w of each lane. */
ALWAYS_INLINE vec_lanes gather_xyz(global const float4* array, int_lanes index, float_lanes* w)
{
    vec_lanes out;
    float_lanes unused;
    gather_records(array, index, &out.x, &out.y, &out.z, w ? w : &unused);
    return out;
}

/* exp of each lane: PoCL's float8 exp gives each lane the bits its float3 exp gives each
 * component, checked on all 2^32 inputs (bench/RESULTS.md, "shade in lanes"). */
ALWAYS_INLINE float_lanes exp_lanes(float_lanes x) { return exp(x); }

/* exp(-σt·d) of each channel. A grey medium (the same σt bits in the three channels, as every
 * bench scene has) asks exp once: the same argument gives the same bits. */
ALWAYS_INLINE vec_lanes attenuation_lanes(float3 sigma_t, float_lanes d)
{
    float_lanes red = exp_lanes(-sigma_t.x * d);
    vec_lanes out = {red, red, red};
    if (as_uint(sigma_t.y) != as_uint(sigma_t.x)) out.y = exp_lanes(-sigma_t.y * d);
    if (as_uint(sigma_t.z) != as_uint(sigma_t.x)) out.z = exp_lanes(-sigma_t.z * d);
    return out;
}

ALWAYS_INLINE float_lanes exact_length_lanes(vec_lanes v)
{
    float_lanes squared = squared_length_lanes(v.x, v.y, v.z);
    float_lanes out = sqrt_lanes(squared);
    int_lanes rare = !((squared >= 1.17549435e-38f) & (squared <= 3.40282347e38f));
    if (any_lanes(rare))
        for (int k = 0; k < LANES; ++k)
            if (rare[k]) out[k] = length(lane_of(v, k));
    return out;
}

#pragma OPENCL FP_CONTRACT OFF /* as the library's dot and cross (inline_math.h) */
ALWAYS_INLINE float_lanes dot_vec_lanes(vec_lanes a, vec_lanes b)
{
    float_lanes x = a.x * b.x, y = a.y * b.y, z = a.z * b.z;
    return z + (x + y);
}

ALWAYS_INLINE vec_lanes cross_lanes(vec_lanes a, vec_lanes b)
{
    vec_lanes out = {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
    return out;
}
#pragma OPENCL FP_CONTRACT ON

ALWAYS_INLINE vec_lanes sub_lanes(vec_lanes a, vec_lanes b)
{
    vec_lanes out = {a.x - b.x, a.y - b.y, a.z - b.z};
    return out;
}

ALWAYS_INLINE vec_lanes negate_lanes(vec_lanes a)
{
    vec_lanes out = {-a.x, -a.y, -a.z};
    return out;
}

/* The shading normal of a smooth triangle where the sample ray meets it: its three vertex
 * normals weighted by the barycentric coordinates of the hit (Möller–Trumbore on the ray,
 * clamped to the triangle, as a sample by an edge may land just outside), normalised.
 * `flat` where that is undefined: a ray in the triangle's plane, or normals that cancel. */
ALWAYS_INLINE vec_lanes smooth_normal_lanes(global const float4* tri_vertices, global const float4* tri_vertex_normals,
                                            int_lanes tri, vec_lanes origin, vec_lanes dir, vec_lanes flat)
{
    vec_lanes v0 = gather_xyz(tri_vertices, 3 * tri, 0);
    vec_lanes edge1 = sub_lanes(gather_xyz(tri_vertices, 3 * tri + 1, 0), v0);
    vec_lanes edge2 = sub_lanes(gather_xyz(tri_vertices, 3 * tri + 2, 0), v0);
    vec_lanes p = cross_lanes(dir, edge2);
    float_lanes det = dot_vec_lanes(edge1, p);
    vec_lanes t = sub_lanes(origin, v0);
    float_lanes u = fmin_lanes(fmax_lanes(dot_vec_lanes(t, p) / det, 0.0f), 1.0f);
    float_lanes v = fmin_lanes(fmax_lanes(dot_vec_lanes(dir, cross_lanes(t, edge1)) / det, 0.0f), 1.0f);
    int_lanes over = u + v > 1.0f;
    float_lanes sum = u + v;
    u = over ? u / sum : u;
    v = over ? v / sum : v;
    vec_lanes n0 = gather_xyz(tri_vertex_normals, 3 * tri, 0), n1 = gather_xyz(tri_vertex_normals, 3 * tri + 1, 0),
              n2 = gather_xyz(tri_vertex_normals, 3 * tri + 2, 0);
    /* The same expression as the one-pixel code's float3 one, so that contraction fuses alike. */
    vec_lanes n = {(1.0f - u - v) * n0.x + u * n1.x + v * n2.x, (1.0f - u - v) * n0.y + u * n1.y + v * n2.y,
                   (1.0f - u - v) * n0.z + u * n1.z + v * n2.z};
    float_lanes n_length = exact_length_lanes(n);
    vec_lanes normalised = {n.x / n_length, n.y / n_length, n.z / n_length};
    return select_lanes((det != 0.0f) & (n_length > 0.0f), normalised, flat);
}

#ifdef MEDIUM_VARYING /* (its lane loops call medium.h's float3 code: walk.h's case, common.h) */
NOT_ACROSS_WORK_ITEMS
#endif
kernel void shade(global const frame_t* frame, global const view_t* views,
                  global const light_t* lights, global const uint* shadow_depth,
                  global const uint* camera_depth, global const int* tri_id,
                  global const float4* tri_vertices, global const float4* tri_normal,
                  global const float4* tri_vertex_normals, global const float4* tri_albedo,
                  global const float2* offsets, global const float4* scatter,
                  global const float* visible_exact, global float4* image SHADE_FEATURE_ARGS)
{
    int pixels = frame->width * frame->height, first = get_global_id(0) * LANES;
    if (first >= pixels) return;
    int_lanes pixel = (int_lanes)(first) + (int_lanes)(0, 1, 2, 3, 4, 5, 6, 7);
    int_lanes inside = pixel < pixels;
    pixel = inside ? pixel : (int_lanes)(first); /* lanes past the image redo the first, unstored */
    /* x and y of each lane without a division per lane (integer vector division has no
     * instruction): the first pixel's, then a step to the next row where a lane passes the
     * width, as often as the width needs. Lanes past the image get coordinates past it, and
     * read their buffers at the first pixel's samples. */
    int width = frame->width;
    int_lanes x = (int_lanes)(first % width) + (int_lanes)(0, 1, 2, 3, 4, 5, 6, 7), y = (int_lanes)(first / width);
    for (int_lanes past = x >= width; any_lanes(past); past = x >= width) {
        x = past ? x - width : x;
        y = past ? y + 1 : y;
    }
    float_lanes x_f = float_of_lanes(x), y_f = float_of_lanes(y);
    /* One sample per pixel and every lane inside: the lanes' samples are first, first + 1, ...,
     * and their buffers are read and written as runs. */
    int run = frame->spp == 1 && all_lanes(inside);
    float3 sigma_t = frame->sigma_t.xyz;
    int light_count = frame->light_count;
    int map_test = frame->surface_shadows != SURFACE_SHADOWS_EXACT && frame->surface_shadows != SURFACE_SHADOWS_FILTERED;
    vec_lanes total = splat_lanes((float3)(0.0f));
#ifdef SHADE_PASSES
    vec_lanes pass_through = splat_lanes((float3)(0.0f)), pass_surface = pass_through, pass_scatter = pass_through;
    float_lanes pass_depth = (float_lanes)(INFINITY);
#endif
    for (int s = 0; s < frame->spp; ++s) {
        int_lanes sample = pixel * frame->spp + s;
        /* view_screen and view_ray (lighting.h) on each lane */
        float2 offset = offsets[s];
        float_lanes screen_x = 2.0f * (x_f + offset.x) / (float)views->width - 1.0f;
        float_lanes screen_y = 1.0f - 2.0f * (y_f + offset.y) / (float)views->height;
        float_lanes right = screen_x * views->scale_x, up = screen_y * views->scale_y;
        vec_lanes origin, dir;
        vec_lanes right_v = {views->right.x * right, views->right.y * right, views->right.z * right};
        vec_lanes up_v = {views->up.x * up, views->up.y * up, views->up.z * up};
        if (views->projection == PROJECTION_PERSPECTIVE) {
            origin = splat_lanes(views->origin.xyz);
            vec_lanes v = {views->forward.x + right_v.x + up_v.x, views->forward.y + right_v.y + up_v.y,
                           views->forward.z + right_v.z + up_v.z};
            float_lanes inverse = 1.0f / sqrt_lanes(squared_length_lanes(v.x, v.y, v.z));
            vec_lanes unit = {v.x * inverse, v.y * inverse, v.z * inverse};
            dir = unit;
        } else {
            vec_lanes o = {views->origin.x + right_v.x + up_v.x, views->origin.y + right_v.y + up_v.y,
                           views->origin.z + right_v.z + up_v.z};
            origin = o;
            dir = splat_lanes(views->forward.xyz);
        }
        float_lanes distance;
        int_lanes tri;
        if (run) {
            distance = load_run((global const float*)camera_depth, first);
            tri = load_int_run(tri_id, first);
        } else {
            for (int k = 0; k < LANES; ++k) {
                distance[k] = as_float(camera_depth[sample[k]]);
                tri[k] = tri_id[sample[k]];
            }
        }
        int_lanes background = (tri < 0) | (distance > frame->far);
#ifdef SHADE_PASSES
        pass_depth = fmin_lanes(pass_depth, background ? (float_lanes)(INFINITY) : distance);
#endif
        distance = background ? frame->far : distance;
        vec_lanes surface = splat_lanes(frame->background.xyz);
        if (!all_lanes(background)) {
            int some_tri = 0; /* a triangle of the lanes that see one: the others read it, unused */
            for (int k = LANES - 1; k >= 0; --k)
                if (!background[k]) some_tri = tri[k];
            int_lanes safe_tri = background ? (int_lanes)(some_tri) : tri;
            vec_lanes p = {origin.x + distance * dir.x, origin.y + distance * dir.y, origin.z + distance * dir.z};
            /* n, the triangle's own normal, picks the side and offsets the shadow lookup;
             * the shading normal (n itself unless the triangle is smooth) weighs the light. */
            float_lanes smooth;
            vec_lanes n = gather_xyz(tri_normal, safe_tri, &smooth);
            vec_lanes shading = n;
            if (any_lanes(smooth != 0.0f))
                shading = select_lanes(smooth != 0.0f,
                                       smooth_normal_lanes(tri_vertices, tri_vertex_normals, safe_tri, origin, dir, n), n);
            int_lanes facing_away = dot_vec_lanes(n, dir) > 0.0f; /* two-sided: face the camera */
            n = select_lanes(facing_away, negate_lanes(n), n);
            shading = select_lanes(facing_away, negate_lanes(shading), shading);
            vec_lanes irradiance = splat_lanes((float3)(0.0f));
            for (int l = 0; l < light_count; ++l) {
                global const light_t* light = lights + l;
                /* light_incident (lighting.h) on each lane */
                vec_lanes to_light, incident;
                if (light->type == LIGHT_DIRECTIONAL) {
                    to_light = splat_lanes(-light->direction.xyz);
                    incident = splat_lanes(light->power.xyz);
#ifdef MEDIUM_VARYING /* T_l: the part of the light's path inside the medium */
                    for (int k = 0; k < LANES; ++k) {
                        float3 through = exp(-sigma_t * SURFACE_LIGHT_DEPTH(light, l, lane_of(p, k)));
                        incident.x[k] *= through.x;
                        incident.y[k] *= through.y;
                        incident.z[k] *= through.z;
                    }
#endif
                } else {
                    vec_lanes w = sub_lanes(p, splat_lanes(light->position.xyz));
                    float_lanes d2 = squared_length_lanes(w.x, w.y, w.z);
                    float_lanes d = sqrt_lanes(d2);
                    vec_lanes away = {-w.x / d, -w.y / d, -w.z / d};
                    to_light = select_lanes(d > 0.0f, away, splat_lanes((float3)(0.0f, 1.0f, 0.0f)));
                    float_lanes falloff = fmax_lanes(d2, 1e-30f);
#ifdef MEDIUM_VARYING /* T_l along the path from the light */
                    vec_lanes attenuated;
                    for (int k = 0; k < LANES; ++k) {
                        float3 through = exp(-sigma_t * SURFACE_LIGHT_DEPTH(light, l, lane_of(p, k)));
                        attenuated.x[k] = through.x;
                        attenuated.y[k] = through.y;
                        attenuated.z[k] = through.z;
                    }
#else
                    vec_lanes attenuated = attenuation_lanes(sigma_t, d);
#endif
                    vec_lanes lit = {light->power.x * attenuated.x / falloff, light->power.y * attenuated.y / falloff,
                                     light->power.z * attenuated.z / falloff};
                    incident = lit;
                    if (light->type == LIGHT_SPOT) {
                        int_lanes outside = dot_lanes(w.x, w.y, w.z, light->direction.x, light->direction.y,
                                                      light->direction.z) < light->cos_cone * d;
                        incident = select_lanes(outside, splat_lanes((float3)(0.0f)), incident);
                    }
                }
#ifdef LIGHT_TEXTURE_LOOKUP
                if (light_textures[l].textured)
                    for (int k = 0; k < LANES; ++k) {
                        if (background[k]) continue;
                        float3 factor = light_texture(light_textures + l, texels, light, lane_of(p, k));
                        incident.x[k] *= factor.x;
                        incident.y[k] *= factor.y;
                        incident.z[k] *= factor.z;
                    }
#endif
                float_lanes cosine = dot_vec_lanes(shading, to_light);
                int_lanes lit = !background & !((cosine <= 0.0f) | (incident.x + incident.y + incident.z == 0.0f));
                if (!any_lanes(lit)) continue;
                float_lanes visible = 1.0f;
                if (eye_in_lamp(light, frame->lamp_radius))
                    visible = 1.0f;
                else if (!map_test)
                    visible = run && light_count == 1 ? load_run(visible_exact, first)
                                                      : LOAD_LANES(visible_exact, sample * light_count + l);
                else
                    for (int k = 0; k < LANES; ++k)
                        if (lit[k])
                            visible[k] = shadow_visibility(light, views, shadow_depth,
                                                           shadow_lookup(light, lane_of(p, k), lane_of(n, k)),
                                                           SURFACE_BIAS_TEXELS, frame->pcf);
#ifdef TRANSLUCENT_LAYERS /* through the translucent surfaces nearer the light (translucency.h) */
                for (int k = 0; k < LANES; ++k) {
                    if (!lit[k] || !(visible[k] > 0.0f)) continue;
                    int at = sample[k] * light_count + l;
                    float3 through = has_surface_through
                                         ? surface_through[at].xyz
                                         : light_transmittance(light, views, layer_depth, layer_clear, layer_stride,
                                                               shadow_lookup(light, lane_of(p, k), lane_of(n, k)),
                                                               SURFACE_BIAS_TEXELS);
                    incident.x[k] *= through.x;
                    incident.y[k] *= through.y;
                    incident.z[k] *= through.z;
                }
#endif
                /* irradiance += incident · (cosine · visible) on the lit lanes, as one statement each
                 * so that contraction fuses it as the one-pixel code's. */
                float_lanes weight = cosine * visible;
                vec_lanes sum = irradiance;
                sum.x += incident.x * weight;
                sum.y += incident.y * weight;
                sum.z += incident.z * weight;
                irradiance = select_lanes(lit, sum, irradiance);
            }
            vec_lanes albedo = gather_xyz(tri_albedo, safe_tri, 0);
            vec_lanes lambert = {albedo.x * irradiance.x * M_1_PI_F, albedo.y * irradiance.y * M_1_PI_F,
                                 albedo.z * irradiance.z * M_1_PI_F};
            surface = select_lanes(background, surface, lambert);
        }
        vec_lanes in_scatter;
        float_lanes unused;
        if (run)
            load_records_run(scatter, first, &in_scatter.x, &in_scatter.y, &in_scatter.z, &unused);
        else
            in_scatter = gather_xyz(scatter, sample, 0);
#ifdef MEDIUM_VARYING /* T_e: the part of the camera ray inside the medium */
        vec_lanes to_eye;
        for (int k = 0; k < LANES; ++k) {
            float3 through = exp(-sigma_t * eye_path_depth(medium, density_grid, light_depth_grid, lane_of(origin, k),
                                                           lane_of(dir, k), distance[k]));
            to_eye.x[k] = through.x;
            to_eye.y[k] = through.y;
            to_eye.z[k] = through.z;
        }
#else
        vec_lanes to_eye = attenuation_lanes(sigma_t, distance);
#endif
        /* camera.near: the sample's ray starts at t0 (lighting.h's camera_ray_start), where the
         * eye's transmittance is measured from: the surface is attenuated over [t0, D], and what
         * the volume stage gathered from t0 on (attenuated from the eye) is divided by T_e(t0),
         * e^{σt·t0} in a homogeneous medium. A surface nearer than t0 is seen, unattenuated
         * (docs/limits.md). */
        int from_near = frame->near_plane.w > 0.0f;
        vec_lanes near_gain;
        if (from_near) {
            float_lanes start = fmin_lanes(frame->near_plane.w / dot_lanes(dir.x, dir.y, dir.z, frame->near_plane.x,
                                                                           frame->near_plane.y, frame->near_plane.z),
                                           distance);
#ifdef MEDIUM_VARYING
            for (int k = 0; k < LANES; ++k) {
                float3 gain = exp(sigma_t * eye_path_depth(medium, density_grid, light_depth_grid, lane_of(origin, k),
                                                           lane_of(dir, k), start[k]));
                near_gain.x[k] = gain.x;
                near_gain.y[k] = gain.y;
                near_gain.z[k] = gain.z;
            }
            to_eye.x *= near_gain.x;
            to_eye.y *= near_gain.y;
            to_eye.z *= near_gain.z;
#else
            to_eye = attenuation_lanes(sigma_t, distance - start);
            near_gain = attenuation_lanes(sigma_t, -start);
#endif
            in_scatter.x *= near_gain.x;
            in_scatter.y *= near_gain.y;
            in_scatter.z *= near_gain.z;
        }
#ifdef SHADE_TRANSPARENCY
        vec_lanes through = gather_xyz(transmittance, sample, 0), front = gather_xyz(in_front, sample, 0);
        if (from_near) { /* the films' light and the fog in front of them, from t0 too */
            front.x *= near_gain.x;
            front.y *= near_gain.y;
            front.z *= near_gain.z;
        }
        total.x += through.x * (surface.x * to_eye.x + in_scatter.x) + front.x;
        total.y += through.y * (surface.y * to_eye.y + in_scatter.y) + front.y;
        total.z += through.z * (surface.z * to_eye.z + in_scatter.z) + front.z;
#else
        total.x += surface.x * to_eye.x + in_scatter.x;
        total.y += surface.y * to_eye.y + in_scatter.y;
        total.z += surface.z * to_eye.z + in_scatter.z;
#endif
#ifdef SHADE_PASSES
        pass_through.x += to_eye.x;
        pass_through.y += to_eye.y;
        pass_through.z += to_eye.z;
        pass_surface.x += surface.x * to_eye.x;
        pass_surface.y += surface.y * to_eye.y;
        pass_surface.z += surface.z * to_eye.z;
        pass_scatter.x += in_scatter.x;
        pass_scatter.y += in_scatter.y;
        pass_scatter.z += in_scatter.z;
#endif
    }
    float spp = (float)frame->spp;
#ifdef SHADE_PASSES
    for (int k = 0; k < LANES; ++k)
        if (inside[k]) {
            passes[3 * pixel[k]] = (float4)(pass_through.x[k] / spp, pass_through.y[k] / spp,
                                            pass_through.z[k] / spp, pass_depth[k]);
            passes[3 * pixel[k] + 1] = (float4)(pass_surface.x[k] / spp, pass_surface.y[k] / spp,
                                                pass_surface.z[k] / spp, 0.0f);
            passes[3 * pixel[k] + 2] = (float4)(pass_scatter.x[k] / spp, pass_scatter.y[k] / spp,
                                                pass_scatter.z[k] / spp, 0.0f);
        }
#endif
    if (run) { /* four stores of two pixels each */
        float_lanes pairs[4];
        records_of_lanes(total.x / spp, total.y / spp, total.z / spp, 1.0f, pairs);
        global float8_at_float* out = (global float8_at_float*)(image + first);
        for (int k = 0; k < 4; ++k) out[k] = pairs[k];
        return;
    }
    for (int k = 0; k < LANES; ++k)
        if (inside[k]) image[pixel[k]] = (float4)(total.x[k] / spp, total.y[k] / spp, total.z[k] / spp, 1.0f);
}
