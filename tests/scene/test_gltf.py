"""glTF 2.0 scenes (clrays/scene/gltf.py, docs/scene-format.md "glTF 2.0 scenes"): what is
read (the node hierarchy, index types, normals, colours, lights, cameras, animation), the
files' forms (.glb, .gltf with a .bin or a data URI), a YAML scene importing one, and
hostile files refused in one line."""
from __future__ import annotations

import base64
import copy
import importlib.util
import io
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli
from clrays.errors import SceneError
from clrays.scene import gltf
from clrays.scene.load import load_scene, parse_scene
from clrays.scene.transforms import quat_to_matrix

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("make_gltf_example", ROOT / "tools" / "make_gltf_example.py")
tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tool)
GltfBuilder, light_ref, quaternion, box = tool.GltfBuilder, tool.light_ref, tool.quaternion, tool.box

SMALL = ["image.width=32", "image.height=18"]
TRIANGLE = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _sorted_triangles(triangles: np.ndarray) -> np.ndarray:
    """Triangles as a set: each one's vertices in a canonical rotation, then sorted rows."""
    t = np.round(np.asarray(triangles, float).reshape(-1, 3, 3), 6)
    keys = []
    for tri in t:
        k = int(np.lexsort(tri.T[::-1])[0])
        keys.append(np.roll(tri, -k, axis=0).reshape(-1))
    keys = np.array(keys)
    return keys[np.lexsort(keys.T[::-1])]


def _write(tmp_path, builder: GltfBuilder, name="scene.glb", document=None) -> Path:
    path = tmp_path / name
    path.write_bytes(builder.glb(document))
    return path


def _lit(builder: GltfBuilder) -> GltfBuilder:
    """A point light of 50 W/sr (in candela, × 683 lm/W), so a file of meshes alone renders."""
    builder.node(extensions=light_ref(builder.light(type="point", intensity=50.0 * 683)), translation=[0, 5, 0])
    return builder


# --------------------------------------------------------------------------- what is read


def test_the_example_is_what_the_tool_writes_and_trimesh_reads_its_geometry():
    """scenes/colonnade.glb is tools/make_gltf_example.py's output, and trimesh (an
    independent reader) finds the same world-space triangles in it."""
    import trimesh

    assert (ROOT / "scenes" / "colonnade.glb").read_bytes() == tool.colonnade().glb()
    scene = load_scene(ROOT / "scenes" / "colonnade.glb")
    other = trimesh.load(ROOT / "scenes" / "colonnade.glb").to_mesh()
    np.testing.assert_allclose(_sorted_triangles(scene.geometry.triangles),
                               _sorted_triangles(other.vertices[other.faces]), atol=2e-6)
    assert (scene.image.width, scene.image.height) == gltf.DEFAULT_IMAGE


def test_node_hierarchy_trs_and_matrix(tmp_path):
    """A mesh under a TRS parent and a matrix child lands where the product of their
    matrices (column vectors, parent first; quaternions x, y, z, w) puts it."""
    b = _lit(GltfBuilder())
    mesh = b.mesh(TRIANGLE, [[0, 1, 2]])
    q = quaternion([1, 2, 3], 40.0)
    parent = b.node(translation=[1, 2, 3], rotation=q, scale=[2, 1, 0.5])
    child_matrix = np.eye(4)
    child_matrix[:3, :3] = quat_to_matrix([math.cos(0.3), 0, math.sin(0.3), 0])
    child_matrix[:3, 3] = [0.5, -1, 2]
    b.node(parent, mesh=mesh, matrix=child_matrix.T.reshape(-1).tolist())  # column-major
    scene = load_scene(_write(tmp_path, b))
    parent_matrix = np.eye(4)
    parent_matrix[:3, :3] = quat_to_matrix([q[3], q[0], q[1], q[2]]) @ np.diag([2, 1, 0.5])
    parent_matrix[:3, 3] = [1, 2, 3]
    world = parent_matrix @ child_matrix
    expected = TRIANGLE @ world[:3, :3].T + world[:3, 3]
    np.testing.assert_allclose(_sorted_triangles(scene.geometry.triangles), _sorted_triangles(expected[None]),
                               atol=1e-5)


@pytest.mark.parametrize("component", [5121, 5123, 5125, None])
def test_every_index_type_and_none(tmp_path, component):
    b = _lit(GltfBuilder())
    vertices, normals, faces = box([1, 1, 1])
    if component is None:  # no indices: every three vertices a triangle
        b.mesh(vertices[faces].reshape(-1, 3), np.arange(36).reshape(-1, 3))
        del b.doc["meshes"][-1]["primitives"][0]["indices"]
    else:
        b.mesh(vertices, faces, index_component=component)
    b.node(mesh=0)
    scene = load_scene(_write(tmp_path, b))
    np.testing.assert_allclose(_sorted_triangles(scene.geometry.triangles), _sorted_triangles(vertices[faces]),
                               atol=1e-6)
    assert scene.geometry.outward.tolist() == [1] * 12  # a closed box, wound outward


def test_normals_from_the_file_else_flat(tmp_path):
    """The file's NORMAL where it has one (here tilted on purpose), interpolated; else each
    face's own normal, flat, as the spec requires."""
    b = _lit(GltfBuilder())
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1.0]])
    tilted = np.array([[0, 1, 1], [0, 1, 1], [0, 1, 1], [0, 1, 1.0]]) / math.sqrt(2)
    b.mesh(vertices, [[0, 2, 1], [0, 3, 2]], normals=tilted)
    b.mesh(vertices, [[0, 2, 1], [0, 3, 2]])
    b.node(mesh=0)
    b.node(mesh=1, translation=[0, 0, 5])
    scene = load_scene(_write(tmp_path, b))
    first = scene.geometry.triangles[:, 0, 2] < 2.5
    np.testing.assert_allclose(scene.geometry.normals[first], np.broadcast_to(tilted[0], (2, 3, 3)), atol=1e-6)
    np.testing.assert_allclose(scene.geometry.normals[~first], np.broadcast_to([0, 1, 0], (2, 3, 3)), atol=1e-9)
    assert scene.geometry.smooth[first].all() and not scene.geometry.smooth[~first].any()


def test_base_colour_factor_and_texture_mean(tmp_path):
    """albedo = baseColorFactor's RGB times the linear mean of the base colour texture."""
    from PIL import Image

    b = _lit(GltfBuilder())
    b.mesh(TRIANGLE, [[0, 1, 2]], colour=(0.5, 0.25, 1.0))
    b.node(mesh=0)
    pixels = np.zeros((2, 2, 3), np.uint8)
    pixels[0, 0] = 255  # one white texel of four: linear mean 0.25
    encoded = io.BytesIO()
    Image.fromarray(pixels).save(encoded, format="PNG")
    b.doc["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(encoded.getvalue()).decode()}]
    b.doc["textures"] = [{"source": 0}]
    b.doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    scene = load_scene(_write(tmp_path, b))
    np.testing.assert_allclose(scene.geometry.albedo[0], [0.125, 0.0625, 0.25], atol=1e-6)


def _lights_file(tmp_path) -> Path:
    b = GltfBuilder()
    b.mesh(TRIANGLE, [[0, 1, 2]])
    b.node(mesh=0)
    point = b.light(type="point", color=[1.0, 0.5, 0.25], intensity=80.0 * 683, range=10.0)  # cd: 80 W/sr
    spot = b.light(type="spot", intensity=200.0 * 683, spot={"innerConeAngle": 0.2, "outerConeAngle": 0.6})
    sun = b.light(type="directional", intensity=3.0 * 683)  # lux: 3 W/m²
    holder = b.node(translation=[0, 4, 0], rotation=quaternion([1, 0, 0], -90.0))  # -Z turned to -Y
    b.node(holder, extensions=light_ref(point), translation=[1, 0, 0])
    b.node(holder, extensions=light_ref(spot))
    b.node(extensions=light_ref(sun), rotation=quaternion([0, 1, 0], 90.0))  # -Z turned to -X
    return _write(tmp_path, b)


def test_lights_carry_their_numbers_and_their_nodes(tmp_path):
    """cd / 683 is W/sr, lux / 683 is W/m², colour multiplies; positions and the -Z axis come from the
    nodes; the spot's cone is its outer angle and its falloff a texture."""
    scene = load_scene(_lights_file(tmp_path))
    point, spot, sun = scene.lights
    np.testing.assert_allclose(point.intensity, [80, 40, 20])
    np.testing.assert_allclose(point.position, [1, 4, 0], atol=1e-12)
    np.testing.assert_allclose(spot.intensity, [200] * 3)
    np.testing.assert_allclose(spot.direction, [0, -1, 0], atol=1e-12)
    assert spot.cone_deg == pytest.approx(math.degrees(0.6))
    np.testing.assert_allclose(sun.irradiance, [3] * 3)
    np.testing.assert_allclose(sun.direction, [-1, 0, 0], atol=1e-12)
    scaled = load_scene(_lights_file(tmp_path), ["gltf.light_scale=0.01"])
    np.testing.assert_allclose(scaled.lights[0].intensity, [0.8, 0.4, 0.2])
    np.testing.assert_allclose(scaled.lights[2].irradiance, [0.03] * 3)


def test_the_falloff_texture_follows_the_spec_attenuation():
    """The spot texture, looked up as every method looks it up (bilinear between texel
    centres, clrays.physics.light_texture), is KHR_lights_punctual's smoothstep-like
    attenuation of the ray's angle: within 2e-3 at the inner cone's kink, 1e-4 elsewhere."""
    from clrays.physics.light_texture import light_texture
    from clrays.scene.model import SpotLight

    inner, outer = math.radians(10), math.radians(40)
    light = SpotLight(position=np.zeros(3), direction=np.array([0, -1.0, 0]), cone_deg=math.degrees(outer),
                      intensity=np.ones(3), texture=gltf.falloff_texture(inner, outer))
    rng = np.random.default_rng(3)
    angles = rng.uniform(0, outer, 4000)
    azimuths = rng.uniform(0, 2 * math.pi, 4000)
    points = np.stack([np.sin(angles) * np.cos(azimuths), -np.cos(angles), np.sin(angles) * np.sin(azimuths)], 1)
    looked_up = light_texture(light, points * 3.0)[:, 0]
    expected = gltf.spot_attenuation(np.cos(angles), inner, outer)
    near_kink = np.abs(angles - inner) < math.radians(0.3)
    assert np.abs(looked_up - expected)[near_kink].max() < 2e-3
    assert np.abs(looked_up - expected)[~near_kink].max() < 1e-4


def test_cameras_first_named_and_default(tmp_path):
    b = _lit(GltfBuilder())
    b.mesh(TRIANGLE, [[0, 1, 2]])
    b.node(mesh=0, translation=[0, 0, -2])
    first = b.camera(math.radians(40), zfar=30.0, name="wide")
    second = b.camera(math.radians(20), name="tele")
    b.node(camera=first, translation=[0, 1, 5])
    b.node(camera=second, name="tele_node", translation=[2, 0, 5], rotation=quaternion([0, 1, 0], 30.0))
    path = _write(tmp_path, b)
    camera = load_scene(path).camera
    assert camera.fov_deg == pytest.approx(40) and camera.far == 30.0
    np.testing.assert_allclose(camera.look_at - camera.position, [0, 0, -1], atol=1e-12)
    for name in ("tele", "tele_node"):
        tele = load_scene(path, [f"gltf.camera={name}"]).camera
        assert tele.fov_deg == pytest.approx(20) and tele.far == 1000.0
        np.testing.assert_allclose(tele.look_at - tele.position, [-0.5, 0, -math.sqrt(3) / 2], atol=1e-12)
    code, out = run_cli("render", path, "--camera", "tele", "-o", tmp_path / "t.npy", *sum((["--set", s] for s in SMALL), []))
    assert code == 0, out
    # No camera: the default view of the bounds (from +z and above, at the centre).
    del b.doc["cameras"]
    for node in b.doc["nodes"]:
        node.pop("camera", None)
    lone = load_scene(_write(tmp_path, b, "lone.glb")).camera
    centre = np.array([0.5, 0.5, -2.0])
    np.testing.assert_allclose(lone.look_at, centre, atol=1e-12)
    direction = (lone.position - centre) / np.linalg.norm(lone.position - centre)
    np.testing.assert_allclose(direction, gltf.DEFAULT_VIEW_DIRECTION, atol=1e-12)


def test_gltf_with_an_external_bin_and_with_a_data_uri(tmp_path):
    b = _lit(GltfBuilder())
    vertices, _, faces = box([1, 2, 3])
    b.mesh(vertices, faces)
    b.node(mesh=0, translation=[1, 0, 0])
    reference = load_scene(_write(tmp_path, b)).geometry.triangles
    document = copy.deepcopy(b.doc)
    document["buffers"] = [{"byteLength": len(b.binary), "uri": "parts/mesh%20data.bin"}]
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "mesh data.bin").write_bytes(bytes(b.binary))
    (tmp_path / "scene.gltf").write_text(json.dumps(document))
    np.testing.assert_array_equal(load_scene(tmp_path / "scene.gltf").geometry.triangles, reference)
    document["buffers"] = [{"byteLength": len(b.binary), "uri": "data:application/octet-stream;base64,"
                            + base64.b64encode(bytes(b.binary)).decode()}]
    (tmp_path / "inline.gltf").write_text(json.dumps(document))
    np.testing.assert_array_equal(load_scene(tmp_path / "inline.gltf").geometry.triangles, reference)


def test_a_yaml_scene_imports_a_gltf_and_adds_its_own(tmp_path):
    """`gltf: {file}` brings meshes, lights and the camera; the YAML adds the medium, its
    own objects and lights (first), and its camera replaces the file's."""
    _lights_file(tmp_path)
    text = """
version: 1
image: {width: 32, height: 18}
gltf: {file: scene.glb, light_scale: 2}
medium: {sigma_s: 0.1}
lights: [{type: point, position: [0, 9, 0], intensity: 5}]
objects: [{type: box, min: [-1, -1, -1], max: [1, 1, 1]}]
"""
    scene = parse_scene(text, tmp_path / "fog.yaml")
    assert [light.type for light in scene.lights] == ["point", "point", "spot", "directional"]
    np.testing.assert_allclose(scene.lights[1].intensity, [160, 80, 40])
    assert scene.geometry.count == 13 and scene.geometry.object_id.tolist() == [0] * 12 + [1]
    np.testing.assert_allclose(scene.medium.sigma_s, 0.1)
    own = parse_scene(text + "camera: {position: [0, 0, 9], look_at: [0, 0, 0]}\n", tmp_path / "fog.yaml")
    np.testing.assert_allclose(own.camera.position, [0, 0, 9])
    with pytest.raises(SceneError, match=r"gltf.camera: expected no gltf.camera beside the scene's own camera"):
        parse_scene(text + "camera: {position: [0, 0, 9], look_at: [0, 0, 0]}\n", tmp_path / "fog.yaml",
                    ["gltf.camera=x"])
    with pytest.raises(SceneError, match=r"missing required key 'camera'"):
        parse_scene(text.replace("gltf: {file: scene.glb, light_scale: 2}\n", ""), tmp_path / "fog.yaml")


def test_the_example_renders_from_the_command_line(tmp_path):
    code, out = run_cli("render", ROOT / "scenes" / "colonnade.yaml", "-o", tmp_path / "c.npy",
                        *sum((["--set", s] for s in SMALL), []))
    assert code == 0, out
    image = np.load(tmp_path / "c.npy")
    assert np.isfinite(image).all() and image.max() > 0


# --------------------------------------------------------------------------- animation


def _moving_box() -> GltfBuilder:
    """A box as the child (offset [0, 0.5, 0]) of a node that turns and moves: rotation keys
    at 0, 1 and 2 s, translation keys at 0 and 2 s, LINEAR."""
    b = _lit(GltfBuilder())
    vertices, _, faces = box([0.5, 0.3, 0.4])
    b.mesh(vertices, faces)
    mover = b.node(name="mover")
    b.node(mover, mesh=0, translation=[0, 0.5, 0])
    b.node(mesh=b.mesh([[-4, -1, -4], [4, -1, -4], [4, -1, 4], [-4, -1, 4]], [[0, 2, 1], [0, 3, 2]]))
    b.animate(mover, "rotation", [0, 1, 2], [quaternion([0, 1, 0], 0), quaternion([0, 1, 1], 80),
                                             quaternion([1, 1, 0], 200)])
    b.animate(mover, "translation", [0, 2], [[0, 0, 0], [1.5, 0.5, -1]])
    b.node(camera=b.camera(math.radians(45)), translation=[0, 1, 6])
    return b


def _moving_box_yaml(tmp_path) -> str:
    """The same motion as YAML keyframes at 12 fps: the box's vertices with the child's
    offset baked in, a `triangles` object, translate and rotate keys at frames 0, 12, 24."""
    vertices, _, faces = box([0.5, 0.3, 0.4])
    vertices = vertices + [0, 0.5, 0]

    def q(axis, angle):  # YAML's quaternion is [w, x, y, z]
        x, y, z, w = quaternion(axis, angle)
        return [w, x, y, z]

    return f"""
version: 1
image: {{width: 48, height: 32}}
camera: {{position: [0, 1, 6], look_at: [0, 1, 5], fov_deg: 45, near: 0.05}}
lights: [{{type: point, position: [0, 5, 0], intensity: 50}}]
medium: {{sigma_s: 0.08}}
objects:
  - {{type: triangles, vertices: {json.dumps(vertices.tolist())}, faces: {json.dumps(faces.tolist())}}}
  - {{type: triangles, vertices: [[-4, -1, -4], [4, -1, -4], [4, -1, 4], [-4, -1, 4]], faces: [[0, 2, 1], [0, 3, 2]]}}
animation:
  frames: [0, 24]
  fps: 12
  objects:
    - object: 0
      keys:
        - {{frame: 0, translate: [0, 0, 0], rotate: {{quaternion: {q([0, 1, 0], 0)}}}}}
        - {{frame: 12, rotate: {{quaternion: {q([0, 1, 1], 80)}}}}}
        - {{frame: 24, translate: [1.5, 0.5, -1], rotate: {{quaternion: {q([1, 1, 0], 200)}}}}}
"""


def test_a_gltf_animation_renders_as_the_same_motion_in_yaml_keyframes(tmp_path):
    """A turning and moving node (SLERP of its quaternions, LINEAR translation) is the
    same motion as YAML keyframes at `gltf.fps`: the same triangles every frame, and the
    same images."""
    import clrays

    path = _write(tmp_path, _moving_box())
    moving = load_scene(path, ["gltf.fps=12", "medium.sigma_s=0.08", "image.width=48", "image.height=32"])
    keyed = parse_scene(_moving_box_yaml(tmp_path), tmp_path / "keyed.yaml")
    assert (moving.animation.first, moving.animation.last) == (0, 24)
    for frame in range(0, 25):
        a = moving.animation.scene_at(moving, frame).geometry.triangles
        b = keyed.animation.scene_at(keyed, frame).geometry.triangles
        np.testing.assert_allclose(_sorted_triangles(a), _sorted_triangles(b), atol=2e-6, err_msg=f"frame {frame}")
    for frame in (7, 18):
        a = clrays.render(moving.animation.scene_at(moving, frame), method="raymarch", reuse=False)
        b = clrays.render(keyed.animation.scene_at(keyed, frame), method="raymarch", reuse=False)
        assert np.abs(a - b).max() <= 1e-3 * b.max(), f"frame {frame}"
    code, out = run_cli("sequence", path, "-o", str(tmp_path / "f_{:02d}.npy"), "--frames", "0:2",
                        "--set", "gltf.fps=12", *sum((["--set", s] for s in SMALL), []))
    assert code == 0, out
    assert sorted(p.name for p in tmp_path.glob("f_*.npy")) == ["f_00.npy", "f_01.npy", "f_02.npy"]


@pytest.mark.parametrize("interpolation", ["STEP", "CUBICSPLINE"])
def test_step_and_cubic_spline_channels(tmp_path, interpolation):
    b = _lit(GltfBuilder())
    b.mesh(TRIANGLE, [[0, 1, 2]])
    mover = b.node(mesh=0)
    if interpolation == "STEP":
        b.animate(mover, "translation", [0, 1], [[0, 0, 0], [2, 0, 0]], "STEP")
        expected = {0: 0.0, 11: 0.0, 12: 2.0, 13: 2.0}
    else:  # in-tangent, value, out-tangent per key; tangents 0 make a smoothstep from 0 to 2
        b.animate(mover, "translation", [0, 1], [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [2, 0, 0], [0, 0, 0]],
                  "CUBICSPLINE")
        expected = {0: 0.0, 6: 1.0, 3: 2 * (3 * 0.25 ** 2 - 2 * 0.25 ** 3), 12: 2.0}
    scene = load_scene(_write(tmp_path, b), ["gltf.fps=12"])
    for frame, x in expected.items():
        moved = scene.animation.scene_at(scene, frame).geometry.triangles
        assert moved[:, :, 0].min() == pytest.approx(x, abs=1e-6), frame


# --------------------------------------------------------------------------- hostile files


def _hostile(tmp_path, change) -> Path:
    """A valid file (a box, a light, a camera), then `change(document, builder)`."""
    b = _lit(GltfBuilder())
    vertices, _, faces = box([1, 1, 1])
    b.mesh(vertices, faces)
    b.node(mesh=0)
    document = copy.deepcopy(b.doc)
    result = change(document, b)
    if isinstance(result, bytes):
        path = tmp_path / "bad.glb"
        path.write_bytes(result)
        return path
    return _write(tmp_path, b, "bad.glb", document)


def _set(path: str, value):
    def change(document, _builder):
        keys = path.split(".")
        node = document
        for key in keys[:-1]:
            node = node[int(key)] if isinstance(node, list) else node[key]
        node[int(keys[-1]) if isinstance(node, list) else keys[-1]] = value
    return change


def _with_nan(document, builder):
    builder.binary[0:4] = np.float32(np.nan).tobytes()  # the first POSITION coordinate


def _cycle(document, _builder):
    document["nodes"] += [{"children": [3]}, {"children": [2]}]


def _two_parents(document, _builder):
    document["nodes"] += [{"children": [4]}, {"children": [4]}, {}]


def _truncated(document, builder):
    data = builder.glb(document)
    return data[:-40]


def _buffer_past_the_end(document, builder):
    data = bytearray(builder.glb(document))
    # the BIN chunk's length field says more than the file holds
    json_length = int.from_bytes(data[12:16], "little")
    at = 20 + json_length
    data[at:at + 4] = (len(data)).to_bytes(4, "little")
    return bytes(data)


def _far_node(document, _builder):
    document["nodes"][-1]["translation"] = [1e13, 0.0, 0.0]  # finite in float32, too far for its products


def _keys_for_ages(document, builder):
    """A translation key at 1e30 s: at 24 fps, more frames than any sequence may have."""
    builder.doc = document
    builder.animate(len(document["nodes"]) - 1, "translation", [0.0, 1e30], [[0, 0, 0], [1, 0, 0]])


def _far_key(document, builder):
    """The mesh's node moved 1e13 away at its second key: finite in float32, too far for the device."""
    builder.doc = document
    builder.animate(len(document["nodes"]) - 1, "translation", [0.0, 1.0], [[0, 0, 0], [1e13, 0, 0]])


def _camera_scaled_to_nothing(document, builder):
    """A camera whose node's scale goes to 0: its direction would be 0/0 at that frame."""
    builder.doc = document
    camera = builder.node(camera=builder.camera(0.8), translation=[0, 1, 6])
    builder.animate(camera, "scale", [0.0, 1.0], [[1, 1, 1], [0, 0, 0]])


def _bomb_texture(document, _builder):
    """A base colour texture whose PNG header claims 20000 × 20000 texels (PIL's own bomb
    limit is below that: it refuses at the header, which must still be one line)."""
    import tempfile

    from test_hostile import png_claiming

    with tempfile.TemporaryDirectory() as folder:
        data = png_claiming(Path(folder) / "bomb.png", 20000, 20000).read_bytes()
    document["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(data).decode()}]
    document["textures"] = [{"source": 0}]
    document["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    for mesh in document["meshes"]:
        for primitive in mesh["primitives"]:
            primitive["material"] = 0


HOSTILE = {
    "vertices beyond float32's safe range": (_far_node, r"meshes: expected world-space coordinates within ±1e\+12.*got "),
    "lying count": (_set("accessors.0.count", 1000), r"accessors\.0\.count: expected at most 24 elements.*got 1000"),
    "lying offset": (_set("accessors.0.byteOffset", 4000), r"accessors\.0\.count: expected at most 0 elements"),
    "view past its buffer": (_set("bufferViews.0.byteLength", 10 ** 6),
                             r"bufferViews\.0\.byteLength: expected a view within its buffer's \d+ bytes"),
    "buffer longer than its data": (_set("buffers", [{"byteLength": 10 ** 6}]), None),
    "BIN chunk past the file's end": (_buffer_past_the_end, r"\(GLB chunk at byte \d+\): expected a length within"),
    "truncated file": (_truncated, r"\(GLB header\): expected the file's length"),
    "uri leaves the folder": (_set("buffers", [{"byteLength": 4, "uri": "../secret.bin"}]),
                              r"buffers\.0\.uri: expected a file inside the glTF file's folder, got \"\.\./secret"),
    "absolute uri": (_set("buffers", [{"byteLength": 4, "uri": "/etc/passwd"}]),
                     r"buffers\.0\.uri: expected a relative file path"),
    "NUL in a uri": (_set("buffers", [{"byteLength": 4, "uri": "a%00b.bin"}]),
                     r"buffers\.0\.uri: expected a relative file path inside the glTF file's folder, got \"a%00b"),
    "remote uri": (_set("buffers", [{"byteLength": 4, "uri": "https://example.com/x.bin"}]),
                   r"buffers\.0\.uri: expected a relative file path"),
    "NaN vertex": (_with_nan, r"accessors\.0: expected finite values for meshes\.0\.primitives\.0\.attributes"
                              r"\.POSITION, got \[nan, -1\.0, -1\.0\] at element 0"),
    "cycle": (_cycle, r"nodes\.\d\.children\.0: expected a node with one parent|expected a node hierarchy without"),
    "two parents": (_two_parents, r"nodes\.3\.children\.0: expected a node with one parent \(a tree, not a graph\), "
                                  r"got node 4, already a child of node 2"),
    "required extension": (_set("extensionsRequired", ["EXT_mesh_manifold", "KHR_lights_punctual"]),
                           r"extensionsRequired: expected only extensions clrays reads \(KHR_lights_punctual, .*\) or "
                           r"that only change materials, got EXT_mesh_manifold"),
    "component type": (_set("accessors.0.componentType", 5130), r"accessors\.0\.componentType: expected one of 5126"),
    "sparse accessor": (_set("accessors.0.sparse", {"count": 1}), r"accessors\.0\.sparse: missing required key "
                                                                    r"'indices'"),
    "index beyond the vertices": (_set("accessors.1.componentType", 5126), r"accessors\.1\.componentType"),
    "stride below the element": (_set("bufferViews.0.byteStride", 4), r"bufferViews\.0\.byteStride: expected at "
                                                                        r"least the element's 12 bytes, got 4"),
    "not json": (lambda d, b: b"{not json", r"\(JSON\): expected a glTF 2\.0 document"),
    "version 1": (_set("asset.version", "1.0"), r"asset\.version: expected a glTF 2\.x file, got \"1\.0\""),
    "orthographic camera": (_set("cameras", [{"type": "orthographic", "orthographic": {}}]), None),
    "quaternion not unit": (_set("nodes.1.rotation", [0, 0, 0, 2]), r"nodes\.1\.rotation: expected a unit"),
    "too many lights": (lambda d, b: d.update(nodes=d["nodes"] + [{"extensions": light_ref(0)}] * 256,
                                              scenes=[{"nodes": list(range(258))}]),
                        r"expected at most 256 lights"),
    "too many triangles": (_set("accessors.1.count", 3 * (1 << 21) + 3),
                           r"meshes\.0\.primitives\.0: expected at most 2097152 triangles"),
    "transform past float32": (_set("nodes.1.scale", [1e39, 1, 1]),
                               r"nodes\.1: expected a transform that, with its parents', stays finite in float32, "
                               r"got a world matrix entry of 1e\+39"),
    "power past float32": (_set("extensions.KHR_lights_punctual.lights.0.intensity", 1e35),
                           r"lights\.0\.intensity: expected a power \(intensity / 683 lm/W × color × light_scale\) "
                           r"of at most 1e\+30, got 1\.46e\+32"),
    "a 401-digit integer": (_set("extensions.KHR_lights_punctual.lights.0.intensity", 10 ** 400),
                            r"lights\.0\.intensity: expected a finite number"),
    "keys 1e30 s long": (_keys_for_ages, r"animations: expected at most 100000 frames at gltf\.fps 24, got 1e\+30 s"),
    "an animated translation of 1e13": (_far_key, r"animations: expected poses within ±1e\+12 .*got up to 1e\+13 "
                                                  r"from the origin for the mesh of nodes\.1, bounded from the keys"),
    "a camera scaled to nothing": (_camera_scaled_to_nothing, r"nodes\.\d+: expected a camera node whose animated "
                                                             r"scale leaves it a direction, got a scale that may reach 0, "
                                                             r"bounded from the keys"),
    "a base colour image claiming 20000²": (_bomb_texture, r"images\.0: expected an image with sides of at most 4096"),
    "spot too wide": (_set("extensions.KHR_lights_punctual.lights.0",
                           {"type": "spot", "spot": {"outerConeAngle": 1.58}}),
                      r"spot\.outerConeAngle: expected a finite number in \[0, 1\.5708\], got 1\.58"),
}


@pytest.mark.parametrize("name", list(HOSTILE))
def test_hostile_files_are_refused_in_one_line(tmp_path, name):
    change, pattern = HOSTILE[name]
    if name == "orthographic camera":
        def change(document, builder):  # noqa: F811 - the case needs a node that uses it
            document["cameras"] = [{"type": "orthographic", "orthographic": {}}]
            document["nodes"].append({"camera": 0})
            document["scenes"][0]["nodes"].append(len(document["nodes"]) - 1)
        pattern = r"cameras\.0\.type: expected a perspective camera .*got \"orthographic\""
    if name == "buffer longer than its data":
        pattern = r"buffers\.0\.byteLength: expected at most the \d+ bytes the buffer holds, got 1000000"
    path = _hostile(tmp_path, change)
    code, out = run_cli("render", path, "-o", tmp_path / "x.png", *sum((["--set", s] for s in SMALL), []))
    assert code == 1, out
    assert out.count("\n") == 1 and out.startswith(f"clrays: error: {path}: "), out
    assert __import__("re").search(pattern, out), out


def test_a_symlink_out_of_the_folder_is_refused(tmp_path):
    (tmp_path / "outside.bin").write_bytes(b"\0" * 64)
    (tmp_path / "inner").mkdir()
    (tmp_path / "inner" / "link.bin").symlink_to(tmp_path / "outside.bin")
    b = _lit(GltfBuilder())
    b.mesh(TRIANGLE, [[0, 1, 2]])
    b.node(mesh=0)
    document = copy.deepcopy(b.doc)
    document["buffers"] = [{"byteLength": 64, "uri": "link.bin"}]
    (tmp_path / "inner" / "x.gltf").write_text(json.dumps(document))
    with pytest.raises(SceneError, match=r"buffers\.0\.uri: expected a file inside the glTF file's folder"):
        load_scene(tmp_path / "inner" / "x.gltf")


def test_a_huge_data_uri_is_refused_before_it_is_decoded(tmp_path, monkeypatch):
    monkeypatch.setattr(gltf, "MAX_GLTF_BYTES", 3000)
    b = _lit(GltfBuilder())
    b.mesh(TRIANGLE, [[0, 1, 2]])
    b.node(mesh=0)
    document = copy.deepcopy(b.doc)
    document["buffers"] = [{"byteLength": 4, "uri": "data:application/octet-stream;base64," + "A" * 8000}]
    (tmp_path / "x.gltf").write_text(json.dumps(document))
    with pytest.raises(SceneError, match=r"buffers\.0\.uri: expected a data URI of at most .* got 8000 base64"):
        load_scene(tmp_path / "x.gltf")


_PEAK = """
import resource, sys, time
from clrays.errors import SceneError
from clrays.scene.load import load_scene
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
start = time.perf_counter()
try:
    load_scene(sys.argv[1])
    print("loaded")
except SceneError as exc:
    print(str(exc))
print(time.perf_counter() - start, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 - before)
"""


def test_a_file_claiming_millions_of_triangles_is_refused_quickly_and_small(tmp_path):
    """Counts are checked against the limits and the bytes before anything is allocated:
    a small file asking for 100 million triangles by one accessor, in a fresh process,
    stops within 2 s, its peak memory less than 50 MB above the imports'."""
    path = _hostile(tmp_path, _set("accessors.1.count", 300_000_000))
    done = subprocess.run([sys.executable, "-c", _PEAK, str(path)], capture_output=True, text=True, timeout=60,
                          cwd=ROOT)
    message, numbers = done.stdout.strip().splitlines()
    seconds, grown_mb = map(float, numbers.split())
    assert "expected at most 2097152 triangles" in message
    assert seconds < 2 and grown_mb < 50, (seconds, grown_mb)


# --------------------------------------------------------------------------- an independent exporter


YARDSTICK = """
version: 1
image: {width: 64, height: 40}
camera: {position: [1, 3, 8], look_at: [0, 1, 0], up: [0, 1, 0], fov_deg: 45, far: 30, near: 0.1}
lights:
  - {type: point, position: [-2, 4, 1], intensity: [40, 30, 20]}
  - {type: spot, position: [1.5, 5, 0.5], direction: [-0.2, -1, -0.1], cone_deg: 25, intensity: 120}
  - {type: directional, direction: [-0.3, -1, -0.2], irradiance: 0.5}
medium: {sigma_s: 0.08, sigma_a: 0.01}
objects:
  - {type: box, min: [-5, -0.1, -5], max: [5, 0, 5], albedo: 0.6}
  - type: box
    min: [-0.5, -0.5, -0.5]
    max: [0.5, 0.5, 0.5]
    albedo: [0.8, 0.2, 0.4]
    transform: {translate: [0.5, 1.2, 0], rotate: {quaternion: QUATERNION}, scale: [1, 0.5, 1.5]}
"""


def _frame_quaternion(forward, up=(0.0, 1.0, 0.0)) -> list[float]:
    """glTF [x, y, z, w] of the rotation that turns -Z to `forward` (and +Y towards `up`)."""
    from clrays.scene.transforms import matrix_to_quat

    back = -np.asarray(forward, float) / np.linalg.norm(forward)
    helper = np.asarray(up, float) if abs(np.dot(back, up)) < 0.99 else np.array([1.0, 0, 0])
    right = np.cross(helper, back)
    right /= np.linalg.norm(right)
    w, x, y, z = matrix_to_quat(np.stack([right, np.cross(back, right), back], axis=1))
    return [x, y, z, w]


def _trimesh_export(tmp_path, rotation_wxyz) -> Path:
    """The YARDSTICK's geometry as trimesh writes it (a scene graph: a floor, and the box
    under a group node, each placed by a matrix), then its lights and camera added to the
    JSON as an exporter of KHR_lights_punctual writes them: lights under a turned and moved
    parent (quaternions), the camera by a matrix."""
    import struct

    import trimesh

    def coloured(mesh, rgb):
        mesh.unmerge_vertices()  # flat faces, as clrays's boxes
        mesh.visual = trimesh.visual.TextureVisuals(
            material=trimesh.visual.material.PBRMaterial(baseColorFactor=[*rgb, 1.0]))
        return mesh

    scene = trimesh.Scene()
    floor = coloured(trimesh.creation.box(extents=[10, 0.1, 10]), [0.6] * 3)
    scene.add_geometry(floor, node_name="floor", transform=trimesh.transformations.translation_matrix([0, -0.05, 0]))
    group = trimesh.transformations.translation_matrix([0.5, 0.2, 0.0])
    scene.graph.update(frame_to="group", frame_from=scene.graph.base_frame, matrix=group)
    box_matrix = np.eye(4)
    box_matrix[:3, :3] = quat_to_matrix(rotation_wxyz) @ np.diag([1, 0.5, 1.5])
    box_matrix[:3, 3] = [0, 1.0, 0]
    scene.add_geometry(coloured(trimesh.creation.box(extents=[1, 1, 1]), [0.8, 0.2, 0.4]), node_name="box",
                       parent_node_name="group", transform=box_matrix)
    data = scene.export(file_type="glb")
    json_length = struct.unpack_from("<I", data, 12)[0]
    document = json.loads(data[20:20 + json_length])
    binary = data[20 + json_length + 8:]

    document["extensionsUsed"] = ["KHR_lights_punctual"]
    document["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"type": "point", "color": [1.0, 0.75, 0.5], "intensity": 40.0 * 683},  # cd, lux: W × 683 lm/W
        {"type": "spot", "intensity": 120.0 * 683, "spot": {"innerConeAngle": math.radians(25),
                                                            "outerConeAngle": math.radians(25)}},
        {"type": "directional", "intensity": 0.5 * 683}]}}
    nodes = document["nodes"]
    parent_q = quaternion([0, 1, 0], 70.0)
    parent_t = np.array([0.3, 0.5, -0.2])
    parent_r = quat_to_matrix([parent_q[3], *parent_q[:3]])
    holder = len(nodes)
    nodes.append({"name": "lights", "translation": parent_t.tolist(), "rotation": parent_q, "children": []})
    for index, (position, direction) in enumerate(([[-2, 4, 1], None], [[1.5, 5, 0.5], [-0.2, -1, -0.1]],
                                                   [[0, 0, 0], [-0.3, -1, -0.2]])):
        world_rotation = quat_to_matrix(np.roll(_frame_quaternion(direction), 1)) if direction else np.eye(3)
        local_rotation = parent_r.T @ world_rotation
        from clrays.scene.transforms import matrix_to_quat

        w, x, y, z = matrix_to_quat(local_rotation)
        nodes[holder]["children"].append(len(nodes))
        nodes.append({"translation": (parent_r.T @ (np.array(position, float) - parent_t)).tolist(),
                      "rotation": [x, y, z, w], "extensions": {"KHR_lights_punctual": {"light": index}}})
    eye, target = np.array([1.0, 3, 8]), np.array([0.0, 1, 0])
    camera = np.eye(4)
    camera[:3, :3] = quat_to_matrix(np.roll(_frame_quaternion(target - eye), 1))
    camera[:3, 3] = eye
    document["cameras"] = [{"type": "perspective", "perspective": {"yfov": math.radians(45), "zfar": 30.0,
                                                                    "znear": 0.1, "aspectRatio": 1.6}}]
    nodes.append({"name": "eye", "camera": 0, "matrix": camera.T.reshape(-1).tolist()})
    document["scenes"][0]["nodes"] += [holder, len(nodes) - 1]
    builder = GltfBuilder()
    builder.binary = bytearray(binary)
    path = tmp_path / "exported.glb"
    path.write_bytes(builder.glb(document))
    return path


@pytest.mark.parametrize("method", ["minmax", "exact"])
def test_a_scene_exported_by_trimesh_renders_as_its_yaml(tmp_path, method):
    """A glTF file written by another exporter (trimesh: node hierarchy, matrices, PBR
    colours; lights and camera added as KHR_lights_punctual and a camera node, with
    quaternions) renders within 0.5 % relative RMSE of the YAML scene it was made from."""
    import clrays
    from clrays.reference.metrics import image_error

    rotation = np.array([math.cos(0.35), 0.3 * math.sin(0.35), math.sin(0.35) * math.sqrt(0.91), 0.0])
    rotation /= np.linalg.norm(rotation)
    yaml_scene = parse_scene(YARDSTICK.replace("QUATERNION", json.dumps(rotation.tolist())), tmp_path / "y.yaml")
    path = _trimesh_export(tmp_path, rotation)
    gltf_scene = load_scene(path, ["image.width=64", "image.height=40", "medium.sigma_s=0.08",
                                   "medium.sigma_a=0.01"])
    for mine, theirs in zip(gltf_scene.lights, yaml_scene.lights):
        assert mine.type == theirs.type
        for name in ("position", "direction", "intensity", "irradiance"):
            if hasattr(theirs, name):
                np.testing.assert_allclose(getattr(mine, name), getattr(theirs, name), atol=1e-6, err_msg=name)
    reference = clrays.render(yaml_scene, method=method, reuse=False)
    image = clrays.render(gltf_scene, method=method, reuse=False)
    error = image_error(image, reference)
    print(f"trimesh export against its YAML, {method}: {error}")
    assert error.pixels > 1000 and error.rmse < 0.005, error


def test_the_scene_limits_apply_to_gltf_files(tmp_path, monkeypatch):
    """File size, nodes, placed primitives (objects) and triangles with a YAML scene's own:
    each refused in one line naming the limit (the limits lowered, so the files stay small)."""
    b = _lit(GltfBuilder())
    b.mesh(TRIANGLE, [[0, 1, 2]])
    for k in range(3):
        b.node(mesh=0, translation=[k, 0, 0])
    path = _write(tmp_path, b)
    monkeypatch.setattr(gltf, "MAX_OBJECTS", 2)
    with pytest.raises(SceneError, match=r"meshes\.0\.primitives\.0: expected at most 2 placed primitives, each an "
                                         r"object .*got 3 with this one \(placed by nodes\.3\)"):
        load_scene(path)
    monkeypatch.undo()
    monkeypatch.setattr(gltf, "MAX_GLTF_NODES", 3)
    with pytest.raises(SceneError, match=r"scene\.glb: nodes: expected at most 3 entries, got 4 entries"):
        load_scene(path)
    monkeypatch.undo()
    monkeypatch.setattr(gltf, "MAX_GLTF_BYTES", 30)
    with pytest.raises(SceneError, match=r"scene\.glb: buffers\.0: expected buffers of at most 30 bytes in all "
                                         r"\(docs/limits\.md\), got 48 bytes with this one"):
        load_scene(path)
    b.binary += bytes(1 << 20)  # the file itself over the limit (which leaves room for base64 buffers)
    with pytest.raises(SceneError, match=r"big\.glb: cannot read glTF file: 1\.0 MiB, more than the limit of "
                                         r"1\.0 MiB"):
        load_scene(_write(tmp_path, b, "big.glb"))
    monkeypatch.undo()
    monkeypatch.setattr(gltf, "MAX_TRIANGLES", 4)
    text = "version: 1\nimage: {width: 8, height: 8}\ngltf: {file: scene.glb}\nobjects: [{type: box, min: [0, 0, 0], max: [1, 1, 1]}]\n"
    with pytest.raises(SceneError, match=r"scene\.glb: meshes: expected at most 4 triangles with the scene's own, "
                                         r"got 15"):
        parse_scene(text, tmp_path / "y.yaml")


@pytest.mark.parametrize("value, pattern", [
    ("scene.obj", r"gltf\.file: expected a glTF file path \(\.glb or \.gltf\), got 'scene\.obj'"),
    ("missing.glb", r"missing\.glb: cannot read glTF file: No such file or directory"),
])
def test_a_bad_gltf_key_in_yaml(tmp_path, value, pattern):
    with pytest.raises(SceneError, match=pattern):
        parse_scene(f"version: 1\nimage: {{width: 8, height: 8}}\ngltf: {{file: {value}}}\n", tmp_path / "y.yaml")


def test_animated_nodes_carry_their_lights_and_camera(tmp_path):
    """A light and the camera under a moving, turning node go with it, frame by frame."""
    b = GltfBuilder()
    b.mesh(TRIANGLE, [[0, 1, 2]])
    b.node(mesh=0)
    mover = b.node()
    b.node(mover, extensions=light_ref(b.light(type="spot", intensity=10.0,
                                                spot={"innerConeAngle": 0.1, "outerConeAngle": 0.5})),
           translation=[0, 2, 0])
    b.node(mover, camera=b.camera(math.radians(40)), translation=[0, 0, 5])
    b.animate(mover, "translation", [0, 1], [[0, 0, 0], [3, 0, 0]])
    b.animate(mover, "rotation", [0, 1], [quaternion([0, 1, 0], 0), quaternion([0, 1, 0], 90)])
    scene = load_scene(_write(tmp_path, b), ["gltf.fps=10"])
    assert (scene.animation.first, scene.animation.last) == (0, 10)
    end = scene.animation.scene_at(scene, 10)
    np.testing.assert_allclose(end.lights[0].position, [3, 2, 0], atol=1e-9)
    np.testing.assert_allclose(end.lights[0].direction, [-1, 0, 0], atol=1e-9)  # -Z turned a quarter about +y
    np.testing.assert_allclose(end.camera.position, [8, 0, 0], atol=1e-9)
    np.testing.assert_allclose(end.camera.look_at - end.camera.position, [-1, 0, 0], atol=1e-9)
    assert end.lights[0].texture is scene.lights[0].texture  # the falloff moves with the light
    half = scene.animation.scene_at(scene, 5)
    np.testing.assert_allclose(half.camera.position, [1.5 + 5 * math.sin(math.pi / 4), 0, 5 * math.cos(math.pi / 4)],
                               atol=1e-9)


def deep_chain() -> tuple[GltfBuilder, int, int]:
    """A light and 65 535 nodes, each the child of the last and 0.001 along x from it (the
    most a file may have), with a triangle's mesh at the end: (builder, first chain node, count)."""
    b = _lit(GltfBuilder())
    b.mesh(TRIANGLE, [[0, 1, 2]])
    count = gltf.MAX_GLTF_NODES - 1  # and the light's node
    first = len(b.doc["nodes"])
    b.doc["nodes"] += [{"children": [first + k + 1], "translation": [0.001, 0, 0]} for k in range(count - 1)]
    b.doc["nodes"].append({"mesh": 0})
    b.doc["scenes"][0]["nodes"].append(first)
    return b, first, count


def test_a_deep_chain_of_nodes_loads_and_a_long_cycle_is_refused_quickly(tmp_path):
    """65 536 nodes, each the child of the last (the most a file may have), with the mesh at
    the end: placed by the product of all their transforms, within seconds; the same chain
    closed into a loop is refused (each node's way up is walked once, not once per node)."""
    import time

    b, first, count = deep_chain()
    start = time.perf_counter()
    scene = load_scene(_write(tmp_path, b))
    assert time.perf_counter() - start < 30  # 5 s measured; a walk per node up the chain would take hours
    assert scene.geometry.triangles[0, :, 0].min() == pytest.approx(0.001 * (count - 1), rel=1e-6)
    b.doc["nodes"][-1]["children"] = [first]
    b.doc["scenes"][0]["nodes"].remove(first)
    start = time.perf_counter()
    with pytest.raises(SceneError, match=r"expected a node hierarchy without cycles, got node \d+ is its own ancestor"):
        load_scene(_write(tmp_path, b, "loop.glb"))
    assert time.perf_counter() - start < 30  # 5 s measured; a walk per node up the chain would take hours
