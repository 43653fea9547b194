"""`clrays tune` and `render.target_error`: the search meets its target (re-measured here
against `exact` without the tuner's code), an unreachable target is one line, the tuned
YAML keeps the user's keys, a scene's target tunes once and is cached, and an animation is
measured on several frames."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from clrays.reference.exact import exact_pixels
from clrays.reference.metrics import depth_edges_at, image_error
from clrays.runs import tune as tuning
from clrays.runs.bench import error_pixels
from clrays.runs.references import ReferenceCache
from clrays.scene.load import load_scene
from clrays.session import Renderer
from conftest import run_cli as run

#: Thin slats under a point light, at sizes far below what the image derives: the tuner
#: must grow them to reach 0.5 % (the start measures 1.700 %, the tuned setting 0.358 %).
SCENE = """\
# slats under a lamp (a comment the tuned file keeps)
version: 1
image: {width: 64, height: 36}
camera: {position: [0, 2, 8], look_at: [0, 1.5, 0], far: 30}
lights:
  - {type: point, position: [0.3, 5, -0.5], intensity: 80}
medium: {sigma_s: 0.08, sigma_a: 0.01}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 12, segments: 2}
  - {type: box, min: [-2, 2.5, -3], max: [-1.9, 2.7, 3]}
  - {type: box, min: [-1.2, 2.5, -3], max: [-1.1, 2.7, 3]}
  - {type: box, min: [-0.4, 2.5, -3], max: [-0.3, 2.7, 3]}
  - {type: box, min: [0.4, 2.5, -3], max: [0.5, 2.7, 3]}
  - {type: box, min: [1.2, 2.5, -3], max: [1.3, 2.7, 3]}
render: {shadow_map: 64, slices: 32, gamma_samples: 32, steps: 64}  # coarse on purpose
"""

ANIMATION = """\
animation:
  frames: [0, 8]
  camera:
    - {frame: 0, position: [0, 2, 8]}
    - {frame: 8, position: [3, 2.5, 7]}
"""


def written_scene(folder, text: str = SCENE):
    """`text` as folder/scene.yaml."""
    path = folder / "scene.yaml"
    path.write_text(text)
    return path


@pytest.fixture
def scene_file(tmp_path):
    return written_scene(tmp_path)


@pytest.fixture
def cache(tmp_path):
    return {"CLRAYS_CACHE": str(tmp_path / "cache")}


def exact_error(scene, image: np.ndarray) -> float:
    """Relative RMSE of `image` against exact on the bench's pixel subset, depth edges out,
    from the metric itself (not the tuner's reference cache)."""
    ys, xs = error_pixels(scene.image.width, scene.image.height, tuning.TUNE_PIXELS)
    return image_error(image[ys, xs], exact_pixels(scene, ys, xs), depth_edges_at(scene, ys, xs)).rmse


def without_trials(text: str) -> list[str]:
    """The output's lines, less the line per setting tried and the build notice (the mark of
    kernels built is kept in the cache, which each test's `cache` makes new)."""
    return [line for line in text.splitlines() if not line.startswith(("clrays: tune:", "building OpenCL kernels"))]


@pytest.mark.parametrize("percent", [2.5, 0.5])
def test_tune_meets_the_target_and_the_written_scene_renders_within_it(scene_file, tmp_path, cache, percent):
    out = tmp_path / f"tuned_{percent}.yaml"
    code, text = run("tune", scene_file, "--target-error", percent, "-o", out, "--no-progress", env=cache)
    assert code == 0, text
    assert "error against exact" in text and f"wrote {out}" in text
    tuned = load_scene(out)
    assert tuned.render.target_error is None
    image = Renderer(reuse=False).render(tuned).image
    error = exact_error(tuned, image)
    assert error <= percent / 100  # measured: 1.700 % at 2.5 % (the start holds), 0.358 % at 0.5 %
    assert f"{100 * error:.3f} %" in text  # the error it prints is the error the file renders with
    render = tuned.render
    if percent == 2.5:  # the start (1.700 %) meets its aim, 80 % of it: the search only takes coarser rungs
        assert render.shadow_map <= 64 and render.slices <= 32 and render.gamma_samples <= 32
        assert render.line_samples <= 37 and render.initial_step >= 3 and render.refine_threshold >= 0.02
    if percent == 0.5:  # the start (1.700 %) is over it: something grew
        assert tuned.render.shadow_map > 64 or tuned.render.slices > 32 or tuned.render.gamma_samples > 32


def test_the_tuned_yaml_keeps_the_users_keys_and_comments(scene_file, tmp_path, cache):
    out = tmp_path / "tuned.yaml"
    code, text = run("tune", scene_file, "--target-error", 2, "-o", out, "--no-progress", env=cache)
    assert code == 0, text
    written = out.read_text()
    assert written.startswith("# slats under a lamp (a comment the tuned file keeps)\n")
    before, after = yaml.safe_load(SCENE), yaml.safe_load(written)
    assert {key: value for key, value in after.items() if key != "render"} == \
           {key: value for key, value in before.items() if key != "render"}
    assert after["render"]["steps"] == 64  # a render key the search does not touch
    assert set(after["render"]) >= {"shadow_map", "slices", "gamma_samples", "line_samples", "initial_step",
                                    "refine_threshold"}
    assert "# coarse on purpose\n" in written  # only the keys tune sets change (test_tune_consent.py)


def test_a_tuned_scene_written_elsewhere_keeps_its_files_and_overrides(tmp_path, cache):
    out = tmp_path / "elsewhere" / "lattice.yaml"
    out.parent.mkdir()
    lattice = Path(__file__).resolve().parents[2] / "scenes" / "lattice.yaml"
    code, text = run("tune", lattice, "--target-error", 50, "--set", "image.width=32", "--set", "image.height=18",
                     "--pixels", 200, "-o", out, "--no-progress", env=cache)
    assert code == 0, text
    tuned = load_scene(out)  # its relief's depth map found from the new folder
    assert (tuned.image.width, tuned.image.height) == (32, 18)


def test_a_tuned_gltf_scene_is_the_yaml_that_imports_it(tmp_path, cache):
    """A .glb is no text to edit: the tuned scene is a YAML file that brings it in by
    `gltf.file` (from the output's folder), with the overrides and the camera chosen."""
    out = tmp_path / "tuned" / "colonnade.yaml"
    out.parent.mkdir()
    glb = Path(__file__).resolve().parents[2] / "scenes" / "colonnade.glb"
    code, text = run("tune", glb, "--target-error", 50, "--set", "image.width=32", "--set", "image.height=18",
                     "--set", "medium.sigma_s=0.06", "--camera", "view", "--pixels", 200, "--most-settings", 3,
                     "-o", out, "--no-progress", env=cache)
    assert code == 0, text
    written = yaml.safe_load(out.read_text())
    assert set(written["gltf"]) == {"file", "camera"} and written["gltf"]["camera"] == "view"
    assert (out.parent / written["gltf"]["file"]).resolve() == glb
    tuned = load_scene(out)
    assert (tuned.image.width, tuned.image.height) == (32, 18) and tuned.medium.sigma_s[0] == 0.06
    assert tuned.render.shadow_map == written["render"]["shadow_map"]


@pytest.mark.parametrize("budget", [pytest.param([], marks=pytest.mark.slow), ["--most-settings", 5]])
def test_an_unreachable_target_is_one_line_naming_the_best_error(scene_file, tmp_path, cache, budget):
    out = tmp_path / "never.yaml"
    code, text = run("tune", scene_file, "--target-error", 0.001, *budget, "-o", out, "--no-progress", env=cache)
    assert code == 1
    lines = without_trials(text)
    assert len(lines) == 1 and lines[0].startswith("clrays: error: ")
    assert "target error 0.001 %: not reached; the best error found is" in lines[0]
    best = float(lines[0].split("the best error found is ")[1].split(" %")[0])
    tried = [float(line.split(": ")[-1].split(" %")[0]) for line in text.splitlines()
             if line.startswith("clrays: tune:") and not line.startswith("clrays: tune: for ")]  # not the cost
    assert best == min(tried)  # the best of the settings it tried
    assert not out.exists()


@pytest.mark.parametrize("value", ["0", "100", "-1", "nan", "abc"])
def test_a_bad_target_is_refused(scene_file, tmp_path, value):
    code, text = run("tune", scene_file, "--target-error", value, "-o", tmp_path / "x.yaml")
    assert code == 2 and "--target-error" in text


def test_a_scene_target_out_of_range_is_one_line(scene_file):
    code, text = run("render", scene_file, "--set", "render.target_error=0", "-o", scene_file.with_suffix(".png"))
    assert code == 1
    assert text.strip().splitlines() == [text.strip()] and "render.target_error" in text


def test_render_target_error_tunes_once_and_caches(scene_file, tmp_path, cache, monkeypatch):
    monkeypatch.setattr(tuning, "TUNE_BUDGET_S", 1000.0)  # a worst case past the budget on a loaded machine
    scene_file.write_text(SCENE.replace("steps: 64}", "steps: 64, target_error: 0.5}"))
    first, second = tmp_path / "a.npy", tmp_path / "b.npy"
    code, text = run("render", scene_file, "-o", first, "--tune", "--stats", "--no-progress", env=cache)
    assert code == 0, text
    assert "clrays: tune:" in text  # searched
    tuned_line = next(line for line in text.splitlines() if "tuned for 0.5 %" in line)
    code, again = run("render", scene_file, "-o", second, "--stats", "--no-progress", env=cache)
    assert code == 0, again
    assert "clrays: tune:" not in again  # read from the cache
    assert "(cached)" in again and tuned_line.strip() in again
    assert np.array_equal(np.load(first), np.load(second))
    scene = load_scene(scene_file)
    assert exact_error(scene, np.load(first)) <= 0.005  # measured: 0.358 %
    files = list((tmp_path / "cache").glob("tuned-*.json"))
    assert len(files) == 1
    files[0].write_text("{not json")  # a corrupt entry is tuned again
    code, third = run("render", scene_file, "-o", first, "--tune", "--stats", "--no-progress", env=cache)
    assert code == 0 and "clrays: tune:" in third and "(cached)" not in third
    # So is one that names a setting the method has no knob for, or a value out of range.
    for settings in ({"bogus": 1}, {"shadow_map": True}, {"slices": -5}, {"refine_threshold": 1e9}):
        files[0].write_text(json.dumps({"settings": settings, "rmse": 0.001, "frame_ms": 1.0}))
        code, again = run("render", scene_file, "-o", first, "--tune", "--stats", "--no-progress", env=cache)
        assert code == 0 and "clrays: tune:" in again and "(cached)" not in again, (settings, again)


@pytest.mark.slow
def test_an_unreachable_scene_target_fails_render_in_one_line(scene_file, tmp_path, cache, monkeypatch):
    monkeypatch.setattr(tuning, "TUNE_BUDGET_S", 1000.0)  # the climb to the ladders' ends takes a minute
    scene_file.write_text(SCENE.replace("steps: 64}", "steps: 64, target_error: 0.001}"))
    code, text = run("render", scene_file, "-o", tmp_path / "x.png", "--tune", "--no-progress", env=cache)
    assert code == 1
    lines = without_trials(text)
    assert len(lines) == 1 and "render.target_error: target error 0.001 %: not reached" in lines[0]
    assert not (tmp_path / "x.png").exists()


@pytest.mark.slow
def test_a_sequence_pays_for_the_tuning_once(scene_file, tmp_path, cache, monkeypatch):
    monkeypatch.setattr(tuning, "TUNE_BUDGET_S", 1000.0)  # a worst case past the budget on a loaded machine
    scene_file.write_text(SCENE.replace("steps: 64}", "steps: 64, target_error: 2}") + ANIMATION)
    code, text = run("sequence", scene_file, "-o", tmp_path / "f_{:02d}.npy", "--frames", "0:2", "--stats",
                     "--tune", "--no-progress", env=cache)
    assert code == 0, text
    assert "tuned for 2 %" in text
    code, again = run("sequence", scene_file, "-o", tmp_path / "g_{:02d}.npy", "--frames", "3:4", "--stats",
                      "--no-progress", env=cache)
    assert code == 0 and "clrays: tune:" not in again and "(cached)" in again


@pytest.mark.slow
def test_a_sequence_keeps_its_tuning_beside_its_frames(scene_file, tmp_path, cache, monkeypatch):
    """The frames' digests hold the tuned settings, so the tuning is kept with the frames
    (OUTPUT/.references), not in the cache: resumed with another cache (another folder,
    another node), the run takes the same settings and keeps every frame."""
    monkeypatch.setattr(tuning, "TUNE_BUDGET_S", 1000.0)  # a worst case past the budget on a loaded machine
    scene_file.write_text(SCENE.replace("steps: 64}", "steps: 64, target_error: 2}") + ANIMATION)
    frames = tmp_path / "frames" / "f_{:02d}.npy"
    code, text = run("sequence", scene_file, "-o", frames, "--frames", "0:2", "--tune", "--no-progress", env=cache)
    assert code == 0 and list((tmp_path / "frames" / ".references").glob("tuned-*.json")), text
    code, again = run("sequence", scene_file, "-o", frames, "--frames", "0:2", "--no-progress",
                      env={"CLRAYS_CACHE": str(tmp_path / "another cache")})
    assert code == 0 and "clrays: tune:" not in again and "0 frames rendered, 3 already there" in again, again


def test_exact_renders_a_scene_with_a_target_as_it_is(scene_file, tmp_path, cache):
    """`exact` is what a target is measured against: it has nothing to tune, and renders."""
    scene_file.write_text(SCENE.replace("steps: 64}", "steps: 64, target_error: 2}"))
    code, text = run("render", scene_file, "--method", "exact", "-o", tmp_path / "x.npy", "--no-progress", env=cache)
    assert code == 0 and "clrays: tune:" not in text, text
    assert not (tmp_path / "cache").exists()


def test_an_animation_is_measured_on_first_middle_and_last_frames(tmp_path):
    path = tmp_path / "animated.yaml"
    path.write_text(SCENE + ANIMATION)
    scene = load_scene(path)
    frames = tuning.measured_frames(scene)
    assert [tuple(frame.camera.position) for frame in frames] == \
           [tuple(scene.animation.scene_at(scene, n).camera.position) for n in (0, 4, 8)]


@pytest.mark.slow
def test_an_animations_error_is_the_largest_of_its_frames(tmp_path):
    path = tmp_path / "animated.yaml"
    path.write_text(SCENE + ANIMATION)
    scene = load_scene(path)
    frames = tuning.measured_frames(scene)
    # 2 %: the start measures 3.746 %, and the first survey's slices=64 1.890 %, so the
    # search reaches it whatever the frame times (a shared machine's load) make it choose.
    result = tuning.tune(scene, 0.02, ReferenceCache(tmp_path / "cache"), Renderer(reuse=False), repeats=1)
    best = result.best
    assert best is not None and result.default.rmse > 0.02
    errors = [exact_error(frame, Renderer(reuse=False).render(tuning.with_settings(frame, best.settings)).image)
              for frame in frames]
    assert best.rmse == pytest.approx(max(errors), rel=1e-9)  # the largest of the frames counts
    assert max(errors) <= 0.02
    assert len(set(errors)) == 3  # three different frames were measured


def test_the_search_grows_finer_rungs_and_stops_at_the_ladders_end():
    shadow_map = tuning.Knob("shadow_map", 64, 4096)
    assert shadow_map.step(1024, True) == 2048 and shadow_map.step(4096, True) is None
    assert shadow_map.step(64, False) is None
    step = tuning.Knob("initial_step", 1, 16, smaller_is_finer=True)
    assert step.step(3, True) == 1 and step.step(1, True) is None and step.step(3, False) == 6
    assert [knob.key for knob in tuning.knobs_for("raymarch", "epipolar")] == ["shadow_map", "steps"]
    assert [knob.key for knob in tuning.knobs_for("minmax", "pixel")] == ["shadow_map", "slices", "gamma_samples",
                                                                          "shaft_edges"]
    ends = tuning.knobs_for("minmax", "pixel")[-1]  # a setting of words: texels the faster, blockers the finer
    assert ends.step("texels", True) == "blockers" and ends.step("blockers", True) is None
    assert ends.step("blockers", False) == "texels" and ends.step("texels", False) is None


@pytest.mark.slow
def test_a_sweep_renders_each_point_with_its_tuned_settings(scene_file, tmp_path, cache, monkeypatch):
    monkeypatch.setattr(tuning, "TUNE_BUDGET_S", 1000.0)  # a worst case past the budget on a loaded machine
    scene_file.write_text(SCENE.replace("steps: 64}", "steps: 64, target_error: 0.5}"))
    out = tmp_path / "sweep"
    code, text = run("sweep", scene_file, "--set", "medium.sigma_s=0.06,0.08", "--format", "npy", "-o", out,
                     "--tune", "--no-progress", env=cache)
    assert code == 0, text
    assert len(list((out / ".references").glob("tuned-*.json"))) == 2  # one per point's scene
    for index, sigma_s in enumerate(("0.06", "0.08")):
        scene = load_scene(scene_file, [f"medium.sigma_s={sigma_s}"])
        assert exact_error(scene, np.load(out / f"{index:03d}.npy")) <= 0.005


def test_a_sweep_of_a_setting_the_target_tunes_is_one_line(scene_file, tmp_path, cache):
    """Sweeping render.slices while render.target_error tunes it would render every point
    at the tuned slices and label it with the swept ones: refused before any point."""
    scene_file.write_text(SCENE.replace("steps: 64}", "steps: 64, target_error: 2}"))
    code, text = run("sweep", scene_file, "--set", "render.slices=32,64", "-o", tmp_path / "sweep", "--no-progress",
                     env=cache)
    lines = text.strip().splitlines()
    assert code == 1 and len(lines) == 1, text
    assert "render.slices is swept, and render.target_error tunes it" in lines[0]
    assert not list((tmp_path / "sweep").glob("*.png"))


def test_a_scene_without_render_gets_one_and_exact_has_nothing_to_tune(scene_file, tmp_path, cache):
    bare = SCENE[:SCENE.index("render:")]
    scene_file.write_text(bare)
    out = tmp_path / "tuned.yaml"
    code, text = run("tune", scene_file, "--target-error", 50, "--pixels", 200, "-o", out, "--no-progress", env=cache)
    assert code == 0, text
    assert out.read_text().startswith(bare) and "shadow_map" in yaml.safe_load(out.read_text())["render"]
    code, text = run("tune", scene_file, "--target-error", 1, "--method", "exact", "-o", out, env=cache)
    assert code == 1 and text.count("\n") == 1 and "exact is the reference itself" in text


def test_a_start_that_does_not_render_is_searched_from_below(scene_file, tmp_path, monkeypatch, renderer):
    """Settings past what the device holds fail to render; where the start is such a
    setting, the search steps every knob coarser until one renders, and goes on from there."""
    from clrays.errors import DeviceError

    render = type(renderer).render

    def render_small_maps_only(self, scene, *args, **kwargs):
        if scene.render.shadow_map is not None and scene.render.shadow_map > 64:
            raise DeviceError("the shadow map does not fit the device (a stand-in for its memory)")
        return render(self, scene, *args, **kwargs)

    monkeypatch.setattr(type(renderer), "render", render_small_maps_only)
    scene = load_scene(scene_file, ["render.shadow_map=256"])
    result = tuning.tune(scene, 0.5, ReferenceCache(tmp_path / "cache"), renderer=renderer, pixels=200,
                         most_settings=8)
    assert result.default.failed and result.best is not None, [t.settings for t in result.trials]
    assert result.best.settings["shadow_map"] <= 64
    assert tuning.default_trial_line(result).startswith("as written: not rendered (the shadow map does not fit")


@pytest.mark.parametrize("first_cost, timed", [(250.0, 1), (50.0, 3)])
def test_a_long_frame_is_timed_once(scene_file, tmp_path, monkeypatch, first_cost, timed):
    """A setting whose first timed frame costs LONG_FRAME_MS or more is timed once (one long
    frame is as good as the median of three, bench/RESULTS.md history); a shorter one three times."""
    scene = load_scene(scene_file)
    search = tuning.Search(scene, "minmax", ReferenceCache(tmp_path / "cache"), Renderer(reuse=False), pixels=200)
    costs = iter([first_cost, first_cost + 10.0, first_cost + 20.0])
    calls = []

    def one_frame(variant):
        calls.append(variant)
        cost = next(costs)
        return cost, cost

    monkeypatch.setattr(search, "_timed", one_frame)
    trial = search.measure(tuning.start_settings(scene, "minmax"))
    assert len(calls) == timed
    assert trial.cost_ms == (first_cost if timed == 1 else first_cost + 10.0)
