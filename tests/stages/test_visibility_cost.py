"""The visibility decision's cost cut (cl/visibility.cl decide_lanes): a lane within the bias
of its bound map has only its own surface's slack worked out on its own
(lit_within_own_slack); where the slack leaves it, it takes the 3 × 3 test with the other
lanes, in lanes, instead of the whole decision again one sample at a time (decide_entry).
The invariant this relies on: the lanes' 3 × 3 test gives such a lane decide_entry's answer,
so every entry's decision, hence every image, is the one decided sample by sample. And the
images stay within 0.5 % relative RMSE of `exact` at small sizes."""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import clrays.stages.visibility as stage
from clrays.device import Device
from clrays.inputs import frame_inputs
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.scene.load import load_scene
from clrays import session
from clrays.session import Renderer
from conftest import make_scene
from test_visibility_bound import LIGHTS, _triangles

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _decision(device, monkeypatch, scene, defines):
    """(visible per sample and light, the shadow rays cast) of a frame whose visibility kernel
    is built with `defines`."""
    real_kernel, real_visibility, kept = Device.kernel, stage.visibility, {}

    def kernel(self, stage_name, name, extra=None):
        if stage_name == "visibility" and name == "visibility" and defines:
            extra = {**(extra or {}), **defines}
        return real_kernel(self, stage_name, name, extra)

    def visibility(device, buffers, *args, **kwargs):
        visible, rays = real_visibility(device, buffers, *args, **kwargs)
        entries = buffers.inputs.samples * max(len(buffers.inputs.scene.lights), 1)
        kept["visible"], kept["rays"] = device.read(visible, entries, np.float32), int(rays)
        return visible, rays

    monkeypatch.setattr(Device, "kernel", kernel)
    monkeypatch.setattr(session, "visibility", visibility)  # (the name the frame calls)
    Renderer(device, reuse=False).render(scene)
    monkeypatch.undo()
    assert "visible" in kept, "the frame ran no visibility stage"
    return kept["visible"], kept["rays"]


# behind's floor is lit at a grazing angle far from the eye: many lanes within the bias of
# their bound, some of which the own slack leaves to the 3 × 3 test; grate's slats over a
# floor give shadow edges every few texels.
@pytest.mark.parametrize("name, size", [("behind", (160, 90)), ("behind", (203, 117)), ("grate", (160, 90)),
                                        ("demo", (160, 90))])
def test_the_decision_in_lanes_is_the_one_sample_by_sample(device, monkeypatch, name, size):
    width, height = size
    scene = load_scene(SCENES / f"{name}.yaml", overrides=[f"image.width={width}", f"image.height={height}"])
    lanes, lane_rays = _decision(device, monkeypatch, scene, None)
    alone, alone_rays = _decision(device, monkeypatch, scene, {"DECIDE_ONE_BY_ONE": 1})
    np.testing.assert_array_equal(lanes.view(np.int32), alone.view(np.int32))
    assert lane_rays == alone_rays
    assert 0.0 < (lanes == 0.0).mean() < 1.0  # some entries shadowed, some lit: the test decides something


@pytest.mark.parametrize("kind", LIGHTS)
def test_several_lights_of_every_type_decide_as_one_by_one(device, monkeypatch, kind):
    # two lights: the entries are no run of samples, so the lanes' answers are stored one by one
    scene = make_scene(_triangles(), [LIGHTS[kind], LIGHTS["point"]], width=37, height=23, spp=2, shadow_map=64)
    lanes, lane_rays = _decision(device, monkeypatch, scene, None)
    alone, alone_rays = _decision(device, monkeypatch, scene, {"DECIDE_ONE_BY_ONE": 1})
    np.testing.assert_array_equal(lanes.view(np.int32), alone.view(np.int32))
    assert lane_rays == alone_rays


@pytest.mark.parametrize("name", ["demo", "behind", "sun", "grate"])
def test_small_images_stay_within_half_a_percent_of_exact(renderer, name):
    scene = load_scene(SCENES / f"{name}.yaml", overrides=["image.width=96", "image.height=54"])
    exact = renderer.render(scene, "exact").image
    error = image_error(renderer.render(scene, "minmax").image, exact, depth_edges(depth_map(scene)))
    print(f"{name} 96×54, minmax against exact: {error}")
    assert error.rmse < 0.005


# The lattice's relief has holes finer than a shadow-map texel, which the 3 × 3 test misses:
# with reliefs it holds only where none of the nine texels was drawn by a relief's triangle
# (VISIBILITY_RELIEF_FIRST), and every other sample the maps leave casts its ray, as a build
# without the test (VISIBILITY_SHADOWED_TEST 0) casts one for each.
@pytest.mark.parametrize("size", [(160, 90), (640, 360)])
def test_the_relief_aware_shadowed_test_gives_the_rays_answers_on_the_lattice(device, monkeypatch, size):
    width, height = size
    scene = load_scene(SCENES / "lattice.yaml", overrides=[f"image.width={width}", f"image.height={height}"])
    assert "VISIBILITY_RELIEF_FIRST" in stage.relief_defines(frame_inputs(scene).scene.geometry, True)
    relief_aware, relief_aware_rays = _decision(device, monkeypatch, scene, None)
    every_ray, every_rays = _decision(device, monkeypatch, scene, {"VISIBILITY_SHADOWED_TEST": 0})
    np.testing.assert_array_equal(relief_aware.view(np.int32), every_ray.view(np.int32))
    print(f"lattice {width}×{height}: {relief_aware_rays} rays with the relief-aware test, {every_rays} without")
    assert relief_aware_rays < every_rays / 2  # the test decides most of the shadowed samples


def test_the_plain_shadowed_test_misses_the_lattices_holes(device, monkeypatch):
    # the 3 × 3 test even beside the relief (no triangle is a relief's): some answers go wrong
    # (6 entries at 640×360), which is why the relief's texels are left to the rays
    scene = load_scene(SCENES / "lattice.yaml", overrides=["image.width=640", "image.height=360"])
    plain, _ = _decision(device, monkeypatch, scene, {"VISIBILITY_RELIEF_FIRST": 2**31 - 1})
    every_ray, _ = _decision(device, monkeypatch, scene, {"VISIBILITY_SHADOWED_TEST": 0})
    wrong = plain != every_ray
    assert wrong.any()
    assert (every_ray[wrong] == 1.0).all() and (plain[wrong] == 0.0).all()  # lit through a hole, called shadowed


def test_the_reliefs_first_triangle_only_where_they_are_last():
    scene = load_scene(SCENES / "lattice.yaml")
    placed = frame_inputs(scene).scene.geometry
    first = stage.relief_first_triangle(placed)
    assert first == placed.count - sum(r.rows.stop - r.rows.start for r in placed.reliefs)
    assert 0 < first < placed.count
    # a relief that is not last: no relief-aware test, the test is built off
    record = placed.reliefs[0]
    moved = replace(placed, reliefs=(replace(record, rows=slice(0, record.rows.stop - record.rows.start)),))
    assert stage.relief_first_triangle(moved) is None
    assert stage.relief_defines(moved, True) == {"VISIBILITY_SHADOWED_TEST": 0}
    # without keys the texels' triangles are unknown
    assert stage.relief_defines(placed, False) == {"VISIBILITY_SHADOWED_TEST": 0}
