"""The visibility stage's shadow rays (cl/visibility.cl, docs/design.md §4.6): in a frame
of few samples, or one whose maps leave fewer rays than it has triangles, they test the
triangles listed as touching their texel instead of walking the BVH, which is then never
built. Both must give the same image, bit for bit."""
from pathlib import Path

import numpy as np
import pytest

import clrays.stages.visibility as stage
from clrays.scene.load import load_scene
from clrays.session import Renderer
from conftest import grid_plane, make_scene
from test_visibility_bound import LIGHTS, _triangles  # a floor, a box, a sub-texel wire, random triangles

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _small_grid() -> np.ndarray:
    """A plate of 1152 small triangles above the floor: many triangles, few shadow edges."""
    return grid_plane(2.2, 1.0, 24)


def _both_ways(device, scene, monkeypatch):
    """(image with the lists, image through the BVH, BVH builds with the lists, with the BVH)."""
    real, built = stage.bvh_build_tree, []

    def counted(*args):
        built.append(1)
        return real(*args)

    monkeypatch.setattr(stage, "bvh_build_tree", counted)
    listed = Renderer(device, reuse=False).render(scene).image
    with_lists = len(built)
    monkeypatch.setattr(stage, "TOUCHING_ENTRIES", 0)
    monkeypatch.setattr(stage, "RAY_LIST_ENTRIES", 0)
    walked = Renderer(device, reuse=False).render(scene).image
    return listed, walked, with_lists, len(built) - with_lists


def _rays_listed_and_walked(device, scene, monkeypatch):
    """(image with the lists of the rays' texels, image through the BVH, how often each
    way was taken) for a frame too large for the first pass's lists."""
    monkeypatch.setattr(stage, "TOUCHING_ENTRIES", 0)
    real_lists, real_build, taken = stage.ray_lists, stage.bvh_build_tree, {"lists": 0, "bvh": 0}

    def lists(*args):
        taken["lists"] += 1
        return real_lists(*args)

    monkeypatch.setattr(stage, "ray_lists", lists)
    monkeypatch.setattr(stage, "bvh_build_tree", lambda *args: taken.__setitem__("bvh", taken["bvh"] + 1) or real_build(*args))
    listed = Renderer(device, reuse=False).render(scene).image
    counts = dict(taken)
    monkeypatch.setattr(stage, "RAY_LIST_ENTRIES", 0)
    walked = Renderer(device, reuse=False).render(scene).image
    return listed, walked, counts, taken["bvh"] - counts["bvh"]


@pytest.mark.parametrize("kind", LIGHTS)
def test_listed_triangles_answer_as_the_bvh(device, monkeypatch, kind):
    scene = make_scene(_triangles(), [LIGHTS[kind]], width=40, height=30, shadow_map=64)
    listed, walked, with_lists, with_bvh = _both_ways(device, scene, monkeypatch)
    assert with_lists == 0 and with_bvh == 1  # rays were cast, through the lists, then the BVH
    np.testing.assert_array_equal(listed, walked)


def test_every_light_has_its_lists(device, monkeypatch):
    scene = make_scene(_triangles(), list(LIGHTS.values()), width=32, height=24, shadow_map=64)
    listed, walked, with_lists, with_bvh = _both_ways(device, scene, monkeypatch)
    assert with_lists == 0 and with_bvh == 1
    np.testing.assert_array_equal(listed, walked)


@pytest.mark.parametrize("size", ["16x9", "64x36"])
def test_the_bunny_thumbnail_builds_no_bvh(device, monkeypatch, size):
    width, height = size.split("x")
    scene = load_scene(SCENES / "bunny.yaml", overrides=[f"image.width={width}", f"image.height={height}"])
    listed, walked, with_lists, with_bvh = _both_ways(device, scene, monkeypatch)
    assert with_lists == 0 and with_bvh == 1
    np.testing.assert_array_equal(listed, walked)


@pytest.mark.parametrize("kind", LIGHTS)
def test_the_rays_texels_listed_answer_as_the_bvh(device, monkeypatch, kind):
    # A grid of small triangles, so that the rays are fewer than the triangles.
    scene = make_scene(np.concatenate([_triangles(), _small_grid()]), [LIGHTS[kind]], width=64, height=48, shadow_map=64)
    listed, walked, counts, with_bvh = _rays_listed_and_walked(device, scene, monkeypatch)
    assert counts == {"lists": 1, "bvh": 0} and with_bvh == 1
    np.testing.assert_array_equal(listed, walked)


def test_the_rays_texels_listed_for_every_light_in_turn(device, monkeypatch):
    # The lights take their turns (clrays.light_turns): each its lists, one BVH for the frame.
    scene = make_scene(np.concatenate([_triangles(), _small_grid()]), list(LIGHTS.values()), width=64, height=48,
                       shadow_map=64)
    listed, walked, counts, with_bvh = _rays_listed_and_walked(device, scene, monkeypatch)
    assert counts == {"lists": len(LIGHTS), "bvh": 0} and with_bvh == 1
    np.testing.assert_array_equal(listed, walked)


def test_the_bunny_at_640x360_builds_no_bvh(device, monkeypatch):
    scene = load_scene(SCENES / "bunny.yaml", overrides=["image.width=640", "image.height=360"])
    listed, walked, counts, with_bvh = _rays_listed_and_walked(device, scene, monkeypatch)
    assert counts == {"lists": 1, "bvh": 0} and with_bvh == 1
    np.testing.assert_array_equal(listed, walked)


def test_full_lists_fall_back_to_the_bvh(device, monkeypatch):
    # Room for one node: the lists are not whole, so the rays take the BVH, with the same image.
    scene = make_scene(_triangles(), [LIGHTS["point"]], width=40, height=30, shadow_map=64)
    reference = Renderer(device, reuse=False).render(scene).image
    monkeypatch.setattr(stage, "TOUCHING_NODES_PER_ENTRY", 0)
    real, built = stage.bvh_build_tree, []
    monkeypatch.setattr(stage, "bvh_build_tree", lambda *args: built.append(1) or real(*args))
    np.testing.assert_array_equal(Renderer(device, reuse=False).render(scene).image, reference)
    assert built == [1]


def test_a_kept_bound_map_lists_by_the_lights_own_texels(device):
    # The spot's bound map, kept from a frame where its texels come first, serves a frame
    # where the point light's cube comes before them: its lists must be read at this
    # frame's addresses (a read at the old ones ran off the lists), and the image must be
    # the one computed from scratch.
    session = Renderer(device)
    spot = make_scene(_triangles(), [LIGHTS["spot"]], width=40, height=30, shadow_map=64)
    both = make_scene(_triangles(), [LIGHTS["point"], LIGHTS["spot"]], width=40, height=30, shadow_map=64)
    session.render(spot)
    kept = session.render(both)
    assert kept.stage_status["visibility"] == "computed"
    np.testing.assert_array_equal(kept.image, Renderer(device, reuse=False).render(both).image)


def test_a_kept_bound_map_lists_its_rays_texels_again(device, monkeypatch):
    # A brighter light keeps the bound map (and its triangles' rectangles) but decides the
    # visibility again: the rays' lists are built from the kept map, and the image is the
    # one computed from scratch.
    calls, real = [], stage.ray_lists
    monkeypatch.setattr(stage, "ray_lists", lambda *args: calls.append(1) or real(*args))
    size = ["image.width=160", "image.height=90"]
    brighter = load_scene(SCENES / "bunny.yaml", overrides=size + ["lights.0.intensity=[500, 450, 400]"])
    session = Renderer(device)
    session.render(load_scene(SCENES / "bunny.yaml", overrides=size))
    kept = session.render(brighter)
    assert kept.stage_status["raster.shadow"] == "reused" and kept.stage_status["visibility"] == "computed"
    assert calls == [1, 1]
    np.testing.assert_array_equal(kept.image, Renderer(device, reuse=False).render(brighter).image)


def test_rays_lists_that_outgrow_their_room_fall_back_to_the_bvh(device, monkeypatch):
    # No room per ray: the lists made for the rays' texels overflow, which the device finds
    # (visibility_reroute), and the rays take the BVH, with the image of the lists.
    scene = make_scene(np.concatenate([_triangles(), _small_grid()]), [LIGHTS["point"]], width=64, height=48,
                       shadow_map=64)
    monkeypatch.setattr(stage, "TOUCHING_ENTRIES", 0)
    reference = Renderer(device, reuse=False).render(scene)
    monkeypatch.setattr(stage, "TOUCHING_NODES_PER_ENTRY", 0)
    real, built = stage.bvh_build_tree, []
    monkeypatch.setattr(stage, "bvh_build_tree", lambda *args: built.append(1) or real(*args))
    overflowed = Renderer(device, reuse=False).render(scene)
    assert built == [1] and overflowed.shadow_rays == reference.shadow_rays > 0
    np.testing.assert_array_equal(overflowed.image, reference.image)


def _host_route(rays, without_texel, counts, capacities, limit, lists_made=None, nodes_per_ray=0):
    """The route as the host chose it when it read the counts (clrays/structs.py VISIBILITY_ROUTE_*)."""
    from clrays import structs

    if not rays:
        return structs.VISIBILITY_ROUTE_NONE
    whole = bool(capacities) and all(0 < c and n <= c for n, c in zip(counts, capacities))
    if whole and not without_texel:
        return structs.VISIBILITY_ROUTE_LISTED
    if not whole and not without_texel and rays <= limit:
        if all(n <= nodes_per_ray * rays for n in lists_made):
            return structs.VISIBILITY_ROUTE_RAY_LISTED
    return structs.VISIBILITY_ROUTE_BVH


def test_the_device_routes_the_rays_as_the_host_did(device):
    """visibility_route and visibility_reroute against the host's rule, over every case:
    no ray; the thumbnail's lists whole or not; rays with no texel; rays within the list
    limit or not; the rays' lists within their room or not."""
    cases = 0
    for rays in (0, 1, 50, 51):
        for without_texel in (0, 1):
            for thumbnail in ([], [(10, 20)], [(10, 20), (30, 20)], [(5, 0)]):
                for made in ([10], [10, 200], [2000]):
                    counts = [n for n, _ in thumbnail]
                    capacities = [c for _, c in thumbnail]
                    route = device.buffer(np.full(1, 99, np.int32))
                    ray_count = device.buffer(np.array([rays, without_texel], np.int32))
                    device.kernel("visibility", "visibility_route")(
                        device.queue, (1,), None, ray_count, np.int32(len(thumbnail)),
                        device.buffer(np.array(counts or [0], np.int32)),
                        device.buffer(np.array(capacities or [0], np.int32)), np.int32(50), route)
                    device.kernel("visibility", "visibility_reroute")(
                        device.queue, (1,), None, ray_count, np.int32(len(made)),
                        device.buffer(np.array(made, np.int32)), np.int32(4), route)
                    got = int(device.read(route, 1, np.int32)[0])
                    assert got == _host_route(rays, without_texel, counts, capacities, 50, made, 4), \
                        (rays, without_texel, thumbnail, made)
                    cases += 1
    assert cases == 96
