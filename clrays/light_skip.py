"""Lights below the error budget (docs/design.md §4.9): a light whose contribution to every
pixel is provably below SKIP_BUDGET of the frame's mean luminance is left out of a frame
that runs its lights in turn (clrays.light_turns), and `--stats` lists it.

The bound (`contribution_bound`, radiance in luminance units, per pixel) takes no occluder
into account, so it holds whatever the shadows are; every transmittance is at most 1:

    surface:        L_surf ≤ albedo_max / π · I_max / d_min²      d_min: the light to the
                                                                  nearest triangle's box
    in-scattering:  L_in ≤ σs_max · ρ_max · I_max · π / h         h: the light to the nearest
                                                                  camera ray, at least the
                                                                  lamp's radius

(∫ dt / (h² + t²) over a whole line is π / h; the lamp's ball holds no medium, so no ray
passes nearer than its radius, physics/radiometry.py.) h is bounded below from the cone
around the camera's frustum (its half-diagonal angle). Behind the camera (every ray within
90° of the cone leads away from the light), a ray's distance r from it grows from D, the
light's from the eye, so ∫ dt / r² ≤ π / 2D, and light reaches the eye only scattered back
(cosθ ≤ 0), where a forward Henyey–Greenstein phase is at most ρ(0). A skipped light's
visibility is 0, so shade adds nothing of it, and its in-scattering is not added.

The proof ends after the frame: the kept lights' image has a mean luminance M_kept at most
the whole frame's (every light adds radiance ≥ 0), so where the skipped bounds sum to at
most SKIP_BUDGET · M_kept, leaving them out changes every pixel by at most SKIP_BUDGET of
the frame's mean luminance: under the relative RMSE `tune` and `clrays bench` measure
(clrays.runs.bench), of which the finest bench target, 0.5 %, is five times SKIP_BUDGET.
Where the sum is over (the lights were chosen before the image was known, from
`CHOOSE_FRACTION` of the largest light's bound), the frame renders again with every light.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .physics.radiometry import lamp_radius
from .scene.camera import camera_basis, half_extents
from .scene.model import DirectionalLight, Scene
from .stages.raster_culling import geometry_boxes

#: A skipped light changes no pixel by more than this fraction of the frame's mean luminance.
SKIP_BUDGET = 1e-3
#: Before the frame, a light is a candidate where the skipped bounds sum to at most
#: SKIP_BUDGET × this × the largest light's bound: a guess at the mean luminance the check
#: after the frame needs (a wrong guess costs the frame again with every light, never the image).
CHOOSE_FRACTION = 1e-2
#: Rec. 709 luminance of linear RGB, as the error is measured (clrays.reference.metrics).
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@dataclass(frozen=True)
class SkippedLights:
    """The lights a frame left out: their indices (of `lights`), the sum of their bounds
    (luminance per pixel) and what it had to meet, SKIP_BUDGET × the kept lights' mean
    luminance."""

    indices: tuple[int, ...]
    lights: int
    bound: float
    allowed: float

    def describe(self) -> str:
        """One line for `--stats` (the first 16 indices)."""
        listed = " ".join(str(index) for index in self.indices[:16]) + (" …" if len(self.indices) > 16 else "")
        return (f"{len(self.indices)} of {self.lights} lights below the error budget, skipped "
                f"(their bound {self.bound:.3g} ≤ {SKIP_BUDGET:g} × the mean luminance = {self.allowed:.3g}): {listed}")


def contribution_bound(scene: Scene, index: int) -> float:
    """An upper bound on light `index`'s radiance (luminance) at any pixel of the frame,
    surface and in-scattering together (module docstring); inf where none is found: a
    directional or textured light, a medium with a density, a surface at the light."""
    light = scene.lights[index]
    if isinstance(light, DirectionalLight) or light.texture is not None or scene.medium.density is not None:
        return math.inf
    position = np.asarray(light.position, np.float64)
    intensity = float(np.max(light.intensity))
    if intensity <= 0:
        return 0.0
    geometry = scene.geometry
    surface = 0.0
    if geometry.count:
        lo, hi = geometry_boxes(geometry, geometry.count)
        nearest = float(np.sqrt((np.maximum(np.maximum(lo - position, position - hi), 0.0) ** 2).sum(axis=1).min()))
        if nearest <= 0:
            return math.inf
        surface = float(np.max(geometry.albedo)) / math.pi * intensity / nearest ** 2
    sigma_s = float(np.max(scene.medium.sigma_s))
    in_scatter = 0.0
    if sigma_s > 0:
        nearest, behind = _nearest_camera_ray(scene, position)
        g = float(scene.medium.phase.g) if scene.medium.phase.type == "hg" else 0.0
        if behind and g >= 0:  # scattered back only: ρ(cosθ ≤ 0) ≤ ρ(0)
            phase_max = (1 - g * g) / (4 * math.pi * (1 + g * g) ** 1.5)
        else:  # Henyey–Greenstein at cosθ = ±1
            phase_max = (1 + abs(g)) / (4 * math.pi * (1 - abs(g)) ** 2)
        along_ray = math.pi / (2 * nearest) if behind else math.pi / max(nearest, lamp_radius(scene))
        in_scatter = sigma_s * phase_max * intensity * along_ray
    return float(LUMINANCE.sum()) * (surface + in_scatter)  # every channel at I_max: luminance weights sum


def _nearest_camera_ray(scene: Scene, position: np.ndarray) -> tuple[float, bool]:
    """(a lower bound on the distance from `position` to any camera ray, whether every ray
    leads away from it): rays lie in the cone of the frustum's half-diagonal angle about the
    view direction."""
    camera, image = scene.camera, scene.image
    to_light = position - np.asarray(camera.position, np.float64)
    distance = float(np.linalg.norm(to_light))
    if distance == 0:
        return 0.0, False
    forward = camera_basis(camera)[2]
    half_diagonal = math.atan(math.hypot(*half_extents(camera, image)))
    off_axis = math.acos(float(np.clip(np.dot(to_light, forward) / distance, -1.0, 1.0)))
    outside = off_axis - half_diagonal
    if outside <= 0:
        return 0.0, False
    return (distance * math.sin(outside), False) if outside < math.pi / 2 else (distance, True)


def candidates(scene: Scene, enabled: bool = True) -> tuple[tuple[int, ...], float]:
    """(the lights to leave out of the frame, the sum of their bounds): the dimmest by
    `contribution_bound` while their sum stays within SKIP_BUDGET × CHOOSE_FRACTION of the
    largest finite bound; none with fewer than two lights or where not `enabled`."""
    if not enabled or len(scene.lights) < 2:
        return (), 0.0
    bounds = [contribution_bound(scene, index) for index in range(len(scene.lights))]
    finite = [bound for bound in bounds if math.isfinite(bound)]
    if not finite:
        return (), 0.0
    limit = SKIP_BUDGET * CHOOSE_FRACTION * max(finite)  # (an unbounded light is never a candidate)
    chosen, total = [], 0.0
    for index in sorted(range(len(bounds)), key=bounds.__getitem__):
        if total + bounds[index] > limit or len(chosen) == len(bounds) - 1:
            break
        chosen.append(index)
        total += bounds[index]
    return tuple(sorted(chosen)), total


def mean_luminance(image: np.ndarray) -> float:
    """The image's mean luminance (linear RGB, (H, W, 3))."""
    return float(np.mean(np.asarray(image, np.float64) @ LUMINANCE))
