"""MP4 (H.264) from a sequence's frames, through imageio-ffmpeg's own ffmpeg binary, so
no system ffmpeg is needed (`pip install 'clrays[video]'`); and GIF, with pillow, on one
dithered palette (`write_gif`).

Players want yuv420p, whose chroma is subsampled 2×2, so the frames are padded to even
width and height (the last row or column repeated). `--crf` and `--video-option
KEY=VALUE` override the defaults below; the keys are the encoder's (VIDEO_OPTIONS), none
that names a file or changes the format, so `f=null` or `y=/elsewhere` cannot make ffmpeg
write nothing, or something, somewhere else.
"""
from __future__ import annotations

import contextlib
import itertools
import os
import subprocess
import tempfile
from fractions import Fraction
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..errors import OutputError
from ..image_io import write_atomic

#: H.264 constant rate factor: 18 is visually near-lossless for renders, at a few MB a minute.
DEFAULT_CRF = 18
#: ffmpeg output options before --crf and --video-option: what players and browsers expect
#: (4:2:0 chroma; the index at the front, so playback starts before the download ends).
DEFAULT_OPTIONS = {"pix_fmt": "yuv420p", "preset": "medium", "movflags": "+faststart"}


#: The ffmpeg output options `--video-option` may set: H.264 (libx264) rate control,
#: speed, compatibility and group of pictures, and the MP4's flags. Not `f` (the format:
#: `f=null` wrote an empty file), nor anything that names a file (`y`, `an`, `vstats_file`,
#: `passlogfile`, and `x264-params`, whose `stats=` and `dump-yuv=` write files).
VIDEO_OPTIONS = {
    "crf": "constant rate factor (as --crf)", "qp": "constant quantizer", "preset": "speed against size",
    "tune": "e.g. film, animation, grain", "profile:v": "H.264 profile", "level": "H.264 level",
    "pix_fmt": "e.g. yuv420p, yuv444p", "b:v": "target bit rate", "maxrate": "bit rate cap",
    "minrate": "bit rate floor", "bufsize": "rate control buffer", "g": "keyframe interval",
    "keyint_min": "shortest keyframe interval", "bf": "B-frames in a row", "refs": "reference frames",
    "movflags": "MP4 flags (+faststart)",
}
#: Other spellings of the same options.
VIDEO_OPTION_ALIASES = {"b": "b:v", "profile": "profile:v"}


def video_encoder_options(path: Path, crf: int | None, options: Sequence[str]) -> dict[str, str]:
    """The ffmpeg output options (name → value) for `path`: the defaults, `crf`, then
    `options` ("KEY=VALUE"). Empty for GIF and WebP, which take neither."""
    if path.suffix.lower() != ".mp4":
        if crf is not None or options:
            raise OutputError(f"{path}: --crf and --video-option apply to .mp4 only, got "
                              f"{'--crf' if crf is not None else '--video-option'} for {path.suffix or '(none)'}")
        return {}
    chosen = {**DEFAULT_OPTIONS, "crf": str(DEFAULT_CRF if crf is None else crf)}
    for text in options:
        key, sep, value = text.partition("=")
        key = key.strip().lstrip("-")
        if not sep or not key or not value.strip():
            raise OutputError(f"--video-option {text}: expected KEY=VALUE like preset=slow, got {text!r}")
        key = VIDEO_OPTION_ALIASES.get(key, key)
        if key not in VIDEO_OPTIONS:
            raise OutputError(f"--video-option {text}: {key!r} is not an encoding option clrays passes to ffmpeg; "
                              f"expected one of {', '.join(VIDEO_OPTIONS)}")
        chosen[key] = value.strip()
    return chosen


def even_size(frame: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 padded to even H and W by repeating the last row / column."""
    pad_h, pad_w = frame.shape[0] % 2, frame.shape[1] % 2
    if pad_h or pad_w:
        frame = np.pad(frame, ((0, pad_h), (0, pad_w), (0, 0)), mode="edge")
    return np.ascontiguousarray(frame)


def write_mp4(frames: Iterable[np.ndarray], out: Path, fps: float, options: dict[str, str]) -> Path:
    """Encode 8-bit sRGB frames (H, W, 3, all one size) to H.264 MP4 at `out`, atomically;
    the frames are streamed to ffmpeg one at a time."""
    try:
        import imageio_ffmpeg
    except ImportError:
        raise OutputError(f"{out}: MP4 needs imageio-ffmpeg: pip install 'clrays[video]'") from None
    unknown = [key for key in options if key not in VIDEO_OPTIONS]
    if unknown:  # the library's callers too: no option that names a file or changes the format
        raise OutputError(f"{out}: {unknown[0]!r} is not an encoding option clrays passes to ffmpeg; "
                          f"expected one of {', '.join(VIDEO_OPTIONS)}")
    frames = iter(frames)
    first = even_size(next(frames))
    height, width = first.shape[:2]
    options = {**DEFAULT_OPTIONS, **options}
    output = [argument for key, value in options.items() for argument in (f"-{key}", value)]

    def encode(temporary: str) -> None:
        command = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-f", "rawvideo",
                   "-pix_fmt", "rgb24", "-s", f"{width}x{height}", "-r", str(Fraction(fps).limit_denominator()),
                   "-i", "-", "-an", "-c:v", "libx264", *output, temporary]
        with tempfile.TemporaryFile() as log:  # a file, not a pipe, so a chatty ffmpeg cannot block
            encoder = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log)
            try:
                for index, frame in enumerate(itertools.chain([first], (even_size(frame) for frame in frames))):
                    if frame.shape != first.shape:  # a video of mixed sizes plays garbage
                        raise OutputError(f"{out}: frame {index} is {frame.shape[1]}×{frame.shape[0]}, the first "
                                          f"{width}×{height}; render the frames again with --overwrite")
                    encoder.stdin.write(frame.tobytes())
            except BrokenPipeError:
                pass  # ffmpeg stopped early; its log says why
            finally:
                with contextlib.suppress(BrokenPipeError):  # flushing to an ffmpeg that stopped early
                    encoder.stdin.close()
                code = encoder.wait()
            if code != 0:
                log.seek(0)
                lines = [line for line in log.read().decode(errors="replace").splitlines() if line.strip()]
                # x264 names a bad option on the first line; ffmpeg's own summary comes last.
                reason = lines[0] if lines else f"exit code {code}"
                raise OutputError(f"{out}: ffmpeg failed: {reason.strip()}")
            if not os.path.isfile(temporary) or os.path.getsize(temporary) == 0:  # exit 0 is not enough
                raise OutputError(f"{out}: ffmpeg exited without writing the video")

    write_atomic(out, encode)
    return out


#: Frames of a GIF whose colours choose its palette, at most (evenly spaced).
GIF_PALETTE_FRAMES = 64


def gif_palette(frames: Sequence[np.ndarray]):
    """One 256-colour palette (a PIL "P" image) for 8-bit sRGB frames (H, W, 3), by median
    cut over the distinct colours they hold, each counted once rather than once per pixel:
    a light's small bright glow holds few pixels but many colours, and a palette fitted to
    the pixels left it a handful of entries, seen as rings (the large dark fog took the rest)."""
    from PIL import Image

    step = max(1, -(-len(frames) // GIF_PALETTE_FRAMES))
    colours = np.unique(np.concatenate([np.unique(_packed(frame)) for frame in frames[::step]]))
    swatch = np.stack([(colours >> 16) & 255, (colours >> 8) & 255, colours & 255], axis=-1).astype(np.uint8)
    return Image.fromarray(swatch[None], mode="RGB").quantize(256, method=Image.Quantize.MEDIANCUT)


def _packed(frame: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 → one int32 per pixel, 0xRRGGBB."""
    frame = frame.astype(np.int32)
    return (frame[..., 0] << 16) | (frame[..., 1] << 8) | frame[..., 2]


def write_gif(frames: Sequence, out: Path, duration_ms: int) -> Path:
    """An animated GIF that loops forever of 8-bit sRGB frames (arrays (H, W, 3) or RGB
    images, all one size), at `out`, atomically: one palette for all frames (`gif_palette`,
    so colours do not flicker between frames), Floyd–Steinberg dithered onto it, so a
    smooth gradient stays smooth where 256 colours cannot hold every step."""
    from PIL import Image

    frames = [np.asarray(frame, dtype=np.uint8) for frame in frames]
    palette = gif_palette(frames)
    images = [Image.fromarray(np.ascontiguousarray(frame), mode="RGB").quantize(palette=palette,
                                                                               dither=Image.Dither.FLOYDSTEINBERG)
              for frame in frames]
    write_atomic(out, lambda temporary: images[0].save(temporary, format="GIF", save_all=True,
                                                       append_images=images[1:], duration=duration_ms, loop=0,
                                                       optimize=False))
    return out
