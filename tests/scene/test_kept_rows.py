"""What a geometry keeps for the frames after it (Geometry.kept; clrays.inputs.face_rows and
the light-anchored vertices): the same rows as computed afresh, read-only, and a bounded
number of anchored sets when a light moves every frame."""
from dataclasses import replace

import numpy as np
import pytest

from clrays.inputs import ANCHORED_KEPT, frame_inputs, light_pass_inputs
from clrays.scene.geometry import box_triangles, sphere_triangles
from conftest import PointLight, grid_plane, make_scene, v3


def _scene(light_position=(0.5, 5.0, 0.3)):
    triangles = np.concatenate([grid_plane(0.0, 6.0, 3), box_triangles([-1, 0, -1], [1, 2, 1]),
                                sphere_triangles([2.0, 1.0, 1.5], 0.8, 12)])
    return make_scene(triangles, [PointLight(v3(*light_position), np.full(3, 30.0))], width=32, height=24)


def _fresh_face_normals(scene, eye):
    tris = scene.geometry.triangles - eye
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, length, out=np.zeros_like(normals), where=length > 0).astype(np.float32)


def test_the_face_rows_are_kept_read_only_and_match_eye_space():
    scene = _scene()
    first, second = frame_inputs(scene), frame_inputs(scene)
    assert first.tri_normal is second.tri_normal and first.tri_albedo is second.tri_albedo
    for rows in (first.tri_normal, first.tri_albedo, first.tri_vertex_normals):
        assert not rows.flags.writeable
        with pytest.raises(ValueError):
            rows[0, 0] = 1.0
    # computed around the world origin, they are the normals of the triangles around the eye
    np.testing.assert_array_equal(first.tri_normal[:, :3], _fresh_face_normals(scene, first.eye_ws))
    np.testing.assert_array_equal(first.tri_albedo[:, :3], scene.geometry.albedo.astype(np.float32))


def test_a_moving_camera_keeps_the_same_face_rows():
    scene = _scene()
    moved = replace(scene, camera=replace(scene.camera, position=scene.camera.position + 3.0))
    assert frame_inputs(scene).tri_normal is frame_inputs(moved).tri_normal
    assert not np.array_equal(frame_inputs(scene).tri_vertices, frame_inputs(moved).tri_vertices)


def test_anchored_vertices_are_the_triangles_around_the_light():
    scene = _scene()
    inputs = frame_inputs(scene)
    anchored = light_pass_inputs(inputs, 0).tri_vertices
    expected = (scene.geometry.triangles - scene.lights[0].position).reshape(-1, 3).astype(np.float32)
    np.testing.assert_array_equal(anchored[:, :3], expected)
    assert light_pass_inputs(frame_inputs(scene), 0).tri_vertices is anchored  # a static light's, kept


def test_a_light_that_moves_every_frame_keeps_a_bounded_number():
    scene = _scene()
    for step in range(3 * ANCHORED_KEPT):
        moved = replace(scene, lights=(replace(scene.lights[0], position=scene.lights[0].position + 0.1 * step),))
        light_pass_inputs(frame_inputs(moved), 0)
    kept = [key for key in scene.geometry._memo() if isinstance(key, tuple) and key[0] == "anchored"]
    assert len(kept) == ANCHORED_KEPT
