"""The `animation` block: parsing, interpolation (linear, eased, SLERP, great-circle
directions), the scene of each frame, and one-line errors for bad input."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from clrays.scene.animation import EASINGS, Key, Track, frame_scenes, slerp_direction
from clrays.errors import SceneError
from clrays.scene.load import load_scene, parse_scene
from clrays.scene.transforms import matrix_to_quat, rotation_axis_angle

REPO = Path(__file__).resolve().parents[2]

BASE = """\
version: 1
image: {width: 32, height: 24}
camera: {position: [0, 2, 8], look_at: [0, 1, 0], fov_deg: 50, far: 30}
lights:
  - {type: point, position: [0, 4, 0], intensity: 30}
  - {type: spot, position: [0, 5, 0], direction: [0, -1, 0], cone_deg: 30, intensity: 50}
  - {type: directional, direction: [0, -1, 0], irradiance: 2}
medium: {sigma_s: 0.05, sigma_a: 0.01, phase: {type: hg, g: 0.2}}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 10, segments: 2}
  - {type: box, min: [-1, 0, -1], max: [1, 1, 1], transform: {translate: [0, 1, 0], scale: 0.5}}
"""


def scene(animation: str, base: str = BASE):
    return parse_scene(base + animation)


def test_frames_fps_and_holds():
    s = scene("""animation:
  frames: [2, 12]
  camera:
    - {frame: 4, position: [0, 2, 8]}
    - {frame: 8, position: [4, 2, 8]}
""")
    a = s.animation
    assert a.frames == range(2, 13) and a.fps == 24 and a.time(12) == 0.5
    x = [a.scene_at(s, f).camera.position[0] for f in a.frames]
    np.testing.assert_allclose(x, [0, 0, 0, 1, 2, 3, 4, 4, 4, 4, 4])  # hold before the first key, after the last
    assert a.scene_at(s, 8).animation is None
    assert [f for f, _ in frame_scenes(s)] == list(range(2, 13))


def test_keys_hit_their_values_exactly():
    keys = (Key(0, matrix_to_quat(rotation_axis_angle([0, 1, 0], 0.3))),
            Key(10, matrix_to_quat(rotation_axis_angle([1, 0, 0], 2.0))))
    track = Track("rotation", keys)
    assert np.array_equal(track.at(0), track.keys[0].value) and np.array_equal(track.at(10), track.keys[1].value)


@pytest.mark.parametrize("easing, expected", [
    ("linear", 0.25), ("ease_in", 0.0625), ("ease_out", 0.4375), ("ease_in_out", 0.15625), ("step", 0.0),
])
def test_easing_reshapes_the_way_between_keys(easing, expected):
    s = scene(f"""animation:
  frames: [0, 8]
  easing: {easing}
  medium:
    - {{frame: 0, sigma_s: 0.0}}
    - {{frame: 8, sigma_s: 1.0}}
""")
    assert s.animation.scene_at(s, 2).medium.sigma_s[0] == pytest.approx(expected)
    assert EASINGS[easing](1.0) == (0.0 if easing == "step" else 1.0)


def test_a_key_easing_applies_to_its_own_segment():
    s = scene("""animation:
  frames: [0, 20]
  medium:
    - {frame: 0, sigma_s: 0.0, easing: step}
    - {frame: 10, sigma_s: 1.0}
    - {frame: 20, sigma_s: 2.0}
""")
    values = [s.animation.scene_at(s, f).medium.sigma_s[0] for f in (5, 10, 15)]
    assert values == pytest.approx([0.0, 1.0, 1.5])


def test_object_rotation_is_slerp_with_constant_speed():
    s = scene("""animation:
  frames: [0, 4]
  objects:
    - object: 1
      keys:
        - {frame: 0, rotate: {axis: [0, 1, 0], angle_deg: 0}}
        - {frame: 4, rotate: {axis: [0, 1, 0], angle_deg: 120}}
""")
    box = s.geometry.object_id == 1
    local = s.animation.objects[1][0].local
    for frame in range(5):
        tris = s.animation.scene_at(s, frame).geometry.triangles
        # translate and scale come from the static transform; the rotation turns 30° a frame
        expected = (local * 0.5) @ rotation_axis_angle([0, 1, 0], math.radians(30 * frame)).T + [0, 1, 0]
        np.testing.assert_allclose(tris[box], expected, atol=1e-12)
        np.testing.assert_array_equal(tris[~box], s.geometry.triangles[~box])  # the plane does not move
    np.testing.assert_allclose(s.animation.scene_at(s, 0).geometry.triangles, s.geometry.triangles, atol=1e-12)


def test_camera_orientation_keys_point_the_camera():
    q0 = matrix_to_quat(rotation_axis_angle([0, 1, 0], 0.0))
    q1 = matrix_to_quat(rotation_axis_angle([0, 1, 0], math.pi / 2))
    s = scene(f"""animation:
  frames: [0, 2]
  camera:
    - {{frame: 0, orientation: {q0.tolist()}, position: [0, 1, 5]}}
    - {{frame: 2, orientation: {q1.tolist()}}}
""")
    for frame, angle in [(0, 0.0), (1, math.pi / 4), (2, math.pi / 2)]:
        camera = s.animation.scene_at(s, frame).camera
        forward = camera.look_at - camera.position
        np.testing.assert_allclose(forward, rotation_axis_angle([0, 1, 0], angle) @ [0, 0, -1], atol=1e-12)
        np.testing.assert_allclose(camera.up, [0, 1, 0], atol=1e-12)
        np.testing.assert_array_equal(camera.position, [0, 1, 5])


def test_light_tracks_by_type():
    s = scene("""animation:
  frames: [0, 2]
  lights:
    - light: 0
      keys:
        - {frame: 0, position: [0, 4, 0], intensity: [30, 30, 30]}
        - {frame: 2, position: [2, 4, 0], intensity: [10, 20, 30]}
    - light: 1
      keys:
        - {frame: 0, direction: [0, -1, 0], cone_deg: 30}
        - {frame: 2, direction: [1, 0, 0], cone_deg: 50}
    - light: 2
      keys:
        - {frame: 0, irradiance: 2}
        - {frame: 2, irradiance: 4}
""")
    mid = s.animation.scene_at(s, 1)
    np.testing.assert_allclose(mid.lights[0].position, [1, 4, 0])
    np.testing.assert_allclose(mid.lights[0].intensity, [20, 25, 30])
    np.testing.assert_allclose(mid.lights[1].direction, [math.sqrt(0.5), -math.sqrt(0.5), 0])  # great circle
    assert mid.lights[1].cone_deg == pytest.approx(40)
    np.testing.assert_allclose(mid.lights[2].irradiance, 3)
    assert mid.lights[2].direction is s.lights[2].direction


def test_medium_g_and_absorption():
    s = scene("""animation:
  frames: [0, 1]
  medium:
    - {frame: 0, g: -0.5, sigma_a: 0}
    - {frame: 1, g: 0.5, sigma_a: [0, 0.1, 0.2]}
""")
    m = s.animation.scene_at(s, 0.5).medium
    assert m.phase.type == "hg" and m.phase.g == pytest.approx(0) and m.sigma_a == pytest.approx([0, 0.05, 0.1])


def test_slerp_direction_is_unit_and_even():
    a, b = np.array([1.0, 0, 0]), np.array([0, 0, 1.0])
    for t in np.linspace(0, 1, 7):
        v = slerp_direction(a, b, t)
        assert np.linalg.norm(v) == pytest.approx(1)
        assert math.acos(np.clip(v @ a, -1, 1)) == pytest.approx(t * math.pi / 2)


def test_overrides_reach_the_animation():
    s = parse_scene(BASE + "animation: {frames: [0, 9]}\n", overrides=["animation.frames=[3,4]", "animation.fps=12"])
    assert s.animation.frames == range(3, 5) and s.animation.fps == 12


def test_scene_without_animation():
    s = parse_scene(BASE)
    assert s.animation is None and [f for f, _ in frame_scenes(s)] == [0]


def test_example_scene_loads():
    s = load_scene(REPO / "scenes" / "orbit.yaml")
    assert s.animation.frames == range(0, 60) and s.animation.fps == 24
    first, last = s.animation.scene_at(s, 0), s.animation.scene_at(s, 59)
    assert not np.array_equal(first.camera.position, last.camera.position)
    assert first.lights[0].position is last.lights[0].position  # the light does not move


@pytest.mark.parametrize("animation, message", [
    ("animation: {fps: 24}", r"animation: missing required key 'frames'"),
    ("animation: {frames: [5, 2]}", r"animation\.frames\.1: expected a last frame >= the first, 5, got 2"),
    ("animation: {frames: [0.5, 2]}", r"animation\.frames\.0: expected an integer in \[0, 100000\], got 0\.5"),
    ("animation: {frames: 3}", r"animation\.frames: expected \[first, last\]"),
    ("animation: {frames: [0, 2], fps: 0}", r"animation\.fps: expected a number in \(0, 1000\]"),
    ("animation: {frames: [0, 2], easing: bounce}", r"animation\.easing: expected one of 'linear'"),
    ("animation: {frames: [0, 2], camera: [{frame: 0}]}",
     r"animation\.camera\.0: expected a key that sets at least one of position, look_at"),
    ("animation: {frames: [0, 2], camera: [{frame: 2, fov_deg: 40}, {frame: 1, fov_deg: 50}]}",
     r"animation\.camera\.1\.frame: expected a frame after 2 \(keys in increasing frame order\), got 1"),
    ("animation: {frames: [0, 2], camera: [{frame: 0, fov_deg: 190}]}",
     r"animation\.camera\.0\.fov_deg: expected a number in \(0, 180\), got 190"),
    ("animation: {frames: [0, 2], camera: [{frame: 0, orientation: [1, 0, 0, 0], look_at: [0, 0, 0]}]}",
     r"animation\.camera\.0\.look_at: expected no look_at or up keys beside orientation keys"),
    ("animation: {frames: [0, 2], camera: [{frame: 0, orientation: [2, 0, 0, 0]}]}",
     r"animation\.camera\.0\.orientation: expected a unit quaternion"),
    ("animation: {frames: [0, 4], camera: [{frame: 0, position: [0, 2, 8]}, {frame: 4, position: [0, 0, -8]}]}",
     r"animation\.camera: expected look_at away from position at every frame, got look_at = position at frame 2"),
    ("animation: {frames: [0, 2], lights: [{light: 3, keys: [{frame: 0, intensity: 1}]}]}",
     r"animation\.lights\.0\.light: expected an integer in \[0, 2\], got 3"),
    ("animation: {frames: [0, 2], lights: [{light: 2, keys: [{frame: 0, position: [0, 1, 0]}]}]}",
     r"animation\.lights\.0\.keys\.0\.position: unknown key; expected one of: frame, easing, direction, irradiance"),
    ("animation: {frames: [0, 2], lights: [{light: 0, keys: [{frame: 0, intensity: -1}]}]}",
     r"animation\.lights\.0\.keys\.0\.intensity: expected .*>= 0, got -1"),
    ("animation: {frames: [0, 2], lights: [{light: 0, keys: [{frame: 0, intensity: 1}]}, "
     "{light: 0, keys: [{frame: 1, intensity: 2}]}]}",
     r"animation\.lights\.1\.light: expected each light animated once \(merge its keys into one entry\), got 0 again"),
    ("animation: {frames: [0, 2], lights: [{light: 1, keys: [{frame: 0, direction: [0, 1, 0]}, "
     "{frame: 1, direction: [0, -1, 0]}]}]}",
     r"animation\.lights\.0\.keys\.1\.direction: expected a direction not opposite to the previous key's"),
    ("animation: {frames: [0, 2], objects: [{object: 2, keys: [{frame: 0, scale: 2}]}]}",
     r"animation\.objects\.0\.object: expected an integer in \[0, 1\], got 2"),
    ("animation: {frames: [0, 2], objects: [{object: 1, keys: [{frame: 0, scale: 0}]}]}",
     r"animation\.objects\.0\.keys\.0\.scale: expected a number > 0, got 0"),
    ("animation: {frames: [0, 2], objects: [{object: 1, keys: [{frame: 0, rotate: {axis: [0, 1, 0]}}]}]}",
     r"animation\.objects\.0\.keys\.0\.rotate: missing required key 'angle_deg'"),
    ("animation: {frames: [0, 2], medium: [{frame: 0, sigma_z: 1}]}",
     r"animation\.medium\.0\.sigma_z: unknown key \(did you mean 'sigma_s'\?\)"),
    ("animation: {frames: [0, 2], cameras: []}", r"animation\.cameras: unknown key \(did you mean 'camera'\?\)"),
])
def test_errors_are_one_line_with_location(animation, message):
    with pytest.raises(SceneError, match=r"^<string>:\d+:\d+: " + message) as info:
        scene(animation + "\n")
    assert "\n" not in str(info.value)


def test_g_needs_an_hg_medium():
    base = BASE.replace("phase: {type: hg, g: 0.2}", "phase: {type: isotropic}")
    with pytest.raises(SceneError, match=r"animation\.medium\.0\.g: expected a medium with phase \{type: hg"):
        scene("animation: {frames: [0, 1], medium: [{frame: 0, g: 0.5}]}\n", base)


def test_error_from_an_override_names_it():
    with pytest.raises(SceneError, match=r"^override animation.frames=\[3,1\]: animation\.frames\.1: expected"):
        parse_scene(BASE + "animation: {frames: [0, 9]}\n", overrides=["animation.frames=[3,1]"])


def test_the_documented_example_loads():
    text = (REPO / "docs" / "scene-format.md").read_text()
    example = text.split("## animation", 1)[1].split("```yaml\n", 1)[1].split("```", 1)[0]
    s = scene(example)
    assert s.animation.frames == range(0, 48) and set(s.animation.camera) == {"position", "fov_deg"}
    last = s.animation.scene_at(s, 47)
    assert last.medium.phase.g == pytest.approx(0.2) and last.camera.fov_deg == 40


@pytest.mark.parametrize("kind", ["linear", "direction"])
def test_track_at_frames_equals_at(kind):
    """The vectorised track (the loader's check of every frame's camera) gives the values
    of `Track.at`, frame by frame, for every easing, before, between and after the keys."""
    rng = np.random.default_rng(7)
    frames = [-3.0, 0.0, 2.5, 7.0, 8.0, 15.0]
    values = rng.normal(size=(len(frames), 3))
    if kind == "direction":
        values /= np.linalg.norm(values, axis=1, keepdims=True)
    easings = list(EASINGS) + ["linear"]
    track = Track(kind, tuple(Key(f, v, easings[i % len(easings)]) for i, (f, v) in enumerate(zip(frames, values))))
    queries = np.linspace(-6, 18, 97)
    expected = np.array([track.at(f) for f in queries])
    np.testing.assert_allclose(track.at_frames(queries), expected, rtol=0, atol=1e-12)
    scalar = Track("linear", tuple(Key(f, float(v[0]), "ease_in_out") for f, v in zip(frames, values)))
    np.testing.assert_allclose(scalar.at_frames(queries), [scalar.at(f) for f in queries], rtol=0, atol=1e-12)


def test_every_frame_of_a_long_camera_path_is_checked_quickly():
    """The format allows 100 001 frames; each one's camera is checked, all at once."""
    import time

    text = ("version: 1\nimage: {width: 8, height: 8}\ncamera: {position: [0, 2, 20], look_at: [0, 0, 0]}\n"
            "lights: [{type: point, position: [0, 8, 0], intensity: 1}]\n"
            "animation: {frames: [0, 100000], camera: [{frame: 0, position: [0, 0, 5]}, "
            "{frame: 100000, position: [0, 0, -5]}]}\n")
    start = time.perf_counter()
    with pytest.raises(SceneError, match=r"expected look_at away from position at every frame, "
                                         r"got look_at = position at frame 50000$"):
        parse_scene(text)
    assert time.perf_counter() - start < 2.0
