"""Shaft edges on the blockers: what the walks need to move a lit run's ends off the texel
boundaries onto the silhouettes of the triangles that bound the shaft (cl/shaft_edges.h,
docs/design.md §4.5, "Shaft edges on the blockers"). rectify keeps each texel's blocking
triangle (`Epipolar.triangles`); this adds the frame's triangles and which triangle lies
across each of their edges, and hands the three buffers to the walks as a walk feature
(clrays/stages/features.py)."""
from __future__ import annotations

import numpy as np

from ..buffers import BufferDecl
from ..device import Device, StageTimer
from ..inputs import see_through
from ..scene.geometry import weld
from ..scene.host_steps import timed


#: Each triangle's neighbour across each of its edges (int3: `edge_neighbours`).
EDGE_NEIGHBOURS = BufferDecl("each triangle's neighbours", 12, lambda sizes: sizes.triangles)

def keeps_blockers(render) -> bool:
    """Whether a frame's shadow maps and epipolar rows keep each texel's blocking triangle:
    minmax with `render.shaft_edges: blockers` (the default)."""
    return render.method == "minmax" and render.shaft_edges == "blockers"


class ShaftEdges:
    """The walk feature SHAFT_EDGES: each texel's blocker, the frame's triangles (eye
    space), each triangle's neighbours across its edges and its sides (`shaft_edge_sides`)."""

    def __init__(self, row_triangles, vertices, neighbours, sides):
        self.row_triangles, self.vertices, self.neighbours, self.sides = row_triangles, vertices, neighbours, sides

    def defines(self) -> dict:
        return {"SHAFT_EDGES": 1}

    def args(self) -> tuple:
        return self.row_triangles, self.vertices, self.neighbours, self.sides


def edge_neighbours(geometry) -> np.ndarray:
    """(T, 3) int32: each triangle's neighbour across its edges v0→v1, v1→v2 and v2→v0, by
    vertex positions; -1 at a border (no other opaque triangle has both ends), and for a
    translucent triangle, through which the light goes on (a pane is no part of its frame's
    silhouette). Where more than two triangles share an edge, each is linked to one other.
    Kept on the geometry: a mesh of 75 536 triangles takes about 60 ms."""
    return _edge_links(geometry)[0]


def edge_windings(geometry) -> np.ndarray:
    """(T,) uint8: bit k set where the neighbour across edge k (`edge_neighbours`) is wound
    the other way, its own copy of the edge running in the same direction: its normal then
    points to the other side of the surface, which `shaft_edge_sides` corrects for."""
    return _edge_links(geometry)[1]


def _edge_links(geometry) -> tuple[np.ndarray, np.ndarray]:
    def build() -> tuple[np.ndarray, np.ndarray]:
        corners = geometry.triangles.reshape(-1, 3)
        vertex = weld(corners)[0].reshape(-1, 3)
        start, end = vertex.ravel(), vertex[:, [1, 2, 0]].ravel()  # edge 3t + k: corner k → corner k + 1
        edge_key = np.minimum(start, end) * (int(vertex.max(initial=0)) + 1) + np.maximum(start, end)
        if geometry.translucent:  # no link to or from a translucent triangle
            edge_key[np.repeat(see_through(geometry), 3)] = -1 - np.arange(3 * int(see_through(geometry).sum()))
        order = np.argsort(edge_key, kind="stable")
        twin = np.flatnonzero(edge_key[order][1:] == edge_key[order][:-1])  # consecutive pairs of one edge
        first, second = order[twin], order[twin + 1]
        own = first // 3 == second // 3  # a degenerate triangle's edges meet each other
        first, second = first[~own], second[~own]
        neighbours = np.full(len(start), -1, dtype=np.int32)
        neighbours[first], neighbours[second] = second // 3, first // 3
        flipped = np.zeros(len(start), dtype=bool)
        flipped[first] = flipped[second] = start[first] == start[second]
        windings = (flipped.reshape(-1, 3) << np.arange(3)).sum(axis=1).astype(np.uint8)
        return neighbours.reshape(-1, 3), windings

    return geometry.kept(("edge links",), timed("edge links")(build))


def shaft_edge_sides(device: Device, epipolar, vertices, windings, count: int, timer: StageTimer):
    """uchar[count] on the device: each triangle's `edge_windings`, and bit FACES_LIGHT
    where its normal (v1 − v0) × (v2 − v0) points to the light's side of its plane, for the
    light of `epipolar`. A blocker's surface, followed across an edge, turns back in γ
    exactly where the two sides differ (with the windings' flip): a silhouette seen from the
    light, in any plane through it, so the walks stop there without cutting the neighbour
    (cl/shaft_edges.h)."""
    sides = device.buffer(nbytes=max(count, 1))
    if count:
        timer.add("traverse", device.kernel("shaft_edges", "shaft_edge_sides")(
            device.queue, (count,), None, epipolar.buffer, vertices, np.int32(count), windings, sides))
    return sides
