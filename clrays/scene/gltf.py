"""glTF 2.0 scenes (`.glb`, `.gltf` with external `.bin` files or data URIs): meshes,
`KHR_lights_punctual` lights, a perspective camera and node animations, read into the
parts of a `clrays.scene.model.Scene` (docs/scene-format.md, "glTF"); skins, morph
targets and EXT_mesh_gpu_instancing are clrays.scene.gltf_motion's.

    imported = import_gltf(Path("scenes/lantern.glb"), "scenes/lantern.glb")

The JSON and the GLB chunks are read directly with `json` and numpy: every offset, length,
count and stride is checked against the bytes that hold it before an array is made, so a
hostile file stops with one line naming the file, the JSON path of the field and its
value:

    scenes/x.glb: accessors.2.count: expected at most 8 elements in bufferViews.1 (96 bytes, stride 12), got 1000

Units: glTF's metres are scene units; a light's `intensity` is photometric, as the
extension defines it (cd for point and spot lights, lux for directional ones): divided by
683 lm/W it is clrays's W/sr or W/m², times its `color` and `light_scale`. A spot's cone
falloff between `innerConeAngle` and `outerConeAngle` (the extension's smooth
attenuation) becomes a light texture over the cone, which every method reads
(docs/light-textures.md); a soft spot wider than that texture can span is a point light
whose cube texture is the falloff, zero outside the cone. A file Blender wrote gets the
falloff Cycles gives the spot it came from (`spot_attenuation`'s "blender").
"""
from __future__ import annotations

import base64
import binascii
import io
import json
import math
import struct
import sys
import urllib.parse
from collections import OrderedDict
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, NoReturn

import numpy as np

from ..errors import SceneError
from . import geometry as primitives
from . import gltf_compression
from . import gltf_motion
from .animation import Animation
from .files import FileRefused, read_regular_file
from .fields import ANIMATION, MAX_POWER
from .limits import (MAX_COORDINATE, MAX_GLB_CHUNKS, MAX_GLTF_BYTES, MAX_GLTF_IMPORT_BYTES, MAX_GLTF_JSON_VALUES,
                     MAX_GLTF_NODES, MAX_LIGHTS, MAX_OBJECTS, MAX_TRIANGLES)
from .model import (Camera, DirectionalLight, Geometry, Light, LightTexture, Medium, Phase, PointLight, Scene,
                    SpotLight)
from .textures import MAX_TEXTURE_SIDE, srgb_to_linear
from .transforms import quat_to_matrix, slerp, transform_normals, transform_points

SUFFIXES = (".glb", ".gltf")
#: The last frame an animation may have: a YAML scene's bound (`animation.frames`).
MAX_ANIMATION_FRAME = int(ANIMATION["frames"].high)
FLOAT32_MAX = float(np.finfo(np.float32).max)
FLOAT64_MAX = float(np.finfo(np.float64).max)
GLB_MAGIC = b"glTF"
_CHUNK_JSON, _CHUNK_BIN = 0x4E4F534A, 0x004E4942
#: Extensions a file may require: those clrays reads. Any other required one is refused by name,
#: unless it only changes materials (`material_only_extension`).
SUPPORTED_EXTENSIONS = ("KHR_lights_punctual", "KHR_mesh_quantization", gltf_motion.EXTENSION) + \
    gltf_compression.EXTENSIONS
#: Required extensions that change only how surfaces look or where their texels come from:
#: clrays's surfaces are diffuse with one albedo per primitive, so the file renders without
#: them, with a notice naming them. Every `KHR_materials_*` is one too.
MATERIAL_ONLY_EXTENSIONS = ("KHR_texture_transform", "KHR_texture_basisu", "EXT_texture_webp", "EXT_texture_avif")
#: How `asset.generator` of a file Blender's exporter wrote begins: its spots get Cycles' falloff.
BLENDER_GENERATOR = "Khronos glTF Blender I/O"
#: lm/W: the luminous efficacy that turns KHR_lights_punctual's cd and lux into W/sr and
#: W/m², the factor Blender's exporter applies the other way in its default lighting mode.
LUMENS_PER_WATT = 683.0

#: componentType -> (numpy little-endian dtype, largest value for `normalized`)
_COMPONENTS = {5120: ("<i1", 127.0), 5121: ("<u1", 255.0), 5122: ("<i2", 32767.0), 5123: ("<u2", 65535.0),
               5125: ("<u4", None), 5126: ("<f4", None)}
#: KHR_mesh_quantization: the componentTypes an attribute may have (POSITION's normalized or
#: not, NORMAL's normalized) in a file that declares it; FLOAT alone otherwise.
QUANTIZATION = "KHR_mesh_quantization"
_QUANTIZED = {"POSITION": (5126, 5120, 5121, 5122, 5123), "NORMAL": (5126, 5120, 5122)}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_TRIANGLES, _TRIANGLE_STRIP, _TRIANGLE_FAN = 4, 5, 6

#: Side of the texture that carries a spot's cone falloff: bilinear between texel centres,
#: it follows the analytic attenuation to within 2e-3 at its kink (the inner cone) and 1e-4
#: elsewhere (tests/scene/test_gltf.py), at 4 MiB per spot on the device.
FALLOFF_TEXTURE_SIDE = 512
#: The widest outer cone whose falloff fits the texture: the texture spans [-tan c, tan c],
#: which grows without bound towards 90° (docs/limits.md). A wider soft spot (up to the
#: spec's 90°) is a point light with its falloff as a cube texture of this side per face.
MAX_SPOT_OUTER_DEG = 85.0
CONE_CUBE_SIDE = 256
#: How far from 1 a rotation quaternion's norm may be (exporters write float32; it is normalised).
QUATERNION_TOLERANCE = 1e-3

#: The image of a scene loaded straight from a glTF file (glTF has no image size); `--set image.width=...`.
DEFAULT_IMAGE = (640, 360)
#: The default view when the file has no camera: its bounds seen from the front and above,
#: at the distance where their sphere fills this vertical field of view.
DEFAULT_VIEW_DIRECTION = np.array([0.0, 0.5, 1.0]) / math.sqrt(1.25)
DEFAULT_FOV_DEG = 50.0


def _stderr_line(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


#: Where an import says, in one line, what it chose for the user (the default fog) or
#: renders without (material-only extensions); None says nothing.
notice: Callable[[str], None] | None = _stderr_line
#: Where it lists, in one line, what the file carries that clrays does not render (points,
#: lines, emissive and transmissive materials, the cameras not chosen); the CLI's
#: --verbose sets it, None (the default) says nothing.
verbose_notice: Callable[[str], None] | None = None


def _notify(line: str, verbose: bool = False) -> None:
    say = verbose_notice if verbose else notice
    if say is not None:
        say(f"clrays: notice: {line}")


def _finite_number(value: Any) -> bool:
    """A JSON number that is finite as a float64: an integer literal of 400 digits is a
    Python int that `math.isfinite` cannot take (OverflowError)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    return abs(value) <= FLOAT64_MAX if isinstance(value, int) else math.isfinite(value)


# --------------------------------------------------------------------------- the parts read


@dataclass(frozen=True)
class _Instance:
    """A mesh primitive placed by a node: its triangles before the node's world matrix."""

    node: int
    rows: slice  # its triangles in Imported.triangles
    local: np.ndarray | None  # (T, 3, 3); None in a file without animation
    local_normals: np.ndarray | None  # (T, 3, 3) smooth normals; None as `local`
    albedo: np.ndarray  # (3,)
    motion: gltf_motion.Deformation | None = None  # a skinned or morphed primitive: its own pose per frame


@dataclass(frozen=True)
class _Channel:
    node: int
    path: str  # translation, rotation, scale, weights
    interpolation: str  # LINEAR, STEP, CUBICSPLINE
    times: np.ndarray  # (K,) seconds
    values: np.ndarray  # (K, n), or (3K, n) for CUBICSPLINE: in-tangent, value, out-tangent; rotation [w, x, y, z];
    # weights: n morph targets


@dataclass(frozen=True, eq=False)
class NodeGraph:
    """The node hierarchy: each node's parent, its static local transform and its TRS
    (for the channels that replace parts of it), in an order that puts parents first."""

    parents: np.ndarray  # (N,) int, -1 for a root
    order: tuple[int, ...]  # the scene's nodes, parents before children
    matrices: tuple[np.ndarray | None, ...]  # a node's `matrix`, or None for TRS
    trs: tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]  # translation, rotation [w, x, y, z], scale
    channels: tuple[_Channel, ...] = ()

    def world(self, time: float | None = None) -> dict[int, np.ndarray]:
        """Each node's 4×4 world matrix, at `time` seconds of the animation (None: the static pose)."""
        trs = [list(parts) for parts in self.trs]
        if time is not None:
            for channel in self.channels:
                trs[channel.node][("translation", "rotation", "scale").index(channel.path)] = _sample(channel, time)
        world: dict[int, np.ndarray] = {}
        for index in self.order:
            local = self.matrices[index]
            if local is None:
                translation, rotation, scale = trs[index]
                local = np.eye(4)
                local[:3, :3] = quat_to_matrix(rotation) @ np.diag(scale)
                local[:3, 3] = translation
            parent = self.parents[index]
            world[index] = local if parent < 0 else world[parent] @ local
        return world


@dataclass(frozen=True)
class Imported:
    """What a glTF file gives a scene: its meshes' triangles, lights, camera and animation."""

    file: str  # as named to the user
    triangles: np.ndarray  # (T, 3, 3) world space
    normals: np.ndarray  # (T, 3, 3)
    albedo: np.ndarray  # (T, 3)
    object_id: np.ndarray  # (T,) one per instance, from 0
    outward: np.ndarray  # (T,) int8
    object_count: int
    instances: tuple[_Instance, ...]
    lights: tuple[Light, ...]
    light_nodes: tuple[int, ...]
    camera: Camera
    camera_node: int | None  # None: the default view
    graph: NodeGraph
    duration: float | None  # seconds of animation, None without one
    volume_bounds: tuple[np.ndarray, np.ndarray] | None = None  # the fog node's world box (`volume_node`)


# --------------------------------------------------------------------------- reading JSON with paths


class _Reader:
    """The document and its buffers, with typed getters that fail in one line naming the
    file and the JSON path."""

    def __init__(self, file: str, folder: Path, document: Any, binary: bytes | None):
        self.file, self.folder, self.binary = file, folder, binary
        self.doc = document
        self._buffers: dict[int, bytes] = {}
        self._items: dict[str, list] = {}
        self._buffer_bytes = 0
        self._accessors: dict[int, np.ndarray] = {}  # accessors.i, read once
        self.charged = 0  # bytes counted against MAX_GLTF_IMPORT_BYTES
        # an image's source (("uri", uri) or ("bufferView", i)) → its linear mean colour, decoded once
        self.image_means: dict[tuple[str, Any], np.ndarray] = {}
        self.decoded: dict[tuple[str, int], Any] = {}  # compressed views and accessors, decoded (gltf_compression)

    def fail(self, path: str, expected: str, got: Any) -> NoReturn:
        raise SceneError(f"{self.file}: {path}: expected {expected}, got {_show(got)}")

    def get(self, obj: dict, key: str, path: str, kind: str, default: Any = ..., lo: float | None = None,
            hi: float | None = None) -> Any:
        """obj[key] checked to be a `kind` (int, number, string, list, dict, bool) within [lo, hi]."""
        where = f"{path}.{key}" if path else key
        if key not in obj:
            if default is ...:
                raise SceneError(f"{self.file}: {path or '(top level)'}: missing required key {key!r}")
            return default
        value = obj[key]
        ok = {"int": lambda v: isinstance(v, int) and not isinstance(v, bool),
              "number": _finite_number,
              "string": lambda v: isinstance(v, str), "list": lambda v: isinstance(v, list),
              "dict": lambda v: isinstance(v, dict), "bool": lambda v: isinstance(v, bool)}[kind](value)
        names = {"int": "an integer", "number": "a finite number", "string": "a string", "list": "a list",
                 "dict": "an object", "bool": "true or false"}
        if not ok:
            self.fail(where, names[kind] + _bounds(lo, hi), value)
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            self.fail(where, names[kind] + _bounds(lo, hi), value)
        return value

    def numbers(self, obj: dict, key: str, path: str, count: int, default: Any = ..., lo: float | None = None,
                hi: float | None = None) -> np.ndarray:
        where = f"{path}.{key}"
        values = self.get(obj, key, path, "list", default)
        if values is default:
            return np.asarray(default, dtype=np.float64)
        if len(values) != count or not all(_finite_number(v) for v in values):
            self.fail(where, f"a list of {count} finite numbers", values)
        array = np.asarray(values, dtype=np.float64)
        if (lo is not None and array.min() < lo) or (hi is not None and array.max() > hi):
            self.fail(where, f"{count} numbers{_bounds(lo, hi)}", values)
        return array

    def items(self, key: str, limit: int | None = None) -> list:
        """A top-level array (empty when absent), each entry an object; checked once."""
        items = self._items.get(key)
        if items is None:
            items = self.get(self.doc, key, "", "list", [])
            for i, item in enumerate(items):
                if not isinstance(item, dict):
                    self.fail(f"{key}.{i}", "an object", item)
            self._items[key] = items
        if limit is not None and len(items) > limit:
            self.fail(key, f"at most {limit} entries", f"{len(items)} entries")
        return items

    def index(self, obj: dict, key: str, path: str, array: str, default: Any = ...) -> int:
        """An index into the top-level array `array`."""
        count = len(self.items(array))
        if key not in obj and default is not ...:
            return default
        value = self.get(obj, key, path, "int")
        if not 0 <= value < count:
            self.fail(f"{path}.{key}", f"an index into {array} (0 to {count - 1})" if count else
                      f"no index ({array} is empty)", value)
        return value

    # ------------------------------------------------------------------ the budget

    def charge(self, count: int, path: str, what: str) -> None:
        """Count `count` bytes that the import is about to materialize (`what`, for the field
        at `path`) against its one budget, MAX_GLTF_IMPORT_BYTES, before they are allocated."""
        if self.charged + count > MAX_GLTF_IMPORT_BYTES:
            self.fail(path, f"at most {_size(MAX_GLTF_IMPORT_BYTES)} read and decoded by the import in all "
                            f"(buffers, accessors as float64, images; docs/limits.md)",
                      f"{count} bytes more for {what}, after {self.charged}")
        self.charged += count

    # ------------------------------------------------------------------ buffers and accessors

    def buffer(self, index: int) -> bytes:
        if index in self._buffers:
            return self._buffers[index]
        path = f"buffers.{index}"
        buffer = self.items("buffers")[index]
        length = self.get(buffer, "byteLength", path, "int", lo=1)
        if "uri" in buffer:
            data = self._uri(self.get(buffer, "uri", path, "string"), f"{path}.uri", "buffer")
        elif index == 0 and self.binary is not None:
            self.charge(len(self.binary), path, "the GLB's BIN chunk")
            data = self.binary
        else:
            self.fail(path, "a uri (only the first buffer of a .glb may use its BIN chunk)", "no uri")
        if len(data) < length:
            self.fail(f"{path}.byteLength", f"at most the {len(data)} bytes the buffer holds", length)
        self._buffer_bytes += length
        if self._buffer_bytes > MAX_GLTF_BYTES:
            self.fail(path, f"buffers of at most {_size(MAX_GLTF_BYTES)} in all (docs/limits.md)",
                      f"{self._buffer_bytes} bytes with this one")
        self._buffers[index] = memoryview(data)[:length]  # a view: a 128 MiB buffer is not copied
        return self._buffers[index]

    def _uri(self, uri: str, path: str, what: str) -> bytes:
        """The bytes a buffer's or an image's `uri` names (`what`: buffer, image): a base64 data
        URI or a file inside the glTF file's folder, charged to the budget."""
        if uri.startswith("data:"):
            head, comma, payload = uri.partition(",")
            if not comma or not head.endswith(";base64"):
                self.fail(path, "a base64 data URI (data:...;base64,...)", json.dumps(uri))
            # Checked before decoding: a data URI's bytes are 3/4 of its base64 characters.
            if len(payload) > (MAX_GLTF_BYTES // 3 + 1) * 4:
                self.fail(path, f"a data URI of at most {_size(MAX_GLTF_BYTES)} (docs/limits.md)",
                          f"{len(payload)} base64 characters")
            self.charge(len(payload) // 4 * 3, path, f"the {what}'s data URI")
            try:
                return base64.b64decode(payload, validate=True)
            except (binascii.Error, ValueError) as exc:
                self.fail(path, "valid base64 data", f"{uri[:40]}... ({exc})")
        relative = urllib.parse.unquote(uri)
        parsed = urllib.parse.urlsplit(uri)
        candidate = (self.folder / relative)
        if (parsed.scheme or relative.startswith(("/", "\\")) or Path(relative).is_absolute() or "\\" in relative
                or "\0" in relative):
            self.fail(path, "a relative file path inside the glTF file's folder", json.dumps(uri))
        try:
            resolved, folder = candidate.resolve(), self.folder.resolve()
        except (OSError, RuntimeError) as exc:
            self.fail(path, "a file path that resolves", f"{uri!r} ({exc})")
        if folder != resolved and folder not in resolved.parents:  # `..` or a link that leaves it: refused
            self.fail(path, "a file inside the glTF file's folder", json.dumps(uri))
        left = MAX_GLTF_IMPORT_BYTES - self.charged  # the read stops there: nothing past the budget is allocated
        try:
            data = read_regular_file(resolved, min(MAX_GLTF_BYTES, left),
                                     "" if left >= MAX_GLTF_BYTES else
                                     f"what is left of the import's budget of {_size(MAX_GLTF_IMPORT_BYTES)}")
        except FileRefused as exc:
            self.fail(path, f"a readable {what} file", f"{uri!r} ({exc})")
        self.charge(len(data), path, f"the {what} file")
        return data

    def view(self, index: int) -> tuple[dict, bytes, int, int]:
        """bufferViews[index]: (the view, its buffer's bytes, its byteOffset, its
        byteLength), the view checked to lie within the buffer."""
        path = f"bufferViews.{index}"
        view = self.items("bufferViews")[index]
        decoded = gltf_compression.meshopt_view(self, index, view)  # EXT_meshopt_compression
        if decoded is not None:
            return decoded
        return (view, *self.byte_range(view, path))

    def byte_range(self, obj: dict, path: str) -> tuple[bytes, int, int]:
        """The bytes obj's `buffer`, `byteOffset` and `byteLength` name (a view's, or a
        compressed view's source): (the buffer's bytes, the offset, the length), checked to
        lie within the buffer."""
        data = self.buffer(self.index(obj, "buffer", path, "buffers"))
        offset = self.get(obj, "byteOffset", path, "int", 0, lo=0)
        length = self.get(obj, "byteLength", path, "int", lo=1)
        if offset + length > len(data):
            self.fail(f"{path}.byteLength", f"a view within its buffer's {len(data)} bytes (byteOffset {offset})",
                      length)
        return data, offset, length

    def accessor(self, index: int, path: str, types: tuple[str, ...], components: tuple[int, ...],
                 normalized: bool = False, hint: str = "") -> np.ndarray:
        """Accessor `index` for the field at `path`, as float64 (count, width) (a SCALAR's
        (count,)): its view's elements, or zeros without a view, with its sparse
        substitutions; normalized integers mapped to [0, 1] or [-1, 1] by the spec's formulas.
        Its type must be one of `types`, its componentType one of `components` (`hint` says
        why not), and, where `normalized`, an integer one normalized. Read once, however many
        fields use it: later uses share the same read-only array."""
        where = f"accessors.{index}"
        acc = self.items("accessors")[index]
        kind = self.get(acc, "type", where, "string")
        if kind not in types:
            self.fail(f"{where}.type", f"one of {', '.join(types)} for {path}", json.dumps(kind))
        component = self.get(acc, "componentType", where, "int")
        if component not in components:
            self.fail(f"{where}.componentType", f"one of {', '.join(map(str, components))} for {path}{hint}",
                      component)
        is_normalized = self.get(acc, "normalized", where, "bool", False)
        if normalized and _COMPONENTS[component][1] is not None and not is_normalized:
            self.fail(f"{where}.normalized", f"true for {path} (its integers stand for [-1, 1])", is_normalized)
        if index not in self._accessors:
            decoded = self.decoded.get(("accessors", index))  # KHR_draco_mesh_compression (gltf_compression)
            values = decoded if decoded is not None else \
                self._read_accessor(acc, where, path, _WIDTHS[kind], component, is_normalized)
            values.flags.writeable = False  # shared by every use
            self._accessors[index] = values[:, 0] if kind == "SCALAR" else values
        return self._accessors[index]

    def attribute(self, index: int, name: str, path: str) -> np.ndarray:
        """Accessor `index` as the POSITION or NORMAL (`name`) of the primitive at `path`: VEC3 of
        FLOAT or, in a file that declares KHR_mesh_quantization, of the integer types its
        table allows (a NORMAL's normalized). The node's transform dequantizes positions, as
        the extension intends; normals are made unit length where they are used."""
        quantized = QUANTIZATION in self.extensions_declared()
        return self.accessor(index, f"{path}.attributes.{name}", ("VEC3",),
                             _QUANTIZED[name] if quantized else (5126,), normalized=name == "NORMAL",
                             hint="" if quantized else f" (integer {name}s need {QUANTIZATION} in extensionsRequired)")

    def extensions_declared(self) -> tuple[str, ...]:
        """The names in extensionsUsed and extensionsRequired."""
        names = [*self.get(self.doc, "extensionsUsed", "", "list", []),
                 *self.get(self.doc, "extensionsRequired", "", "list", [])]
        return tuple(name for name in names if isinstance(name, str))

    def _read_accessor(self, acc: dict, where: str, path: str, width: int, component: int,
                       is_normalized: bool) -> np.ndarray:
        count = self.get(acc, "count", where, "int", lo=1)
        dtype, largest = _COMPONENTS[component]
        self.charge(count * width * 8, where, f"{count} elements of {width} float64s")
        if "bufferView" in acc:
            values = self._elements(acc, where, f"{where}.count", count, width, dtype, strided=True).astype(np.float64)
        else:  # all zeros, by the spec (with sparse substitutions, or values an extension supplies)
            values = np.zeros((count, width))
        if "sparse" in acc:
            self._substitute(acc, where, values, dtype)
        if largest is not None and is_normalized:
            values /= largest
            np.maximum(values, -1.0, out=values)  # the spec's max(c / 127, -1) for signed types
        if dtype == "<f4" and not np.isfinite(values).all():  # integers are always finite
            row = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0])
            self.fail(where, f"finite values for {path}", f"{values[row].tolist()} at element {row}")
        return values

    def _elements(self, holder: dict, where: str, count_path: str, count: int, width: int, dtype: str,
                  strided: bool) -> np.ndarray:
        """(count, width) elements of `dtype` in the view `holder` names (an accessor, or a
        sparse accessor's indices or values: `where`) from its byteOffset: a numpy view of the
        buffer's bytes, nothing copied, checked to lie within the view. Where `strided`, the
        view's byteStride spaces them; a sparse accessor's views have none (tightly packed)."""
        view_index = self.index(holder, "bufferView", where, "bufferViews")
        view_path = f"bufferViews.{view_index}"
        view, data, view_offset, view_length = self.view(view_index)
        size = np.dtype(dtype).itemsize
        element = width * size
        if strided:
            stride = self.get(view, "byteStride", view_path, "int", element, lo=4, hi=252)
            if stride < element:
                self.fail(f"{view_path}.byteStride", f"at least the element's {element} bytes", stride)
        elif "byteStride" in view:
            self.fail(f"{view_path}.byteStride", f"no byteStride (the view of {where} is tightly packed)",
                      view["byteStride"])
        else:
            stride = element
        offset = self.get(holder, "byteOffset", where, "int", 0, lo=0)
        if offset % size:
            self.fail(f"{where}.byteOffset", f"a multiple of the component's {size} bytes", offset)
        most = (view_length - offset - element) // stride + 1 if view_length >= offset + element else 0
        if count > most:
            self.fail(count_path, f"at most {most} elements in {view_path} ({view_length} bytes, "
                      f"byteOffset {offset}, stride {stride})", count)
        return np.ndarray((count, width), dtype=dtype, buffer=data, offset=view_offset + offset,
                          strides=(stride, size))

    def _substitute(self, acc: dict, where: str, values: np.ndarray, dtype: str) -> None:
        """Apply a sparse accessor's substitutions to `values` (its base, as float64): `count`
        strictly increasing indices below the accessor's count, and as many elements of the
        accessor's componentType, both tightly packed in their views (glTF 2.0 §3.6.2.3)."""
        path = f"{where}.sparse"
        count, width = values.shape
        sparse = self.get(acc, "sparse", where, "dict")
        replaced = self.get(sparse, "count", path, "int", lo=1, hi=count)
        indices_at = self.get(sparse, "indices", path, "dict")
        index_component = self.get(indices_at, "componentType", f"{path}.indices", "int")
        if index_component not in (5121, 5123, 5125):
            self.fail(f"{path}.indices.componentType", "one of 5121, 5123, 5125 (unsigned integers)", index_component)
        values_at = self.get(sparse, "values", path, "dict")
        self.charge(replaced * (1 + width) * 8, path, f"{replaced} sparse indices and elements")
        indices = self._elements(indices_at, f"{path}.indices", f"{path}.count", replaced, 1,
                                 _COMPONENTS[index_component][0], strided=False)[:, 0].astype(np.int64)
        steps = np.diff(indices)
        if np.any(steps <= 0):
            k = int(np.argmax(steps <= 0))
            self.fail(f"{path}.indices", "strictly increasing indices",
                      f"{int(indices[k])} then {int(indices[k + 1])} at {k} and {k + 1}")
        if indices[-1] >= count:
            self.fail(f"{path}.indices", f"indices below the accessor's count {count}", int(indices[-1]))
        values[indices] = self._elements(values_at, f"{path}.values", f"{path}.count", replaced, width, dtype,
                                         strided=False)


def _size(n: int) -> str:
    return f"{n / 2**20:g} MiB" if n >= 1 << 20 else f"{n} bytes"


def _bounds(lo, hi) -> str:
    if lo is not None and hi is not None:
        return f" in [{lo:g}, {hi:g}]"
    if lo is not None:
        return f" >= {lo:g}"
    return f" <= {hi:g}" if hi is not None else ""


def _show(value: Any, limit: int = 80) -> str:
    """What was found: a description as written, a JSON value (a number, a list) as JSON.
    A string from the file is passed through json.dumps by the caller, so it shows quoted."""
    text = value if isinstance(value, str) else json.dumps(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


# --------------------------------------------------------------------------- the file


def _open(path: Path, file: str) -> _Reader:
    """The JSON document and the GLB's BIN chunk."""
    try:
        # Room for a .gltf whose buffers are data URIs: base64 takes 4 characters for 3 bytes.
        data = read_regular_file(path, MAX_GLTF_BYTES // 3 * 4 + (1 << 20), "simplify the meshes or split the scene")
    except FileRefused as exc:
        raise SceneError(f"{file}: cannot read glTF file: {exc}") from None
    binary = None
    if data[:4] == GLB_MAGIC:
        if len(data) < 20:
            raise SceneError(f"{file}: (GLB header): expected a 12-byte header and a JSON chunk, got {len(data)} bytes")
        _, version, length = struct.unpack_from("<4sII", data, 0)
        if version != 2:
            raise SceneError(f"{file}: (GLB header): expected version 2, got {version}")
        if length != len(data):
            raise SceneError(f"{file}: (GLB header): expected the file's length, {len(data)} bytes, got {length}")
        chunks = _glb_chunks(data, file)
        if chunks[0][0] != _CHUNK_JSON:
            raise SceneError(f"{file}: (GLB chunk at byte 12): expected the JSON chunk first, got {hex(chunks[0][0])}")
        text = data[chunks[0][1]:chunks[0][2]]
        for position, (kind, start, end) in enumerate(chunks[1:], 1):
            if kind == _CHUNK_BIN and position == 1:
                binary = memoryview(data)[start:end]  # a view: the buffer is not copied
            elif kind in (_CHUNK_JSON, _CHUNK_BIN):
                raise SceneError(f"{file}: (GLB chunk at byte {start - 8}): expected one JSON chunk, first, and at "
                                 f"most one BIN chunk, second (glTF 2.0, GLB chunks), got a "
                                 f"{'JSON' if kind == _CHUNK_JSON else 'BIN'} chunk as chunk {position + 1}")
            # any other type: skipped, as the spec asks (an extension's own chunk)
    else:
        text = data
    values = sum(text.count(mark) for mark in (b",", b":", b"[", b"{")) + 1
    if values > MAX_GLTF_JSON_VALUES:  # counted before parsing: each value costs a Python object
        raise SceneError(f"{file}: (JSON): expected at most {MAX_GLTF_JSON_VALUES} values (docs/limits.md), got about "
                         f"{values}")
    try:
        document = json.loads(text.decode("utf-8"), parse_constant=_no_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SceneError(f"{file}: (JSON): expected a glTF 2.0 document (JSON or GLB), got {reason[:120]}") from None
    if not isinstance(document, dict):
        raise SceneError(f"{file}: (top level): expected a JSON object, got {_show(document)}")
    return _Reader(file, path.parent, document, binary)


def _glb_chunks(data: bytes, file: str) -> list[tuple[int, int, int]]:
    """(type, start, end) of each chunk of a GLB file, after its 12-byte header: at most
    MAX_GLB_CHUNKS, each within the file, nothing copied."""
    chunks, offset = [], 12
    while offset < len(data):
        if len(chunks) == MAX_GLB_CHUNKS:
            raise SceneError(f"{file}: (GLB chunk at byte {offset}): expected at most {MAX_GLB_CHUNKS} chunks (JSON, "
                             f"BIN and chunks of extensions; docs/limits.md), got more")
        if offset + 8 > len(data):
            raise SceneError(f"{file}: (GLB chunk at byte {offset}): expected an 8-byte chunk header, "
                             f"got {len(data) - offset} bytes")
        chunk_length, chunk_type = struct.unpack_from("<II", data, offset)
        if offset + 8 + chunk_length > len(data):
            raise SceneError(f"{file}: (GLB chunk at byte {offset}): expected a length within the file's "
                             f"{len(data) - offset - 8} remaining bytes, got {chunk_length}")
        chunks.append((chunk_type, offset + 8, offset + 8 + chunk_length))
        offset += 8 + chunk_length
    if not chunks:
        raise SceneError(f"{file}: (GLB chunk at byte 12): expected the JSON chunk first, got none")
    return chunks


def _no_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def _check_header(reader: _Reader) -> None:
    asset = reader.get(reader.doc, "asset", "", "dict")
    version = reader.get(asset, "version", "asset", "string")
    if not version.startswith("2."):
        reader.fail("asset.version", "a glTF 2.x file", json.dumps(version))
    required = reader.get(reader.doc, "extensionsRequired", "", "list", [])
    unsupported = [name for name in required if name not in SUPPORTED_EXTENSIONS
                   and not material_only_extension(name)]
    if unsupported:
        reader.fail("extensionsRequired", f"only extensions clrays reads ({', '.join(SUPPORTED_EXTENSIONS)}) or "
                    f"that only change materials", ", ".join(map(str, unsupported)))
    gltf_compression.check_required(reader, required)  # their decoders, optional extras
    materials_only = [name for name in required if material_only_extension(name)]
    if materials_only:
        _notify(f"{reader.file}: requires {', '.join(materials_only)}, which only change materials: rendered "
                f"with clrays's diffuse surfaces (albedo = baseColorFactor × the base colour texture's mean)")


def material_only_extension(name: Any) -> bool:
    """Whether a required extension changes only materials or textures (MATERIAL_ONLY_EXTENSIONS)."""
    return isinstance(name, str) and (name.startswith("KHR_materials_") or name in MATERIAL_ONLY_EXTENSIONS)


# --------------------------------------------------------------------------- nodes


def _graph(reader: _Reader) -> NodeGraph:
    nodes = reader.items("nodes", MAX_GLTF_NODES)
    count = len(nodes)
    parents = np.full(count, -1, dtype=np.int64)
    for i, node in enumerate(nodes):
        for j, child in enumerate(reader.get(node, "children", f"nodes.{i}", "list", [])):
            if not isinstance(child, int) or isinstance(child, bool) or not 0 <= child < count:
                reader.fail(f"nodes.{i}.children.{j}", f"a node index (0 to {count - 1})", child)
            if parents[child] >= 0 or child == i:
                reader.fail(f"nodes.{i}.children.{j}", "a node with one parent (a tree, not a graph)",
                            f"node {child}, already a child of node {parents[child] if child != i else i}")
            parents[child] = i
    # A loop of parents has no root. Each node's way up is walked once: it stops at a node
    # already known to reach a root, so a chain of 65 536 nodes costs 65 536 steps, not their square.
    reaches_root = np.zeros(count, dtype=bool)
    for i in range(count):
        path, on_path, node = [], set(), i
        while node >= 0 and not reaches_root[node]:
            if node in on_path:
                reader.fail(f"nodes.{node}", "a node hierarchy without cycles", f"node {node} is its own ancestor")
            path.append(node)
            on_path.add(node)
            node = int(parents[node])
        reaches_root[path] = True
    scene_index = reader.get(reader.doc, "scene", "", "int", 0, lo=0)
    scenes = reader.items("scenes")
    if scenes:
        if scene_index >= len(scenes):
            reader.fail("scene", f"an index into scenes (0 to {len(scenes) - 1})", scene_index)
        roots = reader.get(scenes[scene_index], "nodes", f"scenes.{scene_index}", "list", [])
        for j, root in enumerate(roots):
            if not isinstance(root, int) or isinstance(root, bool) or not 0 <= root < count:
                reader.fail(f"scenes.{scene_index}.nodes.{j}", f"a node index (0 to {count - 1})", root)
            if parents[root] >= 0:
                reader.fail(f"scenes.{scene_index}.nodes.{j}", "a root node (one without a parent)",
                            f"node {root}, a child of node {parents[root]}")
    else:  # no scenes: every root node
        roots = [i for i in range(count) if parents[i] < 0]
    order, stack, seen = [], list(reversed(roots)), set()
    children = {i: reader.get(node, "children", f"nodes.{i}", "list", []) for i, node in enumerate(nodes)}
    while stack:  # depth first, parents before children; iterative, so a deep chain cannot overflow
        node = stack.pop()
        if node in seen:
            continue
        seen.add(node)
        order.append(node)
        stack.extend(reversed(children[node]))
    matrices, trs = [], []
    for i, node in enumerate(nodes):
        path = f"nodes.{i}"
        translation = reader.numbers(node, "translation", path, 3, (0.0, 0.0, 0.0))
        rotation = _quaternion(reader, reader.numbers(node, "rotation", path, 4, (0.0, 0.0, 0.0, 1.0)),
                               f"{path}.rotation")
        scale = reader.numbers(node, "scale", path, 3, (1.0, 1.0, 1.0))
        trs.append((translation, rotation, scale))
        if "matrix" in node:
            if any(key in node for key in ("translation", "rotation", "scale")):
                reader.fail(f"{path}.matrix", "a matrix or translation/rotation/scale, not both", "both")
            matrix = reader.numbers(node, "matrix", path, 16).reshape(4, 4).T  # column-major
            if not np.allclose(matrix[3], (0.0, 0.0, 0.0, 1.0)):
                reader.fail(f"{path}.matrix", "an affine matrix (last row 0, 0, 0, 1)", matrix[3].tolist())
            matrices.append(matrix)
        else:
            matrices.append(None)
    return NodeGraph(parents, tuple(order), tuple(matrices), tuple(trs))


def _quaternion(reader: _Reader, xyzw: np.ndarray, path: str) -> np.ndarray:
    """glTF's [x, y, z, w] as clrays's unit [w, x, y, z]."""
    norm = float(np.linalg.norm(xyzw))
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        reader.fail(path, f"a unit quaternion [x, y, z, w] (|q| = 1 within {QUATERNION_TOLERANCE:g})",
                    f"{xyzw.tolist()} with |q| = {norm:.6g}")
    x, y, z, w = xyzw / norm
    return np.array([w, x, y, z])


# --------------------------------------------------------------------------- meshes


def _primitive_faces(reader: _Reader, primitive: dict, path: str, vertex_count: int) -> np.ndarray | None:
    """(F, 3) vertex indices of a triangle primitive; None for points and lines (no surface)."""
    mode = reader.get(primitive, "mode", path, "int", _TRIANGLES, lo=0, hi=6)
    if mode < _TRIANGLES:
        return None
    if "indices" in primitive:
        index = reader.index(primitive, "indices", path, "accessors")
        indices = reader.accessor(index, f"{path}.indices", ("SCALAR",), (5121, 5123, 5125))
        if indices.max() >= vertex_count:
            reader.fail(f"accessors.{index}", f"vertex indices below the POSITION count {vertex_count}",
                        int(indices.max()))
        indices = indices.astype(np.int64)
    else:
        indices = np.arange(vertex_count, dtype=np.int64)
    if mode == _TRIANGLES:
        usable = len(indices) - len(indices) % 3
        return indices[:usable].reshape(-1, 3)
    if len(indices) < 3:
        return np.zeros((0, 3), np.int64)
    if mode == _TRIANGLE_STRIP:  # every other triangle flips, to keep the winding
        k = np.arange(len(indices) - 2)
        odd = k % 2 == 1
        return np.stack([indices[k], np.where(odd, indices[k + 2], indices[k + 1]),
                         np.where(odd, indices[k + 1], indices[k + 2])], axis=1)
    k = np.arange(1, len(indices) - 1)  # a fan around the first vertex
    return np.stack([np.full(len(k), indices[0]), indices[k], indices[k + 1]], axis=1)


def _triangle_count(reader: _Reader, primitive: dict, path: str) -> int:
    """A primitive's triangles from its accessor counts alone, before any is read."""
    mode = primitive.get("mode", _TRIANGLES)
    if not isinstance(mode, int) or mode < _TRIANGLES:
        return 0
    attributes = reader.get(primitive, "attributes", path, "dict")
    source = primitive["indices"] if "indices" in primitive else attributes.get("POSITION")
    accessors = reader.items("accessors")
    if not isinstance(source, int) or isinstance(source, bool) or not 0 <= source < len(accessors):
        return 0  # reading it fails with its own message
    count = accessors[source].get("count", 0)
    count = count if isinstance(count, int) else 0
    return count // 3 if mode == _TRIANGLES else max(count - 2, 0)


def _albedo(reader: _Reader, primitive: dict, path: str) -> np.ndarray:
    """baseColorFactor's RGB (alpha ignored), times the mean of a base colour texture."""
    if "material" not in primitive:
        return np.ones(3)
    index = reader.index(primitive, "material", path, "materials")
    where = f"materials.{index}"
    pbr = reader.get(reader.items("materials")[index], "pbrMetallicRoughness", where, "dict", {})
    factor = reader.numbers(pbr, "baseColorFactor", f"{where}.pbrMetallicRoughness", 4, (1.0, 1.0, 1.0, 1.0),
                            0.0, 1.0)[:3]
    texture = reader.get(pbr, "baseColorTexture", f"{where}.pbrMetallicRoughness", "dict", None)
    if texture is None:
        return factor
    return factor * _mean_texture(reader, texture, f"{where}.pbrMetallicRoughness.baseColorTexture")


def _mean_texture(reader: _Reader, texture_info: dict, path: str) -> np.ndarray:
    """The linear mean colour of a texture's image (PNG or JPEG, sRGB-encoded)."""
    texture_index = reader.index(texture_info, "index", path, "textures")
    texture = reader.items("textures")[texture_index]
    if "source" not in texture:
        return np.ones(3)  # a texture of an extension's image format: not read
    image_index = reader.index(texture, "source", f"textures.{texture_index}", "images")
    return _mean_image(reader, image_index)


def _mean_image(reader: _Reader, image_index: int) -> np.ndarray:
    """The linear mean colour of images[image_index] (PNG or JPEG, sRGB-encoded), decoded
    once per source (its URI or buffer view), however many images and materials name it.
    Its size is read from its header and its decoded pixels charged to the import's budget
    before it is decoded; its 8-bit values are counted (PIL's histogram) rather than
    converted: a 4096² image costs its 48 MiB of pixels, not float copies of them."""
    where = f"images.{image_index}"
    image = reader.items("images")[image_index]
    if "uri" in image:
        uri = reader.get(image, "uri", where, "string")
        source = ("uri", uri)
    else:
        view_index = reader.index(image, "bufferView", where, "bufferViews")
        source = ("bufferView", view_index)
    if source not in reader.image_means:
        if "uri" in image:
            data = reader._uri(uri, f"{where}.uri", "image")
        else:
            _, buffer, offset, length = reader.view(view_index)
            data = buffer[offset:offset + length]
        reader.image_means[source] = _decoded_mean(reader, where, data)
    return reader.image_means[source]


def _decoded_mean(reader: _Reader, where: str, data: bytes) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as opened:
            if opened.format not in ("PNG", "JPEG"):
                reader.fail(where, "a PNG or JPEG image", opened.format)
            width, height = opened.size
            if max(width, height) > MAX_TEXTURE_SIDE:  # before decoding: a small file may hold a huge image
                reader.fail(where, f"an image with sides of at most {MAX_TEXTURE_SIDE} pixels", f"{width}×{height}")
            reader.charge(width * height * 4, where, f"its {width}×{height} pixels decoded")
            rgb = opened if opened.mode == "RGB" else opened.convert("RGB")
            counts = np.asarray(rgb.histogram(), dtype=np.float64).reshape(3, 256)  # per channel, per 8-bit value
    except Image.DecompressionBombError as exc:  # PIL's own limit, above ours: refused at its header
        reader.fail(where, f"an image with sides of at most {MAX_TEXTURE_SIDE} pixels", f"({exc})")
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        reader.fail(where, "a readable PNG or JPEG image", f"({exc})")
    linear = srgb_to_linear(np.arange(256) / 255.0)
    return counts @ linear / max(width * height, 1)


def _meshes(reader: _Reader, graph: NodeGraph, world: dict[int, np.ndarray], channels: tuple[_Channel, ...],
            skipped: int | None = None):
    """Each mesh primitive placed by each node of the scene but `skipped` (a fog volume's node):
    (instances, world triangles, normals, albedo, outward). An instance keeps its own triangles
    only when the file has `channels`; a skinned or morphed one keeps its Deformation
    (clrays.scene.gltf_motion)."""
    nodes, meshes = reader.items("nodes"), reader.items("meshes")
    placed = [(index, reader.index(nodes[index], "mesh", f"nodes.{index}", "meshes"))
              for index in graph.order if "mesh" in nodes[index] and index != skipped]
    total, objects = 0, 0
    budget = gltf_motion.MotionBudget(reader)
    for node, mesh in placed:  # counted before anything is read: a few bytes of JSON may ask for millions
        copies = gltf_motion.instance_count(reader, nodes[node], f"nodes.{node}")
        for p, primitive in enumerate(reader.get(meshes[mesh], "primitives", f"meshes.{mesh}", "list")):
            path = f"meshes.{mesh}.primitives.{p}"
            if not isinstance(primitive, dict):
                reader.fail(path, "an object", primitive)
            total += _triangle_count(reader, primitive, path) * copies
            budget.add(nodes[node], primitive, path, copies)
            objects += 1
            if total > MAX_TRIANGLES:
                reader.fail(path, f"at most {MAX_TRIANGLES} triangles in the whole scene (docs/limits.md)",
                            f"{total} with this primitive (placed by nodes.{node})")
            if objects > MAX_OBJECTS:
                reader.fail(path, f"at most {MAX_OBJECTS} placed primitives, each an object (docs/limits.md)",
                            f"{objects} with this one (placed by nodes.{node})")
    animated = bool(channels)
    weight_channels = {channel.node: channel for channel in channels if channel.path == "weights"}
    instances, tris, normals, albedo, outward = [], [], [], [], []
    start, cache, skins = 0, {}, {}
    for node, mesh in placed:
        copies = gltf_motion.instance_matrices(reader, nodes[node], f"nodes.{node}")
        for p, primitive in enumerate(meshes[mesh]["primitives"]):
            path = f"meshes.{mesh}.primitives.{p}"
            if (mesh, p) not in cache:
                cache[(mesh, p)] = _primitive(reader, primitive, path)
            shape = cache[(mesh, p)]
            if shape is None:
                continue
            local, local_normals, colour, vertices, faces = shape
            matrix = world[node]
            motion = gltf_motion.deformation(reader, node, primitive, path, vertices, faces, skins, weight_channels,
                                             copies, world)
            if motion is not None:  # its own pose: a skin's ignores the node's matrix
                triangles, placed_normals = motion.pose(world)
                placed_vertices, faces = triangles.reshape(-1, 3), np.arange(3 * len(triangles)).reshape(-1, 3)
            else:
                if copies is not None:
                    local, local_normals, vertices, faces = gltf_motion.instanced(copies, local, local_normals,
                                                                                  vertices, faces)
                triangles = transform_points(matrix, local)
                placed_normals = _world_normals(matrix, local_normals, triangles)
                placed_vertices = transform_points(matrix, vertices)
            count = len(triangles)
            kept = animated and motion is None  # a Deformation keeps its own vertices
            instances.append(_Instance(node, slice(start, start + count), local if kept else None,
                                       local_normals if kept else None, colour, motion))
            tris.append(triangles)
            normals.append(placed_normals)
            albedo.append(np.broadcast_to(colour, (count, 3)))
            outward.append(np.full(count, primitives.closed_outward(placed_vertices, faces), np.int8))
            start += count
    return instances, tris, normals, albedo, outward


def volume_node(reader: _Reader, graph: NodeGraph, name: str) -> int:
    """The node named `name` whose mesh bounds a fog volume (`medium.bounds: {object: NAME}`):
    one node of the scene with a mesh, not moved by an animation (the bounds are one box).
    glTF names need not be unique (glTF 2.0 §5, "name": "not necessarily unique"), so two
    nodes of that name are refused rather than one picked."""
    nodes = reader.items("nodes")
    found = [index for index in graph.order if "mesh" in nodes[index] and nodes[index].get("name") == name]
    if not found:
        names = sorted({nodes[i]["name"] for i in graph.order if "mesh" in nodes[i]
                        and isinstance(nodes[i].get("name"), str)})
        raise SceneError(f"{reader.file}: nodes: expected a node with a mesh named {name!r} for medium.bounds.object, "
                         f"got {', '.join(map(repr, names[:8])) + (' …' if len(names) > 8 else '') or 'no named mesh node'}")
    if len(found) > 1:
        raise SceneError(f"{reader.file}: nodes: expected one node named {name!r} for medium.bounds.object, got "
                         f"{len(found)} (nodes.{found[0]}, nodes.{found[1]}); rename one in the file")
    node = found[0]
    moved, ancestor = {channel.node for channel in graph.channels}, node
    while ancestor >= 0:
        if ancestor in moved:
            reader.fail(f"nodes.{node}", "a fog volume's node that no animation moves (medium.bounds is one box)",
                        f"{name!r}, animated by nodes.{ancestor}'s keys")
        ancestor = int(graph.parents[ancestor])
    if gltf_motion.instance_count(reader, nodes[node], f"nodes.{node}") != 1:
        reader.fail(f"nodes.{node}", "a fog volume's node placing its mesh once (medium.bounds is one box)",
                    "EXT_mesh_gpu_instancing copies")
    return node


def _volume_bounds(reader: _Reader, node: int, matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The world box around the triangles of `node`'s mesh (placed by `matrix`)."""
    mesh = reader.index(reader.items("nodes")[node], "mesh", f"nodes.{node}", "meshes")
    points = []
    for p, primitive in enumerate(reader.get(reader.items("meshes")[mesh], "primitives", f"meshes.{mesh}", "list")):
        path = f"meshes.{mesh}.primitives.{p}"
        if not isinstance(primitive, dict):
            reader.fail(path, "an object", primitive)
        shape = _primitive(reader, primitive, path)
        if shape is not None:
            points.append(transform_points(matrix, shape[0].reshape(-1, 3)))
    if not points:
        reader.fail(f"meshes.{mesh}", "a fog volume's mesh with triangles (medium.bounds.object)", "none")
    low, high = mesh_bounds(np.concatenate(points))
    flat = [axis for axis in range(3) if not high[axis] > low[axis]]
    if flat:
        reader.fail(f"nodes.{node}", "a fog volume's mesh with extent along x, y and z (medium.bounds.object)",
                    f"a box flat in {'xyz'[flat[0]]}")
    return low, high


def _primitive(reader: _Reader, primitive: dict, path: str):
    """(local triangles, their normals, albedo, vertices, faces) in spatial order, or None for no surface."""
    attributes = reader.get(primitive, "attributes", path, "dict")
    gltf_compression.decode_draco(reader, primitive, path)  # KHR_draco_mesh_compression: its accessors' data
    position = reader.index(attributes, "POSITION", f"{path}.attributes", "accessors")
    vertices = reader.attribute(position, "POSITION", path)
    faces = _primitive_faces(reader, primitive, path, len(vertices))
    if faces is None or len(faces) == 0:
        return None
    given = None
    if "NORMAL" in attributes:
        normal = reader.index(attributes, "NORMAL", f"{path}.attributes", "accessors")
        given = reader.attribute(normal, "NORMAL", path)
        if len(given) != len(vertices):
            reader.fail(f"accessors.{normal}.count", f"the POSITION count {len(vertices)}", len(given))
    # A skinned or morphed primitive keeps every vertex: its per-vertex attributes
    # (gltf_motion) are read whole, and their counts must match POSITION's.
    deformable = "targets" in primitive or any(str(name).startswith("JOINTS_") for name in attributes)
    used, faces = (None, faces) if deformable else _used_vertices(faces, len(vertices))
    if used is not None:  # some vertices of a large or shared accessor: the rest cost nothing more
        vertices, given = vertices[used], (given[used] if given is not None else None)
    triangles = primitives.indexed_triangles(vertices, faces)
    # The file's normals; without them flat ones, as the spec requires ("client
    # implementations must calculate flat normals"): each triangle its own face's normal.
    normals = primitives.flat_normals(triangles) if given is None else primitives.smooth_normals(vertices, faces, given)
    order = primitives.spatial_order(triangles)
    return triangles[order], normals[order], _albedo(reader, primitive, path), vertices, faces[order]


def _used_vertices(faces: np.ndarray, count: int) -> tuple[np.ndarray | None, np.ndarray]:
    """(the vertices `faces` use, in order, and the faces renumbered to them), or (None,
    faces) where they use all `count`: in time that follows the faces, not the count (one
    accessor of millions of vertices may serve many primitives of a few triangles each)."""
    if count <= faces.size:
        mask = np.zeros(count, dtype=bool)
        mask[faces] = True
        if mask.all():
            return None, faces
        return np.flatnonzero(mask), (np.cumsum(mask) - 1)[faces]
    used = np.unique(faces)
    return used, np.searchsorted(used, faces)


def _world_normals(matrix: np.ndarray, local_normals: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Normals through the inverse transpose; a node scaled to nothing (hidden) keeps its faces' normals."""
    if abs(np.linalg.det(matrix[:3, :3])) < 1e-300:
        return primitives.flat_normals(triangles)
    return transform_normals(matrix, local_normals)


# --------------------------------------------------------------------------- lights


def _lights(reader: _Reader, graph: NodeGraph, world: dict[int, np.ndarray], light_scale: float):
    extension = reader.get(reader.get(reader.doc, "extensions", "", "dict", {}), "KHR_lights_punctual",
                           "extensions", "dict", {})
    definitions = reader.get(extension, "lights", "extensions.KHR_lights_punctual", "list", [])
    generator = reader.doc["asset"].get("generator")  # asset: a dict, checked on reading
    falloff = "blender" if isinstance(generator, str) and generator.startswith(BLENDER_GENERATOR) else "gltf"
    nodes = reader.items("nodes")
    lights, light_nodes = [], []
    for index in graph.order:
        node_ext = reader.get(nodes[index], "extensions", f"nodes.{index}", "dict", {})
        if "KHR_lights_punctual" not in node_ext:
            continue
        path = f"nodes.{index}.extensions.KHR_lights_punctual"
        ref = reader.get(node_ext, "KHR_lights_punctual", f"nodes.{index}.extensions", "dict")
        which = reader.get(ref, "light", path, "int")
        if not 0 <= which < len(definitions) or not isinstance(definitions[which], dict):
            reader.fail(f"{path}.light", f"an index into extensions.KHR_lights_punctual.lights "
                        f"(0 to {len(definitions) - 1})" if definitions else "no light (the file defines none)",
                        which)
        if len(lights) == MAX_LIGHTS:
            reader.fail(path, f"at most {MAX_LIGHTS} lights (each light costs its own raster, volume and visibility stages every frame)",
                        f"{len(lights) + 1} with this one")
        lights.append(_light(reader, definitions[which], f"extensions.KHR_lights_punctual.lights.{which}",
                             world[index], light_scale, falloff))
        light_nodes.append(index)
    return lights, light_nodes


def _light(reader: _Reader, light: dict, path: str, matrix: np.ndarray, light_scale: float,
           falloff: str = "gltf") -> Light:
    kind = reader.get(light, "type", path, "string")
    colour = reader.numbers(light, "color", path, 3, (1.0, 1.0, 1.0), 0.0)
    # cd → W/sr, lux → W/m²: Blender's default export (cd = W / 4π × 683) renders at Cycles' brightness.
    power = colour * (reader.get(light, "intensity", path, "number", 1.0, lo=0.0) / LUMENS_PER_WATT) * light_scale
    if not power.max() <= MAX_POWER:  # as a YAML light's: beyond it float32 radiance overflows
        reader.fail(f"{path}.intensity", f"a power (intensity / {LUMENS_PER_WATT:g} lm/W × color × light_scale) "
                    f"of at most {MAX_POWER:g}", f"{power.max():.3g}")
    reader.get(light, "range", path, "number", None, lo=0.0)  # checked, then ignored (docs/scene-format.md)
    position = matrix[:3, 3].copy()
    direction = matrix[:3, :3] @ np.array([0.0, 0.0, -1.0])  # lights shine along their node's -Z
    length = float(np.linalg.norm(direction))
    if kind == "point":
        return PointLight(position=position, intensity=power)
    if kind not in ("spot", "directional"):
        reader.fail(f"{path}.type", "point, spot or directional", json.dumps(kind))
    if not length > 0:
        reader.fail(path, "a light whose node does not scale its -Z axis to nothing", "a zero direction")
    direction = direction / length
    if kind == "directional":
        return DirectionalLight(direction=direction, irradiance=power)
    spot = reader.get(light, "spot", path, "dict", {})
    # Up to π/2 as float32 writes it (Blender's 180° spot is 1.5707963705), taken as π/2.
    written = reader.get(spot, "outerConeAngle", f"{path}.spot", "number", math.pi / 4, lo=0.0,
                         hi=float(np.nextafter(np.float32(math.pi / 2), np.float32(2))))
    inner = min(reader.get(spot, "innerConeAngle", f"{path}.spot", "number", 0.0, lo=0.0, hi=written), math.pi / 2)
    outer = min(written, math.pi / 2)
    if outer <= 0.0:
        reader.fail(f"{path}.spot.outerConeAngle", "an angle in (0, π/2]", outer)
    # Inner and outer angles so close that the spec's clamp of 1 / (cos inner − cos outer) to 1000
    # engages: the falloff is a ring of Δcos = 0.001 at the outer edge, narrower than a texel
    # of the falloff texture: the hard cone at the outer angle is that edge.
    hard = math.cos(inner) - math.cos(outer) <= 0.001
    if hard or math.degrees(outer) <= MAX_SPOT_OUTER_DEG:
        return SpotLight(position=position, direction=direction, cone_deg=math.degrees(outer), intensity=power,
                         texture=None if hard else falloff_texture(inner, outer, falloff=falloff))
    # Wider than the spot's texture can span (it covers [-tan c, tan c]): the point light's
    # cube carries the falloff, zero outside the cone, and its cube shadow map the shadows,
    # as a YAML spot wider than 75° has anyway.
    return PointLight(position=position, intensity=power, texture=cone_cube(inner, outer, direction, falloff=falloff))


def spot_attenuation(cos_angle, inner: float, outer: float, falloff: str = "gltf"):
    """A spot's falloff between the cone angles (radians). "gltf": KHR_lights_punctual's
    recommended one, clamp(cosθ·scale + offset, 0, 1)² with scale = 1/max(0.001, cos inner −
    cos outer), offset = −cos outer·scale. "blender": Cycles' (and EEVEE's) spot blend, which
    the extension's angles came from: Blender's exporter writes inner = outer·(1 − blend), and
    Cycles fades in over the outer (1 − cos outer)·blend of cosθ, smoothstep(x) = x²(3 − 2x) with
    x = (cosθ − cos outer) / ((1 − cos outer)·blend) clamped to [0, 1]."""
    if falloff == "blender":
        blend = 1.0 - inner / outer
        ring = max((1.0 - math.cos(outer)) * blend, 1e-12)
        x = np.clip((np.asarray(cos_angle, dtype=np.float64) - math.cos(outer)) / ring, 0.0, 1.0)
        return x * x * (3.0 - 2.0 * x)
    scale = 1.0 / max(0.001, math.cos(inner) - math.cos(outer))
    offset = -math.cos(outer) * scale
    return np.clip(np.asarray(cos_angle, dtype=np.float64) * scale + offset, 0.0, 1.0) ** 2


_FALLOFF_TEXTURES: dict[tuple, LightTexture] = {}


def falloff_texture(inner: float, outer: float, side: int = FALLOFF_TEXTURE_SIDE,
                    falloff: str = "gltf") -> LightTexture:
    """A spot's cone falloff (`spot_attenuation`) as its light texture: the texture fills
    [−tan outer, tan outer]² of the plane at distance 1 along the axis (docs/light-textures.md),
    so texel centre (sx, sy) lies at tanθ = tan(outer)·|(sx, sy)|. One texture per cone pair and
    falloff, shared."""
    key = (float(inner), float(outer), side, falloff)
    if key not in _FALLOFF_TEXTURES:
        centres = (np.arange(side) + 0.5) / side * 2.0 - 1.0
        radius = np.hypot(centres[None, :], centres[:, None]) * math.tan(outer)
        values = spot_attenuation(1.0 / np.sqrt(1.0 + radius * radius), inner, outer, falloff)
        texels = np.repeat(values[:, :, None], 3, axis=2).astype(np.float32)
        _FALLOFF_TEXTURES[key] = LightTexture(texels, f"cone falloff {math.degrees(inner):g}° to "
                                                      f"{math.degrees(outer):g}°", smooth=True)
    return _FALLOFF_TEXTURES[key]


@dataclass(frozen=True, eq=False)
class ConeCube(LightTexture):
    """A wide spot's falloff as a point light's cube texture: the cone's axis and angles
    (radians) are kept so that an animated node can turn it (`aimed`)."""

    axis: tuple[float, float, float] = (0.0, 0.0, -1.0)
    inner: float = 0.0
    outer: float = math.pi / 2
    falloff: str = "gltf"

    def aimed(self, direction: np.ndarray) -> "ConeCube":
        return cone_cube(self.inner, self.outer, direction, self.width, self.falloff)


#: Six faces as the point light's cube reads them (docs/light-textures.md): axis F, up U, right F × U.
_CUBE_FACES = (((1, 0, 0), (0, 1, 0)), ((-1, 0, 0), (0, 1, 0)), ((0, 1, 0), (0, 0, 1)), ((0, -1, 0), (0, 0, 1)),
               ((0, 0, 1), (0, 1, 0)), ((0, 0, -1), (0, 1, 0)))
#: The last cone cubes made: an animated spot that turns makes one a frame, so they are not all kept.
_CONE_CUBES: OrderedDict[tuple, ConeCube] = OrderedDict()


def cone_cube(inner: float, outer: float, direction, side: int = CONE_CUBE_SIDE, falloff: str = "gltf") -> ConeCube:
    """A spot's cone falloff (`spot_attenuation`) around `direction` as a point light's cube
    texture: each texel the attenuation of the angle between the axis and the ray through
    its centre, so zero outside the outer cone."""
    axis = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
    key = (float(inner), float(outer), side, falloff, *np.round(axis, 12).tolist())
    if key in _CONE_CUBES:
        _CONE_CUBES.move_to_end(key)
        return _CONE_CUBES[key]
    centres = (np.arange(side) + 0.5) / side * 2.0 - 1.0
    sx, sy = np.meshgrid(centres, -centres)  # row 0 is the image's top: +up
    faces = []
    for forward, up in _CUBE_FACES:
        forward, up = np.array(forward, float), np.array(up, float)
        rays = forward + sx[..., None] * np.cross(forward, up) + sy[..., None] * up
        cos_angle = rays @ axis / np.linalg.norm(rays, axis=-1)
        faces.append(spot_attenuation(cos_angle, inner, outer, falloff))
    texels = np.repeat(np.concatenate(faces)[:, :, None], 3, axis=2).astype(np.float32)
    cube = ConeCube(texels, f"cone falloff {math.degrees(inner):g}° to {math.degrees(outer):g}° (cube)", smooth=True,
                    axis=tuple(axis.tolist()), inner=float(inner), outer=float(outer), falloff=falloff)
    _CONE_CUBES[key] = cube
    while len(_CONE_CUBES) > 16:
        _CONE_CUBES.popitem(last=False)
    return cube


# --------------------------------------------------------------------------- camera


def _cameras(reader: _Reader, graph: NodeGraph, world: dict[int, np.ndarray]) -> list[tuple[str, int, dict, str]]:
    """(names, node, camera definition, its path) for every node of the scene with a camera, in node
    order (the order of `nodes`): the first is the default, and `--camera N` takes the N-th."""
    nodes, cameras = reader.items("nodes"), reader.items("cameras")
    found = []
    for index in sorted(graph.order):
        if "camera" in nodes[index]:
            which = reader.index(nodes[index], "camera", f"nodes.{index}", "cameras")
            names = [name for name in (cameras[which].get("name"), nodes[index].get("name")) if isinstance(name, str)]
            found.append((names, index, cameras[which], f"cameras.{which}"))
    return found


def _camera(reader: _Reader, found, name: str | None, matrix_of: dict[int, np.ndarray],
            bounds: tuple[np.ndarray, np.ndarray]) -> tuple[Camera, int | None]:
    if name is not None:
        chosen = [entry for entry in found if name in entry[0]]
        if not chosen and name.isdecimal() and int(name) < len(found):  # an index, where no camera has that name
            chosen = [found[int(name)]]
        if not chosen:
            names = sorted({n for entry in found for n in entry[0]})
            indices = f"an index 0 to {len(found) - 1}" if found else "no index (the scene places no camera)"
            raise SceneError(f"{reader.file}: cameras: expected a camera named {name!r} (the camera's or its "
                             f"node's name) or {indices}, got "
                             f"{', '.join(map(repr, names)) if names else 'no named camera'}")
        found = chosen
    if not found:
        return default_camera(*bounds), None
    _, node, camera, path = found[0]
    kind = reader.get(camera, "type", path, "string")
    if kind != "perspective":
        reader.fail(f"{path}.type", "a perspective camera (clrays has no orthographic one)", json.dumps(kind))
    perspective = reader.get(camera, "perspective", path, "dict")
    yfov = reader.get(perspective, "yfov", f"{path}.perspective", "number", lo=0.0, hi=math.pi)
    if not 0.0 < yfov < math.pi:
        reader.fail(f"{path}.perspective.yfov", "an angle in (0, π) radians", yfov)
    far = reader.get(perspective, "zfar", f"{path}.perspective", "number", None, lo=0.0)
    if far is not None and far <= 0.0:
        reader.fail(f"{path}.perspective.zfar", "a distance > 0", far)
    matrix = matrix_of[node]
    position = matrix[:3, 3].copy()
    forward, up = matrix[:3, :3] @ np.array([0.0, 0.0, -1.0]), matrix[:3, :3] @ np.array([0.0, 1.0, 0.0])
    if not (np.linalg.norm(forward) > 0 and np.linalg.norm(np.cross(forward, up)) > 1e-9 * np.linalg.norm(forward)
            * np.linalg.norm(up)):
        reader.fail(f"nodes.{node}", "a camera node whose matrix keeps -Z and +Y apart", "a degenerate matrix")
    forward = forward / np.linalg.norm(forward)
    far = far if far is not None else Camera.far
    # Camera rays start at znear (Blender writes its Clip Start there), as Cycles starts them. The
    # spec requires it; a file without one starts them at the eye.
    near = reader.get(perspective, "znear", f"{path}.perspective", "number", 0.0, lo=0.0)
    if not near < far:
        reader.fail(f"{path}.perspective.znear", f"a distance in [0, {far:g}) (below the camera's far)", near)
    return Camera(position=position, look_at=position + forward, up=up / np.linalg.norm(up),
                  fov_deg=math.degrees(yfov), far=far, near=near), node


def default_camera(lo: np.ndarray, hi: np.ndarray) -> Camera:
    """The view of bounds lo..hi without a camera: from the front (+z) and above, looking at
    their centre from the distance where their bounding sphere fills a 50° vertical field
    of view; far reaches twice past the sphere."""
    centre, radius = (lo + hi) / 2.0, max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-3)
    distance = radius / math.sin(math.radians(DEFAULT_FOV_DEG) / 2.0)
    return Camera(position=centre + distance * DEFAULT_VIEW_DIRECTION, look_at=centre, up=np.array([0.0, 1.0, 0.0]),
                  fov_deg=DEFAULT_FOV_DEG, far=2.0 * (distance + radius))


# --------------------------------------------------------------------------- animation


def _channels(reader: _Reader, graph: NodeGraph) -> tuple[tuple[_Channel, ...], float | None]:
    channels, end = [], None
    nodes = reader.items("nodes")
    for a, animation in enumerate(reader.items("animations")):
        path = f"animations.{a}"
        samplers = reader.get(animation, "samplers", path, "list")
        for c, channel in enumerate(reader.get(animation, "channels", path, "list")):
            where = f"{path}.channels.{c}"
            if not isinstance(channel, dict):
                reader.fail(where, "an object", channel)
            target = reader.get(channel, "target", where, "dict")
            target_path = reader.get(target, "path", f"{where}.target", "string")
            if target_path not in ("translation", "rotation", "scale", "weights"):
                continue  # extensions' paths (KHR_animation_pointer): not read (docs/scene-format.md)
            if "node" not in target:
                continue  # an extension targets something else
            node = reader.index(target, "node", f"{where}.target", "nodes")
            if "matrix" in nodes[node] and target_path != "weights":
                reader.fail(f"{where}.target.node", "a node with translation/rotation/scale (a matrix cannot be "
                            "animated)", node)
            sampler_index = reader.get(channel, "sampler", where, "int")
            if not 0 <= sampler_index < len(samplers) or not isinstance(samplers[sampler_index], dict):
                reader.fail(f"{where}.sampler", f"an index into {path}.samplers (0 to {len(samplers) - 1})",
                            sampler_index)
            sampler, sampler_path = samplers[sampler_index], f"{path}.samplers.{sampler_index}"
            interpolation = reader.get(sampler, "interpolation", sampler_path, "string", "LINEAR")
            if interpolation not in ("LINEAR", "STEP", "CUBICSPLINE"):
                reader.fail(f"{sampler_path}.interpolation", "LINEAR, STEP or CUBICSPLINE", json.dumps(interpolation))
            input_index = reader.index(sampler, "input", sampler_path, "accessors")
            times = reader.accessor(input_index, f"{sampler_path}.input", ("SCALAR",), (5126,))
            if times.min() < 0 or np.any(np.diff(times) <= 0):
                reader.fail(f"accessors.{input_index}", "key times >= 0 in increasing order", times[:8].tolist())
            output_index = reader.index(sampler, "output", sampler_path, "accessors")
            expected = len(times) * (3 if interpolation == "CUBICSPLINE" else 1)
            if target_path == "weights":  # a scalar per morph target and key (gltf_motion)
                width = gltf_motion.target_count(reader, node, f"{where}.target.node")
                values = reader.accessor(output_index, f"{sampler_path}.output", ("SCALAR",),
                                         (5126, 5120, 5121, 5122, 5123))
                expected *= width
            else:
                width = 4 if target_path == "rotation" else 3
                values = reader.accessor(output_index, f"{sampler_path}.output", ("VEC4" if width == 4 else "VEC3",),
                                         (5126, 5120, 5121, 5122, 5123) if width == 4 else (5126,))
            if len(values) != expected:
                reader.fail(f"accessors.{output_index}.count", f"{expected} values for {len(times)} key times "
                            f"({interpolation}{f', {width} morph targets' if target_path == 'weights' else ''})",
                            len(values))
            values = values.reshape(-1, width)
            if width == 4:
                keyed = values if interpolation != "CUBICSPLINE" else values[1::3]
                norms = np.linalg.norm(keyed, axis=1)
                if np.any(np.abs(norms - 1.0) > QUATERNION_TOLERANCE):
                    key = int(np.argmax(np.abs(norms - 1.0)))
                    reader.fail(f"accessors.{output_index}", "unit quaternions [x, y, z, w]",
                                f"{keyed[key].tolist()} with |q| = {float(norms[key]):.6g} at key {key}")
                values = values[:, [3, 0, 1, 2]]  # [w, x, y, z], as clrays's quaternions
            channels.append(_Channel(node, target_path, interpolation, times, values))
            end = max(end or 0.0, float(times[-1]))
    return tuple(channels), end


def _sample(channel: _Channel, time: float) -> np.ndarray:
    """A channel's value at `time` seconds: held before the first and after the last key."""
    times, values, cubic = channel.times, channel.values, channel.interpolation == "CUBICSPLINE"
    keyed = values[1::3] if cubic else values
    if time <= times[0]:
        value = keyed[0]
    elif time >= times[-1]:
        value = keyed[-1]
    else:
        k = int(np.searchsorted(times, time, side="right")) - 1
        span = times[k + 1] - times[k]
        u = (time - times[k]) / span
        if channel.interpolation == "STEP":
            value = keyed[k]
        elif cubic:  # Hermite with the out-tangent of key k and the in-tangent of key k + 1 (glTF appendix C)
            a, b = keyed[k], keyed[k + 1]
            out_tangent, in_tangent = values[3 * k + 2] * span, values[3 * (k + 1)] * span
            u2, u3 = u * u, u * u * u
            value = ((2 * u3 - 3 * u2 + 1) * a + (u3 - 2 * u2 + u) * out_tangent + (-2 * u3 + 3 * u2) * b
                     + (u3 - u2) * in_tangent)
        elif channel.path == "rotation":
            value = slerp(keyed[k], keyed[k + 1], u)
        else:
            value = keyed[k] + (keyed[k + 1] - keyed[k]) * u
    if channel.path == "rotation":
        norm = float(np.linalg.norm(value))
        value = value / norm if norm > 0 else np.array([1.0, 0.0, 0.0, 0.0])
    return value


@dataclass(frozen=True)
class GltfAnimation(Animation):
    """A glTF file's node animation, as a clrays animation: frame f is at f / fps seconds.
    Each frame's node world matrices place the imported meshes, lights and camera; the
    parts of the scene that did not come from the file keep their own values."""

    graph: NodeGraph = None
    instances: tuple[_Instance, ...] = ()
    first_row: int = 0  # the imported triangles' first row in Scene.geometry
    light_nodes: tuple[tuple[int, int], ...] = ()  # (scene light index, node)
    camera_node: int | None = None
    moving: tuple[int, ...] = ()  # the instances whose triangles some frame moves
    world_cache: dict = field(default_factory=dict, compare=False, repr=False)

    def _world(self, frame: float) -> dict[int, np.ndarray]:
        if frame not in self.world_cache:
            self.world_cache.clear()  # frames come one at a time: keep the last
            self.world_cache[frame] = self.graph.world(self.time(frame))
        return self.world_cache[frame]

    def _camera(self, scene: Scene, frame: float):
        if self.camera_node is None:
            return scene.camera
        matrix = self._world(frame)[self.camera_node]
        position = matrix[:3, 3].copy()
        forward, up = matrix[:3, :3] @ np.array([0.0, 0.0, -1.0]), matrix[:3, :3] @ np.array([0.0, 1.0, 0.0])
        return replace(scene.camera, position=position, look_at=position + forward / np.linalg.norm(forward),
                       up=up / np.linalg.norm(up))

    def _lights(self, scene: Scene, frame: float):
        lights, world = list(scene.lights), self._world(frame)
        for index, node in self.light_nodes:
            matrix, light = world[node], lights[index]
            direction = matrix[:3, :3] @ np.array([0.0, 0.0, -1.0])
            changes = {} if isinstance(light, DirectionalLight) else {"position": matrix[:3, 3].copy()}
            if not isinstance(light, PointLight) and np.linalg.norm(direction) > 0:
                changes["direction"] = direction / np.linalg.norm(direction)
            elif isinstance(light.texture, ConeCube) and np.linalg.norm(direction) > 0:  # a wide spot
                changes["texture"] = light.texture.aimed(direction)
            lights[index] = replace(light, **changes)
        return tuple(lights)

    def _geometry(self, scene: Scene, frame: float) -> Geometry:
        if not self.moving:  # the same Geometry each frame: its digest is made once (clrays.reuse)
            return scene.geometry
        world = self._world(frame)
        triangles, normals = scene.geometry.triangles.copy(), scene.geometry.normals.copy()
        for instance in (self.instances[i] for i in self.moving):
            rows = slice(instance.rows.start + self.first_row, instance.rows.stop + self.first_row)
            if instance.motion is not None:
                motion, time = instance.motion, self.time(frame)
                weights = None if motion.weight_channel is None else _sample(motion.weight_channel, time)
                triangles[rows], normals[rows] = motion.pose(world, weights, f"frame {frame:g} ({time:g} s)")
                continue
            matrix = world[instance.node]
            triangles[rows] = transform_points(matrix, instance.local)
            normals[rows] = _world_normals(matrix, instance.local_normals, triangles[rows])
        return replace(scene.geometry, triangles=triangles, normals=normals)


# --------------------------------------------------------------------------- defaults and notices

#: The default fog's optical depth across the meshes' bounding box diagonal (`default_medium`).
DEFAULT_FOG_DEPTH = 1.0
#: The suggested light's irradiance at the bounds' centre, W/m² (`suggested_light`).
SUGGESTED_IRRADIANCE = 4.0


def mesh_bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of world-space points; [-1, 1]³ without any."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not len(points):
        return np.full(3, -1.0), np.full(3, 1.0)
    return points.min(axis=0), points.max(axis=0)


def default_medium(lo: np.ndarray, hi: np.ndarray) -> Medium:
    """The fog of a glTF scene that gives no medium: isotropic, scattering only, σs such
    that the bounding box's diagonal is DEFAULT_FOG_DEPTH optical depths long (glTF has no
    media; without one there are no shafts, and the sample files want σs from 0.006 to 90
    per unit, so no one number serves)."""
    diagonal = max(float(np.linalg.norm(np.asarray(hi) - np.asarray(lo))), 1e-6)
    return Medium(sigma_s=np.full(3, DEFAULT_FOG_DEPTH / diagonal), sigma_a=np.zeros(3), phase=Phase())


def suggested_light(lo: np.ndarray, hi: np.ndarray) -> str:
    """A `--set` override adding a point light to a scene without one: over the bounds'
    centre, a quarter of their diagonal above their top, bright enough for SUGGESTED_IRRADIANCE W/m² at
    the centre (a surface of albedo 0.8 facing it shows radiance ≈ 1)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    centre, diagonal = (lo + hi) / 2.0, max(float(np.linalg.norm(hi - lo)), 1e-3)
    position = np.array([centre[0], hi[1] + diagonal / 4.0, centre[2]])
    intensity = SUGGESTED_IRRADIANCE * float(np.sum((position - centre) ** 2))
    def written(value: float, digits: int) -> str:  # without an exponent: YAML reads `1e+05` as a string
        return np.format_float_positional(value, precision=digits, unique=False, fractional=False, trim="-")

    return (f"lights.0={{type: point, position: [{', '.join(written(v, 4) for v in position)}], "
            f"intensity: {written(intensity, 3)}}}")


def _interpolated(triangles: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Which triangles interpolate their vertex normals: those whose normals are not their
    face's (a primitive without NORMAL has flat ones, and renders as a YAML solid)."""
    if not len(triangles):
        return np.zeros(0, bool)
    flat = primitives.flat_normals(triangles)
    return ~np.all(np.abs(normals - flat) <= 1e-6, axis=(1, 2))


def _notify_unrendered(reader: _Reader, graph: NodeGraph, camera_count: int) -> None:
    """One --verbose line listing what the file carries that clrays does not render."""
    nodes, meshes, materials = reader.items("nodes"), reader.items("meshes"), reader.items("materials")
    unsurfaced = []
    for mesh in sorted({nodes[i]["mesh"] for i in graph.order if isinstance(nodes[i].get("mesh"), int)}):
        if 0 <= mesh < len(meshes):
            for p, primitive in enumerate(meshes[mesh].get("primitives") or []):
                if isinstance(primitive, dict) and primitive.get("mode", _TRIANGLES) in (0, 1, 2, 3):
                    unsurfaced.append(f"meshes.{mesh}.primitives.{p}")
    emissive, blended, extensions = [], [], set()
    for i, material in enumerate(materials):
        factor = material.get("emissiveFactor")
        if "emissiveTexture" in material or (isinstance(factor, list) and any(
                _finite_number(v) and v > 0 for v in factor)):
            emissive.append(f"materials.{i}")
        if material.get("alphaMode", "OPAQUE") != "OPAQUE":
            blended.append(f"materials.{i}")
        if isinstance(material.get("extensions"), dict):
            extensions.update(name for name in material["extensions"] if material_only_extension(name))
    parts = []
    if unsurfaced:
        parts.append(f"{len(unsurfaced)} point or line primitive(s) ({_first_few(unsurfaced)}: no surface)")
    if emissive:
        parts.append(f"emission ({_first_few(emissive)}: surfaces do not glow)")
    if blended:
        parts.append(f"alphaMode ({_first_few(blended)}: every surface is opaque)")
    if extensions:
        parts.append(", ".join(sorted(extensions)))
    if camera_count > 1:
        parts.append(f"{camera_count - 1} camera(s) not chosen (--camera 0 to {camera_count - 1})")
    if parts:
        _notify(f"{reader.file}: not rendered: {'; '.join(parts)}", verbose=True)


def _notify_fog_like(reader: _Reader, graph: NodeGraph) -> None:
    """A notice naming the mesh nodes whose material has no pbrMetallicRoughness: what Blender's
    exporter writes for a volume-only material (a fog cube). The glTF 2.0 spec gives such a
    material the defaults (§5.19: "When undefined, all the default values of
    pbrMetallicRoughness MUST apply"), a white surface, so clrays draws it, and says how to
    make it the fog's bounds instead (`medium.bounds.object`)."""
    nodes, meshes, materials = reader.items("nodes"), reader.items("meshes"), reader.items("materials")
    bare = {i for i, material in enumerate(materials) if isinstance(material, dict)
            and not {"pbrMetallicRoughness", "extensions", "normalTexture", "emissiveTexture"} & material.keys()}
    named = []
    for i in graph.order:
        mesh = nodes[i].get("mesh")
        if isinstance(mesh, int) and 0 <= mesh < len(meshes) and isinstance(nodes[i].get("name"), str) and any(
                isinstance(primitive, dict) and primitive.get("material") in bare
                for primitive in meshes[mesh].get("primitives") or []):
            named.append(nodes[i]["name"])
    if named:
        _notify(f"{reader.file}: {_first_few([repr(name) for name in named])}: a material without "
                f"pbrMetallicRoughness (Blender's volume-only fog material is written so), drawn as a white "
                f"surface; if it is a fog volume, --set medium.bounds.object={named[0]}")


def _first_few(paths: list[str], count: int = 3) -> str:
    return ", ".join(paths[:count]) + (f" and {len(paths) - count} more" if len(paths) > count else "")


def _moving_instances(graph: NodeGraph, instances: tuple[_Instance, ...]) -> tuple[int, ...]:
    """The instances an animation moves: placed by an animated node or one below it, or
    deformed by a moving joint or animated weights."""
    moving = gltf_motion.moving_nodes(graph.parents, graph.order, {channel.node for channel in graph.channels})
    return tuple(i for i, instance in enumerate(instances)
                 if (instance.motion.moves(moving) if instance.motion is not None else instance.node in moving))


# --------------------------------------------------------------------------- entry points


def _check_coordinates(reader: "_Reader", triangles: np.ndarray, lights, camera) -> None:
    """World-space vertices, light positions and the camera within ±MAX_COORDINATE, as a
    YAML scene's (docs/limits.md): float32 on the device overflows in the products beyond."""
    for what, points in (("meshes", triangles), ("lights", [getattr(light, "position", np.zeros(3)) for light in lights]),
                         ("cameras", [camera.position] if camera is not None else [])):
        largest = float(np.abs(np.asarray(points, dtype=np.float64)).max(initial=0.0))
        if not largest <= MAX_COORDINATE:
            reader.fail(what, f"world-space coordinates within ±{MAX_COORDINATE:g} (float32 on the device overflows "
                              "beyond)", f"{largest:.3g}")


#: On [0, 1] the cubic Hermite basis functions h00 and h01 lie in [0, 1] and sum to 1, while
#: |h10| and |h11| are at most 4/27 (at u = 1/3 and 2/3): the bound on a spline's overshoot.
_HERMITE_TANGENT_BOUND = 4.0 / 27.0


def _channel_extent(channel: _Channel) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi): per component, lo <= |value(t)| <= hi at every time t, from the channel's
    keys alone (`_sample` holds the first and last key outside them). Between two keys a and
    b, LINEAR and STEP values lie between a and b; a CUBICSPLINE's is h00·a + h01·b (between
    them too) plus h10·m0 + h11·m1, at most 4/27 (|m0| + |m1|) with the tangents m scaled by
    the span. A component may reach 0 only where two keys differ in sign (or one is 0)."""
    if channel.interpolation != "CUBICSPLINE":
        keys = np.abs(channel.values)
        overshoot = np.zeros((max(len(keys) - 1, 0), keys.shape[1]))
    else:
        keys = np.abs(channel.values[1::3])
        spans = np.diff(channel.times)[:, None]
        overshoot = _HERMITE_TANGENT_BOUND * spans * (np.abs(channel.values[2::3][:-1]) + np.abs(channel.values[3::3]))
    signs = np.sign(channel.values[1::3] if channel.interpolation == "CUBICSPLINE" else channel.values)
    hi = np.maximum(keys.max(axis=0), (np.maximum(keys[:-1], keys[1:]) + overshoot).max(axis=0, initial=0.0))
    if channel.interpolation == "STEP" or len(keys) == 1:
        return keys.min(axis=0), hi
    one_sign = signs[:-1] * signs[1:] > 0
    segment_lo = np.where(one_sign, np.maximum(np.minimum(keys[:-1], keys[1:]) - overshoot, 0.0), 0.0)
    return segment_lo.min(axis=0), hi


def _times(a: float, b: float) -> float:
    """a·b for bounds >= 0, where 0 wins over infinity: a factor that is always 0 keeps the product 0."""
    return 0.0 if a == 0.0 or b == 0.0 else a * b


def pose_bounds(graph: NodeGraph) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(animated, norm_hi, norm_lo, reach), per node, over every time of the animation: whether
    the node or a parent is animated, bounds on its world matrix's largest and least
    singular values, and on its world translation's length. From each node's own keys alone,
    in time linear in keys and nodes:

    - a node's local transform x -> L·x + t: ‖L‖ <= max |scale|, its least singular value
      >= min |scale| (a rotation keeps lengths), |t| <= the translation's bound, over the
      keys of the channels that replace its static parts (`_channel_extent`); a `matrix` is fixed;
    - composed down the hierarchy: ‖W‖ <= ‖W_parent‖·‖L‖, σ_min(W) >= σ_min(W_parent)·σ_min(L),
      |w| <= |w_parent| + ‖W_parent‖·|t| for the world matrix W and translation w;

    so a point at distance r from a node's origin stays within reach + norm_hi·r of the
    world's. Sound at every time, so it may exceed what the frames reach (a large scale at
    one time and a large translation at another)."""
    count = len(graph.parents)
    animated = np.zeros(count, dtype=bool)
    translation_hi = np.linalg.norm(np.array([t for t, _, _ in graph.trs]).reshape(-1, 3), axis=1)
    scales = np.abs(np.array([s for _, _, s in graph.trs]).reshape(-1, 3))
    scale_hi, scale_lo = scales.max(axis=1, initial=0.0), scales.min(axis=1, initial=np.inf)
    moved, scaled = set(), set()  # nodes whose static part the channels' bounds (all of them) replace
    for channel in graph.channels:
        animated[channel.node] = True
        if channel.path == "rotation":
            continue
        lo, hi = _channel_extent(channel)
        node = channel.node
        if channel.path == "translation":
            bound = float(np.linalg.norm(hi))
            translation_hi[node] = bound if node not in moved else max(translation_hi[node], bound)
            moved.add(node)
        else:
            scale_hi[node] = float(hi.max()) if node not in scaled else max(scale_hi[node], float(hi.max()))
            scale_lo[node] = float(lo.min()) if node not in scaled else min(scale_lo[node], float(lo.min()))
            scaled.add(node)
    fixed = [i for i, matrix in enumerate(graph.matrices) if matrix is not None]
    if fixed:
        matrices = np.stack([graph.matrices[i] for i in fixed])
        singular = np.linalg.svd(matrices[:, :3, :3], compute_uv=False)
        scale_hi[fixed], scale_lo[fixed] = singular[:, 0], singular[:, -1]
        translation_hi[fixed] = np.linalg.norm(matrices[:, :3, 3], axis=1)
    norm_hi, norm_lo, reach = np.zeros(count), np.zeros(count), np.zeros(count)
    for node in graph.order:  # parents first
        parent = graph.parents[node]
        if parent < 0:
            norm_hi[node], norm_lo[node], reach[node] = scale_hi[node], scale_lo[node], translation_hi[node]
        else:
            animated[node] |= animated[parent]
            norm_hi[node] = _times(norm_hi[parent], scale_hi[node])
            norm_lo[node] = norm_lo[parent] * scale_lo[node]
            reach[node] = reach[parent] + _times(norm_hi[parent], translation_hi[node])
    return animated, norm_hi, norm_lo, reach


def _check_animated_poses(reader: "_Reader", graph: NodeGraph, instances, light_nodes, camera_node) -> None:
    """Every animated pose within what the device holds, as a YAML animation's keys are:
    every mesh vertex, light and the camera within ±MAX_COORDINATE at every time, and the
    camera's frame not scaled to nothing (its direction would be 0/0), by `pose_bounds`:
    proved, not sampled (sampling every key time cost key times × nodes: 65 536 nodes and
    400 key times took minutes). Only what lies under an animated node is checked here: the
    static pose is checked exactly (`_check_coordinates`)."""
    if not graph.channels:
        return
    animated, norm_hi, norm_lo, reach = pose_bounds(graph)
    placed = [(instance.node, float(np.sqrt((instance.local.reshape(-1, 3) ** 2).sum(axis=1)).max(initial=0.0)),
               "mesh") for instance in instances]
    placed += [(node, 0.0, "light") for node in light_nodes]
    placed += [(camera_node, 0.0, "camera")] if camera_node is not None else []
    for node, radius, what in placed:
        bound = reach[node] + _times(norm_hi[node], radius)
        if animated[node] and not bound <= MAX_COORDINATE:
            reader.fail("animations", f"poses within ±{MAX_COORDINATE:g} (float32 on the device overflows beyond)",
                        f"up to {bound:.3g} from the origin for the {what} of nodes.{node}, bounded from the keys of "
                        f"it and its parents")
    if camera_node is not None and animated[camera_node] and not norm_lo[camera_node] > 1e-12:
        reader.fail(f"nodes.{camera_node}", "a camera node whose animated scale leaves it a direction",
                    f"a scale that may reach {norm_lo[camera_node]:.3g}, bounded from the keys of it and its parents")


def import_gltf(path: Path, file: str | None = None, camera: str | None = None, light_scale: float = 1.0,
                volume: str | None = None) -> Imported:
    """Read a glTF 2.0 file: `camera` names the camera to take (the first otherwise),
    `light_scale` multiplies every light's power. `file` names it in messages. `volume` names
    the node whose mesh only bounds the fog (`medium.bounds: {object: NAME}`): it is left out
    of the geometry and its world box is `volume_bounds`."""
    path = Path(path)
    file = file or str(path)
    reader = _open(path, file)
    _check_header(reader)
    graph = _graph(reader)
    world = graph.world()
    for node in graph.order:  # the device works in float32: a product of large transforms must stay in its range
        if not np.all(np.abs(world[node]) < FLOAT32_MAX):
            reader.fail(f"nodes.{node}", "a transform that, with its parents', stays finite in float32",
                        f"a world matrix entry of {float(np.abs(world[node]).max()):.3g}")
    channels, duration = _channels(reader, graph)
    fog_node = volume_node(reader, replace(graph, channels=channels), volume) if volume is not None else None
    volume_bounds = _volume_bounds(reader, fog_node, world[fog_node]) if fog_node is not None else None
    instances, tris, normals, albedo, outward = _meshes(reader, graph, world, channels, skipped=fog_node)
    lights, light_nodes = _lights(reader, graph, world, light_scale)
    triangles = np.concatenate(tris) if tris else np.zeros((0, 3, 3))
    del tris
    if len(triangles):
        bounds = (triangles.reshape(-1, 3).min(axis=0), triangles.reshape(-1, 3).max(axis=0))
    else:
        bounds = (np.full(3, -1.0), np.full(3, 1.0))
    cameras = _cameras(reader, graph, world)
    scene_camera, camera_node = _camera(reader, cameras, camera, world, bounds)
    _notify_unrendered(reader, graph, len(cameras))
    if volume is None:
        _notify_fog_like(reader, graph)
    _check_coordinates(reader, triangles, lights, scene_camera)
    # The nodes' channels; a weights channel is its Deformation's (gltf_motion).
    graph = NodeGraph(graph.parents, graph.order, graph.matrices, graph.trs,
                      tuple(channel for channel in channels if channel.path != "weights"))
    _check_animated_poses(reader, graph, [i for i in instances if i.motion is None], light_nodes, camera_node)
    gltf_motion.check_poses([i.motion for i in instances if i.motion is not None], graph, channels, _sample)
    object_id = np.concatenate([np.full(i.rows.stop - i.rows.start, k, np.int32) for k, i in enumerate(instances)]) \
        if instances else np.zeros(0, np.int32)
    return Imported(file=file, triangles=triangles,
                    normals=np.concatenate(normals) if normals else np.zeros((0, 3, 3)),
                    albedo=np.concatenate(albedo) if albedo else np.zeros((0, 3)), object_id=object_id,
                    outward=np.concatenate(outward) if outward else np.zeros(0, np.int8),
                    object_count=len(instances), instances=tuple(instances), lights=tuple(lights),
                    light_nodes=tuple(light_nodes), camera=scene_camera, camera_node=camera_node, graph=graph,
                    duration=duration, volume_bounds=volume_bounds)


def merge(scene: Scene, imported: Imported, own_camera: bool, own_animation: bool, fps: float,
          own_medium: bool = True) -> Scene:
    """The scene with the imported meshes and lights after its own, and the file's animation
    unless the scene has one of its own; without a medium of its own (`own_medium` False)
    the default fog of the bounds (`default_medium`). Checks the limits over both."""
    geometry = scene.geometry
    objects = (int(geometry.object_id.max()) + 1 if geometry.count else 0)
    if objects + imported.object_count > MAX_OBJECTS:
        raise SceneError(f"{imported.file}: meshes: expected at most {MAX_OBJECTS} objects with the scene's own, "
                         f"got {objects + imported.object_count}")
    if geometry.count + len(imported.triangles) > MAX_TRIANGLES:
        raise SceneError(f"{imported.file}: meshes: expected at most {MAX_TRIANGLES} triangles with the scene's "
                         f"own, got {geometry.count + len(imported.triangles)}")
    lights = scene.lights + imported.lights
    bounds = mesh_bounds(np.concatenate([geometry.triangles.reshape(-1, 3), imported.triangles.reshape(-1, 3)]))
    if not lights:
        raise SceneError(f"{imported.file}: extensions.KHR_lights_punctual: expected at least 1 light "
                         f"(KHR_lights_punctual, or the scene's lights), got none; add one above the meshes with "
                         f"--set '{suggested_light(*bounds)}'")
    if len(lights) > MAX_LIGHTS:
        raise SceneError(f"{imported.file}: extensions.KHR_lights_punctual: expected at most {MAX_LIGHTS} lights "
                         f"with the scene's own, got {len(lights)}")
    count = len(imported.triangles)
    opacity = None if geometry.opacity is None else np.concatenate([geometry.opacity, np.ones((count, 3))])
    merged = Geometry(
        triangles=np.ascontiguousarray(np.concatenate([geometry.triangles, imported.triangles]), dtype=np.float64),
        albedo=np.ascontiguousarray(np.concatenate([geometry.albedo, imported.albedo]), dtype=np.float64),
        object_id=np.concatenate([geometry.object_id, imported.object_id + objects]).astype(np.int32),
        normals=np.concatenate([geometry.normals, imported.normals]),
        smooth=np.concatenate([geometry.smooth, _interpolated(imported.triangles, imported.normals)]),
        reliefs=geometry.reliefs, opacity=opacity,
        outward=np.concatenate([geometry.outward, imported.outward]),
        convex_part=np.concatenate([geometry.convex_part,
                                    geometry.count + np.arange(count, dtype=np.int32)]).astype(np.int32))
    # The scene's camera is the file's unless own_camera (the loader took it, its near maybe set).
    scene = replace(scene, lights=lights, geometry=merged)
    if imported.duration is not None and not own_animation:
        frames = imported.duration * fps
        if not frames <= MAX_ANIMATION_FRAME:  # as a YAML animation's frames (fields.ANIMATION)
            raise SceneError(f"{imported.file}: animations: expected at most {MAX_ANIMATION_FRAME} frames at "
                             f"gltf.fps {fps:g}, got {imported.duration:.6g} s of keys ({frames:.6g} frames)")
        first_light = len(lights) - len(imported.lights)
        scene = replace(scene, animation=GltfAnimation(
            fps=fps, first=0, last=max(int(math.ceil(imported.duration * fps - 1e-9)), 0),
            graph=imported.graph, instances=imported.instances, first_row=geometry.count,
            light_nodes=tuple((first_light + i, node) for i, node in enumerate(imported.light_nodes)),
            camera_node=None if own_camera else imported.camera_node,
            moving=_moving_instances(imported.graph, imported.instances)))
    if not own_medium:  # last, so that a refused file says only why
        scene = replace(scene, medium=default_medium(*bounds))
        sigma = f"{float(scene.medium.sigma_s[0]):.3g}"
        _notify(f"{imported.file}: no medium: the default fog, sigma_s = {sigma} per unit (optical depth 1 across "
                f"the meshes' {float(np.linalg.norm(bounds[1] - bounds[0])):.3g}-unit bounding box diagonal); set "
                f"one with --set medium.sigma_s={sigma} (0: clear air)")
    return scene
