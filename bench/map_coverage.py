"""How much of a directional light's shadow map falls where a frame can read it
(bench/RESULTS.md, "Volume visibility: where the error comes from").

    .venv/bin/python bench/map_coverage.py lattice sun --size 320x180

The map is the square around the scene's bounding sphere (clrays/inputs.py). Projected onto
the light's plane: the scene's box; the camera's pyramid cut at `far` (every ray within far
lies in it), intersected with the box's outline (a light ray can be blocked only where it
crosses the box); the frustum clipped to the box in 3D (random points); the visible ray
segments, eye to min(depth, far), from a float64 depth map, within the box's outline. For
each: its bounding rectangle against the square's side (how much finer a map fitted to it
would be along each side), and the share of the 1024² map's texels that touch it.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from matplotlib.path import Path as Polygon

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from arguments import image_size  # noqa: E402  (bench/, beside this script)
from clrays.inputs import _any_up  # noqa: E402
from clrays.physics.radiometry import effective_far  # noqa: E402
from clrays.reference.metrics import depth_map  # noqa: E402
from clrays.scene.camera import camera_basis, half_extents, primary_rays  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.scene.model import DirectionalLight  # noqa: E402

TEXELS = 1024


def hull(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull of 2D points (monotone chain)."""
    ordered = sorted(map(tuple, points))

    def chain(sequence):
        kept = []
        for q in sequence:
            while len(kept) >= 2 and ((kept[-1][0] - kept[-2][0]) * (q[1] - kept[-2][1])
                                      - (kept[-1][1] - kept[-2][1]) * (q[0] - kept[-2][0])) <= 0:
                kept.pop()
            kept.append(q)
        return kept[:-1]

    return np.array(chain(ordered) + chain(ordered[::-1]))


def clip(polygon: np.ndarray, window: np.ndarray) -> np.ndarray:
    """Convex `polygon` ∩ convex `window`, both counter-clockwise (Sutherland–Hodgman)."""
    out = list(polygon)
    for i in range(len(window)):
        a, b = window[i], window[(i + 1) % len(window)]
        inside = lambda q: (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]) >= 0
        crossing = lambda p, q: p + (q - p) * (((a[0] - p[0]) * (b[1] - a[1]) - (a[1] - p[1]) * (b[0] - a[0]))
                                               / ((q[0] - p[0]) * (b[1] - a[1]) - (q[1] - p[1]) * (b[0] - a[0])))
        kept = []
        for j in range(len(out)):
            p, q = out[j - 1], out[j]
            if inside(q):
                if not inside(p):
                    kept.append(crossing(p, q))
                kept.append(q)
            elif inside(p):
                kept.append(crossing(p, q))
        out = kept
    return np.array(out)


def coverage(name: str, width: int, height: int) -> None:
    scene = load_scene(REPO / "scenes" / f"{name}.yaml", overrides=[f"image.width={width}", f"image.height={height}"])
    light = next(light for light in scene.lights if isinstance(light, DirectionalLight))
    forward = np.asarray(light.direction, float) / np.linalg.norm(light.direction)
    right = np.cross(forward, _any_up(forward))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    plane = lambda points: np.stack([points @ right, points @ up], axis=-1)
    lo, hi = scene.geometry.bounds()
    radius = max(np.linalg.norm(hi - lo) / 2, 1e-6) * 1.01  # as clrays/inputs.py fits the map
    side, corner = 2 * radius, plane((lo + hi) / 2) - radius
    box = hull(plane(np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])))
    eye, far = np.asarray(scene.camera.position, float), effective_far(scene)
    cam_right, cam_up, cam_forward = camera_basis(scene.camera)
    tan_x, tan_y = half_extents(scene.camera, scene.image)
    pyramid = [eye] + [eye + far * (cam_forward + sx * tan_x * cam_right + sy * tan_y * cam_up)
                       for sx in (-1, 1) for sy in (-1, 1)]
    seen = clip(hull(plane(np.array(pyramid))), box)
    rng = np.random.default_rng(1)
    d = (cam_forward + rng.uniform(-tan_x, tan_x, (400000, 1)) * cam_right
         + rng.uniform(-tan_y, tan_y, (400000, 1)) * cam_up)
    points = eye + d / np.linalg.norm(d, axis=1, keepdims=True) * far * rng.uniform(0, 1, (400000, 1)) ** (1 / 3)
    clipped = plane(points[np.all((points >= lo) & (points <= hi), axis=1)])
    rays = primary_rays(scene.camera, scene.image, np.array([[0.5, 0.5]])).reshape(-1, 3)
    ends = np.minimum(depth_map(scene).reshape(-1), far)
    along = np.linspace(0, 1, 64)[None, :, None]
    segments = plane((eye + rays[:, None, :] * ends[:, None, None] * along).reshape(-1, 3))
    outline = Polygon(box)
    visible = segments[outline.contains_points(segments, radius=1e-9) | outline.contains_points(segments, radius=-1e-9)]
    grid = np.stack(np.meshgrid(np.arange(TEXELS), np.arange(TEXELS)), -1).reshape(-1, 2)
    centres = corner + (grid + 0.5) * side / TEXELS
    texel = side / TEXELS
    print(f"{name} {width}×{height}: the sphere's square {side:.2f} units, {100 * texel:.2f} cm texels at {TEXELS}²")
    for label, region in (("the box", box), ("the pyramid within the box's outline", seen),
                          ("the frustum clipped to the box (3D)", clipped), ("the visible ray segments", visible)):
        extent = region.max(axis=0) - region.min(axis=0)
        area = Polygon(hull(region))
        touched = area.contains_points(centres, radius=0.7 * texel) | area.contains_points(centres, radius=-0.7 * texel)
        print(f"  {label}: {extent[0]:.2f} × {extent[1]:.2f}, a fitted map {side / extent[0]:.2f} × "
              f"{side / extent[1]:.2f} finer; {100 * touched.mean():.1f} % of the texels")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+", help="scene names in scenes/ with a directional light")
    parser.add_argument("--size", type=image_size, default="320x180")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    for name in args.scenes:
        coverage(name, width, height)


if __name__ == "__main__":
    main()
