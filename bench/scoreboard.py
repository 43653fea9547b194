"""Regenerate bench/RESULTS.md's tables (`make results`): runs each maintained benchmark
and writes its output between the marker comments of its block, stamped with the command,
the machine, the device, the tree and the date; the prose around the blocks stays.

    .venv/bin/python bench/scoreboard.py                            # every block (hours on 2 cores)
    .venv/bin/python bench/scoreboard.py --only stages,accuracy     # some blocks
    .venv/bin/python bench/scoreboard.py --quick --device intel     # a smoke run: out/RESULTS.quick.md
    .venv/bin/python bench/scoreboard.py --list                     # the blocks and their commands

A block in RESULTS.md is

    <!-- results:NAME -->
    ... (rewritten) ...
    <!-- /results:NAME -->

`--quick` runs every benchmark at a thumbnail's size for a few frames, to check that the
whole chain runs; it writes a copy of RESULTS.md (out/RESULTS.quick.md, or `--results`),
never bench/RESULTS.md itself unless named. A benchmark that fails leaves its block as
it was and is named at the end (exit 1). The `gpu` block runs only with `--only gpu` or
a `--device` that names a GPU (nvidia, amd): on a CPU it would replace the GPU's figures
with a CPU's.
"""
from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import REPO, machine, today  # noqa: E402

PYTHON = ".venv/bin/python"
#: Every size the accuracy table has a column for.
ACCURACY_SIZES = "96x64,128x72,160x90,200x150,320x180,480x270,640x360,960x540,1280x720"


@dataclass(frozen=True)
class Block:
    """One table of the scoreboard: the command that makes it, in full and as a smoke run.
    A command's first word `clrays` is the command line; otherwise it is a bench/ script."""
    name: str
    full: tuple[str, ...]
    quick: tuple[str, ...]
    #: Where the table is a file the command writes ({out}: a scratch folder), not its stdout.
    output_file: str | None = None


BLOCKS = (
    Block("speed", ("clrays", "bench", "scenes/demo.yaml", "scenes/bunny.yaml", "scenes/behind.yaml", "-r", "1280x720",
                    "--volume-only", "--repeats", "3", "--targets", "5,1,0.5,0.1", "--no-progress", "-o", "{out}"),
          ("clrays", "bench", "scenes/demo.yaml", "-r", "48x27", "--volume-only", "--quick", "--repeats", "1",
           "--no-progress", "-o", "{out}"), output_file="summary.md"),
    Block("stages", ("bench/stage_times.py", "--size", "1280x720", "--frames", "7", "--kernels"),
          ("bench/stage_times.py", "--size", "96x54", "--frames", "1", "--kernels", "demo", "sun")),
    Block("runtimes", ("bench/runtimes.py", "--size", "1280x720", "--rounds", "7"),
          ("bench/runtimes.py", "--size", "96x54", "--rounds", "1", "demo")),
    Block("accuracy", ("bench/errors.py", "--all", "orbit@10", "--methods", "minmax", "--size", ACCURACY_SIZES),
          ("bench/errors.py", "demo", "sun", "orbit@10", "--methods", "minmax", "--size", "48x27,64x36")),
    Block("dense", ("bench/dense.py", "--pan", "3"),
          ("bench/dense.py", "--rows", "6", "--size", "96x54", "--pan", "2", "--out", "{out}")),
    Block("many_lights", ("bench/many_lights.py",),
          ("bench/many_lights.py", "--lights", "1", "4", "-r", "96x54", "--out", "{out}")),
    Block("hostile", ("bench/hostile.py", "--summary"), ("bench/hostile.py", "--summary", "--only", "workers")),
    Block("memory", ("bench/memory.py",), ("bench/memory.py", "-r", "96x54", "--method", "minmax")),
    Block("gpu", ("bench/gpu.py", "--kernels"),
          ("bench/gpu.py", "demo", "--sizes", "96x54", "--frames", "1", "--methods", "minmax")),
)
GPU_WORDS = ("nvidia", "amd", "gpu")


def marker(name: str) -> re.Pattern:
    """A block's text between its two markers (kept), in group 2."""
    return re.compile(rf"(<!-- results:{name} -->\n)(.*?)(<!-- /results:{name} -->)", re.S)


def command_line(words: tuple[str, ...], device: str | None) -> str:
    """The command as a reader types it in the repository's root."""
    shown = (".venv/bin/clrays", *words[1:]) if words[0] == "clrays" else (PYTHON, *words)
    prefix = f"CLRAYS_DEVICE={device} " if device else ""
    return prefix + " ".join(shlex.quote(word) for word in shown).replace("'{out}'", "OUT").replace("{out}", "OUT")


def device_name(env: dict) -> str:
    """The OpenCL device the benchmarks run on (CLRAYS_DEVICE, else clrays' default)."""
    done = subprocess.run([sys.executable, "-c", "from clrays.device import Device; print(Device().name)"],
                          cwd=REPO, env=env, capture_output=True, text=True)
    return done.stdout.strip().splitlines()[-1] if done.returncode == 0 and done.stdout.strip() else "(unknown)"


def tree() -> str:
    """This tree's commit, `+ changes` where the work tree differs from it."""
    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    return (head.stdout.strip() or "(no git)") + (" + changes" if dirty else "")


def run_block(block: Block, quick: bool, env: dict) -> str:
    """The block's table: the benchmark's stdout, or the file it names; raises RuntimeError
    with the benchmark's last line where it fails."""
    with tempfile.TemporaryDirectory(prefix=f"clrays-results-{block.name}-") as out:
        words = [word.replace("{out}", out) for word in (block.quick if quick else block.full)]
        command = ([sys.executable, "-m", "clrays.cli", *words[1:]] if words[0] == "clrays"
                   else [sys.executable, *words])
        print(f"scoreboard.py: {block.name}: {' '.join(words)}", file=sys.stderr, flush=True)
        done = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True)
        if done.returncode != 0:
            last = (done.stderr.strip().splitlines() or done.stdout.strip().splitlines() or ["no output"])[-1]
            raise RuntimeError(f"exit {done.returncode}: {last}")
        text = (Path(out) / block.output_file).read_text() if block.output_file else done.stdout
    return text.replace(out, "OUT").strip()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="", help="comma-separated block names (default: every block but gpu, "
                                                   "gpu too where --device names a GPU)")
    parser.add_argument("--quick", action="store_true", help="thumbnail sizes, few frames: a smoke run, not results")
    parser.add_argument("--device", help="a --device spec for every benchmark (CLRAYS_DEVICE), e.g. intel, nvidia")
    parser.add_argument("--results", type=Path, help="the file to write (default bench/RESULTS.md; "
                                                     "with --quick, out/RESULTS.quick.md)")
    parser.add_argument("--list", action="store_true", help="list the blocks and their commands, run nothing")
    args = parser.parse_args()
    names = {block.name for block in BLOCKS}
    chosen = [name for name in args.only.split(",") if name]
    if set(chosen) - names:
        parser.error(f"--only: no block {sorted(set(chosen) - names)[0]!r}; the blocks are {', '.join(sorted(names))}")
    on_gpu = any(word in (args.device or "").lower() for word in GPU_WORDS)
    blocks = [block for block in BLOCKS if block.name in chosen or
              (not chosen and (block.name != "gpu" or on_gpu))]
    if args.list:
        for block in BLOCKS:
            print(f"{block.name}: {command_line(block.full, args.device)}")
        return 0
    source = REPO / "bench" / "RESULTS.md"
    target = args.results or (REPO / "out" / "RESULTS.quick.md" if args.quick else source)
    text = (target if target.exists() else source).read_text()
    missing = [block.name for block in blocks if not marker(block.name).search(text)]
    if missing:
        sys.exit(f"scoreboard.py: {target if target.exists() else source}: no block "
                 f"<!-- results:{missing[0]} --> … <!-- /results:{missing[0]} -->")
    env = {**os.environ, "PYTHONPATH": str(REPO), **({"CLRAYS_DEVICE": args.device} if args.device else {})}
    stamp = f"{machine()}; device {device_name(env)}; tree {tree()}; {today()}" + \
        ("; **--quick: a smoke run, not results**" if args.quick else "")
    failed = []
    for block in blocks:
        try:
            table = run_block(block, args.quick, env)
        except RuntimeError as error:
            failed.append(f"{block.name} ({error})")
            continue
        command = command_line(block.quick if args.quick else block.full, args.device)
        body = f"    {command}\n\n{stamp}\n\n{table}\n\n"
        text = marker(block.name).sub(lambda match: match.group(1) + body + match.group(3), text)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text)  # after each block: a long run stopped keeps what it made
        print(f"scoreboard.py: {block.name}: written to {target}", file=sys.stderr, flush=True)
    if failed:
        print("scoreboard.py: kept as they were: " + "; ".join(failed), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
