"""shade's optional inputs are feature groups (clrays/stages/shade.py, cl/shade_features.h):
a frame hands shade the groups it has, and the kernel built with their defines takes its
own arguments and then exactly the groups' ones, in shade_features' order."""
from __future__ import annotations

import numpy as np
import pytest

from clrays.device import Device
from clrays.inputs import frame_inputs, upload
from clrays.scene.load import load_scene
from clrays.stages.features import feature_args, feature_defines
from clrays.stages.shade import LANES, Composite, LightTextures, PassTerms, SurfaceThrough, shade_features
from clrays.stages.translucency import Layers
from conftest import TEST_DEVICE

#: shade's own arguments (cl/shade.cl): frame, views, lights, the raster stage's four, the
#: triangles' four, offsets, the in-scattering, the visibility and the image.
OWN_ARGUMENTS = 14


@pytest.fixture(scope="module")
def device():
    return Device(TEST_DEVICE)


def _groups(device, scene: str, **extra):
    buffers = upload(device, frame_inputs(load_scene(f"scenes/{scene}.yaml", ["image.width=16", "image.height=9"])))
    return shade_features(device, buffers, **extra)


def test_a_frame_hands_shade_the_groups_it_has(device):
    assert _groups(device, "demo") == ()  # an untextured light, opaque objects
    assert [type(group) for group in _groups(device, "gobo")] == [LightTextures]
    layers = Layers(device.buffer(nbytes=16), device.buffer(nbytes=16), 2, 1)
    through = device.buffer(nbytes=16)
    groups = _groups(device, "demo", layers=layers, surface_through=through, films=("T", "in front"))
    assert [type(group) for group in groups] == [Layers, SurfaceThrough, Composite]
    assert feature_args(groups)[3:] == (through, np.int32(1), "T", "in front")
    assert feature_args(_groups(device, "demo", layers=layers))[4] == np.int32(0)  # (its answer not given)


@pytest.mark.parametrize("with_groups", [False, True])
def test_the_kernel_takes_its_own_arguments_then_the_groups(device, with_groups):
    buffer = device.buffer(nbytes=16)
    groups = (LightTextures(buffer, buffer), Layers(buffer, buffer, 2, 1), SurfaceThrough(buffer, True),
              Composite(buffer, buffer), PassTerms(buffer)) if with_groups else ()
    kernel = device.kernel("shade", "shade", feature_defines(groups, {"LANES": LANES}))
    assert kernel.num_args == OWN_ARGUMENTS + len(feature_args(groups))
