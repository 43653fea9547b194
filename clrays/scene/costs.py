"""Sizes that follow the image: the shadow map side, the slice count and the γ texels per
slice that a scene leaves unset are derived from the image (docs/design.md §7,
"Sizes that follow the image").

A shadow-map texel seen from the camera should not be larger than a pixel, so the map
side follows the image diagonal, with a margin of 4 for surfaces seen at a slant. The
epipolar texture resamples that map, so it needs no more slices or γ texels than the map
has texels along a side; and no more than the image can show: each pixel point-samples
the shafts, so a slice count of 4 × the perimeter (8(W + H)) and 8 × the diagonal of γ
texels. Why the factors are that large: on the spot-light slats of tests/stages at 64×48,
slices = perimeter (256) gives a p99 error of 6.5 % against `exact` and γ texels =
diagonal (128) 11.7 %, where 1024 × 1024 gives 2.4 %. Every size is rounded up to a power
of two (sizes change in steps, not with every pixel) and clamped: below by what a shadow
or a slice still resolves, above by the measured defaults of bench/RESULTS.md ("Choosing
defaults"), so 64×48 and larger with a 1024 map render exactly as before.
"""
from __future__ import annotations

import math
from dataclasses import replace

from .model import Scene

#: Upper clamps: the measured defaults (bench/RESULTS.md, "Choosing defaults").
MAX_SHADOW_MAP = 1024
MAX_SLICES = 1024
MAX_GAMMA_SAMPLES = 1024
#: Lower clamps: the smallest sizes the scene format accepts for slices and γ samples,
#: and a shadow map that still resolves an object's shadow on a thumbnail.
MIN_SHADOW_MAP = 64
MIN_SLICES = 16
MIN_GAMMA_SAMPLES = 16
#: Epipolar sampling: samples along the longest slice's line on the screen (shorter lines
#: get as many as keep its spacing: clrays.stages.sampling.line_lengths). That line is at
#: most the diagonal, so a sample per two pixels of the diagonal puts them no further apart
#: than two pixels on any line. One per pixel computes about twice the samples for 1.4× the traverse
#: time and brings behind.yaml's p99 against `exact` from 0.324 to 0.289 % at 1280×720
#: (bench/RESULTS.md, "Epipolar sampling").
LINE_SAMPLES_PER_PIXEL = 0.5
MIN_LINE_SAMPLES = 16
MAX_LINE_SAMPLES = 4096
#: Epipolar sampling: the longest line gets about this many initially computed samples,
#: their step between MIN_INITIAL_STEP and MAX_INITIAL_STEP. A shaft is as wide on a small
#: image as on a large one, measured along the line, so the step shrinks with the image: 6 at
#: 1280×720 (the largest within 10 % of the per-pixel walk's error there), 3 at 640×360,
#: where 6 put behind.yaml's RMSE and p99 against `exact` 19 % and 35 % over the per-pixel
#: walk's and 3 puts them 4 % and 7 % over (bench/RESULTS.md, "The initial step follows the
#: image"). Below 640×360 it stays 3: there the 1024 slices' lines already hold more
#: samples than the image has pixels, and a smaller step would only compute more of them.
INITIAL_SAMPLES_PER_LINE = 120
MIN_INITIAL_STEP = 3
MAX_INITIAL_STEP = 6
#: Shadow-map texels per pixel of the image diagonal.
SHADOW_TEXELS_PER_PIXEL = 4
#: Slices per pixel of the image perimeter, γ texels per pixel of its diagonal (measured, above).
SLICES_PER_BORDER_PIXEL = 4
GAMMA_TEXELS_PER_PIXEL = 8


def _power_of_two_at_least(value: float) -> int:
    return 1 << max(math.ceil(math.log2(max(value, 1.0))), 0)


def _clamped(value: float, low: int, high: int) -> int:
    return min(max(_power_of_two_at_least(value), low), high)


def derived_shadow_map(width: int, height: int) -> int:
    """Shadow map side (texels, per cube face) for a width × height image."""
    return _clamped(SHADOW_TEXELS_PER_PIXEL * math.hypot(width, height), MIN_SHADOW_MAP, MAX_SHADOW_MAP)


def derived_slices(width: int, height: int, shadow_map: int) -> int:
    """Epipolar slices: 4 × the image perimeter or the shadow map side, the smaller."""
    return _clamped(min(SLICES_PER_BORDER_PIXEL * 2 * (width + height), shadow_map), MIN_SLICES, MAX_SLICES)


def derived_gamma_samples(width: int, height: int, shadow_map: int) -> int:
    """γ texels per slice: 8 × the image diagonal or the shadow map side, the smaller."""
    return _clamped(min(GAMMA_TEXELS_PER_PIXEL * math.hypot(width, height), shadow_map),
                    MIN_GAMMA_SAMPLES, MAX_GAMMA_SAMPLES)


def derived_line_samples(width: int, height: int) -> int:
    """Samples along each slice's line: half the image diagonal in pixels."""
    return min(max(math.ceil(LINE_SAMPLES_PER_PIXEL * math.hypot(width, height)), MIN_LINE_SAMPLES),
               MAX_LINE_SAMPLES)


def derived_initial_step(line_samples: int) -> int:
    """Every how many line samples one is computed: about INITIAL_SAMPLES_PER_LINE on the
    longest line, in [MIN_INITIAL_STEP, MAX_INITIAL_STEP]."""
    return min(max(line_samples // INITIAL_SAMPLES_PER_LINE, MIN_INITIAL_STEP), MAX_INITIAL_STEP)


def with_derived_sizes(scene: Scene) -> Scene:
    """The scene with every unset (None) size of `scene.render` filled in from its image;
    sizes the scene sets are kept as written."""
    render, image = scene.render, scene.image
    if None not in (render.shadow_map, render.slices, render.gamma_samples, render.line_samples,
                    render.initial_step):
        return scene
    shadow_map = render.shadow_map or derived_shadow_map(image.width, image.height)
    slices = render.slices or derived_slices(image.width, image.height, shadow_map)
    gamma_samples = render.gamma_samples or derived_gamma_samples(image.width, image.height, shadow_map)
    line_samples = render.line_samples or derived_line_samples(image.width, image.height)
    initial_step = render.initial_step or derived_initial_step(line_samples)
    return replace(scene, render=replace(render, shadow_map=shadow_map, slices=slices, gamma_samples=gamma_samples,
                                         line_samples=line_samples, initial_step=initial_step))
