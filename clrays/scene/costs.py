"""Sizes that follow the image: the shadow map side, the slice count and the γ texels per
slice that a scene leaves unset are derived from the image (docs/design.md §7,
"Sizes that follow the image").

A shadow-map texel seen from the camera should not be larger than a pixel, so the map
side follows the image diagonal, with a margin of 4 for surfaces seen at a slant. The
epipolar texture resamples that map, so it needs no more slices or γ texels than the map
has texels along a side; and no more than the image can show: each pixel point-samples
the shafts, so a slice count of 4 × the perimeter (8(W + H)) and 8 × the diagonal of γ
texels. Why the factors are that large: on the spot-light slats of tests/stages at 64×48,
slices = perimeter (256) gives a p99 error of 6.5 % against `exact` and γ texels =
diagonal (128) 11.7 %, where 1024 × 1024 gives 2.4 %. Every size is rounded up to a power
of two (sizes change in steps, not with every pixel) and clamped: below by what a shadow
or a slice still resolves, above by the measured defaults of bench/RESULTS.md history ("Choosing
defaults"). An image whose diagonal is 100 pixels or more (96×64 and larger) gets the full
1024 map whatever the texels per pixel give: there the map's texel across the scene, not the
pixel, sets the error against `exact` (FULL_SHADOW_MAP_DIAGONAL). So 96×64 and larger get
a 1024 map, 1024 slices and 1024 γ texels, unless a thin solid or a light's texture asks
for more (below).

A textured light asks for more: the rectified texture samples its image once per slice
and γ texel, so neither may be coarser than the image's texels seen from the light (a
point or spot light's, angles) or across its beam (a directional light's, lengths), or
the two-slice blend and the γ cells average its pattern away (docs/light-textures.md).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .light_views import directional_map
from .model import DirectionalLight, Scene, SpotLight

#: Upper clamps: the measured defaults (bench/RESULTS.md history, "Choosing defaults").
MAX_SHADOW_MAP = 1024
MAX_SLICES = 1024
MAX_GAMMA_SAMPLES = 1024
#: Lower clamps: the smallest sizes the scene format accepts for slices and γ samples,
#: and a shadow map that still resolves an object's shadow on a thumbnail.
MIN_SHADOW_MAP = 64
MIN_SLICES = 16
MIN_GAMMA_SAMPLES = 16
#: Epipolar sampling: samples along the longest slice's line on the screen (shorter lines
#: get as many as keep its spacing: clrays.stages.sampling.line_lengths). That line is at
#: most the diagonal, so a sample per two pixels of the diagonal puts them no further apart
#: than two pixels on any line. One per pixel computes about twice the samples for 1.4× the traverse
#: time and brings behind.yaml's p99 against `exact` from 0.324 to 0.289 % at 1280×720
#: (bench/RESULTS.md history, "Epipolar sampling").
LINE_SAMPLES_PER_PIXEL = 0.5
MIN_LINE_SAMPLES = 16
MAX_LINE_SAMPLES = 4096
#: Epipolar sampling: the longest line gets about this many initially computed samples,
#: their step between MIN_INITIAL_STEP and MAX_INITIAL_STEP. A shaft is as wide on a small
#: image as on a large one, measured along the line, so the step shrinks with the image: 6 at
#: 1280×720 (the largest within 10 % of the per-pixel walk's error there), 3 at 640×360,
#: where 6 put behind.yaml's RMSE and p99 against `exact` 19 % and 35 % over the per-pixel
#: walk's and 3 puts them 4 % and 7 % over (bench/RESULTS.md history, "The initial step follows the
#: image"). Below 640×360 it stays 3: there the 1024 slices' lines already hold more
#: samples than the image has pixels, and a smaller step would only compute more of them.
INITIAL_SAMPLES_PER_LINE = 120
MIN_INITIAL_STEP = 3
MAX_INITIAL_STEP = 6
#: Shadow-map texels per pixel of the image diagonal.
SHADOW_TEXELS_PER_PIXEL = 4
#: From this image diagonal (pixels) up, the derived map is MAX_SHADOW_MAP, however few texels
#: per pixel that is. A 512² map misses 0.5 % relative RMSE against `exact` at every size
#: measured from 64×48 to 96×64 alike, so it is the map's texel across the scene's shafts,
#: not a pixel's footprint, that sets the error (sun and room 0.73 and 0.82 % at 64×48, 0.59
#: and 0.94 % at 80×60, 0.65 and 0.84 % at 96×64; orbit's frame 10 1.53 % at 96×64). 1024²,
#: with the 1024 slices and γ texels it lets the image derive, brings every scene of scenes/
#: at 96×64 within it (sun 0.34, room 0.28, orbit's frame 10 0.42 %) but the lattice and the
#: stained glass, which miss it at every size (bench/RESULTS.md history, "The full map from a
#: diagonal of 100 pixels"). Both halves count: the map alone reads sun 0.51, room 0.57 %,
#: the slices and γ texels alone 0.59, 0.75 %. 8 texels per pixel would give 96×64 the same
#: but double every smaller image's map too, for 1.4–4× the frame (64×48: sun 11 → 35 ms,
#: glass_row 134 → 528 ms); images under a diagonal of 100, thumbnails, keep the smaller
#: maps and their error (64×48 above; 32×18: room 1.99 %).
FULL_SHADOW_MAP_DIAGONAL = 100
#: Spot lights wider than this use a cube map: a single perspective map of a wide
#: cone would spend most texels near its rim.
SPOT_SINGLE_VIEW_MAX_DEG = 75.0
#: Texels across the thinnest closed solid, seen from its light, that a derived map gives at
#: least. scenes/grate.yaml's 1 cm slats 2.8 below a point light at 320×180, against `exact`
#: (bench/RESULTS.md history, "Volume visibility"): 1.8 texels of a 1024² cube face 3.26 %, 3.7 texels
#: (2048²) 2.22 %, 7.4 (4096²) 0.24 %; the slices and γ texels moved it by under 0.06.
OCCLUDER_TEXELS = 6
#: A derived map grows for thin solids to at most this many times the image's size, and
#: this side (for all lights' maps together): a 4096² cube map is 384 MiB of depths, the
#: grate's whole frame 1188 MiB of device memory at 320×180 (97 MiB at 1024²).
OCCLUDER_MAP_GROWTH = 4
MAX_OCCLUDER_SHADOW_MAP = 4096
#: Slices per pixel of the image perimeter, γ texels per pixel of its diagonal (measured, above).
SLICES_PER_BORDER_PIXEL = 4
GAMMA_TEXELS_PER_PIXEL = 8
#: Upper clamps of what a light texture asks for. scenes/gobo.yaml (a 256² gobo over a 28°
#: cone) asks for 2048 × 1024; against `exact` that takes its minmax error from 1.47 to
#: 0.44 % at 320×180 and from 0.68 to 0.12 % at 96×64 (bench/RESULTS.md history, "A light texture's
#: slices and γ texels"). scenes/stained_glass.yaml's sun asks for 4096 × 2048 and gets
#: 4096 × 1024: with each γ cell's texture its mean (clrays.stages.light_texture.cell_samples)
#: 0.76 / 0.53 / 0.45 / 0.45 % against `exact` at 96×64 / 320×180 / 640×360 / 1280×720, where
#: 2048 slices gave 0.90 / 0.68 / 0.65 / 0.69 %, for 1.2–1.3× the frame; 2048 γ texels would
#: pass the budget below (bench/RESULTS.md history, "The stained glass within reach of 0.5 %").
#: The prefix sums grow with slices × γ texels (252 MiB at 4096 × 1024, rank 4); a finer
#: texture is left to `render.slices` and `render.gamma_samples`.
MAX_TEXTURE_SLICES = 4096
MAX_TEXTURE_GAMMA_SAMPLES = 1024
#: Device memory that what the textures ask for may take: every textured light's prefix sums
#: (clrays.stages.light_texture) together. One gobo at 2048 × 1024 and rank 4 takes
#: 126 MiB, the stained glass's sun at 4096 × 1024 252 MiB; 16 spot lights sharing a gobo in
#: a 32×18 frame asked for 2.4 GiB (tests/scene/test_hostile.py), so past this the raise is
#: halved, down to the image's sizes.
TEXTURE_SIZES_BUDGET = 256 << 20


#: The largest power of two a derived size is rounded to before its clamps: a ratio of
#: scene values (a texture's texel of 1e-320, a box 1e-320 thin) can be infinite.
MAX_POWER_OF_TWO = 1 << 30


def _power_of_two_at_least(value: float) -> int:
    return 1 << max(math.ceil(math.log2(min(max(value, 1.0), MAX_POWER_OF_TWO))), 0)


def _clamped(value: float, low: int, high: int) -> int:
    return min(max(_power_of_two_at_least(value), low), high)


def derived_shadow_map(width: int, height: int) -> int:
    """Shadow map side (texels, per cube face) for a width × height image."""
    if math.hypot(width, height) >= FULL_SHADOW_MAP_DIAGONAL:
        return MAX_SHADOW_MAP
    return _clamped(SHADOW_TEXELS_PER_PIXEL * math.hypot(width, height), MIN_SHADOW_MAP, MAX_SHADOW_MAP)


def occluder_shadow_map(scene: Scene, image_map: int) -> int:
    """The map side at which the thinnest closed solid, seen from each light, spans
    OCCLUDER_TEXELS texels, when that is more than `image_map`: at most
    OCCLUDER_MAP_GROWTH × `image_map`, and MAX_OCCLUDER_SHADOW_MAP for all lights' maps
    together (halved for each 4× the lights; docs/design.md §8, "Volume visibility"). Light
    passes between such solids in sheets no wider than they are, and a map that decides
    them at a texel or two gets every shaft's share wrong."""
    widths = [thinnest_solid(scene.geometry, light) for light in scene.lights]
    widths = [width for width in widths if width is not None]
    if not widths:
        return image_map
    needed = OCCLUDER_TEXELS / min(widths)  # texels per unit of the map's side, whose extent is 1
    # All lights' maps together no larger than one light's at MAX_OCCLUDER_SHADOW_MAP.
    largest = MAX_OCCLUDER_SHADOW_MAP >> math.ceil(math.log2(len(scene.lights)) / 2)
    return max(min(_power_of_two_at_least(needed), OCCLUDER_MAP_GROWTH * image_map, largest), image_map)


def view_map_sides(geometry, light, floor: int, ceiling: int) -> list[int]:
    """The side of each view of the light's map (`light_view_count`): `floor`, raised for
    the thinnest closed solid reaching into that view to span OCCLUDER_TEXELS texels, as a
    power of two, at most `ceiling` (`render.shadow_map_floor` and `render.shadow_map`,
    texels). A cube face that holds no thin solid keeps the floor: scenes/grate.yaml's slats
    lie in its light's −y face, and the other five faces at 1024² cost a fifth of their
    texels at 4096² (docs/design.md §8, "Sizes from the occluders")."""
    if floor >= ceiling:  # every view at one side: nothing to measure
        return [ceiling] * light_view_count(light)
    sides = []
    for width in thinnest_solid_per_view(geometry, light):
        needed = floor if width is None else _power_of_two_at_least(OCCLUDER_TEXELS / width)
        sides.append(max(min(needed, ceiling), floor))
    return sides


def thinnest_solid(geometry, light) -> float | None:
    """The narrowest width of a closed solid's box as the light's map sees it, as a fraction
    of the map's side (None: no solid counts). For a point or spot light the width is an
    angle (a tangent on the plane one unit from the light, across the solid's direction),
    and the map's side the tangents a view spans: 2 for a cube face, whose texels are
    widest at its centre, 2·tan(cone) for a single-view spot; for a directional light a
    length, and the side the longer of the map's (clrays.scene.light_views). A solid that holds the light or
    reaches more than about 84° from its own direction is no thin occluder and is skipped."""
    widths = thinnest_solid_per_view(geometry, light)
    counted = [width for width in widths if width is not None]
    return min(counted) if counted else None


def light_view_count(light) -> int:
    """The views of a light's map: one for a directional light or a spot light of at most
    SPOT_SINGLE_VIEW_MAX_DEG, else a cube's six faces (clrays.inputs builds them in this order)."""
    if isinstance(light, DirectionalLight) or (isinstance(light, SpotLight)
                                               and light.cone_deg <= SPOT_SINGLE_VIEW_MAX_DEG):
        return 1
    return 6


def thinnest_solid_per_view(geometry, light) -> tuple[float | None, ...]:
    """`thinnest_solid` for each view of the light's map (`light_view_count`): the narrowest
    width among the solids whose box reaches into that view (a cube face's cone from the
    light; a single view holds every solid counted), None where none does."""
    views = light_view_count(light)
    measured = _solid_widths(geometry, light)
    if measured is None:
        return (None,) * views
    widths, reached = measured
    return tuple(float(widths[reached[:, view]].min()) if reached[:, view].any() else None for view in range(views))


def _cube_faces_reached(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(S, 6) bool: whether each box [lo, hi] (S, 3), relative to the light, reaches into each
    cube face's cone (+x, -x, +y, -y, +z, -z, clrays.inputs' order), that of the points
    whose coordinate along the face's axis, signed, is at least the other two's magnitudes.
    Exact for a box whose sides lie along the axes, as a solid's box does: the box's
    farthest extent along the axis against the others' least magnitudes within it."""
    nearest_to_axis = np.abs(np.clip(0.0, lo, hi))  # (S, 3): the least |coordinate| within the box
    reached = []
    for axis in range(3):
        others = [k for k in range(3) if k != axis]
        across = nearest_to_axis[:, others].max(axis=1)
        for along in (hi[:, axis], -lo[:, axis]):  # the face's sign: + then -
            reached.append((along > 0) & (along >= across))
    return np.stack(reached, axis=1)


def _solid_widths(geometry, light) -> tuple[np.ndarray, np.ndarray] | None:
    """(widths (S,), reached (S, views) bool) of the closed solids the light's map counts
    (`thinnest_solid`), as fractions of a view's side, and the views each reaches; None
    when no solid counts."""
    lo, hi = geometry.solid_bounds()
    if not len(lo):
        return None
    corners = _box_corners(lo, hi)  # (S, 8, 3)
    if isinstance(light, DirectionalLight):
        fitted = directional_map(*geometry.bounds(), light.direction)  # the light's map, across the light
        plane = np.stack([corners @ fitted.right, corners @ fitted.up], axis=-1)
        side = fitted.texel_side  # the map's longer texels
        reached = np.ones((len(lo), 1), dtype=bool)
    else:
        towards = corners - np.asarray(light.position, dtype=np.float64)
        if isinstance(light, SpotLight):  # a solid whose bounding sphere lies outside the cone casts nothing
            axis = np.asarray(light.direction, dtype=np.float64) / np.linalg.norm(light.direction)
            middle = towards.mean(axis=1)
            distance = np.maximum(np.linalg.norm(middle, axis=1), 1e-300)
            radius = np.linalg.norm(towards - middle[:, None], axis=2).max(axis=1)
            off_axis = np.arccos(np.clip(middle @ axis / distance, -1.0, 1.0))
            seen = off_axis - np.arcsin(np.minimum(radius / distance, 1.0)) <= math.radians(light.cone_deg)
            if not seen.any():
                return None
            towards = towards[seen]
        centre = towards.mean(axis=1)
        centre /= np.maximum(np.linalg.norm(centre, axis=1, keepdims=True), 1e-300)
        along = np.einsum("sci,si->sc", towards, centre)
        ahead = np.all(along > 0.1 * np.linalg.norm(towards, axis=2), axis=1)  # within ~84° of its centre
        if not ahead.any():
            return None
        towards, centre, along = towards[ahead], centre[ahead], along[ahead]
        right = np.cross(centre, np.where(np.abs(centre[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]]))
        right /= np.linalg.norm(right, axis=1, keepdims=True)
        up = np.cross(right, centre)
        tangent = towards / along[..., None]  # on the plane one unit from the light: texels are tangents
        plane = np.stack([np.einsum("sci,si->sc", tangent, right), np.einsum("sci,si->sc", tangent, up)], axis=-1)
        spot_view = light_view_count(light) == 1
        side = 2 * math.tan(math.radians(light.cone_deg)) if spot_view else 2.0
        reached = np.ones((len(towards), 1), dtype=bool) if spot_view else \
            _cube_faces_reached(towards.min(axis=1), towards.max(axis=1))
    return _min_width(plane) / side, reached


def _box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(S, 8, 3) the corners of S boxes."""
    pick = np.array([[(k >> axis) & 1 for axis in range(3)] for k in range(8)], dtype=bool)  # (8, 3)
    return np.where(pick[None], hi[:, None, :], lo[:, None, :])


def _min_width(points: np.ndarray) -> np.ndarray:
    """(S,) the least width of each set of 2D points (S, P, 2) over all directions: the least
    is across an edge of the hull, so across some pair of the points."""
    i, j = np.triu_indices(points.shape[1], 1)
    edge = points[:, j] - points[:, i]  # (S, pairs, 2)
    normal = np.stack([-edge[..., 1], edge[..., 0]], axis=-1)
    length = np.linalg.norm(normal, axis=-1)
    normal = normal / np.maximum(length, 1e-300)[..., None]
    spread = np.einsum("spk,sqk->spq", normal, points)  # (S, pairs, P)
    widths = np.ptp(spread, axis=-1)
    widths = np.where(length > 0, widths, np.inf)  # two corners at one point give no direction
    return widths.min(axis=1)


def derived_slices(width: int, height: int, shadow_map: int) -> int:
    """Epipolar slices: 4 × the image perimeter or the shadow map side, the smaller."""
    return _clamped(min(SLICES_PER_BORDER_PIXEL * 2 * (width + height), shadow_map), MIN_SLICES, MAX_SLICES)


def tree_gamma_samples(requested: int) -> int:
    """The γ texels of a row of the epipolar texture and its min-max tree: `render.gamma_samples`
    rounded up to a power of two, at least 2 (the tree halves the row at every level)."""
    return 1 << max(int(math.ceil(math.log2(requested))), 1)


def derived_gamma_samples(width: int, height: int, shadow_map: int) -> int:
    """γ texels per slice: 8 × the image diagonal or the shadow map side, the smaller."""
    return _clamped(min(GAMMA_TEXELS_PER_PIXEL * math.hypot(width, height), shadow_map),
                    MIN_GAMMA_SAMPLES, MAX_GAMMA_SAMPLES)


def texture_texel_angle(light) -> float | None:
    """The angle at the light between neighbouring texels of its texture where they are
    widest (at the image's centre), in radians; None without a texture, for a smooth one
    (a glTF cone's falloff, whose 512² texels sample a slow ramp), or for a directional
    light, whose texels are lengths across the beam, not angles."""
    texture = light.texture
    if texture is None or texture.smooth or isinstance(light, DirectionalLight):
        return None
    if light.type == "spot":  # the image fills [−tan c, tan c]² at distance 1 along the axis
        return 2.0 * math.tan(math.radians(light.cone_deg)) / max(texture.width, texture.height)
    return 2.0 / texture.width  # a point light's cube: each face spans [−1, 1]² at distance 1


def texture_texel_length(light) -> float | None:
    """A directional light's texel as a length across its beam: one tile covers
    `texture_size` scene units of the plane perpendicular to the light, so a texel is
    width / columns by height / rows, and the shorter side counts; None without a texture,
    for a smooth one, or for a point or spot light (whose texels are angles)."""
    texture = light.texture
    if texture is None or texture.smooth or not isinstance(light, DirectionalLight):
        return None
    return min(light.texture_size[0] / texture.width, light.texture_size[1] / texture.height)


def directional_texture_reach(scene: Scene, light) -> tuple[float, float]:
    """(fan, reach) of a directional light's epipolar frame as the camera sees it: the angle
    its slices span around the eye's line along the light (`scene.camera.slice_fan`: 2π
    when the sun or the antisun is on screen) and the farthest distance from that line at
    which the camera sees lit fog, γ's largest value: the scene bounds' farthest corner from
    the line, and no more than the effective far (where every ray ends). Fog seen past the
    scene's bounds is not counted: the geometry ends there and the pattern lies far off."""
    from ..physics.radiometry import effective_far
    from .camera import slice_basis, slice_fan  # the frame the rectify stage builds

    towards = -np.asarray(light.direction, dtype=np.float64)
    towards /= np.linalg.norm(towards)
    u, w = slice_basis(towards)
    _, fan, _ = slice_fan(scene, towards, u, w)
    lo, hi = scene.geometry.bounds()
    corners = _box_corners(lo[None], hi[None])[0] - np.asarray(scene.camera.position, dtype=np.float64)
    across = corners - np.outer(corners @ towards, towards)  # off the eye's line along the light
    return fan, min(float(np.linalg.norm(across, axis=1).max()), effective_far(scene))


def texture_sizes(scene: Scene) -> tuple[int, int]:
    """(slices, γ texels) that resolve every textured light's image; (0, 0) when no light
    has a texture with texels to resolve.

    A point or spot light's texels are angles at the light: neighbouring slices at most a
    texel apart where a light ray is perpendicular to the eye–light axis (sin γ = 1, and
    the fan a full circle: 2π / texel), and γ cells at most a texel long over the largest
    γ range, π.

    A directional light's texels are lengths t across its beam. Its epipolar frame
    (docs/design.md §3) puts the light ray (α, γ) on the line γ·r(α) + s·ω: (γ, α) are
    polar coordinates, around the eye's line along ω, of the plane perpendicular to ω,
    the very plane the texture tiles. Neighbouring slices are γ·Δα apart there, widest at
    the reach R, the largest γ the camera sees (`directional_texture_reach`), and the fan's
    span A is cut into slices of Δα = A / slices: slices ≥ A·R / t. A row's γ cells divide
    [0, γ_max ≤ R] evenly: γ texels ≥ R / t."""
    slices = gamma = 0.0
    for light in scene.lights:
        angle = texture_texel_angle(light)
        if angle is not None:
            slices, gamma = max(slices, 2.0 * math.pi / angle), max(gamma, math.pi / angle)
        length = texture_texel_length(light)
        if length is not None:
            fan, reach = directional_texture_reach(scene, light)
            slices, gamma = max(slices, fan * reach / length), max(gamma, reach / length)
    if not slices:
        return 0, 0
    return (_clamped(slices, MIN_SLICES, MAX_TEXTURE_SLICES),
            _clamped(gamma, MIN_GAMMA_SAMPLES, MAX_TEXTURE_GAMMA_SAMPLES))


def texture_raised_sizes(scene: Scene, slices: int, gamma_samples: int) -> tuple[int, int]:
    """`slices` and `gamma_samples` (the image's, or the scene's own) raised to what the
    textured lights ask for (`texture_sizes`), the sizes the scene sets left as they are; while
    every textured light's prefix sums would pass TEXTURE_SIZES_BUDGET,
    the raise, the larger of the two in proportion, is halved."""
    render = scene.render
    wanted_slices, wanted_gamma = texture_sizes(scene)
    raised_slices = slices if render.slices else max(slices, wanted_slices)
    raised_gamma = gamma_samples if render.gamma_samples else max(gamma_samples, wanted_gamma)
    textured = sum(light.texture is not None for light in scene.lights)
    bytes_per_texel = textured * 4 * 3 * (render.svd_rank + 1)  # the prefix sums
    while (raised_slices * raised_gamma * bytes_per_texel > TEXTURE_SIZES_BUDGET
           and (raised_slices > slices or raised_gamma > gamma_samples)):
        if raised_gamma <= gamma_samples or (raised_slices > slices
                                             and raised_slices / slices >= raised_gamma / gamma_samples):
            raised_slices //= 2
        else:
            raised_gamma //= 2
    return raised_slices, raised_gamma


def derived_line_samples(width: int, height: int) -> int:
    """Samples along each slice's line: half the image diagonal in pixels."""
    return min(max(math.ceil(LINE_SAMPLES_PER_PIXEL * math.hypot(width, height)), MIN_LINE_SAMPLES),
               MAX_LINE_SAMPLES)


def derived_initial_step(line_samples: int) -> int:
    """Every how many line samples one is computed: about INITIAL_SAMPLES_PER_LINE on the
    longest line, in [MIN_INITIAL_STEP, MAX_INITIAL_STEP]."""
    return min(max(line_samples // INITIAL_SAMPLES_PER_LINE, MIN_INITIAL_STEP), MAX_INITIAL_STEP)


def with_derived_sizes(scene: Scene) -> Scene:
    """The scene with every unset (None) size of `scene.render` filled in from its image;
    sizes the scene sets are kept as written."""
    render, image = scene.render, scene.image
    if None not in (render.shadow_map, render.shadow_map_floor, render.slices, render.gamma_samples,
                    render.line_samples, render.initial_step):
        return scene
    shadow_map, floor = derived_map_sides(scene)
    slices, gamma_samples = texture_raised_sizes(
        scene, render.slices or derived_slices(image.width, image.height, shadow_map),
        render.gamma_samples or derived_gamma_samples(image.width, image.height, shadow_map))
    line_samples = render.line_samples or derived_line_samples(image.width, image.height)
    initial_step = render.initial_step or derived_initial_step(line_samples)
    return replace(scene, render=replace(render, shadow_map=shadow_map, shadow_map_floor=floor, slices=slices,
                                         gamma_samples=gamma_samples, line_samples=line_samples,
                                         initial_step=initial_step))


def derived_map_sides(scene: Scene) -> tuple[int, int]:
    """(shadow_map, shadow_map_floor): the largest side a light's view may have and the
    side of a view that needs no more (`view_map_sides`), each as the scene sets it or
    derived. Derived, the floor is the image's map and the largest its growth for the
    thinnest solid (`occluder_shadow_map`), at least the floor; a scene that sets
    `shadow_map` alone gets every view at that side, as it asks; a floor is at most the
    largest side."""
    render, image = scene.render, scene.image
    image_map = derived_shadow_map(image.width, image.height)
    if render.shadow_map is None:
        floor = render.shadow_map_floor or image_map
        return max(occluder_shadow_map(scene, image_map), floor), floor
    return render.shadow_map, min(render.shadow_map_floor or render.shadow_map, render.shadow_map)
