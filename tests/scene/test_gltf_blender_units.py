"""Lights as Blender 4.5's own glTF exporter writes them, read back in Cycles' units
(clrays/scene/gltf.py `_light`, docs/scene-format.md "Blender's lighting modes").

The JSON below is copied from real exports (bpy 4.5.15, `bpy.ops.export_scene.gltf` with
export_lights=True and each lighting mode) of a Blender scene holding a 1000 W point light
at (0.6, 0.4, 3) pointing down, two 2000 W spots at (0, 0, 4.5) pointing down with
spot_size 70° (spot_blend 0 and 0.15), and a 5 W/m² sun shining from (-4, 1, 5) towards
(0, 0, 1), every radius and angle 0. Scenes with the point, a hard spot and the sun,
rendered in Cycles 4.5 (direct light, single scattering in a homogeneous isotropic fog, the
camera's clip start 1 mm) and by clrays (`exact`) from the SPEC export, agree to a scale
within 0.1 % of 1 with nothing left beyond Cycles' noise (tools/blender_scenes.py)."""
from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

from clrays.scene import gltf
from clrays.scene.load import load_scene
from clrays.scene.model import DirectionalLight, PointLight, SpotLight

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("make_gltf_example", ROOT / "tools" / "make_gltf_example.py")
tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tool)
GltfBuilder = tool.GltfBuilder

#: extensions.KHR_lights_punctual.lights of the default (SPEC) export, as written.
EXPORTED_LIGHTS = """[{"color": [1, 1, 1], "intensity": 54351.41306588226, "type": "point", "name": "point"},
    {"color": [1, 1, 1], "intensity": 108702.82613176452, "spot": {"innerConeAngle": 0.6108652353286743,
     "outerConeAngle": 0.6108652353286743}, "type": "spot", "name": "spot_hard"},
    {"color": [1, 1, 1], "intensity": 108702.82613176452, "spot": {"innerConeAngle": 0.5192354463883326,
     "outerConeAngle": 0.6108652353286743}, "type": "spot", "name": "spot_soft"},
    {"color": [1, 1, 1], "intensity": 3415, "type": "directional", "name": "sun"}]"""
#: The lights' `intensity` in each lighting mode, as written (the rest of each light is the same).
EXPORTED_INTENSITIES = {"SPEC": [54351.41306588226, 108702.82613176452, 108702.82613176452, 3415],
                        "COMPAT": [79.57747154594767, 159.15494309189535, 159.15494309189535, 5],
                        "RAW": [1000, 2000, 2000, 5]}
#: The light nodes of the same export (every mode writes the same; Blender's Z up is glTF's Y up).
EXPORTED_NODES = """[
    {"extensions": {"KHR_lights_punctual": {"light": 0}}, "name": "point",
     "rotation": [-0.7071068286895752, 0, 0, 0.7071068286895752],
     "translation": [0.6000000238418579, 3, -0.4000000059604645]},
    {"extensions": {"KHR_lights_punctual": {"light": 1}}, "name": "spot_hard",
     "rotation": [-0.7071068286895752, 0, 0, 0.7071068286895752], "translation": [0, 4.5, 0]},
    {"extensions": {"KHR_lights_punctual": {"light": 2}}, "name": "spot_soft",
     "rotation": [-0.7071068286895752, 0, 0, 0.7071068286895752], "translation": [0, 4.5, 0]},
    {"extensions": {"KHR_lights_punctual": {"light": 3}}, "name": "sun",
     "rotation": [-0.23119334876537323, -0.7304713726043701, -0.2961069643497467, 0.5703349113464355],
     "translation": [-4, 5, -1]}]"""

POINT_WATTS, SPOT_WATTS, SUN_IRRADIANCE = 1000.0, 2000.0, 5.0
#: The light_scale docs/scene-format.md gives for each non-default mode: (points and spots, suns).
MODE_SCALES = {"SPEC": (1.0, 1.0), "COMPAT": (683.0, 683.0), "RAW": (683.0 / (4 * math.pi), 683.0)}


def _export(tmp_path, mode: str, light_scale: float):
    """The exported lights and their nodes over a floor, loaded with this light_scale."""
    b = GltfBuilder()
    b.node(mesh=b.mesh([[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], [[0, 2, 1], [0, 3, 2]]))
    for light, intensity in zip(json.loads(EXPORTED_LIGHTS), EXPORTED_INTENSITIES[mode]):
        b.light(**{**light, "intensity": intensity})
    for node in json.loads(EXPORTED_NODES):
        b.node(**node)
    path = tmp_path / f"blender_{mode}.glb"
    path.write_bytes(b.glb())
    return load_scene(path, [f"gltf.light_scale={light_scale!r}"]).lights


def test_blenders_default_export_reads_back_as_cycles_renders_it(tmp_path):
    """SPEC: the point and spots are P / 4π W/sr (Cycles' radiant intensity of a P W point, a spot
    as the point of its power), the sun 5 W/m²; positions, axes and the cone (half of spot_size)
    as Blender placed them; spot_blend 0 is a hard cone, 0.15 the glTF falloff from
    35° × (1 − 0.15) to 35°."""
    point, hard, soft, sun = _export(tmp_path, "SPEC", 1.0)
    assert isinstance(point, PointLight) and isinstance(hard, SpotLight) and isinstance(soft, SpotLight)
    assert isinstance(sun, DirectionalLight)
    np.testing.assert_allclose(point.intensity, [POINT_WATTS / (4 * math.pi)] * 3, rtol=1e-12)
    np.testing.assert_allclose(hard.intensity, [SPOT_WATTS / (4 * math.pi)] * 3, rtol=1e-12)
    np.testing.assert_allclose(soft.intensity, hard.intensity, rtol=0)
    np.testing.assert_allclose(sun.irradiance, [SUN_IRRADIANCE] * 3, rtol=1e-12)

    np.testing.assert_allclose(point.position, [0.6, 3.0, -0.4], atol=1e-6)  # Blender (0.6, 0.4, 3)
    np.testing.assert_allclose(hard.position, [0.0, 4.5, 0.0], atol=1e-6)
    np.testing.assert_allclose(hard.direction, [0.0, -1.0, 0.0], atol=1e-6)
    blender_sun = np.array([0.0, 0.0, 1.0]) - np.array([-4.0, 1.0, 5.0])
    np.testing.assert_allclose(sun.direction, np.array([blender_sun[0], blender_sun[2], -blender_sun[1]])
                               / np.linalg.norm(blender_sun), atol=1e-6)
    assert hard.cone_deg == pytest.approx(35.0, abs=1e-5) and hard.texture is None
    assert soft.cone_deg == pytest.approx(35.0, abs=1e-5) and soft.texture is not None


@pytest.mark.parametrize("mode", ["COMPAT", "RAW"])
def test_the_other_lighting_modes_with_their_documented_light_scale(tmp_path, mode):
    """Unitless (COMPAT) with light_scale 683, and Raw with 683 / 4π for points and spots and 683
    for a sun, read as the default export does."""
    reference = _export(tmp_path, "SPEC", 1.0)
    punctual_scale, sun_scale = MODE_SCALES[mode]
    point, hard, soft, _ = _export(tmp_path, mode, punctual_scale)
    for light, expected in zip((point, hard, soft), reference):
        np.testing.assert_allclose(light.intensity, expected.intensity, rtol=1e-12)
    np.testing.assert_allclose(_export(tmp_path, mode, sun_scale)[3].irradiance, reference[3].irradiance, rtol=1e-12)


# --------------------------------------------------------------------------- the spot's blend

#: `asset` of the same export, as written.
EXPORTED_ASSET = {"generator": "Khronos glTF Blender I/O v4.5.51", "version": "2.0"}
SPOT_SOFT = 2  # its index in EXPORTED_LIGHTS: spot_size 70°, spot_blend 0.15


def _soft_spot(tmp_path, asset: dict, outer: float | None = None):
    """The exported soft spot, alone over a floor, in a file with this `asset` (and this outer cone)."""
    b = GltfBuilder()
    b.doc["asset"] = dict(asset)
    b.node(mesh=b.mesh([[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], [[0, 2, 1], [0, 3, 2]]))
    light = json.loads(EXPORTED_LIGHTS)[SPOT_SOFT]
    if outer is not None:
        light["spot"] = {"innerConeAngle": outer * 0.85, "outerConeAngle": outer}
    b.light(**light)
    b.node(**{**json.loads(EXPORTED_NODES)[SPOT_SOFT], "extensions": {"KHR_lights_punctual": {"light": 0}}})
    path = tmp_path / "soft.glb"
    path.write_bytes(b.glb())
    return load_scene(path).lights[0]


def test_cycles_spot_blend_by_hand():
    """Blender's falloff of a 70° spot of blend 0.15 as exported (inner = outer × 0.85): Cycles fades
    in over the outer 0.15 × (1 − cos 35°) of cosθ along smoothstep: 0 at 35°, 0.15625 a quarter
    of the way in, ½ halfway, 1 from there on; the spec's curve, from 29.75°, is dimmer there."""
    spot = json.loads(EXPORTED_LIGHTS)[SPOT_SOFT]["spot"]
    inner, outer = spot["innerConeAngle"], spot["outerConeAngle"]
    assert inner == pytest.approx(outer * (1 - 0.15), rel=1e-7)
    ring = 0.15 * (1 - math.cos(outer))
    cosines = math.cos(outer) + ring * np.array([-0.5, 0.0, 0.25, 0.5, 1.0, 1.5])
    np.testing.assert_allclose(gltf.spot_attenuation(cosines, inner, outer, "blender"),
                               [0, 0, 0.15625, 0.5, 1, 1], atol=1e-12)
    halfway = (cosines[3] - math.cos(outer)) / (math.cos(inner) - math.cos(outer))
    assert gltf.spot_attenuation(cosines[3], inner, outer) == pytest.approx(halfway ** 2, rel=1e-12)
    assert halfway ** 2 < 0.5 / 2


def test_a_file_blender_wrote_gets_cycles_falloff_and_others_the_specs(tmp_path):
    """The soft spot of Blender's export, looked up as every method looks it up, follows Cycles'
    blend (a render of it matches Cycles within its noise, tools/blender_scenes.py); the same
    light in a file another exporter wrote has the spec's falloff texture."""
    from clrays.physics.light_texture import light_texture

    inner, outer = 0.5192354463883326, 0.6108652353286743
    spot = _soft_spot(tmp_path, EXPORTED_ASSET)
    assert isinstance(spot, SpotLight) and spot.cone_deg == pytest.approx(35.0, abs=1e-5)
    rng = np.random.default_rng(5)
    angles, azimuths = rng.uniform(0, outer, 4000), rng.uniform(0, 2 * math.pi, 4000)
    directions = np.stack([np.sin(angles) * np.cos(azimuths), -np.cos(angles), np.sin(angles) * np.sin(azimuths)], 1)
    looked_up = light_texture(spot, spot.position + directions * 3.0)[:, 0]
    cycles = gltf.spot_attenuation(np.cos(angles), inner, outer, "blender")
    # bilinear between texels 0.11° apart: within 2e-3 where smoothstep's curvature jumps
    assert np.abs(looked_up - cycles).max() < 2e-3
    assert np.abs(looked_up - gltf.spot_attenuation(np.cos(angles), inner, outer)).max() > 0.3  # not the spec's

    other = _soft_spot(tmp_path, {"generator": "another exporter", "version": "2.0"})
    assert other.texture is gltf.falloff_texture(inner, outer)  # the spec's, shared


def test_a_wide_soft_spot_blender_wrote_keeps_cycles_falloff_in_its_cube(tmp_path):
    """Wider than 85°, the spot is a point light whose cube texture carries the falloff: Cycles'
    for a file Blender wrote, kept when an animated node turns it."""
    outer = math.radians(88.0)
    light = _soft_spot(tmp_path, EXPORTED_ASSET, outer)
    assert isinstance(light, PointLight) and light.texture.falloff == "blender"
    assert light.texture.aimed(np.array([1.0, 0.0, 0.0])).falloff == "blender"
    # the -Y face's centre texel looks down the spot's axis, in the full beam; its ring of Cycles' fade
    # lies at cosθ ∈ [cos 88°, cos 88° + 0.15 (1 − cos 88°)], within the cube
    assert light.texture.texels[3 * light.texture.width + light.texture.width // 2,
                                light.texture.width // 2, 0] == pytest.approx(1.0, abs=1e-3)
