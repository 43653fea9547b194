"""The `clrays` command line.

One group, `Clrays`, runs every command and turns what escapes it into one line and
exit code 1 (the traceback only with `--debug`); each command's `--help` lists its
options in sections, and the options that several commands share are declared once
below (`device_option`, `method_option`, ...).
"""
from __future__ import annotations

import contextlib
import json
import math
import signal
import sys
import traceback
from pathlib import Path
from typing import Callable

import click
from click.core import ParameterSource

from . import device as device_settings
from .device import list_devices, select_device
from .errors import ClraysError, DeviceError, OutputError
from .exposure import (AUTO, EV_LIMIT, EXPOSED_IMAGES, EXPOSED_VIDEO, exposure_setting, frame_exposure,
                       parse_exposure)
from .image_io import check_folder, check_name_length, check_output_path, make_folder, make_output_folder
from .outputs import allow_writes, cache_root, check_replaceable, end_writes
from .passes import pass_paths, pass_problem, write_render
from .reference.exact import estimate_seconds
from .runs import bench as bench_run
from .runs.progress import counted
from .runs.references import parse_reference
from .runs.point import REFERENCES
from .runs.sequence import (check_pattern, check_video_path, lock_folder, parse_frames, render_sequence,
                            scene_frames, write_video)
from .runs.video import DEFAULT_CRF, VIDEO_OPTIONS, video_encoder_options
from .runs.sweep import axes_from, format_table, run_sweep
from .runs.tune import TUNE_BUDGET_S, Consent, tuned_scene
from .scene import files as scene_files
from .scene import yaml_tree
from .scene import gltf as gltf_files
from .scene.fields import unread_render_keys
from .scene.limits import MAX_LIGHTS, MAX_SWEEP_POINTS
from .scene import host_steps
from .scene.load import load_scene
from .scene.model import METHODS, RENAMED_METHODS, SHADOW_FILTERS
from .session import Renderer

#: Option sections of a command's --help, in this order (then any other, then "Other").
SCENE, SWEEP, BENCH, OUTPUT, RUN, DEVICE, OTHER = "Scene", "Sweep", "Bench", "Output", "Run", "Device", "Other"
SECTIONS = (SCENE, SWEEP, BENCH, OUTPUT, RUN, DEVICE)

#: `exact` runs estimated to take at least this long are announced up front.
EXACT_ESTIMATE_MIN_S = 5.0


def _set_debug(context: click.Context, parameter, value: bool) -> None:
    """--debug, given to the group or to a command: kept in `ctx.obj`, which they share."""
    settings = context.ensure_object(dict)
    settings["debug"] = settings.get("debug", False) or value
    if value:  # and the OpenCL compiler's own output, which is otherwise kept out of the terminal
        device_settings.show_compiler_output = True


class Option(click.Option):
    """An option with the section (`group`) its command's --help lists it under."""

    def __init__(self, *declarations, group: str = OTHER, **settings):
        super().__init__(*declarations, **settings)
        self.group = group


def option(*declarations, group: str, **settings):
    return click.option(*declarations, cls=Option, group=group, **settings)


class Command(click.Command):
    """A command of `clrays`: it takes --debug too, lists its options in sections, and
    belongs to a `section` of `clrays --help`."""

    def __init__(self, *arguments, section: str = "Commands", **settings):
        super().__init__(*arguments, **settings)
        self.section = section
        self.params.append(Option(["--debug"], group=OTHER, is_flag=True, expose_value=False, callback=_set_debug,
                                  help="Show the traceback of an error."))

    def format_options(self, context: click.Context, formatter: click.HelpFormatter) -> None:
        sections: dict[str, list[tuple[str, str]]] = {}
        for parameter in self.get_params(context):
            record = parameter.get_help_record(context) if isinstance(parameter, click.Option) else None
            if record is not None:
                sections.setdefault(getattr(parameter, "group", OTHER), []).append(record)
        order = [*SECTIONS, *sorted(set(sections) - {*SECTIONS, OTHER}), OTHER]
        _write_sections(formatter, {name: sections[name] for name in order if name in sections})


def _write_sections(formatter: click.HelpFormatter, sections: dict[str, list[tuple[str, str]]]) -> None:
    """Help sections of (term, text) rows, the texts of every section in one column."""
    width = min(max(len(term) for rows in sections.values() for term, _ in rows), 30)
    for name, rows in sections.items():
        with formatter.section(name):
            formatter.write_dl([(term.ljust(width), text) for term, text in rows])


class Clrays(click.Group):
    """The `clrays` group: its commands listed by section, in the order they are defined,
    and every failure of a command reported as one line."""

    command_class = Command

    def list_commands(self, context: click.Context) -> list[str]:
        return list(self.commands)

    def format_commands(self, context: click.Context, formatter: click.HelpFormatter) -> None:
        commands = [(name, self.commands[name]) for name in self.list_commands(context)
                    if not self.commands[name].hidden]
        sections: dict[str, list[tuple[str, str]]] = {}
        for name, command in commands:  # each help's first sentence whole, wrapped rather than cut at "..."
            sections.setdefault(getattr(command, "section", "Commands"), []).append(
                (name, command.get_short_help_str(limit=1000)))
        _write_sections(formatter, sections)

    def invoke(self, context: click.Context):
        try:
            return super().invoke(context)
        except (click.exceptions.Exit, click.exceptions.Abort, click.ClickException, BrokenPipeError):
            raise  # click reports these itself; a reader that left (`clrays ... | head`) ends quietly
        except Exception as exc:  # noqa: BLE001 - every failure becomes one line
            if isinstance(context.obj, dict) and context.obj.get("debug"):
                traceback.print_exception(exc)
            if isinstance(exc, ClraysError):
                click.echo(f"clrays: error: {exc}", err=True)
            else:
                click.echo(f"clrays: internal error: {type(exc).__name__}: {exc} "
                           f"(run with --debug for the traceback)", err=True)
            context.exit(1)


# --------------------------------------------------------------------------- shared options


def device_option():
    return option("--device", envvar="CLRAYS_DEVICE", show_envvar=True, metavar="P:D|NAME", group=DEVICE,
                  help="OpenCL device: 'P:D' or a name substring (see `clrays info`). Default: the first GPU, "
                       "else PoCL's CPU device (Intel's CPU runtime where PoCL cannot build).")


def _confine(context: click.Context, parameter, value: bool) -> None:
    scene_files.confine_scene_files(value)
    context.call_on_close(lambda: scene_files.confine_scene_files(False))  # for this command alone
    context.call_on_close(end_writes)  # the outputs it declared (allow_writes) with it


def confine_option():
    return option("--confine", is_flag=True, expose_value=False, callback=_confine, group=SCENE,
                  help=f"Refuse any file the scene names (meshes, relief maps, light textures) outside the scene "
                       f"file's folder, symbolic links resolved, and any write outside the outputs' folders and "
                       f"the cache; also {scene_files.CONFINE_ENV}=1. For a service that renders scenes it "
                       f"receives.")


def _method(context: click.Context, parameter, value: str | None) -> str | None:
    return RENAMED_METHODS.get(value, value)  # a former name reads as the method's own


def method_option():
    return option("--method", type=click.Choice((*METHODS, *RENAMED_METHODS)), metavar="METHOD", group=SCENE,
                  callback=_method, help=f"Override render.method: {', '.join(METHODS)} (`moments`, the former "
                                         f"name of volume_moments, reads as it).")


def overrides_option(text: str, metavar: str = "KEY.PATH=VALUE", group: str = SCENE):
    return option("--set", "overrides", multiple=True, metavar=metavar, group=group, help=text)


def camera_option():
    return option("--camera", metavar="NAME|INDEX", group=SCENE,
                  help="A glTF scene's camera, by its name or its node's, or by its index among the cameras the "
                       "scene's nodes place, in node order (0, the default, is the first); the same as "
                       "--set gltf.camera=NAME.")


def with_camera(overrides, camera: str | None) -> tuple[str, ...]:
    """The overrides, and `gltf.camera` when --camera names one (JSON-quoted: any name is one YAML string)."""
    if camera is None:
        return tuple(overrides)
    return tuple(overrides) + (yaml_tree.Override(f"gltf.camera={json.dumps(camera)}", f"--camera {camera}"),)


def aov_option():
    return option("--aov", "aovs", metavar="NAME[,NAME...]", group=OUTPUT,
                  help="Render passes to write too: in_scatter, in_scatter_light<i>, transmittance, surface, depth "
                       "(.exr: layers of the one file; .png, .npy: <stem>.<pass>.<ext> beside it). The same as "
                       "--set render.aovs=[...].")


def with_aovs(overrides, aovs: str | None) -> tuple[str, ...]:
    """The overrides, and `render.aovs` when --aov names passes (each JSON-quoted: one YAML string)."""
    if aovs is None:
        return tuple(overrides)
    names = [name.strip() for name in aovs.split(",")]
    for name in names:
        problem = pass_problem(name, MAX_LIGHTS)
        if problem is not None:
            raise ClraysError(f"--aov: expected {problem}, got {name!r}")
    aovs_set = f"render.aovs=[{', '.join(json.dumps(name) for name in names)}]"
    return tuple(overrides) + (yaml_tree.Override(aovs_set, f"--aov {aovs}"),)


def _exposure(takes_auto: bool):
    """The callback of --exposure: stops in [-64, 64] (NaN slips through a FloatRange: every
    comparison is false), or `auto` where the command takes it; None: the scene's
    render.exposure."""

    def parse(context: click.Context, parameter, value: str | None) -> float | str | None:
        if value is None:
            return None
        exposure = parse_exposure(value)
        if exposure is None or (exposure == AUTO and not takes_auto):
            click.echo(f"clrays: error: --exposure: expected a finite number of stops in "
                       f"[-{EV_LIMIT:g}, {EV_LIMIT:g}]{' or auto' if takes_auto else ''}, got {value}", err=True)
            context.exit(2)
        return exposure

    return parse


def exposure_option(applies_to: str, takes_auto: bool = True):
    """--exposure; without `takes_auto`, stops alone (default 0), for an output compared
    with another (`clrays compare`)."""
    if not takes_auto:
        return option("--exposure", default="0", show_default=True, metavar="EV", callback=_exposure(False),
                      group=OUTPUT,
                      help=f"{applies_to}: scale radiance by 2^EV before sRGB encoding.")
    return option("--exposure", metavar="EV|auto", callback=_exposure(True), group=OUTPUT,
                  help=f"{applies_to}: scale radiance by 2^EV before sRGB encoding; `auto` maps the 99th "
                       f"percentile of the lit pixels' brightest channel to near white and prints the EV it chose. "
                       f"Default: the scene's render.exposure (0).")


def check_exposure_applies(exposure: float | str | None, outputs: list[str],
                           exposed: dict[str, str] = EXPOSED_IMAGES) -> None:
    """Refuse an --exposure (a number or `auto`) that would change none of the outputs:
    .exr and .npy keep linear radiance as rendered. `exposed`: the suffixes (and format
    names) of what the command writes that --exposure changes."""
    if exposure not in (None, 0.0) and not any(Path(str(out)).suffix.lower() in exposed for out in outputs):
        names = list(exposed.values())
        formats = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"
        shown = exposure if exposure == AUTO else f"{exposure:g}"
        raise OutputError(f"--exposure {shown}: applies only to {formats} output; "
                          f"{', '.join(str(out) for out in outputs)} keeps linear radiance (drop --exposure)")


def _echo_err(line: str) -> None:
    click.echo(line, err=True)


def verbose_option():
    return option("--verbose", "-v", is_flag=True, group=RUN, callback=_set_verbose,
                  help="Say which scene keys the chosen method does not read, and what a glTF file carries that "
                       "clrays does not render.")


def _set_verbose(_context, _parameter, verbose: bool) -> bool:
    """--verbose: a glTF import lists what it does not render (clrays.scene.gltf.verbose_notice)."""
    gltf_files.verbose_notice = (lambda line: click.echo(line, err=True)) if verbose else None
    return verbose


def _notice_unread_keys(scene, method: str | None) -> None:
    """One line on stderr for each render key set away from its default that `method`
    ignores (the field table's `read_by`), e.g. render.steps with minmax."""
    method = method or scene.render.method
    for text in unread_render_keys(scene.render, method):
        click.echo(f"clrays: notice: {text}; method {method} ignores it", err=True)


def _estimate_exact(scene, method: str | None, progress) -> object:
    """`exact` runs on the host and can take minutes: say how long up front, and when no
    bar is shown (stderr not a terminal) report progress as lines; `raymarch` at many
    steps can too, and reports lines once it has run a while (stages/raymarch.py). Returns
    the progress argument for the render."""
    if (method or scene.render.method) == "raymarch":
        return progress or (lambda line: click.echo(f"clrays: {line}", err=True))
    if (method or scene.render.method) != "exact":
        return progress
    seconds = estimate_seconds(scene)
    if seconds >= EXACT_ESTIMATE_MIN_S:
        image = scene.image
        click.echo(f"clrays: exact on {image.width}×{image.height} at {image.spp} spp, "
                   f"{scene.geometry.count} triangles, {len(scene.lights)} light(s): about "
                   f"{_duration(seconds)} on the host (estimate)", err=True)
    return progress or (lambda line: click.echo(f"clrays: {line}", err=True))


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def overwrite_option(text: str):
    return option("--overwrite", is_flag=True, group=OUTPUT, help=text)


def reuse_option(between: str):
    return option("--reuse/--no-reuse", default=True, show_default=True, group=RUN,
                  help=f"Keep stage results between {between}; re-run a stage only when its inputs changed.")


def _progress_default(context: click.Context, parameter, value: bool | None) -> bool:
    """Neither --progress nor --no-progress: a bar when stderr is a terminal."""
    return sys.stderr.isatty() if value is None else value


def tune_option():
    """--tune: consent to search a scene's render.target_error settings where none are kept."""
    return option("--tune", "tune_now", is_flag=True, group=RUN,
                  help=f"Where the scene sets render.target_error and no tuning for it is kept: search now "
                       f"(cost stated first; refused past {TUNE_BUDGET_S:g} s: then run `clrays tune` first).")


def progress_option(text: str = "Progress bar (default: on a terminal)."):
    return option("--progress/--no-progress", default=None, callback=_progress_default, group=RUN, help=text)


def cluster_options(command):
    """--scheduler / --workers: run the frames or points on dask.distributed workers
    (clrays.runs.distributed); without them the run stays in this process and dask is
    not imported."""
    command = option("--workers", type=click.IntRange(1), metavar="N", group=RUN,
                     help="Render on a local dask cluster of N worker processes, one OpenCL session each (at most "
                          "one per CPU core and ~400 MiB of free memory).")(command)
    return option("--scheduler", metavar="ADDRESS", group=RUN,
                  help="Render on the workers of a running dask scheduler (tcp://HOST:PORT, 5 s to answer); "
                       "each worker uses the device its own CLRAYS_DEVICE names. Output paths must be shared with "
                       "them.")(command)


def _executor(scheduler: str | None, workers: int | None, device: str | None):
    """The dask executor that --scheduler / --workers ask for (a context manager), else none."""
    if scheduler is None and workers is None:
        return contextlib.nullcontext(None)
    from .runs.distributed import DaskExecutor  # imports dask only when asked for

    return DaskExecutor(scheduler, workers, device)


@contextlib.contextmanager
def _stopped_by_signal(context: click.Context, message: Callable[[], str]):
    """Ctrl-C or SIGTERM (`kill`), raised as KeyboardInterrupt so that a half-written file's
    temporary is removed on the way out, ends the run with one line, exit code 130."""
    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    except KeyboardInterrupt:
        click.echo(f"clrays: interrupted{message()}", err=True)
        context.exit(130)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _interruptible(context: click.Context, what: str):
    """A run that does not resume (`render`): the line says what was not written."""
    return _stopped_by_signal(context, lambda: f"; {what}")


def _resumable(context: click.Context, done: Callable[[], str]):
    """A run that resumes: the line says what was `done` and how to resume."""
    return _stopped_by_signal(context, lambda: f" after {done()}; run the same command again to resume")


# --------------------------------------------------------------------------- the commands


@click.group(cls=Clrays, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.option("--debug", is_flag=True, expose_value=False, callback=_set_debug,
              help="Show the traceback of an error (also accepted after the command).")
@click.version_option(package_name="clrays")
@click.pass_context
def main(context: click.Context) -> None:
    """Render volumetric shadows (light shafts in fog) with OpenCL.

    \b
    Examples:
      clrays render scenes/demo.yaml -o out/demo.png
      clrays sequence scenes/orbit.yaml -o 'out/orbit/frame_{:04d}.png'
      clrays watch scenes/demo.yaml -o out/demo.png
      clrays sweep scenes/demo.yaml --set medium.sigma_s=0.02,0.05 -o out/sweep
      clrays tune scenes/grate.yaml --target-error 0.5 -o out/grate_tuned.yaml
      clrays bench scenes/demo.yaml -r 640x360
      clrays info
    """
    # An override's messages name the option that gave it (the Python API's are "override")
    yaml_tree.override_origin = "--set"
    context.call_on_close(lambda: setattr(yaml_tree, "override_origin", "override"))


@main.command(section="Render", epilog="""
\b
Examples:
  clrays render scenes/demo.yaml -o out/demo.png
  clrays render scenes/demo.yaml -o out/demo.exr --method raymarch --set render.steps=1024
  clrays render scenes/demo.yaml -o out/demo.npy --set medium.sigma_s=0.1 --stats
  clrays render scenes/orbit.yaml -o out/orbit_30.png --frame 30
  clrays render scenes/colonnade.glb -o out/c.png --set medium.sigma_s=0.06 --camera view
""")
@click.argument("scene", type=click.Path(path_type=Path))
@confine_option()
@method_option()
@overrides_option("Override a scene field (repeatable), e.g. --set render.steps=1024.")
@camera_option()
@option("--frame", type=int, metavar="N", group=SCENE,
        help="Render frame N of the scene's animation (see `clrays sequence`).")
@option("-o", "--output", required=True, type=click.Path(path_type=Path), group=OUTPUT,
        help="Output image: .png (8-bit sRGB), .exr (float RGB) or .npy (float32 linear H×W×3); its folder is "
             "created.")
@aov_option()
@exposure_option("PNG only")
@option("--stats", is_flag=True, group=RUN, help="Print per-stage device times and device memory.")
@tune_option()
@verbose_option()
@progress_option("Progress bar for the slow methods, exact and raymarch (default: on a terminal; off one, a "
                 "line every 10 % of a long frame).")
@device_option()
@click.pass_context
def render(context, scene: Path, method, overrides, camera, frame, output: Path, aovs, exposure, stats, tune_now,
           verbose, progress, device) -> None:
    """Render SCENE (a YAML file, or glTF: .glb, .gltf) to an image."""
    allow_writes(output.parent)
    check_output_path(output, folder_exists=False)
    check_exposure_applies(exposure, [output])
    with host_steps.timed("load"):
        loaded = load_scene(scene, with_aovs(with_camera(overrides, camera), aovs))
    check_output_path(make_output_folder(output))  # created, as every command creates its output's folder
    for path in pass_paths(output, loaded.render.aovs):
        check_output_path(path)
    if frame is not None:
        parse_frames(str(frame), scene_frames(loaded), "--frame")
    with _interruptible(context, f"{output} was not written"):
        loaded, tuned = _tuned(loaded, method, device, progress, Consent(tune_now), scene)
        if frame is not None and loaded.animation is not None:
            loaded = loaded.animation.scene_at(loaded, frame)
        if stats or verbose:
            _notice_unread_keys(loaded, method)
        progress = _estimate_exact(loaded, method, progress)
        result = Renderer(device).render(loaded, method, progress=progress)
        stops = frame_exposure(exposure_setting(exposure, loaded), result.image, output, _echo_err)
        write_render(output, result, loaded, stops, str(scene))
    if stats:
        _print_stats(result)
        if tuned is not None:
            click.echo(f"  {tuned.line()}")


def _tuned(scene, method: str | None, device: str | None, progress: bool, consent: Consent, path: Path,
           below: Path | None = None):
    """(scene, Tuned or None): with the settings its `render.target_error` asks for
    (clrays.runs.tune.tuned_settings): kept in `below`/.references (where given) or the
    cache, else searched with `consent` (`--tune`) and kept there; a line per setting tried
    when no bar shows."""
    if scene.render.target_error is None:
        return scene, None
    folders = [below / REFERENCES] if below is not None else []
    return tuned_scene(scene, method, folders=[*folders, cache_root()], consent=consent, renderer=Renderer(device),
                       progress=progress, log=lambda line: click.echo(line, err=True), how_to_tune=_how_to_tune(path),
                       below=below)


def _how_to_tune(path: Path) -> str:
    """The way to run a search that a render may not: `clrays tune`, whose kept settings it reads."""
    return (f"run `clrays tune {path} -o TUNED.yaml` with this run's --set, --camera and --method first (no time "
            f"limit; this command then reads the settings it keeps)")


def _stage_statuses(result) -> dict[str, str]:
    """Stage label (as in the timings) → computed / reused / skipped; raster has two parts."""
    names = {"camera": "camera", "shadow": "shadow maps"}
    parts: dict[str, list[tuple[str, str]]] = {}
    for stage, value in result.stage_status.items():
        label, _, part = stage.partition(".")
        parts.setdefault(label, []).append((part, value))
    return {label: ", ".join(f"{names.get(part, part)} {value}" if part else value for part, value in values)
            for label, values in parts.items()}


def _print_stats(result) -> None:
    click.echo(f"method: {result.method}")
    status = _stage_statuses(result)
    width = max([10, *(len(label) for label in (*result.stage_ms, *status))])  # one column for every label
    for label, ms in result.stage_ms.items():
        where = "host" if label in result.host_stages else "device"
        click.echo(f"  {label:<{width}} {ms:9.2f} ms {f'({where})':<8}  {status.get(label, '')}".rstrip())
    for label, text in status.items():
        if label not in result.stage_ms:
            click.echo(f"  {label:<{width}} {'-':>9}              {text}")
    if result.stage_ms:
        click.echo(f"  {'total':<{width}} {sum(result.stage_ms.values()):9.2f} ms (device + host stages)")
    click.echo(f"  {'wall':<{width}} {result.wall_ms:9.2f} ms")
    if result.render is not None:
        render = result.render
        textures = ", ".join(f"{slices}×{texels}" for slices, texels in result.textures) or "none"
        floor = render.shadow_map_floor or render.shadow_map
        coarser = f" ({floor}² in views without thin solids)" if floor < render.shadow_map else ""
        click.echo(f"  sizes      shadow map {render.shadow_map}²{coarser}, {render.slices} slices × "
                   f"{render.gamma_samples} γ texels; rectified (slices×texels per light): {textures}")
    if result.samples is not None:
        counts = result.samples
        click.echo(f"  samples    {counts.computed} line samples computed; camera samples: {counts.interpolated} "
                   f"interpolated, {counts.fixed_up} fixed up (walked their own rays)")
    if result.shadow_rays is not None:
        click.echo(f"  shadows    {result.shadow_rays} shadow rays (surface samples × lights the maps left undecided)")
    if result.skipped_lights is not None:
        click.echo(f"  lights     {result.skipped_lights.describe()}")
    click.echo(f"  device memory {result.device_bytes / 2**20:.1f} MiB")
    steps = host_steps.taken()
    if steps:
        click.echo("  host steps " + ", ".join(f"{step} {ms:.1f} ms" for step, ms in steps.items())
                   + (" (load holds the steps of reading the scene)" if "load" in steps else ""))


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


@main.command(section="Render", epilog="""
\b
Examples:
  clrays sequence scenes/orbit.yaml -o out/orbit/frame_{:04d}.png
  clrays sequence scenes/orbit.yaml -o out/orbit/frame_{:04d}.png --frames 0:23 --video out/orbit.gif
  clrays sequence scenes/orbit.yaml -o out/orbit/f_{:04d}.npy --set image.width=320 --stats
  clrays sequence scenes/orbit.yaml -o out/orbit/frame_{:04d}.png --video out/orbit.mp4 --crf 23
  clrays sequence scenes/orbit.yaml -o out/orbit/frame_{:04d}.png --workers 2

\b
Frames are written atomically: re-running the same command skips the frames already
there, so an interrupted run resumes where it stopped (--overwrite renders all again).
""")
@click.argument("scene", type=click.Path(path_type=Path))
@confine_option()
@option("--frames", metavar="A:B", group=SCENE,
        help="Frames A to B, inclusive (also A:, :B or N). Default: the animation's frames.")
@method_option()
@overrides_option("Override a scene field (repeatable), e.g. --set animation.fps=12.")
@camera_option()
@option("-o", "--output", "pattern", required=True, metavar="PATTERN", group=OUTPUT,
        help="Frame files, with one {} field for the frame number in an integer format: "
             "frames/frame_{:04d}.png (.png, .exr or .npy; the folder is created, and no other run may write "
             "into it meanwhile).")
@option("--video", type=click.Path(dir_okay=False, path_type=Path), group=OUTPUT,
        help="Also write the frames as a video: .mp4 (H.264), .gif or .webp (at the animation's fps).")
@option("--crf", type=click.IntRange(0, 51), default=None, metavar="N", group=OUTPUT,
        help=f"MP4 quality: H.264 constant rate factor, lower is better (default {DEFAULT_CRF}).")
@option("--video-option", "video_options", multiple=True, metavar="KEY=VALUE", group=OUTPUT,
        help=f"MP4: an encoding option for ffmpeg (repeatable), e.g. --video-option preset=slow or "
             f"pix_fmt=yuv444p; KEY is one of {', '.join(VIDEO_OPTIONS)}.")
@aov_option()
@exposure_option("PNG and video, one EV for every frame")
@overwrite_option("Render every frame, also those already written.")
@reuse_option("frames")
@option("--stats", is_flag=True, group=RUN, help="Print each frame's time and reused stages, then a summary.")
@tune_option()
@verbose_option()
@progress_option("Progress bar (default: on a terminal; off one, a line per frame rendered).")
@cluster_options
@device_option()
@click.pass_context
def sequence(context, scene, frames, method, overrides, camera, pattern, video, crf, video_options, aovs, exposure,
             overwrite, reuse, stats, tune_now, verbose, progress, scheduler, workers, device) -> None:
    """Render the frames of SCENE's animation to numbered images."""
    done = []
    with _resumable(context, lambda: counted(len(done), "new frame")):
        check_pattern(pattern)
        allow_writes(lock_folder(pattern), *([video.parent] if video is not None else []))
        if video is not None:
            check_video_path(video)
            encoder_options = video_encoder_options(video, crf, video_options)
        check_exposure_applies(exposure, [pattern] + ([video] if video is not None else []),
                               EXPOSED_IMAGES | EXPOSED_VIDEO)
        overrides = with_aovs(with_camera(overrides, camera), aovs)
        loaded = load_scene(scene, overrides)
        exposure = exposure_setting(exposure, loaded)
        chosen = parse_frames(frames, scene_frames(loaded))
        # Kept beside the frames: their digests hold the tuned settings, so a run resumed from
        # anywhere must find the same ones, or it would take every frame for another scene's.
        loaded, tuned = _tuned(loaded, method, device, progress, Consent(tune_now), scene, lock_folder(str(pattern)))
        if stats and tuned is not None:
            click.echo(tuned.line())
        if stats or verbose:
            _notice_unread_keys(loaded, method)

        seen = []

        def on_frame(frame, path, result):
            seen.append(frame)
            if result is not None:
                done.append(result)
                if stats:
                    click.echo(_frame_line(f"frame {frame}", result))
                elif not progress:  # no bar (stderr is not a terminal): a line per frame rendered
                    click.echo(f"clrays: frame {frame}: {result.wall_ms:.0f} ms ({len(seen)} of {len(chosen)})",
                               err=True)

        with _executor(scheduler, workers, device) as executor:
            report = render_sequence(loaded, pattern, chosen, renderer=Renderer(device, reuse=reuse), method=method,
                                     exposure=exposure, overwrite=overwrite, progress=progress, on_frame=on_frame,
                                     executor=executor, echo=_echo_err)
        click.echo(report.summary())
        if stats and done:
            click.echo("stages over the rendered frames:\n" + _stage_counts(done))
        if video is not None:
            fps = loaded.animation.fps if loaded.animation is not None else 24.0
            click.echo(f"wrote {write_video(report.paths, video, fps, exposure, encoder_options, _echo_err)}")


@main.command(section="Render", epilog="""
\b
Examples:
  clrays watch scenes/demo.yaml -o out/demo.png
  clrays watch scenes/colonnade.yaml -o out/c.exr --also scenes/colonnade.glb --aov in_scatter
  clrays watch scenes/demo.yaml -o out/d.png --set image.width=320 --set image.height=180

\b
Each save renders again in the same session: stages whose inputs the edit left alone are
reused. One line per render (its time, the stages reused); an edit that fails prints its
one-line error and the last image stays. Ctrl-C ends it.
""")
@click.argument("scene", type=click.Path(path_type=Path))
@confine_option()
@option("-o", "--output", required=True, type=click.Path(path_type=Path), group=OUTPUT,
        help="Output image: .png, .exr or .npy, rewritten atomically after each save.")
@option("--also", multiple=True, type=click.Path(path_type=Path), metavar="FILE", group=SCENE,
        help="Another file whose saves render again too (repeatable): a mesh, texture or glTF file the scene reads.")
@method_option()
@overrides_option("Override a scene field (repeatable), e.g. --set image.width=320.")
@camera_option()
@aov_option()
@exposure_option("PNG only")
@option("--max-renders", type=click.IntRange(1), hidden=True, group=RUN, help="Stop after N renders (tests).")
@device_option()
@click.pass_context
def watch(context, scene: Path, output: Path, also, method, overrides, camera, aovs, exposure, max_renders,
          device) -> None:
    """Render SCENE to an image again on every save of it (or of an --also file)."""
    from .runs.watch import watch as watch_files

    allow_writes(output.parent)
    check_output_path(output, folder_exists=False)
    check_exposure_applies(exposure, [output])
    check_output_path(make_output_folder(output))  # created, as every command creates its output's folder
    overrides = with_aovs(with_camera(overrides, camera), aovs)
    renderer = Renderer(device)
    if method != "exact":
        renderer.device  # a device that cannot start fails here, once, not on every save
    counts = [0, 0]

    def echo(line: str) -> None:
        failed = line.startswith("clrays: error:")
        if failed or line.startswith("render "):  # not the exposure's lines
            counts[failed] += 1
        click.echo(line, err=line.startswith("clrays:"))

    click.echo(f"watching {', '.join(map(str, (scene, *also)))}; Ctrl-C to stop")
    with _stopped_by_signal(context, lambda: f": watch stopped after {counts[0]} render(s), {counts[1]} error(s)"):
        watch_files(scene, output, overrides=overrides, method=method, exposure=exposure, renderer=renderer,
                    also=also, max_renders=max_renders, echo=echo)


@main.command(section="Study", short_help="Render SCENE at each combination of --set values, tabulated.",
              epilog="""
\b
Examples:
  clrays sweep scenes/demo.yaml --set medium.sigma_s=0.02,0.05,0.1 --set render.slices=256,1024 -o out/sweep
  clrays sweep scenes/demo.yaml --set render.slices=128,256,512,1024 --reference raymarch:2048 -o out/slices
  clrays sweep scenes/demo.yaml --set 'lights.0.intensity=[100,100,100],[300,300,300]' -o out/power
  clrays sweep scenes/demo.yaml --set render.slices=128,256,512 --scheduler tcp://head:8786 -o /shared/sweep

\b
Writes one image per point (000.png, 001.png, ...), results.csv (the parameters, wall and
per-stage times, reused stages and, with --reference, the error against it in percent) and
contact_sheet.png. Re-running the same command keeps the points already done. wall_ms is
the render's wall time, less the kernel builds during it (build_ms).
""")
@click.argument("scene", type=click.Path(path_type=Path))
@confine_option()
@overrides_option("A swept key with comma-separated values, or a fixed override with one (repeatable; each key "
                  f"once); the points are the cartesian product of the swept keys, at most {MAX_SWEEP_POINTS}.",
                  metavar="KEY.PATH=V1,V2,...", group=SWEEP)
@camera_option()
@option("--reference", metavar="exact|raymarch:N", group=SWEEP,
        help="Measure each point's error against this reference (kept in OUTPUT/.references).")
@method_option()
@option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path), group=OUTPUT,
        help="Folder for the images, results.csv and contact_sheet.png (created).")
@option("--format", "image_format", type=click.Choice(["png", "exr", "npy"]), default="png", show_default=True,
        group=OUTPUT, help="Image format of the points.")
@exposure_option("PNG and contact sheet, `auto` per point")
@overwrite_option("Render every point, also those done by an earlier run.")
@reuse_option("points")
@tune_option()
@progress_option("Progress bar (default: on a terminal; off one, a line per point rendered).")
@cluster_options
@device_option()
@click.pass_context
def sweep(context, scene, overrides, camera, reference, method, out_dir, image_format, exposure, overwrite, reuse,
          tune_now, progress, scheduler, workers, device) -> None:
    """Render SCENE at every combination of the --set values and tabulate the results."""
    done = []
    with _resumable(context, lambda: counted(len(done), "point")):
        allow_writes(out_dir)
        _check_scene_file(scene)
        overrides = with_camera(overrides, camera)
        axes, _ = axes_from(list(overrides))
        parse_reference(reference)
        def on_point(point, row):
            done.append(point)
            if not progress:  # no bar (stderr is not a terminal): a line per point, with its host work
                host = ", ".join(f"{label} {float(row[column]):.0f} ms" for column, label in
                                 (("reference_ms", "reference"), ("edges_ms", "depth edges"), ("warmup_ms", "warm-up"))
                                 if float(row.get(column) or 0) > 0)
                swept = f": {point.label}" if point.label else ""  # fixed values alone sweep nothing
                click.echo(f"clrays: point {point.index}{swept}: {float(row['wall_ms']):.0f} ms"
                           + (f" (+ {host})" if host else ""), err=True)

        with _executor(scheduler, workers, device) as executor:
            report = run_sweep(scene, list(overrides), out_dir, method=method, reference=reference,
                               renderer=Renderer(device, reuse=reuse), exposure=exposure, image_format=image_format,
                               overwrite=overwrite, progress=progress, on_point=on_point, executor=executor,
                               tune=Consent(tune_now), how_to_tune=_how_to_tune(scene))
        click.echo(format_table(report.rows, axes), nl=False)
        click.echo(report.summary())


def _target_percent(context, parameter, value: float | None) -> float | None:
    """--target-error in (0, 100) percent; NaN slips through a FloatRange."""
    if value is not None and not (math.isfinite(value) and 0 < value < 100):
        raise click.BadParameter(f"expected a percentage between 0 and 100 like 0.5, got {value}")
    return value


@main.command(section="Study", short_help="Find the cheapest render settings within an error against exact.",
              epilog="""
\b
Examples:
  clrays tune scenes/lattice.yaml --target-error 1 -o out/lattice_tuned.yaml
  clrays tune scenes/demo.yaml --target-error 0.2 --set image.width=320 --set image.height=180 -o out/demo.yaml

\b
The error is as `clrays bench` measures it: relative RMSE of luminance against `exact` on
a fixed subset of pixels, depth edges left out (`exact` is computed once and kept in
--cache). From the sizes the image derives, the search grows the setting that buys the
most error per millisecond while over the target, then shrinks settings while the target
holds, aiming at 80 % of the target; the settings within it are then checked, cheapest
first, on pixels (and an animation's frames) the search did not measure. An animated scene is measured on its
first, middle and last frames (the largest error counts). Only the render keys it sets
change in the written file. A scene may instead carry render.target_error: `render`,
`sequence` and `sweep` then take the settings this command keeps for it (one search, one
answer), or search with --tune where none are kept.
""")
@click.argument("scene", type=click.Path(path_type=Path))
@option("--target-error", "target", type=float, metavar="PCT", callback=_target_percent, group=SCENE,
        help="Relative RMSE against exact, in percent (default: the scene's render.target_error).")
@confine_option()
@method_option()
@overrides_option("Override a scene field (repeatable), e.g. --set image.width=320.")
@camera_option()
@option("--pixels", type=click.IntRange(16), default=4000, show_default=True, group=RUN,
        help="Pixels (fixed random subset) on which the error against exact is measured.")
@option("--most-settings", type=click.IntRange(1, 1000), default=60, show_default=True, metavar="N", group=RUN,
        help="Stop the search after measuring N settings (each a few frames of each measured frame).")
@option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path), group=OUTPUT,
        help="The tuned scene: SCENE's YAML with the tuned settings in its render mapping.")
@option("--cache", type=click.Path(file_okay=False, path_type=Path), default=None, group=OUTPUT,
        help="Where exact references and tuned settings are kept (default: clrays' cache: $CLRAYS_CACHE, else "
             "~/.cache/clrays, where render.target_error looks for them).")
@progress_option()
@device_option()
@click.pass_context
def tune(context, scene: Path, target, method, overrides, camera, pixels, most_settings, output: Path, cache,
         progress, device) -> None:
    """Find the cheapest render settings of SCENE whose error against exact is at most PCT."""
    from .runs import tune as tuning

    if output.suffix.lower() not in (".yaml", ".yml"):
        raise OutputError(f"{output}: the tuned scene is YAML: expected a .yaml or .yml output, got "
                          f"{output.suffix or '(no extension)'!r}")
    cache = cache or cache_root()
    allow_writes(output.parent, cache)
    _check_scene_file(scene)
    check_replaceable(check_folder(output))  # before the search, not after it
    overrides = with_camera(overrides, camera)
    loaded = load_scene(scene, overrides)
    asked_by = "--target-error"
    if target is None:
        if loaded.render.target_error is None:
            raise ClraysError(f"{scene}: no target: give --target-error PCT or set render.target_error")
        target, asked_by = loaded.render.target_error, "render.target_error"
    with _interruptible(context, f"{output} was not written"):
        # The one search and cache of render.target_error: a scene tuned here renders with these settings.
        tuned, result = tuning.tuned_settings(
            loaded, target / 100, [cache], tuning.Consent(True, budget_s=None), method,
            Renderer(device), progress, lambda line: click.echo(line, err=True), pixels, most_settings,
            asked_by=asked_by)
    settings = {**({"method": method} if method else {}), **tuned.settings}
    tuning.write_tuned_yaml(scene, output, settings, list(overrides))
    click.echo(f"{tuning.settings_text(tuned.settings)}")
    held_out = "" if tuned.held_out is None else f", {100 * tuned.held_out:.3f} % on held-out pixels and frames"
    click.echo(f"error against exact {100 * tuned.rmse:.3f} %{held_out} (target {target:g} %), "
               f"{tuned.frame_ms:.0f} ms a frame")
    if result is None:
        click.echo("kept from an earlier search of this scene and target (clrays tune or render.target_error)")
    else:
        click.echo(f"{tuning.default_trial_line(result)}; {len(result.trials)} settings tried in "
                   f"{result.seconds:.0f} s")
    click.echo(f"wrote {output}")


def _check_scene_file(path: Path) -> None:
    """Before a long run: SCENE exists and is a file (the loader checks the rest, in one line)."""
    if not path.exists():
        raise ClraysError(f"{path}: no such scene file")
    if not path.is_file():
        raise ClraysError(f"{path}: not a scene file ({'a directory' if path.is_dir() else 'not a regular file'})")


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


def _targets(context, parameter, text: str) -> tuple[float, ...]:
    """Click callback: "5,1,0.5" (percent) → (0.05, 0.01, 0.005), usage error otherwise."""
    try:
        values = tuple(sorted({float(part) / 100 for part in text.split(",")}, reverse=True))
        if not values or not all(0 < value < 1 for value in values):
            raise ValueError
    except ValueError:
        raise click.BadParameter(f"expected percentages between 0 and 100 like 5,1,0.5, got {text!r}") from None
    return values


@main.command(section="Study", epilog="""
\b
Examples:
  clrays bench                                  # every bench scene at 640x360
  clrays bench scenes/demo.yaml -r 1280x720 -r 640x360 -o bench/out
  clrays bench --repeats 3 --pixels 500         # a quicker, noisier run
  clrays bench scenes/demo.yaml -r 64x36 --quick  # smoke run: does it all work?
  clrays bench scenes/bunny.yaml --targets 1,0.5,0.1  # equal error down to 0.1 %
""")
@click.argument("scenes", nargs=-1, type=click.Path(path_type=Path))
@confine_option()
@option("-r", "--resolution", "resolutions", multiple=True, default=["640x360"], show_default=True, metavar="WxH",
        callback=_resolutions, group=BENCH, help="WIDTHxHEIGHT to render at (repeatable).")
@option("--repeats", type=click.IntRange(1, 100), default=5, show_default=True, group=BENCH,
        help="Timed frames per point (after one warm-up); the median is reported.")
@option("--pixels", type=click.IntRange(16), default=4000, show_default=True, group=BENCH,
        help="Pixels (fixed random subset) on which the error against exact is measured.")
@option("--targets", default="5,1,0.5", show_default=True, metavar="PERCENTS", callback=_targets, group=BENCH,
        help="Relative RMSEs (%, comma-separated) at which the speedup is read; raymarch climbs to the lowest.")
@option("--quick", is_flag=True, group=BENCH, help="A handful of points per scene: a smoke run, not results.")
@option("--volume-only", "volume", is_flag=True, group=BENCH,
        help="Black surfaces: measure the in-scattering's error alone (a smaller sweep).")
@option("-o", "--output", "out", type=click.Path(file_okay=False, path_type=Path), default=Path("bench/out"),
        show_default=True, group=OUTPUT, help="Folder for bench.csv, bench.png, summary.md, machine.json.")
@option("--out", "out_alias", type=click.Path(file_okay=False, path_type=Path), hidden=True, group=OUTPUT,
        help="The former name of --output.")
@option("--cache", type=click.Path(file_okay=False, path_type=Path), default=None, group=OUTPUT,
        help="Where exact references are cached (default: clrays' cache: $CLRAYS_CACHE, else ~/.cache/clrays).")
@progress_option("Progress bar while an exact reference is computed (default: on a terminal).")
@device_option()
def bench(scenes, resolutions, repeats, pixels, targets, quick, volume, out, out_alias, cache, progress,
          device) -> None:
    """Time every method and setting against its error versus `exact`.

    raymarch's steps are searched (doubled from 8 until the lowest target's relative RMSE,
    then refined at each target's crossing); minmax runs at its defaults and at cheaper
    sizes. Writes a CSV of every point, a log-log plot of error against time with the
    Pareto front, and the headline table (speedup of minmax over raymarch at each target,
    by default 5, 1 and 0.5 % error).
    """
    if out_alias is not None:
        if click.get_current_context().get_parameter_source("out") is not ParameterSource.DEFAULT:
            raise click.UsageError("give -o/--output or --out (its former name), not both")
        out = out_alias
    cache = cache or cache_root()
    allow_writes(out, cache)
    for folder in (out, cache):  # fail before the sweep, not after it
        make_folder(folder)
    paths = [str(path) for path in scenes] or list(bench_run.DEFAULT_SCENES)
    for path in paths:
        _check_scene_file(Path(path))
    points = bench_run.run(paths, resolutions, repeats=repeats, pixels=pixels, cache=cache, device=device,
                           progress=progress, log=lambda line: click.echo(line, err=True), quick=quick, volume=volume,
                           targets=targets)
    bench_run.save(points, out, device=device, targets=targets, extra={
        "repeats": repeats, "pixels": pixels, "volume_only": volume, "targets": list(targets),
        "resolutions": [f"{width}x{height}" for width, height in resolutions], "scenes": paths})
    click.echo(bench_run.markdown_summary(points, targets))
    click.echo(f"wrote {out}/bench.csv, bench.png, summary.md, machine.json")


@main.command("relief-to-mesh", section="Tools", epilog="""
\b
Examples:
  clrays relief-to-mesh scenes/lattice.yaml -o out/lattice.ply
  clrays relief-to-mesh scenes/lattice.yaml -o out/lattice.obj --object 2
""")
@click.argument("scene", type=click.Path(path_type=Path))
@confine_option()
@option("--object", "index", type=int, default=None, metavar="I", group=SCENE,
        help="The relief to convert: objects.I of the scene (default: the first relief).")
@overrides_option("Override a scene field (repeatable), e.g. --set objects.0.height=0.1.")
@option("-o", "--output", required=True, type=click.Path(path_type=Path), group=OUTPUT,
        help="Mesh file: .ply, .obj or .stl, in world space (the object's transform applied); its folder is "
             "created.")
def relief_to_mesh(scene: Path, index, overrides, output: Path) -> None:
    """Write a relief object of SCENE as its height-field triangles (two per texel cell)."""
    from .runs.relief_mesh import relief_to_mesh as convert

    allow_writes(output.parent)
    check_name_length(output)
    index, count = convert(scene, check_folder(make_output_folder(output)), index, overrides)
    click.echo(f"objects.{index}: {count} triangles -> {output}")


def _filter_names(context, parameter, text: str) -> tuple[str, ...]:
    """Click callback: comma-separated shadow filter types, usage error otherwise."""
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    unknown = [name for name in names if name not in SHADOW_FILTERS]
    if unknown or not names:
        raise click.BadParameter(f"expected filter types out of {', '.join(SHADOW_FILTERS)}, got {text!r}")
    return names


@main.command(section="Study", epilog="""
\b
Examples:
  clrays compare scenes/bunny.yaml -o out/compare --radius 2
  clrays compare scenes/demo.yaml -o out/compare --set image.width=320 --set image.height=180 --exact-pixels 2000
  clrays compare scenes/sun.yaml -o out/sun --filters vsm,msm_hamburger --radius 4

\b
Writes <filter>.png, <filter>_diff.png (red: brighter than the reference, a light leak;
blue: darker), reference_pcf.png, compare.csv and compare.md.
""")
@click.argument("scene", type=click.Path(path_type=Path))
@confine_option()
@overrides_option("Override a scene field (repeatable), e.g. --set image.width=320.")
@camera_option()
@option("--radius", type=click.IntRange(0, 16), default=2, show_default=True, group=SCENE,
        help="Filter radius in texels, for every filter and the PCF reference.")
@option("--filters", default=",".join(SHADOW_FILTERS), show_default=True, callback=_filter_names, group=SCENE,
        help="Comma-separated render.shadow_filter types to compare.")
@option("--repeats", type=click.IntRange(1, 100), default=3, show_default=True, group=RUN,
        help="Timed frames per filter (after one warm-up); the median is reported.")
@option("--exact-pixels", type=click.IntRange(0), default=0, show_default=True, group=RUN,
        help="Also measure each filter against `exact` on this many pixels (0: not).")
@option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path), group=OUTPUT,
        help="Folder for the images, heat maps and tables (created).")
@exposure_option("PNG images", takes_auto=False)
@device_option()
def compare(scene, overrides, camera, radius, filters, repeats, exact_pixels, out_dir, exposure, device) -> None:
    """Compare the surface shadow filters of SCENE with PCF at the same radius.

    For each filter: its image, a heat map of its difference from the reference, and its
    relative RMSE, p99, light-leak pixel count and time (docs/design.md §9).
    """
    from .runs.compare import compare as run_compare, markdown_table

    allow_writes(out_dir)
    _check_scene_file(scene)
    loaded = load_scene(scene, with_camera(overrides, camera))
    rows = run_compare(loaded, out_dir, radius=radius, filters=filters, repeats=repeats, exact_pixels=exact_pixels,
                       renderer=Renderer(device, reuse=False), log=lambda line: click.echo(line, err=True),
                       exposure=exposure)
    click.echo(markdown_table(rows), nl=False)
    click.echo(f"wrote {out_dir}/compare.md, compare.csv and the images")


@main.command(section="Tools", epilog="""
\b
Examples:
  clrays info
  CLRAYS_DEVICE=pocl clrays info      # which device that spec picks
""")
@device_option()
@click.pass_context
def info(context, device: str | None) -> None:
    """List OpenCL platforms and devices, and the one clrays would use."""
    devices = list_devices()
    try:
        chosen = select_device(device)
    except DeviceError:
        if device is None or not devices:
            raise
        chosen = None  # list them anyway: they are what the spec should name
    # One mark: a runtime loaded twice can hand out the same device handle on two platforms.
    chosen_at = next(((p, d) for p, d, _, dev in devices if dev == chosen), None)
    for p, d, platform, dev in devices:
        mark = "*" if (p, d) == chosen_at else " "
        memory = dev.global_mem_size / 2**30
        doubles = "fp64" if dev.double_fp_config else "no fp64"
        click.echo(f"{mark} {p}:{d}  {platform.name.strip()} / {dev.name.strip()}  "
                   f"({dev.version.strip()}, {dev.max_compute_units} CUs, {memory:.1f} GiB, {doubles})")
    if chosen is not None:
        click.echo("* = default device (choose with --device or CLRAYS_DEVICE: 'P:D' or a name substring)")
    else:
        source = ("CLRAYS_DEVICE" if context.get_parameter_source("device") is ParameterSource.ENVIRONMENT
                  else "--device")
        click.echo(f"{source}={device!r} matches none of these devices: name one as 'P:D' or by a substring "
                   f"of its name")


if __name__ == "__main__":
    main()
