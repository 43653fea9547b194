"""Stage translucency: per light, the translucent surfaces nearest the light in every
shadow-map texel, with the light's transmittance past each (docs/design.md,
"Translucent occluders: the light side"). Host side of `cl/translucency.cl`; the
lookup is `cl/translucency.h`.

A scene with translucent objects (`Geometry.translucent`) splits its occluders: the
opaque triangles alone make the shadow maps, the visibility stage's bound maps and BVH
(`opaque_occluders`), so their binary visibility is as before, and the translucent ones
make `render.translucent_layers` (K) layers per texel, by depth peeling from the light: K
raster passes over the translucent triangles, each keeping the nearest depth beyond the
previous layer. Layer k stores its depth and the RGB product of (1 − α) of layers 0 … k.
A point of the medium or of a surface then receives the light times its shadow-map
visibility times the transmittance of the last layer nearer the light than itself.

An opaque-only scene never runs this stage, and builds no kernel with the lookup
(`TRANSLUCENT_LAYERS` undefined), so its images are those of a renderer without it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .. import structs
from ..buffers import BufferDecl
from ..device import Device, StageTimer
from ..errors import ClraysError
from ..inputs import FrameBuffers, FrameInputs, frame_sizes, light_pass_inputs, opaque_occluders, see_through
from .raster import raster_passes


#: Every light's layers in the shadow atlas's layout: K per texel, their depths and transmittance
#: (cl/translucency.h).
LAYER_DEPTH = BufferDecl("translucent layers' depths", 4, lambda sizes: sizes.layers * max(sizes.shadow_texels, 1))
LAYER_CLEAR = BufferDecl("translucent layers' transmittance", 8,
                         lambda sizes: sizes.layers * max(sizes.shadow_texels, 1))
#: One light's layers rectified: K per texel of its epipolar texture (cl/translucent_walk.h).
RECTIFIED_BETA = BufferDecl("rectified translucent layers", 4,
                            lambda sizes: sizes.slices * sizes.tree_gamma * sizes.layers)
RECTIFIED_CLEAR = BufferDecl("rectified translucent layers' transmittance", 8,
                             lambda sizes: sizes.slices * sizes.tree_gamma * sizes.layers)
#: With exact surface shadows: what reaches each camera sample's surface of each light (float4).
SURFACE_THROUGH = BufferDecl("surface transmittance", 16, lambda sizes: sizes.entries)


@dataclass
class Layers:
    """Every light's translucent layers, in the shadow atlas's layout (cl/translucency.h)."""

    depth: object  # float[count · stride]
    clear: object  # uint2[count · stride]
    count: int  # K, layers per texel
    stride: int  # texels of the shadow atlas: layer k starts at k · stride

    def defines(self) -> dict:
        """The -D options of a kernel that looks the layers up."""
        return {"TRANSLUCENT_LAYERS": self.count}

    def args(self) -> tuple:
        """The kernel arguments of TRANSLUCENCY_ARGS, appended after a kernel's own."""
        return self.depth, self.clear, np.int32(self.stride)


def opaque_occluder_buffers(device: Device, buffers: FrameBuffers) -> FrameBuffers:
    """`buffers` whose triangles are `opaque_occluders`'s (the visibility stage's BVH and
    shadow rays); `buffers` itself for an opaque-only scene."""
    if not buffers.inputs.scene.geometry.translucent:
        return buffers
    inputs = opaque_occluders(buffers.inputs)
    return replace(buffers, inputs=inputs, tri_vertices=device.buffer(inputs.tri_vertices, writable=False))


def refuse_translucency(scene, method: str) -> None:
    """A one-line error for what cannot show translucent objects: the `volume_moments` method and
    relief objects drawn by their pre-warp on the device."""
    geometry = scene.geometry
    if not geometry.translucent:
        return
    clear = see_through(geometry)
    first = int(geometry.object_id[np.flatnonzero(clear)[0]])
    where = f"{scene.source}: " if scene.source else ""
    if method == "volume_moments":
        raise ClraysError(f"{where}render.method: volume_moments does not support translucent objects "
                          f"(objects.{first}.opacity); use minmax, raymarch or exact")
    for record in geometry.reliefs if scene.render.relief == "prewarp" else ():
        if clear[record.rows].any():
            index = int(geometry.object_id[record.rows.start])
            raise ClraysError(f"{where}objects.{index}.opacity: a relief object is opaque on the device "
                              f"(render.relief: prewarp draws its depth image); use opacity 1, "
                              f"render.relief: triangles, or method exact")


def _translucent_pass_inputs(inputs: FrameInputs, light_index: int) -> tuple[FrameInputs, np.ndarray]:
    """One light's pass over the translucent triangles only (anchored at the light, as its
    shadow map), and their (1 − α) as float4 rows."""
    light_inputs = light_pass_inputs(inputs, light_index)
    geometry = inputs.scene.geometry
    drawn = geometry.count if inputs.raster_triangles is None else inputs.raster_triangles
    rows = np.flatnonzero(see_through(geometry)[:drawn])
    vertices = light_inputs.tri_vertices.reshape(-1, 3, 4)[rows].reshape(-1, 4)
    clear = np.zeros((len(rows), 4), np.float32)
    clear[:, :3] = 1.0 - geometry.opacity_or_ones()[rows]
    return replace(light_inputs, tri_vertices=np.ascontiguousarray(vertices), raster_triangles=None), clear


def _launch(device: Device, name: str, defines: dict, vertices, count: int, views, view_index: int,
            view_size: tuple[int, int], target: tuple, timer: StageTimer) -> None:
    """Both passes of one raster kernel (clrays.stages.raster.raster_passes), built in the
    translucency program, over the translucent triangles: one sample per texel, at its centre."""
    centre = device.buffer(np.array([[0.5, 0.5]], dtype=np.float32), writable=False)
    raster_passes(device, "translucency", name, defines, vertices, count, views, [view_index], [view_size], centre,
                  1, target, timer, stage="translucency")


def translucency(device: Device, buffers: FrameBuffers, timer: StageTimer) -> Layers:
    """The layers of every light (module docstring), K = `render.translucent_layers`.
    Peeling stops at the first layer that is empty everywhere in a light's map."""
    inputs = buffers.inputs
    count = inputs.scene.render.translucent_layers
    # one build of cl/translucency.cl for its kernels (on a GPU its raster passes add
    # RASTER_BIG_SAMPLES, clrays.stages.raster.raster_defines: a second build)
    defines = {"TRANSLUCENT_LAYERS": count}
    stride, sizes = max(inputs.shadow_texels, 1), frame_sizes(inputs)
    layer_depth, layer_clear = LAYER_DEPTH.allocate(device, sizes), LAYER_CLEAR.allocate(device, sizes)
    # A layer's transmittance is read only where its depth is finite: no need to clear it.
    device.fill(layer_depth, structs.DEPTH_EMPTY, 4 * count * stride, timer, "translucency")
    for light_index in range(len(inputs.scene.lights)):
        light_inputs, clear = _translucent_pass_inputs(inputs, light_index)
        triangles = len(clear)
        if triangles == 0:
            continue
        texels = max(light_inputs.shadow_texels, 1)
        offset = int(inputs.views[inputs.light_views[light_index][0]]["depth_offset"])
        vertices = device.buffer(light_inputs.tri_vertices, writable=False)
        views = device.buffer(light_inputs.views, writable=False)
        triangle_clear = device.buffer(clear, writable=False)
        previous = device.buffer(nbytes=4 * texels)
        device.fill(previous, np.uint32(0), 4 * texels, timer, "translucency")
        previous_clear = device.buffer(nbytes=8 * texels)
        for layer in range(count):
            depth = device.buffer(nbytes=4 * texels)
            tri = device.buffer(nbytes=4 * texels)
            device.fill(depth, structs.DEPTH_EMPTY, 4 * texels, timer, "translucency")
            device.fill(tri, np.int32(-1), 4 * texels, timer, "translucency")
            for view in np.flatnonzero(light_inputs.view_needed[1:]) + 1:
                size = int(light_inputs.views[view]["height"]), int(light_inputs.views[view]["width"])
                _launch(device, "translucency_peel", defines, vertices, triangles, views, int(view), size,
                        (depth, previous), timer)
                _launch(device, "raster_resolve", defines, vertices, triangles, views, int(view), size, (depth, tri),
                        timer)
            flag = device.buffer(np.zeros(1, np.uint32))
            device.kernel("translucency", "raster_any", defines)(
                device.queue, (-(-texels // structs.RASTER_ANY_TEXELS),), None, depth, np.int32(texels), flag)
            if not device.read(flag, 1, np.uint32)[0]:
                break  # no texel has this many layers: the rest stay empty
            packed_depth = device.buffer(nbytes=4 * texels)
            packed_clear = device.buffer(nbytes=8 * texels)
            timer.add("translucency", device.kernel("translucency", "translucency_pack", defines)(
                device.queue, (texels,), None, depth, tri, np.int32(texels), triangle_clear, np.int32(layer),
                previous_clear, packed_depth, packed_clear))
            at = layer * stride + offset
            device.cl.enqueue_copy(device.queue, layer_depth, packed_depth, byte_count=4 * texels, dst_offset=4 * at)
            device.cl.enqueue_copy(device.queue, layer_clear, packed_clear, byte_count=8 * texels, dst_offset=8 * at)
            previous, previous_clear = depth, packed_clear
    return Layers(layer_depth, layer_clear, count, stride)


@dataclass
class RectifiedLayers:
    """One light's layers in its epipolar texture (cl/translucent_walk.h reads them)."""

    beta: object  # float[slices][gamma_samples][K]: β of each layer on the texel's light ray, π for none
    clear: object  # uint2[slices][gamma_samples][K]: transmittance past it, as Layers.clear
    rows: object  # int[slices]: 1 where some texel of the slice has a layer
    count: int

    def defines(self) -> dict:
        return {"TRANSLUCENT_LAYERS": self.count}

    def args(self) -> tuple:
        """The kernel arguments of RECTIFIED_LAYER_ARGS."""
        return self.beta, self.clear, self.rows


def rectify_layers(device: Device, buffers: FrameBuffers, layers: Layers, epipolar, timer: StageTimer
                   ) -> RectifiedLayers:
    """The layers of the light of `epipolar` (stage rectify's), resampled at the texels of
    its rectified texture (timed with the translucency stage)."""
    slices, n = int(epipolar.params["slices"]), int(epipolar.params["gamma_samples"])
    sizes = frame_sizes(buffers.inputs)  # (slices, n: the scene's; layers.count: its render.translucent_layers)
    beta, clear = RECTIFIED_BETA.allocate(device, sizes), RECTIFIED_CLEAR.allocate(device, sizes)
    rows = device.buffer(np.zeros(slices, np.int32))
    timer.add("translucency", device.kernel("translucency", "translucency_rectify", layers.defines())(
        device.queue, (n, slices), None, buffers.views, buffers.lights, layers.depth, layers.clear,
        np.int32(layers.stride), epipolar.buffer, beta, clear, rows))
    return RectifiedLayers(beta, clear, rows, layers.count)


def surface_transmittance(device: Device, buffers: FrameBuffers, rastered, layers: Layers, timer: StageTimer):
    """float4[samples × lights]: what reaches each camera sample's surface of each light
    through the translucent surfaces (cl/translucency.cl, translucency_surface): the layers
    where they agree around the sample, else a shadow ray through the translucent
    triangles' BVH, so the edges of a coloured shadow land where `exact` puts them."""
    from ..bvh import build_bvh

    inputs = buffers.inputs
    geometry = inputs.scene.geometry
    drawn = geometry.count if inputs.raster_triangles is None else inputs.raster_triangles
    rows = np.flatnonzero(see_through(geometry)[:drawn])
    vertices = np.ascontiguousarray(inputs.tri_vertices.reshape(-1, 3, 4)[rows].reshape(-1, 4))
    clear = np.zeros((len(rows), 4), np.float32)
    clear[:, :3] = 1.0 - geometry.opacity_or_ones()[rows]
    bvh = build_bvh(vertices[:, :3].reshape(-1, 3, 3))
    out = SURFACE_THROUGH.allocate(device, frame_sizes(inputs))
    timer.add("translucency", device.kernel("translucency", "translucency_surface", layers.defines())(
        device.queue, (inputs.samples,), None, buffers.params, buffers.views, buffers.lights, rastered.camera_depth,
        rastered.tri_id, buffers.tri_normal, buffers.offsets, device.buffer(vertices, writable=False),
        device.buffer(clear, writable=False), device.buffer(bvh.node_bounds, writable=False),
        device.buffer(bvh.node_children, writable=False), np.int32(bvh.root), out, *layers.args()))
    return out
