"""`clrays relief-to-mesh`: a scene's relief object written as the triangle mesh every method
renders for it (docs/design.md, "Relief objects"), to check it in another tool or to render
it as a mesh."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ClraysError
from ..image_io import write_atomic
from ..scene.geometry import MESH_SUFFIXES
from ..scene.load import load_scene, object_kinds


def write_mesh(triangles: np.ndarray, path: Path, albedo: np.ndarray | None = None) -> None:
    """Write triangles (T, 3, 3) as a binary PLY (shared vertices are not merged: two per
    cell, the same floats as the renderer's), or OBJ / STL by suffix; with `albedo` a PLY
    carries it as a face colour (8-bit), which the loader ignores. Written atomically
    (`clrays.image_io.write_atomic`): a failed write is one OutputError naming `path`."""
    import trimesh

    triangles = np.asarray(triangles, float).reshape(-1, 3, 3)
    vertices = triangles.reshape(-1, 3)
    faces = np.arange(len(vertices)).reshape(-1, 3)
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    if albedo is not None and Path(path).suffix.lower() == ".ply":
        mesh.visual.face_colors = np.concatenate(
            [np.round(np.clip(albedo, 0, 1) * 255), np.full((len(albedo), 1), 255)], axis=1).astype(np.uint8)
    # Written beside and renamed, as images are: a full disk leaves no partial mesh.
    write_atomic(Path(path), lambda temporary: mesh.export(temporary, file_type=Path(path).suffix.lower()[1:]))


def relief_to_mesh(scene_path: Path | str, output: Path | str, index: int | None = None,
                   overrides=()) -> tuple[int, int]:
    """Write relief object `index` of a scene (the first relief when None) as a triangle
    mesh in world space, its transform applied: the triangles every method renders for it.
    Returns (object index, triangle count). Raises ClraysError for a scene without such a
    relief or an output suffix other than .ply, .obj or .stl."""
    output = Path(output)
    if output.suffix.lower() not in MESH_SUFFIXES:
        raise ClraysError(f"{output}: unknown mesh extension {output.suffix or '(none)'!r}; expected one of "
                          f"{', '.join(MESH_SUFFIXES)}")
    kinds = object_kinds(scene_path, overrides)
    reliefs = [i for i, kind in enumerate(kinds) if kind == "relief"]
    if index is None:
        if not reliefs:
            raise ClraysError(f"{scene_path}: objects: expected at least one object of type relief, got none")
        index = reliefs[0]
    elif index not in reliefs:
        got = kinds[index] if 0 <= index < len(kinds) else f"no object {index} ({len(kinds)} objects)"
        raise ClraysError(f"{scene_path}: objects.{index}: expected an object of type relief, got {got}")
    geometry = load_scene(scene_path, overrides).geometry
    rows = geometry.object_id == index
    write_mesh(geometry.triangles[rows], output, geometry.albedo[rows])
    return index, int(rows.sum())
