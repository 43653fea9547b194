"""`clrays tune`: the cheapest render settings whose error against `exact` is at most a
target, and the tuned settings a scene asks for with `render.target_error`.

The error is measured as `clrays bench` measures it (`clrays.runs.bench`): relative
luminance RMSE against `exact` on a fixed, seeded subset of pixels, depth edges left
out, the references kept on disk (`clrays.runs.references`), so a scene's `exact` is
computed once and every setting tried is measured against it. A frame's cost is the
median of a few warm frames in one session (one where it is long: LONG_FRAME_MS), every
stage computed: of the process's CPU
time on a CPU device (a shared machine's load moves it by a few per cent, the wall time
by 1–3×), of the wall time on a GPU.

The search is coordinate descent over a ladder per knob (`knobs_for`): from the settings
as written (sizes left unset derived from the image), while the error is over the target
it takes the one-rung step, of one knob or of all of them at once, that buys the most
error per millisecond, and follows it while each rung still pays; once under the target it
takes the coarser rung that saves the most time while the target holds, until none does.
An animated scene is measured on its first, middle and last frames: the error is the
largest of them, the cost the median over all their timed frames.

A promise that holds off the sample: the search aims at SEARCH_MARGIN of the target on its
pixels, and the settings within that aim are then checked, cheapest first, on pixels it
never measured (HELD_OUT_FACTOR times as many, drawn from the rest of the image) and, for
an animation, on two frames it never measured; the first within the target there is the
answer, and where none is, the search aims lower and goes on.

One search, one answer (`tuned_settings`): `clrays tune` and a scene's `render.target_error`
share the kept tuning `tuned-<key>.json`, the key the scene (less its target and passes), the
method, the target and the search's sample and bound. Where no kept tuning is found, `render`,
`sequence` and `sweep` search only with the user's consent (`--tune`, `Consent`), state the
search's cost first, and refuse in one line a search estimated or running past
TUNE_BUDGET_S: `clrays tune` has no budget.
"""
from __future__ import annotations

import json
import math
import os
import statistics
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from ..digest import digest
from ..errors import ClraysError
from ..image_io import write_atomic
from ..outputs import cache_root, make_folders_below
from ..reference.exact import estimate_seconds
from ..reuse import scene_digest
from ..scene import gltf as gltf_files
from ..scene.costs import with_derived_sizes
from ..scene.files import FileRefused, read_regular_file
from ..scene.fields import FORMAT_VERSION, RENDER
from ..scene.yaml_tree import Node, apply_override, compose, mark_where
from ..scene.model import Scene
from ..session import Renderer
from .bench import error_pixels
from .progress import Progress
from .references import EXACT, ReferenceCache

#: Pixels the error is measured on, as `clrays bench` measures it.
TUNE_PIXELS = 4000
#: Timed frames per setting, after the frame whose image is measured (which builds the kernels).
TUNE_REPEATS = 3
#: A setting whose first timed frame costs this much (ms, `Trial.cost_ms`) is timed once: the
#: lattice's 640×360 frames of 249, 493 and 1161 ms of CPU spread by 4.5, 2.2 and 1.8 % over 7
#: runs (the since-removed bench/frame_spread.py), their first within 1.5 % of the median, below TIME_MARGIN's 3 %;
#: timed three times, the fine occluders' 0.5–1 s settings took the lattice's 640×360 search
#: past the 2 minutes asked (bench/RESULTS.md history, "Tuning the lattice at 640×360").
LONG_FRAME_MS = 200.0
#: The most settings one search measures: a survey tries 7 (each knob, and all at once), so
#: this bounds a search at about 8 surveys; a 640×360 frame of the bench scenes costs 0.05–1 s, and a
#: setting 4 of them (bench/RESULTS.md history, "Fine occluders and tuning").
MOST_SETTINGS = 60
#: Along the chosen knob, a finer rung is taken without a new survey while it cuts the error by this fraction.
LINE_GAIN = 0.15
#: A coarser setting must save this fraction of the frame time to be taken: less is the
#: noise of a median of 3 frames on a shared machine.
TIME_MARGIN = 0.03
#: A finer rung must cut the error by at least this fraction to count as progress.
ERROR_MARGIN = 0.01
#: Where the ladders stop. The shadow map at 4096: a point light's cube at 8192² holds
#: 1.5 GiB of depth alone. Slices and γ texels at 4096: a 4096² epipolar texture per light.
MOST_SHADOW_MAP = 4096
MOST_SLICES = 4096
MOST_GAMMA_SAMPLES = 4096
MOST_LINE_SAMPLES = 8192
MOST_STEPS = 4096
LEAST_REFINE_THRESHOLD = 0.0025
MOST_REFINE_THRESHOLD = 0.08
MOST_INITIAL_STEP = 16
#: Frames of an animation that are measured (first, middle, last).
ANIMATION_FRAMES = 3
#: The search aims at this fraction of the target on its own pixels: an error measured on
#: 4000 pixels is a sample's, and a grate seen looking into the light, tuned to 0.5 % on its
#: sample without a margin, measured 0.60 % against an independent reference.
SEARCH_MARGIN = 0.8
#: The chosen setting is checked on this many times the search's pixels, drawn from those the
#: search did not measure (all of them, where fewer remain; none on an image the search
#: measured whole), and where it is over the target the search aims lower, at most
#: HELD_OUT_ROUNDS times in all.
HELD_OUT_FACTOR = 4
HELD_OUT_ROUNDS = 3
HELD_OUT_SEED = 53
#: Settings within the aim checked per round, cheapest first (a check is a frame per measured
#: frame: the held-out pixels' `exact` is computed once): on the grate at 160×90, a search on
#: 4000 pixels measured 0.8 % where the other 10 400 measured 2.8 %, and at finer settings
#: 0.19 % where they measured 0.23 %: the cheapest setting within the aim may miss where the
#: next holds.
HELD_OUT_CHECKS = 8
#: What `render`, `sequence` and `sweep` may spend searching with `--tune`, in all, in
#: seconds: a longer search is refused in one line that names `clrays tune`, which has none.
#: 15 s, so that the whole command (the scene loaded, the setting measured when the time runs
#: out, the frame) ends within 20 s: a 32×18 search for an unreachable target, stopped at
#: 20 s, took 22 s in all.
TUNE_BUDGET_S = 15.0


@dataclass(frozen=True)
class Knob:
    """One render setting and its ladder: `step(value, finer)` gives the next rung towards
    less error (finer) or towards less time, ×2 or ÷2 (or the next of `choices`, coarsest
    first), None past the ladder's end."""

    key: str
    low: float = 0
    high: float = 0
    smaller_is_finer: bool = False  # initial_step, refine_threshold: a smaller value costs more
    choices: tuple = ()  # a setting of words: its values from the fastest to the finest

    def step(self, value, finer: bool):
        if self.choices:
            index = self.choices.index(value) + (1 if finer else -1)
            return self.choices[index] if 0 <= index < len(self.choices) else None
        up = finer != self.smaller_is_finer
        new = value * 2 if up else value / 2
        if isinstance(value, int):
            new = int(new)
        if new < self.low or new > self.high or new == value:
            return None
        return new


def knobs_for(method: str, sampling: str) -> tuple[Knob, ...]:
    """The settings `method` reads that trade time for error."""
    shadow_map = Knob("shadow_map", 64, MOST_SHADOW_MAP)
    if method == "raymarch":
        return shadow_map, Knob("steps", 8, MOST_STEPS)
    if method == "exact":
        return ()
    knobs = (shadow_map, Knob("slices", 16, MOST_SLICES), Knob("gamma_samples", 16, MOST_GAMMA_SAMPLES))
    if method == "minmax" and sampling == "epipolar":
        knobs += (Knob("line_samples", 16, MOST_LINE_SAMPLES), Knob("initial_step", 1, MOST_INITIAL_STEP, True),
                  Knob("refine_threshold", LEAST_REFINE_THRESHOLD, MOST_REFINE_THRESHOLD, True))
    if method == "minmax":  # the runs' ends at the texels are the faster, on the blockers the finer
        knobs += (Knob("shaft_edges", choices=("texels", "blockers")),)
    return knobs


@dataclass
class Trial:
    """One setting measured: its values, the largest error over the frames measured
    (relative RMSE, a fraction) and the median frame time over every timed frame."""

    settings: dict
    rmse: float
    frame_ms: float
    failed: str = ""  # why the setting did not render (its error and times are then inf)
    #: What the search compares: the process's CPU time per frame on a CPU device (every
    #: OpenCL thread's; other processes on a shared machine move it by a few per cent, the
    #: wall time by 1-3x: bench/RESULTS.md history), the wall time on a GPU. Median, as frame_ms.
    cost_ms: float = math.nan


@dataclass
class Tuning:
    """A search's outcome: `best` the cheapest trial at or under `aim` on the search's pixels
    whose error off them (`held_out`) is within `target` too (None: not reached), `closest`
    the lowest error found, and every trial in order."""

    target: float
    method: str
    trials: list[Trial] = field(default_factory=list)
    seconds: float = 0.0
    default: Trial | None = None
    #: (best, default) frame ms timed again in turns at the end, so that a change of the
    #: machine's load during the search does not favour either (None: no best).
    in_turns: tuple[float, float] | None = None
    best: Trial | None = None
    #: What the search last aimed at on its own pixels (SEARCH_MARGIN of the target, or lower).
    aim: float = math.nan
    #: `best`'s largest error on the held-out pixels and frames (None: nothing was held out).
    held_out: float | None = None
    #: Each setting the held-out check measured, and its error there.
    checked: list[tuple[Trial, float | None]] = field(default_factory=list)

    @property
    def closest(self) -> Trial:
        return min(self.trials, key=lambda trial: trial.rmse)


def settings_text(settings: dict) -> str:
    return " ".join(f"{key}={value:g}" if isinstance(value, float) else f"{key}={value}"
                    for key, value in settings.items())


def measured_frames(scene: Scene) -> list[Scene]:
    """The still scenes the error is measured on: the scene itself, or for an animation
    its first, middle and last frames."""
    if scene.animation is None:
        return [scene]
    frames = scene.animation.frames
    chosen = sorted({frames[0], frames[len(frames) // 2], frames[-1]})[:ANIMATION_FRAMES]
    return [scene.animation.scene_at(scene, frame) for frame in chosen]


def held_out_frames(scene: Scene) -> list[Scene]:
    """Frames of an animation the search does not measure and the chosen setting is checked
    on: those a quarter and three quarters of the way (none where they are measured ones)."""
    if scene.animation is None:
        return []
    frames = scene.animation.frames
    measured = {frames[0], frames[len(frames) // 2], frames[-1]}
    chosen = sorted({frames[len(frames) // 4], frames[3 * len(frames) // 4]} - measured)
    return [scene.animation.scene_at(scene, frame) for frame in chosen]


def held_out_pixels(width: int, height: int, searched: tuple[np.ndarray, np.ndarray],
                    count: int) -> tuple[np.ndarray, np.ndarray] | None:
    """A fixed, seeded subset of `count` pixels that `searched` does not hold (all of them
    where fewer remain; None where `searched` is the whole image)."""
    seen = np.zeros(width * height, dtype=bool)
    seen[searched[0] * width + searched[1]] = True
    rest = np.flatnonzero(~seen)
    if not rest.size:
        return None
    if rest.size > count:
        rest = np.sort(np.random.default_rng(HELD_OUT_SEED).choice(rest, size=count, replace=False))
    return np.divmod(rest, width)


def with_settings(scene: Scene, settings: dict) -> Scene:
    return replace(scene, render=replace(scene.render, target_error=None, **settings))


class OverBudget(ClraysError):
    """A search ran past its deadline (`Consent`)."""


class Search:
    """Measures settings of one scene: error against `exact` on the pixel subset of each
    measured frame, and frame time; each setting at most once. Past `deadline` (a
    `time.perf_counter()` value) a measure raises OverBudget."""

    def __init__(self, scene: Scene, method: str, references: ReferenceCache, renderer: Renderer,
                 pixels: int = TUNE_PIXELS, repeats: int = TUNE_REPEATS, on_trial: Callable[[Trial], None] = None,
                 deadline: float | None = None):
        self.frames = [replace(frame, render=replace(frame.render, method=method)) for frame in measured_frames(scene)]
        self.held_out_frames = [replace(frame, render=replace(frame.render, method=method))
                                for frame in held_out_frames(scene)]
        self.method = method
        self.references = references
        self.renderer = renderer
        image = scene.image
        self.pixels = error_pixels(image.width, image.height, pixels)
        self.held_out_pixels = held_out_pixels(image.width, image.height, self.pixels, HELD_OUT_FACTOR * pixels)
        self.repeats = repeats
        self.on_trial = on_trial or (lambda trial: None)
        self.deadline = deadline
        self.trials: dict[tuple, Trial] = {}
        import pyopencl as cl

        self.on_cpu = bool(renderer.device.device.type & cl.device_type.CPU)

    def measure(self, settings: dict) -> Trial:
        key = _key(settings)
        if key in self.trials:
            return self.trials[key]
        self._check_deadline()
        worst, times = 0.0, []
        for frame in self.frames:
            variant = with_settings(frame, settings)
            try:
                image = self.renderer.render(variant, reuse=False).image  # also builds the kernels
            except ClraysError as exc:  # e.g. past the device's memory: a setting the search cannot take
                trial = self.trials[key] = Trial(dict(settings), math.inf, math.inf, str(exc), math.inf)
                self.on_trial(trial)
                return trial
            worst = max(worst, self._error(frame, image, self.pixels))
            for repeat in range(self.repeats):
                times.append(self._timed(variant))
                if repeat == 0 and times[-1][1] >= LONG_FRAME_MS:
                    break  # a long frame: one is as good as the median of three
        walls, costs = zip(*times)
        trial = Trial(dict(settings), worst, statistics.median(walls), cost_ms=statistics.median(costs))
        self.trials[key] = trial
        self.on_trial(trial)
        return trial

    def held_out(self, settings: dict) -> float | None:
        """The largest error of `settings` off the search's sample: on the held-out pixels of
        every frame, and on the search's pixels too of the held-out frames (None: nothing is
        held out, the search measured every pixel of every frame there is)."""
        samples = [(frame, [self.held_out_pixels]) for frame in self.frames if self.held_out_pixels is not None]
        samples += [(frame, [pixels for pixels in (self.pixels, self.held_out_pixels) if pixels is not None])
                    for frame in self.held_out_frames]
        worst = None
        for frame, pixel_sets in samples:
            self._check_deadline()
            image = self.renderer.render(with_settings(frame, settings), reuse=False).image
            worst = max([worst or 0.0] + [self._error(frame, image, pixels) for pixels in pixel_sets])
        return worst

    def frame_ms(self, settings: dict) -> float:
        """Wall ms of a warm frame of `settings` on the first measured frame (after one that
        builds its kernels), for the estimate of a search's cost."""
        variant = with_settings(self.frames[0], settings)
        self.renderer.render(variant, reuse=False)
        return self._timed(variant)[0]

    def estimate(self, frame_ms: float, most_settings: int) -> tuple[float, str]:
        """(seconds, the line that says what they buy): at most `most_settings` settings, each
        a measured frame and its timed ones per frame, the two settings timed in turns at the
        end, and `exact` on the search's and the held-out pixels (a frame of `frame_ms`)."""
        repeats = 1 if frame_ms >= LONG_FRAME_MS else self.repeats
        renders = ((most_settings + 4) * len(self.frames) * (1 + repeats)  # the settings, and the two timed in turns
                   + HELD_OUT_ROUNDS * HELD_OUT_CHECKS * (len(self.frames) + len(self.held_out_frames)))
        held_out = len(self.held_out_pixels[0]) if self.held_out_pixels is not None else 0
        searched = len(self.pixels[0])
        exact_pixels = (searched + held_out) * (len(self.frames) + len(self.held_out_frames))
        exact_s = sum(estimate_seconds(frame, searched + held_out) for frame in self.frames + self.held_out_frames)
        seconds = renders * frame_ms / 1e3 + exact_s
        image = self.frames[0].image
        return seconds, (f"at most {most_settings} settings of {image.width}×{image.height}, {renders} frames of "
                         f"about {frame_ms:.0f} ms, and exact on {exact_pixels} pixels (about {exact_s:.0f} s): "
                         f"about {seconds:.0f} s in all")

    def _error(self, frame: Scene, image: np.ndarray, pixels) -> float:
        error = self.references.error(frame, EXACT, image, pixels)
        if not error.pixels:
            raise ClraysError(f"{frame.source or 'scene'}: at {frame.image.width}x{frame.image.height} no pixel "
                              f"is left to compare against exact (each is dark or on a depth edge); tune it "
                              f"at a larger image")
        return error.rmse

    def _check_deadline(self) -> None:
        if self.deadline is not None and time.perf_counter() > self.deadline:
            raise OverBudget(f"past its budget after {len(self.trials)} settings")

    def in_turns(self, first: dict, second: dict, turns: int = 2) -> tuple[float, float]:
        """Median frame ms of two settings timed in turns: each turn a warm-up frame (a
        change of sizes rebuilds kernels and buffers) and `repeats` timed frames of one,
        then of the other."""
        times: tuple[list, list] = ([], [])
        for _ in range(turns):
            for settings, kept in zip((first, second), times):
                for frame in self.frames:
                    self._check_deadline()
                    variant = with_settings(frame, settings)
                    self.renderer.render(variant, reuse=False)
                    kept.extend(self._timed(variant)[0] for _ in range(self.repeats))
        return statistics.median(times[0]), statistics.median(times[1])

    def _timed(self, scene: Scene) -> tuple[float, float]:
        """(wall ms, cost ms) of one frame, every stage computed (Trial.cost_ms)."""
        start, start_cpu = time.perf_counter(), time.process_time()
        self.renderer.render(scene, reuse=False)
        wall = (time.perf_counter() - start) * 1e3
        return wall, (time.process_time() - start_cpu) * 1e3 if self.on_cpu else wall


def _key(settings: dict) -> tuple:
    return tuple(sorted(settings.items()))


def start_settings(scene: Scene, method: str) -> dict:
    """The settings as the scene renders them: sizes it leaves unset derived from the image."""
    render = with_derived_sizes(replace(scene, render=replace(scene.render, method=method))).render
    return {knob.key: getattr(render, knob.key) for knob in knobs_for(method, render.sampling)}


def _method_of(scene: Scene, method: str | None) -> str:
    method = method or scene.render.method
    if method == "exact":
        raise ClraysError(f"{scene.source or 'scene'}: render.method exact is the reference itself: it has no "
                          f"settings to tune (tune minmax, raymarch or volume_moments)")
    return method


def tune(scene: Scene, target: float, references: ReferenceCache, renderer: Renderer | None = None,
         method: str | None = None, pixels: int = TUNE_PIXELS, repeats: int = TUNE_REPEATS,
         most_settings: int = MOST_SETTINGS, on_trial: Callable[[Trial], None] = None,
         search: Search | None = None, log: Callable[[str], None] = lambda line: None,
         margin: float = SEARCH_MARGIN) -> Tuning:
    """Search the settings of `scene` for the cheapest frame whose relative RMSE against
    `exact` (a fraction; `target` too) is at most `target` (module docstring): at most
    SEARCH_MARGIN of it on the search's pixels, and at most it on the held-out ones.
    `method`: the method to tune (default: the scene's). `on_trial(trial)` after each
    setting; `search`: one already made (`tuned_settings`, which times a frame first);
    `log(line)` when the held-out check sends the search lower; `margin`: the fraction of
    the target aimed at (bench/RESULTS.md, "Tuning", compares 1 without the held-out check)."""
    method = _method_of(scene, method)
    renderer = renderer or Renderer(reuse=False)
    search = search or Search(scene, method, references, renderer, pixels, repeats, on_trial)
    knobs = knobs_for(method, scene.render.sampling)
    started = time.perf_counter()
    current = search.measure(start_settings(scene, method))
    tuning = Tuning(target, method, default=current, aim=target * margin)
    checked: dict[tuple, float | None] = {}
    for _ in range(HELD_OUT_ROUNDS):
        _descend(search, knobs, current, tuning.aim, most_settings)
        good = sorted((trial for trial in search.trials.values() if trial.rmse <= tuning.aim),
                      key=lambda trial: trial.cost_ms)
        if not good:
            break
        current = good[0]
        missed = []
        for trial in [trial for trial in good if _key(trial.settings) not in checked][:HELD_OUT_CHECKS]:
            held_out = checked[_key(trial.settings)] = search.held_out(trial.settings)
            tuning.checked.append((trial, held_out))
            if held_out is None or held_out <= target:
                tuning.best, tuning.held_out = trial, held_out
                break
            missed.append((trial, held_out))
        if tuning.best is not None or not missed:
            break
        # Over the target off the sample: aim lower, as the sample's error would have to be for
        # the setting that missed by the least to hold (and by the margin at least).
        tuning.aim = margin * min(tuning.aim, max(trial.rmse * target / held_out for trial, held_out in missed))
        trial, held_out = min(missed, key=lambda miss: miss[1])
        log(f"clrays: tune: {settings_text(trial.settings)}: {100 * held_out:.3f} % on held-out pixels and "
            f"frames, over {100 * target:g} %; aiming at {100 * tuning.aim:.3f} %")
    tuning.trials = list(search.trials.values())
    if tuning.best is not None and not tuning.default.failed:  # (a start that did not render has no time)
        tuning.in_turns = search.in_turns(tuning.best.settings, tuning.default.settings)
    tuning.seconds = time.perf_counter() - started
    return tuning


def _descend(search: Search, knobs: tuple[Knob, ...], current: Trial, aim: float, most_settings: int) -> Trial:
    """Coordinate descent from `current` to the cheapest setting found at or under `aim` on
    the search's pixels (module docstring); ends at `most_settings` settings measured."""

    def moved(settings: dict, keys: tuple[str, ...], finer: bool) -> dict | None:
        """`settings` with each knob of `keys` one rung on (None where none can move)."""
        changes = {knob.key: knob.step(settings[knob.key], finer) for knob in knobs if knob.key in keys}
        changes = {key: value for key, value in changes.items() if value is not None}
        return {**settings, **changes} if changes else None

    # One knob at a time, and every knob at once: where the error is the largest of several
    # frames, or one size caps what another buys, no single knob may move it.
    moves = [(knob.key,) for knob in knobs] + ([tuple(knob.key for knob in knobs)] if len(knobs) > 1 else [])

    def neighbours(trial: Trial, finer: bool) -> list[tuple[tuple[str, ...], Trial]]:
        found = []
        for keys in moves:
            settings = moved(trial.settings, keys, finer)
            if settings is not None and len(search.trials) < most_settings:
                found.append((keys, search.measure(settings)))
        return found

    # A start that does not render (past the device's memory): every knob a rung coarser at
    # a time until one does, and the search goes on from there.
    while current.failed and len(search.trials) < most_settings:
        settings = moved(current.settings, tuple(knob.key for knob in knobs), False)
        if settings is None:
            break
        current = search.measure(settings)
    # Over the aim: the finer rung that buys the most error per millisecond (a third of
    # the settings kept for the way back, where a rung taken overshoots).
    growing = most_settings - most_settings // 3
    while current.rmse > aim and len(search.trials) < growing:
        better = [(keys, trial) for keys, trial in neighbours(current, True)
                  if trial.rmse < current.rmse * (1 - ERROR_MARGIN)]
        if not better:
            break
        reached = [trial for _, trial in better if trial.rmse <= aim]
        if reached:  # the cheapest step that reaches it
            current = min(reached, key=lambda trial: trial.cost_ms)
            break
        keys, current = max(better, key=lambda move: (current.rmse - move[1].rmse)
                            / max(move[1].cost_ms - current.cost_ms, 0.01 * current.cost_ms))
        # Further along the same move while each rung still cuts the error by LINE_GAIN: a
        # rung costs one setting, a survey of every move seven.
        while current.rmse > aim and len(search.trials) < growing:
            settings = moved(current.settings, keys, True)
            if settings is None:
                break
            trial = search.measure(settings)
            if trial.rmse > current.rmse * (1 - LINE_GAIN):
                break
            current = trial
    # Under it: the coarser rung that saves the most time while the aim holds.
    while current.rmse <= aim and len(search.trials) < most_settings:
        cheaper = [trial for _, trial in neighbours(current, False)
                   if trial.rmse <= aim and trial.cost_ms < current.cost_ms * (1 - TIME_MARGIN)]
        if not cheaper:
            break
        current = min(cheaper, key=lambda trial: trial.cost_ms)
    return current


def unreachable(source: str, tuning: Tuning) -> ClraysError:
    closest = tuning.closest
    if tuning.checked:  # the search's pixels met its aim, the pixels it did not measure not the target
        trial, held_out = min(tuning.checked, key=lambda check: check[1])
        return ClraysError(f"{source}: target error {100 * tuning.target:g} %: not held off the search's pixels; the "
                           f"closest setting measured {100 * trial.rmse:.3f} % on them and {100 * held_out:.3f} % on "
                           f"pixels and frames it did not measure ({settings_text(trial.settings)}, "
                           f"{len(tuning.trials)} settings tried; --most-settings allows more)")
    margin = (f" with its margin (at most {100 * tuning.aim:.3g} % on the search's pixels)"
              if closest.rmse <= tuning.target else "")
    return ClraysError(f"{source}: target error {100 * tuning.target:g} %: not reached{margin}; the best error found "
                       f"is {100 * closest.rmse:.3f} % ({settings_text(closest.settings)}, {len(tuning.trials)} "
                       f"settings tried)")


# --------------------------------------------------------------------------- render.target_error


@dataclass
class Consent:
    """Whether a run may search for settings it finds no kept tuning for (`--tune`), and what
    its searches may take in all (seconds; None: no limit, `clrays tune`)."""

    given: bool = False
    budget_s: float | None = field(default_factory=lambda: TUNE_BUDGET_S)
    spent_s: float = 0.0


@dataclass(frozen=True)
class Tuned:
    """Settings a target is met with, and what the tuning measured: `rmse` the largest error
    on the search's pixels, `held_out` off them (None: nothing was held out)."""

    settings: dict
    rmse: float
    frame_ms: float
    target: float
    held_out: float | None
    cached: bool  # read from a kept tuning rather than searched now

    def line(self) -> str:
        held_out = "" if self.held_out is None else f" ({100 * self.held_out:.3f} % held out)"
        return (f"tuned for {100 * self.target:g} %: {settings_text(self.settings)}; error against exact "
                f"{100 * self.rmse:.3f} %{held_out}, {self.frame_ms:.0f} ms a frame when tuned"
                + (" (cached)" if self.cached else ""))


#: A kept tuning (tuned-<key>.json): a few hundred bytes.
MAX_TUNED_BYTES = 64 << 10
#: The keys of a kept tuning.
TUNED_KEYS = ("settings", "rmse", "frame_ms", "target", "held_out", "cached")


def tuning_key(scene: Scene, method: str, target: float, pixels: int = TUNE_PIXELS,
               most_settings: int = MOST_SETTINGS) -> str:
    """What a kept tuning is found by: each frame the search and its check measure, as it
    renders (not its source path, its target or its render passes, which change what a frame
    writes, not its error), the method, the target (a fraction) and the search's sample and
    bound."""
    frames = [replace(frame, source=None, render=replace(frame.render, aovs=(), target_error=None, method=method))
              for frame in measured_frames(scene) + held_out_frames(scene)]
    return digest("tuned", *map(scene_digest, frames), method, float(target), pixels, most_settings,
                  SEARCH_MARGIN, HELD_OUT_FACTOR).hex()[:24]


def tuned_settings(scene: Scene, target: float, folders: list[Path], consent: Consent, method: str | None = None,
                   renderer: Renderer | None = None, progress: bool = False,
                   log: Callable[[str], None] = lambda line: None, pixels: int = TUNE_PIXELS,
                   most_settings: int = MOST_SETTINGS, how_to_tune: str = "",
                   asked_by: str = "render.target_error", below: Path | None = None) -> tuple[Tuned, Tuning | None]:
    """The settings of `scene` for `target` (a fraction), and the search that found them
    (None: a kept tuning). The one search of `clrays tune` and `render.target_error`: a
    tuning kept in any of `folders` (tuned-<key>.json, `tuning_key`) is read, and copied to
    the folders before it that lack it; else, with `consent`, the search runs, `log` saying
    its cost first and each setting tried where no bar shows, and its result is kept in every
    folder. The exact references are kept in `folders[0]`. ClraysError: no consent, a search
    over `consent`'s budget (`how_to_tune`: how to run it anyway), an unreachable target
    (`asked_by`: what asked for it, as the line names it). below: the user's folder that
    the folders within it lie in (a sweep's, a sequence's), where clrays makes them: a link
    there is one line before anything is read (clrays.outputs)."""
    method = _method_of(scene, method)
    source = scene.source or "scene"
    knobs = knobs_for(method, scene.render.sampling)
    name = f"tuned-{tuning_key(scene, method, target, pixels, most_settings)}.json"
    for index, folder in enumerate(folders):
        if os.path.lexists(folder):  # a link where clrays makes the folder: one line before anything is read
            make_folders_below(_base(folder, below), folder, "the reference folder")
        tuned = _read_tuned(folder / name, target, knobs)
        if tuned is not None:
            for earlier in folders[:index]:
                _keep_tuned(earlier / name, tuned, _base(earlier, below))
            return tuned, None
    anyway = how_to_tune or "run `clrays tune` first"
    if not consent.given:
        raise ClraysError(f"{source}: render.target_error {100 * target:g} %: no tuned settings are kept for it, "
                          f"and finding them is a search of many renders: add --tune to search now (refused "
                          f"past {consent.budget_s:g} s), or {anyway}")
    renderer = renderer or Renderer()
    timing = Renderer(renderer.device, reuse=False)  # every stage computed
    references = ReferenceCache(folders[0], renderer, progress, below=_base(folders[0], below))
    started = time.perf_counter()
    # The cost, before the search: from one timed frame of the start (after the one that builds its kernels).
    search = Search(scene, method, references, timing, pixels, TUNE_REPEATS)
    try:
        seconds, what = search.estimate(search.frame_ms(start_settings(scene, method)), most_settings)
    except ClraysError:  # the start does not render: the search steps down from it, at a cost unknown
        seconds, what = math.inf, f"at most {most_settings} settings"
    left = None if consent.budget_s is None else consent.budget_s - consent.spent_s
    over = f"{source}: render.target_error {100 * target:g} %: the search for its settings"
    if left is not None and seconds > left:
        raise ClraysError(f"{over} ({what}) would take longer than the {consent.budget_s:g} s a render gives it: "
                          f"{anyway}")
    log(f"clrays: tune: for {100 * target:g} %: {what}" + ("" if left is None else f" (refused past {left:.0f} s)"))
    search.deadline = None if left is None else started + left
    with Progress(progress, most_settings, "setting", "tune") as bar:
        def on_trial(trial: Trial) -> None:
            bar.advance(f"{settings_text(trial.settings)}: {100 * trial.rmse:.3f} %")
            if not progress:
                log(trial_line(trial))

        search.on_trial = on_trial
        try:
            tuning = tune(scene, target, references, timing, method, pixels, most_settings=most_settings,
                          search=search, log=log)
        except OverBudget as exc:
            raise ClraysError(f"{over} ran {exc}, {consent.budget_s:g} s: {anyway}") from None
        finally:
            consent.spent_s += time.perf_counter() - started
    best = tuning.best
    if best is None:
        raise unreachable(f"{source}: {asked_by}", tuning)
    tuned = Tuned(best.settings, best.rmse, best.frame_ms, target, tuning.held_out, False)
    for folder in folders:
        _keep_tuned(folder / name, tuned, _base(folder, below))
    return tuned, tuning


def tuned_scene(scene: Scene, method: str | None = None, folders: list[Path] | None = None,
                consent: Consent | None = None, renderer: Renderer | None = None, progress: bool = False,
                log: Callable[[str], None] | None = None, how_to_tune: str = "",
                below: Path | None = None) -> tuple[Scene, Tuned | None]:
    """`scene` with the settings its `render.target_error` asks for (unchanged, and None,
    where it sets none, or renders with exact, the reference the target is measured
    against), by `tuned_settings` (default folders: clrays' cache, `cache_root()`; default consent: none;
    `below` as there)."""
    percent = scene.render.target_error
    if percent is None or (method or scene.render.method) == "exact":
        return scene, None
    tuned, _ = tuned_settings(scene, percent / 100, folders or [cache_root()], consent or Consent(), method,
                              renderer, progress, log or (lambda line: print(line, file=sys.stderr)),
                              how_to_tune=how_to_tune, below=below)
    return with_settings(scene, tuned.settings), tuned


def _base(folder: Path, below: Path | None) -> Path:
    """The folder the user named that `folder` is made in: `below` where it lies there, else itself."""
    return below if below is not None and Path(folder).is_relative_to(below) else folder


def _keep_tuned(path: Path, tuned: Tuned, base: Path) -> None:
    make_folders_below(base, path.parent, "the reference folder")
    text = json.dumps({**asdict(tuned), "cached": None}, indent=1)
    write_atomic(path, lambda temporary: Path(temporary).write_text(text, encoding="utf-8"))


class BadTuning(ValueError):
    """A kept tuning that is not one clrays wrote for this scene and target."""


def _read_tuned(path: Path, target: float, knobs: tuple[Knob, ...]) -> Tuned | None:
    """The kept tuning at `path`, or None where there is none, or (with a one-line notice on
    stderr naming the file, the field and the value) where it is not what clrays writes: JSON
    with exactly TUNED_KEYS; `settings` exactly the method's knobs within the scene format's
    ranges; `rmse` finite, from 0 to the target; `held_out` null or so; `frame_ms` finite and
    positive; `target` this one. The scene is then tuned again, as where none is kept."""
    if not os.path.lexists(path):
        return None
    try:
        try:
            data = json.loads(read_regular_file(path, MAX_TUNED_BYTES, follow_links=False).decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise BadTuning(f"not JSON ({exc})") from None
        if not isinstance(data, dict) or set(data) != set(TUNED_KEYS):
            keys = sorted(data) if isinstance(data, dict) else type(data).__name__
            raise BadTuning(f"expected the keys {', '.join(TUNED_KEYS)}, got {keys}")
        settings = _checked_settings(data["settings"], knobs)
        rmse = _checked_number(data, "rmse", 0.0, target)
        held_out = None if data["held_out"] is None else _checked_number(data, "held_out", 0.0, target)
        frame_ms = _checked_number(data, "frame_ms", 0.0, math.inf, low_open=True)
        if _checked_number(data, "target", 0.0, 1.0) != target:
            raise BadTuning(f"target: expected {target!r}, got {data['target']!r}")
        if data["cached"] is not None:
            raise BadTuning(f"cached: expected null, got {data['cached']!r}")
        return Tuned(settings, rmse, frame_ms, target, held_out, True)
    except (FileRefused, OSError, BadTuning) as exc:
        print(f"clrays: notice: {path}: {str(exc).splitlines()[0]}; the kept tuning is ignored", file=sys.stderr)
        return None


def _checked_settings(settings, knobs: tuple[Knob, ...]) -> dict:
    """Exactly the method's knobs, each of its field's type and within its range."""
    names = [knob.key for knob in knobs]
    if not isinstance(settings, dict) or set(settings) != set(names):
        got = sorted(settings) if isinstance(settings, dict) else repr(settings)
        raise BadTuning(f"settings: expected the keys {', '.join(names)}, got {got}")
    for key, value in settings.items():
        field = RENDER[key]
        if field.choices:
            if value not in field.choices:
                raise BadTuning(f"settings.{key}: expected one of {', '.join(field.choices)}, got {value!r}")
            continue
        number = int if field.type == "integer" else (int, float)
        if isinstance(value, bool) or not isinstance(value, number) or not math.isfinite(value) \
                or not field.low <= value <= field.high:
            raise BadTuning(f"settings.{key}: expected a{'n integer' if field.type == 'integer' else ' number'} from "
                            f"{field.low:g} to {field.high:g}, got {value!r}")
    return {name: settings[name] for name in names}


def _checked_number(data: dict, key: str, low: float, high: float, low_open: bool = False) -> float:
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value < low or value > high or (low_open and value == low):
        raise BadTuning(f"{key}: expected a finite number {'over' if low_open else 'from'} {low:g}"
                        + (f" to {high:g}" if math.isfinite(high) else "") + f", got {value!r}")
    return float(value)


def trial_line(trial: Trial) -> str:
    if trial.failed:
        return f"clrays: tune: {settings_text(trial.settings)}: not rendered: {trial.failed}"
    cpu = f" (CPU {trial.cost_ms:.0f} ms)" if trial.cost_ms != trial.frame_ms else ""
    return f"clrays: tune: {settings_text(trial.settings)}: {100 * trial.rmse:.3f} %, {trial.frame_ms:.0f} ms{cpu}"


# --------------------------------------------------------------------------- writing the tuned scene


def write_tuned_yaml(source: Path, output: Path, settings: dict, overrides=()) -> None:
    """Write the scene file `source` to `output` with `settings` in its `render` mapping
    and no `target_error` (`with_render_settings`: only those keys' text changes, every
    other byte of the file stays as written), unless `overrides` (`--set`) change it or
    `output` lies in another folder: then the file is written out again (comments at its
    top kept), with its overrides applied and its relative file paths (meshes, textures,
    depth maps) made relative to `output`'s folder. A glTF `source` is written as the YAML
    scene that imports it (`gltf: {file: ...}`), with the overrides."""
    import yaml

    if source.suffix.lower() in gltf_files.SUFFIXES:  # binary or JSON: the YAML scene that brings it in
        width, height = gltf_files.DEFAULT_IMAGE
        text = (f"# {source.name} with tuned render settings (clrays tune)\nversion: {FORMAT_VERSION}\n"
                f"image: {{width: {width}, height: {height}}}\ngltf: {{file: {json.dumps(source.name)}}}\n")
    else:
        text = source.read_text(encoding="utf-8")
    moved = output.resolve().parent != source.resolve().parent
    if overrides or moved:
        root = compose(text, "", mark_where(str(source)), str(source))
        for override in overrides:
            apply_override(root, override)
        data = _plain(root)
        if moved:
            _rebase_paths(data, source.parent, output.parent)
        header = "".join(line for line in text.splitlines(keepends=True)[:_leading_comments(text)])
        text = header + yaml.safe_dump(data, default_flow_style=None, sort_keys=False, width=100, allow_unicode=True)
    new = with_render_settings(text, settings)
    write_atomic(output, lambda temporary: Path(temporary).write_text(new, encoding="utf-8"))


def with_render_settings(text: str, settings: dict) -> str:
    """The scene text `text` with `settings` in its top-level `render` mapping and no
    `render.target_error`, every other byte as written: ruamel.yaml's round-trip composer
    gives each key's and value's place in the text, a value there is replaced by the new
    one, a key not there is added after the mapping's last (`, key: value` in a flow
    mapping, a line at the keys' indent in a block one), `target_error` is cut out (in a
    block mapping with its line, whose comment spoke of it), and a file without `render`
    (or with an empty one) gets `render: {...}`."""
    from ruamel.yaml import YAML
    from ruamel.yaml.nodes import MappingNode

    root = YAML().compose(text)
    pairs = root.value if isinstance(root, MappingNode) else []
    found = [(key, value) for key, value in pairs if key.value == "render"]
    flow = "{" + ", ".join(f"{key}: {_yaml_scalar(value)}" for key, value in settings.items()) + "}"
    if not found:
        return text + ("" if text.endswith("\n") or not text else "\n") + f"render: {flow}\n"
    key_node, render = found[-1]
    items = list(render.value) if isinstance(render, MappingNode) else []
    kept = [(key, value) for key, value in items if key.value != "target_error"]
    if not kept:  # `render:`, `render: {}`, `render: null`, or only a target: the mapping anew
        end = render.end_mark.index
        return (text[:key_node.start_mark.index] + f"render: {flow}"
                + ("\n" if text[key_node.start_mark.index:end].endswith("\n") else "") + text[end:])
    edits = []  # (start, end, new text), applied from the end of the file back
    for index, (key, value) in enumerate(items):
        if key.value in settings:
            edits.append((value.start_mark.index, value.end_mark.index, _yaml_scalar(settings[key.value])))
        elif key.value == "target_error":
            edits.append(_cut(text, items, index, render.flow_style))
    added = [(key, value) for key, value in settings.items() if key not in {key.value for key, _ in items}]
    if added:
        last = kept[-1][1].end_mark.index
        if render.flow_style:
            edits.append((last, last, "".join(f", {key}: {_yaml_scalar(value)}" for key, value in added)))
        else:  # after the last kept key's line, at the keys' indent
            indent = " " * kept[0][0].start_mark.column
            line_end = _line_end(text, last)
            edits.append((line_end, line_end, ("" if text[:line_end].endswith("\n") else "\n")
                          + "".join(f"{indent}{key}: {_yaml_scalar(value)}\n" for key, value in added)))
    for start, end, new in sorted(edits, key=lambda edit: edit[0], reverse=True):
        text = text[:start] + new + text[end:]
    return text


def _cut(text: str, items: list, index: int, flow: bool) -> tuple[int, int, str]:
    """The edit that removes the `index`th key and its value of a mapping's `items`."""
    key, value = items[index]
    if flow:  # with the comma before it, or after it where it is the first
        if index > 0:
            return items[index - 1][1].end_mark.index, value.end_mark.index, ""
        if len(items) > 1:
            return key.start_mark.index, items[1][0].start_mark.index, ""
        return key.start_mark.index, value.end_mark.index, ""
    return text.rfind("\n", 0, key.start_mark.index) + 1, _line_end(text, value.end_mark.index), ""


def _line_end(text: str, index: int) -> int:
    """Where the line that holds the character before `index` ends, its newline included."""
    end = text.find("\n", max(index - 1, 0))
    return len(text) if end < 0 else end + 1


def _yaml_scalar(value) -> str:
    """A setting as YAML reads it back: numbers as JSON spells them, words plain."""
    if isinstance(value, str):
        return value if value.replace("_", "").isalnum() else json.dumps(value)
    return json.dumps(value)


def _plain(node: Node):
    """A composed scene tree as plain lists, dicts and scalars."""
    if isinstance(node.value, dict):
        return {key: _plain(value) for key, value in node.value.items()}
    if isinstance(node.value, list):
        return [_plain(item) for item in node.value]
    return node.value


def _leading_comments(text: str) -> int:
    """How many lines at the top of `text` are comments."""
    count = 0
    for line in text.splitlines():
        if not line.startswith("#"):
            break
        count += 1
    return count


def _rebase_paths(data: dict, source_dir: Path, output_dir: Path) -> None:
    """Relative file paths of the scene (light textures, meshes, relief images, a glTF file) made
    relative to `output_dir` instead of `source_dir`."""
    def rebased(value):
        if isinstance(value, str) and value.strip() and not Path(value).is_absolute():
            return os.path.relpath(source_dir.resolve() / value, output_dir.resolve())
        return value

    for light in data.get("lights") or []:
        if isinstance(light, dict) and "texture" in light:
            texture = light["texture"]
            light["texture"] = [rebased(item) for item in texture] if isinstance(texture, list) else rebased(texture)
    for item in data.get("objects") or []:
        if isinstance(item, dict):
            for key in ("file", "depth_map", "albedo_map"):
                if key in item:
                    item[key] = rebased(item[key])
    if isinstance(data.get("gltf"), dict) and "file" in data["gltf"]:
        data["gltf"]["file"] = rebased(data["gltf"]["file"])


def default_trial_line(tuning: Tuning) -> str:
    """The start of the search (the settings as written or derived) beside the result, their
    frames timed in turns."""
    default = tuning.default
    if default.failed:
        return f"as written: not rendered ({default.failed})"
    text = f"as written: {100 * default.rmse:.3f} %"
    if tuning.in_turns is not None:
        best_ms, default_ms = tuning.in_turns
        text += f", {default_ms:.0f} ms a frame against {best_ms:.0f} ms tuned (timed in turns)"
    return text
