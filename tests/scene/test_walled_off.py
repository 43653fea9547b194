"""Lights that a closed opaque solid keeps from everything the eye sees are dark, exactly
(clrays.inputs.walled_off); only a clear inside and outside decide it."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from clrays.inputs import walled_off, without_walled_off_light
from clrays.scene.geometry import box_triangles, sphere_triangles
from clrays.scene.load import load_scene
from conftest import DirectionalLight, PointLight, grid_plane, make_scene, v3, with_closed_solid

SCENES = Path(__file__).resolve().parents[2] / "scenes"
EYE = np.array([0.0, 2.0, 3.0])


def _scene(solid, light, eye=EYE, closed=True):
    floor = grid_plane(0.0, 6.0, 2)
    scene = make_scene(np.concatenate([floor, solid]), [light], position=tuple(eye))
    return with_closed_solid(scene, slice(len(floor), None)) if closed else scene


def _walled(scene) -> bool:
    eye_windings = scene.geometry.solid_windings(scene.camera.position)
    return walled_off(scene.geometry, eye_windings, scene.lights[0])


def test_a_closed_box_between_the_eye_and_the_light():
    box = box_triangles(EYE - 0.5, EYE + 0.5)
    point, sun = PointLight(v3(0, 4, 0), np.full(3, 30.0)), DirectionalLight(v3(0.2, -1, 0.1), np.full(3, 2.0))
    assert _walled(_scene(box, point)) and _walled(_scene(box, sun))
    dark = without_walled_off_light(_scene(box, point))
    assert np.all(dark.lights[0].intensity == 0) and np.array_equal(dark.lights[0].position, point.position)
    # the light in the box with the eye, or an open soup of the same triangles: nothing decided
    assert not _walled(_scene(box, PointLight(v3(*(EYE + 0.2)), np.full(3, 30.0))))
    assert not _walled(_scene(box, point, closed=False))
    assert without_walled_off_light(_scene(box, point, closed=False)).lights[0] is point


def test_a_light_in_a_closed_sphere_and_the_eye_outside():
    sphere = sphere_triangles((0.0, 4.0, 0.0), 0.4, 16)
    assert _walled(_scene(sphere, PointLight(v3(0, 4, 0), np.full(3, 30.0))))
    assert not _walled(_scene(sphere, PointLight(v3(0, 4.6, 0), np.full(3, 30.0))))


def test_an_eye_on_a_wall_decides_nothing():
    """On the surface the winding number is 1/2: neither clearly inside nor outside."""
    box = box_triangles(EYE - [0.5, 0.5, 1.0], EYE + [0.5, 0.5, 0.0])  # the eye on its +z face
    scene = _scene(box, PointLight(v3(0, 4, 0), np.full(3, 30.0)))
    assert abs(abs(scene.geometry.solid_windings(EYE)[0]) - 0.5) < 1e-9
    assert not _walled(scene)


def test_rooms_with_a_window_keep_their_light():
    """The bench's rooms are walls of separate boxes, open at a window: no light is walled off."""
    for name in ("sun", "room", "lattice", "demo", "behind", "bunny"):
        scene = load_scene(SCENES / f"{name}.yaml")
        assert without_walled_off_light(scene) is scene, name
