"""Frame stage time of this tree against another tree's, the two in turns (bench/RESULTS.md,
"Where a frame stands: prepare in lanes, rows owned, the table on the device").

    .venv/bin/python bench/stage_ab.py --repo ../base --size 1280x720 --rounds 4 --frames 5
    .venv/bin/python bench/stage_ab.py --repo ../base --size 16x9 --rounds 2 --frames 7 demo bunny

Each round runs bench/stage_times.py in the other tree (A), then in this one (B), each in its
own process with its own clrays and cl/, so a load that comes and goes falls on both. Prints,
per scene, each stage's median over the rounds of stage_times' per-frame medians, the total's
round medians, their median and the ratio B/A of those medians.
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
sys.path.insert(0, str(Path(__file__).resolve().parent))
from arguments import frame_count, image_size  # noqa: E402  (bench/, beside this script; no clrays import)
from stage_times import SCENES, STAGES  # noqa: E402

ROW = re.compile(r"\| (\w+) \|(.*)\| ([\d.]+) \([\d.]+–[\d.]+\)")
WALL = re.compile(r"\| wall ([\d.]+) \| CPU ([\d.]+) \|")  # (a tree from before stage_times printed them has none)


def round_of(tree: Path, size: str, frames: int, scenes: list[str]) -> dict[str, list[float]]:
    """scene → the stage medians, the total's, then the wall and CPU times' (None where
    the tree prints none), from one stage_times run in `tree`."""
    command = [sys.executable, str(tree / "bench" / "stage_times.py"), "--size", size, "--frames", str(frames), *scenes]
    run = subprocess.run(command, cwd=tree, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(tree)})
    if run.returncode != 0:
        last = (run.stderr.strip().splitlines() or ["no output"])[-1]
        sys.exit(f"stage_ab.py: bench/stage_times.py in {tree} failed: {last}")
    out = run.stdout
    rows = {}
    for line in out.splitlines():
        match = ROW.match(line)
        if match:
            cells = [float(cell) for cell in match.group(2).split("|") if cell.strip()]
            wall = WALL.search(line)
            rows[match.group(1)] = cells[:len(STAGES)] + [float(match.group(3))] + \
                ([float(wall.group(1)), float(wall.group(2))] if wall else [None, None])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=list(SCENES))
    parser.add_argument("--repo", type=Path, required=True, help="the other tree (A)")
    parser.add_argument("--size", type=image_size, default="1280x720")
    parser.add_argument("--rounds", type=frame_count, default=4)
    parser.add_argument("--frames", type=frame_count, default=5, help="frames per stage_times run")
    args = parser.parse_args()
    if not (args.repo / "bench" / "stage_times.py").is_file():
        parser.error(f"--repo: {args.repo} holds no bench/stage_times.py (a clrays checkout, e.g. a git worktree)")
    unknown = sorted(set(args.scenes) - {path.stem for path in (REPO / "scenes").glob("*.yaml")})
    if unknown:
        parser.error(f"scenes: no scenes/{unknown[0]}.yaml")
    trees = {"A": args.repo.resolve(), "B": REPO}
    runs = {tree: [] for tree in trees}
    for number in range(args.rounds):
        for tree, path in trees.items():
            runs[tree].append(round_of(path, args.size, args.frames, args.scenes))
        print(f"round {number + 1} of {args.rounds}, load {os.getloadavg()[0]:.1f}", file=sys.stderr, flush=True)
    print(f"{args.size}, A = {trees['A']}, B = {trees['B']}; stage ms, medians over {args.rounds} rounds of "
          f"{args.frames}-frame medians\n")
    print("| scene | tree | " + " | ".join(STAGES) + " | total, each round | total | B/A | wall | B/A | CPU | B/A |")
    print("|---|---|" + "---|" * (len(STAGES) + 7))
    for scene in args.scenes:
        totals, walls, cpus = {}, {}, {}
        for tree in trees:
            columns = list(zip(*(run[scene] for run in runs[tree])))
            cells = [f"{statistics.median(column):.1f}" for column in columns[:-3]]
            totals[tree] = statistics.median(columns[-3])
            walls[tree], cpus[tree] = (statistics.median(c) if None not in c else None for c in columns[-2:])
            ratio = f"**{totals['B'] / totals['A']:.2f}**" if tree == "B" else ""
            extra = ""
            for measure in (walls, cpus):
                both = tree == "B" and None not in measure.values()
                extra += (" — |" if measure[tree] is None else f" {measure[tree]:.1f} |") + \
                    (f" {measure['B'] / measure['A']:.2f} |" if both else " |")
            print(f"| {scene} | {tree} | " + " | ".join(cells) + f" | {', '.join(f'{t:.0f}' for t in columns[-3])} "
                  f"| **{totals[tree]:.1f}** | {ratio} |{extra}", flush=True)


if __name__ == "__main__":
    main()
