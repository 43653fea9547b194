"""Compressed geometry in glTF files, as the web sends it: `KHR_draco_mesh_compression` (a
primitive's attributes and indices in one Draco stream, decoded by DracoPy) and
`EXT_meshopt_compression` (a bufferView's bytes through meshoptimizer's attribute, triangle
and index codecs and its filters, decoded by the `meshopt` package). Both decoders are
optional extras, imported only when a file needs them:

    pip install 'clrays[draco]'     # DracoPy
    pip install 'clrays[meshopt]'   # meshopt
    pip install 'clrays[web]'       # both

Without the extra, a file that keeps an uncompressed fallback (the extension in
`extensionsUsed`, not `extensionsRequired`) reads the fallback; one without fails in one
line that names the extra. Counts are checked before anything is decoded (the JSON's, and
a Draco header's), and a decoder's failure on corrupt data is one line too:

    x.glb: bufferViews.3.extensions.EXT_meshopt_compression: expected ATTRIBUTES data meshoptimizer decodes, got (Malformed buffer data: -2)

gltf.py calls in at four marked places: `_check_header` (`check_required`), `_Reader.view`
(`meshopt_view`), `_primitive` (`decode_draco`) and `_Reader.accessor` (the Draco-decoded
values `decode_draco` left in `reader.decoded`).
"""
from __future__ import annotations

import importlib
from typing import Any, NoReturn

import numpy as np

from ..errors import SceneError
from .limits import MAX_TRIANGLES

#: gltf.py's _Reader, which calls in here: it imports this module, so this one does not name it.
Reader = Any

DRACO = "KHR_draco_mesh_compression"
MESHOPT = "EXT_meshopt_compression"
EXTENSIONS = (DRACO, MESHOPT)
#: extension -> (the module that decodes it, its package's name, the clrays extra that installs it)
DECODERS = {DRACO: ("DracoPy", "DracoPy", "draco"), MESHOPT: ("meshopt", "meshopt", "meshopt")}
#: The most vertices a decoded primitive may hold: every corner of MAX_TRIANGLES apart.
MAX_DECODED_VERTICES = 3 * MAX_TRIANGLES

_MESHOPT_MODES = ("ATTRIBUTES", "TRIANGLES", "INDICES")
_MESHOPT_FILTERS = ("NONE", "OCTAHEDRAL", "QUATERNION", "EXPONENTIAL")
_TRIANGLES = 4
#: accessor componentType -> bytes, for what a decoded accessor would take stored plainly
_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def _decoder(extension: str):
    """The decoder's module, or None where its extra is not installed."""
    try:
        return importlib.import_module(DECODERS[extension][0])
    except ImportError:
        return None


def _missing(reader: Reader, extension: str, path: str) -> NoReturn:
    _, package, extra = DECODERS[extension]
    raise SceneError(f"{reader.file}: {path}: {extension} needs {package}, not installed: "
                     f"pip install 'clrays[{extra}]'")


def _charge(reader: Reader, size: int, path: str) -> None:
    """Decoded bytes count against the import's one budget with everything else it reads, before they are made."""
    reader.charge(size, path, "decoded compressed data")


def _extension(reader: Reader, obj: dict, name: str, path: str) -> dict | None:
    """obj.extensions[name] (an object), or None where obj does not use it."""
    extensions = obj.get("extensions")
    if not isinstance(extensions, dict) or name not in extensions:
        return None
    return reader.get(extensions, name, f"{path}.extensions", "dict")


def check_required(reader: Reader, required: list) -> None:
    """A required compression extension needs its decoder: said once, at the top, naming the extra."""
    for extension in EXTENSIONS:
        if extension in required and _decoder(extension) is None:
            _missing(reader, extension, "extensionsRequired")


# --------------------------------------------------------------------------- EXT_meshopt_compression


def meshopt_view(reader: Reader, index: int, view: dict) -> tuple[dict, Any, int, int] | None:
    """bufferViews[index] as `_Reader.view` gives it (the view, its bytes, byteOffset, byteLength),
    decoded from its EXT_meshopt_compression data; None where the view has none, or where
    meshopt is not installed and the view's own buffer holds the uncompressed fallback."""
    path = f"bufferViews.{index}"
    where = f"{path}.extensions.{MESHOPT}"
    extension = _extension(reader, view, MESHOPT, path)
    if extension is None:
        return None
    key = ("bufferViews", index)
    if key in reader.decoded:
        return reader.decoded[key]
    meshopt = _decoder(MESHOPT)
    if meshopt is None:
        if _has_fallback(reader, view, path):
            return None
        _missing(reader, MESHOPT, where)
    mode = reader.get(extension, "mode", where, "string")
    if mode not in _MESHOPT_MODES:
        reader.fail(f"{where}.mode", " or ".join(_MESHOPT_MODES), f'"{mode}"')
    filter_name = reader.get(extension, "filter", where, "string", "NONE")
    if filter_name not in _MESHOPT_FILTERS:
        reader.fail(f"{where}.filter", ", ".join(_MESHOPT_FILTERS), f'"{filter_name}"')
    stride = reader.get(extension, "byteStride", where, "int", lo=1, hi=256)
    count = reader.get(extension, "count", where, "int", lo=1)
    _check_meshopt_layout(reader, where, mode, filter_name, stride, count)
    length = reader.get(view, "byteLength", path, "int", lo=1)
    if reader.get(view, "byteStride", path, "int", stride) != stride:
        reader.fail(f"{path}.byteStride", f"the extension's byteStride {stride}", view["byteStride"])
    if count * stride != length:  # the spec's rule; it also bounds what decoding makes by the view's length
        reader.fail(f"{path}.byteLength", f"count × byteStride = {count} × {stride} = {count * stride}", length)
    _charge(reader, length, where)  # before decoding: a few compressed bytes may claim gigabytes
    source, offset, compressed = reader.byte_range(extension, where)
    try:
        rows = meshopt.decode_gltf_buffer(bytes(source[offset:offset + compressed]), count, stride, mode,
                                          filter_name)
    except (ValueError, RuntimeError) as exc:  # meshopt reports malformed data as ValueError
        reader.fail(where, f"{mode} data meshoptimizer decodes", f"({exc})")
    data = np.ascontiguousarray(rows).tobytes()
    reader.decoded[key] = (view, data, 0, length)
    return reader.decoded[key]


def _check_meshopt_layout(reader: Reader, where: str, mode: str, filter_name: str, stride: int,
                          count: int) -> None:
    """The extension's rules on stride, count and filter for each mode (its README, "JSON schema updates")."""
    if mode == "ATTRIBUTES":
        if stride % 4:
            reader.fail(f"{where}.byteStride", "a multiple of 4 for ATTRIBUTES", stride)
        strides = {"OCTAHEDRAL": (4, 8), "QUATERNION": (8,)}.get(filter_name)
        if strides is not None and stride not in strides:
            reader.fail(f"{where}.byteStride", f"{' or '.join(map(str, strides))} for the {filter_name} filter", stride)
        return
    if stride not in (2, 4):
        reader.fail(f"{where}.byteStride", f"2 or 4 for {mode}", stride)
    if filter_name != "NONE":
        reader.fail(f"{where}.filter", f"NONE for {mode}", f'"{filter_name}"')
    if mode == "TRIANGLES" and count % 3:
        reader.fail(f"{where}.count", "a multiple of 3 for TRIANGLES", count)


def _has_fallback(reader: Reader, view: dict, path: str) -> bool:
    """Whether the view's own buffer holds data (a uri, or the GLB's BIN chunk), not a placeholder."""
    buffer_index = reader.index(view, "buffer", path, "buffers")
    return "uri" in reader.items("buffers")[buffer_index] or (buffer_index == 0 and reader.binary is not None)


# --------------------------------------------------------------------------- KHR_draco_mesh_compression


def decode_draco(reader: Reader, primitive: dict, path: str) -> None:
    """Decode a primitive's Draco stream, if it has one, into `reader.decoded`, where
    `_Reader.accessor` finds its attributes and indices in place of their bufferViews. Without
    DracoPy, a primitive whose accessors keep their bufferViews (the fallback) is read from
    them; one without fails naming the extra."""
    where = f"{path}.extensions.{DRACO}"
    extension = _extension(reader, primitive, DRACO, path)
    if extension is None:
        return
    attributes = reader.get(primitive, "attributes", path, "dict")
    ids = reader.get(extension, "attributes", where, "dict")
    accessors = {name: reader.index(attributes, name, f"{path}.attributes", "accessors") for name in ids
                 if name in attributes}
    if "indices" in primitive:
        accessors["indices"] = reader.index(primitive, "indices", path, "accessors")
    draco = _decoder(DRACO)
    if draco is None:
        if all("bufferView" in reader.items("accessors")[index] for index in accessors.values()):
            return
        _missing(reader, DRACO, where)
    if reader.get(primitive, "mode", path, "int", _TRIANGLES) != _TRIANGLES:
        reader.fail(f"{path}.mode", "4 (TRIANGLES) for a Draco primitive (clrays decodes triangle lists)",
                    primitive["mode"])
    if "indices" not in accessors:
        reader.fail(path, "an indices accessor for the Draco primitive's faces", "none")
    for name in ids:
        if name not in attributes:
            reader.fail(f"{where}.attributes.{name}", f"an attribute of the primitive's "
                        f"({', '.join(attributes)})", "none")
        reader.get(ids, name, f"{where}.attributes", "int", lo=0)
    declared = {name: _declared(reader, index) for name, index in accessors.items()}
    vertices = declared.get("POSITION", (0, 0))[0]
    if vertices > MAX_DECODED_VERTICES:
        reader.fail(f"accessors.{accessors['POSITION']}.count", f"at most {MAX_DECODED_VERTICES} vertices "
                    "(docs/limits.md)", vertices)
    _charge(reader, sum(size for _, size in declared.values()), where)
    _, data, offset, length = reader.view(reader.index(extension, "bufferView", where, "bufferViews"))
    stream = bytes(data[offset:offset + length])
    header = draco_header_counts(stream)
    if header is not None:  # checked before decoding: a few bytes of header may ask for millions of faces
        faces, points = header
        if 3 * faces != declared["indices"][0]:
            reader.fail(where, f"{declared['indices'][0] // 3} faces, as accessors.{accessors['indices']}.count "
                        f"says", f"{faces} in the Draco header")
        if points > MAX_DECODED_VERTICES:
            reader.fail(where, f"at most {MAX_DECODED_VERTICES} vertices (docs/limits.md)",
                        f"{points} in the Draco header")
    try:
        mesh = draco.decode(stream)
    except (draco.FileTypeException, ValueError, RuntimeError, TypeError) as exc:  # DracoPy's for corrupt data
        reader.fail(where, "a Draco mesh DracoPy decodes", f"({type(exc).__name__}: {exc})")
    decoded = {"indices": np.asarray(mesh.faces).reshape(-1, 1)}  # rows, as every accessor's values
    for name, unique_id in ids.items():
        attribute = mesh.get_attribute_by_unique_id(unique_id)
        if attribute is None:
            reader.fail(f"{where}.attributes.{name}", "the unique id of an attribute in the Draco data", unique_id)
        decoded[name] = np.asarray(attribute["data"]).reshape(len(attribute["data"]), -1)
    for name, values in decoded.items():  # the spec: the accessors match the decoded data
        index = accessors[name]
        count, _ = declared[name]
        width = _WIDTHS.get(reader.items("accessors")[index].get("type"), 1)
        if len(values) != count or values.shape[1] != width:
            reader.fail(f"accessors.{index}", f"what the Draco data decodes to ({len(values)} × {values.shape[1]})",
                        f"{count} × {width}")
        reader.decoded[("accessors", index)] = values.astype(np.float64)


def _declared(reader: Reader, index: int) -> tuple[int, int]:
    """Accessor `index`'s count and the bytes it would take stored plainly."""
    accessor = reader.items("accessors")[index]
    where = f"accessors.{index}"
    count = reader.get(accessor, "count", where, "int", lo=1)
    width = _WIDTHS.get(reader.get(accessor, "type", where, "string"), 1)
    return count, count * width * _COMPONENT_BYTES.get(accessor.get("componentType"), 4)


def draco_header_counts(stream: bytes) -> tuple[int, int] | None:
    """(faces, vertices) a Draco 2.2 mesh stream declares in its connectivity header (the
    Draco bitstream specification, ParseHeader and Parse*ConnectivityData), read without
    decoding; None where the stream is another version, not a mesh, or opens with
    metadata: the decoder then checks it alone."""
    if len(stream) < 11 or stream[:5] != b"DRACO":
        return None
    major, minor, encoder_type, method = stream[5:9]
    flags = int.from_bytes(stream[9:11], "little")
    if (major, minor) != (2, 2) or encoder_type != 1 or flags & 0x8000:
        return None
    position = 11
    try:
        if method == 0:  # sequential: num_faces, num_points
            faces, position = _varint(stream, position)
            points, position = _varint(stream, position)
            return faces, points
        if method == 1:  # edgebreaker: traversal type, num_encoded_vertices, num_faces, ..., split symbols
            encoded, position = _varint(stream, position + 1)
            faces, position = _varint(stream, position)
            _, position = _varint(stream, position + 1)
            splits, position = _varint(stream, position)
            return faces, encoded + splits
    except IndexError:
        return None
    return None


def _varint(stream: bytes, position: int) -> tuple[int, int]:
    """An unsigned LEB128 integer (Draco's varUI32) at `position`: (value, the position after it)."""
    value, shift = 0, 0
    while True:
        byte = stream[position]
        value |= (byte & 0x7F) << shift
        position += 1
        if not byte & 0x80 or shift > 28:
            return value, position
        shift += 7
