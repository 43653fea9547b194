"""The work-group shape clrays gives a CPU launch (clrays.device.spread_local_size):
divides the launch, leaves every compute unit work-groups to balance, and changes no bit
of a frame against the driver's own choice."""
import numpy as np
import pytest

from clrays.device import GROUPS_PER_UNIT, MAX_CPU_GROUP, spread_local_size
from clrays.scene.load import parse_scene
from clrays.session import Renderer


@pytest.mark.parametrize("shape", [(1,), (7,), (180,), (256,), (1000,), (65535,), (97, 3), (123, 1024), (5, 6, 7)])
@pytest.mark.parametrize("units", [1, 2, 16])
def test_a_shape_divides_the_launch_and_leaves_groups_to_balance(shape, units):
    local = spread_local_size(shape, units)
    assert len(local) == len(shape) and all(g % l == 0 for g, l in zip(shape, local))
    assert local[1:] == (1,) * (len(shape) - 1) and 1 <= local[0] <= MAX_CPU_GROUP
    groups = int(np.prod(shape)) // int(np.prod(local))
    # as many groups as asked for, or every item a group of its own along the first axis
    assert groups >= min(GROUPS_PER_UNIT * units, int(np.prod(shape))) or local[0] == 1


def test_a_device_with_smaller_work_groups_is_obeyed():
    assert spread_local_size((1 << 20,), 1, max_group=256) == (256,)
    assert spread_local_size((1 << 20,), 1) == (MAX_CPU_GROUP,)


def test_the_largest_divisor_is_taken():
    assert spread_local_size((180,), 2) == (2,)  # 180 / 64 rounds down to 2, which divides it
    assert spread_local_size((1000,), 2) == (10,)  # 1000 / 64 → 15; the largest divisor under it
    assert spread_local_size((127,), 2) == (1,)  # a prime: one item per group


SCENE = """version: 1
image: {width: 96, height: 54}
camera: {position: [0, 2, 8], look_at: [0, 1, 0], fov_deg: 50}
lights: [{type: point, position: [0.5, 5, 0.3], intensity: 40}]
medium: {sigma_s: 0.1, sigma_a: 0.01}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 12, albedo: 0.6}
  - {type: box, min: [-1, 0, -1], max: [1, 2, 1], albedo: 0.7}
  - {type: sphere, center: [2, 1, 1.5], radius: 0.8, albedo: 0.5}
"""


def test_spread_launches_give_the_bits_of_the_drivers_shapes(device):
    if not device._spread:
        pytest.skip(f"{device.name} is no CPU device: its launches keep the driver's shapes")
    scene = parse_scene(SCENE)
    spread = Renderer(device, reuse=False).render(scene).image
    device._spread = False
    try:
        drivers = Renderer(device, reuse=False).render(scene).image
    finally:
        device._spread = True
    np.testing.assert_array_equal(spread, drivers)
