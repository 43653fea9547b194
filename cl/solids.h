/* solids.h — the back faces of closed solids, which a view from outside them does not need
 * (docs/design.md §4.1, "Back faces of closed solids").
 *
 * A closed, consistently wound, opaque object (a box, a sphere, a watertight mesh) is met
 * first, by any ray from outside it, at a face turned towards the ray's origin: the ray
 * enters before it leaves. So where a view's rays all start outside every solid (the host
 * sets view_t.cull_back_faces: the eye or the light outside each one, by its winding
 * number; a directional light's map outside the scene's box), the nearest depth along each
 * ray, the bound map's lower bound, the writer map's "one triangle" and the triangles a
 * shadow ray must test are what the faces turned towards the view alone give. Skipping the
 * others halves the triangles a solid puts through the raster and bound passes.
 *
 * tri_vertices[3·t].w holds Geometry.outward of triangle t: +1 where (b − a) × (c − a)
 * points out of its solid, −1 where it points in, 0 for a triangle of no solid, which is
 * never skipped. Only a face clearly turned away is: within BACK_FACE_MARGIN of edge-on
 * (the cosine between its normal and the ray), float32 rounding could flip the sign, and
 * keeping a back face never changes a result. Nor is a sliver (twice its area under
 * BACK_FACE_SLIVER of its longest edge squared), whose float32 normal may point anywhere
 * within far more than that margin. */
#ifndef CLRAYS_SOLIDS_H
#define CLRAYS_SOLIDS_H

#include "common.h"
#include "inline_math.h"

#define BACK_FACE_MARGIN 1e-4f
#define BACK_FACE_SLIVER 0.01f

/* Whether the view may skip the triangle (a, b, c) (a.w: its outward sign): a solid's face
 * turned away from the view's origin (perspective), or along its rays (orthographic). */
ALWAYS_INLINE int faces_away_from_view(global const view_t* view, float4 a, float3 b, float3 c)
{
    if (!view->cull_back_faces || a.w == 0.0f) return 0;
    float3 ab = b - a.xyz, ac = c - a.xyz, bc = c - b;
    float3 normal = a.w * inline_cross(ab, ac);
    float3 along = view->projection == PROJECTION_PERSPECTIVE ? a.xyz - view->origin.xyz : view->forward.xyz;
    float cosine = inline_dot(normal, along); /* times |normal|·|along| */
    float squared = inline_dot(normal, normal);
    float longest = inline_fmax(inline_dot(ab, ab), inline_fmax(inline_dot(ac, ac), inline_dot(bc, bc)));
    return cosine > 0.0f && squared >= BACK_FACE_SLIVER * BACK_FACE_SLIVER * longest * longest
           && cosine * cosine > BACK_FACE_MARGIN * BACK_FACE_MARGIN * squared * inline_dot(along, along);
}

#endif
