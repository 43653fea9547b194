"""Two source trees, A and B, compared on stage times, kernel times or images: the one A/B tool.

    .venv/bin/python bench/ab.py stages --repo ../base --size 1280x720 --rounds 4 --frames 5
    .venv/bin/python bench/ab.py stages --repo HEAD~3 --size 16x9 --rounds 2 --frames 7 demo bunny
    .venv/bin/python bench/ab.py kernels --repo ../base --rounds 4 line_samples,line_scatter demo bunny
    .venv/bin/python bench/ab.py kernels --env POCL_MAX_PTHREAD_COUNT=1 gather demo   # one tree, two environments
    .venv/bin/python bench/ab.py images --repo ../base                  # every image the same bits?
    .venv/bin/python bench/ab.py images --repo ../main --out /tmp/before   # or in two steps
    .venv/bin/python bench/ab.py images --out /tmp/after --against /tmp/before

A tree is a folder (a clrays checkout or git worktree) or a git ref of this repository,
which is exported (`git archive`) to a temporary folder. `--repo` is A (default: this
tree), `--with` is B (default: this tree); `--env NAME=VALUE` gives B another environment.
Each tree's clrays runs from that tree (it is first on PYTHONPATH), its own bench/ script
measuring, each in a process of its own. The names (kernels, scenes) come together, after
the options.

- **stages**: each round runs bench/stage_times.py in A, then in B, so a load that comes
  and goes falls on both; per scene, each stage's median over the rounds of the per-frame
  medians, the total's round medians, their median and B/A, and the same for wall and CPU.
- **kernels**: the named kernels' device time (summed; `(stage total)` is the frame's
  stage time), from `bench/stage_times.py --kernels` (a tree from before that option:
  bench/kernel_times.py), 3 frames a run, median over the rounds in turns.
- **images**: renders, at 96×54 with every stage computed, the bench scenes (minmax,
  raymarch, volume_moments), the translucent scenes (MBOIT and depth peeling at 1, 4 and
  8 layers), the textured lights and the relief, the other scenes (colonnade, grate, room), pixel sampling, filtered surface shadows,
  orbit's first four frames as a sequence and a sweep of gobo, in one session each, and
  says of each image whether B's is A's bit for bit; exits 1 if any is not. With `--out`
  it renders one tree (--repo) into that folder as .npy, and with `--against` compares it
  with another folder's. Scenes come from this tree's scenes/.
"""
from __future__ import annotations

import argparse
import itertools
import os
import re
import statistics
import subprocess
import sys
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import REPO, SCENES, STAGES, check_scenes, frame_count, image_size, in_turns  # noqa: E402

STAGE_ROW = re.compile(r"\| (\w+) \|(.*)\| ([\d.]+) \([\d.]+–[\d.]+\)")
WALL_CPU = re.compile(r"\| wall ([\d.]+) \| CPU ([\d.]+) \|")  # (a tree from before stage_times printed them has none)
KERNEL_LINE = re.compile(r"(\w+): stage total ([\d.]+) ms; (.*)")


def tree_of(spec: str, scratch: Path) -> Path:
    """The folder of a tree given as a folder or as a git ref of this repository (exported into `scratch`)."""
    if Path(spec).is_dir():
        return Path(spec).resolve()
    archive = subprocess.run(["git", "-C", str(REPO), "archive", "--format=tar", spec], capture_output=True)
    if archive.returncode != 0:
        sys.exit(f"ab.py: {spec!r}: neither a folder nor a git ref of {REPO} "
                 f"({archive.stderr.decode(errors='replace').strip().splitlines()[-1]})")
    folder = scratch / re.sub(r"[^\w.-]", "_", spec)
    with tarfile.open(fileobj=BytesIO(archive.stdout)) as tar:
        tar.extractall(folder, filter="data")
    return folder


def run_in(tree: Path, arguments: list[str], env: dict) -> str:
    """stdout of `python ARGUMENTS` in `tree`, its clrays first on the path; a failure exits in one line."""
    run = subprocess.run([sys.executable, *arguments], cwd=tree, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(tree), **env})
    if run.returncode != 0:
        last = (run.stderr.strip().splitlines() or ["no output"])[-1]
        sys.exit(f"ab.py: {arguments[0]} in {tree} failed: {last}")
    return run.stdout


# ------------------------------------------------------------------------------ stages

def stage_round(tree: Path, env: dict, size: str, frames: int, scenes: list[str]) -> dict[str, list]:
    """scene → the stage medians, the total's, then the wall and CPU times' (None where the
    tree prints none), from one bench/stage_times.py run in `tree`."""
    out = run_in(tree, ["bench/stage_times.py", "--size", size, "--frames", str(frames), *scenes], env)
    rows = {}
    for line in out.splitlines():
        match = STAGE_ROW.match(line)
        if match:
            cells = [float(cell) for cell in match.group(2).split("|") if cell.strip()]
            wall = WALL_CPU.search(line)
            rows[match.group(1)] = cells[:len(STAGES)] + [float(match.group(3))] + \
                ([float(wall.group(1)), float(wall.group(2))] if wall else [None, None])
    return rows


def stages(args, sides) -> None:
    runs = in_turns(args.rounds, sides, lambda side: stage_round(*side, args.size, args.frames, args.scenes))
    print(f"{args.size}, A = {sides[0][0]}, B = {sides[1][0]}{described(args.env)}; stage ms, medians over "
          f"{args.rounds} rounds of {args.frames}-frame medians\n")
    print("| scene | tree | " + " | ".join(STAGES) + " | total, each round | total | B/A | wall | B/A | CPU | B/A |")
    print("|---|---|" + "---|" * (len(STAGES) + 7))
    for scene in args.scenes:
        totals, walls, cpus = {}, {}, {}
        for index, tree in enumerate("AB"):
            columns = list(zip(*(run[scene] for run in runs[index])))
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


# ------------------------------------------------------------------------------ kernels

def kernel_round(tree: Path, env: dict, size: str, scenes: list[str]) -> dict[str, dict[str, float]]:
    """scene → kernel → ms of one 3-frame run in `tree`."""
    script = ["bench/kernel_times.py"] if (tree / "bench" / "kernel_times.py").is_file() else \
        ["bench/stage_times.py", "--kernels"]
    out = run_in(tree, [*script, *scenes, "--size", size, "--frames", "3"], env)
    times = {}
    for line in out.splitlines():
        match = KERNEL_LINE.match(line)
        if match:
            times[match.group(1)] = {k: float(v) for k, v in re.findall(r"(\w+) ([\d.]+)", match.group(3))}
            times[match.group(1)]["(stage total)"] = float(match.group(2))
    return times


def kernels(args, sides) -> None:
    names = args.kernels.split(",")
    runs = in_turns(args.rounds, sides, lambda side: kernel_round(*side, args.size, args.scenes))
    print(f"{args.size}, {' + '.join(names)}, ms: medians over {args.rounds} rounds in turns "
          f"(A = {sides[0][0]}, B = {sides[1][0]}{described(args.env)})\n")
    for scene in args.scenes:
        a, b = (statistics.median(sum(run[scene].get(name, 0.0) for name in names) for run in side_runs)
                for side_runs in runs)
        print(f"{scene}: A {a:.2f}, B {b:.2f}, B/A {b / a:.2f}" if a else f"{scene}: A 0, B {b:.2f}")


# ------------------------------------------------------------------------------ images

OPAQUE = ("demo", "bunny", "behind", "sun")
TRANSLUCENT = ("glass_row", "glass_pane", "stained_glass")
OTHERS = ("colonnade", "grate", "room")
METHODS = ("minmax", "raymarch")
SIZE = ["image.width=96", "image.height=54"]


def image_jobs() -> list[tuple[str, str, str, list[str]]]:
    """(image name, scene, method, overrides) of every single frame. Methods go by the names
    both old and new trees read (`moments`)."""
    out = [(f"{scene}_{method}", scene, method, SIZE) for scene in OPAQUE for method in (*METHODS, "moments")]
    out += [(f"{scene}_{method}_default", scene, method, SIZE) for scene in TRANSLUCENT for method in METHODS]
    for layers in (1, 4, 8):
        out += [(f"{scene}_{method}_peel{layers}", scene, method,
                 [*SIZE, f"render.transparency={{type: depth_peeling, layers: {layers}}}"])
                for scene in TRANSLUCENT for method in METHODS]
    out += [(f"{scene}_{method}", scene, method, SIZE) for scene in ("gobo", "lattice") for method in METHODS]
    out += [(f"{scene}_{method}", scene, method, SIZE) for scene in OTHERS for method in METHODS]
    out += [("demo_pixel", "demo", "minmax", [*SIZE, "render.sampling=pixel"]),
            ("bunny_filtered", "bunny", "minmax", [*SIZE, "render.surface_shadows=filtered"])]
    return out


def session_images(load_scene, Renderer):
    """(image name, image) of a sequence and a sweep, each in one session that reuses stages."""
    session = Renderer()
    orbit = load_scene(REPO / "scenes" / "orbit.yaml", overrides=SIZE)
    for frame in range(4):
        yield f"orbit_frame{frame}", session.render(orbit.animation.scene_at(orbit, frame)).image
    session = Renderer()
    for sigma in ("0.05", "0.1"):
        for slices in ("256", "512"):
            scene = load_scene(REPO / "scenes" / "gobo.yaml",
                               overrides=[*SIZE, f"medium.sigma_s={sigma}", f"render.slices={slices}"])
            yield f"gobo_sweep_{sigma}_{slices}", session.render(scene).image


def render_images(tree: Path, out: Path, against: Path | None) -> int:
    """Every image of `image_jobs` and `session_images` by `tree`'s clrays, saved in `out`
    as .npy and, with `against`, compared with the same name there; the number that differ."""
    import numpy as np

    sys.path.insert(0, str(tree))
    import clrays
    from clrays.scene.load import load_scene
    from clrays.session import Renderer

    print(f"clrays from {Path(clrays.__file__).parent}")
    out.mkdir(parents=True, exist_ok=True)
    renderer, differ = Renderer(reuse=False), 0
    frames = ((name, renderer.render(load_scene(REPO / "scenes" / f"{scene}.yaml", overrides=overrides), method).image)
              for name, scene, method, overrides in image_jobs())
    for name, image in itertools.chain(frames, session_images(load_scene, Renderer)):
        np.save(out / f"{name}.npy", image)
        if against is None:
            print(name, flush=True)
            continue
        before = np.load(against / f"{name}.npy")
        same = np.array_equal(image, before)
        differ += not same
        print(f"{name}: {'bit-identical' if same else f'differs, max {np.abs(image - before).max():.3g}'}",
              flush=True)
    return differ


def images(args, sides, scratch: Path) -> int:
    if args.out:  # one tree, one folder (--repo, else this tree)
        return 1 if render_images(sides[0][0], args.out, args.against) else 0
    for (tree, env), name, against in ((sides[0], "A", []), (sides[1], "B", ["--against", str(scratch / "A")])):
        command = [sys.executable, str(Path(__file__).resolve()), "images", "--repo", str(tree),
                   "--out", str(scratch / name), *against]
        done = subprocess.run(command, env={**os.environ, **env}, text=True, capture_output=name == "A")
        if name == "A" and done.returncode:
            sys.exit(f"ab.py: images of A ({tree}) failed: {(done.stderr.strip().splitlines() or ['?'])[-1]}")
    return done.returncode


# ------------------------------------------------------------------------------ main

def described(env: list[str]) -> str:
    return f" with {' '.join(env)}" if env else ""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--repo", default=str(REPO), help="tree A: a folder or a git ref (default: this tree)")
    common.add_argument("--with", dest="other", default=str(REPO), help="tree B: a folder or a git ref "
                                                                         "(default: this tree)")
    common.add_argument("--env", action="append", default=[], metavar="NAME=VALUE", help="B's environment")
    stage_parser = commands.add_parser("stages", parents=[common], help="stage times in turns")
    kernel_parser = commands.add_parser("kernels", parents=[common], help="named kernels' times in turns")
    kernel_parser.add_argument("kernels", help="comma-separated kernel names, summed")
    for timed in (stage_parser, kernel_parser):
        timed.add_argument("scenes", nargs="*", default=list(SCENES), help="scenes in scenes/ (default: the bench four)")
        timed.add_argument("--size", type=image_size, default="1280x720", help="WxH (default 1280x720)")
        timed.add_argument("--rounds", type=frame_count, default=4, help="rounds in turns (default 4)")
    stage_parser.add_argument("--frames", type=frame_count, default=5, help="frames per stage_times run (default 5)")
    image_parser = commands.add_parser("images", parents=[common], help="every image the same bits?")
    image_parser.add_argument("--out", type=Path, help="render --repo's images into this folder (.npy)")
    image_parser.add_argument("--against", type=Path, help="with --out: a folder of another tree's images")
    args = parser.parse_args()
    if any("=" not in item for item in args.env):
        parser.error(f"--env: expected NAME=VALUE, got {next(i for i in args.env if '=' not in i)!r}")
    if args.command != "images":
        check_scenes("ab.py", args.scenes)
    with tempfile.TemporaryDirectory(prefix="clrays-ab-") as scratch:
        trees = [tree_of(spec, Path(scratch)) for spec in (args.repo, args.other)]
        for option, tree in zip(("--repo", "--with"), trees):
            if not (tree / "clrays").is_dir():
                parser.error(f"{option}: {tree} holds no clrays/ (a clrays checkout, a worktree or a git ref)")
        sides = [(trees[0], {}), (trees[1], dict(item.split("=", 1) for item in args.env))]
        if args.command == "stages":
            stages(args, sides)
        elif args.command == "kernels":
            kernels(args, sides)
        else:
            return images(args, sides, Path(scratch))
    return 0


if __name__ == "__main__":
    sys.exit(main())
