"""Pinhole camera: the one definition of which ray a pixel sample is.

Pixel (x, y) has y = 0 at the top. A sample at offset (ox, oy) in [0, 1)^2 inside the
pixel looks along

    forward + ((2(x + ox)/W - 1) · tan(fov/2) · W/H) · right + ((1 - 2(y + oy)/H) · tan(fov/2)) · up

normalised; fov is vertical. The device kernels build the same ray from the same
basis and offsets (see `cl/common.h`, `camera_ray`).
"""
from __future__ import annotations

import math

import numpy as np

from .model import Camera, Image


def camera_basis(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthonormal (right, up, forward) of the camera, float64."""
    forward = camera.look_at - camera.position
    forward = forward / np.linalg.norm(forward)
    right = np.cross(forward, camera.up)
    right = right / np.linalg.norm(right)
    up = np.cross(right, forward)
    return right, up, forward


def half_extents(camera: Camera, image: Image) -> tuple[float, float]:
    """(tan_x, tan_y): the screen's half width and half height at unit distance along
    forward, tan(fov/2) scaled by the aspect ratio horizontally."""
    tan_y = math.tan(math.radians(camera.fov_deg) / 2)
    return tan_y * image.width / image.height, tan_y


def sample_offsets(spp: int) -> np.ndarray:
    """Sub-pixel offsets (spp, 2) in [0, 1): the centre for spp = 1, a stratified grid
    when spp is a square, otherwise the R2 low-discrepancy sequence. Deterministic."""
    if spp == 1:
        return np.array([[0.5, 0.5]])
    n = math.isqrt(spp)
    if n * n == spp:
        i = (np.arange(spp) % n + 0.5) / n
        j = (np.arange(spp) // n + 0.5) / n
        return np.stack([i, j], axis=1)
    # R2 sequence (Roberts 2018): generalised golden ratio in 2D.
    phi = 1.32471795724474602596
    k = np.arange(spp)[:, None] + 1
    return np.mod(0.5 + k * np.array([1 / phi, 1 / phi**2]), 1.0)


def primary_rays(camera: Camera, image: Image, offsets: np.ndarray | None = None) -> np.ndarray:
    """Unit ray directions, shape (H, W, S, 3) float64, S = len(offsets) (default: image.spp)."""
    if offsets is None:
        offsets = sample_offsets(image.spp)
    right, up, forward = camera_basis(camera)
    tan_half = math.tan(math.radians(camera.fov_deg) / 2)
    aspect = image.width / image.height
    xs = np.arange(image.width)[None, :, None] + offsets[None, None, :, 0]
    ys = np.arange(image.height)[:, None, None] + offsets[None, None, :, 1]
    sx = (2 * xs / image.width - 1) * tan_half * aspect  # (1, W, S)
    sy = (1 - 2 * ys / image.height) * tan_half  # (H, 1, S)
    d = (forward[None, None, None, :] + sx[..., None] * right + sy[..., None] * up)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)
