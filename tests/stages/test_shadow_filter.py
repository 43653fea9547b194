"""Stage shadow_filter (render.shadow_filter, docs/design.md §9): each reconstruction
against its float64 numpy reference and against the true visibility of synthetic 1–3-delta
depth distributions; the moment maps' prefilter against a numpy blur; the filters in a
frame against the map's own test and against PCF."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from clrays.device import StageTimer
from clrays.inputs import frame_inputs, upload
from clrays.reference import moments as reference
from clrays.scene.model import DirectionalLight, ShadowFilter, SpotLight
from clrays.stages.raster import RasterResult, raster_shadow_map, shadow_atlas
from clrays.stages.shadow_filter import FILTER_CODES, depth_ranges, shadow_filter_moments
from conftest import grid_plane, make_scene, v3

MOMENT_BIAS = ShadowFilter.moment_bias  # the default, 3e-6


def reconstruct(device, filter_type: str, moments: np.ndarray, depth: np.ndarray, moment_bias: float) -> np.ndarray:
    """The device's reconstruction `filter_type` (a moment filter) of (N, 4) moments at N
    normalised depths: float32 visibility, against clrays.reference.moments's."""
    moments = np.ascontiguousarray(moments, dtype=np.float32)
    depth = np.ascontiguousarray(depth, dtype=np.float32)
    count = len(depth)
    out = device.buffer(nbytes=4 * max(count, 1))
    kernel = device.kernel("shadow_filter", "shadow_filter_reconstruct", {"SHADOW_FILTER": FILTER_CODES[filter_type]})
    kernel(device.queue, (max(count, 1),), None, device.buffer(moments, writable=False),
           device.buffer(depth, writable=False), np.int32(count), np.float32(moment_bias), out)
    return device.read(out, (max(count, 1),), np.float32)[:count]


RECONSTRUCTIONS = {"vsm": lambda b, z: reference.vsm_visibility(b, z, MOMENT_BIAS),
                   "msm_hamburger": lambda b, z: reference.msm_hamburger_visibility(b, z, MOMENT_BIAS),
                   "msm_hausdorff": lambda b, z: reference.msm_hausdorff_visibility(b, z, MOMENT_BIAS)}


def delta_distributions(count: int, seed: int = 12, with_depths: bool = False):
    """`count` random distributions of 1 to 3 depths in [0.05, 0.95] with random weights,
    and a receiver depth for each: (moments (count, 4), receiver (count,), true visibility
    P(depth ≥ receiver) (count,)), and with `with_depths` the depths of each."""
    rng = np.random.default_rng(seed)
    moments, receivers, visible, all_depths = [], [], [], []
    for _ in range(count):
        n = rng.integers(1, 4)
        depths, weights = rng.uniform(0.05, 0.95, n), rng.dirichlet(np.ones(n))
        receiver = rng.uniform(0.0, 1.0)
        moments.append((weights[:, None] * reference.moment_vector(depths)).sum(axis=0))
        receivers.append(receiver)
        visible.append(1.0 - weights[depths < receiver].sum())
        all_depths.append(depths)
    found = np.array(moments), np.array(receivers), np.array(visible)
    return (*found, all_depths) if with_depths else found


@pytest.mark.parametrize("name", sorted(RECONSTRUCTIONS))
def test_reconstruction_never_darkens_below_the_true_visibility(name):
    """Each bound leaks light but never shadows more than the distribution does: its shadow
    is a lower bound of the true shadow, its visibility an upper bound of the true one, up
    to the moment bias (which moves the moments by at most α/2)."""
    moments, receivers, visible = delta_distributions(20000)
    bound = RECONSTRUCTIONS[name](moments, receivers)
    assert np.all(np.isfinite(bound))
    assert np.max(visible - bound) <= MOMENT_BIAS / 2 + 1e-9


@pytest.mark.parametrize("name", ["msm_hamburger", "msm_hausdorff"])
def test_moment_bound_is_the_sharpest_one(name):
    """The closed form is the linear programme's optimum over distributions on a fine grid
    (on ℝ, taken wide, for Hamburger; on [0, 1] for Hausdorff), docs/design.md §9."""
    from scipy.optimize import linprog

    moments, receivers, _, depths = delta_distributions(40, seed=5, with_depths=True)
    # The biased moments are those of the distribution mixed with α/2 at 0 and at 1.
    biased = (1 - MOMENT_BIAS) * moments + MOMENT_BIAS * reference.MOMENT_BIAS_CENTRE
    closed_form = {"msm_hamburger": reference.msm_hamburger_visibility,
                   "msm_hausdorff": reference.msm_hausdorff_visibility}[name]
    low, high, points = (-4.0, 5.0, 2001) if name == "msm_hamburger" else (0.0, 1.0, 1001)
    for b, z, support in zip(biased, receivers, depths):
        grid = np.union1d(np.linspace(low, high, points), [z, 0.0, 1.0, *support])  # feasible: holds the support
        constraints = np.stack([grid ** k for k in range(5)])
        answer = linprog((grid < z).astype(float), A_eq=constraints, b_eq=np.concatenate([[1.0], b]),
                         bounds=(0, None), method="highs")
        assert answer.status == 0, answer.message
        closed = closed_form(b[None], np.array([z]), 0.0)[0]  # bias already in b
        assert abs((1 - answer.fun) - closed) < 2e-3, (b, z)


@pytest.mark.parametrize("name", sorted(RECONSTRUCTIONS))
def test_device_reconstruction_matches_numpy(device, name):
    moments, receivers, visible = delta_distributions(4000, seed=7)
    on_device = reconstruct(device, name, moments, receivers, MOMENT_BIAS)
    expected = RECONSTRUCTIONS[name](moments.astype(np.float32).astype(np.float64),
                                     receivers.astype(np.float32).astype(np.float64))
    # float32 Cholesky of a nearly singular Hankel matrix: single cases differ by a few
    # percent, typical ones by far less.
    error = np.abs(on_device - expected)
    assert np.percentile(error, 99) < 1e-2 and np.median(error) < 1e-4
    assert np.percentile(visible - on_device, 99.9) < 1e-2  # still no darker than the truth


def spot_scene(**render):
    """A spot light over a floor with a blocker plate: one view, a shadow edge in it."""
    plate = np.array([[[-1, 1.5, -1], [1, 1.5, -1], [1, 1.5, 1]], [[-1, 1.5, -1], [1, 1.5, 1], [-1, 1.5, 1]]],
                     dtype=float)
    lights = [SpotLight(v3(0.3, 5, 0), v3(0, -1, 0), 50.0, np.full(3, 40.0))]
    return make_scene(np.concatenate([grid_plane(0.0, 6.0, 4), plate]), lights, width=48, height=36,
                      sigma_s=0.0, sigma_a=0.0, shadow_map=64, **render)


def test_moment_prefilter_matches_a_numpy_box_blur(device):
    """The moment map of a single view, blurred rows then columns with clamped edges, is
    the numpy box blur of the moments of its normalised depths."""
    radius = 3
    scene = spot_scene(surface_shadows="filtered", shadow_filter=ShadowFilter("msm_hamburger", radius))
    inputs = frame_inputs(scene)
    buffers = upload(device, inputs)
    timer = StageTimer()
    atlas = shadow_atlas(device, buffers, [raster_shadow_map(device, buffers, 0, timer)])
    maps = shadow_filter_moments(device, buffers, RasterResult(None, None, atlas), timer)
    side = scene.render.shadow_map
    depth = device.read(atlas, (side, side), np.float32).astype(np.float64)
    near, inverse_range = depth_ranges(inputs)[0]
    z = np.where(np.isinf(depth), 1.0, np.clip((depth - near) * inverse_range, 0, 1))
    assert 0 < np.mean(z < 1) < 1  # the map holds both geometry and empty texels
    expected = reference.box_blur(reference.moment_vector(z), radius)
    blurred = device.read(maps.moments, (side, side, 4), np.float32)
    np.testing.assert_allclose(blurred, expected, atol=2e-6)


def test_hard_filter_is_the_maps_own_test(renderer):
    scene = spot_scene(surface_shadows="map")
    hard = replace(scene, render=replace(scene.render, surface_shadows="filtered",
                                         shadow_filter=ShadowFilter("hard")))
    np.testing.assert_array_equal(renderer.render(hard).image, renderer.render(scene).image)


def test_pcf_filter_of_radius_0_is_the_maps_own_test(renderer):
    scene = spot_scene(surface_shadows="map")
    filtered = replace(scene, render=replace(scene.render, surface_shadows="filtered",
                                             shadow_filter=ShadowFilter("pcf", 0)))
    np.testing.assert_array_equal(renderer.render(filtered).image, renderer.render(scene).image)


@pytest.mark.parametrize("kind", ["pcf", "vsm", "msm_hamburger", "msm_hausdorff"])
def test_a_lit_slope_does_not_shadow_itself(renderer, kind):
    """A floor under a low sun (25° above it) with nothing above: across a 4-texel radius
    its own depth moves by ~8 texels, which the slope term of the bias takes in; the
    plain `pcf` of surface_shadows, without it, darkens it (acne)."""
    sun = DirectionalLight(v3(-0.9, -0.42, 0.0) / np.linalg.norm([-0.9, -0.42, 0.0]), np.full(3, 3.0))
    base = make_scene(grid_plane(0.0, 6.0, 4), [sun], width=48, height=36, position=(0, 5, 7), look_at=(0, 0, 0),
                      sigma_s=0.0, sigma_a=0.0, shadow_map=256)
    unshadowed = renderer.render(replace(base, render=replace(base.render, surface_shadows="exact"))).image
    filtered = renderer.render(replace(base, render=replace(base.render, surface_shadows="filtered",
                                                            shadow_filter=ShadowFilter(kind, 4)))).image
    plain_pcf = renderer.render(replace(base, render=replace(base.render, surface_shadows="pcf", pcf=4))).image
    lit = unshadowed.sum(axis=2) > 0
    assert np.abs(filtered - unshadowed)[lit].max() < 1e-3 * unshadowed.max()
    assert np.mean(plain_pcf[lit] < 0.99 * unshadowed[lit]) > 0.05  # the acne the slope term removes


def test_msm_is_closer_to_pcf_than_vsm_where_occluders_overlap(renderer):
    """Two plates over the floor at different heights: behind the overlap VSM leaks
    light, 4MSM much less (docs/design.md §9)."""
    plates = []
    for height, shift in ((1.5, 0.0), (3.0, 0.6)):
        plates.append([[-1 + shift, height, -1], [1 + shift, height, -1], [1 + shift, height, 1]])
        plates.append([[-1 + shift, height, -1], [1 + shift, height, 1], [-1 + shift, height, 1]])
    lights = [SpotLight(v3(0.3, 6, 0), v3(0, -1, 0), 50.0, np.full(3, 40.0))]
    base = make_scene(np.concatenate([grid_plane(0.0, 6.0, 4), np.array(plates)]), lights, width=64, height=48,
                      position=(0, 6, 7), look_at=(0, 0, 0), sigma_s=0.0, sigma_a=0.0, shadow_map=256)

    def image(kind):
        return renderer.render(replace(base, render=replace(base.render, surface_shadows="filtered",
                                                            shadow_filter=ShadowFilter(kind, 3)))).image

    pcf = image("pcf")
    errors = {kind: float(np.sqrt(np.mean((image(kind) - pcf) ** 2))) for kind in ("vsm", "msm_hamburger")}
    assert errors["msm_hamburger"] < 0.5 * errors["vsm"], errors


def test_blur_runs_across_cube_seams(device):
    """A function of the direction, smooth over the whole sphere, stored in a cube map:
    blurred across the seams it stays close to itself at the faces' edges, where clamping
    at each face's edge (what the kernels do beside a face the frame does not read) is
    off by a first-order amount."""
    radius, side = 3, 64
    inputs = frame_inputs(make_scene(grid_plane(-1.0), shadow_map=side))  # one point light: a cube map
    first, count = inputs.light_views[0]
    assert count == 6
    views = inputs.views[first:first + count]
    axis = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
    centre = (np.arange(side) + 0.5) / side * 2 - 1
    sx, sy = np.meshgrid(centre, -centre)
    values = np.zeros((inputs.shadow_texels, 4), dtype=np.float32)
    for view in views:
        direction = (view["forward"][:3] + sx[..., None] * view["right"][:3] + sy[..., None] * view["up"][:3])
        f = direction @ axis / np.linalg.norm(direction, axis=-1)
        offset = int(view["depth_offset"])
        values[offset:offset + side * side] = f.reshape(-1, 1)
    expected = values[:, 0].reshape(6, side, side)
    edge = np.zeros((side, side), dtype=bool)
    edge[:radius], edge[-radius:], edge[:, :radius], edge[:, -radius:] = True, True, True, True
    # Within `radius` of a cube corner three faces meet and the box is turned (docs/design.md §9).
    corner = np.zeros((side, side), dtype=bool)
    for rows in (slice(None, radius), slice(-radius, None)):
        for columns in (slice(None, radius), slice(-radius, None)):
            corner[rows, columns] = True

    def blurred(needed):
        buffers = upload(device, replace(inputs, view_needed=needed))
        source = device.buffer(values)
        scratch = device.buffer(nbytes=values.nbytes)
        blur = device.kernel("shadow_filter", "shadow_filter_blur")
        needed_buffer = device.buffer(needed.astype(np.int32), writable=False)
        for axis_index, src, dst in ((0, source, scratch), (1, scratch, source)):
            for view_index in range(first, first + count):
                blur(device.queue, (side * side,), None, buffers.views, buffers.lights, needed_buffer, np.int32(0),
                     np.int32(view_index), np.int32(radius), np.int32(axis_index), src, dst)
        return device.read(source, values.shape, np.float32)[:, 0].reshape(6, side, side)

    seams = np.abs(blurred(np.ones(len(inputs.views), dtype=bool)) - expected)
    clamped = np.abs(blurred(np.r_[True, np.zeros(6, dtype=bool)]) - expected)
    along, inside = edge & ~corner, ~edge
    # A box blur of a curved function is off by a second-order amount everywhere: the
    # faces' insides, where no seam is read, say how much.
    interior = seams[:, inside].max()
    assert seams[:, along].max() < 1.5 * interior < 0.5 * clamped[:, along].max(), (
        seams[:, along].max(), interior, clamped[:, along].max())
    assert seams[:, corner].max() < 0.5 * clamped[:, corner].max()
