"""Run time against error: every method and setting of clrays, timed and measured
against `exact` on the same scenes (`clrays bench`).

For each scene and resolution the sweep renders

- `raymarch` on a ladder of step counts (`raymarch_ladder`): doubled from 32 until its
  error reaches the lowest target, then one step count between the two that bracket each
  target, so its cost at equal error is known to within a factor √2 of steps; where the
  scene's shadow map stops it short of the lowest target, the ladder goes on at twice the
  map;
- `minmax` at its defaults and, one parameter at a time, at half the `slices`,
  `gamma_samples` or `shadow_map` (the points that can reach the higher targets for
  less), and at twice the sizes where none of those reaches the lowest target (640×360
  and smaller whole-image sweeps also try `integrand` and `traversal`); `volume_moments` in
  `--quick` only (bench/RESULTS.md compares it with minmax on its own);

and records, per point, the frame time (median of `repeats` renders after a warm-up,
wall clock, host work included; a raymarch point that differs from the last one in its
step count alone, which is a kernel argument, needs no warm-up), the median device time
per stage, the device memory, the 1-minute load average of the machine when the point
ended, and the error against `exact`: relative RMSE of luminance and the 99th-percentile
relative error, on pixels with at least 1% of the mean radiance, depth edges excluded
(`clrays.reference.metrics`). `exact` takes minutes on a full frame, so the error is
measured on a fixed, seeded random subset of pixels (`pixels`, default 4000), the same for
every point; the references are kept on disk (`clrays.runs.references`).
"""
from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import os
import platform
import resource
import statistics
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import ClraysError
from ..image_io import make_folder, write_atomic, write_text
from ..outputs import cache_root
from ..session import Renderer
from ..scene.costs import with_derived_sizes
from ..scene.model import METHODS, Scene
from ..scene.load import load_scene
from .references import EXACT, ReferenceCache

DEFAULT_SCENES = ("scenes/demo.yaml", "scenes/bunny.yaml", "scenes/behind.yaml", "scenes/sun.yaml",
                  # Fine occluders, where volume visibility from the shadow map fails first: a relief
                  # lattice, slats thinner than a texel, a closed room lit through one window.
                  "scenes/lattice.yaml", "scenes/grate.yaml", "scenes/room.yaml")
#: Relative RMSE targets of the headline: the speedup of minmax over raymarch is read at each.
RMSE_TARGETS = (0.05, 0.01, 0.005)
#: raymarch's ladder: the first step count (8, not 32: with equiangular steps the bunny and
#: behind the viewer are under 0.5 % at 32, so a ladder from 32 overstated their speedups),
#: and the most (a 1280×720 frame at 2048 steps
#: takes about a minute on the 2-core machine of bench/RESULTS.md).
RAYMARCH_FIRST_STEPS = 8
RAYMARCH_MOST_STEPS = 2048
#: ... and a frame's CPU time past which it stops doubling (the next rung would take over
#: twice as long): the ladder's cost stays bounded on a frame whose error falls slowly.
#: CPU time, not wall time: on a shared machine the wall time of the same frame varied 3×
#: with the load (bench/RESULTS.md history, the re-run), its CPU time by a few per cent.
#: 30 s, not 20: equiangular raymarch reaches 0.5 % on the demo at 1280×720 at 184 steps,
#: a 23 s frame (bench/RESULTS.md history), one rung past a 20 s cap.
RAYMARCH_MOST_FRAME_CPU_MS = 30_000
#: The largest shadow map the ladder and the minmax points go up to.
MOST_SHADOW_MAP = 2048


def target_tag(target: float) -> str:
    """0.005 → "0.5%", 0.01 → "1%": the label of a target in the summary's keys and tables."""
    return f"{target * 100:g}%"


@dataclass
class BenchPoint:
    scene: str
    resolution: str
    method: str
    setting: str  # the swept parameter and value, e.g. "steps=256 shadow_map=1024"
    frame_ms: float  # median wall time of a frame
    frame_ms_spread: float  # (max - min) / median over the timed repeats
    rmse: float  # relative RMSE of luminance against exact
    p99: float  # 99th percentile of the relative luminance error
    mean_error: float
    device_mib: float
    stage_ms: dict[str, float] = field(default_factory=dict)
    load_average: float = math.nan  # the machine's 1-minute load average when the point ended
    # Median CPU time of the process per frame (every PoCL thread's, host work included):
    # the work a frame does, which other processes on a shared machine change far less
    # than its wall time.
    cpu_ms: float = math.nan


def volume_only(scene: Scene) -> Scene:
    """The scene with black surfaces and background: its image is the in-scattered light
    alone (attenuated), so its error and its cost are the volumetric method's. Black
    surfaces reflect nothing, so their shadows are not computed (`surface_shadows: map`
    skips the exact visibility stage and its BVH; the image is the same to the bit)."""
    geometry = replace(scene.geometry, albedo=np.zeros_like(scene.geometry.albedo))
    return replace(scene, geometry=geometry, background=np.zeros(3),
                   render=replace(scene.render, surface_shadows="map"))


def sweep(scene: Scene, quick: bool = False, volume: bool = False) -> list[tuple[str, str, dict]]:
    """(method, label, render overrides) of the minmax points for one scene; raymarch's
    step counts are searched instead (`raymarch_ladder`). `quick`: a handful of fixed
    points of every method (two of raymarch's) for a smoke run. `volume` (volume-only
    error) and frames larger than 640×360 leave out the integrand and traversal variants,
    to keep the large runs short (the first run in bench/RESULTS.md's history compares them)."""
    from ..scene.model import DirectionalLight

    if quick:
        return [("raymarch", "steps=32 shadow_map=256", {"steps": 32, "shadow_map": 256}),
                ("raymarch", "steps=256 shadow_map=256", {"steps": 256, "shadow_map": 256}),
                ("minmax", "shadow_map=256", {"shadow_map": 256}),
                ("minmax", "shadow_map=256 traversal=scan", {"shadow_map": 256, "traversal": "scan"}),
                ("volume_moments", "shadow_map=256", {"shadow_map": 256})]
    defaults = dataclasses.asdict(with_derived_sizes(scene).render)
    label = (f"defaults (slices={defaults['slices']} gamma_samples={defaults['gamma_samples']} "
             f"shadow_map={defaults['shadow_map']})")
    points = [("minmax", label, {})]
    # Cheaper than the defaults, one at a time: where the higher targets are reached for less.
    cheaper = {"slices": defaults["slices"] // 2, "gamma_samples": defaults["gamma_samples"] // 2,
               "shadow_map": defaults["shadow_map"] // 2}
    points += [("minmax", f"{key}={value}", {key: value}) for key, value in cheaper.items()]
    if volume or scene.image.width * scene.image.height > 640 * 360:
        return points
    points.append(("minmax", "traversal=scan", {"traversal": "scan"}))
    for rank in (2, 4):
        points.append(("minmax", f"integrand=svd svd_rank={rank}", {"integrand": "svd", "svd_rank": rank}))
    if all(isinstance(light, DirectionalLight) for light in scene.lights):
        points.append(("minmax", "integrand=analytic", {"integrand": "analytic"}))
    return points


def finer_minmax(scene: Scene) -> tuple[str, dict]:
    """Twice the default sizes (shadow map at most MOST_SHADOW_MAP): the minmax point tried
    where the defaults miss the lowest target."""
    defaults = with_derived_sizes(scene).render
    finer = {"shadow_map": min(2 * defaults.shadow_map, MOST_SHADOW_MAP), "slices": 2 * defaults.slices,
             "gamma_samples": 2 * defaults.gamma_samples}
    return " ".join(f"{key}={value}" for key, value in finer.items()), finer


def raymarch_ladder(measure_at, shadow_map: int, targets=RMSE_TARGETS, first: int = RAYMARCH_FIRST_STEPS,
                    most: int = RAYMARCH_MOST_STEPS, most_map: int = MOST_SHADOW_MAP,
                    most_cpu_ms: float = RAYMARCH_MOST_FRAME_CPU_MS) -> list[BenchPoint]:
    """raymarch's points, searched rather than swept: `measure_at(steps, shadow_map)` → a
    BenchPoint. Steps double from `first` until the error reaches the lowest target (or
    `most`); each target whose crossing lies between two rungs then gets one more point at
    their geometric mean, so the cheapest point at or under a target costs at most √2× the
    steps it needs. The climb also stops after a frame of more than `most_cpu_ms` of CPU
    time. The uniform steps' error falls until the shadow map's remains (the volume-only
    sun of bench/RESULTS.md history), so it also stops at a doubling that cuts the error by less
    than 1.25× within 2× of the lowest target; a ladder that ends there, short of the
    lowest target, is climbed again at twice the map, from its first rung within 2× of
    that target."""
    lowest = min(targets)
    points: dict[tuple[int, int], BenchPoint] = {}

    def climb(map_size: int, steps: int) -> bool:
        """Up the ladder at one map size; True where it ended on the map's floor."""
        previous = math.inf
        while True:
            point = points[(map_size, steps)] = measure_at(steps, map_size)
            # Near the target, a doubling that no longer cuts the error by 1.25× meets the
            # map's floor: more steps there cost the most and buy nothing.
            floor = point.rmse <= 2 * lowest and point.rmse * 1.25 > previous
            if point.rmse <= lowest or steps * 2 > most or point.cpu_ms > most_cpu_ms or floor:
                return floor and point.rmse > lowest
            previous = point.rmse
            steps *= 2

    def refine(map_size: int) -> None:
        rungs = sorted((steps, point.rmse) for (size, steps), point in points.items() if size == map_size)
        for target in sorted(targets, reverse=True):
            passing = [steps for steps, rmse in rungs if rmse <= target]
            failing = [steps for steps, rmse in rungs if rmse > target and passing and steps < min(passing)]
            if passing and failing and min(passing) >= 2 * max(failing):
                middle = int(round(math.sqrt(min(passing) * max(failing)) / 8) * 8)
                if (map_size, middle) not in points:
                    points[(map_size, middle)] = measure_at(middle, map_size)
                    rungs = sorted((steps, point.rmse) for (size, steps), point in points.items()
                                   if size == map_size)

    on_floor = climb(shadow_map, first)
    refine(shadow_map)
    if on_floor and 2 * shadow_map <= most_map:
        near = [steps for (size, steps), point in sorted(points.items()) if point.rmse <= 2 * lowest]
        climb(2 * shadow_map, near[0])
        refine(2 * shadow_map)
    return list(points.values())


def error_pixels(width: int, height: int, count: int, seed: int = 20111) -> tuple[np.ndarray, np.ndarray]:
    """A fixed, seeded subset of pixels (all of them when count >= width·height)."""
    if count >= width * height:
        ys, xs = np.divmod(np.arange(width * height), width)
        return ys, xs
    flat = np.sort(np.random.default_rng(seed).choice(width * height, size=count, replace=False))
    return np.divmod(flat, width)


def measure(renderer: Renderer, scene: Scene, method: str, repeats: int, warm_up: bool = True):
    """A warm-up frame (kernels built, buffers allocated) unless `warm_up` is False, then
    `repeats` timed frames: (median ms, spread, median stage ms, last result, median CPU ms
    of the process)."""
    if warm_up:
        renderer.render(scene, method)
    walls, cpus, stages, result = [], [], [], None
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = renderer.render(scene, method)
        walls.append((time.perf_counter() - start) * 1e3)
        cpus.append((time.process_time() - start_cpu) * 1e3)
        stages.append(result.stage_ms)
    median = statistics.median(walls)
    stage_ms = {label: statistics.median(s.get(label, 0.0) for s in stages) for label in stages[-1]}
    return median, (max(walls) - min(walls)) / median, stage_ms, result, statistics.median(cpus)


def run(scene_paths=DEFAULT_SCENES, resolutions=((640, 360),), repeats: int = 5, pixels: int = 4000,
        cache: Path | None = None, device: str | None = None, progress: bool = False, log=print,
        quick: bool = False, volume: bool = False, targets=RMSE_TARGETS) -> list[BenchPoint]:
    """The whole sweep; `cache`: the folder of the exact references; `progress`: a bar while
    one is computed; `log(line)` after each point; `volume`: surfaces black, so the error
    is the in-scattering's alone (`volume_only`); `targets`: the relative RMSEs that
    raymarch's ladder climbs to (down to the lowest)."""
    renderer = Renderer(device, reuse=False)  # every frame computed from scratch
    references = ReferenceCache(cache or cache_root(), renderer, progress)
    plan = []
    for path in scene_paths:
        for width, height in resolutions:
            scene = load_scene(path, [f"image.width={width}", f"image.height={height}"])
            if volume:
                scene = volume_only(scene)
            plan.append((path, scene, sweep(scene, quick, volume)))
    results = []
    for path, scene, points in plan:
        image = scene.image
        subset = error_pixels(image.width, image.height, pixels)
        log(f"{path} {image.width}x{image.height}: exact on {len(subset[0])} pixels ...")
        references.radiance(scene, EXACT, subset)
        built = set()  # (method, every override but steps): kernels built, no warm-up needed

        def point_at(method: str, label: str, overrides: dict) -> BenchPoint:
            variant = replace(scene, render=replace(scene.render, **overrides))
            build = (method, tuple(sorted((key, value) for key, value in overrides.items() if key != "steps")))
            frame_ms, spread, stage_ms, result, cpu_ms = measure(renderer, variant, method, repeats,
                                                                 build not in built)
            built.add(build)
            error = references.error(scene, EXACT, result.image, subset)
            if not error.pixels:  # (a thumbnail: its few pixels all dark or on depth edges)
                raise ClraysError(f"{path} at {image.width}x{image.height}: no pixel is left to compare against "
                                  f"exact (each is dark or on a depth edge); bench it at a larger -r")
            point = BenchPoint(Path(path).stem, f"{image.width}x{image.height}", method, label, frame_ms, spread,
                               error.rmse, error.p99, error.mean, result.device_bytes / 2**20, stage_ms,
                               os.getloadavg()[0], cpu_ms)
            results.append(point)
            log(point_line(point))
            return point

        mine = [point_at(method, label, overrides) for method, label, overrides in points]
        if quick:
            continue
        if not any(p.method == "minmax" and p.rmse <= min(targets) for p in mine):
            point_at("minmax", *finer_minmax(scene))
        raymarch_ladder(lambda steps, shadow_map: point_at("raymarch", f"steps={steps} shadow_map={shadow_map}",
                                                           {"steps": steps, "shadow_map": shadow_map}),
                        with_derived_sizes(scene).render.shadow_map, targets)
    return results


def point_line(point: BenchPoint) -> str:
    """A point's line of the console table, its columns aligned whatever the method."""
    return (f"  {point.method:{max(map(len, METHODS))}} {point.setting:44} {point.frame_ms:9.1f} ms "
            f"(cpu {point.cpu_ms:9.1f})  rmse {point.rmse:7.3%}  p99 {point.p99:7.3%}  load {point.load_average:4.1f}")


def cheapest_at(points: list[BenchPoint], method: str, target: float) -> BenchPoint | None:
    """The fastest point of a method whose relative RMSE is at most `target`."""
    good = [p for p in points if p.method == method and p.rmse <= target]
    return min(good, key=lambda p: p.frame_ms) if good else None


def pareto_front(points: list[BenchPoint]) -> list[BenchPoint]:
    """Points no other point beats on both time and error, by increasing time."""
    front, best = [], math.inf
    for point in sorted(points, key=lambda p: (p.frame_ms, p.rmse)):
        if point.rmse < best:
            front.append(point)
            best = point.rmse
    return front


def summary(points: list[BenchPoint], targets=RMSE_TARGETS) -> list[dict]:
    """Per scene and resolution and target: speedup of minmax over raymarch at equal error,
    by wall time and by CPU time. Where raymarch reaches no target, equal error needs more
    than its costliest point: `speedup_above@` is that point's frame time over minmax's, a
    lower bound."""
    rows = []
    for key in dict.fromkeys((p.scene, p.resolution) for p in points):
        group = [p for p in points if (p.scene, p.resolution) == key]
        raymarch = [p for p in group if p.method == "raymarch"]
        costliest = max(raymarch, key=lambda p: p.frame_ms) if raymarch else None
        row = {"scene": key[0], "resolution": key[1]}
        for target in targets:
            fast, slow = cheapest_at(group, "minmax", target), cheapest_at(group, "raymarch", target)
            tag = target_tag(target)
            row[f"minmax_ms@{tag}"] = fast.frame_ms if fast else None
            row[f"minmax_setting@{tag}"] = fast.setting if fast else "not reached"
            row[f"raymarch_ms@{tag}"] = slow.frame_ms if slow else None
            row[f"raymarch_setting@{tag}"] = slow.setting if slow else "not reached"
            row[f"speedup@{tag}"] = slow.frame_ms / fast.frame_ms if fast and slow else None
            row[f"speedup_cpu@{tag}"] = slow.cpu_ms / fast.cpu_ms if fast and slow else None
            above = fast and not slow and costliest
            row[f"speedup_above@{tag}"] = costliest.frame_ms / fast.frame_ms if above else None
            row[f"raymarch_costliest@{tag}"] = (f"{costliest.setting}: {costliest.rmse:.2%} in "
                                                f"{costliest.frame_ms:.0f} ms") if above else ""
        rows.append(row)
    return rows


def write_csv(points: list[BenchPoint], path: Path) -> None:
    stages = sorted({label for p in points for label in p.stage_ms})
    handle = io.StringIO(newline="")
    writer = csv.writer(handle)
    writer.writerow(["scene", "resolution", "method", "setting", "frame_ms", "frame_ms_spread", "rel_rmse",
                     "p99_rel_error", "mean_rel_error", "device_mib", "load_average", "cpu_ms"] + [f"{s}_ms" for s in stages])
    for p in points:
        writer.writerow([p.scene, p.resolution, p.method, p.setting, f"{p.frame_ms:.2f}", f"{p.frame_ms_spread:.3f}",
                         f"{p.rmse:.6f}", f"{p.p99:.6f}", f"{p.mean_error:.6f}", f"{p.device_mib:.1f}", f"{p.load_average:.2f}", f"{p.cpu_ms:.1f}"]
                        + [f"{p.stage_ms.get(s, 0.0):.2f}" for s in stages])
    write_text(path, handle.getvalue(), newline="")


#: Colours of the methods the bench runs; a method not listed takes the next free one.
METHOD_COLOURS = {"raymarch": "tab:orange", "minmax": "tab:blue", "volume_moments": "tab:green"}


def plot(points: list[BenchPoint], path: Path, targets=RMSE_TARGETS) -> None:
    """Error against time, log-log, one panel per scene and resolution, one curve per method,
    the Pareto front of all points marked."""
    import matplotlib.pyplot as plt

    figure = figure_of(points, targets)
    write_atomic(path, lambda temporary: figure.savefig(temporary, dpi=110, format="png"))
    plt.close(figure)


def figure_of(points: list[BenchPoint], targets=RMSE_TARGETS):
    """The matplotlib figure of `plot`. Its legends name the methods a panel has points of,
    by the names they ran under, and nothing else."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def percent(fraction: float) -> float:  # the axis in percent, as the tables; 0 drawn at 0.001 % on the log scale
        return 100 * max(fraction, 1e-5)

    groups = list(dict.fromkeys((p.scene, p.resolution) for p in points))
    columns = min(len(groups), 2)
    rows = math.ceil(len(groups) / columns)
    figure, axes = plt.subplots(rows, columns, figsize=(6.5 * columns, 4.8 * rows), squeeze=False)
    methods = list(dict.fromkeys(p.method for p in points))  # in the order they ran
    spare = (colour for colour in ("tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")
             if colour not in METHOD_COLOURS.values())
    colours = {method: METHOD_COLOURS.get(method) or next(spare, "tab:gray") for method in methods}
    for axis, key in zip(axes.ravel(), groups):
        group = [p for p in points if (p.scene, p.resolution) == key]
        for method in dict.fromkeys(p.method for p in group):
            mine = sorted((p for p in group if p.method == method), key=lambda p: p.frame_ms)
            axis.scatter([p.frame_ms for p in mine], [percent(p.rmse) for p in mine], s=18,
                         color=colours[method], label=method, alpha=0.8)
            front = pareto_front(mine)
            axis.plot([p.frame_ms for p in front], [percent(p.rmse) for p in front], color=colours[method], lw=1.2)
        overall = pareto_front(group)
        axis.scatter([p.frame_ms for p in overall], [percent(p.rmse) for p in overall], s=70,
                     facecolors="none", edgecolors="black", label="Pareto front (all)")
        for target in targets:
            axis.axhline(percent(target), color="grey", ls=":", lw=0.8)
        axis.set_xscale("log")
        axis.set_yscale("log")
        axis.set_xlabel("frame time (ms, median)")
        axis.set_ylabel("relative RMSE vs exact (%)")
        axis.set_title(f"{key[0]} {key[1]}")
        axis.legend(fontsize=8)
    for axis in axes.ravel()[len(groups):]:
        axis.set_visible(False)
    figure.tight_layout()
    return figure


def machine(device: str | None = None) -> dict:
    """What the figures were measured on."""
    import os

    from ..device import Device

    return {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
            "python": platform.python_version(), "device": Device(device).name}


def peak_host_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def markdown_summary(points: list[BenchPoint], targets=RMSE_TARGETS) -> str:
    """The headline table, as it goes into bench/RESULTS.md."""
    lines = ["| scene | resolution | target rel. RMSE | minmax (ms, setting) | raymarch (ms, setting) | speedup "
             "| speedup, CPU time |",
             "|---|---|---|---|---|---|---|"]

    def times(value, spec):
        return "—" if value is None else f"{value:{spec}}"

    for row in summary(points, targets):
        for target in targets:
            tag = target_tag(target)
            raymarch = f"{times(row[f'raymarch_ms@{tag}'], '.0f')} ({row[f'raymarch_setting@{tag}']})"
            speedup = times(row[f"speedup@{tag}"], ".1f") + "×"
            if row[f"speedup_above@{tag}"] is not None:
                raymarch = f"not reached (costliest: {row[f'raymarch_costliest@{tag}']})"
                speedup = f"> {row[f'speedup_above@{tag}']:.1f}×"
            lines.append(f"| {row['scene']} | {row['resolution']} | {tag} | "
                         f"{times(row[f'minmax_ms@{tag}'], '.0f')} ({row[f'minmax_setting@{tag}']}) | {raymarch} | "
                         f"{speedup.replace('—×', '—')} | {times(row[f'speedup_cpu@{tag}'], '.1f')}× |"
                         .replace("| —× |", "| — |"))
    return "\n".join(lines)


def save(points: list[BenchPoint], out: Path, extra: dict | None = None, device: str | None = None,
         targets=RMSE_TARGETS) -> None:
    """CSV, plot, summary table and machine description into `out` (created)."""
    make_folder(out)
    write_csv(points, out / "bench.csv")
    plot(points, out / "bench.png", targets)
    write_text(out / "summary.md", markdown_summary(points, targets) + "\n")
    info = {"machine": machine(device), "peak_host_mib": peak_host_mib(), **(extra or {})}
    write_text(out / "machine.json", json.dumps(info, indent=2) + "\n")
