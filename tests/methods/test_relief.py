"""Relief objects drawn by their pre-warp against the same relief as a triangle mesh
(`clrays relief-to-mesh`), on the lattice window of scenes/lattice.yaml and on a field
of Gaussian bumps, for minmax and raymarch, from in front, 60° off axis and grazing
(docs/design.md, "Relief objects"); the device's warp against numpy's; holes; a relief
seen from behind its base plane."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from clrays import Renderer
from clrays.device import StageTimer
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.reference.prewarp import Viewer, prewarp_two_pass
from clrays.scene.load import load_scene, parse_scene
from clrays.scene.relief import relief_to_mesh, relief_triangles
from clrays.stages.relief import ReliefDrawer, place_reliefs

ROOT = Path(__file__).resolve().parents[2]
LATTICE = ROOT / "scenes" / "lattice.yaml"

BUMPS = """version: 1
image: {{width: 80, height: 60}}
camera: {{position: {position}, look_at: [0, 0.1, 0], up: [0, 0.6, -0.8], fov_deg: 50, far: 20}}
lights: [{{type: spot, position: [1.5, 3.5, 1.0], direction: [-0.35, -1, -0.2], cone_deg: 40, intensity: 12}}]
medium: {{sigma_s: 0.08, sigma_a: 0.01}}
objects:
  - {{type: plane, center: [0, -0.6, 0], normal: [0, 1, 0], size: 8, segments: 1, albedo: 0.6}}
  - {{type: relief, center: [0, 0, 0], normal: [0, 1, 0], up: [0, 0, -1], size: [2.5, 2.5], depth_map: bumps.npy,
     height: 0.45, albedo: [0.7, 0.6, 0.5]}}
"""


def bump_field(size: int = 48, seed: int = 3) -> np.ndarray:
    """Gaussian bumps of random centres and widths, in [0, 1]: smooth slopes."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] + 0.5
    field = np.zeros((size, size))
    for _ in range(7):
        cx, cy = rng.uniform(0.15, 0.85, 2) * size
        width = rng.uniform(0.06, 0.16) * size
        field += np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * width ** 2))
    return field / field.max()


def _view(centre, normal, side, angle_deg, distance):
    """A camera position `angle_deg` off the relief's normal, `side` its tilt direction."""
    angle = math.radians(angle_deg)
    return [float(p) for p in np.asarray(centre) + distance * (math.cos(angle) * np.asarray(normal)
                                                  + math.sin(angle) * np.asarray(side))]


def _as_mesh(scene_path: Path, tmp_path: Path, overrides, relief_index: int, albedo):
    """The scene with its relief replaced by the mesh `relief_to_mesh` writes (of the same
    albedo: the loader reads no colours from a mesh file)."""
    mesh = tmp_path / "relief.ply"
    relief_to_mesh(scene_path, mesh, relief_index, overrides)
    return load_scene(scene_path, list(overrides) + [
        f"objects.{relief_index}={{type: mesh, file: {mesh}, normals: flat, albedo: {albedo}}}"])


def _compare(relief_scene, mesh_scene, method: str):
    session = Renderer(reuse=False)
    image = session.render(relief_scene, method).image
    reference = session.render(mesh_scene, method).image
    edges = depth_edges(depth_map(mesh_scene))
    return image_error(image, reference, exclude=edges), image, reference


VIEWS = {"front": 0.0, "60deg": 60.0, "grazing": 80.0}


@pytest.mark.parametrize("method", ["minmax", "raymarch"])
@pytest.mark.parametrize("view", list(VIEWS))
def test_bump_field_relief_matches_its_mesh(tmp_path, method, view):
    np.save(tmp_path / "bumps.npy", bump_field())
    position = _view([0, 0.1, 0], [0, 1, 0], [0.8, 0, 0.6], VIEWS[view], 3.2)
    path = tmp_path / "bumps.yaml"
    path.write_text(BUMPS.format(position=[round(p, 6) for p in position]))
    error, _, _ = _compare(load_scene(path), _as_mesh(path, tmp_path, (), 1, [0.7, 0.6, 0.5]), method)
    assert error.pixels > 1000
    assert error.rmse < 0.01, f"{view}, {method}: {error}"


@pytest.mark.slow
@pytest.mark.parametrize("method", ["minmax", "raymarch"])
@pytest.mark.parametrize("view", list(VIEWS))
def test_lattice_relief_matches_its_mesh(tmp_path, method, view):
    # From inside the room, towards the window's centre (0, 2.5, -4.08), at 3.6 units.
    position = _view([0, 2.5, -4.08], [0, 0, 1], [1, 0, 0], VIEWS[view], 3.6)
    overrides = [f"camera.position={[round(p, 6) for p in position]}", "camera.look_at=[0, 2.5, -4.08]",
                 "image.width=96", "image.height=72"]
    error, _, _ = _compare(load_scene(LATTICE, overrides), _as_mesh(LATTICE, tmp_path, overrides, 8, [0.55, 0.4, 0.28]), method)
    assert error.pixels > 1000
    assert error.rmse < 0.01, f"{view}, {method}: {error}"
