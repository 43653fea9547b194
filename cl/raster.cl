/* raster — triangles → depth for one view (the camera or a shadow-map view).
 * Reads tri_vertices (3 float4 per triangle, eye space), views[view_index], offsets;
 * writes depth (as_uint(t), atomic min) and, in raster_resolve, tri_id (the nearest
 * triangle per sample, ties to the highest index).
 *
 * One work-item per triangle: it clips the triangle to the view's near side, takes
 * the bounding box of the projected polygon, and ray-tests every sample inside it.
 * The ray test (not interpolation) makes depth exact along the sample ray, and
 * two-sided. Depth buffer layout per view: [height][width][samples]. */
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

/* Screen-space bounds [x0, x1] × [y0, y1] (pixels, clamped) of a triangle; 0 if none. */
inline int triangle_bounds(global const view_t* view, float3 v0, float3 v1, float3 v2,
                           int* x0, int* x1, int* y0, int* y1)
{
    float3 corner[3] = {v0, v1, v2};
    float3 in_view[3];
    float extent = 0.0f;
    for (int k = 0; k < 3; ++k) {
        float3 q = corner[k] - view->origin.xyz;
        in_view[k] = (float3)(dot(q, view->right.xyz), dot(q, view->up.xyz), dot(q, view->forward.xyz));
        extent = fmax(extent, fmax(fabs(in_view[k].x), fmax(fabs(in_view[k].y), fabs(in_view[k].z))));
    }
    float2 lo = (float2)(INFINITY), hi = (float2)(-INFINITY);
    if (view->projection == PROJECTION_PERSPECTIVE) {
        /* Clip the polygon to z >= near (Sutherland–Hodgman, one plane): triangles
         * through or behind the eye get exact bounds instead of the whole screen. */
        float near = 1e-5f * extent;
        int count = 0;
        for (int k = 0; k < 3; ++k) {
            float3 a = in_view[k], b = in_view[(k + 1) % 3];
            float3 point[2];
            int n = 0;
            if (a.z >= near) point[n++] = a;
            if ((a.z >= near) != (b.z >= near)) point[n++] = a + (b - a) * ((near - a.z) / (b.z - a.z));
            for (int m = 0; m < n; ++m) {
                float2 s = (float2)(point[m].x / (point[m].z * view->scale_x), point[m].y / (point[m].z * view->scale_y));
                lo = fmin(lo, s);
                hi = fmax(hi, s);
                ++count;
            }
        }
        if (count == 0) return 0;
    } else {
        for (int k = 0; k < 3; ++k) {
            float2 s = (float2)(in_view[k].x / view->scale_x, in_view[k].y / view->scale_y);
            lo = fmin(lo, s);
            hi = fmax(hi, s);
        }
    }
    /* screen [-1, 1] (y up) → pixel rows/columns, widened by one pixel: the ray test decides. */
    float w = (float)view->width, h = (float)view->height;
    float fx0 = clamp((lo.x + 1.0f) * 0.5f * w - 1.0f, -1.0f, w);
    float fx1 = clamp((hi.x + 1.0f) * 0.5f * w + 1.0f, -1.0f, w);
    float fy0 = clamp((1.0f - hi.y) * 0.5f * h - 1.0f, -1.0f, h);
    float fy1 = clamp((1.0f - lo.y) * 0.5f * h + 1.0f, -1.0f, h);
    *x0 = max((int)floor(fx0), 0);
    *x1 = min((int)ceil(fx1), view->width - 1);
    *y0 = max((int)floor(fy0), 0);
    *y1 = min((int)ceil(fy1), view->height - 1);
    return *x0 <= *x1 && *y0 <= *y1;
}

/* Visit every sample of every pixel a triangle may cover; BODY sees idx and t. */
#define FOR_EACH_COVERED_SAMPLE(BODY)                                                     \
    int tri = get_global_id(0);                                                           \
    if (tri >= tri_count) return;                                                         \
    global const view_t* view = views + view_index;                                       \
    float3 v0 = tri_vertices[3 * tri].xyz, v1 = tri_vertices[3 * tri + 1].xyz,            \
           v2 = tri_vertices[3 * tri + 2].xyz;                                            \
    int x0, x1, y0, y1;                                                                   \
    if (!triangle_bounds(view, v0, v1, v2, &x0, &x1, &y0, &y1)) return;                   \
    for (int y = y0; y <= y1; ++y)                                                        \
        for (int x = x0; x <= x1; ++x)                                                    \
            for (int s = 0; s < sample_count; ++s) {                                      \
                float3 origin, dir;                                                       \
                view_ray(view, view_screen(view, x, y, offsets[s]), &origin, &dir);       \
                float t = intersect_triangle(origin, dir, v0, v1, v2);                    \
                if (t == INFINITY) continue;                                              \
                int idx = view->depth_offset + (y * view->width + x) * sample_count + s;  \
                BODY                                                                      \
            }

kernel void raster_depth(global const float4* tri_vertices, int tri_count,
                         global const view_t* views, int view_index,
                         global const float2* offsets, int sample_count,
                         global uint* depth)
{
    FOR_EACH_COVERED_SAMPLE(atomic_min(depth + idx, as_uint(t));)
}

kernel void raster_resolve(global const float4* tri_vertices, int tri_count,
                           global const view_t* views, int view_index,
                           global const float2* offsets, int sample_count,
                           global const uint* depth, global int* tri_id)
{
    FOR_EACH_COVERED_SAMPLE(if (as_uint(t) == depth[idx]) atomic_max(tri_id + idx, tri);)
}
