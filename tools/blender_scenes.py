"""Blender's side of the Cycles check of glTF import: builds small fog scenes in Blender,
writes each with Blender's own glTF exporter (its default settings, lighting mode Standard,
with lights and cameras included) and renders it with Cycles in the single-scattering,
direct-light-only model clrays renders (docs/design.md §1). clrays never imports it; it
runs in Blender's Python (the `bpy` wheel needs Python 3.11, in a virtualenv of its own):

    python3.11 -m venv /tmp/bpyenv && /tmp/bpyenv/bin/pip install 'bpy==4.5.*'
    /tmp/bpyenv/bin/python tools/blender_scenes.py point out/ --samples 1024 --seed 1
    /tmp/bpyenv/bin/python tools/blender_scenes.py point out/ --samples 1024 --seed 2

writes out/point.glb and out/point.cycles.s1.npy, .s2.npy (linear RGB, H×W×3 float32, row 0
at the top, as clrays's .npy), and prints the clrays command that renders the same file
with the same fog. Then any Python with numpy compares them:

    python tools/blender_scenes.py compare out/point.clrays.npy out/point.cycles.s1.npy out/point.cycles.s2.npy

which prints the best scale of clrays onto Cycles, the RMS error left beyond it, Cycles'
noise (from the two seeds) and the error beyond that noise, over all pixels and away from
edges (where antialiasing differs and at a lamp's own pixel, whose value is all noise).

Scenes (Blender's Z up; the exporter writes glTF's Y up):
  point  a 1000 W point light (radius 0) over a floor, a box casting its shadow
  spot   a hard 70° spot of 2000 W (spot_blend 0, radius 0) through a slot between two plates
  sun    a 5 W/m² sun (angle 0) through a window with bars in a wall
and, with the fog in meshes of a volume-only material (Volume Scatter + Absorption) and no
World volume, as a Blender user makes bounded fog:
  sunroom  the sun through the barred window into a roofed room, all in a 40 m fog cube,
           exported with the file: clrays takes it as `medium.bounds.object` (docs/media.md)
  boxes    the point light over two fog boxes, the camera in one, its rays leaving it and
           entering the other; the boxes are added after the export, and clrays gets their
           union as a 0/1 density grid (boxes.density.npy, written beside the .glb)
  height   the point scene in height fog, σ·exp(−(z − z0)/H) from Geometry Position and
           Math nodes, in the 40 m cube: clrays's `density: {type: height}` on glTF's y

Cycles is set up as clrays renders: Diffuse BSDF (Lambert) of the glTF base colour, one
homogeneous isotropic medium in the World (Volume Scatter + Volume Absorption, densities σs
and σa per metre), direct light only (every bounce count 0), no light threshold, a box
pixel filter, no denoising. Cycles' camera rays, and so its fog, begin at the camera's Clip
Start (Blender's 0.1 m, `--clip-start`), which the exporter writes as the camera's `znear`
and clrays reads as `camera.near` (docs/scene-format.md, "Camera"). One difference of model
needs a setting:
* clrays does not attenuate sunlight on its way in (docs/design.md), and Cycles' World
  volume, infinite, absorbs a sun whole; in the sun scene the medium is left out of shadow
  rays (Light Path "Is Shadow Ray"), unless --sun-through-fog. Point and spot light is
  attenuated, e^(−σt·d), in both.
Fog in a mesh has two settings of its own: rays cross the mesh's surface (transparent, as a
volume-only material's is) as transparent bounces, so that count is not 0; and Cycles
ray-marches a procedural density (height fog) in steps of a tenth of the object's bounds
times the material's Volume Step Rate, which is set to 0.02 (8 cm in the 40 m cube).
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

try:  # `compare` needs numpy alone
    import bpy
    from mathutils import Vector
except ImportError:
    bpy = None

WIDTH, HEIGHT = 160, 90
#: Per scene: fog σs and σa per metre, and the light as Blender holds it.
SCENES = {
    "point": {"sigma_s": 0.15, "sigma_a": 0.05, "light": {"type": "POINT", "energy": 1000.0}},
    "spot": {"sigma_s": 0.2, "sigma_a": 0.0,
             "light": {"type": "SPOT", "energy": 2000.0, "spot_size_deg": 70.0, "spot_blend": 0.0}},
    "sun": {"sigma_s": 0.1, "sigma_a": 0.02, "light": {"type": "SUN", "energy": 5.0}},
    # Fog in meshes (a volume-only material) rather than the World: the sun's light is attenuated
    # on its way through the cube, as clrays's bounded medium does.
    "sunroom": {"sigma_s": 0.04, "sigma_a": 0.01, "light": {"type": "SUN", "energy": 5.0}, "fog": "cube"},
    "boxes": {"sigma_s": 0.25, "sigma_a": 0.05, "light": {"type": "POINT", "energy": 1000.0}, "fog": "boxes"},
    "height": {"sigma_s": 0.2, "sigma_a": 0.05, "light": {"type": "POINT", "energy": 1000.0}, "fog": "height"},
}
#: The 40 m fog cube of `sunroom` and `height` (Blender coordinates, m), its node's name in the glTF.
FOG_CUBE = {"name": "fog", "centre": (0.0, 0.0, 19.0), "size": 40.0}
#: `height`: the density exp(−(z − base)/scale_height), Blender's z (glTF's y), m.
HEIGHT_FOG = {"base": 0.0, "scale_height": 2.0}
#: `boxes`: the two fog boxes (min, max corners, Blender coordinates, m), on the 1/16 m voxel grid
#: that gives clrays the same fog (`boxes_grid`): finer voxels narrow the ramp at its faces.
FOG_BOXES = (((-4.0, -4.0, -0.5), (0.0, 0.0, 3.0)), ((1.0, 0.5, -0.5), (4.0, 4.0, 3.0)))
GRID_STEP = 0.0625


def clear() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)


def material(name: str, albedo: float) -> bpy.types.Material:
    """A Principled BSDF of this base colour, without specular, for the exporter; `render_diffuse`
    swaps it for a Lambertian before Cycles renders."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (albedo, albedo, albedo, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    return mat


def box(name: str, centre, size, mat) -> None:
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=centre)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = size
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    obj.data.materials.append(mat)


#: The camera's clip start, m (Blender's default 0.1): Cycles' camera rays, and so its fog, begin there.
CLIP_START = 0.1


def camera(location, target, clip_start: float, lens_mm: float = 28.0) -> None:
    data = bpy.data.cameras.new("camera")
    data.lens = lens_mm
    data.clip_start = clip_start
    data.clip_end = 100.0
    obj = bpy.data.objects.new("camera", data)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    obj.rotation_euler = (Vector(target) - Vector(location)).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = obj


def light(spec: dict, location, target) -> None:
    data = bpy.data.lights.new("light", spec["type"])
    data.energy = spec["energy"]
    if spec["type"] == "SUN":
        data.angle = 0.0
    else:
        data.shadow_soft_size = 0.0  # a point, as clrays's lights are
    if spec["type"] == "SPOT":
        data.spot_size = math.radians(spec["spot_size_deg"])
        data.spot_blend = spec["spot_blend"]
    obj = bpy.data.objects.new("light", data)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    obj.rotation_euler = (Vector(target) - Vector(location)).to_track_quat("-Z", "Y").to_euler()


def build(name: str, spec: dict, clip_start: float) -> None:
    grey, light_grey = material("grey", 0.5), material("light_grey", 0.7)
    if name == "point":
        box("floor", (0, 0, -0.05), (8, 8, 0.1), grey)
        box("occluder", (0, 0, 0.5), (1, 1, 1), light_grey)
        light(spec, (0.6, 0.4, 3.0), (0.6, 0.4, 0.0))
        camera((5.5, -5.5, 4.0), (0, 0, 0.8), clip_start)
    elif name == "spot":
        box("floor", (0, 0, -0.05), (8, 8, 0.1), grey)
        # two plates at z = 2.5 with a 0.4 m slot between them along y
        box("plate_left", (-1.2, 0, 2.5), (2.0, 4.0, 0.05), light_grey)
        box("plate_right", (1.2, 0, 2.5), (2.0, 4.0, 0.05), light_grey)
        light(spec, (0.0, 0.0, 4.5), (0.0, 0.0, 0.0))
        camera((6.5, -5.0, 3.4), (0, 0, 1.2), clip_start)
    elif name == "sun":
        box("floor", (0, 0, -0.05), (12, 12, 0.1), grey)
        # a wall at x = -2 with a 2 × 2 m window (y ∈ [-1, 1], z ∈ [1, 3]) and three bars
        box("wall_low", (-2, 0, 0.5), (0.2, 12, 1.0), light_grey)
        box("wall_high", (-2, 0, 6.5), (0.2, 12, 7.0), light_grey)
        box("wall_near", (-2, -3.5, 2.0), (0.2, 5.0, 2.0), light_grey)
        box("wall_far", (-2, 3.5, 2.0), (0.2, 5.0, 2.0), light_grey)
        for y in (-0.5, 0.0, 0.5):
            box(f"bar_{y:+.1f}", (-2, y, 2.0), (0.2, 0.1, 2.0), light_grey)
        light(spec, (-4.0, 1.0, 5.0), (0.0, 0.0, 1.0))
        camera((5.0, -4.5, 2.2), (-0.5, 0.3, 1.2), clip_start)
    elif name == "sunroom":  # the sun scene's wall and window under a roof: a room, in the fog cube
        box("floor", (0, 0, -0.05), (12, 12, 0.1), grey)
        box("wall_low", (-2, 0, 0.5), (0.2, 12, 1.0), light_grey)
        box("wall_high", (-2, 0, 3.5), (0.2, 12, 1.0), light_grey)
        box("wall_near", (-2, -3.5, 2.0), (0.2, 5.0, 2.0), light_grey)
        box("wall_far", (-2, 3.5, 2.0), (0.2, 5.0, 2.0), light_grey)
        for y in (-0.5, 0.0, 0.5):
            box(f"bar_{y:+.1f}", (-2, y, 2.0), (0.2, 0.1, 2.0), light_grey)
        box("roof", (2.5, 0, 4.05), (9.2, 12, 0.1), light_grey)
        box("back", (6.95, 0, 2.0), (0.1, 12, 4.0), light_grey)
        light(spec, (-4.0, 1.0, 5.0), (0.0, 0.0, 1.0))
        camera((5.0, -4.5, 2.2), (-0.5, 0.3, 1.2), clip_start)
    elif name == "boxes":  # the camera in one fog box, looking through clear air into the other
        box("floor", (0, 0, -0.05), (10, 10, 0.1), grey)
        box("occluder", (1.0, -1.5, 0.5), (1, 1, 1), light_grey)
        light(spec, (0.5, 0.0, 3.5), (0.5, 0.0, 0.0))
        camera((-3.0, -3.5, 2.0), (2.5, 2.0, 0.8), clip_start)
    elif name == "height":  # the point scene in height fog, in the fog cube
        box("floor", (0, 0, -0.05), (8, 8, 0.1), grey)
        box("occluder", (0, 0, 0.5), (1, 1, 1), light_grey)
        light(spec, (0.6, 0.4, 3.0), (0.6, 0.4, 0.0))
        camera((5.5, -5.5, 4.0), (0, 0, 0.8), clip_start)


def scatter_absorb(nodes, links, output):
    """Volume Scatter (isotropic, white) + Volume Absorption (black: σa = its density) into
    `output`: their Density inputs are σs and σa per metre."""
    scatter = nodes.new("ShaderNodeVolumeScatter")
    scatter.inputs["Color"].default_value = (1, 1, 1, 1)
    scatter.inputs["Anisotropy"].default_value = 0.0
    absorb = nodes.new("ShaderNodeVolumeAbsorption")
    absorb.inputs["Color"].default_value = (0, 0, 0, 1)  # σa = density
    add = nodes.new("ShaderNodeAddShader")
    links.new(scatter.outputs[0], add.inputs[0])
    links.new(absorb.outputs[0], add.inputs[1])
    links.new(add.outputs[0], output)
    return scatter, absorb


def fog_material(name: str, sigma_s: float, sigma_a: float, height: dict | None = None) -> bpy.types.Material:
    """A volume-only material (Volume Scatter + Volume Absorption, σs and σa per metre, no Surface):
    Blender's fog in a mesh. With `height`, both densities times exp(−(z − base)/scale_height) of
    the shading point's world-space z (Geometry Position), built from Math nodes."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.remove(nodes["Principled BSDF"])
    scatter, absorb = scatter_absorb(nodes, links, nodes["Material Output"].inputs["Volume"])
    if height is None:
        scatter.inputs["Density"].default_value = sigma_s
        absorb.inputs["Density"].default_value = sigma_a
        return mat
    # Height fog: a procedural density is ray-marched, in steps of a tenth of the object's bounds
    # times the step rate (4 m in the 40 m cube): 0.02 makes them 8 cm, fine against 2 m.
    mat.cycles.volume_step_rate = 0.02
    position = nodes.new("ShaderNodeNewGeometry")
    z = nodes.new("ShaderNodeSeparateXYZ")
    links.new(position.outputs["Position"], z.inputs[0])
    exponent = nodes.new("ShaderNodeMath")
    exponent.operation = "MULTIPLY_ADD"  # z × (−1/H) + base/H
    links.new(z.outputs["Z"], exponent.inputs[0])
    exponent.inputs[1].default_value = -1.0 / height["scale_height"]
    exponent.inputs[2].default_value = height["base"] / height["scale_height"]
    factor = nodes.new("ShaderNodeMath")
    factor.operation = "EXPONENT"
    links.new(exponent.outputs[0], factor.inputs[0])
    for node, sigma in ((scatter, sigma_s), (absorb, sigma_a)):
        scale = nodes.new("ShaderNodeMath")
        scale.operation = "MULTIPLY"
        links.new(factor.outputs[0], scale.inputs[0])
        scale.inputs[1].default_value = sigma
        links.new(scale.outputs[0], node.inputs["Density"])
    return mat


def fog_cube(mat) -> None:
    """The 40 m cube of FOG_CUBE holding the fog material."""
    size = FOG_CUBE["size"]
    box(FOG_CUBE["name"], FOG_CUBE["centre"], (size, size, size), mat)


def boxes_grid(out: Path) -> tuple[Path, tuple, tuple]:
    """The two fog boxes of `boxes` as a clrays density grid (.npy, axes z, y, x of glTF, 1 inside a
    box, 0 outside) and its bounds (glTF coordinates: x, z, −y of Blender's). The boxes' faces lie
    halfway between voxel centres, where clrays's trilinear ramp crosses 1/2: a ray through a face
    gathers the same optical depth as through the sharp box."""
    def gltf(point):  # Blender (x, y, z) → glTF (x, z, −y)
        return np.array([point[0], point[2], -point[1]])
    corners = np.array([gltf(p) for box_ in FOG_BOXES for p in box_])
    low, high = corners.min(axis=0) - GRID_STEP, corners.max(axis=0) + GRID_STEP  # a voxel of 0 around
    counts = np.rint((high - low) / GRID_STEP).astype(int)
    centres = [low[a] + (np.arange(counts[a]) + 0.5) * GRID_STEP for a in range(3)]
    grid = np.zeros(counts[::-1])
    for box_ in FOG_BOXES:
        lo, hi = np.minimum(gltf(box_[0]), gltf(box_[1])), np.maximum(gltf(box_[0]), gltf(box_[1]))
        inside = [(c > lo[a]) & (c < hi[a]) for a, c in enumerate(centres)]
        grid[np.ix_(inside[2], inside[1], inside[0])] = 1.0
    path = out / "boxes.density.npy"
    np.save(path, grid)
    return path, tuple(low.round(6)), tuple(high.round(6))


def black_world() -> bpy.types.World:
    """A World of no light (and, unless `world_fog` adds one, no volume)."""
    world = bpy.data.worlds.new("world")
    bpy.context.scene.world = world
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    return world


def world_fog(sigma_s: float, sigma_a: float, shadow_rays: bool) -> None:
    world = black_world()
    nodes, links = world.node_tree.nodes, world.node_tree.links
    scatter, absorb = scatter_absorb(nodes, links, nodes["World Output"].inputs["Volume"])
    if shadow_rays:
        scatter.inputs["Density"].default_value = sigma_s
        absorb.inputs["Density"].default_value = sigma_a
    else:  # density × (1 − Is Shadow Ray): the light reaches every point unattenuated
        path = nodes.new("ShaderNodeLightPath")
        for node, sigma in ((scatter, sigma_s), (absorb, sigma_a)):
            scale = nodes.new("ShaderNodeMath")
            scale.operation = "MULTIPLY_ADD"  # shadow × (−σ) + σ
            links.new(path.outputs["Is Shadow Ray"], scale.inputs[0])
            scale.inputs[1].default_value = -sigma
            scale.inputs[2].default_value = sigma
            links.new(scale.outputs[0], node.inputs["Density"])


def render_diffuse() -> None:
    """Each material's Principled BSDF becomes a Diffuse BSDF (roughness 0: Lambert) of its base colour."""
    for mat in bpy.data.materials:
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        if "Principled BSDF" not in nodes:  # a fog material
            continue
        principled = nodes["Principled BSDF"]
        diffuse = nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Color"].default_value = principled.inputs["Base Color"].default_value
        diffuse.inputs["Roughness"].default_value = 0.0
        links.new(diffuse.outputs[0], nodes["Material Output"].inputs["Surface"])


def cycles_settings(samples: int, seed: int) -> None:
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    scene.render.filter_size = 1.0
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = samples
    cycles.seed = seed
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.pixel_filter_type = "BOX"
    cycles.filter_width = 1.0
    cycles.light_sampling_threshold = 0.0
    cycles.max_bounces = 0
    for bounces in ("diffuse_bounces", "glossy_bounces", "transmission_bounces", "volume_bounces"):
        setattr(cycles, bounces, 0)
    # Rays cross a fog mesh's surface (a volume-only material: transparent) as a transparent bounce.
    cycles.transparent_max_bounces = 16
    cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.threads_mode = "FIXED"
    scene.render.threads = 1


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def compare(clrays: np.ndarray, cycles: list[np.ndarray], mask: np.ndarray | None = None) -> dict:
    """The best scale s of clrays onto the mean of the Cycles renders (least squares), the RMS
    of what is left (c − s·clrays) relative to the RMS of c, the noise of that mean (from the
    difference of two renders of different seeds) on the same scale, and the error beyond it."""
    mean = np.mean(cycles, axis=0)
    if mask is not None:
        clrays, mean, cycles = clrays[mask], mean[mask], [c[mask] for c in cycles]
    scale = float(np.sum(mean * clrays) / np.sum(clrays * clrays))
    error = _rms(mean - scale * clrays) / _rms(mean)
    noise = _rms(cycles[0] - cycles[1]) / math.sqrt(2) / _rms(mean) / math.sqrt(len(cycles)) \
        if len(cycles) > 1 else float("nan")
    return {"scale": scale, "mean_ratio": float(mean.sum() / clrays.sum()), "error": error, "noise": noise,
            "beyond_noise": math.sqrt(max(error ** 2 - noise ** 2, 0.0)) if noise == noise else float("nan")}


def away_from_edges(image: np.ndarray, contrast: float = 0.1) -> np.ndarray:
    """Pixels whose 3×3 neighbourhood differs from them by less than `contrast` (relative),
    off the border: where antialiasing (Cycles' box filter against clrays's sample grid) and
    the peak at a lamp play no part."""
    luminance = image.mean(axis=2)
    edge = np.zeros(luminance.shape, bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            shifted = np.roll(np.roll(luminance, dy, 0), dx, 1)
            edge |= np.abs(shifted - luminance) > contrast * np.maximum(luminance, 1e-3)
    edge[[0, -1], :] = edge[:, [0, -1]] = True
    return ~edge


def main_compare(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(prog="blender_scenes.py compare")
    parser.add_argument("clrays", type=Path, help="clrays's render, .npy")
    parser.add_argument("cycles", type=Path, nargs="+", help="Cycles' renders of different seeds, .npy")
    args = parser.parse_args(argv)
    clrays = np.load(args.clrays).astype(np.float64)
    cycles = [np.load(path).astype(np.float64) for path in args.cycles]
    if not np.any(np.mean(cycles, axis=0)):  # e.g. a sun behind the World volume, which absorbs it whole
        sys.exit(f"blender_scenes.py: {args.cycles[0]}: the Cycles render is black")
    mask = away_from_edges(clrays)
    for label, numbers in (("all pixels", compare(clrays, cycles)),
                           (f"off edges ({mask.mean():.0%})", compare(clrays, cycles, mask))):
        print(f"{label}: scale {numbers['scale']:.4f} (of the means {numbers['mean_ratio']:.4f}), "
              f"error {numbers['error']:.2%}, "
              f"Cycles noise {numbers['noise']:.2%}, beyond noise {numbers['beyond_noise']:.2%}")


def main() -> None:
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    if argv[:1] == ["compare"]:
        return main_compare(argv[1:])
    if bpy is None:
        sys.exit("blender_scenes.py: building and rendering needs Blender's bpy (see the docstring)")
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", choices=sorted(SCENES))
    parser.add_argument("out", type=Path)
    parser.add_argument("--samples", type=int, default=1024)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--sigma-s", type=float, help="σs per metre instead of the scene's")
    parser.add_argument("--sigma-a", type=float, help="σa per metre instead of the scene's")
    parser.add_argument("--spot-size", type=float, help="the spot's full cone, degrees, instead of 70")
    parser.add_argument("--spot-blend", type=float, help="the spot's blend instead of 0")
    parser.add_argument("--clip-start", type=float, default=CLIP_START, help="the camera's clip start, m")
    parser.add_argument("--sun-through-fog", action="store_true",
                        help="keep the fog in the sun's shadow rays (Cycles' own world volume; clrays does not)")
    parser.add_argument("--tag", default="", help="added to the output names")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    setup = dict(SCENES[args.scene])
    for key in ("sigma_s", "sigma_a"):
        if getattr(args, key) is not None:
            setup[key] = getattr(args, key)
    setup["light"] = dict(setup["light"])
    for key, value in (("spot_size_deg", args.spot_size), ("spot_blend", args.spot_blend)):
        if value is not None:
            setup["light"][key] = value

    clear()
    build(args.scene, setup["light"], args.clip_start)
    cycles_settings(args.samples, args.seed)
    bpy.context.scene.render.threads = args.threads
    glb = args.out / f"{args.scene}{args.tag}.glb"
    # Blender's defaults (lighting mode Standard, +Y up) with the lights and camera included
    fog = setup.get("fog", "world")
    clrays_medium = ""
    if fog in ("cube", "height"):  # the cube is exported, as users' files hold it: clrays takes it as the bounds
        height = HEIGHT_FOG if fog == "height" else None
        fog_cube(fog_material("fog_volume", setup["sigma_s"], setup["sigma_a"], height))
        clrays_medium = f" --set medium.bounds.object={FOG_CUBE['name']}"
        if height is not None:  # Blender's z is glTF's y
            clrays_medium += (f" --set medium.density.type=height --set medium.density.base={height['base']}"
                              f" --set medium.density.scale_height={height['scale_height']}")
    # Blender's defaults (lighting mode Standard, +Y up) with the lights and camera included
    bpy.ops.export_scene.gltf(filepath=str(glb), export_format="GLB", export_lights=True, export_cameras=True)
    if fog == "boxes":  # added after the export: clrays has one medium, the boxes' union as a density grid
        mat = fog_material("fog_volume", setup["sigma_s"], setup["sigma_a"])
        for k, (lo, hi) in enumerate(FOG_BOXES):
            box(f"fog_{k}", tuple((a + b) / 2 for a, b in zip(lo, hi)), tuple(b - a for a, b in zip(lo, hi)), mat)
        grid, low, high = boxes_grid(args.out)
        clrays_medium = (f" --set medium.density.type=grid --set medium.density.file={grid.resolve()}"
                         f" --set 'medium.density.bounds={{min: {list(low)}, max: {list(high)}}}'"
                         f" --set 'medium.bounds={{min: {list(low)}, max: {list(high)}}}'")
    black_world()
    if fog == "world":
        world_fog(setup["sigma_s"], setup["sigma_a"],
                  shadow_rays=setup["light"]["type"] != "SUN" or args.sun_through_fog)
    render_diffuse()
    exr = args.out / f"{args.scene}{args.tag}.cycles.s{args.seed}.exr"
    bpy.context.scene.render.filepath = str(exr)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(exr))
    pixels = np.array(image.pixels[:], dtype=np.float32).reshape(HEIGHT, WIDTH, 4)[::-1, :, :3]
    np.save(args.out / f"{args.scene}{args.tag}.cycles.s{args.seed}.npy", np.ascontiguousarray(pixels))
    print(f"clrays render {glb} -o {args.out / f'{args.scene}{args.tag}.clrays.npy'} --device intel "
          f"--set image.width={WIDTH} --set image.height={HEIGHT} --set image.spp=256 "
          f"--set medium.sigma_s={setup['sigma_s']} --set medium.sigma_a={setup['sigma_a']}{clrays_medium} "
          f"--set render.method=exact")


if __name__ == "__main__":
    main()
