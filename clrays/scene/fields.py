"""The scene format's keys, written once: the type, default, range and choices of each.

`clrays.scene.load` reads its limits, defaults and choices from these tables, and
`tools/scene_format_doc.py` writes the reference tables of docs/scene-format.md from
them, so the loader and its documentation cannot drift apart. Defaults of keys that
have a field in `clrays.scene.model` are that model's defaults.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..exposure import EV_LIMIT
from .animation import EASINGS
from .limits import MAX_LIGHTS, MAX_MESH_BYTES, MAX_OBJECTS, MAX_SCENE_BYTES, MAX_TRIANGLES
from .costs import (FULL_SHADOW_MAP_DIAGONAL, INITIAL_SAMPLES_PER_LINE, MAX_GAMMA_SAMPLES, MAX_INITIAL_STEP, MAX_LINE_SAMPLES,
                    MAX_OCCLUDER_SHADOW_MAP, MAX_SHADOW_MAP, MAX_SLICES, MAX_TEXTURE_GAMMA_SAMPLES, MAX_TEXTURE_SLICES,
                    MIN_GAMMA_SAMPLES, MIN_INITIAL_STEP, MIN_LINE_SAMPLES, MIN_SHADOW_MAP, MIN_SLICES,
                    OCCLUDER_MAP_GROWTH, OCCLUDER_TEXELS)
from .model import (INTEGRAND_MODES, METHODS, NORMALS, RELIEF_MODES, RENAMED_METHODS, RENAMED_TRANSPARENCY_TYPES,
                    SAMPLINGS, SHADOW_FILTERS, SHAFT_EDGES, STEP_SPACINGS, SURFACE_SHADOWS, TEXTURE_WRAPS, TRANSPARENCY_TYPES, TRANSPARENCY_WARPS, TRAVERSALS, Camera,
                    DirectionalLight, Image, Render, ShadowFilter, Transparency)
from .textures import MAX_SCENE_TEXTURE_TEXELS, MAX_TEXTURE_SIDE

FORMAT_VERSION = 1
MAX_IMAGE_PIXELS = 1 << 26
#: Largest light power accepted: beyond it float32 radiance on the device overflows.
MAX_POWER = 1e30
QUATERNION_TOLERANCE = 1e-6  # how far from 1 a rotation quaternion's norm may be


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


#: The default of a key that must be written.
REQUIRED: Any = _Required()


@dataclass(frozen=True)
class Field:
    """One key: its type as the docs name it, its default (REQUIRED when it must be
    written, None when leaving it out means more than a value, which `shown_default`
    then says), its numeric range (inclusive unless open), its choices, and words for
    the docs: a `rule` the range column adds, and `notes`."""

    key: str
    type: str
    default: Any = None
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] = ()
    rule: str = ""
    shown_default: str = ""
    notes: str = ""
    read_by: tuple[str, ...] = ()  # render keys: the methods that read it (empty: every method)
    renamed: tuple[tuple[str, str], ...] = ()  # choices: (former name, the choice it reads as)

    @property
    def required(self) -> bool:
        return self.default is REQUIRED


@dataclass(frozen=True)
class Section:
    """The keys of one mapping of the format. `name` is the dotted path the docs' markers
    use (`render`, `lights.spot`); a typed mapping (a light, an object, a phase) also has
    a `type` key naming `kind`, not listed in `fields`. `rules` are constraints across
    keys, in words for the docs."""

    name: str
    fields: tuple[Field, ...]
    kind: str = ""
    rules: tuple[str, ...] = ()

    def __getitem__(self, key: str) -> Field:
        return next(field for field in self.fields if field.key == key)

    @property
    def required(self) -> tuple[str, ...]:
        return tuple(field.key for field in self.fields if field.required)

    @property
    def optional(self) -> tuple[str, ...]:
        return tuple(field.key for field in self.fields if not field.required)


def _typed(group: str, kinds: dict[str, tuple[Field, ...]]) -> dict[str, Section]:
    return {kind: Section(f"{group}.{kind}", fields, kind) for kind, fields in kinds.items()}


def kinds(sections: dict[str, Section]) -> dict[str, tuple[tuple[str, ...], tuple[str, ...]]]:
    """type -> (required keys, optional keys) of a typed group, as the loader checks them."""
    return {kind: (section.required, section.optional) for kind, section in sections.items()}


TOP = Section("top", (
    Field("version", "integer", REQUIRED, notes=f"must be `{FORMAT_VERSION}` (checked before anything else)"),
    Field("image", "mapping", REQUIRED, notes="[image](#image)"),
    Field("camera", "mapping", REQUIRED, notes="[camera](#camera); optional with `gltf`"),
    Field("lights", "list of mappings", REQUIRED, notes=f"1 to {MAX_LIGHTS} lights; [lights](#lights); optional "
                                                        f"with `gltf`"),
    Field("medium", "mapping", shown_default="no medium: σs = σa = 0, isotropic",
          notes="[medium](#medium); with `gltf`, the default fog ([glTF](#gltf-20-scenes))"),
    Field("background", "RGB", 0.0, low=0.0, notes="radiance of rays that leave the scene"),
    Field("objects", "list of mappings", shown_default="`[]`", notes=f"at most {MAX_OBJECTS}; [objects](#objects)"),
    Field("render", "mapping", shown_default="all defaults", notes="[render](#render)"),
    Field("animation", "mapping", shown_default="a still scene (one frame, 0)", notes="[animation](#animation)"),
    Field("gltf", "mapping", shown_default="none", notes="a glTF file's meshes, lights, camera and animation; "
                                                         "[glTF](#gltf-20-scenes)"),
), rules=(f"The file is a regular file of at most {MAX_SCENE_BYTES >> 20} MiB, with at most {MAX_LIGHTS} lights, "
          f"{MAX_OBJECTS} objects and {MAX_TRIANGLES} triangles in all (spheres and planes counted before they "
          f"are tessellated): each light keeps its own shadow maps and min-max tree, and large geometry "
          f"belongs in a mesh file ([docs/limits.md](limits.md)).",))

IMAGE = Section("image", (
    Field("width", "integer", REQUIRED, 1, 16384, notes="pixels"),
    Field("height", "integer", REQUIRED, 1, 16384, notes="pixels"),
    Field("spp", "integer", Image.spp, 1, 4096, notes="samples per pixel"),
), rules=(f"`width * height` must be at most {MAX_IMAGE_PIXELS} pixels.",))

CAMERA = Section("camera", (
    Field("position", "vec3", REQUIRED, notes="scene units"),
    Field("look_at", "vec3", REQUIRED, rule="≠ `position`", notes="scene units"),
    Field("up", "direction", (0, 1, 0), rule="not parallel to `look_at - position` (normalised on load)"),
    Field("fov_deg", "number", Camera.fov_deg, 0.0, 180.0, low_open=True, high_open=True,
          notes="degrees, vertical field of view"),
    Field("far", "number", Camera.far, 0.0, low_open=True,
          notes="scene units; a ray that hits nothing runs through the medium this far"),
    Field("near", "number", Camera.near, 0.0, rule="< `far`",
          notes="scene units along the view axis: each camera ray starts where it crosses the plane this far "
                "in front of the eye (near / cos θ along a ray at θ to the view axis), as Blender's Clip Start, "
                "and the fog and its attenuation begin there. With `gltf`, the file camera's `znear` unless "
                "set; there a `camera` of `near` alone keeps the file's camera (`--set camera.near=0`)"),
))

_POSITION = Field("position", "vec3", REQUIRED, notes="scene units")
_TEXTURE_FILE = (f"`.png` (sRGB, decoded to linear), `.exr` or `.npy` (linear, shape (H, W) or (H, W, 3)), its "
                 f"content of the format its name says; sides of at most {MAX_TEXTURE_SIDE} texels, texels finite "
                 f"and >= 0, and at most {MAX_SCENE_TEXTURE_TEXELS} texels in all the lights' textures (a file "
                 f"that several lights name counts once); relative paths start at the YAML file's folder")
LIGHTS = _typed("lights", {
    "point": (
        _POSITION,
        Field("intensity", "RGB", REQUIRED, 0.0, MAX_POWER, notes="radiant intensity, W/sr"),
        Field("texture", "string or list of 6 strings", shown_default="none (white)",
              rule="six square images of one size, `[+x, -x, +y, -y, +z, -z]`, or one cross of 4 × 3 square "
                   "cells; files as for a spot's `texture`",
              notes="a cube texture around the light; its colour multiplies `intensity` per light ray "
                    "([docs/light-textures.md](light-textures.md#point-lights-a-cube))"),
    ),
    "spot": (
        _POSITION,
        Field("direction", "direction", REQUIRED, rule="normalised on load",
              notes="the cone's axis, the way light travels"),
        Field("cone_deg", "number", REQUIRED, 0.0, 90.0, low_open=True, notes="degrees, half-angle of the cone"),
        Field("intensity", "RGB", REQUIRED, 0.0, MAX_POWER, notes="W/sr inside the cone"),
        Field("texture", "string", shown_default="none (white)", rule=_TEXTURE_FILE,
              notes="a gobo: the image fills the square around the cone, its colour multiplies `intensity` per "
                    "light ray ([docs/light-textures.md](light-textures.md))"),
    ),
    "directional": (
        Field("direction", "direction", REQUIRED, rule="normalised on load",
              notes="the way light travels: `[0, -1, 0]` shines down"),
        Field("irradiance", "RGB", REQUIRED, 0.0, MAX_POWER, notes="W/m² on a surface facing the light"),
        Field("texture", "string", shown_default="none (white)", rule=_TEXTURE_FILE,
              notes="a cloud shadow or window pattern, projected along `direction` and centred on the world "
                    "origin; its colour multiplies `irradiance` per light ray "
                    "([docs/light-textures.md](light-textures.md))"),
        Field("texture_size", "`[w, h]`", DirectionalLight.texture_size, 0.0, low_open=True,
              rule="with `texture` only", notes="scene units covered by one copy of the texture"),
        Field("texture_wrap", "string", DirectionalLight.texture_wrap, choices=TEXTURE_WRAPS,
              rule="with `texture` only",
              notes="beyond one copy: `repeat` tiles it, `clamp` repeats its edge texels"),
    ),
})

MEDIUM = Section("medium", (
    Field("sigma_s", "RGB", 0.0, low=0.0, notes="scattering coefficient, 1 / scene unit"),
    Field("sigma_a", "RGB", 0.0, low=0.0, notes="absorption coefficient, 1 / scene unit"),
    Field("phase", "mapping", shown_default="`{type: isotropic}`", notes="phase function, below"),
    Field("bounds", "mapping", shown_default="everywhere",
          notes="`{min: vec3, max: vec3}`: the medium exists only inside this box; with `gltf`, "
                "`{object: NAME}` takes the box of a mesh node ([bounds and density](#bounds-and-density))"),
    Field("density", "mapping", shown_default="1 everywhere",
          notes="a factor on `sigma_s` and `sigma_a`: `height`, `grid` or `noise` ([bounds and density]"
                "(#bounds-and-density))"),
))

#: `medium.bounds` and a density grid's `bounds`: an axis-aligned box.
BOX = Section("medium.bounds", (
    Field("min", "vec3", REQUIRED, notes="scene units"),
    Field("max", "vec3", REQUIRED, rule="greater than `min` on every axis", notes="scene units"),
))

#: `medium.bounds` from a glTF file: a fog volume's mesh node (Blender's cube of a volume-only material).
VOLUME_OBJECT = Section("medium.bounds.object", (
    Field("object", "string", REQUIRED, rule="one mesh node of this name in the `gltf` file, not animated",
          notes="the box around its mesh (world space) bounds the medium; the node is no geometry"),
))

#: The noise grid's voxels along x, y and z when `resolution` is left out.
NOISE_RESOLUTION = (64, 64, 64)

DENSITIES = _typed("medium.density", {
    "height": (
        Field("base", "number", REQUIRED, notes="the height y where the factor is 1, scene units"),
        Field("scale_height", "number", REQUIRED, 0.0, low_open=True,
              notes="scene units: the factor exp(−(y − base)/scale_height) falls by e per this rise"),
    ),
    "grid": (
        Field("file", "string", REQUIRED, rule="`.npy` of axes z, y, x (`.vdb`/`.nvdb` with the `vdb` extra); "
                                               "finite, ≥ 0",
              notes="relative paths start at the YAML file's folder"),
        Field("bounds", "mapping", REQUIRED, notes="`{min, max}`: the box the grid fills; 0 outside it"),
        Field("offset", "vec3", (0.0, 0.0, 0.0), notes="scene units: moves the grid; animatable, so fog drifts"),
    ),
    "noise": (
        Field("bounds", "mapping", REQUIRED, notes="`{min, max}`: the box the baked noise fills; 0 outside it"),
        Field("frequency", "number", 1.0, 0.0, low_open=True, notes="cycles per scene unit of the first octave"),
        Field("octaves", "integer", 4, 1, 12, notes="fBm octaves, each twice the frequency of the one before"),
        Field("seed", "integer", 0, 0, 2 ** 31 - 1),
        Field("offset", "vec3", (0.0, 0.0, 0.0),
              notes="scene units: where in the noise the box samples; animatable (baked again per frame)"),
        Field("resolution", "`[nx, ny, nz]`", NOISE_RESOLUTION, 1, rule="integers; at most the grid's voxel limit "
              "in all", notes="voxels the noise is baked to along x, y, z"),
    ),
})

PHASES = _typed("medium.phase", {
    "isotropic": (),
    "hg": (Field("g", "number", REQUIRED, -1.0, 1.0, low_open=True, high_open=True,
                 notes="Henyey–Greenstein asymmetry: g > 0 scatters forward"),),
})

OBJECT = Section("objects", (
    Field("albedo", "RGB", 0.8, 0.0, 1.0, rule="per channel", notes="diffuse reflectance"),
    Field("opacity", "RGB", 1.0, 0.0, 1.0, rule="per channel",
          notes="1 is opaque; below 1 the surface reflects `opacity` of what an opaque one would and lets "
                "`1 − opacity` through, per channel, light included ([translucent objects](#translucent-objects))"),
    Field("transform", "mapping", shown_default="none",
          notes="[transform](#transform), applied to the object's local geometry"),
))

OBJECTS = _typed("objects", {
    "triangles": (
        Field("vertices", "list of vec3", REQUIRED, rule="at least 3"),
        Field("faces", "list of `[i, j, k]`", REQUIRED,
              rule="at least 1; integer indices into `vertices`, in [0, len(vertices) - 1]"),
    ),
    "plane": (
        Field("center", "vec3", REQUIRED, notes="scene units"),
        Field("normal", "direction", REQUIRED, notes="normalised; triangles face this way"),
        Field("size", "number", REQUIRED, 0.0, low_open=True, notes="side length, scene units"),
        Field("segments", "integer", 8, 1, 1024, notes="cells per side: 2 · segments² triangles"),
    ),
    "box": (
        Field("min", "vec3", REQUIRED),
        Field("max", "vec3", REQUIRED, rule="greater than `min` on every axis"),
    ),
    "sphere": (
        Field("center", "vec3", REQUIRED, notes="scene units"),
        Field("radius", "number", REQUIRED, 0.0, low_open=True, notes="scene units"),
        Field("segments", "integer", 48, 4, 1024, notes="slices around the y axis"),
    ),
    "mesh": (
        Field("file", "string", REQUIRED, rule=f"`.obj`, `.ply` or `.stl`, a regular file of at most "
                                               f"{MAX_MESH_BYTES >> 20} MiB",
              notes="relative paths start at the YAML file's folder (the working directory for "
                    "`parse_scene` without a source)"),
        Field("normals", "string", "smooth", choices=NORMALS,
              notes="shading: `smooth` interpolates vertex normals across each triangle, `flat` uses each "
                    "triangle's own normal ([below](#shading-normals))"),
    ),
    "relief": (
        Field("center", "vec3", REQUIRED, notes="scene units: the base rectangle's centre"),
        Field("normal", "direction", REQUIRED, notes="normalised; the relief rises this way"),
        Field("up", "direction", REQUIRED, rule="not parallel to `normal`",
              notes="the image's up (row 0 is its top edge), projected into the base plane"),
        Field("size", "`[w, h]`", REQUIRED, 0.0, low_open=True, rule="both",
              notes="the base rectangle along the image's rows and columns, scene units"),
        Field("depth_map", "string", REQUIRED,
              rule=f"`.png` (8- or 16-bit), `.exr` or `.npy`, its content of the format its name says, a regular "
                   f"file of at most {MAX_MESH_BYTES >> 20} MiB, at least 2 × 2 texels, finite",
              notes="displacement per texel, white (1) is full `height`; an alpha channel of 0 is a hole. "
                    "Relative paths start at the YAML file's folder"),
        Field("height", "number", REQUIRED, 0.0,
              notes="scene units along `normal` for depth 1; 0 is a flat quad (holes still cut)"),
        Field("albedo_map", "string", shown_default="`albedo` everywhere", rule="texels in [0, 1], as `albedo`",
              notes="colour per texel (`.png`, `.exr`, `.npy`), the depth map's size; its alpha, if any, "
                    "cuts holes too"),
    ),
})

TRANSFORM = Section("objects.transform", (
    Field("translate", "vec3", (0, 0, 0), notes="scene units"),
    Field("rotate", "mapping", shown_default="no rotation", notes="exactly one of the forms below"),
    Field("scale", "number or vec3", 1.0, 0.0, low_open=True, rule="every component",
          notes="a number scales uniformly"),
))

ROTATE = Section("objects.transform.rotate", (
    Field("axis", "direction", notes="axis–angle form, with `angle_deg`"),
    Field("angle_deg", "number", notes="axis–angle form: degrees about `axis`"),
    Field("euler_deg", "3 numbers", notes="Euler form: degrees about the axes of `order`"),
    Field("order", "string", "xyz", rule="3 letters over `xyz`, no two adjacent letters equal",
          notes="Euler form: intrinsic, R = R_{order[0]}(a0) · R_{order[1]}(a1) · R_{order[2]}(a2)"),
    Field("quaternion", "`[w, x, y, z]`", rule=f"unit: ‖q‖ within {QUATERNION_TOLERANCE:g} of 1",
          notes="quaternion form"),
), rules=("Exactly one form: `axis` with `angle_deg`, `euler_deg` (with `order` or not), or `quaternion`.",))

_RASTER_METHODS = ("minmax", "raymarch", "volume_moments")  # the methods with shadow maps; exact has none
_EPIPOLAR_METHODS = ("minmax", "volume_moments")  # the methods with a rectified texture and integrand tables

RENDER = Section("render", (
    Field("method", "string", Render.method, choices=METHODS, renamed=tuple(RENAMED_METHODS.items()),
          notes="volumetric integrator (docs/methods.md); `moments`, its former name, reads as `volume_moments`"),
    Field("steps", "integer", Render.steps, 1, 65536, notes="raymarch samples per pixel ray", read_by=("raymarch",)),
    Field("jitter", "boolean", Render.jitter, notes="raymarch: jitter sample positions (seeded per pixel)",
          read_by=("raymarch",)),
    Field("shadow_map", "integer", Render.shadow_map, 16, 8192,
          shown_default=f"from the image: 4 × its diagonal, as a power of two in [{MIN_SHADOW_MAP}, {MAX_SHADOW_MAP}], "
                        f"{MAX_SHADOW_MAP} from a diagonal of {FULL_SHADOW_MAP_DIAGONAL} pixels; "
                        f"larger where a closed solid seen from its light is under {OCCLUDER_TEXELS} texels wide "
                        f"(up to {OCCLUDER_MAP_GROWTH} × that and {MAX_OCCLUDER_SHADOW_MAP}; only the views that "
                        "hold it grow: `shadow_map_floor`)",
          notes="shadow map side in texels (cube maps: per face)", read_by=_RASTER_METHODS),
    Field("shadow_map_floor", "integer", Render.shadow_map_floor, 16, 8192,
          shown_default="`shadow_map` where the scene sets it, else the side the image derives",
          notes="side of a light's view (a cube face) that holds no closed solid under "
                f"{OCCLUDER_TEXELS} texels wide; the others grow, as a power of two, until it is, up to "
                "`shadow_map` (at most `shadow_map`)", read_by=_RASTER_METHODS),
    Field("surface_shadows", "string", Render.surface_shadows, choices=SURFACE_SHADOWS,
          notes="hard shadows on surfaces: `exact` casts a shadow ray (through a BVH) wherever the shadow map "
                "cannot decide and matches the `exact` reference; `map` is the shadow-map test alone; `pcf` "
                "filters it over `pcf` texels; `filtered` softens it as `shadow_filter` says. Setting only `pcf` > 0 "
                "implies `pcf`, setting only `shadow_filter` implies `filtered`", read_by=_RASTER_METHODS),
    Field("pcf", "integer", Render.pcf, 0, 16,
          notes="`surface_shadows: pcf`: filter radius in texels (0 = hard)", read_by=_RASTER_METHODS),
    Field("shadow_filter", "mapping or string", shown_default="`{type: msm_hamburger}` with `surface_shadows: "
                                                           "filtered`, else unused",
          notes="[render.shadow_filter](#rendershadow_filter): filtered surface shadows; a string is its `type`",
          read_by=_RASTER_METHODS),
    Field("slices", "integer", Render.slices, 16, 16384,
          shown_default=f"from the image: 4 × its perimeter or `shadow_map`, the smaller, as a power of two in "
                        f"[{MIN_SLICES}, {MAX_SLICES}]; up to {MAX_TEXTURE_SLICES} for a textured light "
                        "(one a texel)",
          notes="min-max: epipolar slices", read_by=_EPIPOLAR_METHODS),
    Field("gamma_samples", "integer", Render.gamma_samples, 16, 16384,
          shown_default=f"from the image: 8 × its diagonal or `shadow_map`, the smaller, as a power of two in "
                        f"[{MIN_GAMMA_SAMPLES}, {MAX_GAMMA_SAMPLES}]; up to {MAX_TEXTURE_GAMMA_SAMPLES} for a textured "
                        "light (one a texel)",
          notes="min-max: samples along each slice (rounded up to a power of two)", read_by=_EPIPOLAR_METHODS),
    Field("integrand", "string", Render.integrand, choices=INTEGRAND_MODES,
          notes="min-max: how the scattering integrand is evaluated ([docs/integrand.md](integrand.md)); "
                "`analytic` exists for directional lights only (a point light's closed form needs σt = 0)",
          read_by=_EPIPOLAR_METHODS),
    Field("svd_rank", "integer", Render.svd_rank, 1, 16,
          notes="min-max, `integrand: svd`: rank of the factorisation", read_by=_EPIPOLAR_METHODS),
    Field("traversal", "string", Render.traversal, choices=TRAVERSALS,
          notes="min-max: min-max tree traversal or a linear scan", read_by=("minmax",)),
    Field("sampling", "string", Render.sampling, choices=SAMPLINGS,
          notes="min-max: `epipolar` computes in-scattering at samples along each slice's line on the screen and "
                "interpolates it to the pixels, walking a pixel's own rays only where no sample lies at its "
                "distance (every pixel, for a light whose walks cut a relief: `shaft_edges`); `pixel` walks the "
                "two nearest slices' rows for every pixel sample ([docs/design.md](design.md) §4.5)",
          read_by=("minmax",)),
    Field("shaft_edges", "string", Render.shaft_edges, choices=SHAFT_EDGES,
          notes="min-max: `blockers` ends each lit run on the silhouette of the triangle the shadow map found "
                "there, in the ray's own plane, and cuts a relief's outline in that plane where the map would "
                "miss its holes (the lattice at 1280×720: 0.20 % against `exact`, 1.56 % from the map); "
                "`texels` at the texel boundary, as raymarch does: on the bench "
                "scenes at 1280×720 a frame 1.1–1.3 × faster for 1.3–4.7 × the error against `exact` "
                "([docs/design.md](design.md) §4.5, bench/RESULTS.md history, \"Shaft edges on the blockers\"); e.g. "
                "`--set render.shaft_edges=texels`", read_by=("minmax",)),
    Field("line_samples", "integer", Render.line_samples, 2, 16384,
          shown_default=f"from the image: half its diagonal in pixels, in [{MIN_LINE_SAMPLES}, {MAX_LINE_SAMPLES}]",
          notes="`sampling: epipolar`: samples along the slice's line that is longest on the screen; a "
                "shorter line gets as many as keep the same spacing on the screen (at least 2)", read_by=("minmax",)),
    Field("initial_step", "integer", Render.initial_step, 1, 1024,
          shown_default=f"from `line_samples`: a {INITIAL_SAMPLES_PER_LINE}th of them, in [{MIN_INITIAL_STEP}, "
                        f"{MAX_INITIAL_STEP}] (6 at 1280×720, 3 at 640×360)",
          notes="`sampling: epipolar`: every `initial_step`-th line sample is computed, and those beside a break; "
                "the others are interpolated along the line", read_by=("minmax",)),
    Field("refine_threshold", "number", Render.refine_threshold, 0.0, 1.0,
          notes="`sampling: epipolar`: neighbouring line samples whose camera distance (or a spot light's "
                "unshadowed in-scattering) differ by more than this fraction are a break, computed both; a pixel whose "
                "distance differs this much from its line samples' (and from the blend of its two lines', where "
                "those two agree) walks its own rays", read_by=("minmax",)),
    Field("relief", "string", Render.relief, choices=RELIEF_MODES,
          notes="how relief objects reach the depth maps: `prewarp` warps each relief's depth image for "
                "every view and maps it onto its base rectangle, `triangles` rasterizes its height-field "
                "triangles (the same surface, for comparison)", read_by=_RASTER_METHODS),
    Field("translucent_layers", "integer", Render.translucent_layers, 1, 16,
          notes="translucent objects: how many translucent surfaces each light's map keeps per texel, nearest "
                "the light first; along a light ray, those beyond that many let it through unattenuated "
                "([docs/design.md](design.md#translucent-occluders-the-light-side))", read_by=("minmax", "raymarch")),
    Field("transparency", "mapping or string", shown_default="`{type: gathered}`",
          notes="[render.transparency](#rendertransparency): how the camera composites "
                "[translucent objects](#translucent-objects); a string is its `type`. Read only where an "
                "object has `opacity` below 1", read_by=("minmax", "raymarch")),
    Field("step_spacing", "string", Render.step_spacing, choices=STEP_SPACINGS,
          notes="raymarch: where its `steps` lie along a ray, per point or spot light: `equiangular` at equal "
                "angles seen from the light, dense where the ray passes it, so the 1/d² peak of a light in view "
                "converges; `uniform` at equal distances (the marcher before equiangular steps). Directional "
                "lights always take uniform steps ([docs/design.md](design.md) §4.8)", read_by=("raymarch",)),
    Field("aovs", "list of strings", Render.aovs, shown_default="`[]`",
          notes="[render passes](#render-passes) written beside the image: `in_scatter`, `in_scatter_light<i>`, "
                "`transmittance`, `surface`, `depth` (also `--aov`); not with translucent objects"),
    Field("target_error", "number", Render.target_error, 0.0, 100.0, low_open=True, high_open=True,
          shown_default="none: the settings as written",
          notes="percent relative RMSE against `exact` (as `clrays bench` measures it): `render`, `sequence` and "
                "`sweep` render with the cheapest sizes and sampling settings within it, as `clrays tune` finds "
                "them (one search and one kept answer for both, in the cache). Where none is kept, they search "
                "only with `--tune`, state its cost first, and refuse a search past 15 s in one line (the command within 20 s): run "
                "`clrays tune` first"),
    Field("exposure", "number or `auto`", Render.exposure, -EV_LIMIT, EV_LIMIT,
          notes="stops for the 8-bit outputs (.png, and a sequence's .gif, .webp, .mp4): radiance × 2^EV before "
                "the sRGB curve; `auto` chooses them from the frame ([Exposure](#exposure)). `--exposure` "
                "overrides it; .exr and .npy keep linear radiance whatever it says"),
))


SHADOW_FILTER = Section("render.shadow_filter", (
    Field("type", "string", ShadowFilter.type, choices=SHADOW_FILTERS,
          notes="`hard`: the map's test (as `surface_shadows: map`); `pcf`: the test averaged over the "
                "(2·radius + 1)² texels around the receiver's; `vsm`: Chebyshev's bound from 2 prefiltered moments; "
                "`msm_hamburger`, `msm_hausdorff`: the 4-moment bound on ℝ or on [0, 1] "
                "([docs/design.md §9](design.md#9-filtered-surface-shadows))"),
    Field("radius", "integer", ShadowFilter.radius, 0, 16,
          notes="texels: the box of `pcf`, and the separable box blur of the moment maps"),
    Field("depth_bias", "number", ShadowFilter.depth_bias, 0.0, 64.0,
          notes="texels at the receiver's depth, taken off it before the test"),
    Field("moment_bias", "number", ShadowFilter.moment_bias, 0.0, 0.5,
          notes="`msm_*`: how far the moments are pulled towards those of depth 0.5; `vsm`: the least variance "
                "(normalised depth²). Measured in bench/RESULTS.md history"),
), rules=("With `shadow_filter` set, `surface_shadows` is `filtered` (or left out) and `pcf` is 0.",))

TRANSPARENCY = Section("render.transparency", (
    Field("type", "string", Transparency.type, choices=TRANSPARENCY_TYPES,
          renamed=tuple(RENAMED_TRANSPARENCY_TYPES.items()),
          notes="`depth_peeling`: the `layers` nearest translucent surfaces of each camera ray, composited in "
                "order; `gathered`: every one of them, gathered in no order, each weighted by the exact product "
                "of the (1 − α) in front of it; `mboit`: every one of them, composited with a transmittance "
                "reconstructed from 4 power moments of the absorbance, in no order "
                "(MBOIT; [docs/design.md](design.md#translucent-surfaces-the-camera-side); `moments`, its former "
                "name, reads as `mboit`). Left out, the keys given name it (`layers`: depth_peeling; `warp`, "
                "`moment_bias`: mboit); a key the type does not read is an error"),
    Field("layers", "integer", Transparency.layers, 1, 64,
          notes="`depth_peeling`: layers composited; surfaces behind the last are left out"),
    Field("warp", "string", Transparency.warp, choices=TRANSPARENCY_WARPS,
          notes="`mboit`: the depth coordinate of the moments, linear or logarithmic between the nearest and "
                "the farthest distance of the translucent objects from the camera"),
    Field("moment_bias", "number", Transparency.moment_bias, 0.0, 0.5,
          notes="`mboit`: how far the normalised moments are pulled towards those of depth 0.5. "
                "Measured in bench/RESULTS.md history"),
))


def unread_render_keys(render: Render, method: str) -> list[str]:
    """The `render` keys set away from their default that `method` does not read (the
    `read_by` of RENDER's fields), as `render.KEY = VALUE (read by ...)`."""
    unread = []
    for field in RENDER.fields:
        value = getattr(render, field.key)
        if field.read_by and method not in field.read_by and value != field.default:
            unread.append(f"render.{field.key} = {value} (read by {' and '.join(field.read_by)} only)")
    return unread


ANIMATION = Section("animation", (
    Field("frames", "`[first, last]`", REQUIRED, 0, 100_000, rule="integers, first ≤ last",
          notes="the frames the sequence renders, both inclusive"),
    Field("fps", "number", 24.0, 0.0, 1000.0, low_open=True,
          notes="frames per second: the animation's speed in `--video` output"),
    Field("easing", "string", "linear", choices=tuple(EASINGS),
          notes="every key's easing unless the key sets its own"),
    Field("camera", "list of keys", notes="keys of `position`, `look_at`, `up`, `orientation`, `fov_deg`"),
    Field("lights", "list of `{light: i, keys: [...]}`",
          notes="`i` indexes `lights`; keys of that light's own fields (below)"),
    Field("objects", "list of `{object: i, keys: [...]}`",
          notes="`i` indexes `objects`; keys of `translate`, `rotate`, `scale`"),
    Field("medium", "list of keys", notes="keys of `sigma_s`, `sigma_a`, `g`, `offset`"),
))

GLTF = Section("gltf", (
    Field("file", "string", REQUIRED, notes="a `.glb` or `.gltf` file; a relative path starts at the YAML file's "
                                            "folder"),
    Field("camera", "string", shown_default="the first camera", notes="the name of the camera (or of its node) "
          "to look through, or its index among the cameras the scene's nodes place, in node order; "
          "`--camera NAME` or `--camera INDEX` sets it"),
    Field("light_scale", "number", 1.0, 0.0, MAX_POWER, notes="multiplies every imported light's power "
          "(`intensity` / 683 lm/W × `color`: cd to W/sr, lux to W/m²)"),
    Field("fps", "number", 24.0, 0.0, 1000.0, low_open=True,
          notes="frames per second of the file's animation: frame f is at f / fps seconds"),
))

#: Every section, by the name the docs' markers use, in the order of the format.
SECTIONS: dict[str, Section] = {section.name: section for section in (
    TOP, IMAGE, CAMERA, *LIGHTS.values(), MEDIUM, *PHASES.values(), BOX, VOLUME_OBJECT, *DENSITIES.values(), OBJECT,
    *OBJECTS.values(), TRANSFORM, ROTATE, RENDER, SHADOW_FILTER, TRANSPARENCY, ANIMATION, GLTF)}
