"""Stage raster: triangles → camera depth and triangle ids, and every light's shadow map.

Host side of `cl/raster.cl`. Depth is stored as the uint bits of a positive float
(so `atomic_min` orders it) and starts at +inf (nothing hit).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from .. import structs
from ..buffers import BufferDecl, FrameSizes
from ..device import Device, StageTimer
from ..inputs import FrameBuffers, FrameInputs, frame_sizes, light_pass_inputs, opaque_occluders
from ..scene.host_steps import timed
from . import raster_culling
from .relief import ReliefDrawer
from .relief_cuts import cuts_reliefs
from .shaft_edges import keeps_blockers


@dataclass(frozen=True)
class RasterTarget:
    """The buffers a raster pass writes, declared once (clrays.buffers): its depths, its
    nearest triangles, or the 64-bit keys (depth << 32 | triangle) it draws both with where
    the device has 64-bit atomics, and a copy of those keys from before the reliefs."""

    depth: BufferDecl
    triangles: BufferDecl
    keys: BufferDecl
    keys_before_reliefs: BufferDecl | None = None


#: The camera's: per sample.
CAMERA = RasterTarget(BufferDecl("camera depth", 4, lambda sizes: sizes.samples),
                      BufferDecl("camera triangle ids", 4, lambda sizes: sizes.samples),
                      BufferDecl("camera raster keys (64-bit)", 8, lambda sizes: sizes.samples))


def _map_texels(sizes: FrameSizes) -> int:
    """The texels of the maps (a buffer even where there is none)."""
    return max(sizes.shadow_texels, 1)


#: One light's map: per texel of its views.
SHADOW_MAP = RasterTarget(BufferDecl("shadow map", 4, _map_texels),
                          BufferDecl("shadow map's nearest triangles", 4, _map_texels),
                          BufferDecl("shadow map's raster keys (64-bit)", 8, _map_texels),
                          BufferDecl("shadow map's keys without the reliefs (64-bit)", 8, _map_texels))
#: Every light's maps back to back (shadow_atlas), by part: depths, nearest triangles or their keys,
#: the keys without the reliefs.
ATLAS = {"depth": BufferDecl("shadow maps of all lights together", 4, _map_texels),
         "triangles": BufferDecl("shadow maps' nearest triangles together", 4, _map_texels),
         "keys": BufferDecl("shadow maps' raster keys together (64-bit)", 8, _map_texels),
         "volume": BufferDecl("shadow maps' keys without the reliefs together (64-bit)", 8, _map_texels)}


@dataclass
class RasterResult:
    camera_depth: object  # uint[H·W·spp]: as_uint(distance along the sample ray)
    tri_id: object  # int[H·W·spp]: nearest triangle, -1 where nothing was hit
    shadow_depth: object  # uint[shadow_texels]: every light's views, back to back
    # the blocker nearest the light at each texel, as shadow_depth (None: not kept): its
    # triangle (int, -1: none), or with `blocker_keys` the 64-bit key (depth << 32 | triangle)
    # it was drawn with (ShadowMap)
    shadow_blockers: object = None
    blocker_keys: bool = False
    # the keys the volume reads where its walks cut the reliefs themselves (ShadowMap.volume);
    # None: shadow_blockers
    volume_blockers: object = None
    # shadow_depth is the keys themselves, its depths every other word (`depth_in_keys`)
    depth_in_keys: bool = False


def _launch(device: Device, buffers: FrameBuffers, name: str, defines: dict | None, view_indices: list[int],
            offsets, sample_count: int, target: tuple, timer: StageTimer, drawn: list) -> None:
    """Both passes of one raster kernel over the triangles each view draws (`drawn`,
    `_drawn_lists`), for some views."""
    sizes = [(int(buffers.inputs.views[view]["height"]), int(buffers.inputs.views[view]["width"]))
             for view in view_indices]
    raster_passes(device, "raster", name, defines, buffers.tri_vertices, _drawn_count(buffers.inputs),
                  buffers.views, view_indices, sizes, offsets, sample_count, target, timer, drawn=drawn)


def _drawn_count(inputs: FrameInputs) -> int:
    """The triangles the frame rasterizes: the reliefs' triangles, last, are pre-warped instead."""
    return inputs.tri_vertices.shape[0] // 3 if inputs.raster_triangles is None else inputs.raster_triangles


#: Whether each view draws only the triangles that may reach it (`_drawn_lists`); False:
#: every view draws every triangle, as a yardstick for tests and benches.
CULL_PER_VIEW = True
#: A view whose list keeps more than this share of the triangles draws them all, without
#: the list: pass 1 over a list of blocks (a 2-D launch, its triangles read through the
#: list) took up to 1.2× the time of the plain launch where the list kept every block (the
#: bunny's spot light at 1280×720; bench/RESULTS.md history, "Raster culled per view").
LIST_AT_MOST = 0.9


def _drawn_lists(device: Device, inputs: FrameInputs, view_indices: list[int], anchor_ws: np.ndarray) -> list | None:
    """Per view, (its list on the device of the blocks of CULL_BLOCK triangles that may
    reach it, their count, CULL_BLOCK) (clrays.stages.raster_culling), for vertices anchored
    at `anchor_ws` (world space); the host's time is `--stats`'s host step `raster culling`.
    None without CULL_PER_VIEW."""
    if not CULL_PER_VIEW:
        return None
    count, geometry = _drawn_count(inputs), inputs.scene.geometry
    block = raster_culling.CULL_BLOCK
    with timed("raster culling"):
        lists = [raster_culling.view_blocks(geometry, count, anchor_ws, inputs.views[view]) for view in view_indices]
    # A list that keeps nearly every triangle saves less than its launch costs: every triangle, as without one.
    return [(None, count, 1) if len(blocks) * block >= LIST_AT_MOST * count else
            (device.buffer(blocks, writable=False), len(blocks), block) for blocks in lists]


#: The columns a work-item of a raster rows pass owns on a device other than a CPU: with
#: whole rows a 1024² face had 256 work-items, too few for a GPU (demo's shadow-map rows
#: pass took 13 ms on an H200). A multiple of RASTER_LANES, so that a run of lanes stays
#: inside its block where the block starts on a run.
RASTER_ROWS_COLUMNS_GPU = 32
#: On a device other than a CPU, pass 1 lists a triangle whose texel rectangle holds more
#: pixels than this as well as one taller than RASTER_BIG_ROWS: a wall seen edge-on can be
#: 32 rows by a whole face, one GPU work-item's worth of a frame (cl/raster.cl,
#: big_rectangle). A CPU's cores run many work-items each and keep the rows alone.
RASTER_BIG_SAMPLES_GPU = 1024


#: Keys a work-item of raster_split_runs splits (every build of cl/raster.cl): a shadow map's
#: millions of texels one per work-item cost PoCL 8 ms a 1024² cube map.
RASTER_SPLIT_RUN = 64


def raster_rows_columns(device: Device, width: int) -> int:
    """Columns of a `width`-wide view per work-item of a rows pass: a CPU's cores take whole
    rows, which projects each listed triangle once per block of rows."""
    return width if device.is_cpu else RASTER_ROWS_COLUMNS_GPU


def raster_big_samples(device: Device) -> int:
    """The pixels of a triangle's rectangle past which pass 1 lists it; 0: only its rows count."""
    return 0 if device.is_cpu else RASTER_BIG_SAMPLES_GPU


def raster_count_on_device(device: Device) -> bool:
    """Whether a rows pass reads its list's length on the device, so that the host enqueues
    both passes without waiting (a GPU, which a wait leaves idle), or the host reads the
    lengths, once for every view, and passes each as an argument (a CPU device: PoCL runs
    a loop over an argument uniformly across the work-items it runs together, and over a
    length read on the device the camera's rows pass took 1.6× its time; bench/RESULTS.md history,
    "The host's waits inside a frame")."""
    return not device.is_cpu


def raster_defines(device: Device, defines: dict | None = None) -> dict | None:
    """`defines` for a program built from cl/raster.cl on `device`, with RASTER_BIG_SAMPLES
    where the device lists wide triangles, and RASTER_COUNT_ON_DEVICE 0 where the host reads
    the lists' lengths: every kernel of the program takes the same, so the program is built
    once."""
    big_samples = raster_big_samples(device)
    defines = {**(defines or {}), "RASTER_SPLIT_RUN": RASTER_SPLIT_RUN}
    defines = {**defines, "RASTER_BIG_SAMPLES": big_samples} if big_samples else defines
    return defines if raster_count_on_device(device) else {**(defines or {}), "RASTER_COUNT_ON_DEVICE": 0}


def _blocks_launch(device: Device, block_count: int, block: int) -> tuple[tuple, tuple | None]:
    """(global size, work-group shape) of pass 1 over `block_count` listed blocks of `block`
    triangles: (block, listed blocks), so that a block's triangles are one run of dimension
    0 under one list entry (consecutive loads). On a CPU device the list's length is padded
    to whole work-groups of a power of two of blocks (Device.counted_launch): a view's list
    changes with the camera, and PoCL compiles a kernel for each new work-group shape."""
    _, group = device.counted_launch(block_count * block)
    if group is None:
        return (block, block_count), None
    blocks_per_group = max(1, group[0] // block)
    return (block, -(-block_count // blocks_per_group) * blocks_per_group), (block, blocks_per_group)


def raster_passes(device: Device, program: str, name: str, defines: dict | None, vertices, count: int, views,
                  view_indices: list[int], view_sizes: list[tuple[int, int]], offsets, sample_count: int, target: tuple,
                  timer: StageTimer, stage: str = "raster", drawn: list | None = None) -> None:
    """The two passes of one raster kernel (cl/raster.cl's RASTER_KERNELS, built in
    `program`) over `count` triangles for each view of `view_indices` (`view_sizes`:
    (rows, columns)): `name`, one work-item per triangle, lists the triangles taller than
    RASTER_BIG_ROWS (on a GPU, also those whose rectangle holds more than
    `raster_big_samples` pixels) with their rows; `name_rows` draws those with one
    work-item per block of RASTER_ROWS_PER_ITEM rows by `raster_rows_columns` columns of
    the view, which owns its block (docs/design.md §4.1).
    On a GPU (`raster_count_on_device`) the rows pass reads its list's length from the
    counter pass 1 leaves on the device, so both passes of every view are enqueued without
    the host waiting: a wait for the counts drains the queue twice a frame (camera and
    shadow map), and leaves a GPU idle meanwhile; a view whose list is empty still launches
    its rows pass, whose work-items return at once. On a CPU device the host waits once for
    every view's count and launches the rows passes of the views that listed any. Pass 1
    lists every view before any rows pass runs; the views have texels of their own, and
    every update is a min or a max, which no order changes.
    `drawn`: per view, (a device list of the blocks of triangles pass 1 visits, its length,
    the triangles per block), the blocks that may reach the view
    (clrays.stages.raster_culling); None: all `count`. A view whose list is empty launches
    nothing."""
    drawn = drawn or [(None, count, 1)] * len(view_indices)
    kept = [(view, size, listed) for view, size, listed in zip(view_indices, view_sizes, drawn) if listed[1]]
    if not kept:
        return
    view_indices, view_sizes, drawn = (list(column) for column in zip(*kept))
    defines = raster_defines(device, defines)
    first_pass = device.kernel(program, name, defines)
    lists = []  # per view: its count of big triangles, and their (triangle, first row, last row)
    for view_index, (blocks, block_count, block) in zip(view_indices, drawn):
        # a triangle lists itself at most once
        capacity = min(block_count * block, count, structs.RASTER_BIG_TRIANGLES)
        lists.append((device.buffer(np.zeros(1, np.uint32)), device.buffer(nbytes=12 * capacity)))
        global_size, local_size = (count,), None
        if blocks is not None:
            global_size, local_size = _blocks_launch(device, block_count, block)
        timer.add(stage, first_pass(device.queue, global_size, local_size, vertices, np.int32(count), blocks,
                                    np.int32(block_count), np.int32(block), views, np.int32(view_index), offsets,
                                    np.int32(sample_count), *lists[-1], *target))
    rows_pass = device.kernel(program, f"{name}_rows", defines)
    on_device = raster_count_on_device(device)
    counts = [counter for counter, _ in lists] if on_device else \
        [np.int32(min(int(listed[0]), structs.RASTER_BIG_TRIANGLES))
         for listed in device.read_all([(c, 1) for c, _ in lists], np.uint32)]
    for view_index, (height, width), (_, big), big_count in zip(view_indices, view_sizes, lists, counts):
        if not on_device and not big_count:
            continue
        columns = raster_rows_columns(device, width)
        timer.add(stage, rows_pass(
            device.queue, (-(-height // structs.RASTER_ROWS_PER_ITEM), -(-width // columns)), None, vertices,
            views, np.int32(view_index), offsets, np.int32(sample_count), big, big_count, np.int32(columns),
            *target))


def _rasterize(device: Device, buffers: FrameBuffers, view_indices: list[int], offsets, sample_count: int,
               depth, timer: StageTimer, drawn: list) -> None:
    _launch(device, buffers, "raster_depth", None, view_indices, offsets, sample_count, (depth,), timer, drawn)


def _split(device: Device, defines: dict, nearest, count: int, depth, triangle, timer: StageTimer) -> None:
    """The packed keys `nearest` split into `depth` and `triangle` (raster_split_runs), or
    into `depth` alone where `triangle` is None (raster_split_depth_runs)."""
    name, targets = ("raster_split_runs", (depth, triangle)) if triangle is not None else \
        ("raster_split_depth_runs", (depth,))
    timer.add("raster", device.kernel("raster", name, raster_defines(device, defines))(
        device.queue, (-(-count // RASTER_SPLIT_RUN),), None, nearest, np.int32(count), *targets))


def _atomic64(device: Device) -> bool:
    return "cl_khr_int64_extended_atomics" in device.device.extensions


def _draw(device: Device, buffers: FrameBuffers, reliefs: ReliefDrawer, anchor_ws: np.ndarray, views: list[int],
          offsets, sample_count: int, target: RasterTarget, sizes: FrameSizes, nearest_triangles: bool,
          timer: StageTimer,
          keep_keys: bool = False, before_reliefs: list | None = None,
          depths_from_keys: bool = False) -> tuple[object, object, bool]:
    """Depth of the `target`'s samples over `views` (the triangles, then the reliefs; as many
    as its declarations give for `sizes`), and, with
    `nearest_triangles`, the triangle each depth belongs to (None without): in one pass of
    64-bit keys (depth, triangle), split after, where the device has 64-bit atomics; else
    the depths, then a pass that finds their triangles (ties: the highest index). With
    `keep_keys`, where there are keys, the keys themselves stand for the triangles, and only
    the depths are split out; with `depths_from_keys` too, not even those (the first value is
    the keys: their readers take every other word). The third value: whether the second is
    keys. `before_reliefs`, a list, gets a copy of the keys as the triangles alone drew them
    (where there are keys). `anchor_ws`: where the frame's vertices are anchored (world space),
    for the views' lists of the triangles that may reach them (`_drawn_lists`)."""
    inputs = buffers.inputs
    triangle = None
    count = target.depth.length(sizes)
    drawn = _drawn_lists(device, inputs, views, anchor_ws)
    if nearest_triangles and _atomic64(device):
        defines = {"RASTER_ATOMIC64": 1}
        nearest = target.keys.allocate(device, sizes)
        device.fill(nearest, np.uint64((int(structs.DEPTH_EMPTY) << 32) | 0xFFFFFFFF), 8 * count, timer, "raster")
        _launch(device, buffers, "raster_nearest", defines, views, offsets, sample_count, (nearest,), timer, drawn)
        if before_reliefs is not None:
            kept = target.keys_before_reliefs.allocate(device, sizes)
            timer.add("raster", device.cl.enqueue_copy(device.queue, kept, nearest, byte_count=8 * count))
            before_reliefs.append(kept)
        for view in views:
            reliefs.map("relief_map_nearest", defines, buffers.views, inputs.views, view, offsets, sample_count,
                        (nearest,))
        if keep_keys and depths_from_keys:
            return nearest, nearest, True
        depth = target.depth.allocate(device, sizes)
        if keep_keys:
            _split(device, defines, nearest, count, depth, None, timer)
            return depth, nearest, True
        triangle = target.triangles.allocate(device, sizes)
        _split(device, defines, nearest, count, depth, triangle, timer)
        return depth, triangle, False
    depth = target.depth.allocate(device, sizes)
    device.fill(depth, structs.DEPTH_EMPTY, 4 * count, timer, "raster")
    _rasterize(device, buffers, views, offsets, sample_count, depth, timer, drawn)
    for view in views:
        reliefs.map("relief_map_depth", None, buffers.views, inputs.views, view, offsets, sample_count, (depth,))
    if nearest_triangles:
        triangle = target.triangles.allocate(device, sizes)
        device.fill(triangle, np.int32(-1), 4 * count, timer, "raster")
        _launch(device, buffers, "raster_resolve", None, views, offsets, sample_count, (depth, triangle), timer, drawn)
        for view in views:
            reliefs.map("relief_map_resolve", None, buffers.views, inputs.views, view, offsets, sample_count,
                        (depth, triangle))
    return depth, triangle, False


def depth_in_keys(scene) -> bool:
    """Whether a frame's readers of the shadow maps' depths read them from the maps' 64-bit
    keys (every other word, `SHADOW_DEPTH_IN_KEYS`), so that no depth array is split out of
    them: minmax keeping its blockers, with exact surface shadows and no translucent object,
    whose only readers are rectify (which reads the keys anyway) and visibility. Split out,
    the depths of demo's six 1024² faces cost 2.3 ms a frame and 24 MB (docs/design.md §4.5)."""
    return keeps_blockers(scene.render) and scene.render.surface_shadows == "exact" and not scene.geometry.translucent


def raster_camera(device: Device, buffers: FrameBuffers, timer: StageTimer) -> tuple[object, object]:
    """Camera depth and triangle id of every sample of every pixel."""
    inputs = buffers.inputs
    reliefs = ReliefDrawer(device, inputs.reliefs, inputs.eye_ws, timer)  # eye space, as the triangles
    camera_depth, tri_id, _ = _draw(device, buffers, reliefs, inputs.eye_ws, [0], buffers.offsets,
                                    inputs.scene.image.spp, CAMERA, frame_sizes(inputs), True, timer)
    return camera_depth, tri_id


@dataclass
class ShadowMap:
    """One light's shadow map, in its own buffer (views anchored at the light)."""

    depth: object  # uint[texels]
    # the nearest triangle at each texel, its index in the frame (None: not kept): int[texels]
    # (-1: none), or with `keys` the ulong[texels] keys it was drawn with (depth << 32 |
    # triangle; a texel whose depth is DEPTH_EMPTY has none), which rectify reads in one load
    blockers: object
    keys: bool
    texels: int
    triangles: int  # scene triangles: with none, the map is empty without looking
    # the keys without the reliefs, which the volume reads where its walks cut the reliefs
    # themselves (stages/relief_cuts.py); None: the volume reads `blockers`
    volume: object = None
    # `depth` is the keys (`depth_in_keys`): no depth array is split out of them
    depth_in_keys: bool = False
    empty: bool | None = None  # nothing can be rasterized: filled in by `map_is_empty` when first asked
    # whether a triangle may reach a view the pass draws, asked by `map_is_empty`
    # (`_reaches_views`), or None where the map is empty without looking
    reaches: Callable[[], bool] | None = None


def raster_shadow_map(device: Device, buffers: FrameBuffers, light_index: int, timer: StageTimer) -> ShadowMap:
    """Rasterize one light's views from the geometry translated to the light (float64 on
    the host), so the depths do not depend on the eye and a render session keeps a static
    light's map while the camera moves (docs/design.md §5, §7)."""
    # Translucent triangles are no opaque occluders: they reach the light through the translucency
    # stage. A relief's triangles are not carried (its pre-warp draws it).
    inputs = light_pass_inputs(opaque_occluders(buffers.inputs), light_index, buffers.inputs.raster_triangles)
    light_buffers = replace(buffers, inputs=inputs,
                            views=device.buffer(inputs.views, writable=False),
                            lights=device.buffer(inputs.lights, writable=False),
                            tri_vertices=device.buffer(inputs.tri_vertices, writable=False))
    centre = device.buffer(np.array([[0.5, 0.5]], dtype=np.float32), writable=False)
    reliefs = ReliefDrawer(device, inputs.reliefs, inputs.light_anchor_ws[0], timer)  # anchored, as the triangles
    drawn = [view for view in range(1, len(inputs.views)) if inputs.view_needed[view]]  # (a face no sample reads stays empty)
    # With the depths, minmax's walks take the nearest triangles, to place the shafts'
    # edges on them (cl/shaft_edges.h).
    # Where the walks cut the reliefs themselves (stages/relief_cuts.py), the volume reads the
    # keys from before the reliefs were drawn.
    before_reliefs = [] if cuts_reliefs(inputs, _atomic64(device)) else None
    depth, blockers, keys = _draw(device, light_buffers, reliefs, inputs.light_anchor_ws[0], drawn, centre, 1,
                                  SHADOW_MAP, frame_sizes(inputs), keeps_blockers(inputs.scene.render), timer,
                                  keep_keys=True, before_reliefs=before_reliefs,
                                  depths_from_keys=depth_in_keys(inputs.scene))
    shadow_map = ShadowMap(depth, blockers, keys, inputs.shadow_texels, inputs.scene.geometry.count,
                           volume=before_reliefs[0] if before_reliefs else None, depth_in_keys=keys and depth is blockers)
    if shadow_map.triangles and shadow_map.texels:
        shadow_map.reaches = _reaches_views(inputs)
    return shadow_map


#: Slack of `map_is_empty`'s plane tests, relative to a vertex's largest coordinate in the
#: view: far above the float32 rounding of the device's projection (6e-8), so a triangle the
#: host finds outside a view never reaches a texel there.
OUTSIDE_VIEW_SLACK = 1e-5


def map_is_empty(device: Device, shadow_map: ShadowMap) -> bool:
    """Whether nothing can be rasterized into a light's map, decided on the host from the
    geometry, so the frame does not wait for the device: every triangle the light pass
    draws lies wholly outside one side of each view the frame draws (behind a perspective
    view, or past an edge of its frustum or of an orthographic box), in float64 with
    OUTSIDE_VIEW_SLACK. A triangle inside a view that covers no texel centre, or one the
    view culls as a back face, leaves the map empty while this says False: the frame then
    rectifies and samples the full texture as for any shadowing light, which differs from
    the minimal texture's per-pixel walk by epipolar sampling's interpolation alone
    (clrays.session.Renderer._rectify). No scene in scenes/ has such a map. A relief is drawn by its pre-warp: a map with one
    counts as not empty. `device` is not asked (kept for the callers)."""
    if shadow_map.empty is None:
        shadow_map.empty = shadow_map.reaches is None or not shadow_map.reaches()
        shadow_map.reaches = None
    return shadow_map.empty


#: Triangles `map_is_empty` tests at a time: a map that holds something is usually found
#: in the first block (bunny's 75 536 triangles took 60 ms at once, a block 0.1 ms).
EMPTY_TEST_TRIANGLES = 2048
#: Answers of `map_is_empty` a geometry keeps (light poses it was asked for).
EMPTY_TEST_KEPT = 8


def _reaches_views(inputs: FrameInputs) -> Callable[[], bool]:
    """Whether some triangle of a light pass (`light_pass_inputs`) may reach a view it
    draws (a relief always may), as a question asked later: it holds the geometry, the
    anchor and the views, not the pass's vertices. The answer is kept on the geometry for
    the light's anchor and views, so frames that render a static light afresh (reuse off)
    ask once."""
    carried, has_reliefs = len(inputs.tri_vertices) // 3, bool(inputs.reliefs)
    views = inputs.views[1:][inputs.view_needed[1:]].copy()
    anchor = inputs.light_anchor_ws[0].copy()
    geometry = inputs.scene.geometry
    return lambda: has_reliefs or geometry.kept(
        ("in_views", carried, anchor.tobytes(), views.tobytes()),
        lambda: _triangles_reach(geometry.triangles[:carried], anchor, views), most=EMPTY_TEST_KEPT)


def _triangles_reach(triangles: np.ndarray, anchor: np.ndarray, views: np.ndarray) -> bool:
    """Whether a triangle ((T, 3, 3) world space, float64) is not wholly outside one side of
    each view (anchored at `anchor`), block by block."""
    frames = [(np.stack([view["right"][:3], view["up"][:3], view["forward"][:3]]).astype(np.float64).T,
               view["origin"][:3].astype(np.float64) + anchor, view) for view in views]
    for first in range(0, len(triangles), EMPTY_TEST_TRIANGLES):
        vertices = triangles[first:first + EMPTY_TEST_TRIANGLES].reshape(-1, 3)
        for basis, origin, view in frames:
            x, y, z = ((vertices - origin) @ basis).T
            slack = OUTSIDE_VIEW_SLACK * np.maximum(np.maximum(abs(x), abs(y)), abs(z))
            if view["projection"] == structs.PROJECTION_PERSPECTIVE:
                reach_x, reach_y = float(view["scale_x"]) * z, float(view["scale_y"]) * z
                outside = [z <= 0.0]
            else:
                reach_x, reach_y = float(view["scale_x"]), float(view["scale_y"])
                outside = []
            outside += [x - reach_x > slack, -x - reach_x > slack, y - reach_y > slack, -y - reach_y > slack]
            # a triangle is out of the view when its three vertices are out on the same side
            out = np.zeros(len(vertices) // 3, dtype=bool)
            for side in outside:
                out |= side.reshape(-1, 3).all(axis=1)
            if not out.all():
                return True
    return False


def shadow_atlas(device: Device, buffers: FrameBuffers, maps: list[ShadowMap], part: str = "depth"):
    """Every light's map back to back, at the depth offsets of the frame's views: their
    depths, or (`part="blockers"`) their nearest triangles or keys, or (`"volume"`) their
    keys without the reliefs (ShadowMap), None where the maps keep none."""
    if any(getattr(entry, part) is None for entry in maps):
        return None
    if len(maps) == 1:
        return getattr(maps[0], part)
    # every map of a frame is drawn alike
    declared = ATLAS[("keys" if maps[0].keys else "triangles") if part == "blockers" else part]
    size = declared.element_bytes
    atlas = declared.allocate(device, frame_sizes(buffers.inputs))
    for (first, _), entry in zip(buffers.inputs.light_views, maps):
        offset = size * int(buffers.inputs.views[first]["depth_offset"])
        device.cl.enqueue_copy(device.queue, atlas, getattr(entry, part), byte_count=size * entry.texels,
                               dst_offset=offset)
    return atlas


def read_shadow_depth(device: Device, depth, texels: int, in_keys: bool) -> np.ndarray:
    """A map's (or the atlas's) depths back to the host, float32 (texels,): from the keys'
    depth words where those are the depths (`in_keys`: ShadowMap.depth_in_keys,
    RasterResult.depth_in_keys). For tests and tools."""
    if not in_keys:
        return device.read(depth, texels, np.uint32).view(np.float32)
    return (device.read(depth, texels, np.uint64) >> np.uint64(32)).astype(np.uint32).view(np.float32)


def shadow_atlases(device: Device, buffers: FrameBuffers, maps: list[ShadowMap]) -> tuple:
    """The atlases of the maps' depths, blockers and keys without the reliefs
    (`shadow_atlas`); the depths are the blockers' where the maps' depths are their keys."""
    blockers = shadow_atlas(device, buffers, maps, "blockers")
    depth = blockers if maps and maps[0].depth_in_keys else shadow_atlas(device, buffers, maps)
    return depth, blockers, shadow_atlas(device, buffers, maps, "volume")


def raster(device: Device, buffers: FrameBuffers, timer: StageTimer) -> RasterResult:
    """The whole stage without a session's reuse: every sample of every pixel from the
    camera, and each light's map anchored at the light, as a render session wires them."""
    camera_depth, tri_id = raster_camera(device, buffers, timer)
    maps = [raster_shadow_map(device, buffers, index, timer) for index in range(len(buffers.inputs.scene.lights))]
    depth, blockers, volume = shadow_atlases(device, buffers, maps)
    return RasterResult(camera_depth, tri_id, depth, blockers, bool(maps) and maps[0].keys, volume,
                        bool(maps) and maps[0].depth_in_keys)
