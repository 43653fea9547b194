"""The `clrays` command line."""
from __future__ import annotations

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
"""


class _Context:
    debug = False


def _fail(exc: BaseException) -> None:
    """One line on stderr and exit 1; the traceback only with --debug."""
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
@click.option("--exposure", type=float, default=0.0, show_default=True,
              help="PNG only: scale radiance by 2^EXPOSURE before sRGB encoding.")
@click.option("--stats", is_flag=True, help="Print per-stage device times and device memory.")
@click.option("--device", envvar="CLRAYS_DEVICE", help="OpenCL device: 'P:D' index or name substring.")
@click.option("--progress/--no-progress", default=None, help="Progress bar for slow methods (default: on a terminal).")
def render(scene: Path, output: Path, method, overrides, exposure, stats, device, progress) -> None:
    """Render SCENE (a YAML file) to an image."""
    try:
        from .output import check_output_path, write_image
        from .renderer import Renderer
        from .scene_loader import load_scene

        check_output_path(output)
        loaded = load_scene(scene, overrides)
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


def _print_stats(result) -> None:
    click.echo(f"method: {result.method}")
    for label, ms in result.stage_ms.items():
        click.echo(f"  {label:<10} {ms:9.2f} ms (device)")
    if result.stage_ms:
        click.echo(f"  {'total':<10} {sum(result.stage_ms.values()):9.2f} ms (device)")
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
@click.option("--device", envvar="CLRAYS_DEVICE", help="OpenCL device: 'P:D' index or name substring.")
def bench(scenes, resolutions, out, repeats, pixels, cache, quick, device) -> None:
    """Time every method and setting against its error versus `exact`.

    Writes a CSV of every point, a log-log plot of error against time with the Pareto
    front, and the headline table (speedup of minmax over raymarch at equal error).
    """
    try:
        from . import bench as bench_module

        sizes = resolutions
        paths = [str(path) for path in scenes] or list(bench_module.DEFAULT_SCENES)
        for path in paths:
            if not Path(path).is_file():
                raise ClraysError(f"{path}: no such scene file")
        points = bench_module.run(paths, sizes, repeats=repeats, pixels=pixels, cache=cache, device=device,
                                  log=lambda line: click.echo(line, err=True), quick=quick)
        bench_module.save(points, out, {"repeats": repeats, "pixels": pixels,
                                        "resolutions": [f"{w}x{h}" for w, h in sizes], "scenes": paths})
        click.echo(bench_module.markdown_summary(points))
        click.echo(f"wrote {out}/bench.csv, bench.png, summary.md, machine.json")
    except Exception as exc:  # noqa: BLE001 - every failure becomes one line
        _fail(exc)


if __name__ == "__main__":
    main()
