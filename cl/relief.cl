/* relief — a relief object drawn into one view by its pre-warp (docs/design.md, "Relief objects").
 * Reads displacement, solid, cell_triangle (the relief's texels), tri_vertices (its height-field
 * triangles), views; writes middle and warped (the two 1D passes), then the view's depth
 * (as_uint(t), atomic min) and, for the camera, the nearest triangle, as raster.cl does.
 *
 *   source texels (rows × cols)     middle (rows × target_cols)      warped (target_rows × target_cols)
 *   u_s = c + ½, v_s = r + ½   --rows-->  u moved to u_i, filled  --columns-->  v moved to v_i, filled
 *   each entry of middle and warped: (u_s, v_s, d, 1), or NaN where nothing landed.
 *
 * The target grids' texel (i, j) covers u ∈ [u0 + j, u0 + j + 1), v ∈ [v0 + i, v0 + i + 1)
 * of the base plane. A line's segments (texels k, k + 1) are drawn in the order `segments`,
 * McMillan's occlusion-compatible order, so that a later write, nearer the viewer, wins. */
#include "lighting.h"

/* The same Möller–Trumbore as raster.cl's (two-sided, edges inclusive with the same
 * slack), so a relief sample gets the depth its triangle gets there. */
#define RELIEF_EDGE_SLACK 1e-5f
inline float relief_intersect(float3 origin, float3 dir, float3 v0, float3 v1, float3 v2)
{
    float3 e1 = v1 - v0, e2 = v2 - v0;
    float3 pv = cross(dir, e2);
    float det = dot(e1, pv);
    if (det == 0.0f) return INFINITY;
    float inv = 1.0f / det;
    float3 tv = origin - v0;
    float u = dot(tv, pv) * inv;
    if (u < -RELIEF_EDGE_SLACK || u > 1.0f + RELIEF_EDGE_SLACK) return INFINITY;
    float3 qv = cross(tv, e1);
    float v = dot(dir, qv) * inv;
    if (v < -RELIEF_EDGE_SLACK || u + v > 1.0f + RELIEF_EDGE_SLACK) return INFINITY;
    float t = dot(e2, qv) * inv;
    return t > 0.0f ? t : INFINITY;
}

/* Targets j with centre j + ½ in [lo, hi), clamped to [0, count − 1]. */
inline int2 covered_centres(float lo, float hi, int count)
{
    lo = fmax(lo, -1.0f);
    hi = fmin(hi, (float)count + 1.0f);
    return (int2)(max((int)ceil(lo - 0.5f), 0), min((int)ceil(hi - 0.5f) - 1, count - 1));
}

/* Row pass, one work-item per source row: each texel moves to u_i = (u_s + k1·d)/(1 + k3·d). */
kernel void relief_warp_rows(global const float* displacement, global const uchar* solid, int rows, int cols,
                             global const int* segments, float k1, float k3, float u0, int target_cols,
                             global float4* middle)
{
    int r = get_global_id(0);
    if (r >= rows) return;
    global float4* out = middle + (size_t)r * target_cols;
    for (int j = 0; j < target_cols; ++j) out[j] = (float4)(NAN);
    global const float* d = displacement + (size_t)r * cols;
    global const uchar* ok = solid + (size_t)r * cols;
    for (int n = 0; n < cols - 1; ++n) {
        int k = segments[n];
        float scale0 = 1.0f + k3 * d[k], scale1 = 1.0f + k3 * d[k + 1];
        /* 1 + k3·d ≤ 0: the texel's ray meets the base plane behind the viewer. */
        if (!ok[k] || !ok[k + 1] || scale0 <= 0.0f || scale1 <= 0.0f) continue;
        float x0 = ((float)k + 0.5f + k1 * d[k]) / scale0 - u0;
        float x1 = ((float)k + 1.5f + k1 * d[k + 1]) / scale1 - u0;
        int2 span = covered_centres(fmin(x0, x1), fmax(x0, x1), target_cols);
        for (int j = span.x; j <= span.y; ++j) {
            float t = ((float)j + 0.5f - x0) / (x1 - x0);
            out[j] = (float4)((float)k + 0.5f + t, (float)r + 0.5f, d[k] + t * (d[k + 1] - d[k]), 1.0f);
        }
    }
}

/* Column pass, one work-item per target column: each entry of middle moves to
 * v_i = (v_s + k2·d)/(1 + k3·d); a value whose source lies in a hole cell is not written. */
kernel void relief_warp_columns(global const float4* middle, int rows, int cols, int target_cols,
                                global const int* segments, float k2, float k3, float v0, int target_rows,
                                global const int* cell_triangle, global float4* warped)
{
    int j = get_global_id(0);
    if (j >= target_cols) return;
    for (int i = 0; i < target_rows; ++i) warped[(size_t)i * target_cols + j] = (float4)(NAN);
    for (int n = 0; n < rows - 1; ++n) {
        int k = segments[n];
        float4 e0 = middle[(size_t)k * target_cols + j], e1 = middle[(size_t)(k + 1) * target_cols + j];
        if (isnan(e0.z) || isnan(e1.z)) continue;
        float y0 = (e0.y + k2 * e0.z) / (1.0f + k3 * e0.z) - v0;
        float y1 = (e1.y + k2 * e1.z) / (1.0f + k3 * e1.z) - v0;
        int2 span = covered_centres(fmin(y0, y1), fmax(y0, y1), target_rows);
        for (int i = span.x; i <= span.y; ++i) {
            float t = ((float)i + 0.5f - y0) / (y1 - y0);
            float4 e = e0 + t * (e1 - e0);
            int cell_r = clamp((int)floor(e.y - 0.5f), 0, rows - 2), cell_c = clamp((int)floor(e.x - 0.5f), 0, cols - 2);
            if (cell_triangle[cell_r * (cols - 1) + cell_c] < 0) continue;
            warped[(size_t)i * target_cols + j] = e;
        }
    }
}

#define RELIEF_MAP_ARGS global const view_t* views, int view_index, global const float2* offsets,              \
                        int sample_count, float4 corner, float4 dual_a, float4 dual_b, float4 dual_f,        \
                        float u0, float v0, int target_rows, int target_cols, global const float4* warped,  \
                        int rows, int cols, global const int* cell_triangle, global const float4* tri_vertices, \
                        int first_triangle

/* Mapping, one work-item per view sample: its ray meets the base plane at (u, v); the warped
 * texel there names the source point seen through it; the ray is then tested against the
 * triangles of that cell and its 8 neighbours, so depth and triangle are those the triangles
 * give the ray. BODY sees idx, t and tri. dual_a, dual_b, dual_f: the rows of the inverse of
 * the matrix [a b f], so that u = dual_a·(X − corner). */
#define FOR_THE_RELIEF_HIT(BODY)                                                                      \
    global const view_t* view = views + view_index;                                                   \
    int id = get_global_id(0);                                                                        \
    if (id >= view->width * view->height * sample_count) return;                                      \
    int s = id % sample_count, pixel = id / sample_count;                                             \
    float3 origin, dir;                                                                               \
    view_ray(view, view_screen(view, pixel % view->width, pixel / view->width, offsets[s]), &origin, &dir); \
    float along = dot(dual_f.xyz, dir);                                                               \
    if (along == 0.0f) return;                                                                        \
    float3 q = origin + dir * (-dot(dual_f.xyz, origin - corner.xyz) / along);                        \
    float u = dot(dual_a.xyz, q - corner.xyz) - u0, v = dot(dual_b.xyz, q - corner.xyz) - v0;         \
    if (!(u >= 0.0f && u < (float)target_cols && v >= 0.0f && v < (float)target_rows)) return;        \
    float4 e = warped[(size_t)(int)v * target_cols + (int)u];                                         \
    if (isnan(e.z)) return;                                                                           \
    int cell_r = (int)floor(e.y - 0.5f), cell_c = (int)floor(e.x - 0.5f);                             \
    float t = INFINITY;                                                                               \
    int tri = -1;                                                                                     \
    for (int r = max(cell_r - 1, 0); r <= min(cell_r + 1, rows - 2); ++r)                             \
        for (int c = max(cell_c - 1, 0); c <= min(cell_c + 1, cols - 2); ++c) {                       \
            int first = cell_triangle[r * (cols - 1) + c];                                            \
            if (first < 0) continue;                                                                  \
            for (int second = 0; second < 2; ++second) {                                                  \
                int candidate = first_triangle + first + second;                                   \
                float hit = relief_intersect(origin, dir, tri_vertices[3 * candidate].xyz,            \
                                             tri_vertices[3 * candidate + 1].xyz,                     \
                                             tri_vertices[3 * candidate + 2].xyz);                    \
                if (hit < t) { t = hit; tri = candidate; }                                            \
            }                                                                                         \
        }                                                                                             \
    if (tri < 0) return;                                                                              \
    int idx = view->depth_offset + id;                                                                \
    BODY

kernel void relief_map_depth(RELIEF_MAP_ARGS, global uint* depth) { FOR_THE_RELIEF_HIT(atomic_min(depth + idx, as_uint(t));) }

kernel void relief_map_resolve(RELIEF_MAP_ARGS, global const uint* depth, global int* tri_id)
{
    FOR_THE_RELIEF_HIT(if (as_uint(t) == depth[idx]) atomic_max(tri_id + idx, tri);)
}

#ifdef RASTER_ATOMIC64
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable
kernel void relief_map_nearest(RELIEF_MAP_ARGS, global ulong* nearest)
{
    FOR_THE_RELIEF_HIT(atom_min(nearest + idx, ((ulong)as_uint(t) << 32) | (ulong)tri);)
}
#endif
