"""Kernels known to be fragile on some compilers, run on known data: the suite's cheap check
that the device in use builds them right (docs/design.md §4.5, "Wide vectors" and "Other
CPU runtimes").

- PoCL 3.0 (LLVM 14) on a CPU with AVX-512 miscompiled raster_any's 16-wide reduction: the
  flag came back set on an empty map.
- Intel's CPU compiler garbled the float3 radiance the row walk carries out of its loop when
  it ran several work-items in one vector: it landed in other channels and pixels.
"""
from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from clrays import structs
from clrays.device import kernel_dir
from clrays.stages.raster import raster_defines
from conftest import make_scene

EMPTY = np.uint32(int(structs.kernel_defines()["DEPTH_EMPTY"].rstrip("u"), 16))


def _any_depth(device, depth: np.ndarray) -> bool:
    texels = len(depth)
    flag = device.buffer(np.zeros(1, np.uint32))
    items = -(-texels // structs.RASTER_ANY_TEXELS)
    device.kernel("raster", "raster_any", raster_defines(device))(
        device.queue, (items,), None, device.buffer(depth), np.int32(texels), flag)
    return bool(device.read(flag, 1, np.uint32)[0])


@pytest.mark.parametrize("texels", [1, 255, 256, 257, 4096, 65539])
def test_raster_any_on_known_maps(device, texels):
    empty = np.full(texels, EMPTY, np.uint32)
    assert not _any_depth(device, empty)
    for where in sorted({0, texels // 2, texels - 1}):
        one = empty.copy()
        one[where] = np.float32(2.5).view(np.uint32)
        assert _any_depth(device, one), where


def test_no_kernel_uses_16_wide_vectors():
    # The construct PoCL 3.0 miscompiled with AVX-512 (its library's 512-bit vectors are
    # passed another way than the kernel's); 8-wide vectors are proven on both CPU types,
    # but not of 64-bit lanes: the raster rows pass's min of eight keys as one ulong8, also
    # 512 bits, lost most of its stores (docs/design.md §4.5, "Wide vectors").
    wide = re.compile(r"\b(?:u?char|u?short|u?int|u?long|float|double)16\b|\bv(?:load|store)16\b"
                      r"|\b(?:u?long|double)8\b")
    comments = re.compile(r"/\*.*?\*/|//[^\n]*", re.S)
    found = [path.name for path in sorted(kernel_dir().glob("*.[ch]*"))
             if wide.search(comments.sub("", path.read_text()))]
    assert not found


def test_the_row_walk_keeps_each_channel_and_pixel(renderer):
    # A fogged scene with no occluder and a directional light: every row is one lit run,
    # whose radiance has a closed form; red, green and blue differ (their σs), so a value
    # carried into another channel or pixel shows. Both samplings walk the rows; 56 × 40
    # gives work-groups wide enough for Intel's vectorizer (at 40 × 24 the walk came out
    # right without the fix).
    from clrays.scene.model import DirectionalLight, Phase

    direction = np.array([0.3, -1.0, -0.4]) / np.linalg.norm([0.3, -1.0, -0.4])
    sigma_s = np.array([0.08, 0.05, 0.02])
    for sampling in ("pixel", "epipolar"):
        scene = make_scene(lights=[DirectionalLight(direction, np.full(3, 2.0))], width=56, height=40, far=12.0,
                           sigma_s=0.08, sigma_a=0.02, phase=Phase("isotropic"), integrand="analytic",
                           sampling=sampling)
        scene = replace(scene, medium=replace(scene.medium, sigma_s=sigma_s))
        image = renderer.render(scene, "minmax").image[..., :3]
        sigma_t = sigma_s + 0.02
        expected = sigma_s * 2.0 / (4 * np.pi) * (1 - np.exp(-sigma_t * 12.0)) / sigma_t
        np.testing.assert_allclose(image, np.broadcast_to(expected, image.shape), rtol=1e-4, err_msg=sampling)
