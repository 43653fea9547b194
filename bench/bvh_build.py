"""The visibility stage's BVH alone: built on the host (`clrays.bvh`: `bvh_topology` then
`refit_bvh` around the eye-space float32 vertices, then the upload, what the stage did
before `clrays.stages.bvh_build`) against the device build (Morton keys sorted on the host,
the radix tree and the refit on the device), for the bunny and for a million random
triangles (the set of bench/exact_scale.py); median of a few builds, the two interleaved
(bench/RESULTS.md, "BVH build").

    .venv/bin/python bench/bvh_build.py
    .venv/bin/python bench/bvh_build.py --runs 7 --no-million

Device parts are OpenCL event times; "all" is the wall clock from the first host step to
the device's last box (queue finished), as a frame waits for it.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays.bvh import bvh_topology, refit_bvh  # noqa: E402
from clrays.device import Device, StageTimer  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.stages.bvh_build import bvh_build_refit, bvh_build_tree  # noqa: E402


def eye_space_vertices(triangles: np.ndarray, eye: np.ndarray) -> np.ndarray:
    vertices = (triangles - eye).reshape(-1, 3)
    return np.concatenate([vertices, np.zeros((len(vertices), 1))], axis=1).astype(np.float32)


def host_build(device: Device, triangles: np.ndarray, vertices: np.ndarray) -> dict:
    start = time.perf_counter()
    topology = bvh_topology(triangles)
    tree = time.perf_counter()
    bvh = refit_bvh(topology, vertices[:, :3].reshape(-1, 3, 3))
    boxes = time.perf_counter()
    device.buffer(bvh.node_bounds, writable=False), device.buffer(bvh.node_children, writable=False)
    device.queue.finish()
    end = time.perf_counter()
    return {"tree": tree - start, "boxes": boxes - tree, "upload": end - boxes, "all": end - start}


def device_build(device: Device, triangles: np.ndarray, eye: np.ndarray, vertex_buffer) -> dict:
    timer = StageTimer()
    start = time.perf_counter()
    tree = bvh_build_tree(device, triangles, timer)
    host_tree = timer.host_ms["bvh"]
    tree_events = len(timer.events["bvh"])
    bvh_build_refit(device, tree, eye, vertex_buffer, timer)
    device.queue.finish()
    end = time.perf_counter()
    event_ms = [(event.profile.end - event.profile.start) * 1e-6 for event in timer.events["bvh"]]
    return {"keys (host)": host_tree / 1e3, "tree (device)": sum(event_ms[:tree_events]) / 1e3,
            "pad (host)": (timer.host_ms["bvh"] - host_tree) / 1e3,
            "boxes (device)": sum(event_ms[tree_events:]) / 1e3, "all": end - start,
            "stage": sum(timer.milliseconds().values()) / 1e3}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5, help="builds of each kind per set (default 5)")
    parser.add_argument("--no-million", action="store_true", help="the bunny only")
    args = parser.parse_args()
    device = Device()
    bunny = load_scene(REPO / "scenes" / "bunny.yaml")
    sets = [("bunny", bunny.geometry.triangles, bunny.camera.position)]
    if not args.no_million:
        random = np.random.default_rng(20111).uniform(-1, 1, (1_000_000, 1, 3)) \
            + np.random.default_rng(7).normal(0, 0.01, (1_000_000, 3, 3))
        sets.append(("1M random", random, np.array([0.0, 0.5, 3.0])))
    print(f"{device.name}; load average {os.getloadavg()[0]:.1f} at start; median of {args.runs}, ms\n")
    for name, triangles, eye in sets:
        eye = np.asarray(eye, np.float64)
        vertices = eye_space_vertices(triangles, eye)
        vertex_buffer = device.buffer(vertices, writable=False)
        device_build(device, triangles[:64], eye, vertex_buffer)  # builds the kernels
        host_runs, device_runs = [], []
        for _ in range(args.runs):
            host_runs.append(host_build(device, triangles, vertices))
            device_runs.append(device_build(device, triangles, eye, vertex_buffer))
        for kind, runs in (("host", host_runs), ("device", device_runs)):
            parts = ", ".join(f"{part} {1e3 * statistics.median(run[part] for run in runs):.1f}"
                              for part in runs[0] if part != "all")
            print(f"{name} ({len(triangles)} triangles), {kind} build: "
                  f"{1e3 * statistics.median(run['all'] for run in runs):.1f} ({parts})", flush=True)


if __name__ == "__main__":
    main()
