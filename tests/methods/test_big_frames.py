"""Big frames: a frame the device cannot hold is refused in one line before any device
allocation (session.check_device_memory); a 4K frame renders with both GPU methods
within the memory it is predicted to need (slow: bench/RESULTS.md, "Memory: big frames")."""
from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np
import pytest

from clrays.device import Device
from clrays.errors import ClraysError
from clrays.inputs import frame_inputs
from clrays.scene.load import load_scene
from clrays.session import Renderer, check_device_memory, frame_buffer_bytes
from conftest import TEST_DEVICE, run_cli

DEMO = "scenes/demo.yaml"
UHD = ["image.width=3840", "image.height=2160"]


def test_a_frame_over_the_largest_allocation_is_refused_before_allocating(tmp_path):
    # 4K at 4096 samples per pixel: 34 G samples, far beyond any device's largest buffer.
    renderer = Renderer(Device(TEST_DEVICE), reuse=False)
    scene = load_scene(DEMO, UHD + ["image.spp=4096"])
    with pytest.raises(ClraysError, match=r"demo\.yaml: the frame \(3840×2160 at 4096 spp, 1 light\(s\) with 1024² "
                                          r"shadow maps\) needs a \d+ MiB buffer for the in-scattering, more than the "
                                          r"device's largest allocation of \d+ MiB"):
        renderer.render(scene)
    assert renderer.device.allocated_bytes == 0  # refused before the first buffer
    code, out = run_cli("render", DEMO, "-o", tmp_path / "big.png", "--set", "image.width=3840",
                        "--set", "image.height=2160", "--set", "image.spp=4096")
    assert code == 1 and len(out.strip().splitlines()) == 1 and "largest allocation" in out, out
    assert not (tmp_path / "big.png").exists()


def test_a_frame_over_global_memory_names_the_total_and_the_limit():
    # The device's limits, not its buffers, decide: the same frame against a device that
    # reports 768 MiB of memory in 512 MiB buffers (the sum is checked after the largest;
    # 1.9 GiB with epipolar sampling's line samples and fix-up list, the texels the visibility
    # stage reads and the shadow map's packed keys, which it keeps for rectify).
    scene = load_scene(DEMO, UHD + ["image.spp=4"])
    needs = frame_buffer_bytes(frame_inputs(scene))
    assert max(size for _, size in needs) < 512 * 2**20 < 768 * 2**20 < sum(size for _, size in needs)
    small = SimpleNamespace(name="a small device", device=SimpleNamespace(max_mem_alloc_size=512 * 2**20,
                                                                          global_mem_size=768 * 2**20))
    with pytest.raises(ClraysError, match=r"the frame \(3840×2160 at 4 spp.*\) needs 1\.9 GiB of device memory, "
                                          r"more than the device's 0\.8 GiB \(a small device\)"):
        check_device_memory(small, frame_inputs(scene))


@pytest.mark.slow
@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_4k_renders_within_its_predicted_memory(method):
    """3840×2160 of the demo. Measured on the 2-core PoCL machine under a load of 6-8:
    minmax 25 s (this test) to 47 s, raymarch 409 s (bench/RESULTS.md, "Memory: big frames")."""
    renderer = Renderer(Device(TEST_DEVICE), reuse=False)
    scene = load_scene(DEMO, UHD + [f"render.method={method}"])
    start = time.perf_counter()
    result = renderer.render(scene)
    print(f"4K {method}: {time.perf_counter() - start:.1f} s, device memory {result.device_bytes / 2**20:.0f} MiB")
    assert result.image.shape == (2160, 3840, 3) and np.isfinite(result.image).all() and result.image.max() > 0
    predicted = sum(size for _, size in frame_buffer_bytes(frame_inputs(scene)))
    assert result.device_bytes <= min(1.05 * predicted, renderer.device.device.global_mem_size)
