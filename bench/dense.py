"""A dense scene made at run time: a forest of thin poles (64-sided closed cylinders, about a
million triangles) with a point light behind it, as a PLY mesh in a YAML scene and as a
glTF file. Per tree: the first frame in a fresh process (load included: wall seconds and
peak RSS from GNU time, the host steps and the raster's device time from
`--stats`), then the per-frame cost of a camera pan (a sequence, whose geometry and edge
links are kept across frames) (bench/RESULTS.md, "Dense scenes").

    .venv/bin/python bench/dense.py                          # this tree, 640×360
    .venv/bin/python bench/dense.py --repo ../main --rows 40  # another tree, 400 k triangles

This interpreter runs each tree's clrays (`python -m clrays.cli` with the tree first on
PYTHONPATH, as bench/hostile.py does), on the default device (`--device` to name one).
Prints a markdown table.
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import REPO, image_size, markdown_table, timed_process, tree_python, width_height  # noqa: E402

SIDES = 64
SPACING = 0.25  # between poles, units
RADIUS, HEIGHT = 0.03, 3.0

SCENE = """version: 1
image: {{width: {width}, height: {height}, spp: 1}}
camera: {{position: [0, 1.6, 12], look_at: [0, 1.2, 0], fov_deg: 55, far: 40}}
lights:
  - {{type: point, position: [0.5, 2.5, -10], intensity: [400, 380, 340]}}
medium: {{sigma_s: 0.06, sigma_a: 0.01, phase: {{type: hg, g: 0.4}}}}
background: 0
objects:
  - {{type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 40, albedo: 0.45}}
  - {{type: mesh, file: {mesh}, albedo: 0.6}}
"""
PAN = """animation:
  fps: 24
  frames: [0, {last}]
  camera:
    - {{frame: 0, position: [0, 1.6, 12]}}
    - {{frame: {last}, position: [2, 1.6, 11.8]}}
"""


def poles(rows: int) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of rows × rows closed cylinders standing on y = 0."""
    angle = np.linspace(0, 2 * np.pi, SIDES, endpoint=False)
    ring = np.stack([RADIUS * np.cos(angle), np.zeros(SIDES), RADIUS * np.sin(angle)], axis=1)
    one = np.concatenate([ring, ring + [0, HEIGHT, 0], [[0, 0, 0], [0, HEIGHT, 0]]])
    k, j = np.arange(SIDES), (np.arange(SIDES) + 1) % SIDES
    bottom, top = 2 * SIDES, 2 * SIDES + 1
    faces = np.concatenate([np.stack([k, j, j + SIDES], 1), np.stack([k, j + SIDES, k + SIDES], 1),
                            np.stack([np.full(SIDES, bottom), j, k], 1),
                            np.stack([np.full(SIDES, top), k + SIDES, j + SIDES], 1)])
    offsets = (np.arange(rows) - (rows - 1) / 2) * SPACING
    grid = np.stack(np.meshgrid(offsets, offsets, indexing="ij"), -1).reshape(-1, 2)
    vertices = (one[None] + np.stack([grid[:, 0], np.zeros(len(grid)), grid[:, 1]], 1)[:, None]).reshape(-1, 3)
    faces = (faces[None] + (np.arange(len(grid)) * len(one))[:, None, None]).reshape(-1, 3)
    return vertices, faces


def write_ply(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\nproperty float x\n"
              f"property float y\nproperty float z\nelement face {len(faces)}\n"
              f"property list uchar int vertex_indices\nend_header\n").encode()
    rows = np.zeros(len(faces), dtype=[("n", "u1"), ("v", "<i4", 3)])
    rows["n"], rows["v"] = 3, faces
    path.write_bytes(header + vertices.astype("<f4").tobytes() + rows.tobytes())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repo", type=Path, default=REPO, help="the source tree whose clrays renders")
    parser.add_argument("--rows", type=int, default=62, help="poles a side (62: 3844 poles, 984 k triangles)")
    parser.add_argument("--size", type=image_size, default="640x360", help="WxH (default 640x360)")
    parser.add_argument("--pan", type=int, default=4, help="frames of the camera pan (default 4)")
    parser.add_argument("--device", help="a --device spec (default: the tree's default device)")
    parser.add_argument("--out", type=Path, default=Path("/tmp/clrays-dense"))
    args = parser.parse_args()
    width, height = width_height(args.size)
    args.out.mkdir(parents=True, exist_ok=True)
    vertices, faces = poles(args.rows)
    write_ply(args.out / "poles.ply", vertices, faces)
    still = args.out / "poles.yaml"
    still.write_text(SCENE.format(width=width, height=height, mesh="poles.ply"))
    panned = args.out / "poles_pan.yaml"
    panned.write_text(still.read_text() + PAN.format(last=args.pan - 1))
    clrays = [sys.executable, "-m", "clrays.cli"]
    device = ["--device", args.device] if args.device else []
    wall, rss, output = timed_process(clrays + ["render", str(still), "-o", str(args.out / "poles.png"), "--stats",
                                                *device], cwd=args.repo, env=tree_python(args.repo))
    raster = re.search(r"raster\s+([\d.]+) ms", output)
    host = re.search(r"host steps (.*?)(?: \(load holds|$)", output, re.M)
    pan_wall, pan_rss, pan_output = timed_process(clrays + ["sequence", str(panned), "-o", str(args.out / "pan_{}.png"),
                                                            "--no-progress", "--overwrite", *device],
                                                  cwd=args.repo, env=tree_python(args.repo))
    per_frame = re.search(r"([\d.]+) s per frame", pan_output)
    print(f"tree: {args.repo.resolve()}; {len(faces)} triangles at {args.size}\n")
    print(markdown_table(["first frame, load included (s)", "peak RSS (MiB)", "raster (ms)", "host steps",
                          "pan: s a frame", "pan peak RSS (MiB)"],
                         [[f"{wall:.1f}", f"{rss:.0f}", raster.group(1) if raster else "-",
                           host.group(1) if host else "(not listed)", per_frame.group(1) if per_frame else "-",
                           f"{pan_rss:.0f}"]]))


if __name__ == "__main__":
    main()
