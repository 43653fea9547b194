/* medium.h — a bounded or heterogeneous medium's density ρ(x) (a factor on σs and σa) and
 * optical depths ∫ρ ds (docs/media.md), in eye space. Reads medium_t, the density grid and
 * the lights' and the eye's optical-depth grids (cl/light_depth.cl writes them); writes nothing.
 *
 * Built with any of MEDIUM_BOUNDED (the box), MEDIUM_HEIGHT (ρ = exp(-(y - base)/H)) and
 * MEDIUM_GRID (trilinear between voxel centres, 0 outside the grid's bounds); without them
 * the medium is homogeneous, MEDIUM_VARYING is undefined and MEDIUM_ARGS adds nothing, so a
 * kernel that includes this header keeps its bits. A kernel takes the medium as
 *
 *     kernel void k(... MEDIUM_ARGS)     // clrays.stages.medium.MediumFeature.args()
 *
 * Optical depths are of unit density: multiply by σt for a channel's. */
#ifndef CLRAYS_MEDIUM_H
#define CLRAYS_MEDIUM_H
#include "common.h"

#if defined(MEDIUM_BOUNDED) || defined(MEDIUM_HEIGHT) || defined(MEDIUM_GRID)
#define MEDIUM_VARYING 1
#define MEDIUM_ARGS , global const medium_t* medium, global const float* density_grid, \
                    global const float* light_depth_grid
#define MEDIUM_PASS , medium, density_grid, light_depth_grid
#define MEDIUM_PARAMS global const medium_t* medium, global const float* density_grid, \
                      global const float* light_depth_grid
#else
#define MEDIUM_ARGS
#endif

/* The optical depth of a path that stays in fog for ever (an unbounded height fog below a
 * light from below): e^{-σt·MEDIUM_DEPTH_MAX} is 0 for any σt > 0, and 0·it stays finite. */
#define MEDIUM_DEPTH_MAX 1e30f
/* exp(-(y - base)/H) is evaluated with its exponent at most this: e^80 ≈ 5.5e34 keeps
 * ρ·σ and ρ·length finite in float32 far below the base. */
#define HEIGHT_EXPONENT_MAX 80.0f
/* Midpoint steps per voxel side of a march through the grid, and the most steps a march takes. */
#define GRID_STEPS_PER_VOXEL 2.0f
#define GRID_MARCH_MAX 4096

#ifdef MEDIUM_VARYING

/* [t0, t1] of the ray o + t·d clipped to the box [lo, hi] (slabs; a zero component of d
 * gives ±inf, which the min/max order right). Returns 0 when nothing is left. */
inline int clip_to_box(float3 lo, float3 hi, float3 o, float3 d, float* t0, float* t1)
{
    float3 inv = 1.0f / d;
    float3 ta = (lo - o) * inv, tb = (hi - o) * inv;
    float3 near = fmin(ta, tb), far = fmax(ta, tb);
    *t0 = fmax(*t0, fmax(near.x, fmax(near.y, near.z)));
    *t1 = fmin(*t1, fmin(far.x, fmin(far.y, far.z)));
    return *t0 < *t1;
}

/* Where the ray o + t·d, t ∈ [t0, t1], can meet medium: the box, and the grid's bounds
 * (ρ = 0 beyond them). Returns 0 where it meets none. */
inline int medium_extent(global const medium_t* medium, float3 o, float3 d, float* t0, float* t1)
{
#ifdef MEDIUM_BOUNDED
    if (!clip_to_box(medium->box_min.xyz, medium->box_max.xyz, o, d, t0, t1)) return 0;
#endif
#ifdef MEDIUM_GRID
    if (!clip_to_box(medium->grid_min.xyz, medium->grid_max.xyz, o, d, t0, t1)) return 0;
#endif
    return *t0 < *t1;
}

/* exp(-(y - base)/H) at height y (eye space), its exponent clamped (HEIGHT_EXPONENT_MAX). */
inline float height_density(global const medium_t* medium, float y)
{
    return exp(fmin(-(y - medium->height_base) / medium->scale_height, HEIGHT_EXPONENT_MAX));
}

/* Trilinear lookup of a grid of nx·ny·nz values (x fastest) over [lo, hi] at p: between voxel
 * centres, held at the outermost centres' values out to the bounds, 0 beyond them. */
inline float grid_trilinear(global const float* values, int nx, int ny, int nz, float3 lo, float3 hi, float3 p)
{
    float3 size = (float3)((float)nx, (float)ny, (float)nz);
    float3 c = (p - lo) / (hi - lo) * size;
    if (any(c < 0.0f) || any(c > size)) return 0.0f;
    c = clamp(c - 0.5f, 0.0f, size - 1.0f);
    float3 cell = floor(c);
    float3 f = c - cell;
    int i = (int)cell.x, j = (int)cell.y, k = (int)cell.z;
    int di = i + 1 < nx, dj = (j + 1 < ny) * nx, dk = (k + 1 < nz) * nx * ny;
    global const float* v = values + (k * ny + j) * nx + i;
    float x00 = mix(v[0], v[di], f.x), x10 = mix(v[dj], v[dj + di], f.x);
    float x01 = mix(v[dk], v[dk + di], f.x), x11 = mix(v[dk + dj], v[dk + dj + di], f.x);
    return mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z);
}

/* Trilinear lookup of a grid of nx·ny·nz values (x fastest) at nodes spanning [lo, hi]
 * corner to corner (node i at lo + i·(hi - lo)/(n - 1), n ≥ 2), p clamped into it. */
inline float nodes_trilinear(global const float* values, int nx, int ny, int nz, float3 lo, float3 hi, float3 p)
{
    float3 last = (float3)((float)(nx - 1), (float)(ny - 1), (float)(nz - 1));
    float3 c = clamp((p - lo) / (hi - lo) * last, 0.0f, last);
    float3 cell = fmin(floor(c), last - 1.0f);
    float3 f = c - cell;
    int i = (int)cell.x, j = (int)cell.y, k = (int)cell.z;
    int dj = nx, dk = nx * ny;
    global const float* v = values + (k * ny + j) * nx + i;
    float x00 = mix(v[0], v[1], f.x), x10 = mix(v[dj], v[dj + 1], f.x);
    float x01 = mix(v[dk], v[dk + 1], f.x), x11 = mix(v[dk + dj], v[dk + dj + 1], f.x);
    return mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z);
}

/* ρ(p): the box's indicator × the height or grid factor. */
inline float medium_density(global const medium_t* medium, global const float* density_grid, float3 p)
{
    float rho = 1.0f;
#ifdef MEDIUM_BOUNDED
    if (any(p < medium->box_min.xyz) || any(p > medium->box_max.xyz)) return 0.0f;
#endif
#ifdef MEDIUM_HEIGHT
    rho *= height_density(medium, p.y);
#endif
#ifdef MEDIUM_GRID
    rho *= grid_trilinear(density_grid, medium->grid_nx, medium->grid_ny, medium->grid_nz,
                          medium->grid_min.xyz, medium->grid_max.xyz, p);
#endif
    return rho;
}

/* ∫ρ ds over the grid by midpoint steps of at most 1/steps_per_voxel voxel (and at most
 * GRID_MARCH_MAX steps): ρ is cubic between voxel-centre planes, so the error is
 * O(step²·ρ'') (docs/media.md). [t0, t1] already clipped to the medium's extent. */
inline float grid_march_depth(global const medium_t* medium, global const float* density_grid,
                              float3 o, float3 d, float t0, float t1, float steps_per_voxel)
{
    float3 voxel = (medium->grid_max.xyz - medium->grid_min.xyz)
                   / (float3)((float)medium->grid_nx, (float)medium->grid_ny, (float)medium->grid_nz);
    float side = fmin(voxel.x, fmin(voxel.y, voxel.z));
    int steps = (int)clamp(ceil((t1 - t0) * steps_per_voxel / side), 1.0f, (float)GRID_MARCH_MAX);
    float dt = (t1 - t0) / (float)steps, depth = 0.0f;
    for (int i = 0; i < steps; ++i) depth += medium_density(medium, density_grid, o + (t0 + ((float)i + 0.5f) * dt) * d);
    return depth * dt;
}

/* ∫ρ ds along o + t·d (d unit), t ∈ [t0, t1] (t1 may be +inf). Box and height fog in closed
 * form: with L the clipped length and z = |d_y|·L/H, ∫ = ρ(lower end)·L·(1 - e^{-z})/z
 * (→ ρ·L as z → 0), or ρ(start)·H/d_y for an unbounded ray rising (d_y > 0); the grid by
 * grid_march_depth. */
inline float segment_depth(global const medium_t* medium, global const float* density_grid,
                           float3 o, float3 d, float t0, float t1)
{
    if (!medium_extent(medium, o, d, &t0, &t1)) return 0.0f;
#ifdef MEDIUM_GRID
    return grid_march_depth(medium, density_grid, o, d, t0, t1, GRID_STEPS_PER_VOXEL);
#else
    float length = t1 - t0;
#ifdef MEDIUM_HEIGHT
    if (isinf(length))
        return d.y > 0.0f ? height_density(medium, o.y + t0 * d.y) * medium->scale_height / d.y : MEDIUM_DEPTH_MAX;
    float z = fabs(d.y) * length / medium->scale_height;
    float lower = o.y + (d.y > 0.0f ? t0 : t1) * d.y;
    float ratio = z > 1e-4f ? -expm1(-z) / z : 1.0f - 0.5f * z;
    return height_density(medium, lower) * length * ratio;
#else
    return isinf(length) ? MEDIUM_DEPTH_MAX : length;
#endif
#endif
}

/* The unit direction from p towards the light (*towards), and how far the light is: +inf for a
 * directional light, 0 at a point light's own position (then *towards is up). */
inline float toward_light(global const light_t* light, float3 p, float3* towards)
{
    if (light->type == LIGHT_DIRECTIONAL) {
        *towards = -light->direction.xyz;
        return INFINITY;
    }
    float3 w = light->position.xyz - p;
    float reach = length(w);
    *towards = reach > 0.0f ? w / reach : (float3)(0.0f, 1.0f, 0.0f);
    return reach;
}

#ifdef MEDIUM_GRID
/* Optical-depth grid `index` (a light's, or the eye's at medium->eye_depth_index; written by
 * cl/light_depth.cl) at p, trilinear between its nodes, p clamped into the grid's bounds. */
inline float depth_grid_lookup(global const medium_t* medium, global const float* light_depth_grid, int index,
                               float3 p)
{
    int count = medium->depth_nx * medium->depth_ny * medium->depth_nz;
    return nodes_trilinear(light_depth_grid + index * count, medium->depth_nx, medium->depth_ny, medium->depth_nz,
                           medium->grid_min.xyz, medium->grid_max.xyz, p);
}
#endif

/* ∫ρ ds from p to light `light_index` (to infinity against a directional light's direction):
 * closed form for box and height fog; in a grid, the light's optical-depth grid looked up
 * trilinearly between its nodes (cl/light_depth.cl), or, for a point outside the grid's bounds (a surface),
 * a march through it. */
inline float light_path_depth(MEDIUM_PARAMS, global const light_t* light, int light_index, float3 p)
{
    float3 towards;
    float reach = toward_light(light, p, &towards);
#ifdef MEDIUM_GRID
    if (all(p >= medium->grid_min.xyz) && all(p <= medium->grid_max.xyz))
        return depth_grid_lookup(medium, light_depth_grid, light_index, p);
#endif
    return segment_depth(medium, density_grid, p, towards, 0.0f, reach);
}

/* ∫ρ ds along a camera ray o + t·d (d unit), t ∈ [0, t1]. In a grid, for a ray from the eye
 * (eye space's origin: a perspective camera's), the eye's optical-depth grid looked up where
 * the ray last is in the medium before t1 (ρ = 0 beyond): one lookup, not a march through
 * every voxel on the way; otherwise segment_depth. */
inline float eye_path_depth(MEDIUM_PARAMS, float3 o, float3 d, float t1)
{
#ifdef MEDIUM_GRID
    if (all(o == 0.0f)) {
        float t0 = 0.0f;
        if (!medium_extent(medium, o, d, &t0, &t1)) return 0.0f;
        return depth_grid_lookup(medium, light_depth_grid, medium->eye_depth_index, t1 * d);
    }
#endif
    return segment_depth(medium, density_grid, o, d, 0.0f, t1);
}

#endif /* MEDIUM_VARYING */
#endif
