"""Stage raster against a float64 numpy ray cast of the same rays."""
import numpy as np
import pytest

from clrays.scene.camera import primary_rays
from clrays.physics.geometry import raycast
from clrays.inputs import frame_inputs, upload
from clrays.device import StageTimer
from clrays.scene.geometry import box_triangles, sphere_triangles
from clrays.stages.raster import raster, read_shadow_depth
from conftest import DirectionalLight, PointLight, SpotLight, grid_plane, make_scene, v3


def _scene(**kw):
    triangles = np.concatenate([grid_plane(0.0, 8.0, 4), box_triangles([-1, 0, -1], [1, 2, 1]),
                                sphere_triangles([2.0, 1.0, 1.5], 0.8, 16)])
    return make_scene(triangles, [PointLight(v3(0.5, 5, 0.3), np.full(3, 30.0))], width=48, height=32, **kw)


def _rasterized(device, scene):
    buffers = upload(device, frame_inputs(scene))
    result = raster(device, buffers, StageTimer())
    samples = buffers.inputs.samples
    depth = device.read(result.camera_depth, samples, np.uint32).view(np.float32)
    tri = device.read(result.tri_id, samples, np.int32)
    shadow = read_shadow_depth(device, result.shadow_depth, buffers.inputs.shadow_texels, result.depth_in_keys)
    return buffers, depth, tri, shadow


def test_camera_depth_matches_numpy_raycast(device):
    scene = _scene(spp=4)
    _, depth, tri, _ = _rasterized(device, scene)
    dirs = primary_rays(scene.camera, scene.image).reshape(-1, 3)
    t, index = raycast(scene.camera.position, dirs, scene.geometry.triangles)
    assert np.array_equal(np.isinf(depth), np.isinf(t)), "coverage differs"
    hit = np.isfinite(t)
    assert hit.mean() > 0.5
    # float32 ray-triangle test vs float64: relative error of a few ulps of the scene size.
    np.testing.assert_allclose(depth[hit], t[hit], rtol=1e-5, atol=1e-5)
    # The nearest triangle agrees except on shared edges, where either neighbour is right.
    assert (tri[hit] >= 0).all()
    assert (tri[hit] == index[hit]).mean() > 0.98


def test_cube_shadow_map_matches_numpy_raycast(device):
    scene = _scene(shadow_map=32)
    buffers, _, _, shadow = _rasterized(device, scene)
    light = scene.lights[0].position
    views = buffers.inputs.views
    for face in range(1, 7):
        view = views[face]
        n = int(view["width"])
        centres = (np.arange(n) + 0.5) / n * 2 - 1
        sx, sy = np.meshgrid(centres, -centres)
        dirs = (view["forward"][:3] + sx[..., None] * view["right"][:3] + sy[..., None] * view["up"][:3]).reshape(-1, 3)
        dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        t, _ = raycast(light, dirs.astype(np.float64), scene.geometry.triangles)
        stored = shadow[view["depth_offset"]: view["depth_offset"] + n * n]
        assert np.array_equal(np.isinf(stored), np.isinf(t)), f"face {face} coverage differs"
        hit = np.isfinite(t)
        np.testing.assert_allclose(stored[hit], t[hit], rtol=1e-4)


def test_triangle_through_the_camera_is_rasterized(device):
    # One triangle with a vertex behind the eye: near-plane clipping must still cover
    # the screen area in front of the camera.
    triangles = np.array([[[-20.0, -1.0, 20.0], [20.0, -1.0, 20.0], [0.0, -1.0, -40.0]]])
    scene = make_scene(triangles, width=16, height=12, position=(0, 0, 0), look_at=(0, -0.3, -1))
    _, depth, _, _ = _rasterized(device, scene)
    dirs = primary_rays(scene.camera, scene.image).reshape(-1, 3)
    t, _ = raycast(scene.camera.position, dirs, triangles)
    assert np.isfinite(t).sum() > 50
    np.testing.assert_array_equal(np.isfinite(depth), np.isfinite(t))
    np.testing.assert_allclose(depth[np.isfinite(t)], t[np.isfinite(t)], rtol=1e-5)


def test_big_triangles_in_rows_give_the_same_maps(device, monkeypatch):
    # A floor of two triangles spans every row of the camera view and of the shadow faces
    # below the light: pass 2 draws it one row per work-item. A device built with a row
    # limit no triangle reaches draws every triangle in pass 1, as before; the depth maps,
    # triangle ids and shadow maps must be the same bits.
    from clrays import structs
    from clrays.device import Device
    from conftest import TEST_DEVICE

    scene = _scene(spp=2, shadow_map=256)
    _, depth, tri, shadow = _rasterized(device, scene)
    monkeypatch.setitem(structs.KERNEL_CONSTANTS, "RASTER_BIG_ROWS", 1 << 30)
    _, depth_one_pass, tri_one_pass, shadow_one_pass = _rasterized(Device(TEST_DEVICE), scene)
    assert np.array_equal(depth, depth_one_pass) and np.array_equal(tri, tri_one_pass)
    assert np.array_equal(shadow, shadow_one_pass)


@pytest.mark.parametrize("light, triangles, empty", [
    (SpotLight(v3(0, 3, 0), v3(0, 1, 0), 20.0, np.full(3, 30.0)), "floor", True),  # a narrow spot away from the floor
    (SpotLight(v3(0, 3, 0), v3(0, -1, 0), 20.0, np.full(3, 30.0)), "floor", False),  # onto it
    (SpotLight(v3(0, 3, 0), v3(0, -1, 0), 20.0, np.full(3, 30.0)), "beside", True),  # a box beside its cone
    (PointLight(v3(0, 3, 0), np.full(3, 30.0)), "floor", False),
    (PointLight(v3(0, -1, 0), np.full(3, 30.0)), "box", False),  # under the floor: the box above it
    (DirectionalLight(v3(0.2, -1, 0.1), np.full(3, 2.0)), "floor", False),
    (SpotLight(v3(0, 3, 0), v3(0, -1, 0), 20.0, np.full(3, 30.0)), "none", True),
])
def test_map_is_empty_from_the_geometry(device, light, triangles, empty):
    """map_is_empty decides on the host, from the triangles and the views, without waiting
    for the device; it agrees with the map the device drew."""
    from clrays import structs
    from clrays.stages.raster import map_is_empty, raster_shadow_map

    geometry = {"floor": grid_plane(), "beside": box_triangles(v3(3, 0, -0.5), v3(4, 1, 0.5)),
                "box": box_triangles(v3(-0.5, 1, -0.5), v3(0.5, 2, 0.5)), "none": None}[triangles]
    scene = make_scene(geometry, [light], width=16, height=12, shadow_map=64)
    buffers = upload(device, frame_inputs(scene))
    shadow_map = raster_shadow_map(device, buffers, 0, StageTimer())
    waits = device.host_waits
    assert map_is_empty(device, shadow_map) is empty
    assert device.host_waits == waits
    drawn = read_shadow_depth(device, shadow_map.depth, max(shadow_map.texels, 1), shadow_map.depth_in_keys)
    drawn = drawn.view(np.uint32)
    assert bool(np.all(drawn == structs.DEPTH_EMPTY)) is empty


def test_more_tall_triangles_than_pass_2_lists_give_the_same_maps(device, monkeypatch):
    # Pass 2 takes RASTER_BIG_TRIANGLES tall triangles per launch; the others draw their own
    # rows in pass 1. With room for one, the depth maps must still be the same bits.
    from clrays import structs
    from clrays.device import Device
    from conftest import TEST_DEVICE

    scene = _scene(spp=2, shadow_map=256)
    _, depth, tri, shadow = _rasterized(device, scene)
    monkeypatch.setitem(structs.KERNEL_CONSTANTS, "RASTER_BIG_TRIANGLES", 1)
    monkeypatch.setattr(structs, "RASTER_BIG_TRIANGLES", 1)
    _, depth_one, tri_one, shadow_one = _rasterized(Device(TEST_DEVICE), scene)
    assert np.array_equal(depth, depth_one) and np.array_equal(tri, tri_one)
    assert np.array_equal(shadow, shadow_one)



def test_rows_per_work_item_give_the_same_maps(device, monkeypatch):
    # Pass 2 gives a work-item RASTER_ROWS_PER_ITEM rows of a listed triangle; one row per
    # work-item, or 5 (not dividing any triangle's rows), must draw the same bits.
    from clrays import structs
    from clrays.device import Device
    from conftest import TEST_DEVICE

    scene = _scene(spp=2, shadow_map=256)
    _, depth, tri, shadow = _rasterized(device, scene)
    for rows in (1, 5):
        monkeypatch.setitem(structs.KERNEL_CONSTANTS, "RASTER_ROWS_PER_ITEM", rows)
        monkeypatch.setattr(structs, "RASTER_ROWS_PER_ITEM", rows)
        _, depth_rows, tri_rows, shadow_rows = _rasterized(Device(TEST_DEVICE), scene)
        assert np.array_equal(depth, depth_rows) and np.array_equal(tri, tri_rows), f"{rows} rows per item"
        assert np.array_equal(shadow, shadow_rows), f"{rows} rows per item"


@pytest.mark.parametrize("spp", [1, 2])
@pytest.mark.parametrize("columns, big_samples", [(32, 1024), (13, 64), (8, 0)])
def test_gpu_blocks_give_the_same_maps(device, monkeypatch, spp, columns, big_samples):
    # A GPU's pass 2 gives a work-item a block of columns (raster_rows_columns), where a
    # CPU's takes whole rows, and its pass 1 lists wide triangles too (raster_big_samples):
    # the maps must be the same bits either way, with one sample per pixel (the vector runs;
    # 13 columns end blocks mid-run) and two. This checks that the blocks clip the rows and
    # together cover them: a run that strays into the next block writes the same minimum,
    # and PoCL runs work-items in turn, so an overlap is not seen here.
    import clrays.stages.raster as raster_stage

    scene = _scene(spp=spp, shadow_map=256)
    _, depth, tri, shadow = _rasterized(device, scene)
    widths = []
    monkeypatch.setattr(raster_stage, "raster_rows_columns", lambda device, width: widths.append(width) or columns)
    monkeypatch.setattr(raster_stage, "raster_big_samples", lambda device: big_samples)
    _, depth_blocks, tri_blocks, shadow_blocks = _rasterized(device, scene)
    assert widths, "the scene lists triangles for pass 2"
    assert np.array_equal(depth, depth_blocks) and np.array_equal(tri, tri_blocks)
    assert np.array_equal(shadow, shadow_blocks)


# Every view sample ray-tested twice: by intersect_columns (RASTER_LANES columns at once, the
# path the raster kernels take) and by the one-sample view_ray + intersect_triangle.
_LANES_AGAINST_ONE_SAMPLE = """
#include "raster.cl"
kernel void lanes_against_one_sample(global const view_t* views, int view_index, global const float4* tri_vertices,
                                     float2 offset, global float* lane_t, global float* one_t)
{
    int y = get_global_id(0), tri = get_global_id(1);
    global const view_t* view = views + view_index;
    int width = view->width;
    float3 v0 = tri_vertices[3 * tri].xyz, v1 = tri_vertices[3 * tri + 1].xyz, v2 = tri_vertices[3 * tri + 2].xyz;
    triangle_test_t test = triangle_test(view, v0, v1, v2);
    int row = (tri * view->height + y) * width;
    for (int first = 0; first < width; first += RASTER_LANES) {
        float lanes[RASTER_LANES];
        vstore8(intersect_columns(view, &test, first, width - 1, y, offset), 0, lanes);
        for (int k = 0; k < RASTER_LANES && first + k < width; ++k) lane_t[row + first + k] = lanes[k];
    }
    for (int x = 0; x < width; ++x) {
        float3 origin, dir;
        view_ray(view, view_screen(view, x, y, offset), &origin, &dir);
        one_t[row + x] = intersect_triangle(origin, dir, v0, v1, v2);
    }
}
"""


def test_lanes_give_the_bits_of_the_one_sample_ray_test(device):
    # The raster kernels test RASTER_LANES columns at once with the one-sample test's float
    # operations, unfused: every depth must be the same bits (misses included), in the
    # camera's perspective view and a directional light's orthographic one, at several
    # sample offsets, for random triangles (small, large, around and through the eye).
    import pytest

    from clrays.device import build_options
    from clrays.inputs import light_pass_inputs
    from conftest import DirectionalLight

    if "Portable Computing Language" not in device.device.platform.name:
        # The lanes write normalize out as PoCL's does in its plain range, p·(1/√(p·p));
        # another device's normalize may round differently (docs/design.md §4.1).
        pytest.skip(f"the lanes repeat PoCL's normalize; this session runs on {device.name}")
    rng = np.random.default_rng(7)
    small = rng.uniform(-4, 4, (280, 1, 3)) + [0, 1, 0] + rng.choice([0.2, 1.0, 4.0], (280, 1, 1)) * rng.normal(
        size=(280, 3, 3))
    around_eye = np.array([0.0, 2.0, 8.0]) + 40.0 * rng.normal(size=(20, 3, 3))
    sun = [DirectionalLight(v3(0.3, -1.0, -0.2) / np.linalg.norm([0.3, -1.0, -0.2]), np.ones(3))]
    camera_inputs = frame_inputs(make_scene(np.concatenate([small, around_eye]), sun, width=37, height=21))
    sun_inputs = light_pass_inputs(frame_inputs(make_scene(small, sun, width=37, height=21, shadow_map=61)), 0)
    kernel = device.cl.Kernel(device.cl.Program(device.context, _LANES_AGAINST_ONE_SAMPLE).build(
        options=build_options()), "lanes_against_one_sample")
    for inputs, view_index in ((camera_inputs, 0), (sun_inputs, 1)):
        view, triangles = inputs.views[view_index], len(inputs.tri_vertices) // 3
        samples = triangles * int(view["width"]) * int(view["height"])
        for offset in ((0.5, 0.5), (0.0, 0.0), (0.875, 0.125)):
            lane_t, one_t = device.buffer(nbytes=4 * samples), device.buffer(nbytes=4 * samples)
            kernel(device.queue, (int(view["height"]), triangles), None, device.buffer(inputs.views, writable=False),
                   np.int32(view_index), device.buffer(inputs.tri_vertices, writable=False),
                   np.array(offset, np.float32), lane_t, one_t)
            lanes, one = device.read(lane_t, samples, np.uint32), device.read(one_t, samples, np.uint32)
            assert (one != np.float32(np.inf).view(np.uint32)).sum() > 1000, "too few hits to compare"
            assert np.array_equal(lanes, one), f"view {view_index} offset {offset}: {(lanes != one).sum()} differ"

def _small_triangle_soup(seed: int, count: int = 6000) -> np.ndarray:
    """Triangles from a thousandth of a pixel to a few pixels across at 16×9, in front of
    make_scene's camera: random shapes (slivers among them), a third seen nearly edge-on,
    and a few through the camera's plane beside it."""
    rng = np.random.default_rng(seed)
    centre = rng.uniform([-3.0, -1.0, -3.0], [3.0, 3.0, 3.0], (count, 1, 3))
    size = 10.0 ** rng.uniform(-4.0, -0.5, (count, 1, 1))
    triangles = centre + size * rng.normal(size=(count, 3, 3))
    edge_on = slice(0, count // 3)  # the third vertex on the line of the first two, or nearly
    along = triangles[edge_on, 1] - triangles[edge_on, 0]
    triangles[edge_on, 2] = triangles[edge_on, 0] + rng.uniform(-1, 2, (count // 3, 1)) * along \
        + 1e-4 * size[edge_on, 0] * rng.normal(size=(count // 3, 3))
    near = triangles[-20:]  # beside the eye, through its plane: clipped, and off the screen
    near += np.array([0.3, 2.0, 8.0]) - near.mean(axis=1, keepdims=True) + rng.normal(0, 0.01, (20, 1, 3))
    return triangles


def _unit(*xs) -> np.ndarray:
    return v3(*xs) / np.linalg.norm(xs)


def test_skipped_triangles_change_no_bit(device, monkeypatch):
    # Pass 1 skips a triangle whose grown box holds no sample position (cl/raster.cl,
    # RASTER_CULL). A device built without the skip ray-tests every one: camera depth,
    # triangle ids and the shadow maps of a point light (cube, perspective), a spot and a
    # sun (orthographic) must be the same bits, at a thumbnail's size and larger.
    from clrays import structs
    from clrays.device import Device
    from conftest import TEST_DEVICE, DirectionalLight, SpotLight

    monkeypatch.setitem(structs.KERNEL_CONSTANTS, "RASTER_CULL", 0)
    every = Device(TEST_DEVICE)
    monkeypatch.undo()
    lights = [PointLight(v3(0.5, 5, 0.3), np.full(3, 30.0)),
              SpotLight(v3(-1, 5, 2), _unit(0.1, -1, -0.3), 35.0, np.full(3, 30.0)),
              DirectionalLight(_unit(0.3, -1, 0.2), np.full(3, 3.0))]
    for seed, (width, height, spp, shadow_map) in enumerate([(16, 9, 1, 64), (16, 9, 4, 128), (160, 90, 2, 512)]):
        triangles = _small_triangle_soup(seed)
        for light in lights:
            scene = make_scene(triangles, [light], width=width, height=height, spp=spp, shadow_map=shadow_map)
            skipped, drawn = _rasterized(device, scene), _rasterized(every, scene)
            for ours, theirs in zip(skipped[1:], drawn[1:]):
                assert np.array_equal(ours, theirs, equal_nan=True), (width, height, type(light).__name__)
            assert np.isfinite(skipped[1]).sum() > 0.1 * width * height * spp
