"""Raster views draw only the blocks of triangles that may reach them
(clrays.stages.raster_culling): the lists hold what a constructed case expects, and the
maps drawn from them are the maps drawn from every triangle, bit for bit."""
import numpy as np
import pytest

from clrays import structs
from clrays.device import StageTimer
from clrays.inputs import frame_inputs, light_pass_inputs, upload
from clrays.scene.geometry import box_triangles, sphere_triangles
from clrays.stages import raster as raster_stage
from clrays.stages import raster_culling
from clrays.stages.raster import raster
from conftest import DirectionalLight, PointLight, SpotLight, grid_plane, make_scene, v3

LIGHT = v3(0.0, 3.0, 0.0)


def _small(centre, size=0.3):
    """A small triangle around `centre` (world space)."""
    centre = np.asarray(centre, float)
    return np.array([centre + [-size, -size, 0.0], centre + [size, -size, 0.0], centre + [0.0, size, size]])


def _lists(scene):
    """Per view of the light pass (0: the camera, then the light's), the triangles its list draws."""
    inputs = frame_inputs(scene)
    light = light_pass_inputs(inputs, 0)
    block, count = raster_culling.CULL_BLOCK, scene.geometry.count
    drawn = []
    for view in range(len(light.views)):
        anchor = inputs.eye_ws if view == 0 else light.light_anchor_ws[0]
        blocks = raster_culling.view_blocks(scene.geometry, count, anchor, light.views[view])
        triangles = (blocks[:, None] * block + np.arange(block)).ravel()
        drawn.append(set(triangles[triangles < count].tolist()))
    return drawn


@pytest.fixture
def one_per_block(monkeypatch):
    """Blocks of one triangle: each triangle's own box is tested."""
    monkeypatch.setattr(raster_culling, "CULL_BLOCK", 1)


def test_a_triangle_inside_one_face_is_drawn_there_alone(one_per_block):
    # Around the light: one triangle well inside +x, one across the seam of +x and +z (on
    # the light's plane x = z), one inside -y; the camera looks down -z from z = 20.
    triangles = np.stack([_small(LIGHT + [5.0, 0.0, 0.0]), _small(LIGHT + [4.0, 0.0, 4.0]),
                          _small(LIGHT + [0.2, -5.0, 0.1])])
    scene = make_scene(triangles, [PointLight(LIGHT, np.full(3, 30.0))], position=(0, 3, 20), look_at=(0, 3, 0))
    faces = _lists(scene)[1:]  # +x, -x, +y, -y, +z, -z
    assert faces == [{0, 1}, set(), set(), {2}, {1}, set()]


def test_the_camera_lists_what_its_frustum_may_see(one_per_block):
    # In front of the eye, behind it, far beside the frustum, and one through the eye's plane.
    triangles = np.stack([_small((0.0, 2.0, 0.0)), _small((0.0, 2.0, 12.0)), _small((30.0, 2.0, 0.0)),
                          np.array([[-1.0, 1.5, 9.0], [1.0, 1.5, 9.0], [0.0, 1.5, 6.0]])])
    scene = make_scene(triangles, [PointLight(LIGHT, np.full(3, 30.0))])  # eye at (0, 2, 8), looking at (0, 1, 0)
    assert _lists(scene)[0] == {0, 3}


def test_a_block_beyond_a_plane_is_dropped_whole():
    # 64 triangles far beside the camera's frustum, then 64 in front of it: one block each.
    beside = np.stack([_small((40.0 + 0.01 * k, 2.0, 0.0)) for k in range(raster_culling.CULL_BLOCK)])
    ahead = np.stack([_small((0.01 * k, 2.0, 0.0)) for k in range(raster_culling.CULL_BLOCK)])
    scene = make_scene(np.concatenate([beside, ahead]), [PointLight(LIGHT, np.full(3, 30.0))])
    assert _lists(scene)[0] == set(range(raster_culling.CULL_BLOCK, 2 * raster_culling.CULL_BLOCK))


def _seams_scene(lights, **kw):
    """Triangles across every seam of a cube map at LIGHT, a floor under every face, a box
    and a sphere, a triangle through the camera's eye plane and some beside its frustum."""
    rng = np.random.default_rng(7)
    seams = []
    for a, b in [(0, 1), (0, 2), (1, 2)]:
        for sign_a in (-1, 1):
            for sign_b in (-1, 1):
                for _ in range(6):
                    direction = rng.uniform(-0.9, 0.9, 3)
                    direction[a], direction[b] = sign_a, sign_b  # on the seam of two faces
                    seams.append(_small(LIGHT + 2.5 * direction, size=rng.uniform(0.05, 0.5)))
    through_eye = np.array([[[-20.0, 0.5, 20.0], [20.0, 0.5, 20.0], [0.0, 0.5, -40.0]]])
    beside = np.stack([_small((25.0, 1.0, 0.0)), _small((0.0, 1.0, 30.0)), _small((-3.0, -6.0, 6.0))])
    triangles = np.concatenate([grid_plane(0.0, 8.0, 6), box_triangles([-1, 0, -1], [1, 1.5, 1]),
                                sphere_triangles([2.0, 1.0, 1.5], 0.8, 12), np.stack(seams), through_eye, beside])
    return make_scene(triangles, lights, width=48, height=32, shadow_map=64, **kw)


def _maps(device, scene):
    """Every raster output of a frame, as host arrays."""
    buffers = upload(device, frame_inputs(scene))
    result = raster(device, buffers, StageTimer())
    samples, texels = buffers.inputs.samples, buffers.inputs.shadow_texels
    out = {"camera depth": device.read(result.camera_depth, samples, np.uint32),
           "triangle": device.read(result.tri_id, samples, np.int32),
           "shadow depth": raster_stage.read_shadow_depth(device, result.shadow_depth, texels, result.depth_in_keys)}
    if result.shadow_blockers is not None:
        out["blockers"] = device.read(result.shadow_blockers, texels, np.uint64 if result.blocker_keys else np.int32)
    return out


LIGHTS = {
    "point": [PointLight(LIGHT, np.full(3, 30.0))],
    "spot": [SpotLight(LIGHT, v3(0.3, -1.0, 0.1) / np.linalg.norm([0.3, -1.0, 0.1]), 40.0, np.full(3, 30.0))],
    "sun": [DirectionalLight(v3(0.4, -1.0, 0.3) / np.linalg.norm([0.4, -1.0, 0.3]), np.full(3, 2.0))],
}


@pytest.mark.parametrize("light", list(LIGHTS))
@pytest.mark.parametrize("block", [1, raster_culling.CULL_BLOCK])
def test_culled_maps_are_the_unculled_maps(device, monkeypatch, light, block):
    monkeypatch.setattr(raster_culling, "CULL_BLOCK", block)
    monkeypatch.setattr(raster_stage, "LIST_AT_MOST", 2.0)  # every view draws its list, however long
    scene = _seams_scene(LIGHTS[light], spp=2 if light == "point" else 1)
    if block == 1:  # some view drops triangles: the test compares something
        assert min(len(drawn) for drawn in _lists(scene)) < scene.geometry.count
    culled = _maps(device, scene)
    monkeypatch.setattr(raster_stage, "CULL_PER_VIEW", False)
    every = _maps(device, scene)
    assert (culled["shadow depth"] < np.inf).sum() > 100 and (culled["triangle"] >= 0).sum() > 100
    for name, values in every.items():
        assert np.array_equal(culled[name], values), f"{name} differs"


def test_a_triangle_beside_the_view_costs_no_rows(device):
    # Pass 1 leaves a triangle whose projection lies wholly beside the view before its rows
    # (cl/raster.cl, PROJECT_TRIANGLE): one in front of the eye and beside the camera's view,
    # taller than the view and 19 columns wide, is listed for pass 2 no more.
    beside = np.array([[[9.0, -1.0, 0.0], [10.0, -1.0, 0.0], [9.5, 3.0, 0.0]]])
    scene = make_scene(beside, [PointLight(LIGHT, np.full(3, 30.0))], width=96, height=64, position=(0, 1, 4),
                       look_at=(0, 1, 0))
    buffers = upload(device, frame_inputs(scene))
    samples = buffers.inputs.samples
    depth = device.buffer(nbytes=4 * samples)
    device.fill(depth, structs.DEPTH_EMPTY, 4 * samples, StageTimer(), "raster")
    first_pass = device.kernel("raster", "raster_depth", raster_stage.raster_defines(device))
    counter, big = device.buffer(np.zeros(1, np.uint32)), device.buffer(nbytes=12)
    first_pass(device.queue, (1,), None, buffers.tri_vertices, np.int32(1), None, np.int32(0), np.int32(1),
               buffers.views, np.int32(0), buffers.offsets, np.int32(1), counter, big, depth)
    assert int(device.read(counter, 1, np.uint32)[0]) == 0
    assert (device.read(depth, samples, np.uint32) == structs.DEPTH_EMPTY).all()


def test_a_long_list_pads_to_whole_work_groups(device, monkeypatch):
    # 151 listed blocks of 64 on a CPU device: work-groups of several blocks, the list padded
    # to whole groups, and the padding's work-items draw nothing.
    global_size, local_size = raster_stage._blocks_launch(device, 151, 64)
    assert global_size[0] == 64 and global_size[1] >= 151
    if device.is_cpu:
        assert local_size[0] == 64 and global_size[1] % local_size[1] == 0
        assert global_size[1] > 151  # (an odd count of blocks in groups of a power of two)
    # A floor of 20 000 triangles under a point light and the camera: each view lists part of it.
    monkeypatch.setattr(raster_stage, "LIST_AT_MOST", 2.0)
    triangles = np.concatenate([grid_plane(0.0, 30.0, 100), box_triangles([-1, 0, -1], [1, 1.5, 1])])
    scene = make_scene(triangles, [PointLight(LIGHT, np.full(3, 30.0))], width=48, height=32, shadow_map=64)
    counts = [len(drawn) for drawn in _lists(scene)]
    assert min(counts) < len(triangles) // 2 and max(counts) > 8000
    culled = _maps(device, scene)
    monkeypatch.setattr(raster_stage, "CULL_PER_VIEW", False)
    every = _maps(device, scene)
    for name, values in every.items():
        assert np.array_equal(culled[name], values), f"{name} differs"


def _slivers(seed: int) -> np.ndarray:
    """Thin poles' sides: upright quads 0.001–0.05 wide and 1–3 tall, turned at random."""
    rng = np.random.default_rng(seed)
    quads = []
    for _ in range(150):
        base = rng.uniform([-3.0, 0.0, -3.0], [3.0, 0.5, 3.0])
        across = rng.uniform(0.001, 0.05) * np.array([np.cos(angle := rng.uniform(0, np.pi)), 0.0, np.sin(angle)])
        up = np.array([rng.uniform(-0.05, 0.05), rng.uniform(1.0, 3.0), 0.0])
        a, b, c, d = base, base + across, base + across + up, base + up
        quads += [[a, b, c], [a, c, d]]
    return np.array(quads)


def test_slivers_within_one_column_keep_the_bits(device, monkeypatch):
    # A polygon whose columns lie within one pixel's skips row_span on every row
    # (cl/raster.cl, one_column): a device built without the shortcut asks row_span on each,
    # and the camera's depths and triangles and the maps of a point light, a spot and a sun
    # must be the same bits.
    from clrays.device import Device
    from conftest import TEST_DEVICE

    monkeypatch.setitem(structs.KERNEL_CONSTANTS, "RASTER_ONE_COLUMN", 0)
    every_row = Device(TEST_DEVICE)
    monkeypatch.undo()
    triangles = np.concatenate([_slivers(3), grid_plane(0.0, 6.0, 4)])
    for light in LIGHTS.values():
        for width, height, spp in [(160, 90, 1), (96, 54, 4)]:
            scene = make_scene(triangles, light, width=width, height=height, spp=spp, shadow_map=256,
                               position=(0, 1.5, 7), look_at=(0, 1.2, 0))
            ours, theirs = _maps(device, scene), _maps(every_row, scene)
            assert (ours["triangle"] >= 0).sum() > 100
            for name, values in theirs.items():
                assert np.array_equal(ours[name], values), (name, width, height, spp)
