"""The min-max method: its stages against numpy, the tree walk against the texel scan,
and the whole method against raymarch and exact in the configurations of docs/design.md §6."""
from pathlib import Path

import numpy as np
import pytest

from clrays.device import StageTimer
from clrays.inputs import frame_inputs, upload
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.stages.integrand import integrand_table_size
from clrays.stages.minmax import minmax
from clrays.scene.geometry import box_triangles, load_mesh_triangles
from clrays.stages.raster import raster
from clrays.stages.rectify import rectify
from clrays.scene.camera import primary_rays
from conftest import DirectionalLight, unoccluded_point_quadrature, Phase, PointLight, SpotLight, grid_plane, make_scene, v3

MESHES = Path(__file__).resolve().parents[3] / "shared" / "meshes"


def _unit(*xs):
    x = np.array(xs, dtype=float)
    return x / np.linalg.norm(x)


def _slats():
    """A floor, a slatted roof and a block: shafts in every direction of view."""
    parts = [grid_plane(0.0, 8.0, 4), box_triangles([-2.0, 0.0, -1.0], [-1.0, 1.6, 0.0])]
    parts += [box_triangles([x, 3.0, -3.0], [x + 0.35, 3.15, 2.0]) for x in np.arange(-3.0, 3.0, 0.8)]
    return np.concatenate(parts)


CASES = {
    # camera looks up at a point light over the slats: the epipole is on screen
    "point_in_view": dict(lights=[PointLight(v3(0.2, 5.0, -1.0), np.full(3, 60.0))],
                          position=(0, 1.5, 7), look_at=(0, 3.5, -1)),
    "spot": dict(lights=[SpotLight(v3(0.3, 5.5, -0.5), _unit(0.1, -1, 0.1), 35.0, np.full(3, 80.0))]),
    "directional": dict(lights=[DirectionalLight(_unit(0.35, -1.0, -0.25), np.full(3, 1.5))]),
    # the light is behind the viewer: slices converge at the anti-epipole
    "point_behind_camera": dict(lights=[PointLight(v3(0.5, 5.0, 10.0), np.full(3, 80.0))],
                                position=(0, 2.5, 7), look_at=(0, 1, -2)),
}


def _case_scene(case, **render):
    settings = dict(CASES[case])
    return make_scene(_slats(), width=64, height=48, far=25.0, sigma_s=0.08, sigma_a=0.02,
                      phase=Phase("hg", 0.3), **settings, **render)


@pytest.fixture(scope="module")
def exact_images(renderer):
    return {case: renderer.render(_case_scene(case), "exact").image for case in CASES}


@pytest.mark.parametrize("case", CASES)
def test_minmax_matches_exact_and_raymarch(renderer, exact_images, case):
    scene = _case_scene(case, shadow_map=1024)
    edges = depth_edges(depth_map(scene))
    fast = renderer.render(scene, "minmax").image
    # raymarch on a 4096² map: its shafts' edges are the map's texels, where minmax's lie on
    # the blockers (cl/shaft_edges.h); on the same 1024² map the two differ by raymarch's
    # texel error (spot: p99 6.8 % apart, minmax 4.0 % and raymarch 4.3 % from exact)
    marched = renderer.render(_case_scene(case, shadow_map=4096, steps=4096), "raymarch").image
    versus_exact = image_error(fast, exact_images[case], edges)
    versus_raymarch = image_error(fast, marched, edges)
    print(case, "vs exact:", versus_exact, "| vs raymarch:", versus_raymarch)
    for error in (versus_exact, versus_raymarch):
        assert error.mean <= 0.01 and error.p99 <= 0.05, str(error)


def _mesh_scene(**render):
    """The elephant scan (5,558 triangles), scaled ×3 and hung under a point light over a floor."""
    elephant = load_mesh_triangles(MESHES / "elephant.ply") * 3.0 + np.array([0.0, 3.0, 0.0])
    triangles = np.concatenate([grid_plane(0.0, 8.0, 4), elephant])
    return make_scene(triangles, [PointLight(v3(0.4, 7.0, -0.6), np.full(3, 120.0))], width=48, height=36,
                      position=(0.5, 2.0, 9.0), look_at=(0, 2.8, 0), far=25.0, sigma_s=0.08, sigma_a=0.02,
                      phase=Phase("hg", 0.3), **render)


@pytest.mark.skipif(not (MESHES / "elephant.ply").exists(), reason="../shared/meshes is not beside the checkout")
def test_minmax_on_a_scanned_mesh(renderer):
    scene = _mesh_scene(shadow_map=1024)
    assert scene.geometry.count > 5000
    edges = depth_edges(depth_map(scene))
    fast = renderer.render(scene, "minmax").image
    versus_exact = image_error(fast, renderer.render(scene, "exact").image, edges)
    versus_raymarch = image_error(fast, renderer.render(_mesh_scene(shadow_map=1024, steps=4096), "raymarch").image,
                                  edges)
    print("mesh vs exact:", versus_exact, "| vs raymarch:", versus_raymarch)
    for error in (versus_exact, versus_raymarch):
        assert error.mean <= 0.01 and error.p99 <= 0.05, str(error)


def _stages(device, scene):
    """Raster, rectify and minmax of the first light; returns (epipolar, tree rows)."""
    buffers = upload(device, frame_inputs(scene))
    timer = StageTimer()
    rastered = raster(device, buffers, timer)
    epipolar = rectify(device, buffers, rastered, 0, timer)
    minmax(device, epipolar, timer)
    n, slices = int(epipolar.params["gamma_samples"]), int(epipolar.params["slices"])
    rows = device.read(epipolar.tree, (slices, 2 * n, 2), np.float32)
    return epipolar, rows


@pytest.mark.parametrize("case", ["point_in_view", "directional"])
def test_minmax_mipmap_equals_numpy_reduction(device, case):
    epipolar, rows = _stages(device, _case_scene(case, slices=64, gamma_samples=256))
    n = int(epipolar.params["gamma_samples"])
    level = rows[:, :n]
    assert (level[..., 0] == level[..., 1]).all()
    blocked = level[..., 0] < np.pi * 0.999
    assert 0.02 < blocked.mean() < 0.98, "the scene should mix lit and shadowed texels"
    offset = n
    while level.shape[1] > 1:
        expected = np.stack([np.minimum(level[:, 0::2, 0], level[:, 1::2, 0]),
                             np.maximum(level[:, 0::2, 1], level[:, 1::2, 1])], axis=-1)
        got = rows[:, offset: offset + expected.shape[1]]
        np.testing.assert_array_equal(got, expected)
        offset += expected.shape[1]
        level = expected
    assert offset == 2 * n - 1


@pytest.mark.parametrize("case", list(CASES))
def test_tree_walk_equals_texel_scan(renderer, case):
    tree = renderer.render(_case_scene(case, traversal="tree"), "minmax").image
    scan = renderer.render(_case_scene(case, traversal="scan"), "minmax").image
    np.testing.assert_allclose(tree, scan, rtol=1e-5, atol=1e-7 * scan.max())


#: The smallest image whose integrand tables are full size (128 × 512; smaller images
#: get smaller tables, clrays.stages.integrand.integrand_table_size).
FULL_TABLES = (56, 40)


def test_thumbnail_tables_stay_far_below_the_visibility_error(renderer):
    # 16×9: 32 × 128 tables. Measured max 5e-4 (24×16, 2e-5 with full tables); a 128² shadow
    # map's visibility error at that size is percents.
    assert integrand_table_size(16, 9) == (32, 128) and integrand_table_size(*FULL_TABLES) == (128, 512)
    light = PointLight(v3(0.3, 2.2, 0.5), np.full(3, 20.0))
    scene = make_scene(lights=[light], width=16, height=9, far=12.0, sigma_s=0.08, sigma_a=0.02, shadow_map=None,
                       slices=None, gamma_samples=None)
    image = renderer.render(scene, "minmax").image[..., 0]
    expected, keep = unoccluded_point_quadrature(scene)
    relative = np.abs(image - expected)[keep] / expected[keep]
    print(f"thumbnail table: median {np.median(relative):.2e}, max {relative.max():.2e}")
    assert relative.max() < 1e-3


@pytest.mark.parametrize("mode", ["table", "svd"])
@pytest.mark.parametrize("phase", [Phase(), Phase("hg", 0.3)], ids=["isotropic", "hg"])
def test_integrand_modes_match_quadrature_for_a_point_light(renderer, mode, phase):
    # Unoccluded, so the only error left is the integrand's (and float32).
    light = PointLight(v3(0.3, 2.2, 0.5), np.full(3, 20.0))
    scene = make_scene(lights=[light], width=FULL_TABLES[0], height=FULL_TABLES[1], far=12.0, sigma_s=0.08,
                       sigma_a=0.02, phase=phase, integrand=mode)
    image = renderer.render(scene, "minmax").image[..., 0]
    expected, keep = unoccluded_point_quadrature(scene)
    relative = np.abs(image - expected)[keep] / expected[keep]
    print(f"{mode} {phase.type}: median {np.median(relative):.2e}, max {relative.max():.2e}")
    # docs/integrand.md: table ≤ 5e-4 per segment; svd rank 4 up to ~1e-3 on whole rays.
    assert relative.max() < {"table": 1e-4, "svd": 2e-3}[mode]


@pytest.mark.parametrize("mode", ["analytic", "table", "svd"])
def test_integrand_modes_match_closed_form_for_a_directional_light(renderer, mode):
    sun = DirectionalLight(_unit(0.3, -1.0, -0.4), np.full(3, 2.0))
    scene = make_scene(lights=[sun], width=FULL_TABLES[0], height=FULL_TABLES[1], far=12.0, sigma_s=0.08,
                       sigma_a=0.02, phase=Phase("hg", 0.3), integrand=mode)
    image = renderer.render(scene, "minmax").image[..., 0]
    dirs = primary_rays(scene.camera, scene.image)[:, :, 0]
    cos_theta = dirs @ -sun.direction  # light travels along `direction`, the eye is at -dirs
    rho = (1 - 0.09) / (4 * np.pi * (1 + 0.09 - 0.6 * cos_theta) ** 1.5)
    expected = 0.08 * 2.0 * rho * (1 - np.exp(-0.1 * 12.0)) / 0.1
    relative = np.abs(image - expected) / expected
    print(f"directional {mode}: median {np.median(relative):.2e}, max {relative.max():.2e}")
    assert relative.max() < 1e-4


@pytest.mark.parametrize("look_at", [(0.2, 5.0, -1.0), (-0.2, -5.0, 13.0)], ids=["at_light", "away_from_light"])
@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_degenerate_views_are_finite_and_non_negative(renderer, look_at, method):
    light = PointLight(v3(0.2, 5.0, -1.0), np.full(3, 60.0))
    scene = make_scene(_slats(), [light], width=33, height=33, position=(0.2, 1.0, 3.0), look_at=look_at)
    image = renderer.render(scene, method).image
    assert np.isfinite(image).all() and (image >= 0).all()
    assert image.max() > 0


@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_lights_add_up(renderer, method):
    lights = [CASES["point_in_view"]["lights"][0], CASES["spot"]["lights"][0], CASES["directional"]["lights"][0]]
    alone = [renderer.render(make_scene(_slats(), [light], width=40, height=30), method).image for light in lights]
    together = renderer.render(make_scene(_slats(), lights, width=40, height=30), method).image
    np.testing.assert_allclose(together, sum(alone), rtol=1e-4, atol=1e-6 * together.max())


def test_pcf_softens_surface_shadow_edges(renderer):
    scene = _case_scene("point_behind_camera", surface_shadows="map", shadow_map=128)
    hard = renderer.render(scene, "minmax").image
    soft = renderer.render(_case_scene("point_behind_camera", surface_shadows="pcf", pcf=2, shadow_map=128),
                           "minmax").image
    changed = np.abs(soft - hard).max(axis=-1) > 1e-3 * hard.max()
    # Filtering only touches pixels near shadow edges, and makes them partially lit.
    assert 0 < changed.mean() < 0.2
