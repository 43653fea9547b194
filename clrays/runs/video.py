"""MP4 (H.264) from a sequence's frames, through imageio-ffmpeg's own ffmpeg binary, so
no system ffmpeg is needed (`pip install 'clrays[video]'`).

Players want yuv420p, whose chroma is subsampled 2×2, so the frames are padded to even
width and height (the last row or column repeated). `--crf` and `--video-option
KEY=VALUE` (any ffmpeg output option) override the defaults below.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import OutputError
from ..image_io import write_atomic

#: H.264 constant rate factor: 18 is visually near-lossless for renders, at a few MB a minute.
DEFAULT_CRF = 18
#: ffmpeg output options before --crf and --video-option: what players and browsers expect
#: (4:2:0 chroma; the index at the front, so playback starts before the download ends).
DEFAULT_OPTIONS = {"pix_fmt": "yuv420p", "preset": "medium", "movflags": "+faststart"}


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
        chosen[key] = value.strip()
    return chosen


def even_size(frame: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 padded to even H and W by repeating the last row / column."""
    pad_h, pad_w = frame.shape[0] % 2, frame.shape[1] % 2
    if pad_h or pad_w:
        frame = np.pad(frame, ((0, pad_h), (0, pad_w), (0, 0)), mode="edge")
    return np.ascontiguousarray(frame)


def write_mp4(frames: Sequence[np.ndarray], out: Path, fps: float, options: dict[str, str]) -> Path:
    """Encode 8-bit sRGB frames (H, W, 3) to H.264 MP4 at `out`, atomically."""
    try:
        import imageio_ffmpeg
    except ImportError:
        raise OutputError(f"{out}: MP4 needs imageio-ffmpeg: pip install 'clrays[video]'") from None
    frames = [even_size(frame) for frame in frames]
    height, width = frames[0].shape[:2]
    options = dict(options)
    pix_fmt = options.pop("pix_fmt", DEFAULT_OPTIONS["pix_fmt"])
    output_params = [argument for key, value in options.items() for argument in (f"-{key}", value)]

    def encode(temporary: str) -> None:
        writer = imageio_ffmpeg.write_frames(temporary, (width, height), fps=fps, codec="libx264",
                                             pix_fmt_out=pix_fmt, quality=None, macro_block_size=1,
                                             output_params=output_params, ffmpeg_log_level="error")
        try:
            writer.send(None)  # starts ffmpeg
            for frame in frames:
                writer.send(frame)
            writer.close()
        except (OSError, RuntimeError) as exc:  # ffmpeg's own complaint (a bad option): its last line
            writer.close()
            lines = [line for line in str(exc).splitlines() if line.strip()]
            raise OutputError(f"{out}: ffmpeg failed: {lines[-1] if lines else type(exc).__name__}") from None

    write_atomic(out, encode)
    return out
