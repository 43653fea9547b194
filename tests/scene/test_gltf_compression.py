"""Compressed glTF geometry (clrays/scene/gltf_compression.py, docs/scene-format.md "glTF 2.0
scenes"): KHR_draco_mesh_compression through DracoPy and EXT_meshopt_compression through
meshopt. Each file is written here from a plain twin, encoded by the packages' own
encoders; the import matches the twin within the codec's quantization step and renders
within 0.5 % of it. A missing decoder, an uncompressed fallback, absurd counts and corrupt
streams are each tested for their one line."""
from __future__ import annotations

import base64
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from conftest import run_cli
from clrays.errors import SceneError
from clrays.scene import gltf, gltf_compression
from clrays.scene.load import load_scene

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("make_gltf_example", ROOT / "tools" / "make_gltf_example.py")
tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tool)
GltfBuilder, light_ref, box = tool.GltfBuilder, tool.light_ref, tool.box

DRACO, MESHOPT = gltf_compression.DRACO, gltf_compression.MESHOPT
#: Draco's position quantization here: the decoded positions are within half a step of the plain ones.
POSITION_BITS = 14
#: The exponential filter's mantissa bits: each position within max|row| × 2^-(bits-1) of the plain one.
EXPONENT_BITS = 16
SMALL = ["image.width=64", "image.height=40", "medium.sigma_s=0.08", "medium.sigma_a=0.01"]


def _parts() -> list[tuple[np.ndarray, np.ndarray, np.ndarray, tuple[float, float, float]]]:
    """(vertices, normals, faces, colour) of the scene: a smooth sphere-ish ball on a flat box floor."""
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.8)
    vertices, normals, faces = box([3.0, 0.1, 3.0])
    return [(ball.vertices + [0.0, 0.9, 0.0], np.asarray(ball.vertex_normals), np.asarray(ball.faces),
             (0.9, 0.6, 0.3)),
            (vertices - [0.0, 0.1, 0.0], normals, faces, (0.7, 0.7, 0.7))]


def _finish(builder: GltfBuilder) -> GltfBuilder:
    """Nodes for the meshes, a point light and a camera looking at the ball."""
    for mesh in range(len(builder.doc["meshes"])):
        builder.node(mesh=mesh)
    builder.node(extensions=light_ref(builder.light(type="point", intensity=40.0)), translation=[1.5, 4.0, 1.0])
    builder.node(camera=builder.camera(0.8), translation=[0.0, 1.6, 5.0], rotation=tool.quaternion([1, 0, 0], -10))
    return builder


def _plain() -> GltfBuilder:
    builder = GltfBuilder()
    for vertices, normals, faces, colour in _parts():
        builder.mesh(vertices, faces, colour, normals)
    return _finish(builder)


def _material(builder: GltfBuilder, colour) -> int:
    builder.doc["materials"].append({"pbrMetallicRoughness": {"baseColorFactor": [*colour, 1.0]}})
    return len(builder.doc["materials"]) - 1


def _uses(document: dict, extension: str, required: bool) -> None:
    document.setdefault("extensionsUsed", []).append(extension)
    if required:
        document.setdefault("extensionsRequired", []).append(extension)


# --------------------------------------------------------------------------- writing Draco files


def _draco(bits: int = POSITION_BITS, fallback: bool = False) -> GltfBuilder:
    """The scene with each mesh a Draco stream (DracoPy's encoder). The accessors hold the
    decoded counts, as the extension's implementation note asks; with `fallback` they keep
    bufferViews of the decoded data too, and the extension is used, not required."""
    import DracoPy

    builder = GltfBuilder()
    for vertices, normals, faces, colour in _parts():
        stream = DracoPy.encode(vertices, faces.astype(np.uint32), quantization_bits=bits, normals=normals,
                                normal_quantization_bits=12, compression_level=7)
        decoded = DracoPy.decode(stream)
        ids = {name: next(a["unique_id"] for a in decoded.attributes if a["attribute_type"] == kind)
               for name, kind in (("POSITION", DracoPy.AttributeType.POSITION),
                                  ("NORMAL", DracoPy.AttributeType.NORMAL))}
        attributes = {"POSITION": builder.accessor(decoded.points), "NORMAL": builder.accessor(decoded.normals)}
        indices = builder.accessor(np.asarray(decoded.faces).reshape(-1), 5125)
        if not fallback:
            for index in (*attributes.values(), indices):
                del builder.doc["accessors"][index]["bufferView"]
        while len(builder.binary) % 4:
            builder.binary.append(0)
        builder.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(builder.binary), "byteLength": len(stream)})
        builder.binary += stream
        primitive = {"attributes": attributes, "indices": indices, "mode": 4, "material": _material(builder, colour),
                     "extensions": {DRACO: {"bufferView": len(builder.doc["bufferViews"]) - 1, "attributes": ids}}}
        builder.doc["meshes"].append({"primitives": [primitive]})
    _uses(builder.doc, DRACO, required=not fallback)
    return _finish(builder)


# --------------------------------------------------------------------------- writing meshopt files


class _Meshopt:
    """A GLB whose bufferViews hold EXT_meshopt_compression data in buffer 0 (the BIN chunk)
    and point at buffer 1: a placeholder without data, or with `fallback` the plain bytes
    as a data URI. The extension is required unless there is a fallback, or `required` says."""

    def __init__(self, fallback: bool = False, required: bool | None = None):
        self.builder, self.fallback, self.plain = GltfBuilder(), fallback, bytearray()
        self.required = not fallback if required is None else required

    def view(self, source: np.ndarray, encoded: bytes, mode: str, filter_name: str = "NONE") -> int:
        """A view of `source`'s layout (its rows of bytes), stored as `encoded`; its fallback is
        what decoding gives, as the extension asks."""
        import meshopt

        count, stride = len(source), source.nbytes // len(source)
        rows = np.ascontiguousarray(meshopt.decode_gltf_buffer(encoded, count, stride, mode, filter_name))
        binary = self.builder.binary
        for data in (binary, self.plain):
            while len(data) % 4:
                data.append(0)
        extension = {"buffer": 0, "byteOffset": len(binary), "byteLength": len(encoded), "byteStride": stride,
                     "mode": mode, "count": len(rows), **({"filter": filter_name} if filter_name != "NONE" else {})}
        view = {"buffer": 1, "byteOffset": len(self.plain), "byteLength": rows.nbytes,
                "extensions": {MESHOPT: extension}}
        if mode == "ATTRIBUTES":
            view["byteStride"] = stride
        binary += encoded
        self.plain += rows.tobytes()
        self.builder.doc["bufferViews"].append(view)
        return len(self.builder.doc["bufferViews"]) - 1

    def accessor(self, view: int, count: int, component: int, kind: str, normalized: bool = False) -> int:
        accessor = {"bufferView": view, "componentType": component, "count": count, "type": kind,
                    **({"normalized": True} if normalized else {})}
        self.builder.doc["accessors"].append(accessor)
        return len(self.builder.doc["accessors"]) - 1

    def glb(self) -> bytes:
        document = dict(self.builder.doc)
        buffer = {"byteLength": len(self.plain)}
        if self.fallback:
            buffer["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.plain)).decode()
        document["buffers"] = [{"byteLength": len(self.builder.binary) + (-len(self.builder.binary) % 4)}, buffer]
        _uses(document, MESHOPT, required=self.required)
        return self.builder.glb(document)


def _meshopt_scene(index_mode: str = "TRIANGLES", position_filter: str = "NONE", fallback: bool = False,
                   required: bool | None = None) -> bytes:
    """The scene with every view meshopt-compressed: positions as float32 rows (or through the
    exponential filter), normals as float32 rows, indices as TRIANGLES or INDICES."""
    import meshopt

    writer = _Meshopt(fallback, required)
    for vertices, normals, faces, colour in _parts():
        positions = np.asarray(vertices, np.float32)
        if position_filter == "EXPONENTIAL":
            filtered = meshopt.encode_filter_exp(positions, EXPONENT_BITS, "SharedVector")
            encoded = meshopt.encode_gltf_buffer(filtered, "ATTRIBUTES")
        else:
            encoded = meshopt.encode_gltf_buffer(positions, "ATTRIBUTES")
        position = writer.accessor(writer.view(positions, encoded, "ATTRIBUTES", position_filter), len(vertices),
                                   5126, "VEC3")
        writer.builder.doc["accessors"][position].update(min=np.min(vertices, 0).tolist(),
                                                         max=np.max(vertices, 0).tolist())
        normals32 = np.asarray(normals, np.float32)
        normal = writer.accessor(writer.view(normals32, meshopt.encode_gltf_buffer(normals32, "ATTRIBUTES"),
                                             "ATTRIBUTES"), len(normals), 5126, "VEC3")
        indices = np.asarray(faces, np.uint32).reshape(-1)
        view = writer.view(indices, meshopt.encode_gltf_buffer(indices, index_mode), index_mode)
        primitive = {"attributes": {"POSITION": position, "NORMAL": normal}, "mode": 4,
                     "indices": writer.accessor(view, len(indices), 5125, "SCALAR"),
                     "material": _material(writer.builder, colour)}
        writer.builder.doc["meshes"].append({"primitives": [primitive]})
    _finish(writer.builder)
    return writer.glb()


# --------------------------------------------------------------------------- comparing


def _match(triangles: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Each of `triangles` (T, 3 corners, a position and maybe more per corner) paired with the
    reference triangle of nearest centroid, its corners rotated to fit best (codecs may
    reorder vertices, and meshopt's triangle codec rotates a triangle's corners): the
    largest difference of any component in each pair. Every reference triangle is used once."""
    nearest = cKDTree(reference[:, :, :3].mean(axis=1)).query(triangles[:, :, :3].mean(axis=1))[1]
    assert len(triangles) == len(reference) and len(np.unique(nearest)) == len(reference)
    paired = reference[nearest]
    differences = [np.abs(np.roll(triangles, shift, axis=1) - paired).max(axis=(1, 2)) for shift in range(3)]
    return np.min(differences, axis=0)


def _import(tmp_path: Path, data: bytes, name: str) -> gltf.Imported:
    path = tmp_path / name
    path.write_bytes(data)
    return gltf.import_gltf(path, name)


def _render_error(tmp_path: Path, data: bytes, name: str):
    """The relative error of the file's render against the plain twin's (minmax, 64×40)."""
    import clrays
    from clrays.reference.metrics import image_error

    (tmp_path / "plain.glb").write_bytes(_plain().glb())
    (tmp_path / name).write_bytes(data)
    reference = clrays.render(load_scene(tmp_path / "plain.glb", SMALL), method="minmax", reuse=False)
    image = clrays.render(load_scene(tmp_path / name, SMALL), method="minmax", reuse=False)
    return image_error(image, reference)


def _one_line_refusal(tmp_path: Path, data: bytes, name: str) -> str:
    """The command line's output for a refused file: exit 1, one line, no traceback; the line
    from the file's name on."""
    path = tmp_path / name
    path.write_bytes(data)
    code, out = run_cli("render", path, "-o", tmp_path / "x.png", *sum((["--set", s] for s in SMALL), []))
    assert code == 1 and "Traceback" not in out, out
    lines = [line for line in out.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"clrays: error: {path}: "), out
    return lines[0].removeprefix(f"clrays: error: {tmp_path}/")


# --------------------------------------------------------------------------- Draco


def test_draco_positions_are_the_plain_ones_within_half_a_quantization_step(tmp_path):
    """Draco quantizes positions to 2^bits − 1 steps over the mesh's largest extent: each
    coordinate of each imported corner lies within half a step (and float32's rounding) of
    the plain twin's."""
    pytest.importorskip("DracoPy")
    plain = _import(tmp_path, _plain().glb(), "plain.glb")
    draco = _import(tmp_path, _draco().glb(), "draco.glb")
    assert draco.object_count == plain.object_count == 2
    for k, (vertices, _, _, _) in enumerate(_parts()):
        extent = float(np.ptp(vertices, axis=0).max())
        tolerance = 0.5 * extent / (2 ** POSITION_BITS - 1) + 1e-6
        ours, theirs = (imported.triangles[imported.object_id == k] for imported in (draco, plain))
        distances = _match(ours, theirs)
        assert distances.max() <= tolerance, (k, distances.max(), tolerance)
        assert distances.max() > 0  # quantized, not the fallback's or the plain file's exact values
    np.testing.assert_array_equal(draco.outward, plain.outward)  # the winding survives: closed, outward


def test_draco_reads_the_fallback_without_dracopy(tmp_path, monkeypatch):
    """A file that keeps uncompressed accessors (the extension used, not required) reads them
    when DracoPy is missing; with DracoPy it decodes the stream, which gives the same data."""
    pytest.importorskip("DracoPy")
    data = _draco(fallback=True).glb()
    decoded = _import(tmp_path, data, "draco.glb")
    monkeypatch.setitem(sys.modules, "DracoPy", None)  # `import DracoPy` now raises ImportError
    fallback = _import(tmp_path, data, "draco.glb")
    np.testing.assert_allclose(fallback.triangles, decoded.triangles, atol=1e-6)
    np.testing.assert_allclose(fallback.normals, decoded.normals, atol=1e-6)


def test_draco_without_dracopy_names_the_extra(tmp_path, monkeypatch):
    pytest.importorskip("DracoPy")
    data = _draco().glb()
    monkeypatch.setitem(sys.modules, "DracoPy", None)
    with pytest.raises(SceneError, match=r"^draco.glb: extensionsRequired: KHR_draco_mesh_compression needs "
                                         r"DracoPy, not installed: pip install 'clrays\[draco\]'$"):
        _import(tmp_path, data, "draco.glb")
    line = _one_line_refusal(tmp_path, data, "draco.glb")
    assert line.endswith("pip install 'clrays[draco]'"), line


def test_corrupt_draco_data_is_one_line(tmp_path):
    """Bytes of the stream overwritten after its header: DracoPy's failure becomes one line."""
    pytest.importorskip("DracoPy")
    builder = _draco()
    view = builder.doc["bufferViews"][builder.doc["meshes"][0]["primitives"][0]["extensions"][DRACO]["bufferView"]]
    start = view["byteOffset"] + 24
    builder.binary[start:start + 64] = bytes(range(64))
    line = _one_line_refusal(tmp_path, builder.glb(), "corrupt.glb")
    assert f"meshes.0.primitives.0.extensions.{DRACO}: expected a Draco mesh DracoPy decodes, got (" in line, line


def test_a_draco_header_that_disagrees_with_the_accessors_is_refused_before_decoding(tmp_path, monkeypatch):
    """The faces a Draco header declares are read before decoding and must be the indices
    accessor's count / 3: a file whose stream claims more is refused without decoding it."""
    DracoPy = pytest.importorskip("DracoPy")
    builder = _draco()
    primitive = builder.doc["meshes"][0]["primitives"][0]
    builder.doc["accessors"][primitive["indices"]]["count"] -= 3  # the stream now holds one face more than said
    monkeypatch.setattr(DracoPy, "decode", lambda _: pytest.fail("decoded a stream its header already refused"))
    with pytest.raises(SceneError, match=rf"meshes.0.primitives.0.extensions.{DRACO}: expected 319 faces, as "
                                         rf"accessors.2.count says, got 320 in the Draco header"):
        _import(tmp_path, builder.glb(), "draco.glb")


def test_a_draco_strip_is_refused(tmp_path):
    """Draco decodes triangle lists: a primitive of another mode is one line."""
    pytest.importorskip("DracoPy")
    builder = _draco()
    builder.doc["meshes"][1]["primitives"][0]["mode"] = 5
    with pytest.raises(SceneError, match=r"^draco.glb: meshes.1.primitives.0.mode: expected 4 \(TRIANGLES\) for a "
                                         r"Draco primitive \(clrays decodes triangle lists\), got 5$"):
        _import(tmp_path, builder.glb(), "draco.glb")


def test_the_draco_header_counts_are_read_for_both_connectivity_codecs():
    """Sequential (compression level 0) and edgebreaker streams: the header's faces are the
    mesh's, its vertices at least the mesh's (edgebreaker counts split vertices too)."""
    DracoPy = pytest.importorskip("DracoPy")
    vertices, _, faces, _ = _parts()[0]
    for level in (0, 7):
        stream = DracoPy.encode(vertices, faces.astype(np.uint32), compression_level=level)
        assert stream[8] == (0 if level == 0 else 1)  # the encoder method byte
        counts = gltf_compression.draco_header_counts(stream)
        assert counts[0] == len(faces) and len(vertices) <= counts[1] <= len(vertices) + 2, counts
    assert gltf_compression.draco_header_counts(b"DRACO\x02\x01\x01\x01\x00\x00") is None  # another version


# --------------------------------------------------------------------------- meshopt


@pytest.mark.parametrize("index_mode", ["TRIANGLES", "INDICES"])
def test_meshopt_attributes_and_indices_decode_exactly(tmp_path, index_mode):
    """The attribute codec and both index codecs are lossless: the same triangles with the same
    normals at their corners (TRIANGLES may rotate a triangle's corners)."""
    pytest.importorskip("meshopt")
    plain = _import(tmp_path, _plain().glb(), "plain.glb")
    compressed = _import(tmp_path, _meshopt_scene(index_mode), "meshopt.glb")
    corners = [np.concatenate([imported.triangles, imported.normals], axis=2) for imported in (compressed, plain)]
    assert _match(*corners).max() == 0.0


def test_meshopt_exponential_positions_are_within_the_mantissa_step(tmp_path):
    """The exponential filter keeps EXPONENT_BITS of mantissa with one exponent a vertex: each
    coordinate within max|coordinate| × 2^-(bits-1) of the plain one."""
    pytest.importorskip("meshopt")
    plain = _import(tmp_path, _plain().glb(), "plain.glb")
    compressed = _import(tmp_path, _meshopt_scene(position_filter="EXPONENTIAL"), "meshopt.glb")
    for k in range(2):
        ours, theirs = (imported.triangles[imported.object_id == k] for imported in (compressed, plain))
        distances = _match(ours, theirs)
        tolerance = np.abs(theirs).max() * 2.0 ** -(EXPONENT_BITS - 1)  # the largest coordinate's mantissa step
        assert 0 < distances.max() <= tolerance, (k, distances.max(), tolerance)


@pytest.mark.parametrize("filter_name, bits", [("OCTAHEDRAL", 12), ("QUATERNION", 12)])
def test_meshopt_octahedral_and_quaternion_filters(tmp_path, filter_name, bits):
    """Unit vectors through the octahedral filter and unit quaternions through the quaternion
    filter, read through an accessor as normalized int16: each within two quantization steps
    of `bits` (a quaternion up to its sign)."""
    meshopt = pytest.importorskip("meshopt")
    rng = np.random.default_rng(7)
    values = rng.normal(size=(200, 4))
    if filter_name == "OCTAHEDRAL":
        values[:, :3] /= np.linalg.norm(values[:, :3], axis=1, keepdims=True)
        values[:, 3] = 1.0
        filtered = meshopt.encode_filter_oct(values, 8, bits)
    else:
        values /= np.linalg.norm(values, axis=1, keepdims=True)
        filtered = meshopt.encode_filter_quat(values, 8, bits)
    writer = _Meshopt()
    encoded = meshopt.encode_gltf_buffer(filtered, "ATTRIBUTES")
    accessor = writer.accessor(writer.view(filtered, encoded, "ATTRIBUTES", filter_name), len(values), 5122, "VEC4",
                               normalized=True)
    path = tmp_path / "filtered.glb"
    path.write_bytes(writer.glb())
    reader = gltf._open(path, "filtered.glb")
    read = reader.accessor(accessor, "test", ("VEC4",), (5122,))
    if filter_name == "OCTAHEDRAL":
        read, values = read[:, :3], values[:, :3]
    else:
        read = read * np.sign(np.sum(read * values, axis=1))[:, None]  # (an accessor's values are read-only)
    step = 1.0 / (2 ** (bits - 1) - 1)
    error = np.abs(read - values).max()
    assert 0 < error <= 2 * step, (error, step)


def test_meshopt_reads_the_fallback_buffer_without_meshopt(tmp_path, monkeypatch):
    pytest.importorskip("meshopt")
    data = _meshopt_scene(fallback=True)
    decoded = _import(tmp_path, data, "meshopt.glb")
    monkeypatch.setitem(sys.modules, "meshopt", None)
    fallback = _import(tmp_path, data, "meshopt.glb")
    np.testing.assert_array_equal(fallback.triangles, decoded.triangles)


def test_meshopt_without_the_package_names_the_extra(tmp_path, monkeypatch):
    """Required: refused at the top. Used but with a placeholder buffer (no fallback data):
    refused at the view."""
    pytest.importorskip("meshopt")
    required, used = _meshopt_scene(), _meshopt_scene(required=False)
    monkeypatch.setitem(sys.modules, "meshopt", None)
    line = _one_line_refusal(tmp_path, required, "meshopt.glb")
    assert line == ("meshopt.glb: extensionsRequired: EXT_meshopt_compression needs meshopt, not installed: "
                    "pip install 'clrays[meshopt]'"), line
    path = tmp_path / "placeholder.glb"
    path.write_bytes(used)
    with pytest.raises(SceneError, match=rf"^placeholder.glb: bufferViews.0.extensions.{MESHOPT}: {MESHOPT} needs "
                                         r"meshopt, not installed: pip install 'clrays\[meshopt\]'$"):
        gltf.import_gltf(path, "placeholder.glb")


def test_corrupt_meshopt_data_is_one_line(tmp_path):
    pytest.importorskip("meshopt")
    data = bytearray(_meshopt_scene())
    # The first view's stream starts the BIN chunk: overwrite it after its 0xa0 header byte.
    start = data.index(b"BIN\x00") + 4 + 1
    data[start:start + 40] = b"\xff" * 40
    line = _one_line_refusal(tmp_path, bytes(data), "corrupt.glb")
    assert line.startswith(f"corrupt.glb: bufferViews.0.extensions.{MESHOPT}: expected ATTRIBUTES data "
                           "meshoptimizer decodes, got (Malformed buffer data"), line


def test_absurd_meshopt_counts_are_refused_before_decoding(tmp_path, monkeypatch):
    """A view that claims a billion rows from a few compressed bytes: refused by the byte
    budget before meshopt allocates anything."""
    meshopt = pytest.importorskip("meshopt")
    writer = _Meshopt()
    encoded = meshopt.encode_gltf_buffer(np.zeros((4, 3), np.float32), "ATTRIBUTES")
    writer.accessor(writer.view(np.zeros((4, 3), np.float32), encoded, "ATTRIBUTES"), 4, 5126, "VEC3")
    view = writer.builder.doc["bufferViews"][0]
    view["extensions"][MESHOPT]["count"] = 10 ** 9
    view["byteLength"] = 12 * 10 ** 9
    path = tmp_path / "absurd.glb"
    path.write_bytes(writer.glb())
    monkeypatch.setattr(meshopt, "decode_gltf_buffer", lambda *_: pytest.fail("decoded an absurd count"))
    reader = gltf._open(path, "absurd.glb")
    with pytest.raises(SceneError, match=rf"^absurd.glb: bufferViews.0.extensions.{MESHOPT}: expected at most "
                                         r"1024 MiB read and decoded by the import in all .*, got 12000000000 bytes "):
        reader.view(0)


def test_meshopt_layout_rules(tmp_path):
    """The extension's rules on a view's count, stride and filter, each one line."""
    meshopt = pytest.importorskip("meshopt")
    rows = np.zeros((6, 3), np.float32)
    for change, pattern in ((lambda e, v: e.update(mode="TRIANGLES"), r"byteStride: expected 2 or 4 for TRIANGLES"),
                            (lambda e, v: e.update(filter="COLOUR"), r"filter: expected NONE, OCTAHEDRAL, "),
                            (lambda e, v: e.update(filter="QUATERNION"), r"byteStride: expected 8 for the QUATERNION"),
                            (lambda e, v: v.update(byteLength=60), r"bufferViews.0.byteLength: expected count × "
                                                                   r"byteStride = 6 × 12 = 72, got 60")):
        writer = _Meshopt()
        writer.view(rows, meshopt.encode_gltf_buffer(rows, "ATTRIBUTES"), "ATTRIBUTES")
        view = writer.builder.doc["bufferViews"][0]
        change(view["extensions"][MESHOPT], view)
        path = tmp_path / "rules.glb"
        path.write_bytes(writer.glb())
        with pytest.raises(SceneError, match=pattern):
            gltf._open(path, "rules.glb").view(0)


# --------------------------------------------------------------------------- renders


@pytest.mark.parametrize("codec", ["draco", "meshopt"])
def test_a_compressed_file_renders_as_its_plain_twin(tmp_path, codec):
    """Draco (14-bit positions, 12-bit normals) and meshopt (exponential-filtered positions)
    render within 0.5 % relative RMSE of the plain file."""
    pytest.importorskip({"draco": "DracoPy", "meshopt": "meshopt"}[codec])
    data = _draco().glb() if codec == "draco" else _meshopt_scene(position_filter="EXPONENTIAL")
    error = _render_error(tmp_path, data, f"{codec}.glb")
    print(f"{codec} against its plain twin: {error}")
    assert error.pixels > 1000 and error.rmse < 0.005, error


def test_a_plain_file_never_imports_the_decoders(tmp_path):
    """A file without compression loads without either decoder being imported."""
    import subprocess

    (tmp_path / "plain.glb").write_bytes(_plain().glb())
    code = ("import sys; from clrays.scene.load import load_scene; load_scene(sys.argv[1]); "
            "print(sorted(m for m in ('DracoPy', 'meshopt') if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", code, str(tmp_path / "plain.glb")], capture_output=True, text=True,
                            check=True)
    assert result.stdout.strip() == "[]", result
