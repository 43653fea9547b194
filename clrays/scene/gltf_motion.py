"""What moves inside a glTF mesh (docs/scene-format.md, "glTF 2.0 scenes"): skins, morph
targets and `EXT_mesh_gpu_instancing`, read for clrays.scene.gltf.

* **Skins** (glTF 2.0 §3.7.3): linear blend skinning on the host, in float64 numpy. A
  vertex v with joints j_i and weights w_i is placed at Σ w_i · J_i · v, with
  J_i = world(joints[j_i]) · inverseBindMatrices[j_i]; the transform of the node that holds
  the skinned mesh is ignored, as the spec requires. Normals go through the cofactor of the
  blended 3×3 (its inverse transpose times its determinant), so a non-uniform scale keeps
  them perpendicular.
* **Morph targets** (§3.7.2.2): v + Σ w_k · POSITION_k (and n + Σ w_k · NORMAL_k), the
  weights from the node's `weights`, else the mesh's, else 0, or from a `weights`
  animation channel. Morphing comes before skinning.
* **EXT_mesh_gpu_instancing**: the node's TRANSLATION, ROTATION and SCALE accessors give
  one T·R·S per instance, applied to the mesh before the node's world matrix; the
  instances of a primitive are one object of the scene.

A `Deformation` is one placed primitive whose vertices change with the pose: the animation
calls `pose` for each frame where one of its joints or its weights moves.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import SceneError
from .geometry import flat_normals
from .limits import MAX_COORDINATE, MAX_DEFORMED_VERTICES, MAX_MORPH_VERTICES
from .transforms import quat_to_matrix

EXTENSION = "EXT_mesh_gpu_instancing"
#: JOINTS_n: unsigned byte or short; WEIGHTS_n: float or normalized unsigned byte or short (§3.7.3.1).
JOINT_COMPONENTS = (5121, 5123)
WEIGHT_COMPONENTS = (5126, 5121, 5123)
#: Morph target displacements: float, or (KHR_mesh_quantization) signed byte or short.
TARGET_COMPONENTS = (5126, 5120, 5122)
#: An instance's attributes and their accessor types and component types (the extension's README).
INSTANCE_ATTRIBUTES = {"TRANSLATION": ("VEC3", (5126,)), "ROTATION": ("VEC4", (5126, 5120, 5122)),
                       "SCALE": ("VEC3", (5126,))}
#: JOINTS_n/WEIGHTS_n sets a vertex may have: 32 joints; each set is read as float64, 64 bytes a vertex.
MAX_INFLUENCE_SETS = 8
#: Vertices blended at once: the per-vertex 3×4 matrices of a chunk take 6 MiB.
_SKIN_CHUNK = 1 << 16


@dataclass(frozen=True, eq=False)
class Skin:
    joints: np.ndarray  # (J,) node indices
    inverse_bind: np.ndarray  # (J, 4, 4)


@dataclass(frozen=True, eq=False)
class Deformation:
    """One placed primitive whose vertices move: its rest vertices (mesh space), its faces
    in the order of its rows in the scene, and what moves them."""

    file: str  # for the one-line error of a pose out of range
    node: int
    vertices: np.ndarray  # (V, 3)
    normals: np.ndarray | None  # (V, 3) the file's NORMAL; None: each pose's flat normals
    faces: np.ndarray  # (F, 3)
    targets: np.ndarray | None = None  # (M, V, 3) POSITION displacements
    target_normals: np.ndarray | None = None  # (M, V, 3) NORMAL displacements
    weights: np.ndarray | None = None  # (M,) the static weights
    weight_channel: Any = None  # gltf._Channel of path "weights" (values (K, M)), or None
    skin: Skin | None = None
    joints: np.ndarray | None = None  # (V, K) indices into skin.joints
    joint_weights: np.ndarray | None = None  # (V, K), each row summing to 1
    instances: np.ndarray | None = None  # (N, 4, 4) EXT_mesh_gpu_instancing, mesh → node space

    def moves(self, moving_nodes: set[int]) -> bool:
        """Whether any frame's pose differs from the static one: `moving_nodes` are the nodes
        whose world matrix an animation changes."""
        if self.weight_channel is not None:
            return True
        if self.skin is not None:
            return not moving_nodes.isdisjoint(self.skin.joints.tolist())
        return self.node in moving_nodes

    def pose(self, world: dict[int, np.ndarray], weights: np.ndarray | None = None,
             when: str = "the static pose") -> tuple[np.ndarray, np.ndarray]:
        """(triangles (F·N, 3, 3), their vertex normals) in world space for the node matrices
        `world` and the morph `weights` (None: the static ones). `when` names the pose in
        the error of a coordinate past ±MAX_COORDINATE."""
        points, normals = self.vertices, self.normals
        if self.targets is not None:
            weights = self.weights if weights is None else weights
            points = points + np.tensordot(weights, self.targets, axes=1)
            if normals is not None and self.target_normals is not None:
                normals = normals + np.tensordot(weights, self.target_normals, axes=1)
        if self.skin is not None:
            points, normals = self._skinned(points, normals, world)
        else:
            matrices = world[self.node][None] if self.instances is None else world[self.node] @ self.instances
            points, normals = _placed(matrices, points, normals)
        faces = self.faces if self.instances is None else \
            (self.faces[None] + len(self.vertices) * np.arange(len(self.instances))[:, None, None]).reshape(-1, 3)
        points, normals = points.reshape(-1, 3), None if normals is None else normals.reshape(-1, 3)
        largest = float(np.abs(points).max(initial=0.0))
        if not largest <= MAX_COORDINATE:
            raise SceneError(f"{self.file}: nodes.{self.node}: expected a skinned or morphed mesh within "
                             f"±{MAX_COORDINATE:g} (float32 on the device overflows beyond), got a coordinate of "
                             f"{largest:.3g} at {when}")
        triangles = points[faces]
        return triangles, flat_normals(triangles) if normals is None else _corner_normals(normals, faces, triangles)

    def _skinned(self, points: np.ndarray, normals: np.ndarray | None, world: dict[int, np.ndarray]):
        """Σ w_i · J_i applied to points and (by its cofactor) to normals, a chunk of vertices at a time."""
        joint_matrices = (np.stack([world[int(j)] for j in self.skin.joints]) @ self.skin.inverse_bind)[:, :3, :]
        placed_points = np.empty_like(points)
        placed_normals = None if normals is None else np.empty_like(normals)
        for start in range(0, len(points), _SKIN_CHUNK):
            rows = slice(start, start + _SKIN_CHUNK)
            blend = np.einsum("vk,vkij->vij", self.joint_weights[rows], joint_matrices[self.joints[rows]])
            placed_points[rows] = np.einsum("vij,vj->vi", blend[:, :, :3], points[rows]) + blend[:, :, 3]
            if normals is not None:
                placed_normals[rows] = np.einsum("vij,vj->vi", _cofactor(blend[:, :, :3]), normals[rows])
        return placed_points, placed_normals


def _corner_normals(normals: np.ndarray, faces: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unit vertex normals (V, 3) at each face's corners (F, 3, 3); a normal blended or
    scaled to nothing takes its face's, having no direction left."""
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    corners = np.divide(normals, length, out=np.zeros_like(normals), where=length > 1e-12)[faces]
    lost = ~np.any(corners != 0.0, axis=2)
    rows = np.flatnonzero(lost.any(axis=1))
    if len(rows):
        corners[rows] = np.where(lost[rows, :, None], flat_normals(triangles[rows]), corners[rows])
    return corners


def _cofactor(m: np.ndarray) -> np.ndarray:
    """The cofactor matrices of (..., 3, 3) matrices, signed by their determinants: det·M⁻ᵀ
    with det's sign, so normals keep facing out under mirroring and a singular matrix
    gives zero rather than infinity."""
    c0, c1, c2 = m[..., :, 0], m[..., :, 1], m[..., :, 2]
    cofactor = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=-1)
    det = np.einsum("...i,...i->...", c0, np.cross(c1, c2))
    return cofactor * np.where(det < 0, -1.0, 1.0)[..., None, None]


def _placed(matrices: np.ndarray, points: np.ndarray, normals: np.ndarray | None):
    """Points (V, 3) and normals through each of (N, 4, 4) matrices: (N, V, 3) each."""
    placed = np.einsum("nij,vj->nvi", matrices[:, :3, :3], points) + matrices[:, None, :3, 3]
    if normals is None:
        return placed, None
    return placed, np.einsum("nij,vj->nvi", _cofactor(matrices[:, :3, :3]), normals)


# --------------------------------------------------------------------------- instancing


def instance_count(reader, node: dict, path: str) -> int:
    """How many instances a node's EXT_mesh_gpu_instancing asks for (1 without it), from
    the accessors' counts alone, before any is read."""
    extensions = reader.get(node, "extensions", path, "dict", {})
    if EXTENSION not in extensions:
        return 1
    where = f"{path}.extensions.{EXTENSION}"
    attributes = reader.get(reader.get(extensions, EXTENSION, f"{path}.extensions", "dict"), "attributes", where,
                            "dict")
    counts = {}
    for name in INSTANCE_ATTRIBUTES:
        if name in attributes:
            index = reader.index(attributes, name, f"{where}.attributes", "accessors")
            counts[name] = reader.get(reader.items("accessors")[index], "count", f"accessors.{index}", "int", lo=1)
    if not counts:
        reader.fail(f"{where}.attributes", "at least one of TRANSLATION, ROTATION, SCALE", "none")
    if len(set(counts.values())) > 1:
        reader.fail(f"{where}.attributes", "accessors of one count (one element per instance)",
                    ", ".join(f"{name} {count}" for name, count in counts.items()))
    return next(iter(counts.values()))


def instance_matrices(reader, node: dict, path: str) -> np.ndarray | None:
    """(N, 4, 4) T·R·S of each instance of a node's EXT_mesh_gpu_instancing; None without it."""
    count = instance_count(reader, node, path)  # checks the extension's form
    if EXTENSION not in node.get("extensions", {}):
        return None
    where = f"{path}.extensions.{EXTENSION}.attributes"
    attributes = node["extensions"][EXTENSION]["attributes"]
    read = {}
    for name, (kind, components) in INSTANCE_ATTRIBUTES.items():
        if name in attributes:
            read[name] = reader.accessor(attributes[name], f"{where}.{name}", (kind,), components)
    matrices = np.tile(np.eye(4), (count, 1, 1))
    if "ROTATION" in read:
        xyzw = read["ROTATION"]
        norms = np.linalg.norm(xyzw, axis=1)
        if not np.all(norms > 0.5):  # normalised below: a quantized quaternion is unit only to its precision
            row = int(np.argmin(norms))
            reader.fail(f"accessors.{attributes['ROTATION']}", "unit quaternions [x, y, z, w] for "
                        f"{where}.ROTATION", f"{xyzw[row].tolist()} at instance {row}")
        for i, (x, y, z, w) in enumerate(xyzw / norms[:, None]):
            matrices[i, :3, :3] = quat_to_matrix([w, x, y, z])
    if "SCALE" in read:
        matrices[:, :3, :3] *= read["SCALE"][:, None, :]
    if "TRANSLATION" in read:
        matrices[:, :3, 3] = read["TRANSLATION"]
    return matrices


def instanced(matrices: np.ndarray, triangles: np.ndarray, normals: np.ndarray, vertices: np.ndarray,
              faces: np.ndarray):
    """A static primitive's (triangles, normals, vertices, faces) repeated through each
    instance matrix, in mesh space before the node's: N times as many of each."""
    placed, placed_normals = _placed(matrices, triangles.reshape(-1, 3), normals.reshape(-1, 3))
    placed = placed.reshape(-1, 3, 3)
    placed_normals = _corner_normals(placed_normals.reshape(-1, 3), np.arange(3 * len(placed)).reshape(-1, 3), placed)
    placed_vertices, _ = _placed(matrices, vertices, None)
    all_faces = faces[None] + len(vertices) * np.arange(len(matrices))[:, None, None]
    return placed, placed_normals, placed_vertices.reshape(-1, 3), all_faces.reshape(-1, 3)


# --------------------------------------------------------------------------- bounds


class MotionBudget:
    """The vertices that move each frame and the morph targets' vertices, counted from the
    accessors' counts before any is read (docs/limits.md)."""

    def __init__(self, reader):
        self.reader, self.vertices, self.target_vertices = reader, 0, 0

    def add(self, node: dict, primitive: dict, path: str, instances: int) -> None:
        targets = primitive.get("targets", [])
        skinned = "skin" in node and isinstance(primitive.get("attributes"), dict) and \
            "JOINTS_0" in primitive["attributes"]
        if not (skinned or (isinstance(targets, list) and targets)):
            return
        position = primitive.get("attributes", {}).get("POSITION")
        accessors = self.reader.items("accessors")
        if not isinstance(position, int) or isinstance(position, bool) or not 0 <= position < len(accessors):
            return  # reading it fails with its own message
        count = accessors[position].get("count", 0)
        count = count if isinstance(count, int) and not isinstance(count, bool) else 0
        self.vertices += count * instances
        self.target_vertices += count * len(targets if isinstance(targets, list) else [])
        if self.vertices > MAX_DEFORMED_VERTICES:
            self.reader.fail(path, f"at most {MAX_DEFORMED_VERTICES} skinned or morphed vertices in the scene, each "
                             "posed again every frame (docs/limits.md)", f"{self.vertices} with this primitive")
        if self.target_vertices > MAX_MORPH_VERTICES:
            self.reader.fail(f"{path}.targets", f"at most {MAX_MORPH_VERTICES} morph target vertices (targets × "
                             "vertices) in the scene (docs/limits.md)", f"{self.target_vertices} with this primitive")


# --------------------------------------------------------------------------- reading


def target_count(reader, node_index: int, path: str) -> int:
    """The number of morph targets of the mesh a `weights` channel's node holds."""
    node = reader.items("nodes")[node_index]
    if "mesh" not in node:
        reader.fail(path, "a node with a mesh that has morph targets (for a weights channel)",
                    f"node {node_index} without a mesh")
    mesh = reader.index(node, "mesh", f"nodes.{node_index}", "meshes")
    counts = {len(p.get("targets", [])) if isinstance(p, dict) and isinstance(p.get("targets", []), list) else 0
              for p in reader.get(reader.items("meshes")[mesh], "primitives", f"meshes.{mesh}", "list")}
    if counts == {0} or len(counts) != 1:
        reader.fail(path, "a node whose mesh's primitives have one number of morph targets (for a weights channel)",
                    f"node {node_index}, meshes.{mesh} with {sorted(counts)} targets")
    return counts.pop()


def deformation(reader, node_index: int, primitive: dict, path: str, vertices: np.ndarray, faces: np.ndarray,
                skins: dict, weight_channels: dict, instances: np.ndarray | None,
                world: dict[int, np.ndarray]) -> Deformation | None:
    """The Deformation of a primitive placed by `node_index`, or None when its vertices do
    not move (no morph targets, no skin). `faces` are in the order of its rows; `skins`
    caches each skin read; `weight_channels` maps a node to its `weights` channel."""
    node = reader.items("nodes")[node_index]
    attributes = reader.get(primitive, "attributes", path, "dict")
    targets = reader.get(primitive, "targets", path, "list", [])
    skinned = "skin" in node
    if not targets and not skinned:
        return None
    normals = None
    if "NORMAL" in attributes:  # its count was checked when the primitive was read
        normals = reader.accessor(attributes["NORMAL"], f"{path}.attributes.NORMAL", ("VEC3",), (5126,))
    fields: dict[str, Any] = {}
    if targets:
        fields.update(_morph(reader, node_index, node, primitive, path, targets, len(vertices)))
        fields["weight_channel"] = weight_channels.get(node_index)
    if skinned:
        skin_index = reader.index(node, "skin", f"nodes.{node_index}", "skins")
        if skin_index not in skins:
            skins[skin_index] = _skin(reader, skin_index, world)
        if instances is not None:
            reader.fail(f"nodes.{node_index}.extensions.{EXTENSION}", "instances of a mesh without a skin "
                        "(clrays does not instance skinned meshes)", f"skins.{skin_index}")
        fields.update(_influences(reader, attributes, path, len(vertices), len(skins[skin_index].joints)))
        fields["skin"] = skins[skin_index]
    return Deformation(reader.file, node_index, vertices, normals, faces, instances=instances, **fields)


def _morph(reader, node_index: int, node: dict, primitive: dict, path: str, targets: list, vertex_count: int):
    for k, target in enumerate(targets):
        if not isinstance(target, dict):
            reader.fail(f"{path}.targets.{k}", "an object of attribute displacements", target)
    has_normals = any("NORMAL" in target for target in targets)
    positions, normals = [], []
    for k, target in enumerate(targets):
        for name, into in (("POSITION", positions), ("NORMAL", normals if has_normals else None)):
            if into is None:
                continue
            into.append(np.zeros((vertex_count, 3)) if name not in target else
                        _vertex_attribute(reader, target, name, f"{path}.targets.{k}", "VEC3", TARGET_COMPONENTS,
                                          vertex_count))
    mesh = node["mesh"]
    defaults = reader.numbers(reader.items("meshes")[mesh], "weights", f"meshes.{mesh}", len(targets),
                              np.zeros(len(targets)))
    weights = reader.numbers(node, "weights", f"nodes.{node_index}", len(targets), defaults)
    return {"targets": np.stack(positions), "target_normals": np.stack(normals) if has_normals else None,
            "weights": np.asarray(weights, dtype=np.float64)}


def _skin(reader, skin_index: int, world: dict[int, np.ndarray]) -> Skin:
    path = f"skins.{skin_index}"
    skin = reader.items("skins")[skin_index]
    joints = reader.get(skin, "joints", path, "list")
    nodes = len(reader.items("nodes"))
    if not joints:
        reader.fail(f"{path}.joints", "at least one joint node", "[]")
    seen = set()
    for j, joint in enumerate(joints):  # unique nodes, as the spec asks: no more joints than nodes
        if not isinstance(joint, int) or isinstance(joint, bool) or not 0 <= joint < nodes:
            reader.fail(f"{path}.joints.{j}", f"a node index (0 to {nodes - 1})", joint)
        if joint in seen:
            reader.fail(f"{path}.joints.{j}", "a node not already a joint of the skin", f"node {joint}")
        seen.add(joint)
        if joint not in world:
            reader.fail(f"{path}.joints.{j}", "a node of the scene being rendered", f"node {joint}")
    if "inverseBindMatrices" not in skin:  # identity matrices: the joints are in their bind pose
        return Skin(np.asarray(joints, np.int64), np.tile(np.eye(4), (len(joints), 1, 1)))
    index = reader.index(skin, "inverseBindMatrices", path, "accessors")
    values = reader.accessor(index, f"{path}.inverseBindMatrices", ("MAT4",), (5126,))
    if len(values) != len(joints):
        reader.fail(f"accessors.{index}.count", f"one matrix per joint ({len(joints)})", len(values))
    matrices = values.reshape(-1, 4, 4).transpose(0, 2, 1)  # column-major
    bad = np.flatnonzero(np.abs(matrices[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1) > 1e-6)
    if len(bad):
        reader.fail(f"accessors.{index}", "affine inverse bind matrices (last row 0, 0, 0, 1)",
                    f"{matrices[bad[0], 3].tolist()} in matrix {int(bad[0])}")
    return Skin(np.asarray(joints, np.int64), matrices)


def _influences(reader, attributes: dict, path: str, vertex_count: int, joint_count: int) -> dict:
    """JOINTS_n and WEIGHTS_n, n = 0, 1, ... side by side: (V, 4n) joint indices and
    weights, each vertex's weights divided by their sum (the spec asks for a sum of 1, which
    quantized and exported weights miss by their rounding)."""
    if "JOINTS_0" not in attributes or "WEIGHTS_0" not in attributes:
        reader.fail(f"{path}.attributes", "JOINTS_0 and WEIGHTS_0 on a mesh placed by a node with a skin",
                    ", ".join(sorted(attributes)))
    joints, weights, n = [], [], 0
    while f"JOINTS_{n}" in attributes or f"WEIGHTS_{n}" in attributes:
        if n == MAX_INFLUENCE_SETS:
            reader.fail(f"{path}.attributes", f"at most {MAX_INFLUENCE_SETS} sets of JOINTS_n and WEIGHTS_n "
                        f"({4 * MAX_INFLUENCE_SETS} joints a vertex)", f"JOINTS_{n} or WEIGHTS_{n}")
        for name, into, components in ((f"JOINTS_{n}", joints, JOINT_COMPONENTS),
                                       (f"WEIGHTS_{n}", weights, WEIGHT_COMPONENTS)):
            values = _vertex_attribute(reader, attributes, name, f"{path}.attributes", "VEC4", components,
                                       vertex_count)
            index = attributes[name]
            if name.startswith("JOINTS") and values.max() >= joint_count:
                row = int(np.argmax(values.max(axis=1)))
                reader.fail(f"accessors.{index}", f"joint indices below the skin's {joint_count} joints",
                            f"{values[row].astype(int).tolist()} at vertex {row}")
            if name.startswith("WEIGHTS") and values.min() < 0:
                row = int(np.argmin(values.min(axis=1)))
                reader.fail(f"accessors.{index}", "weights >= 0", f"{values[row].tolist()} at vertex {row}")
            into.append(values)
        n += 1
    joints, weights = np.concatenate(joints, axis=1).astype(np.int64), np.concatenate(weights, axis=1)
    # A vertex without weight (FBX2glTF writes them for vertices no bone holds) follows its
    # first joint, as three.js places it, rather than collapsing to the origin.
    weights[weights.sum(axis=1) == 0, 0] = 1.0
    return {"joints": joints, "joint_weights": weights / weights.sum(axis=1, keepdims=True)}


def _vertex_attribute(reader, obj: dict, name: str, path: str, kind: str, components: tuple[int, ...],
                      vertex_count: int) -> np.ndarray:
    """obj[name], an accessor of one element per vertex: its count checked against the
    POSITION count before it is read."""
    index = reader.index(obj, name, path, "accessors")
    count = reader.get(reader.items("accessors")[index], "count", f"accessors.{index}", "int", lo=1)
    if count != vertex_count:
        reader.fail(f"accessors.{index}.count", f"the POSITION count {vertex_count} for {path}.{name}", count)
    return reader.accessor(index, f"{path}.{name}", (kind,), components)


def moving_nodes(parents: np.ndarray, order: tuple[int, ...], animated: set[int]) -> set[int]:
    """The nodes whose world matrix changes when `animated` nodes' local transforms do:
    those nodes and their descendants (`order` puts parents first)."""
    moving = set()
    for node in order:
        if node in animated or (parents[node] >= 0 and int(parents[node]) in moving):
            moving.add(node)
    return moving


def check_poses(deformations, graph, channels, sample) -> None:
    """The deformed meshes within ±MAX_COORDINATE at each channel's first, last and largest
    key, as gltf._check_animated_poses checks the nodes' poses: `sample(channel, time)` is a
    channel's value, `channels` every channel (transforms and weights)."""
    moving = moving_nodes(graph.parents, graph.order, {c.node for c in graph.channels})
    deformations = [d for d in deformations if d.moves(moving)]
    if not deformations:
        return
    times = set()
    for channel in channels:
        values = channel.values[1::3] if channel.interpolation == "CUBICSPLINE" else channel.values
        times.update((float(channel.times[0]), float(channel.times[-1]),
                      float(channel.times[int(np.abs(values).max(axis=1).argmax())])))
    for time in sorted(times):
        world = graph.world(time)
        for d in deformations:
            d.pose(world, None if d.weight_channel is None else sample(d.weight_channel, time), f"{time:g} s")
