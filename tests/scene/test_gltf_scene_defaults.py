"""A glTF scene as Blender and the sample sets write it (clrays/scene/gltf.py, docs/scene-format.md
"glTF 2.0 scenes"): photometric light units, the light a file without one is told to add,
the default fog, `--set lists.N=` appending, `--camera INDEX`, flat normals without
NORMAL, spots up to 90°, and what is rendered without (required material extensions) or
not rendered at all (said with --verbose)."""
from __future__ import annotations

import importlib.util
import math
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli
from clrays.errors import SceneError
from clrays.scene import gltf
from clrays.scene.load import load_scene, parse_scene
from clrays.scene.model import PointLight, SpotLight

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("make_gltf_example", ROOT / "tools" / "make_gltf_example.py")
tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tool)
GltfBuilder, light_ref, quaternion = tool.GltfBuilder, tool.light_ref, tool.quaternion

SMALL = ["--set", "image.width=32", "--set", "image.height=18"]
FLOOR = [[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], [[0, 2, 1], [0, 3, 2]]


def _write(tmp_path, builder: GltfBuilder, name="scene.glb") -> Path:
    path = tmp_path / name
    path.write_bytes(builder.glb())
    return path


def _floor_and_cube(builder: GltfBuilder) -> GltfBuilder:
    """A floor 8 units square and a unit cube on it, neither with normals: the bounds run
    from [-4, 0, -4] to [4, 1, 4]."""
    builder.node(mesh=builder.mesh(*FLOOR))
    builder.node(mesh=builder.mesh(*_shared_corner_box()), translation=[0, 0.5, 0])
    return builder


def _shared_corner_box(half=0.5) -> tuple[np.ndarray, np.ndarray]:
    """A box of 8 vertices shared by its 12 triangles (wound outward), as an exporter writes
    one without normals: smooth normals by index would round its corners."""
    corners = np.array([[x, y, z] for x in (-half, half) for y in (-half, half) for z in (-half, half)])
    faces = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5],  # -x, +x
             [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],  # -y, +y
             [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]  # -z, +z
    return corners, np.array(faces)


# --------------------------------------------------------------------------- light units


def test_light_intensity_is_photometric_as_blender_writes_it(tmp_path):
    """Blender's default (SPEC) export writes a 1000 W point or spot as 1000 / 4π × 683 cd
    and a 3 W/m² sun as 3 × 683 lux: they read back as Cycles' 1000 / 4π W/sr and 3 W/m².
    `gltf.light_scale` multiplies on top."""
    watts, sun = 1000.0, 3.0
    b = GltfBuilder()
    b.node(mesh=b.mesh(*FLOOR))
    candela = watts / (4 * math.pi) * 683
    b.node(extensions=light_ref(b.light(type="point", intensity=candela, color=[1, 0.5, 0.25])), translation=[0, 3, 0])
    b.node(extensions=light_ref(b.light(type="spot", intensity=candela, spot={"outerConeAngle": 0.5})),
           translation=[0, 3, 0], rotation=quaternion([1, 0, 0], -90))
    b.node(extensions=light_ref(b.light(type="directional", intensity=sun * 683)))
    path = _write(tmp_path, b)
    point, spot, directional = load_scene(path).lights
    np.testing.assert_allclose(point.intensity, np.array([1, 0.5, 0.25]) * watts / (4 * math.pi), rtol=1e-12)
    np.testing.assert_allclose(spot.intensity, [watts / (4 * math.pi)] * 3, rtol=1e-12)
    np.testing.assert_allclose(directional.irradiance, [sun] * 3, rtol=1e-12)
    scaled = load_scene(path, ["gltf.light_scale=683"])  # Blender's COMPAT mode: W / 4π, no 683
    np.testing.assert_allclose(scaled.lights[2].irradiance, [sun * 683] * 3, rtol=1e-12)
    yaml = parse_scene("version: 1\nimage: {width: 8, height: 8}\ncamera: {position: [0, 1, 5], look_at: [0, 0, 0]}\n"
                       "lights: [{type: point, position: [0, 3, 0], intensity: 80}]\n", tmp_path / "y.yaml")
    np.testing.assert_allclose(yaml.lights[0].intensity, [80] * 3)  # YAML stays radiometric


# --------------------------------------------------------------------------- a file without lights


def test_a_file_without_lights_is_refused_with_the_set_that_adds_one(tmp_path):
    """One line naming the file and the missing light, with a `--set` that places a point
    light over the meshes; running it renders a lit image."""
    path = _write(tmp_path, _floor_and_cube(GltfBuilder()))
    code, out = run_cli("render", path, "-o", tmp_path / "none.npy", *SMALL)
    assert code == 1 and out.count("\n") == 1, out
    assert out.startswith(f"clrays: error: {path}: extensions.KHR_lights_punctual: expected at least 1 light"), out
    suggestion = re.search(r"--set ('lights\.0=\{.*\}')$", out.strip())
    assert suggestion, out
    override = shlex.split(suggestion.group(1))[0]
    light = load_scene(path, [override]).lights[0]
    diagonal = math.sqrt(8 ** 2 + 1 + 8 ** 2)
    np.testing.assert_allclose(light.position, [0, 1 + diagonal / 4, 0], rtol=1e-3)  # over the centre, above the top
    centre_distance = 0.5 + diagonal / 4
    np.testing.assert_allclose(light.intensity, [gltf.SUGGESTED_IRRADIANCE * centre_distance ** 2] * 3, rtol=1e-2)
    code, out = run_cli("render", path, "-o", tmp_path / "lit.npy", "--set", override, *SMALL)
    assert code == 0, out
    image = np.load(tmp_path / "lit.npy")
    assert np.isfinite(image).all() and np.percentile(image.mean(axis=2), 50) > 0.01
    # Written without exponents, which YAML would read as strings: a floor 800 km across.
    override = gltf.suggested_light(np.array([-4e5, 0, -4e5]), np.array([4e5, 1, 4e5]))
    assert "e" not in override.replace("type", "").replace("intensity", "")
    big = GltfBuilder()
    big.node(mesh=big.mesh(np.array(FLOOR[0]) * 1e5, FLOOR[1]))
    assert load_scene(_write(tmp_path, big, "big.glb"), [override]).lights[0].position[1] == pytest.approx(282800)


# --------------------------------------------------------------------------- the default fog


def test_a_file_without_a_medium_gets_fog_scaled_to_its_bounds(tmp_path):
    """σs = 1 / the bounding box's diagonal (optical depth 1 across it), isotropic, no
    absorption, with a one-line notice giving the `--set` that changes it; a medium from
    `--set` or a YAML scene's own replaces it, and a YAML scene that names the file without
    a medium gets it too."""
    b = _floor_and_cube(GltfBuilder())
    b.node(extensions=light_ref(b.light(type="point", intensity=50 * 683)), translation=[0, 4, 0])
    path = _write(tmp_path, b)
    diagonal = math.sqrt(8 ** 2 + 1 + 8 ** 2)
    medium = load_scene(path).medium
    np.testing.assert_allclose(medium.sigma_s, [1 / diagonal] * 3, rtol=1e-12)
    assert not medium.sigma_a.any() and medium.phase.type == "isotropic"
    code, out = run_cli("render", path, "-o", tmp_path / "fog.npy", *SMALL)
    assert code == 0, out
    notices = [line for line in out.splitlines() if "no medium" in line]
    assert notices == [f"clrays: notice: {path}: no medium: the default fog, sigma_s = {1 / diagonal:.3g} per unit "
                       f"(optical depth 1 across the meshes' {diagonal:.3g}-unit bounding box diagonal); set one "
                       f"with --set medium.sigma_s={1 / diagonal:.3g} (0: clear air)"], out
    code, out = run_cli("render", path, "-o", tmp_path / "clear.npy", "--set", "medium.sigma_s=0", *SMALL)
    assert code == 0 and "no medium" not in out, out
    assert not load_scene(path, ["medium.sigma_s=0"]).medium.sigma_s.any()
    head = "version: 1\nimage: {width: 8, height: 8}\ngltf: {file: scene.glb}\n"
    np.testing.assert_allclose(parse_scene(head + "medium: {sigma_s: 0.3}\n", tmp_path / "y.yaml").medium.sigma_s, 0.3)
    np.testing.assert_allclose(parse_scene(head, tmp_path / "y.yaml").medium.sigma_s, 1 / diagonal, rtol=1e-12)
    bare = "version: 1\nimage: {width: 8, height: 8}\ncamera: {position: [0, 1, 5], look_at: [0, 0, 0]}\n" \
           "lights: [{type: point, position: [0, 3, 0], intensity: 80}]\n"
    assert not parse_scene(bare, tmp_path / "y.yaml").medium.sigma_s.any()  # a YAML scene alone: clear air


# --------------------------------------------------------------------------- --set lists.N


def test_set_appends_at_a_lists_length_and_starts_a_missing_list(tmp_path):
    """`lights.0={...}` on a file without lights starts the list; `lights.N` with N the
    length appends; past it, one line saying what indices there are."""
    path = _write(tmp_path, _floor_and_cube(GltfBuilder()))
    one = "lights.0={type: point, position: [0, 4, 0], intensity: 20}"
    two = "lights.1={type: directional, direction: [0, -1, 0], irradiance: 0.5}"
    scene = load_scene(path, [one, two])
    assert [light.type for light in scene.lights] == ["point", "directional"]
    with pytest.raises(SceneError, match=r"^override lights\.3=\{type: point\}: lights\.3: expected a list index in "
                                         r"\[0, 1\] or 2 to append, got '3'$"):
        load_scene(path, [one, two, "lights.3={type: point}"])
    with pytest.raises(SceneError, match=r"^override lights\.1=\{type: point\}: lights\.1: expected no index \(the list "
                                         r"is empty\); set it whole or use 0 to append, got '1'$"):
        load_scene(path, ["lights.1={type: point}"])
    yaml = parse_scene("version: 1\nimage: {width: 8, height: 8}\ncamera: {position: [0, 1, 5], look_at: [0, 0, 0]}\n"
                       "lights: [{type: point, position: [0, 3, 0], intensity: 80}]\n", tmp_path / "y.yaml",
                       ["lights.1={type: point, position: [1, 3, 0], intensity: 5}"])
    assert len(yaml.lights) == 2 and yaml.lights[1].intensity[0] == 5


# --------------------------------------------------------------------------- --camera INDEX


def test_camera_by_index_in_node_order(tmp_path):
    """`--camera N` is the N-th camera the scene's nodes place, in node order (0 the
    default); a camera whose name is a number is found by its name first."""
    b = _floor_and_cube(GltfBuilder())
    b.node(extensions=light_ref(b.light(type="point", intensity=50 * 683)), translation=[0, 4, 0])
    unnamed = b.camera(math.radians(40))
    b.node(camera=unnamed, translation=[0, 1, 6])
    b.node(camera=b.camera(math.radians(20)), translation=[2, 1, 6])
    path = _write(tmp_path, b)
    assert load_scene(path, ["gltf.camera=0"]).camera.fov_deg == pytest.approx(40)
    second = load_scene(path, ["gltf.camera=1"]).camera
    assert second.fov_deg == pytest.approx(20)
    np.testing.assert_allclose(second.position, [2, 1, 6])
    code, out = run_cli("render", path, "--camera", "1", "-o", tmp_path / "c.npy", *SMALL)
    assert code == 0, out
    code, out = run_cli("render", path, "--camera", "2", "-o", tmp_path / "c.npy", *SMALL)
    assert code == 1 and out.count("\n") == 1, out
    assert f"{path}: cameras: expected a camera named '2' (the camera's or its node's name) or an index 0 to 1, " \
           f"got no named camera" in out
    b.doc["cameras"][1]["name"] = "0"  # a name wins over an index
    assert load_scene(_write(tmp_path, b, "named.glb"), ["gltf.camera=0"]).camera.fov_deg == pytest.approx(20)


# --------------------------------------------------------------------------- flat normals


def test_a_primitive_without_normals_is_flat_and_renders_as_its_yaml_twin(tmp_path):
    """Without NORMAL each triangle takes its face's normal and is shaded flat: a box of
    shared corners renders within 0.5 % relative RMSE of the YAML box (smooth normals by
    index rounded its corners: 13 % off)."""
    import clrays
    from clrays.reference.metrics import image_error

    b = GltfBuilder()
    b.node(mesh=b.mesh(*FLOOR))
    vertices, faces = _shared_corner_box()
    b.node(mesh=b.mesh(vertices, faces, colour=(0.8, 0.3, 0.2)), translation=[0.3, 0.5, 0.2],
           rotation=quaternion([0, 1, 0], 30))
    b.node(extensions=light_ref(b.light(type="point", intensity=30 * 683)), translation=[-1.5, 3.5, 1.0])
    b.node(camera=b.camera(math.radians(45)), translation=[0.5, 2.2, 5.5], rotation=quaternion([1, 0, 0], -18))
    path = _write(tmp_path, b)
    common = ["image.width=64", "image.height=40", "medium.sigma_s=0.05"]
    imported = load_scene(path, common)
    assert not imported.geometry.smooth.any()
    from clrays.scene.geometry import flat_normals
    np.testing.assert_allclose(imported.geometry.normals, flat_normals(imported.geometry.triangles), atol=1e-9)
    turn = quaternion([0, 1, 0], 30)
    twin = parse_scene(f"""
version: 1
image: {{width: 64, height: 40}}
camera: {{position: [0.5, 2.2, 5.5], look_at: {(np.array([0.5, 2.2, 5.5]) + imported.camera.look_at
                                               - imported.camera.position).tolist()}, fov_deg: 45}}
lights: [{{type: point, position: [-1.5, 3.5, 1.0], intensity: 30}}]
medium: {{sigma_s: 0.05}}
objects:
  - {{type: triangles, vertices: {FLOOR[0]}, faces: {FLOOR[1]}}}
  - type: box
    min: [-0.5, -0.5, -0.5]
    max: [0.5, 0.5, 0.5]
    albedo: [0.8, 0.3, 0.2]
    transform: {{translate: [0.3, 0.5, 0.2], rotate: {{quaternion: {[turn[3], *turn[:3]]}}}}}
""", tmp_path / "twin.yaml")
    reference = clrays.render(twin, method="minmax", reuse=False)
    image = clrays.render(imported, method="minmax", reuse=False)
    error = image_error(image, reference)
    print(f"glTF box without normals against its YAML twin: {error}")
    assert error.pixels > 1500 and error.rmse <= 0.005, error


# --------------------------------------------------------------------------- spots up to 90°


def test_a_spot_wider_than_85_degrees_is_a_point_light_with_its_cone_as_a_cube():
    """A soft spot up to the spec's π/2: a point light whose cube texture, looked up as
    every method looks it up, is the extension's attenuation of the angle from the axis,
    zero outside the outer cone: within 1e-4 inside the faces (6e-5 measured), 1e-2 within a
    texel of a face's edge, where the lookup clamps rather than blends across the seam, and
    at the inner cone's kink (6e-3 measured over 200 000 rays)."""
    from clrays.physics.light_texture import light_texture

    inner, outer = math.radians(60), math.radians(90)
    axis = np.array([0.3, -1.0, 0.2]) / np.linalg.norm([0.3, -1.0, 0.2])
    light = PointLight(position=np.zeros(3), intensity=np.ones(3), texture=gltf.cone_cube(inner, outer, axis))
    rng = np.random.default_rng(7)
    rays = rng.normal(size=(200000, 3))
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    looked_up = light_texture(light, rays * 2.5)[:, 0]
    cos_angle = rays @ axis
    expected = gltf.spot_attenuation(cos_angle, inner, outer)
    angle = np.degrees(np.arccos(np.clip(cos_angle, -1, 1)))
    near_kink = np.abs(angle - 60) < 0.5
    sorted_axes = np.sort(np.abs(rays), axis=1)
    near_seam = sorted_axes[:, 1] / sorted_axes[:, 2] > 1 - 2.0 / gltf.CONE_CUBE_SIDE
    inside = ~near_kink & ~near_seam
    error = np.abs(looked_up - expected)
    print(f"cone cube: largest error {error[inside].max():.2e} inside the faces, {error[~inside].max():.2e} at "
          f"their seams and the inner cone")
    assert error[inside].max() < 1e-4 and error[~inside].max() < 1e-2
    assert looked_up[angle > 90.5].max() == 0.0  # nothing behind the cone's edge


def _wide_spots() -> GltfBuilder:
    """A floor under two spots pointing down from [0, 3, 0]: a soft one of 90° (inner 1
    rad) and a hard one of 1.5 rad (86°)."""
    b = GltfBuilder()
    b.node(mesh=b.mesh(*FLOOR))
    b.node(extensions=light_ref(b.light(type="spot", intensity=683, spot={"innerConeAngle": 1.0,
                                                                          "outerConeAngle": math.pi / 2})),
           translation=[0, 3, 0], rotation=quaternion([1, 0, 0], -90))
    b.node(extensions=light_ref(b.light(type="spot", intensity=683, spot={"innerConeAngle": 1.5,
                                                                          "outerConeAngle": 1.5})),
           translation=[0, 3, 0], rotation=quaternion([1, 0, 0], -90))
    return b


def test_wide_spots_load_render_and_turn_with_their_node(tmp_path):
    """The soft one is a point light with a cone cube, the hard one a spot without a
    texture; both render, and the cube turns with an animated node."""
    b = _wide_spots()
    path = _write(tmp_path, b)
    soft, hard = load_scene(path).lights
    assert isinstance(soft, PointLight) and isinstance(soft.texture, gltf.ConeCube)
    np.testing.assert_allclose(soft.texture.axis, [0, -1, 0], atol=1e-12)
    assert isinstance(hard, SpotLight) and hard.texture is None and hard.cone_deg == pytest.approx(math.degrees(1.5))
    code, out = run_cli("render", path, "-o", tmp_path / "wide.npy", *SMALL)
    assert code == 0, out
    assert np.load(tmp_path / "wide.npy").max() > 0
    # Under a turning node the cube turns with it, frame by frame.
    holder = b.node(name="turner")
    b.doc["scenes"][0]["nodes"].remove(1)
    b.doc["nodes"][holder]["children"] = [1]
    b.animate(holder, "rotation", [0, 1], [quaternion([0, 0, 1], 0), quaternion([0, 0, 1], 90)])
    scene = load_scene(_write(tmp_path, b, "turning.glb"), ["gltf.fps=4"])
    end = next(light for light in scene.animation.scene_at(scene, 4).lights if isinstance(light, PointLight))
    np.testing.assert_allclose(end.texture.axis, [1, 0, 0], atol=1e-9)  # -y turned a quarter about +z
    assert end.texture.inner == 1.0 and end.texture.outer == math.pi / 2


def test_a_cone_cube_renders_as_the_spot_texture_where_both_serve(tmp_path):
    """On the device: an 80° soft spot as a spot with its planar falloff texture and as a
    point light with the cone cube give the same image within 1 % relative RMSE (the cube's
    faces are read the way they are written)."""
    import dataclasses

    import clrays
    from clrays.reference.metrics import image_error

    b = GltfBuilder()
    b.node(mesh=b.mesh(*FLOOR))
    b.node(mesh=b.mesh(*_shared_corner_box()), translation=[0.5, 0.5, 0])
    b.node(extensions=light_ref(b.light(type="spot", intensity=20 * 683, spot={"innerConeAngle": math.radians(30),
                                                                               "outerConeAngle": math.radians(80)})),
           translation=[-0.5, 2.5, 0.3], rotation=quaternion([1, 0, 0.4], -80))
    b.node(camera=b.camera(math.radians(50)), translation=[0, 2.5, 6], rotation=quaternion([1, 0, 0], -20))
    scene = load_scene(_write(tmp_path, b), ["image.width=64", "image.height=40"])
    spot = scene.lights[0]
    assert isinstance(spot, SpotLight) and spot.texture is not None
    cube = PointLight(position=spot.position, intensity=spot.intensity,
                      texture=gltf.cone_cube(math.radians(30), math.radians(80), spot.direction))
    reference = clrays.render(scene, method="minmax", reuse=False)
    image = clrays.render(dataclasses.replace(scene, lights=(cube,)), method="minmax", reuse=False)
    error = image_error(image, reference)
    print(f"80° soft spot, cone cube against the spot's texture: {error}")
    assert error.pixels > 1500 and error.rmse < 0.01, error


# --------------------------------------------------------------------------- extensions and what is not rendered


def test_required_material_extensions_render_with_a_notice(tmp_path):
    """Required extensions that only change materials render, with one notice naming
    them; an unknown required extension is still refused by name."""
    b = _floor_and_cube(GltfBuilder())
    b.node(extensions=light_ref(b.light(type="point", intensity=50 * 683)), translation=[0, 4, 0])
    b.doc["extensionsRequired"] = ["KHR_lights_punctual", "KHR_texture_transform", "KHR_materials_emissive_strength"]
    path = _write(tmp_path, b)
    code, out = run_cli("render", path, "-o", tmp_path / "m.npy", "--set", "medium.sigma_s=0.1", *SMALL)
    assert code == 0, out
    assert out.count("KHR_texture_transform") == 1 and [line for line in out.splitlines() if "requires" in line] == [
        f"clrays: notice: {path}: requires KHR_texture_transform, KHR_materials_emissive_strength, which only change "
        f"materials: rendered with clrays's diffuse surfaces (albedo = baseColorFactor × the base colour texture's "
        f"mean)"], out
    b.doc["extensionsRequired"].append("EXT_some_geometry")
    with pytest.raises(SceneError, match=r"extensionsRequired: expected only extensions clrays reads .* or that only "
                                         r"change materials, got EXT_some_geometry$"):
        load_scene(_write(tmp_path, b, "unknown.glb"))


def test_what_is_not_rendered_is_said_with_verbose(tmp_path):
    """Points and lines, emission, alpha, material extensions and the cameras not chosen:
    one line with --verbose, none without."""
    b = _floor_and_cube(GltfBuilder())
    b.node(extensions=light_ref(b.light(type="point", intensity=50 * 683)), translation=[0, 4, 0])
    lines = b.mesh([[0, 0, 0], [1, 1, 1]], [[0, 1]])
    b.doc["meshes"][lines]["primitives"][0]["mode"] = 1
    b.node(mesh=lines)
    b.doc["materials"][0]["emissiveFactor"] = [1.0, 0.5, 0.0]
    b.doc["materials"][1]["alphaMode"] = "BLEND"
    b.doc["materials"][1]["extensions"] = {"KHR_materials_transmission": {"transmissionFactor": 1.0}}
    b.node(camera=b.camera(math.radians(40)), translation=[0, 1, 6])
    b.node(camera=b.camera(math.radians(30)), translation=[0, 2, 6])
    path = _write(tmp_path, b)
    arguments = ("render", path, "-o", tmp_path / "v.npy", "--set", "medium.sigma_s=0.1", *SMALL)
    code, out = run_cli(*arguments)
    assert code == 0 and "not rendered" not in out, out
    code, out = run_cli(*arguments, "--verbose")
    assert code == 0, out
    said = [line for line in out.splitlines() if "not rendered" in line]
    assert said == [f"clrays: notice: {path}: not rendered: 1 point or line primitive(s) (meshes.2.primitives.0: no "
                    f"surface); emission (materials.0: surfaces do not glow); alphaMode (materials.1: every surface "
                    f"is opaque); KHR_materials_transmission; 1 camera(s) not chosen (--camera 0 to 1)"], out


def test_a_180_degree_spot_as_blender_writes_it_in_float32(tmp_path):
    """Blender writes a 180° spot's half-angle from float32: 1.5707963705 > π/2. It is π/2,
    and inner = outer there is the hard cone."""
    b = GltfBuilder()
    b.node(mesh=b.mesh(*FLOOR))
    half = float(np.float32(np.float32(math.pi) / 2))
    assert half > math.pi / 2
    b.node(extensions=light_ref(b.light(type="spot", intensity=683, spot={"innerConeAngle": half,
                                                                          "outerConeAngle": half})),
           translation=[0, 3, 0], rotation=quaternion([1, 0, 0], -90))
    spot = load_scene(_write(tmp_path, b)).lights[0]
    assert isinstance(spot, SpotLight) and spot.cone_deg == 90.0 and spot.texture is None
