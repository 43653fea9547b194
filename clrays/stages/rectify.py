"""Stage rectify: the shadow map resampled into the epipolar texture S[α, γ].

Host side of `cl/rectify.cl`: the light's epipolar frame (axis, slice basis), the
fan of slices that crosses the screen, the β and γ ranges of the visible rays
(reduced on the device from the camera depth, and kept there: VisibleRanges), and the
rectify launch that writes level 0 of the min-max tree.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import structs
from ..scene.camera import slice_basis, slice_fan
from ..device import Device, StageTimer
from ..buffers import BufferDecl
from ..inputs import FrameBuffers, frame_sizes
from .raster import RasterResult
from ..scene.costs import tree_gamma_samples
from ..scene.model import DirectionalLight

# Camera samples (rectify_bounds) and texels (rectify) one work-item computes at a time, as
# float8 lanes (cl/lanes.h).
LANES = 8
# Batches of LANES texels one rectify work-item computes on a CPU device, every batch's
# shadow-map reads issued before any is used: the reads miss the cache, and a core waits
# on 64 of them at once about as long as on 8 (bench/RESULTS.md history, "Column blocks on a GPU,
# fewer and earlier loads on a CPU"). A GPU hides the wait with other work-items, and keeps
# one batch each.
RECTIFY_BATCHES_CPU = 8
# Camera samples one rectify_bounds work-item reduces, LANES at a time (cl/rectify.cl); a
# multiple of LANES.
BOUNDS_CHUNK = 64
# Slices one rectify work-group covers at the same texels: neighbouring slices read
# neighbouring shadow-map texels, so a group that sweeps across slices, rather than along
# one slice's row, finds them in cache (PoCL runs a group's work-items in turn).
SLICES_PER_GROUP = 64

#: Per slice, the (min, max) of its row's γ texels and of the levels above them (float2).
TREE = BufferDecl("min-max tree", 8, lambda sizes: sizes.slices * 2 * sizes.tree_gamma)
#: Each texel's blocking triangle, where the maps keep them (cl/shaft_edges.h).
ROW_BLOCKERS = BufferDecl("rows' blockers", 4, lambda sizes: sizes.slices * sizes.tree_gamma)


def rectify_batches(device: Device) -> int:
    """Batches of LANES texels per rectify work-item."""
    return RECTIFY_BATCHES_CPU if device.is_cpu else 1


def _defines(device: Device) -> dict:
    """The rectify program's build constants, one build for both its kernels."""
    return {"BOUNDS_CHUNK": BOUNDS_CHUNK, "LANES": LANES, "RECTIFY_BATCHES": rectify_batches(device)}


@dataclass
class VisibleRanges:
    """The β and γ ranges of one light's visible rays, on the device: `bounds`, the
    pseudo-angles rectify_bounds reduces, and `ranges`, the float4 (β_min, β_max, γ_max,
    1/max(β_max - β_min, 1e-6)) rectify_ranges makes of them. The kernels that need the
    ranges read them there, so a frame never waits for them; `host` reads them back, once,
    for the host-side paths that need the values (the `svd` integrand, a light's texture)
    and for tests, each such read a host wait (Device.host_waits)."""

    device: Device
    bounds: object  # uint[4]: pseudo-angles of β_min, β_max, γ_max (cl/visible_ranges.h)
    ranges: object  # float4
    directional: bool
    gamma_samples: int  # texels of the texture's rows, which divide γ_max into its step
    _host: tuple | None = None

    def host(self) -> tuple[float, float, float, float]:
        """(β_min, β_max, γ_max, γ step): β in radians, γ in radians (point, spot) or length
        (directional); γ_max ≤ 0 where no visible ray has extent in γ. β and γ_max in
        float64 from the bounds, as cl/visible_ranges.h; the step in float32, as the
        texture's (rectify_ranges)."""
        if self._host is None:
            bounds = self.device.read(self.bounds, 4, np.uint32)
            q_beta_min, q_beta_max, gamma = bounds[:3].view(np.float32).astype(float)
            gamma_max = gamma if self.directional else angle_of_pseudo(gamma)
            n = self.gamma_samples
            gamma_step = float(np.float32(gamma_max / n) if gamma_max > 0 else np.float32(1.0) / np.float32(n))
            self._host = (min(angle_of_pseudo(q_beta_min), math.pi), min(angle_of_pseudo(q_beta_max), math.pi),
                          float(gamma_max), gamma_step)
        return self._host


@dataclass
class Epipolar:
    """The epipolar texture of one light and what it was built from."""

    params: np.ndarray  # epipolar_t, gamma_step 0: rectify_ranges writes it into `buffer` (host: gamma_step)
    buffer: object  # the epipolar_t on the device
    tree: object  # float2[slices][2·gamma_samples]: the min-max tree rows
    visible: VisibleRanges  # the β and γ ranges of the visible rays, on the device
    triangles: object = None  # int[slices][gamma_samples]: each texel's blocker, -1 for none
    levels_built: bool = False  # the minmax stage has filled levels 1..log2(N) of `tree`
    unshadowed: bool = False  # the minimal texture of a light that casts no shadow (clrays.session)

    @property
    def d_el(self) -> float:
        """Eye–light distance (0 for a directional light)."""
        return float(self.params["d_el"])

    # The ranges on the host: each reads them back once (VisibleRanges.host), a host wait.
    @property
    def beta_min(self) -> float:
        return self.visible.host()[0]

    @property
    def beta_max(self) -> float:
        return self.visible.host()[1]

    @property
    def gamma_max(self) -> float:
        return self.visible.host()[2]

    @property
    def gamma_step(self) -> float:
        return self.visible.host()[3]

    @property
    def gamma_warp(self) -> float:
        """W of the γ texels' spacing (structs.GAMMA_TEXEL_WARP; 0, even, for a directional light)."""
        return float(self.params["gamma_warp"])


def epipolar_frame(scene, buffers: FrameBuffers, light_index: int) -> np.ndarray:
    """epipolar_t for one light, without the ranges that need the depth map."""
    light = scene.lights[light_index]
    params = np.zeros((), dtype=structs.epipolar_dtype)
    if isinstance(light, DirectionalLight):
        axis, d_el = -light.direction, 0.0
    else:
        to_light = light.position - buffers.inputs.eye_ws
        d_el = float(np.linalg.norm(to_light))
        axis = to_light / d_el
    u, w = slice_basis(axis)
    alpha_min, span, full = slice_fan(scene, axis, u, w)
    slices = scene.render.slices
    gamma_samples = tree_gamma_samples(scene.render.gamma_samples)
    params["axis"], params["u"], params["w"] = structs.float4(axis), structs.float4(u), structs.float4(w)
    params["d_el"] = d_el
    params["alpha_min"], params["alpha_step"], params["slices"] = alpha_min, span / slices, slices
    params["gamma_samples"], params["levels"] = gamma_samples, int(math.log2(gamma_samples))
    params["light_index"], params["full_circle"] = light_index, int(full)
    # γ texels finer near the eye's light ray for a point or spot light (gamma_texels.h)
    params["gamma_warp"] = 0.0 if isinstance(light, DirectionalLight) else structs.GAMMA_TEXEL_WARP
    return params


def slice_sides(params: np.ndarray) -> np.ndarray:
    """(slices, 4) float32: u·cos α + w·sin α at each slice's centre, the direction its
    half-plane opens towards."""
    u, w = params["u"][:3].astype(float), params["w"][:3].astype(float)
    alpha = float(params["alpha_min"]) + (np.arange(int(params["slices"])) + 0.5) * float(params["alpha_step"])
    sides = np.zeros((len(alpha), 4), dtype=np.float32)
    sides[:, :3] = np.outer(np.cos(alpha), u) + np.outer(np.sin(alpha), w)
    return sides


def texel_angles(params: np.ndarray, gamma_step: float) -> np.ndarray:
    """(gamma_samples, 4) float32: (γ, cos γ, sin γ, 0) of each texel of a row: its centre
    (structs.texel_gamma), texel 0 at γ = 0 (cl/rectify.cl rectify); what rectify_ranges
    writes on the device."""
    n = int(params["gamma_samples"])
    warp = float(params["gamma_warp"])
    if warp > 0:  # float64, as rectify_ranges in double
        gamma = structs.texel_gamma(gamma_step, n, np.arange(n) + 0.5, warp).astype(np.float32)
    else:
        gamma = (np.arange(n, dtype=np.float32) + np.float32(0.5)) * np.float32(gamma_step)
    gamma[0] = 0.0
    angles = np.zeros((n, 4), dtype=np.float32)
    angles[:, 0], angles[:, 1], angles[:, 2] = gamma, np.cos(gamma.astype(float)), np.sin(gamma.astype(float))
    return angles


def angle_of_pseudo(q: float) -> float:
    """The angle θ ∈ [0, π] of cl/rectify.cl pseudo_angle_lanes q: 2·atan(q) up to q = 1, π - 2·atan(2 - q)
    above (q = 2 - cot(θ/2)); +inf (no camera sample) stays +inf. cl/visible_ranges.h is the
    device's copy."""
    if not math.isfinite(q):
        return q
    return 2.0 * math.atan(q) if q <= 1.0 else math.pi - 2.0 * math.atan(2.0 - q)


def rectify(device: Device, buffers: FrameBuffers, rastered: RasterResult, light_index: int,
            timer: StageTimer) -> Epipolar:
    """Build S[α, γ] for one light. The β and γ ranges of the visible rays are reduced,
    and turned into the texture's γ step, on the device (`Epipolar.visible`): nothing here
    waits for them. Where no visible ray has any extent in γ the texture spans γ ∈ [0, 1]
    and the walks find every ray's span empty (the integrand's `no_extent`, set on the
    device), so the light adds nothing."""
    scene = buffers.inputs.scene
    params = epipolar_frame(scene, buffers, light_index)
    frame_buffer = device.buffer(params.reshape(1))  # rectify_ranges writes its gamma_step
    bounds_buffer = device.buffer(np.array([structs.DEPTH_EMPTY, 0, 0, 0], dtype=np.uint32))
    samples = buffers.inputs.samples
    defines = _defines(device)
    event = device.kernel("rectify", "rectify_bounds", defines)(
        device.queue, (-(-samples // BOUNDS_CHUNK),), None, buffers.params, buffers.views, buffers.lights,
        frame_buffer, rastered.camera_depth, buffers.offsets, bounds_buffer)
    timer.add("rectify", event)
    n, slices = int(params["gamma_samples"]), int(params["slices"])
    angles, ranges = device.buffer(nbytes=16 * n), device.buffer(nbytes=16)
    timer.add("rectify", device.kernel("rectify", "rectify_ranges", defines)(
        device.queue, (n,), None, bounds_buffer, buffers.lights, frame_buffer, angles, ranges))
    sizes = frame_sizes(buffers.inputs)  # (slices and n are the scene's: epipolar_frame)
    tree = TREE.allocate(device, sizes)
    triangles = None if rastered.shadow_blockers is None else ROW_BLOCKERS.allocate(device, sizes)
    # (the keys without the reliefs where the walks cut those themselves: stages/relief_cuts.py)
    volume = rastered.shadow_blockers if rastered.volume_blockers is None else rastered.volume_blockers
    blockers = () if triangles is None else (volume, triangles)
    if triangles is not None:  # the maps' triangles, or their keys, which hold depth and triangle in one load
        defines = {**defines, "RECTIFY_BLOCKERS": 1, "RECTIFY_BLOCKER_KEYS": int(rastered.blocker_keys)}
    sides = device.buffer(slice_sides(params), writable=False)
    group = min(SLICES_PER_GROUP, slices)
    event = device.kernel("rectify", "rectify", defines)(
        device.queue, (-(-n // (defines["RECTIFY_BATCHES"] * LANES)), -(-slices // group) * group), (1, group),
        buffers.views, buffers.lights, rastered.shadow_depth, frame_buffer, sides, angles, tree, *blockers)
    timer.add("rectify", event)
    visible = VisibleRanges(device, bounds_buffer, ranges, isinstance(scene.lights[light_index], DirectionalLight), n)
    return Epipolar(params, frame_buffer, tree, visible, triangles)
