"""Lights in turn (clrays.light_turns): a frame of several lights runs each light's stages
through one light's buffers, so its image is the frame that holds every light at once, bit
for bit, its memory one light's, and the light cap (256) is one line past it."""
import importlib.util
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import clrays.session as session
from clrays.device import Device
from clrays.errors import SceneError
from clrays.scene.limits import MAX_LIGHTS
from clrays.scene.load import load_scene, parse_scene
from clrays.scene.model import PointLight
from clrays.session import Renderer
from conftest import TEST_DEVICE, make_scene, v3

ROOT = Path(__file__).resolve().parents[2]
#: A floor and a tilted quad above it, which casts a shadow and shafts from every light.
FLOOR = [[[-6, 0, -6], [6, 0, -6], [6, 0, 6]], [[-6, 0, -6], [6, 0, 6], [-6, 0, 6]]]
BLOCKER = [[[-1, 2, -1], [1, 2.4, -1], [1, 2.4, 1]], [[-1, 2, -1], [1, 2.4, 1], [-1, 2, 1]]]
POSITIONS = [(-1.5, 4.5, 0.5), (1.2, 5.0, -0.8), (0.3, 4.0, 1.4), (2.0, 5.5, 0.0)]
SMALL = dict(shadow_map=128, slices=128, gamma_samples=128)


def _scene(positions, share: int | None = None, **render):
    """Point lights at `positions`, each with 1/`share` (default: 1/their count) of the power."""
    share = share or len(positions)
    lights = [PointLight(v3(*position), np.array([30.0, 25.0, 20.0]) / share) for position in positions]
    return make_scene(FLOOR + BLOCKER, lights, width=48, height=32, **{**SMALL, **render})


@pytest.fixture(scope="module")
def renderer():
    return Renderer(Device(TEST_DEVICE), reuse=False)


def _all_at_once(renderer, scene, monkeypatch, method=None):
    """The frame that holds every light's maps at once, as every frame did before."""
    with monkeypatch.context() as patched:
        patched.setattr(session, "lights_in_turn", lambda *_: False)
        return renderer.render(scene, method).image


@pytest.mark.parametrize("method, render", [("minmax", {}), ("minmax", {"sampling": "pixel"}),
                                            ("volume_moments", {}), ("minmax", {"aovs": ("in_scatter_light2",)})])
def test_lights_in_turn_give_the_all_at_once_image_bit_for_bit(renderer, monkeypatch, method, render):
    scene = _scene(POSITIONS, **render)
    assert session.lights_in_turn(scene, method)
    in_turn = renderer.render(scene, method)
    np.testing.assert_array_equal(in_turn.image, _all_at_once(renderer, scene, monkeypatch, method))
    assert in_turn.stage_status["raster.shadow"] == "computed" and in_turn.shadow_rays is not None
    if render.get("aovs"):  # a light's own pass is still its part of the whole
        assert in_turn.passes["in_scatter_light2"].max() > 0


def test_four_lights_are_the_sum_of_each_alone(renderer):
    """Each light's surface and in-scattering terms are the same float32 numbers alone as
    together; together they are summed in float32 (irradiance over the lights before
    shade's albedo/π and attenuation, in-scattering light after light), alone in float64 here.
    Every term is non-negative, so each of the ≤ 8 float32 roundings that separate the two
    sums moves a pixel by at most 2⁻²⁴ of its value: 8 × 2⁻²⁴ relative, with an absolute
    floor for pixels near zero."""
    together = renderer.render(_scene(POSITIONS)).image.astype(np.float64)
    alone = sum(renderer.render(_scene([position], share=len(POSITIONS))).image.astype(np.float64)
                for position in POSITIONS)
    assert together.max() > 0 and np.count_nonzero(together) > together.size // 2
    np.testing.assert_allclose(together, alone, rtol=8 * 2.0 ** -24, atol=1e-7 * together.max())


def test_the_device_memory_of_eight_lights_is_about_one_lights(renderer):
    """The CPU device's pool ends a frame holding every large buffer the frame took at once at
    its peak: with 8 lights that is one light's maps, trees and bound maps, as with 1, plus a
    float per sample and light of visibility (1.5× leaves room for that and the lights' records)."""
    peaks = []
    for count in (1, 8):
        fresh = Renderer(Device(TEST_DEVICE), reuse=True)
        if fresh.device.pool_bytes() is None:
            pytest.skip("only a CPU device pools its buffers")
        positions = [(x, 4.5, z) for x in (-1.5, -0.5, 0.5, 1.5) for z in (-0.5, 0.5)][:count]
        fresh.render(_scene(positions, shadow_map=512))
        peaks.append(fresh.device.pool_bytes()[0])
    assert peaks[1] <= 1.5 * peaks[0], peaks


def test_frames_of_many_lights_keep_no_per_light_results():
    """Past LIGHTS_KEPT lights, a session keeps no light's stage results for later frames:
    the second frame computes every light again and holds no more than the first."""
    fresh = Renderer(Device(TEST_DEVICE), reuse=True)
    scene = _scene(POSITIONS)
    first = fresh.render(scene)
    again = fresh.render(replace(scene, camera=replace(scene.camera, fov_deg=49.0)))
    assert first.stage_status["raster.shadow"] == again.stage_status["raster.shadow"] == "computed"
    two = _scene(POSITIONS[:2])
    fresh.render(two)
    assert fresh.render(replace(two, camera=replace(two.camera, fov_deg=49.0))).stage_status["raster.shadow"] == \
        "reused"


def _yaml_lights(count: int) -> str:
    rows = "".join(f"  - {{type: point, position: [{i % 16 - 8}, 6, {i // 16 - 8}], intensity: 1}}\n"
                   for i in range(count))
    return ("version: 1\nimage: {width: 8, height: 8}\ncamera: {position: [0, 2, 9], look_at: [0, 0, 0]}\n"
            f"lights:\n{rows}objects: [{{type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 10}}]\n")


def test_256_lights_load_and_257_are_refused_in_one_line(tmp_path):
    assert MAX_LIGHTS == 256
    assert len(parse_scene(_yaml_lights(MAX_LIGHTS), tmp_path / "many.yaml").lights) == MAX_LIGHTS
    with pytest.raises(SceneError, match=r"^[^\n]*many\.yaml:5:3: lights: expected at most 256 lights \(each light "
                                         r"costs [^\n]*\), got 257 lights$"):
        parse_scene(_yaml_lights(MAX_LIGHTS + 1), tmp_path / "many.yaml")


def test_257_lights_by_set_are_refused_in_one_line(tmp_path):
    path = tmp_path / "one.yaml"
    path.write_text(_yaml_lights(1))
    lights = "[" + ", ".join("{type: point, position: [0, 6, 0], intensity: 1}" for _ in range(MAX_LIGHTS + 1)) + "]"
    with pytest.raises(SceneError, match=r"^[^\n]*lights: expected at most 256 lights .*, got 257 lights$"):
        load_scene(path, [f"lights={lights}"])


def test_a_gltf_of_257_lights_is_refused_in_one_line(tmp_path):
    tool = importlib.util.spec_from_file_location("make_gltf_example", ROOT / "tools" / "make_gltf_example.py")
    module = importlib.util.module_from_spec(tool)
    tool.loader.exec_module(module)
    builder, light_ref = module.GltfBuilder(), module.light_ref
    builder.mesh(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), [[0, 1, 2]])
    builder.node(mesh=0)
    point = builder.light(type="point", intensity=683.0)
    for k in range(MAX_LIGHTS + 1):
        builder.node(extensions=light_ref(point), translation=[k % 16, 5, k // 16])
    path = tmp_path / "scene.glb"
    path.write_bytes(builder.glb())
    with pytest.raises(SceneError, match=r"^[^\n]*scene\.glb: [^\n]*expected at most 256 lights \(each light costs "
                                         r"[^\n]*\), got 257 with this one$"):
        load_scene(path)
