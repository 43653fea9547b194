"""Shaft edges on the blockers (cl/shaft_edges.h, clrays/stages/shaft_edges.py): which
triangle lies across each edge, the blocker rectify keeps per texel, and the walks' runs
ending on the blockers' silhouettes rather than at texel boundaries."""
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from clrays.device import StageTimer
from clrays.inputs import frame_inputs, upload
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.scene.geometry import box_triangles
from clrays.scene.load import load_scene
from clrays.stages import raster as raster_stage
from clrays.stages.raster import raster
from clrays.stages.rectify import rectify
from clrays.stages.shaft_edges import edge_neighbours, edge_windings
from conftest import DirectionalLight, PointLight, grid_plane, make_scene, v3

SCENES = Path(__file__).resolve().parents[2] / "scenes"
PI_F = float(np.float32(math.pi))  # S of an unblocked light ray


def test_a_closed_box_links_every_edge_both_ways():
    scene = make_scene(box_triangles([-1.0, 0.0, -1.0], [1.0, 2.0, 1.0]))
    neighbours = edge_neighbours(scene.geometry)
    assert neighbours.shape == (12, 3) and (neighbours >= 0).all()
    for triangle, across in enumerate(neighbours):
        for other in across:
            assert other != triangle and triangle in neighbours[other]


def test_a_border_and_a_translucent_triangle_have_no_neighbour_there():
    square = grid_plane(0.0, 1.0, 1)  # two triangles sharing a diagonal; its sides are its border
    assert sorted(edge_neighbours(make_scene(square).geometry).ravel().tolist()) == [-1, -1, -1, -1, 0, 1]
    geometry = make_scene(np.concatenate([square, square + [0.0, 0.0, 2.0]])).geometry  # sharing z = 1
    assert (edge_neighbours(geometry)[:2] >= 2).any()
    opacity = np.ones((4, 3))
    opacity[2:] = 0.5  # the second square a pane: the light goes on through it
    linked = edge_neighbours(replace(geometry, opacity=opacity))
    assert (linked[:2] < 2).all() and (linked[2:] == -1).all()


def test_windings_mark_a_neighbour_wound_the_other_way():
    square = grid_plane(0.0, 1.0, 1)  # (a, b, c) and (a, c, d): their shared edge runs c → a, then a → c
    assert edge_windings(make_scene(square).geometry).tolist() == [0, 0]
    square[1] = square[1][[0, 2, 1]]  # (a, d, c): the shared edge, its edge 2, now runs c → a as in the first
    assert edge_windings(make_scene(square).geometry).tolist() == [4, 4]
    box = box_triangles([-1.0, 0.0, -1.0], [1.0, 2.0, 1.0])
    assert not edge_windings(make_scene(box).geometry).any()  # a closed box, wound outward throughout
    box[5] = box[5][[0, 2, 1]]
    windings = edge_windings(make_scene(box).geometry)
    assert windings[5] == 7 and sum(bin(w).count("1") for w in windings) == 6  # its three edges, seen from both sides


def test_a_surface_wound_either_way_ends_its_shafts_alike(monkeypatch):
    """A walk follows a blocker's surface across its edges until one triangle faces the light
    and the next does not (cl/shaft_edges.h, surface_turns); a neighbour wound the other way
    has its normal the other way, which its winding bit undoes. A slab of 128 coplanar
    triangles, every other one wound the other way, casts the shafts the slab wound one way
    casts. Read without the windings, the flipped slab's walks stop at its inner edges (the
    test of the test: the images then differ)."""
    import clrays.session as session
    from clrays.session import Renderer

    floor, slab = grid_plane(0.0, 8.0, 2), grid_plane(2.0, 1.5, 8)
    flipped = slab.copy()
    flipped[::2] = flipped[::2][:, [0, 2, 1]]
    make = lambda occluder: make_scene(  # noqa: E731
        np.concatenate([floor, occluder]), [PointLight(v3(0.3, 5.0, -0.4), np.full(3, 40.0))], width=48, height=32,
        position=(0.0, 1.2, 7.0), look_at=(0.0, 1.8, 0.0), shadow_map=256, slices=64, gamma_samples=256)
    image = lambda scene: Renderer(reuse=False).render(scene, "minmax").image  # noqa: E731
    wound_one_way = image(make(slab))
    assert wound_one_way.max() > 0.0
    np.testing.assert_array_equal(image(make(flipped)), wound_one_way)
    monkeypatch.setattr(session, "edge_windings", lambda geometry: np.zeros(geometry.count, np.uint8))
    unwound = image(make(flipped))
    apart = (np.abs(unwound - wound_one_way) > 1e-5 * wound_one_way.max()).any(axis=-1)
    assert apart.sum() >= 10  # measured: 37 pixels of 1536, by up to 6e-5 of the brightest


def _blockers(device, scene):
    """(S, blocker) of level 0 of the first light's tree, as rectify wrote them."""
    buffers = upload(device, frame_inputs(scene))
    timer = StageTimer()
    epipolar = rectify(device, buffers, raster(device, buffers, timer), 0, timer)
    n, slices = int(epipolar.params["gamma_samples"]), int(epipolar.params["slices"])
    tree = device.read(epipolar.tree, slices * 2 * n * 2, np.float32).reshape(slices, 2 * n, 2)
    blocker = device.read(epipolar.triangles, slices * n, np.int32).reshape(slices, n)
    return tree[:, :n, 0], blocker


def _scene(light):
    triangles = np.concatenate([grid_plane(0.0, 8.0, 4), box_triangles([-1.0, 1.2, -1.0], [1.0, 1.6, 0.8])])
    return make_scene(triangles, [light], width=48, height=32, position=(0, 2.5, 8), look_at=(0, 2.0, 0),
                      shadow_map=128, slices=48, gamma_samples=128)


@pytest.mark.parametrize("light", [PointLight(v3(0.4, 4.5, -0.6), np.full(3, 40.0)),
                                   DirectionalLight(v3(0.35, -1.0, -0.25) / np.linalg.norm([0.35, -1.0, -0.25]),
                                                    np.full(3, 1.5))], ids=["point", "directional"])
def test_every_blocked_texel_keeps_its_blocker(device, monkeypatch, light):
    scene = _scene(light)
    beta, blocker = _blockers(device, scene)
    blocked = beta < PI_F
    assert blocked.any() and (~blocked).any()
    assert (blocker[blocked] >= 0).all() and (blocker[blocked] < scene.geometry.count).all()
    assert (beta[blocker == -1] == PI_F).all()  # (a blocker far behind the eye may give π too)
    # The floor's blockers are the floor's triangles; the box's, the box's: some of each.
    assert (blocker[blocked] < 32).any() and (blocker[blocked] >= 32).any()
    # A device without 64-bit atomics resolves the nearest triangle in a second pass: the same.
    monkeypatch.setattr(raster_stage, "_atomic64", lambda device: False)
    beta_resolved, blocker_resolved = _blockers(device, scene)
    np.testing.assert_array_equal(beta_resolved, beta)
    np.testing.assert_array_equal(blocker_resolved, blocker)


def test_two_lights_blockers_from_keys_or_resolved_give_one_image(device, monkeypatch):
    """Two lights' maps in one atlas: rectify reads each texel's blocker from the 64-bit keys
    raster drew (8 bytes a texel in the atlas) or, on a device without 64-bit atomics, from
    the triangles a second pass resolved; the images are the same bits."""
    from clrays.session import Renderer

    sun = DirectionalLight(v3(0.35, -1.0, -0.25) / np.linalg.norm([0.35, -1.0, -0.25]), np.full(3, 1.5))
    scene = replace(_scene(PointLight(v3(0.4, 4.5, -0.6), np.full(3, 40.0))),
                    lights=(PointLight(v3(0.4, 4.5, -0.6), np.full(3, 40.0)), sun))
    keys = Renderer(device, reuse=False).render(scene, "minmax").image
    monkeypatch.setattr(raster_stage, "_atomic64", lambda device: False)
    resolved = Renderer(device, reuse=False).render(scene, "minmax").image
    assert keys.max() > 0.0
    np.testing.assert_array_equal(keys, resolved)


def test_a_relief_blocks_with_its_own_triangles(device, monkeypatch):
    """Where the walks cut a relief themselves (stages/relief_cuts.py) the rows leave it out
    and keep the walls around it; where they cannot (a device without 64-bit keys), the
    relief is in the rows by its own triangles' ids."""
    scene = load_scene(SCENES / "lattice.yaml", ["image.width=32", "image.height=18", "render.shadow_map=256",
                                                 "render.slices=64", "render.gamma_samples=256"])
    inputs = frame_inputs(scene)
    relief = range(inputs.raster_triangles, inputs.scene.geometry.count)  # placed last (place_reliefs)
    beta, blocker = _blockers(device, scene)
    ids = blocker[beta < PI_F]
    assert ids.size and not np.isin(ids, relief).any()
    assert (ids >= 0).all() and (ids < inputs.raster_triangles).all()
    monkeypatch.setattr(raster_stage, "_atomic64", lambda device: False)
    beta, blocker = _blockers(device, scene)
    ids = blocker[beta < PI_F]
    assert np.isin(ids, relief).any()
    assert (ids >= 0).all() and (ids < inputs.scene.geometry.count).all()


def test_slat_shafts_have_their_edges_on_the_slats(renderer):
    """Slats 12 cm wide under a sun, seen across their shafts: with the shafts' edges on the
    slats a map gets closer to `exact` than the texels alone allow. Measured relative RMSE at
    512² / 1024²: 0.214 / 0.127 % (with the runs' ends at the texels 0.365 / 0.212 %). With
    the map over the bounding sphere instead of the bounds' outline (clrays.scene.light_views)
    they were 0.318 / 0.162 and 0.512 / 0.265 %."""
    parts = [grid_plane(0.0, 8.0, 4)]
    parts += [box_triangles([x, 2.0, -3.0], [x + 0.12, 2.1, 3.0]) for x in np.arange(-3.0, 3.0, 0.5)]
    sun = DirectionalLight(v3(0.3, -1.0, 0.2) / np.linalg.norm([0.3, -1.0, 0.2]), np.full(3, 1.5))
    make = lambda size, ends="blockers": make_scene(  # noqa: E731
        np.concatenate(parts), [sun], width=64, height=36, position=(0.0, 1.0, 6.0), look_at=(0.5, 1.2, 0.0),
        far=20.0, sigma_s=0.1, sigma_a=0.02, shadow_map=size, shaft_edges=ends)
    reference = renderer.render(make(1024), "exact").image
    edges = depth_edges(depth_map(make(1024)))
    errors = {(size, ends): image_error(renderer.render(make(size, ends), "minmax").image, reference, edges).rmse
              for size in (512, 1024) for ends in ("blockers", "texels")}
    print("slat shafts, relative RMSE:", errors)
    assert errors[512, "blockers"] <= 0.003 and errors[1024, "blockers"] <= 0.0016
    for size in (512, 1024):  # `render.shaft_edges: texels`, the runs' ends at the texels
        assert errors[size, "blockers"] < 0.75 * errors[size, "texels"]


def test_texel_ends_keep_no_blockers(device):
    scene = _scene(PointLight(v3(0.4, 4.5, -0.6), np.full(3, 40.0)))
    scene = replace(scene, render=replace(scene.render, shaft_edges="texels"))
    buffers = upload(device, frame_inputs(scene))
    timer = StageTimer()
    rastered = raster(device, buffers, timer)
    assert rastered.shadow_blockers is None
    assert rectify(device, buffers, rastered, 0, timer).triangles is None


def test_an_unknown_shaft_edges_value_is_one_line(tmp_path):
    from conftest import run_cli

    code, out = run_cli("render", SCENES / "demo.yaml", "-o", tmp_path / "x.png", "--set", "render.shaft_edges=edges")
    assert code == 1 and out.strip().splitlines() == [
        "clrays: error: --set render.shaft_edges=edges: render.shaft_edges: expected one of 'blockers', 'texels', "
        "got 'edges'"]
    assert not (tmp_path / "x.png").exists()
