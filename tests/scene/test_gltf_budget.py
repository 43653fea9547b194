"""Small glTF files that used to cost minutes or gigabytes (clrays/scene/gltf.py,
docs/limits.md "glTF"): accessors without a view, the same accessor or image read again,
the animated-pose check, a GLB's chunk list, and a missing image reported as one. Each
runs in a fresh process, as the command line would, and must end within 20 s and 2 GB in
one error line or a correct import."""
from __future__ import annotations

import io
import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clrays.errors import SceneError
from clrays.scene import gltf
from clrays.scene.limits import MAX_GLB_CHUNKS, MAX_GLTF_IMPORT_BYTES
from clrays.scene.load import load_scene
from test_gltf import ROOT, TRIANGLE, GltfBuilder, _lit, _write, box, deep_chain

SECONDS, PEAK_MB = 20, 2048
#: float32 VEC3 elements in 128 MiB, the most one buffer may hold: the issue's accessors without a view.
BIG_COUNT = (128 << 20) // 12

_LOAD = """
import json, resource, sys, time
from clrays.errors import SceneError
from clrays.scene.load import load_scene
start = time.perf_counter()
try:
    scene = load_scene(sys.argv[1])
    result = {"count": len(scene.geometry.triangles), "first": scene.geometry.triangles[:24].tolist(),
              "albedo": scene.geometry.albedo[:1].tolist()}
except SceneError as exc:
    result = {"error": str(exc)}
result["seconds"] = time.perf_counter() - start
# this process's own peak (VmHWM): ru_maxrss would keep the parent's from before the exec
status = dict(line.split(":", 1) for line in open("/proc/self/status") if ":" in line)
result["peak_mb"] = (int(status["VmHWM"].split()[0]) if "VmHWM" in status else
                     resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) / 1024
print(json.dumps(result))
"""


def _load_fresh(path: Path) -> dict:
    """load_scene(path) in a fresh process: its triangles or its error, its seconds and peak MB."""
    done = subprocess.run([sys.executable, "-c", _LOAD, str(path)], capture_output=True, text=True,
                          timeout=4 * SECONDS, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    print(path.name, {k: v for k, v in result.items() if k != "first"})
    assert result["seconds"] < SECONDS and result["peak_mb"] < PEAK_MB, result
    assert "\n" not in result.get("error", ""), result
    return result


def _zeros(builder: GltfBuilder, count: int = BIG_COUNT) -> int:
    """An accessor of `count` float VEC3s without a bufferView: all zeros, by the spec."""
    builder.doc["accessors"].append({"componentType": 5126, "count": count, "type": "VEC3"})
    return len(builder.doc["accessors"]) - 1


def _triangle_on(builder: GltfBuilder, position: int, indices: int, mode: int = 4) -> int:
    """A mesh of one primitive: `position` indexed by `indices`, placed by a new node."""
    builder.doc["meshes"].append({"primitives": [{"attributes": {"POSITION": position}, "indices": indices,
                                                  "mode": mode}]})
    return builder.node(mesh=len(builder.doc["meshes"]) - 1)


# --------------------------------------------------------------------------- accessors without a view


def test_accessors_without_a_view_are_counted_against_the_budget(tmp_path):
    """24 primitives, each a 128 MiB accessor of zeros (1.5 KB of JSON): each would become
    268 MB of float64, so the fifth passes the budget and the file is refused in one line,
    in seconds (it was killed at 60 s; 3 primitives took 25 s and 771 MB)."""
    b = _lit(GltfBuilder())
    indices = b.accessor([0, 1, 2], 5125)
    for _ in range(24):
        _triangle_on(b, _zeros(b), indices)
    path = _write(tmp_path, b)
    assert path.stat().st_size < 4000
    result = _load_fresh(path)
    assert result["error"].startswith(f"{path}: accessors.5: expected at most 1024 MiB read and decoded by the "
                                      f"import in all (buffers, accessors as float64, images; docs/limits.md), got "
                                      f"268435440 bytes more for 11184810 elements of 3 float64s, after "), result


def test_an_accessor_named_by_many_primitives_is_read_once(tmp_path):
    """One 128 MiB accessor of zeros, three of its elements replaced by a sparse
    substitution to make a triangle, named by 24 triangle primitives and 24 point
    primitives: read once, and each primitive keeps only the vertices its faces use, so
    the file imports its 24 triangles in seconds."""
    b = _lit(GltfBuilder())
    shared = _zeros(b)
    b.doc["accessors"][shared]["sparse"] = {
        "count": 3, "indices": {"bufferView": b.doc["accessors"][b.accessor([5, 70, 900], 5125)]["bufferView"],
                                "componentType": 5125},
        "values": {"bufferView": b.doc["accessors"][b.accessor(TRIANGLE)]["bufferView"]}}
    indices = b.accessor([5, 70, 900], 5125)
    for k in range(24):
        _triangle_on(b, shared, indices)
        _triangle_on(b, shared, indices, mode=0)  # points: no surface
    result = _load_fresh(_write(tmp_path, b))
    assert "error" not in result, result
    assert result["count"] == 24
    np.testing.assert_array_equal(np.array(result["first"]), np.broadcast_to(TRIANGLE, (24, 3, 3)))


def test_a_second_use_of_an_accessor_is_the_first_read(tmp_path):
    """The reader hands every use of an accessor the same read-only array and charges its
    bytes once."""
    b = _lit(GltfBuilder())
    position = b.accessor(TRIANGLE)
    path = _write(tmp_path, b)
    reader = gltf._open(path, str(path))
    first = reader.accessor(position, "first use", ("VEC3",), (5126,))
    charged = reader.charged
    assert reader.accessor(position, "second use", ("VEC3",), (5126,)) is first
    assert reader.charged == charged and charged >= first.nbytes
    with pytest.raises(ValueError, match="read-only"):
        first[0, 0] = 1.0


# --------------------------------------------------------------------------- the animated-pose check


def test_the_pose_check_of_many_nodes_and_keys_is_linear(tmp_path):
    """65 536 nodes in a chain, the mesh at its end, 40 of them animated with 400 key
    times each (the check was killed at 60 s: it composed every node at every key time):
    bounded from each node's own keys and composed once, the file loads in seconds."""
    b, first, count = deep_chain()
    times = np.linspace(0.0, 4.0, 400)
    for k in range(40):
        wave = np.stack([np.full(400, 0.001), 0.01 * np.sin(times * (k + 1)), np.zeros(400)], axis=1)
        b.animate(first + k * 1000, "translation", times, wave)
    path = _write(tmp_path, b)
    assert path.stat().st_size < 4 << 20
    result = _load_fresh(path)
    assert "error" not in result, result
    assert np.array(result["first"])[0, :, 0].min() == pytest.approx(0.001 * (count - 1), rel=1e-6)


def _animated(key_values, interpolation="LINEAR", path="translation", tangents=None, camera=False):
    """A box whose node moves by `key_values` at 0, 1, 2... s (or a camera's node, scaled)."""
    b = _lit(GltfBuilder())
    vertices, _, faces = box([1, 1, 1])
    b.mesh(vertices, faces)
    node = b.node(mesh=0) if not camera else b.node(camera=b.camera(0.8), translation=[0, 1, 6])
    values = np.asarray(key_values, float)
    if interpolation == "CUBICSPLINE":  # in-tangent, value, out-tangent per key
        values = np.stack([tangents, values, tangents], axis=1).reshape(-1, values.shape[1])
    b.animate(node, path, np.arange(len(key_values), dtype=float), values, interpolation)
    return b


@pytest.mark.parametrize("case, pattern", [
    ("a key just inside", None),
    ("a key past 1e12", r"animations: expected poses within ±1e\+12 .*got up to 1\.01e\+12 from the origin for the "
                        r"mesh of nodes\.1"),
    ("a spline whose tangents overshoot between keys", r"got up to 1\.48e\+12 from the origin for the mesh of nodes\.1"),
    ("a scale through 0 between keys", r"nodes\.1: expected a camera node whose animated scale leaves it a direction, "
                                       r"got a scale that may reach 0"),
])
def test_the_pose_bound_holds_between_keys(tmp_path, case, pattern):
    """The bound covers every time, not just the keys: a cubic spline whose keys are all
    at 0 but whose tangents carry it to 1e12 between them (4/27 of the tangents), and a
    camera scaled from 1 to -1 (through 0 half way), are refused, as a key past the limit
    is; a key just inside it loads."""
    if case == "a key just inside":
        b = _animated([[0, 0, 0], [0.99e12, 0, 0]])
    elif case == "a key past 1e12":
        b = _animated([[0, 0, 0], [1.01e12, 0, 0]])
    elif case == "a spline whose tangents overshoot between keys":
        b = _animated([[0, 0, 0], [0, 0, 0]], "CUBICSPLINE", tangents=[[5e12, 0, 0], [5e12, 0, 0]])
    else:
        b = _animated([[1, 1, 1], [-1, -1, -1]], path="scale", camera=True)
    path = _write(tmp_path, b)
    if pattern is None:
        assert len(load_scene(path).geometry.triangles) == 12
    else:
        with pytest.raises(SceneError, match=pattern):
            load_scene(path)


def test_the_pose_bounds_hold_at_every_sampled_time(tmp_path):
    """A random hierarchy of TRS and matrix nodes with LINEAR, STEP and CUBICSPLINE channels
    on translations, rotations and scales (some through 0), sampled at 4001 times and every
    key: every node's world matrix and translation lie within `pose_bounds`; and a root
    moved by keys [0, 0, 0] and [3, 4, 0] alone is bounded by 5, what it reaches."""
    from clrays.scene.gltf import NodeGraph, pose_bounds
    from test_gltf import quaternion

    rng = np.random.default_rng(7)
    b = GltfBuilder()
    nodes = [b.node(translation=[3.0, 4.0, 0.0])]
    for k in range(1, 14):
        parent = nodes[int(rng.integers(0, len(nodes)))]
        if k % 5 == 0:
            matrix = np.eye(4)
            matrix[:3, :3] = rng.normal(size=(3, 3))
            matrix[:3, 3] = rng.normal(size=3)
            nodes.append(b.node(parent, matrix=matrix.T.reshape(-1).tolist()))
        else:
            nodes.append(b.node(parent, translation=rng.normal(size=3).tolist(),
                                rotation=quaternion(rng.normal(size=3), float(rng.uniform(0, 180))),
                                scale=rng.uniform(0.5, 2.0, 3).tolist()))
    b.animate(nodes[0], "translation", [0.0, 1.0], [[0, 0, 0], [3, 4, 0]])
    for k, node in enumerate(nodes[1:], 1):
        if k % 5 == 0 or rng.uniform() < 0.2:
            continue
        path = ["translation", "rotation", "scale"][k % 3]
        interpolation = ["LINEAR", "STEP", "CUBICSPLINE"][int(rng.integers(0, 3))]
        times = np.sort(rng.uniform(0.0, 3.0, 5))
        if path == "rotation":
            values = np.array([quaternion(rng.normal(size=3), float(rng.uniform(0, 360))) for _ in times])
        else:
            values = rng.normal(size=(5, 3)) * (2.0 if path == "translation" else 1.0)  # scales through 0
        if interpolation == "CUBICSPLINE":
            tangents = rng.normal(size=(5, values.shape[1])) * 3.0
            values = np.stack([tangents, values, -tangents], axis=1).reshape(-1, values.shape[1])
        b.animate(node, path, times, values, interpolation)
    path = _write(tmp_path, b)
    reader = gltf._open(path, str(path))
    graph = gltf._graph(reader)
    channels, _ = gltf._channels(reader, graph)
    graph = NodeGraph(graph.parents, graph.order, graph.matrices, graph.trs, channels)
    animated, norm_hi, norm_lo, reach = pose_bounds(graph)
    assert animated.sum() > 5 and reach[nodes[0]] == pytest.approx(5.0)
    keys = np.concatenate([channel.times for channel in channels])
    largest_reach = np.zeros(len(nodes))
    for time in np.concatenate([np.linspace(-0.5, 3.5, 4001), keys]):
        world = graph.world(float(time))
        for node in nodes:
            singular = np.linalg.svd(world[node][:3, :3], compute_uv=False)
            moved = float(np.linalg.norm(world[node][:3, 3]))
            largest_reach[node] = max(largest_reach[node], moved)
            assert singular[0] <= norm_hi[node] * (1 + 1e-9), (node, time)
            assert singular[-1] >= norm_lo[node] * (1 - 1e-9) - 1e-12, (node, time)
            assert moved <= reach[node] * (1 + 1e-9), (node, time)
    assert largest_reach[nodes[0]] == pytest.approx(5.0)


# --------------------------------------------------------------------------- images


def _png(side: int = 4096) -> bytes:
    """A side² RGB PNG, a quarter of it white: 49 KB at 4096², 48 MiB decoded."""
    from PIL import Image

    pixels = np.zeros((side, side, 3), np.uint8)
    pixels[: side // 2, : side // 2] = 255
    encoded = io.BytesIO()
    Image.fromarray(pixels).save(encoded, format="PNG")
    return encoded.getvalue()


def _textured(builder: GltfBuilder, images: list[dict]) -> None:
    """One textured triangle per image entry, each its own material."""
    builder.doc["images"] = images
    builder.doc["textures"] = [{"source": i} for i in range(len(images))]
    position = builder.accessor(TRIANGLE)
    indices = builder.accessor([0, 1, 2], 5125)
    for i in range(len(images)):
        builder.doc["materials"].append({"pbrMetallicRoughness": {"baseColorTexture": {"index": i}}})
        builder.doc["meshes"].append({"primitives": [{"attributes": {"POSITION": position}, "indices": indices,
                                                      "material": len(builder.doc["materials"]) - 1}]})
        builder.node(mesh=len(builder.doc["meshes"]) - 1)


@pytest.mark.parametrize("form", ["file", "bufferView"])
def test_one_image_named_by_200_entries_is_decoded_once(tmp_path, form):
    """A 49 KB PNG of 4096² pixels named by 200 `images` entries (a file each names, or one
    buffer view): decoded once, so the file loads in seconds (it was killed at 60 s; 20
    entries took 33 s), every triangle with the image's mean colour, a quarter white."""
    data = _png()
    b = _lit(GltfBuilder())
    if form == "file":
        (tmp_path / "texture.png").write_bytes(data)
        images = [{"uri": "texture.png"}] * 200
    else:
        while len(b.binary) % 4:
            b.binary.append(0)
        b.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(b.binary), "byteLength": len(data)})
        b.binary += data
        images = [{"bufferView": len(b.doc["bufferViews"]) - 1, "mimeType": "image/png"}] * 200
    _textured(b, images)
    result = _load_fresh(_write(tmp_path, b))
    assert result.get("count") == 200, result
    np.testing.assert_allclose(result["albedo"][0], [0.25, 0.25, 0.25], atol=1e-9)


def test_decoded_pixels_are_counted_against_the_budget(tmp_path):
    """200 image entries, each its own buffer view of the same 49 KB PNG (identical data
    URIs would be one source): 64 MiB of pixels each decoded (4 bytes a pixel), so the
    16th passes the budget (with the buffer's bytes) and the file is refused in one line,
    in seconds."""
    data = _png()
    b = _lit(GltfBuilder())
    b.doc["bufferViews"] += [{"buffer": 0, "byteOffset": len(b.binary), "byteLength": len(data)}] * 200
    b.binary += data
    _textured(b, [{"bufferView": k, "mimeType": "image/png"} for k in range(200)])
    result = _load_fresh(_write(tmp_path, b))
    assert MAX_GLTF_IMPORT_BYTES // (64 << 20) == 16
    assert ": images.15: expected at most 1024 MiB read and decoded by the import in all" in result["error"], result
    assert "got 67108864 bytes more for its 4096×4096 pixels decoded" in result["error"], result


def test_a_missing_image_is_reported_as_an_image(tmp_path):
    b = _lit(GltfBuilder())
    _textured(b, [{"uri": "missing%20texture.png"}])
    with pytest.raises(SceneError, match=r"images\.0\.uri: expected a readable image file, got 'missing%20texture\.png' "
                                         r"\(No such file or directory\)$"):
        load_scene(_write(tmp_path, b))


# --------------------------------------------------------------------------- GLB chunks


def _glb_with_chunks(builder: GltfBuilder, extra: bytes) -> bytes:
    """builder's GLB with `extra` chunk bytes appended after its last chunk."""
    data = builder.glb() + extra
    return data[:8] + struct.pack("<I", len(data)) + data[12:]


def test_19_million_empty_chunks_are_refused_at_the_chunk_limit(tmp_path):
    """19 million empty chunks of an unknown type after the JSON and BIN chunks (a 152 MB
    file, within the file limit): walked up to the chunk limit, then refused in one line,
    in seconds (it took 52 s and 2.1 GB, then loaded)."""
    b = _lit(GltfBuilder())
    b.mesh(TRIANGLE, [[0, 1, 2]])
    b.node(mesh=0)
    path = tmp_path / "chunks.glb"
    path.write_bytes(_glb_with_chunks(b, struct.pack("<II", 0, 0x58595A57) * 19_000_000))
    result = _load_fresh(path)
    assert f"expected at most {MAX_GLB_CHUNKS} chunks (JSON, BIN and chunks of extensions; docs/limits.md), got " \
           f"more" in result["error"], result


def test_a_few_unknown_chunks_are_skipped_and_a_second_bin_chunk_refused(tmp_path):
    """Chunks of unknown types after the first two are skipped, as the spec asks; a JSON or
    BIN chunk there breaks the spec's order and is refused by its position."""
    b = _lit(GltfBuilder())
    b.mesh(TRIANGLE, [[0, 1, 2]])
    b.node(mesh=0)
    unknown = struct.pack("<II", 4, 0x58595A57) + b"abcd"
    path = tmp_path / "skipped.glb"
    path.write_bytes(_glb_with_chunks(b, unknown * (MAX_GLB_CHUNKS - 2)))
    np.testing.assert_allclose(load_scene(path).geometry.triangles[0], TRIANGLE)
    path.write_bytes(_glb_with_chunks(b, unknown * (MAX_GLB_CHUNKS - 1)))
    with pytest.raises(SceneError, match=rf"\(GLB chunk at byte \d+\): expected at most {MAX_GLB_CHUNKS} chunks"):
        load_scene(path)
    path.write_bytes(_glb_with_chunks(b, unknown + struct.pack("<II", 4, 0x004E4942) + bytes(4)))
    with pytest.raises(SceneError, match=r"\(GLB chunk at byte \d+\): expected one JSON chunk, first, and at most one "
                                         r"BIN chunk, second \(glTF 2\.0, GLB chunks\), got a BIN chunk as chunk 4"):
        load_scene(path)


# --------------------------------------------------------------------------- the JSON itself


def test_json_of_millions_of_small_values_is_refused_before_it_is_parsed(tmp_path):
    """27 MB of `[],` in a .gltf's `extras` (9 million empty lists: 540 MB to parse at 21 MB,
    4 GB at the file limit): counted before parsing and refused in one line, in a fraction
    of the memory."""
    path = tmp_path / "lists.gltf"
    path.write_bytes(b'{"asset": {"version": "2.0"}, "extras": [' + b"[]," * 9_000_000 + b"[]]}")
    result = _load_fresh(path)
    assert result["error"] == f"{path}: (JSON): expected at most {gltf.MAX_GLTF_JSON_VALUES} values " \
                              f"(docs/limits.md), got about 18000009", result  # 9 M commas and 9 M brackets, and the rest
    assert result["peak_mb"] < 300, result


def test_a_json_of_ordinary_size_is_parsed():
    """scenes/colonnade.glb's JSON, far below the count, loads as before."""
    scene = load_scene(ROOT / "scenes" / "colonnade.glb")
    assert len(scene.geometry.triangles) > 0
