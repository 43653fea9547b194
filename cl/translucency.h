/* translucency.h — the light's transmittance through translucent surfaces at a point
 * (docs/design.md, "Translucent occluders: the light side"): the lookup into the layers
 * the translucency stage (cl/translucency.cl) keeps per shadow-map texel.
 *
 * Only a scene with translucent objects builds with TRANSLUCENT_LAYERS (the layer count
 * K); without it, TRANSLUCENCY_ARGS is empty and nothing here is compiled, so an
 * opaque-only scene runs the very same kernels as before.
 *
 * Layout, for a shadow atlas of `layer_stride` texels (views at their depth_offset):
 *
 *   layer_depth[k · layer_stride + texel]   float: depth of the k-th translucent surface
 *                                           from the light (+inf: none), ascending in k
 *   layer_clear[k · layer_stride + texel]   uint2: RGB transmittance past layers 0 … k,
 *                                           unorm16 (x = r | g << 16, y = b) */
#ifndef CLRAYS_TRANSLUCENCY_H
#define CLRAYS_TRANSLUCENCY_H
#include "gamma_texels.h"
#include "lighting.h"

#ifdef TRANSLUCENT_LAYERS

#define TRANSLUCENCY_ARGS , global const float* layer_depth, global const uint2* layer_clear, int layer_stride
#define TRANSLUCENCY_PASS , layer_depth, layer_clear, layer_stride

inline float3 unpack_clear(uint2 packed)
{
    return (float3)((float)(packed.x & 0xffffu), (float)(packed.x >> 16), (float)(packed.y & 0xffffu))
           * (1.0f / 65535.0f);
}

/* What reaches p of the light through the translucent layers nearer the light than p's
 * depth less `bias` texels (the same tolerance as shadow_visibility's); 1 off the map. */
inline float3 light_transmittance(global const light_t* light, global const view_t* views,
                                  global const float* layer_depth, global const uint2* layer_clear,
                                  int layer_stride, float3 p, float bias)
{
    global const view_t* view = views + light_view_index(light, p);
    float2 texel;
    float depth;
    if (!view_project(view, p, &texel, &depth)) return (float3)(1.0f);
    if (texel.x < 0.0f || texel.y < 0.0f || texel.x >= (float)view->width || texel.y >= (float)view->height)
        return (float3)(1.0f);
    float tolerance = bias * shadow_texel_size(light, depth);
    int index = view->depth_offset + (int)texel.y * view->width + (int)texel.x;
    float3 through = (float3)(1.0f);
    for (int k = 0; k < TRANSLUCENT_LAYERS; ++k) {
        if (!(layer_depth[k * layer_stride + index] + tolerance < depth)) break;
        through = unpack_clear(layer_clear[k * layer_stride + index]);
    }
    return through;
}

#else
#define TRANSLUCENCY_ARGS
#define TRANSLUCENCY_PASS
#endif

#endif
