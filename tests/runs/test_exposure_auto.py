"""`--exposure auto` and `render.exposure` (clrays/exposure.py): the statistic on images
whose answer is known, the EV line, the warnings for a black or mostly white 8-bit frame,
one exposure for every frame of a sequence (also when it is resumed), and the refusal for
float outputs."""
import re

import numpy as np
import pytest
from PIL import Image

from clrays.errors import SceneError
from clrays.exposure import AUTO, auto_ev, brightest_channel, exposure_problem, parse_exposure, problem_of_8bit
from clrays.image_io import to_srgb8
from clrays.reuse import scene_digest
from clrays.runs.frame_manifest import EXPOSURE_RECORD, record_exposure, recorded_exposure
from clrays.scene.load import load_scene
from conftest import run_cli as run

TINY = ["--set", "image.width=32", "--set", "image.height=18"]
BRIGHT = ["--set", "lights.0.intensity=[1e6,1e6,1e6]"]
EV_LINE = re.compile(r"^clrays: exposure auto: ([+-]\d+\.\d) EV", re.MULTILINE)


def grey(values, shape=(40, 50)) -> np.ndarray:
    """An (H, W, 3) image whose pixels take `values` in turn, grey."""
    flat = np.resize(np.asarray(values, dtype=np.float32), shape[0] * shape[1])
    return np.repeat(flat.reshape(shape)[..., None], 3, axis=2)


def clipped_fraction(png) -> float:
    return float(np.mean(np.asarray(Image.open(png)).max(axis=2) == 255))


# --------------------------------------------------------------------------- the statistic


def test_auto_maps_the_99th_percentile_to_near_white():
    assert auto_ev(grey([0.99 / 4])) == 2.0  # a flat grey of 0.99 / 4: two stops up to 0.99
    assert auto_ev(grey([0.99 * 4])) == -2.0
    # 19 highlights of 100 among 2000 pixels (under 1 %): the 99th percentile is the rest's.
    assert auto_ev(grey([100.0] * 19 + [0.99 / 2] * 1981, shape=(40, 50))) == 1.0


def test_a_flat_frame_does_not_clip():
    # Every pixel at the percentile: mapped within a tenth of a stop below 0.99 (246 to 254), not to white.
    for value in (0.25, 0.3, 7.0, 0.99 / 4):
        ev = auto_ev(grey([value]))
        assert 246 <= to_srgb8(grey([value]), ev).max() <= 254
        assert exposure_problem(grey([value]), ev) is None


def test_auto_reads_the_brightest_channel_and_leaves_black_out():
    blue = np.zeros((10, 10, 3), np.float32)
    blue[..., 2] = 0.99 / 8  # luminance 0.009: its blue channel clips first
    assert auto_ev(blue) == 3.0
    sky = np.zeros((100, 100, 3), np.float32)
    sky[:10, :10] = 0.99 / 4  # a lit 1 % on a black background
    assert auto_ev(sky) == 2.0


def test_auto_is_in_tenths_rounded_down_and_bounded():
    value = 0.99 * 2.0 ** -2.35
    assert auto_ev(grey([value])) == 2.3  # never brighter than the percentile to 0.99
    assert value * 2.0 ** auto_ev(grey([value])) <= 0.99
    assert auto_ev(np.zeros((4, 4, 3), np.float32)) == 0.0  # nothing lit: nothing to expose
    assert auto_ev(grey([1e-30])) == 64.0 and auto_ev(grey([1e30])) == -64.0


def test_a_light_in_view_clips_under_2_percent():
    # A lamp's glow: radiance falling as 1/d² from a point in the frame, over a dim floor.
    y, x = np.mgrid[0:90, 0:160]
    glow = 50.0 / (1.0 + ((x - 80) ** 2 + (y - 30) ** 2) / 4.0) + 0.01
    image = np.stack([glow, 0.9 * glow, 0.7 * glow], axis=2).astype(np.float32)
    ev = auto_ev(image)
    assert float(np.mean(to_srgb8(image, ev).max(axis=2) == 255)) < 0.02
    assert float(np.mean(to_srgb8(image, 0.0).max(axis=2) == 255)) > 0.02  # where EV 0 clips more


def test_parse_exposure():
    assert parse_exposure("auto") == AUTO and parse_exposure(" AUTO ") == AUTO
    assert parse_exposure("2.5") == 2.5 and parse_exposure(-64) == -64.0
    for bad in ("nan", "inf", "65", "bright", True, None, [1]):
        assert parse_exposure(bad) is None, bad


def test_problems_of_an_8bit_frame():
    assert problem_of_8bit(np.zeros((4, 4), np.uint8)).kind == "black"
    assert exposure_problem(grey([1e-5]), 0.0).kind == "black"  # 1e-5 rounds to 0 in 8 bits
    assert exposure_problem(grey([1e-5]), 10.0) is None
    problem = exposure_problem(grey([2.0] * 6 + [0.1] * 4, shape=(10, 10)), 0.0)
    assert problem.kind == "clipped" and problem.text.startswith("60% of the pixels clip")
    assert exposure_problem(grey([2.0] * 4 + [0.1] * 6, shape=(10, 10)), 0.0) is None  # 40 %: most do not


def test_the_brightest_channel_encodes_as_the_whole_pixel_does():
    # exposure_problem encodes only each pixel's brightest channel: the same as the image's.
    rng = np.random.default_rng(7)
    image = rng.lognormal(-2, 2, size=(30, 40, 3)).astype(np.float32)
    for ev in (-3.0, 0.0, 2.7):
        np.testing.assert_array_equal(to_srgb8(brightest_channel(image), ev), to_srgb8(image, ev).max(axis=2))


# --------------------------------------------------------------------------- the scene key


def test_render_exposure_key():
    assert load_scene("scenes/demo.yaml").render.exposure == 0.0
    assert load_scene("scenes/demo.yaml", ["render.exposure=auto"]).render.exposure == AUTO
    assert load_scene("scenes/demo.yaml", ["render.exposure=-1.5"]).render.exposure == -1.5
    with pytest.raises(SceneError, match=r"render\.exposure: expected a number of stops in \[-64, 64\] or auto, "
                                         r"got 'bright'"):
        load_scene("scenes/demo.yaml", ["render.exposure=bright"])
    with pytest.raises(SceneError, match=r"render\.exposure: .* got 100"):
        load_scene("scenes/demo.yaml", ["render.exposure=100"])
    # An exposure changes no radiance: the frame's stages and caches stay the same.
    assert scene_digest(load_scene("scenes/demo.yaml", ["render.exposure=auto"])) == \
        scene_digest(load_scene("scenes/demo.yaml"))


def test_the_sequence_record(tmp_path):
    assert recorded_exposure(tmp_path, "a") is None
    record_exposure(tmp_path, "a", 3.2)
    assert recorded_exposure(tmp_path, "a") == 3.2
    assert recorded_exposure(tmp_path, "b") is None  # another sequence's
    for text in ("{", "[1]", '{"sequence": "a", "ev": NaN}', '{"sequence": "a"}'):
        (tmp_path / EXPOSURE_RECORD).write_text(text)
        assert recorded_exposure(tmp_path, "a") is None, text


# --------------------------------------------------------------------------- the command line


def test_render_auto_prints_the_ev_and_does_not_clip(tmp_path):
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "auto.png", *TINY, "--exposure", "auto")
    assert code == 0, out
    ev = EV_LINE.findall(out)
    assert len(ev) == 1, out
    assert clipped_fraction(tmp_path / "auto.png") < 0.02
    assert "warning" not in out
    # The EV printed is the one applied: given as a number, it writes the same image.
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "number.png", *TINY, "--exposure", ev[0])
    assert code == 0, out
    np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "auto.png")),
                                  np.asarray(Image.open(tmp_path / "number.png")))
    # And it is the statistic of the frame's radiance.
    assert run("render", "scenes/demo.yaml", "-o", tmp_path / "linear.npy", *TINY)[0] == 0
    assert float(ev[0]) == auto_ev(np.load(tmp_path / "linear.npy"))


def test_a_bright_scene_warns_without_auto_and_not_with_it(tmp_path):
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "white.png", *TINY, *BRIGHT)
    assert code == 0, out
    assert re.search(r"^clrays: warning: .*white\.png: \d+% of the pixels clip \(255 in some channel\); "
                     r"try --exposure auto, or a lower --exposure$", out, re.MULTILINE), out
    assert clipped_fraction(tmp_path / "white.png") > 0.5
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "auto.png", *TINY, *BRIGHT, "--exposure", "auto")
    assert code == 0, out
    assert float(EV_LINE.findall(out)[0]) < -10 and "warning" not in out
    assert clipped_fraction(tmp_path / "auto.png") < 0.02


def test_a_black_frame_warns(tmp_path):
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "black.png", *TINY, "--exposure", "-40")
    assert code == 0, out
    assert re.search(r"^clrays: warning: .*black\.png: every pixel is black \(0 in every channel\); "
                     r"try --exposure auto, or a higher --exposure$", out, re.MULTILINE), out
    assert np.asarray(Image.open(tmp_path / "black.png")).max() == 0


def test_the_scene_key_exposes_and_the_option_overrides_it(tmp_path):
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "a.png", *TINY, "--set", "render.exposure=auto")
    assert code == 0 and len(EV_LINE.findall(out)) == 1, out
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "b.png", *TINY, "--set", "render.exposure=auto",
                    "--exposure", "0")
    assert code == 0 and not EV_LINE.findall(out), out
    # A float output keeps linear radiance whatever the scene's key says: no refusal, no line.
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "c.npy", *TINY, "--set", "render.exposure=auto")
    assert code == 0 and out.strip() == "", out


@pytest.mark.parametrize("name", ["a.exr", "a.npy"])
def test_auto_on_a_float_output_is_refused(tmp_path, name):
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / name, "--exposure", "auto")
    assert code == 1
    assert out.strip() == (f"clrays: error: --exposure auto: applies only to PNG output; "
                           f"{tmp_path / name} keeps linear radiance (drop --exposure)")
    assert not list(tmp_path.iterdir())
    code, out = run("sequence", "scenes/orbit.yaml", "-o", tmp_path / ("f_{}" + name[1:]), "--exposure", "auto")
    assert code == 1 and "--exposure auto: applies only to PNG, MP4, GIF and WebP output" in out, out


def test_compare_takes_no_auto(tmp_path):
    code, out = run("compare", "scenes/demo.yaml", "-o", tmp_path, "--exposure", "auto")
    assert code == 2
    assert out.strip() == "clrays: error: --exposure: expected a finite number of stops in [-64, 64], got auto"


def test_a_sequence_shares_one_exposure_also_when_resumed(tmp_path):
    # orbit.yaml's light fades in over its first 12 frames: frame 0 alone would whiten the rest.
    pattern = str(tmp_path / "auto" / "f_{:02d}.png")
    code, out = run("sequence", "scenes/orbit.yaml", "-o", pattern, "--frames", "0:1", *TINY, "--exposure", "auto")
    assert code == 0, out
    ev = EV_LINE.findall(out)
    assert len(ev) == 1 and "(from frames 0, 30, 59, for every frame)" in out, out
    # The least of the three frames' own statistics, whichever frames the run renders.
    own = []
    for frame in (0, 30, 59):
        assert run("render", "scenes/orbit.yaml", "-o", tmp_path / f"{frame}.npy", "--frame", frame, *TINY)[0] == 0
        own.append(auto_ev(np.load(tmp_path / f"{frame}.npy")))
    assert float(ev[0]) == min(own) < own[0]
    # Resumed with more frames: the recorded EV, the frames there kept, the new one at the same EV.
    code, out = run("sequence", "scenes/orbit.yaml", "-o", pattern, "--frames", "0:2", *TINY, "--exposure", "auto")
    assert code == 0, out
    assert EV_LINE.findall(out) == ev and "recorded in" in out, out
    assert "1 frame rendered, 2 already there" in out, out
    # Every frame as a run at that one EV writes it: no frame chose its own.
    fixed = str(tmp_path / "fixed" / "f_{:02d}.png")
    assert run("sequence", "scenes/orbit.yaml", "-o", fixed, "--frames", "0:2", *TINY, "--exposure", ev[0])[0] == 0
    for frame in range(3):
        np.testing.assert_array_equal(np.asarray(Image.open(pattern.format(frame))),
                                      np.asarray(Image.open(fixed.format(frame))))
    # Another scene in the folder: chosen again, and its frames rendered over the others.
    code, out = run("sequence", "scenes/orbit.yaml", "-o", pattern, "--frames", "0:2", *TINY,
                    "--set", "medium.sigma_s=0.5", "--exposure", "auto")
    assert code == 0 and "(from frames 0, 30, 59, for every frame)" in out and "3 frames rendered" in out, out


def test_a_sequence_warns_once_for_its_black_frames(tmp_path):
    code, out = run("sequence", "scenes/orbit.yaml", "-o", tmp_path / "f_{:02d}.png", "--frames", "0:2", *TINY,
                    "--exposure", "-40")
    assert code == 0, out
    warnings = [line for line in out.splitlines() if line.startswith("clrays: warning:")]
    assert warnings == ["clrays: warning: frame 0 and 2 more of the 3 rendered: every pixel is black (0 in every "
                        "channel); try --exposure auto, or a higher --exposure"], out


def test_a_video_of_float_frames_exposes_them_from_the_first(tmp_path):
    pattern = str(tmp_path / "f_{:02d}.npy")
    code, out = run("sequence", "scenes/orbit.yaml", "-o", pattern, "--frames", "0:1", *TINY,
                    "--video", tmp_path / "v.gif", "--exposure", "auto")
    assert code == 0, out
    ev = EV_LINE.findall(out)
    assert len(ev) == 1 and f"from {pattern.format(0)}, for {tmp_path / 'v.gif'}" in out, out
    assert float(ev[0]) == auto_ev(np.load(pattern.format(0)))
    with Image.open(tmp_path / "v.gif") as gif:
        assert gif.n_frames == 2


def test_watch_exposes_each_render(tmp_path):
    code, out = run("watch", "scenes/demo.yaml", "-o", tmp_path / "w.png", *TINY, "--exposure", "auto",
                    "--max-renders", "1")
    assert code == 0, out
    assert len(EV_LINE.findall(out)) == 1 and re.search(r"^render 1: ", out, re.MULTILINE), out
    assert clipped_fraction(tmp_path / "w.png") < 0.02


def test_a_sweep_exposes_each_point_as_its_scene_says(tmp_path):
    code, out = run("sweep", "scenes/demo.yaml", *TINY, "--set", "render.exposure=auto,-40", "-o", tmp_path)
    assert code == 0, out
    assert clipped_fraction(tmp_path / "000.png") < 0.02  # `auto`: the point's own statistic
    assert np.asarray(Image.open(tmp_path / "001.png")).max() == 0
    # An exposure changes no radiance: the second point is the first frame, kept by the session.
    assert re.search(r"^-40 .*raster\.camera raster\.shadow", out, re.MULTILINE), out


def test_a_sequence_on_a_worker_is_exposed_as_here(tmp_path):
    pytest.importorskip("distributed")
    from clrays.runs.distributed import DaskExecutor
    from clrays.runs.sequence import render_sequence
    from clrays.session import Renderer

    scene = load_scene("scenes/orbit.yaml", ["image.width=32", "image.height=18"])
    here_lines, there_lines, black_lines = [], [], []
    here = render_sequence(scene, tmp_path / "here" / "f_{:02d}.png", range(0, 2), renderer=Renderer(),
                           exposure=AUTO, echo=here_lines.append)
    with DaskExecutor(workers=1) as executor:
        executor.client.wait_for_workers(1, timeout=120)
        there = render_sequence(scene, tmp_path / "there" / "f_{:02d}.png", range(0, 2), exposure=AUTO,
                                executor=executor, echo=there_lines.append)
        # A worker's frame comes back without its image: its warning is read from its file.
        render_sequence(scene, tmp_path / "black" / "f_{:02d}.png", range(0, 2), exposure=-40.0, executor=executor,
                        echo=black_lines.append)
    assert there.exposure == here.exposure and there_lines == here_lines and len(here_lines) == 1
    for frame in range(2):
        assert (tmp_path / "there" / f"f_{frame:02d}.png").read_bytes() == \
            (tmp_path / "here" / f"f_{frame:02d}.png").read_bytes()
    assert black_lines == ["clrays: warning: frame 0 and 1 more of the 2 rendered: every pixel is black (0 in every "
                           "channel); try --exposure auto, or a higher --exposure"]
