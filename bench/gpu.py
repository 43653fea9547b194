"""A frame's cost on one device at the sizes the published anchors used, with the error that
goes with it: per bench scene, size and method, the device time per kernel, the wall time
per frame in a warm session and in a sequence, the host's share, the host's waits, and the
error against `exact` measured from this device's images (bench/RESULTS.md, "The GPU
table").

    CLRAYS_DEVICE=nvidia .venv/bin/python bench/gpu.py                      # the whole table
    .venv/bin/python bench/gpu.py demo --sizes 320x180 --frames 3          # a quick look on a CPU
    .venv/bin/python bench/gpu.py --methods minmax --sizes 1280x720,2560x1600 --kernels

Every size's scene is the scene file's with its image size replaced, sizes derived from it
as `clrays render` derives them (docs/scene-format.md). Columns:
- **device ms**: the median frame's device time, every kernel's profiling event summed
  (and the host-timed stages, `--stats`'s total); `--kernels` lists the largest kernels.
- **warm wall ms**: a frame rendered from scratch (no stage reused) in a session whose
  kernels are built, median of `--frames`.
- **sequence wall ms**: per frame of a `--frames`-long sequence whose camera turns 0.5°
  about its target each frame (so every camera stage runs again, and a shadow map whose
  light and geometry stand still is kept, as `clrays sequence` keeps it), with frames in
  flight where `clrays sequence` keeps them (a GPU): the whole sequence's wall time over
  its frames.
- **host ms**: sequence wall less the sequence's device time per frame (its frames' own
  kernels, what a frame kept from the one before left out; host-timed stages count as the
  host's): the host's work the device waits for.
- **waits**: the times the host waited for the device in one frame (`RenderResult.host_waits`).
- **RMSE % / p99 %**: against `exact` on the bench's pixel subset (`--pixels`, kept in
  `--cache`), depth edges out, of the last warm frame's image.
"""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import REPO, SCENES, KernelClock, check_scenes, frame_count, image_sizes, load  # noqa: E402
from clrays.runs.bench import error_pixels  # noqa: E402
from clrays.runs.references import EXACT, ReferenceCache  # noqa: E402
from clrays.session import Renderer  # noqa: E402

SIZES = "1280x720,1920x1080,2560x1600,3840x2160"
#: The camera's turn per frame of the timed sequence, about its target.
TURN_DEGREES = 0.5


def turned(scene, frame: int):
    """`scene` with its camera turned frame × TURN_DEGREES about the vertical through its target."""
    camera = scene.camera
    angle = math.radians(TURN_DEGREES * frame)
    offset = np.asarray(camera.position, float) - np.asarray(camera.look_at, float)
    c, s = math.cos(angle), math.sin(angle)
    rotated = np.array([c * offset[0] + s * offset[2], offset[1], -s * offset[0] + c * offset[2]])
    return replace(scene, camera=replace(camera, position=np.asarray(camera.look_at, float) + rotated))


def sequence_ms(renderer: Renderer, scene, frames: int) -> tuple[float, float]:
    """(wall ms, device ms) per frame of a sequence of `frames` turned frames, each image
    read back, as `clrays sequence` renders them: frame N+1 submitted before frame N is
    read where frames in flight win on the device (Renderer.frames_in_flight_win: a GPU),
    else one by one. The device time is the frames' own (RenderResult.device_ms), stages a
    frame kept from the one before left out, as the sequence's are."""
    scenes = [turned(scene, index + 1) for index in range(frames)]
    results = []
    start = time.perf_counter()
    if renderer.frames_in_flight_win:
        pending = renderer.submit(scenes[0])
        for upcoming in scenes[1:]:
            following = renderer.submit(upcoming)
            results.append(pending.result())
            pending = following
        results.append(pending.result())
    else:
        results = [renderer.render(each) for each in scenes]
    wall = (time.perf_counter() - start) * 1e3 / frames
    return wall, sum(result.device_ms for result in results) / frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=list(SCENES), help="scene names in scenes/ (default: the bench four)")
    parser.add_argument("--sizes", type=image_sizes, default=image_sizes(SIZES), help=f"WxH,... (default {SIZES})")
    parser.add_argument("--methods", default="minmax,volume_moments", help="comma-separated methods (default "
                                                                           "minmax,volume_moments)")
    parser.add_argument("--frames", type=frame_count, default=5, help="timed frames (default 5)")
    parser.add_argument("--kernels", action="store_true", help="list the largest kernels of each row")
    parser.add_argument("--pixels", type=frame_count, default=4000, help="pixels the error is measured on (default 4000)")
    parser.add_argument("--cache", default=str(REPO / ".cache" / "references"), help="where exact's pixels are kept")
    args = parser.parse_args()
    check_scenes("gpu.py", args.scenes)
    methods = [method for method in args.methods.split(",") if method]
    clock = KernelClock()
    references = ReferenceCache(Path(args.cache))
    renderer = Renderer()
    print(f"{renderer.device.name}; median of {args.frames} frames\n")
    print("| scene | size | method | device ms | warm wall ms | sequence wall ms | host ms | waits | RMSE % | p99 % |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        for size in args.sizes:
            width, height = (int(v) for v in size.split("x"))
            for method in methods:
                scene = load("gpu.py", name, width, height, [f"render.method={method}"])
                renderer.clear()
                renderer.render(scene, reuse=False)  # kernels built, buffers pooled
                clock.frame_done(keep=False)
                device, walls, waits = [], [], []
                result = None
                for _ in range(args.frames):
                    start = time.perf_counter()
                    result = renderer.render(scene, reuse=False)
                    walls.append((time.perf_counter() - start) * 1e3)
                    device.append(sum(result.stage_ms.values()))
                    waits.append(result.host_waits)
                    clock.frame_done()
                image = result.image
                renderer.clear()
                renderer.render(turned(scene, 0))  # the sequence's first frame: what it keeps is kept
                sequence, sequence_device = sequence_ms(renderer, scene, args.frames)
                kernels = clock.medians()
                clock.frame_done(keep=False)
                error = references.error(scene, EXACT, image, error_pixels(width, height, args.pixels))
                device_ms = statistics.median(device)
                print(f"| {name} | {width}×{height} | {method} | {device_ms:.2f} | {statistics.median(walls):.2f} | "
                      f"{sequence:.2f} | {sequence - sequence_device:.2f} | {statistics.median(waits):.0f} | "
                      f"{100 * error.rmse:.4f} | {100 * error.p99:.4f} |", flush=True)
                if args.kernels:
                    print("  " + ", ".join(f"{k} {m:.2f}" for m, k in kernels[:8]), flush=True)


if __name__ == "__main__":
    main()
