/* visibility_bound — the maps a light's lit tests read (visibility.h).
 * visibility_bound, visibility_bound_rows read tri_vertices, views; write bound (a lower
 * bound of the depth of every triangle that touches each texel, a min), writer (the
 * one triangle that touches each texel, or WRITER_MANY), with a capacity the lists of the
 * triangles touching each texel read (touching_head, touching, touching_count) and the
 * list of triangles whose rectangles the rows pass takes, with their rows and columns
 * (big_items, big_count). A view from outside every closed solid leaves out the faces they turn
 * away from it (solids.h): the first blocker of any segment to the light is a face turned
 * towards the light, and it touches the same texels. */
#include "visibility.h"

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
                             global int* writer, global int* touching_head, int touching_capacity, ROUTE_ARGS)
{
    RETURN_UNLESS_ROUTED
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
                             int rect_mode, global int4* rects, ROUTE_ARGS)
{
    RETURN_UNLESS_ROUTED
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
                                  global const int4* big_items, global const int* listed, int rows_per_item,
                                  int columns_per_item, ROUTE_ARGS)
{
    RETURN_UNLESS_ROUTED
    int big_count = *listed; /* (read here: the host enqueues this pass without waiting for it) */
    if (big_count == 0) return;
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

/* The rows pass's list of a view ordered nearest the view first (by the distance of each
 * listed triangle's centroid from the view's origin; orthographic: its depth along
 * `forward`): a far floor under nearer triangles then mostly finds their bounds already
 * below its own nearest depth and skips its texel maths. Any order gives the same maps.
 * The list's length is read here, so the host enqueues this without waiting for it. One
 * work-group sorts (key, place) pairs in local memory (a bitonic sort over the power of two
 * ORDER_LONGEST, the pairs past the list's length at +inf); a list longer than that keeps
 * the order in which the first pass listed it. */
#define ORDER_LONGEST 2048 /* 16 KiB of local memory */
kernel void visibility_order(global const float4* tri_vertices, global const view_t* views, int view_index,
                             global const int4* big_items, global const int* big_count, global int4* ordered,
                             ROUTE_ARGS)
{
    RETURN_UNLESS_ROUTED
    local float keys[ORDER_LONGEST];
    local int places[ORDER_LONGEST];
    int count = *big_count, item = get_local_id(0), items = get_local_size(0);
    if (count > ORDER_LONGEST) {
        for (int k = item; k < count; k += items) ordered[k] = big_items[k];
        return;
    }
    int size = 1;
    while (size < count) size <<= 1;
    global const view_t* view = views + view_index;
    for (int k = item; k < size; k += items) {
        float key = INFINITY;
        if (k < count) {
            int tri = big_items[k].x;
            float3 centroid = (tri_vertices[3 * tri].xyz + tri_vertices[3 * tri + 1].xyz
                               + tri_vertices[3 * tri + 2].xyz) / 3.0f - view->origin.xyz;
            key = view->projection == PROJECTION_PERSPECTIVE ? length(centroid) : dot(centroid, view->forward.xyz);
        }
        keys[k] = key;
        places[k] = k;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int run = 2; run <= size; run <<= 1) {
        for (int stride = run >> 1; stride > 0; stride >>= 1) {
            for (int k = item; k < size; k += items) {
                int other = k ^ stride;
                if (other > k) {
                    int ascending = (k & run) == 0;
                    float a = keys[k], b = keys[other];
                    if ((a > b) == ascending && a != b) {
                        keys[k] = b;
                        keys[other] = a;
                        int place = places[k];
                        places[k] = places[other];
                        places[other] = place;
                    }
                }
            }
            barrier(CLK_LOCAL_MEM_FENCE);
        }
    }
    for (int k = item; k < count; k += items) ordered[k] = big_items[places[k]];
}
