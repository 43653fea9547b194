"""visibility_prepare's and the decision's lanes (8 samples per work-item, cl/visibility.cl
prepare_lanes, decide_lanes) against the kernels built to take every sample one by one
(prepare_entry, decide_entry): the same answers and the same texels, bit for bit, for
every light type, on the bench scenes and on frames whose sample count is no multiple of
8. The depth each sample compares with its texel is the same bits on PoCL, whose compiler
fuses the lanes and the scalar statements alike; NVIDIA's fuses them differently, and it
may differ there by a few units in the last place."""
from pathlib import Path

import numpy as np
import pytest

import clrays.stages.visibility as stage
from clrays import structs
from clrays.device import Device, StageTimer
from clrays.inputs import frame_inputs, upload
from clrays.scene.load import load_scene
from clrays.session import Renderer
from clrays.stages.raster import raster
from conftest import TEST_ON_POCL, make_scene
from test_visibility_bound import LIGHTS, _triangles

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _prepared(device, scene, defines):
    """(visible, map_read, read_mask) of visibility_prepare built with `defines`."""
    buffers = upload(device, frame_inputs(scene))
    timer = StageTimer()
    rastered = raster(device, buffers, timer)
    kernel = device.kernel("visibility_prepare", "visibility_prepare", defines)
    inputs = buffers.inputs
    lights = max(len(scene.lights), 1)
    entries = inputs.samples * lights
    visible, map_read = device.buffer(nbytes=4 * entries), device.buffer(nbytes=8 * entries)
    words = max((inputs.shadow_texels + 31) // 32, 1)
    read_mask = device.buffer(np.zeros(words, np.uint32))
    kernel(device.queue, (-(-inputs.samples // stage.PREPARE_LANES), lights), None, buffers.params, buffers.views,
           buffers.lights, rastered.camera_depth, rastered.tri_id, buffers.tri_normal, buffers.tri_vertex_normals,
           buffers.offsets, visible, map_read, read_mask)
    return (device.read(visible, entries, np.float32), device.read(map_read, (entries, 2), np.int32),
            device.read(read_mask, words, np.uint32))


#: Off PoCL: units in the last place a sample's depth may differ by, and the share of samples
#: whose position, an ulp away, falls in the next texel (measured on an H100: 2 ulps; 1 sample
#: of 14,400 on the bunny at 160×90).
DEPTH_ULPS_ELSEWHERE = 4
OTHER_TEXEL_SHARE_ELSEWHERE = 1e-3


def _same(device, scene):
    lanes = _prepared(device, scene, None)
    one_by_one = _prepared(device, scene, {"PREPARE_ONE_BY_ONE": 1})
    np.testing.assert_array_equal(lanes[0].view(np.int32), one_by_one[0].view(np.int32))
    if TEST_ON_POCL:
        np.testing.assert_array_equal(lanes[1], one_by_one[1])
        np.testing.assert_array_equal(lanes[2], one_by_one[2])  # the same texels marked read
        return lanes
    texel, texel_alone = lanes[1][:, 0], one_by_one[1][:, 0]
    other = texel != texel_alone
    assert other.mean() <= OTHER_TEXEL_SHARE_ELSEWHERE, f"{other.sum()} of {other.size} samples read another texel"
    np.testing.assert_array_equal(texel < 0, texel_alone < 0)  # the same samples need no texel
    # depths are positive floats: their bits order like them
    ulps = np.abs(lanes[1][~other, 1].astype(np.int64) - one_by_one[1][~other, 1])
    assert ulps.max() <= DEPTH_ULPS_ELSEWHERE, f"sample depths differ by {ulps.max()} ulps"
    return lanes


@pytest.mark.parametrize("name", ["demo", "bunny", "behind", "sun"])
def test_bench_scenes(device, name):
    scene = load_scene(SCENES / f"{name}.yaml", overrides=["image.width=160", "image.height=90"])
    visible, _, _ = _same(device, scene)
    assert (visible == structs.VISIBILITY_PENDING).any()  # the lanes answered some samples with a texel


@pytest.mark.parametrize("kind", LIGHTS)
def test_every_light_type_and_a_ragged_end(device, kind):
    scene = make_scene(_triangles(), [LIGHTS[kind]], width=37, height=23, shadow_map=64)
    _same(device, scene)


def test_several_lights_and_samples(device):
    scene = make_scene(_triangles(), list(LIGHTS.values()), width=24, height=16, spp=4, shadow_map=64)
    _same(device, scene)


def _image(device, scene, monkeypatch, defines):
    """The frame with the decision kernel built with `defines` (None: as it ships)."""
    real = Device.kernel

    def kernel(self, stage_name, name, extra=None):
        if (stage_name, name) == ("visibility", "visibility") and defines:
            extra = {**(extra or {}), **defines}
        return real(self, stage_name, name, extra)

    monkeypatch.setattr(Device, "kernel", kernel)
    image = Renderer(device, reuse=False).render(scene).image
    monkeypatch.setattr(Device, "kernel", real)
    return image


@pytest.mark.parametrize("name", ["demo", "behind", "sun"])
def test_the_decision_in_lanes_gives_the_same_image(device, monkeypatch, name):
    scene = load_scene(SCENES / f"{name}.yaml", overrides=["image.width=160", "image.height=90"])
    np.testing.assert_array_equal(_image(device, scene, monkeypatch, None),
                                  _image(device, scene, monkeypatch, {"DECIDE_ONE_BY_ONE": 1}))


@pytest.mark.parametrize("kind", LIGHTS)
def test_the_decision_for_every_light_type(device, monkeypatch, kind):
    scene = make_scene(_triangles(), [LIGHTS[kind]], width=37, height=23, spp=2, shadow_map=64)
    np.testing.assert_array_equal(_image(device, scene, monkeypatch, None),
                                  _image(device, scene, monkeypatch, {"DECIDE_ONE_BY_ONE": 1}))


def test_a_frame_narrower_than_the_lanes(device):
    # 5 pixels wide: a run of 8 samples spans rows, so the lanes divide per lane (cl/lanes.h
    # sample_pixel_lanes); the answers must still be prepare_entry's.
    scene = make_scene(_triangles(), [LIGHTS["point"]], width=5, height=7, shadow_map=64)
    visible, _, _ = _same(device, scene)
    assert (visible == structs.VISIBILITY_PENDING).any() or (visible == 0.0).any()
