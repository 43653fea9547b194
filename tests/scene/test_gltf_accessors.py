"""How glTF accessors are read (clrays/scene/gltf.py, `_Reader.accessor`): sparse
accessors (glTF 2.0 §3.6.2.3) over a view or over zeros, every one of their fields
checked, and KHR_mesh_quantization's integer positions and normals, each compared with
vertices computed here from the float geometry they stand for."""
from __future__ import annotations

import math

import numpy as np
import pytest

from clrays.errors import SceneError
from clrays.scene.load import load_scene
from test_gltf import GltfBuilder, _lit, _sorted_triangles, _write, box

QUANTIZATION = "KHR_mesh_quantization"
#: componentType -> (numpy dtype, the divisor of a normalized value), glTF 2.0 §3.6.2 and the extension's table
COMPONENTS = {5120: (np.int8, 127.0), 5121: (np.uint8, 255.0), 5122: (np.int16, 32767.0), 5123: (np.uint16, 65535.0)}


def _view(builder: GltfBuilder, array: np.ndarray, stride: int | None = None) -> int:
    """A buffer view holding `array`'s rows, each padded to `stride` bytes (tightly packed without)."""
    rows = np.ascontiguousarray(array).reshape(len(array), -1)
    raw = rows.view(np.uint8).reshape(len(rows), -1)
    if stride is not None:
        raw = np.concatenate([raw, np.zeros((len(rows), stride - raw.shape[1]), np.uint8)], axis=1)
    while len(builder.binary) % 4:
        builder.binary.append(0)
    view = {"buffer": 0, "byteOffset": len(builder.binary), "byteLength": raw.size}
    if stride is not None:
        view["byteStride"] = stride
    builder.doc["bufferViews"].append(view)
    builder.binary += raw.tobytes()
    return len(builder.doc["bufferViews"]) - 1


def _mesh(builder: GltfBuilder, position: int, faces: np.ndarray, normal: int | None = None, **node) -> int:
    attributes = {"POSITION": position, **({"NORMAL": normal} if normal is not None else {})}
    builder.doc["meshes"].append({"primitives": [{"attributes": attributes,
                                                  "indices": builder.accessor(faces.reshape(-1), 5125)}]})
    return builder.node(mesh=len(builder.doc["meshes"]) - 1, **node)


def _triangles(builder: GltfBuilder, tmp_path, name: str = "scene.glb") -> np.ndarray:
    return load_scene(_write(tmp_path, builder, name)).geometry.triangles


# --------------------------------------------------------------------------- sparse accessors


def _sparse(builder: GltfBuilder, indices, values, index_component: int = 5125) -> dict:
    """A `sparse` object: `indices` as `index_component`, `values` as float VEC3s, each in its own view."""
    dtype = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32}[index_component]
    return {"count": len(indices),
            "indices": {"bufferView": _view(builder, np.asarray(indices, dtype)), "componentType": index_component},
            "values": {"bufferView": _view(builder, np.asarray(values, np.float32))}}


@pytest.mark.parametrize("index_component", [5121, 5123, 5125])
def test_sparse_positions_over_a_view(tmp_path, index_component):
    """A unit box whose top four corners a sparse substitution lifts by 2: the triangles of
    the box with those vertices moved, for each index type."""
    vertices, _, faces = box([1, 1, 1])
    top = np.flatnonzero(vertices[:, 1] > 0)[[0, 3, 5, 9]]  # four of the twelve top corners (4 a face, 3 faces)
    b = _lit(GltfBuilder())
    position = b.accessor(vertices)
    moved = vertices[top] + [0, 2, 0]
    b.doc["accessors"][position]["sparse"] = _sparse(b, top, moved, index_component)
    _mesh(b, position, faces)
    expected = vertices.copy()
    expected[top] = moved
    np.testing.assert_allclose(_sorted_triangles(_triangles(b, tmp_path)), _sorted_triangles(expected[faces]),
                               atol=1e-6)


def test_sparse_positions_over_zeros_and_sparse_animation_keys(tmp_path):
    """An accessor without a view is zeros: a sparse substitution can give it every vertex
    of a triangle (the rest stay at the origin), and an animation's output keys too."""
    b = _lit(GltfBuilder())
    b.doc["accessors"].append({"componentType": 5126, "count": 10, "type": "VEC3"})
    corners = np.array([[0, 0, 0], [2, 0, 0], [0, 3, 0.0]])
    b.doc["accessors"][-1]["sparse"] = _sparse(b, [2, 5, 9], corners)
    node = _mesh(b, len(b.doc["accessors"]) - 1, np.array([[2, 5, 9]]))
    b.animate(node, "translation", [0.0, 1.0, 2.0], np.zeros((3, 3)))
    keys = b.doc["accessors"][-1]
    del keys["bufferView"]  # the keys are zeros, but for the last: at 2 s the node is 4 along x
    keys["sparse"] = _sparse(b, [2], [[4, 0, 0]])
    scene = load_scene(_write(tmp_path, b), ["gltf.fps=2"])
    np.testing.assert_allclose(scene.geometry.triangles[0], corners, atol=1e-6)
    for frame, shift in ((2, 0.0), (3, 2.0), (4, 4.0)):  # 1 s: the second key, 0; 1.5 s: half way to the last
        np.testing.assert_allclose(scene.animation.scene_at(scene, frame).geometry.triangles[0],
                                   corners + [shift, 0, 0], atol=1e-6)


def _bad_sparse(change):
    """A triangle whose POSITION has a valid sparse substitution of one vertex, then `change(sparse, builder)`."""
    def build(tmp_path):
        b = _lit(GltfBuilder())
        position = b.accessor(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]))
        sparse = _sparse(b, [1], [[2, 0, 0]])
        b.doc["accessors"][position]["sparse"] = sparse
        _mesh(b, position, np.array([[0, 1, 2]]))
        change(sparse, b)
        return _write(tmp_path, b)
    return build


BAD_SPARSE = {
    "count above the accessor's": (lambda s, b: s.update(count=4),
                                   r"accessors\.0\.sparse\.count: expected an integer in \[1, 3\], got 4"),
    "count 0": (lambda s, b: s.update(count=0), r"accessors\.0\.sparse\.count: expected an integer in \[1, 3\], got 0"),
    "more indices than the view holds": (lambda s, b: s.update(count=2),
                                         r"accessors\.0\.sparse\.count: expected at most 1 elements in bufferViews\.\d "
                                         r"\(4 bytes, byteOffset 0, stride 4\), got 2"),
    "an index past the count": (lambda s, b: b.binary.__setitem__(
        slice(b.doc["bufferViews"][s["indices"]["bufferView"]]["byteOffset"],
              b.doc["bufferViews"][s["indices"]["bufferView"]]["byteOffset"] + 4), np.uint32(3).tobytes()),
        r"accessors\.0\.sparse\.indices: expected indices below the accessor's count 3, got 3"),
    "indices not increasing": (lambda s, b: s.update(count=2, indices={
        "bufferView": _view(b, np.array([2, 2], np.uint32)), "componentType": 5125},
        values={"bufferView": _view(b, np.zeros((2, 3), np.float32))}),
        r"accessors\.0\.sparse\.indices: expected strictly increasing indices, got 2 then 2 at 0 and 1"),
    "float indices": (lambda s, b: s["indices"].update(componentType=5126),
                      r"accessors\.0\.sparse\.indices\.componentType: expected one of 5121, 5123, 5125 \(unsigned "
                      r"integers\), got 5126"),
    "a strided index view": (lambda s, b: b.doc["bufferViews"][s["indices"]["bufferView"]].update(byteStride=4),
                             r"bufferViews\.\d\.byteStride: expected no byteStride \(the view of "
                             r"accessors\.0\.sparse\.indices is tightly packed\), got 4"),
    "values past their view": (lambda s, b: s["values"].update(byteOffset=4),
                               r"accessors\.0\.sparse\.count: expected at most 0 elements in bufferViews\.\d "
                               r"\(12 bytes, byteOffset 4, stride 12\)"),
    "misaligned values": (lambda s, b: s["values"].update(byteOffset=2),
                          r"accessors\.0\.sparse\.values\.byteOffset: expected a multiple of the component's 4 bytes"),
    "no values": (lambda s, b: s.pop("values"), r"accessors\.0\.sparse: missing required key 'values'"),
    "values not an object": (lambda s, b: s.update(values=[1]),
                             r"accessors\.0\.sparse\.values: expected an object, got \[1\]"),
    "a NaN substituted": (lambda s, b: s.update(values={"bufferView": _view(b, np.full((1, 3), np.nan, np.float32))}),
                          r"accessors\.0: expected finite values for meshes\.0\.primitives\.0\.attributes\.POSITION, "
                          r"got \[nan, nan, nan\] at element 1"),
}


@pytest.mark.parametrize("name", list(BAD_SPARSE))
def test_a_bad_sparse_accessor_is_refused_in_one_line(tmp_path, name):
    change, pattern = BAD_SPARSE[name]
    with pytest.raises(SceneError, match=pattern) as raised:
        load_scene(_bad_sparse(change)(tmp_path))
    assert "\n" not in str(raised.value)


# --------------------------------------------------------------------------- KHR_mesh_quantization


def _quantized_box(component: int, normalized: bool, declare: str | None = "extensionsRequired"):
    """A 2 × 1 × 0.5 box off the origin, its positions stored as `component` integers
    (`normalized` or not) and its normals as normalized bytes, the node's translation and
    uniform scale mapping them back, as the extension intends. Returns (builder, the float
    box's vertices, faces, normals, the largest error quantizing allows per coordinate)."""
    dtype, divisor = COMPONENTS[component]
    info = np.iinfo(dtype)
    vertices, normals, faces = box([1.0, 0.5, 0.25])
    vertices = vertices + [3.0, -1.0, 2.0]
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    signed = info.min < 0
    offset = (low + high) / 2 if signed else low  # the integers' zero
    extent = float((high - low).max()) / (2 if signed else 1)  # what the largest integer (or 1) stands for
    largest = divisor if normalized else float(info.max)
    scale = extent / (1.0 if normalized else largest)
    codes = np.round((vertices - offset) / extent * largest).astype(dtype)
    b = _lit(GltfBuilder())
    element = 3 * np.dtype(dtype).itemsize
    position = {"bufferView": _view(b, codes, stride=4 * math.ceil(element / 4)), "componentType": component,
                "count": len(codes), "type": "VEC3", **({"normalized": True} if normalized else {})}
    b.doc["accessors"].append(position)
    normal_codes = np.round(normals * 127).astype(np.int8)
    b.doc["accessors"].append({"bufferView": _view(b, normal_codes, stride=4), "componentType": 5120,
                               "count": len(normal_codes), "type": "VEC3", "normalized": True})
    _mesh(b, len(b.doc["accessors"]) - 2, faces, normal=len(b.doc["accessors"]) - 1,
          translation=offset.tolist(), scale=[scale] * 3)
    if declare:
        b.doc.setdefault(declare, []).append(QUANTIZATION)
    return b, vertices, faces, normals, extent / (2 * largest)


@pytest.mark.parametrize("component", [5120, 5121, 5122, 5123])
@pytest.mark.parametrize("normalized", [True, False], ids=["normalized", "integer"])
def test_quantized_positions_import_as_their_float_twin(tmp_path, component, normalized):
    """Every integer position form the extension's table allows, dequantized by the node:
    the same triangles as the float box within half a quantization step, and its normals
    (normalized bytes, made unit) those of the float box's faces."""
    b, vertices, faces, normals, step = _quantized_box(component, normalized)
    scene = load_scene(_write(tmp_path, b))
    got = _sorted_triangles(scene.geometry.triangles)
    expected = _sorted_triangles(vertices[faces])
    assert got.shape == expected.shape
    rounding = 1e-6  # _sorted_triangles rounds both to 6 decimals
    assert np.abs(got - expected).max() <= step + rounding, (np.abs(got - expected).max(), step)
    got_normals = np.unique(np.round(scene.geometry.normals.reshape(-1, 3), 9), axis=0, return_counts=True)
    expected_normals = np.unique(normals[faces].reshape(-1, 3), axis=0, return_counts=True)
    for got_part, expected_part in zip(got_normals, expected_normals):
        np.testing.assert_array_equal(got_part, expected_part)


def test_the_spec_formulas_for_normalized_integers(tmp_path):
    """f = max(c / 127, -1) for a BYTE (so -128 and -127 are both -1), c / 255 for an
    UNSIGNED_BYTE: three vertices written as codes, read back as the spec says."""
    b = _lit(GltfBuilder())
    b.doc["extensionsRequired"] = [QUANTIZATION]
    codes = np.array([[-128, 0, 0], [127, -127, 0], [0, 64, 1]], np.int8)
    b.doc["accessors"].append({"bufferView": _view(b, codes, stride=4), "componentType": 5120, "count": 3,
                               "type": "VEC3", "normalized": True})
    _mesh(b, len(b.doc["accessors"]) - 1, np.array([[0, 1, 2]]))
    expected = np.array([[-1, 0, 0], [1, -1, 0], [0, 64 / 127, 1 / 127]])
    np.testing.assert_allclose(_sorted_triangles(_triangles(b, tmp_path)), _sorted_triangles(expected[None]),
                               atol=1e-12)


def test_quantized_positions_need_the_extension_declared(tmp_path):
    """Integer positions in a file that does not declare KHR_mesh_quantization are refused,
    naming it; declared in extensionsUsed alone (which the spec says it must also be
    required in), the file is read."""
    b, *_ = _quantized_box(5122, True, declare=None)
    with pytest.raises(SceneError, match=r"accessors\.\d+\.componentType: expected one of 5126 for "
                                         r"meshes\.0\.primitives\.0\.attributes\.POSITION \(integer POSITIONs need "
                                         r"KHR_mesh_quantization in extensionsRequired\), got 5122"):
        load_scene(_write(tmp_path, b))
    b.doc["extensionsUsed"].append(QUANTIZATION)
    assert len(_triangles(b, tmp_path, "used.glb")) == 12


@pytest.mark.parametrize("change, pattern", [
    (lambda normal: normal.pop("normalized"), r"accessors\.\d+\.normalized: expected true for "
                                             r"meshes\.0\.primitives\.0\.attributes\.NORMAL"),
    (lambda normal: normal.update(componentType=5121), r"accessors\.\d+\.componentType: expected one of 5126, 5120, "
                                                      r"5122 for meshes\.0\.primitives\.0\.attributes\.NORMAL, got 5121"),
])
def test_quantized_normals_are_signed_and_normalized(tmp_path, change, pattern):
    """The extension allows normalized BYTE and SHORT normals only."""
    b, *_ = _quantized_box(5122, True)
    change(b.doc["accessors"][b.doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"]])
    with pytest.raises(SceneError, match=pattern):
        load_scene(_write(tmp_path, b))
