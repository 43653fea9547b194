"""Images of the bench scenes from one source tree, and whether another tree's are the same
bit for bit: for a change that must not move the opaque path or depth peeling
(bench/RESULTS.md, "Translucent objects: the camera side").

    .venv/bin/python bench/same_images.py --repo ../main --out /tmp/before   # the tree before
    .venv/bin/python bench/same_images.py --out /tmp/after --against /tmp/before

Renders demo, bunny, behind and sun (opaque) and glass_row, glass_pane, stained_glass with
depth peeling at 1, 4 and 8 layers, each with minmax and raymarch, at 96×54 (every stage
computed), saves each as .npy in --out, and with --against prints per image whether it is
identical to the one of the same name there; exits 1 if any is not.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
OPAQUE = ("demo", "bunny", "behind", "sun")
TRANSLUCENT = ("glass_row", "glass_pane", "stained_glass")
METHODS = ("minmax", "raymarch")


def jobs() -> list[tuple[str, str, list[str]]]:
    """(image name, scene, overrides) of every image."""
    size = ["image.width=96", "image.height=54"]
    out = [(f"{scene}_{method}", scene, method, size) for scene in OPAQUE for method in METHODS]
    for layers in (1, 4, 8):
        out += [(f"{scene}_{method}_peel{layers}", scene, method,
                 [*size, f"render.transparency={{type: depth_peeling, layers: {layers}}}"])
                for scene in TRANSLUCENT for method in METHODS]
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=Path, default=REPO, help="the source tree whose clrays renders")
    parser.add_argument("--out", type=Path, required=True, help="folder of the .npy images")
    parser.add_argument("--against", type=Path, help="folder of another tree's images to compare with")
    args = parser.parse_args()
    sys.path.insert(0, str(args.repo.resolve()))
    import clrays
    from clrays.scene.load import load_scene
    from clrays.session import Renderer

    print(f"clrays from {Path(clrays.__file__).parent}")
    args.out.mkdir(parents=True, exist_ok=True)
    renderer, differ = Renderer(reuse=False), 0
    for name, scene, method, overrides in jobs():
        image = renderer.render(load_scene(REPO / "scenes" / f"{scene}.yaml", overrides=overrides), method).image
        np.save(args.out / f"{name}.npy", image)
        if args.against is None:
            print(name, flush=True)
            continue
        before = np.load(args.against / f"{name}.npy")
        same = np.array_equal(image, before)
        differ += not same
        print(f"{name}: {'bit-identical' if same else f'differs, max {np.abs(image - before).max():.3g}'}",
              flush=True)
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
