"""The common binary PLY mesh read in numpy, without trimesh: a `vertex` element of scalar
properties with x, y and z, then a `face` element of one list of triangles, as scanners and
exporters write it. Importing trimesh (and the scipy it imports) cost 1.2–2.5 s of a
million-triangle forest's first frame, reading its 984 k faces 0.2 s (bench/dense.py).
Anything else (ASCII, vertex normals, other elements, faces of more corners, a size that
does not add up) is left to trimesh, which also words the errors of a bad file."""
from __future__ import annotations

import re

import numpy as np

#: PLY scalar types as numpy type codes (both spellings of the format).
_SCALARS = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
            "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
            "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_FORMATS = {"binary_little_endian": "<", "binary_big_endian": ">"}
#: The longest header read (a header of comments longer than this goes to trimesh).
_MOST_HEADER_BYTES = 1 << 16


def read_binary_triangles(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """(vertices (V, 3) float64, faces (F, 3) int64) of a binary PLY file of that common
    shape (module docstring), as trimesh reads them; None for any other file."""
    end = data.find(b"end_header\n", 0, _MOST_HEADER_BYTES)
    if not data.startswith(b"ply\n") or end < 0:
        return None
    header = data[:end].decode("ascii", errors="replace").split("\n")[1:]
    lines = [line.split() for line in header if line.strip() and not re.match(r"(comment|obj_info)\b", line)]
    if not lines or len(lines[0]) != 3 or lines[0][0] != "format" or lines[0][1] not in _FORMATS:
        return None
    order = _FORMATS[lines[0][1]]
    elements = []  # (name, count, [property words])
    for words in lines[1:]:
        if words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            elements[-1][2].append(words[1:])
        else:
            return None
    if [name for name, _, _ in elements] != ["vertex", "face"]:
        return None
    (_, vertex_count, vertex_properties), (_, face_count, face_properties) = elements
    if vertex_count == 0 or face_count == 0:
        return None
    if any(len(words) != 2 or words[0] not in _SCALARS for words in vertex_properties):
        return None
    names = [words[1] for words in vertex_properties]
    if len(set(names)) != len(names) or not {"x", "y", "z"} <= set(names) or {"nx", "ny", "nz"} & set(names):
        return None  # (trimesh reads vertex normals)
    if len(face_properties) != 1:
        return None
    words = face_properties[0]
    if len(words) != 4 or words[0] != "list" or words[3] not in ("vertex_indices", "vertex_index") \
            or words[1] not in _SCALARS or words[2] not in _SCALARS or _SCALARS[words[2]][0] == "f":
        return None
    vertex_type = np.dtype([(name, order + _SCALARS[kind]) for kind, name in vertex_properties])
    face_type = np.dtype([("count", order + _SCALARS[words[1]]), ("corners", order + _SCALARS[words[2]], 3)])
    start = end + len(b"end_header\n")
    faces_at = start + vertex_count * vertex_type.itemsize
    if faces_at + face_count * face_type.itemsize != len(data):
        return None  # faces of other sizes, or bytes missing or left over
    rows = np.frombuffer(data, face_type, face_count, faces_at)
    if not np.all(rows["count"] == 3):
        return None
    points = np.frombuffer(data, vertex_type, vertex_count, start)
    vertices = np.stack([points[axis].astype(np.float64) for axis in "xyz"], axis=1)
    return vertices, rows["corners"].astype(np.int64)
