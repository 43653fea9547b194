"""The demo room lit by many point lights of the same total power: peak RSS and wall time of
one frame per light count and image size, from GNU time around `clrays render`
(bench/RESULTS.md, "Many lights").

    .venv/bin/python bench/many_lights.py                               # this tree
    .venv/bin/python bench/many_lights.py --repo ../before --lights 1 16  # another tree

Writes many_lights_<n>.yaml (scenes/demo.yaml with its one light split into n on a grid
over the roof, each with 1/n of the power) into --out, renders each with the tree's
clrays (`python -m clrays.cli render ...`, the tree first on PYTHONPATH; on the default
device, `--device` names one) and prints a markdown table.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import REPO, image_size, timed_process, tree_python, width_height  # noqa: E402
DEMO_LIGHT = "  - {type: point, position: [0.3, 7.5, -1.0], intensity: [260, 230, 190]}\n"


def scene_text(lights: int) -> str:
    """scenes/demo.yaml with `lights` point lights on a grid 8 × 4 units wide above the roof."""
    text = (REPO / "scenes" / "demo.yaml").read_text()
    columns = math.ceil(math.sqrt(2 * lights))
    rows = math.ceil(lights / columns)
    grid = [(0.3 + 8 * ((i % columns + 0.5) / columns - 0.5) * (columns > 1),
             -1.0 + 4 * ((i // columns + 0.5) / rows - 0.5) * (rows > 1)) for i in range(lights)]
    power = ", ".join(f"{value / lights:.6g}" for value in (260, 230, 190))
    block = "".join(f"  - {{type: point, position: [{x:.4f}, 7.5, {z:.4f}], intensity: [{power}]}}\n"
                    for x, z in grid)
    assert DEMO_LIGHT in text
    return text.replace(DEMO_LIGHT, block)


def measure(repo: Path, scene: Path, width: int, height: int, out: Path, device: str | None = None
            ) -> tuple[float, float]:
    """(wall seconds, peak RSS in MiB) of one render in a fresh process."""
    command = [sys.executable, "-m", "clrays.cli", "render", str(scene), "-o", str(out),
               *(["--device", device] if device else []), "--set", f"image.width={width}", "--set",
               f"image.height={height}"]
    seconds, peak, _ = timed_process(command, cwd=repo, env=tree_python(repo))
    return seconds, peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repo", type=Path, default=REPO, help="the source tree whose .venv renders")
    parser.add_argument("--lights", type=int, nargs="+", default=[1, 16, 64])
    parser.add_argument("-r", "--resolution", type=image_size, nargs="+", default=["640x360", "1280x720"])
    parser.add_argument("--out", type=Path, default=Path("/tmp/many_lights"))
    parser.add_argument("--device", help="a --device spec (default: the tree's default device)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"tree: {args.repo.resolve()}\n\n| lights | resolution | wall (s) | peak RSS (MiB) |\n|---|---|---|---|")
    for resolution in args.resolution:
        width, height = width_height(resolution)
        for lights in args.lights:
            scene = args.out / f"many_lights_{lights}.yaml"
            scene.write_text(scene_text(lights))
            wall, rss = measure(args.repo, scene, width, height, args.out / f"many_lights_{lights}_{resolution}.npy",
                                args.device)
            print(f"| {lights} | {width}×{height} | {wall:.1f} | {rss:.0f} |", flush=True)


if __name__ == "__main__":
    main()
