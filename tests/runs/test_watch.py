"""`clrays watch` (clrays/runs/watch.py): a render now and after each save, in one warm
session that reuses the stages an edit leaves alone; a bad edit prints one error line and
keeps the last image; an --also file's save renders too; Ctrl-C ends it in one line."""
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from conftest import run_cli
from clrays.runs.watch import watch
from clrays.scene.load import load_scene
from clrays.session import Renderer

REPO = Path(__file__).resolve().parents[2]
SCENE = """version: 1
image: {width: 24, height: 16}
camera: {position: [0, 2, 8], look_at: [0, 1, 0], fov_deg: 50, far: 30}
lights:
  - {type: point, position: [0, 4, 0], intensity: 30}
medium: {sigma_s: 0.05, sigma_a: 0.01}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 10, segments: 2}
  - {type: box, min: [-1, 2, -1], max: [1, 2.2, 1]}
render: {method: minmax, shadow_map: 64}
"""


def save(path: Path, text: str) -> None:
    """As an editor saves: a new file renamed over the old one."""
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(text)
    os.replace(temporary, path)


def wait_for(condition, seconds: float = 60.0) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


class Watching:
    """watch() in a thread, its lines collected, stopped on exit."""

    def __init__(self, scene: Path, output: Path, **options):
        self.lines: list[str] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=watch, args=(scene, output), daemon=True, kwargs=dict(
            interval=0.02, stop=self.stop, echo=self.lines.append, renderer=Renderer(), **options))

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(30)
        assert not self.thread.is_alive()


def test_two_saves_two_renders_and_one_error(tmp_path):
    scene, output = tmp_path / "scene.yaml", tmp_path / "out.npy"
    scene.write_text(SCENE)
    with Watching(scene, output) as watching:
        wait_for(lambda: len(watching.lines) >= 1)
        first = np.load(output)
        save(scene, SCENE.replace("sigma_s: 0.05", "sigma_s: 0.12"))  # a valid edit: the fog alone
        wait_for(lambda: len(watching.lines) >= 2)
        second = np.load(output)
        written = output.stat().st_mtime_ns
        save(scene, SCENE.replace("sigma_s: 0.05", "sigma_s: -1"))  # a bad one
        wait_for(lambda: len(watching.lines) >= 3)
        time.sleep(0.3)  # nothing more comes without another save
    lines = watching.lines
    assert len(lines) == 3, lines
    assert lines[0].startswith("render 1: ") and lines[1].startswith("render 2: ")
    assert " ms  reused: " in lines[1]
    reused = lines[1].split("reused: ")[1].split()
    assert "raster.camera" in reused and "raster.shadow" in reused and "rectify" in reused  # the fog changed only
    assert "integrand" not in reused
    assert lines[2].startswith("clrays: error: ") and "\n" not in lines[2]
    assert "medium.sigma_s" in lines[2] and "scene.yaml" in lines[2]
    assert output.stat().st_mtime_ns == written  # the bad edit left the last image
    assert not np.array_equal(first, second)
    # what render 2 wrote is the edited scene's image, reuse or not
    scene.write_text(SCENE.replace("sigma_s: 0.05", "sigma_s: 0.12"))
    np.testing.assert_array_equal(second, Renderer(reuse=False).render(load_scene(scene)).image)
    assert not list(tmp_path.glob(".*clrays-*"))  # no temporary left


def test_a_save_of_an_also_file_renders_again(tmp_path):
    scene, output, mesh = tmp_path / "scene.yaml", tmp_path / "out.png", tmp_path / "notes.txt"
    scene.write_text(SCENE)
    mesh.write_text("a")
    with Watching(scene, output, also=[mesh]) as watching:
        wait_for(lambda: len(watching.lines) >= 1)
        save(mesh, "ab")
        wait_for(lambda: len(watching.lines) >= 2)
    assert watching.lines[1].startswith("render 2: ")
    assert "shade" in watching.lines[1].split("reused: ")[1].split()  # the same frame: all of it kept


def test_command_line_max_renders(tmp_path):
    scene, output = tmp_path / "scene.yaml", tmp_path / "out.png"
    scene.write_text(SCENE)
    code, out = run_cli("watch", scene, "-o", output, "--max-renders", "1", "--aov", "depth")
    assert code == 0, out
    lines = out.strip().splitlines()
    assert lines[0].startswith("watching ") and lines[1].startswith("render 1: ") and len(lines) == 2, out
    assert output.exists() and (tmp_path / "out.depth.png").exists()


def test_ctrl_c_ends_it_in_one_line(tmp_path):
    scene, output = tmp_path / "scene.yaml", tmp_path / "out.png"
    scene.write_text(SCENE)
    process = subprocess.Popen([sys.executable, "-c", "from clrays.cli import main; main()", "watch", str(scene),
                                "-o", str(output)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        assert process.stdout.readline().startswith("watching ")
        assert process.stdout.readline().startswith("render 1: ")
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=30)
    finally:
        process.kill()
    assert process.returncode == 130
    assert out == "" and err.strip().splitlines() == ["clrays: interrupted: watch stopped after 1 render(s), 0 error(s)"]


def test_confine_refuses_a_file_outside_the_scenes_folder(tmp_path):
    """`watch --confine`, as every command that loads a scene: a mesh named outside the
    scene's folder is the edit's one error line, and the watch waits for the next save."""
    folder = tmp_path / "scenes"
    folder.mkdir()
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene = folder / "scene.yaml"
    scene.write_text(SCENE.replace("objects:\n", "objects:\n  - {type: mesh, file: ../m.obj}\n"))
    process = subprocess.Popen([sys.executable, "-c", "from clrays.cli import main; main()", "watch", str(scene),
                                "-o", str(tmp_path / "out.png"), "--confine"], cwd=REPO, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        assert process.stdout.readline().startswith("watching ")
        error = process.stderr.readline()
        process.send_signal(signal.SIGINT)
        process.communicate(timeout=30)
    finally:
        process.kill()
    assert error.startswith("clrays: error: ") and "objects.0.file" in error and "outside the scene's folder" in error
    assert not (tmp_path / "out.png").exists()
