"""The host's share of a frame: per bench scene, the integrand table build on its own (its
arguments captured from a real frame, rebuilt on one core), the main thread's CPU time per
frame, the frame's wall time, its stage time, the wall time less the stage time (the median
of each frame's) and the times the host waited for the device in a frame; medians over
frames rendered from scratch (bench/RESULTS.md, "Host stages").

    .venv/bin/python bench/host_stages.py --size 1280x720 --frames 5
    .venv/bin/python bench/host_stages.py --repo ../main --size 1280x720 --frames 5   # another tree
    .venv/bin/python bench/host_stages.py --against ../main   # and its table build, in turns

`--repo` imports clrays from another source tree (as bench/same_images.py), so two trees
can be timed in turns on the same machine. The build's time is the median of `--builds`
rebuilds after one warm-up; with `--against`, the other tree's stages/integrand.py builds
the same tables in turns with this one's, in this process (the fairest comparison on a
loaded machine), and must give the same float32 tables. CPU time is `time.thread_time` of
the rendering thread (the device's threads are not in it).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENES = ("demo", "bunny", "behind", "sun")
sys.path.insert(0, str(Path(__file__).resolve().parent))
from arguments import frame_count, image_size  # noqa: E402  (bench/, beside this script; no clrays import)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=SCENES, help="scene names in scenes/ (default: the bench four)")
    parser.add_argument("--repo", type=Path, default=REPO, help="the source tree whose clrays runs")
    parser.add_argument("--size", type=image_size, default="1280x720", help="WxH (default 1280x720)")
    parser.add_argument("--frames", type=frame_count, default=5, help="timed frames per scene (default 5)")
    parser.add_argument("--builds", type=frame_count, default=9, help="integrand rebuilds per scene (default 9)")
    parser.add_argument("--against", type=Path, help="another source tree whose table build runs in turns")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    sys.path.insert(0, str(args.repo.resolve()))
    import clrays
    import clrays.stages.integrand as integrand_stage
    from clrays.scene.load import load_scene
    from clrays.session import Renderer

    print(f"clrays from {Path(clrays.__file__).parent}, {width}×{height}, median of {args.frames} frames\n")
    other = None
    if args.against is not None:  # the other tree's module, its imports resolved in this package
        import importlib.util

        spec = importlib.util.spec_from_file_location("clrays.stages.integrand_against",
                                                      args.against / "clrays" / "stages" / "integrand.py")
        other = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = other
        spec.loader.exec_module(other)
    against = " | against's build ms | same float32 tables" if other else ""
    print("| scene | integrand build ms (one core) | main thread CPU ms / frame | wall ms | stage ms | wall − stage ms "
          "| host waits" + against + " |")
    print("|---|---|---|---|---|---|---|" + "---|---|" * bool(other))
    build = integrand_stage.build_integrand
    for name in args.scenes:
        scene = load_scene(REPO / "scenes" / f"{name}.yaml", overrides=[f"image.width={width}", f"image.height={height}"])
        renderer = Renderer(reuse=False)
        calls = []

        def capture(*a, **k):
            calls.append((a, k))
            return build(*a, **k)

        integrand_stage.build_integrand = capture
        renderer.render(scene)  # builds the kernels, and captures the build's arguments
        integrand_stage.build_integrand = build
        cpu, wall, stage, host, waits = [], [], [], [], []
        for _ in range(args.frames):
            started_cpu, started = time.thread_time(), time.perf_counter()
            result = renderer.render(scene)
            wall.append((time.perf_counter() - started) * 1e3)
            cpu.append((time.thread_time() - started_cpu) * 1e3)
            stage.append(sum(result.stage_ms.values()))
            host.append(wall[-1] - stage[-1])
            waits.append(getattr(result, "host_waits", None))  # (None: a tree from before it counted them)
        builds, theirs, same = [], [], True
        for a, k in calls[:1] * (args.builds + 1):
            started = time.perf_counter()
            tables = build(*a, **k)
            builds.append((time.perf_counter() - started) * 1e3)
            if other is not None:
                started = time.perf_counter()
                reference = other.build_integrand(*a, **k)
                theirs.append((time.perf_counter() - started) * 1e3)
                same = same and all(
                    (mine is None and their is None) or np.array_equal(np.float32(mine), np.float32(their))
                    for mine, their in ((tables.prefix, reference.prefix), (tables.basis_beta, reference.basis_beta),
                                        (tables.prefix_gamma, reference.prefix_gamma)))
        built = f"{statistics.median(builds[1:]):.1f}" if calls else "—"
        compared = f" | {statistics.median(theirs[1:]):.1f} | {'yes' if same else 'NO'}" if other and calls else \
            (" | — | —" if other else "")
        counted = "—" if None in waits else f"{statistics.median(waits):.0f}"
        print(f"| {name} | {built} | {statistics.median(cpu):.1f} | {statistics.median(wall):.1f} | "
              f"{statistics.median(stage):.1f} | {statistics.median(host):.1f} | {counted}{compared} |", flush=True)


if __name__ == "__main__":
    main()
