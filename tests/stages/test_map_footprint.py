"""Each view of a light's map as fine as the thin solids it holds need (clrays.scene.costs
.view_map_sides): a cube face that holds none keeps the image's side, `render.shadow_map_floor`,
while a face with a slat grows to `render.shadow_map` (docs/design.md §8, "Sizes from the
occluders")."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from clrays.inputs import frame_inputs
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.scene.costs import MIN_SHADOW_MAP, _cube_faces_reached, view_map_sides, with_derived_sizes
from clrays.scene.geometry import box_triangles
from clrays.scene.load import load_scene
from conftest import DirectionalLight, PointLight, SpotLight, grid_plane, make_scene, v3, with_closed_solid

SCENES = Path(__file__).resolve().parents[2] / "scenes"
UNSET = dict(shadow_map=None, slices=None, gamma_samples=None)
#: Cube faces in the order of clrays.inputs' views: +x, -x, +y, -y, +z, -z.
MINUS_Y = 3


def _slats_scene(light, centres_x=(0.0,), width=0.01, depth=0.2, image=(320, 180), **render):
    """A floor at y = 0 and slats `width` wide (x), `depth` deep (y), 3 long, their tops at
    y = 3.2, one centred on each of `centres_x`; each slat a closed solid."""
    floor = grid_plane(0.0, 8.0, 2)
    slats = [box_triangles([x - width / 2, 3.2 - depth, -1.5], [x + width / 2, 3.2, 1.5]) for x in centres_x]
    scene = make_scene(np.concatenate([floor, *slats]), [light], width=image[0], height=image[1],
                       position=(0, 2, 9), look_at=(0, 1.5, 0), **{**UNSET, **render})
    for first in range(len(floor), len(scene.geometry.triangles), len(slats[0])):
        scene = with_closed_solid(scene, slice(first, first + len(slats[0])))
    return scene


def _sides(scene) -> list[int]:
    derived = with_derived_sizes(scene)
    render = derived.render
    return view_map_sides(derived.geometry, derived.lights[0], render.shadow_map_floor, render.shadow_map)


POINT = PointLight(v3(0, 6, 0), np.full(3, 30.0))


def test_only_the_face_below_grows_for_a_slat_below_a_point_light():
    """1 cm at 2.8 below the light is 1.8 texels of a 1024² face: the −y face grows to 4096²
    (7.1 texels), the five others keep the image's 1024², a fifth of the texels of six
    4096² faces (4096² + 5 · 1024² against 6 · 4096²)."""
    scene = _slats_scene(POINT)
    assert _sides(scene) == [1024, 1024, 1024, 4096, 1024, 1024]
    render = with_derived_sizes(scene).render
    assert (render.shadow_map, render.shadow_map_floor) == (4096, 1024)
    inputs = frame_inputs(scene)
    # the +y face's cone misses the camera's view: never read, a token side (below)
    assert inputs.view_needed[1:].tolist() == [True, True, False, True, True, True]
    sides = [1024, 1024, MIN_SHADOW_MAP, 4096, 1024, 1024]
    assert [int(view["width"]) for view in inputs.views[1:]] == sides
    assert [int(view["height"]) for view in inputs.views[1:]] == sides
    assert inputs.shadow_texels == sum(side * side for side in sides)
    # the views lie back to back
    offsets = np.cumsum([0] + [int(v["width"]) * int(v["height"]) for v in inputs.views[1:-1]])
    assert inputs.views[1:]["depth_offset"].tolist() == offsets.tolist()


def test_a_rod_across_a_face_edge_grows_both_faces():
    """A rod 1 cm square at x = 2.805 under a light at x = 0, 2.8 to 2.81 below it: its box
    reaches past the plane |x| = |y| between the −y and +x faces, so both grow (1.7 texels
    of 1024 across it, seen 45° off the faces' axes); one at x = 3.5 lies in the +x face
    alone. (A slat 20 cm deep seen that far off its face's axis is no thin solid.)"""
    assert _sides(_slats_scene(POINT, centres_x=(2.805,), depth=0.01)) == [4096, 1024, 1024, 4096, 1024, 1024]
    assert _sides(_slats_scene(POINT, centres_x=(3.5,), depth=0.01)) == [4096, 1024, 1024, 1024, 1024, 1024]


def test_cube_faces_reached_is_exact_for_boxes():
    """Against points drawn inside random boxes (each box's corners and its point nearest to
    each axis among them): every face a point lies in is reached, and a face is reached only
    where the box's farthest point along the face's axis reaches it."""
    rng = np.random.default_rng(7)
    corners_lo = rng.uniform(-3, 3, (300, 3))
    lo, hi = corners_lo, corners_lo + rng.uniform(0.01, 2.0, (300, 3))
    reached = _cube_faces_reached(lo, hi)
    points = lo[:, None] + rng.uniform(0, 1, (300, 4000, 3)) * (hi - lo)[:, None]
    for k in range(3):  # the box's points nearest to axis k (the others at their least magnitude)
        nearest = np.clip(0.0, lo, hi)
        for end in (lo[:, k], hi[:, k]):
            extreme = nearest.copy()
            extreme[:, k] = end
            points = np.concatenate([points, extreme[:, None]], axis=1)
    axis = np.abs(points).argmax(axis=2)  # the face each point lies in
    sign = np.take_along_axis(points, axis[..., None], axis=2)[..., 0] < 0
    face = 2 * axis + sign
    seen = np.zeros_like(reached)
    for f in range(6):
        seen[:, f] = (face == f).any(axis=1)
    assert not (seen & ~reached).any()  # never a face missed
    assert (reached == seen).mean() > 0.99  # and hardly one reached that no drawn point lies in
    assert _cube_faces_reached(np.array([[-0.5, -3.0, -0.5]]), np.array([[0.5, -2.0, 0.5]])).tolist() == \
        [[False, False, False, True, False, False]]


def test_a_spot_and_the_sun_have_one_view():
    """A single-view spot light and a directional light grow their one view as before."""
    spot = _slats_scene(SpotLight(v3(0, 6, 0), v3(0, -1, 0), 30.0, np.full(3, 30.0)))
    sun = _slats_scene(DirectionalLight(v3(0, -1, 0), np.full(3, 2.0)))
    assert _sides(spot) == [2048]
    assert _sides(sun) == [with_derived_sizes(sun).render.shadow_map]
    wide_spot = _slats_scene(SpotLight(v3(0, 6, 0), v3(0, -1, 0), 80.0, np.full(3, 30.0)))  # a cube
    assert _sides(wide_spot) == [1024, 1024, 1024, 4096, 1024, 1024]


def test_a_scene_that_sets_the_map_gets_it_in_every_view():
    """`render.shadow_map` alone: every view at that side, as before; with a floor, the
    views without thin solids at the floor; a floor above the map is the map."""
    assert _sides(_slats_scene(POINT, shadow_map=2048)) == [2048] * 6
    assert _sides(_slats_scene(POINT, shadow_map=4096, shadow_map_floor=256)) == [256, 256, 256, 4096, 256, 256]
    assert _sides(_slats_scene(POINT, shadow_map=512, shadow_map_floor=1024)) == [512] * 6
    floor_only = with_derived_sizes(_slats_scene(POINT, shadow_map_floor=2048)).render
    assert (floor_only.shadow_map, floor_only.shadow_map_floor) == (4096, 2048)
    no_slat = with_derived_sizes(_slats_scene(POINT, width=0.2, shadow_map_floor=2048)).render
    assert (no_slat.shadow_map, no_slat.shadow_map_floor) == (2048, 2048)


def test_the_depth_bias_follows_the_coarsest_face_read():
    """One texel size per light scales every face's depth bias: that of the coarsest face
    the frame reads (a finer face's bias is larger than its texel, never smaller)."""
    inputs = frame_inputs(_slats_scene(POINT))
    read = inputs.view_needed[1:]
    widths = inputs.views[1:]["width"]
    assert float(inputs.lights[0]["texel_angle"]) == pytest.approx(2.0 / widths[read].min())
    assert float(inputs.lights[0]["texel_angle"]) == pytest.approx(2.0 / 1024)


def test_the_grate_grows_its_light_s_face_below_alone():
    """scenes/grate.yaml: every slat and the frame lie in the −y face of its point light; the
    +y face, which the camera cannot read, keeps a token side."""
    inputs = frame_inputs(load_scene(SCENES / "grate.yaml", overrides=["image.width=160", "image.height=90"]))
    assert [int(view["width"]) for view in inputs.views[1:]] == [1024, 1024, MIN_SHADOW_MAP, 4096, 1024, 1024]
    assert inputs.view_needed[1:].tolist() == [True, True, False, True, True, True]


def test_a_face_the_frame_never_reads_keeps_a_token_side():
    """scenes/behind.yaml's camera reads two faces of its light's cube: the four others are
    never drawn nor read, and take MIN_SHADOW_MAP² texels each, also where the scene sets
    the map's side."""
    for overrides in ([], ["render.shadow_map=512"]):
        inputs = frame_inputs(load_scene(SCENES / "behind.yaml", overrides=["image.width=160", "image.height=90",
                                                                            *overrides]))
        read, widths = inputs.view_needed[1:], inputs.views[1:]["width"]
        assert 0 < read.sum() < 6
        assert set(widths[read].tolist()) == {inputs.scene.render.shadow_map}
        assert set(widths[~read].tolist()) == {MIN_SHADOW_MAP}


def test_no_other_scene_changes_its_map():
    """The scenes of scenes/ without solids thinner than 6 texels of 1024² keep one side in
    every view the frame reads (clrays.scene.costs.OCCLUDER_TEXELS)."""
    for path in sorted(SCENES.glob("*.yaml")):
        if path.stem == "grate":
            continue
        scene = load_scene(path, overrides=["image.width=160", "image.height=90"])
        inputs = frame_inputs(scene)
        widths = set(inputs.views[1:][inputs.view_needed[1:]]["width"].tolist())
        assert widths == {inputs.scene.render.shadow_map}, path.stem


@pytest.mark.parametrize("light_x, depth", [(0.0, 0.2), (2.6, 0.01)])
def test_slats_against_exact_with_faces_of_their_own_sides(renderer, light_x, depth):
    """Slats every 4 cm below a point light, minmax at the sizes 96×64 derives: slats 20 cm
    deep under the light (x = 0: in its −y face alone), and rods 1 cm square off to the side
    (x = 2.6: across the −y and −x faces, both grown). Within 0.5 % relative RMSE of
    `exact`, depth edges out, and within 0.1 % of the image with every face at 4096²."""
    light = PointLight(v3(light_x, 6, 0), np.full(3, 40.0))
    scene = _slats_scene(light, centres_x=tuple(np.arange(-1.0, 1.0, 0.04)), depth=depth, image=(96, 64))
    sides = _sides(scene)
    assert sides[MINUS_Y] == 4096 and min(sides) == 1024
    assert sides[1] == (4096 if light_x else 1024)  # the −x face
    edges = depth_edges(depth_map(scene))
    exact = renderer.render(scene, "exact").image
    image = renderer.render(scene, "minmax").image
    error = image_error(image, exact, edges)
    print(f"slats under x = {light_x}, 96×64, minmax against exact: {error}")
    assert error.rmse < 0.005
    uniform = renderer.render(dataclasses.replace(scene, render=dataclasses.replace(scene.render, shadow_map=4096)),
                              "minmax").image
    assert image_error(image, uniform, edges).rmse < 0.001
