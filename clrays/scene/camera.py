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


def ray_starts(camera: Camera, dirs: np.ndarray) -> np.ndarray:
    """Where camera rays along unit `dirs` (..., 3) start (`camera.near`, as Cycles' Clip
    Start): at the plane `near` in front of the eye along the view axis, t0 = near / cos θ
    (θ the ray's angle to the axis). Zeros for near = 0. The device's twin is
    `camera_ray_start` (cl/lighting.h)."""
    if camera.near == 0.0:
        return np.zeros(dirs.shape[:-1])
    return camera.near / (dirs @ camera_basis(camera)[2])


def from_ray_starts(ray: np.ndarray, a: np.ndarray, b: np.ndarray, starts: np.ndarray, *more: np.ndarray):
    """Intervals [a, b] of rays `ray` (indices into `starts`, `ray_starts`) cut to begin no
    earlier than their ray's start, the empty ones dropped: (ray, a, b, *more), each of
    `more` an array per interval kept alongside."""
    a = np.maximum(a, starts[ray])
    keep = b > a
    return (ray[keep], a[keep], b[keep], *(values[keep] for values in more))


def slice_basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit u, w with (u, w, axis) orthonormal: α = atan2(v·w, v·u)."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def poles_on_screen(scene, axis: np.ndarray) -> tuple[bool, bool]:
    """Whether the epipole (the direction `axis`) and the anti-epipole (`-axis`) are on screen."""
    camera, image = scene.camera, scene.image
    right, up, forward = camera_basis(camera)
    tan_x, tan_y = half_extents(camera, image)
    on_screen = []
    for pole in (axis, -axis):
        depth = pole @ forward
        on_screen.append(bool(depth > 0 and abs(pole @ right / depth) <= tan_x and abs(pole @ up / depth) <= tan_y))
    return on_screen[0], on_screen[1]


def slice_fan(scene, axis: np.ndarray, u: np.ndarray, w: np.ndarray) -> tuple[float, float, bool]:
    """(alpha_min, alpha_span, full_circle): the slice angles that rays through the
    screen take. When the epipole (axis) or anti-epipole (-axis) is on screen the slices
    close the circle; otherwise α is continuous over the screen and its range is the
    circle minus the largest gap between the angles of rays along the screen border."""
    camera, image = scene.camera, scene.image
    right, up, forward = camera_basis(camera)
    tan_x, tan_y = half_extents(camera, image)
    if any(poles_on_screen(scene, axis)):
        return -math.pi, 2 * math.pi, True
    edge = np.linspace(-1.0, 1.0, 4 * max(image.width, image.height) + 1)
    ones = np.ones_like(edge)
    border = np.concatenate([np.stack([edge, ones]), np.stack([edge, -ones]),
                             np.stack([ones, edge]), np.stack([-ones, edge])], axis=1)
    dirs = forward[:, None] + right[:, None] * (border[0] * tan_x) + up[:, None] * (border[1] * tan_y)
    alpha = np.sort(np.arctan2(w @ dirs, u @ dirs))
    gaps = np.diff(np.concatenate([alpha, alpha[:1] + 2 * math.pi]))
    largest = int(np.argmax(gaps))
    start = alpha[(largest + 1) % len(alpha)]
    span = 2 * math.pi - gaps[largest]
    # A margin of 1% keeps border pixels between two slices rather than past the last one.
    margin = 0.01 * span + 1e-6
    return float(start - margin), float(min(span + 2 * margin, 2 * math.pi)), False
