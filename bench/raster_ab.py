"""The raster stage of this tree against another tree's, kernel by kernel, and whether
their depth maps are the same bits (bench/RESULTS.md, "Raster: lanes").

    .venv/bin/python bench/raster_ab.py --repo ../main --size 1280x720 --rounds 11
    .venv/bin/python bench/raster_ab.py --repo ../main --size 16x9 --rounds 15 demo bunny
    .venv/bin/python bench/raster_ab.py --repo ../main --size 640x360 --rounds 3 /tmp/poles.yaml

Each tree runs in its own process (its own clrays and cl/), and the two draw the same scene
in turn, A then B, then B then A, so a load that comes and goes falls on both; a frame is the
raster stage alone (camera depth and triangle ids, every light's map), from scratch. Prints,
per scene, the median device ms of each kernel in both trees, the median of the per-round
ratios A/B, and whether the camera depth, the triangle ids and every shadow map of the first
frame are the same bits in both; exits 1 if any is not.
"""
from __future__ import annotations

import argparse
import collections
import hashlib
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCENES = ("demo", "bunny", "behind", "sun")
sys.path.insert(0, str(Path(__file__).resolve().parent))
from arguments import frame_count, image_size  # noqa: E402  (bench/, beside this script; no clrays import)


def child(tree: Path, size: str, names: list[str]) -> None:
    """One tree's side: a raster frame of the named scene per line on stdin, answered with a
    JSON line of device ms per kernel (and, for the first frame, a digest of every map)."""
    sys.path.insert(0, str(tree))
    import numpy as np

    import clrays
    import clrays.device as device_module

    assert Path(clrays.__file__).resolve().parents[1] == tree, f"clrays from {clrays.__file__}, not {tree}"
    from clrays.device import StageTimer
    from clrays.inputs import frame_inputs, upload
    from clrays.scene.load import load_scene
    from clrays.session import Renderer
    from clrays.stages.raster import raster_camera, raster_shadow_map

    events = []
    kernel, fill = device_module.Device.kernel, device_module.Device.fill

    def timed_kernel(self, stage, name, defines=None):
        launch = kernel(self, stage, name, defines)
        return lambda *args: events.append((name, launch(*args))) or events[-1][1]

    def timed_fill(self, buffer, value, nbytes, timer=None, label="fill"):
        events.append(("fill", fill(self, buffer, value, nbytes, timer, label)))
        return events[-1][1]

    device_module.Device.kernel, device_module.Device.fill = timed_kernel, timed_fill
    device = Renderer().device
    width, height = size.split("x")
    frames = {}
    for name in names:
        path = Path(name) if name.endswith(".yaml") else tree / "scenes" / f"{name}.yaml"  # a bench scene, or a file
        scene = load_scene(path, overrides=[f"image.width={width}", f"image.height={height}"])
        frames[name] = (scene, upload(device, frame_inputs(scene)))

    def frame(name: str, digest: bool) -> dict:
        scene, buffers = frames[name]
        events.clear()
        depth, tri = raster_camera(device, buffers, StageTimer())
        maps = [raster_shadow_map(device, buffers, index, StageTimer()) for index in range(len(scene.lights))]
        device.queue.finish()
        ms = collections.Counter()
        for label, event in events:
            ms[label] += (event.profile.end - event.profile.start) * 1e-6
        answer = {"ms": ms}
        if digest:
            samples = buffers.inputs.samples
            arrays = [device.read(depth, samples, np.uint32), device.read(tri, samples, np.int32)]
            arrays += [device.read(entry.depth, max(entry.texels, 1), np.uint32) for entry in maps]
            answer["digest"] = [hashlib.sha256(array.tobytes()).hexdigest() for array in arrays]
        return answer

    digests = {name: frame(name, True)["digest"] for name in names}  # (also builds the kernels)
    print(json.dumps(digests), flush=True)
    for line in sys.stdin:
        print(json.dumps(frame(line.strip(), False)), flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=Path, required=True, help="the other source tree (A); this one is B")
    parser.add_argument("--size", type=image_size, default="1280x720", help="image WxH (default 1280x720)")
    parser.add_argument("--rounds", type=frame_count, default=11, help="frames per scene and tree (default 11)")
    parser.add_argument("scenes", nargs="*", default=list(SCENES), help="bench scenes' names, or .yaml files")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.repo.resolve(), args.size, args.scenes)
        return 0
    trees = {"A": args.repo.resolve(), "B": REPO}
    procs, digests = {}, {}
    for tag, tree in trees.items():  # each child imports clrays from its own tree
        procs[tag] = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--child", "--repo", str(tree), "--size", args.size,
             *args.scenes], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    for tag, proc in procs.items():
        digests[tag] = json.loads(proc.stdout.readline())
    ms = {(tag, name): [] for tag in trees for name in args.scenes}
    for round_index in range(args.rounds):
        for name in args.scenes:
            for tag in ("AB" if round_index % 2 == 0 else "BA"):
                procs[tag].stdin.write(name + "\n")
                procs[tag].stdin.flush()
                ms[(tag, name)].append(json.loads(procs[tag].stdout.readline())["ms"])
    for proc in procs.values():
        proc.stdin.close()
        proc.wait()
    print(f"A = {trees['A']}, B = {trees['B']}, {args.size}, {args.rounds} rounds, "
          f"load average {os.getloadavg()[0]:.1f} at the end; median device ms")
    differ = 0
    for name in args.scenes:
        a, b = ms[("A", name)], ms[("B", name)]
        total_a, total_b = [sum(frame.values()) for frame in a], [sum(frame.values()) for frame in b]
        ratio = statistics.median(x / y for x, y in zip(total_a, total_b))
        same = digests["A"][name] == digests["B"][name]
        differ += not same
        print(f"{name}: raster {statistics.median(total_a):.1f} → {statistics.median(total_b):.1f} ms, "
              f"A/B {ratio:.2f}; maps {'bit-identical' if same else 'DIFFER'}")
        kernels = sorted({k for frame in a + b for k in frame}, key=lambda k: -statistics.median(f.get(k, 0) for f in a))
        print("   " + " | ".join(f"{k} {statistics.median(f.get(k, 0) for f in a):.1f} → "
                                 f"{statistics.median(f.get(k, 0) for f in b):.1f}" for k in kernels))
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
