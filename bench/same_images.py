"""Images of the bench scenes from one source tree, and whether another tree's are the same
bit for bit: for a change that must not move any image (bench/RESULTS.md, "Translucent
objects: the camera side", "One frame, one figure").

    .venv/bin/python bench/same_images.py --repo ../main --out /tmp/before   # the tree before
    .venv/bin/python bench/same_images.py --out /tmp/after --against /tmp/before

Renders, at 96×54 with every stage computed: demo, bunny, behind and sun (opaque) with
minmax, raymarch and volume_moments; glass_row, glass_pane, stained_glass with their default
transparency (MBOIT) and with depth peeling at 1, 4 and 8 layers, minmax and raymarch; the
textured lights of gobo and stained_glass and the relief of lattice, minmax and raymarch;
the other scenes (colonnade, grate, room), minmax and raymarch;
demo with pixel sampling and bunny with filtered surface shadows; then orbit's first four
frames as a sequence (one session, stages reused between frames) and a sweep of gobo over
two σs and two slice counts (one session, reused between points). Saves each as .npy in
--out, and with --against prints per image whether it is identical to the one of the same
name there; exits 1 if any is not. Methods go by the names both trees read (`moments`).
"""
from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
OPAQUE = ("demo", "bunny", "behind", "sun")
TRANSLUCENT = ("glass_row", "glass_pane", "stained_glass")
OTHERS = ("colonnade", "grate", "room")
METHODS = ("minmax", "raymarch")


SIZE = ["image.width=96", "image.height=54"]


def jobs() -> list[tuple[str, str, str, list[str]]]:
    """(image name, scene, method, overrides) of every single frame."""
    out = [(f"{scene}_{method}", scene, method, SIZE) for scene in OPAQUE for method in (*METHODS, "moments")]
    out += [(f"{scene}_{method}_default", scene, method, SIZE) for scene in TRANSLUCENT for method in METHODS]
    for layers in (1, 4, 8):
        out += [(f"{scene}_{method}_peel{layers}", scene, method,
                 [*SIZE, f"render.transparency={{type: depth_peeling, layers: {layers}}}"])
                for scene in TRANSLUCENT for method in METHODS]
    out += [(f"{scene}_{method}", scene, method, SIZE) for scene in ("gobo", "lattice") for method in METHODS]
    out += [(f"{scene}_{method}", scene, method, SIZE) for scene in OTHERS for method in METHODS]
    out += [("demo_pixel", "demo", "minmax", [*SIZE, "render.sampling=pixel"]),
            ("bunny_filtered", "bunny", "minmax", [*SIZE, "render.surface_shadows=filtered"])]
    return out


def runs(load_scene, Renderer):
    """(image name, image) of a sequence and a sweep, each in one session that reuses stages."""
    session = Renderer()
    orbit = load_scene(REPO / "scenes" / "orbit.yaml", overrides=SIZE)
    for frame in range(4):
        yield f"orbit_frame{frame}", session.render(orbit.animation.scene_at(orbit, frame)).image
    session = Renderer()
    for sigma in ("0.05", "0.1"):
        for slices in ("256", "512"):
            scene = load_scene(REPO / "scenes" / "gobo.yaml",
                               overrides=[*SIZE, f"medium.sigma_s={sigma}", f"render.slices={slices}"])
            yield f"gobo_sweep_{sigma}_{slices}", session.render(scene).image


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
    frames = ((name, renderer.render(load_scene(REPO / "scenes" / f"{scene}.yaml", overrides=overrides), method).image)
              for name, scene, method, overrides in jobs())
    for name, image in itertools.chain(frames, runs(load_scene, Renderer)):
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
