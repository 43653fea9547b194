"""`exact`: the ground-truth renderer (numpy, float64, no shadow map).

For each camera sample ray x(s) = e + s·v (v unit) it computes, per light and per RGB
channel (docs/design.md §1, §4),

    L = L_surf·e^{-σt·D} + Σ_lights Σ_{lit [a, b]} ∫_a^b e^{-σt·s}·σs·ρ(cosθ)·Lin(x_s) ds

- D is the first hit of the ray (Möller–Trumbore), or camera.far
  (clamped: `radiometry.effective_far`) for a miss, in which case L_surf is the background.
- L_surf = albedo/π · Σ_lights Lin(x)·max(0, n·ω_l)·V(x), n the shading normal (the
  geometric normal, or on a smooth mesh the interpolated vertex normals) turned towards the
  camera with the geometric normal, V by a shadow ray.
- The lit set of [0, D] is exact: a triangle's shadow volume is convex (the region
  beyond its plane inside the three planes through the light — or parallel to a
  directional light — and each edge), so it meets the ray in one interval found by
  clipping against 4 half-spaces; the shadowed set is the union of those intervals and
  the lit set its complement (for a spot light: within the ray's interval inside the cone),
  less the lamp: the medium-free ball of `radiometry.lamp_radius` around a point or spot
  light, which keeps a ray through the light, and the eye at the light, finite.
- With `camera.near` each ray starts at t0 = near / cos θ (`camera.ray_starts`), as Cycles'
  Clip Start: the lit intervals are cut to [t0, D] and the eye's transmittance is measured
  from t0, e^{-σt·(s - t0)}, so the sum above is times e^{σt·t0}. The first hit is still
  searched from the eye (as the device's camera depth): a surface nearer than t0 is seen.
- Each lit interval is integrated by `radiometry.in_scatter_segments`: closed form for a
  directional light, adaptive composite Gauss–Legendre in the angle φ of
  s = s0 + h·tanφ for point and spot lights. A textured light's (docs/light-textures.md)
  is cut where its texture's bilinear lookup has kinks and each piece integrated by
  Gauss–Legendre (`light_texture.textured_in_scatter`); its texture also multiplies Lin
  on surfaces.

The three geometric queries (first hit, shadow ray, lit set) run on a BVH
(`bvh_queries.SceneBvh`), which lists the few triangles each ray can meet, so the cost
grows with pixels × those candidates, not pixels × triangles; `bvh=False` tests every
triangle (`AllTriangles`), the yardstick the BVH path is tested against. Rays go in
chunks so memory stays around 100 MB.

A bounded or heterogeneous medium (`Medium.bounds`, `Medium.density`) replaces e^{-σt·s} by
T_e(s) = e^{-σt·∫ρ}, Lin by Lin·T_l and σs by σs·ρ (`media.py`, docs/media.md): surfaces take
`light_incident_media`, the surface radiance T_e(D), each lit interval `in_scatter_media`; so
does the translucent path below.

A scene with translucent objects (`Geometry.translucent`) goes through
`translucency.translucent_radiance` instead: light through translucent occluders is
scaled by the product of their (1 − α), and the camera ray composites the translucent
surfaces in front of its first opaque hit. An opaque-only scene never reaches it.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..physics import radiometry
from ..scene.camera import from_ray_starts, primary_rays, ray_starts, sample_offsets
from ..physics.geometry import (BUDGET_BYTES, CLIP_PAIR_BYTES, dot, lit_intervals, occluded, raycast, shading_normals,
                                shadow_halfspaces, triangle_normals)
from .bvh_queries import SceneBvh
from ..physics.light_texture import light_texture
from .media import eye_transmittance, in_scatter_lit, incident_through, near_gain
from .translucency import TranslucentQueries, translucent_radiance
from ..physics.radiometry import propagation_direction, rgb
from ..scene.model import GridDensity, Scene


#: Seconds per camera ray, light and doubling of the triangle count that `exact` on the
#: BVH takes on the 2-core CI-class machine, for estimates: a ray's BVH walk grows with
#: log2 of the triangles, and a directional light's rays cost DIRECTIONAL_RAY_COST of the
#: others'. Measured at 128×72 and 320×180 on a quiet machine, µs a ray: behind (point,
#: 380 triangles) 59–63, sun (directional, 2340) 56–59, demo (point, 2456) 102–105, bunny
#: (spot, 75 536) 135–140, where this estimate is 0.97–1.31× the time taken; a machine
#: busy with other work took up to twice as long. The former flat 300 µs a ray was 2.1–5.4×
#: (it announced 69 s for sun's 26.5 s at 640×360).
SECONDS_PER_RAY_LIGHT_DOUBLING = 9e-6
DIRECTIONAL_RAY_COST = 0.7
#: What a density grid adds per camera ray and light, per square of the planes the quadrature
#: breaks at (nx + ny + nz + 6: voxel centres and bounds), since each node's light path crosses
#: them all (media.py). Measured 28–61 µs on 4³ to 12³ grids at 8×6, a point light or a sun.
GRID_SECONDS_PER_RAY_PLANE2 = 4e-5
#: Camera rays per batch on the BVH: the (ray, node) and (ray, triangle) pair arrays of
#: a batch stay in the tens of MB.
BVH_CHUNK_RAYS = 4096
# Progress without a bar (stderr not a terminal): a line per this many percent.
PROGRESS_LINE_PERCENT = 10


def estimate_seconds(scene: Scene, pixels: int | None = None) -> float:
    """Rough run time of `exact` on `pixels` pixels (default: the whole image): rays ×
    Σ over lights of SECONDS_PER_RAY_LIGHT_DOUBLING · log2(triangles) (× DIRECTIONAL_RAY_COST
    for a directional light), and in a density grid GRID_SECONDS_PER_RAY_PLANE2 · planes² more."""
    pixels = scene.image.width * scene.image.height if pixels is None else pixels
    per_ray = SECONDS_PER_RAY_LIGHT_DOUBLING * math.log2(max(scene.geometry.count, 2))
    lights = sum(DIRECTIONAL_RAY_COST if light.type == "directional" else 1.0 for light in scene.lights) or 1.0
    seconds = pixels * scene.image.spp * lights * per_ray
    density = scene.medium.density
    if isinstance(density, GridDensity):
        planes = sum(density.values.shape) + 6
        seconds += pixels * scene.image.spp * max(len(scene.lights), 1) * GRID_SECONDS_PER_RAY_PLANE2 * planes ** 2
    return seconds


class AllTriangles:
    """The three geometric queries of `exact` against every triangle (`geometry`): the
    cost is rays × triangles. `SceneBvh` answers the same on a BVH; this is its yardstick."""

    def __init__(self, triangles):
        self.triangles = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)

    def raycast(self, origins, dirs, t_max=np.inf):
        return raycast(origins, dirs, self.triangles, t_max=t_max)

    def occluded(self, points, light, normals=None):
        return occluded(points, light, self.triangles, normals=normals)

    def lit_intervals(self, origins, dirs, D, light, halfspaces, lamp_radius: float = 0.0):
        return lit_intervals(origins, dirs, D, light, self.triangles, halfspaces=halfspaces, lamp_radius=lamp_radius)


def _radiance(scene: Scene, eye: np.ndarray, dirs: np.ndarray, prepared, quad: dict, queries,
              parts: dict | None = None) -> np.ndarray:
    """Radiance (N, 3) of unit rays from the eye (the model in the module docstring);
    `queries`: `SceneBvh` or `AllTriangles`. `parts`, a dict, receives the terms of the
    render passes (clrays.passes): `transmittance` e^{-σt·D}, `attenuated_surface`,
    `depth` (+inf without a surface) and `lights`, each light's in-scattering (L, N, 3)."""
    n = len(dirs)
    tri = np.asarray(scene.geometry.triangles, dtype=np.float64).reshape(-1, 3, 3)
    medium = scene.medium
    sigma_s = rgb(medium.sigma_s)
    far = radiometry.effective_far(scene)
    t, idx = queries.raycast(eye, dirs, t_max=far)
    hit = idx >= 0
    D = np.where(hit, t, far)
    starts = ray_starts(scene.camera, dirs)  # camera.near: each ray starts at t0 (0 without)
    gain = near_gain(medium, eye, dirs, starts, D)  # 1/T_e(t0): light attenuated from t0, not from the eye
    surf = np.zeros((n, 3))
    surf[~hit] = rgb(scene.background)
    hits = np.flatnonzero(hit)
    if len(hits):
        x = eye + t[hits, None] * dirs[hits]
        nrm = triangle_normals(tri[idx[hits]])
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        shading = shading_normals(scene.geometry, tri, idx[hits], x, nrm)
        # Two-sided: the face normal that faces the camera, and the shading normal with it.
        facing = np.where(dot(nrm, dirs[hits]) > 0, -1.0, 1.0)[:, None]
        nrm *= facing
        shading *= facing
        irradiance = np.zeros((len(hits), 3))
        for light, _ in prepared:
            to_light = -propagation_direction(light, x)
            # Unlit where the surface itself turns away, whatever a smooth normal says (as
            # cl/visibility_prepare.cl's turned_away): no light through an opaque wall.
            cos_l = np.where(dot(nrm, to_light) > 0.0, np.maximum(0.0, dot(shading, to_light)), 0.0)
            lin = incident_through(light, medium, x) * cos_l[:, None] * light_texture(light, x)
            lit = np.flatnonzero(np.any(lin > 0, axis=1))
            if len(lit):
                blocked = queries.occluded(x[lit], light, normals=nrm[lit])
                lin[lit[blocked]] = 0.0
            irradiance += lin
        surf[hits] = np.asarray(scene.geometry.albedo, dtype=np.float64)[idx[hits]] / math.pi * irradiance
    transmittance = eye_transmittance(medium, eye, dirs, D, start=np.minimum(starts, D))
    out = surf * transmittance
    if parts is not None:
        parts["transmittance"] = transmittance
        parts["attenuated_surface"] = out.copy()
        parts["depth"] = np.where(hit, t, np.inf)
        parts["lights"] = np.zeros((len(prepared), n, 3))
    if np.any(sigma_s > 0):
        for index, (light, halfspaces) in enumerate(prepared):
            ray, a, b = from_ray_starts(*queries.lit_intervals(eye, dirs, D, light, halfspaces,
                                                               lamp_radius=radiometry.lamp_radius(scene)), starts)
            seg = in_scatter_lit(light, medium, eye, dirs[ray], a, b, quad) * gain[ray]
            for ch in range(3):
                light_part = np.bincount(ray, weights=seg[:, ch], minlength=n)
                out[:, ch] += light_part
                if parts is not None:
                    parts["lights"][index, :, ch] = light_part
    return out


def render_exact(scene: Scene, progress: bool = False, rows=None, *, panels: int = 8,
                 tol: float | None = 1e-10, bvh: bool = True, parts: dict | None = None) -> np.ndarray:
    """Ground-truth radiance image (H, W, 3) float64 (or (len(rows), W, 3) with `rows`).

    Each pixel is the mean over its `image.spp` sample rays (`camera.primary_rays`, one
    definition of pixel rays for every method) of the radiance described in the module
    docstring. `rows` selects image rows (a slice or indices) for tests on big images;
    `progress` shows a tqdm bar over ray chunks (or, a function, lines of text); `panels` and `tol` are the point-light
    quadrature's starting panel count and relative tolerance (tol=None: one fixed pass);
    `bvh` and `parts` as in `exact_pixels` (its arrays shaped as the image's).
    """
    image = scene.image
    row_idx = np.atleast_1d(np.arange(image.height)[slice(None) if rows is None else rows])
    ys, xs = np.repeat(row_idx, image.width), np.tile(np.arange(image.width), len(row_idx))
    radiance = exact_pixels(scene, ys, xs, progress, panels=panels, tol=tol, bvh=bvh, parts=parts)
    if parts is not None:
        for name, value in parts.items():
            parts[name] = value.reshape(*value.shape[:-2], len(row_idx), image.width, *value.shape[-1:]) \
                if name == "lights" else value.reshape(len(row_idx), image.width, *value.shape[1:])
    return radiance.reshape(len(row_idx), image.width, 3)


class _ProgressLines:
    """Progress as text lines, for a log or a pipe where a bar would not show: one line per
    PROGRESS_LINE_PERCENT of the work, with the time spent and the time left."""

    def __init__(self, log, total: int):
        self.log, self.total, self.done, self.shown = log, max(total, 1), 0, 0
        self.start = time.perf_counter()

    def update(self, count: int) -> None:
        self.done += count
        percent = 100 * self.done // self.total
        if percent >= self.shown + PROGRESS_LINE_PERCENT or (self.done == self.total and percent > self.shown):
            self.shown = percent
            spent = time.perf_counter() - self.start
            left = spent * (self.total - self.done) / self.done
            self.log(f"exact: {percent}% ({spent:.0f} s, about {left:.0f} s left)")

    def close(self) -> None:
        pass


def exact_pixels(scene: Scene, ys, xs, progress=False, *, panels: int = 8,
                 tol: float | None = 1e-10, bvh: bool = True, parts: dict | None = None) -> np.ndarray:
    """Ground-truth radiance (N, 3) float64 of the pixels (ys[i], xs[i]): what
    `render_exact` gives there, at a cost proportional to the number of pixels (for
    measuring error on a fixed subset of a large image). `progress`: True for a tqdm bar,
    or a function that takes a line of text, called every PROGRESS_LINE_PERCENT.
    `bvh`: find the triangles each ray can meet on a BVH (`bvh_queries.SceneBvh`), or,
    False, test every triangle (`AllTriangles`: same images up to rounding, slow).
    `parts`, a dict (opaque scenes), receives the per-pixel terms of the render passes
    (clrays.passes): the means over the samples of `transmittance` and `attenuated_surface`
    (N, 3), of each light's in-scattering `lights` (L, N, 3), and the nearest `depth` (N,)."""
    image, camera = scene.image, scene.camera
    ys, xs = np.asarray(ys, dtype=np.intp), np.asarray(xs, dtype=np.intp)
    offsets = sample_offsets(image.spp)
    eye = np.asarray(camera.position, dtype=np.float64)
    tri = np.asarray(scene.geometry.triangles, dtype=np.float64).reshape(-1, 3, 3)
    radiance = _radiance
    prepared = [(light, shadow_halfspaces(light, tri)) for light in scene.lights]
    if scene.geometry.translucent:  # translucent objects: their own queries and compositing (translucency.py)
        radiance = translucent_radiance
        queries = TranslucentQueries(scene.geometry, bvh=bvh)
        prepared = [(light, queries.halfspaces(light)) for light in scene.lights]
        chunk = BVH_CHUNK_RAYS if bvh else max(1, BUDGET_BYTES // (CLIP_PAIR_BYTES * (len(tri) + 1)))
    elif bvh:
        queries = SceneBvh.build(tri)
        chunk = BVH_CHUNK_RAYS
    else:
        queries = AllTriangles(tri)
        # Chunks small enough for the (rays × triangles) clipping, and not so small that
        # per-chunk overhead dominates when there are few triangles.
        chunk = int(np.clip(BUDGET_BYTES // (CLIP_PAIR_BYTES * (len(tri) + 1)), 64, 16384))
    starts = range(0, len(ys), chunk)
    bar = None
    if callable(progress):
        bar = _ProgressLines(progress, len(offsets) * len(starts))
    elif progress:
        from tqdm import tqdm

        bar = tqdm(total=len(offsets) * len(starts), desc="exact", unit="chunk")
    quad = {"panels": panels, "tol": tol}
    total = np.zeros((len(ys), 3))
    if parts is not None:
        parts.update(transmittance=np.zeros((len(ys), 3)), attenuated_surface=np.zeros((len(ys), 3)),
                     lights=np.zeros((len(prepared), len(ys), 3)), depth=np.full(len(ys), np.inf))
    for k in range(len(offsets)):
        # One sample offset at a time keeps the ray array at H·W·3 floats.
        dirs = primary_rays(camera, image, offsets[k:k + 1])[ys, xs, 0, :]
        for s in starts:
            ray_parts = None if parts is None else {}
            extra = {} if parts is None else {"parts": ray_parts}  # (opaque scenes' _radiance only)
            total[s:s + chunk] += radiance(scene, eye, dirs[s:s + chunk], prepared, quad, queries, **extra)
            if parts is not None:
                for name in ("transmittance", "attenuated_surface"):
                    parts[name][s:s + chunk] += ray_parts[name] / len(offsets)
                parts["lights"][:, s:s + chunk] += ray_parts["lights"] / len(offsets)
                parts["depth"][s:s + chunk] = np.minimum(parts["depth"][s:s + chunk], ray_parts["depth"])
            if bar is not None:
                bar.update(1)
    if bar is not None:
        bar.close()
    return total / len(offsets)


__all__ = ["exact_pixels", "render_exact", "estimate_seconds"]
