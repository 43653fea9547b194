"""Image sequences: every frame of a scene's animation to numbered files, resumable.

    scene = load_scene("scenes/orbit.yaml")
    report = render_sequence(scene, "out/orbit/frame_{:04d}.png")
    write_video(report.paths, "out/orbit.gif", fps=scene.animation.fps)

Frames are written atomically (`clrays.image_io.write_frame`), and a manifest beside the
frames (`frame_manifest.MANIFEST`) gets a line per frame written: the digest of the scene it was rendered
from and the digest of its bytes. Running the same sequence again skips the frames whose
scene is unchanged and whose file is the one written for it, and renders again those of
a changed scene (another `--set`, an edited file) or replaced by another writer; an
interrupted run loses nothing but the frame it was on. A run holds the lock of the folder
above its frames (`lock_folder`), so a second run into it stops at once. `--exposure auto`
exposes every frame alike, so that they do not flicker: at the stops chosen from the
animation's first, middle and last frames, whichever frames a run renders, and recorded in
that folder for the runs that resume it (`sequence_exposure`). One render
session (`Renderer`) renders all frames, so what a frame shares with the previous one is
not computed again (docs/design.md §7); on a GPU with two frames in flight: the next frame
is prepared and enqueued before a frame's image is read and written (docs/design.md §4).
"""
from __future__ import annotations

import os
import re
import string
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..errors import ClraysError, OutputError
from ..exposure import (AUTO, Problem, auto_ev, auto_line, brightest_channel, exposure_problem, exposure_setting,
                        problem_of_8bit, warning_line)
from ..image_io import (FORMATS, check_folder, check_name_length, check_output_path, folder_lock, make_folder,
                        make_output_folder, read_linear, read_srgb8, write_atomic)
from ..outputs import check_replaceable, make_folders_below
from ..passes import pass_paths, write_render, written_pass_files
from ..scene.animation import scene_at
from ..scene.limits import MAX_FRAME_FIELD_WIDTH
from ..session import Renderer, RenderResult
from ..scene.model import Scene
from .frame_manifest import (EXPOSURE_RECORD, FrameManifest, frame_digest, record_exposure, recorded_exposure,
                             sequence_exposure_key)
from .progress import Progress, counted

VIDEO_FORMATS = (".mp4", ".gif", ".webp")


def scene_frames(scene: Scene) -> range:
    """The frames a scene has: its animation's range, or frame 0 alone."""
    return scene.animation.frames if scene.animation is not None else range(0, 1)


def parse_frames(text: str | None, available: range, option: str = "--frames") -> range:
    """`A:B` (inclusive), `A:`, `:B` or `N` within `available`; None: all of it. `option`
    names the command-line option in messages."""
    if text is None:
        return available
    first, last = available.start, available.stop - 1
    where = f"{option} {text}"
    head, colon, tail = text.strip().partition(":")
    try:
        a = int(head) if head.strip() else first
        b = (int(tail) if tail.strip() else last) if colon else a
    except ValueError:
        raise ClraysError(f"{where}: expected A:B, A:, :B or N (frame numbers), got {text!r}") from None
    if not first <= a <= b <= last:
        if first == last:  # a still scene: frame 0 alone
            raise ClraysError(f"{where}: the scene has no animation, so frame {first} alone; got {a}:{b}")
        raise ClraysError(f"{where}: expected frames {first} <= A <= B <= {last} (the scene's frames), "
                          f"got {a}:{b}")
    return range(a, b + 1)


#: A frame field's format spec: an integer presentation ([[fill]align][sign][#][0][width]
#: [grouping][type]), the width bounded by MAX_FRAME_FIELD_WIDTH. No precision, no `c`
#: (frame 0 is a NUL), no nested fields.
_FRAME_SPEC = re.compile(r"(?:(?P<fill>[^{}/\x00-\x1f\x7f])?[<>=^])?[-+ ]?#?0?(?P<width>\d*)[_,]?[bdoxXn]?")
#: Characters no frame path should hold: NUL (which no file system takes) and the controls.
_BAD_CHARACTER = re.compile(r"[\x00-\x1f\x7f]")


def check_pattern(pattern: str | Path) -> str:
    """A frame path pattern with exactly one replacement field for the frame number
    (`{}`, `{:04d}`, `{0:04d}` or `{frame:04d}`: an integer format of width at most
    MAX_FRAME_FIELD_WIDTH) and an image extension; checked before anything is formatted."""
    pattern = str(pattern)
    example = "like frames/frame_{:04d}.png"
    if _BAD_CHARACTER.search(pattern):  # checked first: no message prints one
        raise OutputError(f"{pattern!r}: expected no NUL or control characters in a frame pattern")
    try:
        fields = [(name, spec, conversion) for _, name, spec, conversion in string.Formatter().parse(pattern)
                  if name is not None]
    except ValueError as exc:
        raise OutputError(f"{pattern}: expected a frame pattern {example} ({exc})") from None
    if len(fields) != 1:
        raise OutputError(f"{pattern}: expected one {{}} field for the frame number ({example}), "
                          f"got {len(fields)} fields")
    name, spec, conversion = fields[0]
    field_text = "{" + name + (f"!{conversion}" if conversion else "") + (f":{spec}" if spec else "") + "}"
    match = _FRAME_SPEC.fullmatch(spec or "")
    if name not in ("", "0", "frame") or conversion or match is None:
        raise OutputError(f"{pattern}: field {field_text!r}: expected a frame pattern {example}: its one field "
                          f"{{}}, {{0}} or {{frame}}, in an integer format (fill, align, sign, width, grouping; "
                          f"b, d, o, x, X or n)")
    if match["width"] and int(match["width"]) > MAX_FRAME_FIELD_WIDTH:
        raise OutputError(f"{pattern}: field {field_text!r}: expected a width of at most {MAX_FRAME_FIELD_WIDTH}, "
                          f"got {int(match['width']) if len(match['width']) < 20 else match['width'][:20] + '...'}")
    try:
        sample = [frame_path(pattern, n) for n in (0, 1)]
    except ValueError as exc:  # e.g. a sign with `n`
        raise OutputError(f"{pattern}: field {field_text!r}: {exc}") from None
    if sample[0] == sample[1]:
        raise OutputError(f"{pattern}: expected a different file per frame, got {sample[0]} for frames 0 and 1")
    if Path(pattern).suffix.lower() not in FORMATS or "{" in Path(pattern).suffix:
        raise OutputError(f"{pattern}: unknown frame extension {Path(pattern).suffix or '(none)'!r}; "
                          f"expected one of {', '.join(FORMATS)}")
    return pattern


def frame_path(pattern: str, frame: int) -> Path:
    return Path(pattern.format(frame, frame=frame))


def lock_folder(pattern: str) -> Path:
    """The folder a sequence locks: the deepest one that holds every frame of `pattern`
    (the frame number may name folders: `out/{:04d}/beauty.png` locks `out`)."""
    parts = Path(pattern).parts
    # The first part with a replacement field: `{{` is a literal brace, which names no frame.
    fixed = next(i for i, part in enumerate(parts)
                 if any(field is not None for _, field, _, _ in string.Formatter().parse(part)))
    return Path(*(part.format() for part in parts[:fixed])) if fixed else Path(".")  # `{{1}}` names `{1}`


@dataclass
class SequenceReport:
    """What a sequence run did."""

    paths: list[Path]  # every frame's file, in frame order
    rendered: list[int] = field(default_factory=list)  # frames rendered by this run
    kept: list[int] = field(default_factory=list)  # frames whose file was already there, of the same scene
    stale: list[int] = field(default_factory=list)  # rendered again: their file was of another scene
    # rendered again: their file has no line in the manifest (a run stopped between writing
    # it and recording it, or another program wrote it)
    unrecorded: list[int] = field(default_factory=list)
    # of the rendered frames, without their images (in the files): times, reuse, sizes
    results: dict[int, RenderResult] = field(default_factory=dict)
    wall_s: float = 0.0
    exposure: float = 0.0  # the stops of the .png frames (`auto`: those chosen for the sequence)
    problems: dict[int, Problem] = field(default_factory=dict)  # rendered .png frames black or mostly white

    def problem_lines(self) -> list[str]:
        """One warning per kind of problem (black, clipped), naming its first frame."""
        lines = []
        for kind in dict.fromkeys(problem.kind for problem in self.problems.values()):
            frames = sorted(frame for frame, problem in self.problems.items() if problem.kind == kind)
            more = f" and {len(frames) - 1} more of the {len(self.rendered)} rendered" if len(frames) > 1 else ""
            lines.append(warning_line(f"frame {frames[0]}{more}", self.problems[frames[0]]))
        return lines

    def summary(self) -> str:
        per = f", {self.wall_s / len(self.rendered):.2f} s per frame" if self.rendered else ""
        replaced = [f"{len(self.stale)} of them replacing frames of a changed scene"] if self.stale else []
        if self.unrecorded:
            replaced.append(f"{len(self.unrecorded)} {'' if replaced else 'of them '}replacing files no run "
                            f"recorded as finished")
        stale = f" ({', '.join(replaced)})" if replaced else ""
        return (f"{counted(len(self.rendered), 'frame')} rendered{stale}, {len(self.kept)} already there "
                f"(of {len(self.paths)}) in {self.wall_s:.1f} s{per}")


def render_sequence(scene: Scene, pattern: str | Path, frames: range | None = None, *,
                    renderer: Renderer | None = None, method: str | None = None,
                    exposure: float | str | None = None,
                    overwrite: bool = False, progress: bool = False,
                    on_frame: Callable[[int, Path, RenderResult | None], None] | None = None,
                    executor=None, in_flight: bool | None = None,
                    echo: Callable[[str], None] | None = None) -> SequenceReport:
    """Render `frames` (default: all of the animation) of `scene` to `pattern`.

    pattern: a path with one `{}` field for the frame number, e.g. `out/frame_{:04d}.png`
    (its folders are created, and the one above them locked for the run: `lock_folder`).
    Frames whose file exists, of the same scene, are skipped unless `overwrite`.
    renderer: the session to use (default: a new one with reuse). on_frame(frame, path,
    result or None when skipped) is called after each frame. executor: a
    `clrays.runs.distributed.DaskExecutor` to render the frames on its workers instead
    (each with its own session; `renderer` then only gives the reuse setting), in any
    order; the result's image is then empty, the frame being in its file. in_flight: whether
    the session prepares each frame while the device renders the one before
    (`_frames_in_flight`); None (default): where that gains time (Renderer.frames_in_flight_win).
    exposure: stops, or AUTO: one for every frame (`sequence_exposure`); None (default): the
    scene's render.exposure. echo(line) gets
    the EV `auto` chose and, at the end, a warning per kind of .png frame rendered black or
    mostly white (clrays.exposure.exposure_problem)."""
    pattern = check_pattern(pattern)
    frames = scene_frames(scene) if frames is None else frames
    paths = [frame_path(pattern, frame) for frame in frames]
    locked = make_folder(lock_folder(pattern))
    for path in paths[:1]:  # the others' folders are created as the run reaches them
        check_output_path(make_folders_below(locked, path.parent) / path.name)
    renderer = renderer or Renderer()
    report = SequenceReport(paths)
    start = time.perf_counter()
    echo = echo or (lambda line: None)
    with folder_lock(lock_folder(pattern)):
        try:
            if paths and paths[0].suffix.lower() == ".png":  # float frames keep linear radiance
                report.exposure = sequence_exposure(scene, pattern, renderer, method,
                                                    exposure_setting(exposure, scene), overwrite, executor, echo)
            with Progress(progress, len(paths), "frame", "sequence") as bar:
                _run_frames(scene, frames, paths, renderer, method, report.exposure, overwrite, progress, on_frame,
                            executor, report, bar, in_flight, locked)
        finally:
            report.wall_s = time.perf_counter() - start
            report.rendered.sort()
            report.kept.sort()
    for line in report.problem_lines():
        echo(line)
    return report


def exposure_frames(scene: Scene) -> list[int]:
    """The frames `auto` exposes a sequence from: its animation's first, middle and last."""
    frames = scene_frames(scene)
    return sorted({frames[0], frames[len(frames) // 2], frames[-1]})


def sequence_exposure(scene: Scene, pattern: str, renderer: Renderer, method: str | None, exposure: float | str,
                      overwrite: bool, executor, echo: Callable[[str], None]) -> float:
    """The stops of every frame: `exposure` itself, or for AUTO the least `auto_ev` of the
    `exposure_frames` (the brightest of them clips no more than `auto` lets a still frame),
    whichever frames this run renders. Recorded in the locked folder (EXPOSURE_RECORD, for
    the scene, its animation and the method), so that a resumed run reads it rather than
    rendering those frames again; a frame among them that this run renders comes from the
    session's kept frames where reuse is on."""
    if exposure != AUTO:
        return float(exposure)
    folder, key = lock_folder(pattern), sequence_exposure_key(scene, method)
    stops = None if overwrite else recorded_exposure(folder, key)
    if stops is not None:
        echo(auto_line(stops, f"recorded in {folder / EXPOSURE_RECORD}, for every frame"))
        return stops
    sampled = exposure_frames(scene)
    if executor is None:
        stops = min(auto_ev(renderer.render(scene_at(scene, frame), method).image) for frame in sampled)
    else:
        from .distributed import auto_exposure_task

        stops = min(ev for _, ev in executor.run(auto_exposure_task, sampled,
                                                 dict(scene=scene, method=method, reuse=renderer.reuse)))
    record_exposure(folder, key, stops)
    echo(auto_line(stops, f"from frame{'s' if len(sampled) > 1 else ''} {', '.join(map(str, sampled))}, "
                          f"for every frame"))
    return stops


def _run_frames(scene, frames, paths, renderer, method, exposure, overwrite, progress, on_frame, executor,
                report: SequenceReport, bar: Progress, in_flight: bool | None = None, locked: Path = Path(".")) -> None:
    """The frames in order, each checked against its folder's manifest just before it is
    rendered: the first frame starts at once, and the run is linear in the frame count.
    `locked`: the folder locked, which holds every frame's."""
    manifests: dict[Path, FrameManifest] = {}

    def manifest_of(path: Path) -> FrameManifest:
        if path.parent not in manifests:
            make_folders_below(locked, path.parent)  # the frame number may be in a folder name
            manifests[path.parent] = FrameManifest(path.parent)
        return manifests[path.parent]

    def checked():
        """(frame, path, frame digest, frame scene, whether its file is kept) of every frame,
        in order; a stale file removed before its frame is yielded."""
        for frame, path in zip(frames, paths):
            frame_scene = scene_at(scene, frame)
            manifest = manifest_of(path)
            key = frame_digest(frame_scene, method, exposure, path.suffix.lower())
            if not overwrite and manifest.matches(path, key) and all(
                    part.exists() for part in pass_paths(path, frame_scene.render.aovs)):
                yield frame, path, key, frame_scene, True
                continue
            if os.path.lexists(path) and not (overwrite and manifest.matches(path, key)):
                # A stale frame goes before its new one is rendered (here or by a worker, which
                # skips a file that is there), so that no kill leaves it to be taken for new.
                parts = (path, *written_pass_files(path))  # its passes go with it: they were its scene's
                for part in parts:
                    check_replaceable(part)  # a link or a FIFO there is refused, not removed unseen
                try:
                    for part in parts:
                        part.unlink(missing_ok=True)
                except OSError as exc:
                    raise OutputError(f"{path}: cannot replace the stale frame: {exc.strerror or exc}") from None
                if not overwrite:
                    (report.stale if path.name in manifest.entries else report.unrecorded).append(frame)
            yield frame, path, key, frame_scene, False

    def kept(frame: int, path: Path) -> None:
        report.kept.append(frame)
        if on_frame:
            on_frame(frame, path, None)
        bar.advance(f"frame {frame}")

    if executor is None:
        _frames_in_flight(checked(), renderer, method, exposure, manifest_of, kept, report, on_frame, bar, in_flight)
        return
    from .distributed import render_frame_task

    def to_render():
        for frame, path, key, frame_scene, is_kept in checked():
            if is_kept:
                kept(frame, path)
            else:
                yield frame, path, key

    # A worker appends its frame's line itself (`append_frame_line`), also for a frame that
    # lands after this run was stopped.
    outcomes = executor.run(render_frame_task, list(to_render()),
                            dict(scene=scene, method=method, exposure=exposure, reuse=renderer.reuse,
                                 overwrite=overwrite))
    for (frame, path, _), result in outcomes:
        _done(report, frame, path, result, on_frame, bar,
              f"frame {frame}" + (f", {executor.busy_label()}" if progress else ""))


def _frames_in_flight(checked, renderer: Renderer, method, exposure, manifest_of, kept, report: SequenceReport,
                      on_frame, bar: Progress, in_flight: bool | None = None) -> None:
    """The frames of `checked` rendered in one session, in order, two in flight: frame N+1 is
    derived, uploaded and enqueued (Renderer.submit) before frame N's image is read and
    written, so the host prepares one while the device works on the other. Files, manifest
    lines and reports come in frame order. A frame that fails or is interrupted (Ctrl-C)
    still has the one before it written: a run loses nothing but the frame it was on. Not
    `in_flight` (None: `renderer.frames_in_flight_win`): each frame is written before the
    next is submitted."""
    unwritten = []  # (frame, path, key, frame scene, PendingFrame) of the frame submitted, not yet written

    def write_unwritten() -> None:
        if not unwritten:
            return
        frame, path, key, frame_scene, pending = unwritten.pop()
        result = pending.result()
        content = write_render(path, result, frame_scene, exposure, f"frame {frame}")
        manifest_of(path).record(path, key, content)
        _done(report, frame, path, result, on_frame, bar, f"frame {frame}")

    try:
        for frame, path, key, frame_scene, is_kept in checked:
            if is_kept:
                write_unwritten()
                kept(frame, path)
                continue
            pending = renderer.submit(frame_scene, method)
            write_unwritten()  # the frame before, while the device renders this one
            unwritten.append((frame, path, key, frame_scene, pending))
            if not (renderer.frames_in_flight_win if in_flight is None else in_flight):
                write_unwritten()
        write_unwritten()
    except BaseException:
        write_unwritten()
        raise


def _done(report: SequenceReport, frame: int, path: Path, result, on_frame, bar: Progress, label: str) -> None:
    if result is None:  # written by a worker that died before reporting it
        report.kept.append(frame)
    else:
        report.rendered.append(frame)
        if path.suffix.lower() == ".png":
            # A worker's result comes without its image: the frame is read back from its file.
            problem = exposure_problem(result.image, report.exposure) if result.image.size else \
                problem_of_8bit(brightest_channel(read_srgb8(path)))
            if problem is not None:
                report.problems[frame] = problem
        report.results[frame] = result.without_pixels()  # a long sequence keeps no images
    if on_frame:
        on_frame(frame, path, result)
    bar.advance(label)


def check_video_path(path: str | Path) -> Path:
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in VIDEO_FORMATS:
        raise OutputError(f"{path}: unknown video extension {path.suffix or '(none)'!r}; "
                          f"expected one of {', '.join(VIDEO_FORMATS)}")
    check_name_length(path)
    check_replaceable(path)  # a link there is one line before the frames, not after them
    return check_folder(make_output_folder(path))  # created, as the frames' folders are


def write_video(paths: list[Path], out: str | Path, fps: float, exposure: float | str = 0.0,
                encoder_options: dict[str, str] | None = None, echo: Callable[[str], None] | None = None) -> Path:
    """An H.264 MP4 (`clrays.runs.video`; encoder_options: its ffmpeg options, default
    `video_encoder_options`), or an animated GIF or WebP that loops forever, of the frame
    files; written atomically, like images. `exposure` encodes .exr and .npy frames (a .png
    frame is as written); AUTO: `auto_ev` of the first frame, for all, said to `echo`."""
    from PIL import Image

    out = check_video_path(out)
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise OutputError(f"{out}: frames missing: {', '.join(missing[:3])}{' ...' if len(missing) > 3 else ''}")
    if not paths:
        raise OutputError(f"{out}: no frames")
    if exposure == AUTO:
        exposure = 0.0 if paths[0].suffix.lower() == ".png" else auto_ev(read_linear(paths[0]))
        if paths[0].suffix.lower() != ".png" and echo is not None:
            echo(auto_line(exposure, f"from {paths[0]}, for {out}"))
    if out.suffix.lower() == ".mp4":
        from .video import video_encoder_options, write_mp4

        options = encoder_options or video_encoder_options(out, None, ())
        return write_mp4((read_srgb8(p, exposure) for p in paths), out, fps, options)
    images = [Image.fromarray(read_srgb8(p, exposure), mode="RGB") for p in paths]
    sizes = {image.size for image in images}
    if len(sizes) > 1:  # a GIF of mixed sizes plays garbage: refuse rather than pad
        odd, size = next((p, image.size) for p, image in zip(paths, images) if image.size != images[0].size)
        raise OutputError(f"{out}: frames of different sizes ({paths[0]}: {images[0].size[0]}×{images[0].size[1]}, "
                          f"{odd}: {size[0]}×{size[1]}); render them again with --overwrite")
    # Milliseconds per frame; GIF stores centiseconds in 16 bits, so slow rates are clamped.
    duration = int(min(max(round(1000.0 / fps), 1), 655_350))
    if out.suffix.lower() == ".gif":
        from .video import write_gif

        return write_gif(images, out, duration)
    write_atomic(out, lambda temporary: images[0].save(temporary, save_all=True, append_images=images[1:],
                                                       duration=duration, loop=0, lossless=True))
    return out
