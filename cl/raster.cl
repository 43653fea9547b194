/* raster — triangles → depth for one view (the camera or a shadow-map view).
 * Reads tri_vertices (3 float4 per triangle, eye space; the first row's w: its solid's
 * outward sign, solids.h), views[view_index], offsets;
 * writes depth (as_uint(t), atomic min) and, for the camera, the nearest triangle:
 * raster_nearest packs (depth, triangle) in one 64-bit atomic min and raster_split_runs
 * unpacks it; without 64-bit atomics, raster_resolve re-tests (ties: highest index).
 *
 * One work-item per triangle the view lists (clrays/stages/raster_culling.py): it skips
 * a closed solid's face turned away from the view (solids.h), clips the triangle to the
 * view's near side, projects the polygon, and per pixel row ray-tests the samples in the
 * row's span of the polygon, 8 columns per test (intersect_columns); triangles taller than
 * RASTER_BIG_ROWS go to a second pass with one work-item per block of RASTER_ROWS_PER_ITEM
 * rows (and, on a GPU, a few dozen columns) of the view, which owns it (`*_rows`). The
 * ray test (not interpolation) makes depth exact along the sample ray, and two-sided.
 * Depth buffer layout per view: [height][width][samples]. */
#include "lighting.h"
#include "solids.h"

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

/* PoCL calls its library for dot, fabs, fmax, floor and the like (no inlining): in the
 * per-triangle and per-row code, where they were a fifth of a small triangle's cost, a clang
 * build does the same operations inline (its builtins; dot as PoCL's: products, then
 * (x + y) + z, unfused); another compiler keeps the OpenCL functions. */
#ifdef __clang__
inline float dot_inline(float3 a, float3 b)
{
#pragma OPENCL FP_CONTRACT OFF
    return (a.x * b.x + a.y * b.y) + a.z * b.z;
}
inline float dot2_inline(float2 a, float2 b)
{
#pragma OPENCL FP_CONTRACT OFF
    return a.x * b.x + a.y * b.y;
}
#define DOT_3(a, b) dot_inline(a, b)
#define DOT_2(a, b) dot2_inline(a, b)
#define CROSS_3(a, b) inline_cross(a, b)
#define FABS(x) __builtin_fabsf(x)
#define FMIN(a, b) __builtin_fminf(a, b)
#define FMAX(a, b) __builtin_fmaxf(a, b)
#define FLOOR(x) __builtin_floorf(x)
#define CEIL(x) __builtin_ceilf(x)
#else
#define DOT_3(a, b) dot(a, b)
#define DOT_2(a, b) dot(a, b)
#define CROSS_3(a, b) cross(a, b)
#define FABS(x) fabs(x)
#define FMIN(a, b) fmin(a, b)
#define FMAX(a, b) fmax(a, b)
#define FLOOR(x) floor(x)
#define CEIL(x) ceil(x)
#endif
#define FLOOR_INT(x) ((int)FLOOR(x))
#define CEIL_INT(x) ((int)CEIL(x))
#define FMIN_2(a, b) ((float2)(FMIN((a).x, (b).x), FMIN((a).y, (b).y)))
#define FMAX_2(a, b) ((float2)(FMAX((a).x, (b).x), FMAX((a).y, (b).y)))
#define MAX_INT(a, b) ((a) > (b) ? (a) : (b))
#define MIN_INT(a, b) ((a) < (b) ? (a) : (b))

/* The triangle clipped to the view's near side and projected to pixel coordinates
 * (x right, y down): a convex polygon of up to 4 corners. Returns the corner count. */
inline int projected_polygon(global const view_t* view, float3 v0, float3 v1, float3 v2, float2 corner[4])
{
    float3 world[3] = {v0, v1, v2};
    float3 in_view[3];
    float extent = 0.0f;
    for (int k = 0; k < 3; ++k) {
        float3 q = world[k] - view->origin.xyz;
        in_view[k] = (float3)(DOT_3(q, view->right.xyz), DOT_3(q, view->up.xyz), DOT_3(q, view->forward.xyz));
        extent = FMAX(extent, FMAX(FABS(in_view[k].x), FMAX(FABS(in_view[k].y), FABS(in_view[k].z))));
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
    /* Comparisons, not fmin/fmax (library calls on PoCL, a tenth of a small triangle's cost):
     * they differ only on a NaN, which both skip, and on ±0, which floor to the same column. */
#define WIDEN_SPAN(x) { lo = (x) < lo ? (x) : lo; hi = (x) > hi ? (x) : hi; }
    for (int k = 0; k < count; ++k) {
        float2 a = corner[k], b = corner[k + 1 < count ? k + 1 : 0];
        if (a.y >= top && a.y <= bottom) WIDEN_SPAN(a.x)
        if (a.y != b.y) {
            for (int side = 0; side < 2; ++side) {
                float edge_y = side ? bottom : top;
                if ((a.y - edge_y) * (b.y - edge_y) <= 0.0f) {
                    float x = a.x + (edge_y - a.y) * (b.x - a.x) / (b.y - a.y);
                    WIDEN_SPAN(x)
                }
            }
        }
    }
#undef WIDEN_SPAN
    if (!(lo <= hi)) return 0;
    *x0 = MAX_INT(FLOOR_INT(FMAX(lo, -1.0f)) - 1, 0);
    *x1 = MIN_INT(CEIL_INT(FMIN(hi, (float)width)) + 1, width - 1);
    return *x0 <= *x1;
}

/* The terms of a triangle's Möller–Trumbore test that are the same for every sample of a
 * view, computed once per triangle with intersect_triangle's operations: for a perspective
 * view the ray origin is fixed (tv, qv and the numerator of t), for an orthographic one the
 * direction (pv, det and 1/det). */
typedef struct {
    float3 v0, e1, e2;
    float3 tv, qv;  /* perspective: origin − v0, cross(tv, e1) */
    float t_num;    /* perspective: dot(e2, qv) */
    float3 pv;      /* orthographic: cross(forward, e2) */
    float det, inv; /* orthographic: dot(e1, pv), 1 / det */
} triangle_test_t;

inline triangle_test_t triangle_test(global const view_t* view, float3 v0, float3 v1, float3 v2)
{
    triangle_test_t test;
    test.v0 = v0;
    test.e1 = v1 - v0;
    test.e2 = v2 - v0;
    if (view->projection == PROJECTION_PERSPECTIVE) {
        test.tv = view->origin.xyz - v0;
        test.qv = CROSS_3(test.tv, test.e1);
        test.t_num = DOT_3(test.e2, test.qv);
    } else {
        test.pv = CROSS_3(view->forward.xyz, test.e2);
        test.det = DOT_3(test.e1, test.pv);
        test.inv = 1.0f / test.det;
    }
    return test;
}

/* Lanes of the column loop: one ray test covers this many neighbouring columns of a row
 * (8 floats fill a 256-bit vector register; a compiler that does not vectorize the
 * work-item loop, as PoCL does not for this one, still does each lane's arithmetic at once). */
#define RASTER_LANES 8

/* Whether any lane of a comparison is true, without a library call (PoCL's any() is one). */
inline int any_lane(int8 mask)
{
    int4 halves = mask.lo | mask.hi;
    int2 quarters = halves.lo | halves.hi;
    return (quarters.x | quarters.y) != 0;
}

/* The triangle against the rays of columns [x, x + RASTER_LANES) of row y at one sample
 * offset: t per lane, INFINITY where the ray misses (or lies past column `last`).
 * Every lane does exactly the float operations of view_screen, view_ray (normalize: p times
 * 1/sqrt(dot(p, p)) for dot(p, p) in [FLT_MIN, ∞)) and intersect_triangle, in the same
 * order, unfused, so its t has the same bits as the one-sample path; a lane outside that
 * range of dot(p, p) (none in a valid view) takes the one-sample path itself. */
inline float8 intersect_columns(global const view_t* view, const triangle_test_t* test, int x, int last, int y,
                                float2 offset)
{
#pragma OPENCL FP_CONTRACT OFF
    const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    float8 sx = 2.0f * (convert_float8(x + lane) + offset.x) / (float)view->width - 1.0f;
    float sy = 1.0f - 2.0f * ((float)y + offset.y) / (float)view->height;
    float8 right_scale = sx * view->scale_x;
    float3 up = view->up.xyz * (sy * view->scale_y);
    float8 rx = view->right.x * right_scale, ry = view->right.y * right_scale, rz = view->right.z * right_scale;
    float8 t;
    int8 hit;
    if (view->projection == PROJECTION_PERSPECTIVE) {
        float8 px = (view->forward.x + rx) + up.x, py = (view->forward.y + ry) + up.y,
               pz = (view->forward.z + rz) + up.z;
        float8 length2 = (px * px + py * py) + pz * pz;
        int8 plain = length2 >= FLT_MIN && length2 < INFINITY;
        float8 inv_length = 1.0f / sqrt(length2);
        float8 dx = px * inv_length, dy = py * inv_length, dz = pz * inv_length;
        float3 e1 = test->e1, e2 = test->e2, tv = test->tv, qv = test->qv;
        float8 pvx = dy * e2.z - dz * e2.y, pvy = dz * e2.x - dx * e2.z, pvz = dx * e2.y - dy * e2.x;
        float8 det = (e1.x * pvx + e1.y * pvy) + e1.z * pvz;
        float8 inv = 1.0f / det;
        float8 u = ((tv.x * pvx + tv.y * pvy) + tv.z * pvz) * inv;
        float8 v = ((dx * qv.x + dy * qv.y) + dz * qv.z) * inv;
        t = test->t_num * inv;
        hit = det != 0.0f && !(u < -EDGE_SLACK || u > 1.0f + EDGE_SLACK)
              && !(v < -EDGE_SLACK || u + v > 1.0f + EDGE_SLACK) && t > 0.0f;
        if (any_lane(~plain)) { /* dot(p, p) outside normalize's plain range: the one-sample path */
            float lane_t[RASTER_LANES];
            for (int k = 0; k < RASTER_LANES; ++k) {
                float3 origin, dir;
                view_ray(view, view_screen(view, x + k, y, offset), &origin, &dir);
                lane_t[k] = intersect_triangle(origin, dir, test->v0, test->v0 + e1, test->v0 + e2);
            }
            t = vload8(0, lane_t);
            hit = t != INFINITY;
        }
    } else {
        if (test->det == 0.0f) return (float8)(INFINITY);
        float3 v0 = test->v0, e1 = test->e1, e2 = test->e2, pv = test->pv, forward = view->forward.xyz;
        float8 tvx = ((view->origin.x + rx) + up.x) - v0.x, tvy = ((view->origin.y + ry) + up.y) - v0.y,
               tvz = ((view->origin.z + rz) + up.z) - v0.z;
        float8 u = ((tvx * pv.x + tvy * pv.y) + tvz * pv.z) * test->inv;
        float8 qx = tvy * e1.z - tvz * e1.y, qy = tvz * e1.x - tvx * e1.z, qz = tvx * e1.y - tvy * e1.x;
        float8 v = ((forward.x * qx + forward.y * qy) + forward.z * qz) * test->inv;
        t = ((e2.x * qx + e2.y * qy) + e2.z * qz) * test->inv;
        hit = !(u < -EDGE_SLACK || u > 1.0f + EDGE_SLACK) && !(v < -EDGE_SLACK || u + v > 1.0f + EDGE_SLACK)
              && t > 0.0f;
    }
    return hit && x + lane <= last ? t : (float8)(INFINITY);
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
    float x = DOT_3(q, view->right.xyz), y = DOT_3(q, view->up.xyz), z = DOT_3(q, view->forward.xyz);
    float2 to_pixels = (float2)(0.5f * (float)view->width, 0.5f * (float)view->height);
    if (view->projection != PROJECTION_PERSPECTIVE) {
        *corner = (float2)(x / view->scale_x + 1.0f, 1.0f - y / view->scale_y) * to_pixels;
        return 1;
    }
    *corner = (float2)(x / (z * view->scale_x) + 1.0f, 1.0f - y / (z * view->scale_y)) * to_pixels;
    return z > 0.0f && z * z >= CULL_IN_FRONT * CULL_IN_FRONT * DOT_3(q, q);
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
    float2 lo = FMIN_2(a, FMIN_2(b, c)), hi = FMAX_2(a, FMAX_2(b, c));
    float2 e0 = b - a, e1 = c - a, e2 = c - b;
    float longest = FMAX(DOT_2(e0, e0), FMAX(DOT_2(e1, e1), DOT_2(e2, e2)));
    float twice_area = FABS(e0.x * e1.y - e0.y * e1.x);
    if (!(twice_area >= CULL_SLIVER * longest) || !(longest > 0.0f)) return 0;
    float pixels_per_unit = 0.5f * FMAX((float)view->width / view->scale_x, (float)view->height / view->scale_y);
    float2 margin = (float2)(CULL_MARGIN + CULL_CONDITION * pixels_per_unit * longest / twice_area)
                    + CULL_MARGIN_REL * (hi - lo);
    lo -= margin;
    hi += margin;
    for (int s = 0; s < sample_count; ++s) {
        float2 o = offsets[s];
        if (FLOOR(hi.x - o.x) >= CEIL(lo.x - o.x) && FLOOR(hi.y - o.y) >= CEIL(lo.y - o.y)) return 0;
    }
    return 1;
}

/* Whether the projected polygon's columns lie within one pixel's, (n, n + 1), with the
 * rounding of row_span's edge points (SPAN_ROUNDING): then every row whose strip meets the
 * polygon has the span row_span finds, [max(n - 1, 0), min(n + 2, width - 1)] (its ends'
 * floor and ceiling are n and n + 1, less and more one), and a sliver of a pole, a fraction
 * of a pixel wide and a hundred rows tall, skips row_span's edge cuts on each row: half
 * its cost (bench/RESULTS.md, "Raster culled per view"). Only for corners finite and within
 * 2^20 pixels, where the edge points cannot overflow, and only on a row whose strip meets
 * the polygon's rows (COVERED_SAMPLES_OF_ROW): there row_span always finds a point (a
 * corner in the strip, or an edge across its top line), and so a span. */
#define SPAN_ROUNDING 1e-5f
#define ONE_COLUMN_REACH 1048576.0f
#ifndef RASTER_ONE_COLUMN
#define RASTER_ONE_COLUMN 1 /* 0: every row asks row_span (a test's yardstick) */
#endif
inline int one_column(const float2 corner[4], int count, int width, int* x0, int* x1)
{
    if (!RASTER_ONE_COLUMN) return 0;
    float left = INFINITY, right = -INFINITY;
    for (int k = 0; k < 4; ++k) /* (a fixed count, as PROJECT_TRIANGLE's) */
        if (k < count) {
            if (!(FABS(corner[k].x) < ONE_COLUMN_REACH && FABS(corner[k].y) < ONE_COLUMN_REACH)) return 0;
            left = FMIN(left, corner[k].x);
            right = FMAX(right, corner[k].x);
        }
    float slack = SPAN_ROUNDING * (FABS(left) + FABS(right)) + 1e-6f;
    float column = FLOOR(left - slack);
    if (!(left - slack > column && right + slack < column + 1.0f)) return 0;
    *x0 = MAX_INT((int)column - 1, 0);
    *x1 = MIN_INT((int)column + 2, width - 1);
    return 1;
}

/* The triangle `tri` clipped and projected into the view; its rows are [y0, y1]. EXIT
 * leaves when nothing of it is in front of the view. */
#define PROJECT_TRIANGLE(EXIT)                                                              \
    global const view_t* view = views + view_index;                                         \
    float3 v0 = tri_vertices[3 * tri].xyz, v1 = tri_vertices[3 * tri + 1].xyz,              \
           v2 = tri_vertices[3 * tri + 2].xyz;                                              \
    float2 corner[4];                                                                       \
    int count = projected_polygon(view, v0, v1, v2, corner);                                \
    if (count < 3) EXIT;                                                                    \
    float top = INFINITY, bottom = -INFINITY;                                               \
    for (int k = 0; k < 4; ++k) /* (a fixed count: Intel's CPU compiler crashed on `k < count`) */ \
        if (k < count) { top = FMIN(top, corner[k].y); bottom = FMAX(bottom, corner[k].y); } \
    int y0 = MAX_INT(FLOOR_INT(FMAX(top, -1.0f)) - 1, 0);                                   \
    int y1 = MIN_INT(CEIL_INT(FMIN(bottom, (float)view->height)), view->height - 1);        \
    int one_x0 = 0, one_x1 = -1; /* (one_column) */                                         \
    int in_one_column = one_column(corner, count, view->width, &one_x0, &one_x1);          \
    triangle_test_t test = triangle_test(view, v0, v1, v2);

/* Whether every row's span (row_span) of the projected polygon is empty because it lies
 * wholly left or right of the view: pass 1 leaves such a triangle before its rows, which it
 * cost one by one, or pass 2 a block at a time (a pole beside a cube face: 133 rows of a
 * 1024² face). A span's ends lie within the corners' columns, but for the rounding of the
 * edge points, at most a few ulps of the columns' range (SPAN_ROUNDING); row_span widens
 * them by a pixel and keeps columns [-1, width]: the polygon lies more than 3 pixels beyond.
 * A NaN corner counts as in the view. */
inline int beside_view(global const view_t* view, const float2 corner[4], int count)
{
    float left = INFINITY, right = -INFINITY;
    for (int k = 0; k < 4; ++k) /* (a fixed count, as PROJECT_TRIANGLE's) */
        if (k < count) { left = FMIN(left, corner[k].x); right = FMAX(right, corner[k].x); }
    float slack = 3.0f + SPAN_ROUNDING * (FABS(left) + FABS(right));
    return right < -slack || left > (float)view->width + slack;
}

/* Every sample of row y in columns [column_lo, column_hi] that the triangle may cover,
 * RASTER_LANES columns per ray test; BODY sees idx, t and tri for each sample the
 * triangle covers. A row whose strip
 * [y, y + 1] lies wholly above or below the polygon is skipped before row_span, which
 * would find it empty: no corner lies in the strip, and no edge reaches it (the products
 * of its sign test are at least 2^-48, no underflow to 0, except for the strip [0, 1]
 * below a polygon that ends a hair above y = 0, which row_span is left to decide). A
 * polygon within one pixel's columns takes its span from one_column on the rows its strip
 * meets (not that strip [0, 1]). */
#define COVERED_SAMPLES_OF_ROW(y, column_lo, column_hi, BODY, LANES_BODY)                  \
    if (!((float)(y + 1) < top || ((float)y > bottom && y > 0))) {                          \
        int x0 = one_x0, x1 = one_x1;                                                       \
        if ((in_one_column && (float)y <= bottom ? 1 : row_span(corner, count, y, view->width, &x0, &x1)) \
            && (x0 = max(x0, column_lo)) <= (x1 = min(x1, column_hi)))                      \
            for (int s = 0; s < sample_count; ++s) {                                        \
                float2 offset = offsets[s];                                                 \
                for (int first = x0; first <= x1; first += RASTER_LANES) {                 \
                    float8 lanes = intersect_columns(view, &test, first, x1, y, offset);    \
                    if (!any_lane(lanes != INFINITY)) continue;                             \
                    LANES_BODY                                                              \
                    float lane_t[RASTER_LANES];                                             \
                    vstore8(lanes, 0, lane_t);                                              \
                    for (int k = 0; k < RASTER_LANES; ++k) {                                \
                        float t = lane_t[k];                                                \
                        if (t == INFINITY) continue;                                        \
                        int idx = view->depth_offset + (y * view->width + first + k) * sample_count + s; \
                        BODY                                                                \
                    }                                                                       \
                }                                                                           \
            }                                                                               \
    }

/* Whether a triangle of rows [y0, y1] has a texel rectangle of more than RASTER_BIG_SAMPLES
 * pixels: a GPU lists these too (clrays/stages/raster.py), where one work-item drawing a
 * wall seen edge-on, 32 rows by a whole face, held up the pass (demo's pass 1 took 12 ms
 * on an H200). */
#ifndef RASTER_BIG_SAMPLES
#define RASTER_BIG_SAMPLES 0 /* 0: the rows alone decide (a CPU) */
#endif
inline int big_rectangle(const float2 corner[4], int count, int y0, int y1)
{
    float left = corner[0].x, right = corner[0].x;
    for (int k = 1; k < count; ++k) {
        left = corner[k].x < left ? corner[k].x : left;
        right = corner[k].x > right ? corner[k].x : right;
    }
    return (right - left + 2.0f) * (float)(y1 - y0 + 1) > (float)RASTER_BIG_SAMPLES;
}

/* Pass 1, one work-item per triangle (of `drawn`, the view's list of the `drawn_blocks`
 * blocks of `drawn_block` consecutive triangles that may reach it,
 * clrays/stages/raster_culling.py, over (drawn_block, listed blocks) work-items; NULL:
 * every triangle, over (triangles)): it visits every covered sample
 * of its rows, unless it spans more than RASTER_BIG_ROWS rows (or, on a GPU,
 * RASTER_BIG_SAMPLES pixels); then it lists itself in `big` as
 * (triangle, first row, last row) (while there is room) for pass 2, so a floor plane does
 * not keep one work-item busy for the whole view. The samples are the same either way,
 * and every update is a min (or max) that does not depend on the order, so is the depth
 * map. */
#define FOR_EACH_COVERED_SAMPLE(BODY)                                                       \
    int tri = get_global_id(0);                                                             \
    if (drawn) { /* (triangle of its block, listed block) */                                \
        if ((int)get_global_id(1) >= drawn_blocks) return;                                  \
        tri += drawn[get_global_id(1)] * drawn_block;                                       \
    }                                                                                       \
    if (tri >= tri_count) return;                                                           \
    if (faces_away_from_view(views + view_index, tri_vertices[3 * tri], tri_vertices[3 * tri + 1].xyz, \
                             tri_vertices[3 * tri + 2].xyz)) return;                        \
    if (misses_every_sample(views + view_index, tri_vertices, tri, offsets, sample_count)) return; \
    PROJECT_TRIANGLE(return)                                                                \
    if (beside_view(view, corner, count)) return;                                           \
    if (y1 - y0 + 1 > RASTER_BIG_ROWS || (RASTER_BIG_SAMPLES > 0 && big_rectangle(corner, count, y0, y1))) { \
        uint slot = atomic_inc(big_count);                                                  \
        if (slot < RASTER_BIG_TRIANGLES) { vstore3((int3)(tri, y0, y1), slot, big); return; } \
    }                                                                                       \
    for (int y = y0; y <= y1; ++y) COVERED_SAMPLES_OF_ROW(y, 0, view->width - 1, BODY, )

/* Pass 2, one work-item per block of RASTER_ROWS_PER_ITEM rows by `columns_per_item`
 * columns of the view (a CPU device: whole rows; a GPU: a few dozen columns, for work-items
 * enough): it draws its block of every triangle pass 1 listed. Pass 1 has finished, and no
 * other work-item touches these samples, so the updates need no atomics (OWNED_BODY), and a
 * run of RASTER_LANES samples of one row inside the block can be read, updated and written
 * as one vector (LANES_BODY).
 * With RASTER_COUNT_ON_DEVICE (clrays.stages.raster.raster_count_on_device: a GPU) the
 * list's length is read here, from pass 1's counter (which counts the triangles it found
 * no room for too): the host enqueues this pass without waiting to learn it, and with an
 * empty list every work-item returns at once. Without it (a CPU device) the host reads the
 * counters and passes the length, an argument every work-item shares: PoCL keeps a loop
 * over it uniform across the work-items it runs together, and read on the device the
 * length made the camera's rows pass take 1.6× its time. */
#ifndef RASTER_COUNT_ON_DEVICE
#define RASTER_COUNT_ON_DEVICE 1
#endif
#if RASTER_COUNT_ON_DEVICE
#define RASTER_BIG_COUNT_ARG global const uint* big_counter
#define RASTER_BIG_COUNT                                                                    \
    int big_count = (int)min(*big_counter, (uint)RASTER_BIG_TRIANGLES);                     \
    if (big_count == 0) return;
#else
#define RASTER_BIG_COUNT_ARG int big_count
#define RASTER_BIG_COUNT
#endif
#define FOR_EACH_COVERED_SAMPLE_OF_OWNED_ROWS(OWNED_BODY, LANES_BODY)                        \
    int row0 = get_global_id(0) * RASTER_ROWS_PER_ITEM;                                     \
    int column0 = get_global_id(1) * columns_per_item;                                      \
    RASTER_BIG_COUNT                                                                        \
    if (row0 >= views[view_index].height || column0 >= views[view_index].width) return;    \
    int row1 = min(row0 + RASTER_ROWS_PER_ITEM, views[view_index].height) - 1;              \
    int column1 = min(column0 + columns_per_item, views[view_index].width) - 1;             \
    for (int listed = 0; listed < big_count; ++listed) {                                    \
        int3 entry = vload3(listed, big);                                                   \
        if (entry.z < row0 || entry.y > row1) continue;                                     \
        int tri = entry.x;                                                                  \
        PROJECT_TRIANGLE(continue)                                                          \
        int last_row = min(row1, y1);                                                       \
        for (int y = max(row0, y0); y <= last_row; ++y)                                     \
            COVERED_SAMPLES_OF_ROW(y, column0, column1, OWNED_BODY, LANES_BODY)             \
    }

#define RASTER_ARGS global const float4* tri_vertices, int tri_count, global const int* drawn,   \
                    int drawn_blocks, int drawn_block, global const view_t* views,             \
                    int view_index, global const float2* offsets, int sample_count,           \
                    global uint* big_count, global int* big

#define RASTER_ROWS_ARGS global const float4* tri_vertices, global const view_t* views, int view_index, \
                         global const float2* offsets, int sample_count, global const int* big,       \
                         RASTER_BIG_COUNT_ARG, int columns_per_item

/* Each pass-1 kernel `name` has a pass-2 twin `name_rows`. */
#define RASTER_KERNELS(name, TARGET, BODY, OWNED_BODY, LANES_BODY)                          \
    kernel void name(RASTER_ARGS, TARGET) { FOR_EACH_COVERED_SAMPLE(BODY) }                \
    kernel void name##_rows(RASTER_ROWS_ARGS, TARGET) { FOR_EACH_COVERED_SAMPLE_OF_OWNED_ROWS(OWNED_BODY, LANES_BODY) }

/* Pass 2's depth update of a whole run of RASTER_LANES columns, with one sample per pixel
 * and the run inside the work-item's block: the stored depths and the run's as one vector
 * min (a lane the triangle misses holds INFINITY, whose bits are DEPTH_EMPTY, the largest
 * depth). */
#define DEPTH_MIN_LANES(depth)                                                              \
    if (sample_count == 1 && first + RASTER_LANES <= column1 + 1) {                        \
        global uint8_at_uint* run = (global uint8_at_uint*)(depth + view->depth_offset + y * view->width + first); \
        *run = min(*run, as_uint8(lanes));                                                  \
        continue;                                                                           \
    }

/* A uint8 aligned as its elements are, as vload8 and vstore8 take it: a plain vector load
 * or store, where PoCL's vload8 is a library call. */
typedef uint8 __attribute__((aligned(4))) uint8_at_uint;

/* The stored depths only ever decrease, so a depth that does not beat the one read now
 * cannot win the atomic later: the plain read skips most atomics where triangles overlap. */
RASTER_KERNELS(raster_depth, global uint* depth,
               if (as_uint(t) < depth[idx]) atomic_min(depth + idx, as_uint(t));,
               if (as_uint(t) < depth[idx]) depth[idx] = as_uint(t);,
               DEPTH_MIN_LANES(depth))

#define RESOLVE_TARGET global const uint* depth, global int* tri_id
RASTER_KERNELS(raster_resolve, RESOLVE_TARGET,
               if (as_uint(t) == depth[idx] && tri > tri_id[idx]) atomic_max(tri_id + idx, tri);,
               if (as_uint(t) == depth[idx] && tri > tri_id[idx]) tri_id[idx] = tri;, )

#ifdef RASTER_ATOMIC64
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable
#ifndef RASTER_SPLIT_RUN
#error "RASTER_SPLIT_RUN comes from clrays/stages/raster.py (raster_defines)"
#endif
/* One pass for depth and triangle: the key (as_uint(t) << 32 | tri) orders by depth
 * first (positive floats order like their bits), ties to the lowest index. The key's depth
 * word (32 bits, read whole on any device, unlike a plain 64-bit read) only ever decreases:
 * a sample whose depth is beyond it now cannot win the atomic later (KEY_DEPTH_WORD,
 * lighting.h). */
/* Pass 2's update of a whole run of RASTER_LANES columns, one sample per pixel, as
 * DEPTH_MIN_LANES's: the run's keys and the stored ones as one vector min. A lane the
 * triangle misses holds (DEPTH_EMPTY, tri), which raster_split_runs reads as nothing hit, and
 * which any hit beats. Two ulong4 halves: as one ulong8, PoCL 3.0 on a CPU with AVX-512
 * lost most of the run's stores (tests/stages/test_raster.py; docs/design.md §4.5, "Wide
 * vectors"). */
typedef ulong4 __attribute__((aligned(8))) ulong4_at_ulong;
#define NEAREST_MIN_LANES(nearest)                                                          \
    if (sample_count == 1 && first + RASTER_LANES <= column1 + 1) {                        \
        global ulong4_at_ulong* run = (global ulong4_at_ulong*)(nearest + view->depth_offset + y * view->width + first); \
        ulong4 low = (convert_ulong4(as_uint4(lanes.lo)) << 32) | (ulong4)((ulong)(uint)tri);  \
        ulong4 high = (convert_ulong4(as_uint4(lanes.hi)) << 32) | (ulong4)((ulong)(uint)tri); \
        run[0] = min(run[0], low);                                                          \
        run[1] = min(run[1], high);                                                         \
        continue;                                                                           \
    }
RASTER_KERNELS(raster_nearest, global ulong* nearest,
               if (as_uint(t) <= ((global const uint*)(nearest + idx))[KEY_DEPTH_WORD])
                   atom_min(nearest + idx, ((ulong)as_uint(t) << 32) | (ulong)tri);,
               ulong key = ((ulong)as_uint(t) << 32) | (ulong)tri; if (key < nearest[idx]) nearest[idx] = key;,
               NEAREST_MIN_LANES(nearest))

/* The keys split into depth and triangle (-1 where nothing was hit), RASTER_SPLIT_RUN keys
 * per work-item, four at a time as vectors: a shadow map's millions of texels one per
 * work-item cost PoCL 8 ms a cube map. */
typedef uint4 __attribute__((aligned(4))) uint4_at_uint;
typedef int4 __attribute__((aligned(4))) int4_at_int;
kernel void raster_split_runs(global const ulong* nearest, int samples, global uint* depth, global int* tri_id)
{
    int first = get_global_id(0) * RASTER_SPLIT_RUN;
    int end = min(first + RASTER_SPLIT_RUN, samples);
    int i = first;
    for (; i + 4 <= end; i += 4) {
        ulong4 key = *(global const ulong4_at_ulong*)(nearest + i);
        uint4 key_depth = convert_uint4(key >> 32);
        *(global uint4_at_uint*)(depth + i) = key_depth;
        *(global int4_at_int*)(tri_id + i) = key_depth == (uint4)(DEPTH_EMPTY) ? (int4)(-1) : convert_int4(convert_uint4(key));
    }
    for (; i < end; ++i) {
        ulong key = nearest[i];
        depth[i] = (uint)(key >> 32);
        tri_id[i] = depth[i] == DEPTH_EMPTY ? -1 : (int)(uint)key;
    }
}

/* The depths alone, as raster_split_runs's: a shadow map's keys stay, and rectify reads
 * each texel's depth and triangle from its key in one load (RECTIFY_BLOCKER_KEYS), where
 * two arrays cost it two cache misses per texel. */
kernel void raster_split_depth_runs(global const ulong* nearest, int samples, global uint* depth)
{
    int first = get_global_id(0) * RASTER_SPLIT_RUN;
    int end = min(first + RASTER_SPLIT_RUN, samples);
    int i = first;
    for (; i + 4 <= end; i += 4) {
        ulong4 key = *(global const ulong4_at_ulong*)(nearest + i);
        *(global uint4_at_uint*)(depth + i) = convert_uint4(key >> 32);
    }
    for (; i < end; ++i) depth[i] = (uint)(nearest[i] >> 32);
}
#endif

/* Whether any texel of a depth buffer holds a depth (map_is_empty): a flag set on the
 * device, so the host reads 4 bytes instead of the whole map. One work-item per
 * RASTER_ANY_TEXELS texels (clrays/structs.py); once the flag is set, the work-items after
 * it read nothing more (a map with any occluder is the usual case, and a stale 0 only means
 * one more scan). A plain loop, which compilers vectorize themselves: PoCL 3.0 on a CPU
 * with AVX-512 miscompiled the uint16 reduction this was (the flag set on an empty map),
 * and the loop is as fast on PoCL (docs/design.md §4.5, "Wide vectors"). */
kernel void raster_any(global const uint* depth, int texels, volatile global uint* any)
{
    int first = get_global_id(0) * RASTER_ANY_TEXELS;
    if (first >= texels || *any) return;
    int end = min(first + RASTER_ANY_TEXELS, texels);
    uint seen = 0u;
    for (int i = first; i < end; ++i) seen |= depth[i] ^ DEPTH_EMPTY;
    if (seen != 0u) *any = 1u;
}
