"""Reference raymarch: in-scattering by `render.steps` samples per camera ray and light,
equiangular about a point or spot light or uniform (`render.step_spacing`), a shadow-map
lookup per sample. Host side of `cl/raymarch.cl`."""
from __future__ import annotations

import time
from typing import Callable

from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from ..scene.model import STEP_SPACINGS
from .features import feature_args, feature_defines, present
from .medium import medium_feature
from .raster import RasterResult


#: Parts a raymarch with progress is cut into, marched one after another (camera samples
#: in order), so that a bar or a line can move between them.
PROGRESS_PARTS = 20
#: The first part tells how long the march will take: one expected to end within this
#: many seconds marches the rest in one launch (a split costs one wait), a longer one goes
#: on in parts.
PROGRESS_MIN_S = 2.0
#: Lines (progress off a terminal) start once a raymarch has run this long: a quick frame
#: says nothing, a long one says how far it is every PROGRESS_LINE_PERCENT.
PROGRESS_LINES_AFTER_S = 5.0
PROGRESS_LINE_PERCENT = 10


def raymarch(device: Device, buffers: FrameBuffers, rastered: RasterResult, scatter, timer: StageTimer,
             layers=None, walk=None, progress=None, only_light: int | None = None) -> None:
    """Write every camera sample's in-scattered radiance (float4, rgb) into `scatter`.
    `layers`: the translucency stage's, looked up per step (None: an opaque-only scene).
    `walk`: (work items, defines, arguments, label) of MBOIT's weighted fog march
    (clrays.stages.transparency_walk), which marches only the samples with films.
    `progress`: True for a tqdm bar, or a function that takes a line of text (lines every
    PROGRESS_LINE_PERCENT once PROGRESS_LINES_AFTER_S have passed); the samples are then
    marched in PROGRESS_PARTS launches where the first says the march is long.
    `only_light`: march that light alone (a render pass of its in-scattering)."""
    work_items, label = buffers.inputs.samples, "raymarch"
    # STEP_SPACING 0: equiangular, 1: uniform (clrays.structs.STEP_SPACING_*)
    features = present(layers, medium_feature(device, buffers, timer))  # cl/raymarch.cl's argument order
    defines = feature_defines(features, {"STEP_SPACING": STEP_SPACINGS.index(buffers.inputs.scene.render.step_spacing)})
    extra = feature_args(features)
    if only_light is not None:
        defines = {**defines, "ONLY_LIGHT": only_light}
    if walk is not None:
        work_items, walk_defines, walk_args, label = walk
        defines, extra = {**defines, **walk_defines}, (*extra, *walk_args)
    kernel = device.kernel("raymarch", "raymarch", defines)
    arguments = (buffers.params, buffers.views, buffers.lights, rastered.shadow_depth, rastered.camera_depth,
                 buffers.offsets, buffers.light_textures, buffers.texels, scatter, *extra)
    if not progress or walk is not None:
        timer.add(label, kernel(device.queue, (work_items,), None, *arguments))
        return

    def march(start: int, count: int) -> None:  # the kernel's sample is get_global_id, which the offset moves
        event = kernel(device.queue, (count,), None, *arguments, global_offset=(start,))
        timer.add(label, event)
        event.wait()

    part = -(-work_items // PROGRESS_PARTS)
    began = time.perf_counter()
    march(0, part)
    if (time.perf_counter() - began) * PROGRESS_PARTS < PROGRESS_MIN_S:  # a short march: the rest at once
        if part < work_items:
            march(part, work_items - part)
        return
    report = _progress_report(progress, work_items, began)
    try:
        report(part)
        for start in range(part, work_items, part):
            count = min(part, work_items - start)
            march(start, count)
            report(start + count)
    finally:
        getattr(report, "close", lambda: None)()


def _progress_report(progress, total: int, start: float) -> Callable[[int], None]:
    """A function of the samples done so far that moves a tqdm bar (progress True) or
    writes lines through `progress` (a function of a line), for a march begun at `start`
    (time.perf_counter)."""
    if not callable(progress):
        from tqdm import tqdm

        bar = tqdm(total=total, desc="raymarch", unit="sample", unit_scale=True)

        def move(done: int) -> None:
            bar.update(done - bar.n)

        move.close = bar.close
        return move
    shown = [0]

    def line(done: int) -> None:
        spent = time.perf_counter() - start
        percent = 100 * done // total
        if spent >= PROGRESS_LINES_AFTER_S and (percent >= shown[0] + PROGRESS_LINE_PERCENT or done == total):
            shown[0] = percent
            progress(f"raymarch: {percent}% ({spent:.0f} s, about {spent * (total - done) / done:.0f} s left)")

    return line
