"""Which kernel a device gets wrong: one frame rendered on PoCL, on the device under test
with a setting it is known to be right with, and on it as it comes; every buffer a kernel
takes is read back after each launch, and the launches whose buffers differ from PoCL's
where the known-right run agrees with PoCL are listed (bench/RESULTS.md, "Every CPU, every
runtime"; docs/design.md §4.5, "Other CPU runtimes").

    .venv/bin/python bench/kernel_diff.py intel demo minmax --right CL_CONFIG_CPU_VECTORIZER_MODE=1
    .venv/bin/python bench/kernel_diff.py intel glass_row minmax --set render.transparency=depth_peeling

Only elements where the known-right run matches PoCL (within 1e-4) count: a buffer a
kernel writes in part holds whatever the pool left in the rest. The first launch listed is
the suspect; the ones after it may only have read its output. Frames are 96×54, every stage
computed; each run is a fresh process, with the compiler's cache off (PYOPENCL_NO_CACHE).
"""
from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
MAX_BUFFER_BYTES = 64 << 20


def record(device: str, scene: str, method: str, overrides: list[str], out: Path) -> None:
    """Render once on `device`, keeping (kernel, [(argument, float32 copy)]) per launch."""
    sys.path.insert(0, str(REPO))
    import pyopencl as cl

    from clrays import device as device_module
    from clrays.scene.load import load_scene
    from clrays.session import Renderer

    launches = []
    launch = device_module._Launcher.__call__

    def recorded(self, queue, global_size, local_size, *args, **kwargs):
        event = launch(self, queue, global_size, local_size, *args, **kwargs)
        event.wait()
        copies = []
        for index, argument in enumerate(args):
            if isinstance(argument, cl.MemoryObjectHolder) and argument.size <= MAX_BUFFER_BYTES:
                copy = np.empty(argument.size // 4, np.float32)
                cl.enqueue_copy(queue, copy, argument).wait()
                copies.append((index, copy))
        launches.append((self._kernel.function_name, copies))
        return event

    device_module._Launcher.__call__ = recorded
    loaded = load_scene(REPO / "scenes" / f"{scene}.yaml", overrides=["image.width=96", "image.height=54", *overrides])
    Renderer(device_module.Device(device), reuse=False).render(loaded, method)
    out.write_bytes(pickle.dumps(launches))


def wrong_elements(reference: np.ndarray, right: np.ndarray, tested: np.ndarray) -> tuple[int, int]:
    """(elements where `tested` is off, elements that count): those where `right` agrees
    with `reference`."""
    if not reference.shape == right.shape == tested.shape:
        return 0, 0
    with np.errstate(all="ignore"):
        same = lambda a, b, tolerance: (a.view(np.uint32) == b.view(np.uint32)) | (np.abs(a - b) <= tolerance * np.abs(a))
        counted = same(reference, right, 1e-4) & (np.abs(reference) > 1e-30)
        wrong = counted & ~same(reference, tested, 1e-3)
    return int(wrong.sum()), int(counted.sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("device", help="the device under test, a --device spec")
    parser.add_argument("scene", help="a scene name in scenes/")
    parser.add_argument("method", nargs="?", default="minmax")
    parser.add_argument("--right", action="append", default=[], metavar="NAME=VALUE",
                        help="environment of the known-right run (default: the device as it comes, which then "
                             "only shows where it differs from PoCL)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--record", nargs=1, metavar="OUT", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.record:
        record(args.device, args.scene, args.method, args.overrides, Path(args.record[0]))
        return
    runs = {"reference": ("Portable Computing Language", {}),
            "right": (args.device, dict(item.split("=", 1) for item in args.right)),
            "tested": (args.device, {})}
    launches = {}
    with tempfile.TemporaryDirectory() as folder:
        for name, (device, extra) in runs.items():
            out = Path(folder) / f"{name}.pickle"
            command = [sys.executable, __file__, args.device, args.scene, args.method, "--record", str(out),
                       *[f"--set={item}" for item in args.overrides]]
            command[2] = device
            env = {**os.environ, "PYOPENCL_NO_CACHE": "1", **extra}
            subprocess.run(command, check=True, env=env, stdout=subprocess.DEVNULL)
            launches[name] = pickle.loads(out.read_bytes())
    print(f"{args.scene}, {args.method}, {' '.join(args.overrides)}: {len(launches['reference'])} launches")
    listed = set()
    for number, (reference, right, tested) in enumerate(zip(*launches.values())):
        if not reference[0] == right[0] == tested[0]:
            sys.exit(f"launch {number}: the runs launched {reference[0]}, {right[0]} and {tested[0]}")
        for (argument, a), (_, b), (_, c) in zip(reference[1], right[1], tested[1]):
            wrong, counted = wrong_elements(a, b, c)
            if wrong and reference[0] not in listed:
                listed.add(reference[0])
                print(f"  launch {number}: {reference[0]}, argument {argument}: {wrong} of {counted} elements off")
                break
    if not listed:
        print("  every kernel agrees with PoCL")


if __name__ == "__main__":
    main()
