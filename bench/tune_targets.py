"""`clrays tune` on the fine-occluder and bench scenes at several targets: per scene and
target the tuned setting, its error against `exact` and frame time, the search's time
and settings tried, beside the defaults' error and time; with `--grid`, also the fastest
setting of a grid over the same knobs that meets each target (bench/RESULTS.md, "Tuning").

    .venv/bin/python bench/tune_targets.py --size 320x180
    .venv/bin/python bench/tune_targets.py lattice grate --size 640x360 --targets 1,0.5
    .venv/bin/python bench/tune_targets.py demo --size 320x180 --grid

The grid: shadow_map 256–4096, slices and gamma_samples 256–2048 (×2 steps), and for
minmax's epipolar sampling line_samples at ½, 1 and 2× the derived count with
initial_step 1, 3 and 6 (refine_threshold at its default), and minmax's shaft edges on
the blockers or at the texels: 1440 settings, each timed as
tune times them (median of 3 warm frames, after the frame whose error is measured). Both
compare by `clrays tune`'s cost, the process's CPU time per frame on a CPU device (columns
"CPU ms"), which the load of a shared machine moves far less than the wall time.
"""
from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import REPO, image_size  # noqa: E402
from clrays.runs import tune as tuning  # noqa: E402
from clrays.runs.references import ReferenceCache  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402


def grid(scene, method: str) -> list[dict]:
    start = tuning.start_settings(scene, method)
    maps, sizes = (256, 512, 1024, 2048, 4096), (256, 512, 1024, 2048)
    settings = []
    edges = ("texels", "blockers") if "shaft_edges" in start else (None,)
    for shadow_map, slices, gamma, edge in itertools.product(maps, sizes, sizes, edges):
        base = {**start, "shadow_map": shadow_map, "slices": slices, "gamma_samples": gamma}
        if edge is not None:
            base["shaft_edges"] = edge
        if "line_samples" not in start:
            settings.append(base)
            continue
        for scale, step in itertools.product((0.5, 1, 2), (1, 3, 6)):
            settings.append({**base, "line_samples": max(16, int(start["line_samples"] * scale)), "initial_step": step})
    return settings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=["lattice", "grate", "demo", "bunny", "behind", "sun"])
    parser.add_argument("--size", type=image_size, default="320x180")
    parser.add_argument("--targets", default="1,0.5,0.2", help="percent, comma-separated")
    parser.add_argument("--grid", action="store_true", help="also the fastest grid setting at each target")
    parser.add_argument("--cache", default=str(REPO / ".cache" / "references"))
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    targets = [float(text) / 100 for text in args.targets.split(",")]
    references = ReferenceCache(Path(args.cache))
    renderer = Renderer(reuse=False)
    print(f"{width}×{height}; relative RMSE against exact on {tuning.TUNE_PIXELS} pixels, depth edges out; frame: "
          f"median of {tuning.TUNE_REPEATS} warm frames\n")
    head = ("| scene | target | tuned setting | error % | frame ms | CPU ms | defaults: error %, ms, CPU ms | tried "
            "| tuning s |")
    rule = "|---|---|---|---|---|---|---|---|---|"
    if args.grid:
        head, rule = head + " grid's fastest: setting, error %, CPU ms | tuned / grid, CPU |", rule + "---|---|"
    print(head)
    print(rule)
    for name in args.scenes:
        scene = load_scene(REPO / "scenes" / f"{name}.yaml", [f"image.width={width}", f"image.height={height}"])
        grid_trials = None
        if args.grid:
            search = tuning.Search(scene, scene.render.method, references, renderer)
            grid_trials = [search.measure(settings) for settings in grid(scene, scene.render.method)]
        for target in targets:
            start = time.perf_counter()
            result = tuning.tune(scene, target, references, renderer)
            seconds = time.perf_counter() - start
            best, default = result.best, result.default
            cells = [name, f"{100 * target:g} %"]
            if best is None:
                cells += [f"not reached (best {100 * result.closest.rmse:.3f} %: "
                          f"{tuning.settings_text(result.closest.settings)})", "—", "—", "—"]
            else:
                cells += [tuning.settings_text(best.settings), f"{100 * best.rmse:.3f}", f"{best.frame_ms:.0f}",
                          f"{best.cost_ms:.0f}"]
            cells += [f"{100 * default.rmse:.3f}, {default.frame_ms:.0f}, {default.cost_ms:.0f}",
                      str(len(result.trials)), f"{seconds:.0f}"]
            if grid_trials is not None:
                good = [trial for trial in grid_trials if trial.rmse <= target]
                fastest = min(good, key=lambda trial: trial.cost_ms) if good else None
                cells.append(f"{tuning.settings_text(fastest.settings)}, {100 * fastest.rmse:.3f}, "
                             f"{fastest.cost_ms:.0f}" if fastest else "none meets it")
                cells.append(f"{best.cost_ms / fastest.cost_ms:.2f}" if fastest and best else "—")
            print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
