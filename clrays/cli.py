"""The `clrays` command line."""
from __future__ import annotations

import contextlib
import signal
import sys
import traceback
from pathlib import Path

import click

from .errors import ClraysError

EXAMPLES_RENDER = """
\b
Examples:
  clrays render scenes/demo.yaml -o out/demo.png
  clrays render scenes/demo.yaml -o out/demo.exr --method raymarch --set render.steps=1024
  clrays render scenes/demo.yaml -o out/demo.npy --set medium.sigma_s=0.1 --stats
  clrays render scenes/orbit.yaml -o out/orbit_30.png --frame 30
"""


class _Context:
    debug = False


def _fail(exc: BaseException) -> None:
    """One line on stderr and exit 1; the traceback only with --debug."""
    if isinstance(exc, BrokenPipeError):  # `clrays ... | head`: the reader left, nothing to report
        sys.stderr.close()
        sys.exit(1)
    if _Context.debug:
        traceback.print_exception(exc)
    if isinstance(exc, ClraysError):
        click.echo(f"clrays: error: {exc}", err=True)
    else:
        click.echo(f"clrays: internal error: {type(exc).__name__}: {exc} (run with --debug for the traceback)",
                   err=True)
    sys.exit(1)


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.option("--debug", is_flag=True, help="Show tracebacks for errors.")
@click.version_option(package_name="clrays")
def main(debug: bool) -> None:
    """Render volumetric shadows (light shafts in fog) with OpenCL.

    \b
    Examples:
      clrays render scenes/demo.yaml -o out/demo.png
      clrays sequence scenes/orbit.yaml -o 'out/orbit/frame_{:04d}.png'
      clrays sweep scenes/demo.yaml --set medium.sigma_s=0.02,0.05 -o out/sweep
      clrays bench scenes/demo.yaml -r 640x360
      clrays info
    """
    _Context.debug = debug


@main.command()
@click.option("--device", envvar="CLRAYS_DEVICE", help="Only show this device spec's choice.")
def info(device: str | None) -> None:
    """List OpenCL platforms and devices, and the one clrays would use.

    \b
    Example:
      clrays info
    """
    try:
        from .device import list_devices, select_device

        chosen = select_device(device)
        for p, d, platform, dev in list_devices():
            mark = "*" if dev == chosen else " "
            memory = dev.global_mem_size / 2**30
            doubles = "fp64" if dev.double_fp_config else "no fp64"
            click.echo(f"{mark} {p}:{d}  {platform.name.strip()} / {dev.name.strip()}  "
                       f"({dev.version.strip()}, {dev.max_compute_units} CUs, {memory:.1f} GiB, {doubles})")
        click.echo("* = default device (choose with --device or CLRAYS_DEVICE: 'P:D' or a name substring)")
    except Exception as exc:  # noqa: BLE001 - every failure becomes one line
        _fail(exc)


@main.command(epilog=EXAMPLES_RENDER)
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(path_type=Path),
              help="Output image: .png (8-bit sRGB), .exr (float RGB) or .npy (float32 linear H×W×3).")
@click.option("--method", type=click.Choice(["minmax", "raymarch", "exact"]),
              help="Override render.method.")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override a scene field (repeatable), e.g. --set render.steps=1024.")
@click.option("--exposure", type=click.FloatRange(-64, 64), default=0.0, show_default=True,
              help="PNG only: scale radiance by 2^EXPOSURE before sRGB encoding.")
@click.option("--stats", is_flag=True, help="Print per-stage device times and device memory.")
@click.option("--device", envvar="CLRAYS_DEVICE", help="OpenCL device: 'P:D' index or name substring.")
@click.option("--progress/--no-progress", default=None, help="Progress bar for slow methods (default: on a terminal).")
@click.option("--frame", type=int, metavar="N", help="Render frame N of the scene's animation (see `clrays sequence`).")
def render(scene: Path, output: Path, method, overrides, exposure, stats, device, progress, frame) -> None:
    """Render SCENE (a YAML file) to an image."""
    try:
        from .image_io import check_output_path, write_image
        from .session import Renderer
        from .scene.load import load_scene
        from .runs.sequence import parse_frames, scene_frames

        check_output_path(output)
        loaded = load_scene(scene, overrides)
        if frame is not None:
            parse_frames(str(frame), scene_frames(loaded), "--frame")
            loaded = loaded.animation.scene_at(loaded, frame) if loaded.animation is not None else loaded
        show_progress = sys.stderr.isatty() if progress is None else progress
        result = Renderer(device).render(loaded, method, progress=show_progress)
        if not np_isfinite(result.image):
            raise ClraysError(f"{scene}: the render produced non-finite values (a bug: please report the scene)")
        write_image(output, result.image, exposure)
        if stats:
            _print_stats(result)
    except Exception as exc:  # noqa: BLE001 - every failure becomes one line
        _fail(exc)


def np_isfinite(image) -> bool:
    import numpy as np

    return bool(np.isfinite(image).all())


def _stage_statuses(result) -> dict[str, str]:
    """Stage label (as in the timings) → computed / reused / skipped; raster has two parts."""
    status, shown = {}, {}
    for stage, value in result.stage_status.items():
        label, _, part = stage.partition(".")
        status.setdefault(label, []).append((part, value))
    for label, parts in status.items():
        names = {"camera": "camera", "shadow": "shadow maps"}
        shown[label] = ", ".join(f"{names.get(p, p)} {v}" if p else v for p, v in parts)
    return shown


#: Stages that run on the host (their time is wall clock, not an OpenCL event).
HOST_STAGES = {"integrand"}


def _print_stats(result) -> None:
    click.echo(f"method: {result.method}")
    status = _stage_statuses(result)
    for label, ms in result.stage_ms.items():
        where = "host" if label in HOST_STAGES else "device"
        click.echo(f"  {label:<10} {ms:9.2f} ms {f'({where})':<8}  {status.get(label, '')}".rstrip())
    for label, text in status.items():
        if label not in result.stage_ms:
            click.echo(f"  {label:<10} {'-':>9}              {text}")
    if result.stage_ms:
        click.echo(f"  {'total':<10} {sum(result.stage_ms.values()):9.2f} ms (device + host stages)")
    click.echo(f"  wall       {result.wall_ms:9.2f} ms")
    click.echo(f"  device memory {result.device_bytes / 2**20:.1f} MiB")


def _resolutions(context, parameter, texts) -> list[tuple[int, int]]:
    """Click callback: WIDTHxHEIGHT strings → (width, height) pairs, usage error otherwise."""
    sizes = []
    for text in texts:
        try:
            width, height = (int(part) for part in text.lower().split("x"))
            if width < 1 or height < 1:
                raise ValueError
        except ValueError:
            raise click.BadParameter(f"expected WIDTHxHEIGHT like 640x360, got {text!r}") from None
        sizes.append((width, height))
    return sizes


@main.command(epilog="""
\b
Examples:
  clrays bench                                  # every bench scene at 640x360
  clrays bench scenes/demo.yaml -r 1280x720 -r 640x360 --out bench/out
  clrays bench --repeats 3 --pixels 500         # a quicker, noisier run
  clrays bench scenes/demo.yaml -r 64x36 --quick  # smoke run: does it all work?
""")
@click.argument("scenes", nargs=-1, type=click.Path(dir_okay=False, path_type=Path))
@click.option("-r", "--resolution", "resolutions", multiple=True, default=["640x360"], show_default=True,
              callback=_resolutions, help="WIDTHxHEIGHT to render at (repeatable).")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("bench/out"),
              show_default=True, help="Folder for bench.csv, bench.png, summary.md, machine.json.")
@click.option("--repeats", type=click.IntRange(1, 100), default=5, show_default=True,
              help="Timed frames per point (after one warm-up); the median is reported.")
@click.option("--pixels", type=click.IntRange(16), default=4000, show_default=True,
              help="Pixels (fixed random subset) on which the error against exact is measured.")
@click.option("--cache", type=click.Path(file_okay=False, path_type=Path), default=Path(".cache/clrays"),
              show_default=True, help="Where exact references are cached.")
@click.option("--quick", is_flag=True, help="A handful of points per scene: a smoke run, not results.")
@click.option("--volume-only", "volume", is_flag=True,
              help="Black surfaces: measure the in-scattering's error alone (a smaller sweep).")
@click.option("--device", envvar="CLRAYS_DEVICE", help="OpenCL device: 'P:D' index or name substring.")
def bench(scenes, resolutions, out, repeats, pixels, cache, quick, volume, device) -> None:
    """Time every method and setting against its error versus `exact`.

    Writes a CSV of every point, a log-log plot of error against time with the Pareto
    front, and the headline table (speedup of minmax over raymarch at equal error).
    """
    try:
        from .runs import bench as bench_module
        from .image_io import check_folder

        sizes = resolutions
        for folder in (out, cache):  # fail before the sweep, not after it
            try:
                folder.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise ClraysError(f"{folder}: cannot create folder: {exc.strerror or exc}") from None
            check_folder(folder / "probe")
        paths = [str(path) for path in scenes] or list(bench_module.DEFAULT_SCENES)
        for path in paths:
            if not Path(path).is_file():
                raise ClraysError(f"{path}: no such scene file")
        points = bench_module.run(paths, sizes, repeats=repeats, pixels=pixels, cache=cache, device=device,
                                  log=lambda line: click.echo(line, err=True), quick=quick, volume=volume)
        bench_module.save(points, out, device=device, extra={"repeats": repeats, "pixels": pixels, "volume_only": volume,
                                        "resolutions": [f"{w}x{h}" for w, h in sizes], "scenes": paths})
        click.echo(bench_module.markdown_summary(points))
        click.echo(f"wrote {out}/bench.csv, bench.png, summary.md, machine.json")
    except Exception as exc:  # noqa: BLE001 - every failure becomes one line
        _fail(exc)



@contextlib.contextmanager
def _sigterm_as_interrupt():
    """SIGTERM raises KeyboardInterrupt, like Ctrl-C, so a half-written frame's temporary
    file is removed on the way out and the run ends with its resume hint."""
    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _stage_counts(results) -> str:
    """Per stage over many frames: how often it was computed, reused, skipped."""
    counts: dict[str, dict[str, int]] = {}
    for result in results:
        for stage, status in result.stage_status.items():
            kind = status.split()[0]
            counts.setdefault(stage, {}).setdefault(kind, 0)
            counts[stage][kind] += 1
    lines = [f"  {stage:<14} " + ", ".join(f"{kind} {n}" for kind, n in sorted(kinds.items()))
             for stage, kinds in counts.items()]
    labels = list(dict.fromkeys(label for result in results for label in result.stage_ms))
    means = {label: sum(r.stage_ms.get(label, 0.0) for r in results) / len(results) for label in labels}
    wall = sum(r.wall_ms for r in results) / len(results)
    lines.append("  mean per frame: " + ", ".join(f"{label} {ms:.1f}" for label, ms in means.items())
                 + f"; stage total (device + host) {sum(means.values()):.1f}; wall {wall:.1f} ms")
    return "\n".join(lines)


def _frame_line(label: str, result) -> str:
    reused = " ".join(result.reused) or "-"
    return f"{label}: {result.wall_ms:8.1f} ms  reused: {reused}"


EXAMPLES_SEQUENCE = """
\b
Examples:
  clrays sequence scenes/orbit.yaml -o out/orbit/frame_{:04d}.png
  clrays sequence scenes/orbit.yaml -o out/orbit/frame_{:04d}.png --frames 0:23 --video out/orbit.gif
  clrays sequence scenes/orbit.yaml -o out/orbit/f_{:04d}.npy --set image.width=320 --stats

\b
Frames are written atomically: re-running the same command skips the frames already
there, so an interrupted run resumes where it stopped (--overwrite renders all again).
"""


@main.command(epilog=EXAMPLES_SEQUENCE)
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", "pattern", required=True, metavar="PATTERN",
              help="Frame files, with one {} field for the frame number: frames/frame_{:04d}.png "
                   "(.png, .exr or .npy; the folder is created).")
@click.option("--frames", metavar="A:B", help="Frames A to B, inclusive (also A:, :B or N). Default: the "
                                             "animation's frames.")
@click.option("--video", type=click.Path(dir_okay=False, path_type=Path),
              help="Also write the frames as an animation: .gif or .webp (at the animation's fps).")
@click.option("--method", type=click.Choice(["minmax", "raymarch", "exact"]), help="Override render.method.")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override a scene field (repeatable), e.g. --set animation.fps=12.")
@click.option("--exposure", type=click.FloatRange(-64, 64), default=0.0, show_default=True,
              help="PNG and video: scale radiance by 2^EXPOSURE before sRGB encoding.")
@click.option("--overwrite", is_flag=True, help="Render every frame, also those already written.")
@click.option("--reuse/--no-reuse", default=True, show_default=True,
              help="Keep stage results between frames; re-run a stage only when its inputs changed.")
@click.option("--stats", is_flag=True, help="Print each frame's time and reused stages, then a summary.")
@click.option("--device", envvar="CLRAYS_DEVICE", help="OpenCL device: 'P:D' index or name substring.")
@click.option("--progress/--no-progress", default=None, help="Progress bar (default: on a terminal).")
def sequence(scene, pattern, frames, video, method, overrides, exposure, overwrite, reuse, stats, device,
             progress) -> None:
    """Render the frames of SCENE's animation to numbered images."""
    done = []
    try:
        from .session import Renderer
        from .scene.load import load_scene
        from .runs.sequence import check_pattern, check_video_path, parse_frames, render_sequence, scene_frames, write_video

        check_pattern(pattern)
        if video is not None:
            check_video_path(video)
        loaded = load_scene(scene, overrides)
        chosen = parse_frames(frames, scene_frames(loaded))
        show_progress = sys.stderr.isatty() if progress is None else progress

        def on_frame(frame, path, result):
            if result is not None:
                done.append(result)
                if stats:
                    click.echo(_frame_line(f"frame {frame}", result))

        with _sigterm_as_interrupt():
            report = render_sequence(loaded, pattern, chosen, renderer=Renderer(device, reuse=reuse), method=method,
                                     exposure=exposure, overwrite=overwrite, progress=show_progress,
                                     on_frame=on_frame)
        click.echo(report.summary())
        if stats and done:
            click.echo("stages over the rendered frames:\n" + _stage_counts(done))
        if video is not None:
            fps = loaded.animation.fps if loaded.animation is not None else 24.0
            click.echo(f"wrote {write_video(report.paths, video, fps, exposure)}")
    except KeyboardInterrupt:
        click.echo(f"clrays: interrupted after {len(done)} new frames; run the same command again to resume",
                   err=True)
        sys.exit(130)
    except Exception as exc:  # noqa: BLE001 - every failure becomes one line
        _fail(exc)


EXAMPLES_SWEEP = """
\b
Examples:
  clrays sweep scenes/demo.yaml --set medium.sigma_s=0.02,0.05,0.1 --set render.slices=256,1024 -o out/sweep
  clrays sweep scenes/demo.yaml --set render.slices=128,256,512,1024 --reference raymarch:2048 -o out/slices
  clrays sweep scenes/demo.yaml --set 'lights.0.intensity=[100,100,100],[300,300,300]' -o out/power

\b
Writes one image per point (000.png, 001.png, ...), results.csv (the parameters, wall and
per-stage times, reused stages and, with --reference, the error against it) and
contact_sheet.png. Re-running the same command keeps the points already done.
"""


@main.command(epilog=EXAMPLES_SWEEP)
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--set", "settings", multiple=True, metavar="KEY.PATH=V1,V2,...",
              help="A swept key with comma-separated values, or a fixed override with one (repeatable); the "
                   "points are the cartesian product of the swept keys.")
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Folder for the images, results.csv and contact_sheet.png (created).")
@click.option("--reference", metavar="exact|raymarch:N", help="Measure each point's error against this reference.")
@click.option("--method", type=click.Choice(["minmax", "raymarch", "exact"]), help="Override render.method.")
@click.option("--format", "image_format", type=click.Choice(["png", "exr", "npy"]), default="png",
              show_default=True, help="Image format of the points.")
@click.option("--exposure", type=click.FloatRange(-64, 64), default=0.0, show_default=True,
              help="PNG and contact sheet: scale radiance by 2^EXPOSURE before sRGB encoding.")
@click.option("--overwrite", is_flag=True, help="Render every point, also those done by an earlier run.")
@click.option("--reuse/--no-reuse", default=True, show_default=True,
              help="Keep stage results between points; re-run a stage only when its inputs changed.")
@click.option("--device", envvar="CLRAYS_DEVICE", help="OpenCL device: 'P:D' index or name substring.")
@click.option("--progress/--no-progress", default=None, help="Progress bar (default: on a terminal).")
def sweep(scene, settings, out_dir, reference, method, image_format, exposure, overwrite, reuse, device,
          progress) -> None:
    """Render SCENE at every combination of the --set values and tabulate the results."""
    done = []
    try:
        from .session import Renderer
        from .runs.sweep import axes_from, format_table, parse_reference, run_sweep

        if not scene.is_file():
            raise ClraysError(f"{scene}: no such scene file")
        axes, _ = axes_from(list(settings))
        parse_reference(reference)
        show_progress = sys.stderr.isatty() if progress is None else progress
        with _sigterm_as_interrupt():
            report = run_sweep(scene, list(settings), out_dir, method=method, reference=reference,
                               renderer=Renderer(device, reuse=reuse), exposure=exposure, image_format=image_format,
                               overwrite=overwrite, progress=show_progress,
                               on_point=lambda point, row: done.append(point))
        click.echo(format_table(report.rows, axes), nl=False)
        click.echo(report.summary())
    except KeyboardInterrupt:
        click.echo(f"clrays: interrupted after {len(done)} points; run the same command again to resume", err=True)
        sys.exit(130)
    except Exception as exc:  # noqa: BLE001 - every failure becomes one line
        _fail(exc)

if __name__ == "__main__":
    main()
