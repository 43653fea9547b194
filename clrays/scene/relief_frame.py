"""What a frame asks of a relief's triangles, answered from its texels (docs/design.md,
"Relief objects", "What a frame carries").

A 1024² relief is 2 M height-field triangles; its texels are 1 M points and its world
placement four handle vertices (`ReliefRecord`). A frame needs of those triangles their
bounds (directional maps, the lamp radius), their farthest vertex from the eye (the
effective far), a digest (reuse keys) and, for shading, each triangle's normal and
albedo. Each is taken here from the relief's own inputs, the texels and the handles,
and kept on the record while the handles stay where they are, so a frame that draws the
relief by its pre-warp reads its 2 M triangles nowhere.

The texel points are those of `world_frame`, the frame the pre-warp draws in: they are
the triangles' vertices up to float64 rounding (the loader transformed the local
vertices, `world_frame` the local frame).
"""
from __future__ import annotations

from typing import Iterator

import numpy as np

from ..digest import digest
from .relief import ReliefRecord, world_frame

#: World placements kept per relief: a still relief needs one, a sweep that moves it revisits a few,
#: and each costs memory of the order of its triangles (the faces: 32 bytes per triangle).
PLACEMENTS_KEPT = 2


def handle_points(record: ReliefRecord, triangles: np.ndarray) -> np.ndarray:
    """(4, 3) the record's handle vertices where `triangles` (the scene's) put them: with
    the relief's texels, they fix its triangles (an affine map, `world_frame`)."""
    return triangles[record.rows].reshape(-1, 3)[record.handles]


def vertex_texels(record: ReliefRecord) -> np.ndarray:
    """(H, W) bool: the texels that are a vertex of some triangle (a corner of a cell that
    is not a hole)."""
    if "vertex_texels" not in record.memo:
        cells = record.cell_triangle >= 0
        used = np.zeros(record.shape, bool)
        used[:-1, :-1] |= cells
        used[:-1, 1:] |= cells
        used[1:, :-1] |= cells
        used[1:, 1:] |= cells
        record.memo["vertex_texels"] = used
    return record.memo["vertex_texels"]


def _placed(record: ReliefRecord, triangles: np.ndarray) -> dict:
    """The per-placement memo of a relief (its texel points' bounds, the points themselves),
    keyed by its handle vertices."""
    key = handle_points(record, triangles).tobytes()
    placements = record.memo.setdefault("placements", {})
    if key not in placements:
        if len(placements) >= PLACEMENTS_KEPT:
            placements.pop(next(iter(placements)))
        frame, displacement = world_frame(record, triangles)
        points = frame.points(displacement)[vertex_texels(record)]
        placements[key] = {"points": points, "bounds": (points.min(axis=0), points.max(axis=0))}
    return placements[key]


def relief_bounds(record: ReliefRecord, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the relief's triangles' vertices, world space."""
    return _placed(record, triangles)["bounds"]


def relief_farthest(record: ReliefRecord, triangles: np.ndarray, point: np.ndarray) -> float:
    """Squared distance from `point` to the relief's farthest vertex (one pass over its
    texel points, kept for the last point: a frame asks for its eye several times, and a
    still camera's frames alike)."""
    placed = _placed(record, triangles)
    key = np.asarray(point, np.float64).tobytes()
    if placed.get("farthest_from") != key:
        placed["farthest"] = float((((placed["points"] - point) ** 2).sum(axis=1)).max())
        placed["farthest_from"] = key
    return placed["farthest"]


def relief_digest_parts(record: ReliefRecord, triangles: np.ndarray, albedo: np.ndarray | None) -> tuple:
    """What fixes the relief's rows of a Geometry: its texels (and albedo map), digested once
    per relief, its handle vertices, and, unless `albedo` is None (a key of the triangles
    alone), its first triangle's albedo (the object's albedo when it has no albedo map).
    Its normals are its triangles' face normals."""
    if "digest" not in record.memo:
        relief = record.relief
        record.memo["digest"] = digest("relief", relief.frame, relief.displacement, relief.solid, relief.albedo,
                                       record.rows.stop - record.rows.start, record.handles, record.handle_points)
    return (record.rows.start, record.memo["digest"], handle_points(record, triangles),
            None if albedo is None else albedo[record.rows.start])


def relief_faces(record: ReliefRecord, geometry) -> tuple[np.ndarray, np.ndarray]:
    """((T, 4) float32 unit face normals, w = 0, (T, 4) float32 albedo) of the relief's
    triangles in `geometry`, as `clrays.inputs.frame_inputs` packs them, kept per placement
    (the handles fix the normals): the shade and shadow stages look them up by triangle id."""
    normals, albedo = geometry.normals, geometry.albedo
    key = (handle_points(record, geometry.triangles).tobytes(), albedo[record.rows.start].tobytes())
    faces = record.memo.setdefault("faces", {})
    if key not in faces:
        if len(faces) >= PLACEMENTS_KEPT:
            faces.pop(next(iter(faces)))
        count = record.rows.stop - record.rows.start
        packed_normals = np.zeros((count, 4), np.float32)
        packed_normals[:, :3] = normals[record.rows, 0]  # flat: every vertex holds the face normal
        packed_albedo = np.zeros((count, 4), np.float32)
        packed_albedo[:, :3] = albedo[record.rows]
        faces[key] = (packed_normals, packed_albedo)
    return faces[key]


def other_rows(count: int, reliefs) -> Iterator[slice]:
    """The runs of rows of a Geometry of `count` triangles that belong to no relief."""
    start = 0
    for rows in sorted((record.rows for record in reliefs), key=lambda rows: rows.start):
        if rows.start > start:
            yield slice(start, rows.start)
        start = max(start, rows.stop)
    if start < count:
        yield slice(start, count)
