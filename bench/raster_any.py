"""raster_any's loop (cl/raster.cl) against the vector reductions it could be, on every CPU
OpenCL runtime installed: each variant's answer on an empty map and on maps with one depth,
and its device time on a 16 MB map (bench/RESULTS.md, "Every CPU, every runtime").

    .venv/bin/python bench/raster_any.py --rounds 9

The `uint16` variant is the one PoCL 3.0 miscompiled on a CPU with AVX-512: it says
"WRONG" there. Times are medians over the rounds of an empty map (every texel read).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import warnings
from pathlib import Path

import numpy as np
import pyopencl as cl

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays import structs  # noqa: E402
from clrays.device import list_devices  # noqa: E402

TEXELS = structs.RASTER_ANY_TEXELS
EMPTY = int(structs.kernel_defines()["DEPTH_EMPTY"].rstrip("u"), 16)
HEAD = f"#define EMPTY {EMPTY}u\n#define T {TEXELS}\n"
def reduction(width: int, load: str) -> str:
    """A kernel body that ORs `width`-wide vectors of the texels (each loaded by `load`, a C
    expression of k), then halves the vector down to one flag."""
    body = f"\n        uint{width} seen = (uint{width})(0u);\n"
    body += f"        for (int k = 0; k < T / {width}; ++k) seen |= {load} ^ EMPTY;\n"
    name, half = "seen", width
    while half > 2:
        half //= 2
        body += f"        uint{half} seen{half} = {name}.lo | {name}.hi;\n"
        name = f"seen{half}"
    return body + f"        if (({name}.x | {name}.y) != 0u) *flag = 1u;"


VARIANTS = {
    "loop (cl/raster.cl)": """
        uint seen = 0u;
        for (int i = first; i < first + T; ++i) seen |= depth[i] ^ EMPTY;
        if (seen != 0u) *flag = 1u;""",
    "uint4": reduction(4, "((global const uint4*)(depth + first))[k]"),
    "vload8": reduction(8, "vload8(0, depth + first + 8 * k)"),
    "vload16 (before)": reduction(16, "vload16(0, depth + first + 16 * k)"),
}


def source() -> str:
    kernels = [f"kernel void variant{k}(global const uint* depth, volatile global uint* flag)\n{{\n"
               f"    int first = get_global_id(0) * T;\n    if (*flag) return;{body}\n}}\n"
               for k, body in enumerate(VARIANTS.values())]
    return HEAD + "".join(kernels)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--megabytes", type=int, default=16)
    args = parser.parse_args()
    n = args.megabytes * (1 << 20) // 4 // TEXELS * TEXELS
    maps = {"empty": np.full(n, EMPTY, np.uint32)}
    for where in (0, n // 2, n - 1):
        maps[f"depth at {where}"] = maps["empty"].copy()
        maps[f"depth at {where}"][where] = np.float32(1.0).view(np.uint32)
    for p, d, platform, device in list_devices():
        if not device.type & cl.device_type.CPU:
            continue
        context = cl.Context([device])
        queue = cl.CommandQueue(context, properties=cl.command_queue_properties.PROFILING_ENABLE)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            program = cl.Program(context, source()).build()
        print(f"\n{platform.name.strip()} / {device.name.strip()} ({p}:{d}), {args.megabytes} MB map, "
              f"median of {args.rounds}\n")
        print("| variant | answers right | ms, empty map |\n|---|---|---|")
        mf = cl.mem_flags
        buffers = {name: cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=data) for name, data in maps.items()}
        flag = cl.Buffer(context, mf.READ_WRITE, 4)
        for k, name in enumerate(VARIANTS):
            kernel = cl.Kernel(program, f"variant{k}")
            right, times = True, []
            for map_name, buffer in buffers.items():
                for _ in range(args.rounds if map_name == "empty" else 1):
                    cl.enqueue_copy(queue, flag, np.zeros(1, np.uint32))
                    event = kernel(queue, (n // TEXELS,), None, buffer, flag)
                    event.wait()
                    if map_name == "empty":
                        times.append((event.profile.end - event.profile.start) * 1e-6)
                    answer = np.empty(1, np.uint32)
                    cl.enqueue_copy(queue, answer, flag).wait()
                    right &= bool(answer[0]) == (map_name != "empty")
            print(f"| {name} | {'yes' if right else 'WRONG'} | {statistics.median(times):.3f} |", flush=True)


if __name__ == "__main__":
    main()
