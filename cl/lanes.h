/* lanes.h — LANES samples per work-item as one float8 of each quantity, for the kernels
 * where PoCL would otherwise run one sample at a time (docs/design.md §4.5, "Cost on
 * PoCL").
 *
 * PoCL runs a work-group's work-items as a loop, which its vectorizer takes only when the
 * kernel has neither calls nor float3 arithmetic (inline_math.h); sampling.cl's kernels
 * have both, so they spell the vectors out instead. Each function here does, on every
 * lane, the operations of its scalar namesake in inline_math.h or atan2_approx.h in the
 * same order: the results are the same bit for bit. */
#ifndef CLRAYS_LANES_H
#define CLRAYS_LANES_H

#include "inline_math.h"
#include "atan2_approx.h"

/* LANES comes from clrays/stages/sampling.py (-D); the vectors below are float8. */
#ifndef LANES
#define LANES 8
#endif
#if LANES != 8
#error "lanes.h spells its vectors as float8: LANES must be 8"
#endif
typedef float8 float_lanes;
typedef int8 int_lanes;

/* A vector of `type` holding pointer[index] for each lane's index. */
#define GATHER_LANES(type, pointer, index)                                                                  \
    ((type)((pointer)[(index).s0], (pointer)[(index).s1], (pointer)[(index).s2], (pointer)[(index).s3],     \
            (pointer)[(index).s4], (pointer)[(index).s5], (pointer)[(index).s6], (pointer)[(index).s7]))
#define LOAD_LANES(pointer, index) GATHER_LANES(float_lanes, pointer, index)

/* A float8 aligned as its elements are: 8 consecutive floats in one plain load, where
 * PoCL's vload8 is a library call. */
typedef float8 __attribute__((aligned(4))) float8_at_float;

/* For each lane, the 8 floats at pointer + 4·index (two float4 records, one after the
 * other), as 8 vectors of lanes: out[k] holds float k of every lane's run. One vector
 * load per lane and a transpose, where LOAD_LANES would take 8 scalar loads per lane. */
ALWAYS_INLINE void load_runs_of_8(global const float* pointer, int_lanes index, float_lanes out[8])
{
    float8 p0 = *(global const float8_at_float*)(pointer + 4 * index.s0);
    float8 p1 = *(global const float8_at_float*)(pointer + 4 * index.s1);
    float8 p2 = *(global const float8_at_float*)(pointer + 4 * index.s2);
    float8 p3 = *(global const float8_at_float*)(pointer + 4 * index.s3);
    float8 p4 = *(global const float8_at_float*)(pointer + 4 * index.s4);
    float8 p5 = *(global const float8_at_float*)(pointer + 4 * index.s5);
    float8 p6 = *(global const float8_at_float*)(pointer + 4 * index.s6);
    float8 p7 = *(global const float8_at_float*)(pointer + 4 * index.s7);
    out[0] = (float8)(p0.s0, p1.s0, p2.s0, p3.s0, p4.s0, p5.s0, p6.s0, p7.s0);
    out[1] = (float8)(p0.s1, p1.s1, p2.s1, p3.s1, p4.s1, p5.s1, p6.s1, p7.s1);
    out[2] = (float8)(p0.s2, p1.s2, p2.s2, p3.s2, p4.s2, p5.s2, p6.s2, p7.s2);
    out[3] = (float8)(p0.s3, p1.s3, p2.s3, p3.s3, p4.s3, p5.s3, p6.s3, p7.s3);
    out[4] = (float8)(p0.s4, p1.s4, p2.s4, p3.s4, p4.s4, p5.s4, p6.s4, p7.s4);
    out[5] = (float8)(p0.s5, p1.s5, p2.s5, p3.s5, p4.s5, p5.s5, p6.s5, p7.s5);
    out[6] = (float8)(p0.s6, p1.s6, p2.s6, p3.s6, p4.s6, p5.s6, p6.s6, p7.s6);
    out[7] = (float8)(p0.s7, p1.s7, p2.s7, p3.s7, p4.s7, p5.s7, p6.s7, p7.s7);
}
#define LOAD_INT_LANES(pointer, index) GATHER_LANES(int_lanes, pointer, index)

typedef int8 __attribute__((aligned(4))) int8_at_int;
typedef uchar8 __attribute__((aligned(1))) uchar8_at_uchar;
/* pointer[first + k] on lane k: where the lanes' indices are known to run on by one (a
 * work-item's consecutive samples), one plain vector load, where LOAD_LANES takes 8 scalar
 * loads and inserts, and PoCL's vload8 is a library call. */
ALWAYS_INLINE float_lanes load_run(global const float* pointer, int first)
{
    return *(global const float8_at_float*)(pointer + first);
}
ALWAYS_INLINE int_lanes load_int_run(global const int* pointer, int first)
{
    return *(global const int8_at_int*)(pointer + first);
}
/* The pairs pointer[2·(first + k)], pointer[2·(first + k) + 1] on lane k, as two vectors:
 * two vector loads and a transpose. */
ALWAYS_INLINE void load_pairs_run(global const float* pointer, int first, float_lanes* even, float_lanes* odd)
{
    float_lanes a = load_run(pointer, 2 * first), b = load_run(pointer, 2 * first + 8);
    *even = (float_lanes)(a.s0, a.s2, a.s4, a.s6, b.s0, b.s2, b.s4, b.s6);
    *odd = (float_lanes)(a.s1, a.s3, a.s5, a.s7, b.s1, b.s3, b.s5, b.s7);
}

/* Eight float4 records as vectors of their x, y, z and w over the lanes: the records side
 * by side in pairs, interleaved, then picked, which compiles to a few shuffles. Picked
 * component by component (out.x[k] = record.x), the same transpose was 32 inserts: shade
 * took 0.71–0.83 of its time with this (docs/design.md §4.5, "Cost on PoCL"). */
ALWAYS_INLINE void transpose_records(float4 r0, float4 r1, float4 r2, float4 r3, float4 r4, float4 r5, float4 r6,
                                     float4 r7, float_lanes* x, float_lanes* y, float_lanes* z, float_lanes* w)
{
    float_lanes a = (float_lanes)(r0, r4), b = (float_lanes)(r1, r5);
    float_lanes c = (float_lanes)(r2, r6), d = (float_lanes)(r3, r7);
    float_lanes ab_lo = (float_lanes)(a.s0, b.s0, a.s1, b.s1, a.s4, b.s4, a.s5, b.s5);
    float_lanes cd_lo = (float_lanes)(c.s0, d.s0, c.s1, d.s1, c.s4, d.s4, c.s5, d.s5);
    float_lanes ab_hi = (float_lanes)(a.s2, b.s2, a.s3, b.s3, a.s6, b.s6, a.s7, b.s7);
    float_lanes cd_hi = (float_lanes)(c.s2, d.s2, c.s3, d.s3, c.s6, d.s6, c.s7, d.s7);
    *x = (float_lanes)(ab_lo.s0, ab_lo.s1, cd_lo.s0, cd_lo.s1, ab_lo.s4, ab_lo.s5, cd_lo.s4, cd_lo.s5);
    *y = (float_lanes)(ab_lo.s2, ab_lo.s3, cd_lo.s2, cd_lo.s3, ab_lo.s6, ab_lo.s7, cd_lo.s6, cd_lo.s7);
    *z = (float_lanes)(ab_hi.s0, ab_hi.s1, cd_hi.s0, cd_hi.s1, ab_hi.s4, ab_hi.s5, cd_hi.s4, cd_hi.s5);
    *w = (float_lanes)(ab_hi.s2, ab_hi.s3, cd_hi.s2, cd_hi.s3, ab_hi.s6, ab_hi.s7, cd_hi.s6, cd_hi.s7);
}

/* records[index] of each lane, as its x, y, z and w over the lanes. */
ALWAYS_INLINE void gather_records(global const float4* records, int_lanes index, float_lanes* x, float_lanes* y,
                                  float_lanes* z, float_lanes* w)
{
    transpose_records(records[index.s0], records[index.s1], records[index.s2], records[index.s3], records[index.s4],
                      records[index.s5], records[index.s6], records[index.s7], x, y, z, w);
}

/* records[first + k] on lane k, for a run of 8 consecutive records: four vector loads of
 * two records each and transpose_records. */
ALWAYS_INLINE void load_records_run(global const float4* records, int first, float_lanes* x, float_lanes* y,
                                    float_lanes* z, float_lanes* w)
{
    global const float* p = (global const float*)(records + first);
    float_lanes a = load_run(p, 0), b = load_run(p, 8), c = load_run(p, 16), d = load_run(p, 24);
    transpose_records(a.lo, a.hi, b.lo, b.hi, c.lo, c.hi, d.lo, d.hi, x, y, z, w);
}

/* The other way: lane k's (x, y, z, w) as record k of a run, two records to each of the
 * four vectors in `pairs` (to store at records + first as float8_at_float). */
ALWAYS_INLINE void records_of_lanes(float_lanes x, float_lanes y, float_lanes z, float_lanes w, float_lanes pairs[4])
{
    pairs[0] = (float_lanes)(x.s0, y.s0, z.s0, w.s0, x.s1, y.s1, z.s1, w.s1);
    pairs[1] = (float_lanes)(x.s2, y.s2, z.s2, w.s2, x.s3, y.s3, z.s3, w.s3);
    pairs[2] = (float_lanes)(x.s4, y.s4, z.s4, w.s4, x.s5, y.s5, z.s5, w.s5);
    pairs[3] = (float_lanes)(x.s6, y.s6, z.s6, w.s6, x.s7, y.s7, z.s7, w.s7);
}

/* load_pairs_run's inverse: lane k's (even, odd) stored at pointer[2·(first + k)] and the
 * float after it, as two vector stores. */
ALWAYS_INLINE void store_pairs_run(global float* pointer, int first, float_lanes even, float_lanes odd)
{
    global float8_at_float* out = (global float8_at_float*)(pointer + 2 * first);
    out[0] = (float_lanes)(even.s0, odd.s0, even.s1, odd.s1, even.s2, odd.s2, even.s3, odd.s3);
    out[1] = (float_lanes)(even.s4, odd.s4, even.s5, odd.s5, even.s6, odd.s6, even.s7, odd.s7);
}

ALWAYS_INLINE float_lanes float_of_lanes(int_lanes x) { return __builtin_convertvector(x, float_lanes); }
ALWAYS_INLINE int_lanes int_of_lanes(float_lanes x) { return __builtin_convertvector(x, int_lanes); }
ALWAYS_INLINE float_lanes fabs_lanes(float_lanes x) { return as_float8(as_uint8(x) & 0x7fffffffu); }
ALWAYS_INLINE float_lanes copysign_lanes(float_lanes x, float_lanes sign)
{
    return as_float8((as_uint8(x) & 0x7fffffffu) | (as_uint8(sign) & 0x80000000u));
}
ALWAYS_INLINE float_lanes fmax_lanes(float_lanes a, float_lanes b) { return ((b != b) | (a > b)) ? a : b; }
ALWAYS_INLINE float_lanes fmin_lanes(float_lanes a, float_lanes b) { return ((b != b) | (a < b)) ? a : b; }
/* Whether every (any) lane of a comparison is true, without PoCL's all() (any()) library call. */
ALWAYS_INLINE int all_lanes(int_lanes mask)
{
    int4 halves = mask.lo & mask.hi;
    int2 quarters = halves.lo & halves.hi;
    return (quarters.x & quarters.y) != 0;
}
ALWAYS_INLINE int any_lanes(int_lanes mask)
{
    int4 halves = mask.lo | mask.hi;
    int2 quarters = halves.lo | halves.hi;
    return (quarters.x | quarters.y) != 0;
}
ALWAYS_INLINE int_lanes min_lanes(int_lanes a, int_lanes b) { return a > b ? b : a; }
ALWAYS_INLINE int_lanes max_lanes(int_lanes a, int_lanes b) { return a < b ? b : a; }
/* Each lane clamped to [0, size - 1] of its own size (shadow_texel's clamp). */
ALWAYS_INLINE int_lanes clamp_lanes_of_lanes(int_lanes x, int_lanes size)
{
    return min_lanes(max_lanes(x, (int_lanes)(0)), size - 1);
}
ALWAYS_INLINE int_lanes clamp_int_lanes(int_lanes x, int lo, int hi)
{
    return min_lanes(max_lanes(x, (int_lanes)(lo)), (int_lanes)(hi));
}

/* inline_floor's operations on each lane. */
ALWAYS_INLINE float_lanes floor_lanes(float_lanes x)
{
    float_lanes fraction = x - float_of_lanes(int_of_lanes(x));
    fraction = fraction < 0.0f ? fraction + 1.0f : fraction;
    float_lanes floored = copysign_lanes(x - fraction, x);
    return fabs_lanes(x) < 8388608.0f ? floored : x;
}

ALWAYS_INLINE float_lanes sqrt_lanes(float_lanes x)
{
    return (float_lanes)(__builtin_sqrtf(x.s0), __builtin_sqrtf(x.s1), __builtin_sqrtf(x.s2), __builtin_sqrtf(x.s3),
                         __builtin_sqrtf(x.s4), __builtin_sqrtf(x.s5), __builtin_sqrtf(x.s6), __builtin_sqrtf(x.s7));
}

#pragma OPENCL FP_CONTRACT OFF /* as the library's dot, cross and mix (inline_math.h) */
ALWAYS_INLINE float_lanes dot_lanes(float_lanes ax, float_lanes ay, float_lanes az, float bx, float by, float bz)
{
    float_lanes x = ax * bx, y = ay * by, z = az * bz;
    return z + (x + y);
}

/* dot_lanes where both vectors vary by lane. */
ALWAYS_INLINE float_lanes dot_lanes_of_lanes(float_lanes ax, float_lanes ay, float_lanes az, float_lanes bx,
                                             float_lanes by, float_lanes bz)
{
    float_lanes x = ax * bx, y = ay * by, z = az * bz;
    return z + (x + y);
}

ALWAYS_INLINE float_lanes squared_length_lanes(float_lanes ax, float_lanes ay, float_lanes az)
{
    float_lanes x = ax * ax, y = ay * ay, z = az * az;
    return z + (x + y);
}

/* inline_length on each lane. */
ALWAYS_INLINE float_lanes length_lanes(float_lanes x, float_lanes y, float_lanes z)
{
    float_lanes squared = squared_length_lanes(x, y, z);
    return squared >= 1.17549435e-38f ? sqrt_lanes(squared) : 0.0f;
}

ALWAYS_INLINE float_lanes cross_length_lanes(float_lanes ax, float_lanes ay, float_lanes az, float bx, float by,
                                             float bz)
{
    float_lanes cx = ay * bz - az * by, cy = az * bx - ax * bz, cz = ax * by - ay * bx;
    return length_lanes(cx, cy, cz);
}

ALWAYS_INLINE float_lanes mix_lanes(float_lanes a, float_lanes b, float_lanes t) { return (b - a) * t + a; }

#pragma OPENCL FP_CONTRACT ON

/* atan2_approx (atan2_approx.h) on each lane. */
ALWAYS_INLINE float_lanes atan2_approx_lanes(float_lanes y, float_lanes x)
{
    float_lanes ax = fabs_lanes(x), ay = fabs_lanes(y);
    float_lanes big = fmax_lanes(ax, ay), small = fmin_lanes(ax, ay);
    float_lanes t = big > 0.0f ? small / big : 0.0f;
    int_lanes reduced = t > ATAN_REDUCE_ABOVE;
    float_lanes r = reduced ? (t - 1.0f) / (t + 1.0f) : t;
    float_lanes z = r * r;
    float_lanes a = ATAN_OF_REDUCED(r, z);
    a = reduced ? a + M_PI_4_F : a;
    a = ay > ax ? M_PI_2_F - a : a;
    a = x < 0.0f ? M_PI_F - a : a;
    return copysign_lanes(a, y);
}


/* Each lane's pixel column and row and its sample within the pixel. Eight consecutive
 * samples of a one-sample-per-pixel frame at least 8 wide lie in one row or wrap once into
 * the next: one scalar division then, instead of integer divisions on every lane (each a
 * slow instruction of its own on a CPU). */
ALWAYS_INLINE void sample_pixel_lanes(global const frame_t* frame, int_lanes sample, int_lanes* column, int_lanes* row,
                                      int_lanes* sub)
{
    const int_lanes lane = (int_lanes)(0, 1, 2, 3, 4, 5, 6, 7);
    int first = sample.s0, width = frame->width;
    if (frame->spp == 1 && width >= LANES && all_lanes(sample == first + lane)) {
        int_lanes x = first % width + lane;
        int_lanes wraps = x >= width; /* -1 where the run passes the row's end */
        *column = wraps ? x - width : x;
        *row = first / width - wraps;
        *sub = (int_lanes)(0);
        return;
    }
    int_lanes pixel = sample / frame->spp;
    *sub = sample % frame->spp;
    *column = pixel % width;
    *row = pixel / width;
}

/* The camera's ray direction for LANES camera samples: view_screen and view_ray
 * (lighting.h) operation for operation, each product in its own statement as there (no
 * fused multiply-add), so the same bits; an orthographic view's direction is forward.
 * Needs common.h's frame_t and view_t (its includers have them). */
ALWAYS_INLINE void camera_ray_lanes(global const frame_t* frame, global const view_t* views,
                                    global const float2* offsets, int_lanes sample, float_lanes* dx,
                                    float_lanes* dy, float_lanes* dz)
{
    int_lanes column, row, sub;
    sample_pixel_lanes(frame, sample, &column, &row, &sub);
    global const float* offset = (global const float*)offsets;
    float_lanes offset_x, offset_y;
    if (frame->spp == 1) { /* every lane's offset is the one sample's: read once */
        offset_x = offset[0];
        offset_y = offset[1];
    } else {
        offset_x = LOAD_LANES(offset, 2 * sub);
        offset_y = LOAD_LANES(offset, 2 * sub + 1);
    }
    float_lanes sx = 2.0f * (float_of_lanes(column) + offset_x) / (float)views->width - 1.0f;
    float_lanes sy = 1.0f - 2.0f * (float_of_lanes(row) + offset_y) / (float)views->height;
    float3 forward = views->forward.xyz, right = views->right.xyz, up = views->up.xyz;
    *dx = forward.x;
    *dy = forward.y;
    *dz = forward.z;
    if (views->projection == PROJECTION_PERSPECTIVE) {
        float_lanes along_right = sx * views->scale_x, along_up = sy * views->scale_y;
        float_lanes rx = right.x * along_right, ry = right.y * along_right, rz = right.z * along_right;
        float_lanes ux = up.x * along_up, uy = up.y * along_up, uz = up.z * along_up;
        float_lanes x = *dx + rx + ux, y = *dy + ry + uy, z = *dz + rz + uz;
        float_lanes inverse = 1.0f / sqrt_lanes(squared_length_lanes(x, y, z));
        *dx = x * inverse;
        *dy = y * inverse;
        *dz = z * inverse;
    }
}


/* A vector of component `component` of field `field` of each lane's view (views[index]). */
#define VIEW_LANES(views, index, field, component)                                                         \
    LOAD_LANES((global const float*)(views) + __builtin_offsetof(view_t, field) / 4 + (component),          \
               (index) * (int)(sizeof(view_t) / 4))
#define VIEW_INT_LANES(views, index, field) as_int8(VIEW_LANES(views, index, field, 0))

/* The fields of a view that a projection reads, one per lane. */
typedef struct {
    float_lanes origin_x, origin_y, origin_z, right_x, right_y, right_z, up_x, up_y, up_z;
    float_lanes forward_x, forward_y, forward_z, scale_x, scale_y;
    int_lanes width, height, depth_offset;
} view_lanes_t;

/* Each lane's own view, views[index]. */
ALWAYS_INLINE view_lanes_t view_gather(global const view_t* views, int_lanes index)
{
    view_lanes_t v;
    v.origin_x = VIEW_LANES(views, index, origin, 0), v.origin_y = VIEW_LANES(views, index, origin, 1);
    v.origin_z = VIEW_LANES(views, index, origin, 2);
    v.right_x = VIEW_LANES(views, index, right, 0), v.right_y = VIEW_LANES(views, index, right, 1);
    v.right_z = VIEW_LANES(views, index, right, 2);
    v.up_x = VIEW_LANES(views, index, up, 0), v.up_y = VIEW_LANES(views, index, up, 1), v.up_z = VIEW_LANES(views, index, up, 2);
    v.forward_x = VIEW_LANES(views, index, forward, 0), v.forward_y = VIEW_LANES(views, index, forward, 1);
    v.forward_z = VIEW_LANES(views, index, forward, 2);
    v.scale_x = VIEW_LANES(views, index, scale_x, 0), v.scale_y = VIEW_LANES(views, index, scale_y, 0);
    v.width = VIEW_INT_LANES(views, index, width), v.height = VIEW_INT_LANES(views, index, height);
    v.depth_offset = VIEW_INT_LANES(views, index, depth_offset);
    return v;
}

/* One view for every lane. */
ALWAYS_INLINE view_lanes_t view_broadcast(global const view_t* view)
{
    view_lanes_t v;
    v.origin_x = view->origin.x, v.origin_y = view->origin.y, v.origin_z = view->origin.z;
    v.right_x = view->right.x, v.right_y = view->right.y, v.right_z = view->right.z;
    v.up_x = view->up.x, v.up_y = view->up.y, v.up_z = view->up.z;
    v.forward_x = view->forward.x, v.forward_y = view->forward.y, v.forward_z = view->forward.z;
    v.scale_x = view->scale_x, v.scale_y = view->scale_y;
    v.width = view->width, v.height = view->height, v.depth_offset = view->depth_offset;
    return v;
}

/* light_view_index (lighting.h) on each lane: the light's one view, or the cube face of
 * the major axis of p - the light's position. */
ALWAYS_INLINE int_lanes light_view_index_lanes(global const light_t* light, float_lanes px, float_lanes py,
                                               float_lanes pz)
{
    if (light->view_count == 1) return (int_lanes)(light->first_view);
    float_lanes wx = px - light->position.x, wy = py - light->position.y, wz = pz - light->position.z;
    float_lanes ax = fabs_lanes(wx), ay = fabs_lanes(wy), az = fabs_lanes(wz);
    int_lanes axis_index = (ax >= ay & ax >= az) ? 0 : (ay >= az ? 1 : 2);
    float_lanes component = axis_index == 0 ? wx : (axis_index == 1 ? wy : wz);
    return light->first_view + 2 * axis_index + (component < 0.0f ? 1 : 0);
}

/* The views of the lanes' indices: read once when the lanes share one (the same values,
 * so the same bits), else gathered. */
ALWAYS_INLINE view_lanes_t views_of_lanes(global const view_t* views, int_lanes index)
{
    return all_lanes(index == index.s0) ? view_broadcast(views + index.s0) : view_gather(views, index);
}

#endif
