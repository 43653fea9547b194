/* raster — triangles → depth for one view (the camera or a shadow-map view).
 * Reads tri_vertices (3 float4 per triangle, eye space), views[view_index], offsets;
 * writes depth (as_uint(t), atomic min) and, for the camera, the nearest triangle:
 * raster_nearest packs (depth, triangle) in one 64-bit atomic min and raster_split
 * unpacks it; without 64-bit atomics, raster_resolve re-tests (ties: highest index).
 *
 * One work-item per triangle: it clips the triangle to the view's near side,
 * projects the polygon, and per pixel row ray-tests the samples in the row's span of
 * the polygon; triangles taller than RASTER_BIG_ROWS go to a second pass with one
 * work-item per (triangle, row it spans) (`*_rows`). The ray test (not interpolation)
 * makes depth exact along the sample ray, and two-sided. Depth buffer layout per view:
 * [height][width][samples]. */
#include "lighting.h"

/* Barycentric slack: float32 rounding can put a ray through a shared edge outside
 * both triangles; a relative 1e-5 overlap closes such cracks (depth test resolves it). */
#define EDGE_SLACK 1e-5f

/* Möller–Trumbore, two-sided, edges inclusive with EDGE_SLACK. */
inline float intersect_triangle(float3 origin, float3 dir, float3 v0, float3 v1, float3 v2)
{
    float3 e1 = v1 - v0, e2 = v2 - v0;
    float3 pv = cross(dir, e2);
    float det = dot(e1, pv);
    if (det == 0.0f) return INFINITY;
    float inv = 1.0f / det;
    float3 tv = origin - v0;
    float u = dot(tv, pv) * inv;
    if (u < -EDGE_SLACK || u > 1.0f + EDGE_SLACK) return INFINITY;
    float3 qv = cross(tv, e1);
    float v = dot(dir, qv) * inv;
    if (v < -EDGE_SLACK || u + v > 1.0f + EDGE_SLACK) return INFINITY;
    float t = dot(e2, qv) * inv;
    return t > 0.0f ? t : INFINITY;
}

/* The triangle clipped to the view's near side and projected to pixel coordinates
 * (x right, y down): a convex polygon of up to 4 corners. Returns the corner count. */
inline int projected_polygon(global const view_t* view, float3 v0, float3 v1, float3 v2, float2 corner[4])
{
    float3 world[3] = {v0, v1, v2};
    float3 in_view[3];
    float extent = 0.0f;
    for (int k = 0; k < 3; ++k) {
        float3 q = world[k] - view->origin.xyz;
        in_view[k] = (float3)(dot(q, view->right.xyz), dot(q, view->up.xyz), dot(q, view->forward.xyz));
        extent = fmax(extent, fmax(fabs(in_view[k].x), fmax(fabs(in_view[k].y), fabs(in_view[k].z))));
    }
    float2 to_pixels = (float2)(0.5f * (float)view->width, 0.5f * (float)view->height);
    int count = 0;
    if (view->projection == PROJECTION_PERSPECTIVE) {
        /* Sutherland–Hodgman against z >= near: triangles through or behind the eye
         * get exact spans instead of the whole screen. */
        float near_z = 1e-5f * extent;
        for (int k = 0; k < 3; ++k) {
            float3 a = in_view[k], b = in_view[(k + 1) % 3];
            float3 point[2];
            int n = 0;
            if (a.z >= near_z) point[n++] = a;
            if ((a.z >= near_z) != (b.z >= near_z)) point[n++] = a + (b - a) * ((near_z - a.z) / (b.z - a.z));
            for (int m = 0; m < n; ++m) {
                float2 s = (float2)(point[m].x / (point[m].z * view->scale_x), point[m].y / (point[m].z * view->scale_y));
                corner[count++] = (float2)(s.x + 1.0f, 1.0f - s.y) * to_pixels;
            }
        }
    } else {
        for (int k = 0; k < 3; ++k) {
            float2 s = (float2)(in_view[k].x / view->scale_x, in_view[k].y / view->scale_y);
            corner[count++] = (float2)(s.x + 1.0f, 1.0f - s.y) * to_pixels;
        }
    }
    return count;
}

/* Columns [x0, x1] of pixel row y that the polygon may cover: the polygon cut by the
 * strip [y, y + 1] (every sample offset of the row), widened by a pixel because the
 * ray test decides. Returns 0 for an empty span. */
inline int row_span(const float2 corner[4], int count, int y, int width, int* x0, int* x1)
{
    float top = (float)y, bottom = (float)(y + 1);
    float lo = INFINITY, hi = -INFINITY;
    for (int k = 0; k < count; ++k) {
        float2 a = corner[k], b = corner[(k + 1) % count];
        if (a.y >= top && a.y <= bottom) { lo = fmin(lo, a.x); hi = fmax(hi, a.x); }
        if (a.y != b.y) {
            for (int side = 0; side < 2; ++side) {
                float edge_y = side ? bottom : top;
                if ((a.y - edge_y) * (b.y - edge_y) <= 0.0f) {
                    float x = a.x + (edge_y - a.y) * (b.x - a.x) / (b.y - a.y);
                    lo = fmin(lo, x);
                    hi = fmax(hi, x);
                }
            }
        }
    }
    if (!(lo <= hi)) return 0;
    *x0 = max((int)floor(fmax(lo, -1.0f)) - 1, 0);
    *x1 = min((int)ceil(fmin(hi, (float)width)) + 1, width - 1);
    return *x0 <= *x1;
}

/* Pass 1 skips a triangle whose ray tests could hit no sample (RASTER_CULL, 1 unless a
 * test builds with 0): at a thumbnail's size, or in a shadow map of a scanned mesh, most
 * triangles are a small fraction of a pixel and fall between sample positions, and their
 * ray tests (a 3 × 4 block of pixels around each) are most of the stage's time. The test
 * is conservative: the corners' box, grown by a margin, holds no sample position
 * (x + offset.x, y + offset.y). The margin covers what can move a ray test's hit off the
 * projected triangle: EDGE_SLACK (a relative 1e-5 of the triangle), float32 rounding of
 * the projection and of the ray test (a few ulps of the coordinates, under 1e-3 pixel at
 * the sizes the views have), and the ray test's ill-conditioning for a triangle seen
 * nearly edge-on, which grows as longest edge² / twice its area (in pixels): that term
 * gets its own share, and a sliver (area under 1 % of longest edge²) or a triangle with a
 * vertex near or behind a perspective view's origin (one the near plane may clip) is
 * never skipped. The test runs first, on the vertices, in straight-line code: the
 * clipping's loops and arrays cost several times more on a CPU device. Images are
 * bit-identical with and without it (tests/stages/test_raster.py, bench/RESULTS.md). */
#ifndef RASTER_CULL
#define RASTER_CULL 1
#endif
#define CULL_MARGIN 0.05f        /* pixels, for rounding (no hit outside the box seen at all) */
#define CULL_MARGIN_REL 1e-4f    /* of the box's extent: EDGE_SLACK's 1e-5 on three vertices, ×3 */
#define CULL_SLIVER 0.01f        /* twice the area / longest edge² under this: never skipped */
#define CULL_CONDITION 1e-6f     /* × pixels per unit of screen × longest edge² / twice the area */
#define CULL_IN_FRONT 1e-3f      /* perspective: each vertex's depth / distance at least this */

/* A vertex in pixel coordinates (projected_polygon's formula), and whether it lies well
 * in front of a perspective view (always, orthographic). */
inline int cull_corner(global const view_t* view, float3 v, float2* corner)
{
    float3 q = v - view->origin.xyz;
    float x = dot(q, view->right.xyz), y = dot(q, view->up.xyz), z = dot(q, view->forward.xyz);
    float2 to_pixels = (float2)(0.5f * (float)view->width, 0.5f * (float)view->height);
    if (view->projection != PROJECTION_PERSPECTIVE) {
        *corner = (float2)(x / view->scale_x + 1.0f, 1.0f - y / view->scale_y) * to_pixels;
        return 1;
    }
    *corner = (float2)(x / (z * view->scale_x) + 1.0f, 1.0f - y / (z * view->scale_y)) * to_pixels;
    return z > 0.0f && z * z >= CULL_IN_FRONT * CULL_IN_FRONT * dot(q, q);
}

inline int misses_every_sample(global const view_t* view, global const float4* tri_vertices, int tri,
                               global const float2* offsets, int sample_count)
{
    if (!RASTER_CULL) return 0;
    float2 a, b, c;
    int in_front = cull_corner(view, tri_vertices[3 * tri].xyz, &a);
    in_front &= cull_corner(view, tri_vertices[3 * tri + 1].xyz, &b);
    in_front &= cull_corner(view, tri_vertices[3 * tri + 2].xyz, &c);
    if (!in_front) return 0; /* clipped, or nearly: never skipped */
    float2 lo = fmin(a, fmin(b, c)), hi = fmax(a, fmax(b, c));
    float2 e0 = b - a, e1 = c - a, e2 = c - b;
    float longest = fmax(dot(e0, e0), fmax(dot(e1, e1), dot(e2, e2)));
    float twice_area = fabs(e0.x * e1.y - e0.y * e1.x);
    if (!(twice_area >= CULL_SLIVER * longest) || !(longest > 0.0f)) return 0;
    float pixels_per_unit = 0.5f * fmax((float)view->width / view->scale_x, (float)view->height / view->scale_y);
    float2 margin = (float2)(CULL_MARGIN + CULL_CONDITION * pixels_per_unit * longest / twice_area)
                    + CULL_MARGIN_REL * (hi - lo);
    lo -= margin;
    hi += margin;
    for (int s = 0; s < sample_count; ++s) {
        float2 o = offsets[s];
        if (floor(hi.x - o.x) >= ceil(lo.x - o.x) && floor(hi.y - o.y) >= ceil(lo.y - o.y)) return 0;
    }
    return 1;
}

/* The triangle `tri` clipped and projected into the view; its rows are [y0, y1]. */
#define PROJECT_TRIANGLE                                                                    \
    global const view_t* view = views + view_index;                                         \
    float3 v0 = tri_vertices[3 * tri].xyz, v1 = tri_vertices[3 * tri + 1].xyz,              \
           v2 = tri_vertices[3 * tri + 2].xyz;                                              \
    float2 corner[4];                                                                       \
    int count = projected_polygon(view, v0, v1, v2, corner);                                \
    if (count < 3) return;                                                                  \
    float top = INFINITY, bottom = -INFINITY;                                               \
    for (int k = 0; k < count; ++k) { top = fmin(top, corner[k].y); bottom = fmax(bottom, corner[k].y); } \
    int y0 = max((int)floor(fmax(top, -1.0f)) - 1, 0);                                      \
    int y1 = min((int)ceil(fmin(bottom, (float)view->height)), view->height - 1);

/* Every sample of row y that the triangle may cover; BODY sees idx, t and tri. */
#define COVERED_SAMPLES_OF_ROW(y, BODY)                                                     \
    {                                                                                       \
        int x0, x1;                                                                         \
        if (row_span(corner, count, y, view->width, &x0, &x1))                              \
            for (int x = x0; x <= x1; ++x)                                                  \
                for (int s = 0; s < sample_count; ++s) {                                    \
                    float3 origin, dir;                                                     \
                    view_ray(view, view_screen(view, x, y, offsets[s]), &origin, &dir);     \
                    float t = intersect_triangle(origin, dir, v0, v1, v2);                  \
                    if (t == INFINITY) continue;                                            \
                    int idx = view->depth_offset + (y * view->width + x) * sample_count + s; \
                    BODY                                                                    \
                }                                                                           \
    }

/* Pass 1, one work-item per triangle: it visits every covered sample of its rows, unless
 * it spans more than RASTER_BIG_ROWS rows; then it lists itself in `big` as (triangle,
 * first row, last row) (while there is room) for pass 2, so a floor plane does not keep
 * one work-item busy for the whole view. The samples and the atomic updates are the same
 * either way, so is the depth map. */
#define FOR_EACH_COVERED_SAMPLE(BODY)                                                       \
    int tri = get_global_id(0);                                                             \
    if (tri >= tri_count) return;                                                           \
    if (misses_every_sample(views + view_index, tri_vertices, tri, offsets, sample_count)) return; \
    PROJECT_TRIANGLE                                                                        \
    if (y1 - y0 + 1 > RASTER_BIG_ROWS) {                                                    \
        uint slot = atomic_inc(big_count);                                                  \
        if (slot < RASTER_BIG_TRIANGLES) { vstore3((int3)(tri, y0, y1), slot, big); return; } \
    }                                                                                       \
    for (int y = y0; y <= y1; ++y) COVERED_SAMPLES_OF_ROW(y, BODY)

/* Pass 2, one work-item per (listed triangle, row): the host expands pass 1's list into
 * `rows` (clrays/stages/raster.py), so no work-item waits on a row outside its triangle. */
#define FOR_EACH_COVERED_SAMPLE_OF_BIG_ROW(BODY)                                            \
    int item = get_global_id(0);                                                            \
    if (item >= row_count) return;                                                          \
    int tri = rows[item].x, y = rows[item].y;                                               \
    PROJECT_TRIANGLE                                                                        \
    COVERED_SAMPLES_OF_ROW(y, BODY)

#define RASTER_ARGS global const float4* tri_vertices, int tri_count, global const view_t* views, \
                    int view_index, global const float2* offsets, int sample_count,           \
                    global uint* big_count, global int* big

#define RASTER_ROWS_ARGS global const float4* tri_vertices, global const view_t* views, int view_index, \
                         global const float2* offsets, int sample_count, global const int2* rows, int row_count

/* Each pass-1 kernel `name` has a pass-2 twin `name_rows`. */
#define RASTER_KERNELS(name, TARGET, BODY)                                                  \
    kernel void name(RASTER_ARGS, TARGET) { FOR_EACH_COVERED_SAMPLE(BODY) }                \
    kernel void name##_rows(RASTER_ROWS_ARGS, TARGET) { FOR_EACH_COVERED_SAMPLE_OF_BIG_ROW(BODY) }

RASTER_KERNELS(raster_depth, global uint* depth, atomic_min(depth + idx, as_uint(t));)

#define RESOLVE_TARGET global const uint* depth, global int* tri_id
RASTER_KERNELS(raster_resolve, RESOLVE_TARGET,
               if (as_uint(t) == depth[idx]) atomic_max(tri_id + idx, tri);)

#ifdef RASTER_ATOMIC64
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable
/* One pass for depth and triangle: the key (as_uint(t) << 32 | tri) orders by depth
 * first (positive floats order like their bits), ties to the lowest index. */
RASTER_KERNELS(raster_nearest, global ulong* nearest,
               atom_min(nearest + idx, ((ulong)as_uint(t) << 32) | (ulong)tri);)

kernel void raster_split(global const ulong* nearest, int samples, global uint* depth, global int* tri_id)
{
    int i = get_global_id(0);
    if (i >= samples) return;
    ulong key = nearest[i];
    depth[i] = (uint)(key >> 32);
    tri_id[i] = depth[i] == DEPTH_EMPTY ? -1 : (int)(uint)key;
}
#endif

/* Whether any texel of a depth buffer holds a depth (map_is_empty): a flag set on the
 * device, so the host reads 4 bytes instead of the whole map. */
kernel void raster_any(global const uint* depth, int texels, global uint* any)
{
    int i = get_global_id(0);
    if (i < texels && depth[i] != DEPTH_EMPTY) *any = 1u;
}
