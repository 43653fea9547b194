"""Stage visibility: exact hard shadows on surfaces (`render.surface_shadows: exact`).
Host side of `cl/visibility*.cl` (one file per kernel family, cl/visibility.h) and `cl/bvh.h`
(docs/design.md §4, visibility).

Per camera sample and light, the shadow map answers where its neighbourhood is
unanimous: lit where a conservative bound map (every triangle that touches a texel,
however thin, at a depth no larger than its own there) has nothing nearer the light than
the sample, or where the writer map beside it says the sample's own triangle is the only
one touching its texel; shadowed where every texel centre around it holds a blocker. The
rest, the samples on shadow edges, ask the BVH whether the segment to the light is
blocked, so a shadow edge lands where the `exact` reference puts it. A sample whose
surface turns away from the light needs neither: shade weighs it by zero.

In order: `visibility_prepare` decides what needs no map and notes the texel each other
sample's lit test reads, `visibility_bound` draws each light's maps at those texels only,
`visibility` decides the rest from the maps and lists those left to a shadow ray, and
`visibility_rays` casts them through the BVH, built only then; in a frame of few samples
(a thumbnail) the bound passes also list, per texel read, the triangles touching it, and
`visibility_rays_listed` tests those instead: no BVH at all; in a frame that leaves fewer
rays than it has triangles, the bound passes run again over the rays' texels alone to
list them (`ray_lists`; docs/design.md §4.6). The counts stay on the device: the passes
read their lists' lengths there, the listed ways run or return by a route the device
decides (`visibility_route`); on a CPU device the host waits once, before the BVH, which
it builds only where that route asks for it, and on a GPU (`bvh_ahead`) the BVH is built
or kept before the route is known and its rays gated on it: no wait.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .. import structs
from ..bvh import Bvh, BvhTopology, bvh_topology, refit_bvh
from ..relief_bvh import JoinedTopology, geometry_bvh_topology, refit_frame_bvh
from .bvh_build import DeviceBvhTree, bvh_build_refit, bvh_build_tree
from ..buffers import BufferDecl, FrameSizes
from ..device import Device, StageTimer
from ..inputs import FrameBuffers, FrameInputs, frame_sizes, light_pass_inputs
from .raster import RasterResult

#: `visibility_bound` does a triangle's texel rectangle of up to this many rows in one
#: work-item (most triangles of a fine mesh: one item each, no idle ones) and leaves
#: taller ones to `visibility_bound_rows`, whose work-items each own a block of the view
#: (a floor's rectangle can be a whole face).
BOUND_SMALL_ROWS = 8
#: The block of a view that one work-item of `visibility_bound_rows` owns: on a CPU device
#: 16 whole rows, so that a listed triangle is projected and clipped once per 16 rows and
#: each core has dozens of work-items per face; elsewhere a row's 32 columns (a GPU wants
#: tens of thousands of work-items: with whole rows, 1024 per face, demo's bound passes
#: took 18 ms on an H200).
BOUND_ROWS_PER_ITEM_CPU = 16
BOUND_COLUMNS_PER_ITEM_GPU = 32


def rows_pass_block(device: Device, width: int) -> tuple[int, int]:
    """(rows, columns) of a view `width` texels wide that a work-item of the rows pass owns."""
    return (BOUND_ROWS_PER_ITEM_CPU, width) if device.is_cpu else (1, BOUND_COLUMNS_PER_ITEM_GPU)

#: A frame of at most TOUCHING_ENTRIES samples × lights (a 64×64 thumbnail) has the bound
#: passes list, per texel read, the triangles touching it, in up to
#: TOUCHING_NODES_PER_ENTRY × entries nodes (the bunny at 16×9: 3.5k of 9.2k, 84 per texel): its
#: shadow rays test those instead of building the BVH. Larger frames cast enough rays for
#: the BVH to pay, and their lists would be millions of nodes.
TOUCHING_ENTRIES = 4096
TOUCHING_NODES_PER_ENTRY = 64
#: A larger frame whose maps leave at most this many shadow rays, and no more than it has
#: triangles, lists the triangles touching the texels of those rays alone (`ray_lists`: the
#: bound passes again over those texels) rather than building the BVH.
RAY_LIST_ENTRIES = 1 << 17


def _map_texels(sizes: FrameSizes) -> int:
    return max(sizes.shadow_texels, 1)


def _mask_words(sizes: FrameSizes) -> int:
    return max((sizes.shadow_texels + 31) // 32, 1)


#: Per camera sample and light: the answer, the texel its lit test reads (address, depth),
#: and its place in the list of shadow rays; a bit per texel of the maps read.
VISIBLE = BufferDecl("visibility's answers", 4, lambda sizes: sizes.entries)
MAP_READ = BufferDecl("texels the visibility stage reads", 8, lambda sizes: sizes.entries)
READ_MASK = BufferDecl("the shadow maps' texels read", 4, _mask_words)
RAY_ENTRIES = BufferDecl("the list of shadow rays", 4, lambda sizes: sizes.entries)
#: A light's bound and writer maps (BoundMap), and every light's back to back.
BOUND = BufferDecl("bound map", 4, _map_texels)
WRITER = BufferDecl("writer map", 4, _map_texels)
BOUND_ATLAS = BufferDecl("bound maps together", 4, _map_texels)
WRITER_ATLAS = BufferDecl("writer maps together", 4, _map_texels)
#: A thumbnail's lists of the triangles touching each texel read (at most TOUCHING_ENTRIES entries).
TOUCHING_HEADS = BufferDecl("the heads of the texels' lists", 4, _map_texels)
TOUCHING_NODES = BufferDecl("the texels' lists of triangles", 8,
                            lambda sizes: max(TOUCHING_NODES_PER_ENTRY * sizes.entries, 1))
#: A larger frame's lists for its shadow rays' texels alone (ray_lists): a bit per texel of
#: the maps a listed ray reads, and per light the lists' heads and nodes.
RAY_LIST_MASK = BufferDecl("the shadow rays' texels", 4, _mask_words)
RAY_LIST_HEADS = BufferDecl("the heads of the shadow rays' lists", 4, _map_texels)
RAY_LIST_NODES = BufferDecl("the shadow rays' lists of triangles", 8,
                            lambda sizes: max(TOUCHING_NODES_PER_ENTRY * ray_list_length(sizes), 1))
#: Work-items of the one work-group that orders a view's list of tall triangles nearest
#: first (cl/visibility_bound.cl, visibility_order: a bitonic sort in local memory of up to
#: ORDER_LONGEST, 2048; a longer list stays in the order it was listed in, which gives the
#: same maps. The bench scenes list at most 829: demo, a face, at 1280×720).
ORDER_ITEMS = 256
#: Camera samples one visibility_prepare or visibility work-item takes, as float8 lanes (cl/lanes.h).
PREPARE_LANES = 8


@dataclass
class DeviceBvh:
    """A BVH over the frame's eye-space triangles, on the device."""

    node_bounds: object
    node_children: object
    root: int


def bvh_topology_of(device: Device, inputs: FrameInputs, timer: StageTimer) -> BvhTopology | DeviceBvhTree:
    """The BVH's tree over the world-space triangles (timed as `bvh`): it depends on the
    geometry alone, so a session keeps it while the camera moves. Built on the device
    (clrays.stages.bvh_build) but for a scene with reliefs, whose subtrees the host keeps
    (clrays.relief_bvh), and one of fewer than two triangles (no internal node)."""
    geometry = inputs.scene.geometry
    if not geometry.reliefs and geometry.count >= 2:
        return bvh_build_tree(device, geometry.triangles, timer)
    start = time.perf_counter()
    topology = geometry_bvh_topology(geometry) if geometry.reliefs else bvh_topology(geometry.triangles)
    timer.add_host("bvh", (time.perf_counter() - start) * 1e3)
    return topology


def upload_bvh(device: Device, buffers: FrameBuffers, topology: BvhTopology | DeviceBvhTree,
               timer: StageTimer) -> DeviceBvh:
    """Refit `topology` around the eye-space triangles the device intersects, so its boxes
    hold exactly the float32 vertices the rays meet (timed as `bvh`): on the device for a
    tree built there, else on the host, then uploaded."""
    inputs = buffers.inputs
    if isinstance(topology, DeviceBvhTree):
        node_bounds = bvh_build_refit(device, topology, inputs.eye_ws, buffers.tri_vertices, timer)
        return DeviceBvh(node_bounds, topology.node_children, 0)
    start = time.perf_counter()
    bvh: Bvh = (refit_frame_bvh(topology, inputs) if isinstance(topology, JoinedTopology)  # a relief's boxes kept
                else refit_bvh(topology, inputs.tri_vertices[:, :3].reshape(-1, 3, 3)))
    timer.add_host("bvh", (time.perf_counter() - start) * 1e3)
    return DeviceBvh(device.buffer(bvh.node_bounds, writable=False),
                     device.buffer(bvh.node_children, writable=False), bvh.root)


@dataclass
class Prepared:
    """visibility_prepare's answers, before the bound maps: each sample's and light's
    visibility where it needs no map (1 no light, 0 turned away, else pending), the
    texel of the bound and writer maps that a pending one's lit test reads, and a bit
    per texel read (the bound passes draw only those)."""

    visible: object  # float[samples × lights]: 1, 0 or pending (cl/visibility.h, VISIBILITY_PENDING*)
    map_read: object  # int2[samples × lights]: texel address (or MAP_TEXEL_*), as_int(depth)
    read_mask: object  # uint per 32 texels of the frame's shadow maps, by address: a bit per texel read


def visibility_prepare(device: Device, buffers: FrameBuffers, rastered: RasterResult, timer: StageTimer) -> Prepared:
    """The part of the decision that needs no bound map (no light, turned away, or pending),
    and the texels that the pending samples will read."""
    inputs = buffers.inputs
    lights, sizes = max(len(inputs.scene.lights), 1), frame_sizes(inputs)
    visible, map_read = VISIBLE.allocate(device, sizes), MAP_READ.allocate(device, sizes)
    read_mask = READ_MASK.allocate(device, sizes)
    device.fill(read_mask, np.uint32(0), READ_MASK.nbytes(sizes), timer, "visibility")
    timer.add("visibility", device.kernel("visibility_prepare", "visibility_prepare")(
        device.queue, (-(-inputs.samples // PREPARE_LANES), lights), None, buffers.params, buffers.views,
        buffers.lights, rastered.camera_depth, rastered.tri_id, buffers.tri_normal,
        buffers.tri_vertex_normals, buffers.offsets, visible, map_read, read_mask))
    return Prepared(visible, map_read, read_mask)


@dataclass
class TouchingLists:
    """One light's lists, per texel read, of the triangles touching it (cl/visibility_bound.cl
    note_touching): what a shadow ray from a sample in that texel tests instead of the BVH."""

    head: object  # int per texel of the light's maps: first node, -1 none
    nodes: object  # int2 per node: (triangle, next node)
    count: object  # int: nodes taken; more than `capacity`, and some were left out
    capacity: int


@dataclass
class BoundMap:
    """A light's (or every light's, back to back) bound and writer maps, texel for texel
    the layout of its shadow map, and for a frame of few samples the light's lists of the
    triangles touching each texel read."""

    bound: object  # uint per texel, as_uint(depth): no triangle touching the texel is nearer
    writer: object  # int per texel: the one triangle that touches it, -1 none, -2 several
    texels: int
    touching: TouchingLists | None = None
    rects: dict | None = None  # view → int4 per triangle: its texel rectangle there (x0 > x1: none)


def visibility_bound(device: Device, buffers: FrameBuffers, light_index: int, timer: StageTimer,
                     prepared: Prepared | None = None) -> BoundMap:
    """One light's bound and writer maps, in the light-anchored space of its shadow map
    (clrays.inputs.light_pass_inputs), so the depths match. With `prepared`, only the
    texels whose bit its read_mask has are drawn (the others hold no value); without,
    every texel."""
    inputs = light_pass_inputs(buffers.inputs, light_index)
    # the frame's address of this light's texel 0 (read_mask is by frame addresses)
    first = int(buffers.inputs.views[buffers.inputs.light_views[light_index][0]]["depth_offset"])
    texels = max(inputs.shadow_texels, 1)
    sizes = frame_sizes(buffers.inputs).for_light(light_index)
    bound, writer = BOUND.allocate(device, sizes), WRITER.allocate(device, sizes)
    touching = None
    if prepared is not None and sizes.entries <= TOUCHING_ENTRIES:
        capacity = TOUCHING_NODES.length(sizes)  # (at least 1: 0 would read as lists left whole)
        touching = TouchingLists(TOUCHING_HEADS.allocate(device, sizes), TOUCHING_NODES.allocate(device, sizes),
                                 device.buffer(np.zeros(1, np.int32)), capacity)
    lists = ((touching.head, touching.nodes, touching.count, np.int32(touching.capacity)) if touching is not None
             else (device.buffer(nbytes=4), device.buffer(nbytes=8), device.buffer(nbytes=4), np.int32(0)))
    if prepared is None:
        device.fill(bound, structs.DEPTH_EMPTY, 4 * texels, timer, "visibility")
        device.fill(writer, np.int32(structs.WRITER_NONE), 4 * texels, timer, "visibility")
    elif inputs.shadow_texels:
        # Only the texels read: the others are never drawn nor read, and their memory never
        # touched (on a CPU device, filling a fresh 1024² cube's two maps costs more than
        # drawing them).
        words = (first + inputs.shadow_texels - 1) // 32 - first // 32 + 1
        timer.add("visibility", device.kernel("visibility_bound", "visibility_clear")(
            device.queue, (-(-words // structs.VISIBILITY_CLEAR_WORDS),), None, prepared.read_mask,
            np.int32(first), np.int32(inputs.shadow_texels), np.int32(1), bound, writer, lists[0], lists[3],
            *ungated(device)))
    # A frame too large for lists now may list its rays' texels later (ray_lists): the
    # rectangles let that pass skip the triangles that touch none of them.
    rects = {} if prepared is not None and touching is None else None
    _bound_passes(device, inputs, first, bound, writer, prepared.read_mask if prepared is not None else None, lists,
                  timer, rects)
    return BoundMap(bound, writer, inputs.shadow_texels, touching, rects)


def ungated(device: Device) -> tuple:
    """The route arguments (cl/visibility.h ROUTE_ARGS) of a launch that runs whatever the route."""
    return device.buffer(np.full(1, structs.VISIBILITY_ROUTE_ANY, np.int32)), np.int32(structs.VISIBILITY_ROUTE_ANY)


def _bound_passes(device: Device, inputs: FrameInputs, first: int, bound, writer, read_mask, lists: tuple,
                  timer: StageTimer, rects: dict | None = None, filter_rects: bool = False,
                  route: tuple | None = None) -> None:
    """Both bound passes of one light (`inputs` anchored at it) over the views the frame
    can read: with `read_mask`, only the texels whose bit it has (at the texel's address +
    `first`); `lists`, the touching-list arguments (capacity 0: none). `rects` (view →
    buffer): filled with each triangle's texel rectangle, or with `filter_rects`, read to
    skip the triangles whose rectangle holds no texel of `read_mask`. `route`: (visibility's
    route buffer, the route these passes run under), else they always run."""
    count = inputs.tri_vertices.shape[0] // 3
    if not count:
        return
    route = route or ungated(device)
    vertices = device.buffer(inputs.tri_vertices, writable=False)
    views = device.buffer(inputs.views, writable=False)
    masked = np.int32(read_mask is not None)
    read_mask = read_mask if read_mask is not None else device.buffer(nbytes=4)
    first_pass = device.kernel("visibility_bound", "visibility_bound")
    rows_pass = device.kernel("visibility_bound", "visibility_bound_rows")
    # Only the cube faces the frame can read (`view_needed`, as raster.shadow does): no
    # sample projects into the others, so their texels are never asked for.
    drawn = [int(view) for view in np.flatnonzero(inputs.view_needed[1:]) + 1]
    # Every view's first pass, then each view's list ordered nearest first and its rows
    # pass, all on the device: the kernels read the lists' lengths themselves, so the host
    # enqueues every pass without waiting (it read the lengths and the lists, and ordered
    # them itself: two waits per run of the passes, each draining the queue). Each view has
    # texels of its own, and a texel's values do not depend on the order of the passes.
    big = {}  # view → (its list of big items, their count)
    for view in drawn:
        if rects is None or (filter_rects and view not in rects):  # (a view the recording frame did not draw)
            mode = structs.RECTS_NONE
        else:
            mode = structs.RECTS_FILTER if filter_rects else structs.RECTS_RECORD
        if mode == structs.RECTS_RECORD:
            rects[view] = device.buffer(nbytes=16 * count)
        big[view] = device.buffer(nbytes=16 * count), device.buffer(np.zeros(1, np.int32))
        view_rects = rects[view] if mode != structs.RECTS_NONE else big[view][1]  # (unread without rects)
        timer.add("visibility", first_pass(
            device.queue, (count,), None, vertices, np.int32(count), views, np.int32(view), np.int32(1), bound,
            writer, masked, read_mask, np.int32(first), *lists, np.int32(BOUND_SMALL_ROWS), *big[view],
            np.int32(mode), view_rects, *route))
    # (one list's order at a time: the queue is in order, so each view's rows pass has read
    # its list before the next view's order overwrites it)
    ordered = device.buffer(nbytes=16 * count)
    order = device.kernel("visibility_bound", "visibility_order")
    for view in drawn:
        items, listed = big[view]
        timer.add("visibility", order(device.queue, (ORDER_ITEMS,), (ORDER_ITEMS,), vertices, views, np.int32(view),
                                      items, listed, ordered, *route))
        height, width = int(inputs.views[view]["height"]), int(inputs.views[view]["width"])
        # the first pass packs a triangle's first and last column in 16 bits each
        # (big_items' w; shadow maps are at most 8192 wide, clrays.scene.fields)
        assert width < 1 << 15, f"a view {width} texels wide"
        rows, columns = rows_pass_block(device, width)
        timer.add("visibility", rows_pass(
            device.queue, (-(-height // rows), -(-width // columns)), None, vertices, views, np.int32(view),
            np.int32(1), bound, writer, masked, read_mask, np.int32(first), *lists, ordered, listed,
            np.int32(rows), np.int32(columns), *route))


def ray_lists(device: Device, buffers: FrameBuffers, prepared: Prepared, ray_entries, ray_count,
              bounds: list[BoundMap], route, timer: StageTimer) -> list[TouchingLists]:
    """Per light, the triangles touching each texel that a listed shadow ray reads. The bound
    passes run again over those texels alone: they write the bound and writer maps' own
    values again (each texel's is the least, or the one, of the same triangles), and list
    the triangles as they go. Enqueued before the device knows whether the rays take this
    way: every launch returns at once unless `route` (visibility_route's) says
    VISIBILITY_ROUTE_RAY_LISTS, and the rays' count is read on the device. The lists have
    room for TOUCHING_NODES_PER_ENTRY nodes per ray of the most rays that take this way
    (visibility_route's list limit); visibility_reroute sends the rays to the BVH where a
    list holds more than TOUCHING_NODES_PER_ENTRY per ray of this frame's."""
    inputs, sizes = buffers.inputs, frame_sizes(buffers.inputs)
    gate = (route, np.int32(structs.VISIBILITY_ROUTE_RAY_LISTS))
    mask = RAY_LIST_MASK.allocate(device, sizes)
    device.fill(mask, np.uint32(0), RAY_LIST_MASK.nbytes(sizes), timer, "visibility")
    timer.add("visibility", device.kernel("visibility_prepare", "visibility_mark_listed")(
        device.queue, *device.list_launch(ray_list_limit(inputs)), ray_entries, ray_count, prepared.map_read, mask,
        *gate))
    capacity = RAY_LIST_NODES.length(sizes)
    lists = []
    for index, light in enumerate(bounds):
        light_inputs = light_pass_inputs(inputs, index)
        first = int(inputs.views[inputs.light_views[index][0]]["depth_offset"])
        light_sizes = sizes.for_light(index)
        touching = TouchingLists(RAY_LIST_HEADS.allocate(device, light_sizes),
                                 RAY_LIST_NODES.allocate(device, light_sizes), device.buffer(np.zeros(1, np.int32)),
                                 capacity)
        arguments = (touching.head, touching.nodes, touching.count, np.int32(capacity))
        if light.texels:
            light_words = (first + light.texels - 1) // 32 - first // 32 + 1
            # the lists' heads only: the maps keep their values, which the passes write again
            timer.add("visibility", device.kernel("visibility_bound", "visibility_clear")(
                device.queue, (-(-light_words // structs.VISIBILITY_CLEAR_WORDS),), None, mask, np.int32(first),
                np.int32(light.texels), np.int32(0), light.bound, light.writer, touching.head, np.int32(capacity),
                *gate))
            _bound_passes(device, light_inputs, first, light.bound, light.writer, mask, arguments, timer,
                          light.rects, filter_rects=light.rects is not None, route=gate)
        lists.append(touching)
    return lists


def ray_list_limit(inputs: FrameInputs) -> int:
    """The most shadow rays that ray_lists lists the texels of: RAY_LIST_ENTRIES, and no more
    than the frame has triangles (more rays, and the BVH is the cheaper way) or entries."""
    return ray_list_length(frame_sizes(inputs))


def ray_list_length(sizes: FrameSizes) -> int:
    """`ray_list_limit` from the frame's sizes."""
    return min(RAY_LIST_ENTRIES, sizes.triangles, sizes.entries)


def list_counts(device: Device, lists: list[TouchingLists]):
    """The node counts of every light's lists in one buffer (device copies: no wait)."""
    counts = device.buffer(nbytes=4 * max(len(lists), 1))
    for index, touching in enumerate(lists):
        device.cl.enqueue_copy(device.queue, counts, touching.count, byte_count=4, dst_offset=4 * index)
    return counts


def bound_atlas(device: Device, buffers: FrameBuffers, bounds: list[BoundMap]) -> BoundMap:
    """Every light's bound and writer maps back to back, at the depth offsets of the frame's views."""
    if len(bounds) == 1:
        return bounds[0]
    sizes = frame_sizes(buffers.inputs)
    atlas = BoundMap(BOUND_ATLAS.allocate(device, sizes), WRITER_ATLAS.allocate(device, sizes), _map_texels(sizes))
    for (first, _), light in zip(buffers.inputs.light_views, bounds):
        offset = 4 * int(buffers.inputs.views[first]["depth_offset"])
        for whole, part in ((atlas.bound, light.bound), (atlas.writer, light.writer)):
            device.cl.enqueue_copy(device.queue, whole, part, byte_count=4 * light.texels, dst_offset=offset)
    return atlas


def visibility(device: Device, buffers: FrameBuffers, rastered: RasterResult, prepared: Prepared, bound: BoundMap,
               bvh: Callable[[], DeviceBvh], timer: StageTimer, lights: list[BoundMap] | None = None):
    """(float[samples × lights]: 1 where the sample sees the light, 0 where it does not
    (`prepared.visible`, its pending entries decided), the shadow rays cast). The maps decide
    first; the entries they leave cast a shadow ray: against the triangles touching their
    texel where every light's BoundMap in `lists` has its lists whole and every ray has a
    texel; else, where the rays are few (ray_list_limit) and each has a texel, against lists
    made for their texels alone (ray_lists) where those are whole; else through the BVH,
    which `bvh()` builds (or gives the one a session kept) only then.

    The route is decided on the device (visibility_route, visibility_reroute), and the
    listed ways are enqueued before it, each launch returning at once unless the route is
    its own. On a CPU device the host then waits once, for the rays' count and the route,
    and builds the BVH only where the route asks for it (a scene with reliefs builds its
    tree on the host); on a GPU (`bvh_ahead`) the BVH is built or kept first and its rays
    gated on the route, and the count is read after the image (`RayCount`)."""
    inputs = buffers.inputs
    entries = inputs.samples * max(len(inputs.scene.lights), 1)
    ray_entries = RAY_ENTRIES.allocate(device, frame_sizes(inputs))
    ray_count = device.buffer(np.zeros(2, np.int32))  # rays, and those with no texel
    defines = {"SHADOW_DEPTH_IN_KEYS": 1} if rastered.depth_in_keys else {}  # (stages/raster.py depth_in_keys)
    defines.update(relief_defines(inputs.scene.geometry, rastered.depth_in_keys))
    timer.add("visibility", device.kernel("visibility", "visibility", defines)(
        device.queue, (-(-inputs.samples // PREPARE_LANES),), None, buffers.params, buffers.views, buffers.lights,
        rastered.shadow_depth, bound.bound, bound.writer, prepared.map_read, rastered.camera_depth, rastered.tri_id,
        buffers.tri_vertices, buffers.tri_normal, buffers.offsets, prepared.visible, ray_entries, ray_count))
    lights = lights or []
    own = [light.touching for light in lights]
    own = own if own and all(lists is not None for lists in own) else []  # a thumbnail's lists, for every light
    limit = ray_list_limit(inputs) if lights else 0
    route = device.buffer(nbytes=4)
    timer.add("visibility", device.kernel("visibility", "visibility_route")(
        device.queue, (1,), None, ray_count, np.int32(len(own)), list_counts(device, own),
        device.buffer(np.array([lists.capacity for lists in own] or [0], np.int32), writable=False),
        np.int32(limit), route))

    def rays_listed(lists: list[TouchingLists], wanted: int) -> None:
        for index, touching in enumerate(lists):
            # this frame's address of the light's texel 0 (a kept map's lists are by the light's own addresses)
            first = int(inputs.views[inputs.light_views[index][0]]["depth_offset"])
            timer.add("visibility", device.kernel("visibility_rays", "visibility_rays_listed")(
                device.queue, *device.list_launch(entries), buffers.params, buffers.views, buffers.lights,
                rastered.camera_depth, rastered.tri_id, buffers.tri_vertices, buffers.tri_normal, buffers.offsets,
                prepared.map_read, np.int32(index), np.int32(first), touching.head, touching.nodes, ray_entries,
                ray_count, prepared.visible, route, np.int32(wanted)))

    rays_listed(own, structs.VISIBILITY_ROUTE_LISTED)
    if limit:
        made = ray_lists(device, buffers, prepared, ray_entries, ray_count, lights, route, timer)
        timer.add("visibility", device.kernel("visibility", "visibility_reroute")(
            device.queue, (1,), None, ray_count, np.int32(len(made)), list_counts(device, made),
            np.int32(TOUCHING_NODES_PER_ENTRY), route))
        rays_listed(made, structs.VISIBILITY_ROUTE_RAY_LISTED)
    if bvh_ahead(device):  # the tree built (or kept) before the route is known, its rays gated by it
        _cast_through_bvh(device, buffers, rastered, prepared, bvh(), ray_entries, ray_count, entries,
                          (route, np.int32(structs.VISIBILITY_ROUTE_BVH)), timer)
        return prepared.visible, RayCount(device, ray_count)
    (rays, _), (taken,) = device.read_all([(ray_count, 2), (route, 1)], np.int32)
    if taken == structs.VISIBILITY_ROUTE_BVH:
        _cast_through_bvh(device, buffers, rastered, prepared, bvh(), ray_entries, ray_count, int(rays),
                          (route, np.int32(structs.VISIBILITY_ROUTE_ANY)), timer)
    return prepared.visible, int(rays)


def relief_defines(geometry, depth_in_keys: bool) -> dict:
    """The visibility kernel's defines for a geometry's reliefs. A relief's holes are finer
    than the map's texels, and the 3 × 3 test calls a sample seen through one shadowed
    (docs/visibility.md): where the maps' depths are their keys, which carry each texel's
    triangle, and the reliefs' triangles are the last ones (`place_reliefs`), the test skips
    a sample whose nine texels hold a relief's triangle (`VISIBILITY_RELIEF_FIRST`); else
    it is built without the test, and every sample the maps do not call lit casts its ray."""
    if not geometry.reliefs:
        return {}
    first = relief_first_triangle(geometry)
    if not depth_in_keys or first is None:
        return {"VISIBILITY_SHADOWED_TEST": 0}
    return {"VISIBILITY_RELIEF_FIRST": first}


def relief_first_triangle(geometry) -> int | None:
    """The index of the reliefs' first triangle where their triangles are the geometry's
    last (`place_reliefs` puts them there for the pre-warp), None otherwise."""
    rows = sorted((record.rows.start, record.rows.stop) for record in geometry.reliefs)
    contiguous = all(stop == next_start for (_, stop), (next_start, _) in zip(rows, rows[1:]))
    return rows[0][0] if contiguous and rows[-1][1] == geometry.count else None


def bvh_ahead(device: Device) -> bool:
    """Whether visibility builds the frame's BVH (or takes the kept one) before it knows
    whether a ray needs it, so that the host never waits inside the stage: on a GPU, where a
    wait leaves the device idle while the host enqueues what follows, and the tree's refit
    costs little. A CPU device waits for the rays' count and route instead and builds the
    tree only where a ray needs it (the host's wait costs it nothing: its cores run the
    kernels either way)."""
    return not device.is_cpu


def _cast_through_bvh(device: Device, buffers: FrameBuffers, rastered: RasterResult, prepared: Prepared,
                      tree: DeviceBvh, ray_entries, ray_count, bound: int, route: tuple, timer: StageTimer) -> None:
    """visibility_rays over the listed entries (at most `bound`, their count on the device),
    under `route` (visibility_rays' ROUTE_ARGS)."""
    timer.add("visibility", device.kernel("visibility_rays", "visibility_rays")(
        device.queue, *device.list_launch(max(bound, 1)), buffers.params, buffers.views, buffers.lights,
        rastered.camera_depth, rastered.tri_id, buffers.tri_vertices, buffers.tri_normal, buffers.offsets,
        tree.node_bounds, tree.node_children, np.int32(tree.root), ray_entries, ray_count, prepared.visible, *route))


class RayCount:
    """The shadow rays a frame cast, counted on the device (bvh_ahead): copied to the host
    behind the frame and read when asked for, by then (after the image) without a wait."""

    def __init__(self, device: Device, ray_count):
        self._device, self._host = device, np.zeros(2, np.int32)
        self._copy = device.cl.enqueue_copy(device.queue, self._host, ray_count, is_blocking=False)

    def __int__(self) -> int:
        self._device.collect(self._copy)
        return int(self._host[0])
