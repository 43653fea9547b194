/* common.h — the one C definition of every struct shared by host and device.
 * clrays/structs.py mirrors each struct as a numpy dtype (same fields, same order);
 * tests/layout/test_layout.py checks sizes and offsets against the device.
 *
 * The enumerations and constants shared with Python are defined in clrays/structs.py
 * only and reach every build as -D options (clrays.device.build_options):
 *   PROJECTION_PERSPECTIVE, PROJECTION_ORTHOGRAPHIC       view_t.projection
 *   LIGHT_POINT, LIGHT_SPOT, LIGHT_DIRECTIONAL            light_t.type, integrand_t.light_type
 *   PHASE_ISOTROPIC, PHASE_HG                             frame_t.phase_type
 *   INTEGRAND_TABLE, INTEGRAND_SVD, INTEGRAND_ANALYTIC    integrand_t.mode
 *   TRAVERSAL_TREE, TRAVERSAL_SCAN                        traverse.cl's TRAVERSAL
 *   TEXTURE_WRAP_REPEAT, TEXTURE_WRAP_CLAMP               light_texture_t.wrap
 *   SURFACE_SHADOWS_EXACT, _MAP, _PCF                     frame_t.surface_shadows
 *   DEPTH_EMPTY      as_uint(+INFINITY): nothing rasterized here (uint)
 *   SIN_BETA_MIN     the clamp of sinβ in every 1/sinβ (float) */
#ifndef CLRAYS_COMMON_H
#define CLRAYS_COMMON_H

#if !defined(PROJECTION_PERSPECTIVE) || !defined(PROJECTION_ORTHOGRAPHIC) || !defined(LIGHT_POINT) \
    || !defined(LIGHT_SPOT) || !defined(LIGHT_DIRECTIONAL) || !defined(PHASE_ISOTROPIC) || !defined(PHASE_HG) \
    || !defined(INTEGRAND_TABLE) || !defined(INTEGRAND_SVD) || !defined(INTEGRAND_ANALYTIC) \
    || !defined(TRAVERSAL_TREE) || !defined(TRAVERSAL_SCAN) || !defined(DEPTH_EMPTY) \
    || !defined(SURFACE_SHADOWS_EXACT) || !defined(SURFACE_SHADOWS_MAP) || !defined(SURFACE_SHADOWS_PCF) \
    || !defined(SIN_BETA_MIN) || !defined(TEXTURE_WRAP_REPEAT) || !defined(TEXTURE_WRAP_CLAMP)
#error "the constants of clrays/structs.py are missing: build with clrays.device.build_options()"
#endif

/* On the line before a kernel that Intel's CPU compiler must run one work-item at a time.
 * Its implicit vectorizer (several work-items in the lanes of one vector) garbles the float3
 * that walk.h's row walk carries out of its loop: the radiance lands in other colour
 * channels and work-items (its 2026.2 release; docs/design.md §4.5, "Other CPU runtimes").
 * Other compilers do not know the attribute, and build these kernels as before. */
#ifdef cl_intel_vec_len_hint
#define NOT_ACROSS_WORK_ITEMS __attribute__((intel_vec_len_hint(1)))
#else
#define NOT_ACROSS_WORK_ITEMS
#endif

/* Barycentric slack of every camera-ray triangle test (Möller–Trumbore, edges inclusive):
 * float32 rounding, fused or not, can put a ray through an edge two triangles share outside
 * both; a relative 1e-5 overlap closes such cracks (the depth test, or a same-surface merge,
 * resolves the double hit). */
#define EDGE_SLACK 1e-5f

/* A pinhole or orthographic view: the camera, a spot light's map, a cube face,
 * a directional light's map. All positions are in eye space: world space
 * translated so the camera sits at the origin (keeps float32 precise far from
 * the world origin).
 *
 *   perspective:  ray(x, y) = origin + t·normalize(forward + sx·scale_x·right + sy·scale_y·up)
 *   orthographic: ray(x, y) = origin + sx·scale_x·right + sy·scale_y·up + t·forward
 *   with sx = 2(x + ox)/width - 1, sy = 1 - 2(y + oy)/height (y = 0 is the top row).
 *   depth = t: distance along the ray (perspective) or along forward (orthographic). */
typedef struct {
    float4 origin;
    float4 right;
    float4 up;
    float4 forward;
    float scale_x;  /* tan(half angle) or half extent, horizontal */
    float scale_y;  /* tan(half angle) or half extent, vertical */
    int width;
    int height;
    int projection; /* PROJECTION_* */
    int depth_offset; /* first texel of this view in its depth buffer */
    int cull_back_faces; /* 1: its origin is outside every closed solid (solids.h) */
    int _pad1;
} view_t;

/* One light. Its shadow map is view_count views (1, or 6 cube faces) starting at
 * views[first_view], stored in the shared shadow depth buffer. */
typedef struct {
    float4 position;  /* eye space (point, spot) */
    float4 direction; /* unit propagation direction (spot axis, directional) */
    float4 power;     /* intensity W/sr (point, spot) or irradiance (directional), rgb */
    int type;         /* LIGHT_* */
    float cos_cone;   /* spot: cos(half angle) */
    int first_view;
    int view_count;
    float texel_angle; /* perspective maps: angular size of a texel (rad); ortho: texel size */
    int _pad0;
    int _pad1;
    int _pad2;
} light_t;

/* Everything per frame that is not a buffer. */
typedef struct {
    float4 sigma_s;    /* scattering coefficient, rgb, 1/unit */
    float4 sigma_t;    /* extinction coefficient, rgb, 1/unit */
    float4 background; /* radiance of rays that hit nothing, rgb */
    float4 near_plane; /* the camera's unit view axis (xyz) and camera.near (w): lighting.h's camera_ray_start */
    float phase_g;     /* Henyey-Greenstein asymmetry */
    int phase_type;    /* PHASE_* */
    float far;         /* rays that hit nothing end here (camera.far, clamped: radiometry.effective_far) */
    int light_count;
    int width;
    int height;
    int spp;
    int steps;         /* raymarch samples per ray */
    int jitter;        /* raymarch: jitter sample positions */
    int pcf;           /* surface shadow filter radius, texels */
    float lamp_radius; /* radius of a point or spot light's medium-free ball (lighting.h) */
    int surface_shadows; /* SURFACE_SHADOWS_* */
} frame_t;

/* The epipolar frame of one light for one frame (docs/design.md §2, §3).
 *
 *            light l (or ω towards a directional light)
 *              *
 *             /|\        slice α: the half-plane through the eye-light line
 *        γ   / | \       that holds u·cos α + w·sin α;
 *           /  |  \      β: angle at the eye between a camera ray and axis;
 *          /   |   \     γ: angle at the light between a light ray and l → e
 *   eye e *----+----      (directional: distance from the eye's light line).
 *          axis a
 *
 * The rectified texture S[α, γ] holds, per light ray, the β of its blocker: a
 * point (β, γ) is lit iff β < S (S = π: unblocked; rectify writes π outside a spot
 * light's cone too, since traverse clips each ray to the cone itself). */
typedef struct {
    float4 axis;       /* a = (l - e)/|l - e|, or ω = -direction for directional lights */
    float4 u;          /* slice frame, u ⟂ axis */
    float4 w;          /* w = axis × u */
    float d_el;        /* eye-light distance (point, spot) */
    float alpha_min;   /* first slice's lower edge, rad */
    float alpha_step;  /* slice spacing, rad */
    int slices;
    float gamma_step;  /* γ_max / gamma_samples, the mean texel: rad (point, spot) or length (directional) */
    int gamma_samples; /* texels per row, a power of two */
    int levels;        /* log2(gamma_samples): the mip chain has levels + 1 levels */
    int light_index;
    int full_circle;   /* slices wrap around: the epipole or anti-epipole is on screen */
    float gamma_warp;  /* W of the γ texels' spacing (gamma_texels.h): 0 (even) for a directional light */
    int _pad1;
    int _pad2;
} epipolar_t;

/* The integrand tables of one light for one frame (docs/design.md §4, clrays/stages/integrand.py):
 * what turns a lit interval [γ0, γ1) of ray β into radiance. */
typedef struct {
    float4 amplitude; /* σs·I (point, spot) or σs·E (directional), rgb */
    float4 sigma_t;   /* extinction, rgb */
    float4 s_end;     /* directional rows: where a row ends in distance s, rgb */
    float beta_min;   /* β range of the table rows */
    float beta_max;
    float d_el;       /* eye-light distance (point, spot) */
    float g;          /* Henyey-Greenstein g (0: isotropic) */
    int mode;         /* INTEGRAND_* */
    int n_beta;
    int n_gamma;
    int rank;         /* svd terms */
    int light_type;   /* LIGHT_* */
    int grey;         /* table: one plane of unit amplitude, times amplitude per channel */
    int no_extent;    /* no visible ray has extent in γ: every ray's span is empty (integrand_rows) */
    int _pad2;
} integrand_t;

/* A light's texture (docs/light-textures.md; cl/light_texture.h looks it up): texels
 * width × height from texels[first_texel], row 0 on top. A light ray maps to screen
 * coordinates (sx, sy) ∈ [-1, 1]² over the image:
 *   spot:        w = p - position; (sx, sy) = (w·right, w·up)·(scale_x, scale_y)/(w·direction)
 *                scale = 1/tan(cone): the image fills the square around the cone
 *   directional: q = p - origin;   (sx, sy) = 2·(q·right, q·up)·(scale_x, scale_y)
 *                origin = the world origin in eye space, scale = 1/texture_size */
typedef struct {
    float4 right;
    float4 up;
    float4 origin;
    float scale_x;
    float scale_y;
    int first_texel;
    int width;
    int height;
    int wrap;     /* TEXTURE_WRAP_* */
    int textured; /* 0: a white light, nothing to look up */
    int _pad0;
} light_texture_t;

/* The low-rank integrand of a textured light in (β, γ) (docs/light-textures.md, minmax):
 * I(β, γ)·sinβ ≈ Σ_i B_i(β)·Γ_i(γ), B_i on n_beta sin²-spaced rows over [beta_min, beta_max]
 * (as integrand_t's), Γ_i on the gamma_samples cells of the min-max tree; each of the
 * slices rows stores prefix sums of T·Γ_i (cl/light_texture.cl). */
typedef struct {
    float beta_min;
    float beta_max;
    int n_beta;
    int rank;
    int gamma_samples;
    int slices;
    int textured;     /* 0: the light has no texture and traverse reads nothing here */
    int _pad0;
} textured_integrand_t;

/* A bounded or heterogeneous medium (docs/media.md; cl/medium.h reads it), in eye space.
 * Which parts are read is a build choice: MEDIUM_BOUNDED (the box), MEDIUM_HEIGHT (the
 * exponential height density), MEDIUM_GRID (a dense density grid, and the per-light
 * optical-depth grids of cl/light_depth.cl). The homogeneous medium builds none of them. */
typedef struct {
    float4 box_min;       /* MEDIUM_BOUNDED: the medium exists only inside [box_min, box_max] */
    float4 box_max;
    float4 grid_min;      /* MEDIUM_GRID: the grid's bounds; voxel (i, j, k) is centred at */
    float4 grid_max;      /*   grid_min + (i + ½, j + ½, k + ½)·(grid_max - grid_min)/(nx, ny, nz) */
    float height_base;    /* MEDIUM_HEIGHT: ρ = exp(-(y - height_base)/scale_height) */
    float scale_height;
    int grid_nx;          /* density voxels, x fastest: values[(k·ny + j)·nx + i] */
    int grid_ny;
    int grid_nz;
    int depth_nx;         /* optical-depth grid per light: nodes spanning the grid's bounds, */
    int depth_ny;         /*   light l's voxels start at l·depth_nx·depth_ny·depth_nz */
    int depth_nz;
    int eye_depth_index;  /* the eye's optical-depth grid follows the lights': at this index */
    int _pad0;
    int _pad1;
    int _pad2;
} medium_t;

#endif
