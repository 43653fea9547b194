"""Epipolar sampling (`render.sampling: epipolar`, minmax's default) against the walk of
every camera sample (`pixel`), which it interpolates (docs/design.md §4.5). Surfaces are
black (albedo 0), so the images hold the in-scattering alone, the only part sampling
changes. Tolerances are about twice the largest errors measured when they were written
(given beside each)."""
from dataclasses import replace

import numpy as np
import pytest

from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.scene.geometry import box_triangles, sphere_triangles
from conftest import TEST_ON_POCL, DirectionalLight, PointLight, SpotLight, grid_plane, make_scene, v3


def _sampled(scene, sampling):
    return replace(scene, render=replace(scene.render, sampling=sampling))


def _both(renderer, scene):
    """(epipolar result, pixel result) of one scene."""
    return (renderer.render(_sampled(scene, "epipolar"), "minmax", reuse=False),
            renderer.render(_sampled(scene, "pixel"), "minmax", reuse=False))


def _error(renderer, scene):
    epipolar, pixel = _both(renderer, scene)
    assert np.all(np.isfinite(epipolar.image))
    return image_error(epipolar.image, pixel.image, depth_edges(depth_map(scene))), epipolar


def _shafts(light, extra=(), **kwargs):
    """Fog over a floor, under a slatted board that cuts the light into shafts, plus `extra`."""
    slats = [box_triangles([-3.0 + 0.8 * k, 3.0, -2.0], [-2.6 + 0.8 * k, 3.1, 2.0]) for k in range(8)]
    triangles = np.concatenate([grid_plane(0.0, 8.0, 4), *slats, *extra])
    settings = dict(width=96, height=64, far=25.0, sigma_s=0.08, sigma_a=0.02, albedo=0.0)
    return make_scene(triangles, [light], **{**settings, **kwargs})


POINT = PointLight(v3(0.3, 5.0, -0.5), np.full(3, 60.0))

#: Epipolar against the walk, relative RMSE and p99 of luminance, depth edges out: measured
#: at most 0.18 % and 1.18 % over the depth-break, epipole and directional cases below.
RMSE_TOLERANCE, P99_TOLERANCE = 0.004, 0.025


@pytest.mark.parametrize("occluder", ["pole", "sphere"])
def test_interpolation_matches_the_walk_across_depth_breaks(renderer, occluder):
    """A thin pole in front of the shafts, a sphere against a far wall: pixels whose
    distance the line samples beside them do not share are walked, not smeared."""
    if occluder == "pole":
        extra = [box_triangles([0.4, 0.0, 2.0], [0.47, 4.0, 2.07])]  # thinner than two pixels
    else:
        extra = [sphere_triangles(v3(-0.5, 1.2, -1.0), 0.9, 24), box_triangles([-8, 0, -4.2], [8, 8, -4.0])]
    error, epipolar = _error(renderer, _shafts(POINT, extra))
    assert epipolar.samples.fixed_up > 0  # the breaks were found
    assert error.rmse < RMSE_TOLERANCE and error.p99 < P99_TOLERANCE, error


def test_a_floor_at_a_grazing_angle_is_interpolated(renderer):
    """A floor out to the horizon under a light, 128 slices at 320×180 (a slice every few
    pixels, as 1024 are at 1280×720): the floor's distance changes across the slices, a
    pixel's by more than the threshold from either line's, and gather follows it with the
    blend of the two lines' distances instead of walking. Measured: 33 % of the camera
    samples fixed up (46 % when each line alone had to match), relative RMSE 0.08 % and p99
    1.7 % against the walk."""
    light = PointLight(v3(0.0, 6.0, -4.0), np.full(3, 80.0))
    scene = make_scene(grid_plane(0.0, 60.0, 4), [light], width=320, height=180, far=40.0, sigma_s=0.08,
                       sigma_a=0.02, albedo=0.0, slices=128, position=(0.0, 1.0, 10.0), look_at=(0.0, 0.6, 0.0),
                       fov_deg=60.0)
    error, epipolar = _error(renderer, scene)
    assert epipolar.samples.fixed_up < 0.4 * 320 * 180, epipolar.samples
    assert error.rmse < RMSE_TOLERANCE and error.p99 < P99_TOLERANCE, error


def test_lights_add_after_the_first_writes(renderer):
    """The in-scattering buffer is not cleared before epipolar sampling's gather, which
    writes every sample of the first light it takes; a second light adds to it. Two lights
    together give what each gives alone, summed (surfaces black: the in-scattering alone),
    on a frame rendered after a brighter one, whose values a buffer left as it was would
    keep."""
    second = SpotLight(v3(-2.0, 4.5, 1.0), np.array([0.3, -1.0, -0.2]) / np.linalg.norm([0.3, -1.0, -0.2]), 40.0,
                       np.full(3, 50.0))
    first, other = (_shafts(light, width=97, height=61) for light in (POINT, second))
    both = replace(first, lights=(POINT, second))
    renderer.render(_shafts(PointLight(v3(0.3, 5.0, -0.5), np.full(3, 6000.0)), width=97, height=61), "minmax",
                    reuse=False)  # a brighter frame first
    together = renderer.render(both, "minmax", reuse=False).image
    alone = sum(renderer.render(scene, "minmax", reuse=False).image for scene in (first, other))
    assert np.all(alone > 0.0)
    assert np.max(np.abs(together - alone) / alone) < 1e-5  # measured 1.2e-7: float rounding of one addition


CAMERA = dict(position=(0.0, 2.0, 8.0), look_at=(0.0, 1.5, 0.0), fov_deg=50.0)
EPIPOLES = {  # where the light projects, for the camera above
    "in view": v3(0.3, 3.5, 0.0),
    "off screen": v3(9.0, 4.0, 2.0),
    "at a corner": v3(-3.2, 3.6, 1.0),
    "behind the camera": v3(1.0, 4.0, 11.0),
}


@pytest.mark.parametrize("where", EPIPOLES)
def test_epipole_anywhere(renderer, where):
    scene = _shafts(PointLight(EPIPOLES[where], np.full(3, 60.0)), **CAMERA)
    error, _ = _error(renderer, scene)
    assert error.rmse < RMSE_TOLERANCE and error.p99 < P99_TOLERANCE, error


@pytest.mark.parametrize("direction", ["along the view", "against the view", "across the view"])
def test_directional_light_parallel_to_the_view(renderer, direction):
    """A sun straight behind the camera (anti-epipole at the centre), straight ahead
    (epipole at the centre), and parallel to the image plane (parallel lines)."""
    forward = v3(0.0, -0.5, -8.0) / np.linalg.norm([0.0, -0.5, -8.0])
    light_direction = {"along the view": forward, "against the view": -forward,
                       "across the view": v3(1.0, 0.0, 0.0)}[direction]
    board = [box_triangles([-3.0 + 0.8 * k, -1.0, -2.0], [-2.6 + 0.8 * k, 4.0, -1.9]) for k in range(8)]
    scene = make_scene(np.concatenate([grid_plane(0.0, 8.0, 4), *board]),
                       [DirectionalLight(light_direction, np.full(3, 1.5))], width=96, height=64, far=25.0,
                       sigma_s=0.08, sigma_a=0.02, albedo=0.0, **CAMERA)
    error, _ = _error(renderer, scene)
    assert error.rmse < RMSE_TOLERANCE and error.p99 < P99_TOLERANCE, error


def test_no_seams_between_slices(renderer):
    """Unshadowed fog under a spot light: the in-scattering is smooth, so the epipolar
    image follows the walked one everywhere, and its steps from pixel to pixel are no
    larger (a seam between two slices' lines would be a step of its own)."""
    spot = SpotLight(v3(0.0, 5.0, 0.0), v3(0.0, -1.0, 0.0), 35.0, np.full(3, 80.0))
    scene = make_scene(grid_plane(0.0, 8.0, 4), [spot], width=96, height=64, far=25.0, sigma_s=0.08,
                       sigma_a=0.02, albedo=0.0, **CAMERA)
    epipolar, pixel = _both(renderer, scene)
    lum_e, lum_p = epipolar.image.sum(-1), pixel.image.sum(-1)
    inside = lum_p > 0.05 * lum_p.max()
    assert np.max(np.abs(lum_e - lum_p)[inside] / lum_p[inside]) < 0.02  # measured 0.77 %
    for axis in (0, 1):
        steps_e, steps_p = np.abs(np.diff(lum_e, axis=axis)), np.abs(np.diff(lum_p, axis=axis))
        assert steps_e.max() <= 1.05 * steps_p.max() + 1e-6  # measured: equal


def test_orbit_adds_no_flicker(renderer):
    """60 frames of a camera orbiting the shafts: the change from frame to frame with
    epipolar sampling is that of the walk (sampling moves with the lines, so a flicker of
    its own would show as a larger change)."""
    scene = _shafts(POINT, width=64, height=40)
    changes = {"epipolar": [], "pixel": []}
    previous = {}
    for frame in range(60):
        angle = 2 * np.pi * frame / 60
        camera = replace(scene.camera, position=v3(8 * np.sin(angle), 2.5, 8 * np.cos(angle)))
        for sampling in changes:
            image = renderer.render(_sampled(replace(scene, camera=camera), sampling), "minmax", reuse=False).image
            if sampling in previous:
                changes[sampling].append(np.mean(np.abs(image - previous[sampling])))
            previous[sampling] = image
    epipolar, pixel = np.array(changes["epipolar"]), np.array(changes["pixel"])
    assert np.max(np.abs(epipolar - pixel) / pixel) < 1e-3  # measured 1.6e-4
    assert epipolar.mean() <= 1.001 * pixel.mean()  # measured 1.00002


def test_stats_count_what_sampling_did(renderer):
    """Every camera sample is interpolated or fixed up; under one box's shadow, at 640×360,
    most are interpolated, from fewer line samples than there are pixels. (On the other
    tests' 96×64 images most pixels are fixed up: near the light the in-scattering changes
    faster than samples two pixels apart follow. Sampling pays at large images: at 320×180
    the 1024 slices' lines, at the initial step of 3, compute more samples than there are
    pixels.)"""
    scene = make_scene(np.concatenate([grid_plane(0.0, 8.0, 4), box_triangles([-1.0, 3.0, -1.0], [1.0, 3.2, 1.0])]),
                       [POINT], width=640, height=360, far=25.0, sigma_s=0.08, sigma_a=0.02, albedo=0.0)
    epipolar, pixel = _both(renderer, scene)
    counts = epipolar.samples
    assert counts.interpolated + counts.fixed_up == 640 * 360
    assert counts.interpolated > 0.5 * 640 * 360
    assert 0 < counts.computed < 640 * 360
    assert pixel.samples is None


def test_a_textured_light_keeps_its_pattern(renderer):
    """scenes/gobo.yaml at 160×90: epipolar sampling stays within 1 % of `exact` and keeps
    the pattern's fine detail (the size of its steps from pixel to pixel) instead of
    smoothing it along the lines. Measured: relative RMSE 0.45 % against the per-pixel
    walk's 0.24 % (mean 0.31 % and p99 2.7 % both): a few pixels where the pattern's edge
    runs along a line between two samples that agree within the threshold."""
    from pathlib import Path

    from clrays.scene.load import load_scene

    scene = load_scene(Path(__file__).resolve().parents[2] / "scenes" / "gobo.yaml",
                       ["image.width=160", "image.height=90", "render.shadow_map=1024", "render.slices=1024",
                        "render.gamma_samples=1024"])
    exact = renderer.render(scene, "exact").image
    epipolar, pixel = _both(renderer, scene)
    edges = depth_edges(depth_map(scene))
    error_epipolar, error_pixel = image_error(epipolar.image, exact, edges), image_error(pixel.image, exact, edges)
    assert error_epipolar.rmse < 0.01 and error_epipolar.mean < 1.1 * error_pixel.mean, (error_epipolar, error_pixel)
    detail_epipolar, detail_pixel = (np.abs(np.diff(image.sum(-1), axis=1)).mean()
                                     for image in (epipolar.image, pixel.image))
    assert detail_epipolar > 0.97 * detail_pixel


#: A spot light whose cone reaches the image's last row (tilted towards the camera).
SPOT_TOWARDS_CAMERA = SpotLight(v3(0.3, 5.0, -0.5), np.array([0.3, -1.0, 0.9]) / np.linalg.norm([0.3, -1.0, 0.9]),
                                50.0, np.full(3, 80.0))


@pytest.mark.parametrize("light", ["point", "spot"])
def test_a_partial_last_vector_of_camera_samples(renderer, light):
    """gather and line_samples take 8 samples per work-item (cl/lanes.h); here neither the
    camera samples (97×61 pixels × 3 samples) nor the line samples (61) fill their last
    vector, and the samples there are interpolated or fixed up like the rest: the last row
    follows the walked one to its last pixel, and every camera sample is counted once."""
    scene = _shafts({"point": POINT, "spot": SPOT_TOWARDS_CAMERA}[light], width=97, height=61, spp=3,
                    line_samples=61)
    assert (97 * 61 * 3) % 8 and 61 % 8  # the last vectors are partial
    error, epipolar = _error(renderer, scene)
    pixel = renderer.render(_sampled(scene, "pixel"), "minmax", reuse=False)
    assert epipolar.samples.interpolated + epipolar.samples.fixed_up == 97 * 61 * 3
    assert error.rmse < RMSE_TOLERANCE and error.p99 < P99_TOLERANCE, error  # measured 0.05–0.08 %, 0.16–0.86 %
    last_e, last_p = epipolar.image[-1].sum(-1), pixel.image[-1].sum(-1)
    assert np.all(last_p > 0.0)  # the light reaches the last row
    # measured 0.10 % (point), 0.21 % (spot); a last vector left out is 100 % off
    assert np.max(np.abs(last_e - last_p) / last_p) < 0.01


def _epipole_pixel(scene):
    """(column, row) of the light's projection, pixel units, for a camera like CAMERA."""
    from clrays.scene.camera import camera_basis, half_extents

    right, up, forward = camera_basis(scene.camera)
    to_light = scene.lights[0].position - scene.camera.position
    tan_x, tan_y = half_extents(scene.camera, scene.image)
    z = to_light @ forward
    return ((to_light @ right / (z * tan_x) + 1) * scene.image.width / 2,
            (1 - to_light @ up / (z * tan_y)) * scene.image.height / 2)


def test_the_pixels_beside_the_epipole_walk_their_rays(renderer):
    """Within EPIPOLE_WALK_PIXELS of a point light's epipole every pixel is walked: it has
    the per-pixel walk's value, where interpolation would follow 1/sin β too slowly.
    Interpolated, these pixels were up to 8e-4 off (258 of the 390 by more than 5e-5). On
    PoCL the two walks are the same bits; NVIDIA's compiler builds fix_up's walk and
    traverse's apart, 9.5e-6 at most on an H100."""
    from clrays.stages.sampling import EPIPOLE_WALK_PIXELS

    scene = _shafts(PointLight(EPIPOLES["in view"], np.full(3, 60.0)), width=320, height=180, **CAMERA)
    epipolar, pixel = _both(renderer, scene)
    x, y = _epipole_pixel(scene)
    rows, columns = np.mgrid[0:scene.image.height, 0:scene.image.width]
    near = np.hypot(columns + 0.5 - x, rows + 0.5 - y) < 0.8 * EPIPOLE_WALK_PIXELS
    assert near.sum() > 20
    np.testing.assert_allclose(epipolar.image[near], pixel.image[near], rtol=1e-6 if TEST_ON_POCL else 5e-5)
    assert not np.allclose(epipolar.image[~near], pixel.image[~near], rtol=1e-6)  # the rest is interpolated


def test_each_line_gets_samples_as_long_as_it_is():
    """line_lengths: the longest line on the screen gets line_samples, a shorter one as many
    as keep that spacing (at least 2), a slice that misses the screen 2."""
    from types import SimpleNamespace

    from clrays.inputs import frame_inputs
    from clrays.stages.rectify import epipolar_frame
    from clrays.stages.sampling import beta_of_pseudo, line_lengths, line_ranges, pseudo_beta

    betas = np.linspace(0.0, np.pi, 1001)
    np.testing.assert_allclose(beta_of_pseudo(pseudo_beta(betas)), betas, atol=1e-12)  # the ends' β

    scene = _shafts(PointLight(EPIPOLES["off screen"], np.full(3, 60.0)), **CAMERA)
    inputs = frame_inputs(scene)
    params = epipolar_frame(inputs.scene, SimpleNamespace(inputs=inputs), 0)
    ranges = line_ranges(inputs.scene, params)
    n = 200
    lengths = line_lengths(inputs.scene, params, ranges, n)
    crosses = ranges[:, 0] <= ranges[:, 1]
    assert lengths.max() == n and (lengths[~crosses] == 2).all() and (lengths >= 2).all()
    assert lengths[crosses].min() < n // 2  # lines across a corner are short
    # twice the n: twice the samples on every line but the shortest (rounding up, and the floor of 2)
    doubled = line_lengths(inputs.scene, params, ranges, 2 * n - 1)
    long_lines = crosses & (lengths > 10)
    np.testing.assert_allclose((doubled[long_lines] - 1) / (lengths[long_lines] - 1), 2.0, rtol=0.1)
