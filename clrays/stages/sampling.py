"""Stage sampling: epipolar sampling, minmax's default path (`render.sampling: epipolar`,
docs/design.md §4.5 "Epipolar sampling"). Host side of `cl/sampling.cl`.

Instead of every camera sample walking the rows of its two nearest slices (stage
traverse), samples placed along each slice's line on the screen walk their own row:
every `render.initial_step`-th one, those beside a break (an edge, a spot light's cone)
and those between computed samples whose radiance differs (a shadow's edge); the rest
are interpolated along the line. Each camera sample interpolates its two slices at its
β, and walks a row itself (the fix-up pass) only where the samples there do not stand
for it.
"""
from __future__ import annotations

import numpy as np

from .. import structs
from ..buffers import BufferDecl, FrameSizes
from ..device import Device, StageTimer
from ..inputs import FrameBuffers, frame_sizes
from ..scene.model import TRAVERSALS, DirectionalLight, SpotLight
from ..scene.camera import camera_basis, half_extents
from .integrand import DeviceIntegrand
from .features import WalkFeature, feature_args, feature_defines
from .medium import MediumFeature
from .raster import RasterResult
from ..scene.camera import poles_on_screen
from .rectify import Epipolar, slice_sides


class SampleCounts:
    """What epipolar sampling did in one frame, summed over its lights: line samples that
    walked their row (`computed`), camera samples interpolated on both of their slices
    (`interpolated`), and camera samples that walked at least one row themselves
    (`fixed_up`).

    The counts are made on the device (cl/sampling.cl, fixup_offsets), and each light's
    are copied to the host behind the rest of its frame: they are read when first asked
    for, by then (after the frame's image was read) without waiting for the device.
    Reading them inside the frame made the host wait for the device twice per light."""

    def __init__(self, computed: int = 0, interpolated: int = 0, fixed_up: int = 0, pending: tuple = ()):
        self._counts = (computed, interpolated, fixed_up)
        # per light still on its way: (device, host array of COUNT_*, its copy's event, camera samples)
        self._pending = tuple(pending)

    @classmethod
    def on_device(cls, device: Device, counts, samples: int) -> SampleCounts:
        """One light's counts, in `counts` (uint[2], cl/sampling.cl COUNT_*) once the device
        gets there, over `samples` camera samples: their copy is enqueued now, not waited for."""
        host = np.zeros(2, np.uint32)
        return cls(pending=((device, host, device.cl.enqueue_copy(device.queue, host, counts, is_blocking=False),
                             samples),))

    def _settled(self) -> tuple[int, int, int]:
        computed, interpolated, fixed_up = self._counts
        for device, host, copy, samples in self._pending:
            device.collect(copy)
            computed, interpolated, fixed_up = (computed + int(host[0]), interpolated + samples - int(host[1]),
                                                fixed_up + int(host[1]))
        self._counts, self._pending = (computed, interpolated, fixed_up), ()
        return self._counts

    @property
    def computed(self) -> int:
        return self._settled()[0]

    @property
    def interpolated(self) -> int:
        return self._settled()[1]

    @property
    def fixed_up(self) -> int:
        return self._settled()[2]

    def __add__(self, other: SampleCounts) -> SampleCounts:
        counts = tuple(a + b for a, b in zip(self._counts, other._counts))
        return SampleCounts(*counts, pending=self._pending + other._pending)

    def __eq__(self, other) -> bool:
        return isinstance(other, SampleCounts) and self._settled() == other._settled()

    def __repr__(self) -> str:
        computed, interpolated, fixed_up = self._settled()
        return f"SampleCounts(computed={computed}, interpolated={interpolated}, fixed_up={fixed_up})"

    def __getstate__(self) -> dict:
        """Pickled (a dask worker's result) as the counts themselves: events stay behind."""
        return {"_counts": self._settled(), "_pending": ()}


def line_ranges(scene, params: np.ndarray) -> np.ndarray:
    """(slices, 2) float32: the range [lo, hi] of q (`pseudo_beta`) on the screen beside
    each slice, that is
    between the centre lines of its two neighbours (the camera samples that read the
    slice); lo > hi where the slice does not cross the screen.

    β on the screen has its only extremes at the epipole (0) and the anti-epipole (π), and
    is monotonic along each slice's line, so over a wedge it is extreme where the wedge's
    lines cross the screen border, at a screen corner inside the wedge, or at a pole on
    screen. Found here from the lines and not from the pixels, since near an epipole just
    off screen slices are narrower than a pixel, and a slice no pixel centre falls into
    is still read by the pixels beside it."""
    camera, image = scene.camera, scene.image
    right, up, forward = camera_basis(camera)
    tan_x, tan_y = half_extents(camera, image)
    axis, u, w = (params[name][:3].astype(float) for name in ("axis", "u", "w"))
    slices, step = int(params["slices"]), float(params["alpha_step"])
    centres = float(params["alpha_min"]) + (np.arange(slices) + 0.5) * step

    def screen_direction(sx, sy):
        return forward + np.multiply.outer(sx * tan_x, right) + np.multiply.outer(sy * tan_y, up)

    def beta_of(directions):
        directions = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
        return np.arccos(np.clip(directions @ axis, -1.0, 1.0))

    # The centre lines of each slice and of its two neighbours, (3, slices), where they
    # cross the screen's four edges (a + b·sx + c·sy = 0 on the slice's plane), all at once.
    alpha = np.stack([centres - step, centres, centres + step])
    normal = np.multiply.outer(np.cos(alpha), w) - np.multiply.outer(np.sin(alpha), u)  # the slice's plane
    side = np.multiply.outer(np.cos(alpha), u) + np.multiply.outer(np.sin(alpha), w)  # its half
    a, b, c = normal @ forward, tan_x * (normal @ right), tan_y * (normal @ up)
    edge = np.array([-1.0, 1.0])[:, None, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        sx = np.concatenate([np.broadcast_to(edge, (2, *a.shape)), -(a + c * edge) / b])  # (4, 3, slices)
        sy = np.concatenate([-(a + b * edge) / c, np.broadcast_to(edge, (2, *a.shape))])
    inside = (np.abs(sx) <= 1.0 + 1e-6) & (np.abs(sy) <= 1.0 + 1e-6)
    directions = screen_direction(np.where(inside, sx, 0.0), np.where(inside, sy, 0.0))
    on_half = np.einsum("...j,...j->...", directions, side) > 0
    betas = np.where(inside & on_half, beta_of(directions), np.nan).reshape(12, slices).T  # NaN: absent
    corners = np.array([(-1, -1), (-1, 1), (1, -1), (1, 1)], dtype=float)
    corner_dirs = screen_direction(corners[:, 0], corners[:, 1])
    corner_alpha = np.arctan2(corner_dirs @ w, corner_dirs @ u)
    near = np.abs((corner_alpha[:, None] - centres + np.pi) % (2 * np.pi) - np.pi) < step  # (4, slices)
    betas = np.concatenate([betas, np.where(near, beta_of(corner_dirs)[:, None], np.nan).T], axis=1)
    lo = np.min(np.where(np.isnan(betas), np.inf, betas), axis=1)
    hi = np.max(np.where(np.isnan(betas), -np.inf, betas), axis=1)
    epipole, anti_epipole = poles_on_screen(scene, axis)
    if epipole:  # every slice's line starts there
        lo[:] = 0.0
    if anti_epipole:  # or ends there
        hi[:] = np.pi
    with np.errstate(invalid="ignore"):
        return np.stack([pseudo_beta(lo), pseudo_beta(hi)], axis=1).astype(np.float32)


def line_lengths(scene, params: np.ndarray, ranges: np.ndarray, n: int) -> np.ndarray:
    """(slices,) int32: the line samples of each slice, `n` on the line that is longest on
    the screen and on the others as many as keep that line's spacing (at least 2: its
    ends). Evenly spaced in q, a line's samples are as far apart on the screen as its
    length over their count, and lines through a corner or along the short side of the
    frame are a fraction of the longest: with `n` samples each they were walked several
    times as densely, for no error. A line's length is between the screen points of its
    range's ends (a plane through the eye meets the screen in a straight line); a slice
    that does not cross the screen gets 2, and every slice gets `n` where an end is not in
    front of the eye."""
    camera, image = scene.camera, scene.image
    right, up, forward = camera_basis(camera)
    tan_x, tan_y = half_extents(camera, image)
    axis = params["axis"][:3].astype(float)
    sides = slice_sides(params)[:, :3].astype(float)
    lo, hi = ranges[:, 0].astype(float), ranges[:, 1].astype(float)
    crosses = lo <= hi

    def screen_point(q):
        beta = beta_of_pseudo(q)
        direction = np.cos(beta)[:, None] * axis + np.sin(beta)[:, None] * sides
        depth = direction @ forward
        with np.errstate(divide="ignore", invalid="ignore"):
            x = 0.5 * image.width * (direction @ right) / (depth * tan_x)
            y = 0.5 * image.height * (direction @ up) / (depth * tan_y)
        return np.stack([x, y], axis=1), depth

    start, start_depth = screen_point(np.where(crosses, lo, 0.0))
    end, end_depth = screen_point(np.where(crosses, hi, 0.0))
    with np.errstate(invalid="ignore"):  # (an end in the eye's plane is at infinity: `n` below, as behind it)
        length = np.where(crosses, np.linalg.norm(end - start, axis=1), 0.0)
    longest = float(length.max()) if len(length) else 0.0
    if not (np.isfinite(longest) and longest > 0.0) or np.any(crosses & ((start_depth <= 0) | (end_depth <= 0))):
        return np.where(crosses, n, 2).astype(np.int32)
    counts = np.ceil((n - 1) * length / longest - 1e-9).astype(np.int64) + 1
    return np.where(crosses, np.clip(counts, 2, n), 2).astype(np.int32)


#: Pixels from the epipole within which gather walks every camera sample (epipole_sin).
EPIPOLE_WALK_PIXELS = 8.0


def epipole_sin(scene, light) -> float:
    """sin β of EPIPOLE_WALK_PIXELS pixels (at the image's centre) from the epipole of a
    point or spot light: closer, the radiance grows as 1/sin β faster than the samples of a
    line follow. 0 for a directional light, whose radiance has no such growth."""
    if isinstance(light, DirectionalLight):
        return 0.0
    pixel = 2.0 * half_extents(scene.camera, scene.image)[1] / scene.image.height
    return float(np.sin(np.arctan(EPIPOLE_WALK_PIXELS * pixel)))


def pseudo_beta(beta: np.ndarray) -> np.ndarray:
    """q(β), the monotonic stand-in for β that line samples are spaced evenly in:
    tan(β/2) up to π/2, 2 - cot(β/2) above (cl/sampling.cl, line_samples and gather)."""
    half = np.asarray(beta, dtype=float) / 2
    with np.errstate(divide="ignore"):
        return np.where(half <= np.pi / 4, np.tan(half), 2.0 - 1.0 / np.tan(half))


def beta_of_pseudo(q: np.ndarray) -> np.ndarray:
    """β of q: the inverse of pseudo_beta, q in [0, 2]."""
    q = np.asarray(q, dtype=float)
    return np.where(q <= 1.0, 2.0 * np.arctan(q), np.pi - 2.0 * np.arctan(np.maximum(2.0 - q, 0.0)))


#: Camera or line samples per work-item of gather and line_samples: cl/lanes.h's float8.
LANES = 8
#: Camera samples per block of the fix-up list (fixup_count, fixup_list).
FIXUP_BLOCK = 1024
#: Work-items of fixup_offsets' one work-group (cl/sampling.cl FIXUP_SCAN_ITEMS).
FIXUP_SCAN_ITEMS = 256
#: Per line sample: (distance, lit extent), and (r, g, b times radiance_scale, distance).
LINE_SAMPLES = BufferDecl("epipolar line samples", 8, lambda sizes: sizes.slices * sizes.line_samples)
LINE_RADIANCE = BufferDecl("epipolar line samples' radiance", 16, lambda sizes: sizes.slices * sizes.line_samples)
#: The camera samples listed for fix_up: room for every one.
FIXUP_LIST = BufferDecl("epipolar fix-up list", 4, lambda sizes: sizes.samples)


def epipolar_sampling(device: Device, buffers: FrameBuffers, rastered: RasterResult, epipolar: Epipolar,
                      integrand: DeviceIntegrand, scatter, overwrite: bool, timer: StageTimer,
                      features: tuple[WalkFeature, ...] = ()) -> SampleCounts:
    """Add one light's in-scattered radiance into `scatter` (float4 per camera sample), or
    with `overwrite` write it there (gather writes every sample: no clear needed before);
    `features`: what the walks carry (clrays/stages/features.py), which the kernels that walk
    rows take last."""
    inputs = buffers.inputs
    render = inputs.scene.render
    slices, n = int(epipolar.params["slices"]), render.line_samples
    step, threshold = np.int32(render.initial_step), np.float32(render.refine_threshold)
    ranges = line_ranges(inputs.scene, epipolar.params)
    ranges_buffer = device.buffer(ranges, writable=False)
    sides = device.buffer(slice_sides(epipolar.params), writable=False)
    lengths = device.buffer(line_lengths(inputs.scene, epipolar.params, ranges, n), writable=False)
    sizes = frame_sizes(inputs)  # (slices: the scene's, as the epipolar frame's)
    line = LINE_SAMPLES.allocate(device, sizes)
    wedges = device.buffer(nbytes=8 * slices)  # a spot light's lit wedge of γ per slice (cl/spot_wedge.h)
    radiance = LINE_RADIANCE.allocate(device, sizes)
    state = device.buffer(nbytes=slices * n)  # per line sample: left, computed or refined (cl/sampling.cl LINE_*)
    samples, n32 = inputs.samples, np.int32(n)
    light = inputs.scene.lights[int(epipolar.params["light_index"])]
    traversal = {"TRAVERSAL": TRAVERSALS.index(render.traversal), "LANES": LANES, "FIXUP_BLOCK": FIXUP_BLOCK,
                 "FIXUP_SCAN_ITEMS": FIXUP_SCAN_ITEMS,
                 "SAMPLING_LIGHT": structs.LIGHT_SPOT if isinstance(light, SpotLight) else structs.LIGHT_POINT}
    traversal, walked = feature_defines(features, traversal), feature_args(features)

    def run(name, global_size, local_size, *args):
        event = device.kernel("sampling", name, traversal)(device.queue, global_size, local_size, *args)
        timer.add("traverse", event)  # the traverse stage, sampled

    run("line_samples", (-(-n // LANES), slices), None, buffers.params, buffers.views, buffers.lights, epipolar.buffer,
        rastered.camera_depth, ranges_buffer, sides, n32, lengths, line, wedges)
    runs = -(-(n - 1) // int(step))  # the runs between every step-th line sample
    walks = device.buffer(nbytes=2 * runs * slices)  # per run: its line samples that walked their row
    run("line_scatter", (runs, slices), None, buffers.params, buffers.views, buffers.lights,
        epipolar.buffer, epipolar.tree, integrand.params, integrand.data, ranges_buffer, sides, wedges, line, n32,
        lengths, step, threshold, radiance, state, walks, *walked)
    run("line_refine_fill", (runs, slices), None, buffers.params, buffers.lights, epipolar.buffer, epipolar.tree,
        integrand.params, integrand.data, ranges_buffer, sides, wedges, line, n32, lengths, step, threshold, radiance,
        state, walks, *walked)
    fixup_flags = device.buffer(nbytes=samples)  # per camera sample: a bit per slice fix_up walks
    # a bounded or heterogeneous medium: gather compares the faces a sample's and its line samples' rays cross
    medium = [(sides, *feature.args()) for feature in features if isinstance(feature, MediumFeature)]
    run("gather", (-(-samples // LANES),), None, buffers.params, buffers.views, buffers.lights,
        epipolar.buffer, rastered.camera_depth, buffers.offsets, ranges_buffer, line, radiance, n32, lengths, threshold,
        np.float32(epipole_sin(inputs.scene, light)), np.int32(samples), np.int32(overwrite), scatter, fixup_flags,
        *(medium[0] if medium else ()))
    fixups, counts = fixup_list(device, fixup_flags, sizes, walks, runs * slices, run)
    run("fix_up", *device.list_launch(samples), buffers.params, buffers.views, buffers.lights, epipolar.buffer,
        epipolar.tree, integrand.params, integrand.data, rastered.camera_depth, buffers.offsets, fixups, counts,
        scatter, *walked)
    return SampleCounts.on_device(device, counts, samples)


def fixup_list(device: Device, fixup_flags, sizes: FrameSizes, walks, walk_entries: int, run) -> tuple[object, object]:
    """(the fix-up list, its counts) from gather's flags: each block of FIXUP_BLOCK camera
    samples counts its flagged ones, and lists them from the prefix sum of the counts
    before it. An atomic append in gather costs about as much (measured); the flags keep
    the list in sample order, the same from run to run. The prefix sum is one work-group's
    on the device (fixup_offsets), which also sums `walks` (its first `walk_entries`): the
    counts (uint[2], cl/sampling.cl COUNT_*) stay there, and the list has room for every
    camera sample, so the host waits for neither."""
    samples = sizes.samples
    blocks, samples32 = -(-samples // FIXUP_BLOCK), np.int32(samples)
    block_counts = device.buffer(nbytes=4 * blocks)
    block_offsets = device.buffer(nbytes=4 * blocks)
    counts = device.buffer(nbytes=4 * 2)
    run("fixup_count", (blocks,), None, samples32, fixup_flags, block_counts)
    run("fixup_offsets", (FIXUP_SCAN_ITEMS,), (FIXUP_SCAN_ITEMS,), np.int32(blocks), block_counts,
        np.int32(walk_entries), walks, block_offsets, counts)
    fixups = FIXUP_LIST.allocate(device, sizes)
    run("fixup_list", (blocks,), None, samples32, fixup_flags, block_offsets, fixups)
    return fixups, counts
