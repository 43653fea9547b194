"""Relief objects drawn by their pre-warp against the same relief as a triangle mesh
(`clrays relief-to-mesh`), on the lattice window of scenes/lattice.yaml and on a field
of Gaussian bumps, for minmax and raymarch, from in front, 60° off axis and grazing
(docs/design.md, "Relief objects"); the device's warp against numpy's; holes; a relief
seen from behind its base plane."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from clrays import Renderer, structs
from clrays.device import StageTimer
from clrays.inputs import frame_inputs, light_pass_inputs, upload
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.physics.prewarp import Viewer, prewarp_two_pass
from clrays.scene.camera import primary_rays
from clrays.scene.costs import with_derived_sizes
from clrays.scene.load import load_scene
from clrays.runs.relief_mesh import relief_to_mesh
from clrays.scene.relief import Relief, relief_frame, relief_record
from clrays.stages.raster import raster_camera, raster_shadow_map, read_shadow_depth
from clrays.scene.relief_placement import PlacedRelief
from clrays.stages.relief import ReliefDrawer, footprint

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
    print(f"bump field, {view}, {method}: {error}")
    assert error.pixels > 1000
    assert error.rmse < 0.01, f"{view}, {method}: {error}"


def _lattice_view(view: str) -> list[str]:
    """Overrides of scenes/lattice.yaml: a 96 × 72 image from inside the room, towards the
    window's centre (0, 2.5, -4.08), at 3.6 units, VIEWS[view] off its normal."""
    position = _view([0, 2.5, -4.08], [0, 0, 1], [1, 0, 0], VIEWS[view], 3.6)
    return [f"camera.position={[round(p, 6) for p in position]}", "camera.look_at=[0, 2.5, -4.08]",
            "image.width=96", "image.height=72"]


@pytest.mark.parametrize("view", list(VIEWS))
def test_lattice_camera_depth_matches_its_triangles(device, view):
    """Every camera sample of the lattice gets from the pre-warp's mapping the depth its
    triangles give it, bars seen edge-on included: at 80° a ray that grazes over a bar's ridge
    (which the warp puts in its way) or meets a bar's side where the warp left a gap hits a
    bar farther along its trace, beyond the mapping's fixed reach around the warp's answer
    (28 such samples at 80°, 3 at 60°, before the walk went on to where the ray leaves the
    relief: docs/design.md, "Relief objects")."""
    depths = []
    for mode in ("prewarp", "triangles"):
        scene = with_derived_sizes(load_scene(LATTICE, _lattice_view(view) + [f"render.relief={mode}"]))
        buffers = upload(device, frame_inputs(scene))
        camera_depth, _ = raster_camera(device, buffers, StageTimer())
        depths.append(device.read(camera_depth, buffers.inputs.samples, np.uint32).view(np.float32))
    prewarp, triangles = depths
    assert np.isfinite(triangles).sum() > 3000  # the lattice and the room behind it
    # Both see something, within float rounding, or both see nothing (inf): an inf beside a
    # finite depth is a miss or a false hit, never within any tolerance.
    finite = np.isfinite(triangles)
    seen = np.where(finite, triangles, 0.0)
    same = (prewarp == triangles) | ((np.isfinite(prewarp) == finite) & (np.abs(prewarp - seen) <= 1e-5 * seen))
    assert (~same).sum() == 0, f"{view}: {np.flatnonzero(~same)} of {prewarp.size} samples differ"


def test_lattice_sun_map_matches_its_triangles(device):
    """The sun's map of the lattice by the pre-warp, which maps only the pixels of the map
    its footprint covers (clrays.stages.relief.footprint), holds the depths and nearest
    triangles its triangles give every texel. The footprint is a small part of a map fitted
    to the whole room: 3.8 % of it here, where mapping every texel took the lattice's
    320×180 frame 37 of its 125 ms (bench/RESULTS.md history, "A relief maps its footprint only")."""
    maps = []
    for mode in ("prewarp", "triangles"):
        scene = with_derived_sizes(load_scene(LATTICE, ["image.width=96", "image.height=72", "render.shadow_map=512",
                                                        f"render.relief={mode}"]))
        buffers = upload(device, frame_inputs(scene))
        shadow_map = raster_shadow_map(device, buffers, 0, StageTimer())
        depth = read_shadow_depth(device, shadow_map.depth, shadow_map.texels, shadow_map.depth_in_keys).view(np.uint32)
        if shadow_map.keys:  # depth << 32 | triangle, as raster drew them
            keys = device.read(shadow_map.blockers, shadow_map.texels, np.uint64)
            assert np.array_equal((keys >> np.uint64(32)).astype(np.uint32), depth)
            triangle = np.where(depth == structs.DEPTH_EMPTY, -1, (keys & np.uint64(0xFFFFFFFF)).astype(np.int64))
        else:
            triangle = device.read(shadow_map.blockers, shadow_map.texels, np.int32)
        maps.append((depth.view(np.float32), triangle))
        if mode == "prewarp":
            drawer = ReliefDrawer(device, buffers.inputs.reliefs, buffers.inputs.light_anchor_ws[0], StageTimer())
            placed, frame = drawer.reliefs[0]
            view = light_pass_inputs(buffers.inputs, 0).views[1]
            _, _, columns, rows = footprint(view, frame, *drawer._height_range(0), *placed.displacement.shape)
            share = columns * rows / shadow_map.texels
    (prewarp, prewarp_triangle), (triangles, triangle) = maps
    print(f"footprint: {share:.3f} of the map")
    assert 0.0 < share < 0.1
    finite = np.isfinite(triangles)
    assert (np.isfinite(prewarp) == finite).all()
    assert np.abs(prewarp[finite] - triangles[finite]).max() <= 1e-5 * np.abs(triangles[finite]).max()
    relief_texels = triangle >= scene.geometry.reliefs[0].rows.start
    assert relief_texels.sum() > 1000
    assert (prewarp_triangle == triangle).mean() > 0.999


@pytest.mark.slow
@pytest.mark.parametrize("method", ["minmax", "raymarch"])
@pytest.mark.parametrize("view", list(VIEWS))
def test_lattice_relief_matches_its_mesh(tmp_path, method, view):
    """The pre-warp draws exactly the lattice's triangles into every map. minmax compares the
    two with the relief read from the map (`shaft_edges: texels`): with `blockers` the walks
    cut the relief per ray and read a mesh from the map, and differ by the map's error
    (tests/stages/test_relief_cuts.py holds the cuts against `exact`)."""
    overrides = _lattice_view(view) + (["render.shaft_edges=texels"] if method == "minmax" else [])
    mesh_scene = _as_mesh(LATTICE, tmp_path, overrides, 8, [0.55, 0.4, 0.28])
    error, _, _ = _compare(load_scene(LATTICE, overrides), mesh_scene, method)
    print(f"lattice, {view}, {method}: {error}")
    assert error.pixels > 1000
    assert error.rmse < 0.01, f"{view}, {method}: {error}"


def test_device_warp_matches_numpy(device):
    """The device's two passes against `prewarp_two_pass` on the same target grid, for random
    perspective and orthographic viewers: the same texels written (float32 against float64
    moves a few across a centre) and the same source points."""
    rng = np.random.default_rng(5)
    n = 40
    checked = 0
    for trial in range(8):
        displacement = 0.3 * bump_field(n, seed=trial)
        solid = rng.random((n, n)) > 0.03
        frame = relief_frame(rng.normal(size=3), [0, 1, 0], [0, 0, -1], (2.0, 2.0), (n, n))
        relief = Relief(frame, displacement, solid, None)
        triangles, _ = relief.triangles()
        record = relief_record(relief, slice(0, len(triangles)), triangles)
        placed = PlacedRelief(frame, displacement, solid, record.cell_triangle, 0)
        view = np.zeros((), dtype=structs.view_dtype)
        if trial % 2:
            view["projection"] = structs.PROJECTION_ORTHOGRAPHIC
            direction = np.array([rng.uniform(-0.8, 0.8), -1.0, rng.uniform(-0.8, 0.8)])
            view["forward"][:3] = direction / np.linalg.norm(direction)
            viewer = Viewer(direction=view["forward"][:3].astype(np.float64))
        else:
            view["projection"] = structs.PROJECTION_PERSPECTIVE
            view["origin"][:3] = frame.corner + [rng.uniform(0, 2), rng.uniform(1.5, 3), rng.uniform(-2, 0)]
            viewer = Viewer(position=view["origin"][:3].astype(np.float64))
        drawer = ReliefDrawer(device, [placed], np.zeros(3), StageTimer())
        warp = drawer.warp(0, view)
        ours = device.read(warp.warped, (warp.target_rows, warp.target_cols, 4), np.float32)[..., :3]
        theirs = prewarp_two_pass(frame, displacement, viewer, solid, shape=(warp.target_rows, warp.target_cols),
                                  origin=(warp.u0, warp.v0))
        written, expected = ~np.isnan(ours[..., 2]), ~np.isnan(theirs[..., 2])
        assert (written != expected).sum() <= 0.002 * expected.sum() + 2
        both = written & expected
        difference = np.abs(ours[both] - theirs[both])
        assert np.percentile(difference[:, :2], 99) < 1e-2  # texels
        checked += int(both.sum())
    assert checked > 5000


HOLES = """version: 1
image: {width: 64, height: 48}
camera: {position: [0, 3.5, 2.5], look_at: [0, 0, 0], fov_deg: 50}
lights: [{type: directional, direction: [0, -1, 0], irradiance: 2}]
medium: {sigma_s: 0.05}
render: {surface_shadows: map}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 6, segments: 1, albedo: 0.8}
  - {type: relief, center: [0, 1.5, 0], normal: [0, 1, 0], up: [0, 0, -1], size: [2, 2], depth_map: holes.png,
     height: 0.1}
"""


def test_holes_let_light_through(tmp_path):
    """A sheet with a square hole over a floor, lit from straight above: with the pre-warp
    drawing the relief into the shadow map, the floor under the hole is lit, the floor
    under the sheet is not, as with its triangles."""
    depth = np.full((32, 32), 128, np.uint8)
    alpha = np.full((32, 32), 255, np.uint8)
    alpha[10:22, 10:22] = 0  # the hole: x, z in about [-0.4, 0.4]
    Image.fromarray(np.dstack([depth, alpha]), "LA").save(tmp_path / "holes.png")
    path = tmp_path / "holes.yaml"
    path.write_text(HOLES)
    session = Renderer(reuse=False)
    scene = load_scene(path)
    image = session.render(scene, "raymarch").image
    triangles = session.render(load_scene(path, ["render.relief=triangles"]), "raymarch").image
    depth = depth_map(scene)
    # Pixels of the floor under the hole and under the sheet, from where their rays meet y = 0.
    directions = primary_rays(scene.camera, scene.image, np.array([[0.5, 0.5]]))[:, :, 0, :]
    t_floor = -scene.camera.position[1] / directions[..., 1]
    hit = scene.camera.position + t_floor[..., None] * directions
    sees_floor = np.abs(depth - t_floor) < 1e-6
    under_hole = sees_floor & (np.abs(hit[..., 0]) < 0.3) & (np.abs(hit[..., 2]) < 0.3)
    under_sheet = sees_floor & (np.abs(hit[..., 0]) < 0.9) & (np.abs(hit[..., 2]) < 0.9) & ~(
        (np.abs(hit[..., 0]) < 0.5) & (np.abs(hit[..., 2]) < 0.5))
    assert under_hole.sum() > 20 and under_sheet.sum() > 20
    lum = image.mean(axis=2)
    assert lum[under_hole].mean() > 10 * lum[under_sheet].mean()
    assert np.abs(image - triangles).max() < 1e-3 * image.max()


def test_relief_seen_from_behind(tmp_path):
    """The camera on the far side of the base plane: the relief rises away from it. The
    pre-warp's render matches its triangles' (the occlusion-compatible order holds on
    either side, docs/design.md "Relief objects")."""
    np.save(tmp_path / "bumps.npy", bump_field())
    position = _view([0, 0.1, 0], [0, -1, 0], [0.8, 0, 0.6], 35.0, 3.0)
    path = tmp_path / "bumps.yaml"
    path.write_text(BUMPS.format(position=[round(p, 6) for p in position]).replace(
        "center: [0, -0.6, 0]", "center: [0, -3, 0]").replace("position: [1.5, 3.5, 1.0]", "position: [1.5, -2.5, 1.0]")
        .replace("direction: [-0.35, -1, -0.2]", "direction: [-0.35, 1, -0.2]"))
    scene = load_scene(path)
    session = Renderer(reuse=False)
    for method in ("minmax", "raymarch"):
        image = session.render(scene, method).image
        reference = session.render(load_scene(path, ["render.relief=triangles"]), method).image
        error = image_error(image, reference, exclude=depth_edges(depth_map(scene)))
        print(f"seen from behind, {method}: {error}")
        assert error.pixels > 1000
        assert error.rmse < 0.01, f"{method}: {error}"


def test_animated_relief_follows_its_keys(tmp_path):
    """An animation that turns and moves the relief moves its warp with its triangles (the
    frame comes from four of its vertices): prewarp and triangles agree at a keyed frame."""
    np.save(tmp_path / "bumps.npy", bump_field(24))
    path = tmp_path / "bumps.yaml"
    path.write_text(BUMPS.format(position=[2.0, 2.5, 2.0]).replace("80, height: 60", "48, height: 36") + """\
animation:
  frames: [0, 10]
  objects:
    - object: 1
      keys:
        - {frame: 0, translate: [0, 0, 0]}
        - {frame: 10, translate: [0.3, 0.2, -0.1], rotate: {axis: [1, 0, 1], angle_deg: 25}}
""")
    scene = load_scene(path)
    at_frame = scene.animation.scene_at(scene, 7)
    triangles = scene.animation.scene_at(load_scene(path, ["render.relief=triangles"]), 7)
    session = Renderer(reuse=False)
    error = image_error(session.render(at_frame, "raymarch").image, session.render(triangles, "raymarch").image,
                        exclude=depth_edges(depth_map(at_frame)))
    print(f"animated, frame 7: {error}")
    assert error.pixels > 500 and error.rmse < 0.01
