"""Device.fill: a pattern of 4 or 8 bytes over the first bytes of a buffer, the same bytes
whether the driver fills it or, large fills on a CPU device, a kernel on every core."""
import numpy as np
import pytest

from clrays.device import PARALLEL_FILL_BYTES


@pytest.mark.parametrize("value", [np.uint32(0x7F800000), np.int32(-1), np.float32(0.0),
                                   np.uint64((0x7F800000 << 32) | 0xFFFFFFFF)])
@pytest.mark.parametrize("nbytes", [16, 4096, PARALLEL_FILL_BYTES, PARALLEL_FILL_BYTES + 8,
                                    3 * PARALLEL_FILL_BYTES + 24])
def test_a_fill_writes_its_pattern_and_nothing_past_it(device, value, nbytes):
    room = nbytes + 64
    before = np.frombuffer(np.random.default_rng(nbytes).bytes(room), np.uint8).copy()
    buffer = device.buffer(before)
    device.fill(buffer, value, nbytes).wait()
    after = device.read(buffer, room, np.uint8)
    expected = np.frombuffer(np.tile(np.asarray(value), nbytes // value.itemsize).tobytes(), np.uint8)
    np.testing.assert_array_equal(after[:nbytes], expected)
    np.testing.assert_array_equal(after[nbytes:], before[nbytes:])


def test_a_large_fill_on_a_cpu_device_runs_on_every_core(device):
    if not device.device.type & device.cl.device_type.CPU:
        pytest.skip("the driver's fill serves other devices")
    kernels = []
    built = device.kernel

    def kernel(stage, name, defines=None):
        kernels.append(name)
        return built(stage, name, defines)

    device.kernel = kernel
    try:
        device.fill(device.buffer(nbytes=PARALLEL_FILL_BYTES), np.uint32(1), PARALLEL_FILL_BYTES).wait()
        device.fill(device.buffer(nbytes=4096), np.uint32(1), 4096).wait()
    finally:
        del device.kernel
    assert kernels == ["fill_vectors"]


def test_a_buffer_read_in_place_holds_what_a_read_gives(device):
    """Device.read_in_place (shade's image): on a CPU device the buffer's memory mapped, not
    copied, the same values as a read, after a kernel wrote them, and writable."""
    values = np.random.default_rng(7).random((6, 5, 4), dtype=np.float32)
    buffer = device.buffer(values)
    device.fill(buffer, np.float32(0.5), 16 * 5)  # the first row, by the device, before the read
    expected = values.copy()
    expected[0] = 0.5
    image = device.read_in_place(buffer, (6, 5, 4), np.float32)
    np.testing.assert_array_equal(image, expected)
    image[..., :3] *= 2.0  # a caller's own use of its image
    if device.device.type & device.cl.device_type.CPU:
        assert image.base is not None  # a view of the mapping, no copy
