"""The visibility stage draws its bound and writer maps only at the texels that a camera
sample's lit test reads (visibility_prepare's map_read and read_mask;
docs/design.md §4.6): at every one of them both maps must hold what drawing the whole
map gives, for every light of a frame (the second light's texels sit after the first's)."""
import numpy as np

from clrays.device import StageTimer
from clrays.inputs import frame_inputs, upload
from clrays.stages.raster import raster
from clrays.stages.visibility import visibility_bound, visibility_prepare
from conftest import DirectionalLight, PointLight, SpotLight, make_scene, v3
from test_visibility_bound import _triangles  # a floor, a box, a sub-texel wire, random triangles

LIGHTS = [
    PointLight(v3(0.4, 4.0, 0.3), np.full(3, 30.0)),
    SpotLight(v3(-1.0, 3.5, 2.0), v3(0.2, -0.8, -0.4) / np.linalg.norm([0.2, -0.8, -0.4]), 50.0, np.full(3, 30.0)),
    DirectionalLight(v3(-0.5, -0.8, 0.3) / np.linalg.norm([-0.5, -0.8, 0.3]), np.full(3, 3.0)),
]


def test_the_texels_read_hold_what_the_whole_maps_hold(device):
    scene = make_scene(_triangles(), LIGHTS, width=96, height=64, shadow_map=48)
    buffers = upload(device, frame_inputs(scene))
    timer = StageTimer()
    prepared = visibility_prepare(device, buffers, raster(device, buffers, timer), timer)
    inputs = buffers.inputs
    lights = len(LIGHTS)
    map_read = device.read(prepared.map_read, (inputs.samples, lights, 2), np.int32)[..., 0]
    texels = 0
    for index, (first_view, _) in enumerate(inputs.light_views):
        masked = visibility_bound(device, buffers, index, timer, prepared)
        whole = visibility_bound(device, buffers, index, timer)
        first = int(inputs.views[first_view]["depth_offset"])
        read = np.unique(map_read[:, index][map_read[:, index] >= 0]) - first  # this light's own addresses
        count = masked.texels
        assert read.size and read.min() >= 0 and read.max() < count, f"light {index}: texels read outside its maps"
        for name in ("bound", "writer"):
            drawn = device.read(getattr(masked, name), count, np.int32)[read]
            full = device.read(getattr(whole, name), count, np.int32)[read]
            np.testing.assert_array_equal(drawn, full, err_msg=f"light {index}: {name} map")
        texels += read.size
    assert texels > 1000  # the samples did read the maps
