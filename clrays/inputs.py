"""Per-frame device inputs: the scene moved into eye space and packed into the
structs of `cl/common.h` (views, lights, frame parameters) and triangle buffers.

Eye space is world space translated so the camera sits at the origin (no rotation).
The subtraction happens in float64 on the host, so float32 on the device keeps its
precision however far the scene is from the world origin.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from . import structs
from .scene.camera import camera_basis, sample_offsets
from .device import Device
from .errors import ClraysError
from .physics.radiometry import effective_far, lamp_radius
from .scene.costs import SPOT_SINGLE_VIEW_MAX_DEG, with_derived_sizes
from .scene.light_views import directional_map, up_hint
from .stages.cube_faces import sampled_cube_faces
from .stages.light_texture import pack_light_textures
from .scene.relief_frame import relief_faces
from .stages.relief import carries_relief_triangles, place_reliefs
from .scene.model import DirectionalLight, Scene, SpotLight

#: All lights' shadow maps share one depth buffer, indexed by an int offset per view.
MAX_SHADOW_TEXELS = 2**31 - 1
#: Light-anchored vertex sets a geometry keeps (light_pass_inputs): a few static lights' own.
ANCHORED_KEPT = 4

#: Cube faces in the order `light_view_index` expects: +x, -x, +y, -y, +z, -z, with an up vector each.
_CUBE_FACES = [
    ((1, 0, 0), (0, 1, 0)), ((-1, 0, 0), (0, 1, 0)),
    ((0, 1, 0), (0, 0, 1)), ((0, -1, 0), (0, 0, 1)),
    ((0, 0, 1), (0, 1, 0)), ((0, 0, -1), (0, 1, 0)),
]


def _view(origin, forward, up, scale_x, scale_y, width, height, projection, depth_offset) -> np.ndarray:
    forward = np.asarray(forward, float) / np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    v = np.zeros((), dtype=structs.view_dtype)
    v["origin"] = structs.float4(origin)
    v["right"], v["up"], v["forward"] = structs.float4(right), structs.float4(true_up), structs.float4(forward)
    v["scale_x"], v["scale_y"] = scale_x, scale_y
    v["width"], v["height"] = width, height
    v["projection"] = projection
    v["depth_offset"] = depth_offset
    return v


def without_walled_off_light(scene: Scene) -> Scene:
    """`scene` with the power of every light that `walled_off` separates from the eye set to
    0, which is exact: no texel-sized gap of a shadow map lets it through then."""
    if not scene.lights or not scene.geometry.outward.any():
        return scene
    eye_windings = scene.geometry.solid_windings(scene.camera.position)
    if not (np.abs(eye_windings) > 0.75).any() and all(isinstance(light, DirectionalLight) for light in scene.lights):
        return scene
    walled = [walled_off(scene.geometry, eye_windings, light) for light in scene.lights]
    if not any(walled):
        return scene
    return replace(scene, lights=tuple(_dark(light) if dark else light for light, dark in zip(scene.lights, walled)))


def _dark(light):
    field = "irradiance" if isinstance(light, DirectionalLight) else "intensity"
    return replace(light, **{field: np.zeros(3)})


def walled_off(geometry, eye_windings: np.ndarray, light) -> bool:
    """Whether a closed opaque solid holds the eye and not the light, or the light and not
    the eye. Then every point the camera sees, on the eye's side of the solid's walls, is cut
    off from the light: its in-scattering and direct light are 0, as `exact` finds them.
    The shadow maps alone would let a layer about a texel thick behind each wall count as
    lit (docs/stability.md, "Closed geometry"). Clearly inside is a winding number of
    magnitude above 3/4, clearly outside below 1/4; a point on a wall decides nothing."""
    if not len(eye_windings):
        return False
    light_windings = (np.zeros_like(eye_windings) if isinstance(light, DirectionalLight)
                      else geometry.solid_windings(light.position))
    inside = lambda windings: np.abs(windings) > 0.75
    outside = lambda windings: np.abs(windings) < 0.25
    return bool(np.any((inside(eye_windings) & outside(light_windings))
                       | (outside(eye_windings) & inside(light_windings))))


@dataclass
class FrameInputs:
    """Host-side arrays for one frame, ready to upload."""

    scene: Scene
    eye_ws: np.ndarray  # camera position, world space (float64)
    views: np.ndarray  # view_t[]: views[0] is the camera, then every shadow-map view
    lights: np.ndarray  # light_t[]
    params: np.ndarray  # frame_t
    offsets: np.ndarray  # (spp, 2) float32 sample offsets
    tri_vertices: np.ndarray  # (3T, 4) float32, eye space (a pre-warped relief's only where carries_relief_triangles)
    tri_normal: np.ndarray  # (T, 4) float32, unit geometric normals; w = 1 where the triangle is shaded smooth
    tri_vertex_normals: np.ndarray  # (3T, 4) float32, the shading normal at each vertex; (0, 4) when none is smooth
    tri_albedo: np.ndarray  # (T, 4) float32
    shadow_texels: int  # size of the shared shadow depth buffer
    light_anchor_ws: np.ndarray  # (L, 3) float64: each light's shadow-map origin, world space
    # (V,) bool per view: whether the frame can read it; raster skips the others (the cube
    # faces that the camera's view misses, clrays.stages.cube_faces)
    view_needed: np.ndarray = None
    light_textures: np.ndarray = None  # light_texture_t[] per light (clrays.stages.light_texture)
    texels: np.ndarray = None  # (N, 4) float32: every light's texture texels
    # Relief objects drawn by their pre-warp (clrays.stages.relief): their triangles come
    # last, and the raster stage draws only the first `raster_triangles` (None: all).
    reliefs: tuple = ()
    raster_triangles: int | None = None

    @property
    def light_views(self) -> list[tuple[int, int]]:
        """(first view, view count) of each light."""
        return [(int(entry["first_view"]), int(entry["view_count"])) for entry in self.lights[:len(self.scene.lights)]]

    @property
    def samples(self) -> int:
        return self.scene.image.width * self.scene.image.height * self.scene.image.spp


def padded_float32(rows: np.ndarray) -> np.ndarray:
    """(n, 3) rows as the device's float4: cast to float32 into a zeroed (n, 4) array, with
    no float64 copy between (a 75 k-triangle mesh's vertices are 225 k rows a frame)."""
    out = np.zeros((len(rows), 4), dtype=np.float32)
    out[:, :3] = rows
    return out


def vertex_rows(triangles: np.ndarray, geometry, count: int) -> np.ndarray:
    """The first `count` of (T, 3, 3) triangles as the device's 3T float4 rows; in w, what
    the kernels know of each triangle besides its corners: in its first row its
    `Geometry.outward` sign (cl/solids.h), in its second the bits of its int
    `Geometry.convex_part` label (the writer map's, cl/visibility.h), in its third 0."""
    rows = padded_float32(triangles[:count].reshape(-1, 3))
    rows[0::3, 3] = geometry.outward[:count]
    rows.view(np.int32)[1::3, 3] = geometry.convex_part[:count]
    return rows


def _read_only(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def face_rows(geometry, drawn: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The float4 rows of the first `drawn` triangles that no eye moves, kept on the
    geometry (a scanned mesh's cost milliseconds a frame): unit face normals, w = 1 where
    the triangle is shaded smooth; albedo; the shading normal at each vertex, (0, 4) when
    no triangle is smooth. Normals do not move with eye space's translation."""
    def rows():
        tris = geometry.triangles[:drawn]
        normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
        smooth = geometry.smooth[:drawn]  # a relief is flat
        tri_normal = padded_float32(normals)
        tri_normal[:, 3] = smooth  # the shade kernel's flag: interpolate the vertex normals
        vertex_normals = geometry.normals[:drawn].reshape(-1, 3) if smooth.any() else np.zeros((0, 3))
        return (_read_only(tri_normal), _read_only(padded_float32(geometry.albedo[:drawn])),
                _read_only(padded_float32(vertex_normals)))
    return geometry.kept(("face rows", drawn), rows)


def frame_inputs(scene: Scene) -> FrameInputs:
    """Pack a scene into the device structs, in eye space; sizes the scene leaves unset
    are derived from its image first (`inputs.scene` holds them)."""
    scene = with_derived_sizes(scene)
    scene, reliefs, raster_triangles = place_reliefs(scene)  # reliefs' triangles last, for the pre-warp
    eye_ws = np.asarray(scene.camera.position, dtype=np.float64)
    image, camera, medium = scene.image, scene.camera, scene.medium
    # A relief drawn by its pre-warp needs no vertices on the device (relief.cl builds its
    # cells from the texels), only its faces' normals and albedo, kept with it; only the
    # exact and filtered surface shadows read its vertices (docs/design.md, "What a frame carries").
    drawn = scene.geometry.count if raster_triangles is None else raster_triangles
    carried = scene.geometry.count if carries_relief_triangles(scene) else drawn
    tris = scene.geometry.triangles[:carried] - eye_ws  # float64 translation, then float32
    lo, hi = scene.geometry.bounds()  # world space: the directional maps must not depend on the eye

    right, up, forward = camera_basis(camera)
    tan_half = math.tan(math.radians(camera.fov_deg) / 2)
    views = [_view(np.zeros(3), forward, up, tan_half * image.width / image.height, tan_half,
                   image.width, image.height, structs.PROJECTION_PERSPECTIVE, 0)]
    # A view may skip the faces the closed solids turn away from it where its rays start
    # outside all of them (cl/solids.h): a directional light's start outside the scene's box.
    views[0]["cull_back_faces"] = not scene.geometry.inside_a_solid(eye_ws)
    lights, anchors = [], []
    needed = [True]  # the camera view, then one flag per shadow-map view
    n = scene.render.shadow_map
    texels = 0
    for index, light in enumerate(scene.lights):
        if texels + 6 * n * n > MAX_SHADOW_TEXELS:  # a light takes at most a cube: 6 views
            where = f"{scene.source}: " if scene.source else ""
            raise ClraysError(f"{where}the shadow maps of lights 0 to {index} at render.shadow_map {n} need more than "
                              f"{MAX_SHADOW_TEXELS} texels, the most a view's int depth_offset (cl/common.h) "
                              f"addresses; lower render.shadow_map or the light count")
        entry = np.zeros((), dtype=structs.light_dtype)
        entry["first_view"] = len(views)
        if isinstance(light, DirectionalLight):
            entry["type"] = structs.LIGHT_DIRECTIONAL
            entry["direction"] = structs.float4(light.direction)
            entry["power"] = structs.float4(light.irradiance)
            # Orthographic, over the scene box's outline across the light (scene/light_views.py).
            fitted = directional_map(lo, hi, light.direction)
            anchors.append(fitted.anchor)
            needed.append(True)
            views.append(_view(anchors[-1] - eye_ws, light.direction, fitted.up, fitted.half_width,
                               fitted.half_height, n, n, structs.PROJECTION_ORTHOGRAPHIC, texels))
            entry["texel_angle"] = fitted.texel_side / n  # the longer side of its texels: the bias's scale
            texels += n * n
        else:
            anchors.append(np.asarray(light.position, dtype=np.float64))
            position = light.position - eye_ws
            entry["position"] = structs.float4(position)
            entry["power"] = structs.float4(light.intensity)
            if isinstance(light, SpotLight):
                entry["type"] = structs.LIGHT_SPOT
                entry["direction"] = structs.float4(light.direction)
                entry["cos_cone"] = math.cos(math.radians(light.cone_deg))
            else:
                entry["type"] = structs.LIGHT_POINT
            if isinstance(light, SpotLight) and light.cone_deg <= SPOT_SINGLE_VIEW_MAX_DEG:
                scale = math.tan(math.radians(light.cone_deg))
                needed.append(True)
                views.append(_view(position, light.direction, up_hint(light.direction), scale, scale,
                                   n, n, structs.PROJECTION_PERSPECTIVE, texels))
                entry["texel_angle"] = 2 * scale / n
                texels += n * n
            else:
                needed += sampled_cube_faces(scene, light.position, scene.render.slices)
                for face_forward, face_up in _CUBE_FACES:
                    views.append(_view(position, face_forward, face_up, 1.0, 1.0, n, n,
                                       structs.PROJECTION_PERSPECTIVE, texels))
                    texels += n * n
                entry["texel_angle"] = 2.0 / n
        entry["view_count"] = len(views) - entry["first_view"]
        outside = isinstance(light, DirectionalLight) or not scene.geometry.inside_a_solid(light.position)
        for view in views[entry["first_view"]:]:
            view["cull_back_faces"] = outside
        lights.append(entry)

    params = np.zeros((), dtype=structs.frame_dtype)
    params["sigma_s"] = structs.float4(medium.sigma_s)
    params["sigma_t"] = structs.float4(medium.sigma_t)
    params["background"] = structs.float4(scene.background)
    params["phase_g"] = medium.phase.g
    params["phase_type"] = structs.PHASE_HG if medium.phase.type == "hg" else structs.PHASE_ISOTROPIC
    params["far"] = effective_far(scene)  # camera.far, clamped where it changes nothing
    params["lamp_radius"] = lamp_radius(scene)  # from the scene's size, not far (docs/design.md §1)
    params["light_count"] = len(lights)
    params["width"], params["height"], params["spp"] = image.width, image.height, image.spp
    params["steps"] = scene.render.steps
    params["jitter"] = int(scene.render.jitter)
    params["surface_shadows"] = {"exact": structs.SURFACE_SHADOWS_EXACT, "map": structs.SURFACE_SHADOWS_MAP,
                                 "pcf": structs.SURFACE_SHADOWS_PCF,
                                 "filtered": structs.SURFACE_SHADOWS_FILTERED}[scene.render.surface_shadows]
    params["pcf"] = scene.render.pcf if scene.render.surface_shadows == "pcf" else 0

    tri_normal, tri_albedo, vertex_normals = face_rows(scene.geometry, drawn)
    if drawn < scene.geometry.count:  # the reliefs' faces, after the others (place_reliefs)
        faces = [relief_faces(record, scene.geometry) for record in scene.geometry.reliefs]
        tri_normal = np.concatenate([tri_normal] + [normal for normal, _ in faces])
        tri_albedo = np.concatenate([tri_albedo] + [albedo for _, albedo in faces])
    # A frame without smooth triangles uploads no vertex normals, and shade reads them for
    # smooth triangles only, none of which is a relief's.
    return FrameInputs(
        scene=scene, eye_ws=eye_ws,
        views=np.array(views, dtype=structs.view_dtype),
        lights=np.array(lights, dtype=structs.light_dtype) if lights else np.zeros(1, structs.light_dtype),
        params=params,
        offsets=sample_offsets(image.spp).astype(np.float32),
        tri_vertices=vertex_rows(tris, scene.geometry, carried),
        tri_normal=tri_normal,
        tri_vertex_normals=vertex_normals,
        tri_albedo=tri_albedo,
        shadow_texels=texels,
        light_anchor_ws=np.array(anchors, dtype=np.float64).reshape(-1, 3),
        view_needed=np.array(needed, dtype=bool),
        **dict(zip(("light_textures", "texels"), pack_light_textures(scene, eye_ws))),
        reliefs=reliefs,
        raster_triangles=raster_triangles,
    )


@dataclass
class FrameBuffers:
    """The frame inputs on the device; stage outputs are added by the stages."""

    inputs: FrameInputs
    views: object
    lights: object
    params: object
    offsets: object
    tri_vertices: object
    tri_normal: object
    tri_vertex_normals: object
    tri_albedo: object
    light_textures: object = None
    texels: object = None
    medium: object = None  # a bounded or heterogeneous medium's kernel feature (clrays.stages.medium)


def upload(device: Device, inputs: FrameInputs) -> FrameBuffers:
    return FrameBuffers(
        inputs=inputs,
        views=device.buffer(inputs.views, writable=False),
        lights=device.buffer(inputs.lights, writable=False),
        params=device.buffer(inputs.params.reshape(1), writable=False),
        offsets=device.buffer(inputs.offsets, writable=False),
        tri_vertices=device.buffer(inputs.tri_vertices, writable=False),
        tri_normal=device.buffer(inputs.tri_normal, writable=False),
        tri_vertex_normals=device.buffer(inputs.tri_vertex_normals, writable=False),
        tri_albedo=device.buffer(inputs.tri_albedo, writable=False),
        light_textures=device.buffer(inputs.light_textures, writable=False),
        texels=device.buffer(inputs.texels, writable=False),
    )


def light_pass_inputs(inputs: FrameInputs, light_index: int, triangles: int | None = None) -> FrameInputs:
    """The inputs of one light's shadow-map pass, anchored at the light.

    Vertices and the light's views are translated (float64, on the host) so the map's
    origin sits at zero: the map's depths are distances from that origin whatever the
    eye space, so they depend only on the geometry and the light. That is what lets a
    render session keep a static light's map while the camera moves (docs/design.md §7). The
    camera view stays in views[0]; the light's views follow from views[1], with depth
    offsets from 0, and `shadow_texels` counts this light's texels only. `triangles`: how
    many of the frame's triangles the pass reads (None: all it carries). Kept on `inputs`
    per light and count: the raster and visibility stages both ask, and translating a
    scanned mesh costs milliseconds (the result is not to be changed).
    """
    carried = len(inputs.tri_vertices) // 3
    key = (light_index, carried if triangles is None else triangles)
    passes = inputs.__dict__.setdefault("_light_passes", {})  # not a field: `replace` starts afresh
    if key not in passes:
        passes[key] = _light_pass_inputs(inputs, light_index, key[1])
    return passes[key]


def _light_pass_inputs(inputs: FrameInputs, light_index: int, triangles: int) -> FrameInputs:
    first, count = inputs.light_views[light_index]
    anchor = inputs.light_anchor_ws[light_index]
    views = inputs.views[first:first + count].copy()
    views["origin"] = 0.0
    views["depth_offset"] -= views["depth_offset"][0]
    texels = int(sum(int(v["width"]) * int(v["height"]) for v in views))
    light = inputs.lights[light_index:light_index + 1].copy()
    light["first_view"] = 1
    if light["type"][0] != structs.LIGHT_DIRECTIONAL:
        light["position"] = 0.0
    geometry = inputs.scene.geometry
    # the vertices around the light: no eye moves them, so a static light's are kept
    anchored = lambda: _read_only(vertex_rows(geometry.triangles[:triangles] - anchor, geometry, triangles))
    vertices = geometry.kept(("anchored", triangles, anchor.tobytes()), anchored, most=ANCHORED_KEPT)
    return replace(
        inputs,
        views=np.concatenate([inputs.views[:1], views]),
        view_needed=np.concatenate([[True], inputs.view_needed[first:first + count]]),
        lights=light,
        tri_vertices=vertices,
        shadow_texels=texels,
        light_anchor_ws=anchor.reshape(1, 3),
    )


def see_through(geometry) -> np.ndarray:
    """(T,) bool: the triangles that let some light through (any channel of opacity < 1)."""
    return np.any(geometry.opacity_or_ones() < 1.0, axis=1)


def opaque_occluders(inputs: FrameInputs) -> FrameInputs:
    """`inputs` with every translucent triangle collapsed onto its first vertex: a triangle
    of no area, which no ray meets, so the shadow maps, bound maps and the BVH see the
    opaque occluders only while every triangle keeps its index. Unchanged for an
    opaque-only scene."""
    geometry = inputs.scene.geometry
    if not geometry.translucent:
        return inputs
    clear = see_through(geometry)
    triangles = geometry.triangles.copy()
    triangles[clear] = triangles[clear][:, :1]
    vertices = inputs.tri_vertices.reshape(-1, 3, 4).copy()
    carried = clear[:len(vertices)]  # a relief's rows, listed last, may not be carried (clrays.scene.relief_frame)
    vertices[carried] = vertices[carried][:, :1]
    scene = replace(inputs.scene, geometry=replace(geometry, triangles=triangles))
    return replace(inputs, scene=scene, tri_vertices=vertices.reshape(-1, 4))
