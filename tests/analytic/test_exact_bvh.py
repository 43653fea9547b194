"""`exact` on the BVH (clrays.reference.bvh_queries) against `exact` testing every
triangle (`bvh=False`): the same images up to float64 rounding, for every light type, a
smooth mesh, a random triangle soup, a scene far from the origin, and each query alone."""
from __future__ import annotations

import numpy as np
import pytest

from clrays.physics import geometry, radiometry
from clrays.reference.bvh_queries import SceneBvh
from clrays.reference.exact import render_exact
from clrays.scene.camera import primary_rays
from clrays.scene.load import load_scene
from clrays.scene.model import (Camera, DirectionalLight, Geometry, Image, Medium, Phase, PointLight, Render, Scene,
                                SpotLight)

# The two paths run the same float64 arithmetic on the same triangles (the BVH only leaves
# out those that cannot matter), so they agree to rounding.
RTOL = 1e-12


def soup_scene(light, count=3000, seed=11, offset=(0.0, 0.0, 0.0), width=24, height=16) -> Scene:
    """Random small triangles in a box over a floor: many overlapping shadows per ray."""
    rng = np.random.default_rng(seed)
    center = rng.uniform([-2, 0.5, -2], [2, 3.5, 2], (count, 1, 3))
    tri = center + rng.normal(0, 0.15, (count, 3, 3))
    floor = np.array([[[-6, 0, -6], [6, 0, -6], [6, 0, 6]], [[-6, 0, -6], [6, 0, 6], [-6, 0, 6]]], float)
    tri = np.concatenate([tri, floor]) + np.asarray(offset)
    v = lambda *x: np.asarray(x, float) + np.asarray(offset)  # noqa: E731
    light = {"point": PointLight(v(0.5, 6.0, 0.3), np.array([60.0, 50, 40])),
             "spot": SpotLight(v(0.5, 6.0, 0.3), np.array([0.1, -1.0, 0.05]) / np.linalg.norm([0.1, -1.0, 0.05]),
                               35.0, np.array([60.0, 50, 40])),
             "directional": DirectionalLight(np.array([-0.4, -1.0, 0.3]) / np.linalg.norm([-0.4, -1.0, 0.3]),
                                             np.array([2.0, 1.8, 1.6]))}[light]
    return Scene(image=Image(width, height, 1),
                 camera=Camera(v(0.3, 2.2, 8.0), v(0, 1.8, 0), np.array([0.0, 1, 0]), 55.0, 30.0),
                 lights=(light,),
                 medium=Medium(np.array([0.05, 0.08, 0.1]), np.array([0.01, 0.0, 0.02]), Phase("hg", 0.3)),
                 background=np.array([0.1, 0.1, 0.2]),
                 geometry=Geometry(tri, np.full((len(tri), 3), 0.7), np.zeros(len(tri), np.int32)),
                 render=Render(method="exact"))


def assert_same_image(scene: Scene) -> None:
    fast, slow = render_exact(scene), render_exact(scene, bvh=False)
    np.testing.assert_allclose(fast, slow, rtol=RTOL, atol=RTOL * np.abs(slow).max())


@pytest.mark.parametrize("light", ["point", "spot", "directional"])
def test_a_triangle_soup_renders_the_same_on_the_bvh(light):
    assert_same_image(soup_scene(light))


def test_far_from_the_origin_renders_the_same_on_the_bvh():
    assert_same_image(soup_scene("point", count=800, offset=(1e4, -1e4, 1e4)))


@pytest.mark.parametrize("name", ["demo", "sun", "behind", "bunny"])
def test_the_bench_scenes_render_the_same_on_the_bvh(name):
    """The bench scenes at 16×9 (the bunny: smooth normals, a spot light; sun: directional)."""
    assert_same_image(load_scene(f"scenes/{name}.yaml", overrides=["image.width=16", "image.height=9"]))


def test_each_query_gives_the_all_triangles_answer():
    """First hits (t and index), shadow rays and lit intervals, query by query."""
    scene = soup_scene("point", count=2000, width=40, height=30)
    tri = scene.geometry.triangles
    queries = SceneBvh.build(tri)
    eye = scene.camera.position
    dirs = primary_rays(scene.camera, scene.image, np.zeros((1, 2)) + 0.5)[:, :, 0].reshape(-1, 3)
    t_fast, i_fast = queries.raycast(eye, dirs, t_max=30.0)
    t_slow, i_slow = geometry.raycast(eye, dirs, tri, t_max=30.0)
    np.testing.assert_array_equal(i_fast, i_slow)
    np.testing.assert_allclose(t_fast, t_slow, rtol=RTOL)
    assert (i_slow >= 0).sum() > 0.5 * len(dirs)  # the test sees geometry
    light = scene.lights[0]
    hit = i_slow >= 0
    points = eye + t_slow[hit, None] * dirs[hit]
    normals = geometry.triangle_normals(tri[i_slow[hit]])
    blocked = geometry.occluded(points, light, tri, normals=normals)
    np.testing.assert_array_equal(queries.occluded(points, light, normals=normals), blocked)
    assert 0.1 < blocked.mean() < 0.9
    D = np.where(hit, t_slow, 30.0)
    halfspaces = geometry.shadow_halfspaces(light, tri)
    radius = radiometry.lamp_radius(scene)
    fast = queries.lit_intervals(eye, dirs, D, light, halfspaces, lamp_radius=radius)
    slow = geometry.lit_intervals(eye, dirs, D, light, tri, halfspaces=halfspaces, lamp_radius=radius)
    # Intervals of a few ulps (where a shadow ends on the surface the ray hits) come and
    # go with the rounding of the clip; they carry no light.
    fast, slow = ([x[keep] for x in found] for found in (fast, slow)
                  for keep in [found[2] - found[1] > 1e-12 * np.abs(found[2])])
    np.testing.assert_array_equal(fast[0], slow[0])
    np.testing.assert_allclose(fast[1], slow[1], rtol=RTOL)
    np.testing.assert_allclose(fast[2], slow[2], rtol=RTOL)
    assert len(slow[0]) > 2 * len(dirs)  # rays cross several shadows


def test_the_bvh_lists_a_small_part_of_the_triangles():
    """What makes `exact` scale: a camera ray's shadow polygon meets a few percent of a
    3000-triangle soup, not all of it."""
    scene = soup_scene("point")
    queries = SceneBvh.build(scene.geometry.triangles)
    dirs = primary_rays(scene.camera, scene.image, np.zeros((1, 2)) + 0.5)[:, :, 0].reshape(-1, 3)
    lo, hi = np.zeros(len(dirs)), np.full(len(dirs), 30.0)
    polygons = queries._shadow_polygons(scene.lights[0], np.broadcast_to(scene.camera.position, dirs.shape),
                                        dirs, lo, hi)
    ray, _ = queries._polygon_candidates(polygons)
    assert len(ray) / len(dirs) < 0.25 * len(scene.geometry.triangles)
