"""Error of an image against a reference, as the tests and benchmarks report it.

Pixels compared: those whose reference luminance is at least `floor` (default 1%)
of the reference image's mean, minus pixels at depth discontinuities (where a
pixel's surface, or lack of one, differs from a neighbour's: the methods sample
the same pixel differently there, so its error says nothing about the method).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..scene.camera import primary_rays
from ..physics.radiometry import effective_far
from ..scene.model import Scene

_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def luminance(image: np.ndarray) -> np.ndarray:
    return np.asarray(image, dtype=np.float64) @ _LUMINANCE


def depth_map(scene: Scene) -> np.ndarray:
    """Distance to the first surface through each pixel centre (inf: none), float64; ray
    casts on a BVH (`bvh_queries.SceneBvh`, the same hits as against every triangle)."""
    from .bvh_queries import SceneBvh

    dirs = primary_rays(scene.camera, scene.image, np.array([[0.5, 0.5]])).reshape(-1, 3)
    t, _ = SceneBvh.build(scene.geometry.triangles).raycast(scene.camera.position, dirs, t_max=effective_far(scene))
    return t.reshape(scene.image.height, scene.image.width)


def depth_edges(depth: np.ndarray, relative: float = 0.05) -> np.ndarray:
    """Boolean mask of pixels whose depth differs from a 4-neighbour's by more than
    `relative` (or where one of them hits nothing and the other does)."""
    edges = np.zeros(depth.shape, dtype=bool)
    finite = np.where(np.isfinite(depth), depth, -1.0)
    for axis in (0, 1):
        a = np.take(finite, range(0, depth.shape[axis] - 1), axis=axis)
        b = np.take(finite, range(1, depth.shape[axis]), axis=axis)
        jump = ((a < 0) != (b < 0)) | (np.abs(a - b) > relative * np.maximum(np.abs(a), np.abs(b)))
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        edges[tuple(lo)] |= jump
        edges[tuple(hi)] |= jump
    return edges


def depth_edges_at(scene: Scene, ys, xs, relative: float = 0.05) -> np.ndarray:
    """`depth_edges` for the pixels (ys[i], xs[i]) only, from float64 ray casts of each
    pixel and its 4 neighbours (on a BVH): for error on a pixel subset of a large image."""
    from .bvh_queries import SceneBvh

    ys, xs = np.asarray(ys), np.asarray(xs)
    h, w = scene.image.height, scene.image.width
    dirs = primary_rays(scene.camera, scene.image, np.array([[0.5, 0.5]]))[..., 0, :]
    neighbours = [(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)]
    cy = np.stack([np.clip(ys + dy, 0, h - 1) for dy, _ in neighbours])
    cx = np.stack([np.clip(xs + dx, 0, w - 1) for _, dx in neighbours])
    t, _ = SceneBvh.build(scene.geometry.triangles).raycast(scene.camera.position, dirs[cy.ravel(), cx.ravel()],
                                                            t_max=effective_far(scene))
    depth = np.where(np.isfinite(t), t, -1.0).reshape(len(neighbours), -1)
    centre, around = depth[0], depth[1:]
    jump = ((centre < 0) != (around < 0)) | (np.abs(around - centre) > relative * np.maximum(np.abs(around),
                                                                                              np.abs(centre)))
    return jump.any(axis=0)


@dataclass(frozen=True)
class ImageError:
    mean: float  # mean relative luminance error over the compared pixels
    p99: float  # 99th percentile of the relative luminance error
    rmse: float  # relative RMSE: sqrt(mean((L - Lref)^2)) / mean(Lref), compared pixels
    pixels: int  # how many pixels were compared

    def __str__(self) -> str:
        return f"mean {self.mean:.3%}, p99 {self.p99:.3%}, rel. RMSE {self.rmse:.3%} over {self.pixels} px"


def image_error(image: np.ndarray, reference: np.ndarray, exclude: np.ndarray | None = None,
                floor: float = 0.01) -> ImageError:
    """Relative luminance error of `image` against `reference` (module docstring); NaN, over
    0 pixels, where no pixel is left to compare (a thumbnail whose few pixels all lie on
    depth edges)."""
    lum, ref = luminance(image), luminance(reference)
    mask = ref >= floor * ref.mean()
    if exclude is not None:
        mask &= ~exclude
    if not mask.any():
        return ImageError(math.nan, math.nan, math.nan, 0)
    relative = np.abs(lum[mask] - ref[mask]) / ref[mask]
    rmse = float(np.sqrt(np.mean((lum[mask] - ref[mask]) ** 2)) / ref[mask].mean())
    return ImageError(float(relative.mean()), float(np.percentile(relative, 99)), rmse, int(mask.sum()))
