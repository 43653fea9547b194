/* relief — a relief object drawn into one view by its pre-warp (docs/design.md, "Relief objects").
 * Reads displacement, solid, cell_triangle (the relief's texels), views; writes middle and warped
 * (the two 1D passes), then the view's depth (as_uint(t), atomic min) and, for the camera, the
 * nearest triangle, as raster.cl does.
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
 * EDGE_SLACK), so a relief sample gets the depth its triangle gets there. */
inline float relief_intersect(float3 origin, float3 dir, float3 v0, float3 v1, float3 v2)
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


/* The most cells a sample tests along each axis of the box of the warped points around it:
 * it spans more only across a depth edge, where those points belong to unrelated parts. */
#define RELIEF_MAX_BOX 12
/* How far, in cells, before those points the walk along the sample's own line starts. */
#define RELIEF_CORRIDOR 8.0f
/* How far, in target texels, a sample whose warped texels are empty looks for one. */
#define RELIEF_GAP_SEARCH 16

/* The relief in the view's space: texel (r, c) sits at corner + (c + ½)·a + (r + ½)·b + d·f
 * (clrays/scene/relief.py), so the mapping builds the cells it tests from the texels and
 * needs none of the relief's triangles on the device (docs/design.md, "What a frame carries"). */
typedef struct {
    float3 corner, a, b, f;
    global const float* displacement;
    int cols;
} relief_surface_t;

inline float3 relief_point(const relief_surface_t* surface, int r, int c)
{
    return surface->corner + ((float)c + 0.5f) * surface->a + ((float)r + 0.5f) * surface->b
           + surface->displacement[(size_t)r * surface->cols + c] * surface->f;
}

/* The nearer of the ray's hits with cell (r, c)'s two triangles and *t, in *t and *tri: the
 * triangles (p00, p11, p01) and (p00, p10, p11) of `relief_triangles`, ids first_triangle +
 * the cell's first + 0 or 1. */
inline void relief_test_cell(int r, int c, global const int* cell_triangle, const relief_surface_t* surface,
                             int first_triangle, float3 origin, float3 dir, float* t, int* tri)
{
    int first = cell_triangle[r * (surface->cols - 1) + c];
    if (first < 0) return;
    float3 p00 = relief_point(surface, r, c), p01 = relief_point(surface, r, c + 1);
    float3 p10 = relief_point(surface, r + 1, c), p11 = relief_point(surface, r + 1, c + 1);
    float hit = relief_intersect(origin, dir, p00, p11, p01);
    if (hit < *t) { *t = hit; *tri = first_triangle + first; }
    hit = relief_intersect(origin, dir, p00, p10, p11);
    if (hit < *t) { *t = hit; *tri = first_triangle + first + 1; }
}

/* The ray parameters where the ray enters and leaves the relief's bounds: the slab between the
 * base plane's parallels at its lowest and highest solid texel (heights, along f) and the box of
 * its cells; no hit lies outside them, so the walk along the trace need not either. */
inline float2 relief_span(float3 origin, float3 dir, float4 corner, float4 dual_a, float4 dual_b, float4 dual_f,
                          float2 heights, int rows, int cols)
{
    float3 from_corner = origin - corner.xyz;
    float3 at = (float3)(dot(dual_a.xyz, from_corner), dot(dual_b.xyz, from_corner), dot(dual_f.xyz, from_corner));
    float3 rate = (float3)(dot(dual_a.xyz, dir), dot(dual_b.xyz, dir), dot(dual_f.xyz, dir));
    /* Texel centres run from ½ to cols − ½ (rows − ½): the cells' box. A rate of 0 gives ±INFINITY
     * (or NaN, which fmin and fmax pass over) for that axis. */
    float3 lo = (float3)(0.5f, 0.5f, heights.x), hi = (float3)((float)cols - 0.5f, (float)rows - 0.5f, heights.y);
    float3 to_lo = (lo - at) / rate, to_hi = (hi - at) / rate;
    float3 enter = fmin(to_lo, to_hi), leave = fmax(to_lo, to_hi);
    return (float2)(fmax(fmax(enter.x, enter.y), enter.z), fmin(fmin(leave.x, leave.y), leave.z));
}

/* The first hit of a view sample's ray with the relief (INFINITY: none), and its triangle.
 *
 * The ray meets the base plane at (u, v); the four warped texels around that point name the
 * source points seen through their centres. The ray is tested against the triangles of every
 * cell in the box of those points, widened by a cell, and of the cells that the ray's own
 * trace on the base plane (the line of its points' (u, v)) crosses from RELIEF_CORRIDOR cells
 * before them up to the first hit, or without one to where the ray leaves the relief: its true
 * hit lies on that trace. The box alone is enough except at grazing views, where the two 1D
 * passes may leave a warped point that lies on no ray's hit (a skin stretched between two rows'
 * entries, a ridge the ray passes over) or a gap where a cell is seen edge-on. Depth and
 * triangle are then those the triangles give the ray. dual_a, dual_b, dual_f: the rows of the
 * inverse of [a b f], so u = dual_a·(X − corner). */
inline float relief_hit(float3 origin, float3 dir, float4 corner, float4 dual_a, float4 dual_b, float4 dual_f,
                        float u0, float v0, int target_rows, int target_cols, global const float4* warped,
                        int rows, int cols, global const int* cell_triangle, const relief_surface_t* surface,
                        int first_triangle, float2 heights, int* tri)
{
    float t = INFINITY;
    *tri = -1;
    float along = dot(dual_f.xyz, dir);
    if (along == 0.0f) return t;
    float3 q = origin + dir * (-dot(dual_f.xyz, origin - corner.xyz) / along);
    float u = dot(dual_a.xyz, q - corner.xyz) - u0, v = dot(dual_b.xyz, q - corner.xyz) - v0;
    if (!(u >= -1.0f && u < (float)target_cols + 1.0f && v >= -1.0f && v < (float)target_rows + 1.0f)) return t;
    int j0 = (int)floor(u - 0.5f), i0 = (int)floor(v - 0.5f);
    float2 lo = (float2)(INFINITY), hi = (float2)(-INFINITY);
    for (int i = max(i0, 0); i <= min(i0 + 1, target_rows - 1); ++i)
        for (int j = max(j0, 0); j <= min(j0 + 1, target_cols - 1); ++j) {
            float4 e = warped[(size_t)i * target_cols + j];
            if (isnan(e.z)) continue;
            lo = fmin(lo, e.xy);
            hi = fmax(hi, e.xy);
        }
    /* None: the two passes left a gap here. Each row resolves visibility along itself alone,
     * so at a grazing view a row's raised texel can hide, in that row, what the ray passing
     * between two rows sees; the nearest warped texel along the target row or column stands
     * in, and the search along the ray's trace below finds the hit. */
    for (int reach = 1; reach <= RELIEF_GAP_SEARCH && !(lo.x <= hi.x); ++reach) {
        int2 probe[4] = {(int2)(i0, j0 - reach), (int2)(i0, j0 + 1 + reach), (int2)(i0 - reach, j0),
                         (int2)(i0 + 1 + reach, j0)};
        for (int p = 0; p < 4; ++p) {
            if (probe[p].x < 0 || probe[p].x >= target_rows || probe[p].y < 0 || probe[p].y >= target_cols) continue;
            float4 e = warped[(size_t)probe[p].x * target_cols + probe[p].y];
            if (isnan(e.z)) continue;
            lo = fmin(lo, e.xy);
            hi = fmax(hi, e.xy);
        }
    }
    if (!(lo.x <= hi.x)) return t;
    /* Cell (r, c) lies between texel centres: u_s in [c + ½, c + 3/2), v_s in [r + ½, r + 3/2). */
    int c0 = max((int)floor(lo.x - 0.5f) - 1, 0), c1 = min((int)floor(hi.x - 0.5f) + 1, cols - 2);
    int r0 = max((int)floor(lo.y - 0.5f) - 1, 0), r1 = min((int)floor(hi.y - 0.5f) + 1, rows - 2);
    c1 = min(c1, c0 + RELIEF_MAX_BOX - 1);
    r1 = min(r1, r0 + RELIEF_MAX_BOX - 1);
    for (int r = r0; r <= r1; ++r)
        for (int c = c0; c <= c1; ++c)
            relief_test_cell(r, c, cell_triangle, surface, first_triangle, origin, dir, &t, tri);
    /* The ray's trace on the base plane, in cell coordinates (u_s − ½, v_s − ½), walked cell by
     * cell (Amanatides–Woo) from RELIEF_CORRIDOR before the box's corner nearest the viewer along
     * it (the box is clipped to RELIEF_MAX_BOX across a depth edge, the walk is not), but from no
     * earlier than where the ray enters the relief's bounds (relief_span, a cell of slack). The cells
     * are prisms along f, crossed in the ray's order, so the first hit the walk meets is the
     * nearest: it stops a cell of slack past the box's hit or its own. Without a hit it goes on
     * to where the ray leaves the relief (relief_span): a ray that grazes over a ridge the warp
     * put in its way, or that sees a cell edge-on where the warp left a gap, hits farther along
     * its trace than any fixed reach. */
    float2 start = (float2)(dot(dual_a.xyz, origin - corner.xyz), dot(dual_b.xyz, origin - corner.xyz)) - 0.5f;
    float2 step = (float2)(dot(dual_a.xyz, dir), dot(dual_b.xyz, dir));
    float step_length = length(step);
    if (step_length == 0.0f) return t;
    float2 unit = step / step_length;
    float2 box_lo = lo - 0.5f - start, box_hi = hi - 0.5f - start;
    float from_along = fmin(box_lo.x * unit.x, box_hi.x * unit.x) + fmin(box_lo.y * unit.y, box_hi.y * unit.y)
                       - RELIEF_CORRIDOR;
    float2 span = relief_span(origin, dir, corner, dual_a, dual_b, dual_f, heights, rows, cols) * step_length;
    from_along = fmax(from_along, span.x - 1.5f);
    float2 from = start + from_along * unit;
    int2 cell = convert_int2(floor(from));
    int2 direction = (int2)(unit.x > 0.0f ? 1 : -1, unit.y > 0.0f ? 1 : -1);
    float2 delta = fabs(1.0f / unit);
    float2 next = (float2)((unit.x > 0.0f ? (float)cell.x + 1.0f - from.x : from.x - (float)cell.x) * delta.x,
                           (unit.y > 0.0f ? (float)cell.y + 1.0f - from.y : from.y - (float)cell.y) * delta.y);
    for (float walked = 0.0f; walked <= fmin(t * step_length, span.y) - from_along + 1.5f;) {
        if (cell.x >= 0 && cell.x <= cols - 2 && cell.y >= 0 && cell.y <= rows - 2)
            relief_test_cell(cell.y, cell.x, cell_triangle, surface, first_triangle, origin, dir, &t, tri);
        if (next.x < next.y) { walked = next.x; next.x += delta.x; cell.x += direction.x; }
        else { walked = next.y; next.y += delta.y; cell.y += direction.y; }
    }
    return t;
}

#define RELIEF_MAP_ARGS global const view_t* views, int view_index, int x0, int y0, int columns,              \
                        global const float2* offsets,                                                        \
                        int sample_count, float4 corner, float4 dual_a, float4 dual_b, float4 dual_f,        \
                        float u0, float v0, int target_rows, int target_cols, global const float4* warped,  \
                        int rows, int cols, global const int* cell_triangle, global const float* displacement, \
                        float4 axis_a, float4 axis_b, float4 axis_f, int first_triangle, float2 heights

/* Mapping, one work-item per sample of the view's pixels from (x0, y0), `columns` wide, that
 * may see the relief (clrays/stages/relief.py footprint; relief_hit); BODY sees idx, t and
 * tri. */
#define FOR_THE_RELIEF_HIT(BODY)                                                                      \
    global const view_t* view = views + view_index;                                                   \
    int id = get_global_id(0);                                                                        \
    int s = id % sample_count, placed = id / sample_count;                                            \
    int x = x0 + placed % columns, y = y0 + placed / columns;                                         \
    if (x >= view->width || y >= view->height) return;                                                \
    float3 origin, dir;                                                                               \
    view_ray(view, view_screen(view, x, y, offsets[s]), &origin, &dir);                               \
    int tri;                                                                                          \
    relief_surface_t surface = {corner.xyz, axis_a.xyz, axis_b.xyz, axis_f.xyz, displacement, cols};   \
    float t = relief_hit(origin, dir, corner, dual_a, dual_b, dual_f, u0, v0, target_rows, target_cols, warped, \
                         rows, cols, cell_triangle, &surface, first_triangle, heights, &tri);                  \
    if (tri < 0) return;                                                                              \
    int idx = view->depth_offset + (y * view->width + x) * sample_count + s;                          \
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
