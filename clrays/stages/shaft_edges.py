"""Shaft edges on the blockers: what the walks need to move a lit run's ends off the texel
boundaries onto the silhouettes of the triangles that bound the shaft (cl/shaft_edges.h,
docs/design.md §4.5, "Shaft edges on the blockers"). rectify keeps each texel's blocking
triangle (`Epipolar.triangles`); this adds the frame's triangles and which triangle lies
across each of their edges, and hands the three buffers to the walks as a walk feature
(clrays/stages/features.py)."""
from __future__ import annotations

import numpy as np

from ..inputs import see_through


def keeps_blockers(render) -> bool:
    """Whether a frame's shadow maps and epipolar rows keep each texel's blocking triangle:
    minmax with `render.shaft_edges: blockers` (the default)."""
    return render.method == "minmax" and render.shaft_edges == "blockers"


class ShaftEdges:
    """The walk feature SHAFT_EDGES: each texel's blocker, the frame's triangles (eye
    space) and each triangle's neighbours across its edges."""

    def __init__(self, row_triangles, vertices, neighbours):
        self.row_triangles, self.vertices, self.neighbours = row_triangles, vertices, neighbours

    def defines(self) -> dict:
        return {"SHAFT_EDGES": 1}

    def args(self) -> tuple:
        return self.row_triangles, self.vertices, self.neighbours


def edge_neighbours(geometry) -> np.ndarray:
    """(T, 3) int32: each triangle's neighbour across its edges v0→v1, v1→v2 and v2→v0, by
    vertex positions; -1 at a border (no other opaque triangle has both ends), and for a
    translucent triangle, through which the light goes on (a pane is no part of its frame's
    silhouette). Where more than two triangles share an edge, each is linked to one other.
    Kept on the geometry: a mesh of 75 536 triangles takes about 60 ms."""
    def build() -> np.ndarray:
        corners = geometry.triangles.reshape(-1, 3)
        _, vertex = np.unique(corners, axis=0, return_inverse=True)
        vertex = vertex.reshape(-1, 3).astype(np.int64)
        start, end = vertex.ravel(), vertex[:, [1, 2, 0]].ravel()  # edge 3t + k: corner k → corner k + 1
        edge_key = np.minimum(start, end) * (int(vertex.max(initial=0)) + 1) + np.maximum(start, end)
        if geometry.translucent:  # no link to or from a translucent triangle
            edge_key[np.repeat(see_through(geometry), 3)] = -1 - np.arange(3 * int(see_through(geometry).sum()))
        order = np.argsort(edge_key, kind="stable")
        twin = np.flatnonzero(edge_key[order][1:] == edge_key[order][:-1])  # consecutive pairs of one edge
        first, second = order[twin], order[twin + 1]
        neighbours = np.full(len(start), -1, dtype=np.int32)
        neighbours[first], neighbours[second] = second // 3, first // 3
        own = first // 3 == second // 3  # a degenerate triangle's edges meet each other
        neighbours[first[own]] = neighbours[second[own]] = -1
        return neighbours.reshape(-1, 3)

    return geometry.kept(("edge neighbours",), build)
