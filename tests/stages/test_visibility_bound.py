"""The visibility stage's bound and writer maps (cl/visibility.cl, docs/design.md §4.6)
against a float64 numpy ray cast of 5 × 5 rays across every texel, triangle by triangle:
the bound must be at or under every depth a triangle has in the texel (the map's lit test
relies on it), and the writer must name the triangle when it is the only one touching the
texel, and be WRITER_MANY when two or more do."""
import numpy as np
import pytest

from clrays import structs
from clrays.device import StageTimer
from clrays.inputs import frame_inputs, light_pass_inputs, upload
from clrays.physics.geometry import raycast
from clrays.scene.geometry import box_triangles
from clrays.stages.visibility import visibility_bound
from conftest import DirectionalLight, PointLight, SpotLight, grid_plane, make_scene, v3

RAYS_PER_SIDE = 5


def _triangles() -> np.ndarray:
    """A floor, a box, a wire far thinner than a texel and a few random triangles (seeded)."""
    rng = np.random.default_rng(11)
    wire = np.array([[[-2.5, 1.2, -1.0], [2.5, 1.25, 1.0], [2.5, 1.2005, 1.0]]])
    random = rng.uniform(-2.0, 2.0, (6, 3, 3)) * [1.0, 0.4, 1.0] + [0.0, 1.6, 0.0]
    return np.concatenate([grid_plane(0.0, 5.0, 1), box_triangles([-1.5, 0.0, 0.8], [-0.7, 0.9, 1.6]), wire, random])


LIGHTS = {
    "point": PointLight(v3(0.4, 4.0, 0.3), np.full(3, 30.0)),
    "spot": SpotLight(v3(-1.0, 3.5, 2.0), v3(0.2, -0.8, -0.4) / np.linalg.norm([0.2, -0.8, -0.4]), 50.0,
                      np.full(3, 30.0)),
    "directional": DirectionalLight(v3(-0.5, -0.8, 0.3) / np.linalg.norm([-0.5, -0.8, 0.3]), np.full(3, 3.0)),
}


def _texel_rays(view):
    """Origins and directions of RAYS_PER_SIDE² rays through every texel of a view, and the
    texel of each ray; depth along a ray is t·|direction| (perspective) or t - reach."""
    width, height = int(view["width"]), int(view["height"])
    offsets = (np.arange(RAYS_PER_SIDE) + 0.5) / RAYS_PER_SIDE
    px = (np.arange(width)[:, None] + offsets).ravel()
    py = (np.arange(height)[:, None] + offsets).ravel()
    gx, gy = np.meshgrid(px, py)
    texel = (gy.astype(int) * width + gx.astype(int)).ravel()
    sx, sy = (2.0 * gx / width - 1.0).ravel(), (1.0 - 2.0 * gy / height).ravel()
    right, up, forward = (np.asarray(view[k][:3], np.float64) for k in ("right", "up", "forward"))
    across = sx[:, None] * float(view["scale_x"]) * right + sy[:, None] * float(view["scale_y"]) * up
    if view["projection"] == structs.PROJECTION_PERSPECTIVE:
        return np.zeros(3), forward + across, texel
    return across - 1e3 * forward, np.broadcast_to(forward, across.shape), texel


@pytest.mark.parametrize("kind", LIGHTS)
def test_bound_and_writer_maps_hold_every_triangle_they_must(device, kind):
    scene = make_scene(_triangles(), [LIGHTS[kind]], shadow_map=48)
    buffers = upload(device, frame_inputs(scene))
    maps = visibility_bound(device, buffers, 0, StageTimer())
    inputs = light_pass_inputs(buffers.inputs, 0)
    bound = device.read(maps.bound, inputs.shadow_texels, np.uint32).view(np.float32)
    writer = device.read(maps.writer, inputs.shadow_texels, np.int32)
    triangles = inputs.tri_vertices[:, :3].astype(np.float64).reshape(-1, 3, 3)  # as the device has them
    checked = touched_twice = 0
    for index in np.flatnonzero(inputs.view_needed[1:]) + 1:
        view = inputs.views[index]
        texels = slice(int(view["depth_offset"]), int(view["depth_offset"]) + int(view["width"] * view["height"]))
        origins, directions, texel = _texel_rays(view)
        perspective = view["projection"] == structs.PROJECTION_PERSPECTIVE
        touching = np.zeros(int(view["width"] * view["height"]), np.int64)
        only = np.full(touching.shape, -1)
        for tri, triangle in enumerate(triangles):
            t, _ = raycast(origins, directions, triangle[None], t_min=0.0 if perspective else 1.0)
            hit = np.isfinite(t)
            if perspective:
                depth = t[hit] * np.linalg.norm(directions[hit], axis=1)
            else:
                depth = t[hit] - 1e3
            # No depth of the triangle in a texel lies under the texel's bound (float32 margin 1e-5).
            lowest = np.full(touching.shape, np.inf)
            np.minimum.at(lowest, texel[hit], depth)
            assert (bound[texels] <= lowest * (1 + 1e-5) + 1e-5).all(), f"{kind}: triangle {tri} under a bound"
            seen = np.unique(texel[hit])
            touching[seen] += 1
            only[seen] = tri
            checked += len(seen)
        mine = writer[texels]
        assert (mine[touching >= 2] == structs.WRITER_MANY).all(), f"{kind}: a texel two triangles touch names one"
        single = touching == 1
        named = (mine[single] == only[single]) | (mine[single] == structs.WRITER_MANY)
        assert named.all(), f"{kind}: a texel one triangle touches names another"
        touched_twice += int((touching >= 2).sum())
    assert checked > 1000 and touched_twice > 100  # the rays did meet the triangles, and overlap


def test_a_frame_without_big_triangles_asks_for_no_empty_wait(renderer):
    """No view lists a triangle for the rows pass (a small sphere on a 64² map): the
    host then waits for no read at all. OpenCL refuses an empty wait list
    (CL_INVALID_VALUE, PoCL and NVIDIA alike), and every frame of small triangles failed."""
    from clrays.scene.geometry import sphere_triangles

    ball = sphere_triangles(np.array([0.0, 1.0, 0.0]), 0.3, 16)
    scene = make_scene(ball, [PointLight(v3(0.5, 4.0, 0.5), np.full(3, 30.0))], width=32, height=18, shadow_map=64)
    image = renderer.render(scene, reuse=False).image
    assert np.isfinite(image).all() and image.max() > 0


@pytest.mark.parametrize("rows, columns", [(1, 0), (3, 0), (1, 32), (3, 5)])
def test_the_rows_pass_draws_the_same_maps_whatever_block_a_work_item_owns(device, monkeypatch, rows, columns):
    """A CPU's rows pass gives a work-item 16 whole rows, a GPU's 32 columns of one row
    (rows_pass_block): every texel's bound is a minimum and its writer one part or many,
    so the maps are the same bits however the texels are dealt out (3 and 5: blocks that
    end inside a triangle; columns 0: whole rows). This checks that the blocks clip each
    triangle to them and together cover it; a texel written by two work-items would give
    the same values too, and PoCL runs work-items in turn, so overlap is not seen here."""
    import clrays.stages.visibility as visibility_stage

    scene = make_scene(_triangles(), [LIGHTS["point"]], shadow_map=48)
    buffers = upload(device, frame_inputs(scene))
    texels = light_pass_inputs(buffers.inputs, 0).shadow_texels

    def maps():
        drawn = visibility_bound(device, buffers, 0, StageTimer())
        return device.read(drawn.bound, texels, np.uint32), device.read(drawn.writer, texels, np.int32)

    bound, writer = maps()
    blocks = []
    monkeypatch.setattr(visibility_stage, "rows_pass_block",
                        lambda device, width: blocks.append(width) or (rows, columns or width))
    other_bound, other_writer = maps()
    assert blocks, "the scene has triangles taller than the first pass's rows"
    np.testing.assert_array_equal(other_bound, bound)
    np.testing.assert_array_equal(other_writer, writer)


@pytest.mark.parametrize("kind", ["point", "directional"])
@pytest.mark.parametrize("listed", [0, 1, 37, 300, 2048, 2049])
def test_the_rows_pass_list_is_ordered_nearest_first_on_the_device(device, kind, listed):
    """visibility_order against numpy: the list, whose length the kernel reads from the
    device, comes back as the same items nearest the view first (a triangle's centroid from
    the view's origin; orthographic: along `forward`), within float32 rounding of the
    distances; a list longer than ORDER_LONGEST (2048) comes back as it was."""
    from clrays.stages.visibility import ORDER_ITEMS, ungated

    scene = make_scene(_triangles(), [LIGHTS[kind]], shadow_map=48)
    inputs = light_pass_inputs(frame_inputs(scene), 0)
    view = 1
    rng = np.random.default_rng(listed)
    triangles = inputs.tri_vertices.shape[0] // 3
    items = np.stack([rng.integers(0, triangles, listed), rng.integers(0, 48, listed), rng.integers(0, 48, listed),
                      rng.integers(0, 1 << 20, listed)], axis=1).astype(np.int32).reshape(-1, 4)
    ordered = device.buffer(nbytes=16 * max(listed, 1))
    device.kernel("visibility_bound", "visibility_order")(
        device.queue, (ORDER_ITEMS,), (ORDER_ITEMS,), device.buffer(inputs.tri_vertices), device.buffer(inputs.views),
        np.int32(view), device.buffer(items if listed else np.zeros((1, 4), np.int32)),
        device.buffer(np.array([listed], np.int32)), ordered, *ungated(device))
    got = device.read(ordered, (max(listed, 1), 4), np.int32)[:listed]
    if listed > 2048:
        np.testing.assert_array_equal(got, items)
        return
    assert sorted(map(tuple, got)) == sorted(map(tuple, items))  # the same items, each once
    centroids = inputs.tri_vertices[:, :3].reshape(-1, 3, 3).astype(np.float64).mean(axis=1)[got[:, 0]]
    centroids -= np.asarray(inputs.views[view]["origin"][:3], np.float64)
    if inputs.views[view]["projection"] == structs.PROJECTION_PERSPECTIVE:
        distance = np.linalg.norm(centroids, axis=1)
    else:
        distance = centroids @ np.asarray(inputs.views[view]["forward"][:3], np.float64)
    assert np.all(np.diff(distance) >= -1e-5 * (1.0 + np.abs(distance[1:])))
