"""What moves inside a glTF mesh (clrays/scene/gltf_motion.py, docs/scene-format.md "glTF
2.0 scenes"): skins, morph targets with animated weights and EXT_mesh_gpu_instancing, each
against a pose worked out here by hand (rotations about z written out with cos and sin,
displacements added by their weights, instance matrices built from their parts), and the
bad files of each refused in one line."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli
from test_gltf import GltfBuilder, box, light_ref, quaternion  # tools/make_gltf_example.py's writer
from clrays.errors import SceneError
from clrays.scene.load import load_scene

SMALL = ["image.width=32", "image.height=18"]


def _points(triangles: np.ndarray) -> np.ndarray:
    """The distinct corners of triangles, rounded to 1e-6 and sorted: a pose as a point set."""
    return np.unique(np.round(np.asarray(triangles).reshape(-1, 3), 6), axis=0)


def _write(tmp_path, builder: GltfBuilder, name="scene.glb") -> Path:
    path = tmp_path / name
    path.write_bytes(builder.glb())
    return path


# --------------------------------------------------------------------------- skins

#: A strip 1 wide and 2 tall in the z = 0 plane, rows at y = 0, 0.5, 1, 1.5, 2: the joint
#: at the origin holds the rows below 1, the joint at (0, 1, 0) those above, the middle row
#: half each.
STRIP = np.array([[x, y, 0.0] for y in (0.0, 0.5, 1.0, 1.5, 2.0) for x in (-0.5, 0.5)])
STRIP_FACES = np.array([[r, r + 1, r + 3] for r in range(0, 8, 2)] + [[r, r + 3, r + 2] for r in range(0, 8, 2)])
UPPER_WEIGHT = np.array([0.0, 0.0, 0.0, 0.0, 0.5, 0.5, 1.0, 1.0, 1.0, 1.0])


def _bending_strip(angle_deg: float = 90.0, extra_weights: bool = False) -> tuple[GltfBuilder, dict]:
    """The strip skinned to two joints: the elbow (a child of the root joint, at y = 1) turns
    about +z from 0° at 0 s to `angle_deg` at 1 s. The skinned mesh's node is moved and
    scaled, which the spec says to ignore."""
    b = GltfBuilder()
    b.node(extensions=light_ref(b.light(type="point", intensity=30.0)), translation=[0, 3, 4])
    mesh = b.mesh(STRIP, STRIP_FACES)
    primitive = b.doc["meshes"][mesh]["primitives"][0]
    joints = np.zeros((len(STRIP), 4), np.uint16)
    joints[:, 1] = 1
    weights = np.zeros((len(STRIP), 4))
    weights[:, 0], weights[:, 1] = 1.0 - UPPER_WEIGHT, UPPER_WEIGHT
    if extra_weights:  # a JOINTS_1/WEIGHTS_1 pair that adds nothing, and weights summing to 2
        weights *= 2.0
        primitive["attributes"]["JOINTS_1"] = b.accessor(np.zeros((len(STRIP), 4), np.uint8), 5121)
        primitive["attributes"]["WEIGHTS_1"] = b.accessor(np.zeros((len(STRIP), 4)))
    primitive["attributes"]["JOINTS_0"] = b.accessor(joints, 5123)
    primitive["attributes"]["WEIGHTS_0"] = b.accessor(weights)
    root = b.node(name="root")
    elbow = b.node(root, name="elbow", translation=[0, 1, 0])
    inverse_bind = np.array([np.eye(4), np.eye(4)])
    inverse_bind[1, 1, 3] = -1.0  # the elbow's bind pose is a translation by (0, 1, 0)
    skin = {"joints": [root, elbow],
            "inverseBindMatrices": b.accessor(inverse_bind.transpose(0, 2, 1).reshape(2, 16), kind="MAT4")}
    b.doc["skins"] = [skin]
    b.node(mesh=mesh, skin=0, translation=[5, 0, 0], scale=[3, 3, 3])
    b.animate(elbow, "rotation", [0, 1], [quaternion([0, 0, 1], 0), quaternion([0, 0, 1], angle_deg)])
    return b, skin


def _bent_strip(angle_deg: float) -> np.ndarray:
    """The strip's vertices with the upper joint turned by angle_deg about the z axis through
    (0, 1, 0), blended by hand: (1 − w)·v + w·(pivot + R(v − pivot))."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    bent = []
    for (x, y, z), w in zip(STRIP, UPPER_WEIGHT):
        dx, dy = x, y - 1.0
        turned = np.array([c * dx - s * dy, 1.0 + s * dx + c * dy, z])
        bent.append((1.0 - w) * np.array([x, y, z]) + w * turned)
    return np.array(bent)


def test_a_two_joint_skin_bends_at_its_elbow(tmp_path):
    """At 1 s the elbow has turned 90°: the top corners (±0.5, 2) are at (−1, 1.5) and
    (−1, 0.5), the middle row, half on each joint, at (0.25, 1.25) and (−0.25, 0.75); the
    rows below the elbow stay. At 0.5 s it is 45°. The mesh node's own transform (moved 5,
    scaled 3) is ignored."""
    scene = load_scene(_write(tmp_path, _bending_strip()[0]), ["gltf.fps=12"])
    animation = scene.animation
    assert (animation.first, animation.last) == (0, 12)
    np.testing.assert_allclose(_points(scene.geometry.triangles), _points(STRIP), atol=1e-6)
    at_1s = _points(animation.scene_at(scene, 12).geometry.triangles)
    for corner in ([-1.0, 1.5, 0.0], [-1.0, 0.5, 0.0], [0.25, 1.25, 0.0], [-0.25, 0.75, 0.0], [0.5, 0.5, 0.0]):
        assert np.min(np.linalg.norm(at_1s - corner, axis=1)) < 1e-6, corner
    np.testing.assert_allclose(at_1s, _points(_bent_strip(90.0)), atol=1e-6)
    np.testing.assert_allclose(_points(animation.scene_at(scene, 6).geometry.triangles), _points(_bent_strip(45.0)),
                               atol=1e-6)


def test_weights_are_normalised_and_a_second_set_of_joints_is_read(tmp_path):
    """Weights that sum to 2 (JOINTS_1/WEIGHTS_1 present, all zero) pose as the same weights
    divided by their sum."""
    scene = load_scene(_write(tmp_path, _bending_strip(extra_weights=True)[0]), ["gltf.fps=12"])
    np.testing.assert_allclose(_points(scene.animation.scene_at(scene, 12).geometry.triangles),
                               _points(_bent_strip(90.0)), atol=1e-6)


def test_a_vertex_without_weight_follows_its_first_joint(tmp_path):
    """Top corner 8, (−0.5, 2), with weights (0, 0, 0, 0) and joints (0, 1, 0, 0): it stays
    with the root joint (as three.js places it) while the rest of its row turns."""
    b, _ = _bending_strip()
    weights = np.zeros((len(STRIP), 4))
    weights[:, 0], weights[:, 1] = 1.0 - UPPER_WEIGHT, UPPER_WEIGHT
    weights[8] = 0.0
    b.doc["meshes"][0]["primitives"][0]["attributes"]["WEIGHTS_0"] = b.accessor(weights)
    scene = load_scene(_write(tmp_path, b), ["gltf.fps=12"])
    expected = _bent_strip(90.0)
    expected[8] = STRIP[8]
    np.testing.assert_allclose(_points(scene.animation.scene_at(scene, 12).geometry.triangles), _points(expected),
                               atol=1e-6)


def test_a_skin_moved_by_its_joints_parent_and_a_still_one(tmp_path):
    """The joints' parents move the skin (here a root turned by 90° about z); a skin whose
    joints no channel moves is posed once and the frames share its geometry."""
    b, _ = _bending_strip(0.0)  # the elbow's channel keeps it straight
    base = b.node(name="base")
    b.doc["scenes"][0]["nodes"].remove(1)  # the root joint (node 1) goes under `base`
    b.doc["nodes"][base]["children"] = [1]
    b.animate(base, "rotation", [0, 1], [quaternion([0, 0, 1], 0), quaternion([0, 0, 1], 90)])
    scene = load_scene(_write(tmp_path, b), ["gltf.fps=12"])
    turned = _points(STRIP @ np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).T)
    np.testing.assert_allclose(_points(scene.animation.scene_at(scene, 12).geometry.triangles), turned, atol=1e-6)

    still, _ = _bending_strip(0.0)
    still.doc["animations"][0]["channels"][0]["target"]["node"] = 0  # the light's node moves, no joint does
    still.doc["animations"][0]["channels"][0]["target"]["path"] = "translation"
    still.doc["animations"][0]["samplers"][0]["output"] = still.accessor([[0, 3, 4], [1, 3, 4]])
    scene = load_scene(_write(tmp_path, still, "still.glb"), ["gltf.fps=12"])
    assert scene.animation.scene_at(scene, 7).geometry is scene.geometry


def test_a_sequence_of_an_animated_skin_has_frames_that_differ(tmp_path):
    path = _write(tmp_path, _bending_strip()[0])
    code, out = run_cli("sequence", path, "-o", str(tmp_path / "f_{:02d}.npy"), "--frames", "0:2",
                        "--set", "gltf.fps=2", "--set", "medium.sigma_s=0.05",
                        *sum((["--set", s] for s in SMALL), []))
    assert code == 0, out
    frames = [np.load(tmp_path / f"f_{k:02d}.npy") for k in range(3)]
    assert all(np.isfinite(f).all() and f.max() > 0 for f in frames)
    assert np.abs(frames[1] - frames[0]).max() > 1e-3 * frames[0].max()
    assert np.abs(frames[2] - frames[1]).max() > 1e-3 * frames[0].max()


def _skin_change(b: GltfBuilder, what: str) -> None:
    attributes = b.doc["meshes"][0]["primitives"][0]["attributes"]
    accessors = b.doc["accessors"]
    if what == "joint out of range":
        joints = np.zeros((len(STRIP), 4), np.uint16)
        joints[3] = [0, 2, 0, 0]
        attributes["JOINTS_0"] = b.accessor(joints, 5123)
    elif what == "negative weight":
        weights = np.zeros((len(STRIP), 4))
        weights[:, 0] = 1.0
        weights[4] = [1.5, -0.5, 0, 0]
        attributes["WEIGHTS_0"] = b.accessor(weights)
    elif what == "float joints":
        attributes["JOINTS_0"] = b.accessor(np.zeros((len(STRIP), 4)))
    elif what == "no joints":
        del attributes["JOINTS_0"]
    elif what == "one inverse bind matrix":
        accessors[b.doc["skins"][0]["inverseBindMatrices"]]["count"] = 1
    elif what == "a joint outside the scene":
        b.doc["nodes"].append({})
        b.doc["skins"][0]["joints"][1] = len(b.doc["nodes"]) - 1
    elif what == "a joint twice":
        b.doc["skins"][0]["joints"][1] = b.doc["skins"][0]["joints"][0]
    elif what == "nine influence sets":
        for n in range(1, 9):
            attributes[f"JOINTS_{n}"], attributes[f"WEIGHTS_{n}"] = attributes["JOINTS_0"], attributes["WEIGHTS_0"]
    elif what == "short weights":
        attributes["WEIGHTS_0"] = b.accessor(np.zeros((3, 4)))
    elif what == "instanced":
        b.doc["nodes"][-1]["extensions"] = {"EXT_mesh_gpu_instancing": {
            "attributes": {"TRANSLATION": b.accessor([[0, 0, 0], [1, 0, 0]])}}}


@pytest.mark.parametrize("what, pattern", [
    ("joint out of range", r"accessors\.\d+: expected joint indices below the skin's 2 joints, got \[0, 2, 0, 0\] "
                           r"at vertex 3"),
    ("negative weight", r"accessors\.\d+: expected weights >= 0, got \[1\.5, -0\.5, 0\.0, 0\.0\] at vertex 4"),
    ("float joints", r"accessors\.\d+\.componentType: expected one of 5121, 5123 for "
                     r"meshes\.0\.primitives\.0\.attributes\.JOINTS_0, got 5126"),
    ("no joints", r"meshes\.0\.primitives\.0\.attributes: expected JOINTS_0 and WEIGHTS_0 on a mesh placed by a node "
                  r"with a skin"),
    ("one inverse bind matrix", r"accessors\.\d+\.count: expected one matrix per joint \(2\), got 1"),
    ("a joint outside the scene", r"skins\.0\.joints\.1: expected a node of the scene being rendered, got node \d+"),
    ("a joint twice", r"skins\.0\.joints\.1: expected a node not already a joint of the skin, got node 1"),
    ("nine influence sets", r"meshes\.0\.primitives\.0\.attributes: expected at most 8 sets of JOINTS_n and "
                            r"WEIGHTS_n \(32 joints a vertex\), got JOINTS_8 or WEIGHTS_8"),
    ("short weights", r"accessors\.\d+\.count: expected the POSITION count 10 for "
                      r"meshes\.0\.primitives\.0\.attributes\.WEIGHTS_0, got 3"),
    ("instanced", r"nodes\.\d+\.extensions\.EXT_mesh_gpu_instancing: expected instances of a mesh without a skin"),
])
def test_a_bad_skin_is_refused_in_one_line(tmp_path, what, pattern):
    b, _ = _bending_strip()
    _skin_change(b, what)
    with pytest.raises(SceneError, match=r"^\S+scene\.glb: " + pattern) as info:
        load_scene(_write(tmp_path, b), ["gltf.fps=12"])
    assert "\n" not in str(info.value)


def test_a_pose_out_of_range_is_refused_at_load(tmp_path):
    """A joint carried to 1e13 at 1 s puts the skin past ±1e12: refused when the file is
    read, not in the middle of a sequence."""
    b, _ = _bending_strip()
    b.animate(1, "translation", [0, 1], [[0, 0, 0], [1e13, 0, 0]])
    with pytest.raises(SceneError, match=r"scene\.glb: nodes\.3: expected a skinned or morphed mesh within ±1e\+12 "
                                         r"\(float32 on the device overflows beyond\), got a coordinate of 1e\+13 at 1 s$"):
        load_scene(_write(tmp_path, b), ["gltf.fps=12"])


# --------------------------------------------------------------------------- morph targets


#: Target 1's NORMAL displacement on the +x face: its normals lean towards +y.
TILT = np.array([0.0, 0.4, 0.0])


def _morph_cube(interpolation: str = "LINEAR", node_weights=None) -> tuple[GltfBuilder, np.ndarray, np.ndarray]:
    """A unit box with two targets: 0 lifts the top face by 1, 1 pushes the +x face out by
    0.5 (and turns its normals a little). Its weights go (0, 0) → (1, 0.5) → (0, 1) over
    0, 1, 2 s."""
    b = GltfBuilder()
    b.node(extensions=light_ref(b.light(type="point", intensity=30.0)), translation=[0, 3, 4])
    vertices, normals, faces = box([0.5, 0.5, 0.5])
    mesh = b.mesh(vertices, faces, normals=normals)
    lift = np.where(vertices[:, 1:2] > 0, [0.0, 1.0, 0.0], 0.0)
    push = np.where(vertices[:, 0:1] > 0, [0.5, 0.0, 0.0], 0.0)
    primitive = b.doc["meshes"][mesh]["primitives"][0]
    primitive["targets"] = [{"POSITION": b.accessor(lift)},
                            {"POSITION": b.accessor(push), "NORMAL": b.accessor(TILT * (push[:, :1] > 0))}]
    b.doc["meshes"][mesh]["weights"] = [0.0, 0.0]
    cube = b.node(mesh=mesh, translation=[0, 0, -1], **({"weights": node_weights} if node_weights else {}))
    if interpolation == "CUBICSPLINE":  # in-tangent, value, out-tangent per key, tangents 0
        values = [[0, 0], [0, 0], [0, 0], [0, 0], [1, 0.5], [0, 0], [0, 0], [0, 1], [0, 0]]
    else:
        values = [[0, 0], [1, 0.5], [0, 1]]
    b.animate(cube, "weights", [0, 1, 2], np.asarray(values, float).reshape(-1), interpolation)
    return b, lift, push


@pytest.mark.parametrize("interpolation, frame, weights", [
    ("LINEAR", 6, (0.5, 0.25)), ("LINEAR", 18, (0.5, 0.75)), ("LINEAR", 24, (0.0, 1.0)),
    ("STEP", 6, (0.0, 0.0)), ("STEP", 18, (1.0, 0.5)),
    # Hermite with zero tangents between (0, 0) and (1, 0.5) at u = 0.5: 3u² − 2u³ = 0.5 of the way
    ("CUBICSPLINE", 6, (0.5, 0.25)), ("CUBICSPLINE", 3, (0.15625, 0.078125)),
])
def test_a_morph_cube_follows_its_animated_weights(tmp_path, interpolation, frame, weights):
    b, lift, push = _morph_cube(interpolation)
    scene = load_scene(_write(tmp_path, b), ["gltf.fps=12"])
    assert (scene.animation.first, scene.animation.last) == (0, 24)
    vertices = box([0.5, 0.5, 0.5])[0]
    expected = vertices + weights[0] * lift + weights[1] * push + [0.0, 0.0, -1.0]  # and the node's translation
    posed = scene.animation.scene_at(scene, frame).geometry
    np.testing.assert_allclose(_points(posed.triangles), _points(expected), atol=1e-6)
    # The +x face's normals: n + w1·ΔN, normalised; the others keep the file's.
    leaning = np.array([1.0, 0.0, 0.0]) + weights[1] * TILT
    assert np.min(np.linalg.norm(posed.normals.reshape(-1, 3) - leaning / np.linalg.norm(leaning), axis=1)) < 1e-6
    assert np.min(np.linalg.norm(posed.normals.reshape(-1, 3) - [0.0, 1.0, 0.0], axis=1)) < 1e-9


def test_a_node_s_weights_override_the_mesh_s(tmp_path):
    """Without an animation, the static pose takes the node's `weights` over the mesh's."""
    b, lift, push = _morph_cube(node_weights=[0.0, 1.0])
    del b.doc["animations"]
    b.doc["meshes"][0]["weights"] = [1.0, 0.0]
    scene = load_scene(_write(tmp_path, b))
    assert scene.animation is None
    expected = box([0.5, 0.5, 0.5])[0] + push + [0.0, 0.0, -1.0]
    np.testing.assert_allclose(_points(scene.geometry.triangles), _points(expected), atol=1e-6)


def test_an_instanced_morph_cube_morphs_every_instance(tmp_path):
    """Two instances, 3 apart along x and the second scaled by 2: each morphed, then placed."""
    b, lift, push = _morph_cube()
    b.doc["nodes"][1]["extensions"] = {"EXT_mesh_gpu_instancing": {"attributes": {
        "TRANSLATION": b.accessor([[0, 0, 0], [3, 0, 0]]), "SCALE": b.accessor([[1, 1, 1], [2, 2, 2]])}}}
    scene = load_scene(_write(tmp_path, b), ["gltf.fps=12"])
    morphed = box([0.5, 0.5, 0.5])[0] + 0.5 * lift + 0.25 * push
    expected = np.concatenate([morphed, 2.0 * morphed + [3.0, 0.0, 0.0]]) + [0.0, 0.0, -1.0]
    np.testing.assert_allclose(_points(scene.animation.scene_at(scene, 6).geometry.triangles), _points(expected),
                               atol=1e-6)


def test_morph_weights_with_the_wrong_count_are_refused(tmp_path):
    b, _, _ = _morph_cube()
    b.doc["animations"][0]["channels"][0]["target"]["node"] = 0  # the light's node: no mesh
    with pytest.raises(SceneError, match=r"animations\.0\.channels\.0\.target\.node: expected a node with a mesh that "
                                         r"has morph targets \(for a weights channel\), got node 0 without a mesh$"):
        load_scene(_write(tmp_path, b))
    b, _, _ = _morph_cube()
    b.doc["animations"][0]["samplers"][0]["output"] = b.accessor(np.zeros(5))
    with pytest.raises(SceneError, match=r"accessors\.\d+\.count: expected 6 values for 3 key times \(LINEAR, 2 morph "
                                         r"targets\), got 5$"):
        load_scene(_write(tmp_path, b))
    b, _, _ = _morph_cube()
    b.doc["meshes"][0]["primitives"][0]["targets"][1]["POSITION"] = b.accessor(np.zeros((3, 3)))
    with pytest.raises(SceneError, match=r"accessors\.\d+\.count: expected the POSITION count 24 for "
                                         r"meshes\.0\.primitives\.0\.targets\.1\.POSITION, got 3$"):
        load_scene(_write(tmp_path, b))


# --------------------------------------------------------------------------- instancing


def _instance_grid() -> tuple[GltfBuilder, list[np.ndarray]]:
    """125 instances of one box (5 × 5 × 5, 2.5 apart), each turned about y by 7° more than
    the last and scaled 1 + (i mod 3)/4; the node moves them all by (1, 0, 0)."""
    b = GltfBuilder()
    b.node(extensions=light_ref(b.light(type="point", intensity=30.0)), translation=[0, 20, 20])
    vertices, normals, faces = box([0.5, 0.5, 0.5])
    mesh = b.mesh(vertices, faces, normals=normals)
    translations, rotations, scales, matrices = [], [], [], []
    for i, (x, y, z) in enumerate(np.ndindex(5, 5, 5)):
        translation, angle, scale = np.array([x, y, z]) * 2.5, 7.0 * i, 1.0 + (i % 3) / 4
        translations.append(translation)
        rotations.append(quaternion([0, 1, 0], angle))
        scales.append([scale] * 3)
        c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
        matrix = np.eye(4)
        matrix[:3, :3] = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) * scale
        matrix[:3, 3] = translation + [1.0, 0.0, 0.0]
        matrices.append(matrix)
    b.node(mesh=mesh, translation=[1, 0, 0], extensions={"EXT_mesh_gpu_instancing": {"attributes": {
        "TRANSLATION": b.accessor(translations), "ROTATION": b.accessor(rotations), "SCALE": b.accessor(scales)}}})
    return b, matrices


def test_instancing_places_125_boxes(tmp_path):
    b, matrices = _instance_grid()
    b.doc["extensionsRequired"] = ["EXT_mesh_gpu_instancing"]
    scene = load_scene(_write(tmp_path, b))
    assert scene.geometry.count == 125 * 12
    vertices = box([0.5, 0.5, 0.5])[0]
    expected = np.concatenate([vertices @ m[:3, :3].T + m[:3, 3] for m in matrices])
    np.testing.assert_allclose(_points(scene.geometry.triangles), _points(expected), atol=1e-6)
    # Each box is a closed solid wound outwards, and its normals turn with it.
    assert np.all(scene.geometry.outward == 1)
    first = scene.geometry.triangles.reshape(-1, 3, 3)
    face_normals = np.cross(first[:, 1] - first[:, 0], first[:, 2] - first[:, 0])
    face_normals /= np.linalg.norm(face_normals, axis=1, keepdims=True)
    np.testing.assert_allclose(scene.geometry.normals[:, 0], face_normals, atol=1e-6)


def test_instancing_counts_against_the_triangle_limit_before_reading(tmp_path):
    """200 000 instances of a 12-triangle box ask for 2.4 M triangles: refused from the
    accessor's count, its zeros never read."""
    b, _ = _instance_grid()
    node = b.doc["nodes"][-1]
    b.doc["accessors"].append({"componentType": 5126, "count": 200_000, "type": "VEC3"})
    node["extensions"]["EXT_mesh_gpu_instancing"]["attributes"] = {"TRANSLATION": len(b.doc["accessors"]) - 1}
    with pytest.raises(SceneError, match=r"meshes\.0\.primitives\.0: expected at most 2097152 triangles in the whole "
                                         r"scene \(docs/limits\.md\), got 2400000"):
        load_scene(_write(tmp_path, b))
    b.doc["accessors"].append({"componentType": 5126, "count": 3, "type": "VEC3"})
    node["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]["SCALE"] = len(b.doc["accessors"]) - 1
    with pytest.raises(SceneError, match=r"EXT_mesh_gpu_instancing\.attributes: expected accessors of one count"):
        load_scene(_write(tmp_path, b))


def test_deformed_vertices_count_against_their_limits_before_reading(tmp_path):
    """A skinned mesh of 1.1 M vertices, and 5 morph targets on 0.9 M: refused from the
    POSITION accessor's count."""
    b, _ = _bending_strip()
    b.doc["accessors"][b.doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]["count"] = 1_100_000
    with pytest.raises(SceneError, match=r"meshes\.0\.primitives\.0: expected at most 1048576 skinned or morphed "
                                         r"vertices .*got 1100000 with this primitive"):
        load_scene(_write(tmp_path, b))
    b, _, _ = _morph_cube()
    primitive = b.doc["meshes"][0]["primitives"][0]
    b.doc["accessors"][primitive["attributes"]["POSITION"]]["count"] = 900_000
    primitive["targets"] = (primitive["targets"] * 3)[:5]
    del b.doc["animations"]
    with pytest.raises(SceneError, match=r"meshes\.0\.primitives\.0\.targets: expected at most 4194304 morph target "
                                         r"vertices .*got 4500000 with this primitive"):
        load_scene(_write(tmp_path, b))
