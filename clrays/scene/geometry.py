"""Triangle tessellations of the scene's primitive objects and meshes, float64 numpy.

Every function returns triangles of shape (T, 3, 3) in the object's local frame (the
loader applies the object's transform afterwards). Surfaces are two-sided for the
renderer, but closed shapes are still wound counter-clockwise seen from outside, so
(b - a) x (c - a) is the outward normal; a plane's triangles face along its normal.
Shading normals come per triangle vertex, (T, 3, 3): a mesh's vertex normals for smooth
shading, or each triangle's own normal on all three of its vertices for flat shading.
"""
from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np

from .files import FileRefused, missing, read_regular_file
from .host_steps import timed
from .limits import MAX_MESH_BYTES
from .ply import read_binary_triangles

MESH_SUFFIXES = (".obj", ".ply", ".stl")


def indexed_triangles(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Gather (F, 3) integer faces over (V, 3) vertices into (F, 3, 3) triangles."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces)
    f = (f if f.dtype.kind in "iu" else f.astype(np.int64)).reshape(-1, 3)  # any integer type indexes, uncopied
    return v[f]


def box_triangles(lo, hi) -> np.ndarray:
    """The 12 triangles (2 per face) of the axis-aligned box [lo, hi], outward wound."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    # Corner i has x from bit 0, y from bit 1, z from bit 2 (0 = lo, 1 = hi).
    corners = np.array([[(hi if i >> k & 1 else lo)[k] for k in range(3)] for i in range(8)])
    quads = [  # each counter-clockwise seen from outside
        (0, 4, 6, 2),  # -x
        (1, 3, 7, 5),  # +x
        (0, 1, 5, 4),  # -y
        (2, 6, 7, 3),  # +y
        (0, 2, 3, 1),  # -z
        (4, 5, 7, 6),  # +z
    ]
    faces = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return indexed_triangles(corners, faces)


def sphere_triangles(center, radius: float, segments: int) -> np.ndarray:
    """A UV sphere: `segments` slices around the y axis and segments // 2 rings from pole
    to pole, so 2 * segments * (rings - 1) triangles (2208 for 48 segments)."""
    return indexed_triangles(*sphere_mesh(center, radius, segments))


def sphere_mesh(center, radius: float, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """(points (V, 3), faces (F, 3)) of `sphere_triangles`."""
    if segments < 4:
        raise ValueError(f"a sphere needs at least 4 segments, got {segments}")
    rings = segments // 2
    theta = np.linspace(0.0, np.pi, rings + 1)[1:-1]  # polar angle of the inner rings
    phi = np.arange(segments) * (2.0 * np.pi / segments)
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring_pts = np.stack([st * np.sin(phi), np.broadcast_to(ct, (len(theta), segments)),
                         st * np.cos(phi)], axis=-1).reshape(-1, 3)  # ring r, slice j -> r*segments+j
    north, south = np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, -1.0, 0.0]])
    pts = np.concatenate([ring_pts, north, south]) * radius + np.asarray(center, dtype=np.float64)
    n_idx, s_idx = len(ring_pts), len(ring_pts) + 1

    # Per slice j, in this order: the north cap's triangle, the south cap's, then two per
    # band between rings r and r + 1 (built as arrays: a 1024-segment sphere has a million).
    j = np.arange(segments, dtype=np.int32)[:, None]  # (int32: a million triangles' faces are 12 MB, not 24)
    j_next = (j + 1) % segments
    r = np.arange(rings - 2, dtype=np.int32)[None, :]
    a, b = r * segments + j, r * segments + j_next
    c, d = (r + 1) * segments + j_next, (r + 1) * segments + j
    bands = np.stack([np.stack([a, d, c], axis=-1), np.stack([a, c, b], axis=-1)], axis=2)
    bands = bands.reshape(segments, 2 * (rings - 2), 3)
    last = (rings - 2) * segments
    north = np.concatenate([np.full_like(j, n_idx), j, j_next], axis=1)[:, None]
    south = np.concatenate([np.full_like(j, s_idx), last + j_next, last + j], axis=1)[:, None]
    faces = np.concatenate([north, south, bands], axis=1).reshape(-1, 3)
    return pts, faces


def sphere_normals(points: np.ndarray, center) -> np.ndarray:
    """The exact normal of a sphere around `center` at each of its points (`sphere_mesh`),
    (V, 3): smooth shading interpolates them across its faces, as it does a mesh's
    vertex normals."""
    return _unit_rows(np.asarray(points, dtype=np.float64) - np.asarray(center, dtype=np.float64))


def plane_basis(normal) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents (u, v) with u x v = normal (normal must be unit). u is built from the
    world axis least aligned with the normal, so the choice is deterministic."""
    n = np.asarray(normal, dtype=np.float64)
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(helper, n)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def plane_triangles(center, normal, size: float, segments: int) -> np.ndarray:
    """A size x size square centred on `center`, perpendicular to the unit `normal`, as a
    segments x segments grid: 2 * segments**2 triangles facing along the normal."""
    u, v = plane_basis(normal)
    s = np.linspace(-size / 2.0, size / 2.0, segments + 1)
    grid = (np.asarray(center, dtype=np.float64)
            + s[:, None, None] * u + s[None, :, None] * v)  # (i along u, j along v, 3)
    p00, p10 = grid[:-1, :-1], grid[1:, :-1]
    p11, p01 = grid[1:, 1:], grid[:-1, 1:]
    tri_a = np.stack([p00, p10, p11], axis=-2).reshape(-1, 3, 3)
    tri_b = np.stack([p00, p11, p01], axis=-2).reshape(-1, 3, 3)
    return np.concatenate([tri_a, tri_b])


#: Multipliers of weld's hash (splitmix64's), mixing each coordinate's bits into the key.
_WELD_MIX = tuple(np.uint64(m) for m in (0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB))


def weld(points: np.ndarray, ordered: bool = False) -> tuple[np.ndarray, int]:
    """(ids, count): an index per row of `points` (N, 3), equal where the coordinates are
    equal (+0 and −0 alike), in 0..count−1; `ordered`: numbered in the rows' lexicographic
    order, as `np.unique(axis=0)` numbers them (a sort of the count distinct rows more).
    The rows' bits are hashed to one 64-bit key
    and the keys sorted, so the cost is one sort of N integers: `np.unique(axis=0)` over
    the rows compared them as records, 11 s of a million-triangle mesh's 3 M corners
    against about 1 s. Rows that share a key but differ (a hash collision) are welded by
    sorting the rows themselves instead."""
    words = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3) + 0.0).view(np.uint64)
    if len(words) == 0:
        return np.zeros(0, np.int64), 0
    key = words[:, 0] * _WELD_MIX[0]
    for axis, mix in ((1, _WELD_MIX[1]), (2, _WELD_MIX[2])):
        key ^= key >> np.uint64(31)
        key += words[:, axis]
        key *= mix
    key ^= key >> np.uint64(32)
    order = np.argsort(key)
    sorted_keys = key[order]
    same = sorted_keys[1:] == sorted_keys[:-1]
    ids = np.empty(len(words), np.int64)
    ids[order] = np.concatenate([[0], np.cumsum(~same)])
    count = int(len(words) - np.count_nonzero(same))
    kept = np.empty((count, 3), np.uint64)
    kept[ids] = words
    if not np.array_equal(kept[ids], words):  # a collision: two rows share a key, so sort the rows
        order = np.lexsort(words.T[::-1])
        same = np.all(words[order[1:]] == words[order[:-1]], axis=1)
        ids[order] = np.concatenate([[0], np.cumsum(~same)])
        count = int(len(words) - np.count_nonzero(same))
    if ordered:
        distinct = np.empty((count, 3))
        distinct[ids] = np.asarray(points, dtype=np.float64).reshape(-1, 3) + 0.0
        rank = np.empty(count, np.int64)
        rank[np.lexsort(distinct.T[::-1])] = np.arange(count)
        ids = rank[ids]
    return ids, count


@timed("solids")
def closed_outward(vertices: np.ndarray, faces: np.ndarray) -> int:
    """+1 where the faces close solids wound counter-clockwise seen from outside, so that
    (b - a) x (c - a) points out of them; -1 where all are wound the other way; 0 for an
    open surface, one wound inconsistently or not a manifold (an edge of more than two
    faces), parts wound opposite ways (an inverted cube inside another), or a part of no
    volume. Vertices are one where their coordinates are equal, so an STL file's repeated
    corners join. Closed means every edge a -> b of a face is b -> a of exactly one other:
    the views that skip such a solid's back faces rely on it (docs/design.md §4.1, "Back
    faces of closed solids"). A surface that turns inside out through itself is not seen."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(f) < 4:
        return 0
    joined, count = weld(v)
    unique = np.empty((count, 3))
    unique[joined] = v
    f = joined[f]
    if np.any((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])):
        return 0  # a face with two corners at one point
    # Each edge a -> b as its undirected key (one integer) and its direction; edge k is face
    # k // 3's. Closed: every key twice, once each way. Sorted by key, the edges then pair
    # off, 2j with 2j + 1 (one sort: a binary search per edge for its reverse cost a
    # million-triangle mesh 1.2 s in cache misses).
    n = np.int64(len(unique))
    start, end = f.reshape(-1), np.roll(f, -1, axis=1).reshape(-1)
    key = np.minimum(start, end) * n + np.maximum(start, end)
    order = np.argsort(key)
    first, second = order[0::2], order[1::2]
    if len(first) != len(second) or np.any(key[first] != key[second]) \
            or np.any(key[second[:-1]] == key[first[1:]]) or np.any((start < end)[first] == (start < end)[second]):
        return 0  # an edge of one face, of three or more, or of two wound the same way
    found = np.empty_like(order)  # each edge's reverse
    found[first], found[second] = second, first
    # the face across each edge (its reverse's), then the connected parts, each named by
    # its least face: every pair of neighbours joins their parts' names (the larger name
    # takes the smaller), and every name then follows its chain to the end, until nothing
    # changes (a few rounds)
    face, across = np.arange(len(key)) // 3, found // 3
    part = np.arange(len(f))
    while True:
        mine, theirs = part[face], part[across]
        joined_parts = part.copy()
        np.minimum.at(joined_parts, np.maximum(mine, theirs), np.minimum(mine, theirs))
        while True:
            root = joined_parts[joined_parts]
            if np.array_equal(root, joined_parts):
                break
            joined_parts = root
        if np.array_equal(joined_parts, part):
            break
        part = joined_parts
    a, b, c = unique[f[:, 0]], unique[f[:, 1]], unique[f[:, 2]]
    centre = unique.mean(axis=0)  # about the solid: the volume's sum cancels less
    volume = np.einsum("ij,ij->i", a - centre, np.cross(b - centre, c - centre)) / 6.0
    volumes = np.bincount(part, weights=volume)[np.unique(part)]
    scale = np.ptp(unique, axis=0).max() ** 3
    if not np.all(np.abs(volumes) > 1e-9 * scale):
        return 0
    if np.all(volumes > 0):
        return 1
    return -1 if np.all(volumes < 0) else 0


def flat_normals(triangles: np.ndarray) -> np.ndarray:
    """Each triangle's unit normal (b - a) x (c - a) on all three of its vertices, (T, 3, 3);
    zero for a triangle without area."""
    triangles = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    normals = _unit_rows(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]))
    return np.repeat(normals[:, None], 3, axis=1)


def _unit_rows(v: np.ndarray) -> np.ndarray:
    """Rows of v normalised; rows of zero length stay zero."""
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, length, out=np.zeros_like(v), where=length > 0)


def smooth_normals(vertices: np.ndarray, faces: np.ndarray, given: np.ndarray | None = None) -> np.ndarray:
    """The normal at each vertex of each face, (F, 3, 3), for smooth shading.

    A vertex's normal is `given[vertex]` (a file's vertex normals) where that is finite and
    non-zero, else the mean of the normals of the faces that share the vertex, weighted
    by their areas. Faces share a vertex by index, as the file wrote them, so a mesh that
    repeats vertices along an edge (every STL file) keeps that edge sharp. A vertex whose
    faces' normals cancel takes each face's own normal.
    """
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # |cross| = twice the face's area
    # Each vertex's faces summed in the order np.add.at took them, corner by corner, so
    # the sums keep their bits; bincount does it in one pass (np.add.at: 2 s a 1 M mesh).
    corner_major = f.T.ravel()
    summed = np.stack([np.bincount(corner_major, weights=np.tile(cross[:, axis], 3), minlength=len(v))
                       for axis in range(3)], axis=1)
    normals = _unit_rows(summed)
    if given is not None:
        given = np.asarray(given, dtype=np.float64).reshape(-1, 3)
        usable = np.isfinite(given).all(axis=1)
        given = _unit_rows(np.where(usable[:, None], given, 0.0))
        normals = np.where(np.any(given != 0.0, axis=1, keepdims=True), given, normals)
    corners = normals[f]
    # the face normal only where a corner has none (a million flat normals cost 0.5 s)
    missing = ~np.any(corners != 0.0, axis=2)
    rows = np.flatnonzero(missing.any(axis=1))
    if len(rows):
        corners[rows] = np.where(missing[rows, :, None], flat_normals(v[f[rows]]), corners[rows])
    return corners


def load_mesh(path: Path, max_triangles: int | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Read an OBJ, PLY or STL file with trimesh (a binary PLY of triangles in numpy,
    clrays.scene.ply): (triangles (T, 3, 3), the smooth normal
    at each of their vertices (T, 3, 3), from `smooth_normals` with the file's vertex
    normals where it has them, and `closed_outward` of its faces), the triangles in
    `spatial_order`.

    Raises ValueError with a one-line reason for an unknown suffix, a missing, unreadable
    or corrupt file, something other than a regular file, a file over `MAX_MESH_BYTES`,
    a file without triangles, or non-finite vertices; and an OBJ whose faces make more
    than `max_triangles` triangles, counted before trimesh builds them.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise ValueError(f"unsupported mesh format {path.suffix or '(no suffix)'!r}")
    if missing(path):
        raise ValueError("no such file")
    try:
        data = read_regular_file(path, MAX_MESH_BYTES)
    except FileRefused as exc:
        raise ValueError(str(exc)) from None
    if suffix == ".obj":
        data = _obj_as_utf8(data)
        if max_triangles is not None and obj_triangle_count(data) > max_triangles:
            raise MeshTooLarge(obj_triangle_count(data))
    elif suffix == ".stl":
        data = _stl_with_true_count(data)
    # A binary PLY of triangles is read in numpy: importing trimesh costs seconds (clrays.scene.ply).
    read = read_binary_triangles(data) if suffix == ".ply" else None
    vertices, faces, given = _read_with_trimesh(data, suffix) if read is None else (*read, None)
    if faces.ndim != 2 or faces.shape[0] == 0 or faces.shape[1] != 3:
        raise ValueError("the file has no triangles")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError("a face refers to a vertex that does not exist")
    tris = indexed_triangles(vertices, faces)
    if not np.isfinite(tris).all():
        raise ValueError("the file has non-finite vertex coordinates")
    order = spatial_order(tris)
    return tris[order], smooth_normals(vertices, faces, given)[order], closed_outward(vertices, faces)


def _read_with_trimesh(data: bytes, suffix: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(vertices, faces, the file's vertex normals or None) of a mesh file's bytes, read by
    trimesh; ValueError with trimesh's reason for a corrupt file."""
    import trimesh  # slow to import; only scenes with meshes pay for it

    try:
        # A file of one mesh loads as that mesh, with the vertex normals it holds; one of
        # several is concatenated (and its normals are recomputed).
        loaded = trimesh.load(io.BytesIO(data), file_type=suffix[1:], process=False)
        if isinstance(loaded, trimesh.Scene):
            loaded = loaded.to_mesh()
    except Exception as exc:  # trimesh raises many types for corrupt files
        detail = " ".join(str(exc).split())
        reason = f"{type(exc).__name__}: {detail}" if detail else type(exc).__name__
        raise ValueError(f"not a valid {suffix[1:].upper()} file ({reason})") from None
    if not isinstance(loaded, trimesh.Trimesh):
        raise ValueError("the file has no triangles")
    # trimesh computes vertex normals on demand; only those read from the file sit in its cache.
    given = np.asarray(loaded.vertex_normals) if "vertex_normals" in loaded._cache else None
    return np.asarray(loaded.vertices, dtype=np.float64), np.asarray(loaded.faces, dtype=np.int64), given


#: Bits per axis of spatial_order's Morton code.
MORTON_BITS = 10


@timed("spatial order")
def spatial_order(triangles: np.ndarray) -> np.ndarray:
    """The triangles' indices along a Morton curve through their centroids (in the box
    around them, MORTON_BITS per axis; ties keep the file's order). The passes with a
    work-item per triangle (raster, the visibility stage's bound maps) then write nearby
    texels from nearby work-items: a scanned mesh in its file's order scatters them over
    the map, and each visit was a cache miss (the bunny at 1280×720, those three passes:
    56.6 → 52.2 ms, bench/RESULTS.md history, "Fewer waits, parallel fills, meshes in spatial
    order")."""
    centroids = triangles.mean(axis=1)
    low, extent = centroids.min(axis=0), np.ptp(centroids, axis=0)
    steps = (1 << MORTON_BITS) - 1
    cells = np.floor((centroids - low) / np.where(extent > 0, extent, 1.0) * steps).astype(np.uint64)
    code = np.zeros(len(triangles), np.uint64)
    for axis in range(3):  # bit `bit` of an axis goes to bit 3·bit + axis
        code |= _every_third_bit(cells[:, axis]) << np.uint64(axis)
    return np.argsort(code, kind="stable")


def _every_third_bit(cells: np.ndarray) -> np.ndarray:
    """The MORTON_BITS (10) low bits of each uint64 moved to every third bit (bit i to bit
    3i), by four shifts and masks where a loop over the bits took thirty (0.9 s a million
    triangles)."""
    spread = cells.copy()
    for shift, mask in ((16, 0x030000FF), (8, 0x0300F00F), (4, 0x030C30C3), (2, 0x09249249)):
        spread |= spread << np.uint64(shift)
        spread &= np.uint64(mask)
    return spread


class MeshTooLarge(ValueError):
    """A mesh file whose faces make more triangles than the scene may hold: `count`."""

    def __init__(self, count: int):
        super().__init__(f"{count} triangles in its faces")
        self.count = count


def _stl_with_true_count(data: bytes) -> bytes:
    """A binary STL's bytes with the triangle count its size gives: 84 bytes of header and
    count, then 50 a triangle. Some writers leave the count 0 (they stream the triangles),
    and a file whose count lies was read by trimesh as ASCII, which failed on a missing
    module; a file of whole triangles is read as those triangles. An ASCII STL (text that
    starts with `solid`) is left as it is."""
    if data[:5].lower() == b"solid":
        try:
            data.decode("utf-8")
            return data
        except UnicodeDecodeError:
            pass  # binary, with a header that starts with "solid" (some exporters write that)
    if len(data) < 84:
        raise ValueError(f"not a valid STL file ({len(data)} bytes: a binary STL has at least 84)")
    count, body = int.from_bytes(data[80:84], "little"), len(data) - 84
    if body % 50:
        raise ValueError(f"not a valid STL file (a binary STL is 84 bytes and 50 a triangle; this one has "
                         f"{len(data)} bytes, and its header says {count} triangles)")
    if count == body // 50:
        return data
    return data[:80] + (body // 50).to_bytes(4, "little") + data[84:]


def obj_triangle_count(data: bytes) -> int:
    """The triangles an OBJ's face lines make, counted on its bytes before any is built: a
    face of n corners is a fan of n - 2. One line of a 22 MB file can name 11 million
    corners, which trimesh expanded (5 GB) before the loader could count them.

    Every token of a face line after the `f` is a corner, so the count is the tokens of
    the face lines less 3 per line; positions only (numpy), no token is copied out."""
    if re.search(rb"(?m)^[ \t]+f[ \t]", data):  # indented faces: counted as the others
        data = re.sub(rb"(?m)^[ \t]+", b"", data)
    buffer = np.frombuffer(data, np.uint8)
    if len(buffer) == 0:
        return 0
    starts = np.concatenate([[0], np.flatnonzero(buffer == ord("\n")) + 1])
    starts = starts[starts < len(buffer) - 1]
    after_f = buffer[starts + 1]
    faces = starts[(buffer[starts] == ord("f")) & ((after_f == ord(" ")) | (after_f == ord("\t")))]
    if len(faces) == 0:
        return 0
    ends = np.searchsorted(starts, faces, side="right")
    ends = np.where(ends < len(starts), starts[np.minimum(ends, len(starts) - 1)], len(buffer))
    space = buffer <= ord(" ")  # spaces, tabs, line ends: what separates tokens
    token_starts = np.flatnonzero(~space[1:] & space[:-1]) + 1  # (the first byte of the file is no face's)
    tokens = np.searchsorted(token_starts, ends) - np.searchsorted(token_starts, faces + 1)
    return int(np.maximum(tokens - 2, 0).sum())  # tokens after the "f" - 2


def _obj_as_utf8(data: bytes) -> bytes:
    """An OBJ's bytes as UTF-8. Its numbers and keywords are ASCII; a comment or a name in
    another encoding (Latin-1, from older exporters) is read as Latin-1, which decodes any
    byte, rather than left to trimesh's guess, which needs a package we do not depend on."""
    try:
        data.decode("utf-8")
        return data
    except UnicodeDecodeError:
        return data.decode("latin-1").encode("utf-8")


def load_mesh_triangles(path: Path) -> np.ndarray:
    """The triangles of `load_mesh`, (T, 3, 3)."""
    return load_mesh(path)[0]
