"""A glTF spot's cone falloff (KHR_lights_punctual's smooth attenuation between the inner
and outer angles, carried as a light texture: clrays/scene/gltf.py) in every method: each
follows `exact` with that falloff within 0.5 % relative RMSE, in the volume (black
surfaces) and on surfaces (no medium), at 96×64."""
from __future__ import annotations

import dataclasses
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

import clrays
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.scene.load import parse_scene

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("make_gltf_example", ROOT / "tools" / "make_gltf_example.py")
tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tool)

SCENE = """
version: 1
image: {width: 96, height: 64}
camera: {position: [0, 2.5, 7], look_at: [0, 1, 0], far: 15}
gltf: {file: spot.glb}
medium: MEDIUM
"""
FOG = "{sigma_s: 0.1, sigma_a: 0.02, phase: {type: hg, g: 0.3}}"


def _spot_file(folder: Path) -> Path:
    """A floor and a box under a spot with a wide soft edge: inner 8°, outer 35°."""
    b = tool.GltfBuilder()
    b.mesh([[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]], [[0, 2, 1], [0, 3, 2]], colour=(0.8, 0.8, 0.8))
    vertices, normals, faces = tool.box([0.4, 0.3, 0.4])
    b.mesh(vertices, faces, normals=normals, colour=(0.7, 0.6, 0.5))
    b.node(mesh=0)
    b.node(mesh=1, translation=[0.3, 1.2, 0.1])
    spot = b.light(type="spot", intensity=60.0 * 683,  # cd: 60 W/sr
                   spot={"innerConeAngle": math.radians(8), "outerConeAngle": math.radians(35)})
    b.node(extensions=tool.light_ref(spot), translation=[0.2, 5, 0.3], rotation=tool.quaternion([1, 0, 0.1], -85))
    path = folder / "spot.glb"
    path.write_bytes(b.glb())
    return path


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("spot")
    _spot_file(folder)
    fog = parse_scene(SCENE.replace("MEDIUM", FOG), folder / "spot.yaml")
    volume = dataclasses.replace(fog, geometry=dataclasses.replace(
        fog.geometry, albedo=np.zeros_like(fog.geometry.albedo)))  # black surfaces: the volume alone
    surface = parse_scene(SCENE.replace("MEDIUM", "{sigma_s: 0, sigma_a: 0}"), folder / "spot.yaml")
    assert fog.lights[0].texture is not None and fog.lights[0].cone_deg == pytest.approx(35)
    return {name: (scene, clrays.render(scene, method="exact"))
            for name, scene in (("volume", volume), ("surface", surface))}


@pytest.mark.parametrize("part", ["volume", "surface"])
@pytest.mark.parametrize("method", ["minmax", "raymarch", "volume_moments"])
def test_a_soft_spot_follows_exact_in_every_method(scenes, part, method):
    scene, exact = scenes[part]
    image = clrays.render(scene, method=method, reuse=False)
    error = image_error(image, exact, depth_edges(depth_map(scene)))
    print(f"soft spot, {part}, {method} against exact: {error}")
    assert error.pixels > 1000 and error.rmse < 0.005, f"{method}, {part}: {error}"
