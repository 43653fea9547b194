"""raymarch at 1280×720 at step counts `clrays bench`'s ladder does not visit (past its cap,
or under its first rung of 32): one frame per STEPS:SHADOW_MAP argument, its relative RMSE
against exact on the bench's own 4000 pixels (the same reference cache), its CPU and wall
time (bench/RESULTS.md, equiangular re-run).

    PYTHONPATH=. python bench/raymarch_past_cap.py scenes/sun.yaml 1024:2048 --volume-only --cache .cache/clrays
"""
import argparse
import time
from dataclasses import replace

from clrays.runs.bench import error_pixels, volume_only
from clrays.runs.references import EXACT, ReferenceCache
from clrays.scene.load import load_scene
from clrays.session import Renderer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("points", nargs="+", metavar="STEPS:SHADOW_MAP")
    parser.add_argument("--volume-only", action="store_true", help="as `clrays bench --volume-only`")
    parser.add_argument("--cache", default=".cache/clrays", help="exact references (as `clrays bench --cache`)")
    args = parser.parse_args()
    scene = load_scene(args.scene)
    scene = replace(scene, image=replace(scene.image, width=1280, height=720))
    scene = volume_only(scene) if args.volume_only else scene
    pixels = error_pixels(1280, 720, 4000)  # the bench's seeded subset
    cache, renderer = ReferenceCache(args.cache), Renderer(reuse=False)
    for point in args.points:
        steps, shadow_map = (int(part) for part in point.split(":"))
        marched = replace(scene, render=replace(scene.render, method="raymarch", steps=steps, shadow_map=shadow_map))
        cpu, wall = time.process_time(), time.perf_counter()
        image = renderer.render(marched, "raymarch").image
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        error = cache.error(marched, EXACT, image, pixels)
        print(f"{args.scene}{' volume-only' if args.volume_only else ''} 1280x720 raymarch steps={steps} shadow_map={shadow_map}: rel. RMSE {error.rmse:.3%}, "
              f"p99 {error.p99:.3%}, cpu {cpu * 1e3:.0f} ms, wall {wall * 1e3:.0f} ms (one frame, kernel build "
              f"included)", flush=True)


if __name__ == "__main__":
    main()
