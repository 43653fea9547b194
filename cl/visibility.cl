/* visibility — exact hard shadows on surfaces: per camera sample and light, 1 when the
 * segment to the light is clear, else 0. The shadow map decides where its neighbourhood
 * is unanimous; the other samples cast a shadow ray through the BVH, or in a frame of few
 * samples against the triangles touching their texel (docs/design.md §4, visibility).
 * visibility_bound, visibility_bound_rows read tri_vertices, views; write bound (a lower
 * bound of the depth of every triangle that touches each texel, a min), writer (the
 * one triangle that touches each texel, or WRITER_MANY), with a capacity the lists of the
 * triangles touching each texel read (touching_head, touching, touching_count) and the
 * list of triangles whose rectangles the rows pass takes, with their rows and columns
 * (big_items, big_count). A view from outside every closed solid leaves out the faces they turn
 * away from it (solids.h): the first blocker of any segment to the light is a face turned
 * towards the light, and it touches the same texels.
 * visibility_prepare reads frame, views, lights, camera_depth, tri_id,
 * tri_normal, tri_vertex_normals, offsets; writes visible (1 no light reaches the sample,
 * 0 its surface turns away from the light, else pending: the maps or a ray decide),
 * map_read (per sample and light, the bound map's texel its lit test reads and its depth
 * there) and read_mask (a bit per texel read): the bound passes draw only those.
 * visibility reads frame, views, lights, shadow_depth, bound, writer, map_read, camera_depth, tri_id,
 * tri_vertices, tri_normal, offsets; writes visible where the maps decide a pending entry
 * (float per sample and light, [sample][light]; 0 where the surface turns away from the
 * light, which shade then weighs by zero) and lists the entries they leave (ray_entries,
 * ray_count: the count, and how many have no texel); visibility_rays reads those,
 * tri_vertices, node_bounds, node_children, and visibility_rays_listed those, map_read and
 * a light's lists, and both write their visible from a shadow ray. */
#include "lighting.h"
#include "bvh.h"
#include "lanes.h"
#include "solids.h"

/* SURFACE_BIAS_TEXELS, the map test's depth tolerance, and SHADOW_RAY_OFFSET_REL, how far
 * a shadow ray leaves its surface, come from clrays/structs.py (-D). */
/* Bounds are shrunk by this relative margin against float32 rounding of the bound itself. */
#define BOUND_MARGIN_REL 1e-5f
/* VISIBILITY_PENDING (clrays/structs.py): visible's value, between visibility_prepare and
 * visibility, of a sample and light that the maps or a ray decide (never left in it). */
/* map_read's texel, between the two: the address of the texel of the bound and writer
 * maps that decides the lit test, or one of these. */
#define MAP_TEXEL_OUTSIDE -1 /* the point projects outside the map: lit (a map covers every occluder) */
#define MAP_TEXEL_NONE -2    /* behind a perspective view: a ray decides */
/* visibility_bound's rect_mode, RECTS_* (clrays/structs.py): none, record each item's
 * texel rectangle, or skip the items whose recorded rectangle holds no texel read. */

/* Closest point of triangle abc to p (Ericson, Real-Time Collision Detection §5.1.5). */
inline float3 closest_on_triangle(float3 p, float3 a, float3 b, float3 c)
{
    float3 ab = b - a, ac = c - a, ap = p - a;
    float d1 = inline_dot(ab, ap), d2 = inline_dot(ac, ap);
    if (d1 <= 0.0f && d2 <= 0.0f) return a;
    float3 bp = p - b;
    float d3 = inline_dot(ab, bp), d4 = inline_dot(ac, bp);
    if (d3 >= 0.0f && d4 <= d3) return b;
    float vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0f && d1 >= 0.0f && d3 <= 0.0f) return a + ab * (d1 / (d1 - d3));
    float3 cp = p - c;
    float d5 = inline_dot(ab, cp), d6 = inline_dot(ac, cp);
    if (d6 >= 0.0f && d5 <= d6) return c;
    float vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0f && d2 >= 0.0f && d6 <= 0.0f) return a + ac * (d2 / (d2 - d6));
    float va = d3 * d6 - d5 * d4;
    if (va <= 0.0f && (d4 - d3) >= 0.0f && (d5 - d6) >= 0.0f)
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    float denom = 1.0f / (va + vb + vc);
    return a + ab * (vb * denom) + ac * (vc * denom);
}

/* Unit direction of the view ray through pixel coordinates (px, py) of a perspective view. */
inline float3 view_direction(global const view_t* view, float px, float py)
{
    float sx = 2.0f * px / (float)view->width - 1.0f, sy = 1.0f - 2.0f * py / (float)view->height;
    return inline_normalize(view->forward.xyz + view->right.xyz * (sx * view->scale_x) + view->up.xyz * (sy * view->scale_y));
}

/* Signed side of q (view coordinates: right, up, forward) against one of the five planes
 * of a view's frustum, ≥ 0 inside: 0 the near plane (perspective: z ≥ 1e-5·extent), 1–4
 * the sides, widened by the factor `grow` so that rounding never clips a texel's edge. */
inline float frustum_side(global const view_t* view, int plane, float3 q, float grow, float extent)
{
    int perspective = view->projection == PROJECTION_PERSPECTIVE;
    float reach_x = grow * view->scale_x * (perspective ? q.z : 1.0f);
    float reach_y = grow * view->scale_y * (perspective ? q.z : 1.0f);
    switch (plane) {
    case 0: return perspective ? q.z - 1e-5f * extent : 1.0f;
    case 1: return reach_x - q.x;
    case 2: return reach_x + q.x;
    case 3: return reach_y - q.y;
    default: return reach_y + q.y;
    }
}

/* A texel's square grown by this many texels on each side is what a triangle's polygon
 * must meet to write there. The segment from a sample to the light projects to one point,
 * inside its texel and inside the polygon of every triangle it crosses, so only rounding
 * needs a margin: of the corners (≤ 2e-4 texels within two texels of the view) and of the
 * edges' directions (polygon_edges), several hundred times under this. */
#define COVER_GROWTH 0.25f

/* Texel coordinates (x right, y down, texel (i, j) covers [i, i + 1) × [j, j + 1)) of q,
 * a point in view coordinates (right, up, forward); perspective needs q.z > 0. */
inline float2 texel_coordinates(global const view_t* view, float3 q, int perspective)
{
    float z = perspective ? q.z : 1.0f;
    float2 s = (float2)(q.x / (z * view->scale_x), q.y / (z * view->scale_y));
    return (float2)((s.x + 1.0f) * 0.5f * (float)view->width, (1.0f - s.y) * 0.5f * (float)view->height);
}

/* Whether every corner lies within two texels of the view: then the texel maths below
 * stays in the range where float32 rounding is far under a texel. */
inline int near_the_view(global const view_t* view, const float2* corner, int corners)
{
    for (int k = 0; k < corners; ++k)
        if (!(inline_fabs(corner[k].x - 0.5f * view->width) <= 0.5f * view->width + 2.0f
              && inline_fabs(corner[k].y - 0.5f * view->height) <= 0.5f * view->height + 2.0f))
            return 0;
    return 1;
}

/* Clips the polygon (view coordinates, 3 corners in, up to 8 out) to the view's frustum
 * (near plane and four sides, Sutherland–Hodgman, planes a little outside the view so that
 * rounding never clips a texel's edge); returns the corner count, 0 when nothing is left. */
inline int clip_to_frustum(global const view_t* view, float3* polygon, float extent)
{
    float3 clipped[8];
    float grow = 1.0f + 4.0f / (float)inline_min(view->width, view->height);
    int corners = 3;
    for (int plane = 0; plane < 5 && corners > 0; ++plane) {
        int kept = 0;
        for (int k = 0; k < corners; ++k) {
            float3 a = polygon[k], b = polygon[(k + 1) % corners];
            float fa = frustum_side(view, plane, a, grow, extent), fb = frustum_side(view, plane, b, grow, extent);
            if (fa >= 0.0f) clipped[kept++] = a;
            if ((fa >= 0.0f) != (fb >= 0.0f)) clipped[kept++] = a + (b - a) * (fa / (fa - fb));
        }
        corners = kept;
        for (int k = 0; k < corners; ++k) polygon[k] = clipped[k];
    }
    return corners;
}

/* The convex polygon's edges as half-planes a·x + b·y + c ≥ 0 (edge = (a, b, c)) holding
 * it, in texel coordinates; the count. None (the whole rectangle is kept) when the
 * polygon is so thin that rounding could flip its orientation: twice its area under 0.01
 * texel × its perimeter, where the corners' rounding moves it by under 1e-3 × perimeter.
 * An edge shorter than 0.05 texel or 2e-3 of the polygon's size is left out (fewer
 * half-planes only keep more texels): the rounding of its direction could tilt its line
 * by 0.03 texel across the polygon. */
inline int polygon_edges(const float2* corner, int corners, float3* edge)
{
    float area = 0.0f, perimeter = 0.0f; /* twice the signed area */
    float2 lo = corner[0], hi = corner[0];
    for (int k = 0; k < corners; ++k) {
        float2 u = corner[k] - corner[0], v = corner[(k + 1) % corners] - corner[0];
        area += u.x * v.y - u.y * v.x;
        perimeter += inline_fabs(v.x - u.x) + inline_fabs(v.y - u.y);
        lo = (float2)(inline_fmin(lo.x, corner[k].x), inline_fmin(lo.y, corner[k].y));
        hi = (float2)(inline_fmax(hi.x, corner[k].x), inline_fmax(hi.y, corner[k].y));
    }
    if (!(inline_fabs(area) >= 0.01f * perimeter)) return 0;
    float orientation = area > 0.0f ? 1.0f : -1.0f;
    float shortest = inline_fmax(0.05f, 2e-3f * inline_fmax(hi.x - lo.x, hi.y - lo.y));
    int edges = 0;
    for (int k = 0; k < corners; ++k) {
        float2 from = corner[k], along = corner[(k + 1) % corners] - from;
        if (inline_fabs(along.x) + inline_fabs(along.y) < shortest) continue;
        float a = -orientation * along.y, b = orientation * along.x;
        edge[edges++] = (float3)(a, b, -(a * from.x + b * from.y));
    }
    return edges;
}

/* Narrows [*first, *last] to the texels of row ty whose square, grown by COVER_GROWTH,
 * meets every half-plane; 0 when none does. */
inline int row_span(const float3* edge, int edges, int ty, int* first, int* last)
{
    float y_low = (float)ty - COVER_GROWTH, y_high = (float)ty + 1.0f + COVER_GROWTH;
    float left = (float)*first, right = (float)*last;
    for (int k = 0; k < edges; ++k) {
        float a = edge[k].x, rest = edge[k].z + inline_fmax(edge[k].y * y_low, edge[k].y * y_high);
        if (a > 0.0f) /* the square's right side x = tx + 1 + growth is the most inside */
            left = inline_fmax(left, inline_ceil(-rest / a - 1.0f - COVER_GROWTH));
        else if (a < 0.0f) /* its left side x = tx - growth */
            right = inline_fmin(right, inline_floor(rest / -a + COVER_GROWTH));
        else if (rest < 0.0f)
            return 0;
    }
    if (!(left <= right)) return 0;
    *first = (int)left;
    *last = (int)right;
    return 1;
}

/* The writer map beside the bound map: per texel, the one convex part whose triangles
 * touch it (WRITER_NONE: none yet), or WRITER_MANY once a second one does (both from
 * clrays/structs.py). A sample whose texel's only writer is its own convex part is lit:
 * no other triangle comes near its segment to the light, which projects into that texel,
 * and the part lies wholly on the far side of the sample's plane from the light (the
 * sample's face turns towards it), which the segment leaves at the sample. A part is a
 * label per triangle, the bits in w of its second vertex row (clrays.inputs.vertex_rows):
 * a plane's, a box's or a sphere's triangles share one, any other triangle has its own
 * (Geometry.convex_part). So the seams of a floor's triangles and a box's edges leave
 * their texels to no other test. A box's or a sphere's label has CONVEX_OUTSIDE_ONLY:
 * the argument holds for a point of its outside, which its winding faces; seen from
 * inside (a room, a dome) the sample's face turns towards a light beyond the far wall,
 * which the same part blocks. */
ALWAYS_INLINE int convex_part_of(global const float4* tri_vertices, int tri)
{
    return as_int(tri_vertices[3 * tri + 1].w);
}

/* Whether the writer map's `writer`, at a sample on triangle `tri` seen along `dir`, is
 * the sample's own part alone, with the sample on a side of it that the part cannot shadow. */
ALWAYS_INLINE int only_own_part(global const float4* tri_vertices, global const float4* tri_normal, int tri,
                                int writer, float3 dir)
{
    int part = convex_part_of(tri_vertices, tri);
    return writer == part && (!(part & CONVEX_OUTSIDE_ONLY) || inline_dot(tri_normal[tri].xyz, dir) < 0.0f);
}

inline void note_writer(global int* texel_writer, int part)
{
    int seen = *texel_writer; /* the read spares the atomics once a texel is decided */
    if (seen == part || seen == WRITER_MANY) return;
    int before = atomic_cmpxchg(texel_writer, WRITER_NONE, part);
    if (before != WRITER_NONE && before != part) atomic_xchg(texel_writer, WRITER_MANY);
}

/* note_writer where no other work-item writes the texel meanwhile (visibility_bound_rows). */
inline void note_owned_writer(global int* texel_writer, int part)
{
    int seen = *texel_writer;
    if (seen != part && seen != WRITER_MANY) *texel_writer = seen == WRITER_NONE ? part : WRITER_MANY;
}

/* Whether any texel of [x0, x1] in the row at frame address `row` has its read_mask bit:
 * a word of 32 texels at a time. */
inline int row_is_read(global const uint* read_mask, int row, int x0, int x1)
{
    for (int at = row + x0, last = row + x1; at <= last;) {
        int bits = inline_min(32 - (at & 31), last - at + 1);
        uint span = bits == 32 ? 0xffffffffu : ((1u << bits) - 1u) << (at & 31);
        if (read_mask[at >> 5] & span) return 1;
        at += bits;
    }
    return 0;
}

/* Whether the read_mask has a bit in the texel rectangle [x0, x1] × [y0, y1] of a view:
 * texel by texel up to `texel_rows` rows, a word of 32 at a time for more (a thumbnail
 * reads a few dozen texels of a face). */
inline int rectangle_is_read(global const view_t* view, global const uint* read_mask, int mask_offset, int x0, int y0,
                             int x1, int y1, int texel_rows)
{
    int row_start = mask_offset + view->depth_offset;
    if (y1 - y0 + 1 > texel_rows) {
        for (int ty = y0; ty <= y1; ++ty)
            if (row_is_read(read_mask, row_start + ty * view->width, x0, x1)) return 1;
        return 0;
    }
    for (int ty = y0; ty <= y1; ++ty)
        for (int tx = x0; tx <= x1; ++tx) {
            int at = row_start + ty * view->width + tx;
            if ((read_mask[at >> 5] >> (at & 31)) & 1u) return 1;
        }
    return 0;
}

/* Beside the writer map, with a capacity (touching_capacity > 0: a frame of few samples,
 * clrays/stages/visibility.py), every triangle that touches a texel read, as a list per
 * texel: touching_head[texel] (-1 empty) → touching[node] = (triangle, next node). The
 * segment from a sample to the light projects into its texel, so every triangle it
 * crosses is in that texel's list (the writer map's argument), and visibility_rays_listed
 * tests those alone instead of walking a BVH. Nodes past the capacity are not linked;
 * the host then builds the BVH. */
#define TOUCHING_ARGS global int* touching_head, global int2* touching, volatile global int* touching_count, \
                      int touching_capacity
#define TOUCHING_PASS touching_head, touching, touching_count, touching_capacity

inline void note_touching(global int* head, int tri, global int2* touching, volatile global int* touching_count,
                          int touching_capacity)
{
    if (touching_capacity <= 0) return;
    int node = atomic_inc(touching_count);
    if (node >= touching_capacity) return;
    touching[node].x = tri;
    touching[node].y = atomic_xchg(head, node);
}

/* The conservative bound map: every texel a triangle may touch (per row, the span whose
 * squares, grown by COVER_GROWTH, meet the projection of its part inside the frustum)
 * gets a depth no larger than the triangle's nearest point inside that texel's footprint:
 *   perspective: inline_max(distance to the closest point of the triangle, distance to its plane
 *     along the texel's cone, bounded by the cone's half-angle ρ: h / cos(inline_max(φ - ρ, 0)));
 *   orthographic: inline_max(nearest vertex, the plane's depth at the texel's nearest corner).
 * A triangle thinner than a texel, which the centre-sampled map may miss, is still here.
 * The same texels get the triangle in the writer map (note_writer).
 * With a read_mask (masked ≠ 0), only the texels that a camera sample's lit test reads are
 * drawn (mark_read): those whose bit it has, at the texel's address + mask_offset
 * (the frame's address of the light's texel 0). No sample reads the others, and only they
 * hold starting values (visibility_clear). */
inline void bound_triangle(global const float4* tri_vertices, global const view_t* views, int first_view,
                           int view_count, global uint* bound, global int* writer, int masked,
                           global const uint* read_mask, int mask_offset, TOUCHING_ARGS, int item, int row_begin,
                           int row_end, int column_begin, int column_end, int owned, int small_rows,
                           global int4* big_items, volatile global int* big_count, global int4* rect)
{
    int tri = item / view_count;
    global const view_t* view = views + first_view + item % view_count;
    if (faces_away_from_view(view, tri_vertices[3 * tri], tri_vertices[3 * tri + 1].xyz,
                             tri_vertices[3 * tri + 2].xyz)) {
        if (rect) *rect = (int4)(0, 0, -1, -1); /* as a triangle outside the view */
        return;
    }
    float3 vertex[3], in_view[3];
    float extent = 0.0f;
    for (int k = 0; k < 3; ++k) {
        vertex[k] = tri_vertices[3 * tri + k].xyz - view->origin.xyz;
        in_view[k] = (float3)(inline_dot(vertex[k], view->right.xyz), inline_dot(vertex[k], view->up.xyz),
                              inline_dot(vertex[k], view->forward.xyz));
        extent = inline_fmax(extent, inline_fmax(inline_fabs(in_view[k].x), inline_fmax(inline_fabs(in_view[k].y), inline_fabs(in_view[k].z))));
    }
    int perspective = view->projection == PROJECTION_PERSPECTIVE;
    /* The part of the triangle inside the view's frustum (near plane and four sides,
     * Sutherland–Hodgman, planes a little outside the view), then its texel rectangle.
     * A triangle wholly in front of a perspective view's origin (or any, orthographic)
     * skips the clipping when its corners stay within two texels of the view. */
    float3 polygon[8];
    int corners = 3;
    for (int k = 0; k < 3; ++k) polygon[k] = in_view[k];
    float2 corner[8]; /* the polygon's corners in texel coordinates */
    int clip = perspective && inline_fmin(in_view[0].z, inline_fmin(in_view[1].z, in_view[2].z)) <= 1e-5f * extent;
    if (!clip) {
        for (int k = 0; k < 3; ++k) corner[k] = texel_coordinates(view, polygon[k], perspective);
        clip = !near_the_view(view, corner, 3);
    }
    if (clip) {
        corners = clip_to_frustum(view, polygon, extent);
        if (corners == 0) {
            if (rect) *rect = (int4)(0, 0, -1, -1); /* nothing of it in the view */
            return;
        }
        for (int k = 0; k < corners; ++k) corner[k] = texel_coordinates(view, polygon[k], perspective);
    }
    float2 lo = (float2)(INFINITY), hi = (float2)(-INFINITY);
    for (int k = 0; k < corners; ++k) {
        lo = (float2)(inline_fmin(lo.x, corner[k].x), inline_fmin(lo.y, corner[k].y));
        hi = (float2)(inline_fmax(hi.x, corner[k].x), inline_fmax(hi.y, corner[k].y));
    }
    int x0 = inline_max((int)inline_floor(inline_fmax(lo.x, -2.0f)) - 1, 0), y0 = inline_max((int)inline_floor(inline_fmax(lo.y, -2.0f)) - 1, 0);
    int x1 = inline_min((int)inline_floor(inline_fmin(hi.x, (float)view->width + 2.0f)) + 1, view->width - 1);
    int y1 = inline_min((int)inline_floor(inline_fmin(hi.y, (float)view->height + 2.0f)) + 1, view->height - 1);
    if (rect) *rect = (int4)(x0, y0, x1, y1);
    int first_row = inline_max(y0, row_begin), last_row = inline_min(y1, row_end - 1);
    int first_column = inline_max(x0, column_begin), last_column = inline_min(x1, column_end - 1);
    if (first_column > last_column || first_row > last_row) return; /* outside the view, or not this item's texels */
    /* no sample reads its rectangle: nothing to draw */
    if (masked && small_rows > 0 && !rectangle_is_read(view, read_mask, mask_offset, x0, y0, x1, y1, small_rows))
        return;
    if (small_rows > 0 && y1 - y0 + 1 > small_rows) { /* many rows: the rows pass takes them */
        big_items[atomic_inc(big_count)] = (int4)(item, y0, y1, x0 | x1 << 16); /* a view is at most 8192 wide */
        return;
    }
    int part = convex_part_of(tri_vertices, tri); /* the writer map's label */
    float3 normal = inline_cross(vertex[1] - vertex[0], vertex[2] - vertex[0]);
    float normal_length = exact_length(normal);
    float3 n = normal_length > 0.0f ? normal / normal_length : (float3)(0.0f);
    float plane = inline_dot(n, vertex[0]); /* signed distance of the plane from the view origin */
    if (plane < 0.0f) {
        n = -n;
        plane = -plane;
    }
    float nearest; /* the triangle's nearest depth anywhere */
    if (perspective) {
        nearest = exact_length(closest_on_triangle((float3)(0.0f), vertex[0], vertex[1], vertex[2]));
    } else {
        nearest = inline_fmin(in_view[0].z, inline_fmin(in_view[1].z, in_view[2].z));
    }
    float n_forward = inline_dot(n, view->forward.xyz);
    /* A texel's cone is widest at the view's centre: ρ there bounds every texel's. */
    float3 middle = view_direction(view, 0.5f * (float)view->width, 0.5f * (float)view->height);
    float3 diagonal = view_direction(view, 0.5f * (float)view->width + 1.0f, 0.5f * (float)view->height + 1.0f);
    /* sin ρ from the cross product: ρ is a few thousandths, where sqrt(1 - cos² ρ) is up to
     * 1 % off (the rounding of cos ρ), which at a slant lifts a texel's bound past its 1e-5
     * margin */
    float cos_rho = inline_dot(middle, diagonal), sin_rho = inline_length(inline_cross(middle, diagonal));
    /* No texel gets less than this from the triangle (the margin below is monotonic in the
     * depth): a texel already at or under it is skipped before its cone maths, which
     * leaves the atomic-min result unchanged. */
    uint floor_bits = as_uint(inline_fmax(nearest - BOUND_MARGIN_REL * inline_fabs(nearest) - BOUND_MARGIN_REL * extent, 0.0f));
    /* The texel maths in view coordinates (right, up, forward), per row what a row shares:
     * the centre of texel (tx, ty) looks along (x, y, 1), x = ((2·tx + 1)/width - 1)·scale_x,
     * y = (1 - (2·ty + 1)/height)·scale_y (view_direction, unnormalised). */
    float3 n_view = (float3)(inline_dot(n, view->right.xyz), inline_dot(n, view->up.xyz), n_forward);
    float inverse_width = 1.0f / (float)view->width, inverse_height = 1.0f / (float)view->height;
    /* Orthographic: the plane's depth (plane - n_r·x - n_u·y) / n_f is linear across the
     * texel, so its least corner is the same one in every texel, (tx + corner_x, ty + corner_y). */
    int corner_x = n_view.x * n_forward > 0.0f, corner_y = n_view.y * n_forward < 0.0f;
    float3 edge[8];
    int edges = polygon_edges(corner, corners, edge);
    for (int ty = first_row; ty <= last_row; ++ty) {
        int first = first_column, last = last_column;
        if (!row_span(edge, edges, ty, &first, &last)) continue;
        float y_centre = (1.0f - (2.0f * (float)ty + 1.0f) * inverse_height) * view->scale_y;
        float row_dot = n_view.z + n_view.y * y_centre, row_length2 = 1.0f + y_centre * y_centre;
        float y_corner = (1.0f - 2.0f * (float)(ty + corner_y) * inverse_height) * view->scale_y;
        float row_plane = plane - n_view.y * y_corner;
        for (int tx = first; tx <= last; ++tx) {
            if (masked) {
                int at = mask_offset + view->depth_offset + ty * view->width + tx;
                uint bits = read_mask[at >> 5] >> (at & 31); /* this texel's and the next ones in its word */
                if (bits == 0u) tx += 31 - (at & 31); /* none read to the word's end */
                if (!(bits & 1u)) continue;
            }
            if (owned)
                note_owned_writer(writer + view->depth_offset + ty * view->width + tx, part);
            else
                note_writer(writer + view->depth_offset + ty * view->width + tx, part);
            note_touching(touching_head + view->depth_offset + ty * view->width + tx, tri, touching, touching_count,
                          touching_capacity);
            if (bound[view->depth_offset + ty * view->width + tx] <= floor_bits) continue;
            float depth = nearest;
            if (perspective && normal_length > 0.0f) {
                float x_centre = ((2.0f * (float)tx + 1.0f) * inverse_width - 1.0f) * view->scale_x;
                float cos_phi = (row_dot + n_view.x * x_centre) * (1.0f / inline_sqrt(row_length2 + x_centre * x_centre));
                float sin_phi = inline_sqrt(inline_fmax(1.0f - cos_phi * cos_phi, 0.0f));
                /* cos(φ - ρ) ≥ the largest n·u over the texel's cone; φ ≤ ρ: the foot may be inside */
                float cos_gap = cos_phi >= cos_rho ? 1.0f : cos_phi * cos_rho + sin_phi * sin_rho;
                if (cos_gap <= 0.0f) continue; /* no ray of this texel meets the plane */
                depth = inline_fmax(depth, plane / cos_gap);
            } else if (!perspective && inline_fabs(n_forward) > 1e-6f) {
                float x_corner = (2.0f * (float)(tx + corner_x) * inverse_width - 1.0f) * view->scale_x;
                depth = inline_fmax(depth, (row_plane - n_view.x * x_corner) / n_forward);
            }
            depth = inline_fmax(depth - BOUND_MARGIN_REL * inline_fabs(depth) - BOUND_MARGIN_REL * extent, 0.0f);
            global uint* texel = bound + view->depth_offset + ty * view->width + tx;
            if (as_uint(depth) < *texel) { /* the read spares most atomics */
                if (owned)
                    *texel = as_uint(depth);
                else
                    atomic_min(texel, as_uint(depth));
            }
        }
    }
}

/* Before the bound passes, with a read_mask: only the texels read get their starting
 * values (bound DEPTH_EMPTY, writer WRITER_NONE, unless clear_maps is 0; the touching
 * lists' heads -1), as only they are drawn and read; one work-item per
 * VISIBILITY_CLEAR_WORDS words of the mask over the light's texels [first, first + texels)
 * (frame addresses; the light's own maps are at address - first). A work-item per word was mostly its own overhead: a
 * cube's mask is 196k words, few of them with a bit set. */
kernel void visibility_clear(global const uint* read_mask, int first, int texels, int clear_maps, global uint* bound,
                             global int* writer, global int* touching_head, int touching_capacity)
{
    int first_word = first >> 5, last_word = (first + texels - 1) >> 5;
    int begin = first_word + get_global_id(0) * VISIBILITY_CLEAR_WORDS;
    int end = min(begin + VISIBILITY_CLEAR_WORDS, last_word + 1);
    for (int word = begin; word < end; ++word) {
        uint bits = read_mask[word];
        /* only the set bits, lowest first (__builtin_ctz is an instruction, not a library call) */
        for (; bits != 0u; bits &= bits - 1u) {
            int at = 32 * word + __builtin_ctz(bits);
            if (at >= first && at < first + texels) {
                if (clear_maps) {
                    bound[at - first] = DEPTH_EMPTY;
                    writer[at - first] = WRITER_NONE;
                }
                if (touching_capacity > 0) touching_head[at - first] = -1;
            }
        }
    }
}

/* Two passes, because a triangle's rectangle may hold a few texels or a whole face:
 * visibility_bound takes one work-item per triangle and view and does the rectangles of
 * up to `small_rows` rows at once, listing the others in big_items with their rows;
 * visibility_bound_rows then gives each work-item a block of the view, `rows_per_item`
 * rows by `columns_per_item` columns, which it draws for every listed triangle in the
 * list's order. Only that work-item writes those texels in this pass, so its updates are
 * plain stores, not atomics: spread over the rows of each triangle instead, demo.yaml's
 * floor and walls spent about 40 % of the pass in them (docs/design.md §4.6). A triangle
 * is projected and clipped once per block it covers. A launch draws one view
 * (view_count 1), whose size bounds the blocks; a block is drawn for a listed triangle
 * where the texel rectangle the first pass found for it (rows [y0, y1], columns
 * [x0, x1]) meets the block (bound_triangle clips again to the same texels). */
kernel void visibility_bound(global const float4* tri_vertices, int count, global const view_t* views,
                             int first_view, int view_count, global uint* bound, global int* writer,
                             int masked, global const uint* read_mask, int mask_offset, TOUCHING_ARGS,
                             int small_rows, global int4* big_items, volatile global int* big_count,
                             int rect_mode, global int4* rects)
{
    int item = get_global_id(0);
    if (item >= count * view_count) return;
    if (rect_mode == RECTS_FILTER) {
        /* a pass again over fewer texels: a triangle whose rectangle holds none of them is
         * done before its projection */
        int4 rect = rects[item];
        global const view_t* view = views + first_view + item % view_count;
        if (rect.x > rect.z
            || !rectangle_is_read(view, read_mask, mask_offset, rect.x, rect.y, rect.z, rect.w, small_rows))
            return;
    }
    bound_triangle(tri_vertices, views, first_view, view_count, bound, writer, masked, read_mask, mask_offset,
                   TOUCHING_PASS, item, 0, INT_MAX, 0, INT_MAX, 0, small_rows, big_items, big_count,
                   rect_mode == RECTS_RECORD ? rects + item : 0);
}

kernel void visibility_bound_rows(global const float4* tri_vertices, global const view_t* views, int first_view,
                                  int view_count, global uint* bound, global int* writer,
                                  int masked, global const uint* read_mask, int mask_offset, TOUCHING_ARGS,
                                  global const int4* big_items, int big_count, int rows_per_item,
                                  int columns_per_item)
{
    int row_begin = get_global_id(0) * rows_per_item, row_end = row_begin + rows_per_item;
    int column_begin = get_global_id(1) * columns_per_item, column_end = column_begin + columns_per_item;
    if (row_begin >= views[first_view].height || column_begin >= views[first_view].width) return;
    for (int index = 0; index < big_count; ++index) {
        int4 big = big_items[index]; /* (item, its first row, its last row, its first column | its last << 16) */
        if (big.y >= row_end || big.z < row_begin || (big.w & 0xffff) >= column_end || big.w >> 16 < column_begin)
            continue;
        bound_triangle(tri_vertices, views, first_view, view_count, bound, writer, masked, read_mask, mask_offset,
                       TOUCHING_PASS, big.x, row_begin, row_end, column_begin, column_end, 1, 0, 0, 0, 0);
    }
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

/* The per-sample helpers below are written with inline_math.h's functions (the
 * library's operations in its order: the same bits) so that the per-sample kernels make
 * no library call on their common path (docs/design.md §4.5, "Cost on PoCL"). */

/* The maps' shadowed test (blocked_all_around), 1 unless a test builds with 0: then every
 * sample the lit tests leave casts a ray, which the test's answers must match. */
#ifndef VISIBILITY_SHADOWED_TEST
#define VISIBILITY_SHADOWED_TEST 1
#endif

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
            float own = own_plane_depth(view, p, n, cx, cy);
            if (own > 0.0f && stored + tolerance >= own) return 0;
        }
    return 1;
}

/* Whether shade's cosine for this light is ≤ 0 wherever the sample lies on its triangle,
 * so its visibility is never read: the flat normal n (already facing the camera) turns
 * away from the light and, on a smooth triangle, so does every vertex normal (flipped
 * with n), whose weighted sum is shade's shading normal. The margin keeps the float32
 * rounding of that sum from ever making shade's cosine positive where this says ≤ 0. */
ALWAYS_INLINE int turned_away(global const float4* tri_normal, global const float4* tri_vertex_normals, int tri,
                              float3 n, float3 to_light)
{
    const float margin = -1e-4f;
    if (inline_dot(n, to_light) > margin) return 0;
    if (tri_normal[tri].w == 0.0f) return 1;
    float side = inline_dot(n, tri_normal[tri].xyz) >= 0.0f ? 1.0f : -1.0f;
    for (int k = 0; k < 3; ++k)
        if (side * inline_dot(tri_vertex_normals[3 * tri + k].xyz, to_light) > margin) return 0;
    return 1;
}

/* Whether light_incident is non-zero at p (any light arrives), and as it, the unit
 * direction from p towards the light. Its three exp() only where they could decide it:
 * inside a spot's cone, some channel with power ≥ 1e-6, σt·d ≤ 30 and d² ≤ 1e10 is
 * ≥ 1e-29 for sure, a normal float, so non-zero. */
ALWAYS_INLINE int light_reaches(global const light_t* light, float3 sigma_t, float3 p, float3* to_light)
{
    if (light->type != LIGHT_DIRECTIONAL) {
        float3 w = p - light->position.xyz;
        float d2 = inline_dot(w, w);
        float d = inline_sqrt(d2);
        *to_light = d > 0.0f ? -w / d : (float3)(0.0f, 1.0f, 0.0f);
        if (light->type == LIGHT_SPOT && inline_dot(w, light->direction.xyz) < light->cos_cone * d) return 0;
        float3 power = light->power.xyz, attenuation = sigma_t * d;
        if (d2 <= 1e10f && ((power.x >= 1e-6f && attenuation.x <= 30.0f) || (power.y >= 1e-6f && attenuation.y <= 30.0f)
                            || (power.z >= 1e-6f && attenuation.z <= 30.0f)))
            return 1;
    }
    float3 incident = light_incident(light, sigma_t, p, to_light);
    return incident.x + incident.y + incident.z != 0.0f;
}

/* Where the shadow ray leaves: on the light's side of the surface, as the exact
 * reference's does. */
ALWAYS_INLINE float3 shadow_ray_start(global const light_t* light, float3 p, float3 n, float3 to_light)
{
    float to_light_distance = light->type == LIGHT_DIRECTIONAL ? 0.0f : exact_length(light->position.xyz - p);
    float3 side = inline_dot(n, to_light) >= 0.0f ? n : -n;
    return p + side * (SHADOW_RAY_OFFSET_REL * (exact_length(p) + to_light_distance));
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
    if (turned_away(tri_normal, tri_vertex_normals, tri, n, to_light)) {
        if (reaches) visible[entry] = 0.0f; /* shade weighs this light by a cosine ≤ 0: no map test, no ray */
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

/* light_view_index, then view_project (lighting.h) on each lane: the view of p, its
 * continuous texel coordinates and its depth there; the lanes where p is behind a
 * perspective view come back 0 (their texel and depth unused). */
ALWAYS_INLINE int_lanes light_project_lanes(global const view_t* views, global const light_t* light, float_lanes px,
                                            float_lanes py, float_lanes pz, view_lanes_t* v, float_lanes* texel_x,
                                            float_lanes* texel_y, float_lanes* depth)
{
    *v = views_of_lanes(views, light_view_index_lanes(light, px, py, pz));
    float_lanes qx = px - v->origin_x, qy = py - v->origin_y, qz = pz - v->origin_z;
    float_lanes x = dot_lanes_of_lanes(qx, qy, qz, v->right_x, v->right_y, v->right_z);
    float_lanes y = dot_lanes_of_lanes(qx, qy, qz, v->up_x, v->up_y, v->up_z);
    float_lanes z = dot_lanes_of_lanes(qx, qy, qz, v->forward_x, v->forward_y, v->forward_z);
    int perspective = views[light->first_view].projection == PROJECTION_PERSPECTIVE;
    *depth = perspective ? length_lanes(qx, qy, qz) : z;
    float_lanes screen_x = perspective ? x / (z * v->scale_x) : x / v->scale_x;
    float_lanes screen_y = perspective ? y / (z * v->scale_y) : y / v->scale_y;
    *texel_x = (screen_x + 1.0f) * 0.5f * float_of_lanes(v->width);
    *texel_y = (1.0f - screen_y) * 0.5f * float_of_lanes(v->height);
    return perspective ? !(z <= 0.0f) : (int_lanes)(-1);
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
    float_lanes nx, ny, nz, flat_w; /* the triangle's normal; w: 0 flat, else smooth */
    gather_records(tri_normal, own, &nx, &ny, &nz, &flat_w);
    float_lanes own_x = nx, own_y = ny, own_z = nz;
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
    float_lanes side = dot_lanes_of_lanes(nx, ny, nz, own_x, own_y, own_z) >= 0.0f ? 1.0f : -1.0f;
    int_lanes vertex_lit = (int_lanes)(0);
    if (any_lanes(surface & !(facing > margin) & flat_w != 0.0f)) /* a smooth triangle's vertex normals decide */
        for (int k = 0; k < 3; ++k) {
            float_lanes vx, vy, vz, unused;
            gather_records(tri_vertex_normals, 3 * own + k, &vx, &vy, &vz, &unused);
            vertex_lit |= side * dot_lanes_of_lanes(vx, vy, vz, lx, ly, lz) > margin;
        }
    int_lanes turned = !(facing > margin) & ((flat_w == 0.0f) | !vertex_lit);
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
    float_lanes push = SHADOW_RAY_OFFSET_REL * (sqrt_lanes(p_squared) + to_light_distance);
    int_lanes towards = facing >= 0.0f;
    float_lanes sx = towards ? nx : -nx, sy = towards ? ny : -ny, sz = towards ? nz : -nz;
    float_lanes start_x = px + sx * push, start_y = py + sy * push, start_z = pz + sz * push;
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
 * their addresses get their bit in read_mask, as visibility_prepare's. */
kernel void visibility_mark_listed(global const int* ray_entries, int ray_count, global const int2* map_read,
                                   global uint* read_mask)
{
    int item = get_global_id(0);
    if (item >= ray_count) return;
    mark_read(read_mask, map_read[ray_entries[item]].x);
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
        if (depth <= bound_depth + SURFACE_BIAS_TEXELS * shadow_texel_size(light, depth)) {
            float3 to_light;
            light_reaches(light, frame->sigma_t.xyz, p, &to_light);
            float3 start = shadow_ray_start(light, p, n, to_light);
            global const view_t* view = views + light_view_index(light, start);
            float reach = 0.0f; /* of the sample's triangle from the view's origin */
            for (int k = 0; k < 3; ++k)
                reach = inline_fmax(reach, exact_length(tri_vertices[3 * tri + k].xyz - view->origin.xyz));
            if (depth <= bound_depth + own_surface_slack(light, view, start, n, depth, reach)) {
                out[l] = 1.0f;
                return;
            }
        }
        float3 lookup = p + n * shadow_texel_size(light, exact_length(p - light->position.xyz));
        if (blocked_all_around(light, views, shadow_depth, lookup, p, n)) {
            out[l] = 0.0f;
            return;
        }
    }
    ray_entries[atomic_inc(ray_count)] = sample * frame->light_count + l;
    if (read.x < 0) atomic_inc(ray_count + 1); /* no texel: only the BVH can answer it */
}

/* decide_entry on LANES consecutive samples and one light at once. A lane within the bias
 * of its bound, whose own surface's slack decides (acos, cos), takes decide_entry alone;
 * 0, having written nothing, where a lane needs exact_length's library call. An
 * orthographic camera is never sent here. */
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
    int_lanes blocked = (int_lanes)(0), slack = (int_lanes)(0);
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
        slack = heavy & (depth <= bound_depth + SURFACE_BIAS_TEXELS * bias_size); /* decide_entry's, lane by lane */
        heavy &= !slack;
        /* lookup = p + n · shadow_texel_size(|p - light|), then blocked_all_around */
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
                float_lanes stored = LOAD_LANES((global const float*)shadow_depth,
                                                v.depth_offset + cys[j] * v.width + cxs[i]);
                float_lanes t = perspective
                                    ? num * sqrt_lanes(1.0f + spread_x[i] + spread_y[j])
                                          / (along_forward + across_x[i] + across_y[j])
                                    : (num - across_x[i] - across_y[j]) / along_forward;
                int_lanes own_plane = (t > 0.0f) & (stored + tolerance >= t);
                blocked &= !(lookup_depth <= stored + tolerance) & !own_plane;
            }
    }
    if (runs && !any_lanes(slack)) { /* the answers as one run of stores; the lanes left listed in turn */
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
        if (slack[k]) {
            decide_entry(frame, views, lights, shadow_depth, bound, writer, map_read, camera_depth, tri_id, tri_vertices,
                         tri_normal, offsets, visible, ray_entries, ray_count, first + k, l);
        } else if (lit[k]) {
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

/* A listed entry's shadow ray: from the point moved off the surface on the light's side,
 * to the light (t in (0, t_max)); its sample's own triangle is skipped. */
inline void listed_shadow_ray(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                              global const uint* camera_depth, global const int* tri_id,
                              global const float4* tri_normal, global const float2* offsets, int entry,
                              float3* start, float3* ray, float* t_max)
{
    int sample = entry / frame->light_count;
    global const light_t* light = lights + entry % frame->light_count;
    float3 p, dir, n;
    camera_surface_point(frame, views, camera_depth, tri_id, tri_normal, offsets, sample, &p, &dir, &n);
    float3 to_light;
    light_reaches(light, frame->sigma_t.xyz, p, &to_light);
    *start = shadow_ray_start(light, p, n, to_light);
    *ray = light->type == LIGHT_DIRECTIONAL ? to_light : light->position.xyz - *start;
    *t_max = light->type == LIGHT_DIRECTIONAL ? INFINITY : 1.0f;
}

/* The shadow rays of the entries visibility listed, through the BVH, one work-item per
 * entry. Each entry's answer depends on it alone, so the list's order (atomics) changes
 * nothing. */
kernel void visibility_rays(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                            global const uint* camera_depth, global const int* tri_id,
                            global const float4* tri_vertices, global const float4* tri_normal,
                            global const float2* offsets, global const float4* node_bounds,
                            global const int2* node_children, int root, global const int* ray_entries,
                            int ray_count, global float* visible)
{
    int item = get_global_id(0);
    if (item >= ray_count) return;
    int entry = ray_entries[item];
    float3 start, ray;
    float t_max;
    listed_shadow_ray(frame, views, lights, camera_depth, tri_id, tri_normal, offsets, entry, &start, &ray, &t_max);
    visible[entry] = bvh_occluded(node_bounds, node_children, root, tri_vertices, start, ray, 0.0f, t_max,
                                  tri_id[entry / frame->light_count]) ? 0.0f : 1.0f;
}

/* The same rays of one light's entries (`light`), each against the triangles that touch
 * its texel (note_touching: the light's lists, texel addresses less `first`, the frame's
 * address of the light's texel 0) instead of the BVH's: the same triangles that can meet
 * the segment, tested by the same ray test, so the same answer (docs/design.md §4.6). */
kernel void visibility_rays_listed(global const frame_t* frame, global const view_t* views,
                                   global const light_t* lights, global const uint* camera_depth,
                                   global const int* tri_id, global const float4* tri_vertices,
                                   global const float4* tri_normal, global const float2* offsets,
                                   global const int2* map_read, int light, int first,
                                   global const int* touching_head, global const int2* touching,
                                   global const int* ray_entries, int ray_count, global float* visible)
{
    int item = get_global_id(0);
    if (item >= ray_count) return;
    int entry = ray_entries[item];
    if (entry % frame->light_count != light) return;
    float3 start, ray;
    float t_max;
    listed_shadow_ray(frame, views, lights, camera_depth, tri_id, tri_normal, offsets, entry, &start, &ray, &t_max);
    int skip = tri_id[entry / frame->light_count], occluded = 0;
    for (int node = touching_head[map_read[entry].x - first]; node >= 0 && !occluded; node = touching[node].y) {
        int tri = touching[node].x;
        occluded = tri != skip && ray_meets_triangle(start, ray, 0.0f, t_max, tri_vertices[3 * tri].xyz,
                                                     tri_vertices[3 * tri + 1].xyz, tri_vertices[3 * tri + 2].xyz);
    }
    visible[entry] = occluded ? 0.0f : 1.0f;
}
