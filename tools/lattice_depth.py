"""Write the depth image of scenes/lattice.yaml: a lattice window (mashrabiya) as one
8-bit grey + alpha PNG, the relief's depth in grey and its holes in alpha.

    .venv/bin/python tools/lattice_depth.py                      # scenes/textures/lattice.png, 128 x 192
    .venv/bin/python tools/lattice_depth.py -o out/big.png --width 1024 --height 1024

The pattern, in texel units of a cell `period` texels wide: bars along the cell borders
and along both diagonals of each cell, and a ring around each cell's centre, each bar
`bar` texels wide with a rounded profile (depth cos² across the bar: 1 on its ridge,
0 at its edges); a frame of full depth around the image. Everything else is a hole
(alpha 0). Deterministic: the same arguments write the same bytes.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image

DEFAULT_OUTPUT = Path(__file__).resolve().parents[1] / "scenes" / "textures" / "lattice.png"


def lattice_depth(width: int, height: int, period: float, bar: float, frame: int) -> tuple[np.ndarray, np.ndarray]:
    """(depth in [0, 1], solid) of the lattice, each (height, width)."""
    y, x = np.mgrid[0:height, 0:width] + 0.5
    half = bar / 2
    # Position inside the cell, centred: in [-period/2, period/2).
    cx = (x % period) - period / 2
    cy = (y % period) - period / 2
    distances = [
        period / 2 - np.abs(cx),  # to the cell's vertical borders
        period / 2 - np.abs(cy),  # to its horizontal borders
        np.abs(cx - cy) / np.sqrt(2),  # to its diagonals
        np.abs(cx + cy) / np.sqrt(2),
        np.abs(np.hypot(cx, cy) - period * 0.3),  # to the ring
    ]
    nearest = np.minimum.reduce(distances)
    depth = np.where(nearest < half, np.cos(0.5 * np.pi * nearest / half) ** 2, 0.0)
    solid = nearest < half
    border = (x < frame) | (y < frame) | (x > width - frame) | (y > height - frame)
    depth[border], solid[border] = 1.0, True
    return depth, solid


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", type=Path, default=DEFAULT_OUTPUT)
    parser.add_argument("--width", type=int, default=128)
    parser.add_argument("--height", type=int, default=192)
    parser.add_argument("--period", type=float, default=32.0, help="cell size, texels")
    parser.add_argument("--bar", type=float, default=3.0, help="bar width, texels")
    parser.add_argument("--frame", type=int, default=4, help="border width, texels")
    args = parser.parse_args()
    depth, solid = lattice_depth(args.width, args.height, args.period, args.bar, args.frame)
    grey = np.round(depth * 255).astype(np.uint8)
    alpha = np.where(solid, 255, 0).astype(np.uint8)
    Image.fromarray(np.dstack([grey, alpha]), "LA").save(args.output)
    print(f"{args.output}: {args.width} x {args.height}, {solid.mean():.0%} solid")


if __name__ == "__main__":
    main()
