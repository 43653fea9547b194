/* visibility_prepare — per camera sample and light, what the maps are asked (visibility.h).
 * visibility_prepare reads frame, views, lights, camera_depth, tri_id,
 * tri_normal, offsets (tri_vertex_normals stays in its signature, unread); writes visible (1 no light reaches the sample,
 * 0 its surface turns away from the light, else pending: the maps or a ray decide),
 * map_read (per sample and light, the bound map's texel its lit test reads and its depth
 * there) and read_mask (a bit per texel read): the bound passes draw only those. */
#include "visibility.h"

/* Whether the sample's surface turns away from the light: its flat normal n (already
 * facing the camera) does. An opaque surface is not lit from behind, whatever a smooth
 * triangle's vertex normals say: were they to decide, a sphere seen from inside took
 * light through its own wall at the terminator. Its visibility is then never read. The
 * margin keeps float32 rounding on the lit side. */
ALWAYS_INLINE int turned_away(float3 n, float3 to_light)
{
    const float margin = -1e-4f;
    return !(inline_dot(n, to_light) > margin);
}

/* A texel that a lit test reads gets its bit in read_mask (32 texels a word, by address;
 * starts at 0): the bound passes draw only those. */
ALWAYS_INLINE void mark_read_bits(global uint* read_mask, int word_index, uint bits)
{
    global uint* word = read_mask + word_index;
    if (bits & ~*word) atomic_or(word, bits); /* the read spares most atomics */
}

ALWAYS_INLINE void mark_read(global uint* read_mask, int address)
{
    if (address >= 0) mark_read_bits(read_mask, address >> 5, 1u << (address & 31));
}

/* The part of the decision that needs no bound map, before it is drawn, one work-item per
 * sample and light: visible gets 1 where no light arrives (or
 * the eye is in the lamp), 0 where the surface turns away from the light, else
 * VISIBILITY_PENDING; map_read gets the texel of the
 * bound and writer maps that the lit test reads (the point the shadow ray leaves from,
 * projected: its address, or MAP_TEXEL_*) and the point's depth there. The texel is
 * given for every sample not turned away, whatever the light's power and the medium, so
 * the texels read (mark_read) follow the geometry with its shading normals (which
 * turn a surface away and offset the ray's start), the camera and the light's place alone,
 * which is what a kept bound map is keyed on (clrays/session.py). */
inline void prepare_entry(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                          global const uint* camera_depth, global const int* tri_id, global const float4* tri_normal,
                          global const float4* tri_vertex_normals, global const float2* offsets,
                          global float* visible, global int2* map_read, global uint* read_mask, int sample, int l)
{
    int entry = sample * frame->light_count + l;
    visible[entry] = 1.0f;
    map_read[entry] = (int2)(MAP_TEXEL_NONE, 0);
    float3 p, dir, n;
    if (!camera_surface_point(frame, views, camera_depth, tri_id, tri_normal, offsets, sample, &p, &dir, &n)) return;
    int tri = tri_id[sample];
    global const light_t* light = lights + l;
    float3 to_light;
    int reaches = light_reaches(light, frame->sigma_t.xyz, p, &to_light)
                  && !eye_in_lamp(light, frame->lamp_radius);
    if (turned_away(n, to_light)) {
        if (reaches) visible[entry] = 0.0f; /* unlit from behind: no map test, no ray */
        return;
    }
    float3 start = shadow_ray_start(light, p, n, to_light);
    global const view_t* view = views + light_view_index(light, start);
    float2 texel;
    float depth = 0.0f;
    int address = MAP_TEXEL_NONE;
    if (view_project(view, start, &texel, &depth)) {
        address = MAP_TEXEL_OUTSIDE;
        if (texel.x >= 0.0f && texel.y >= 0.0f && texel.x < (float)view->width && texel.y < (float)view->height)
            address = view->depth_offset + (int)texel.y * view->width + (int)texel.x;
    }
    map_read[entry] = (int2)(address, as_int(depth));
    mark_read(read_mask, address);
    if (reaches) visible[entry] = VISIBILITY_PENDING;
}

/* What prepare_lanes writes for LANES consecutive samples and light l: each entry's
 * answer and the texel (address, depth bits) its lit test reads. With one light the entries
 * are the samples, and the stores are runs. */
ALWAYS_INLINE void store_prepared(global const frame_t* frame, int first, int l, float_lanes answer,
                                  int_lanes address, int_lanes depth, global float* visible, global int2* map_read)
{
    if (frame->light_count == 1) {
        *(global float8_at_float*)(visible + first) = answer;
        store_pairs_run((global float*)map_read, first, as_float8(address), as_float8(depth));
        return;
    }
    for (int k = 0; k < LANES; ++k) {
        int entry = (first + k) * frame->light_count + l;
        visible[entry] = answer[k];
        map_read[entry] = (int2)(address[k], depth[k]);
    }
}

/* prepare_entry on LANES consecutive samples at once; 0, having written nothing, where a
 * lane needs a path written only there (visibility_prepare). */
ALWAYS_INLINE int prepare_lanes(global const frame_t* frame, global const view_t* views, global const light_t* light,
                                int l, global const uint* camera_depth, global const int* tri_id,
                                global const float4* tri_normal, global const float4* tri_vertex_normals,
                                global const float2* offsets, int first, global float* visible,
                                global int2* map_read, global uint* read_mask)
{
    int_lanes sample = first + (int_lanes)(0, 1, 2, 3, 4, 5, 6, 7);
    /* camera_surface_point */
    float_lanes distance = load_run((global const float*)camera_depth, first);
    int_lanes tri = load_int_run(tri_id, first);
    int_lanes surface = (tri >= 0) & !(distance > frame->far);
    if (!any_lanes(surface)) { /* the sky, or past far: lit, no texel */
        store_prepared(frame, first, l, 1.0f, MAP_TEXEL_NONE, 0, visible, map_read);
        return 1;
    }
    int_lanes own = surface ? tri : 0;
    float_lanes dx, dy, dz;
    camera_ray_lanes(frame, views, offsets, sample, &dx, &dy, &dz);
    float3 eye = views->origin.xyz;
    float_lanes px = eye.x + distance * dx, py = eye.y + distance * dy, pz = eye.z + distance * dz;
    float_lanes nx, ny, nz, flat_w; /* the triangle's normal; w: 0 flat, else smooth (unread here) */
    gather_records(tri_normal, own, &nx, &ny, &nz, &flat_w);
    int_lanes facing_away = dot_lanes_of_lanes(nx, ny, nz, dx, dy, dz) > 0.0f;
    nx = facing_away ? -nx : nx, ny = facing_away ? -ny : ny, nz = facing_away ? -nz : nz;
    /* light_reaches, where no exp is needed to know */
    float_lanes lx, ly, lz; /* to_light */
    int_lanes reaches;
    float3 position = light->position.xyz;
    if (light->type == LIGHT_DIRECTIONAL) {
        float3 power = light->power.xyz;
        lx = -light->direction.x, ly = -light->direction.y, lz = -light->direction.z;
        reaches = (int_lanes)(power.x + power.y + power.z != 0.0f ? -1 : 0);
    } else {
        float_lanes wx = px - position.x, wy = py - position.y, wz = pz - position.z;
        float_lanes d2 = squared_length_lanes(wx, wy, wz);
        float_lanes d = sqrt_lanes(d2);
        int_lanes away = d > 0.0f;
        lx = away ? -wx / d : 0.0f, ly = away ? -wy / d : 1.0f, lz = away ? -wz / d : 0.0f;
        float3 spot = light->direction.xyz, power = light->power.xyz, sigma_t = frame->sigma_t.xyz;
        int_lanes outside = light->type == LIGHT_SPOT ? dot_lanes(wx, wy, wz, spot.x, spot.y, spot.z)
                                                            < light->cos_cone * d
                                                      : (int_lanes)(0);
        float_lanes ax = sigma_t.x * d, ay = sigma_t.y * d, az = sigma_t.z * d;
        /* (a scalar comparison is 1, a vector's -1: the channels' tests stay vectors) */
        int_lanes none = (int_lanes)(0);
        int_lanes arrives = (d2 <= 1e10f)
                            & ((power.x >= 1e-6f ? ax <= 30.0f : none) | (power.y >= 1e-6f ? ay <= 30.0f : none)
                               | (power.z >= 1e-6f ? az <= 30.0f : none));
        if (any_lanes(surface & !outside & !arrives)) return 0; /* light_incident decides */
        reaches = !outside & arrives;
    }
    if (eye_in_lamp(light, frame->lamp_radius)) reaches = (int_lanes)(0);
    /* turned_away */
    const float margin = -1e-4f;
    float_lanes facing = dot_lanes_of_lanes(nx, ny, nz, lx, ly, lz);
    int_lanes turned = !(facing > margin);
    if (!any_lanes(surface & !turned)) { /* nothing to project: no surface, or turned away */
        store_prepared(frame, first, l, (surface & reaches) ? 0.0f : 1.0f, MAP_TEXEL_NONE, 0, visible, map_read);
        return 1;
    }
    /* shadow_ray_start */
    float_lanes ex = position.x - px, ey = position.y - py, ez = position.z - pz;
    float_lanes to_light_squared = squared_length_lanes(ex, ey, ez), p_squared = squared_length_lanes(px, py, pz);
    int_lanes plain = (p_squared >= 1.17549435e-38f) & (p_squared <= 3.40282347e38f);
    if (light->type != LIGHT_DIRECTIONAL)
        plain &= (to_light_squared >= 1.17549435e-38f) & (to_light_squared <= 3.40282347e38f);
    if (any_lanes(surface & !turned & !plain)) return 0; /* exact_length's library call */
    float_lanes to_light_distance = light->type == LIGHT_DIRECTIONAL ? 0.0f : sqrt_lanes(to_light_squared);
    int_lanes towards = facing >= 0.0f;
    float_lanes sx = towards ? nx : -nx, sy = towards ? ny : -ny, sz = towards ? nz : -nz;
    float_lanes cosine = fabs_lanes(facing);
    float_lanes push = SHADOW_RAY_OFFSET_REL * (sqrt_lanes(p_squared) + to_light_distance);
    float_lanes along = push / fmax_lanes(cosine, (float_lanes)(SHADOW_RAY_ALONG_MIN));
    float_lanes lift = push - along * cosine;
    float_lanes start_x = px + lx * along + sx * lift, start_y = py + ly * along + sy * lift,
                start_z = pz + lz * along + sz * lift;
    view_lanes_t v;
    float_lanes texel_x, texel_y, depth;
    int_lanes projects = light_project_lanes(views, light, start_x, start_y, start_z, &v, &texel_x, &texel_y, &depth);
    int_lanes inside = texel_x >= 0.0f & texel_y >= 0.0f & texel_x < float_of_lanes(v.width)
                       & texel_y < float_of_lanes(v.height);
    int_lanes address = projects ? (inside ? v.depth_offset + int_of_lanes(texel_y) * v.width + int_of_lanes(texel_x)
                                           : (int_lanes)(MAP_TEXEL_OUTSIDE))
                                 : (int_lanes)(MAP_TEXEL_NONE);
    depth = projects ? depth : 0.0f;
    /* what prepare_entry writes: no surface, turned away, or pending with its texel */
    float_lanes when_reached = turned ? (float_lanes)(0.0f) : (float_lanes)(VISIBILITY_PENDING);
    float_lanes answer = (surface & reaches) ? when_reached : (float_lanes)(1.0f);
    int_lanes read_address = (surface & !turned) ? address : (int_lanes)(MAP_TEXEL_NONE);
    int_lanes read_depth = (surface & !turned) ? as_int8(depth) : (int_lanes)(0);
    store_prepared(frame, first, l, answer, read_address, read_depth, visible, map_read);
    /* Where every lane reads a texel of one mask word (neighbouring samples often do, as on
     * demo's floor), their bits go in at once; else lane by lane. */
    int_lanes word = read_address >> 5, reads = read_address >= 0;
    if (reads.s0 && all_lanes(!reads | (word == word.s0))) {
        uint8 bits = reads ? (uint8)(1u) << as_uint8(read_address & 31) : (uint8)(0u);
        uint4 halves = bits.lo | bits.hi;
        uint2 quarters = halves.lo | halves.hi;
        mark_read_bits(read_mask, word.s0, quarters.x | quarters.y);
    } else {
        for (int k = 0; k < LANES; ++k) mark_read(read_mask, read_address[k]);
    }
    return 1;
}

/* visibility_prepare for LANES camera samples and one light per work-item, as float8
 * (lanes.h): prepare_entry's operations on each lane, each statement of the same shape,
 * so the same bits (tests/stages/test_visibility_prepare.py). A group of lanes where one
 * would take a rarer path (an orthographic camera, a light that needs light_incident's
 * exp to know it arrives, a length outside inline_length's range) takes prepare_entry
 * lane by lane. PREPARE_ONE_BY_ONE builds the kernel with prepare_entry alone (the test). */
kernel void visibility_prepare(global const frame_t* frame, global const view_t* views,
                               global const light_t* lights, global const uint* camera_depth, global const int* tri_id,
                               global const float4* tri_normal, global const float4* tri_vertex_normals,
                               global const float2* offsets, global float* visible, global int2* map_read,
                               global uint* read_mask)
{
    int first = get_global_id(0) * LANES, l = get_global_id(1);
    int samples = frame->width * frame->height * frame->spp;
    if (first >= samples) return;
    global const light_t* light = lights + l;
#ifndef PREPARE_ONE_BY_ONE
    if (first + LANES <= samples && views->projection == PROJECTION_PERSPECTIVE
        && prepare_lanes(frame, views, light, l, camera_depth, tri_id, tri_normal, tri_vertex_normals, offsets, first,
                         visible, map_read, read_mask))
        return;
#endif
    for (int k = 0; k < LANES && first + k < samples; ++k)
        prepare_entry(frame, views, lights, camera_depth, tri_id, tri_normal, tri_vertex_normals, offsets, visible,
                      map_read, read_mask, first + k, l);
}

/* The texels of the entries left to a shadow ray (clrays/stages/visibility.py ray_lists):
 * their addresses get their bit in read_mask, as visibility_prepare's. The entries' count is
 * read here (ray_count[0]), each work-item taking a run of them. */
kernel void visibility_mark_listed(global const int* ray_entries, global const int* ray_count,
                                   global const int2* map_read, global uint* read_mask, ROUTE_ARGS)
{
    RETURN_UNLESS_ROUTED
    LIST_RUN(ray_count[0], begin, end)
    for (int item = begin; item < end; ++item) mark_read(read_mask, map_read[ray_entries[item]].x);
}
