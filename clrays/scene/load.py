"""Load and validate a YAML scene file (format version 1) into a `clrays.scene.model.Scene`.

    scene = load_scene("scenes/demo.yaml", overrides=["render.steps=1024"])

The YAML becomes a tree of nodes that remember where each value was written, with the
`--set` overrides spliced in (`clrays.scene.yaml_tree`); each section is then read
against its keys in `clrays.scene.fields` (types, defaults, ranges, choices) into the
frozen dataclasses. Any problem raises `SceneError` with one line, like a compiler:

    scenes/x.yaml:14:9: lights.0.cone_deg: expected a number in (0, 90], got 120
    --set render.steps=abc: render.steps: expected an integer in [1, 65536], got 'abc'

A glTF file (.glb, .gltf) is read as the scene `{version: 1, image: ..., gltf: {file: ...}}`
(clrays.scene.gltf), so the same overrides reach it. The full format is documented in
docs/scene-format.md.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from . import geometry as primitives
from . import gltf as gltf_files
from . import relief as relief_images
from ..errors import SceneError
from ..exposure import parse_exposure
from ..passes import pass_problem
from ..structs import CONVEX_OUTSIDE_ONLY
from . import density_sources
from .animation import Animation, DensityDrift, Key, ObjectRig, Track
from .files import FileRefused, read_regular_file, scene_files
from .fields import (ANIMATION, BOX, VOLUME_OBJECT, CAMERA, DENSITIES, FORMAT_VERSION, GLTF, IMAGE, LIGHTS, MAX_IMAGE_PIXELS,
                     MAX_POWER, MEDIUM, OBJECT, OBJECTS, PHASES, QUATERNION_TOLERANCE, RENDER, ROTATE, SHADOW_FILTER,
                     TOP, TRANSFORM, TRANSPARENCY, Field, kinds)
from .limits import MAX_COORDINATE, MAX_LIGHTS, MAX_OBJECTS, MAX_SCENE_BYTES, MAX_TRIANGLES
from .model import (Box, Camera, Density, DirectionalLight, Geometry, HeightDensity, Image, Light, LightTexture,
                    Medium, Phase, PointLight, Render, Scene, ShadowFilter, SpotLight, Transparency)
from .textures import TextureCache, TextureError
from .transforms import (affine, matrix_to_quat, quat_to_matrix, rotation_axis_angle, rotation_euler,
                         transform_normals, transform_points)
from .yaml_tree import (Node, apply_override, boolean, choice, compose, direction, integer, mapping, mark_where,
                        number, numbers, rgb, sequence, show, typed, vec3)

PARALLEL_TOLERANCE = 1e-6  # |sin| of the angle between camera up and the view direction

#: The most raymarch steps a scene may ask for; `clrays.runs.sweep` checks `--reference raymarch:N` against it.
MAX_STEPS = RENDER["steps"].high


def _read(field: Field, node: Node | None) -> Any:
    """A scalar key checked against its field's type, range and choices; the field's
    default when the key is absent."""
    default = None if field.required else field.default
    if field.type == "integer":
        return integer(node, field.low, field.high, default=default)
    if field.type == "number":
        return number(node, field.low, field.high, lo_open=field.low_open, hi_open=field.high_open,
                      default=default)
    if field.type == "boolean":
        return boolean(node, default)
    if field.type == "RGB":
        return rgb(node, field.low, field.high, default=default)
    if field.choices:
        return choice(node, field.choices, default, dict(field.renamed))
    raise TypeError(f"{field.key}: a {field.type} has a reader of its own")


def _power(field: Field, node: Node) -> np.ndarray:
    """A light's intensity (W/sr) or irradiance: RGB ≥ 0, at most the field's high end,
    beyond which float32 radiance on the device overflows."""
    power = rgb(node, field.low)
    if power.max() > field.high:
        node.fail(f"a power of at most {field.high:g} (beyond it float32 radiance overflows)")
    return power


def _scale(node: Node | None) -> np.ndarray:
    """A positive number or a list of 3 positive numbers."""
    field = TRANSFORM["scale"]
    if node is None:
        return np.full(3, field.default)
    if isinstance(node.value, list):
        return numbers(node, 3, "a number > 0 or a list of 3 numbers > 0", field.low, lo_open=field.low_open)
    return np.full(3, number(node, field.low, lo_open=field.low_open))


def _within_float32(node: Node, what: str, points, got: Callable[[float], str] | None = None) -> None:
    """Points (any shape, scene units) within ±MAX_COORDINATE, where the device's float32
    products stay finite (clrays.scene.limits); NaN and infinity fail too."""
    points = np.asarray(points, dtype=np.float64)
    if points.size == 0:
        return
    largest = max(float(points.max()), -float(points.min()))  # no |points| copy: a million triangles are 72 MB
    if not largest <= MAX_COORDINATE:  # (NaN fails too)
        value = largest if not math.isnan(largest) else float("nan")
        node.fail(f"{what} within ±{MAX_COORDINATE:g} (scene units; float32 on the device overflows beyond)",
                  got(value) if got else f"{value:g}")


def _point(node: Node) -> np.ndarray:
    """A position: a vec3 within ±MAX_COORDINATE."""
    point = vec3(node)
    _within_float32(node, "a point", point, lambda _: show(node))
    return point


# --------------------------------------------------------------------------- sections


def _image(node: Node) -> Image:
    m = mapping(node, IMAGE.required, IMAGE.optional)
    width = _read(IMAGE["width"], m["width"])
    height = _read(IMAGE["height"], m["height"])
    if width * height > MAX_IMAGE_PIXELS:
        node.fail(f"width * height <= {MAX_IMAGE_PIXELS} pixels",
                  f"{width} x {height} = {width * height}")
    return Image(width=width, height=height, spp=_read(IMAGE["spp"], m.get("spp")))


def _camera(node: Node) -> Camera:
    m = mapping(node, CAMERA.required, CAMERA.optional)
    position = _point(m["position"])
    look_at = _point(m["look_at"])
    if np.array_equal(position, look_at):
        m["look_at"].fail("a point different from camera.position")
    default_up = CAMERA["up"].default
    up = direction(m["up"]) if "up" in m else np.array(default_up, dtype=np.float64)
    forward = (look_at - position) / np.linalg.norm(look_at - position)
    if np.linalg.norm(np.cross(forward, up)) < PARALLEL_TOLERANCE:
        up_node = m.get("up") or Node(list(default_up), node.where, node.child_path("up"))
        up_node.fail("a direction not parallel to look_at - position",
                     None if "up" in m else f"{show(up_node)} (default)")
    far = _read(CAMERA["far"], m.get("far"))
    return Camera(position=position, look_at=look_at, up=up, fov_deg=_read(CAMERA["fov_deg"], m.get("fov_deg")),
                  far=far, near=_near(m.get("near"), far))


def _near(node: Node | None, far: float) -> float:
    """camera.near: a number in [0, far): a camera ray that starts beyond far has no length."""
    near = _read(CAMERA["near"], node)
    if node is not None and not near < far:
        node.fail(f"a number in [0, {far:g}) (below camera.far)")
    return near


def _near_alone(node: Node) -> bool:
    """A `camera` of `near` alone: beside `gltf`, it sets the near of the file's camera."""
    return isinstance(node.value, dict) and set(node.value) == {"near"}


def _scene_camera(node: Node | None, own_camera: bool, imported) -> Camera:
    """The scene's own camera, or the glTF file's (its near set by a `camera` of `near` alone)."""
    if own_camera:
        return _camera(node)
    if node is None:
        return imported.camera
    return dataclasses.replace(imported.camera, near=_near(node.value["near"], imported.camera.far))


def _texture_path(node: Node, base_dir: Path) -> Path:
    if not isinstance(node.value, str) or not node.value.strip():
        node.fail("a texture file path (.png, .exr or .npy)")
    path = Path(node.value)
    return path if path.is_absolute() else base_dir / path


def _texture(node: Node | None, base_dir: Path, cache: TextureCache) -> LightTexture | None:
    """A light's texture file read into linear texels (clrays.scene.textures), or None;
    read once for all the lights that name it (`cache`)."""
    if node is None:
        return None
    path = _texture_path(node, base_dir)
    try:
        return LightTexture(cache.image(path), node.value)
    except TextureError as exc:
        node.fail("a texture image (.png, .exr or .npy) with finite texels >= 0", f"{show(node)}: {exc} ({path})")


def _cube_texture(node: Node | None, base_dir: Path, cache: TextureCache) -> LightTexture | None:
    """A point light's cube texture: six files (a list) or one cross layout (a string)."""
    if node is None:
        return None
    if isinstance(node.value, list):
        if len(node.value) != 6:
            node.fail("six texture files [+x, -x, +y, -y, +z, -z] or one cross image", f"{len(node.value)} files")
        paths = [_texture_path(item, base_dir) for item in node.value]
        try:
            texels = cache.cube_faces(paths)
        except TextureError as exc:
            if exc.face is None:
                node.fail("six square texture images of one size", f"{show(node)}: {exc}")
            face = node.value[exc.face]
            face.fail("a texture image (.png, .exr or .npy) with finite texels >= 0",
                      f"{show(face)}: {exc} ({paths[exc.face]})")
        return LightTexture(texels, ", ".join(item.value for item in node.value))
    path = _texture_path(node, base_dir)
    try:
        return LightTexture(cache.cube_cross(path), node.value)
    except TextureError as exc:
        node.fail("a cross of 4 × 3 square cells, or a list of six files, with finite texels >= 0",
                  f"{show(node)}: {exc} ({path})")


def _texture_only(m: dict[str, Node], *keys: str) -> None:
    """Keys that only mean something with a texture."""
    if "texture" not in m:
        for key in keys:
            if key in m:
                m[key].fail("no " + key + " without a texture (add `texture: FILE`, or remove the key)",
                            show(m[key]))


def _light(node: Node, base_dir: Path = Path("."), cache: TextureCache | None = None) -> Light:
    cache = TextureCache() if cache is None else cache
    kind, m = typed(node, kinds(LIGHTS))
    keys = LIGHTS[kind]
    if kind == "point":
        light = PointLight(position=_point(m["position"]), intensity=_power(keys["intensity"], m["intensity"]),
                           texture=_cube_texture(m.get("texture"), base_dir, cache))
        return _textured_power(m, light, light.intensity, cache)
    if kind == "spot":
        light = SpotLight(position=_point(m["position"]), direction=direction(m["direction"]),
                          cone_deg=_read(keys["cone_deg"], m["cone_deg"]),
                          intensity=_power(keys["intensity"], m["intensity"]),
                          texture=_texture(m.get("texture"), base_dir, cache))
        return _textured_power(m, light, light.intensity, cache)
    _texture_only(m, "texture_size", "texture_wrap")
    size_field = keys["texture_size"]
    size = tuple(numbers(m["texture_size"], 2, "a list of 2 numbers > 0 [width, height]", size_field.low,
                         lo_open=size_field.low_open)) if "texture_size" in m else size_field.default
    light = DirectionalLight(direction=direction(m["direction"]),
                             irradiance=_power(keys["irradiance"], m["irradiance"]),
                             texture=_texture(m.get("texture"), base_dir, cache),
                             texture_size=tuple(float(v) for v in size),
                             texture_wrap=_read(keys["texture_wrap"], m.get("texture_wrap")))
    return _textured_power(m, light, light.irradiance, cache)


def _textured_power(m: dict[str, Node], light: Light, power: np.ndarray, cache: TextureCache,
                    power_node: Node | None = None) -> Light:
    """The light, its power × its brightest texel checked against MAX_POWER: the texture
    multiplies the power per light ray (a 2e37 texel at intensity 1e30 overflowed float32)."""
    if light.texture is None:
        return light
    brightest = cache.brightest(light.texture.texels)
    if float(np.max(power)) * brightest > MAX_POWER:
        key = "irradiance" if isinstance(light, DirectionalLight) else "intensity"
        (power_node or m[key]).fail(f"a power whose product with the brightest texel ({brightest:g}) is at most "
                                    f"{MAX_POWER:g} (beyond it float32 radiance overflows)",
                                    f"{float(np.max(power)):g}")
    return light


def _lights(node: Node) -> list[Node]:
    items = sequence(node, "a list of at least 1 light", 1)
    if len(items) > MAX_LIGHTS:  # checked before reading any: each light costs a frame its own stages
        node.fail(f"at most {MAX_LIGHTS} lights (each light costs its own raster, volume and visibility stages every frame)",
                  f"{len(items)} lights")
    return items


def _phase(node: Node) -> Phase:
    kind, m = typed(node, kinds(PHASES))
    if kind == "isotropic":
        return Phase()
    return Phase(type="hg", g=_read(PHASES["hg"]["g"], m["g"]))


def _medium(node: Node | None, base_dir: Path = Path(".")) -> tuple[Medium, DensityDrift | None]:
    """The medium, and what an animated `offset` of its grid or noise density moves."""
    if node is None:
        return Medium(sigma_s=np.zeros(3), sigma_a=np.zeros(3)), None
    m = mapping(node, optional=MEDIUM.optional)
    density, drift = _density(m["density"], base_dir) if "density" in m else (None, None)
    return Medium(sigma_s=_read(MEDIUM["sigma_s"], m.get("sigma_s")),
                  sigma_a=_read(MEDIUM["sigma_a"], m.get("sigma_a")),
                  phase=_phase(m["phase"]) if "phase" in m else Phase(),
                  bounds=_bounds(m["bounds"]) if "bounds" in m and not _volume_object(node) else None,
                  density=density), drift


def _volume_object(medium: Node | None) -> Node | None:
    """`medium.bounds: {object: NAME}`'s name: a glTF node whose mesh bounds the fog (the box
    around it) and is no geometry; None for a `{min, max}` box or no bounds."""
    bounds = medium.value.get("bounds") if medium is not None and isinstance(medium.value, dict) else None
    if bounds is None or not isinstance(bounds.value, dict) or "object" not in bounds.value:
        return None
    name = mapping(bounds, VOLUME_OBJECT.required)["object"]
    if not isinstance(name.value, str) or not name.value:
        name.fail("the name of a glTF node with a mesh")
    return name


def _bounds(node: Node) -> Box:
    """`{min: vec3, max: vec3}` with max > min on every axis."""
    m = mapping(node, BOX.required)
    low, high = _point(m["min"]), _point(m["max"])
    for axis, name in enumerate("xyz"):
        if not high[axis] > low[axis]:
            node.fail("max > min on every axis", f"{name}: min {low[axis]:g}, max {high[axis]:g}")
    return Box(low, high)


def _density(node: Node, base_dir: Path) -> tuple[Density, DensityDrift | None]:
    """`medium.density`: a height fog, a grid file or noise baked to a grid (with, for a grid
    or noise, the `DensityDrift` that its offset's keys move)."""
    kind, m = typed(node, kinds(DENSITIES))
    fields = DENSITIES[kind]
    if kind == "height":
        return HeightDensity(base=_read(fields["base"], m["base"]),
                             scale_height=_read(fields["scale_height"], m["scale_height"])), None
    bounds = _bounds(m["bounds"])
    offset = _offset(m["offset"]) if "offset" in m else np.asarray(fields["offset"].default, dtype=np.float64)
    if kind == "grid":
        file = m["file"]
        if not isinstance(file.value, str) or not file.value.strip():
            file.fail("a grid file path (.npy)")
        path = Path(file.value)
        values = density_sources.load_grid_file(path if path.is_absolute() else base_dir / path,
                                                f"{file.where}: {file.label}")
        values.flags.writeable = False  # shared by every frame of a drifting grid
        drift = DensityDrift(bounds, values=values)
    else:
        resolution_node = m.get("resolution")
        resolution = fields["resolution"].default if resolution_node is None else tuple(
            integer(item, fields["resolution"].low) for item in _three(resolution_node))
        voxels = math.prod(resolution)
        if voxels > density_sources.GRID_VOXELS_MAX:  # counted before baking
            resolution_node.fail(f"at most {density_sources.GRID_VOXELS_MAX} voxels in all",
                                 f"{' × '.join(map(str, resolution))} = {voxels}")
        noise = (_read(fields["frequency"], m.get("frequency")), _read(fields["octaves"], m.get("octaves")),
                 _read(fields["seed"], m.get("seed")), resolution)
        drift = DensityDrift(bounds, noise=noise, where=f"{node.where}: {node.label}")
    return drift.at(offset), drift


def _offset(node: Node) -> np.ndarray:
    """A grid's or the noise's offset: a vec3 within ±MAX_COORDINATE."""
    offset = vec3(node)
    _within_float32(node, "an offset", offset)
    return offset


def _three(node: Node) -> list[Node]:
    """A list of exactly 3 items."""
    if not isinstance(node.value, list) or len(node.value) != 3:
        node.fail("a list of 3 integers [nx, ny, nz]")
    return node.value


def _render(node: Node | None) -> Render:
    if node is None:
        return Render()
    m = mapping(node, optional=RENDER.optional)
    # A size left out stays None: the renderer derives it from the image (clrays.scene.costs).
    values = {field.key: None if field.default is None and field.key not in m else _read(field, m.get(field.key))
              for field in RENDER.fields if field.key not in ("shadow_filter", "transparency", "aovs", "exposure")}
    values["aovs"] = _aovs(m.get("aovs"))
    values["exposure"] = _exposure(m.get("exposure"))
    values["shadow_filter"] = _shadow_filter(m, values)
    values["transparency"] = _transparency(m.get("transparency"))
    if values["surface_shadows"] == "filtered" and values["shadow_filter"] is None:
        values["shadow_filter"] = ShadowFilter()
    if values["pcf"] > 0:
        if "surface_shadows" not in m:
            values["surface_shadows"] = "pcf"  # the key before surface_shadows existed: pcf alone filters
        elif values["surface_shadows"] != "pcf":
            m["pcf"].fail(f"0 with surface_shadows: {values['surface_shadows']} (a filter radius needs "
                          f"surface_shadows: pcf)", str(values["pcf"]))
    return Render(**values)


def _exposure(node: Node | None) -> float | str:
    """`render.exposure`: stops, or `auto` (clrays.exposure)."""
    field = RENDER["exposure"]
    if node is None:
        return field.default
    value = parse_exposure(node.value)
    if value is None:
        node.fail(f"a number of stops in [{field.low:g}, {field.high:g}] or auto")
    return value


def _aovs(node: Node | None) -> tuple[str, ...]:
    """`render.aovs`: a list of pass names (clrays.passes), each once; the light indices are
    checked with the lights (`_check_aovs`)."""
    if node is None:
        return ()
    if not isinstance(node.value, list):
        node.fail("a list of pass names")
    names = []
    for item in node.value:
        problem = pass_problem(item.value, MAX_LIGHTS)
        if problem is not None:
            item.fail(problem)
        if item.value in names:
            item.fail("each pass once", f"{item.value!r} twice")
        names.append(item.value)
    return tuple(names)


def _check_aovs(scene: Scene, node: Node | None) -> None:
    """The passes against the scene: a light index it has, and no translucent object (the
    films in front of a surface are no term of the passes' sum)."""
    if node is None or not scene.render.aovs:
        return
    for item in node.value:
        problem = pass_problem(item.value, len(scene.lights))
        if problem is not None:
            item.fail(problem)
    if scene.geometry.translucent:
        node.fail("no render passes in a scene with translucent objects (opacity below 1)",
                  ", ".join(scene.render.aovs))


def _shadow_filter(m: dict[str, Node], values: dict[str, Any]) -> ShadowFilter | None:
    """`render.shadow_filter` (a mapping, or a string naming its type), checked against
    `surface_shadows` and `pcf`, which it must not contradict (docs/scene-format.md)."""
    node = m.get("shadow_filter")
    if node is None:
        return None
    if "surface_shadows" not in m:
        values["surface_shadows"] = "filtered"  # a filter alone asks for filtered shadows
    elif values["surface_shadows"] != "filtered":
        node.fail(f"no shadow_filter with render.surface_shadows: {values['surface_shadows']} (a filter needs "
                  f"surface_shadows: filtered, or surface_shadows left out)", "a shadow_filter")
    if values["pcf"] > 0:
        m["pcf"].fail("0 with render.shadow_filter (its radius is the filter's: shadow_filter: {type: pcf, "
                      "radius: N})", str(values["pcf"]))
    if isinstance(node.value, str):
        return ShadowFilter(type=choice(node, SHADOW_FILTER["type"].choices))
    keys = mapping(node, optional=SHADOW_FILTER.optional)
    return ShadowFilter(**{field.key: _read(field, keys.get(field.key)) for field in SHADOW_FILTER.fields})


def _transparency(node: Node | None) -> Transparency | None:
    """`render.transparency` (a mapping, or a string naming its type); None when left out."""
    if node is None:
        return None
    if isinstance(node.value, str):
        return Transparency(type=choice(node, TRANSPARENCY["type"].choices, renamed=dict(TRANSPARENCY["type"].renamed)))
    keys = mapping(node, optional=TRANSPARENCY.optional)
    values = {field.key: _read(field, keys.get(field.key)) for field in TRANSPARENCY.fields}
    # Each type reads keys of its own: they name the type when it is left out, and a key the
    # named type would ignore is a mistake, not a setting.
    readers = {"layers": "depth_peeling", "warp": "mboit", "moment_bias": "mboit"}
    implied = {readers[key] for key in keys if key in readers}
    if "type" not in keys:
        if len(implied) > 1:
            raise SceneError(f"{node.where}: {node.path}: layers is read by depth_peeling, warp and moment_bias "
                             f"by mboit: add type: depth_peeling or type: mboit")
        values["type"] = implied.pop() if implied else Transparency.type
    for key in keys:
        if readers.get(key, values["type"]) != values["type"]:
            raise SceneError(f"{node.key_where.get(key, node.where)}: {node.child_path(key)}: only "
                             f"{readers[key]} reads it, got type {values['type']}")
    return Transparency(**values)


# --------------------------------------------------------------------------- objects


def _rotation(node: Node) -> np.ndarray:
    """3x3 from exactly one of {axis, angle_deg}, {euler_deg, order}, {quaternion}."""
    forms = {"axis-angle": ("axis", "angle_deg"), "euler": ("euler_deg", "order"),
             "quaternion": ("quaternion",)}
    m = mapping(node, optional=ROTATE.optional)
    used = [name for name, keys in forms.items() if any(k in m for k in keys)]
    if len(used) != 1:
        node.fail("exactly one of {axis, angle_deg}, {euler_deg, order} or {quaternion}")
    if used == ["axis-angle"]:
        m = mapping(node, required=("axis", "angle_deg"))
        return rotation_axis_angle(direction(m["axis"]), math.radians(number(m["angle_deg"])))
    if used == ["euler"]:
        m = mapping(node, required=("euler_deg",), optional=("order",))
        angles = numbers(m["euler_deg"], 3, "a list of 3 angles in degrees")
        order = ROTATE["order"].default
        if "order" in m:
            order = m["order"].value
            if (not isinstance(order, str) or len(order) != 3 or set(order) - set("xyz")
                    or order[0] == order[1] or order[1] == order[2]):
                m["order"].fail("3 letters over 'xyz' with no adjacent repeats, like 'xyz' or 'zxz'")
        return rotation_euler(np.radians(angles), order)
    return quat_to_matrix(_unit_quaternion(m["quaternion"]))


def _unit_quaternion(node: Node) -> np.ndarray:
    q = numbers(node, 4, "a unit quaternion [w, x, y, z]")
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        node.fail(f"a unit quaternion [w, x, y, z] (|q| = 1 within {QUATERNION_TOLERANCE:g})",
                  f"{show(node)} with |q| = {norm:.9g}")
    return q


def _transform_parts(node: Node | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(translate (3,), rotation 3x3, scale (3,)); the identity for no transform."""
    translate = np.array(TRANSFORM["translate"].default, dtype=np.float64)
    if node is None:
        return translate, np.eye(3), _scale(None)
    m = mapping(node, optional=TRANSFORM.optional)
    translate = vec3(m["translate"]) if "translate" in m else translate
    rotate = _rotation(m["rotate"]) if "rotate" in m else np.eye(3)
    return translate, rotate, _scale(m.get("scale"))


@dataclasses.dataclass(frozen=True)
class _VertexNormals:
    """A smooth shape's normals at its points and the faces that index them, spread to
    each triangle's vertices (F, 3, 3) only as the scene's geometry is assembled: a sphere
    of a million triangles keeps 12 MB of normals while the others load, not 72."""

    at_points: np.ndarray  # (V, 3) unit
    faces: np.ndarray  # (F, 3) indices into at_points

    def array(self) -> np.ndarray:
        return primitives.indexed_triangles(self.at_points, self.faces)

    def transformed(self, matrix: np.ndarray) -> "_VertexNormals":
        return _VertexNormals(transform_normals(matrix, self.at_points), self.faces)


def _normals_array(normals: np.ndarray | _VertexNormals | None) -> np.ndarray | None:
    return normals.array() if isinstance(normals, _VertexNormals) else normals


# An object's shape in its own frame: triangles (T, 3, 3); for a smooth object, the normal
# at each of their vertices ((T, 3, 3), or _VertexNormals), None for a flat one; and its
# outward winding (geometry.closed_outward: +1, -1, or 0 for a surface that closes no solid).
_Shape = tuple[np.ndarray, np.ndarray | _VertexNormals | None, int]


def _triangles(m: dict[str, Node]) -> _Shape:
    vertices = np.array([vec3(v) for v in sequence(m["vertices"], "a list of at least 3 vertices [x, y, z]", 3)])
    n = len(vertices)
    faces = []
    for face in sequence(m["faces"], "a list of at least 1 face [i, j, k]", 1):
        if not isinstance(face.value, list) or len(face.value) != 3:
            face.fail("a face: a list of 3 vertex indices [i, j, k]")
        faces.append([integer(i, 0, n - 1) for i in face.value])
    faces = np.array(faces)
    triangles = primitives.indexed_triangles(vertices, faces)
    order = primitives.spatial_order(triangles)  # as a mesh file's
    return triangles[order], None, primitives.closed_outward(vertices, faces)


def _box(m: dict[str, Node]) -> _Shape:
    lo, hi = vec3(m["min"]), vec3(m["max"])
    if not (lo < hi).all():
        m["max"].fail(f"a point above min {show(m['min'])} on every axis")
    return primitives.box_triangles(lo, hi), None, 1  # closed, wound outward


def _sphere(m: dict[str, Node]) -> _Shape:
    """A sphere's triangles, shaded smooth with its analytic normals (flat, its 48 segments
    showed as bands across a lit top)."""
    keys = OBJECTS["sphere"]
    center = _point(m["center"])
    points, faces = primitives.sphere_mesh(center, _read(keys["radius"], m["radius"]),
                                           _read(keys["segments"], m.get("segments")))
    normals = _VertexNormals(primitives.sphere_normals(points, center), faces)
    return primitives.indexed_triangles(points, faces), normals, 1  # closed, wound outward


def _plane(m: dict[str, Node]) -> _Shape:
    keys = OBJECTS["plane"]
    return primitives.plane_triangles(vec3(m["center"]), direction(m["normal"]), _read(keys["size"], m["size"]),
                                      _read(keys["segments"], m.get("segments"))), None, 0


def _mesh(m: dict[str, Node], base_dir: Path) -> _Shape:
    node = m["file"]
    if not isinstance(node.value, str) or not node.value.strip():
        node.fail("a mesh file path (.obj, .ply or .stl)")
    smooth = _read(OBJECTS["mesh"]["normals"], m.get("normals")) == "smooth"
    path = Path(node.value)
    path = path if path.is_absolute() else base_dir / path
    try:
        triangles, normals, outward = primitives.load_mesh(path, MAX_TRIANGLES)
    except primitives.MeshTooLarge as exc:  # counted before trimesh builds them
        node.fail(f"at most {MAX_TRIANGLES} triangles in the whole scene (simplify the mesh)",
                  f"{show(node)} ({exc.count} triangles in its faces)")
    except (ValueError, OSError) as exc:
        node.fail("a readable mesh file (.obj, .ply or .stl) with triangles",
                  f"{show(node)} ({exc}: {path})")
    return triangles, normals if smooth else None, outward


def _relief_image(node: Node, base_dir: Path, check_shape: Callable[[int, int], None]) -> np.ndarray:
    """An image key of a relief read into (H, W, C) floats, its size checked by
    `check_shape(height, width)` before it is decoded; a one-line error naming the key,
    its value and the reason otherwise."""
    if not isinstance(node.value, str) or not node.value.strip():
        node.fail("an image file path (.png, .exr or .npy)")
    path = Path(node.value)
    path = path if path.is_absolute() else base_dir / path
    try:
        return relief_images.read_image(path, check_shape)
    except (ValueError, OSError) as exc:
        node.fail("a readable 2D image (.png 8 or 16 bit, .exr or .npy)", f"{show(node)} ({exc}: {path})")


def read_relief(m: dict[str, Node], base_dir: Path) -> relief_images.Relief:
    """A relief's keys (docs/design.md, "Relief objects"): its texel frame, displacement, holes and colours."""
    keys = OBJECTS["relief"]
    normal, up = direction(m["normal"]), direction(m["up"])
    if np.linalg.norm(np.cross(normal, up)) < PARALLEL_TOLERANCE:
        m["up"].fail("a direction not parallel to normal")
    size = numbers(m["size"], 2, "a list of 2 numbers [w, h] > 0", keys["size"].low, lo_open=True)
    _within_float32(m["size"], "sizes", size, lambda _: show(m["size"]))
    height = _read(keys["height"], m["height"])
    _within_float32(m["height"], "a height", height)
    center = _point(m["center"])

    def triangles_fit(rows: int, cols: int) -> None:  # before decoding: a small PNG may hold 13000² texels
        if relief_images.cell_count((rows, cols)) > MAX_TRIANGLES:
            m["depth_map"].fail(f"at most {MAX_TRIANGLES} triangles (two per cell of four texels)",
                                f"{show(m['depth_map'])} ({cols} × {rows} texels: "
                                f"{relief_images.cell_count((rows, cols))} triangles)")

    image = _relief_image(m["depth_map"], base_dir, triangles_fit)
    depth, alpha = relief_images.depth_and_alpha(image)
    solid = np.ones(depth.shape, bool) if alpha is None else alpha > 0
    albedo = None
    if "albedo_map" in m:
        def same_size(rows: int, cols: int) -> None:
            if (rows, cols) != depth.shape:
                m["albedo_map"].fail(f"an image of the depth map's size, {depth.shape[1]} × {depth.shape[0]}",
                                     f"{show(m['albedo_map'])} ({cols} × {rows})")

        colours = _relief_image(m["albedo_map"], base_dir, same_size)
        albedo, colour_alpha = relief_images.colour_and_alpha(colours)
        low, high = OBJECT["albedo"].low, OBJECT["albedo"].high
        outside = (albedo < low) | (albedo > high)
        if outside.any():  # as a scalar albedo is: a texel of 1e6 would be a lamp
            y, x, c = np.argwhere(outside)[0]
            m["albedo_map"].fail(f"albedo texels in [{low:g}, {high:g}], as albedo's",
                                 f"{show(m['albedo_map'])} ({albedo[y, x, c]:g} at texel (x={x}, y={y}), "
                                 f"{int(outside.any(axis=2).sum())} outside in all)")
        if colour_alpha is not None:
            solid &= colour_alpha > 0
    frame = relief_images.relief_frame(center, normal, up, size, depth.shape)
    return relief_images.Relief(frame, height * depth, solid, albedo)


def _relief(m: dict[str, Node], base_dir: Path):
    """(the relief, its height-field triangles, their albedo when it has an albedo_map)."""
    relief = read_relief(m, base_dir)
    triangles, albedo = relief.triangles()
    if len(triangles) == 0:
        m["depth_map"].fail("a depth map with at least one cell of four texels whose alpha is not 0",
                            f"{show(m['depth_map'])} (every cell is a hole)")
    return relief, triangles, albedo


_BUILDERS: dict[str, Callable[[dict[str, Node], Path], _Shape]] = {
    "triangles": lambda m, _: _triangles(m),
    "plane": lambda m, _: _plane(m),
    "box": lambda m, _: _box(m),
    "sphere": lambda m, _: _sphere(m),
    "mesh": _mesh,
}


def _reject_normals_off_meshes(node: Node) -> None:
    """`normals` on an object other than a mesh: say why, rather than only 'unknown key'."""
    if not isinstance(node.value, dict) or "normals" not in node.value or "type" not in node.value:
        return
    kind = node.value["type"].value
    if isinstance(kind, str) and kind in OBJECTS and "normals" not in OBJECTS[kind].optional:
        node.value["normals"].fail(f"no normals key on a {kind} (only a mesh chooses between its vertex normals "
                                   f"and flat shading; a sphere is shaded smooth, every other object flat)")


@dataclasses.dataclass(frozen=True)
class _Object:
    """One object as the loader builds it: world-space triangles and shading normals, its
    albedo, and what an animation of it needs (its own triangles and normals, its transform)."""

    triangles: np.ndarray  # (T, 3, 3) world space
    normals: np.ndarray | _VertexNormals | None  # (T, 3, 3) world space, unit, for a smooth object
    albedo: np.ndarray  # (3,), or (T, 3) for a relief with an albedo_map
    opacity: np.ndarray  # (3,)
    local: np.ndarray  # (T, 3, 3) before the transform
    local_normals: np.ndarray | _VertexNormals | None  # before the transform, for a smooth object
    parts: tuple[np.ndarray, np.ndarray, np.ndarray]  # translate (3,), rotation 3x3, scale (3,)
    relief: relief_images.Relief | None = None  # a relief object's texels, for the pre-warp
    outward: int = 0  # +1 or -1: a closed, opaque solid and its winding (Geometry.outward); 0: none


def _object(node: Node, base_dir: Path) -> _Object:
    _reject_normals_off_meshes(node)
    kind, m = typed(node, kinds(OBJECTS), OBJECT.optional)
    albedo = _read(OBJECT["albedo"], m.get("albedo"))
    opacity = _read(OBJECT["opacity"], m.get("opacity"))
    parts = _transform_parts(m.get("transform"))
    relief, outward = None, 0
    if kind == "relief":  # its colours come per triangle from its albedo_map, if it has one
        relief, local, texel_albedo = _relief(m, base_dir)
        local_normals = None
        if texel_albedo is not None:
            albedo = texel_albedo
    else:
        local, local_normals, outward = _BUILDERS[kind](m, base_dir)
    if np.any(opacity < 1.0):  # light passes through: each of its surfaces counts
        outward = 0
    _within_float32(node, "vertices", local)  # before the transform multiplies them
    triangles, normals = local, local_normals
    if "transform" in m:
        matrix = affine(*parts)
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused just below
            triangles = transform_points(matrix, local)
        _within_float32(m["transform"], "vertices (after the transform)", triangles)
        if isinstance(local_normals, _VertexNormals):
            normals = local_normals.transformed(matrix)
        elif local_normals is not None:
            normals = transform_normals(matrix, local_normals)
    return _Object(triangles, normals, albedo, opacity, local, local_normals, parts, relief, outward)


def _tessellated_count(node: Node) -> int:
    """The triangles a sphere or plane will have, from its keys, before it is built (0 for
    other objects, or when the keys are invalid: building then fails with their message)."""
    m = node.value if isinstance(node.value, dict) else {}
    kind = m["type"].value if "type" in m else None
    if kind not in ("sphere", "plane"):
        return 0
    try:
        segments = _read(OBJECTS[kind]["segments"], m.get("segments"))
    except SceneError:
        return 0
    return 2 * segments * (segments // 2 - 1) if kind == "sphere" else 2 * segments * segments


def _check_triangle_count(node: Node, index: int, count: int) -> None:
    if count > MAX_TRIANGLES:
        node.fail(f"at most {MAX_TRIANGLES} triangles in the whole scene (lower the segments of spheres and "
                  f"planes, or simplify meshes)", f"{count} with objects 0 to {index}")


def _geometry(node: Node | None, base_dir: Path, rigs: list | None = None) -> Geometry:
    """All objects flattened; `rigs`, when given, receives each object's ObjectRig."""
    tris, albedo, ids = [np.zeros((0, 3, 3))], [np.zeros((0, 3))], [np.zeros(0, np.int32)]
    opacity, outward, convex_part = [np.ones((0, 3))], [np.zeros(0, np.int8)], [np.zeros(0, np.int32)]
    smooth_normals: list[tuple[slice, np.ndarray]] = []
    reliefs: list[relief_images.ReliefRecord] = []
    start = 0
    items = sequence(node, "a list of objects") if node is not None else []
    if len(items) > MAX_OBJECTS:
        node.fail(f"at most {MAX_OBJECTS} objects (join many small ones into one mesh file)", f"{len(items)} objects")
    for i, item in enumerate(items):
        _check_triangle_count(item, i, start + _tessellated_count(item))  # before tessellating: it may be huge
        obj = _object(item, base_dir)
        count = len(obj.triangles)
        if rigs is not None:
            translate, rotate, scale = obj.parts
            rigs.append(ObjectRig(obj.local, slice(start, start + count), translate, matrix_to_quat(rotate), scale,
                                  _normals_array(obj.local_normals)))
        if obj.normals is not None:
            smooth_normals.append((slice(start, start + count), obj.normals))
        if obj.relief is not None:
            reliefs.append(relief_images.relief_record(obj.relief, slice(start, start + count), obj.local))
        start += count
        _check_triangle_count(item, i, start)  # a mesh's count is known once it is read
        tris.append(obj.triangles)
        albedo.append(np.broadcast_to(obj.albedo, (count, 3)))
        opacity.append(np.broadcast_to(obj.opacity, (count, 3)))
        ids.append(np.full(count, i, dtype=np.int32))
        outward.append(np.full(count, obj.outward, dtype=np.int8))
        convex_part.append((start - count) + _convex_parts(item, count))  # (the flag is above any index)
    triangles = np.ascontiguousarray(np.concatenate(tris), dtype=np.float64)
    normals = primitives.flat_normals(triangles)  # once for all objects: per object, it dominated loading
    smooth = np.zeros(len(triangles), bool)
    for rows, object_normals in smooth_normals:
        normals[rows], smooth[rows] = _normals_array(object_normals), True
    return Geometry(triangles=triangles, albedo=np.ascontiguousarray(np.concatenate(albedo), dtype=np.float64),
                    object_id=np.concatenate(ids).astype(np.int32), normals=normals, smooth=smooth,
                    reliefs=tuple(reliefs), opacity=_opacity_or_none(np.concatenate(opacity)),
                    outward=np.concatenate(outward), convex_part=np.concatenate(convex_part))


def _convex_parts(node: Node, count: int) -> np.ndarray:
    """(count,) int32: each of an object's triangles' convex part, numbered from 0 (the
    index of its first triangle in the object): a plane is one, and a box or a sphere one
    flagged CONVEX_OUTSIDE_ONLY (a solid's triangles cannot shadow a point of its outside,
    where their winding faces; from inside, its far side does); any other object's
    triangles each their own. A sphere's tessellation is the convex hull of its points, and
    a transform (its scale is positive) keeps either of them convex."""
    kind = node.value["type"].value
    if kind == "plane":
        return np.zeros(count, np.int32)
    if kind in ("box", "sphere"):
        return np.full(count, CONVEX_OUTSIDE_ONLY, np.int32)
    return np.arange(count, dtype=np.int32)


def _opacity_or_none(opacity: np.ndarray) -> np.ndarray | None:
    """None when every triangle is opaque: such a scene keeps the opaque-only path."""
    return None if bool((opacity == 1.0).all()) else np.ascontiguousarray(opacity, dtype=np.float64)


# --------------------------------------------------------------------------- animation

# Animated properties: name -> (reader, interpolation). Lights by type, like LIGHTS.
_Reader = tuple[Callable[[Node], Any], str]
_CAMERA_TRACKS: dict[str, _Reader] = {
    "position": (_point, "linear"),
    "look_at": (_point, "linear"),
    "up": (direction, "direction"),
    "orientation": (_unit_quaternion, "rotation"),
    "fov_deg": (lambda n: _read(CAMERA["fov_deg"], n), "linear"),
}
_LIGHT_TRACKS: dict[str, dict[str, _Reader]] = {
    "point": {"position": (_point, "linear"),
              "intensity": (lambda n: _power(LIGHTS["point"]["intensity"], n), "linear")},
    "spot": {"position": (_point, "linear"), "direction": (direction, "direction"),
             "cone_deg": (lambda n: _read(LIGHTS["spot"]["cone_deg"], n), "linear"),
             "intensity": (lambda n: _power(LIGHTS["spot"]["intensity"], n), "linear")},
    "directional": {"direction": (direction, "direction"),
                    "irradiance": (lambda n: _power(LIGHTS["directional"]["irradiance"], n), "linear")},
}
_OBJECT_TRACKS: dict[str, _Reader] = {
    "translate": (vec3, "linear"),
    "rotate": (lambda n: matrix_to_quat(_rotation(n)), "rotation"),
    "scale": (_scale, "linear"),
}
_MEDIUM_TRACKS: dict[str, _Reader] = {
    "sigma_s": (lambda n: _read(MEDIUM["sigma_s"], n), "linear"),
    "sigma_a": (lambda n: _read(MEDIUM["sigma_a"], n), "linear"),
    "g": (lambda n: _read(PHASES["hg"]["g"], n), "linear"),
    "offset": (lambda n: _offset(n), "linear"),
}


def _keys(node: Node, tracks: dict[str, _Reader], easing: str) -> tuple[dict[str, Track], dict[str, list[Node]]]:
    """A list of keys {frame, [easing], property: value, ...} → one Track per property
    (and the value nodes of each, for later messages)."""
    keys: dict[str, list[Key]] = {}
    nodes: dict[str, list[Node]] = {}
    previous = None
    for item in sequence(node, "a list of at least 1 key {frame: ..., <property>: ...}", 1):
        m = mapping(item, required=("frame",), optional=("easing",) + tuple(tracks))
        frame = number(m["frame"])
        if previous is not None and frame <= previous:
            m["frame"].fail(f"a frame after {previous:g} (keys in increasing frame order)")
        previous = frame
        key_easing = choice(m.get("easing"), ANIMATION["easing"].choices, easing)
        names = [name for name in m if name in tracks]
        if not names:
            item.fail(f"a key that sets at least one of {', '.join(tracks)}")
        for name in names:
            reader, kind = tracks[name]
            value = reader(m[name])
            if kind == "direction" and keys.get(name) and float(value @ keys[name][-1].value) <= -1.0 + 1e-12:
                m[name].fail("a direction not opposite to the previous key's (the way between them is undefined)")
            keys.setdefault(name, []).append(Key(frame, value, key_easing))
            nodes.setdefault(name, []).append(m[name])
    return {name: Track(tracks[name][1], tuple(k)) for name, k in keys.items()}, nodes


def _indexed_tracks(node: Node, what: str, count: int, tracks_of: Callable[[int], dict[str, _Reader]],
                    easing: str) -> dict[int, tuple[dict[str, Track], dict[str, list[Node]]]]:
    """A list of {<what>: index, keys: [...]} (a light or an object per entry)."""
    found: dict[int, tuple[dict[str, Track], dict[str, list[Node]]]] = {}
    for entry in sequence(node, f"a list of {{{what}: index, keys: [...]}}"):
        m = mapping(entry, required=(what, "keys"))
        index = integer(m[what], 0, count - 1) if count else m[what].fail(f"no {what} index (there are none)")
        if index in found:
            m[what].fail(f"each {what} animated once (merge its keys into one entry)", f"{index} again")
        found[index] = _keys(m["keys"], tracks_of(index), easing)
    return found


def _animation(node: Node, scene: Scene, rigs: list[ObjectRig], drift: DensityDrift | None = None) -> Animation:
    m = mapping(node, ANIMATION.required, ANIMATION.optional)
    fps = _read(ANIMATION["fps"], m.get("fps"))
    frames, frames_field = m["frames"], ANIMATION["frames"]
    if not isinstance(frames.value, list) or len(frames.value) != 2:
        frames.fail("[first, last]: the first and last frame, inclusive")
    first, last = (integer(n, frames_field.low, frames_field.high) for n in frames.value)
    if last < first:
        frames.value[1].fail(f"a last frame >= the first, {first}")
    easing = _read(ANIMATION["easing"], m.get("easing"))

    camera, camera_nodes = _keys(m["camera"], _CAMERA_TRACKS, easing) if "camera" in m else ({}, {})
    if "orientation" in camera:
        for name in ("look_at", "up"):
            if name in camera:
                camera_nodes[name][0].fail("no look_at or up keys beside orientation keys (the orientation "
                                           "points the camera)", f"{name} keys")
    lights = _indexed_tracks(m["lights"], "light", len(scene.lights),
                             lambda i: _LIGHT_TRACKS[scene.lights[i].type], easing) if "lights" in m else {}
    objects = _indexed_tracks(m["objects"], "object", len(rigs), lambda i: _OBJECT_TRACKS,
                              easing) if "objects" in m else {}
    for index, (tracks, nodes) in objects.items():
        _check_object_track_extent(rigs[index], tracks, nodes)
    for index, (tracks, nodes) in lights.items():
        for name in ("intensity", "irradiance"):
            texture = scene.lights[index].texture
            if name in tracks and texture is not None:
                brightest = float(texture.texels.max())
                for key, key_node in zip(tracks[name].keys, nodes[name]):
                    if float(np.max(key.value)) * brightest > MAX_POWER:
                        key_node.fail(f"a power whose product with the brightest texel ({brightest:g}) is at "
                                      f"most {MAX_POWER:g} (beyond it float32 radiance overflows)",
                                      f"{float(np.max(key.value)):g}")
    medium, medium_nodes = _keys(m["medium"], _MEDIUM_TRACKS, easing) if "medium" in m else ({}, {})
    if "g" in medium and scene.medium.phase.type != "hg":
        medium_nodes["g"][0].fail("a medium with phase {type: hg, g: ...} (only then is there a g to animate)",
                                  f"{show(medium_nodes['g'][0])} with phase {scene.medium.phase.type!r}")
    if "offset" in medium and drift is None:
        medium_nodes["offset"][0].fail("a medium with a grid or noise density (only then is there an offset to "
                                       "animate)", show(medium_nodes["offset"][0]))
    animation = Animation(
        fps=fps, first=first, last=last, camera=camera, medium=medium, drift=drift if "offset" in medium else None,
        lights={i: tracks for i, (tracks, _) in lights.items()},
        objects={i: (rigs[i], tracks) for i, (tracks, _) in objects.items()},
    )
    if camera.keys() & {"position", "look_at", "up"} and "orientation" not in camera:
        _check_camera_path(m["camera"], animation, scene)
    return animation


def _check_object_track_extent(rig: ObjectRig, tracks: dict[str, Track], nodes: dict[str, list[Node]]) -> None:
    """An animated object's vertices stay within ±MAX_COORDINATE at every frame: |R·S·p + t|
    is at most max(scale)·|p| + |t|, and every easing keeps a track between its keys, so
    checking each key against half the bound covers every frame between them."""
    half = MAX_COORDINATE / 2
    extent = float(np.max(np.linalg.norm(rig.local.reshape(-1, 3), axis=1))) if rig.local.size else 0.0
    translates = [key.value for key in tracks["translate"].keys] if "translate" in tracks else [rig.translate]
    scales = [key.value for key in tracks["scale"].keys] if "scale" in tracks else [rig.scale]
    for i, value in enumerate(translates):
        if not float(np.linalg.norm(value)) <= half:
            node = nodes["translate"][i] if "translate" in tracks else None
            if node is not None:
                node.fail(f"a translation of length at most {half:g} (scene units: every frame's vertices stay "
                          f"within ±{MAX_COORDINATE:g}, where float32 on the device holds)", show(node))
    for i, value in enumerate(scales):
        if not float(np.max(value)) * extent <= half:
            node = nodes["scale"][i] if "scale" in tracks else None
            if node is not None:
                node.fail(f"a scale of at most {half / max(extent, 1e-300):g} for this object (its vertices stay "
                          f"within ±{MAX_COORDINATE:g}, where float32 on the device holds)", show(node))


def _check_camera_path(node: Node, animation: Animation, scene: Scene) -> None:
    """Every frame's camera must be valid, like a static one (look_at off the position,
    up off the view direction). All frames at once: one at a time, the 100 001 frames the
    format allows took 19 s to check."""
    frames = np.arange(animation.first, animation.last + 1, dtype=np.float64)
    camera, tracks = scene.camera, animation.camera

    def path(name: str) -> np.ndarray:
        return tracks[name].at_frames(frames) if name in tracks else np.broadcast_to(getattr(camera, name),
                                                                                      (len(frames), 3))

    view = path("look_at") - path("position")
    length = np.linalg.norm(view, axis=1)
    if not np.all(length > 0):
        frame = animation.first + int(np.argmin(length > 0))
        node.fail("look_at away from position at every frame", f"look_at = position at frame {frame}")
    sin_angle = np.linalg.norm(np.cross(view / length[:, None], path("up")), axis=1)
    if np.any(sin_angle < PARALLEL_TOLERANCE):
        frame = animation.first + int(np.argmax(sin_angle < PARALLEL_TOLERANCE))
        node.fail("up not parallel to look_at - position at every frame", f"parallel at frame {frame}")


# --------------------------------------------------------------------------- entry points


def parse_scene(text: str, source: Path | str | None = None, overrides: Sequence[str] = ()) -> Scene:
    """Parse scene YAML text. `source` names the file in messages and its folder is where
    relative mesh paths start (the working directory when None)."""
    with scene_files(Path(source).parent if source is not None else Path.cwd()):  # --confine: to that folder
        return _parse(text, str(source) if source is not None else "<string>", source, overrides)


def _parse(text: str, filename: str, source: Path | str | None, overrides: Sequence[str]) -> Scene:
    root = compose(text, "", mark_where(filename), filename)
    if root is None:
        raise SceneError(f"{filename}:1:1: (top level): expected a mapping, got an empty document")
    if not isinstance(root.value, dict):
        root.fail("a mapping")
    return _scene(root, filename, source, overrides)


def _scene(root: Node, filename: str, source: Path | str | None, overrides: Sequence[str]) -> Scene:
    """The scene of a composed tree, after the overrides."""
    if isinstance(overrides, str):
        overrides = [overrides]
    for override in overrides:
        apply_override(root, override)

    top = root.value
    if "version" not in top:
        raise SceneError(f"{root.where}: (top level): missing required key 'version' "
                         f"(this loader reads version: {FORMAT_VERSION})")
    version = top["version"]
    if not isinstance(version.value, int) or isinstance(version.value, bool) or version.value != FORMAT_VERSION:
        version.fail(f"version {FORMAT_VERSION}")
    # A glTF file may bring the camera and the lights.
    imports = ("camera", "lights") if "gltf" in top else ()
    m = mapping(root, tuple(key for key in TOP.required if key not in imports), TOP.optional + imports)

    base_dir = Path(source).parent if source is not None else Path.cwd()
    # With gltf, a camera of `near` alone adjusts the file's camera rather than replacing it.
    own_camera = "camera" in m and not ("gltf" in m and _near_alone(m["camera"]))
    volume = _volume_object(m.get("medium"))
    if volume is not None and "gltf" not in m:
        volume.fail("a glTF node's name, with a `gltf` file to find it in", f"{volume.value!r} without gltf")
    imported, fps = _gltf(m["gltf"], base_dir, own_camera, volume) if "gltf" in m else (None, None)
    rigs: list[ObjectRig] = []
    textures = TextureCache()  # a file that several lights name is read once, and shared
    # Sections are read (and fail) in the order the format lists them.
    image = _image(m["image"])
    camera = _scene_camera(m.get("camera"), own_camera, imported)
    lights = tuple(_light(n, base_dir, textures) for n in _lights(m["lights"])) if "lights" in m else ()
    medium, drift = _medium(m.get("medium"), base_dir)
    scene = Scene(
        image=image,
        camera=camera,
        lights=lights,
        medium=medium,
        background=_read(TOP["background"], m.get("background")),
        geometry=_geometry(m.get("objects"), base_dir, rigs if "animation" in m else None),
        render=_render(m.get("render")),
        source=Path(source) if source is not None else None,
    )
    if imported is not None:
        # A YAML medium that only places the fog (bounds, density) keeps the file's default fog's σ.
        own_sigma = "medium" in m and not (isinstance(m["medium"].value, dict)
                                           and m["medium"].value.keys() <= {"bounds", "density"})
        scene = gltf_files.merge(scene, imported, own_camera=own_camera, own_animation="animation" in m, fps=fps,
                                 own_medium=own_sigma)
        if not own_sigma and "medium" in m:
            scene = dataclasses.replace(scene, medium=dataclasses.replace(
                scene.medium, bounds=medium.bounds, density=medium.density))
        if imported.volume_bounds is not None:
            scene = dataclasses.replace(scene, medium=dataclasses.replace(
                scene.medium, bounds=Box(*imported.volume_bounds)))
    if "render" in m and isinstance(m["render"].value, dict):
        _check_aovs(scene, m["render"].value.get("aovs"))
    if "animation" in m:
        scene = dataclasses.replace(scene, animation=_animation(m["animation"], scene, rigs, drift))
    return scene


def _gltf(node: Node, base_dir: Path, own_camera: bool,
          volume: Node | None = None) -> tuple[gltf_files.Imported, float]:
    """`gltf: {file, camera, light_scale, fps}`: the file read (clrays.scene.gltf), and its fps;
    `volume`, `medium.bounds.object`, names its fog node."""
    if isinstance(node.value, dict) and "file" not in node.value and "camera" in node.value:
        node.fail("a glTF file to take the camera from (`--camera` names a camera of a glTF scene)",
                  "no gltf.file")
    m = mapping(node, GLTF.required, GLTF.optional)
    file = m["file"]
    if not isinstance(file.value, str) or Path(file.value).suffix.lower() not in gltf_files.SUFFIXES:
        file.fail("a glTF file path (.glb or .gltf)")
    camera = None
    if "camera" in m:
        if own_camera:
            m["camera"].fail("no gltf.camera beside the scene's own camera (remove one of them)")
        if not isinstance(m["camera"].value, (str, int)) or isinstance(m["camera"].value, bool):
            m["camera"].fail("a camera's name or index")
        camera = str(m["camera"].value)
    path = Path(file.value)
    path = path if path.is_absolute() else base_dir / path
    imported = gltf_files.import_gltf(path, str(path), camera, _read(GLTF["light_scale"], m.get("light_scale")),
                                      volume.value if volume is not None else None)
    return imported, _read(GLTF["fps"], m.get("fps"))


def _load_gltf(path: Path, overrides: Sequence[str]) -> Scene:
    """A glTF file as the scene `{version: 1, image: DEFAULT_IMAGE, gltf: {file: path}}`, so
    `--set` reaches the image, medium, render settings and the `gltf` keys alike."""
    where = str(path)
    width, height = gltf_files.DEFAULT_IMAGE
    root = Node({"version": Node(FORMAT_VERSION, where, "version"),
                 "image": Node({"width": Node(width, where, "image.width"),
                                "height": Node(height, where, "image.height")}, where, "image"),
                 "gltf": Node({"file": Node(path.name, where, "gltf.file")}, where, "gltf")}, where, "")
    return _scene(root, where, path, overrides)


def load_scene(path: Path | str, overrides: Sequence[str] = ()) -> Scene:
    """Read, override (`key.path=value` strings, as from `--set`) and validate a scene file:
    YAML, or glTF 2.0 (.glb, .gltf: clrays.scene.gltf)."""
    if Path(path).suffix.lower() in gltf_files.SUFFIXES:
        with scene_files(Path(path).parent):  # --confine: its buffer files, to its folder
            return _load_gltf(Path(path), overrides)
    try:
        data = read_regular_file(path, MAX_SCENE_BYTES, "put large geometry in a mesh file "
                                                        "(objects: - {type: mesh, file: ...})")
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(f"{path}: cannot read scene file: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except FileRefused as exc:
        raise SceneError(f"{path}: cannot read scene file: {exc}") from None
    with scene_files(Path(path).parent):  # --confine: the files it names, to its folder
        return _parse(text, str(path), path, overrides)


def object_kinds(path: Path | str, overrides: Sequence[str] = ()) -> list[str]:
    """The `type` of each object of a scene file, in order (for `relief_to_mesh`, which
    needs to know which objects are reliefs; the scene itself keeps only triangles)."""
    scene = load_scene(path, overrides)  # validates everything first
    del scene
    text = read_regular_file(path, MAX_SCENE_BYTES).decode("utf-8")
    root = compose(text, "", mark_where(str(path)), str(path))
    for override in ([overrides] if isinstance(overrides, str) else overrides):
        apply_override(root, override)
    objects = root.value.get("objects")
    return [item.value["type"].value for item in objects.value] if objects is not None else []
