"""The relief pre-warp in numpy (docs/design.md, "Relief objects"): the viewer's coefficients
and the segment order that the relief stage hands the device, and the warp itself, the
yardstick of the device's.

Three pieces, each a plain transcription of the equations of docs/design.md, "Relief objects":

- `prewarp_coefficients`: k1, k2, k3 of a viewer (a centre of projection, or a direction
  for an orthographic view), and `prewarp_positions`: where each texel moves in the base
  plane, u_i = (u_s + k1·d)/(1 + k3·d), v_i = (v_s + k2·d)/(1 + k3·d).
- `splat_in_order` and `splat_zbuffer`: every texel warped to the target texel it lands
  in, visibility by McMillan's occlusion-compatible order (a later write wins) or by a
  z-buffer (the nearest to the viewer wins). The tests check that they agree.
- `prewarp_two_pass`: the warp as the device runs it, a row pass then a column pass
  (1D each), in occlusion-compatible order, filling between consecutive warped texels.

Texel coordinates: texel (row r, column c) has u_s = c + ½, v_s = r + ½ (`ReliefFrame`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene.relief import ReliefFrame


@dataclass(frozen=True)
class Viewer:
    """A view's centre of projection `position`, or for an orthographic view (a
    directional light's map) the `direction` its rays travel."""

    position: np.ndarray | None = None
    direction: np.ndarray | None = None

    def __post_init__(self):
        if (self.position is None) == (self.direction is None):
            raise ValueError("a viewer has a position or a direction, not both")


def prewarp_coefficients(frame: ReliefFrame, viewer: Viewer) -> tuple[float, float, float]:
    """(k1, k2, k3) of docs/design.md, "Relief objects" with c = C_s − C_t. An orthographic viewer is the
    limit C_t = C_s − t·direction, t → ∞: c ∝ direction, and k3 → 0."""
    a, b, f = frame.a, frame.b, frame.f
    c = frame.corner - viewer.position if viewer.position is not None else np.asarray(viewer.direction, float)
    k1 = np.dot(f, np.cross(b, c)) / np.dot(a, np.cross(b, c))
    k2 = np.dot(f, np.cross(c, a)) / np.dot(b, np.cross(c, a))
    k3 = np.dot(f, np.cross(a, b)) / np.dot(c, np.cross(a, b)) if viewer.position is not None else 0.0
    return float(k1), float(k2), float(k3)


def prewarp_positions(displacement: np.ndarray, k: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """(u_i, v_i), each (H, W): where texel (r, c) of displacement d moves in the base plane."""
    k1, k2, k3 = k
    rows, cols = displacement.shape
    u_s = np.arange(cols)[None, :] + 0.5
    v_s = np.arange(rows)[:, None] + 0.5
    scale = 1.0 / (1.0 + k3 * displacement)
    return (u_s + k1 * displacement) * scale, (v_s + k2 * displacement) * scale


def epipole(frame: ReliefFrame, viewer: Viewer) -> tuple[float, float, bool]:
    """(u_e, v_e, in_front): the viewer projected along f onto the base plane, in texel
    coordinates (for an orthographic viewer: a point far along the direction the rays come
    from), and whether the viewer is on the side the relief rises to (+f)."""
    basis = np.stack([frame.a, frame.b, frame.f], axis=1)
    if viewer.position is not None:
        u_e, v_e, height = np.linalg.solve(basis, viewer.position - frame.corner)
        return float(u_e), float(v_e), bool(height > 0)
    towards_viewer = np.linalg.solve(basis, -np.asarray(viewer.direction, float))
    far = 1e12
    return float(far * towards_viewer[0]), float(far * towards_viewer[1]), bool(towards_viewer[2] > 0)


def processing_order(coordinate: np.ndarray, epipole_coordinate: float) -> np.ndarray:
    """A rank per texel along one axis: McMillan's occlusion-compatible order, from the
    borders towards the epipole (closer to it: later, so it wins). Along any viewer ray the
    distance from the epipole in the base plane grows with the distance from the viewer,
    on either side of the plane, so the order is the same seen from behind."""
    return -np.abs(coordinate - epipole_coordinate)


def _target_cells(u_i, v_i, shape, origin) -> tuple[np.ndarray, np.ndarray]:
    """Flat target index of each warped texel (−1 outside the target grid)."""
    rows, cols = shape
    column = np.floor(u_i - origin[0]).astype(np.int64)
    row = np.floor(v_i - origin[1]).astype(np.int64)
    inside = (column >= 0) & (column < cols) & (row >= 0) & (row < rows)
    return np.where(inside, row * cols + column, -1), inside


def splat_in_order(frame: ReliefFrame, displacement: np.ndarray, viewer: Viewer, shape=None,
                   origin=(0.0, 0.0)) -> np.ndarray:
    """Each texel warped to the target texel it lands in, in occlusion-compatible order
    (quadrants around the epipole; in each, rows then columns towards it): (shape) flat
    source index of the texel that wins each target texel, −1 where none lands. The target
    grid has `shape` (the source's by default) and its texel (0, 0) starts at `origin`."""
    shape = displacement.shape if shape is None else shape
    u_i, v_i = prewarp_positions(displacement, prewarp_coefficients(frame, viewer))
    u_e, v_e, _ = epipole(frame, viewer)
    rows, cols = displacement.shape
    row_rank = processing_order(np.arange(rows) + 0.5, v_e)
    column_rank = processing_order(np.arange(cols) + 0.5, u_e)
    # Rank of each texel in the sweep: rows in their order, each row's columns in theirs.
    order = np.lexsort((np.broadcast_to(column_rank[None, :], (rows, cols)).ravel(),
                        np.broadcast_to(row_rank[:, None], (rows, cols)).ravel()))
    rank = np.empty(rows * cols, np.int64)
    rank[order] = np.arange(rows * cols)
    cells, inside = _target_cells(u_i, v_i, shape, origin)
    best = np.full(shape[0] * shape[1], -1, np.int64)
    np.maximum.at(best, cells.ravel()[inside.ravel()], rank[inside.ravel()])
    return np.where(best >= 0, order[np.maximum(best, 0)], -1).reshape(shape)


def splat_zbuffer(frame: ReliefFrame, displacement: np.ndarray, viewer: Viewer, shape=None,
                  origin=(0.0, 0.0)) -> np.ndarray:
    """As `splat_in_order`, but the texel nearest to the viewer wins (a z-buffer)."""
    shape = displacement.shape if shape is None else shape
    u_i, v_i = prewarp_positions(displacement, prewarp_coefficients(frame, viewer))
    points = frame.points(displacement).reshape(-1, 3)
    if viewer.position is not None:
        depth = np.linalg.norm(points - viewer.position, axis=1)
    else:
        depth = points @ np.asarray(viewer.direction, float)
    cells, inside = _target_cells(u_i, v_i, shape, origin)
    cells, inside = cells.ravel(), inside.ravel()
    source = np.flatnonzero(inside)
    order = np.lexsort((depth[source], cells[source]))  # by cell, nearest first
    sorted_cells = cells[source][order]
    first = np.ones(len(order), bool)
    first[1:] = sorted_cells[1:] != sorted_cells[:-1]
    best = np.full(shape[0] * shape[1], -1, np.int64)
    best[sorted_cells[first]] = source[order][first]
    return best.reshape(shape)


#: The attributes each pass carries per target texel: the source coordinates (u_s, v_s)
#: and the displacement, enough to rebuild the displaced point P (docs/design.md, "Relief objects").
EMPTY = np.nan


def segment_order(length: int, epipole_coordinate: float) -> np.ndarray:
    """The order in which a line's segments (k, k + 1), k = 0 … length − 2, are drawn:
    McMillan's order, each segment ranked by its end nearer the epipole, the farthest first
    (so segments on the two sides of the epipole interleave, and the nearest wins)."""
    centres = np.arange(length) + 0.5
    nearer = np.maximum(processing_order(centres[:-1], epipole_coordinate),
                        processing_order(centres[1:], epipole_coordinate))
    return np.argsort(nearer, kind="stable")


def _fill_pass(coordinate_i, attributes, valid, segments, cells_out, accept=None):
    """One 1D pass over every line (row of the arrays): for each segment k, k + 1 of a line,
    in the order `segments`, both ends valid, the output texels whose centres lie in
    [min(x_k, x_k+1), max(...)) get the attributes interpolated linearly between its
    ends, unless `accept(values)` says no; a later write wins. Returns (lines, cells_out,
    A), NaN where nothing was written."""
    lines, _ = coordinate_i.shape
    out = np.full((lines, cells_out, attributes.shape[2]), EMPTY)
    centres = np.arange(cells_out) + 0.5
    for line in range(lines):
        x, attr, ok = coordinate_i[line], attributes[line], valid[line]
        for k in segments:
            if not (ok[k] and ok[k + 1]):
                continue
            lo, hi = sorted((x[k], x[k + 1]))
            hit = np.flatnonzero((centres >= lo) & (centres < hi))
            if len(hit) == 0:
                continue
            t = (centres[hit] - x[k]) / (x[k + 1] - x[k])
            values = attr[k] + t[:, None] * (attr[k + 1] - attr[k])
            if accept is not None:
                keep = accept(values)
                hit, values = hit[keep], values[keep]
            out[line, hit] = values
    return out


def prewarp_two_pass(frame: ReliefFrame, displacement: np.ndarray, viewer: Viewer, solid: np.ndarray | None = None,
                     shape=None, origin=(0.0, 0.0)) -> np.ndarray:
    """The pre-warp as 1D passes (docs/design.md, "Relief objects"), (shape + (3,)): per target texel the
    (u_s, v_s, d) of the displaced surface seen through it, NaN where none is.

    Row pass: each source row, its texels in occlusion-compatible order along u, moved to
    u_i; between consecutive texels the target columns are filled by linear
    interpolation (the height field's edge between them). Column pass: each column of that
    intermediate image, its rows in order along v, moved to v_i (computed from its v_s and
    d), filled the same way. A segment over a hole (a cell with a corner of alpha 0) is
    not filled. A later write wins in both passes."""
    shape = displacement.shape if shape is None else shape
    rows, cols = displacement.shape
    solid = np.ones(displacement.shape, bool) if solid is None else solid
    k1, k2, k3 = prewarp_coefficients(frame, viewer)
    u_e, v_e, _ = epipole(frame, viewer)
    u_s = np.broadcast_to(np.arange(cols)[None, :] + 0.5, displacement.shape)
    v_s = np.broadcast_to(np.arange(rows)[:, None] + 0.5, displacement.shape)
    # 1 + k3·d ≤ 0: the texel is as far from the base plane as the viewer or beyond; its
    # ray meets the plane behind the viewer, and the warp leaves it out.
    ahead = 1.0 + k3 * displacement > 0
    u_i = (u_s + k1 * displacement) / np.where(ahead, 1.0 + k3 * displacement, 1.0) - origin[0]
    # Row pass: intermediate (rows, target columns, [u_s, v_s, d]).
    attributes = np.stack([u_s, v_s, displacement], axis=2)
    middle = _fill_pass(u_i, attributes, solid & ahead, segment_order(cols, u_e), shape[1])
    # Column pass: each intermediate column, v_i from its (v_s, d); a value whose source
    # point lies in a hole cell (a corner of alpha 0) is not written.
    d = middle[:, :, 2]
    v_i = (middle[:, :, 1] + k2 * d) / (1.0 + k3 * d) - origin[1]
    kept = solid[:-1, :-1] & solid[:-1, 1:] & solid[1:, :-1] & solid[1:, 1:]

    def outside_holes(values):
        cell_r = np.clip(np.floor(values[:, 1] - 0.5), 0, rows - 2).astype(int)
        cell_c = np.clip(np.floor(values[:, 0] - 0.5), 0, cols - 2).astype(int)
        return kept[cell_r, cell_c]

    out = _fill_pass(v_i.T, middle.transpose(1, 0, 2), ~np.isnan(d).T, segment_order(rows, v_e), shape[0],
                     outside_holes)
    return out.transpose(1, 0, 2)
