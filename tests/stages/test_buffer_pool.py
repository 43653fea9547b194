"""The CPU device's buffer pool (clrays.device, POOLED_BYTES): a frame's large buffers are
the ones an earlier frame let go of, so the images must not depend on what those held,
an image the host still maps must not be handed out again, and the pool must not keep
what a sequence no longer needs."""
from pathlib import Path

import numpy as np
import pytest

from clrays.device import POOL_HELD_FRAMES, POOL_WINDOW, Device
from clrays.scene.load import load_scene
from clrays.session import Renderer
from conftest import TEST_DEVICE

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _scene(name: str, width: int = 160, height: int = 90):
    return load_scene(SCENES / f"{name}.yaml", overrides=[f"image.width={width}", f"image.height={height}"])


@pytest.fixture
def pooled_renderer():
    renderer = Renderer(Device(TEST_DEVICE), reuse=False)
    if renderer.device.pool_bytes() is None:
        pytest.skip("only a CPU device pools its buffers")
    return renderer


def test_a_second_frame_takes_the_first_frames_buffers(pooled_renderer):
    scene = _scene("demo")
    pooled_renderer.render(scene)
    managed, active = pooled_renderer.device.pool_bytes()
    assert managed > 0 and active < managed  # the frame's buffers went back to the pool
    pooled_renderer.render(scene)
    assert pooled_renderer.device.pool_bytes()[0] == managed  # and the second frame took them again


#: Frames that take every stage between them: the bench scenes, translucent films and
#: layers, textured lights, a relief-free lattice, the other methods, the per-pixel walk,
#: several samples per pixel and the filtered surface shadows.
FRAMES = {
    "demo": ("demo", ()), "behind": ("behind", ()), "sun": ("sun", ()),
    "glass_row": ("glass_row", ()), "stained_glass": ("stained_glass", ()), "gobo": ("gobo", ()),
    "lattice": ("lattice", ()),
    "raymarch": ("demo", ("render.method=raymarch", "render.steps=32")),
    "volume_moments": ("behind", ("render.method=volume_moments",)),
    "pixel walk": ("sun", ("render.sampling=pixel",)),
    "4 spp": ("demo", ("image.spp=4",)),
    "filtered": ("behind", ("render.surface_shadows=filtered",)),
}


def _frame(name: str):
    scene, overrides = FRAMES[name]
    return load_scene(SCENES / f"{scene}.yaml", overrides=["image.width=96", "image.height=54", *overrides])


def test_images_do_not_depend_on_what_earlier_frames_left_in_the_buffers(pooled_renderer):
    """Each frame after the others, in one pool, against the same frame on a fresh device:
    a kernel reading a buffer before its frame wrote it would see the earlier frames'
    values, where a fresh device's pages are zero."""
    fresh = {name: Renderer(Device(TEST_DEVICE), reuse=False).render(_frame(name)).image for name in FRAMES}
    for name in [*FRAMES, *reversed(FRAMES)]:
        np.testing.assert_array_equal(pooled_renderer.render(_frame(name)).image, fresh[name], err_msg=name)


def test_a_kept_image_survives_later_frames(pooled_renderer):
    first = pooled_renderer.render(_scene("demo")).image
    kept = first.copy()
    for name in ("behind", "sun", "demo"):
        pooled_renderer.render(_scene(name))
    np.testing.assert_array_equal(first, kept)


def test_the_pool_keeps_its_buffers_through_cached_frames():
    """A frame the cache answers allocates nothing, and must not empty the pool that the
    next full frame takes from."""
    renderer = Renderer(Device(TEST_DEVICE), reuse=True)
    if renderer.device.pool_bytes() is None:
        pytest.skip("only a CPU device pools its buffers")
    scene = _scene("demo")
    renderer.render(scene)
    managed = renderer.device.pool_bytes()[0]
    assert renderer.render(scene).device_bytes == 0  # the cache's frame
    assert renderer.device.pool_bytes()[0] == managed


def test_the_pool_lets_go_of_a_larger_frames_buffers(pooled_renderer):
    pooled_renderer.render(_scene("demo", 640, 360))
    large = pooled_renderer.device.pool_bytes()[0]
    for _ in range(POOL_WINDOW):  # until the large frame leaves the window
        small = pooled_renderer.render(_scene("demo", 64, 36))
    managed, active = pooled_renderer.device.pool_bytes()
    assert managed - active <= POOL_HELD_FRAMES * small.device_bytes < large
