"""Cube faces the camera cannot see are not rasterized (clrays.physics.cube_faces), and
that never changes an image: each frame is compared with one that rasterizes all six."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import clrays.session
from clrays.inputs import frame_inputs
from clrays.session import Renderer
from clrays.physics.cube_faces import sampled_cube_faces

from conftest import PointLight, box_triangles, grid_plane, make_scene, v3


def _slats():
    return np.concatenate([grid_plane(0.0, 6.0, 2)] + [box_triangles(v3(x, 2.5, -3), v3(x + 0.4, 2.7, 3))
                                                        for x in (-2.0, -1.0, 0.0, 1.0)]
                          + [box_triangles(v3(-3.0, 0.0, 6.0), v3(3.0, 3.0, 6.5))])


#: name → light position; the camera sits at (0, 2, 8) looking at (0, 1, 0).
LIGHTS = {
    "in_view": v3(0.3, 4.0, -0.5),
    "behind_camera": v3(0.5, 3.5, 12.0),
    "above_out_of_view": v3(0.0, 14.0, 9.0),
}


def _scene(where, **render):
    return make_scene(_slats(), [PointLight(LIGHTS[where], np.full(3, 60.0))], width=40, height=30, far=20.0,
                      sigma_s=0.08, sigma_a=0.02, shadow_map=128, slices=64, gamma_samples=128, pcf=1, **render)


@pytest.mark.parametrize("where", LIGHTS)
@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_culling_faces_never_changes_the_image(device, monkeypatch, where, method):
    scene = _scene(where, steps=64)
    needed = frame_inputs(scene).view_needed[1:]
    if where != "in_view":
        assert not needed.all(), "the test means to cull some face"
    culled = Renderer(device, reuse=False).render(scene, method).image
    uncut = []

    def every_face(scene):  # every cube face rastered, also those the frame cannot read
        inputs = frame_inputs(scene)
        uncut.append(replace(inputs, view_needed=np.ones_like(inputs.view_needed)))
        return uncut[-1]

    monkeypatch.setattr(clrays.session, "frame_inputs", every_face)
    np.testing.assert_array_equal(culled, Renderer(device, reuse=False).render(scene, method).image)
    assert uncut, "the frame took its inputs elsewhere"


def test_a_light_inside_the_view_keeps_every_face():
    scene = _scene("in_view")
    assert sampled_cube_faces(scene, scene.lights[0].position, 64) == (True,) * 6


def test_a_light_behind_the_camera_keeps_the_faces_towards_the_view():
    scene = _scene("behind_camera")
    faces = sampled_cube_faces(scene, scene.lights[0].position, 1024)
    assert faces[5] and not faces[4]  # -z (towards the scene) kept, +z (away from it) culled


def test_a_moving_camera_recomputes_the_map_when_the_faces_change(device):
    # The faces are part of the shadow map's key: reuse must not hand a map culled for one
    # view to a view that needs another face.
    from dataclasses import replace

    scene = _scene("behind_camera")
    turned = replace(scene, camera=replace(scene.camera, look_at=v3(0.0, 2.0, 20.0)))  # towards the light
    assert not np.array_equal(frame_inputs(scene).view_needed, frame_inputs(turned).view_needed)
    session, fresh = Renderer(device), Renderer(device, reuse=False)
    session.render(scene)
    np.testing.assert_array_equal(session.render(turned).image, fresh.render(turned).image)
