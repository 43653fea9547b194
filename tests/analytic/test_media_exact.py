"""`exact` in a bounded or heterogeneous medium (clrays/reference/media.py, docs/media.md)
against references that share nothing with it but the pixel rays:

- height fog under a sun, in closed form: with ℓ the unit direction towards the sun and d the
  ray's, f(s) = σt·(τ_e(s) + τ_l(s)) has f' = σt·ρ·(ℓ_y − d_y)/ℓ_y, so
  ∫_a^b σs·ρ·T_e·T_l ds = α·ℓ_y/(ℓ_y − d_y)·(e^{−f(a)} − e^{−f(b)}), α = σs/σt (≤ 1e-4);
- a brute-force float64 quadrature written here (numpy only): composite Simpson on a fine
  grid inside the box (clipped by its own slab test), T_e by a cumulative trapezoid, T_l by
  Simpson along each light path, and the grid's trilinear density as a tensor product of
  `np.interp` hat functions; for a box with a point light and for a grid;
- a homogeneous box holding the whole scene renders as the unbounded medium.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from clrays.physics.radiometry import effective_far
from clrays.reference.exact import exact_pixels
from clrays.reference.media import in_scatter_media, optical_depth
from clrays.scene.camera import primary_rays
from clrays.scene.model import Box, GridDensity, HeightDensity
from conftest import DirectionalLight, PointLight, grid_plane, make_scene, v3

SIGMA_S, SIGMA_A = 0.3, 0.1


def _sun(direction=(0.4, -1.0, 0.3), irradiance=2.0) -> DirectionalLight:
    w = v3(*direction) / np.linalg.norm(direction)
    return DirectionalLight(w, np.full(3, irradiance))


def _isotropic() -> float:
    return 1.0 / (4.0 * math.pi)


# ----------------------------------------------------------------- height fog, closed form


def _height_closed_form(eye, d, toward_sun, irradiance, base, height, sigma_s, sigma_t, a, b):
    """σs·E·p·∫_a^b ρ·T_e·T_l ds for unbounded height fog under a sun (module docstring)."""
    rho = lambda s: math.exp(-((eye[1] + s * d[1]) - base) / height)
    ly, dy = toward_sun[1], d[1]

    def f(s):  # σt·(eye depth to s + sun depth from s); the eye depth H·(ρ(0) − ρ(s))/d_y, → ρ·s
        eye_depth = height * (rho(0) - rho(s)) / dy if abs(dy) > 1e-12 else rho(0) * s
        return sigma_t * (eye_depth + height * rho(s) / ly)

    if abs(ly - dy) < 1e-12:  # f constant: σs·e^{-f}·∫ρ
        eye_depth = lambda s: height * (rho(0) - rho(s)) / dy
        integral = math.exp(-f(a)) * (eye_depth(b) - eye_depth(a))
        return sigma_s * irradiance * _isotropic() * integral
    alpha = sigma_s / sigma_t
    return irradiance * _isotropic() * alpha * ly / (ly - dy) * (math.exp(-f(a)) - math.exp(-f(b)))


def test_height_fog_under_a_sun_matches_its_closed_form():
    sun = _sun()
    scene = make_scene(lights=[sun], width=12, height=8, sigma_s=SIGMA_S, sigma_a=SIGMA_A, position=(0, 1.5, 8),
                       look_at=(0, 2.5, 0), fov_deg=70.0, far=40.0)
    density = HeightDensity(base=0.5, scale_height=1.5)
    scene = replace(scene, medium=replace(scene.medium, density=density))
    ys, xs = np.divmod(np.arange(12 * 8), 12)
    parts = {}
    exact_pixels(scene, ys, xs, parts=parts)
    dirs = primary_rays(scene.camera, scene.image)[ys, xs, 0]
    far = effective_far(scene)
    eye, toward = scene.camera.position, -sun.direction
    expected = np.array([_height_closed_form(eye, d, toward, 2.0, 0.5, 1.5, SIGMA_S, SIGMA_S + SIGMA_A, 0.0, far)
                         for d in dirs])
    got = parts["lights"][0, :, 0]
    assert np.max(np.abs(got - expected) / expected) <= 1e-4, np.max(np.abs(got - expected) / expected)
    # The transmittance to the far end too: e^{-σt·H·(ρ(0) − ρ(far))/d_y}.
    rho0 = math.exp(-(eye[1] - 0.5) / 1.5)
    rho_far = np.exp(-((eye[1] + far * dirs[:, 1]) - 0.5) / 1.5)
    transmittance = np.exp(-(SIGMA_S + SIGMA_A) * 1.5 * (rho0 - rho_far) / dirs[:, 1])
    np.testing.assert_allclose(parts["transmittance"][:, 0], transmittance, rtol=1e-9)


@pytest.mark.parametrize("kind", ["towards the sun", "level"])
def test_height_fog_closed_form_at_its_limits(kind):
    """d_y → ℓ_y (the ray along the sun's own direction: f is constant) and d_y → 0."""
    sun = _sun((0.2, -0.6, 0.1))
    toward = -sun.direction
    d = toward.copy() if kind == "towards the sun" else v3(1.0, 0.0, 0.3) / np.linalg.norm([1.0, 0.0, 0.3])
    scene = make_scene(lights=[sun], sigma_s=SIGMA_S, sigma_a=SIGMA_A)
    medium = replace(scene.medium, density=HeightDensity(base=0.0, scale_height=2.0))
    eye = v3(0.0, 1.0, 0.0)
    got = in_scatter_media(sun, medium, eye, d[None], np.zeros(1), np.full(1, 6.0), tol=1e-9)[0, 0]
    expected = _height_closed_form(eye, d, toward, 2.0, 0.0, 2.0, SIGMA_S, SIGMA_S + SIGMA_A, 0.0, 6.0)
    assert abs(got - expected) <= 1e-6 * expected, (got, expected)


# ------------------------------------------------------------ brute force, written out here


def _slab(o, d, lo, hi, t0, t1):
    """[t0, t1] ∩ the box along o + t·d (its own slab test)."""
    for axis in range(3):
        if d[axis] == 0.0:
            if not lo[axis] <= o[axis] <= hi[axis]:
                return t0, t0
            continue
        ta, tb = (lo[axis] - o[axis]) / d[axis], (hi[axis] - o[axis]) / d[axis]
        t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
    return t0, max(t0, t1)


def _hat_weights(x, lo, hi, n):
    """(N, n) weights of the n voxel centres of [lo, hi] at coordinates x: piecewise-linear
    interpolation, held beyond the outermost centres (np.interp of each unit vector)."""
    centres = lo + (np.arange(n) + 0.5) * (hi - lo) / n
    return np.stack([np.interp(x, centres, np.eye(n)[i]) for i in range(n)], axis=1)


def _brute_density(box: Box | None, grid: GridDensity | None):
    def rho(points):
        points = np.atleast_2d(points)
        out = np.ones(len(points))
        if box is not None:  # (a face's own points in, whatever the rounding of the clipped ends)
            out *= np.all((points >= box.min - 1e-9) & (points <= box.max + 1e-9), axis=1)
        if grid is not None:
            nz, ny, nx = grid.values.shape
            lo, hi = grid.bounds.min, grid.bounds.max
            w = [_hat_weights(points[:, axis], lo[axis], hi[axis], n) for axis, n in enumerate((nx, ny, nz))]
            inside = np.all((points >= lo - 1e-9) & (points <= hi + 1e-9), axis=1)
            out *= inside * np.einsum("pi,pj,pk,kji->p", w[0], w[1], w[2], grid.values.astype(np.float64))
        return out
    return rho


def _simpson(values, h):
    """Composite Simpson over an odd number of equally spaced values (along the last axis)."""
    return h / 3.0 * (values[..., 0] + values[..., -1] + 4 * values[..., 1:-1:2].sum(axis=-1)
                      + 2 * values[..., 2:-1:2].sum(axis=-1))


def _brute_point_light(eye, d, D, light_position, intensity, sigma_s, sigma_t, rho, extent, samples=2001,
                       light_samples=401):
    """(in-scattering, T_e(D)) along eye + s·d, s ∈ [0, D], lit by an isotropic point light with
    no occluder, the medium inside `extent` (lo, hi) only."""
    a, b = _slab(eye, d, extent[0], extent[1], 0.0, D)
    if b <= a:
        return 0.0, 1.0
    s = np.linspace(a, b, samples)
    x = eye + s[:, None] * d
    rho_x = rho(x)
    h = s[1] - s[0]
    eye_depth = np.concatenate([[0.0], np.cumsum(0.5 * (rho_x[1:] + rho_x[:-1]) * h)])
    u = np.linspace(0.0, 1.0, light_samples)
    path = x[:, None, :] + u[None, :, None] * (light_position - x)[:, None, :]  # x → light
    r = np.linalg.norm(light_position - x, axis=1)
    light_depth = _simpson(rho(path.reshape(-1, 3)).reshape(len(s), -1), 1.0 / (light_samples - 1)) * r
    integrand = sigma_s * rho_x * _isotropic() * intensity / r ** 2 * np.exp(-sigma_t * (eye_depth + light_depth))
    total_depth = eye_depth[-1]
    return _simpson(integrand, h), math.exp(-sigma_t * total_depth)


def _box_scene(medium_box, density=None, position=(0.3, 1.6, 6.0)):
    light = PointLight(v3(0.4, 3.2, -0.3), np.full(3, 20.0))
    scene = make_scene(grid_plane(0.0, 6.0, 2), lights=[light], width=8, height=6, sigma_s=SIGMA_S,
                       sigma_a=SIGMA_A, position=position, look_at=(0, 0.8, 0), fov_deg=60.0)
    return replace(scene, medium=replace(scene.medium, bounds=medium_box, density=density))


@pytest.mark.parametrize("eye", ["outside", "inside"])
def test_a_box_with_a_point_light_matches_a_brute_force_quadrature(eye):
    box = Box(v3(-1.5, 0.0, -1.2), v3(1.4, 2.5, 1.6))
    scene = _box_scene(box, position=(0.3, 1.6, 6.0) if eye == "outside" else (0.2, 1.2, 0.9))
    _compare_brute_force(scene, box, None, (box.min, box.max))


def test_a_grid_with_a_point_light_matches_a_brute_force_quadrature():
    values = np.random.default_rng(7).random((4, 5, 3)).astype(np.float32) * 2.0
    grid = GridDensity(values, Box(v3(-1.2, 0.2, -1.0), v3(1.3, 2.4, 1.1)))
    scene = _box_scene(None, grid)
    _compare_brute_force(scene, None, grid, (grid.bounds.min, grid.bounds.max))


def _compare_brute_force(scene, box, grid, extent):
    ys, xs = np.divmod(np.arange(scene.image.width * scene.image.height), scene.image.width)
    parts = {}
    exact_pixels(scene, ys, xs, parts=parts)
    dirs = primary_rays(scene.camera, scene.image)[ys, xs, 0]
    eye = scene.camera.position
    light = scene.lights[0]
    rho = _brute_density(box, grid)
    checked, worst = 0, 0.0
    for i, d in enumerate(dirs):
        if d[1] >= 0 or i % 3:  # every third ray that meets the floor (the brute force is slow)
            continue
        D = -eye[1] / d[1]
        hit = eye + D * d
        if np.max(np.abs(hit[[0, 2]])) > 5.9:  # off the floor's edge
            continue
        scatter, transmittance = _brute_point_light(eye, d, D, light.position, 20.0, SIGMA_S, SIGMA_S + SIGMA_A,
                                                    rho, extent)
        assert parts["depth"][i] == pytest.approx(D, rel=1e-9)
        assert parts["lights"][0, i, 0] == pytest.approx(scatter, rel=1e-4, abs=1e-9), i
        assert parts["transmittance"][i, 0] == pytest.approx(transmittance, rel=1e-5), i
        if scatter > 0:  # (a ray that misses the fog scatters nothing)
            worst = max(worst, abs(parts["lights"][0, i, 0] / scatter - 1.0))
        checked += 1
    print(f"{checked} rays, in-scattering within {worst:.2e} relative")  # measured: 4e-6 to 1.5e-5, the brute force's own error
    assert checked >= 5


def test_exact_optical_depth_in_a_grid_is_exact_for_a_linear_density():
    """A grid whose values are linear in x has ρ linear between the outermost centres: the
    optical depth of a segment there is the mean of its end values times its length."""
    nx = 6
    values = np.broadcast_to(np.arange(nx, dtype=np.float32), (3, 4, nx)).copy()
    grid = GridDensity(values, Box(v3(0, 0, 0), v3(6, 4, 3)))
    scene = make_scene()
    medium = replace(scene.medium, density=grid)
    o, d = v3(0.5, 1.0, 1.0), v3(1.0, 0.0, 0.0)  # from the first centre, x = 0.5, to the last, 5.5
    assert optical_depth(medium, o, d[None], 0.0, 5.0)[0] == pytest.approx(0.5 * (0 + 5) * 5.0, rel=1e-13)
    # Past the last centre the value holds (5), and beyond the bounds it is 0.
    assert optical_depth(medium, o, d[None], 0.0, 9.0)[0] == pytest.approx(12.5 + 5 * 0.5, rel=1e-13)


def test_a_homogeneous_box_around_the_whole_scene_is_the_unbounded_medium():
    light = PointLight(v3(0.4, 3.2, -0.3), np.full(3, 20.0))
    sun = _sun()
    scene = make_scene(grid_plane(0.0, 6.0, 2), lights=[light, sun], width=10, height=6, sigma_s=SIGMA_S,
                       sigma_a=SIGMA_A, far=30.0)
    ys, xs = np.divmod(np.arange(60), 10)
    unbounded = exact_pixels(scene, ys, xs)
    # The box holds every ray to its far end (30 from the eye); the sun's light also crosses
    # the box's top, 100 above: in the box it is attenuated over that path.
    bounded = replace(scene, medium=replace(scene.medium, bounds=Box(v3(-100, -100, -100), v3(100, 100, 100))))
    point_only = replace(scene, lights=(light,))
    np.testing.assert_allclose(exact_pixels(replace(bounded, lights=(light,)), ys, xs),
                               exact_pixels(point_only, ys, xs), rtol=1e-6)
    assert np.all(exact_pixels(bounded, ys, xs) <= unbounded * (1 + 1e-9))


def test_the_translucent_path_takes_the_same_medium():
    """exact's path for scenes with translucent objects (reference/translucency.py) reads the
    medium through the same functions: a half-clear pane behind the camera, which no ray or
    light path meets, leaves a bounded height fog's image as the opaque path renders it."""
    box = Box(v3(-1.5, 0.0, -1.2), v3(1.4, 2.5, 1.6))
    scene = _box_scene(box, HeightDensity(0.5, 1.0))
    pane = np.array([[[-1.0, 0.0, 9.0], [1.0, 0.0, 9.0], [0.0, 1.0, 9.5]]])
    geometry = scene.geometry
    triangles = np.concatenate([geometry.triangles, pane])
    with_pane = replace(scene, geometry=replace(
        geometry, triangles=triangles, albedo=np.concatenate([geometry.albedo, [[0.5, 0.5, 0.5]]]),
        object_id=np.concatenate([geometry.object_id, [geometry.object_id.max() + 1]]),
        normals=None, outward=None, opacity=np.concatenate([np.ones((geometry.count, 3)), [[0.5, 0.5, 0.5]]])))
    assert with_pane.geometry.translucent
    ys, xs = np.divmod(np.arange(48), 8)
    np.testing.assert_allclose(exact_pixels(with_pane, ys, xs), exact_pixels(scene, ys, xs), rtol=1e-7)


def test_the_announced_time_of_exact_counts_a_grid():
    """exact's estimate (the command line announces it) grows with a grid's planes squared."""
    from clrays.reference.exact import GRID_SECONDS_PER_RAY_PLANE2, estimate_seconds

    scene = _box_scene(None)
    grid = GridDensity(np.ones((10, 20, 30), np.float32), Box(v3(0, 0, 0), v3(1, 1, 1)))
    gridded = replace(scene, medium=replace(scene.medium, density=grid))
    added = estimate_seconds(gridded) - estimate_seconds(scene)
    assert added == pytest.approx(48 * GRID_SECONDS_PER_RAY_PLANE2 * 66 ** 2)
