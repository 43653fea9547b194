"""Relief shadows in the volume, cut per ray: the walk feature RELIEF_CUTS (cl/relief_cuts.h;
docs/design.md §4.5, "A relief's shadow cut per ray").

A relief's bars and holes are finer than the shadow map an image derives: a sliver of
light between two bars falls between the texel centres of the map, of the γ row and of
the slices, and a ray between two slices blends two different patterns. So where the walks
place their runs on the blockers (minmax with `render.shaft_edges: blockers`), a relief
drawn by its pre-warp stays out of the map the volume reads (raster keeps the keys from
before the reliefs: `ShadowMap.volume`), and each walk cuts the relief in its ray's own
half-plane instead.

What the walk cuts is the relief's outline seen from the light: the edges of its triangles
where the number of them that a light ray crosses changes (a border, a hole's rim, a fold
where the surface turns from facing the light to facing away). Each keeps that change (±1
or ±2 for passing it one way); the edges two triangles facing the same way share change
nothing and are left out. Along the ray, a point is in the relief's shadow where the light
ray through it crosses some triangle between it and the light: the walk starts from the
eye's own count (`eye_layers`, float64 on the host) and adds each crossing's change in
rising γ, where the crossing lies towards the light from the ray. The edges are binned by
their angle α around the eye's light ray, so a ray reads only its bin's edges.
"""
from __future__ import annotations

import math

import numpy as np

from ..scene.geometry import weld
from ..scene.model import DirectionalLight

#: Crossings one ray gathers at most (cl/relief_cuts.h): the bins are made fine enough that
#: no bin holds more edges than this.
RELIEF_CROSSINGS = 256
#: Bins of α around the eye's light ray, at least and at most.
MIN_BINS, MAX_BINS = 1024, 65536
#: Fewest bins, where edges spanning wide angles (an eye beside a relief) would take more
#: than MAX_BINNED_EDGES at MIN_BINS.
FEWEST_BINS = 16
#: Edges written into the bins at most (32 bytes each: 128 MiB). An edge is written into every
#: bin its angle spans, so finer bins cost more of them; the bins stop doubling before this.
MAX_BINNED_EDGES = 4 * 2**20
#: Entries per edge the bins double towards, once every bin is within RELIEF_CROSSINGS: an
#: edge's bins are those its arc passes and one either side, so a ray reads, besides the edges
#: that cross its half-plane, those whose arc ends in a neighbouring bin. At 16 entries an edge
#: those two make up an eighth of the entries on average. On scenes/lattice.yaml (13 k outline edges) the
#: 4096 bins where none held over 256 edges gave a ray 132 edges to read for 82 that cross it;
#: 16384 bins give it 95, for 296 k entries (9.5 MB).
ENTRIES_PER_EDGE = 16


def cuts_reliefs(inputs, has_keys: bool) -> bool:
    """Whether a frame's walks cut its reliefs themselves, the volume's map leaving them
    out: minmax placing its runs on the blockers, reliefs drawn by their pre-warp, shadow
    maps drawn with 64-bit keys (`has_keys`: the keys from before the reliefs are the
    volume's map), and no translucent object (whose layers are walked texel by texel)."""
    scene = inputs.scene
    render = scene.render
    return (render.method == "minmax" and render.shaft_edges == "blockers" and bool(inputs.reliefs)
            and has_keys and not scene.geometry.translucent and bool(scene.lights))


def relief_outline(triangles: np.ndarray, light, record=None) -> tuple[np.ndarray, np.ndarray]:
    """The outline of one relief's triangles (T, 3, 3, float64) seen from `light`:
    ((E, 2, 3) each edge's ends, lower vertex first; (E,) how the number of triangles a
    light ray crosses changes when it passes the edge from its right to its left). A
    triangle a, b, c lies left of its side a → b where det(b − a, c − a, t) > 0, t towards
    the light (ω, or the light's position less a); one seen edge-on from the light lies on
    neither side. `record`: the relief's record, which keeps the edges' topology."""
    topology = None if record is None else record.memo.get("relief_cut_edges")
    if topology is None:
        corners = triangles.reshape(-1, 3)
        vertex = weld(corners, ordered=True)[0].reshape(-1, 3)  # "lower" below: first in (x, y, z) order
        start, end = vertex.ravel(), vertex[:, [1, 2, 0]].ravel()
        forward = start < end
        key = np.minimum(start, end) * (int(vertex.max(initial=0)) + 1) + np.maximum(start, end)
        _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
        topology = {"forward": forward, "first": first, "inverse": inverse.ravel()}
        if record is not None:
            record.memo["relief_cut_edges"] = topology
    a = triangles.reshape(-1, 3)
    b = triangles[:, [1, 2, 0]].reshape(-1, 3)
    c = triangles[:, [2, 0, 1]].reshape(-1, 3)
    towards = -np.asarray(light.direction, np.float64) if isinstance(light, DirectionalLight) \
        else np.asarray(light.position, np.float64) - a
    side = np.sign(np.einsum("ij,ij->i", np.cross(b - a, c - a), np.broadcast_to(towards, a.shape)))
    forward = topology["forward"]
    change = np.bincount(topology["inverse"], weights=np.where(forward, side, -side),
                         minlength=len(topology["first"]))
    kept = topology["first"][change != 0]
    low = np.where(forward[kept, None], a[kept], b[kept])
    high = np.where(forward[kept, None], b[kept], a[kept])
    return np.stack([low, high], axis=1), change[change != 0]


#: Where the eye's light ray meets an edge or a vertex of a relief (a scene of round numbers
#: can put it there), the count at the eye is ambiguous: the rays leaving it in different
#: directions start in different triangles, or outside. The walks' rays are taken to start
#: this fraction of the edges' reach from the eye beside it instead, across its light ray, in a
#: direction no scene is likely to line up with: there the count is one number. Above
#: float32's rounding of the edges around the eye (6e-8 of that reach), so that the
#: walks see the point on the side the count took, and small enough to move no image: at
#: 1e-5 of it the lattice's errors against `exact` rose in their third digit
#: (the shafts all shift one way, and a grazing ray adds up the shifts of 50 crossings).
EYE_NUDGE = 1e-6
_NUDGE_DIRECTION = np.array([0.5377, 0.3121, -0.7836])


def nudged_eye(eye: np.ndarray, light, size: float) -> np.ndarray:
    """The point EYE_NUDGE × `size` beside `eye`, across its light ray, where the walks cut
    the reliefs from (world space, float64); `size` is the reach of the edges around the
    eye, whose float32 rounding in eye space the nudge must clear."""
    direction = -np.asarray(light.direction, np.float64) if isinstance(light, DirectionalLight) \
        else np.asarray(light.position, np.float64) - eye
    direction = direction / np.linalg.norm(direction)
    across = _NUDGE_DIRECTION - (_NUDGE_DIRECTION @ direction) * direction
    return eye + EYE_NUDGE * size * across / np.linalg.norm(across)


def eye_layers(triangles: np.ndarray, eye: np.ndarray, light) -> int:
    """How many of the triangles (T, 3, 3) the light ray from `eye` crosses on its way to the
    light (float64): the relief's count where every ray of the eye begins (at a point no
    edge's light ray passes through: `nudged_eye`)."""
    if isinstance(light, DirectionalLight):
        direction, reach = -np.asarray(light.direction, np.float64), math.inf
    else:
        to_light = np.asarray(light.position, np.float64) - eye
        reach = float(np.linalg.norm(to_light))
        direction = to_light / reach
    v0, edge1, edge2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    p = np.cross(direction, edge2)
    det = np.einsum("ij,ij->i", edge1, p)
    usable = np.abs(det) > 1e-300
    inv = np.where(usable, 1.0 / np.where(usable, det, 1.0), 0.0)
    s = eye - v0
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, edge1)
    v = np.einsum("j,ij->i", direction, q) * inv
    t = np.einsum("ij,ij->i", edge2, q) * inv
    hit = usable & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t < reach)
    return int(hit.sum())


def alpha_bins(ends: np.ndarray, u: np.ndarray, w: np.ndarray) -> tuple[int, np.ndarray, np.ndarray, np.ndarray] | None:
    """The edges (E, 2, 3, eye space) binned by α = atan2(p·w, p·u), the angle around the
    eye's light ray, over the whole turn: (bins, (bins + 1,) int32 offsets, the edges of
    every bin one after another, each bin's in order of their nearest distance from the
    eye's light ray, and (E,) that distance, at most that of their ends). An edge goes
    into every bin its shorter arc of α passes, and one more either side (a ray's α on the
    device may round into the next bin). The bins double from MIN_BINS while one holds
    more than RELIEF_CROSSINGS edges (fewer than MIN_BINS where the edges would take more
    than MAX_BINNED_EDGES entries there), then on while the entries are fewer than
    ENTRIES_PER_EDGE per edge and the next doubling stays within MAX_BINS and
    MAX_BINNED_EDGES: a ray reads fewer edges that miss its half-plane. None where no count of bins up to MAX_BINS keeps
    every bin within RELIEF_CROSSINGS edges and all within MAX_BINNED_EDGES entries: the
    light then reads its reliefs from the map (clrays.session)."""
    x, y = ends @ u, ends @ w
    alpha = np.arctan2(y, x)
    sweep = np.remainder(alpha[:, 1] - alpha[:, 0] + math.pi, 2 * math.pi) - math.pi
    low = np.minimum(alpha[:, 0], alpha[:, 0] + sweep)
    high = np.maximum(alpha[:, 0], alpha[:, 0] + sweep)
    # each edge's nearest approach to the light ray, in the plane across it (its ends', or
    # the foot of the perpendicular where that falls between them)
    dx, dy = x[:, 1] - x[:, 0], y[:, 1] - y[:, 0]
    along = np.clip(-(x[:, 0] * dx + y[:, 0] * dy) / np.maximum(dx * dx + dy * dy, 1e-300), 0.0, 1.0)
    distance = np.hypot(x[:, 0] + along * dx, y[:, 0] + along * dy)

    def spans_at(bins: int):
        first = np.floor((low + math.pi) / (2 * math.pi) * bins).astype(np.int64) - 1
        last = np.floor((high + math.pi) / (2 * math.pi) * bins).astype(np.int64) + 1
        return first, np.minimum(last - first + 1, bins)

    def counts_at(bins: int, first: np.ndarray, spans: np.ndarray) -> np.ndarray:
        """Each bin's edges, from where the spans start and end (the entries themselves are
        written once, at the bins chosen): a span that wraps past the last bin goes on from 0."""
        start = np.remainder(first, bins)
        change = np.bincount(start, minlength=2 * bins + 1) - np.bincount(start + spans, minlength=2 * bins + 1)
        running = np.cumsum(change)[:2 * bins]
        return running[:bins] + running[bins:]

    bins = MIN_BINS
    while bins > FEWEST_BINS and int(spans_at(bins)[1].sum()) > MAX_BINNED_EDGES:  # (edges spanning wide angles)
        bins //= 2
    while True:
        first, spans = spans_at(bins)
        entries = int(spans.sum())
        if entries > MAX_BINNED_EDGES:
            return None
        counts = counts_at(bins, first, spans)
        within = counts.max(initial=0) <= RELIEF_CROSSINGS
        finer = bins < MAX_BINS and int(spans_at(2 * bins)[1].sum()) <= MAX_BINNED_EDGES
        if within and (not finer or entries >= ENTRIES_PER_EDGE * len(ends)):
            break
        if not finer:
            return None
        bins *= 2
    # the entries, edge by edge nearest the light ray first, then put in bin order by a
    # stable sort, so each bin keeps that order (on 16-bit keys numpy's stable sort is a
    # radix sort: 6 ms for the lattice's 296 k entries, where 32-bit keys took 28)
    nearest_first = np.argsort(distance, kind="stable")
    edge = np.repeat(nearest_first, spans[nearest_first])
    step = np.arange(len(edge)) - np.repeat(np.cumsum(spans[nearest_first]) - spans[nearest_first],
                                            spans[nearest_first])
    where = np.remainder(first[edge] + step, bins)
    order = np.argsort(where.astype(np.uint16 if bins <= 2**16 else np.int64), kind="stable")
    offsets = np.zeros(bins + 1, np.int32)
    offsets[1:] = np.cumsum(counts)
    return bins, offsets, edge[order], distance


class ReliefCuts:
    """The walk feature RELIEF_CUTS of one light: its reliefs' outline edges in eye space,
    bin after bin of α (a float4 pair each: the lower end and the edge's change, the higher
    end and a distance from the eye's light ray that none of the edge's points is under),
    each bin's first entry, and the eye's count. An edge is written once in each of its
    bins: a ray then reads its bin's edges one after another."""

    def __init__(self, device, edges: np.ndarray, change: np.ndarray, bins: int, offsets: np.ndarray,
                 binned: np.ndarray, distance: np.ndarray, eye_count: int):
        packed = np.zeros((len(binned), 2, 4), np.float32)
        packed[:, :, :3] = edges[binned]
        packed[:, 0, 3] = change[binned]
        # rounded down to float32, so that the device's break on it is never too early
        near = distance[binned].astype(np.float32)
        packed[:, 1, 3] = np.where(near.astype(np.float64) > distance[binned], np.nextafter(near, np.float32(0)), near)
        self.edges = device.buffer(packed.reshape(-1, 4) if len(packed) else np.zeros((2, 4), np.float32),
                                   writable=False)
        self.offsets = device.buffer(offsets, writable=False)
        self.bins, self.eye_count = bins, eye_count

    def defines(self) -> dict:
        return {"RELIEF_CUTS": 1, "RELIEF_CROSSINGS": RELIEF_CROSSINGS}

    def args(self) -> tuple:
        return self.edges, self.offsets, np.int32(self.bins), np.int32(self.eye_count)


def relief_outlines(scene, light) -> tuple[np.ndarray, np.ndarray]:
    """The outline of every relief of `scene` (its triangles in `scene.geometry`) seen from
    `light`, world space: ((E, 2, 3) the edges' ends, (E,) their changes)."""
    outlines = [relief_outline(scene.geometry.triangles[record.rows].astype(np.float64), light, record)
                for record in scene.geometry.reliefs]
    return np.concatenate([ends for ends, _ in outlines]), np.concatenate([change for _, change in outlines])


def relief_cuts(device, scene, light_index: int, outline: tuple[np.ndarray, np.ndarray], eye: np.ndarray,
                params: np.ndarray) -> ReliefCuts | None:
    """One light's RELIEF_CUTS: its reliefs' outline (`relief_outlines`) around the eye
    `eye` (world space; taken from `nudged_eye`), binned around the axis of its epipolar
    frame `params`, with the eye's count. None where the bins cannot hold the outline
    (`alpha_bins`)."""
    light = scene.lights[light_index]
    # the scale of the edges' float32 coordinates around the eye, which the nudge must clear
    size = float(np.abs(outline[0] - eye).max(initial=0.0))
    eye = nudged_eye(eye, light, size)
    ends = outline[0] - eye
    binned = alpha_bins(ends, params["u"][:3].astype(np.float64), params["w"][:3].astype(np.float64))
    if binned is None:
        return None
    eye_count = sum(eye_layers(scene.geometry.triangles[record.rows].astype(np.float64), eye, light)
                    for record in scene.geometry.reliefs)
    return ReliefCuts(device, ends.astype(np.float32), outline[1], *binned, eye_count)
