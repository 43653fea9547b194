/* visibility — the maps' decision of every entry visibility_prepare left pending (visibility.h).
 * visibility reads frame, views, lights, shadow_depth, bound, writer, map_read, camera_depth, tri_id,
 * tri_vertices, tri_normal, offsets; writes visible where the maps decide a pending entry
 * (float per sample and light, [sample][light]; 0 where the surface turns away from the
 * light, which shade then weighs by zero) and lists the entries they leave (ray_entries,
 * ray_count: the count, and how many have no texel) for visibility_rays.cl. */
#include "visibility.h"

/* Whether the writer map's `writer`, at a sample on triangle `tri` seen along `dir`, is
 * the sample's own part alone, with the sample on a side of it that the part cannot shadow. */
ALWAYS_INLINE int only_own_part(global const float4* tri_vertices, global const float4* tri_normal, int tri,
                                int writer, float3 dir)
{
    int part = convex_part_of(tri_vertices, tri);
    return writer == part && (!(part & CONVEX_OUTSIDE_ONLY) || inline_dot(tri_normal[tri].xyz, dir) < 0.0f);
}

/* How far the sample's own triangle (plane through p with unit normal n, largest distance
 * `reach` of a vertex from the view's origin) may have written its bound below the depth of
 * p in p's texel: the plane's depth over the texel's cone (perspective: within 2ρ of p's
 * direction, ρ the widest texel's half-angle; orthographic: across the texel), plus the
 * bound's rounding margin. */
inline float own_surface_slack(global const light_t* light, global const view_t* view, float3 p, float3 n,
                               float depth, float reach)
{
    float margin = 2.0f * BOUND_MARGIN_REL * (depth + reach);
    if (view->projection != PROJECTION_PERSPECTIVE) {
        float n_forward = fabs(dot(n, view->forward.xyz));
        if (n_forward < 1e-6f) return INFINITY;
        return light->texel_angle * (fabs(dot(n, view->right.xyz)) + fabs(dot(n, view->up.xyz))) / n_forward + margin;
    }
    /* cos(max(φ - 2ρ, 0)) by the angle difference identity, without acos and cos (library
     * calls, most of this function's time). sin ρ from the cross product, as in
     * bound_triangle. */
    float3 middle = view_direction(view, 0.5f * (float)view->width, 0.5f * (float)view->height);
    float3 diagonal = view_direction(view, 0.5f * (float)view->width + 1.0f, 0.5f * (float)view->height + 1.0f);
    float sin_rho = inline_length(inline_cross(middle, diagonal)), cos_rho = inline_dot(middle, diagonal);
    float sin_2rho = 2.0f * sin_rho * cos_rho, cos_2rho = 1.0f - 2.0f * sin_rho * sin_rho;
    float3 to_p = inline_normalize(p - view->origin.xyz);
    float cos_phi = inline_fabs(inline_dot(n, to_p)), sin_phi = inline_length(inline_cross(n, to_p));
    float cos_difference = cos_phi >= cos_2rho ? 1.0f : cos_phi * cos_2rho + sin_phi * sin_2rho;
    float nearest = depth * cos_phi / cos_difference;
    return depth - nearest + margin;
}

/* Whether a sample at p (normal n, on triangle tri) whose depth in its texel is at most the
 * bias above the bound there is lit after all: its own surface's slack across the texel
 * covers the difference (own_surface_slack, at the shadow ray's start). */
inline int lit_within_own_slack(global const frame_t* frame, global const view_t* views,
                                global const light_t* light, global const float4* tri_vertices, int tri, float3 p,
                                float3 n, float depth, float bound_depth)
{
    float3 to_light;
    light_reaches(light, frame->sigma_t.xyz, p, &to_light);
    float3 start = shadow_ray_start(light, p, n, to_light);
    global const view_t* view = views + light_view_index(light, start);
    float reach = 0.0f; /* of the sample's triangle from the view's origin */
    for (int k = 0; k < 3; ++k)
        reach = inline_fmax(reach, exact_length(tri_vertices[3 * tri + k].xyz - view->origin.xyz));
    return depth <= bound_depth + own_surface_slack(light, view, start, n, depth, reach);
}

/* The per-sample helpers below are written with inline_math.h's functions (the
 * library's operations in its order: the same bits) so that the per-sample kernels make
 * no library call on their common path (docs/design.md §4.5, "Cost on PoCL"). */

/* The maps' shadowed test (blocked_all_around), 1 unless a test builds with 0: then every
 * sample the lit tests leave casts a ray, which the test's answers must match. */
#ifndef VISIBILITY_SHADOWED_TEST
#define VISIBILITY_SHADOWED_TEST 1
#endif

/* With reliefs, the first of their triangles (they come after all others: place_reliefs):
 * the 3 × 3 test holds only where none of the nine texels was drawn by a relief, whose
 * holes, finer than a texel, it would miss; those samples cast their rays. The triangle is
 * the keys' other word, so the maps' depths must be their keys (SHADOW_DEPTH_IN_KEYS). */
#ifdef VISIBILITY_RELIEF_FIRST
#if !SHADOW_DEPTH_IN_KEYS
#error "VISIBILITY_RELIEF_FIRST reads the shadow maps' keys: build with SHADOW_DEPTH_IN_KEYS"
#endif
#define SHADOW_TRIANGLE_AT(i) (2 * (i) + 1 - KEY_DEPTH_WORD)
#endif

/* Whether shadow-map texel i (clamped, of the whole atlas) was drawn by a relief's triangle. */
ALWAYS_INLINE int drawn_by_relief(global const uint* shadow_depth, int i)
{
#ifdef VISIBILITY_RELIEF_FIRST
    return (int)shadow_depth[SHADOW_TRIANGLE_AT(i)] >= VISIBILITY_RELIEF_FIRST; /* none: -1 */
#else
    return 0;
#endif
}

/* The depth, along the ray of texel centre (tx, ty) of a view, of the plane through p
 * with normal n: where that ray meets the sample's own plane; not positive where it does
 * not (behind the origin, or parallel: ±INFINITY or NaN). With the view's right, up and
 * forward orthonormal, a perspective ray's direction forward + x·right + y·up has length
 * √(1 + x² + y²) and n·direction linear in x and y; an orthographic ray starts at
 * origin + x·right + y·up. */
ALWAYS_INLINE float own_plane_depth(global const view_t* view, float3 p, float3 n, int tx, int ty)
{
    float num = inline_dot(n, p - view->origin.xyz);
    float along_right = view->scale_x * inline_dot(n, view->right.xyz);
    float along_up = view->scale_y * inline_dot(n, view->up.xyz);
    float along_forward = inline_dot(n, view->forward.xyz);
    float sx = (2.0f * (float)tx + 1.0f) / (float)view->width - 1.0f;
    float sy = 1.0f - (2.0f * (float)ty + 1.0f) / (float)view->height;
    float across_x = along_right * sx, across_y = along_up * sy;
    if (view->projection != PROJECTION_PERSPECTIVE) return (num - across_x - across_y) / along_forward;
    float spread = 1.0f + (sx * view->scale_x) * (sx * view->scale_x) + (sy * view->scale_y) * (sy * view->scale_y);
    return num * inline_sqrt(spread) / (along_forward + across_x + across_y);
}

/* Whether the map says the sample is shadowed: every centre of the 3×3 texels around the
 * sample p's own texel holds a blocker nearer than `lookup` (p moved off its surface,
 * towards the light's side) by the bias (a hole smaller than a texel in an occluder is
 * missed here, the map's one approximation). The nine centres surround p's ray by half a
 * texel or more, so an occluder whose outline is straight there covers it; around the
 * lookup's own texel, up to a texel aside at an inclined surface, they had left p's ray
 * outside on one side, and a lit sample beside a shadow's edge read as shadowed (demo,
 * behind and sun: 71–91 pixels at 1280×720, 40–98 % off). A texel that holds the sample's
 * own plane (p, n) there, within the bias, is no blocker either: an inclined surface comes
 * nearer than the lookup within the nine (docs/design.md §4.6). */
ALWAYS_INLINE int blocked_all_around(global const light_t* light, global const view_t* views,
                              global const uint* shadow_depth, float3 lookup, float3 p, float3 n)
{
    if (!VISIBILITY_SHADOWED_TEST) return 0;
    global const view_t* view = views + light_view_index(light, p);
    float2 texel, lookup_texel;
    float depth, p_depth;
    if (!view_project(view, p, &texel, &p_depth) || !view_project(view, lookup, &lookup_texel, &depth)) return 0;
    float tolerance = SURFACE_BIAS_TEXELS * shadow_texel_size(light, depth);
    int tx = (int)texel.x, ty = (int)texel.y;
    for (int j = -1; j <= 1; ++j)
        for (int i = -1; i <= 1; ++i) {
            float stored = shadow_texel(view, shadow_depth, tx + i, ty + j);
            if (depth <= stored + tolerance) return 0;
            int cx = inline_clamp_int(tx + i, 0, view->width - 1), cy = inline_clamp_int(ty + j, 0, view->height - 1);
            if (drawn_by_relief(shadow_depth, view->depth_offset + cy * view->width + cx)) return 0;
            float own = own_plane_depth(view, p, n, cx, cy);
            if (own > 0.0f && stored + tolerance >= own) return 0;
        }
    return 1;
}

/* The rest of the decision, for the pending samples and lights. Lit: the bound map says no
 * triangle in the texel comes nearer the light than the sample's own depth, less what its
 * own surface may have written there (at most the map's bias); or the writer map says no
 * triangle but those of the sample's own convex part touches that texel. Shadowed: the 3 × 3 test. Otherwise
 * the entry (sample × light_count + light) stays pending and is listed in ray_entries
 * (ray_count starts at 0) for visibility_rays: the host builds the BVH only when some
 * entry needs a ray (clrays/stages/visibility.py). */
/* The decision of one sample and light (entry = sample × light_count + l) that
 * visibility_prepare left pending. */
inline void decide_entry(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                         global const uint* shadow_depth, global const uint* bound, global const int* writer,
                         global const int2* map_read, global const uint* camera_depth, global const int* tri_id,
                         global const float4* tri_vertices, global const float4* tri_normal,
                         global const float2* offsets, global float* visible, global int* ray_entries,
                         volatile global int* ray_count, int sample, int l)
{
    global float* out = visible + sample * frame->light_count;
    if (out[l] != VISIBILITY_PENDING) return;
    int tri = tri_id[sample];
    global const light_t* light = lights + l;
    int2 read = map_read[sample * frame->light_count + l];
    if (read.x == MAP_TEXEL_OUTSIDE) {
        out[l] = 1.0f;
        return;
    }
    float depth = as_float(read.y), bound_depth = read.x >= 0 ? as_float(bound[read.x]) : 0.0f;
    if (read.x >= 0 && depth <= bound_depth) {
        out[l] = 1.0f;
        return;
    }
    if (read.x >= 0) {
        float3 p, dir, n;
        camera_surface_point(frame, views, camera_depth, tri_id, tri_normal, offsets, sample, &p, &dir, &n);
        if (only_own_part(tri_vertices, tri_normal, tri, writer[read.x], dir)) {
            out[l] = 1.0f;
            return;
        }
        /* Lit when depth ≤ bound + min(bias, slack), both ≥ 0: the slack's trigonometry
         * only within the bias (same answer as computing it first). */
        if (depth <= bound_depth + SURFACE_BIAS_TEXELS * shadow_texel_size(light, depth)
            && lit_within_own_slack(frame, views, light, tri_vertices, tri, p, n, depth, bound_depth)) {
            out[l] = 1.0f;
            return;
        }
        float3 lookup = shadow_lookup(light, p, n);
        if (blocked_all_around(light, views, shadow_depth, lookup, p, n)) {
            out[l] = 0.0f;
            return;
        }
    }
    ray_entries[atomic_inc(ray_count)] = sample * frame->light_count + l;
    if (read.x < 0) atomic_inc(ray_count + 1); /* no texel: only the BVH can answer it */
}

/* decide_entry on LANES consecutive samples and one light at once. A lane within the bias
 * of its bound has only its own surface's slack worked out alone (lit_within_own_slack);
 * where that leaves it, it takes the 3 × 3 test with the others, in lanes, rather than the
 * whole decision again (tests/stages/test_visibility_cost.py). 0, having written nothing,
 * where a lane needs exact_length's library call. An orthographic camera is never sent here. */
ALWAYS_INLINE int decide_lanes(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                               int l, global const uint* shadow_depth, global const uint* bound,
                               global const int* writer, global const int2* map_read, global const uint* camera_depth,
                               global const int* tri_id, global const float4* tri_vertices,
                               global const float4* tri_normal, global const float2* offsets, global float* visible,
                               global int* ray_entries, volatile global int* ray_count, int first)
{
    global const light_t* light = lights + l;
    int light_count = frame->light_count;
    int_lanes sample = first + (int_lanes)(0, 1, 2, 3, 4, 5, 6, 7), entry = sample * light_count + l;
    int runs = light_count == 1; /* the entries are the samples: runs of loads */
    float_lanes answer = runs ? load_run(visible, first) : LOAD_LANES(visible, entry);
    int_lanes pending = answer == VISIBILITY_PENDING;
    if (!any_lanes(pending)) return 1;
    global const float* reads = (global const float*)map_read;
    float_lanes address_bits, depth;
    if (runs) {
        load_pairs_run(reads, first, &address_bits, &depth);
    } else {
        address_bits = LOAD_LANES(reads, 2 * entry);
        depth = LOAD_LANES(reads, 2 * entry + 1);
    }
    int_lanes address = as_int8(address_bits);
    int_lanes texel = address >= 0, safe = texel ? address : 0;
    int_lanes tri = load_int_run(tri_id, first);
    float_lanes bound_depth = texel ? LOAD_LANES((global const float*)bound, safe) : 0.0f;
    /* only_own_part: the own part alone; a solid's, seen from its outside */
    int_lanes safe_tri = tri >= 0 ? tri : 0;
    int_lanes own_part = as_int8(LOAD_LANES((global const float*)tri_vertices, 12 * safe_tri + 7));
    int_lanes only_own = pending & texel & (as_int8(LOAD_LANES((global const float*)writer, safe)) == own_part);
    int_lanes outside_only = only_own & ((own_part & CONVEX_OUTSIDE_ONLY) != 0);
    if (any_lanes(outside_only)) {
        float_lanes dx, dy, dz;
        camera_ray_lanes(frame, views, offsets, sample, &dx, &dy, &dz);
        float_lanes fx, fy, fz, unused;
        gather_records(tri_normal, safe_tri, &fx, &fy, &fz, &unused);
        float_lanes front = fx * dx + fy * dy + fz * dz;
        only_own &= !outside_only | (front < 0.0f);
    }
    int_lanes lit = pending & ((address == MAP_TEXEL_OUTSIDE) | (texel & ((depth <= bound_depth) | only_own)));
    int_lanes heavy = pending & texel & !lit;
    int_lanes blocked = (int_lanes)(0);
    if (any_lanes(heavy)) {
        /* camera_surface_point */
        float_lanes distance = load_run((global const float*)camera_depth, first);
        float_lanes dx, dy, dz;
        camera_ray_lanes(frame, views, offsets, sample, &dx, &dy, &dz);
        float3 eye = views->origin.xyz;
        float_lanes px = eye.x + distance * dx, py = eye.y + distance * dy, pz = eye.z + distance * dz;
        int_lanes own = heavy ? tri : 0;
        float_lanes nx, ny, nz, unused;
        gather_records(tri_normal, own, &nx, &ny, &nz, &unused);
        int_lanes facing_away = dot_lanes_of_lanes(nx, ny, nz, dx, dy, dz) > 0.0f;
        nx = facing_away ? -nx : nx, ny = facing_away ? -ny : ny, nz = facing_away ? -nz : nz;
        float_lanes bias_size = light->type == LIGHT_DIRECTIONAL ? (float_lanes)(light->texel_angle)
                                                                 : depth * light->texel_angle;
        /* Within the bias of the bound, the own surface's slack decides, lane by lane; a lane
         * it leaves takes the 3 × 3 test with the others, in lanes. */
        int_lanes slack = heavy & (depth <= bound_depth + SURFACE_BIAS_TEXELS * bias_size);
        if (any_lanes(slack))
            for (int k = 0; k < LANES; ++k)
                if (slack[k]
                    && lit_within_own_slack(frame, views, light, tri_vertices, tri[k], (float3)(px[k], py[k], pz[k]),
                                            (float3)(nx[k], ny[k], nz[k]), depth[k], bound_depth[k]))
                    lit[k] = -1;
        heavy &= !lit;
        /* lookup = shadow_lookup (lighting.h) lane by lane, then blocked_all_around */
        float3 position = light->position.xyz;
        float_lanes wx = px - position.x, wy = py - position.y, wz = pz - position.z;
        float_lanes w_squared = squared_length_lanes(wx, wy, wz);
        if (light->type != LIGHT_DIRECTIONAL && any_lanes(heavy & !((w_squared >= 1.17549435e-38f) & (w_squared <= 3.40282347e38f))))
            return 0; /* exact_length's library call */
        float_lanes lookup_size = light->type == LIGHT_DIRECTIONAL ? (float_lanes)(light->texel_angle)
                                                                   : sqrt_lanes(w_squared) * light->texel_angle;
        float_lanes lx = px + nx * lookup_size, ly = py + ny * lookup_size, lz = pz + nz * lookup_size;
        view_lanes_t v; /* blocked_all_around's: the texels around p's, the lookup's depth */
        float_lanes texel_x, texel_y, p_depth;
        int_lanes projects = light_project_lanes(views, light, px, py, pz, &v, &texel_x, &texel_y, &p_depth);
        float_lanes qx = lx - v.origin_x, qy = ly - v.origin_y, qz = lz - v.origin_z;
        float_lanes lookup_depth = light->type != LIGHT_DIRECTIONAL
                                       ? length_lanes(qx, qy, qz)
                                       : dot_lanes_of_lanes(qx, qy, qz, v.forward_x, v.forward_y, v.forward_z);
        if (light->type != LIGHT_DIRECTIONAL) /* view_project's z > 0 */
            projects &= dot_lanes_of_lanes(qx, qy, qz, v.forward_x, v.forward_y, v.forward_z) > 0.0f;
        float_lanes size = light->type == LIGHT_DIRECTIONAL ? (float_lanes)(light->texel_angle)
                                                            : lookup_depth * light->texel_angle;
        float_lanes tolerance = SURFACE_BIAS_TEXELS * size;
        int_lanes tx = int_of_lanes(texel_x), ty = int_of_lanes(texel_y);
        blocked = VISIBILITY_SHADOWED_TEST ? heavy & projects : (int_lanes)(0);
        /* own_plane_depth, each lane's own plane (p, n), the same operations; its terms
         * along a row and a column of texels once for the three of each */
        float_lanes num = nx * (px - v.origin_x) + ny * (py - v.origin_y) + nz * (pz - v.origin_z);
        float_lanes along_right = v.scale_x * (nx * v.right_x + ny * v.right_y + nz * v.right_z);
        float_lanes along_up = v.scale_y * (nx * v.up_x + ny * v.up_y + nz * v.up_z);
        float_lanes along_forward = nx * v.forward_x + ny * v.forward_y + nz * v.forward_z;
        float_lanes across_x[3], across_y[3], spread_x[3], spread_y[3];
        int_lanes cxs[3], cys[3];
        for (int k = 0; k < 3; ++k) {
            cxs[k] = clamp_lanes_of_lanes(tx + k - 1, v.width), cys[k] = clamp_lanes_of_lanes(ty + k - 1, v.height);
            float_lanes sx = (2.0f * float_of_lanes(cxs[k]) + 1.0f) / float_of_lanes(v.width) - 1.0f;
            float_lanes sy = 1.0f - (2.0f * float_of_lanes(cys[k]) + 1.0f) / float_of_lanes(v.height);
            across_x[k] = along_right * sx, across_y[k] = along_up * sy;
            spread_x[k] = (sx * v.scale_x) * (sx * v.scale_x), spread_y[k] = (sy * v.scale_y) * (sy * v.scale_y);
        }
        int perspective = light->type != LIGHT_DIRECTIONAL;
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i) {
                int_lanes texel_index = v.depth_offset + cys[j] * v.width + cxs[i];
                float_lanes stored = LOAD_LANES((global const float*)shadow_depth, SHADOW_DEPTH_AT(texel_index));
#ifdef VISIBILITY_RELIEF_FIRST /* drawn_by_relief */
                blocked &= as_int8(LOAD_LANES((global const float*)shadow_depth, SHADOW_TRIANGLE_AT(texel_index)))
                           < VISIBILITY_RELIEF_FIRST;
#endif
                float_lanes t = perspective
                                    ? num * sqrt_lanes(1.0f + spread_x[i] + spread_y[j])
                                          / (along_forward + across_x[i] + across_y[j])
                                    : (num - across_x[i] - across_y[j]) / along_forward;
                int_lanes own_plane = (t > 0.0f) & (stored + tolerance >= t);
                blocked &= !(lookup_depth <= stored + tolerance) & !own_plane;
            }
    }
    if (runs) { /* the answers as one run of stores; the lanes left listed in turn */
        float_lanes decided = lit ? 1.0f : (blocked ? 0.0f : answer);
        *(global float8_at_float*)(visible + first) = pending ? decided : answer;
        int_lanes listed = pending & !lit & !blocked;
        if (any_lanes(listed))
            for (int k = 0; k < LANES; ++k) {
                if (!listed[k]) continue;
                ray_entries[atomic_inc(ray_count)] = entry[k];
                if (!texel[k]) atomic_inc(ray_count + 1); /* no texel: only the BVH can answer it */
            }
        return 1;
    }
    for (int k = 0; k < LANES; ++k) {
        if (!pending[k]) continue;
        if (lit[k]) {
            visible[entry[k]] = 1.0f;
        } else if (blocked[k]) {
            visible[entry[k]] = 0.0f;
        } else {
            ray_entries[atomic_inc(ray_count)] = entry[k];
            if (!texel[k]) atomic_inc(ray_count + 1); /* no texel: only the BVH can answer it */
        }
    }
    return 1;
}

/* The rest of the decision, for the pending samples and lights. Lit: the bound map says no
 * triangle in the texel comes nearer the light than the sample's own depth, less what its
 * own surface may have written there (at most the map's bias); or the writer map says no
 * triangle but those of the sample's own convex part touches that texel. Shadowed: the 3 × 3 test. Otherwise
 * the entry (sample × light_count + light) stays pending and is listed in ray_entries
 * (ray_count starts at 0) for visibility_rays: the host builds the BVH only when some
 * entry needs a ray (clrays/stages/visibility.py). One work-item per LANES samples
 * (decide_lanes, the same bits as decide_entry's; DECIDE_ONE_BY_ONE builds it with
 * decide_entry alone, for tests/stages/test_visibility_prepare.py). */
kernel void visibility(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                       global const uint* shadow_depth, global const uint* bound, global const int* writer,
                       global const int2* map_read, global const uint* camera_depth, global const int* tri_id,
                       global const float4* tri_vertices, global const float4* tri_normal,
                       global const float2* offsets, global float* visible, global int* ray_entries,
                       volatile global int* ray_count)
{
    int first = get_global_id(0) * LANES;
    int samples = frame->width * frame->height * frame->spp;
    if (first >= samples) return;
    for (int l = 0; l < frame->light_count; ++l) {
#ifndef DECIDE_ONE_BY_ONE
        if (first + LANES <= samples && views->projection == PROJECTION_PERSPECTIVE
            && decide_lanes(frame, views, lights, l, shadow_depth, bound, writer, map_read, camera_depth, tri_id,
                            tri_vertices, tri_normal, offsets, visible, ray_entries, ray_count, first))
            continue;
#endif
        for (int k = 0; k < LANES && first + k < samples; ++k)
            decide_entry(frame, views, lights, shadow_depth, bound, writer, map_read, camera_depth, tri_id, tri_vertices,
                         tri_normal, offsets, visible, ray_entries, ray_count, first + k, l);
    }
}

/* After visibility: the way the entries it left go (VISIBILITY_ROUTE_*), one work-item. None
 * left; else the frame's own lists of the triangles at each texel (a thumbnail), where every
 * light has them whole (`list_counts` of `lights`, each at most its `list_capacities`; no
 * lists: list_capacities 0) and every entry has a texel; else lists made for the rays'
 * texels alone (ray_lists), where those rays are at most `list_limit` and each has a
 * texel; else the BVH. */
kernel void visibility_route(global const int* ray_count, int lights, global const int* list_counts,
                             global const int* list_capacities, int list_limit, global int* route)
{
    if (get_global_id(0) != 0) return;
    int rays = ray_count[0], without_texel = ray_count[1], whole = lights > 0;
    for (int l = 0; l < lights; ++l) whole = whole && list_capacities[l] > 0 && list_counts[l] <= list_capacities[l];
    *route = rays == 0                             ? VISIBILITY_ROUTE_NONE
           : whole && !without_texel               ? VISIBILITY_ROUTE_LISTED
           : !whole && !without_texel && rays <= list_limit ? VISIBILITY_ROUTE_RAY_LISTS
                                                   : VISIBILITY_ROUTE_BVH;
}

/* After ray_lists: its lists answer the rays where every light's holds at most
 * `nodes_per_ray` nodes per ray (the room they had: more, and the BVH is the cheaper way);
 * else the BVH. One work-item. */
kernel void visibility_reroute(global const int* ray_count, int lights, global const int* list_counts,
                               int nodes_per_ray, global int* route)
{
    if (get_global_id(0) != 0 || *route != VISIBILITY_ROUTE_RAY_LISTS) return;
    int whole = 1;
    for (int l = 0; l < lights; ++l) whole = whole && list_counts[l] <= nodes_per_ray * ray_count[0];
    *route = whole ? VISIBILITY_ROUTE_RAY_LISTED : VISIBILITY_ROUTE_BVH;
}
