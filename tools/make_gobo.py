"""Write the light textures of the example scenes (docs/light-textures.md): deterministic
patterns drawn with numpy, saved as 8-bit sRGB PNGs beside the scenes.

    .venv/bin/python tools/make_gobo.py            # writes scenes/textures/gobo.png and stained_glass.png
    .venv/bin/python tools/make_gobo.py --check    # exit 1 if a file differs from what this writes

gobo.png (256²): a stage gobo, a disc cut into ten curved blades around an open centre, with
a ring of round holes, in amber and blue glass, black where the metal stops the light.
stained_glass.png (256²): a window of 16 × 16 coloured panes, each split by a diagonal,
with lead lines two texels wide: a texture with detail at every texel scale, tiled by a
directional light.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from PIL import Image

FOLDER = Path(__file__).resolve().parents[1] / "scenes" / "textures"


def _encode(linear: np.ndarray) -> np.ndarray:
    """Linear [0, 1] → 8-bit sRGB (the inverse of clrays.scene.textures.srgb_to_linear)."""
    c = np.clip(linear, 0.0, 1.0)
    encoded = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    return np.round(encoded * 255.0).astype(np.uint8)


def gobo(size: int = 256) -> np.ndarray:
    """The stage gobo, linear RGB (size, size, 3)."""
    y, x = (np.mgrid[0:size, 0:size] + 0.5) / size * 2.0 - 1.0
    r, theta = np.hypot(x, y), np.arctan2(y, x)
    # Ten blades that curve with the radius: open where sin(10·(θ + 1.4·r)) > 0.
    blades = np.sin(10.0 * (theta + 1.4 * r)) > -0.15
    open_ = (r < 0.92) & ((r < 0.22) | blades)
    # A ring of twelve round holes across the blades.
    hole_angle = np.round(theta / (2 * np.pi / 12)) * (2 * np.pi / 12)
    hx, hy = 0.62 * np.cos(hole_angle), 0.62 * np.sin(hole_angle)
    open_ |= (np.hypot(x - hx, y - hy) < 0.07) & (r < 0.92)
    amber = np.array([1.0, 0.62, 0.22])
    blue = np.array([0.35, 0.55, 1.0])
    colour = np.where((r < 0.45)[..., None], amber, blue)
    return np.where(open_[..., None], colour, 0.0)


def stained_glass(size: int = 256, panes: int = 16, seed: int = 14) -> np.ndarray:
    """The stained-glass window, linear RGB (size, size, 3)."""
    rng = np.random.default_rng(seed)
    palette = np.array([[0.9, 0.15, 0.1], [0.1, 0.35, 0.9], [0.95, 0.8, 0.15], [0.15, 0.7, 0.3],
                        [0.6, 0.2, 0.8], [0.95, 0.95, 0.9]])
    y, x = np.mgrid[0:size, 0:size]
    cell = size // panes
    i, j = y // cell, x // cell
    u, v = (x % cell) / cell, (y % cell) / cell
    upper = u > v  # each pane is split along its diagonal
    choice = rng.integers(0, len(palette), size=(panes, panes, 2))
    colour = palette[choice[i, j, upper.astype(int)]]
    lead = (x % cell < 2) | (y % cell < 2) | (np.abs(u - v) * cell < 1.0)
    return np.where(lead[..., None], 0.0, colour)


TEXTURES = {"gobo.png": gobo, "stained_glass.png": stained_glass}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare instead of writing")
    args = parser.parse_args(argv)
    FOLDER.mkdir(parents=True, exist_ok=True)
    stale = []
    for name, make in TEXTURES.items():
        pixels = _encode(make())
        path = FOLDER / name
        if args.check:
            if not path.is_file() or not np.array_equal(np.asarray(Image.open(path).convert("RGB")), pixels):
                stale.append(name)
        else:
            Image.fromarray(pixels, "RGB").save(path, optimize=True)
            print(f"wrote {path}")
    if stale:
        print(f"stale: {', '.join(stale)} (run tools/make_gobo.py)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
