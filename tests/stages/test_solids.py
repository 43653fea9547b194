"""Back faces of closed solids (cl/solids.h): which objects are solids, which points are
inside one, and that a view skips a solid's back faces only from outside, with the images
it would have drawn with every face."""
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from clrays import structs
from clrays.inputs import frame_inputs
from clrays.reference.exact import render_exact
from clrays.physics.geometry import raycast
from clrays.scene.camera import primary_rays
from clrays.scene.geometry import box_triangles, closed_outward, load_mesh, sphere_triangles
from clrays.scene.load import load_scene, parse_scene
from clrays.scene.model import DirectionalLight, Geometry
from conftest import PointLight, grid_plane, make_scene, v3
from test_raster import _rasterized  # (buffers, camera depth, nearest triangle, shadow maps)
from tests.methods.test_surface_shadows import compare, lights, mismatched_pixels, surface_scene

MESHES = Path(__file__).resolve().parents[2] / "scenes" / "meshes"


def _indexed(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a triangle soup, corners joined where equal."""
    vertices, faces = np.unique(triangles.reshape(-1, 3), axis=0, return_inverse=True)
    return vertices, faces.reshape(-1, 3)


def test_boxes_spheres_and_closed_meshes_are_solids_wound_outward():
    assert closed_outward(*_indexed(box_triangles([-1, 0, -1], [1, 2, 3]))) == 1
    assert closed_outward(*_indexed(sphere_triangles([0.5, 1, 0], 0.7, 16))) == 1
    for name in ("cube.ply", "cube.stl", "tetrahedron.obj", "bunny.ply"):  # an STL repeats every corner
        assert load_mesh(MESHES / name)[2] == 1, name


def test_parts_wound_opposite_ways_are_no_solid():
    """A cube with an inverted cube inside it (a hollow, wound as a cavity would not be:
    both outward's opposite) closes every edge, but its parts' volumes have opposite signs."""
    outer, inner = box_triangles([0, 0, 0], [3, 3, 3]), box_triangles([1, 1, 1], [2, 2, 2])
    assert closed_outward(*_indexed(np.concatenate([outer, inner[:, ::-1]]))) == 0
    apart = box_triangles([5, 0, 0], [6, 1, 1])
    assert closed_outward(*_indexed(np.concatenate([outer, apart]))) == 1
    assert closed_outward(*_indexed(np.concatenate([outer, apart])[:, ::-1])) == -1


def test_a_solid_wound_inward_is_minus_one_and_open_or_torn_surfaces_are_none():
    vertices, faces = _indexed(box_triangles([0, 0, 0], [1, 1, 1]))
    assert closed_outward(vertices, faces[:, ::-1]) == -1
    assert closed_outward(vertices, faces[1:]) == 0  # a face missing
    flipped = faces.copy()
    flipped[0] = flipped[0, ::-1]  # one face wound the other way
    assert closed_outward(vertices, flipped) == 0
    assert closed_outward(vertices, np.concatenate([faces, faces])) == 0  # every edge of four faces
    assert closed_outward(*_indexed(grid_plane(0.0, 2.0, 2))) == 0
    flat = vertices * np.array([1.0, 0.0, 1.0])  # the box squashed flat: closed, but no volume
    assert closed_outward(flat, faces) == 0


def test_the_loader_marks_opaque_solids_only():
    scene = parse_scene("""
version: 1
image: {width: 16, height: 9}
camera: {position: [0, 2, 8], look_at: [0, 1, 0]}
lights: [{type: point, position: [0, 5, 0], intensity: 10}]
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 8}
  - {type: box, min: [-1, 0, -1], max: [1, 1, 1]}
  - {type: box, min: [2, 0, -1], max: [3, 1, 1], opacity: 0.5}
  - {type: sphere, center: [-2, 1, 0], radius: 0.5, segments: 8, transform: {scale: [1, 2, 0.5]}}
""")
    outward, ids = scene.geometry.outward, scene.geometry.object_id
    assert [set(outward[ids == i]) for i in range(4)] == [{0}, {1}, {0}, {1}]


def _room(light_inside: bool, eye_inside: bool):
    """A closed box around a smaller box and a sphere, the light and eye in or out of it."""
    triangles = [box_triangles([-4, 0, -4], [4, 5, 4]), box_triangles([-1, 0, -1], [1, 1.5, 1]),
                 sphere_triangles([2.0, 1.0, 1.5], 0.8, 16)]
    count = [len(t) for t in triangles]
    scene = make_scene(np.concatenate(triangles),
                       [PointLight(v3(0.5, 4 if light_inside else 9, 0.3), np.full(3, 30.0))],
                       position=(0, 2, 3.5 if eye_inside else 8), width=48, height=32, shadow_map=64)
    solids = dataclasses.replace(scene.geometry, object_id=np.repeat(np.arange(3), count).astype(np.int32),
                                 outward=np.ones(sum(count), np.int8))
    return dataclasses.replace(scene, geometry=solids)


def _without_solids(scene):
    geometry = scene.geometry
    return dataclasses.replace(scene, geometry=dataclasses.replace(geometry, outward=np.zeros_like(geometry.outward)))


def test_points_in_a_solid_its_surface_and_outside_it():
    geometry = _room(True, True).geometry
    assert geometry.inside_a_solid([0.5, 4, 0.3])  # in the room
    assert geometry.inside_a_solid([0, 0.5, 0])  # in the small box (and the room)
    assert geometry.inside_a_solid([4, 2, 0])  # on the room's wall: cannot tell
    assert not geometry.inside_a_solid([0.5, 9, 0.3])
    assert not geometry.inside_a_solid([4.001, 2, 0])


@pytest.mark.parametrize("light_inside, eye_inside", [(True, True), (True, False), (False, True)])
def test_a_view_from_inside_a_solid_draws_every_face(renderer, device, light_inside, eye_inside):
    """The room's walls face out, so from inside it every wall is a back face: a view from
    there must draw them all, and the image is the one without solids, bit for bit. Where
    the room's walls part the eye from the light, that image is black (inputs.walled_off),
    and the depths of the camera and the light are those without solids, bit for bit."""
    scene = _room(light_inside, eye_inside)
    views = frame_inputs(scene).views
    assert views["cull_back_faces"][0] == (not eye_inside)
    assert (views["cull_back_faces"][1:] == (not light_inside)).all()
    image = renderer.render(scene, reuse=False).image
    if light_inside == eye_inside:
        assert np.array_equal(image, renderer.render(_without_solids(scene), reuse=False).image)
    else:
        assert image.max() == 0.0
        for culled, drawn in zip(_rasterized(device, scene)[1:], _rasterized(device, _without_solids(scene))[1:]):
            assert np.array_equal(culled, drawn)
    if light_inside and eye_inside:
        assert (image.mean(axis=-1) > 0).mean() > 0.9  # lit walls, floor and fog everywhere


def _texel_rays(view, origin):
    """(starts, directions) of a shadow-map view's texel centres, world space."""
    n = int(view["width"])
    centres = (np.arange(n) + 0.5) / n * 2 - 1
    sx, sy = (a.reshape(-1, 1) for a in np.meshgrid(centres, -centres))
    right, up, forward = (view[k][:3].astype(np.float64) for k in ("right", "up", "forward"))
    if view["projection"] == structs.PROJECTION_PERSPECTIVE:
        dirs = forward + sx * view["scale_x"] * right + sy * view["scale_y"] * up
        return np.broadcast_to(origin, dirs.shape), dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    starts = origin + sx * view["scale_x"] * right + sy * view["scale_y"] * up
    return starts, np.broadcast_to(forward, starts.shape)


def _nearest(starts, dirs, triangles):
    return raycast(np.ascontiguousarray(starts), np.ascontiguousarray(dirs), triangles)[0]


def _turned_towards(view, origin, triangles):
    """The triangles a view keeps: those whose normal (b - a) x (c - a) faces its origin,
    or against its rays (orthographic)."""
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    along = (triangles[:, 0] - origin if view["projection"] == structs.PROJECTION_PERSPECTIVE
             else view["forward"][:3].astype(np.float64))
    return triangles[np.einsum("ij,ij->i", normal, np.broadcast_to(along, normal.shape)) <= 0]


@pytest.mark.parametrize("light", ["point", "directional"])
def test_views_from_outside_skip_back_faces_and_keep_every_nearest_hit(device, light):
    """A box and a sphere seen from outside: the camera's depths and nearest triangles, and
    the light's map, are float64 ray casts' through every face. Two open surfaces marked
    as solids' faces show that the views do skip faces: a quad that faces the camera and
    turns away from the light, and a sliver that faces the camera from above and turns away
    from the light; each view's map is the ray cast through the faces it turns towards."""
    lights = {"point": PointLight(v3(0.5, 6, 0.3), np.full(3, 30.0)),
              "directional": DirectionalLight(v3(0.3, -1, 0.2) / np.linalg.norm([0.3, 1, 0.2]), np.full(3, 3.0))}
    scene = _room(False, False)
    quad = np.array([[[-1, 3, 2], [1, 3, 2], [1, 3.5, 2]], [[-1, 3, 2], [1, 3.5, 2], [-1, 3.5, 2]]], float)  # faces +z
    sliver = np.array([[[-3, 2.5, -2], [-2, 2.5, -1], [-3, 2.5, -1]]], float)  # faces -y
    triangles = np.concatenate([scene.geometry.triangles[12:], quad, sliver])  # the room's walls left out
    ids = np.concatenate([scene.geometry.object_id[12:] - 1, [2, 2, 3]]).astype(np.int32)
    geometry = Geometry(triangles, np.full((len(triangles), 3), 0.8), ids, outward=np.ones(len(triangles), np.int8))
    scene = dataclasses.replace(scene, lights=(lights[light],), geometry=geometry,
                                render=dataclasses.replace(scene.render, shadow_map=48))
    buffers, depth, tri, shadow = _rasterized(device, scene)
    assert buffers.inputs.views["cull_back_faces"].all()
    dirs = primary_rays(scene.camera, scene.image).reshape(-1, 3)
    t, index = raycast(scene.camera.position, dirs, triangles)
    hit = np.isfinite(t)
    assert np.isin(index[hit], [len(triangles) - 3, len(triangles) - 2]).sum() > 20  # the quad is in view
    assert np.array_equal(np.isfinite(depth), hit)
    np.testing.assert_allclose(depth[hit], t[hit], rtol=1e-5, atol=1e-5)
    assert (tri[hit] == index[hit]).mean() > 0.98
    anchor = buffers.inputs.light_anchor_ws[0]
    skipped = 0
    for view in buffers.inputs.views[1:]:
        stored = shadow[view["depth_offset"]: view["depth_offset"] + int(view["width"]) ** 2]
        starts, directions = _texel_rays(view, anchor)
        kept = _nearest(starts, directions, _turned_towards(view, anchor, triangles))
        skipped += int((_nearest(starts, directions, triangles) < kept).sum())
        assert np.array_equal(np.isfinite(stored), np.isfinite(kept))
        finite = np.isfinite(kept)
        np.testing.assert_allclose(stored[finite], kept[finite], rtol=1e-4)
    assert skipped > 20  # the quad and the sliver would have been nearest there


@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
def test_exact_surface_shadows_of_solids_match_the_reference(renderer, kind):
    """The bound and writer maps without the boxes' back faces, and shadow rays that test
    only the faces listed there, still put shadow edges where the reference does."""
    scene = surface_scene(lights((0.3, 4.0, -0.5))[kind], shadow_map=64, width=64, height=36)
    plane = len(grid_plane(0.0, 6.0, 4))
    ids = np.concatenate([np.zeros(plane), np.ones(12), np.full(12, 2)]).astype(np.int32)
    outward = np.concatenate([np.zeros(plane), np.ones(24)]).astype(np.int8)
    scene = dataclasses.replace(scene, geometry=dataclasses.replace(scene.geometry, object_id=ids, outward=outward))
    assert frame_inputs(scene).views["cull_back_faces"].all()
    _, _, _, bad_exact, bad_map = compare(renderer, scene, kind)
    assert bad_exact <= 1, f"{kind}: {bad_exact} pixels differ from exact (map: {bad_map})"


GRAZING = """
version: 1
image: {width: 96, height: 54}
camera: {position: [0.3, 1.8, 4.5], look_at: [0, 1.0, -6], fov_deg: 60, far: 40}
lights: [{type: point, position: [-5, 1.2, 6], intensity: 60}]
medium: {sigma_s: 0.0, sigma_a: 0.0}
objects:
  - {type: plane, center: [0, 0, -6], normal: [0, 1, 0], size: 30, segments: 8}
  - {type: box, min: [-1.2, 0, -1.5], max: [-0.6, 2.5, -0.9]}
  - {type: box, min: [1.0, 0, -4.5], max: [1.6, 3.0, -3.9], transform: {rotate: {axis: [0, 1, 0], angle_deg: 30}}}
  - {type: sphere, center: [-1.5, 0.8, -5], radius: 0.8, segments: 24}
  - {type: mesh, file: meshes/tetrahedron.obj, transform: {translate: [0.5, 0, -2], scale: 0.6}}
render: {shadow_map: 256}
"""


def test_planes_boxes_and_spheres_are_one_convex_part_each_meshes_a_part_per_triangle():
    scene = parse_scene(GRAZING, source=Path(__file__).resolve().parents[2] / "scenes" / "grazing.yaml")
    parts, ids = scene.geometry.convex_part, scene.geometry.object_id
    assert [len(set(parts[ids == i])) for i in range(5)] == [1, 1, 1, 1, int((ids == 4).sum())]
    outside_only = [bool(parts[ids == i][0] & structs.CONVEX_OUTSIDE_ONLY) for i in range(5)]
    assert outside_only == [False, True, True, True, False]  # a box's or a sphere's: a solid's
    assert len({int(parts[ids == i][0]) for i in range(4)} | set(parts[ids == 4].tolist())) == 4 + (ids == 4).sum()


def test_every_triangle_of_a_mesh_is_a_part_of_its_own():
    """The bunny's 75 408 triangles follow the floor's 128: each its own label, none
    another object's (a label is the object's first row plus the triangle's index in it)."""
    geometry = load_scene(MESHES.parent / "bunny.yaml").geometry
    bunny = geometry.convex_part[geometry.object_id == 1]
    assert len(np.unique(bunny)) == len(bunny) == 75408
    assert not np.isin(bunny, geometry.convex_part[geometry.object_id == 0]).any()


def test_a_convex_part_lit_at_a_grazing_angle_needs_no_shadow_ray_on_its_seams(renderer):
    """The floor's 128 triangles meet along seams, and the boxes' faces along edges, in
    texels of the writer map that two triangles touch: as one convex part each, the map says
    the sample's own part alone touches them, and no shadow ray is cast there. The images
    are the same as with a part per triangle, and the exact reference's."""
    scene = parse_scene(GRAZING, source=Path(__file__).resolve().parents[2] / "scenes" / "grazing.yaml")
    geometry = scene.geometry
    per_triangle = dataclasses.replace(scene, geometry=dataclasses.replace(
        geometry, convex_part=np.arange(geometry.count, dtype=np.int32)))
    joined, apart = renderer.render(scene, reuse=False), renderer.render(per_triangle, reuse=False)
    print(f"shadow rays: {joined.shadow_rays} with convex parts, {apart.shadow_rays} with a part per triangle")
    assert joined.shadow_rays < 0.5 * apart.shadow_rays
    assert np.array_equal(joined.image, apart.image)
    assert mismatched_pixels(joined.image, render_exact(scene), scene) <= 1


@pytest.mark.parametrize("light", ["{type: directional, direction: [0.3, -1, 0.2], irradiance: 3}",
                                   "{type: point, position: [0.5, 9, 0.3], intensity: 300}"])
@pytest.mark.parametrize("room", ["{type: box, min: [-4, 0, -4], max: [4, 5, 4]}",
                                  "{type: sphere, center: [0, 0, 0], radius: 4.5, segments: 24}"])
def test_inside_a_closed_room_lit_from_outside_every_surface_is_dark(renderer, light, room):
    """Seen from inside a box or a sphere, a floor's face turns towards a light outside,
    beyond the ceiling, which the same convex part is: the writer map's own-part test must
    not call it lit (it holds for the part's outside only)."""
    scene = parse_scene(f"""
version: 1
image: {{width: 32, height: 18}}
camera: {{position: [0, 2, 3], look_at: [0, 0.5, -3], fov_deg: 70, far: 40}}
lights: [{light}]
medium: {{sigma_s: 0.0, sigma_a: 0.0}}
objects:
  - {room}
  - {{type: plane, center: [0, 0.01, 0], normal: [0, 1, 0], size: 6}}
  - {{type: box, min: [-1, 0, -1], max: [1, 1.5, 1]}}
render: {{shadow_map: 64}}
""")
    image = renderer.render(scene, reuse=False).image
    assert float(render_exact(scene).max()) == 0.0
    assert float(image.max()) == 0.0, f"{int((image.max(axis=-1) > 0).sum())} pixels lit in a closed room"
