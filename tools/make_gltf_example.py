"""Write scenes/colonnade.glb, the glTF example: a ring of pillars on a floor under a spot
light with a wide soft cone (KHR_lights_punctual), a camera, and a slow turn of the ring.
scenes/colonnade.yaml brings it in and adds the fog.

    .venv/bin/python tools/make_gltf_example.py           # rewrites scenes/colonnade.glb
    .venv/bin/python tools/make_gltf_example.py --check   # exit 1 if the committed file differs

The file is written with json and struct alone (`GltfBuilder`, which the tests use too),
so it is plain glTF 2.0 that other tools open: trimesh reads its geometry.
"""
from __future__ import annotations

import argparse
import json
import math
import struct
import sys
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parents[1] / "scenes" / "colonnade.glb"


class GltfBuilder:
    """A glTF 2.0 document and its one binary buffer, built up by accessors, meshes and nodes."""

    def __init__(self):
        self.doc = {"asset": {"version": "2.0", "generator": "clrays tools/make_gltf_example.py"},
                    "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [], "materials": [],
                    "accessors": [], "bufferViews": [], "buffers": []}
        self.binary = bytearray()

    def accessor(self, array, component: int = 5126, kind: str | None = None) -> int:
        """Append `array` (rows of 1 to 4 values, or a flat list) as a tightly packed view."""
        dtype = {5126: "<f4", 5125: "<u4", 5123: "<u2", 5121: "<u1"}[component]
        array = np.asarray(array, dtype=dtype)
        rows = array.reshape(len(array), -1)
        kind = kind or {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}[rows.shape[1]]
        while len(self.binary) % 4:
            self.binary.append(0)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.binary), "byteLength": rows.nbytes})
        self.binary += rows.tobytes()
        accessor = {"bufferView": len(self.doc["bufferViews"]) - 1, "componentType": component,
                    "count": len(rows), "type": kind}
        if component == 5126:  # min and max, as the spec asks of POSITION
            accessor["min"] = rows.min(axis=0).astype(float).tolist()
            accessor["max"] = rows.max(axis=0).astype(float).tolist()
        self.doc["accessors"].append(accessor)
        return len(self.doc["accessors"]) - 1

    def mesh(self, vertices, faces, colour=(0.8, 0.8, 0.8), normals=None, index_component: int = 5125) -> int:
        attributes = {"POSITION": self.accessor(vertices)}
        if normals is not None:
            attributes["NORMAL"] = self.accessor(normals)
        self.doc["materials"].append({"pbrMetallicRoughness": {"baseColorFactor": [*map(float, colour), 1.0]}})
        primitive = {"attributes": attributes, "material": len(self.doc["materials"]) - 1,
                     "indices": self.accessor(np.asarray(faces).reshape(-1), index_component), "mode": 4}
        self.doc["meshes"].append({"primitives": [primitive]})
        return len(self.doc["meshes"]) - 1

    def node(self, parent: int | None = None, **fields) -> int:
        """A node (translation, rotation [x, y, z, w], scale, matrix, mesh, camera, name, ...), a root
        of the scene or a child of `parent`."""
        self.doc["nodes"].append(fields)
        index = len(self.doc["nodes"]) - 1
        if parent is None:
            self.doc["scenes"][0]["nodes"].append(index)
        else:
            self.doc["nodes"][parent].setdefault("children", []).append(index)
        return index

    def light(self, **definition) -> int:
        """A KHR_lights_punctual light definition; place it with node(extensions=light_ref(i))."""
        self.doc.setdefault("extensionsUsed", [])
        if "KHR_lights_punctual" not in self.doc["extensionsUsed"]:
            self.doc["extensionsUsed"].append("KHR_lights_punctual")
        lights = self.doc.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {"lights": []})["lights"]
        lights.append(definition)
        return len(lights) - 1

    def camera(self, yfov: float, zfar: float | None = None, name: str | None = None, znear: float = 0.05) -> int:
        perspective = {"yfov": yfov, "znear": znear, **({"zfar": zfar} if zfar is not None else {})}
        self.doc.setdefault("cameras", []).append({"type": "perspective", "perspective": perspective,
                                                   **({"name": name} if name else {})})
        return len(self.doc["cameras"]) - 1

    def animate(self, node: int, path: str, times, values, interpolation: str = "LINEAR") -> None:
        animations = self.doc.setdefault("animations", [{"samplers": [], "channels": []}])
        animation = animations[0]
        animation["samplers"].append({"input": self.accessor(np.asarray(times, float)),
                                      "output": self.accessor(values), "interpolation": interpolation})
        animation["channels"].append({"sampler": len(animation["samplers"]) - 1,
                                      "target": {"node": node, "path": path}})

    def glb(self, document: dict | None = None) -> bytes:
        """The GLB file: header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
        document = dict(document or self.doc)
        binary = bytes(self.binary) + b"\0" * (-len(self.binary) % 4)
        if not document.get("buffers"):  # a document may bring buffers of its own (the tests' hostile ones)
            document["buffers"] = [{"byteLength": len(binary)}] if binary else []
        if not document["buffers"]:
            del document["buffers"]
        text = json.dumps(document, separators=(",", ":")).encode()
        text += b" " * (-len(text) % 4)
        chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
        if binary:
            chunks += struct.pack("<II", len(binary), 0x004E4942) + binary
        return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def light_ref(index: int) -> dict:
    return {"KHR_lights_punctual": {"light": index}}


def quaternion(axis, angle_deg: float) -> list[float]:
    """glTF's [x, y, z, w] of a rotation by angle_deg about axis."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    half = math.radians(angle_deg) / 2.0
    return [*(axis * math.sin(half)).tolist(), math.cos(half)]


def box(half_size) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A box centred on the origin with flat faces: 24 vertices (4 a face, with the face's
    normal), 12 triangles wound counter-clockwise seen from outside."""
    h = np.asarray(half_size, float)
    vertices, normals, faces = [], [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = np.zeros(3)
            n[axis] = sign
            u, v = np.zeros(3), np.zeros(3)
            u[(axis + 1) % 3], v[(axis + 2) % 3] = 1.0, 1.0
            if sign < 0:
                u, v = v, u
            base = len(vertices)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                vertices.append((n + a * u + b * v) * h)
                normals.append(n)
            faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return np.array(vertices), np.array(normals), np.array(faces)


def colonnade() -> GltfBuilder:
    builder = GltfBuilder()
    floor = builder.mesh([[-6, 0, -6], [6, 0, -6], [6, 0, 6], [-6, 0, 6]], [[0, 2, 1], [0, 3, 2]],
                         colour=(0.7, 0.68, 0.62), normals=[[0, 1, 0]] * 4)
    vertices, normals, faces = box([0.22, 1.2, 0.22])
    pillar = builder.mesh(vertices, normals=normals, faces=faces, colour=(0.85, 0.8, 0.72), index_component=5123)
    builder.node(name="floor", mesh=floor)
    ring = builder.node(name="ring", rotation=quaternion([0, 1, 0], 15.0))
    for k in range(8):
        angle = 2 * math.pi * k / 8
        builder.node(ring, name=f"pillar{k}", mesh=pillar, translation=[2.2 * math.cos(angle), 1.2,
                                                                           2.2 * math.sin(angle)])
    builder.animate(ring, "rotation", [0.0, 2.0, 4.0],
                    [quaternion([0, 1, 0], 15.0), quaternion([0, 1, 0], 37.5), quaternion([0, 1, 0], 60.0)])
    # A spot high above, pointing down and a little to the side: a wide soft edge (inner 12°, outer 32°);
    # 180 W/sr, written in candela as the extension asks (× 683 lm/W).
    spot = builder.light(type="spot", name="lantern", color=[1.0, 0.92, 0.8], intensity=180.0 * 683.0,
                         spot={"innerConeAngle": math.radians(12), "outerConeAngle": math.radians(32)})
    builder.node(name="lantern", extensions=light_ref(spot), translation=[0.6, 7.0, -0.4],
                 rotation=quaternion([1, 0, 0.15], -88.0))
    eye = builder.camera(math.radians(48), zfar=40.0, name="view")
    builder.node(name="view", camera=eye, translation=[0.0, 3.2, 9.0], rotation=quaternion([1, 0, 0], -13.0))
    return builder


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the committed file differs")
    args = parser.parse_args()
    data = colonnade().glb()
    if args.check:
        same = OUT.exists() and OUT.read_bytes() == data
        print(f"{OUT}: {'up to date' if same else 'differs from what this script writes'}")
        return 0 if same else 1
    OUT.write_bytes(data)
    print(f"wrote {OUT} ({len(data)} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
