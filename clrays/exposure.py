"""Exposure of the 8-bit outputs (.png, and the .gif, .webp and .mp4 a sequence writes):
a number of stops (EV; radiance × 2^EV before the sRGB curve), or `auto`, chosen from the
frame's own radiance.

`auto` maps the 99th percentile of the pixels' brightest channel (max of R, G and B, over
the pixels that are not black) to just below white (AUTO_WHITE, which 8 bits write as
254), in tenths of a stop rounded down:

    EV = floor(10 · log2(0.99 / p99)) / 10

A pixel clips when its brightest channel reaches white, so at most 1 % of the lit pixels
clip, whatever the light's colour; luminance would let a saturated channel clip below it.
Below white, not at it: a frame lit flat (one radiance over much of it) would otherwise
clip where its percentile lies.
The black pixels (a background with no medium) are left out, or a small lit object on a
black sky would have a p99 of 0. The log-average key of Reinhard et al. mapped to 0.18
follows the dark majority of a frame instead: with a light in view its glow whitens a
large disc (docs/scene-format.md, "Exposure", gives the figures). The EV is printed, and
is a tenth of a stop exactly, so that `--exposure EV` gives the same image.

`exposure_problem` says when an 8-bit frame is black or mostly white, for a one-line
warning.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from .image_io import to_srgb8

#: The outputs an exposure changes, suffix → format name: 8-bit images and videos (a
#: sequence's); .exr and .npy keep linear radiance.
EXPOSED_IMAGES = {".png": "PNG"}
EXPOSED_VIDEO = {".mp4": "MP4", ".gif": "GIF", ".webp": "WebP"}
EXPOSED_FORMATS = tuple(EXPOSED_IMAGES | EXPOSED_VIDEO)
#: The exposure that chooses itself from the frame (`auto_ev`).
AUTO = "auto"
#: Stops an exposure may take either way (beyond, float32 radiance × 2^EV under- or overflows).
EV_LIMIT = 64.0
#: `auto`: the percentile of the lit pixels' brightest channel that is mapped to AUTO_WHITE.
AUTO_PERCENTILE = 99.0
#: `auto`: the linear value that percentile is mapped to, 254 in 8 bits (255 is 0.9955 on).
AUTO_WHITE = 0.99
#: A frame warns when more of its pixels than this reach 255 in some channel.
CLIPPED_WARNING = 0.5


def parse_exposure(value: object) -> float | str | None:
    """`auto`, or a finite number of stops in [-EV_LIMIT, EV_LIMIT]; None when `value` is
    neither (the caller names the option or key in its one-line error)."""
    if isinstance(value, str) and value.strip().lower() == AUTO:
        return AUTO
    if isinstance(value, bool):
        return None
    try:
        stops = float(value)
    except (TypeError, ValueError):
        return None
    return stops if math.isfinite(stops) and -EV_LIMIT <= stops <= EV_LIMIT else None


def brightest_channel(radiance: np.ndarray) -> np.ndarray:
    """max(R, G, B) of each pixel of (H, W, 3) radiance (H, W), what clips first."""
    # Channel by channel: a reduction over the last axis of 3 is ten times slower.
    return np.maximum(np.maximum(radiance[..., 0], radiance[..., 1]), radiance[..., 2])


def auto_ev(radiance: np.ndarray) -> float:
    """The `auto` exposure of (H, W, 3) linear radiance, in stops: its lit pixels' 99th
    percentile of the brightest channel to AUTO_WHITE (module docstring), a multiple of 0.1,
    within ±EV_LIMIT. A black frame gets 0: no exposure shows it."""
    brightest = brightest_channel(radiance).reshape(-1).astype(np.float64)
    lit = brightest[np.isfinite(brightest) & (brightest > 0)]
    if lit.size == 0:
        return 0.0
    high = float(np.percentile(lit, AUTO_PERCENTILE))
    # + 1e-6: a tenth that float32 rounding puts a hair below stays that tenth.
    stops = math.floor(10 * math.log2(AUTO_WHITE / high) + 1e-6) / 10
    return min(max(stops, -EV_LIMIT), EV_LIMIT)


def exposure_setting(option: float | str | None, scene) -> float | str:
    """What exposes a frame of `scene`: the command's --exposure, else its render.exposure."""
    return scene.render.exposure if option is None else option


def resolve(exposure: float | str, radiance: np.ndarray) -> float:
    """The stops `exposure` stands for on this frame: `auto_ev` for AUTO, else itself."""
    return auto_ev(radiance) if exposure == AUTO else float(exposure)


def auto_line(ev: float, how: str = "") -> str:
    """The line that says which exposure `auto` chose."""
    return f"clrays: exposure auto: {ev:+.1f} EV{f' ({how})' if how else ''}"


class Problem(NamedTuple):
    """What is wrong with an 8-bit frame: its `kind` ("black" or "clipped") and the words."""

    kind: str
    text: str


def problem_of_8bit(brightest: np.ndarray) -> Problem | None:
    """The Problem of an 8-bit frame given its pixels' brightest channel (uint8, any
    shape), or None: every pixel 0, or more than CLIPPED_WARNING of them at 255, each with
    the hint that mends it."""
    if brightest.size == 0:
        return None
    if int(brightest.max()) == 0:
        return Problem("black", "every pixel is black (0 in every channel); try --exposure auto, "
                                "or a higher --exposure")
    clipped = float(np.mean(brightest == 255))
    if clipped > CLIPPED_WARNING:
        return Problem("clipped", f"{clipped:.0%} of the pixels clip (255 in some channel); try --exposure auto, "
                                  f"or a lower --exposure")
    return None


def exposure_problem(radiance: np.ndarray, ev: float) -> Problem | None:
    """`problem_of_8bit` of (H, W, 3) radiance encoded at `ev` stops."""
    # The brightest channel alone: the sRGB curve and its rounding keep the order of values.
    return problem_of_8bit(to_srgb8(brightest_channel(radiance), ev))


def warning_line(subject: str, problem: Problem) -> str:
    return f"clrays: warning: {subject}: {problem.text}"


def frame_exposure(setting: float | str, radiance: np.ndarray, path: str | Path,
                   echo: Callable[[str], None]) -> float:
    """The stops to write `radiance` at into `path`: `setting` (stops or AUTO) on this
    frame. For an 8-bit file, `echo` gets the EV `auto` chose and a warning when the frame
    encodes black or mostly white; a float file keeps linear radiance (0)."""
    if Path(path).suffix.lower() not in EXPOSED_FORMATS:
        return 0.0
    ev = resolve(setting, radiance)
    if setting == AUTO:
        echo(auto_line(ev))
    problem = exposure_problem(radiance, ev)
    if problem is not None:
        echo(warning_line(str(path), problem))
    return ev
