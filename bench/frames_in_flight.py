"""Frames in flight: a sequence's wall time per frame when the host prepares frame N+1
while the device renders frame N (Renderer.submit, `clrays sequence`), against one
frame at a time.

    .venv/bin/python bench/frames_in_flight.py                          # orbit 0:11, 1280x720
    .venv/bin/python bench/frames_in_flight.py --size 640x360 --rounds 5

Each round runs the frames both ways, twice: as a sequence (render_sequence, the frame
files written as `clrays sequence` writes them, into a scratch folder), and through the
Python API alone (Renderer.submit of frame N+1 before frame N's `result()`, against
`render`), in one process on one device, alternating which way goes first so that load
from other processes falls on both alike. Each run has a fresh session (its stage cache
empty); the kernels are built, and one round run, before timing. Both ways' images and
files are checked bit for bit. Prints the median over rounds of the wall time per frame
of each, the ratio of the medians, and the median of each round's ratio (in flight / one
at a time).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from arguments import frame_count, image_size  # noqa: E402  (bench/, beside this script)
from clrays.device import Device  # noqa: E402
from clrays.runs.sequence import render_sequence  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402

WAYS = {"in flight": True, "one at a time": False}
RUNS = ("sequence", "API")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default="orbit", help="a scene name in scenes/ (default: orbit)")
    parser.add_argument("--size", type=image_size, default="1280x720", help="WxH (default 1280x720)")
    parser.add_argument("--frames", type=frame_count, default=12, help="frames 0..N-1 (default 12)")
    parser.add_argument("--rounds", type=frame_count, default=3, help="runs of each way (default 3)")
    parser.add_argument("--format", default="png", choices=("png", "exr", "npy"), help="frame files (default png)")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    scene = load_scene(REPO / "scenes" / f"{args.scene}.yaml",
                       overrides=[f"image.width={width}", f"image.height={height}"])
    frames = range(args.frames)
    device = Device()
    Renderer(device, reuse=False).render(scene.animation.scene_at(scene, 0) if scene.animation else scene)  # builds
    scenes = [scene.animation.scene_at(scene, frame) if scene.animation else scene for frame in frames]
    times: dict[tuple[str, str], list[float]] = {(run, way): [] for run in RUNS for way in WAYS}
    images: dict[str, list[np.ndarray]] = {}
    with tempfile.TemporaryDirectory() as scratch:
        # Round 0 warms up (the pool's buffers, the PNG encoder, the page cache) and is not counted.
        for round_index in range(args.rounds + 1):
            ways = list(WAYS.items())
            for run in RUNS:
                for way, in_flight in (ways if round_index % 2 == 0 else ways[::-1]):
                    start = time.perf_counter()
                    if run == "sequence":
                        pattern = str(Path(scratch) / way.replace(" ", "_") / f"f_{{:03d}}.{args.format}")
                        render_sequence(scene, pattern, frames, renderer=Renderer(device), overwrite=True,
                                        in_flight=in_flight)
                    else:
                        images[way] = api_frames(Renderer(device), scenes, in_flight)
                    if round_index > 0:
                        times[run, way].append((time.perf_counter() - start) * 1e3 / len(frames))
            if round_index > 0:
                print(f"round {round_index}: " + ", ".join(f"{run} {way} {spent[-1]:.1f} ms"
                                                         for (run, way), spent in times.items()), flush=True)
        folders = [Path(scratch) / way.replace(" ", "_") for way in WAYS]
        for frame, *pair in zip(frames, *images.values()):
            files = [folder / f"f_{frame:03d}.{args.format}" for folder in folders]
            if files[0].read_bytes() != files[1].read_bytes() or not np.array_equal(*pair):
                raise SystemExit(f"frame {frame}: the frames in flight made another image")
    print(f"\n{args.scene} frames 0:{args.frames - 1}, {width}×{height}, {device.name}, {args.rounds} rounds; "
          f"wall time per frame, median over rounds\n")
    print("| run | " + " | ".join(WAYS) + " | ratio of the medians | median of the rounds' ratios | "
          "rounds (ms per frame) |")
    print("|---|" + "---|" * (len(WAYS) + 3))
    for run in RUNS:
        medians = [statistics.median(times[run, way]) for way in WAYS]
        # Each round's two runs ran back to back, so their ratio is the steadier figure
        # where other processes load the cores unevenly over the rounds.
        paired = statistics.median(a / b for a, b in zip(*(times[run, way] for way in WAYS)))
        rounds = "; ".join(f"{way}: {', '.join(f'{t:.0f}' for t in times[run, way])}" for way in WAYS)
        print(f"| {run} | " + " | ".join(f"{m:.1f} ms" for m in medians) + f" | {medians[0] / medians[1]:.3f} | "
              f"{paired:.3f} | {rounds} |")


def api_frames(renderer: Renderer, scenes: list, in_flight: bool) -> list[np.ndarray]:
    """The images of `scenes`: each submitted before the one before is read (`in_flight`),
    or rendered one at a time."""
    if not in_flight:
        return [renderer.render(scene).image for scene in scenes]
    images, pending = [], None
    for scene in scenes:
        submitted = renderer.submit(scene)
        if pending is not None:
            images.append(pending.result().image)
        pending = submitted
    return images + [pending.result().image]


if __name__ == "__main__":
    main()
