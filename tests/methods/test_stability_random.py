"""Numerical stability, continued: random scenes (hypothesis), and the min-max path in
float32 (the device) against the same walk in float64 (numpy).

Scenes, helpers and the yardstick come from test_stability.py.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clrays.scene.camera import primary_rays
from clrays.structs import texel_coordinate, texel_gamma
from clrays.device import StageTimer
from clrays.inputs import frame_inputs, upload
from clrays.stages.integrand import segment_radiance
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.stages.minmax import minmax
from clrays.stages.integrand import integrand
from clrays.physics.radiometry import cone_interval, lamp_radius
from clrays.stages.raster import raster
from clrays.stages.rectify import rectify
from clrays.stages.traverse import traverse
from conftest import DirectionalLight, Phase, PointLight, SpotLight, grid_plane, make_scene
from test_stability import (LIGHT_POSITION, _epipole_scene, assert_finite_non_negative, assert_matches_exact,
                            box_triangles, error_against, lights_at, render_all, stress_scene, unit)

# --------------------------------------------------------------------------- random scenes

coordinate = st.floats(-1.0, 1.0)


@st.composite
def random_scenes(draw):
    """A camera somewhere above a floor looking at the middle, a light of any type, a
    medium from clear to thick, one to three boxes; 32 × 32 pixels. Cameras and lights
    inside a box are left out (closed geometry has its own tests), and so are point and
    spot lights in the plane of a box's face: that face is then edge-on to the light and
    its shadow boundary grazes every ray beside it, the case of
    test_grazing_shadow_boundary_* below (hypothesis found one with the light level with a
    box's top a metre from the camera: mean 1.98 %, p99 20.6 % against exact, the same
    with and without epipolar sampling). The shadow map is 2048:
    at the default 1024, hypothesis finds cameras close to a shadow boundary's plane,
    where the map's texel error is stretched along rays that cross it at a grazing angle;
    those are kept below (test_grazing_shadow_boundary_*) with their numbers."""
    boxes = []
    for _ in range(draw(st.integers(1, 3))):
        low = np.array([draw(st.floats(-3.0, 2.5)), draw(st.floats(0.0, 2.5)), draw(st.floats(-3.0, 2.5))])
        size = np.array([draw(st.floats(0.2, 2.0)) for _ in range(3)])
        boxes.append((low, low + size))

    def outside_boxes(point):
        return all(np.any(point < low - 0.05) or np.any(point > high + 0.05) for low, high in boxes)

    def off_face_planes(point):  # within 0.05 of a box face's plane, the face is edge-on to the light
        return all(np.all(np.abs(point - low) > 0.05) and np.all(np.abs(point - high) > 0.05) for low, high in boxes)

    position = np.array([draw(st.floats(-7.0, 7.0)), draw(st.floats(0.3, 7.0)), draw(st.floats(-7.0, 8.0))])
    look_at = np.array([draw(st.floats(-2.0, 2.0)), draw(st.floats(0.0, 2.0)), draw(st.floats(-2.0, 2.0))])
    light_position = np.array([draw(st.floats(-5.0, 5.0)), draw(st.floats(0.5, 7.0)), draw(st.floats(-5.0, 5.0))])
    kind = draw(st.sampled_from(["point", "spot", "directional"]))
    if np.linalg.norm(look_at - position) < 1.5 or not outside_boxes(position) or \
            (kind != "directional" and not (outside_boxes(light_position) and off_face_planes(light_position))):
        position = look_at + np.array([0.0, 4.0, 7.0])
        light_position = np.array([0.3, 6.5, -0.5])
    if kind == "point":
        light = PointLight(light_position, np.full(3, draw(st.floats(5.0, 200.0))))
    elif kind == "spot":
        target = look_at + 2.0 * np.array([draw(coordinate), 0.0, draw(coordinate)])
        light = SpotLight(light_position, unit(*(target - light_position)), draw(st.floats(15.0, 80.0)),
                          np.full(3, draw(st.floats(5.0, 200.0))))
    else:
        light = DirectionalLight(unit(draw(coordinate), draw(st.floats(-1.0, -0.15)), draw(coordinate)),
                                 np.full(3, draw(st.floats(0.2, 5.0))))
    sigma_s, sigma_a = draw(st.floats(0.005, 0.3)), draw(st.floats(0.0, 0.2))
    phase = draw(st.one_of(st.just(Phase()), st.floats(-0.6, 0.6).map(lambda g: Phase("hg", g))))
    triangles = np.concatenate([grid_plane(0.0, 8.0, 4)] + [box_triangles(low, high) for low, high in boxes])
    return make_scene(triangles, [light], width=32, height=32, position=tuple(position), look_at=tuple(look_at),
                      far=25.0, sigma_s=sigma_s, sigma_a=sigma_a, phase=phase, shadow_map=2048)


@settings(derandomize=True, max_examples=12, deadline=None)
@given(scene=random_scenes())
def test_random_scenes(renderer, scene):
    """Every method finite and non-negative; minmax's in-scattering (the scene with black
    surfaces) within the yardstick of exact. Surfaces are left out of the comparison
    because their hard shadow edges are the shadow map's business, not the min-max
    method's: hypothesis found scenes where they alone break the yardstick at the default
    map, kept below as test_surface_shadow_edges_*."""
    for method, image in render_all(renderer, scene).items():
        assert_finite_non_negative(image, f"random scene {method}")
    in_scatter = replace(scene, geometry=replace(scene.geometry, albedo=np.zeros_like(scene.geometry.albedo)))
    images = render_all(renderer, in_scatter, ("minmax", "exact"))
    light = scene.lights[0]
    label = (f"random {type(light).__name__} at {getattr(light, 'position', getattr(light, 'direction', None))}, "
             f"eye {scene.camera.position}, σs {scene.medium.sigma_s[0]:.3f}, σa {scene.medium.sigma_a[0]:.3f}")
    # A light in view makes the mean, and so the yardstick's 1 % floor, large: fewer pixels qualify.
    assert_matches_exact(images["minmax"], images["exact"], in_scatter, label, min_fraction=0.05)


def _grazing_shadow_boundary(case, size=1024):
    """Found by test_random_scenes at the default 1024 map (shrunk, rounded): cameras close
    to the plane of a block's shadow side, so that rays cross that shadow boundary at a
    grazing angle and a texel's error in the boundary is stretched along them.
    `size`: the shadow map and the epipolar texture (slices, γ texels)."""
    resolution = dict(shadow_map=size, slices=size, gamma_samples=size)
    if case == "point_level_with_a_block_top":  # rays cross the boundary at 7.5°
        triangles = np.concatenate([grid_plane(0.0, 8.0, 4), box_triangles([1.0, 0.0, 0.0], [3.0, 1.0, 1.0])])
        return make_scene(triangles, [PointLight(np.array([0.0, 1.0, -0.25]), np.full(3, 5.0))], width=32,
                          height=32, position=(4.0, 1.0, 0.0), look_at=(0.0, 0.0, 0.0), far=25.0, sigma_s=0.25,
                          sigma_a=0.0, albedo=0.0, **resolution)
    triangles = np.concatenate([grid_plane(0.0, 8.0, 4), box_triangles([-1.359, 0.745, 0.0], [-0.195, 2.645, 1.24])])
    return make_scene(triangles, [DirectionalLight(np.array([0.0, -1.0, 0.0]), np.full(3, 1.5))], width=32,
                      height=32, position=(0.0, 1.01, 0.0), look_at=(0.0, 0.0, 1.363), far=25.0, sigma_s=0.3,
                      sigma_a=0.2, phase=Phase("hg", 0.45), albedo=0.0, **resolution)


@pytest.mark.parametrize("case", ["point_level_with_a_block_top", "sun_above_the_eye_on_a_shadow_side"])
def test_grazing_shadow_boundary_converges_with_resolution(renderer, case):
    """The in-scattering error of rays that cross a shadow boundary at a grazing angle falls
    as the shadow map and the epipolar texture are refined, for minmax and raymarch alike:
    the shadow map's resolution, not the min-max method."""
    reference = renderer.render(_grazing_shadow_boundary(case), "exact").image
    for method in ("minmax", "raymarch"):
        errors = [error_against(renderer.render(_grazing_shadow_boundary(case, size), method).image, reference,
                                _grazing_shadow_boundary(case))
                  for size in (1024, 2048, 4096)]
        print(f"grazing shadow boundary {case} {method}, 1024/2048/4096: " + " | ".join(map(str, errors)))
        assert errors[0].mean > errors[1].mean > errors[2].mean
        assert errors[2].mean <= 0.01 and errors[2].p99 <= 0.05


def test_grazing_shadow_boundary_at_the_default_resolution(renderer):
    """At the default 1024 map and 1024 × 1024 texture minmax places the grazing boundary on
    the block's edge (cl/shaft_edges.h): measured vs exact mean 0.025 %, p99 0.32 %. With the
    runs' ends at the texels it was mean 1.38 %, p99 8.1 % (raymarch: mean 1.39 %, p99 3.9 %;
    minmax at 4096: mean 0.39 %, p99 2.2 %), beyond assert_matches_exact's bounds."""
    scene = _grazing_shadow_boundary("point_level_with_a_block_top")
    assert_matches_exact(renderer.render(scene, "minmax").image, renderer.render(scene, "exact").image, scene,
                         "grazing shadow boundary at 1024")


def _low_spot_under_a_hovering_block(shadow_map=1024, surface_shadows="exact"):
    """Found by test_random_scenes: a spot light 2 m up, a block hovering 0.43 m above the
    floor, so that light grazes under it and its shadow edges cross the floor at a
    shallow angle."""
    light = SpotLight(np.array([4.45, 2.0, 4.185]), unit(-0.731, -0.139, -0.668), 68.51, np.full(3, 24.85))
    triangles = np.concatenate([grid_plane(0.0, 8.0, 4), box_triangles([0.0, 0.434, 0.0], [0.4, 0.818, 2.0])])
    return make_scene(triangles, [light], width=32, height=32, position=(0.0, 5.553, 3.053),
                      look_at=(-1.88, 0.8, -1.598), far=25.0, sigma_s=0.1387, sigma_a=0.04, shadow_map=shadow_map,
                      surface_shadows=surface_shadows)


def test_surface_shadow_edges_converge_with_the_shadow_map(renderer):
    """A surface point is lit or not: where the shadow map's texel (and the shading's normal
    offset of one texel) straddles a shadow edge, a pixel gets all or none of its surface
    light. The band of such pixels narrows with the texel; at 4096 it is gone here
    (`surface_shadows: map`; the default, exact, has no such band: the test below)."""
    reference = renderer.render(_low_spot_under_a_hovering_block(), "exact").image
    errors = {}
    for size in (1024, 2048, 4096):
        scene = _low_spot_under_a_hovering_block(size, "map")
        errors[size] = image_error(renderer.render(scene, "minmax").image, reference, depth_edges(depth_map(scene)))
        print(f"surface shadow edges, {size} map: {errors[size]}")
    assert errors[1024].p99 > errors[2048].p99 > errors[4096].p99
    assert errors[4096].mean <= 0.01 and errors[4096].p99 <= 0.05


def test_surface_shadow_edges_at_the_default_map(renderer):
    """With `surface_shadows: map` the band of pixels whose hard shadow test is off by a
    texel broke the yardstick here at 1024 (mean 0.28 %, p99 10.7 %); the default exact
    surface shadows cast rays on that band."""
    scene = _low_spot_under_a_hovering_block()
    assert_matches_exact(renderer.render(scene, "minmax").image, renderer.render(scene, "exact").image, scene,
                         "surface shadow edges at 1024")


# --------------------------------------------------------------------------- float32 vs float64

def walk_in_float64(scene, epipolar, tables, rows, depth) -> np.ndarray:
    """The traverse kernel's computation (cl/traverse.cl) for every camera sample, in
    float64: β and γ from float64 rays, the same slice blend, the same texel scan of the
    device's rectified rows (the tree walk equals the scan: test_minmax), the same lamp
    chord, and `integrand.segment_radiance` (the kernel's lookups, float64) on float64
    tables. A spot light's cone is met along the ray in depth (`cone_interval`), where the
    kernel takes it as a wedge of γ: in float64 the two agree. Returns (samples, 3)
    in-scattered radiance."""
    light = scene.lights[0]
    params = epipolar.params
    axis, u, w = (params[name][:3].astype(np.float64) for name in ("axis", "u", "w"))
    d_el, step = float(params["d_el"]), epipolar.gamma_step  # (the step is made on the device)
    warp = epipolar.gamma_warp
    slices, samples_per_row = int(params["slices"]), int(params["gamma_samples"])
    alpha_min, alpha_step = float(params["alpha_min"]), float(params["alpha_step"])
    directional = isinstance(light, DirectionalLight)
    dirs = primary_rays(scene.camera, scene.image).reshape(-1, 3)
    distance = np.minimum(depth.astype(np.float64), scene.camera.far)
    begin, end = np.zeros(len(dirs)), distance.copy()
    if isinstance(light, SpotLight):
        begin, end = cone_interval(light, scene.camera.position, dirs, begin, end)

    cos_beta = dirs @ axis
    sin_beta = np.maximum(np.linalg.norm(np.cross(dirs, axis), axis=1), 1e-9)
    beta = np.arctan2(sin_beta, cos_beta)

    def gamma_at(s):
        return s * sin_beta if directional else np.arctan2(s * sin_beta, d_el - s * cos_beta)

    gamma_begin, gamma_end = gamma_at(begin), gamma_at(end)
    lamp0, lamp1 = gamma_end.copy(), gamma_end.copy()
    if not directional:
        radius = lamp_radius(scene)
        miss = d_el * sin_beta
        through = miss < radius
        half_chord = np.sqrt(np.maximum(radius * radius - miss * miss, 0.0))
        closest = d_el * cos_beta
        lamp0 = np.where(through, gamma_at(np.clip(closest - half_chord, begin, end)), lamp0)
        lamp1 = np.where(through, gamma_at(np.clip(closest + half_chord, begin, end)), lamp1)
    offset = np.mod(np.arctan2(dirs @ w, dirs @ u) - alpha_min, 2 * math.pi)
    if not params["full_circle"]:
        offset = np.where(offset > math.pi + 0.5 * alpha_step * slices, offset - 2 * math.pi, offset)
    fraction = offset / alpha_step - 0.5
    first = np.floor(fraction).astype(int)
    blend = fraction - first
    if params["full_circle"]:
        near = [np.mod(first, slices), np.mod(first + 1, slices)]
    else:
        near = [np.clip(first, 0, slices - 1), np.clip(first + 1, 0, slices - 1)]

    segments = []  # (sample, slice weight, γ0, γ1)
    for sample in np.flatnonzero(gamma_end > gamma_begin):
        for which, weight in ((0, 1.0 - blend[sample]), (1, blend[sample])):
            row = rows[near[which][sample]]
            for low, high in ((gamma_begin[sample], lamp0[sample]), (lamp1[sample], gamma_end[sample])):
                start = min(max(int(math.floor(texel_coordinate(step, samples_per_row, low, warp))), 0),
                            samples_per_row)
                stop = min(samples_per_row, int(math.ceil(texel_coordinate(step, samples_per_row, high, warp))))
                if stop <= start:
                    continue
                lit = np.concatenate([[False], row[start:stop] > beta[sample], [False]])
                edges = np.flatnonzero(np.diff(lit.astype(np.int8)))
                for run_start, run_end in zip(edges[0::2] + start, edges[1::2] + start):
                    segments.append((sample, weight, max(texel_gamma(step, samples_per_row, run_start, warp), low),
                                     min(texel_gamma(step, samples_per_row, run_end, warp), high)))
    radiance = np.zeros((len(dirs), 3))
    if segments:
        sample, weight, gamma0, gamma1 = (np.array(column) for column in zip(*segments))
        values = segment_radiance(tables, beta[sample], gamma0, gamma1) * weight[:, None]
        for channel in range(3):
            radiance[:, channel] = np.bincount(sample, weights=values[:, channel], minlength=len(dirs))
    return radiance


def minmax_in_both_precisions(device, scene):
    """(device float32 in-scattering, the same walk in float64), each (H, W, 3)."""
    buffers = upload(device, frame_inputs(scene))
    timer = StageTimer()
    rastered = raster(device, buffers, timer)
    epipolar = rectify(device, buffers, rastered, 0, timer)
    minmax(device, epipolar, timer)
    packed = integrand(device, scene, scene.lights[0], epipolar, timer)
    tables = packed.tables
    samples = buffers.inputs.samples
    scatter = device.buffer(nbytes=16 * samples)
    device.fill(scatter, np.float32(0), 16 * samples)
    traverse(device, buffers, rastered, epipolar, packed, scatter, timer)
    single = device.read(scatter, (samples, 4), np.float32)[:, :3]
    n, slices = int(epipolar.params["gamma_samples"]), int(epipolar.params["slices"])
    rows = device.read(epipolar.tree, (slices, 2 * n, 2), np.float32)[:, :n, 0].astype(np.float64)
    depth = device.read(rastered.camera_depth, samples, np.uint32).view(np.float32)
    double = walk_in_float64(scene, epipolar, tables, rows, depth)
    shape = (scene.image.height, scene.image.width, 3)
    return single.reshape(shape), double.reshape(shape)


PRECISION_CASES = {
    "default": lambda kind: stress_scene(lights_at(LIGHT_POSITION)[kind], albedo=0.0, background=0.0),
    "looking_at_light": lambda kind: _epipole_scene("looking_at_light", kind, size=25, albedo=0.0),
    "looking_away_from_light": lambda kind: _epipole_scene("looking_away_from_light", kind, size=25, albedo=0.0),
}


@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
@pytest.mark.parametrize("case", list(PRECISION_CASES))
def test_float32_error_is_below_the_method_error(renderer, device, case, kind):
    """The min-max path in float32 (the device: rays, β/γ/α, float32 tables, run sums)
    against the same walk in float64 on the same rectified rows: their difference must be
    smaller than the method's own error (float64 walk against exact), on the yardstick's
    pixels. Black surfaces, so that both images are the in-scattering alone.

    Why this comparison rather than a `-D` double build of the kernels: the rectified rows
    are the method's discretisation and are shared, so the difference is precision alone;
    the float64 side reuses `integrand.segment_radiance`, the kernel's lookups written in
    numpy, and needs no second, double-precision copy of the kernels or of their tables
    to keep in step."""
    scene = PRECISION_CASES[case](kind)
    single, double = minmax_in_both_precisions(device, scene)
    assert_finite_non_negative(single, f"float32 {case} {kind}")
    exact = renderer.render(scene, "exact").image
    edges = depth_edges(depth_map(scene))
    precision = image_error(single, double, edges)
    method = image_error(double, exact, edges)
    print(f"float32 vs float64 {case}/{kind}: {precision} | float64 walk vs exact: {method}")
    assert precision.mean <= method.mean and precision.p99 <= method.p99, (str(precision), str(method))
