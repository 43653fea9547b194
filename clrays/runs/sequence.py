"""Image sequences: every frame of a scene's animation to numbered files, resumable.

    scene = load_scene("scenes/orbit.yaml")
    report = render_sequence(scene, "out/orbit/frame_{:04d}.png")
    write_video(report.paths, "out/orbit.gif", fps=scene.animation.fps)

Frames are written atomically (`clrays.image_io.write_image`), so a file that exists is
a finished frame, and a manifest beside the frames (MANIFEST) holds the digest of the
scene each was rendered from: running the same sequence again skips the frames whose
scene is unchanged and renders again those of a changed one (another `--set`, an edited
file), and an interrupted run loses nothing but the frame it was on. One render session (`Renderer`) renders all
frames, so what a frame shares with the previous one is not computed again
(docs/design.md §7).
"""
from __future__ import annotations

import json
import string
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..errors import ClraysError, OutputError
from ..image_io import FORMATS, check_folder, check_output_path, make_folder, read_srgb8, write_atomic
from ..passes import write_render
from ..reuse import digest, scene_digest
from ..session import Renderer, RenderResult
from ..scene.model import Scene
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


def check_pattern(pattern: str | Path) -> str:
    """A frame path pattern with exactly one replacement field for the frame number
    (`{}`, `{:04d}`, `{0:04d}` or `{frame:04d}`) and an image extension."""
    pattern = str(pattern)
    example = "like frames/frame_{:04d}.png"
    try:
        fields = [name for _, name, _, _ in string.Formatter().parse(pattern) if name is not None]
        if len(fields) != 1:
            raise OutputError(f"{pattern}: expected one {{}} field for the frame number ({example}), "
                              f"got {len(fields)} fields")
        sample = [frame_path(pattern, n) for n in (0, 1)]
    except (ValueError, IndexError, KeyError) as exc:
        raise OutputError(f"{pattern}: expected a frame pattern {example} ({type(exc).__name__}: {exc})") from None
    if sample[0] == sample[1]:
        raise OutputError(f"{pattern}: expected a different file per frame, got {sample[0]} for frames 0 and 1")
    if Path(pattern).suffix.lower() not in FORMATS or "{" in Path(pattern).suffix:
        raise OutputError(f"{pattern}: unknown frame extension {Path(pattern).suffix or '(none)'!r}; "
                          f"expected one of {', '.join(FORMATS)}")
    return pattern


def frame_path(pattern: str, frame: int) -> Path:
    return Path(pattern.format(frame, frame=frame))


@dataclass
class SequenceReport:
    """What a sequence run did."""

    paths: list[Path]  # every frame's file, in frame order
    rendered: list[int] = field(default_factory=list)  # frames rendered by this run
    kept: list[int] = field(default_factory=list)  # frames whose file was already there, of the same scene
    stale: list[int] = field(default_factory=list)  # rendered again: their file was of another scene
    results: dict[int, RenderResult] = field(default_factory=dict)  # of the rendered frames
    wall_s: float = 0.0

    def summary(self) -> str:
        per = f", {self.wall_s / len(self.rendered):.2f} s per frame" if self.rendered else ""
        stale = f" ({len(self.stale)} of them replacing frames of a changed scene)" if self.stale else ""
        return (f"{counted(len(self.rendered), 'frame')} rendered{stale}, {len(self.kept)} already there "
                f"(of {len(self.paths)}) in {self.wall_s:.1f} s{per}")


#: Beside the frames, in each folder that holds some: frame file name → the digest of what
#: its image depends on (`frame_digest`), so that a resumed run can tell a finished frame
#: from a stale one.
MANIFEST = ".clrays-frames.json"


def frame_digest(frame_scene: Scene, method: str | None, exposure: float, suffix: str) -> str:
    """Everything a frame file depends on: the frame's scene (`reuse.scene_digest`), the
    method, the format, and the exposure where the format applies it."""
    method = method or frame_scene.render.method
    return digest("frame file", scene_digest(frame_scene), method, suffix,
                  exposure if suffix == ".png" else 0.0).hex()


class FrameManifest:
    """The digests of the frames of one folder (MANIFEST), rewritten atomically before each
    frame file is written: a frame file without an entry, or with another digest, is stale."""

    def __init__(self, folder: Path):
        self.path = folder / MANIFEST
        self.entries: dict[str, str] = {}
        try:
            entries = json.loads(self.path.read_text())
            if isinstance(entries, dict):
                self.entries = {str(k): str(v) for k, v in entries.items()}
        except (OSError, ValueError):
            pass  # none yet, or unreadable: every frame file there counts as stale

    def matches(self, path: Path, frame_digest_hex: str) -> bool:
        return path.exists() and self.entries.get(path.name) == frame_digest_hex

    def record(self, path: Path, frame_digest_hex: str) -> None:
        self.entries[path.name] = frame_digest_hex
        text = json.dumps(self.entries, indent=0, sort_keys=True)
        write_atomic(self.path, lambda temporary: Path(temporary).write_text(text))


def render_sequence(scene: Scene, pattern: str | Path, frames: range | None = None, *,
                    renderer: Renderer | None = None, method: str | None = None, exposure: float = 0.0,
                    overwrite: bool = False, progress: bool = False,
                    on_frame: Callable[[int, Path, RenderResult | None], None] | None = None,
                    executor=None) -> SequenceReport:
    """Render `frames` (default: all of the animation) of `scene` to `pattern`.

    pattern: a path with one `{}` field for the frame number, e.g. `out/frame_{:04d}.png`
    (its folders are created). Frames whose file exists are skipped unless `overwrite`.
    renderer: the session to use (default: a new one with reuse). on_frame(frame, path,
    result or None when skipped) is called after each frame. executor: a
    `clrays.runs.distributed.DaskExecutor` to render the frames on its workers instead
    (each with its own session; `renderer` then only gives the reuse setting), in any
    order; the result's image is then empty, the frame being in its file."""
    pattern = check_pattern(pattern)
    frames = scene_frames(scene) if frames is None else frames
    paths = [frame_path(pattern, frame) for frame in frames]
    for folder in dict.fromkeys(path.parent for path in paths):  # the frame number may be in a folder name
        make_folder(folder)
    for path in paths[:1]:
        check_output_path(path)
    renderer = renderer or Renderer()
    report = SequenceReport(paths)
    manifests: dict[Path, FrameManifest] = {}
    start = time.perf_counter()

    def render_here(work):
        for frame, path in work:
            frame_scene = scene.animation.scene_at(scene, frame) if scene.animation is not None else scene
            result = renderer.render(frame_scene, method)
            write_render(path, result, frame_scene, exposure, f"frame {frame}")
            yield (frame, path), result

    try:
        with Progress(progress, len(paths), "frame", "sequence") as bar:
            work = []
            for frame, path in zip(frames, paths):
                frame_scene = scene.animation.scene_at(scene, frame) if scene.animation is not None else scene
                manifest = manifests.setdefault(path.parent, FrameManifest(path.parent))
                key = frame_digest(frame_scene, method, exposure, path.suffix.lower())
                if manifest.matches(path, key) and not overwrite:
                    report.kept.append(frame)
                    if on_frame:
                        on_frame(frame, path, None)
                    bar.advance(f"frame {frame}")
                    continue
                if path.exists() and manifest.entries.get(path.name) != key:
                    # A stale frame goes before its new digest is recorded, and the digest
                    # before the new file is written (here or by a worker): a kill anywhere
                    # between leaves no file that a later run could take for finished.
                    path.unlink()
                    if not overwrite:
                        report.stale.append(frame)
                manifest.record(path, key)
                work.append((frame, path))
            if executor is None:
                outcomes = render_here(work)
            else:
                from .distributed import render_frame_task

                outcomes = executor.run(render_frame_task, work, dict(scene=scene, method=method, exposure=exposure,
                                                                      reuse=renderer.reuse, overwrite=overwrite))
            for (frame, path), result in outcomes:
                if result is None:  # written by a worker that died before reporting it
                    report.kept.append(frame)
                else:
                    report.rendered.append(frame)
                    report.results[frame] = result
                if on_frame:
                    on_frame(frame, path, result)
                bar.advance(f"frame {frame}" + (f", {executor.busy_label()}" if executor and progress else ""))
    finally:
        report.wall_s = time.perf_counter() - start
        report.rendered.sort()
        report.kept.sort()
    return report


def check_video_path(path: str | Path) -> Path:
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in VIDEO_FORMATS:
        raise OutputError(f"{path}: unknown video extension {path.suffix or '(none)'!r}; "
                          f"expected one of {', '.join(VIDEO_FORMATS)}")
    return check_folder(path)


def write_video(paths: list[Path], out: str | Path, fps: float, exposure: float = 0.0,
                encoder_options: dict[str, str] | None = None) -> Path:
    """An H.264 MP4 (`clrays.runs.video`; encoder_options: its ffmpeg options, default
    `video_encoder_options`), or an animated GIF or WebP that loops forever, of the frame
    files; written atomically, like images."""
    from PIL import Image

    out = check_video_path(out)
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise OutputError(f"{out}: frames missing: {', '.join(missing[:3])}{' ...' if len(missing) > 3 else ''}")
    if not paths:
        raise OutputError(f"{out}: no frames")
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
    options = {"optimize": False} if out.suffix.lower() == ".gif" else {"lossless": True}
    write_atomic(out, lambda temporary: images[0].save(temporary, save_all=True, append_images=images[1:],
                                                       duration=duration, loop=0, **options))
    return out
