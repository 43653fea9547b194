"""Hostile and mistaken scene files, as a user (or an attacker) would hand them to the
command line: each is refused in one line with exit 1, within seconds and a few hundred
MB, before anything large is built (docs/limits.md). And the inputs that look odd but
are valid (a Latin-1 comment in an OBJ) render."""
from __future__ import annotations

import io
import json
import os
import re
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli
from clrays.scene.limits import (MAX_ALIAS_NODES, MAX_COORDINATE, MAX_LIGHTS, MAX_MESH_BYTES, MAX_NESTING,
                                 MAX_NUMBER_DIGITS, MAX_OBJECTS, MAX_SCENE_BYTES, MAX_TRIANGLES)
from clrays.scene.textures import MAX_SCENE_TEXTURE_TEXELS

REPO = Path(__file__).resolve().parents[2]
SECONDS = 10  # each case, through the whole command line
PEAK_MB = 500

HEAD = """\
version: 1
image: {width: 32, height: 18, spp: 1}
camera: {position: [0, 2, 20], look_at: [0, 0, 0], far: 40}
lights: [{type: point, position: [0, 8, 0], intensity: 100}]
medium: {sigma_s: 0.05}
"""


def alias_bomb(levels: int, merge: bool = False) -> str:
    """The "billion laughs": each anchor repeats the one before nine times (9^levels values
    from a few hundred bytes). `merge` builds it from `<<` merge keys instead."""
    if merge:
        lines = ["a0: &a0 {x: 1}"] + [
            f"a{i}: &a{i} {{<<: [{', '.join([f'*a{i - 1}'] * 9)}], y{i}: 1}}" for i in range(1, levels + 1)]
    else:
        lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]'] + [
            f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, levels + 1)]
    return "version: 1\n" + "\n".join(lines) + "\n"


def set_bomb(levels: int) -> str:
    """An alias bomb in one `--set` value."""
    anchors = ["&a0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"] + [
        f"&a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, levels + 1)]
    return f"render.steps=[{', '.join(anchors)}]"


def big_inline_scene(path: Path, triangles: int = 333_000) -> None:
    """The 50 MB scene of the probe: every triangle written out in the YAML."""
    vertex = "      - [0.123456, 1.234567, 2.345678]\n"
    with open(path, "w") as f:
        f.write(HEAD + "objects:\n  - type: triangles\n    vertices:\n")
        f.write(vertex * (3 * triangles))
        f.write("    faces:\n" + "      - [0, 1, 2]\n" * triangles)


def lights(count: int) -> str:
    rows = "".join(f"  - {{type: point, position: [{i * 0.1 - 10:.2f}, 8, 0], intensity: 10}}\n"
                   for i in range(count))
    return HEAD.replace("lights: [{type: point, position: [0, 8, 0], intensity: 100}]\n", "lights:\n" + rows)


def objects(count: int) -> str:
    return HEAD + "objects:\n" + "  - {type: box, min: [-1, 0, -1], max: [1, 1, 1]}\n" * count


def sparse(path: Path, size: int) -> None:
    """A file of `size` bytes that takes no disk space."""
    with open(path, "wb") as f:
        f.truncate(size)


def write(tmp_path: Path, text: str, name: str = "scene.yaml") -> Path:
    (tmp_path / name).write_text(text)
    return tmp_path / name


def stl(path: Path, triangles: int, claimed: int | None = None, extra: bytes = b"") -> Path:
    """A binary STL of `triangles` triangles (a fan over the floor) whose header says `claimed`."""
    records = b""
    for i in range(triangles):
        corners = np.array([[-2 + i, 0, -2], [2 + i, 0, -2], [i, 1, 2]], np.float32)
        records += struct.pack("<3f", 0, 1, 0) + corners.tobytes() + b"\0\0"
    path.write_bytes(bytes(80) + struct.pack("<I", triangles if claimed is None else claimed) + records + extra)
    return path


def png_claiming(path: Path, width: int, height: int) -> Path:
    """A PNG whose header says width × height RGBA texels, with a token of data: the size
    must be refused from the header, before anything is decoded (a real 13000² PNG of
    zeros is 657 KB, and writing one would take 676 MB here)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(b"\0" * 1000)) + chunk(b"IEND", b""))
    return path


def exr_claiming(path: Path, width: int, height: int) -> Path:
    """A 4 × 4 EXR whose header's windows say width × height (the probe's was a 548 KB 16k² file)."""
    import OpenEXR

    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"RGB": np.zeros((4, 4, 3), np.float32)}) as exr:
        exr.write(str(path))
    data = bytearray(path.read_bytes())
    for name in (b"dataWindow\0box2i\0", b"displayWindow\0box2i\0"):
        at = data.index(name) + len(name) + 4
        data[at:at + 16] = struct.pack("<4i", 0, 0, width - 1, height - 1)
    path.write_bytes(bytes(data))
    return path


def exr_hiding(path: Path, kind: str) -> Path:
    """A 4 × 4 RGB EXR that decodes to far more than its data window shows: a second part
    of 2000 × 3000 (`parts`), or 64 channels beside R, G, B (`channels`)."""
    import OpenEXR

    def header():  # one each: OpenEXR writes the part's data window into it; one display window for both
        return {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
                "displayWindow": (np.array([0, 0], np.int32), np.array([1999, 2999], np.int32))}

    small = {"RGB": np.zeros((4, 4, 3), np.float32)}
    if kind == "parts":
        with OpenEXR.File([OpenEXR.Part(header(), small, "shown"),
                           OpenEXR.Part(header(), {"Z": np.zeros((3000, 2000), np.float32)}, "hidden")]) as exr:
            exr.write(str(path))
    else:
        with OpenEXR.File(header(), {**small, **{f"extra{i}": np.zeros((4, 4), np.float32) for i in range(64)}}) as exr:
            exr.write(str(path))
    return path


def npy_claiming(path: Path, shape: tuple) -> Path:
    """A .npy of a few hundred bytes whose header claims `shape` float64 values."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": shape})
    path.write_bytes(header.getvalue() + bytes(72))
    return path


RELIEF = ("objects: [{type: relief, center: [0, 0, 0], normal: [0, 1, 0], up: [0, 0, -1], size: [4, 4], "
          "height: 1, depth_map: depth.npy}]\n")


def relief(d: Path, depth_map: str = "depth.npy", **keys) -> Path:
    """A scene of one relief over an 8 × 8 depth map, its keys replaced by `keys`."""
    np.save(d / "depth.npy", np.random.default_rng(0).random((8, 8)))
    text = RELIEF.replace("depth.npy", depth_map)
    for key, value in keys.items():
        text = re.sub(rf"{key}: (\[[^]]*\]|[^,}}]+)", f"{key}: {value}", text, count=1) if f"{key}:" in text \
            else text.replace("}]", f", {key}: {value}}}]")
    return write(d, HEAD + text)


def gobo_light(texture: str, intensity: str = "100") -> str:
    return HEAD.replace("lights: [{type: point, position: [0, 8, 0], intensity: 100}]",
                        f"lights: [{{type: spot, position: [0, 8, 0], direction: [0, -1, 0], cone_deg: 30, "
                        f"intensity: {intensity}, texture: {texture}}}]")


def image_named_png(d: Path, name: str, form: str) -> Path:
    """An image of another format (JPEG, GIF, a float TIFF of NaN) named .png."""
    from PIL import Image

    if form == "TIFF":
        Image.fromarray(np.full((16, 16), np.nan, np.float32)).save(d / name, format="TIFF")
    else:
        pixels = (np.random.default_rng(1).random((16, 16, 3)) * 255).astype(np.uint8)
        Image.fromarray(pixels).save(d / name, format=form)
    return d / name


def obj_fan(path: Path, corners: int) -> Path:
    """An OBJ of three vertices and one face line of `corners` corners: a fan of corners - 2 triangles."""
    with open(path, "wb") as f:
        f.write(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf ")
        f.write(b"1 2 3 " * (corners // 3) + b"\n")
    return path


# (case id, how to build it in a folder: -> (scene path, extra CLI args), the error's pattern)
CASES = [
    ("alias bomb", lambda d: (write(d, alias_bomb(9)), []),
     rf"scene\.yaml:\d+:\d+: a\d[\d.]*: expected aliases that copy at most {MAX_ALIAS_NODES} values"),
    ("alias bomb, 7 levels, before its unknown keys", lambda d: (write(d, alias_bomb(7)), []),
     rf"expected aliases that copy at most {MAX_ALIAS_NODES} values in all, got more"),
    ("merge-key bomb", lambda d: (write(d, alias_bomb(9, merge=True)), []),
     rf"expected aliases that copy at most {MAX_ALIAS_NODES} values in all, got more"),
    ("alias bomb in --set", lambda d: (write(d, HEAD), ["--set", set_bomb(8)]),
     rf"--set render\.steps=\[&a0 .*: render\.steps[\d.]*: expected aliases that copy at most {MAX_ALIAS_NODES}"),
    ("aliases nesting deeper than the text", lambda d: (write(d, "version: 1\na0: &a0 [1]\n" + "".join(
        f"a{i}: &a{i} [*a{i - 1}]\n" for i in range(1, 100))), []),
     rf"expected at most {MAX_NESTING} levels of nesting, got more through aliases"),
    ("/dev/zero", lambda d: (Path("/dev/zero"), []),
     r"^clrays: error: /dev/zero: cannot read scene file: not a regular file \(a character device\)$"),
    ("FIFO", lambda d: (os.mkfifo(d / "fifo.yaml") or d / "fifo.yaml", []),
     r"fifo\.yaml: cannot read scene file: not a regular file \(a FIFO\)$"),
    ("100k nesting, flow", lambda d: (write(d, "version: 1\nx: " + "[" * 100_000 + "]" * 100_000 + "\n"), []),
     rf"scene\.yaml:2:{MAX_NESTING + 3}: \(top level\): expected at most {MAX_NESTING} levels of nesting, got more$"),
    ("100k nesting after quoted brackets",
     lambda d: (write(d, 'version: 1\nx: ["[[[[[[[[", ' + "[" * 100_000 + "]" * 100_000 + "]\n"), []),
     rf"scene\.yaml:2:{MAX_NESTING + 15}: \(top level\): expected at most {MAX_NESTING} levels of nesting, got more$"),
    ("100k nesting, block", lambda d: (write(d, "version: 1\nx:\n" + "- " * 100_000 + "1\n"), []),
     rf"expected at most {MAX_NESTING} levels of nesting, got more$"),
    ("100k nesting in --set", lambda d: (write(d, HEAD), ["--set", "render.steps=" + "[" * 100_000]),
     rf"--set render\.steps=\[\[\[+\.\.\.: render\.steps: expected at most {MAX_NESTING} levels of nesting"),
    ("100k-key --set path", lambda d: (write(d, HEAD), ["--set", "render" + ".x" * 100_000 + "=1"]),
     rf"--set render\.x\.x[.x]*\.\.\.: expected a key path of at most {MAX_NESTING} keys, got 100001$"),
    ("5000-digit integer", lambda d: (write(d, HEAD.replace("spp: 1", "spp: " + "1" * 5000)), []),
     rf"scene\.yaml:2:37: image\.spp: expected a number of at most {MAX_NUMBER_DIGITS} digits, got one of 5000$"),
    ("5000-digit hex integer", lambda d: (write(d, HEAD.replace("spp: 1", "spp: 0x" + "f" * 5000)), []),
     rf"image\.spp: expected a number of at most {MAX_NUMBER_DIGITS} digits, got one of 5002$"),
    ("5000-digit float", lambda d: (write(d, HEAD.replace("far: 40", "far: 4" + "0" * 5000 + ".5")), []),
     rf"camera\.far: expected a number of at most {MAX_NUMBER_DIGITS} digits"),
    ("5000-digit integer in --set", lambda d: (write(d, HEAD), ["--set", "image.spp=" + "9" * 5000]),
     rf"image\.spp: expected a number of at most {MAX_NUMBER_DIGITS} digits, got one of 5000$"),
    ("base-60 integer", lambda d: (write(d, HEAD.replace("spp: 1", "spp: 1:30")), []),
     r"scene\.yaml:2:37: image\.spp: expected an integer in \[1, 4096\], got '1:30' \(a number in YAML 1\.1 only: clrays reads YAML 1\.2's, without `_`, `0b` or base 60\)$"),
    ("base-60 float", lambda d: (write(d, HEAD.replace("far: 40", "far: 1:30.5")), []),
     r"camera\.far: expected a number > 0, got '1:30.5' \(a number in YAML 1\.1 only: clrays reads YAML 1\.2's, without `_`, `0b` or base 60\)$"),
    ("base-60 with a tag", lambda d: (write(d, HEAD.replace("spp: 1", "spp: !!int 1:30")), []),
     r"image\.spp: expected a number, got '1:30' \(YAML 1\.1 base-60 numbers are not read\)$"),
    ("tagged non-number", lambda d: (write(d, HEAD.replace("spp: 1", "spp: !!int abc")), []),
     r"image\.spp: expected a value that int can read, got 'abc'"),
    ("the 50 MB scene of inline triangles", lambda d: (big_inline_scene(d / "big.yaml") or d / "big.yaml", []),
     rf"big\.yaml: cannot read scene file: 4\d\.\d MiB, more than the limit of {MAX_SCENE_BYTES >> 20}\.0 MiB; "
     r"put large geometry in a mesh file"),
    ("257 lights", lambda d: (write(d, lights(MAX_LIGHTS + 1)), []),
     rf"scene\.yaml:5:3: lights: expected at most {MAX_LIGHTS} lights .*, got {MAX_LIGHTS + 1} lights$"),
    ("shadow maps past the views' int offsets", lambda d: (write(d, lights(6)), ["--set", "render.shadow_map=8192"]),
     r"scene\.yaml: the shadow maps of lights 0 to 5 at render\.shadow_map 8192 need more than 2147483647 texels"),
    ("too many objects", lambda d: (write(d, objects(MAX_OBJECTS + 1)), []),
     rf"scene\.yaml:7:3: objects: expected at most {MAX_OBJECTS} objects .*, got {MAX_OBJECTS + 1} objects$"),
    ("mesh file that is a FIFO", lambda d: (os.mkfifo(d / "m.obj") or write(
        d, HEAD + "objects: [{type: mesh, file: m.obj}]\n"), []),
     r"objects\.0\.file: expected a readable mesh file .*not a regular file \(a FIFO\)"),
    ("mesh file over the size limit", lambda d: (sparse(d / "m.stl", MAX_MESH_BYTES + 1) or write(
        d, HEAD + "objects: [{type: mesh, file: m.stl}]\n"), []),
     rf"objects\.0\.file: expected a readable mesh file .*more than the limit of {MAX_MESH_BYTES >> 20}\.0 MiB"),
    # Sizes counted from image headers, .npy headers and face lines, before decoding.
    ("a 13000² PNG as a depth map", lambda d: (png_claiming(d / "big.png", 13000, 13000) and relief(d, "big.png"), []),
     rf"objects\.0\.depth_map: expected at most {MAX_TRIANGLES} triangles \(two per cell of four texels\), got "
     r"'big\.png' \(13000 × 13000 texels: 337948002 triangles\)$"),
    ("a 30000² PNG as a depth map (PIL's bomb error)",
     lambda d: (png_claiming(d / "huge.png", 30000, 30000) and relief(d, "huge.png"), []),
     rf"objects\.0\.depth_map: expected at most {MAX_TRIANGLES} triangles .*30000 × 30000 texels"),
    ("a 30000² PNG as a gobo", lambda d: (png_claiming(d / "huge.png", 30000, 30000) and write(
        d, gobo_light("huge.png")), []),
     r"lights\.0\.texture: .*'huge\.png': an image of 30000×30000 texels, not sides in \[1, 4096\]"),
    ("a 16k² EXR as a depth map", lambda d: (exr_claiming(d / "big.exr", 16384, 16384) and relief(d, "big.exr"), []),
     rf"objects\.0\.depth_map: expected at most {MAX_TRIANGLES} triangles .*16384 × 16384 texels"),
    ("a two-part EXR as a gobo", lambda d: (exr_hiding(d / "p.exr", "parts") and write(d, gobo_light("p.exr")), []),
     r"lights\.0\.texture: .*an EXR of 2 parts, not one image"),
    ("an EXR of 67 channels as a depth map", lambda d: (exr_hiding(d / "c.exr", "channels") and relief(d, "c.exr"), []),
     r"objects\.0\.depth_map: .*an EXR of 67 channels, not an image of at most 4"),
    ("a 16k² EXR as a gobo", lambda d: (exr_claiming(d / "big.exr", 16384, 16384) and write(
        d, gobo_light("big.exr")), []),
     r"lights\.0\.texture: .*'big\.exr': an image of 16384×16384 texels, not sides in \[1, 4096\]"),
    ("a 200-byte .npy claiming 4.9e9 elements as a gobo",
     lambda d: (npy_claiming(d / "claim.npy", (70000, 70000)) and write(d, gobo_light("claim.npy")), []),
     r"lights\.0\.texture: .*'claim\.npy': a \.npy header that claims 70000 × 70000 of float64 \(3\.92e\+10 "
     r"bytes\), but the file holds 72 bytes after it"),
    ("a .npy claiming 4.9e9 elements as a depth map",
     lambda d: (npy_claiming(d / "claim.npy", (70000, 70000)) and relief(d, "claim.npy"), []),
     r"objects\.0\.depth_map: .*a \.npy header that claims 70000 × 70000 of float64"),
    ("a 22 MB OBJ whose one face fans out to 11 M triangles",
     lambda d: (obj_fan(d / "fan.obj", 11_100_000) and write(d, HEAD + "objects: [{type: mesh, file: fan.obj}]\n"), []),
     rf"objects\.0\.file: expected at most {MAX_TRIANGLES} triangles in the whole scene .*, got 'fan\.obj' "
     r"\(11099998 triangles in its faces\)$"),
    ("six 4096² faces of one gobo as a point light's cube", lambda d: (
        png_claiming(d / "gobo.png", 4096, 4096) and write(d, HEAD.replace(
            "intensity: 100}", "intensity: 100, texture: [" + ", ".join(["gobo.png"] * 6) + "]}")), []),
     rf"lights\.0\.texture\.0: .*a texture of 100663296 texels from an image of 4096×4096, more than the "
     rf"{MAX_SCENE_TEXTURE_TEXELS} left"),
    # Values finite in float64 that overflow float32.
    ("a mesh vertex at 1e39", lambda d: (
        (d / "far.obj").write_text("v 0 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n")
        and write(d, HEAD + "objects: [{type: mesh, file: far.obj}]\n"), []),
     re.escape(f"objects.0: expected vertices within ±{MAX_COORDINATE:g} (scene units; float32 on the device "
               f"overflows beyond), got 1e+39") + "$"),
    ("scale: 1e300", lambda d: (write(d, HEAD + "objects: [{type: box, min: [-1, 0, -1], max: [1, 1, 1], "
                                         "transform: {scale: 1e300}}]\n"), []),
     r"objects\.0\.transform: expected vertices \(after the transform\) within ±1e\+12 .*, got 1e\+300$"),
    ("relief height: 1e300", lambda d: (relief(d, height="1e300"), []),
     r"objects\.0\.height: expected a height within ±1e\+12 .*, got 1e\+300$"),
    ("relief size: [1e300, 1e300]", lambda d: (relief(d, size="[1e300, 1e300]"), []),
     r"objects\.0\.size: expected sizes within ±1e\+12 .*, got \[1e\+300, 1e\+300\]$"),
    ("relief center: [1e30, 0, 0]", lambda d: (relief(d, center="[1e30, 0, 0]"), []),
     r"objects\.0\.center: expected a point within ±1e\+12 .*, got \[1e\+30, 0, 0\]$"),
    ("relief depth_map of 1e30",
     lambda d: (np.save(d / "tall.npy", np.full((8, 8), 1e30)) or relief(d, "tall.npy"), []),
     r"objects\.0: expected vertices within ±1e\+12 .*, got 1e\+30$"),
    ("relief albedo_map of 1e6", lambda d: (np.save(d / "a.npy", np.full((8, 8, 3), 1e6)) or relief(
        d, albedo_map="a.npy"), []),
     r"objects\.0\.albedo_map: expected albedo texels in \[0, 1\], as albedo's, got 'a\.npy' \(1e\+06 at texel "
     r"\(x=0, y=0\), 64 outside in all\)$"),
    ("relief albedo_map of -1000", lambda d: (np.save(d / "a.npy", np.full((8, 8), -1000.0)) or relief(
        d, albedo_map="a.npy"), []),
     r"objects\.0\.albedo_map: expected albedo texels in \[0, 1\], .*\(-1000 at texel"),
    ("an animated translate of 1e39", lambda d: (write(
        d, HEAD + "objects: [{type: box, min: [-1, 0, -1], max: [1, 1, 1]}]\nanimation: {frames: [0, 2], objects: "
        "[{object: 0, keys: [{frame: 0, translate: [0, 0, 0]}, {frame: 2, translate: [1e39, 0, 0]}]}]}\n"), []),
     r"animation\.objects\.0\.keys\.1\.translate: expected a translation of length at most 5e\+11 .*, got "
     r"\[1e\+39, 0, 0\]$"),
    ("an animated scale that takes the vertices past 1e12", lambda d: (write(
        d, HEAD + "objects: [{type: box, min: [-1, 0, -1], max: [1, 1, 1]}]\nanimation: {frames: [0, 2], objects: "
        "[{object: 0, keys: [{frame: 0, scale: 1}, {frame: 2, scale: 1e300}]}]}\n"), []),
     r"animation\.objects\.0\.keys\.1\.scale: expected a scale of at most .* for this object"),
    ("a camera at 1e39", lambda d: (write(d, HEAD.replace("position: [0, 2, 20]", "position: [0, 2, 1e39]")), []),
     r"camera\.position: expected a point within ±1e\+12 .*, got \[0, 2, 1e\+39\]$"),
    ("a 2e37 texel at intensity 1e30", lambda d: (np.save(d / "hot.npy", np.full((4, 4, 3), 2e37, np.float32)) or write(
        d, gobo_light("hot.npy", "1e30")), []),
     r"lights\.0\.intensity: expected a power whose product with the brightest texel \(2e\+37\) is at most 1e\+30 "
     r".*, got 1e\+30$"),
    ("a directional texture_size of 1e-6 with exact", lambda d: (np.save(d / "t.npy", np.ones((4, 4))) or write(
        d, HEAD.replace("lights: [{type: point, position: [0, 8, 0], intensity: 100}]",
                        "lights: [{type: directional, direction: [0.3, -1, 0.2], irradiance: 2, texture: t.npy, "
                        "texture_size: [1e-6, 1e-6]}]") + "objects: [{type: plane, center: [0, 0, 0], normal: [0, 1, 0], "
                                                          "size: 20}]\n"), ["--method", "exact"]),
     r"^clrays: error: exact: the rays cross about [\d.]+e\+\d+ texel centres of a light's texture, more than the "
     r"8388608 that exact integrates piece by piece .*; use a larger texture_size or another method$"),
    # Image files with another format's content.
    ("a JPEG named .png as a depth map", lambda d: (image_named_png(d, "j.png", "JPEG") and relief(d, "j.png"), []),
     r"objects\.0\.depth_map: expected a readable 2D image .*\(a JPEG image named \.png: "),
    ("a GIF named .png as a depth map", lambda d: (image_named_png(d, "g.png", "GIF") and relief(d, "g.png"), []),
     r"objects\.0\.depth_map: expected a readable 2D image .*\(a GIF image named \.png: "),
    ("a NaN TIFF named .png as a depth map", lambda d: (image_named_png(d, "t.png", "TIFF") and relief(d, "t.png"), []),
     r"objects\.0\.depth_map: expected a readable 2D image .*\(a TIFF image named \.png: "),
    ("a NaN TIFF named .png as a gobo", lambda d: (image_named_png(d, "t.png", "TIFF") and write(d, gobo_light("t.png")), []),
     r"lights\.0\.texture: .*'t\.png': a TIFF image named \.png"),
    ("a NaN .npy as a depth map", lambda d: (np.save(d / "n.npy", np.full((8, 8), np.nan)) or relief(d, "n.npy"), []),
     r"objects\.0\.depth_map: .*the image has non-finite values \(nan at texel \(x=0, y=0\), 64 in all\)"),
    ("a binary STL cut within a triangle", lambda d: (stl(d / "cut.stl", 2, claimed=1000, extra=b"xx") and write(
        d, HEAD + "objects: [{type: mesh, file: cut.stl}]\n"), []),
     r"objects\.0\.file: expected a readable mesh file .*not a valid STL file \(a binary STL is 84 bytes and 50 a "
     r"triangle; this one has 186 bytes, and its header says 1000 triangles\)"),
    ("an unknown render pass", lambda d: (write(d, HEAD), ["--aov", "in_scatter,fog"]),
     r"^clrays: error: --aov: expected one of in_scatter, transmittance, surface, depth or in_scatter_light<i>, "
     r"got 'fog'$"),
    ("a render pass of a light the scene lacks", lambda d: (write(d, HEAD + "render: {aovs: [in_scatter_light1]}\n"), []),
     r"scene\.yaml:\d+:\d+: render\.aovs\.0: expected in_scatter_light<i> with i below the scene's 1 light\(s\), "
     r"got 'in_scatter_light1'$"),
    ("a render pass twice", lambda d: (write(d, HEAD), ["--aov", "depth,depth"]),
     r"render\.aovs\.1: expected each pass once, got 'depth' twice$"),
    ("render passes as a string", lambda d: (write(d, HEAD), ["--set", "render.aovs=depth"]),
     r"render\.aovs: expected a list of pass names, got 'depth'$"),
    ("render passes with translucent objects", lambda d: (write(
        d, HEAD + "objects: [{type: box, min: [0, 0, 0], max: [1, 1, 1], opacity: 0.5}]\n"), ["--aov", "depth"]),
     r"render\.aovs: expected no render passes in a scene with translucent objects \(opacity below 1\), got depth$"),
    # last: it builds two million triangles before it is refused, and the peak only grows
    ("4096 spheres of a million triangles each", lambda d: (write(d, HEAD + "objects:\n" + (
        "  - {type: sphere, center: [0, 0, 0], radius: 1, segments: 1024}\n" * MAX_OBJECTS)), []),
     rf"scene\.yaml:9:5: objects\.2: expected at most {MAX_TRIANGLES} triangles in the whole scene .*, "
     rf"got 3139584 with objects 0 to 2$"),
]


@pytest.mark.parametrize("build, pattern", [case[1:] for case in CASES], ids=[case[0] for case in CASES])
def test_refused_in_one_line(tmp_path, build, pattern):
    scene, extra = build(tmp_path)
    start = time.perf_counter()
    code, output = run_cli("render", scene, "-o", tmp_path / "out.png", *extra)
    seconds = time.perf_counter() - start
    lines = output.strip().splitlines()
    assert code == 1 and len(lines) == 1, output[:2000]
    assert lines[0].startswith("clrays: error: "), lines[0][:300]
    assert re.search(pattern, lines[0]), lines[0][:600]
    assert len(lines[0]) < 700, "a message should show a value, not all of it"
    assert seconds < SECONDS, f"{seconds:.1f} s"
    assert not (tmp_path / "out.png").exists()


_PEAK_SCRIPT = """
import json, resource, sys, time
from click.testing import CliRunner
from clrays.cli import main

def peak_mb():
    # VmHWM: this process's own high-water mark. ru_maxrss would also count the pytest
    # process this one was forked from (Linux carries it across exec).
    try:
        with open("/proc/self/status") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:")) / 1024
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

results = []
for name, args in json.loads(open(sys.argv[1]).read()):
    start = time.perf_counter()
    result = CliRunner().invoke(main, args)
    results.append([name, result.exit_code, time.perf_counter() - start, peak_mb()])
print(json.dumps(results))
"""


def test_peak_memory_of_the_refusals(tmp_path):
    """All the cases, one after another in a fresh process: its peak resident memory (which
    only grows) stays under PEAK_MB after each, and each takes under SECONDS."""
    runs = []
    for index, (name, build, _) in enumerate(CASES):
        folder = tmp_path / str(index)
        folder.mkdir()
        scene, extra = build(folder)
        runs.append([name, ["render", str(scene), "-o", str(folder / "out.png"), *extra]])
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    (tmp_path / "runs.json").write_text(json.dumps(runs))  # one argument may hold at most 128 KiB
    done = subprocess.run([sys.executable, "-c", _PEAK_SCRIPT, str(tmp_path / "runs.json")], capture_output=True,
                          text=True, env=env, timeout=len(CASES) * SECONDS, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    results = json.loads(done.stdout.strip().splitlines()[-1])
    report = "\n".join(f"  {name}: exit {code}, {seconds:.2f} s, peak {peak:.0f} MB"
                       for name, code, seconds, peak in results)
    print("\n" + report)
    for name, code, seconds, peak in results:
        assert code == 1, report
        assert seconds < SECONDS, report
        assert peak < PEAK_MB, report


def test_directory_and_missing_file_refused(tmp_path):
    """(The command line refuses a directory itself, as a usage error.)"""
    from clrays.errors import SceneError
    from clrays.scene.load import load_scene

    with pytest.raises(SceneError, match=r": cannot read scene file: not a regular file \(a directory\)$"):
        load_scene(tmp_path)
    with pytest.raises(SceneError, match=r"nope\.yaml: cannot read scene file: No such file or directory$"):
        load_scene(tmp_path / "nope.yaml")


def test_latin1_obj_renders(tmp_path):
    """An OBJ from an older exporter, with a Latin-1 comment, renders (it used to need
    trimesh's optional charset detector)."""
    (tmp_path / "latin1.obj").write_bytes("# modèle exporté en Latin-1\nv -2 0 -2\nv 2 0 -2\nv 0 0 2\n"
                                          "f 1 3 2\n".encode("latin-1"))
    scene = write(tmp_path, HEAD + "objects: [{type: mesh, file: latin1.obj}]\n")
    code, output = run_cli("render", scene, "-o", tmp_path / "out.png")
    assert code == 0, output
    assert (tmp_path / "out.png").stat().st_size > 0


def test_just_under_the_limits_loads(tmp_path):
    """The caps sit above what a scene needs: the most lights and objects, aliases, a
    21-digit number, all load."""
    from clrays.scene.load import load_scene

    text = lights(MAX_LIGHTS).replace("far: 40", "far: 40.0000000000000000000") + "objects:\n" + "  - &box {type: box, min: [-1, 0, -1], max: [1, 1, 1]}\n" + \
        "  - *box\n" * (MAX_OBJECTS - 1)
    scene = load_scene(write(tmp_path, text))
    assert len(scene.lights) == MAX_LIGHTS and len(scene.geometry.triangles) == 12 * MAX_OBJECTS
    assert scene.camera.far == 40.0


def _fresh_process(tmp_path: Path, runs: list) -> list:
    """[name, exit code, seconds, peak MB] of each run of `runs` ([name, CLI args]), one after
    another in a fresh process (_PEAK_SCRIPT)."""
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    (tmp_path / "runs.json").write_text(json.dumps(runs))
    done = subprocess.run([sys.executable, "-c", _PEAK_SCRIPT, str(tmp_path / "runs.json")], capture_output=True,
                          text=True, env=env, timeout=120, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def sixteen_gobo_lights(d: Path) -> Path:
    """16 spot lights sharing one 4096² PNG gobo (a grid of lines: 27 KB)."""
    from PIL import Image

    pixels = np.zeros((4096, 4096), np.uint8)
    pixels[::64], pixels[:, ::64] = 255, 255
    Image.fromarray(pixels).save(d / "gobo.png")
    rows = "".join(f"  - {{type: spot, position: [{i * 0.5 - 4:.1f}, 8, 0], direction: [0, -1, 0], cone_deg: 30, "
                   f"intensity: 50, texture: gobo.png}}\n" for i in range(16))
    return write(d, HEAD.replace("lights: [{type: point, position: [0, 8, 0], intensity: 100}]\n", "lights:\n" + rows)
                 + "objects: [{type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 20}]\n")


def test_lights_sharing_a_texture_share_its_texels(tmp_path):
    """The file is decoded once and the lights hold one array, which the device holds once."""
    from clrays.scene.load import load_scene
    from clrays.physics.light_texture import pack_light_textures

    scene = load_scene(sixteen_gobo_lights(tmp_path))
    first = scene.lights[0].texture.texels
    assert first.shape == (4096, 4096, 3)
    assert all(light.texture.texels is first for light in scene.lights)
    entries, texels = pack_light_textures(scene, np.zeros(3))
    assert len(texels) == 4096 * 4096 and set(entries["first_texel"]) == {0}
    np.testing.assert_array_equal(texels[:4096, :3], first[0])


def test_valid_renders_stay_small(tmp_path):
    """What the probe found taking gigabytes renders under 2 GB, in a fresh process: 16 spot
    lights sharing a 4096² gobo (7.4 GB, then a MemoryError) and a binary STL whose header
    count lies (refused for want of an optional module)."""
    (tmp_path / "gobo").mkdir()
    (tmp_path / "stl").mkdir()
    gobos = sixteen_gobo_lights(tmp_path / "gobo")
    stl(tmp_path / "stl" / "lie.stl", 2, claimed=1000)
    lying = write(tmp_path / "stl", HEAD + "objects: [{type: mesh, file: lie.stl}]\n")
    results = _fresh_process(tmp_path, [
        ["16 lights sharing a 4096² gobo", ["render", str(gobos), "-o", str(tmp_path / "gobo.png")]],
        ["a binary STL whose count lies", ["render", str(lying), "-o", str(tmp_path / "stl.png")]]])
    report = "\n".join(f"  {name}: exit {code}, {seconds:.2f} s, peak {peak:.0f} MB"
                       for name, code, seconds, peak in results)
    print("\n" + report)
    for name, code, seconds, peak in results:
        assert code == 0 and peak < 2000 and seconds < 60, report
    assert (tmp_path / "gobo.png").stat().st_size > 0 and (tmp_path / "stl.png").stat().st_size > 0


def test_a_lying_stl_count_reads_the_triangles_the_file_holds(tmp_path):
    from clrays.scene.geometry import load_mesh

    triangles = load_mesh(stl(tmp_path / "lie.stl", 3, claimed=7))[0]
    assert len(triangles) == 3
    assert len(load_mesh(stl(tmp_path / "zero.stl", 3, claimed=0))[0]) == 3  # streaming writers leave 0


def test_obj_triangle_count_counts_fans_without_building_them():
    from clrays.scene.geometry import obj_triangle_count

    text = b"v 0 0 0\nf 1 2 3\nf 1  2 3 4\r\n\tf 1 2 3 4 5\nf\t1/1/1 2/2/2 3/3/3\n# f 1 2 3 4 5 6\nfoo 1 2 3\nf 1 2 3"
    assert obj_triangle_count(text) == 1 + 2 + 3 + 1 + 1
    assert obj_triangle_count(b"") == 0 and obj_triangle_count(b"v 0 0 0\n") == 0


def test_an_animated_power_times_the_brightest_texel_is_checked(tmp_path):
    from clrays.errors import SceneError
    from clrays.scene.load import load_scene

    np.save(tmp_path / "hot.npy", np.full((4, 4, 3), 2e20, np.float32))
    text = gobo_light("hot.npy", "1") + ("animation: {frames: [0, 2], lights: [{light: 0, keys: [{frame: 0, "
                                         "intensity: 1}, {frame: 2, intensity: 1e20}]}]}\n")
    with pytest.raises(SceneError, match=r"animation\.lights\.0\.keys\.1\.intensity: expected a power whose product "
                                         r"with the brightest texel \(2e\+20\) is at most 1e\+30 .*, got 1e\+20$"):
        load_scene(write(tmp_path, text))
