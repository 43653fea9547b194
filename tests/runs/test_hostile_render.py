"""What a hostile or careless user can do to a render and its output, and what clrays
answers: the same image whatever `camera.far` in a closed room, one-line errors for bad
options and unwritable outputs, no stale frames or temp files left behind."""
import os
import re
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from clrays import load_scene
from clrays.errors import OutputError
from clrays.physics.radiometry import effective_far, lamp_radius
from conftest import TEST_ON_POCL
from conftest import run_cli as run

# A closed room: every camera ray hits a wall, so camera.far bounds nothing.
ROOM = """version: 1
image: {width: 32, height: 24}
camera: {position: [0, 1.5, 3.5], look_at: [0, 1.5, 0], fov_deg: 60, far: 40}
lights:
  - {type: point, position: [0.5, 3.2, 0.0], intensity: 20}
  - {type: spot, position: [-2, 3.5, -2], direction: [0.3, -1, 0.3], cone_deg: 30, intensity: 40}
medium: {sigma_s: 0.1, sigma_a: 0.02}
objects:
  - {type: box, min: [-4, 0, -4], max: [4, 4, 4], albedo: 0.5}
  - {type: box, min: [-0.5, 1.8, -0.5], max: [0.5, 2.0, 0.5], albedo: 0.7}
render: {steps: 256, shadow_map: 256}
"""


@pytest.fixture
def room(tmp_path):
    path = tmp_path / "room.yaml"
    path.write_text(ROOM)
    return path


def relative_rmse(image, reference) -> float:
    image, reference = image.astype(np.float64), reference.astype(np.float64)
    return float(np.sqrt(np.mean((image - reference) ** 2) / np.mean(reference ** 2)))


@pytest.mark.parametrize("method", ["minmax", "raymarch", "exact"])
def test_far_does_not_change_a_closed_room(renderer, room, method):
    # The lamp radius used to be 1e-6 × far: at far 1e7 a 10-unit ball without medium
    # swallowed the room (rel RMSE 0.86). It now follows the scene's size.
    near, distant = (load_scene(room, overrides=[f"camera.far={far}"]) for far in ("40", "1e7"))
    assert lamp_radius(near) == lamp_radius(distant)
    reference = renderer.render(near, method).image
    assert reference.mean() > 0.05
    assert relative_rmse(renderer.render(distant, method).image, reference) <= 1e-3


@pytest.mark.parametrize("method", ["minmax", "raymarch", "exact"])
def test_absurd_far_keeps_the_fog(renderer, method):
    # far reaches float32 clamped (radiometry.effective_far): no overflow warning, and the
    # fog of rays that hit nothing is there as with far 1e7.
    overrides = ["image.width=24", "image.height=14", "render.steps=128", "render.shadow_map=128"]
    sane = load_scene("scenes/demo.yaml", overrides=overrides + ["camera.far=1e7"])
    absurd = load_scene("scenes/demo.yaml", overrides=overrides + ["camera.far=1e300"])
    assert effective_far(absurd) == effective_far(sane) < 1e3
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        image = renderer.render(absurd, method).image
    assert np.isfinite(image).all()
    np.testing.assert_array_equal(image, renderer.render(sane, method).image)
    assert image[0].mean() > 0.02  # the top row sees only fog


# --------------------------------------------------------------------------- the command line

SMALL = ["--set", "image.width=16", "--set", "image.height=9", "--set", "render.shadow_map=64",
         "--set", "render.slices=32", "--set", "render.gamma_samples=32"]


def one_line(out: str) -> str:
    lines = out.strip().splitlines()
    assert len(lines) == 1, out
    return lines[0]


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "100"])
def test_exposure_must_be_a_finite_number_of_stops(tmp_path, value):
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "a.png", "--exposure", value)
    assert code == 2
    assert one_line(out) == f"clrays: error: --exposure: expected a finite number of stops in [-64, 64] or auto, " \
                            f"got {value}"
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("name", ["a.exr", "a.npy"])
def test_exposure_on_linear_output_is_refused(tmp_path, name):
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / name, "--exposure", "2")
    assert code == 1
    assert one_line(out).startswith("clrays: error: --exposure 2: applies only to PNG output;")
    code, out = run("sequence", "scenes/demo.yaml", "-o", tmp_path / "f_{}.npy", "--exposure", "2")
    assert code == 1 and "applies only to PNG, MP4, GIF and WebP output" in one_line(out)


def test_a_key_the_method_does_not_read_gets_a_notice(tmp_path):
    args = ["render", "scenes/demo.yaml", "-o", tmp_path / "a.npy", *SMALL, "--set", "render.steps=1024"]
    code, out = run(*args, "--verbose")
    assert code == 0, out
    assert "clrays: notice: render.steps = 1024 (read by raymarch only); method minmax ignores it" in out
    assert "render.slices" not in out  # minmax reads it
    code, out = run(*args, "--stats", "--method", "raymarch")
    assert code == 0 and "render.steps" not in out and "render.slices = 32 (read by minmax and volume_moments only)" in out
    code, out = run(*args)
    assert code == 0 and "notice" not in out  # quiet unless asked


def test_unread_keys_come_from_the_field_table():
    from clrays.scene.fields import RENDER

    read_by = {field.key: field.read_by for field in RENDER.fields}
    assert read_by["steps"] == ("raymarch",) and read_by["slices"] == ("minmax", "volume_moments")
    assert read_by["method"] == ()  # every method
    assert "exact" not in read_by["shadow_map"]


@pytest.mark.parametrize("name", ["a" * 300 + ".png", "x" * 252 + ".npy"])
def test_a_file_name_too_long_is_one_line(tmp_path, name):
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / name)
    assert code == 1
    assert re.search(r"^clrays: error: .*\.\.\.: file name too long: \d+ bytes, the file system takes at most "
                     r"\d+$", one_line(out))
    code, out = run("sequence", "scenes/demo.yaml", "-o", tmp_path / ("{}" + name))
    assert code == 1 and "file name too long" in one_line(out)


def test_render_on_the_test_device_by_a_name_alias(tmp_path):
    # README: `--device pocl` (the platform is "Portable Computing Language").
    from conftest import TEST_DEVICE

    if TEST_DEVICE != "Portable Computing Language" and "pocl" not in TEST_DEVICE.lower():
        pytest.skip("the alias is PoCL's")
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "a.npy", *SMALL, "--device", "pocl")
    assert code == 0, out


def test_a_frame_past_the_device_buffer_limit_is_one_line(tmp_path):
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "a.png", "--set", "image.width=4096",
                    "--set", "image.height=4096", "--set", "image.spp=256")
    assert code == 1
    assert re.search(r"^clrays: error: scenes/demo\.yaml: the frame \(4096×4096 at 256 spp, .*\) needs a \d+ MiB "
                     r"buffer for the .*, more than the device's largest allocation of \d+ MiB", one_line(out))
    assert not list(tmp_path.iterdir())


def test_exact_says_how_long_and_shows_progress_off_a_terminal(tmp_path, monkeypatch):
    import clrays.cli

    monkeypatch.setattr(clrays.cli, "EXACT_ESTIMATE_MIN_S", 0.0)  # announce even this small image
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "a.npy", "--set", "image.width=24",
                    "--set", "image.height=14", "--method", "exact", "--no-progress")
    assert code == 0, out
    lines = out.strip().splitlines()
    assert re.fullmatch(r"clrays: exact on 24×14 at 1 spp, \d+ triangles, 1 light\(s\): about \d+ s on the host "
                        r"\(estimate\)", lines[0]), out
    progress = [line for line in lines[1:] if line.startswith("clrays: exact: ")]
    assert progress and progress[-1].startswith("clrays: exact: 100% (") and len(progress) <= 11, out


# --------------------------------------------------------------------------- interrupted writes


def _render_process(out: Path, *extra) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "clrays.cli", "render", "scenes/demo.yaml", "-o", str(out),
                             "--no-progress", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})


def test_sigterm_during_a_render_exits_cleanly(tmp_path):
    # exact on the host: a render long enough to be stopped midway, its progress lines say when.
    process = _render_process(tmp_path / "a.png", "--method", "exact", "--set", "image.width=64",
                              "--set", "image.height=36")
    for line in process.stderr:
        if line.startswith("clrays: exact: "):
            break
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert stderr.strip().splitlines()[-1] == f"clrays: interrupted; {tmp_path / 'a.png'} was not written"
    assert not list(tmp_path.iterdir())


def test_a_temporary_of_a_dead_writer_is_removed_by_the_next_write(tmp_path):
    from clrays.image_io import temporary_beside, write_image

    dead = subprocess.Popen([sys.executable, "-c", "import os; print(os.getpid())"], stdout=subprocess.PIPE,
                            text=True)
    dead_pid = int(dead.communicate()[0])
    mine = Path(temporary_beside(tmp_path / "a.png"))  # this process's: alive
    stale = tmp_path / mine.name.replace(f"-{os.getpid()}-", f"-{dead_pid}-")
    mine.rename(stale)
    alive = Path(temporary_beside(tmp_path / "b.png"))
    foreign = tmp_path / ".c.png.tmp1234.png"  # not a clrays temporary: left alone
    foreign.write_text("")
    write_image(tmp_path / "d.npy", np.zeros((2, 2, 3), np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([alive.name, foreign.name, "d.npy"])


# --------------------------------------------------------------------------- stale frames


SEQUENCE = ROOM.replace("render: {steps: 256, shadow_map: 256}", """\
render: {shadow_map: 64, slices: 32, gamma_samples: 32}
animation: {frames: [0, 2], camera: [{frame: 0, position: [0, 1.5, 3.5]}, {frame: 2, position: [1, 1.5, 3]}]}""")


def test_a_resumed_sequence_renders_again_the_frames_whose_scene_changed(tmp_path):
    scene = tmp_path / "room.yaml"
    scene.write_text(SEQUENCE)
    pattern = tmp_path / "out" / "f_{}.npy"
    code, out = run("sequence", scene, "-o", pattern, "--no-progress")
    assert code == 0 and "3 frames rendered, 0 already there" in out, out
    first = np.load(tmp_path / "out" / "f_1.npy")
    code, out = run("sequence", scene, "-o", pattern, "--no-progress")
    assert code == 0 and "0 frames rendered, 3 already there" in out, out

    code, out = run("sequence", scene, "-o", pattern, "--no-progress", "--set", "medium.sigma_s=0.3")
    assert code == 0 and "3 frames rendered (3 of them replacing frames of a changed scene), 0 already there" in out
    assert not np.array_equal(np.load(tmp_path / "out" / "f_1.npy"), first)
    code, out = run("sequence", scene, "-o", pattern, "--no-progress", "--set", "medium.sigma_s=0.3",
                    "--frames", "1")
    assert code == 0 and "0 frames rendered, 1 already there" in out


def test_a_gif_never_mixes_frame_sizes(tmp_path):
    scene = tmp_path / "room.yaml"
    scene.write_text(SEQUENCE)
    pattern, gif = tmp_path / "out" / "f_{}.png", tmp_path / "a.gif"
    assert run("sequence", scene, "-o", pattern, "--no-progress")[0] == 0
    # A smaller image is another scene: every frame is rendered again, and the GIF is whole.
    code, out = run("sequence", scene, "-o", pattern, "--no-progress", "--set", "image.width=16", "--video", gif)
    assert code == 0 and "3 frames rendered" in out, out
    with Image.open(gif) as animation:
        assert animation.n_frames == 3 and animation.size == (16, 24)
    # Frames written by hand (or by another tool) at another size are refused, not mixed.
    Image.new("RGB", (8, 8)).save(tmp_path / "out" / "f_1.png")
    from clrays.runs.sequence import write_video

    with pytest.raises(OutputError, match=r"frames of different sizes .* render them again with --overwrite"):
        write_video([tmp_path / "out" / f"f_{i}.png" for i in range(3)], tmp_path / "b.gif", 12)


# --------------------------------------------------------------------------- the README


def test_each_readme_python_snippet_defines_what_it_uses():
    # A newcomer pastes one block at a time: each must import or assign every name it reads.
    # The README's, and those it moved to docs/cli.md.
    import ast
    import builtins

    repo = Path(__file__).parents[2]
    text = "\n".join((repo / name).read_text() for name in ("README.md", "docs/cli.md"))
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 2
    for block in blocks:
        tree = ast.parse(block)
        bound = set(dir(builtins))
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                bound |= {(alias.asname or alias.name).split(".")[0] for alias in node.names}
            elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
                bound.add(node.id)
        used = {node.id for node in ast.walk(tree) if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load)}
        assert used <= bound, f"README snippet uses {sorted(used - bound)} without defining them:\n{block}"


@pytest.mark.parametrize("arguments, message", [
    (("--device", "²:0"), "device '²:0': no platform name or vendor, or device name, contains it"),
    (("--set", "lights.²=1"), "lights.²: expected a list index in [0, 0] or 1 to append, got '²'"),
])
def test_superscript_digits_are_one_line_errors(tmp_path, arguments, message):
    # '²'.isdigit() is true and int('²') fails: an index or a device number takes decimal digits.
    code, out = run("render", Path(__file__).resolve().parents[2] / "scenes" / "demo.yaml", "-o", tmp_path / "x.png",
                    *arguments)
    assert code == 1 and "internal error" not in out and len(out.strip().splitlines()) == 1, out
    assert message in out


def test_a_reference_step_count_of_superscript_digits_is_refused():
    from clrays.errors import ClraysError
    from clrays.runs.references import parse_reference

    with pytest.raises(ClraysError, match="expected exact or raymarch:N"):
        parse_reference("raymarch:²")


@pytest.mark.skipif(not TEST_ON_POCL, reason="PoCL's kernel cache")
def test_a_kernel_cache_that_cannot_be_written_is_one_line(tmp_path):
    """PoCL writes each program's source into its kernel cache before it builds or looks
    the binary up, so where the cache's disk is full every build fails. That is one line
    naming the cache, not the compiler's options and log twice over (8 lines). A file-size
    limit of 16 KiB on the process stands in for the full disk."""
    import resource

    scene = tmp_path / "s.yaml"
    scene.write_text("version: 1\nimage: {width: 8, height: 6}\ncamera: {position: [0, 1, 5], look_at: [0, 0, 0]}\n"
                     "lights: [{type: point, position: [0, 3, 0], intensity: 10}]\nmedium: {sigma_s: 0.1}\n")
    cache = tmp_path / "pocl-cache"
    env = {**os.environ, "POCL_CACHE_DIR": str(cache), "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    limit = 16 << 10
    done = subprocess.run([sys.executable, "-m", "clrays", "render", str(scene), "-o", str(tmp_path / "x.png")],
                          env=env, capture_output=True, text=True, timeout=120,
                          preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit)))
    lines = (done.stdout + done.stderr).strip().splitlines()
    assert done.returncode == 1 and len(lines) == 1, lines
    assert re.fullmatch(rf"clrays: error: .*\.cl: the OpenCL compiler could not build it: PoCL cannot write its kernel "
                        rf"cache {re.escape(str(cache))} \(File too large; .*POCL_CACHE_DIR\) \(run with --debug .*\)",
                        lines[0]), lines[0]


def test_a_write_past_a_file_size_limit_is_one_line_on_any_runtime(tmp_path):
    """Under a 16 KiB file-size limit the .exr write fails with EFBIG: one line, on every
    runtime (Intel's installs LLVM's crash handler for SIGXFSZ, which printed its own line
    first; clrays puts Python's SIG_IGN back)."""
    import resource

    args = ["render", "scenes/demo.yaml", "-o", tmp_path / "a.exr", "--set", "image.width=160", "--set",
            "image.height=90"]
    assert run(*args)[0] == 0  # kernels built and cached, unlimited
    (tmp_path / "a.exr").unlink()

    def limited():
        resource.setrlimit(resource.RLIMIT_FSIZE, (16384, 16384))

    done = subprocess.run([sys.executable, "-m", "clrays.cli", *map(str, args)], capture_output=True, text=True,
                          preexec_fn=limited, timeout=300, cwd=Path(__file__).resolve().parents[2])
    assert done.returncode == 1
    assert done.stdout + done.stderr == f"clrays: error: {tmp_path / 'a.exr'}: cannot write: File too large\n"
    assert not list(tmp_path.iterdir())
