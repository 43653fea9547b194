/* relief_cuts.h — a relief's shadow along one ray, cut in the ray's own half-plane
 * (docs/design.md §4.5, "A relief's shadow cut per ray"; the host side is
 * clrays/stages/relief_cuts.py). The volume's shadow map leaves the reliefs out; their
 * outline seen from the light comes as edges, each with the change in how many of the
 * relief's triangles a light ray crosses when it passes that edge. In the ray's half-plane
 * (shaft_edges.h's ray_plane_t) an edge crosses at one point; where that point lies
 * towards the light from the ray (its β at most the ray's: the ray never crosses the
 * relief, it would end there, so that holds all along the triangles beside it), passing it
 * changes how many triangles lie between the ray and the light. From the eye's own count,
 * the crossings in rising γ give the ray's shadowed stretches: where that count is above 0.
 * (The edges are placed around a point a hair beside the eye, where that count is one
 * number: relief_cuts.py, nudged_eye.) */
#ifndef CLRAYS_RELIEF_CUTS_H
#define CLRAYS_RELIEF_CUTS_H
#include "shaft_edges.h"

/* The relief's shadow along a ray: γ stretches [bound[0], bound[1]), [bound[2], bound[3]) …
 * in rising order. */
typedef struct {
    float bound[RELIEF_CROSSINGS + 2];
    int bounds;
} relief_shadow_t;

/* The relief's shadow along the ray of half-plane `plane` up to γ `reach` (`planar` 0: a ray
 * along the eye's light ray, in no half-plane, shadowed throughout where the eye is). No bin
 * holds more than RELIEF_CROSSINGS edges (clrays/stages/relief_cuts.py alpha_bins). */
inline void relief_shadow_of(global const epipolar_t* ep, const ray_plane_t* plane, int planar, float reach,
                             const walk_features_t* features, relief_shadow_t* shadow)
{
    float crossing[RELIEF_CROSSINGS];
    int change[RELIEF_CROSSINGS];
    int count = 0;
    shadow->bounds = 0;
    if (planar) {
        float3 across = plane->across, normal = plane->normal, axis = plane->axis;
        float alpha = atan2_approx(inline_dot(across, ep->w.xyz), inline_dot(across, ep->u.xyz));
        int bins = features->relief_bins;
        int bin = inline_clamp_int((int)inline_floor((alpha + M_PI_F) * ((float)bins / (2.0f * M_PI_F))), 0, bins - 1);
        int first = features->relief_bin_offsets[bin], last = features->relief_bin_offsets[bin + 1];
        for (int k = first; k < last; ++k) {
            float4 low = features->relief_edges[2 * k], high = features->relief_edges[2 * k + 1];
            /* A directional light's γ is the distance from the eye's light ray: the bin's
             * edges come nearest first, and none of the rest reaches the ray's extent. */
            if (plane->directional && high.w > reach) break;
            float h0 = inline_dot(low.xyz, normal), h1 = inline_dot(high.xyz, normal);
            if ((h0 >= 0.0f) == (h1 >= 0.0f)) continue;
            float3 p = low.xyz + (high.xyz - low.xyz) * (h0 / (h0 - h1));
            float a = inline_dot(p, axis), b = inline_dot(p, across);
            /* in the other half of the plane, or not towards the light from the ray */
            if (b < 0.0f || b * plane->cos_beta - a * plane->sin_beta > 0.0f) continue;
            if (count == RELIEF_CROSSINGS) break; /* (the host's bins hold no more edges than this) */
            float gamma = plane->directional ? b : atan2_approx(b, plane->d_el - a);
            /* passing from the edge's right to its left adds `low.w`: the lower end on the
             * normal's negative side is passing it from left to right */
            int step = h0 < 0.0f ? -(int)low.w : (int)low.w;
            int at = count++;
            while (at > 0 && crossing[at - 1] > gamma) {
                crossing[at] = crossing[at - 1];
                change[at] = change[at - 1];
                --at;
            }
            crossing[at] = gamma;
            change[at] = step;
        }
    }
    int layers = features->relief_eye_count;
    if (layers > 0) shadow->bound[shadow->bounds++] = 0.0f;
    for (int k = 0; k < count; ++k) {
        int before = layers > 0;
        layers += change[k];
        if ((layers > 0) != before) shadow->bound[shadow->bounds++] = crossing[k];
    }
    if (shadow->bounds & 1) shadow->bound[shadow->bounds++] = INFINITY;
}

#endif
