"""The scene model: frozen, typed, validated objects built from a YAML file.

Vectors are float64 numpy arrays of shape (3,); colours are RGB arrays of shape (3,)
(a scalar in the file is broadcast to RGB). Geometry is flattened into one triangle
list at load time so every method (raster, raymarch, exact, minmax) sees the same
triangles.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Protocol, Union

import numpy as np

from .geometry import flat_normals

Vec3 = np.ndarray
RGB = np.ndarray

#: The choices of the scene's enumerated fields, written once: the loader, the command
#: line, the session and the docs read them from here.
METHODS = ("minmax", "raymarch", "exact", "volume_moments")
INTEGRAND_MODES = ("table", "svd", "analytic")
TRAVERSALS = ("tree", "scan")
# min-max: in-scattering at samples along epipolar lines, interpolated; or walked for every camera sample.
SAMPLINGS = ("epipolar", "pixel")
#: render.shaft_edges: where a lit run ends (cl/shaft_edges.h)
SHAFT_EDGES = ("blockers", "texels")
# raymarch: steps at equal angles seen from a point or spot light (dense where the ray passes
# it), or at equal distances along the ray. Directional lights always take uniform steps.
STEP_SPACINGS = ("equiangular", "uniform")
# Hard surface shadows: shadow rays where the map cannot decide, the map alone, or the map filtered.
SURFACE_SHADOWS = ("exact", "map", "pcf", "filtered")  # filtered: `render.shadow_filter` decides
TEXTURE_WRAPS = ("repeat", "clamp")  # a directional light's texture beyond its first tile
# Filtered surface shadows (`render.shadow_filter.type`, docs/design.md §9): the map's test, PCF, or a
# reconstruction from prefiltered moments (2 for VSM, 4 for the moment shadow maps).
SHADOW_FILTERS = ("hard", "pcf", "vsm", "msm_hamburger", "msm_hausdorff")
# Translucent surfaces seen by the camera (`render.transparency.type`, docs/design.md, translucent
# surfaces: the camera side): the K nearest layers in order; every layer gathered in no order, with
# the exact transmittance of the list; or moment-based order-independent transparency (MBOIT).
TRANSPARENCY_TYPES = ("depth_peeling", "gathered", "mboit")
TRANSPARENCY_WARPS = ("none", "log")  # MBOIT's depth warp before the moments are taken
PHASE_TYPES = ("isotropic", "hg")
NORMALS = ("smooth", "flat")  # a mesh's shading normals: interpolated vertex normals, or each face's own
# How the raster stage draws relief objects: by their pre-warp, or as their triangles (the same surface).
RELIEF_MODES = ("prewarp", "triangles")
# "moments" named three features: each has its own name now (the volume method volume_moments,
# the camera's MBOIT transparency mboit, the moment shadow maps of render.shadow_filter). The
# old name still reads as before where it was accepted.
RENAMED_METHODS = {"moments": "volume_moments"}
RENAMED_TRANSPARENCY_TYPES = {"moments": "mboit"}


@dataclass(frozen=True)
class Image:
    width: int
    height: int
    spp: int = 1


@dataclass(frozen=True)
class Camera:
    position: Vec3
    look_at: Vec3
    up: Vec3
    fov_deg: float = 50.0  # vertical field of view
    far: float = 1000.0  # a ray that hits nothing runs through the medium to here
    # Camera rays start this far from the eye along the view axis (t0 = near / cos θ), as Cycles'
    # Clip Start: the fog begins there (docs/scene-format.md, camera).
    near: float = 0.0


@dataclass(frozen=True, eq=False)
class LightTexture:
    """A light's texture (docs/light-textures.md): linear RGB texels that multiply the
    light's power per light ray. Row 0 is the image's top. Compared by identity (the
    scene digest reads the digest of the texels, `digest_parts`). Lights that name one
    file share one texels array (clrays.scene.textures.TextureCache), read-only."""

    texels: np.ndarray  # (H, W, 3) float32, finite, >= 0
    file: str  # as written in the scene, for messages
    #: True for a texture that varies slowly across its texels (a glTF spot's cone falloff):
    #: the sizes derived for a textured light need not resolve each texel (scene/costs.py).
    smooth: bool = False

    def __post_init__(self):
        self.texels.flags.writeable = False  # shared between lights, and digested once

    def digest_parts(self) -> tuple:
        """What clrays.digest reads of it: the file and its texels' digest, made once per
        texels array (every stage key holds the lights: 16 lights sharing a 4096² texture
        hashed 200 MB about 120 times a frame, 54 s)."""
        return self.file, _texels_digest(self.texels)

    @property
    def width(self) -> int:
        return int(self.texels.shape[1])

    @property
    def height(self) -> int:
        return int(self.texels.shape[0])


#: id(texels) -> (a weak reference to the array, its digest): `LightTexture.digest_parts`.
_TEXEL_DIGESTS: dict[int, tuple[weakref.ref, bytes]] = {}


def _texels_digest(texels: np.ndarray) -> bytes:
    key = id(texels)
    known = _TEXEL_DIGESTS.get(key)
    if known is not None and known[0]() is texels:
        return known[1]
    from ..digest import digest

    value = digest(texels)
    _TEXEL_DIGESTS[key] = (weakref.ref(texels, lambda _, key=key: _TEXEL_DIGESTS.pop(key, None)), value)
    return value


@dataclass(frozen=True)
class PointLight:
    position: Vec3
    intensity: RGB  # radiant intensity, W/sr
    type: Literal["point"] = "point"
    texture: LightTexture | None = None  # a cube: six square faces stacked in rows, +x, -x, +y, -y, +z, -z


@dataclass(frozen=True)
class SpotLight:
    position: Vec3
    direction: Vec3  # unit, the cone's axis (direction light travels)
    cone_deg: float  # half-angle, hard edge, in (0, 90]
    intensity: RGB
    type: Literal["spot"] = "spot"
    texture: LightTexture | None = None  # projected over the cone, filling the square around it


@dataclass(frozen=True)
class DirectionalLight:
    direction: Vec3  # unit, the direction light travels (e.g. [0, -1, 0] shines down)
    irradiance: RGB
    type: Literal["directional"] = "directional"
    texture: LightTexture | None = None  # projected along `direction`, centred on the world origin
    texture_size: tuple[float, float] = (1.0, 1.0)  # one tile's width and height, scene units
    texture_wrap: str = "repeat"  # one of TEXTURE_WRAPS


Light = Union[PointLight, SpotLight, DirectionalLight]


@dataclass(frozen=True)
class Phase:
    type: str = "isotropic"  # one of PHASE_TYPES
    g: float = 0.0  # Henyey-Greenstein asymmetry, in (-1, 1)


@dataclass(frozen=True)
class Box:
    """An axis-aligned box, `min` ≤ `max` per axis (scene units)."""

    min: Vec3
    max: Vec3


@dataclass(frozen=True)
class HeightDensity:
    """`medium.density: {type: height}`: exp(−(y − base)/scale_height), y up."""

    base: float
    scale_height: float  # > 0, scene units
    type: Literal["height"] = "height"


@dataclass(frozen=True)
class GridDensity:
    """`medium.density: {type: grid}` (and `noise`, baked to a grid): a dense grid of density
    factors, float32 (nz, ny, nx), finite and ≥ 0, over the box `bounds`; trilinear between
    voxel centres, 0 outside `bounds`."""

    values: np.ndarray
    bounds: Box
    type: Literal["grid"] = "grid"


Density = Union[HeightDensity, GridDensity]


@dataclass(frozen=True)
class Medium:
    sigma_s: RGB  # scattering coefficient, 1/unit
    sigma_a: RGB  # absorption coefficient, 1/unit
    phase: Phase = field(default_factory=Phase)
    # Where the medium is: everywhere (None) or inside a box. Its density: a factor on σs
    # and σa, 1 everywhere (None) or a HeightDensity / GridDensity.
    bounds: Box | None = None
    density: Density | None = None

    @property
    def homogeneous(self) -> bool:
        """One constant σ everywhere: the kernels and tables of the unbounded medium."""
        return self.bounds is None and self.density is None

    @property
    def sigma_t(self) -> RGB:
        return self.sigma_s + self.sigma_a


@dataclass(frozen=True)
class ShadowFilter:
    """`render.shadow_filter`: how `surface_shadows: filtered` softens the shadow map."""

    type: str = "msm_hamburger"  # one of SHADOW_FILTERS
    radius: int = 2  # texels: the (2·radius + 1)² box of PCF, and of the moment maps' prefilter
    depth_bias: float = 1.5  # texels (at the receiver's depth), taken off the receiver's depth
    # msm: weight pulling the moments towards 0.5; vsm: the least variance. The smallest that keeps the
    # float32 reconstruction within 1e-3 of its bound (bench/RESULTS.md history, "Filtered surface shadows").
    moment_bias: float = 3e-6


@dataclass(frozen=True)
class Transparency:
    """`render.transparency`: how the camera composites translucent surfaces (docs/design.md,
    translucent surfaces: the camera side)."""

    # The gathered list by default: on glass_row as accurate as 8-layer peeling and as fast as MBOIT
    # (its fog is one walk per pixel, peeling's one per film), where MBOIT's 4-moment estimate of
    # the transmittance costs 1 % (bench/RESULTS.md history, docs/design.md).
    type: str = "gathered"  # one of TRANSPARENCY_TYPES
    # The nearest layers composited; those behind them are dropped. Peeling stops where no sample
    # finds another layer, so a frame with fewer films pays for those only.
    layers: int = 8
    warp: str = "log"  # mboit: one of TRANSPARENCY_WARPS
    # mboit: weight pulling the normalised moments towards those of depth 0.5 (cl/moments.h),
    # measured on scenes/glass_row.yaml (bench/RESULTS.md history, "Translucent objects: the camera side").
    moment_bias: float = 5e-3


@dataclass(frozen=True)
class Render:
    method: str = "minmax"  # one of METHODS
    steps: int = 256  # raymarch samples per pixel
    jitter: bool = False  # raymarch: jitter sample positions (seeded per pixel)
    # Sizes left None are derived from the image when a frame is rendered (clrays.scene.costs).
    shadow_map: int | None = None  # shadow map side, texels (cube maps: per face)
    # the side of a light's view (a cube face) that holds no solid thinner than the map resolves;
    # the others grow up to shadow_map (clrays.scene.costs.view_map_sides)
    shadow_map_floor: int | None = None
    surface_shadows: str = "exact"  # one of SURFACE_SHADOWS
    pcf: int = 0  # surface_shadows `pcf`: filter radius in texels
    shadow_filter: ShadowFilter | None = None  # surface_shadows `filtered`: None until it is set
    # min-max method
    slices: int | None = None  # epipolar slices
    gamma_samples: int | None = None  # γ texels per slice
    integrand: str = "table"  # one of INTEGRAND_MODES
    svd_rank: int = 4
    traversal: str = "tree"  # one of TRAVERSALS
    sampling: str = "epipolar"  # one of SAMPLINGS
    shaft_edges: str = "blockers"  # one of SHAFT_EDGES
    line_samples: int | None = None  # epipolar: samples along each slice's line
    initial_step: int | None = None  # epipolar: every initial_step-th line sample walks its row
    # epipolar: relative change in distance (a spot light's: or unshadowed radiance) that is a break
    refine_threshold: float = 0.02
    relief: str = "prewarp"  # one of RELIEF_MODES
    translucent_layers: int = 4  # translucent surfaces per light texel, nearest the light first
    transparency: Transparency | None = None  # translucent surfaces: None takes Transparency()'s defaults
    step_spacing: str = "equiangular"  # raymarch: one of STEP_SPACINGS
    aovs: tuple[str, ...] = ()  # render passes (clrays.passes): none unless asked for
    # Percent relative RMSE against `exact` to tune the settings for (clrays.runs.tune); None: as written.
    target_error: float | None = None
    # 8-bit outputs: stops (radiance × 2^EV before the sRGB curve), or "auto" (clrays.exposure).
    exposure: float | str = 0.0


@dataclass(frozen=True)
class Geometry:
    """All objects, flattened. Triangle t has vertices triangles[t] (3, 3), albedo albedo[t],
    and the shading normal normals[t, i] at its vertex i; where smooth[t] the renderer
    interpolates those across the triangle, elsewhere it shades with the face normal
    (which flat triangles also hold at every vertex)."""

    triangles: np.ndarray  # (T, 3, 3) float64, world space
    albedo: np.ndarray  # (T, 3) float64, RGB in [0, 1]
    object_id: np.ndarray  # (T,) int32, index into Scene.objects order
    normals: np.ndarray = None  # (T, 3, 3) float64, world space, unit; None: the face normals
    smooth: np.ndarray = None  # (T,) bool; None: no triangle is smooth
    # The relief objects among them (clrays.scene.relief.ReliefRecord): their rows and texels.
    reliefs: tuple = ()
    # (T, 3) float64 per-channel opacity in [0, 1] (docs/scene-format.md, translucent objects);
    # None when every triangle is opaque, which is the fast opaque-only path.
    opacity: np.ndarray | None = None
    # (T,) int8: +1 or -1 where the triangle belongs to a closed, opaque solid, whose outside
    # (b - a) x (c - a) times it points to; 0 elsewhere (a plane, a relief, an open or
    # translucent surface). The views that see a solid from outside skip the faces it turns
    # away (docs/design.md §4.1, "Back faces of closed solids"). None: no solids.
    outward: np.ndarray | None = None
    # (T,) int32: a label per convex part, the same on the triangles of a plane, a box or a
    # sphere (each a convex polyhedron; a box's and a sphere's with CONVEX_OUTSIDE_ONLY),
    # else each triangle's own (its index at loading). No triangle of a convex part can
    # shadow a point of the part that faces the light (a solid's: from outside), which the
    # writer map uses (docs/design.md §4.6). None: every triangle its own part.
    convex_part: np.ndarray | None = None

    def __post_init__(self):
        if self.outward is None:
            object.__setattr__(self, "outward", np.zeros(len(self.triangles), dtype=np.int8))
        if self.convex_part is None:
            object.__setattr__(self, "convex_part", np.arange(len(self.triangles), dtype=np.int32))
        if self.normals is None:
            object.__setattr__(self, "normals", flat_normals(self.triangles))
        if self.smooth is None:
            object.__setattr__(self, "smooth", np.zeros(len(self.triangles), dtype=bool))

    @property
    def count(self) -> int:
        return int(self.triangles.shape[0])

    @property
    def translucent(self) -> bool:
        """Whether any triangle lets light through."""
        return self.opacity is not None

    def opacity_or_ones(self) -> np.ndarray:
        """(T, 3) per-channel opacity, ones for an opaque-only scene."""
        return np.ones((self.count, 3)) if self.opacity is None else self.opacity

    def _memo(self) -> dict:
        """Per-instance results of the passes over every vertex below: a frame asks for them
        several times (frame inputs, scene size, far, the lamp), and a mesh's vertices cost
        milliseconds a pass. The arrays are not changed after construction (`replace` makes
        a new Geometry, with an empty memo)."""
        memo = self.__dict__.get("_vertex_memo")
        if memo is None:
            memo = {}
            object.__setattr__(self, "_vertex_memo", memo)
        return memo

    def kept(self, key, compute, most: int | None = None):
        """compute()'s result, computed once per `key` for this geometry: arrays derived from
        it that frames ask for again (clrays.inputs), which must not be changed. With `most`,
        at most that many results of keys beginning with key[0] are kept, the oldest dropped
        first (a light that moves every frame would otherwise keep one per frame)."""
        memo = self._memo()
        if key not in memo:
            if most is not None:
                kin = [k for k in memo if isinstance(k, tuple) and k[:1] == key[:1]]
                for old in kin[:max(len(kin) - most + 1, 0)]:
                    del memo[old]
            memo[key] = compute()
        return memo[key]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds (lo, hi); a unit box at the origin when there are no triangles.
        A relief's part comes from its texels (clrays.scene.relief_frame), not its triangles."""
        memo = self._memo()
        if "bounds" not in memo:
            memo["bounds"] = self._bounds()
        lo, hi = memo["bounds"]
        return lo.copy(), hi.copy()

    def _bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if self.count == 0:
            return np.full(3, -1.0), np.full(3, 1.0)
        if not self.reliefs:
            pts = self.triangles.reshape(-1, 3)
            return pts.min(axis=0), pts.max(axis=0)
        from .relief_frame import other_rows, relief_bounds

        parts = [relief_bounds(record, self.triangles) for record in self.reliefs]
        parts += [(pts.min(axis=0), pts.max(axis=0)) for rows in other_rows(self.count, self.reliefs)
                  for pts in [self.triangles[rows].reshape(-1, 3)]]
        return np.min([lo for lo, _ in parts], axis=0), np.max([hi for _, hi in parts], axis=0)

    def inside_a_solid(self, point) -> bool:
        """Whether `point` lies inside one of the closed solids (`outward`), or too near a
        solid's surface to tell: a view from there may not skip their back faces. Outside a
        solid's box is outside it; inside the box, its winding number decides: the solid
        angle its triangles span seen from `point` over 4π (Van Oosterom and Strackee's
        formula), 0 outside, ±1 inside, ±1/2 on the surface."""
        return bool((np.abs(self.solid_windings(point)) >= 0.25).any())

    def solid_windings(self, point) -> np.ndarray:
        """(S,) the winding number of each closed solid (`outward`) around `point`: 0 outside
        (and outside the solid's box), ±1 inside, ±1/2 on the surface."""
        point = np.asarray(point, dtype=np.float64)
        solids, lo, hi = self.kept(("solids",), self._solids)
        windings = np.zeros(len(solids))
        margin = 1e-6 * np.max(hi - lo, axis=1, keepdims=True) if len(solids) else 0.0
        near = np.flatnonzero(np.all((point >= lo - margin) & (point <= hi + margin), axis=1))
        for k in near:
            a, b, c = (self.triangles[solids[k], i] - point for i in range(3))
            la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
            det = np.einsum("ij,ij->i", a, np.cross(b, c))
            div = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la \
                + np.einsum("ij,ij->i", c, a) * lb
            windings[k] = 2.0 * np.arctan2(det, div).sum() / (4.0 * np.pi)
        return windings

    def solid_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi), each (S, 3): the box of each closed solid (`outward`)."""
        _, lo, hi = self.kept(("solids",), self._solids)
        return lo, hi

    def _solids(self) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
        """The closed solids: each one's triangles' rows, and their bounds lo, hi (S, 3)."""
        rows = np.flatnonzero(self.outward != 0)
        if not len(rows):
            return [], np.zeros((0, 3)), np.zeros((0, 3))
        rows = rows[np.argsort(self.object_id[rows], kind="stable")]  # each object's rows together
        starts = np.flatnonzero(np.diff(self.object_id[rows], prepend=-1))
        corners = self.triangles[rows]  # (rows, 3, 3)
        lo = np.minimum.reduceat(corners.min(axis=1), starts)
        hi = np.maximum.reduceat(corners.max(axis=1), starts)
        return np.split(rows, starts[1:]), lo, hi

    def farthest_from(self, point) -> float:
        """Distance from `point` to the farthest triangle vertex (0 without triangles); a
        relief's part from its texels, as `bounds`. Kept for the last point asked (the eye)."""
        point = np.asarray(point, dtype=np.float64)
        memo, key = self._memo(), point.tobytes()
        if memo.get("farthest_from") != key:
            memo["farthest"] = self._farthest_from(point)
            memo["farthest_from"] = key
        return memo["farthest"]

    def _farthest_from(self, point: np.ndarray) -> float:
        if not self.reliefs:
            return float(np.sqrt(_farthest_squared(self.triangles.reshape(-1, 3), point, self.kept)))
        from .relief_frame import other_rows, relief_farthest

        squared = [relief_farthest(record, self.triangles, point) for record in self.reliefs]
        squared += [float(((self.triangles[rows].reshape(-1, 3) - point) ** 2).sum(axis=1).max())
                    for rows in other_rows(self.count, self.reliefs)]
        return float(np.sqrt(max(squared)))


class Keyframes(Protocol):
    """What a scene's animation is to the scene: clrays.scene.animation.Animation, which
    builds on this module (so this one names it only by what it offers)."""

    fps: float
    first: int
    last: int

    @property
    def frames(self) -> range: ...

    def scene_at(self, scene: Scene, frame: float) -> Scene: ...


#: Vertices per box of `_farthest_squared`'s test.
FARTHEST_BLOCK = 64


def _farthest_squared(corners: np.ndarray, point: np.ndarray, kept) -> float:
    """The largest ((v − point)²).sum() over the rows v of `corners` (0 for none), the same
    bits as over every row, but only over the blocks of FARTHEST_BLOCK rows whose box's
    farthest corner is as far as some block's first row: a camera pan over a million
    triangles asks once a frame (0.1–0.6 s a frame over all 3 M corners). Rounding keeps the
    order: a box's corner is no nearer in float than any row inside it. `kept`: the
    geometry's `kept`, which holds the boxes."""
    if len(corners) <= 16 * FARTHEST_BLOCK:
        return float(((corners - point) ** 2).sum(axis=1).max()) if len(corners) else 0.0

    def boxes() -> tuple[np.ndarray, np.ndarray]:
        whole = len(corners) // FARTHEST_BLOCK * FARTHEST_BLOCK
        blocks = corners[:whole].reshape(-1, FARTHEST_BLOCK, 3)
        lo, hi = [blocks.min(axis=1)], [blocks.max(axis=1)]
        if whole < len(corners):
            lo.append(corners[whole:].min(axis=0, keepdims=True))
            hi.append(corners[whole:].max(axis=0, keepdims=True))
        return np.concatenate(lo), np.concatenate(hi)

    lo, hi = kept(("farthest boxes", len(corners), FARTHEST_BLOCK), boxes)
    reach = (np.maximum(np.abs(lo - point), np.abs(hi - point)) ** 2).sum(axis=1)
    found = ((corners[::FARTHEST_BLOCK] - point) ** 2).sum(axis=1).max()
    rows = (np.flatnonzero(reach >= found)[:, None] * FARTHEST_BLOCK + np.arange(FARTHEST_BLOCK)).ravel()
    return float(((corners[rows[rows < len(corners)]] - point) ** 2).sum(axis=1).max())


@dataclass(frozen=True)
class Scene:
    image: Image
    camera: Camera
    lights: tuple[Light, ...]
    medium: Medium
    background: RGB
    geometry: Geometry
    render: Render
    source: Path | None = None  # the YAML file, for messages and relative paths
    animation: Keyframes | None = None  # keyframes (clrays.scene.animation): `animation.scene_at(scene, frame)`
