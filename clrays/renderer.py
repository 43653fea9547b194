"""One frame, stage by stage: raster → (raymarch | rectify → minmax → integrand →
traverse) → shade. The `exact` reference runs on the host in float64 instead."""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from .device import Device, StageTimer
from .frame import frame_inputs, upload
from .raster import raster
from .raymarch import raymarch
from .scene import Scene
from .shade import shade

METHODS = ("raymarch", "exact", "minmax")


@dataclass
class RenderResult:
    image: np.ndarray  # (H, W, 3) float32 linear radiance
    method: str
    stage_ms: dict[str, float] = field(default_factory=dict)  # device time per stage
    wall_ms: float = 0.0
    device_bytes: int = 0  # device memory allocated for the frame


class Renderer:
    """Renders scenes on one OpenCL device; built kernels are kept between frames."""

    def __init__(self, device: Device | str | None = None):
        self._device = device if isinstance(device, Device) else None
        self._device_spec = device if isinstance(device, str) else None

    @property
    def device(self) -> Device:
        if self._device is None:  # created lazily: `exact` needs no device
            self._device = Device(self._device_spec)
        return self._device

    def render(self, scene: Scene, method: str | None = None, progress: bool = False) -> RenderResult:
        method = method or scene.render.method
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
        scene = replace(scene, render=replace(scene.render, method=method))
        start = time.perf_counter()
        if method == "exact":
            from .exact import render_exact

            image = render_exact(scene, progress=progress).astype(np.float32)
            return RenderResult(image, method, wall_ms=(time.perf_counter() - start) * 1e3)

        device, timer = self.device, StageTimer()
        device.allocated_bytes = 0
        buffers = upload(device, frame_inputs(scene))  # the scene in eye space, packed into device structs
        rastered = raster(device, buffers, timer)  # raster: camera depth + triangle ids, shadow maps
        scatter = self._in_scatter(method, buffers, rastered, timer)  # in-scattered radiance per sample
        image = shade(device, buffers, rastered, scatter, timer)  # shade: surfaces, attenuation, + scatter
        wall_ms = (time.perf_counter() - start) * 1e3
        return RenderResult(image, method, timer.milliseconds(), wall_ms, device.allocated_bytes)

    def _in_scatter(self, method, buffers, rastered, timer):
        device, inputs = self.device, buffers.inputs
        if not np.any(inputs.scene.medium.sigma_s > 0):
            # No medium: no volume stages at all, just a zero scatter buffer.
            scatter = device.buffer(nbytes=16 * inputs.samples)
            device.fill(scatter, np.float32(0), 16 * inputs.samples)
            return scatter
        if method == "raymarch":
            return raymarch(device, buffers, rastered, timer)  # raymarch: the brute-force reference
        from .minmax_path import minmax_in_scatter

        return minmax_in_scatter(device, buffers, rastered, timer)


_renderers: dict[str | None, Renderer] = {}


def render(scene: Scene, method: str | None = None, device: str | None = None, stats: bool = False,
           progress: bool = False):
    """Render a scene; returns (H, W, 3) float32 linear radiance, or a RenderResult with
    per-stage device times when `stats=True`. `method` overrides `scene.render.method`;
    `device` is a device spec as for `--device`."""
    renderer = _renderers.setdefault(device, Renderer(device))
    result = renderer.render(scene, method, progress=progress)
    return result if stats else result.image
