"""Where a frame puts its reliefs (docs/design.md, "Relief objects", "What a frame carries"):
with `render.relief: prewarp` the reliefs' triangles go after every other, so that the
raster stage draws the first `raster_triangles` itself and the relief stage
(clrays/stages/relief.py) the rest by their pre-warp; and whether the frame's triangle
buffers carry the reliefs' triangles at all. Data for the frame's inputs (clrays.inputs),
which the stages read.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .model import Scene
from .relief import ReliefFrame, ReliefRecord, world_frame


@dataclass(frozen=True)
class PlacedRelief:
    """One relief of a frame: its frame in world space and where its triangles are in the
    frame's triangle buffers (after every triangle the raster stage draws itself)."""

    frame: ReliefFrame  # world space, float64
    displacement: np.ndarray  # (H, W) scene units along frame.f
    solid: np.ndarray  # (H, W) bool
    cell_triangle: np.ndarray  # (H - 1, W - 1) int32, within the relief's triangles; −1: hole
    first_triangle: int


def place_reliefs(scene: Scene) -> tuple[Scene, tuple[PlacedRelief, ...], int | None]:
    """With `render.relief: prewarp`, the scene with its reliefs' triangles moved after all
    the others (same triangles, another order; nothing moves where they are last already,
    as a scene that lists its reliefs last has them), the reliefs placed, and how many
    triangles the raster stage draws itself; the scene unchanged, (), None otherwise."""
    geometry = scene.geometry
    if scene.render.relief != "prewarp" or not geometry.reliefs:
        return scene, (), None
    drawn = geometry.count - sum(record.rows.stop - record.rows.start for record in geometry.reliefs)
    records, start = [], drawn
    for record in geometry.reliefs:
        rows = slice(start, start + record.rows.stop - record.rows.start)
        records.append(record if rows == record.rows else _moved_record(record, rows))
        start = rows.stop
    if any(moved is not record for moved, record in zip(records, geometry.reliefs)):
        is_relief = np.zeros(geometry.count, bool)
        for record in geometry.reliefs:
            is_relief[record.rows] = True
        order = np.concatenate([np.flatnonzero(~is_relief)]
                               + [np.arange(geometry.count)[r.rows] for r in geometry.reliefs])
        geometry = replace(geometry, triangles=geometry.triangles[order], albedo=geometry.albedo[order],
                           object_id=geometry.object_id[order], normals=geometry.normals[order],
                           smooth=geometry.smooth[order], outward=geometry.outward[order], reliefs=tuple(records),
                           convex_part=geometry.convex_part[order],
                           opacity=None if geometry.opacity is None else geometry.opacity[order])
    placed = []
    for record in records:
        frame, displacement = world_frame(record, geometry.triangles)
        placed.append(PlacedRelief(frame, displacement, record.relief.solid, record.cell_triangle, record.rows.start))
    return replace(scene, geometry=geometry), tuple(placed), drawn


def _moved_record(record: ReliefRecord, rows: slice) -> ReliefRecord:
    """The record at other rows, sharing what frames derived from its texels (the memo holds
    nothing that depends on where its rows are)."""
    moved = replace(record, rows=rows)
    moved.__dict__["memo"] = record.memo
    return moved


def carries_relief_triangles(scene: Scene) -> bool:
    """Whether a frame's triangle buffers hold its reliefs' triangles besides the pre-warp:
    the exact surface shadows' BVH and bound map, the filtered shadows' depth range, and
    minmax's walks, which place the shafts' edges on the blockers (cl/shaft_edges.h), read
    them (docs/design.md, "What a frame carries"). Otherwise they are left out."""
    render = scene.render
    return bool(scene.lights) and (render.surface_shadows in ("exact", "filtered")
                                   or (render.method == "minmax" and render.shaft_edges == "blockers"))
