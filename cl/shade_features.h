/* shade_features.h — what shade (shade.cl) may take besides the frame, the raster stage's
 * buffers, the in-scattering and the visibility: each group is built only where the frame
 * has it, and declares here, once, its kernel arguments (the host side is
 * clrays/stages/shade.py, `shade_features`).
 *
 *   LIGHT_TEXTURE_LOOKUP  every light's texture, looked up per surface point (light_texture.h,
 *                         docs/light-textures.md): where some light has one
 *   TRANSLUCENT_LAYERS    the translucency stage's layers (translucency.h), then its answer
 *                         per sample and light, given with exact surface shadows
 *   SHADE_TRANSPARENCY    the transparency stage's films composited before the camera
 *   SHADE_PASSES          the render passes' terms, written (clrays/passes.py)
 *   MEDIUM_VARYING        a bounded or heterogeneous medium (medium.h, docs/media.md): its
 *                         parameters, density grid and each light's optical-depth grid
 *
 * shade takes SHADE_FEATURE_ARGS after its own arguments, in this order. Without a group its
 * arguments are not there at all, and the kernel is the one it was without the feature. */
#ifndef CLRAYS_SHADE_FEATURES_H
#define CLRAYS_SHADE_FEATURES_H
#include "light_texture.h"
#include "medium.h"
#include "translucency.h"

#ifdef LIGHT_TEXTURE_LOOKUP
#define LIGHT_TEXTURE_LOOKUP_ARGS , global const light_texture_t* light_textures, global const float4* texels
#else
#define LIGHT_TEXTURE_LOOKUP_ARGS
#endif

/* The translucency_surface answer per sample and light, when given (exact surface shadows);
 * else the layers' own lookup. */
#ifdef TRANSLUCENT_LAYERS
#define SURFACE_THROUGH_ARGS , global const float4* surface_through, int has_surface_through
#else
#define SURFACE_THROUGH_ARGS
#endif

/* A scene with translucent objects builds shade with SHADE_TRANSPARENCY: the transparency stage's
 * T(D) and the light of the layers in front of each sample (docs/design.md, translucent surfaces:
 * the camera side) come as two more buffers. Opaque-only scenes build it without, and their
 * images are unchanged. */
#ifdef SHADE_TRANSPARENCY
#define TRANSPARENCY_ARGS , global const float4* transmittance, global const float4* in_front
#else
#define TRANSPARENCY_ARGS
#endif

/* Render passes (clrays/passes.py) build shade with SHADE_PASSES: per pixel, three float4 of
 * `passes` take the mean transmittance to the first surface (w: the nearest sample's depth, +inf
 * where none meets a surface), the mean attenuated surface radiance and the mean in-scattering.
 * A frame without passes builds shade without, and nothing of it is compiled. */
#ifdef SHADE_PASSES
#define PASSES_ARGS , global float4* passes
#else
#define PASSES_ARGS
#endif

#define SHADE_FEATURE_ARGS \
    LIGHT_TEXTURE_LOOKUP_ARGS TRANSLUCENCY_ARGS SURFACE_THROUGH_ARGS TRANSPARENCY_ARGS PASSES_ARGS MEDIUM_ARGS

#endif
