"""Peak host and device memory of one frame at 720p, 1080p and 4K (bench/RESULTS.md,
"Memory: big frames").

    .venv/bin/python bench/memory.py                       # scenes/demo.yaml, minmax and raymarch
    .venv/bin/python bench/memory.py -r 3840x2160 --method minmax

Each point runs in a fresh process, so its peak resident set (ru_maxrss) is that frame's
alone; the process first builds the kernels on a 16×16 frame, whose peak is printed as
the baseline. Device memory is what the frame allocated (`RenderResult.device_bytes`,
every buffer of a frame is live until its end, so this is the device peak) beside what
`clrays.session.frame_buffer_bytes` predicts for the refusal check.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import REPO, image_size, width_height  # noqa: E402

ONE_POINT = """
import json, resource, sys, time
sys.path.insert(0, {repo!r})
from clrays.inputs import frame_inputs
from clrays.scene.load import load_scene
from clrays.session import Renderer, frame_buffer_bytes
scene_path, width, height, method = {scene!r}, {width}, {height}, {method!r}
renderer = Renderer(reuse=False)
renderer.render(load_scene(scene_path, ["image.width=16", "image.height=16"]), method)  # kernels built
baseline = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
scene = load_scene(scene_path, [f"image.width={{width}}", f"image.height={{height}}", f"render.method={{method}}"])
start = time.perf_counter()
result = renderer.render(scene, method)
seconds = time.perf_counter() - start
predicted = sum(size for _, size in frame_buffer_bytes(frame_inputs(scene)))
print(json.dumps(dict(seconds=seconds, device_bytes=result.device_bytes, predicted_bytes=predicted,
                      host_peak_kib=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, host_baseline_kib=baseline,
                      device=renderer.device.name, global_bytes=int(renderer.device.device.global_mem_size),
                      max_alloc_bytes=int(renderer.device.device.max_mem_alloc_size))))
"""


def measure(scene: str, width: int, height: int, method: str) -> dict:
    code = ONE_POINT.format(repo=str(REPO), scene=scene, width=width, height=height, method=method)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", nargs="?", default=str(REPO / "scenes" / "demo.yaml"))
    parser.add_argument("-r", "--resolution", type=image_size, action="append",
                        help="WxH (repeatable); default 720p, 1080p, 4K")
    parser.add_argument("--method", action="append", choices=["minmax", "raymarch"])
    args = parser.parse_args()
    sizes = [width_height(text) for text in args.resolution or ["1280x720", "1920x1080", "3840x2160"]]
    print("| resolution | method | frame time (s) | device memory (MiB) | predicted (MiB) | host peak (MiB) "
          "| host before the frame (MiB) |")
    print("|---|---|---|---|---|---|---|")
    last = None
    for width, height in sizes:
        for method in args.method or ["minmax", "raymarch"]:
            point = last = measure(args.scene, width, height, method)
            print(f"| {width}×{height} | {method} | {point['seconds']:.1f} | {point['device_bytes'] / 2**20:.0f} "
                  f"| {point['predicted_bytes'] / 2**20:.0f} | {point['host_peak_kib'] / 1024:.0f} "
                  f"| {point['host_baseline_kib'] / 1024:.0f} |", flush=True)
    if last is not None:
        print(f"\ndevice: {last['device']}, global memory {last['global_bytes'] / 2**20:.0f} MiB, "
              f"largest allocation {last['max_alloc_bytes'] / 2**20:.0f} MiB")


if __name__ == "__main__":
    main()
