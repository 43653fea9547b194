"""Relief objects: a base rectangle with a depth per texel (docs/design.md, "Relief objects").

A relief is the base rectangle `center`, `normal`, `up`, `size: [w, h]` and a depth
image; texel (row r, column c) of an H × W image sits at the texel's centre,

    P(r, c) = corner + (c + ½)·a + (r + ½)·b + height·depth(r, c)·f

with a = right·w/W, b = -up·h/H (row 0 is the top of the image, as it is drawn),
f = the unit normal, and corner the base rectangle's top-left corner. Its triangles
(`relief_triangles`) are the height field through those points: two per cell of four
neighbouring texels, so (H - 1)·(W - 1)·2 of them; a cell with a corner of alpha 0 is a
hole and has none. Those triangles are the relief's definition: `exact`, the surface
shadows and the mesh that `clrays relief-to-mesh` writes all use them.

Images are read as arrays in [0, 1]: PNG (8- or 16-bit, grey, grey + alpha, RGB or
RGBA), OpenEXR, or `.npy` (H × W, H × W × 2 for depth and alpha, H × W × 3 or × 4 for a
colour with or without alpha). A depth image with colour channels uses their mean.
"""
from __future__ import annotations

import io
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Callable

import numpy as np

from .files import FileRefused, missing, read_regular_file
from .image_files import image_shape, load_npy, npy_header
from .limits import MAX_MESH_BYTES

IMAGE_SUFFIXES = (".png", ".exr", ".npy")
#: An image file's size: the mesh limit, as a relief replaces a mesh of the same detail.
MAX_RELIEF_IMAGE_BYTES = MAX_MESH_BYTES


@dataclass(frozen=True)
class ReliefFrame:
    """Where the texels sit, in the object's own frame (before its transform)."""

    corner: np.ndarray  # (3,) the base rectangle's corner above texel (0, 0): top-left
    a: np.ndarray  # (3,) one texel along a row (column + 1)
    b: np.ndarray  # (3,) one texel down a column (row + 1)
    f: np.ndarray  # (3,) unit displacement direction, the base plane's normal

    def points(self, displacement: np.ndarray) -> np.ndarray:
        """(H, W, 3) texel-centre points displaced by `displacement` (H, W), scene units."""
        rows, cols = displacement.shape
        c = np.arange(cols) + 0.5
        r = np.arange(rows) + 0.5
        return (self.corner + c[None, :, None] * self.a + r[:, None, None] * self.b
                + displacement[:, :, None] * self.f)


def relief_frame(center, normal, up, size, shape) -> ReliefFrame:
    """The texel frame of a base rectangle `size` = (w, h) around `center`, facing the unit
    `normal`, its `up` projected into the plane (the loader checks it is not parallel)."""
    normal = np.asarray(normal, float)
    up = np.asarray(up, float) - np.dot(up, normal) * normal
    up /= np.linalg.norm(up)
    right = np.cross(up, normal)  # right × up = normal: the image is seen unmirrored from the front
    rows, cols = shape
    width, height = size
    corner = np.asarray(center, float) - right * width / 2 + up * height / 2
    return ReliefFrame(corner, right * width / cols, -up * height / rows, normal)


def read_image(path: Path, check_shape: Callable[[int, int], None] | None = None) -> np.ndarray:
    """An image file as float64 (H, W, C) in [0, 1], C in 1..4 (grey, grey + alpha, RGB,
    RGBA). Raises ValueError with a one-line reason (no file, unreadable, another format
    than its extension says, not 2D, non-finite values, …). Its size is read from its
    header and checked, by `check_shape(height, width)` too when given (which raises
    ValueError), before anything is decoded."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in IMAGE_SUFFIXES:
        raise ValueError(f"unsupported image format {path.suffix or '(no suffix)'!r}; expected .png, .exr or .npy")
    if missing(path):
        raise ValueError("no such file")
    try:
        data = read_regular_file(path, MAX_RELIEF_IMAGE_BYTES)
    except FileRefused as exc:
        raise ValueError(str(exc)) from None
    if suffix == ".npy":
        shape = npy_header(data)[0]
        if len(shape) not in (2, 3):
            raise ValueError(f"not a 2D image (an array of shape {shape}; expected H × W with 1 to 4 channels)")
    height, width = image_shape(data, suffix, path)
    if min(height, width) < 2:
        raise ValueError(f"an image of {width} × {height} texels has no cell (at least 2 × 2)")
    if check_shape is not None:
        check_shape(height, width)
    if suffix == ".npy":
        image = _read_npy(data)
    elif suffix == ".png":
        image = _read_png(data)
    else:
        image = _read_exr(path)
    if image.ndim == 2:
        image = image[:, :, None]
    if image.ndim != 3 or image.shape[2] not in (1, 2, 3, 4):
        raise ValueError(f"not a 2D image (an array of shape {tuple(image.shape)}; expected H × W with 1 to 4 "
                         f"channels)")
    if min(image.shape[:2]) < 2:
        raise ValueError(f"an image of {image.shape[1]} × {image.shape[0]} texels has no cell (at least 2 × 2)")
    bad = ~np.isfinite(image)
    if bad.any():
        y, x, c = np.argwhere(bad)[0]
        raise ValueError(f"the image has non-finite values ({image[y, x, c]} at texel (x={x}, y={y}), "
                         f"{int(bad.any(axis=2).sum())} in all)")
    return image


def _read_npy(data: bytes) -> np.ndarray:
    array = load_npy(data)  # numbers only: its header is checked (image_files.npy_header)
    return array.astype(np.float64)


def _read_png(data: bytes) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as image:
            if image.format != "PNG":
                raise ValueError(f"a {image.format} image named .png")
            image.load()
            mode = image.mode
            if mode in ("I;16", "I;16B", "I;16L", "I"):  # 16-bit grey
                return np.asarray(image, dtype=np.float64) / 65535.0
            if mode not in ("L", "LA", "RGB", "RGBA"):
                image = image.convert("RGBA" if "A" in image.getbands() or "transparency" in image.info else "RGB")
            return np.asarray(image, dtype=np.float64) / 255.0
    except (UnidentifiedImageError, OSError, SyntaxError) as exc:
        raise ValueError(f"not a readable PNG image ({type(exc).__name__})") from None


def _read_exr(path: Path) -> np.ndarray:
    import OpenEXR

    try:
        with OpenEXR.File(str(path)) as exr:
            channels = exr.channels()
            names = list(channels)
            for wanted in (("RGBA",), ("RGB",), ("R", "G", "B", "A"), ("R", "G", "B"), ("Y", "A"), ("Y",)):
                if all(name in channels for name in wanted):
                    parts = [np.asarray(channels[name].pixels, dtype=np.float64) for name in wanted]
                    break
            else:
                parts = [np.asarray(channels[names[0]].pixels, dtype=np.float64)]
    except Exception as exc:  # OpenEXR raises several types for a corrupt file
        raise ValueError(f"not a valid EXR file ({type(exc).__name__})") from None
    parts = [p if p.ndim == 3 else p[:, :, None] for p in parts]
    return np.concatenate(parts, axis=2)


def depth_and_alpha(image: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(depth (H, W), alpha (H, W) or None) of a depth image: grey, or the mean of its
    colour channels; alpha from its last channel when it has one (2 or 4 channels)."""
    channels = image.shape[2]
    colour = image[:, :, :1] if channels <= 2 else image[:, :, :3]
    alpha = image[:, :, -1] if channels in (2, 4) else None
    return colour.mean(axis=2), alpha


def colour_and_alpha(image: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(RGB (H, W, 3), alpha or None) of a colour image (grey is broadcast to RGB)."""
    channels = image.shape[2]
    colour = image[:, :, :1] if channels <= 2 else image[:, :, :3]
    alpha = image[:, :, -1] if channels in (2, 4) else None
    return np.broadcast_to(colour, image.shape[:2] + (3,)).copy(), alpha


def cell_count(shape) -> int:
    """Triangles of a relief of `shape` (H, W) without holes: two per cell."""
    rows, cols = shape
    return 2 * (rows - 1) * (cols - 1)


def relief_triangles(frame: ReliefFrame, displacement: np.ndarray, solid: np.ndarray | None = None,
                     albedo: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """The height field through the displaced texel centres: (triangles (T, 3, 3), the
    albedo of each (T, 3) or None without `albedo`).

    displacement: (H, W) scene units along `frame.f`. solid: (H, W) bool, False where
    alpha is 0; a cell with a corner that is not solid is a hole. albedo: (H, W, 3), each
    triangle taking the mean of its cell's four texels. The cell of texels (r, c) to
    (r + 1, c + 1) is split along its p00–p11 diagonal, both triangles wound so that
    (b − a) × (c − a) points along +f on a flat relief. Cells come row by row, the two
    triangles of a cell one after the other (`cell_of_triangle` inverts the order).
    """
    points = frame.points(displacement)
    p00, p01 = points[:-1, :-1], points[:-1, 1:]  # p_rc: row offset r, column offset c
    p10, p11 = points[1:, :-1], points[1:, 1:]
    # a × b = right × (-up) = -normal: wind (p00, p11, p01) so that the face normal is +f.
    first = np.stack([p00, p11, p01], axis=-2)
    second = np.stack([p00, p10, p11], axis=-2)
    triangles = np.stack([first, second], axis=2)  # (H-1, W-1, 2, 3, 3)
    keep = np.ones(displacement.shape, bool) if solid is None else np.asarray(solid, bool)
    cells = keep[:-1, :-1] & keep[:-1, 1:] & keep[1:, :-1] & keep[1:, 1:]
    out = triangles[cells].reshape(-1, 3, 3)
    if albedo is None:
        return out, None
    cell_albedo = (albedo[:-1, :-1] + albedo[:-1, 1:] + albedo[1:, :-1] + albedo[1:, 1:]) / 4
    return out, np.repeat(cell_albedo[cells], 2, axis=0)


@dataclass(frozen=True)
class Relief:
    """A relief as the loader reads it (local frame, before the object's transform)."""

    frame: ReliefFrame
    displacement: np.ndarray  # (H, W) scene units along frame.f: height · depth
    solid: np.ndarray  # (H, W) bool: alpha ≠ 0
    albedo: np.ndarray | None  # (H, W, 3) from albedo_map, or None (the object's albedo)

    def triangles(self) -> tuple[np.ndarray, np.ndarray | None]:
        return relief_triangles(self.frame, self.displacement, self.solid, self.albedo)


@dataclass(frozen=True)
class ReliefRecord:
    """A relief as the renderer's pre-warp needs it (`Geometry.reliefs`): where its
    triangles are, its texels, and four of its vertices that pin its frame, so that the
    frame in world space follows the triangles wherever a transform or an animation put
    them (`world_frame`)."""

    rows: slice  # its triangles in Geometry.triangles
    relief: Relief  # texels and frame in the object's own coordinates
    handles: np.ndarray  # (4,) int: indices into its vertices (rows, flattened to (3T, 3))
    handle_points: np.ndarray  # (4, 3) those vertices in the object's own coordinates
    cell_triangle: np.ndarray  # (H - 1, W - 1) int32: the cell's first triangle within rows, −1 for a hole

    @property
    def shape(self) -> tuple[int, int]:
        return self.relief.displacement.shape

    @cached_property
    def memo(self) -> dict:
        """What a frame derives from the relief's texels, kept with it (clrays.scene.relief_frame)."""
        return {}

    def __getstate__(self):
        """Pickled without the memo (a scene sent to a worker process): it is rebuilt there."""
        state = dict(self.__dict__)
        state.pop("memo", None)
        return state


def relief_record(relief: Relief, rows: slice, local_triangles: np.ndarray) -> ReliefRecord:
    """The record of a relief whose triangles (`relief.triangles()`, in its own frame) sit at
    `rows` of the scene's geometry."""
    vertices = local_triangles.reshape(-1, 3)
    first = 0
    second = int(np.argmax(np.linalg.norm(vertices - vertices[first], axis=1)))
    line = vertices[second] - vertices[first]
    off_line = np.linalg.norm(np.cross(vertices - vertices[first], line), axis=1)
    third = int(np.argmax(off_line))
    normal = np.cross(line, vertices[third] - vertices[first])
    fourth = int(np.argmax(np.abs((vertices - vertices[first]) @ normal)))
    handles = np.array([first, second, third, fourth])
    kept = np.ones(relief.displacement.shape, bool) if relief.solid is None else relief.solid
    cells = kept[:-1, :-1] & kept[:-1, 1:] & kept[1:, :-1] & kept[1:, 1:]
    cell_triangle = np.full(cells.shape, -1, np.int32)
    cell_triangle[cells] = 2 * np.arange(int(cells.sum()), dtype=np.int32)
    return ReliefRecord(rows, relief, handles, vertices[handles].copy(), cell_triangle)


def world_frame(record: ReliefRecord, triangles: np.ndarray) -> tuple[ReliefFrame, np.ndarray]:
    """(frame, displacement) of a relief where `triangles` (the scene's, world space) put it.

    The object's transform is affine, and an affine map keeps P = C_s + u·a + v·b + d·f in
    that form with the mapped C_s, a, b, f: the four handle vertices give the map. A flat
    relief (its vertices in one plane, constant d) pins only the plane: it becomes a relief
    of displacement 0 in that plane."""
    local = record.handle_points
    world = triangles[record.rows].reshape(-1, 3)[record.handles]
    frame = record.relief.frame
    homogeneous = np.concatenate([local, np.ones((4, 1))], axis=1)
    scale = max(float(np.abs(local - local[0]).max()), 1e-300)
    if abs(np.linalg.det(local[1:] - local[0])) > 1e-9 * scale ** 3:
        affine = np.linalg.solve(homogeneous, world)  # rows: x, y, z weights, then the translation
        linear, shift = affine[:3].T, affine[3]
        mapped = ReliefFrame(linear @ frame.corner + shift, linear @ frame.a, linear @ frame.b, linear @ frame.f)
        return mapped, record.relief.displacement
    # Flat: solve W_k = X + u_k·a' + v_k·b' on three handles (u, v: their texel coordinates).
    basis = np.stack([frame.a, frame.b, frame.f], axis=1)
    uvd = np.linalg.solve(basis, (local[:3] - frame.corner).T).T
    system = np.concatenate([np.ones((3, 1)), uvd[:, :2]], axis=1)
    origin, a, b = np.linalg.solve(system, world[:3])
    normal = np.cross(a, b)
    return ReliefFrame(origin, a, b, normal / np.linalg.norm(normal)), np.zeros_like(record.relief.displacement)
