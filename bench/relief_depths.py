"""How many view samples the relief's pre-warp gives another depth than its triangles
(bench/RESULTS.md, "Relief objects"; docs/design.md, "Relief objects"):

    .venv/bin/python bench/relief_depths.py             # the lattice from 3 angles, and bench/relief.py's scene
    .venv/bin/python bench/relief_depths.py --no-bench  # the lattice only (seconds)

For each scene, the raster stage runs twice on the device, with `render.relief: prewarp`
and `render.relief: triangles`, and the camera depths and each light's shadow-map depths
are compared sample by sample: a sample differs when the two depths are not equal to 1e-5
of the triangles' depth. "farther" counts those where the pre-warp's depth is the larger
(a hit the mapping missed: it sees past the relief, or a farther part of it). The lattice
views are those of tests/methods/test_relief.py (96 × 72, 0°, 60° and 80° off the
window's normal); the bench scene is bench/relief.py's (640 × 360, a 1024² bump field).
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from relief import SCENE, bump_field  # noqa: E402  (bench/relief.py)

from clrays.device import Device, StageTimer  # noqa: E402
from clrays.inputs import frame_inputs, upload  # noqa: E402
from clrays.scene.costs import with_derived_sizes  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.stages.raster import raster_camera, raster_shadow_map  # noqa: E402

LATTICE = REPO / "scenes" / "lattice.yaml"


def lattice_view(angle_deg: float) -> list[str]:
    """tests/methods/test_relief.py's lattice view: towards the window's centre from 3.6
    units, `angle_deg` off its normal towards +x."""
    angle = math.radians(angle_deg)
    position = np.array([0, 2.5, -4.08]) + 3.6 * np.array([math.sin(angle), 0.0, math.cos(angle)])
    return [f"camera.position={[round(float(p), 6) for p in position]}", "camera.look_at=[0, 2.5, -4.08]",
            "image.width=96", "image.height=72"]


def depths(device: Device, path: Path, overrides: list[str]) -> list[np.ndarray]:
    """The camera's depths, then each light's shadow-map depths, as float32."""
    scene = with_derived_sizes(load_scene(path, overrides))
    buffers = upload(device, frame_inputs(scene))
    timer = StageTimer()
    camera_depth, _ = raster_camera(device, buffers, timer)
    result = [device.read(camera_depth, buffers.inputs.samples, np.uint32).view(np.float32)]
    for index in range(len(scene.lights)):
        shadow_map = raster_shadow_map(device, buffers, index, timer)
        result.append(device.read(shadow_map.depth, shadow_map.texels, np.uint32).view(np.float32))
    return result


def differing(prewarp: np.ndarray, triangles: np.ndarray) -> tuple[int, int]:
    """(samples whose depths differ, of which the pre-warp's is farther)."""
    with np.errstate(invalid="ignore"):  # inf − inf: both see nothing, equal already
        differ = ~((prewarp == triangles) | (np.abs(prewarp - triangles) <= 1e-5 * triangles))
    return int(differ.sum()), int((prewarp[differ] > triangles[differ]).sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--no-bench", action="store_true", help="leave out bench/relief.py's 1024² scene")
    args = parser.parse_args()
    cases = [(f"lattice, {angle}°, 96×72", LATTICE, lattice_view(angle)) for angle in (0, 60, 80)]
    if not args.no_bench:
        folder = Path(tempfile.mkdtemp(prefix="clrays-relief-depths-"))
        np.save(folder / "bumps.npy", bump_field(1024))
        (folder / "bumps.yaml").write_text(SCENE.format(width=640, height=360, shadows="map"))
        cases.append(("bench/relief.py's 1024² bump field, 640×360", folder / "bumps.yaml", []))
    device = Device()
    print("| scene | camera samples differing (farther) | shadow-map texels differing (farther) |")
    print("|---|---|---|")
    for name, path, overrides in cases:
        prewarp = depths(device, path, overrides + ["render.relief=prewarp"])
        triangles = depths(device, path, overrides + ["render.relief=triangles"])
        cells = [differing(a, b) for a, b in zip(prewarp, triangles)]
        camera, maps = cells[0], cells[1:]
        print(f"| {name} | {camera[0]} of {prewarp[0].size} ({camera[1]}) | "
              + ", ".join(f"{n} of {a.size} ({f})" for (n, f), a in zip(maps, prewarp[1:])) + " |", flush=True)


if __name__ == "__main__":
    main()
