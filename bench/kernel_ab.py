"""Named kernels' device time in this tree against another tree's, bench/kernel_times.py run
in each in turns (bench/RESULTS.md, "Where a frame stands: both cores busy, lines as long as
they are"): per scene, the sum of the named kernels per run, median over the rounds.

    .venv/bin/python bench/kernel_ab.py --repo ../base --rounds 4 line_samples,line_scatter demo bunny
    .venv/bin/python bench/kernel_ab.py --repo ../a --with ../b gather demo   # two other trees

"(stage total)" as a kernel name is the frame's stage time.

`--env` gives B another environment (both sides in this tree when --repo is left out), e.g.
`--env POCL_MAX_PTHREAD_COUNT=1` for one PoCL thread against the default.
"""
from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LINE = re.compile(r"(\w+): stage total ([\d.]+) ms; (.*)")


def kernel_times(tree: Path, scenes: list[str], size: str, env: dict) -> dict[str, dict[str, float]]:
    """scene → kernel → ms of one bench/kernel_times.py run in `tree` (3 frames)."""
    run = subprocess.run([sys.executable, "bench/kernel_times.py", *scenes, "--size", size, "--frames", "3"],
                         cwd=tree, capture_output=True, text=True, env={**os.environ, **env})
    if run.returncode:
        sys.exit(f"kernel_ab.py: {tree}: {run.stderr.strip().splitlines()[-1] if run.stderr.strip() else 'failed'}")
    times = {}
    for line in run.stdout.splitlines():
        match = LINE.match(line)
        if match:
            times[match.group(1)] = {k: float(v) for k, v in re.findall(r"(\w+) ([\d.]+)", match.group(3))}
            times[match.group(1)]["(stage total)"] = float(match.group(2))
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("kernels", help="comma-separated kernel names, summed")
    parser.add_argument("scenes", nargs="*", default=["demo", "bunny", "behind", "sun"])
    parser.add_argument("--repo", type=Path, default=REPO, help="the other tree (A; default: this one)")
    parser.add_argument("--with", dest="other", type=Path, default=REPO, help="B's tree (default: this one)")
    parser.add_argument("--env", action="append", default=[], metavar="NAME=VALUE", help="B's environment")
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--rounds", type=int, default=4)
    args = parser.parse_args()
    for option, tree in (("--repo", args.repo), ("--with", args.other)):
        if not (tree / "bench" / "kernel_times.py").is_file():
            sys.exit(f"kernel_ab.py: {option}: no bench/kernel_times.py in {tree}")
    if any("=" not in item for item in args.env):
        sys.exit(f"kernel_ab.py: --env: expected NAME=VALUE, got {next(i for i in args.env if '=' not in i)!r}")
    names = args.kernels.split(",")
    sides = [(args.repo, {}), (args.other, dict(item.split("=", 1) for item in args.env))]
    sums = {(side, scene): [] for side in range(2) for scene in args.scenes}
    for round_index in range(args.rounds):
        print(f"round {round_index + 1} of {args.rounds}", file=sys.stderr, flush=True)
        for side, (tree, env) in enumerate(sides):
            for scene, times in kernel_times(tree, args.scenes, args.size, env).items():
                sums[(side, scene)].append(sum(times.get(name, 0.0) for name in names))
    print(f"{args.size}, {' + '.join(names)}, ms: medians over {args.rounds} rounds in turns "
          f"(A = {sides[0][0]}, B = {sides[1][0]}{' with ' + ' '.join(args.env) if args.env else ''})\n")
    for scene in args.scenes:
        a, b = statistics.median(sums[(0, scene)]), statistics.median(sums[(1, scene)])
        print(f"{scene}: A {a:.2f}, B {b:.2f}, B/A {b / a:.2f}" if a else f"{scene}: A 0, B {b:.2f}")


if __name__ == "__main__":
    main()
