"""Stage relief (part of raster): relief objects drawn into a view by their pre-warp.

Host side of `cl/relief.cl` (docs/design.md, "Relief objects"). For each relief and each
viewer (the camera, or a light: a cube map's six faces share one warp), the host works
out the k coefficients, the epipole and the target grid in float64; the device warps the
depth image in two 1D passes and maps the result onto the base rectangle in each view,
writing the depth and triangle of the height field's hit, as raster.cl would have.
The raster stage leaves the reliefs' triangles out (`FrameInputs.raster_triangles`) and
calls `draw_reliefs` after its own triangles.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import structs
from ..device import Device, StageTimer
from ..physics.prewarp import Viewer, epipole, prewarp_coefficients, segment_order
from ..scene.relief import ReliefFrame
from ..scene.relief_placement import PlacedRelief

#: How far outside its base rectangle a warped texel is still drawn, in rectangle sizes:
#: a grazing view stretches the warp towards the horizon, and the target grid (and its
#: memory) with it; what lands farther out is left out.
MAX_TARGET_SPREAD = 4.0


@dataclass
class Warp:
    """One relief warped for one viewer: the target grid on the device and where it sits."""

    warped: object  # float4[target_rows][target_cols]
    u0: float
    v0: float
    target_rows: int
    target_cols: int


def _viewer(view: np.ndarray) -> Viewer:
    if int(view["projection"]) == structs.PROJECTION_ORTHOGRAPHIC:
        return Viewer(direction=np.asarray(view["forward"][:3], np.float64))
    return Viewer(position=np.asarray(view["origin"][:3], np.float64))


def _target_grid(displacement, solid, k, rows, cols) -> tuple[float, float, int, int] | None:
    """(u0, v0, target rows, target columns) covering where the solid texels land, clipped
    to MAX_TARGET_SPREAD around the rectangle; None when none lands ahead of the viewer."""
    k1, k2, k3 = k
    scale = 1.0 + k3 * displacement
    ahead = solid & (scale > 0)
    if not ahead.any():
        return None
    u_i = ((np.arange(cols)[None, :] + 0.5 + k1 * displacement) / np.where(ahead, scale, 1.0))[ahead]
    v_i = ((np.arange(rows)[:, None] + 0.5 + k2 * displacement) / np.where(ahead, scale, 1.0))[ahead]
    u_lo = max(np.floor(u_i.min()), -MAX_TARGET_SPREAD * cols)
    u_hi = min(np.ceil(u_i.max()), (1 + MAX_TARGET_SPREAD) * cols)
    v_lo = max(np.floor(v_i.min()), -MAX_TARGET_SPREAD * rows)
    v_hi = min(np.ceil(v_i.max()), (1 + MAX_TARGET_SPREAD) * rows)
    if u_hi <= u_lo or v_hi <= v_lo:
        return None
    return float(u_lo), float(v_lo), int(v_hi - v_lo), int(u_hi - u_lo)


def _vector(v) -> np.ndarray:
    """A 3-vector as an OpenCL float4 kernel argument (w = 0)."""
    from pyopencl import cltypes

    return cltypes.make_float4(float(v[0]), float(v[1]), float(v[2]), 0.0)


def _frame_in(placed: PlacedRelief, space_origin_ws: np.ndarray) -> ReliefFrame:
    frame = placed.frame
    return ReliefFrame(frame.corner - space_origin_ws, frame.a, frame.b, frame.f)


class ReliefDrawer:
    """The reliefs of one pass (the camera's, or one light's map) on the device, in the
    pass's space (eye space, or anchored at the light: `space_origin_ws`)."""

    def __init__(self, device: Device, reliefs, space_origin_ws: np.ndarray, timer: StageTimer):
        self.device, self.timer = device, timer
        self.reliefs = [(placed, _frame_in(placed, space_origin_ws)) for placed in reliefs]
        self._texels = {}
        self._warps = {}
        self._slabs = {}

    def _texel_buffers(self, index: int):
        if index not in self._texels:
            placed = self.reliefs[index][0]
            self._texels[index] = (
                self.device.buffer(placed.displacement.astype(np.float32), writable=False),
                self.device.buffer(placed.solid.astype(np.uint8), writable=False),
                self.device.buffer(placed.cell_triangle.astype(np.int32), writable=False))
        return self._texels[index]

    def warp(self, index: int, view: np.ndarray) -> Warp | None:
        """Relief `index` pre-warped for `view`'s viewer (kept for the other views of the same
        viewer: a cube map's faces)."""
        viewer = _viewer(view)
        key = (index, viewer.position.tobytes() if viewer.position is not None else viewer.direction.tobytes())
        if key in self._warps:
            return self._warps[key]
        placed, frame = self.reliefs[index]
        rows, cols = placed.displacement.shape
        k = prewarp_coefficients(frame, viewer)
        grid = _target_grid(placed.displacement, placed.solid, k, rows, cols)
        if grid is None:
            self._warps[key] = None
            return None
        u0, v0, target_rows, target_cols = grid
        u_e, v_e, _ = epipole(frame, viewer)
        displacement, solid, cell_triangle = self._texel_buffers(index)
        device = self.device
        middle = device.buffer(nbytes=16 * rows * target_cols)
        warped = device.buffer(nbytes=16 * target_rows * target_cols)
        row_segments = device.buffer(segment_order(cols, u_e).astype(np.int32), writable=False)
        column_segments = device.buffer(segment_order(rows, v_e).astype(np.int32), writable=False)
        k1, k2, k3 = (np.float32(value) for value in k)
        self.timer.add("relief", device.kernel("relief", "relief_warp_rows")(
            device.queue, (rows,), None, displacement, solid, np.int32(rows), np.int32(cols), row_segments,
            k1, k3, np.float32(u0), np.int32(target_cols), middle))
        self.timer.add("relief", device.kernel("relief", "relief_warp_columns")(
            device.queue, (target_cols,), None, middle, np.int32(rows), np.int32(cols), np.int32(target_cols),
            column_segments, k2, k3, np.float32(v0), np.int32(target_rows), cell_triangle, warped))
        self._warps[key] = Warp(warped, u0, v0, target_rows, target_cols)
        return self._warps[key]

    def map(self, kernel: str, defines, views_buffer, views: np.ndarray, view_index: int, offsets,
            sample_count: int, targets: tuple) -> None:
        """Every relief mapped onto view `view_index` by `kernel` (relief_map_depth,
        relief_map_resolve or relief_map_nearest) into `targets`: the cells it tests are
        built from the texels, so the relief's triangles need not be on the device."""
        view = views[view_index]
        for index, (placed, frame) in enumerate(self.reliefs):
            warp = self.warp(index, view)
            if warp is None:
                continue
            rows, cols = placed.displacement.shape
            low, high = self._height_range(index)
            x0, y0, columns, lines = footprint(view, frame, low, high, rows, cols)
            if not columns or not lines:
                continue
            dual = np.linalg.inv(np.stack([frame.a, frame.b, frame.f], axis=1))  # rows: dual_a, dual_b, dual_f
            samples = columns * lines * sample_count
            self.timer.add("relief", self.device.kernel("relief", kernel, defines)(
                self.device.queue, (samples,), None, views_buffer, np.int32(view_index), np.int32(x0), np.int32(y0),
                np.int32(columns), offsets,
                np.int32(sample_count), _vector(frame.corner), _vector(dual[0]), _vector(dual[1]),
                _vector(dual[2]), np.float32(warp.u0), np.float32(warp.v0),
                np.int32(warp.target_rows), np.int32(warp.target_cols), warp.warped, np.int32(rows),
                np.int32(cols), self._texel_buffers(index)[2], self._texel_buffers(index)[0], _vector(frame.a),
                _vector(frame.b), _vector(frame.f), np.int32(placed.first_triangle), self._heights(index), *targets))

    def _height_range(self, index: int) -> tuple[float, float]:
        """(lowest, highest) displacement of relief `index`'s solid texels: the slab its
        surface lies in, beyond which a ray's walk along its trace stops."""
        if index not in self._slabs:
            placed = self.reliefs[index][0]
            solid = placed.displacement[placed.solid]
            self._slabs[index] = (float(solid.min()), float(solid.max())) if solid.size else (0.0, 0.0)
        return self._slabs[index]

    def _heights(self, index: int):
        """`_height_range` as a float2."""
        from pyopencl import cltypes

        return cltypes.make_float2(*self._height_range(index))


#: Pixels a relief's footprint (`footprint`) is widened by on each side: its corners are
#: projected in float64, the device's rays cast in float32.
FOOTPRINT_MARGIN = 2


def footprint(view: np.ndarray, frame: ReliefFrame, low: float, high: float, rows: int,
              cols: int) -> tuple[int, int, int, int]:
    """(x0, y0, columns, rows) of the view's pixels whose rays may meet a relief: the box of
    its cells (texel centres from ½ to cols − ½ along a, rows − ½ along b, heights [low,
    high] along f, as relief_span bounds the walk), projected, widened by FOOTPRINT_MARGIN and
    clipped to the view; every pixel where a perspective view has the box reaching behind
    its eye. No ray outside it meets a cell, so relief_map leaves those pixels as they are:
    a relief seen small in a large view (a window's lattice in a sun's map that spans the
    scene) costs its own pixels, not the view's."""
    width, height = int(view["width"]), int(view["height"])
    pick = np.array([[(k >> axis) & 1 for axis in range(3)] for k in range(8)], dtype=np.float64)
    lo, hi = np.array([0.5, 0.5, low]), np.array([cols - 0.5, rows - 0.5, high])
    local = lo + pick * (hi - lo)  # (8, 3): along a, b, f
    corners = frame.corner + local @ np.stack([frame.a, frame.b, frame.f])
    q = corners - np.asarray(view["origin"][:3], np.float64)
    x, y = q @ np.asarray(view["right"][:3], np.float64), q @ np.asarray(view["up"][:3], np.float64)
    if int(view["projection"]) == structs.PROJECTION_PERSPECTIVE:
        z = q @ np.asarray(view["forward"][:3], np.float64)
        if not np.all(z > 1e-6 * np.linalg.norm(q, axis=1)):
            return 0, 0, width, height
        x, y = x / z, y / z
    screen_x = (x / float(view["scale_x"]) + 1.0) * 0.5 * width  # a sample's x + its offset in [0, 1)
    screen_y = (1.0 - y / float(view["scale_y"])) * 0.5 * height
    if not (np.isfinite(screen_x).all() and np.isfinite(screen_y).all()):
        return 0, 0, width, height
    x0 = int(np.clip(np.floor(screen_x.min()) - FOOTPRINT_MARGIN, 0, width))
    x1 = int(np.clip(np.ceil(screen_x.max()) + FOOTPRINT_MARGIN, 0, width))
    y0 = int(np.clip(np.floor(screen_y.min()) - FOOTPRINT_MARGIN, 0, height))
    y1 = int(np.clip(np.ceil(screen_y.max()) + FOOTPRINT_MARGIN, 0, height))
    return x0, y0, x1 - x0, y1 - y0

