"""The YAML scene loader: values, defaults, broadcasting, tessellation, transforms,
`--set` overrides and every kind of invalid input (one-line SceneError messages)."""
from __future__ import annotations

import copy
import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from clrays.errors import SceneError
from clrays.scene.geometry import box_triangles, plane_triangles, sphere_triangles
from clrays.scene.model import DirectionalLight, PointLight, Render, SpotLight
from clrays.scene.load import load_scene, parse_scene
from clrays.scene.transforms import rotation_axis_angle

REPO = Path(__file__).resolve().parents[2]
MESHES = REPO / "scenes" / "meshes"
ANCHOR = REPO / "scenes" / "test.yaml"  # mesh paths resolve against scenes/ (file need not exist)

FULL = """\
version: 1
image: {width: 640, height: 360, spp: 4}
camera: {position: [0, 2, 8], look_at: [0, 1, 0], up: [0, 2, 0], fov_deg: 45, far: 500}
lights:
  - {type: point, position: [0, 5, 0], intensity: [30, 20, 10]}
  - {type: spot, position: [0, 5, 0], direction: [0, -2, 0], cone_deg: 30, intensity: 50}
  - {type: directional, direction: [3, -4, 0], irradiance: [2, 2, 2]}
medium: {sigma_s: [0.05, 0.04, 0.03], sigma_a: 0.01, phase: {type: hg, g: 0.3}}
background: 0.25
objects:
  - {type: triangles, vertices: [[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces: [[0, 1, 2]], albedo: 0.5}
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 20, albedo: [0.6, 0.6, 0.5]}
  - {type: box, min: [-1, 0, -1], max: [1, 2, 1]}
  - {type: sphere, center: [0, 1, 0], radius: 1}
  - type: mesh
    file: meshes/tetrahedron.obj
    transform: {translate: [1, 2, 3], rotate: {axis: [0, 1, 0], angle_deg: 90}, scale: 2}
render: {method: minmax, steps: 128, shadow_map: 512, jitter: true, pcf: 2, slices: 256,
         gamma_samples: 64, integrand: svd, svd_rank: 8, traversal: scan}
"""

MINIMAL = {
    "version": 1,
    "image": {"width": 64, "height": 32},
    "camera": {"position": [0, 2, 8], "look_at": [0, 1, 0]},
    "lights": [{"type": "point", "position": [0, 5, 0], "intensity": 10}],
}


def scene_text(changes: dict | None = None, base: dict = MINIMAL) -> str:
    """YAML for `base` with `changes` applied: {"camera.fov_deg": 0, "image.spp": DELETE, ...}.
    Keys are dotted paths (list indices allowed); DELETE removes the key."""
    tree = copy.deepcopy(base)
    for path, value in (changes or {}).items():
        *parents, last = path.split(".")
        node = tree
        for p in parents:
            node = node[int(p)] if isinstance(node, list) else node.setdefault(p, {})
        if isinstance(node, list):
            node[int(last)] = value
        elif value is DELETE:
            del node[last]
        else:
            node[last] = value
    return yaml.safe_dump(tree, sort_keys=False, default_flow_style=None)


DELETE = object()


def with_object(obj: dict, **top) -> dict:
    return {**MINIMAL, "objects": [obj], **top}


def load_text(text: str, overrides=()):
    return parse_scene(text, ANCHOR, overrides)


def tri_of(scene, object_index: int) -> np.ndarray:
    return scene.geometry.triangles[scene.geometry.object_id == object_index]


# --------------------------------------------------------------------------- valid scenes


def test_full_scene_values():
    s = load_text(FULL)
    assert (s.image.width, s.image.height, s.image.spp) == (640, 360, 4)
    np.testing.assert_array_equal(s.camera.position, [0, 2, 8])
    np.testing.assert_array_equal(s.camera.look_at, [0, 1, 0])
    np.testing.assert_allclose(s.camera.up, [0, 1, 0])  # normalised
    assert (s.camera.fov_deg, s.camera.far) == (45.0, 500.0)

    point, spot, sun = s.lights
    assert isinstance(point, PointLight) and isinstance(spot, SpotLight)
    assert isinstance(sun, DirectionalLight)
    np.testing.assert_array_equal(point.intensity, [30, 20, 10])
    np.testing.assert_array_equal(spot.intensity, [50, 50, 50])  # scalar broadcast
    np.testing.assert_allclose(spot.direction, [0, -1, 0])  # normalised
    assert spot.cone_deg == 30.0
    np.testing.assert_allclose(sun.direction, [0.6, -0.8, 0])
    np.testing.assert_array_equal(sun.irradiance, [2, 2, 2])

    np.testing.assert_array_equal(s.medium.sigma_s, [0.05, 0.04, 0.03])
    np.testing.assert_array_equal(s.medium.sigma_a, [0.01, 0.01, 0.01])
    np.testing.assert_allclose(s.medium.sigma_t, [0.06, 0.05, 0.04])
    assert (s.medium.phase.type, s.medium.phase.g) == ("hg", 0.3)
    np.testing.assert_array_equal(s.background, [0.25, 0.25, 0.25])

    # pcf alone (the key before surface_shadows) implies surface_shadows: pcf
    assert s.render == Render(method="minmax", steps=128, jitter=True, shadow_map=512, surface_shadows="pcf", pcf=2,
                              slices=256, gamma_samples=64, integrand="svd", svd_rank=8,
                              traversal="scan")
    assert s.source == ANCHOR


def test_full_scene_geometry():
    g = load_text(FULL).geometry
    counts = np.bincount(g.object_id)
    assert list(counts) == [1, 8 * 8 * 2, 12, 2 * 48 * 23, 4]
    assert g.triangles.shape == (g.count, 3, 3) and g.triangles.dtype == np.float64
    assert g.albedo.shape == (g.count, 3) and g.object_id.dtype == np.int32
    np.testing.assert_array_equal(g.albedo[g.object_id == 0], 0.5)
    np.testing.assert_array_equal(g.albedo[g.object_id == 1], [[0.6, 0.6, 0.5]] * 128)
    np.testing.assert_array_equal(g.albedo[g.object_id == 2], 0.8)  # default
    np.testing.assert_array_equal(g.triangles[0], [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    assert g.opacity is None and not g.translucent  # every object opaque: the opaque-only path


def test_opacity_per_object_and_channel():
    tree = yaml.safe_load(FULL)
    tree["objects"][1]["opacity"] = [0.2, 0.9, 0.9]
    tree["objects"][3]["opacity"] = 0.5
    g = load_text(yaml.safe_dump(tree)).geometry
    assert g.translucent and g.opacity.shape == (g.count, 3)
    np.testing.assert_array_equal(g.opacity[g.object_id == 1], [[0.2, 0.9, 0.9]] * 128)
    np.testing.assert_array_equal(g.opacity[g.object_id == 3], 0.5)
    np.testing.assert_array_equal(g.opacity[(g.object_id != 1) & (g.object_id != 3)], 1.0)


def test_defaults():
    s = load_text(scene_text())
    assert s.image.spp == 1
    np.testing.assert_array_equal(s.camera.up, [0, 1, 0])
    assert (s.camera.fov_deg, s.camera.far) == (50.0, 1000.0)
    np.testing.assert_array_equal(s.medium.sigma_s, 0)
    np.testing.assert_array_equal(s.medium.sigma_a, 0)
    assert s.medium.phase.type == "isotropic"
    np.testing.assert_array_equal(s.background, [0, 0, 0])
    assert s.render == Render()
    assert s.geometry.count == 0 and s.geometry.triangles.shape == (0, 3, 3)
    assert s.geometry.albedo.shape == (0, 3) and s.geometry.object_id.shape == (0,)


def test_medium_partial_and_isotropic():
    s = load_text(scene_text({"medium": {"sigma_s": 0.1, "phase": {"type": "isotropic"}}}))
    np.testing.assert_array_equal(s.medium.sigma_s, [0.1] * 3)
    np.testing.assert_array_equal(s.medium.sigma_a, [0] * 3)
    assert s.medium.phase.type == "isotropic" and s.medium.phase.g == 0.0


def test_yaml12_exponent_floats_are_numbers():
    s = load_text(scene_text().replace("intensity: 10", "intensity: 1e3"))
    np.testing.assert_array_equal(s.lights[0].intensity, [1000.0] * 3)


def test_yaml_anchor_and_merge():
    text = """\
version: 1
image: {width: 8, height: 8}
camera: {position: [0, 0, 5], look_at: [0, 0, 0]}
background: &white [1, 1, 1]
lights:
  - &key {type: point, position: [0, 5, 0], intensity: *white}
  - {<<: *key, position: [5, 0, 0]}
"""
    s = load_text(text)
    np.testing.assert_array_equal(s.background, [1, 1, 1])
    np.testing.assert_array_equal(s.lights[0].intensity, [1, 1, 1])
    np.testing.assert_array_equal(s.lights[1].intensity, [1, 1, 1])
    np.testing.assert_array_equal(s.lights[1].position, [5, 0, 0])


def test_box_sphere_plane_tessellation_and_winding():
    box = box_triangles([-1, 0, -2], [1, 2, 3])
    sphere = sphere_triangles([1, 2, 3], 2.0, 48)
    assert box.shape == (12, 3, 3) and sphere.shape == (2208, 3, 3)
    for tris, centre in ((box, [0, 1, 0.5]), (sphere, [1, 2, 3])):
        normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        outward = np.einsum("ij,ij->i", normals, tris.mean(axis=1) - centre)
        assert (outward > 0).all()
    np.testing.assert_allclose(np.linalg.norm(sphere - [1, 2, 3], axis=-1), 2.0)
    n = np.array([0.3, -1.0, 0.4]) / np.linalg.norm([0.3, -1.0, 0.4])
    plane = plane_triangles([1, 1, 1], n, 4.0, 8)
    assert plane.shape == (128, 3, 3)
    normals = np.cross(plane[:, 1] - plane[:, 0], plane[:, 2] - plane[:, 0])
    np.testing.assert_allclose(normals / np.linalg.norm(normals, axis=1)[:, None], [n] * 128)
    np.testing.assert_allclose((plane - [1, 1, 1]) @ n, 0, atol=1e-12)
    assert np.isclose(np.sum(np.linalg.norm(normals, axis=1)) / 2, 16.0)  # area = size^2


def test_segments_options():
    s = load_text(scene_text(base={**MINIMAL, "objects": [
        {"type": "sphere", "center": [0, 0, 0], "radius": 1, "segments": 8},
        {"type": "plane", "center": [0, 0, 0], "normal": [0, 0, 1], "size": 2, "segments": 3},
    ]}))
    assert list(np.bincount(s.geometry.object_id)) == [2 * 8 * 3, 2 * 9]
    np.testing.assert_allclose(tri_of(s, 1)[..., 2], 0)
    assert np.abs(tri_of(s, 1)).max() == 1.0


def test_mesh_transform_moves_known_vertex():
    s = load_text(FULL)
    tets = tri_of(s, 4)
    # Tetrahedron vertex (1, 0, 0): scale 2 -> (2, 0, 0); 90 deg about +y -> (0, 0, -2);
    # translate (1, 2, 3) -> (1, 2, 1). The origin vertex goes to the translation.
    pts = tets.reshape(-1, 3)
    assert np.isclose(pts, [1, 2, 1], atol=1e-12).all(axis=1).any()
    assert np.isclose(pts, [1, 2, 3], atol=1e-12).all(axis=1).any()
    assert np.isclose(pts, [1, 4, 3], atol=1e-12).all(axis=1).any()  # (0, 1, 0) -> (0, 2, 0)
    assert np.isclose(pts, [3, 2, 3], atol=1e-12).all(axis=1).any()  # (0, 0, 1) -> (2, 0, 0)


def test_non_uniform_scale_and_box_transform():
    obj = {"type": "box", "min": [0, 0, 0], "max": [1, 1, 1],
           "transform": {"scale": [1, 2, 3], "translate": [10, 0, 0]}}
    g = load_text(scene_text(base=with_object(obj))).geometry
    lo, hi = g.bounds()
    np.testing.assert_allclose(lo, [10, 0, 0])
    np.testing.assert_allclose(hi, [11, 2, 3])


def _mesh_with_rotation(rotate: dict) -> np.ndarray:
    obj = {"type": "mesh", "file": "meshes/tetrahedron.obj", "transform": {"rotate": rotate}}
    return tri_of(load_text(scene_text(base=with_object(obj))), 0)


def test_rotation_forms_agree():
    by_axis = _mesh_with_rotation({"axis": [0, 1, 0], "angle_deg": 90})
    by_euler = _mesh_with_rotation({"euler_deg": [0, 90, 0], "order": "xyz"})
    s = math.sqrt(0.5)
    by_quat = _mesh_with_rotation({"quaternion": [s, 0, s, 0]})
    np.testing.assert_allclose(by_euler, by_axis, atol=1e-12)
    np.testing.assert_allclose(by_quat, by_axis, atol=1e-12)
    # (1, 0, 0) turns to (0, 0, -1) under +90 deg about +y.
    assert np.isclose(by_axis.reshape(-1, 3), [0, 0, -1], atol=1e-12).all(axis=1).any()


def test_euler_order_is_intrinsic():
    got = _mesh_with_rotation({"euler_deg": [30, 40, 50], "order": "zyx"})
    r = (rotation_axis_angle([0, 0, 1], math.radians(30))
         @ rotation_axis_angle([0, 1, 0], math.radians(40))
         @ rotation_axis_angle([1, 0, 0], math.radians(50)))
    base = _mesh_with_rotation({"axis": [1, 0, 0], "angle_deg": 0})
    np.testing.assert_allclose(got, base @ r.T, atol=1e-12)
    default_order = _mesh_with_rotation({"euler_deg": [30, 40, 50]})
    r_xyz = (rotation_axis_angle([1, 0, 0], math.radians(30))
             @ rotation_axis_angle([0, 1, 0], math.radians(40))
             @ rotation_axis_angle([0, 0, 1], math.radians(50)))
    np.testing.assert_allclose(default_order, base @ r_xyz.T, atol=1e-12)


def test_quaternion_general_agrees_with_axis_angle():
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    a = math.radians(70)
    q = [math.cos(a / 2), *(math.sin(a / 2) * axis).tolist()]
    np.testing.assert_allclose(_mesh_with_rotation({"quaternion": q}),
                               _mesh_with_rotation({"axis": axis.tolist(), "angle_deg": 70}),
                               atol=1e-12)


@pytest.mark.parametrize("name", ["tetrahedron.obj", "cube.ply", "cube.stl"])
def test_mesh_formats(name):
    obj = {"type": "mesh", "file": f"meshes/{name}", "albedo": [0.1, 0.2, 0.3]}
    g = load_text(scene_text(base=with_object(obj))).geometry
    assert g.count == (4 if name.endswith("obj") else 12)
    np.testing.assert_array_equal(g.albedo, [[0.1, 0.2, 0.3]] * g.count)


def test_mesh_path_relative_to_yaml_file(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "t.obj").write_text((MESHES / "tetrahedron.obj").read_text())
    scene = tmp_path / "scene.yaml"
    scene.write_text(scene_text(base=with_object({"type": "mesh", "file": "sub/t.obj"})))
    s = load_scene(scene)
    assert s.geometry.count == 4 and s.source == scene
    s = load_scene(str(scene), ["objects.0.file=" + str(tmp_path / "sub" / "t.obj")])
    assert s.geometry.count == 4


def test_parse_scene_without_source_uses_cwd(monkeypatch):
    monkeypatch.chdir(REPO / "scenes")
    s = parse_scene(scene_text(base=with_object({"type": "mesh", "file": "meshes/cube.ply"})))
    assert s.geometry.count == 12 and s.source is None


# --------------------------------------------------------------------------- overrides


def test_overrides():
    s = load_text(FULL, ["render.steps=1024", "medium.sigma_s=0.1", "lights.0.intensity=[1,2,3]",
                         "camera.position=[0, 1, 5]", "render.method=raymarch",
                         "objects.3.radius=2", "render.jitter=false"])
    assert s.render.steps == 1024 and s.render.method == "raymarch" and not s.render.jitter
    np.testing.assert_array_equal(s.medium.sigma_s, [0.1] * 3)
    np.testing.assert_array_equal(s.lights[0].intensity, [1, 2, 3])
    np.testing.assert_array_equal(s.camera.position, [0, 1, 5])
    assert np.linalg.norm(tri_of(s, 3) - [0, 1, 0], axis=-1).max() == pytest.approx(2.0)


def test_override_creates_sections_and_appends():
    s = load_text(scene_text(), ["medium.phase={type: hg, g: -0.5}", "render.steps=8",
                                 "lights.1={type: directional, direction: [0, -1, 0], irradiance: 1}"])
    assert s.medium.phase.g == -0.5 and s.render.steps == 8
    assert len(s.lights) == 2 and isinstance(s.lights[1], DirectionalLight)
    s = load_text(scene_text(), ["objects=[{type: box, min: [0,0,0], max: [1,1,1]}]"])
    assert s.geometry.count == 12


def test_override_whitespace_and_equals_in_value():
    s = load_text(scene_text(), [" render.method = exact"])
    assert s.render.method == "exact"


OVERRIDE_ERRORS = [
    ("render.steps=abc", r"^override render\.steps=abc: render\.steps: expected an integer in \[1, 65536\], got 'abc'$"),
    ("render.stepz=4", r"^override render\.stepz=4: render\.stepz: unknown key \(did you mean 'steps'\?\)"),
    ("colour=1", r"^override colour=1: colour: unknown key"),
    ("lights.0.power=1", r"^override lights\.0\.power=1: lights\.0\.power: unknown key"),
    ("render.steps", r"^override render\.steps: expected key\.path=value, got 'render\.steps'$"),
    ("=3", r"^override =3: expected key\.path=value"),
    ("render..steps=3", r"^override render\.\.steps=3: expected key\.path=value"),
    ("lights.5.intensity=1", r"^override lights\.5\.intensity=1: lights\.5: expected a list index in \[0, 0\]"),
    ("lights.x=1", r"lights\.x: expected a list index"),
    ("image.width.fine=1", r"image\.width\.fine: expected a mapping or a list to set fine in, got 64$"),
    ("lights.0.intensity=[1, 2", r"^override lights\.0\.intensity=\[1, 2: lights\.0\.intensity: malformed YAML"),
    ("version=2", r"^override version=2: version: expected version 1, got 2$"),
    ("camera.far=-1", r"^override camera\.far=-1: camera\.far: expected a number > 0, got -1$"),
    ("render.steps=", r"render\.steps: expected an integer in \[1, 65536\], got null$"),
]


@pytest.mark.parametrize("override, message", OVERRIDE_ERRORS)
def test_override_errors(override, message):
    with pytest.raises(SceneError, match=message):
        load_text(scene_text(), [override])


# --------------------------------------------------------------------------- invalid input

# (changes to MINIMAL, regex on the message after "<string>:L:C: ")
BAD = [
    # version and top level
    ({"version": DELETE}, r"\(top level\): missing required key 'version'"),
    ({"version": 2}, r"version: expected version 1, got 2"),
    ({"version": "1"}, r"version: expected version 1, got '1'"),
    ({"version": True}, r"version: expected version 1, got true"),
    ({"colour": 1}, r"colour: unknown key"),
    ({"image": DELETE}, r"\(top level\): missing required key 'image'"),
    ({"camera": DELETE}, r"\(top level\): missing required key 'camera'"),
    ({"lights": DELETE}, r"\(top level\): missing required key 'lights'"),
    ({"lights": []}, r"lights: expected a list of at least 1 light, got \[\]"),
    ({"lights": {"type": "point"}}, r"lights: expected a list of at least 1 light"),
    ({"objects": {"type": "box"}}, r"objects: expected a list of objects"),
    ({"objects": None}, r"objects: expected a list of objects, got null"),
    ({"image": [64, 32]}, r"image: expected a mapping, got \[64, 32\]"),
    # image
    ({"image.width": DELETE}, r"image: missing required key 'width'"),
    ({"image.width": 0}, r"image\.width: expected an integer in \[1, 16384\], got 0"),
    ({"image.height": 16385}, r"image\.height: expected an integer in \[1, 16384\], got 16385"),
    ({"image.width": 64.0}, r"image\.width: expected an integer in \[1, 16384\], got 64\.0"),
    ({"image.width": "64"}, r"image\.width: expected an integer in \[1, 16384\], got '64'"),
    ({"image.width": True}, r"image\.width: expected an integer in \[1, 16384\], got true"),
    ({"image": {"width": 16384, "height": 8192}},
     r"image: expected width \* height <= 67108864 pixels, got 16384 x 8192 = 134217728"),
    ({"image.spp": 0}, r"image\.spp: expected an integer in \[1, 4096\], got 0"),
    ({"image.spp": 4097}, r"image\.spp: expected an integer in \[1, 4096\], got 4097"),
    ({"image.dpi": 72}, r"image\.dpi: unknown key; expected one of: width, height, spp"),
    # camera
    ({"camera.position": DELETE}, r"camera: missing required key 'position'"),
    ({"camera.look_at": DELETE}, r"camera: missing required key 'look_at'"),
    ({"camera.position": [0, 1]}, r"camera\.position: expected a list of 3 numbers \[x, y, z\], got \[0, 1\]"),
    ({"camera.position": [0, 1, 2, 3]}, r"camera\.position: expected a list of 3 numbers"),
    ({"camera.position": 5}, r"camera\.position: expected a list of 3 numbers"),
    ({"camera.position": [0, "a", 2]}, r"camera\.position\.1: expected a number, got 'a'"),
    ({"camera.position": [0, False, 2]}, r"camera\.position\.1: expected a number, got false"),
    ({"camera.position": [0, float("nan"), 2]}, r"camera\.position\.1: expected a finite number, got \.nan"),
    ({"camera.position": [0, float("-inf"), 2]}, r"camera\.position\.1: expected a finite number, got -\.inf"),
    ({"camera.look_at": [0, 2, 8]}, r"camera\.look_at: expected a point different from camera\.position"),
    ({"camera.position": [0, 1, 8], "camera.up": [0, 0, -2]}, r"camera\.up: expected a direction not parallel to look_at - position"),
    ({"camera.up": [0, 0, 0]}, r"camera\.up: expected a non-zero direction"),
    ({"camera.look_at": [0, 7, 0], "camera.position": [0, 9, 0]},
     r"camera\.up: expected a direction not parallel to look_at - position, got \[0, 1, 0\] \(default\)"),
    ({"camera.fov_deg": 0}, r"camera\.fov_deg: expected a number in \(0, 180\), got 0"),
    ({"camera.fov_deg": 180}, r"camera\.fov_deg: expected a number in \(0, 180\), got 180"),
    ({"camera.fov_deg": "wide"}, r"camera\.fov_deg: expected a number in \(0, 180\), got 'wide'"),
    ({"camera.fov_deg": True}, r"camera\.fov_deg: expected a number in \(0, 180\), got true"),
    ({"camera.far": 0}, r"camera\.far: expected a number > 0, got 0"),
    ({"camera.far": float("inf")}, r"camera\.far: expected a finite number > 0, got \.inf"),
    ({"camera.fov": 40}, r"camera\.fov: unknown key \(did you mean 'fov_deg'\?\)"),
    # lights
    ({"lights.0": {"position": [0, 1, 0], "intensity": 1}}, r"lights\.0: missing required key 'type'"),
    ({"lights.0": {"type": "area", "position": [0, 1, 0]}},
     r"lights\.0\.type: expected one of 'point', 'spot', 'directional', got 'area'"),
    ({"lights.0": {"type": 3}}, r"lights\.0\.type: expected one of 'point', 'spot', 'directional', got 3"),
    ({"lights.0": "sun"}, r"lights\.0: expected a mapping, got 'sun'"),
    ({"lights.0.intensity": DELETE}, r"lights\.0: missing required key 'intensity'"),
    ({"lights.0.intensity": -1}, r"lights\.0\.intensity: expected a number >= 0, got -1"),
    ({"lights.0.intensity": [1, -1, 1]}, r"lights\.0\.intensity\.1: expected a number >= 0, got -1"),
    ({"lights.0.intensity": [1, 1]}, r"lights\.0\.intensity: expected a list of 3 numbers \(RGB\) or a single number >= 0"),
    ({"lights.0.intensity": float("nan")}, r"lights\.0\.intensity: expected a finite number >= 0, got \.nan"),
    ({"lights.0.intensity": "bright"}, r"lights\.0\.intensity: expected a number >= 0, got 'bright'"),
    ({"lights.0.direction": [0, -1, 0]}, r"lights\.0\.direction: unknown key; expected one of: type, position, intensity"),
    ({"lights.0": {"type": "spot", "position": [0, 5, 0], "direction": [0, -1, 0], "cone_deg": 120, "intensity": 1}},
     r"lights\.0\.cone_deg: expected a number in \(0, 90\], got 120"),
    ({"lights.0": {"type": "spot", "position": [0, 5, 0], "direction": [0, -1, 0], "cone_deg": 0, "intensity": 1}},
     r"lights\.0\.cone_deg: expected a number in \(0, 90\], got 0"),
    ({"lights.0": {"type": "spot", "position": [0, 5, 0], "direction": [0, 0, 0], "cone_deg": 30, "intensity": 1}},
     r"lights\.0\.direction: expected a non-zero direction \[x, y, z\], got \[0, 0, 0\]"),
    ({"lights.0": {"type": "spot", "position": [0, 5, 0], "cone_deg": 30, "intensity": 1}},
     r"lights\.0: missing required key 'direction'"),
    ({"lights.0": {"type": "directional", "direction": [0, 0, 0], "irradiance": 1}},
     r"lights\.0\.direction: expected a non-zero direction"),
    ({"lights.0": {"type": "directional", "direction": [0, -1, 0], "irradiance": -2}},
     r"lights\.0\.irradiance: expected a number >= 0, got -2"),
    ({"lights.0": {"type": "directional", "direction": [0, -1, 0], "intensity": 2}},
     r"lights\.0\.intensity: unknown key"),
    # medium
    ({"medium": {"sigma_s": -0.1}}, r"medium\.sigma_s: expected a number >= 0, got -0\.1"),
    ({"medium": {"sigma_a": [0, 0, -1]}}, r"medium\.sigma_a\.2: expected a number >= 0, got -1"),
    ({"medium": {"sigma_t": 1}}, r"medium\.sigma_t: unknown key"),
    ({"medium": {"phase": {"type": "rayleigh"}}}, r"medium\.phase\.type: expected one of 'isotropic', 'hg', got 'rayleigh'"),
    ({"medium": {"phase": {"type": "hg", "g": 1}}}, r"medium\.phase\.g: expected a number in \(-1, 1\), got 1"),
    ({"medium": {"phase": {"type": "hg", "g": -1.0}}}, r"medium\.phase\.g: expected a number in \(-1, 1\), got -1\.0"),
    ({"medium": {"phase": {"type": "hg"}}}, r"medium\.phase: missing required key 'g'"),
    ({"medium": {"phase": {"type": "isotropic", "g": 0.2}}}, r"medium\.phase\.g: unknown key"),
    ({"medium": {"phase": {"type": "hg", "g": 0.2, "k": 1}}}, r"medium\.phase\.k: unknown key"),
    ({"medium": {"phase": "hg"}}, r"medium\.phase: expected a mapping, got 'hg'"),
    # background
    ({"background": -1}, r"background: expected a number >= 0, got -1"),
    ({"background": [0, 0]}, r"background: expected a list of 3 numbers"),
    ({"background": "black"}, r"background: expected a number >= 0, got 'black'"),
    # render
    ({"render": {"method": "pathtrace"}}, r"render\.method: expected one of 'minmax', 'raymarch', 'exact', 'volume_moments', got 'pathtrace'"),
    ({"render": {"steps": 0}}, r"render\.steps: expected an integer in \[1, 65536\], got 0"),
    ({"render": {"steps": 65537}}, r"render\.steps: expected an integer in \[1, 65536\], got 65537"),
    ({"render": {"steps": 2.5}}, r"render\.steps: expected an integer in \[1, 65536\], got 2\.5"),
    ({"render": {"shadow_map": 8}}, r"render\.shadow_map: expected an integer in \[16, 8192\], got 8"),
    ({"render": {"shadow_map": 16384}}, r"render\.shadow_map: expected an integer in \[16, 8192\], got 16384"),
    ({"render": {"slices": 15}}, r"render\.slices: expected an integer in \[16, 16384\], got 15"),
    ({"render": {"gamma_samples": 20000}}, r"render\.gamma_samples: expected an integer in \[16, 16384\], got 20000"),
    ({"render": {"svd_rank": 0}}, r"render\.svd_rank: expected an integer in \[1, 16\], got 0"),
    ({"render": {"svd_rank": 17}}, r"render\.svd_rank: expected an integer in \[1, 16\], got 17"),
    ({"render": {"integrand": "magic"}}, r"render\.integrand: expected one of 'table', 'svd', 'analytic', got 'magic'"),
    ({"render": {"traversal": "bfs"}}, r"render\.traversal: expected one of 'tree', 'scan', got 'bfs'"),
    ({"render": {"jitter": "yes please"}}, r"render\.jitter: expected true or false, got 'yes please'"),
    ({"render": {"jitter": 1}}, r"render\.jitter: expected true or false, got 1"),
    ({"render": {"pcf": -1}}, r"render\.pcf: expected an integer in \[0, 16\], got -1"),
    ({"render": {"surface_shadows": "soft"}},
     r"render\.surface_shadows: expected one of 'exact', 'map', 'pcf', 'filtered', got 'soft'"),
    ({"render": {"surface_shadows": "map", "pcf": 2}},
     r"render\.pcf: expected 0 with surface_shadows: map \(a filter radius needs surface_shadows: pcf\), got 2"),
    ({"render": {"sptes": 3}}, r"render\.sptes: unknown key \(did you mean 'steps'\?\)"),
]

BOX = {"type": "box", "min": [-1, 0, -1], "max": [1, 2, 1]}
SPHERE = {"type": "sphere", "center": [0, 1, 0], "radius": 1}
PLANE = {"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0], "size": 20}
TRIS = {"type": "triangles", "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [[0, 1, 2]]}
MESH = {"type": "mesh", "file": "meshes/tetrahedron.obj"}
ROT = "objects.0.transform.rotate"

BAD_OBJECTS = [
    ({"type": "torus"}, r"objects\.0\.type: expected one of 'triangles', 'plane', 'box', 'sphere', 'mesh', 'relief', got 'torus'"),
    ({"min": [0, 0, 0]}, r"objects\.0: missing required key 'type'"),
    ({**BOX, "radius": 1}, r"objects\.0\.radius: unknown key; expected one of: type, min, max, albedo, opacity, transform"),
    ({**BOX, "colour": 1}, r"objects\.0\.colour: unknown key"),
    ({**BOX, "max": DELETE}, r"objects\.0: missing required key 'max'"),
    ({**BOX, "max": [1, 0, 1]}, r"objects\.0\.max: expected a point above min \[-1, 0, -1\] on every axis, got \[1, 0, 1\]"),
    ({**BOX, "albedo": 1.5}, r"objects\.0\.albedo: expected a number in \[0, 1\], got 1\.5"),
    ({**BOX, "albedo": -0.1}, r"objects\.0\.albedo: expected a number in \[0, 1\], got -0\.1"),
    ({**BOX, "albedo": [0.5, 1.01, 0.5]}, r"objects\.0\.albedo\.1: expected a number in \[0, 1\], got 1\.01"),
    ({**BOX, "albedo": True}, r"objects\.0\.albedo: expected a number in \[0, 1\], got true"),
    ({**BOX, "opacity": -0.1}, r"objects\.0\.opacity: expected a number in \[0, 1\], got -0\.1"),
    ({**BOX, "opacity": 1.2}, r"objects\.0\.opacity: expected a number in \[0, 1\], got 1\.2"),
    ({**BOX, "opacity": float("nan")}, r"objects\.0\.opacity: expected a .*number in \[0, 1\], got \.nan"),
    ({**BOX, "opacity": [0.5, 0.5]}, r"objects\.0\.opacity: expected a list of 3 numbers \(RGB\) or a single number in \[0, 1\], got \[0\.5, 0\.5\]"),
    ({**BOX, "opacity": [0.5, 2, 0.5]}, r"objects\.0\.opacity\.1: expected a number in \[0, 1\], got 2"),
    ({**SPHERE, "radius": 0}, r"objects\.0\.radius: expected a number > 0, got 0"),
    ({**SPHERE, "radius": -2}, r"objects\.0\.radius: expected a number > 0, got -2"),
    ({**SPHERE, "segments": 3}, r"objects\.0\.segments: expected an integer in \[4, 1024\], got 3"),
    ({**SPHERE, "center": [0, 1]}, r"objects\.0\.center: expected a list of 3 numbers"),
    ({**PLANE, "size": 0}, r"objects\.0\.size: expected a number > 0, got 0"),
    ({**PLANE, "size": -1}, r"objects\.0\.size: expected a number > 0, got -1"),
    ({**PLANE, "normal": [0, 0, 0]}, r"objects\.0\.normal: expected a non-zero direction"),
    ({**PLANE, "segments": 0}, r"objects\.0\.segments: expected an integer in \[1, 1024\], got 0"),
    ({**TRIS, "faces": [[0, 1, 3]]}, r"objects\.0\.faces\.0\.2: expected an integer in \[0, 2\], got 3"),
    ({**TRIS, "faces": [[0, -1, 2]]}, r"objects\.0\.faces\.0\.1: expected an integer in \[0, 2\], got -1"),
    ({**TRIS, "faces": [[0, 1.5, 2]]}, r"objects\.0\.faces\.0\.1: expected an integer in \[0, 2\], got 1\.5"),
    ({**TRIS, "faces": [[0, 1.0, 2]]}, r"objects\.0\.faces\.0\.1: expected an integer in \[0, 2\], got 1\.0"),
    ({**TRIS, "faces": [[0, "1", 2]]}, r"objects\.0\.faces\.0\.1: expected an integer in \[0, 2\], got '1'"),
    ({**TRIS, "faces": [[0, 1]]}, r"objects\.0\.faces\.0: expected a face: a list of 3 vertex indices"),
    ({**TRIS, "faces": []}, r"objects\.0\.faces: expected a list of at least 1 face"),
    ({**TRIS, "vertices": [[0, 0, 0], [1, 0, 0]]}, r"objects\.0\.vertices: expected a list of at least 3 vertices"),
    ({**TRIS, "vertices": [[0, 0, 0], [1, 0], [0, 1, 0]]}, r"objects\.0\.vertices\.1: expected a list of 3 numbers"),
    ({**MESH, "file": "meshes/missing.obj"},
     r"objects\.0\.file: expected a readable mesh file \(\.obj, \.ply or \.stl\) with triangles, "
     r"got 'meshes/missing\.obj' \(no such file: .*missing\.obj\)"),
    ({**MESH, "file": "meshes/tetrahedron.fbx"}, r"objects\.0\.file: .*got 'meshes/tetrahedron\.fbx' \(unsupported mesh format '\.fbx'"),
    ({**MESH, "file": "meshes"}, r"objects\.0\.file: .*got 'meshes' \(unsupported mesh format"),
    ({**MESH, "file": 3}, r"objects\.0\.file: expected a mesh file path"),
    ({**MESH, "file": DELETE}, r"objects\.0: missing required key 'file'"),
    # transforms
    ({**BOX, "transform": {"translate": [1, 2]}}, r"objects\.0\.transform\.translate: expected a list of 3 numbers"),
    ({**BOX, "transform": {"shear": 1}}, r"objects\.0\.transform\.shear: unknown key; expected one of: translate, rotate, scale"),
    ({**BOX, "transform": {"scale": 0}}, r"objects\.0\.transform\.scale: expected a number > 0, got 0"),
    ({**BOX, "transform": {"scale": -2}}, r"objects\.0\.transform\.scale: expected a number > 0, got -2"),
    ({**BOX, "transform": {"scale": [1, -1, 1]}}, r"objects\.0\.transform\.scale\.1: expected a number > 0, got -1"),
    ({**BOX, "transform": {"scale": [1, 1]}}, r"objects\.0\.transform\.scale: expected a number > 0 or a list of 3 numbers > 0"),
    ({**BOX, "transform": {"rotate": {}}}, rf"{ROT}: expected exactly one of \{{axis, angle_deg\}}, \{{euler_deg, order\}} or \{{quaternion\}}, got \{{\}}"),
    ({**BOX, "transform": {"rotate": {"axis": [0, 1, 0], "angle_deg": 3, "quaternion": [1, 0, 0, 0]}}},
     rf"{ROT}: expected exactly one of"),
    ({**BOX, "transform": {"rotate": {"axis": [0, 1, 0]}}}, rf"{ROT}: missing required key 'angle_deg'"),
    ({**BOX, "transform": {"rotate": {"angle_deg": 30}}}, rf"{ROT}: missing required key 'axis'"),
    ({**BOX, "transform": {"rotate": {"axis": [0, 0, 0], "angle_deg": 30}}}, rf"{ROT}\.axis: expected a non-zero direction"),
    ({**BOX, "transform": {"rotate": {"axis": [0, 1, 0], "angle": 30}}}, rf"{ROT}\.angle: unknown key \(did you mean 'angle_deg'\?\)"),
    ({**BOX, "transform": {"rotate": {"order": "xyz"}}}, rf"{ROT}: missing required key 'euler_deg'"),
    ({**BOX, "transform": {"rotate": {"euler_deg": [1, 2]}}}, rf"{ROT}\.euler_deg: expected a list of 3 angles in degrees"),
    ({**BOX, "transform": {"rotate": {"euler_deg": [1, 2, 3], "order": "xxy"}}}, rf"{ROT}\.order: expected 3 letters over 'xyz'"),
    ({**BOX, "transform": {"rotate": {"euler_deg": [1, 2, 3], "order": "abc"}}}, rf"{ROT}\.order: expected 3 letters over 'xyz'.*got 'abc'"),
    ({**BOX, "transform": {"rotate": {"quaternion": [1, 0, 0, 0.01]}}},
     rf"{ROT}\.quaternion: expected a unit quaternion \[w, x, y, z\] \(\|q\| = 1 within 1e-06\), got \[1, 0, 0, 0\.01\] with \|q\| = 1\.0000"),
    ({**BOX, "transform": {"rotate": {"quaternion": [1, 0, 0]}}}, rf"{ROT}\.quaternion: expected a unit quaternion"),
    ({**BOX, "transform": {"rotate": {"quaternion": [0, 0, 0, 0]}}}, rf"{ROT}\.quaternion: expected a unit quaternion"),
    ({**BOX, "transform": [1, 2, 3]}, r"objects\.0\.transform: expected a mapping, got \[1, 2, 3\]"),
]


def _fails(text: str, pattern: str, where: str = r"<string>:\d+:\d+: "):
    with pytest.raises(SceneError) as info:
        parse_scene(text)
    message = str(info.value)
    assert "\n" not in message
    assert re.search("^" + where + "(?:" + pattern + ")", message), message
    return message


@pytest.mark.parametrize("changes, pattern", BAD, ids=[p[:50] for _, p in BAD])
def test_bad_scene(changes, pattern, monkeypatch):
    monkeypatch.chdir(REPO / "scenes")
    _fails(scene_text(changes), pattern)


@pytest.mark.parametrize("obj, pattern", BAD_OBJECTS, ids=[p[:50] for _, p in BAD_OBJECTS])
def test_bad_object(obj, pattern, monkeypatch):
    monkeypatch.chdir(REPO / "scenes")
    obj = {k: v for k, v in obj.items() if v is not DELETE}
    _fails(scene_text(base=with_object(obj)), pattern)


def test_error_points_at_offending_node():
    text = FULL.replace("cone_deg: 30", "cone_deg: 120")
    line = next(i for i, l in enumerate(text.splitlines(), 1) if "cone_deg" in l)
    col = text.splitlines()[line - 1].index("120") + 1
    with pytest.raises(SceneError) as info:
        parse_scene(text, Path("scenes/x.yaml"))
    assert str(info.value) == f"scenes/x.yaml:{line}:{col}: lights.1.cone_deg: expected a number in (0, 90], got 120"


def test_unknown_key_points_at_key(monkeypatch):
    monkeypatch.chdir(REPO / "scenes")
    text = FULL.replace("shadow_map: 512", "shadow_mop: 512")
    line = next(i for i, l in enumerate(text.splitlines(), 1) if "shadow_mop" in l)
    col = text.splitlines()[line - 1].index("shadow_mop") + 1
    _fails(text, r"render\.shadow_mop: unknown key \(did you mean 'shadow_map'\?\)", where=f"<string>:{line}:{col}: ")


def test_missing_key_points_at_mapping():
    _fails("version: 1\nimage: {width: 4, height: 4}\ncamera:\n  position: [0, 0, 1]\n"
           "lights: [{type: point, position: [0, 0, 0], intensity: 1}]\n",
           r"camera: missing required key 'look_at'", where="<string>:4:3: ")


def test_load_scene_reports_file_as_given(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.yaml").write_text(scene_text({"image.spp": 0}))
    with pytest.raises(SceneError, match=r"^\./s\.yaml:\d+:\d+: image\.spp: expected"):
        load_scene("./s.yaml")


@pytest.mark.parametrize("text, pattern, where", [
    ("version: 1\nimage: {width: 4\n", r"malformed YAML: ", r"<string>:3:1: "),
    ("version: 1\n  bad: indent\n", r"malformed YAML: mapping values are not allowed (here|in this context)", r"<string>:2:6: "),
    ("version: 1\nimage:\n\t- 1\n", r"malformed YAML: found character .*\(a tab: indent with spaces\)$", r"<string>:3:1: "),
    ("a: 1\n---\nb: 2\n", r"malformed YAML: ", r"<string>:\d+:\d+: "),
    ("", r"\(top level\): expected a mapping, got an empty document", r"<string>:1:1: "),
    ("# only a comment\n", r"\(top level\): expected a mapping, got an empty document", r"<string>:1:1: "),
    ("- 1\n- 2\n", r"\(top level\): expected a mapping, got \[1, 2\]", r"<string>:1:1: "),
    ("just text", r"\(top level\): expected a mapping, got 'just text'", r"<string>:1:1: "),
    ("version: 1\nversion: 1\n", r"version: expected each key once, got a duplicate \(first at line 1\)", r"<string>:2:1: "),
    ("version: 1\n1: 2\n", r"\(top level\): expected a string key, got 1", r"<string>:2:1: "),
    ("version: 1\nimage: &a {width: 2, height: 2, spp: *a}\n", r"image\.spp: expected a finite tree, got a recursive alias", r"<string>:\d+:\d+: "),
    ("version: 1\nimage: *nothing\n", r"malformed YAML: found undefined alias 'nothing'", r"<string>:2:8: "),
])
def test_malformed_yaml(text, pattern, where):
    _fails(text, pattern, where)


def test_version_checked_before_other_keys():
    _fails("version: 2\nfuture_key: 1\n", r"version: expected version 1, got 2$", r"<string>:1:10: ")


def test_missing_scene_file(tmp_path):
    with pytest.raises(SceneError, match=r"nope\.yaml: cannot read scene file: No such file"):
        load_scene(tmp_path / "nope.yaml")
    with pytest.raises(SceneError, match=r"cannot read scene file"):
        load_scene(tmp_path)
    (tmp_path / "bin.yaml").write_bytes(b"version: 1\n\xff\xfe\n")
    with pytest.raises(SceneError, match=r"bin\.yaml: cannot read scene file: not UTF-8"):
        load_scene(tmp_path / "bin.yaml")


@pytest.mark.parametrize("name, content, reason", [
    ("garbage.obj", b"hello world\nthis is not an obj\n", r"the file has no triangles"),
    ("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", r"the file has no triangles"),
    ("empty.stl", b"", r"the file has no triangles|not a valid STL file"),
    ("noise.stl", bytes(range(256)) * 3, r"not a valid STL file|the file has no triangles"),
    ("broken.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1 2\n",
     r"not a valid PLY file"),
    ("badindex.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", r"not a valid OBJ file|a face refers to a vertex"),
])
def test_corrupt_mesh_files(tmp_path, name, content, reason):
    (tmp_path / name).write_bytes(content)
    scene = tmp_path / "scene.yaml"
    scene.write_text(scene_text(base=with_object({"type": "mesh", "file": name})))
    with pytest.raises(SceneError) as info:
        load_scene(scene)
    message = str(info.value)
    assert "\n" not in message
    assert re.search(rf"^{re.escape(str(scene))}:\d+:\d+: objects\.0\.file: expected a readable mesh file "
                     rf".*got '{re.escape(name)}' \((?:{reason}).*{re.escape(name)}\)$", message), message


def test_light_power_beyond_float32_range_is_a_scene_error():
    # float32 radiance on the device overflows beyond ~3e38: refuse it at load time.
    with pytest.raises(SceneError, match=r"lights\.0\.intensity: expected"):
        load_text(scene_text({"lights.0.intensity": 1e39}))

