"""The device buffers a frame is predicted to need (clrays.frame_memory, from each stage's
declarations in clrays.buffers) are the ones its stages allocate: a frame's bytes under
each declaration's name (Device.allocated_by_name) equal the prediction, or stay within it
where the declaration is a bound (the films a ray meets)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from clrays.buffers import BufferDecl, FrameSizes
from clrays.device import Device
from clrays.frame_memory import frame_buffer_bytes, frame_buffers
from clrays.inputs import frame_inputs
from clrays.scene.load import load_scene
from clrays.session import Renderer
from clrays.stages.raster import _atomic64
from conftest import TEST_DEVICE


@pytest.fixture(scope="module")
def renderer():
    return Renderer(Device(TEST_DEVICE), reuse=False)


@pytest.mark.parametrize("scene, overrides", [
    ("demo", ["image.width=96", "image.height=54"]),  # minmax, exact surface shadows, epipolar sampling
    ("demo", ["image.width=160", "image.height=90", "render.method=volume_moments"]),
    ("glass_pane", ["image.width=96", "image.height=54"]),  # translucent: layers, MBOIT's films
    ("bunny", ["image.width=64", "image.height=36", "image.spp=2", "render.surface_shadows=filtered"]),
])
def test_the_predicted_buffers_are_the_ones_allocated(renderer, scene, overrides):
    if not _atomic64(renderer.device):
        pytest.skip("the prediction counts the 64-bit keys of the one-pass raster, which this device lacks")
    loaded = load_scene(f"scenes/{scene}.yaml", overrides)
    result = renderer.render(loaded)
    assert np.isfinite(result.image).all()
    allocated = renderer.device.allocated_by_name
    predicted, bounds = {}, set()
    for _, decl, size in frame_buffers(frame_inputs(loaded)):
        predicted[decl.name] = predicted.get(decl.name, 0) + size
        if decl.bound:
            bounds.add(decl.name)
    assert set(allocated) <= set(predicted), "allocated by a declaration the prediction leaves out"
    exact = {name: size for name, size in predicted.items() if name not in bounds}
    assert {name: allocated.get(name, 0) for name in exact} == exact
    assert all(allocated.get(name, 0) <= predicted[name] for name in bounds)


def test_a_declaration_sizes_its_upload():
    sizes = FrameSizes(samples=4)
    decl = BufferDecl("one int per sample", 4, lambda sizes: sizes.samples)
    bound = BufferDecl("at most one int per sample", 4, lambda sizes: sizes.samples, bound=True)
    assert decl.nbytes(sizes) == bound.nbytes(sizes) == 16
    with pytest.raises(ValueError, match="one int per sample: 12 bytes to upload, declared 16"):
        decl.upload(None, np.zeros(3, np.int32), sizes)
    with pytest.raises(ValueError, match="at most one int per sample: 20 bytes to upload, declared 16"):
        bound.upload(None, np.zeros(5, np.int32), sizes)


def test_the_frame_bytes_name_every_light_held():
    # two lights, held at once with map shadows: each one's map, then both back to back
    scene = load_scene("scenes/demo.yaml", ["image.width=32", "image.height=18", "render.shadow_map=64",
                                            "render.surface_shadows=map"])
    scene = replace(scene, lights=scene.lights * 2)
    names = [name for name, _ in frame_buffer_bytes(frame_inputs(scene))]
    assert {"shadow map of light 0", "shadow map of light 1", "shadow maps of all lights together",
            "min-max tree of light 0", "min-max tree of light 1"} <= set(names)
