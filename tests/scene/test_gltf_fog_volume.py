"""A glTF file's fog volume: `medium.bounds: {object: NAME}` takes the medium's box from a mesh
node and leaves that node out of the geometry. fog_cube.glb is Blender's own export of a fog
cube (a volume-only material) over a floor (tests/scene/data/make_fog_cube.py)."""
from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli
from clrays.errors import SceneError
from clrays.scene.load import load_scene, parse_scene

FOG_CUBE = Path(__file__).parent / "data" / "fog_cube.glb"
#: The fog node's world box in glTF coordinates (Blender's x, z, −y): make_fog_cube.py's cube.
FOG_BOX = (np.array([-1.0, 0.5, -1.0]), np.array([3.0, 2.5, 2.0]))
FLOOR_TRIANGLES = 2
SMALL = ("--set", "image.width=16", "--set", "image.height=9", "--set", "image.spp=1")


def _glb_parts(path: Path) -> tuple[dict, bytes]:
    """The JSON and binary chunks of a GLB."""
    data = path.read_bytes()
    json_length = struct.unpack_from("<I", data, 12)[0]
    document = json.loads(data[20:20 + json_length])
    return document, data[20 + json_length + 8:]


def _write_gltf(tmp_path: Path, document: dict, binary: bytes, name: str = "edited.gltf") -> Path:
    """document as a .gltf whose one buffer is binary, as a data URI."""
    document["buffers"] = [{"byteLength": len(binary),
                            "uri": "data:application/octet-stream;base64," + base64.b64encode(binary).decode()}]
    path = tmp_path / name
    path.write_text(json.dumps(document))
    return path


def _fog_node(document: dict) -> int:
    return next(i for i, node in enumerate(document["nodes"]) if node.get("name") == "fog")


def test_blenders_fog_cube_is_written_as_a_plain_mesh():
    """What the exporter writes for a volume-only material, and why clrays cannot decide from the
    file alone: the cube is an ordinary mesh, its material has no pbrMetallicRoughness (which the
    glTF 2.0 spec fills with its defaults: a white surface) and no volume extension."""
    document, _ = _glb_parts(FOG_CUBE)
    node = document["nodes"][_fog_node(document)]
    material = document["materials"][document["meshes"][node["mesh"]]["primitives"][0]["material"]]
    assert material == {"doubleSided": True, "name": "fog_volume"}
    assert not any(name.startswith("KHR_materials") for name in document.get("extensionsUsed", []))


def test_the_fog_node_bounds_the_medium_and_is_no_geometry():
    scene = load_scene(FOG_CUBE, ["medium.bounds.object=fog", "medium.sigma_s=0.2"])
    np.testing.assert_allclose(scene.medium.bounds.min, FOG_BOX[0], atol=1e-6)
    np.testing.assert_allclose(scene.medium.bounds.max, FOG_BOX[1], atol=1e-6)
    assert scene.geometry.count == FLOOR_TRIANGLES
    np.testing.assert_array_equal(scene.medium.sigma_s, [0.2] * 3)


def test_without_the_field_the_cube_is_a_surface_with_a_notice(capsys):
    scene = load_scene(FOG_CUBE, ["medium.sigma_s=0.2"])
    assert scene.medium.bounds is None
    assert scene.geometry.count == FLOOR_TRIANGLES + 12
    notices = [line for line in capsys.readouterr().err.splitlines() if "pbrMetallicRoughness" in line]
    assert len(notices) == 1 and notices[0].endswith("--set medium.bounds.object=fog"), notices


def test_a_yaml_scene_names_the_fog_node_beside_its_own_medium(tmp_path):
    """The same as the file without the fog node and an explicit box, and density keys kept."""
    text = f"""version: 1
image: {{width: 16, height: 9}}
gltf: {{file: {FOG_CUBE}}}
medium:
  sigma_s: 0.1
  bounds: {{object: fog}}
  density: {{type: height, base: 0.5, scale_height: 2}}
"""
    scene = parse_scene(text, str(tmp_path / "fog.yaml"))
    document, binary = _glb_parts(FOG_CUBE)
    fog = _fog_node(document)
    document["scenes"][0]["nodes"].remove(fog)
    without = _write_gltf(tmp_path, document, binary)
    box = f"{{min: {FOG_BOX[0].tolist()}, max: {FOG_BOX[1].tolist()}}}"
    explicit = parse_scene(text.replace(str(FOG_CUBE), str(without)).replace("{object: fog}", box),
                           str(tmp_path / "explicit.yaml"))
    np.testing.assert_allclose(scene.medium.bounds.min, explicit.medium.bounds.min, atol=1e-6)
    np.testing.assert_allclose(scene.medium.bounds.max, explicit.medium.bounds.max, atol=1e-6)
    np.testing.assert_array_equal(scene.geometry.triangles, explicit.geometry.triangles)
    assert scene.medium.density == explicit.medium.density


def test_a_render_of_the_fog_cube_matches_the_explicit_box(tmp_path):
    """End to end: the exact image of the fog node's bounds is that of its box written out."""
    document, binary = _glb_parts(FOG_CUBE)
    document["scenes"][0]["nodes"].remove(_fog_node(document))
    without = _write_gltf(tmp_path, document, binary)
    common = (*SMALL, "--set", "medium.sigma_s=0.3", "--set", "render.method=exact")
    code, out = run_cli("render", FOG_CUBE, "-o", tmp_path / "object.npy", "--set", "medium.bounds.object=fog",
                        *common)
    assert code == 0, out
    code, out = run_cli("render", without, "-o", tmp_path / "box.npy", "--set",
                        f"medium.bounds={{min: {FOG_BOX[0].tolist()}, max: {FOG_BOX[1].tolist()}}}", *common)
    assert code == 0, out
    by_object, by_box = np.load(tmp_path / "object.npy"), np.load(tmp_path / "box.npy")
    assert by_box.max() > 0
    np.testing.assert_allclose(by_object, by_box, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("override, message", [
    ("medium.bounds.object=fig", r"fog_cube.glb: nodes: expected a node with a mesh named 'fig' for "
                                 r"medium.bounds.object, got 'floor', 'fog'$"),
    ("medium.bounds.object=3", r"medium.bounds.object: expected the name of a glTF node with a mesh, got 3$"),
    ("medium.bounds={object: fog, min: [0, 0, 0]}", r"medium.bounds.min: unknown key; expected one of: object"),
])
def test_bad_names_fail_in_one_line(override, message):
    with pytest.raises(SceneError, match=message) as raised:
        load_scene(FOG_CUBE, [override])
    assert "\n" not in str(raised.value)


def test_a_name_on_two_nodes_is_refused(tmp_path):
    """glTF names need not be unique: clrays refuses to pick one."""
    document, binary = _glb_parts(FOG_CUBE)
    document["nodes"][0]["name"] = "fog"
    path = _write_gltf(tmp_path, document, binary)
    with pytest.raises(SceneError, match=r"edited.gltf: nodes: expected one node named 'fog' for "
                                         r"medium.bounds.object, got 2 \(nodes.0, nodes.1\); rename one"):
        load_scene(path, ["medium.bounds.object=fog"])


def test_an_animated_fog_node_is_refused(tmp_path):
    """The bounds are one box: a fog node that an animation moves is refused, naming it."""
    document, binary = _glb_parts(FOG_CUBE)
    fog = _fog_node(document)
    keys = np.array([0.0, 1.0], np.float32).tobytes() + np.array([[0, 0, 0], [1, 0, 0]], np.float32).tobytes()
    start = len(binary) + (-len(binary) % 4)
    binary = binary + bytes(start - len(binary)) + keys
    views = len(document["bufferViews"])
    document["bufferViews"] += [{"buffer": 0, "byteOffset": start, "byteLength": 8},
                                {"buffer": 0, "byteOffset": start + 8, "byteLength": 24}]
    accessors = len(document["accessors"])
    document["accessors"] += [
        {"bufferView": views, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]},
        {"bufferView": views + 1, "componentType": 5126, "count": 2, "type": "VEC3"}]
    document["animations"] = [{"samplers": [{"input": accessors, "output": accessors + 1}],
                               "channels": [{"sampler": 0, "target": {"node": fog, "path": "translation"}}]}]
    path = _write_gltf(tmp_path, document, binary)
    with pytest.raises(SceneError, match=rf"nodes.{fog}: expected a fog volume's node that no animation moves"):
        load_scene(path, ["medium.bounds.object=fog"])


def test_the_field_needs_a_gltf_file(tmp_path):
    code, out = run_cli("render", _yaml_without_gltf(tmp_path), "-o", tmp_path / "x.npy")
    assert code == 1
    assert out.strip().splitlines()[-1].endswith(
        "medium.bounds.object: expected a glTF node's name, with a `gltf` file to find it in, got 'fog' without "
        "gltf"), out


def _yaml_without_gltf(tmp_path: Path) -> Path:
    path = tmp_path / "scene.yaml"
    path.write_text("""version: 1
image: {width: 16, height: 9}
camera: {position: [0, 1, 5], look_at: [0, 0, 0], fov_deg: 60}
lights: [{type: point, position: [0, 3, 0], intensity: 10}]
medium: {sigma_s: 0.1, bounds: {object: fog}}
""")
    return path
