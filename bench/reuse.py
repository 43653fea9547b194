"""Stage reuse across frames: a render session that keeps stage results against
independent renders, on a camera orbit (static light) and a σs sweep.

    .venv/bin/python bench/reuse.py                 # both workloads, 640x360
    .venv/bin/python bench/reuse.py --frames 12     # a quicker orbit

Both sessions share one device (kernels built once, before timing) and render each
frame in turn, alternating which goes first, so load from other processes falls on
both alike. Every image of the reusing session is checked bit for bit against the
independent one. Prints a markdown table (bench/RESULTS.md, "Stage reuse").
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays.device import Device  # noqa: E402
from clrays.session import Renderer  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402

SIGMAS = [f"{0.01 * i:.2f}" for i in range(1, 13)]


def compare(name: str, scenes: list, device: Device) -> dict:
    kept, scratch = Renderer(device), Renderer(device, reuse=False)
    Renderer(device, reuse=False).render(scenes[0])  # build every kernel before timing
    times = {"reuse": [], "independent": []}
    stages = {"reuse": {}, "independent": {}}
    reused_counts: dict[str, int] = {}
    for n, scene in enumerate(scenes):
        order = [("reuse", kept), ("independent", scratch)]
        results = {}
        for label, session in (order if n % 2 == 0 else order[::-1]):
            start = time.perf_counter()
            results[label] = session.render(scene)
            times[label].append(time.perf_counter() - start)
            for stage, ms in results[label].stage_ms.items():
                stages[label][stage] = stages[label].get(stage, 0.0) + ms
        if not np.array_equal(results["reuse"].image, results["independent"].image):
            raise SystemExit(f"{name}: frame {n}: reuse changed the image")
        for stage in results["reuse"].reused:
            reused_counts[stage] = reused_counts.get(stage, 0) + 1
    return {"name": name, "frames": len(scenes), "times": times,
            "stages": {k: {s: ms / len(scenes) for s, ms in v.items()} for k, v in stages.items()},
            "reused": reused_counts}


def table(results: list[dict]) -> str:
    lines = ["| workload | frames | independent: total (mean/frame) | with reuse: total (mean/frame) | speedup | "
             "stages reused (frames) |", "|---|---|---|---|---|---|"]
    for r in results:
        a, b = sum(r["times"]["independent"]), sum(r["times"]["reuse"])
        reused = ", ".join(f"{s} {n}" for s, n in r["reused"].items())
        lines.append(f"| {r['name']} | {r['frames']} | {a:.1f} s ({1e3 * a / r['frames']:.0f} ms) | "
                     f"{b:.1f} s ({1e3 * b / r['frames']:.0f} ms) | {a / b:.2f}x | {reused} |")
    lines += ["", "Mean device (host for integrand) ms per frame by stage:", "",
              "| workload | session | " + " | ".join(STAGES) + " |", "|---|---|" + "---|" * len(STAGES)]
    for r in results:
        for session in ("independent", "reuse"):
            ms = r["stages"][session]
            lines.append(f"| {r['name']} | {session} | " + " | ".join(f"{ms.get(s, 0.0):.1f}" for s in STAGES) + " |")
    lines += ["", "Median wall ms per frame (independent / reuse): " + "; ".join(
        f"{r['name']} {1e3 * statistics.median(r['times']['independent']):.0f} / "
        f"{1e3 * statistics.median(r['times']['reuse']):.0f}" for r in results)]
    return "\n".join(lines)


STAGES = ("raster", "rectify", "minmax", "integrand", "traverse", "shade")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=60, help="orbit frames (default: all 60)")
    parser.add_argument("--device", default=None)
    args = parser.parse_args()
    device = Device(args.device)
    orbit = load_scene(REPO / "scenes" / "orbit.yaml")
    frames = list(orbit.animation.frames)[:args.frames]
    results = [
        compare("camera orbit, static light (scenes/orbit.yaml)",
                [orbit.animation.scene_at(orbit, f) for f in frames], device),
        compare("12-point sigma_s sweep (scenes/demo.yaml)",
                [load_scene(REPO / "scenes" / "demo.yaml", [f"medium.sigma_s={s}"]) for s in SIGMAS], device),
    ]
    print(f"device: {device.name}\n")
    print(table(results))


if __name__ == "__main__":
    main()
