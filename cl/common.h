/* common.h — the one C definition of every struct shared by host and device.
 * clrays/structs.py mirrors each struct as a numpy dtype (same fields, same order);
 * tests/test_layout.py checks sizes and offsets against the device. */
#ifndef CLRAYS_COMMON_H
#define CLRAYS_COMMON_H

#define PROJECTION_PERSPECTIVE 0
#define PROJECTION_ORTHOGRAPHIC 1

#define LIGHT_POINT 0
#define LIGHT_SPOT 1
#define LIGHT_DIRECTIONAL 2

#define PHASE_ISOTROPIC 0
#define PHASE_HG 1

#define DEPTH_EMPTY 0x7f800000u /* as_uint(+INFINITY): nothing rasterized here */

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
    int _pad0;
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
    float phase_g;     /* Henyey-Greenstein asymmetry */
    int phase_type;    /* PHASE_* */
    float far;         /* rays that hit nothing end here */
    int light_count;
    int width;
    int height;
    int spp;
    int steps;         /* raymarch samples per ray */
    int jitter;        /* raymarch: jitter sample positions */
    int pcf;           /* surface shadow filter radius, texels */
    int _pad0;
    int _pad1;
} frame_t;

#endif
