"""Numerical stability: the configurations where volumetric renderers break (docs/design.md §6),
for every light type and every method (minmax, raymarch, exact).

Each test renders small images and asserts that every pixel is finite and non-negative,
and, where a reference exists, the yardstick of test_minmax: mean relative error ≤ 1 % and
99th percentile ≤ 5 % against `exact` on pixels with ≥ 1 % of the mean radiance, depth
edges excluded. docs/stability.md lists each configuration, how clrays handles it and the
error measured here (run with `-s` to see the numbers). Random scenes and float32 vs
float64 are in test_stability_random.py.
"""
from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np
import pytest

from clrays.scene.camera import camera_basis, half_extents, primary_rays
from clrays.reference.metrics import depth_edges, depth_map, image_error, luminance
from clrays.scene.geometry import box_triangles, sphere_triangles
from clrays.physics.radiometry import in_scatter_unoccluded, lamp_radius, phase
from conftest import (TEST_ON_POCL, DirectionalLight, Phase, PointLight, SpotLight, grid_plane, make_scene, v3,
                      with_closed_solid)

METHODS = ("minmax", "raymarch", "exact")
MEAN_TOLERANCE, P99_TOLERANCE = 0.01, 0.05
# raymarch is the brute-force reference: compared at a step count where its own error is
# small, so that what is measured is the configuration, not the step size.
RAYMARCH_STEPS = 2048


def unit(*xs) -> np.ndarray:
    x = np.array(xs, dtype=np.float64)
    return x / np.linalg.norm(x)


def occluders() -> np.ndarray:
    """A floor, a slab hung above it and a block standing on it: shafts and surface shadows."""
    return np.concatenate([grid_plane(0.0, 8.0, 4), box_triangles([-1.5, 1.5, -1.0], [0.5, 1.8, 0.5]),
                           box_triangles([1.0, 0.0, -2.0], [1.8, 1.2, -1.2])])


LIGHT_POSITION = v3(0.3, 4.0, -0.5)


def lights_at(position, towards=(0.0, 0.0, -0.5)) -> dict:
    """One light of each type: a point and a spot light at `position` (the spot aimed at
    `towards`), and a sun whose light arrives from `position` as seen from the origin."""
    position = np.asarray(position, dtype=np.float64)
    return {
        "point": PointLight(position, np.full(3, 40.0)),
        "spot": SpotLight(position, unit(*(np.asarray(towards) - position)), 50.0, np.full(3, 60.0)),
        "directional": DirectionalLight(unit(*-position), np.full(3, 1.5)),
    }


def stress_scene(light, triangles="default", **settings):
    """The suite's scene: `occluders()` in a thin grey fog with a forward-scattering phase,
    seen from above (few depth edges), 24 × 24 pixels."""
    defaults = dict(width=24, height=24, position=(0, 4.5, 7), look_at=(0, 0.8, 0), far=25.0, sigma_s=0.08,
                    sigma_a=0.02, phase=Phase("hg", 0.3), steps=RAYMARCH_STEPS)
    defaults.update(settings)
    return make_scene(occluders() if isinstance(triangles, str) else triangles, [light], **defaults)


def render_all(renderer, scene, methods=METHODS) -> dict:
    return {method: renderer.render(scene, method).image for method in methods}


def assert_finite_non_negative(image, label=""):
    bad = ~np.isfinite(image)
    assert not bad.any(), f"{label}: {bad.sum()} non-finite values, first at {np.argwhere(bad)[0].tolist()}"
    assert image.min() >= 0.0, f"{label}: negative radiance {image.min():.3e} at " \
                               f"{np.unravel_index(image.argmin(), image.shape)}"


def error_against(image, reference, scene):
    """image_error with depth edges excluded; None when the reference is black."""
    if luminance(reference).max() <= 0.0:
        return None
    return image_error(image, reference, depth_edges(depth_map(scene)))


def assert_matches_exact(image, reference, scene, label="", min_fraction=0.1):
    """The yardstick of test_minmax, on at least `min_fraction` of the pixels (so that a
    test cannot pass by comparing nothing). A black reference asks for a black image."""
    error = error_against(image, reference, scene)
    if error is None:
        assert image.max() == 0.0, f"{label}: {image.max():.3e} where exact is black"
        print(f"{label}: black, as exact")
        return
    print(f"{label} vs exact: {error}")
    assert error.pixels >= min_fraction * image.shape[0] * image.shape[1], \
        f"{label}: too few pixels compared ({error})"
    assert error.mean <= MEAN_TOLERANCE and error.p99 <= P99_TOLERANCE, f"{label}: {error}"


# --------------------------------------------------------------------------- the epipole

# A camera looking nearly level over the floor, so that lights can sit anywhere around it.
EPIPOLE_CAMERA = dict(position=(0.0, 2.0, 8.0), look_at=(0.0, 1.0, 0.0), fov_deg=50.0)


def _screen_point(sx, sy, distance):
    """The point at `distance` along the ray through screen point (sx, sy) ∈ [-1, 1]² of
    the epipole camera (square image, so the same tangent both ways)."""
    camera = make_scene(**EPIPOLE_CAMERA).camera
    right, up, forward = camera_basis(camera)
    tangent = math.tan(math.radians(EPIPOLE_CAMERA["fov_deg"]) / 2)
    return camera.position + distance * unit(*(forward + sx * tangent * right + sy * tangent * up))


def _epipole_light_positions():
    camera = make_scene(**EPIPOLE_CAMERA).camera
    right, up, forward = camera_basis(camera)
    eye = camera.position
    return {
        "in_view": _screen_point(0.2, 0.6, 6.0),
        "at_screen_edge": _screen_point(1.0, 0.5, 6.0),
        "just_off_screen": _screen_point(1.08, 0.5, 6.0),
        "behind_camera": eye - 3.0 * forward + 2.0 * up,  # slices converge at the anti-epipole
        "in_focal_plane": eye + 3.0 * right + 1.0 * up,  # epipole at infinity
        "behind_look_at": eye + 12.0 * forward,  # epipole at the centre, light past the target
    }


def _epipole_scene(case, kind, size=24, **settings):
    """Light (or, for the sun, the direction it shines from) placed relative to the camera.
    An odd `size` puts a pixel centre exactly on the screen's centre (β = 0 or π there)."""
    eye = np.asarray(EPIPOLE_CAMERA["position"], dtype=np.float64)
    camera = dict(EPIPOLE_CAMERA)
    if case in ("looking_at_light", "looking_away_from_light"):
        light = lights_at(LIGHT_POSITION)[kind]
        source = LIGHT_POSITION if kind != "directional" else eye - light.direction
        camera["look_at"] = tuple(source if case == "looking_at_light" else 2 * eye - source)
        if kind == "spot":  # aimed back at the camera, so the camera sits inside its cone
            light = replace(light, direction=unit(*(eye - LIGHT_POSITION)))
    else:
        position = _epipole_light_positions()[case]
        light = lights_at(position)[kind]
        if kind == "directional":
            light = replace(light, direction=unit(*(eye - position)))
    return stress_scene(light, width=size, height=size, **camera, **settings)


EPIPOLE_CASES = ["in_view", "at_screen_edge", "just_off_screen", "behind_camera", "in_focal_plane",
                 "behind_look_at", "looking_at_light", "looking_away_from_light"]


@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
@pytest.mark.parametrize("case", EPIPOLE_CASES)
def test_epipole_geometry_matches_exact(renderer, case, kind):
    scene = _epipole_scene(case, kind)
    images = render_all(renderer, scene)
    for method, image in images.items():
        assert_finite_non_negative(image, f"{case}/{kind}/{method}")
    for method in ("minmax", "raymarch"):
        assert_matches_exact(images[method], images["exact"], scene, f"epipole {case}/{kind}/{method}")


@pytest.mark.parametrize("case", ["looking_at_light", "looking_away_from_light"])
@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
def test_ray_on_the_eye_light_axis_is_not_dropped(renderer, case, kind):
    """The centre pixel of an odd image lies exactly on the axis (β = 0 or β = π): its ray
    has in-scattered light like its neighbours (once it was skipped as having no γ extent)."""
    scene = _epipole_scene(case, kind, size=25, albedo=0.0)
    images = render_all(renderer, scene)
    centre = {method: float(image[12, 12, 0]) for method, image in images.items()}
    around = images["exact"][11:14, 11:14, 0]
    print(f"axis pixel {case}/{kind}: {centre}, exact neighbours {around.min():.4g}..{around.max():.4g}")
    assert centre["exact"] > 0.0
    assert centre["minmax"] == pytest.approx(centre["exact"], rel=0.02)


# --------------------------------------------------------------------------- β → 0

def _light_pixel_scene(kind, spp, **settings):
    """A narrow view aimed exactly at the light: the light sits on the centre of pixel (4, 4)."""
    light = lights_at(LIGHT_POSITION)[kind]
    eye = v3(0.5, 2.0, 7.0)
    if kind == "spot":
        light = replace(light, direction=unit(*(eye - LIGHT_POSITION)), cone_deg=30.0)
    return stress_scene(light, width=9, height=9, spp=spp, position=tuple(eye), look_at=tuple(LIGHT_POSITION),
                        fov_deg=20.0, **settings)


@pytest.mark.parametrize("kind", ["point", "spot"])
def test_light_pixel_converges_with_supersampling(renderer, kind):
    """β → 0: a ray passing the light at distance h gathers ~π/h. The pixel average is
    finite (∫dA/h converges) and supersampling converges to it; the ray exactly through
    the light (spp 1) is finite (the lamp, radiometry.py); the neighbours do not feel it."""
    from clrays.reference.exact import render_exact

    reference = render_exact(_light_pixel_scene(kind, 256), rows=slice(4, 5))[0, 4, 0]
    values = {}
    for spp in (1, 16, 64):
        scene = _light_pixel_scene(kind, spp)
        images = render_all(renderer, scene)
        for method, image in images.items():
            assert_finite_non_negative(image, f"light pixel {kind} spp {spp} {method}")
            values[method, spp] = float(image[4, 4, 0])
        for method in ("minmax", "raymarch"):
            neighbours = np.delete(images[method][3:6, 3:6].reshape(9, 3), 4, axis=0)
            exact_neighbours = np.delete(images["exact"][3:6, 3:6].reshape(9, 3), 4, axis=0)
            np.testing.assert_allclose(neighbours, exact_neighbours, rtol=2e-3,
                                       err_msg=f"{kind} spp {spp}: {method} neighbours of the light pixel")
            if spp > 1:
                assert values[method, spp] == pytest.approx(values["exact", spp], rel=5e-3), (method, spp)
    print(f"light pixel {kind}: " + ", ".join(f"{m} spp {s}: {v:.6g}" for (m, s), v in values.items())
          + f"; exact at spp 256: {reference:.6g}")
    assert values["minmax", 1] == pytest.approx(values["exact", 1], rel=0.02)  # the ray through the light
    for method in METHODS:
        distance = [abs(values[method, spp] - reference) for spp in (1, 16, 64)]
        assert distance[0] > distance[1] > distance[2], (method, distance)


@pytest.mark.parametrize("sampling", ["epipolar", "pixel"])
def test_a_spot_lights_cone_beside_its_apex(renderer, sampling):
    """A spot light seen from the side, in view: the rays of the pixels around it pass the
    light within a pixel and cross both sides of its cone next to the apex, where the
    cone's quadric has two nearly equal roots. Found in float32 along the ray, they put
    the lit part far off (before the cone was taken as a wedge of γ: 1.8 % at the light's
    pixel here, 32 % at 1280×720 on the bunny); measured since at most 1.3e-4."""
    from clrays.reference.exact import render_exact

    direction = unit(0.15, -0.55, 0.82)
    light = SpotLight(v3(-0.6, 4.2, -4.0), direction, 38.0, np.full(3, 400.0))
    scene = make_scene(grid_plane(0.0, 24.0, 2), [light], width=320, height=180, position=(0.5, 1.6, 7.5),
                       look_at=(0.0, 1.6, 0.0), far=30.0, sigma_s=0.06, sigma_a=0.01, albedo=0.0)
    scene = replace(scene, render=replace(scene.render, sampling=sampling))
    right, up, forward = camera_basis(scene.camera)
    to_light = light.position - scene.camera.position
    tan_x, tan_y = half_extents(scene.camera, scene.image)
    x = int((1 + (to_light @ right) / (to_light @ forward) / tan_x) / 2 * scene.image.width)
    y = int((1 - (to_light @ up) / (to_light @ forward) / tan_y) / 2 * scene.image.height)
    image = renderer.render(scene, "minmax").image[y - 1:y + 2, x - 1:x + 2]
    exact = render_exact(scene, rows=slice(y - 1, y + 2))[:, x - 1:x + 2]
    error = np.abs(luminance(image) - luminance(exact)) / luminance(exact)
    print(f"spot light's pixel ({y}, {x}) and neighbours, {sampling}: relative error {error.max():.2e}")
    assert error.max() < 1e-3, error


# --------------------------------------------------------------------------- d_el → 0

def _eye_at_light_scenes(kind, offset):
    """The eye at a light (plus `offset`), looking down past two blocks: with the blocks, and
    with the floor alone (the unshadowed result, by the same method)."""
    light = lights_at(LIGHT_POSITION, towards=(0.3, 0.0, -1.8))[kind]
    blocks = np.concatenate([box_triangles([-1.5, 1.5, -2.0], [0.5, 1.8, -1.5]),
                             box_triangles([1.0, 0.0, -2.0], [1.8, 1.2, -1.2])])
    settings = dict(position=tuple(LIGHT_POSITION + [offset, 0.0, 0.0]), look_at=(0.3, 0.0, -1.5), fov_deg=70.0)
    floor = grid_plane(0.0, 8.0, 4)
    return (stress_scene(light, np.concatenate([floor, blocks]), **settings),
            stress_scene(light, floor, **settings))


@pytest.mark.parametrize("offset", [0.0, 1e-6], ids=["at_light", "1e-6_from_light"])
@pytest.mark.parametrize("kind", ["point", "spot"])
def test_eye_at_the_light_is_unshadowed(renderer, kind, offset):
    """d_el → 0 (docs/design.md §6): everything the eye sees, the light sees, so the render equals
    the same method's render without the blocks wherever the blocks are not in view; the
    1/s² divergence at s = 0 is cut by the lamp (radiometry.py), so every method is finite,
    and minmax (its unshadowed fallback) matches exact."""
    with_blocks, floor_only = _eye_at_light_scenes(kind, offset)
    assert np.linalg.norm(with_blocks.camera.position - LIGHT_POSITION) < lamp_radius(with_blocks)
    same_depth = depth_map(with_blocks) == depth_map(floor_only)
    assert 0.3 < same_depth.mean() < 0.95
    shadowed, unshadowed = render_all(renderer, with_blocks), render_all(renderer, floor_only)
    for method in METHODS:
        assert_finite_non_negative(shadowed[method], f"eye at {kind} {method}")
        difference = np.abs(shadowed[method] - unshadowed[method])[same_depth].max()
        print(f"eye at {kind} ({offset:g}) {method}: max {shadowed[method].max():.4g}, "
              f"|with blocks - floor only| ≤ {difference / unshadowed[method][same_depth].max():.1e} relative")
        np.testing.assert_allclose(shadowed[method][same_depth], unshadowed[method][same_depth], rtol=1e-5,
                                   err_msg=f"{method}: a block shadows what the eye at the light sees")
    assert_matches_exact(shadowed["minmax"], shadowed["exact"], with_blocks, f"eye at {kind} ({offset:g}) minmax")


def test_eye_at_the_light_is_the_lamp_closed_form(renderer):
    """With the eye at an isotropic point light in a non-absorbing medium (σt = σs), each
    ray's in-scattering is σs·I/(4π)·∫_r^D e^{-2σs·s}/s² ds from the lamp radius r to its
    depth: the value the lamp gives the divergent integral, by scipy."""
    from scipy.integrate import quad

    light = PointLight(LIGHT_POSITION, np.full(3, 40.0))
    scene = stress_scene(light, grid_plane(0.0, 8.0, 4), position=tuple(LIGHT_POSITION), look_at=(0.3, 0.0, -1.5),
                         sigma_a=0.0, phase=Phase(), albedo=0.0, width=5, height=5)
    radius, depth = lamp_radius(scene), np.minimum(depth_map(scene), scene.camera.far)
    sigma = 0.08
    # In u = 1/s the integral is ∫_{1/D}^{1/r} e^{-2σ/u} du, smooth and bounded.
    expected = np.array([[sigma * 40.0 / (4 * math.pi) * quad(lambda u: math.exp(-2 * sigma / u), 1 / d, 1 / radius,
                                                              epsrel=1e-12, limit=200)[0] for d in row]
                         for row in depth])
    for method in ("minmax", "exact"):
        image = renderer.render(scene, method).image[..., 0]
        np.testing.assert_allclose(image, expected, rtol=1e-5, err_msg=method)


# --------------------------------------------------------------------------- invariances

def _moved(scene, offset):
    offset = np.asarray(offset, dtype=np.float64)
    lights = tuple(replace(light, position=light.position + offset) if hasattr(light, "position") else light
                   for light in scene.lights)
    camera = replace(scene.camera, position=scene.camera.position + offset, look_at=scene.camera.look_at + offset)
    return replace(scene, camera=camera, lights=lights,
                   geometry=replace(scene.geometry, triangles=scene.geometry.triangles + offset))


def _scaled(scene, k):
    """Lengths × k, σ × 1/k, point intensities × k² (irradiance unchanged): the same image."""
    lights = tuple(replace(light, position=light.position * k, intensity=light.intensity * k * k)
                   if hasattr(light, "position") else light for light in scene.lights)
    camera = replace(scene.camera, position=scene.camera.position * k, look_at=scene.camera.look_at * k,
                     far=scene.camera.far * k)
    medium = replace(scene.medium, sigma_s=scene.medium.sigma_s / k, sigma_a=scene.medium.sigma_a / k)
    return replace(scene, camera=camera, lights=lights, medium=medium,
                   geometry=replace(scene.geometry, triangles=scene.geometry.triangles * k))


def assert_same_image(image, reference, label, tolerance=1e-3):
    error = image_error(image, reference)
    print(f"{label}: {error}")
    assert error.mean <= tolerance and error.p99 <= tolerance, f"{label}: {error}"


@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
def test_translation_invariance(renderer, kind):
    """Device math is relative to the camera (frame.py translates in float64)."""
    scene = stress_scene(lights_at(LIGHT_POSITION)[kind])
    far_away = _moved(scene, (1e4, -3e3, 5e3))
    for method in METHODS:
        moved = renderer.render(far_away, method).image
        assert_finite_non_negative(moved, f"moved {kind} {method}")
        assert_same_image(moved, renderer.render(scene, method).image, f"translated {kind} {method}")


@pytest.mark.parametrize("k", [1e-3, 1e3])
@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
def test_scale_invariance(renderer, kind, k):
    scene = stress_scene(lights_at(LIGHT_POSITION)[kind])
    for method in METHODS:
        scaled = renderer.render(_scaled(scene, k), method).image
        assert_finite_non_negative(scaled, f"scaled {kind} {method}")
        assert_same_image(scaled, renderer.render(scene, method).image, f"scaled ×{k:g} {kind} {method}")


# --------------------------------------------------------------------------- monotonicity

def _in_scatter_scene(light, parts, **settings):
    """Black surfaces and background: the image is the in-scattered light alone."""
    return stress_scene(light, np.concatenate(parts), albedo=0.0, background=0.0, **settings)


# The floor and four posts at the corners fix the scene's bounds (and so the directional
# map's fit); every occluder added after them lies inside.
_FRAME = [grid_plane(0.0, 8.0, 4)] + [box_triangles([x, 0.0, z], [x + 0.1, 3.0, z + 0.1])
                                      for x in (-8.0, 7.9) for z in (-8.0, 7.9)]
_ADDED = [box_triangles([-1.5, 1.5, -1.0], [0.5, 1.8, 0.5]), box_triangles([1.0, 0.0, -2.0], [1.8, 1.2, -1.2]),
          box_triangles([-0.5, 2.5, -0.8], [0.9, 2.6, 0.2]), sphere_triangles([-2.0, 1.0, 1.0], 0.6, 12)]


# On NVIDIA's OpenCL (an H100), the per-pixel walk and the line samples of a spot light's
# in-scattering differ by up to 6.1e-5 of a pixel (on PoCL they agree within 1e-6): 6 pixels of
# 576 are walked alone with no geometry and interpolated from line samples with the floor in,
# and come out brighter by that much.
_SPOT_OFF_POCL = pytest.mark.xfail(not TEST_ON_POCL, strict=False,
                                   reason="off PoCL the walk and the line samples of a spot light differ by "
                                          "up to 6.1e-5 (H100): a fixed-up pixel may brighten by that much")


@pytest.mark.parametrize("kind", ["point", pytest.param("spot", marks=_SPOT_OFF_POCL), "directional"])
def test_adding_an_occluder_never_adds_light(renderer, kind):
    """In-scattering only (black surfaces): each occluder added can only shorten rays and
    shadow more of them, so no pixel brightens; and 0 ≤ every result ≤ the unshadowed one
    (no geometry at all: rays to `far`, nothing shadowed). Float32 sums of the same lit
    runs, merged differently, may differ by rounding: 1e-6 relative is allowed for that."""
    light = lights_at(LIGHT_POSITION)[kind]
    for method in METHODS:
        previous = renderer.render(_in_scatter_scene(light, [np.zeros((0, 3, 3))]), method).image
        unshadowed = previous
        worst = 0.0
        for count in range(len(_ADDED) + 1):
            image = renderer.render(_in_scatter_scene(light, _FRAME + _ADDED[:count]), method).image
            assert_finite_non_negative(image, f"{kind} {method} with {count} occluders")
            increase = (image - previous) / np.maximum(previous, 1e-30)
            worst = max(worst, float(increase.max()))
            assert np.all(image <= previous * (1 + 1e-6)), \
                f"{kind} {method}: occluder {count} brightens a pixel by {increase.max():.2e}"
            assert np.all(image <= unshadowed * (1 + 1e-6))
            previous = image
        print(f"monotone {kind} {method}: largest increase {worst:.1e}")


@pytest.mark.xfail(strict=True, reason="the directional shadow map is fitted to the scene bounds: an occluder "
                   "that grows them refits the map and moves shadow edges by up to a texel; measured: a pixel "
                   "brightens by 0.18 % (minmax), 0.036 % (raymarch) at a shaft edge (0.44 and 0.51 % with "
                   "the map over the bounding sphere, not the bounds' outline)")
def test_an_occluder_that_grows_the_bounds_never_adds_light(renderer):
    light = lights_at(LIGHT_POSITION)["directional"]
    parts = [grid_plane(0.0, 8.0, 4), box_triangles([-1.5, 1.5, -1.0], [0.5, 1.8, 0.5]),
             box_triangles([1.0, 0.0, -2.0], [1.8, 1.2, -1.2]), box_triangles([-0.5, 2.5, -0.8], [0.9, 2.6, 0.2])]
    worst = {}
    for method in ("minmax", "raymarch"):
        images = [renderer.render(_in_scatter_scene(light, parts[:count], width=32, height=32), method).image
                  for count in range(1, len(parts) + 1)]
        worst[method] = max(float(((b - a) / np.maximum(a, 1e-30)).max()) for a, b in zip(images, images[1:]))
    print(f"bounds-growing occluder, largest increase: {worst}")
    assert max(worst.values()) <= 1e-6


# --------------------------------------------------------------------------- the medium

@pytest.mark.parametrize("sigma_a", [0.0, 0.05], ids=["no_medium", "absorbing_only"])
@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
def test_no_scattering_is_the_surface_image_without_volume_stages(renderer, kind, sigma_a):
    """σs = 0: the image is the surfaces attenuated by e^{-σa·D}, exactly what exact gives,
    and no volume stage runs (docs/design.md §7)."""
    scene = stress_scene(lights_at(LIGHT_POSITION)[kind], sigma_s=0.0, sigma_a=sigma_a)
    reference = renderer.render(scene, "exact").image
    for method in ("minmax", "raymarch"):
        result = renderer.render(scene, method)
        assert_finite_non_negative(result.image, f"σs = 0 {kind} {method}")
        volume = {"rectify", "minmax", "integrand", "traverse", "raymarch"} & set(result.stage_ms)
        assert not volume, f"{method} ran {volume} with σs = 0"
        assert_matches_exact(result.image, reference, scene, f"σs = 0, σa = {sigma_a} {kind} {method}")


@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
def test_vanishing_medium_is_linear_in_sigma(renderer, kind):
    """σt → 0 (σs = σt = 1e-20): the in-scattering is σs times the σt = 0 integral, with no
    0/0 in the closed forms (expm1(-σt·Δs)/σt) and no underflow on the way."""
    scene = stress_scene(lights_at(LIGHT_POSITION)[kind], sigma_s=1e-20, sigma_a=0.0, albedo=0.0)
    images = render_all(renderer, scene)
    for method in ("minmax", "raymarch"):
        assert_finite_non_negative(images[method], f"σ = 1e-20 {kind} {method}")
        assert_matches_exact(images[method], images["exact"], scene, f"σ = 1e-20 {kind} {method}")


def test_opaque_fog_directional_is_the_closed_form(renderer):
    """σt = 1e3 over rays of length ~5: e^{-σt·s} underflows past s ≈ 0.1 and surfaces are
    black; what the eye sees is σs·E·ρ(cosθ)/σt from its first millimetres of fog."""
    sun = lights_at(LIGHT_POSITION)["directional"]
    scene = stress_scene(sun, sigma_s=500.0, sigma_a=500.0)
    dirs = primary_rays(scene.camera, scene.image)[:, :, 0]
    expected = 500.0 * 1.5 * phase(-(dirs @ sun.direction), Phase("hg", 0.3)) / 1000.0
    for method in METHODS:
        image = renderer.render(scene, method).image
        assert_finite_non_negative(image, f"opaque fog {method}")
        np.testing.assert_allclose(image[..., 0], expected, rtol=1e-3, err_msg=method)


@pytest.mark.parametrize("kind", ["point", "spot"])
def test_opaque_fog_near_a_light(renderer, kind):
    """σt = 200 with the light 2 cm from the eye: the light reaches a few centimetres, the
    rest of every ray (and every surface) underflows to 0. raymarch spreads its steps over
    the whole ray, so it needs 16384 of them to put ~100 in those centimetres."""
    eye = v3(0.0, 2.0, 3.0)
    light = lights_at(eye + [0.02, 0.0, -0.005], towards=(0.0, 0.0, -0.5))[kind]
    scene = stress_scene(light, position=tuple(eye), look_at=(0.0, 0.5, 0.0), sigma_s=100.0, sigma_a=100.0,
                         steps=16384)
    images = render_all(renderer, scene)
    for method, image in images.items():
        assert_finite_non_negative(image, f"opaque fog {kind} {method}")
    for method in ("minmax", "raymarch"):
        assert_matches_exact(images[method], images["exact"], scene, f"opaque fog near {kind} {method}")


@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
def test_opaque_fog_far_from_the_light_is_black(renderer, kind):
    """σt = 2e4: everything but the sun's first 0.1 mm of fog underflows. No NaN from 0·∞."""
    scene = stress_scene(lights_at(LIGHT_POSITION)[kind], sigma_s=1e4, sigma_a=1e4)
    images = render_all(renderer, scene)
    for method, image in images.items():
        assert_finite_non_negative(image, f"σt = 2e4 {kind} {method}")
        if kind != "directional":
            assert image.max() == 0.0, method
    if kind == "directional":
        for method in ("minmax", "raymarch"):
            assert_matches_exact(images[method], images["exact"], scene, f"σt = 2e4 sun {method}")


@pytest.mark.xfail(strict=True, reason="dense fog, σt·d_el ≈ 150: a lit run that starts far into a ray (here at "
                   "the spot cone's edge) is a difference of two nearly equal prefix values F(x1) - F(x0) of the "
                   "integrand table, carrying < 1e-20 of the row; measured minmax vs exact: mean 4.2 %, p99 22 % "
                   "(σt·d_el ≈ 75: mean 0.7 %, p99 1.8 %, within tolerance)")
def test_dense_fog_spot_light_matches_exact(renderer):
    light = SpotLight(LIGHT_POSITION, unit(0.1, -1, 0.1), 50.0, np.full(3, 60.0 * math.exp(60)))
    scene = stress_scene(light, triangles=None, sigma_s=10.0, sigma_a=10.0, albedo=0.0)
    images = render_all(renderer, scene, ("minmax", "exact"))
    assert_finite_non_negative(images["minmax"], "dense fog spot")
    assert_matches_exact(images["minmax"], images["exact"], scene, "dense fog spot minmax")


# --------------------------------------------------------------------------- geometry

_EYE = np.array([0.0, 4.5, 7.0])
GEOMETRY = {
    "zero_area": np.array([[[0, 2, 0], [0, 2, 0], [0, 2, 0]], [[0, 2, 0], [1, 2, 0], [2, 2, 0]],
                           [[-1, 2.5, 0], [1, 2.5, 0], [-1, 2.5, 0]]], dtype=float),
    "slivers": np.array([[[-3, 2.0, 0], [3, 2.0, 0], [0, 2.0, 1e-6]],
                         [[-3, 2.2, -1], [3, 2.2, -1], [3, 2.2 + 1e-7, -1]],
                         [[-2, 1, 0.5], [2, 3, 0.5], [0, 2, 0.5 + 1e-9]]], dtype=float),
    "duplicate_vertices_and_faces": np.concatenate([box_triangles([-1.5, 1.5, -1.0], [0.5, 1.8, 0.5])] * 2 + [
        np.array([[[0.5, 1.0, 1.0], [0.5, 1.0, 1.0], [1.5, 1.0, 2.0]], [[2, 1, 0], [3, 1, 0], [3, 1, 0]]],
                 dtype=float)]),
    # the eye lies inside this triangle, whose plane is edge-on to the camera
    "triangle_through_the_eye": np.array([[_EYE + [-3, -1, -1], _EYE + [3, -1, -1], _EYE + [0, 2, 2]]]),
    # a narrow sheet reaching from behind the eye to in front of it, beside and below it
    "triangle_across_the_eye_plane": np.array([[_EYE + [0.6, -0.3, 3], _EYE + [1.2, -0.3, 3], _EYE + [1.5, -2.5, -6]]]),
}


@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
@pytest.mark.parametrize("case", list(GEOMETRY))
def test_degenerate_triangles(renderer, case, kind):
    scene = stress_scene(lights_at(LIGHT_POSITION)[kind], np.concatenate([occluders(), GEOMETRY[case]]))
    images = render_all(renderer, scene)
    for method, image in images.items():
        assert_finite_non_negative(image, f"{case} {kind} {method}")
    for method in ("minmax", "raymarch"):
        assert_matches_exact(images[method], images["exact"], scene, f"{case}/{kind}/{method}")


def _closed_scenes():
    """Scenes whose visible medium and surfaces no light can reach."""
    box_around_eye = np.concatenate([occluders(), box_triangles(_EYE - 0.5, _EYE + 0.5)])
    sphere_around_light = np.concatenate([occluders(), sphere_triangles(LIGHT_POSITION, 0.4, 16)])
    room = np.concatenate([occluders(), box_triangles([-6.0, -0.01, -6.0], [6.0, 6.0, 8.0])])
    lights = lights_at(LIGHT_POSITION)
    closed = slice(len(occluders()), None)  # the box, the sphere, the room: closed solids, as loading marks them
    return {
        "camera_in_a_box": {kind: with_closed_solid(stress_scene(lights[kind], box_around_eye), closed)
                            for kind in lights},
        "light_in_a_sphere": {kind: with_closed_solid(stress_scene(lights[kind], sphere_around_light), closed)
                              for kind in ("point", "spot")},
        "sun_outside_a_room": {"directional": with_closed_solid(stress_scene(lights["directional"], room,
                                                                             position=(0, 3, 6)), closed)},
    }


CLOSED_CASES = [(case, kind) for case, scenes in _closed_scenes().items() for kind in scenes]


def _leak(image, scene):
    """(largest pixel, largest pixel / the unshadowed in-scattering of the same ray)."""
    dirs = primary_rays(scene.camera, scene.image)[:, :, 0].reshape(-1, 3)
    depth = np.minimum(depth_map(scene), scene.camera.far).reshape(-1)
    unshadowed = in_scatter_unoccluded(scene.lights[0], scene.medium, scene.camera.position, dirs, depth)
    ratio = luminance(image).reshape(-1) / np.maximum(luminance(unshadowed), 1e-300)
    return float(image.max()), float(ratio.max())


@pytest.mark.parametrize("case, kind", CLOSED_CASES)
def test_closed_geometry_lets_no_light_through(renderer, case, kind):
    """A closed box around the eye, a closed sphere around the light, a sun outside a closed
    room. exact: black, but for its float64 shadow volumes' cracks ~1e-16 wide between
    adjacent triangles. minmax and raymarch see the walls through the shadow map: what
    leaks past them must stay below the yardstick's floor, 1 % of the open scene's mean
    (test_closed_geometry_is_black_for_the_shadow_map_methods holds them to black)."""
    scene = _closed_scenes()[case][kind]
    light = scene.lights[0]
    open_scene = stress_scene(light, triangles=None, position=tuple(scene.camera.position))
    floor = 0.01 * luminance(renderer.render(open_scene, "exact").image).mean()
    for method, image in render_all(renderer, scene).items():
        assert_finite_non_negative(image, f"{case} {kind} {method}")
        largest, relative = _leak(image, scene)
        print(f"{case} {kind} {method}: largest {largest:.2e} = {largest / floor / 100:.1e} of the open mean, "
              f"{relative:.1e} of the same ray unshadowed")
        limit = 1e-12 * floor if method == "exact" else floor
        assert luminance(image).max() <= limit, f"{method}: {largest:.3e} where no light reaches"


def test_closed_geometry_is_black_for_the_shadow_map_methods(renderer):
    """A closed solid between the eye and the light: black, exactly (inputs.walled_off). From
    the maps alone a layer about a texel thick behind the walls had counted as lit; with a
    1024 map, largest pixel / the same ray unshadowed: camera in a box 1.3 % (minmax, point),
    2.0 % (minmax, sun), 1.9 % (raymarch, sun), 0.16 % (raymarch, point); light in a sphere
    0.07 % (minmax); sun outside a room 0.06 % (minmax), 0.05 % (raymarch)."""
    worst = {}
    for case, kind in CLOSED_CASES:
        scene = _closed_scenes()[case][kind]
        for method in ("minmax", "raymarch"):
            worst[case, kind, method] = _leak(renderer.render(scene, method).image, scene)[1]
    print("leak / unshadowed:", {key: f"{value:.1e}" for key, value in worst.items()})
    assert max(worst.values()) <= 1e-6


@pytest.mark.xfail(strict=True, raises=AssertionError, reason="from the shadow maps alone, a layer about a texel thick behind a wall "
                   "counts as lit: the same closed scenes with their solids not marked closed (an open mesh, a "
                   "room of separate walls), largest pixel / the same ray unshadowed: camera in a box 1.0 % "
                   "(minmax, point), 1.7 % (minmax, sun), 1.4 % (raymarch, sun), 0.20 % (raymarch, point); light "
                   "in a sphere 0.24 % (minmax, point); sun outside a room 0.054 % (minmax), 0.025 % (raymarch) "
                   "(the sun's: 2.2, 1.9, 0.07 and 0.05 % with its map over the bounding sphere). "
                   "With the runs' ends on the blockers a lit run of the layer may end on a wall's far edge: "
                   "minmax read 2.0 / 0.17 / 0.06 % with them at the texels")
def test_walls_not_marked_closed_let_no_light_through(renderer):
    """The scenes of test_closed_geometry_is_black_for_the_shadow_map_methods with their walls
    left unmarked, so the walled-off rule does not apply and the maps alone decide."""
    worst = {}
    for case, kind in CLOSED_CASES:
        scene = _closed_scenes()[case][kind]
        scene = replace(scene, geometry=replace(scene.geometry, outward=np.zeros_like(scene.geometry.outward)))
        for method in ("minmax", "raymarch"):
            worst[case, kind, method] = _leak(renderer.render(scene, method).image, scene)[1]
    print("leak / unshadowed, unmarked:", {key: f"{value:.1e}" for key, value in worst.items()})
    assert max(worst.values()) <= 1e-6


@pytest.mark.parametrize("kind", ["point", "directional"])
def test_a_camera_leaving_a_closed_box_reuses_only_what_holds(renderer, kind):
    """The eye inside the box (the light dark), outside it (lit), inside again: a session
    that keeps its stages gives each frame bit for bit as one that keeps none. A walled-off
    light's power is 0 in the scene the stage keys read, so the integrand and light-texture
    keys follow it; the trees, which do not read the power, are kept."""
    from clrays.session import Renderer

    inside, outside = _EYE, _EYE + np.array([0.0, 0.0, 1.5])
    scenes = [with_closed_solid(stress_scene(lights_at(LIGHT_POSITION)[kind], np.concatenate(
        [occluders(), box_triangles(_EYE - 0.5, _EYE + 0.5)]), position=tuple(eye)), slice(len(occluders()), None))
        for eye in (inside, outside, inside)]
    keeping = Renderer(renderer.device)
    fresh = Renderer(renderer.device, reuse=False)
    images = []
    for scene in scenes:
        kept = keeping.render(scene, "minmax").image
        assert np.array_equal(kept, fresh.render(scene, "minmax").image)
        images.append(kept)
    assert images[0].max() == 0.0 and images[2].max() == 0.0 and images[1].max() > 0.0


@pytest.mark.parametrize("kind", ["point", "spot"])
def test_camera_and_light_inside_a_room(renderer, kind):
    """Camera and light inside a closed room: every ray ends on a wall, the walls' outsides
    are never seen, and the methods agree with exact."""
    room = box_triangles([-6.0, -0.01, -6.0], [6.0, 6.0, 8.0])
    scene = stress_scene(lights_at(LIGHT_POSITION)[kind], np.concatenate([occluders(), room]), position=(0, 3, 6))
    images = render_all(renderer, scene)
    for method, image in images.items():
        assert_finite_non_negative(image, f"room {kind} {method}")
    for method in ("minmax", "raymarch"):
        assert_matches_exact(images[method], images["exact"], scene, f"room {kind} {method}")


@pytest.mark.slow
@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_a_million_triangles(renderer, method):
    """1,000,000 triangles (a 708 × 706 × 2 heightfield under a point light): memory and
    time reported, no crash, finite and non-negative. exact would take hours: not run."""
    import resource

    from clrays.session import Renderer

    n = 707
    xs = np.linspace(-8.0, 8.0, n + 1)
    x, z = np.meshgrid(xs, xs, indexing="ij")
    y = 0.3 * np.sin(1.7 * x) * np.cos(1.3 * z) + 0.3
    corners = np.stack([x, y, z], axis=-1)
    a, b, c, d = corners[:-1, :-1], corners[1:, :-1], corners[1:, 1:], corners[:-1, 1:]
    triangles = np.concatenate([np.stack([a, b, c], axis=2).reshape(-1, 3, 3),
                                np.stack([a, c, d], axis=2).reshape(-1, 3, 3)])
    extra = 1_000_000 - len(triangles)
    triangles = np.concatenate([triangles, np.repeat(box_triangles([-1.5, 1.5, -1.0], [0.5, 1.8, 0.5]),
                                                     extra // 12 + 1, axis=0)[:extra]])
    assert len(triangles) == 1_000_000
    scene = stress_scene(lights_at(LIGHT_POSITION)["point"], triangles, width=48, height=48)
    fresh = Renderer(renderer.device, reuse=False)  # every stage runs and is timed, none is kept
    start = time.perf_counter()
    result = fresh.render(scene, method)
    seconds = time.perf_counter() - start
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"1M triangles {method}: {seconds:.2f} s, device memory {result.device_bytes / 2**20:.1f} MiB, "
          f"host peak RSS {peak_mib:.0f} MiB, stages {result.stage_ms}")
    assert_finite_non_negative(result.image, f"1M triangles {method}")
    assert result.image.max() > 0
