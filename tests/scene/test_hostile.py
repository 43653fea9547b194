"""Hostile and mistaken scene files, as a user (or an attacker) would hand them to the
command line: each is refused in one line with exit 1, within seconds and a few hundred
MB, before anything large is built (docs/limits.md). And the inputs that look odd but
are valid (a Latin-1 comment in an OBJ) render."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import run_cli
from clrays.scene.limits import (MAX_ALIAS_NODES, MAX_LIGHTS, MAX_MESH_BYTES, MAX_NESTING, MAX_NUMBER_DIGITS,
                                 MAX_OBJECTS, MAX_SCENE_BYTES, MAX_TRIANGLES)

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
     r"scene\.yaml:2:37: image\.spp: expected an integer in \[1, 4096\], got '1:30'$"),
    ("base-60 float", lambda d: (write(d, HEAD.replace("far: 40", "far: 1:30.5")), []),
     r"camera\.far: expected a number > 0, got '1:30.5'$"),
    ("base-60 with a tag", lambda d: (write(d, HEAD.replace("spp: 1", "spp: !!int 1:30")), []),
     r"image\.spp: expected a number, got '1:30' \(YAML 1\.1 base-60 numbers are not read\)$"),
    ("tagged non-number", lambda d: (write(d, HEAD.replace("spp: 1", "spp: !!int abc")), []),
     r"image\.spp: expected a value that int can read, got 'abc'"),
    ("the 50 MB scene of inline triangles", lambda d: (big_inline_scene(d / "big.yaml") or d / "big.yaml", []),
     rf"big\.yaml: cannot read scene file: 4\d\.\d MiB, more than the limit of {MAX_SCENE_BYTES >> 20}\.0 MiB; "
     r"put large geometry in a mesh file"),
    ("201 lights", lambda d: (write(d, lights(201)), []),
     rf"scene\.yaml:5:3: lights: expected at most {MAX_LIGHTS} lights .*, got 201 lights$"),
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
