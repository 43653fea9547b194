"""The host's waits for the device inside a frame (Device.host_waits): the counts that size
a launch (raster's and the bound passes' lists of big triangles, epipolar sampling's fix-up
list) are read on the device by the kernels that need them, the visible rays' β and γ ranges
stay there for the kernels that follow rectify, whether a light's map is empty is decided on
the host from the geometry, and the frame's statistics (SampleCounts) are read only when
asked for, after the image."""
import pickle
import sys
from pathlib import Path

import numpy as np
import pytest

from clrays.buffers import FrameSizes
from clrays.device import Device
from clrays.scene.load import load_scene
from clrays.stages.sampling import FIXUP_BLOCK, FIXUP_SCAN_ITEMS, SampleCounts, fixup_list

SCENES = Path(__file__).resolve().parents[2] / "scenes"
BENCH_SCENES = ("demo", "bunny", "behind", "sun")

#: Waits of a default frame of each bench scene at 96×54 (method minmax, epipolar
#: sampling, exact surface shadows) on a CPU device, each named by the function that waits:
#: - raster_passes (stages/raster.py): the lists' lengths of every view, before the rows
#:   passes, once for the camera and once for the shadow maps, 2 (on a GPU none:
#:   raster.raster_count_on_device, below);
#: - visibility (stages/visibility.py): the shadow rays' count and route, once the listed
#:   ways are enqueued: on a CPU device the host builds the BVH (on the host for reliefs)
#:   only where the route asks for it, 1 (on a GPU none: visibility.bvh_ahead, below);
#: - _read (session.py, PendingFrame.result): the image, whose read shade enqueued, 1.
#: None comes from epipolar sampling, or visibility's bound passes and rays' lists.
WAITS_96x54 = {"raster_passes": 2, "visibility": 1, "_read": 1}
FREE_OF_WAITS = ("map_is_empty", "rectify", "integrand", "epipolar_sampling", "fixup_list", "_bound_passes",
                 "ray_lists")
DEVICE_READS = ("read", "read_all", "read_in_place")


def _waits_by_caller(monkeypatch) -> list[list[str]]:
    """Every Device.wait from now on that waits (not one deferred to the frame's result), as
    the names of the functions on the stack."""
    stacks = []
    wait = Device.wait

    def recording(self, event):
        if self._deferred_waits is not None:
            return wait(self, event)
        frame, names = sys._getframe(1), []
        while frame is not None:
            names.append(frame.f_code.co_name)
            frame = frame.f_back
        stacks.append(names)
        return wait(self, event)

    monkeypatch.setattr(Device, "wait", recording)
    return stacks


@pytest.mark.parametrize("name", BENCH_SCENES)
def test_a_default_frame_waits_only_where_listed(renderer, monkeypatch, name):
    scene = load_scene(SCENES / f"{name}.yaml", overrides=["image.width=96", "image.height=54"])
    renderer.render(scene, reuse=False)  # (kernels built)
    stacks = _waits_by_caller(monkeypatch)
    result = renderer.render(scene, reuse=False)
    assert result.host_waits == sum(WAITS_96x54.values()), [names[:3] for names in stacks]
    callers = {}
    for names in stacks:
        caller = next(name for name in names if name not in DEVICE_READS)
        callers[caller] = callers.get(caller, 0) + 1
        assert not set(names) & set(FREE_OF_WAITS), names[:6]
    assert callers == WAITS_96x54


def test_sample_counts_are_read_without_a_wait(renderer, device):
    """Asked for after the frame, the counts are on the host already: no wait, the same
    values every time, and a pickled result (a dask worker's) carries them."""
    scene = load_scene(SCENES / "demo.yaml", overrides=["image.width=64", "image.height=36"])
    result = renderer.render(scene, reuse=False)
    waits = renderer.device.host_waits
    counts = result.samples
    assert counts.interpolated + counts.fixed_up == 64 * 36 * scene.image.spp
    assert 0 < counts.fixed_up and 0 < counts.computed
    assert renderer.device.host_waits == waits
    again = pickle.loads(pickle.dumps(result.without_pixels())).samples
    assert (again.computed, again.interpolated, again.fixed_up) == (counts.computed, counts.interpolated,
                                                                     counts.fixed_up)
    assert again == counts and repr(again) == repr(counts)
    assert counts + counts == SampleCounts(2 * counts.computed, 2 * counts.interpolated, 2 * counts.fixed_up)


@pytest.mark.parametrize("samples", [1, FIXUP_BLOCK, 3 * FIXUP_BLOCK + 5, (FIXUP_SCAN_ITEMS + 3) * FIXUP_BLOCK + 17])
def test_fixup_list_and_counts_match_numpy(device, samples):
    """fixup_count → fixup_offsets → fixup_list against numpy: the flagged samples in order,
    with their flags; the list's length and the walks' sum in `counts`. The largest case has
    more blocks than fixup_offsets has work-items (runs of two blocks)."""
    rng = np.random.default_rng(samples)
    flags = np.where(rng.random(samples) < 0.3, rng.integers(1, 4, samples), 0).astype(np.uint8)
    walks = rng.integers(0, 9, 1000, dtype=np.uint16)

    def run(name, global_size, local_size, *args):
        device.kernel("sampling", name, {"FIXUP_BLOCK": FIXUP_BLOCK, "FIXUP_SCAN_ITEMS": FIXUP_SCAN_ITEMS})(
            device.queue, global_size, local_size, *args)

    fixups, counts = fixup_list(device, device.buffer(flags), FrameSizes(samples=samples), device.buffer(walks), 997,
                                run)
    listed = np.flatnonzero(flags)
    computed, fixed_up = device.read(counts, 2, np.uint32)
    assert fixed_up == len(listed) and computed == int(walks[:997].sum())
    got = device.read(fixups, max(len(listed), 1), np.uint32)[:len(listed)]
    np.testing.assert_array_equal(got >> 2, listed)
    np.testing.assert_array_equal(got & 3, flags[listed])


def test_list_launches_give_the_same_image_in_either_shape(renderer, monkeypatch):
    """fix_up, and visibility's listed rays and marks, are launched over Device.list_launch
    of an upper bound (fix_up: the camera samples; the rays: the entries), each work-item
    taking a run of the list whose length the kernel reads: PoCL's few runs per work-item
    and a GPU's one item per work-item (the rest returning at once) give the same bits."""
    scene = load_scene(SCENES / "sun.yaml", overrides=["image.width=80", "image.height=45"])
    image = renderer.render(scene, reuse=False).image
    bounds = []
    list_launch = Device.list_launch

    def spy(self, bound):
        bounds.append(bound)
        return list_launch(self, bound)

    monkeypatch.setattr(Device, "list_launch", spy)
    assert np.array_equal(renderer.render(scene, reuse=False).image, image)
    samples = 80 * 45 * scene.image.spp
    assert bounds.count(samples) >= 2  # fix_up's, and the rays' (one light: an entry per sample)
    monkeypatch.setattr(Device, "list_launch", lambda self, bound: ((max(bound, 1),), None))
    assert np.array_equal(renderer.render(scene, reuse=False).image, image)


@pytest.mark.parametrize("name", BENCH_SCENES)
@pytest.mark.parametrize("size", [(32, 18), (160, 90)])
def test_a_gpus_frame_waits_once_for_the_same_image(renderer, monkeypatch, name, size):
    """As on a GPU: the rows passes read their lists' lengths on the device
    (raster.raster_count_on_device), and the BVH is built before the rays' route is known,
    its rays gated on the device (visibility.bvh_ahead), so the frame waits for its image
    alone; the image and the shadow rays counted are those of the frame that waits,
    whichever route the rays take (a thumbnail's lists at 32×18, the BVH at 160×90)."""
    from clrays.stages import raster, visibility

    scene = load_scene(SCENES / f"{name}.yaml", overrides=[f"image.width={size[0]}", f"image.height={size[1]}"])
    waiting = renderer.render(scene, reuse=False)
    monkeypatch.setattr(visibility, "bvh_ahead", lambda device: True)
    monkeypatch.setattr(raster, "raster_count_on_device", lambda device: True)
    ahead = renderer.render(scene, reuse=False)
    assert np.array_equal(ahead.image, waiting.image)
    assert ahead.shadow_rays == waiting.shadow_rays and ahead.shadow_rays > 0
    assert (waiting.host_waits, ahead.host_waits) == (sum(WAITS_96x54.values()), 1)
