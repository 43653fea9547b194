"""Stage light_texture: a textured light's texture rectified beside its shadow map, folded
into per-row prefix sums through a low-rank integrand (docs/light-textures.md, minmax).
Host side of `cl/light_texture.cl`.

    texture_tables = light_texture(device, buffers, light, epipolar, integrand, timer)

Per frame and textured light:
1. On the host (float64), the integrand sinβ·I(β, γ) of docs/integrand.md in the tree's own
   γ, sampled on 64 × 64 (β, γ) nodes and factorised, K ≈ Σ_i B_i(β)·Γ_i(γ) (the paper's
   SVD; Nyström-extended to the integrand table's β rows and the tree's γ cells), with the
   prefix sums P_i of Γ_i over the cells.
2. On the device, `light_texture_prefix` takes each (slice, γ cell)'s texture T[α, γ] as
   its mean over `cell_samples` points of the cell's light rays, and sums T and T·Γ_i
   along each row (one pass: the rectified texture is never stored).
3. traverse turns a lit run into radiance with `textured_run_radiance` (cl/light_texture.h):
   N lookups per run, whatever the texture holds.

The kernels that look a texture up per point (raymarch, shade) read every light's texture
as the frame's inputs pack it (clrays.physics.light_texture.pack_light_textures).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .. import structs
from ..buffers import BufferDecl
from ..inputs import FrameBuffers, frame_sizes
from ..scene.costs import texture_texel_angle, texture_texel_length
from ..scene.model import DirectionalLight
from .integrand import SVD_RELATIVE_CUTOFF, SVD_SAMPLES, _beta_nodes, integrand_exact

#: Points per texel of a γ cell's length whose mean is the cell's texture
#: (cl/light_texture.cl), at least 1 and at most MAX_CELL_SAMPLES: the cell's centre alone
#: aliases a texture finer than the cell. scenes/stained_glass.yaml's cells are 1.9 of its
#: texels long (γ_max ≈ 19 through the window, 1024 cells) and take 2 points; against
#: `exact` at 160×90, 2048 slices, 1 point gives 0.65 %, 2 0.58 %, 3 0.56 %, 4 0.56 %,
#: 8 0.56 %, and at its 4096 slices 2 points 0.495 %, 3 0.489 % for about 1.15× the frame
#: more at 640×360 (bench/RESULTS.md history, "The stained glass within reach of 0.5 %").
CELL_SAMPLES_PER_TEXEL = 1.0
MAX_CELL_SAMPLES = 4
#: A textured light's prefix sums: per slice and γ cell boundary, 3 channels of T and T·Γ_i.
TEXTURE_PREFIX = BufferDecl("texture prefix sums", 4,
                            lambda sizes: sizes.slices * 3 * (sizes.svd_rank + 1) * (sizes.tree_gamma + 1))


def cell_samples(light, gamma_step: float, gamma_warp: float) -> int:
    """Points per γ cell for `light`'s texture: CELL_SAMPLES_PER_TEXEL per texel along the
    longest cell (1 + warp of the even step: docs/design.md §4.2), γ and texel both lengths
    (a directional light) or both angles at the light; 1 for a smooth texture."""
    texel = texture_texel_length(light) if isinstance(light, DirectionalLight) else texture_texel_angle(light)
    if not texel:
        return 1
    longest = gamma_step * (1.0 + gamma_warp)
    return min(max(math.ceil(min(CELL_SAMPLES_PER_TEXEL * longest / texel, MAX_CELL_SAMPLES)), 1), MAX_CELL_SAMPLES)


if TYPE_CHECKING:
    from ..device import Device, StageTimer
    from .integrand import DeviceIntegrand
    from .rectify import Epipolar


# --------------------------------------------------------------------------- the low-rank integrand in γ


@dataclass(frozen=True)
class GammaBasis:
    """sinβ·I(β, γ) ≈ Σ_i B_i(β)·Γ_i(γ) per channel (float64): B (3, rank, n_beta) on the sin²
    β nodes over [beta_min, beta_max], Γ (3, rank, n) at the centres of the n γ cells of a
    row (structs.texel_gamma), P (3, rank, n + 1) = cumsum(cell width·Γ), 0 first."""

    basis_beta: np.ndarray
    gamma: np.ndarray
    prefix: np.ndarray
    beta_min: float
    beta_max: float
    rank: int


def gamma_basis(light_kind, medium, power, d_el, beta_min, beta_max, gamma_step, n, n_beta, rank,
                gamma_warp=0.0) -> GammaBasis:
    """The truncated SVD of K = sinβ·I(β, γ) (docs/integrand.md's I, in the tree's γ: the
    light angle, or s·sinβ for a directional light) sampled on SVD_SAMPLES² nodes (β on
    sin²-spaced nodes, γ at cell centres over [0, n·gamma_step]), extended to the n_beta
    β nodes and the n γ cells by Nyström: B_i(β) = Σ_k K(β, γ_k)·v_ik and
    Γ_i(γ) = Σ_j u_ji·K(β_j, γ)/σ_i, which on the sample grid is exactly the truncated SVD.

    Beyond a point light's ray end (γ ≥ π - β) no run is ever integrated; K there is K at
    the end (0 when σt > 0), which keeps it continuous for the fit."""
    kind = "directional" if light_kind == "directional" else "point"
    gamma_max = n * gamma_step

    def k(beta, gamma):
        beta, gamma = np.meshgrid(beta, gamma, indexing="ij")
        if kind == "point":
            gamma = np.minimum(gamma, (math.pi - beta) * (1.0 - 1e-9))
        sin_beta = np.maximum(np.sin(beta), structs.SIN_BETA_MIN)
        value = integrand_exact(kind, medium.sigma_s, medium.sigma_t, medium.phase, power, d_el, beta, gamma)
        return np.moveaxis(value * sin_beta[..., None], -1, 0)  # (3, len(beta), len(gamma))

    beta_samples = _beta_nodes(beta_min, beta_max, SVD_SAMPLES)
    gamma_samples = (np.arange(SVD_SAMPLES) + 0.5) * (gamma_max / SVD_SAMPLES)
    samples = k(beta_samples, gamma_samples)
    beta_rows = _beta_nodes(beta_min, beta_max, n_beta)
    cells = structs.texel_gamma(gamma_step, n, np.arange(n) + 0.5, gamma_warp)
    at_rows, at_cells = k(beta_rows, gamma_samples), k(beta_samples, cells)
    basis_beta = np.zeros((3, rank, n_beta))
    gamma = np.zeros((3, rank, n))
    # A grey medium (one σt) makes the channels proportional: K_c = a_c·K with a_c = σs_c·power_c.
    # One factorisation then serves all three, its B scaled by a_c / a_0 (one SVD, not three).
    amplitude = np.asarray(medium.sigma_s, dtype=np.float64) * np.broadcast_to(np.asarray(power, float), (3,))
    grey = np.all(medium.sigma_t == medium.sigma_t[0]) and amplitude[0] > 0
    for c in range(1 if grey else 3):
        u, sigma, vt = np.linalg.svd(samples[c], full_matrices=False)
        keep = min(rank, int(np.sum(sigma > SVD_RELATIVE_CUTOFF * max(sigma[0], 1e-300))))
        for i in range(keep):
            basis_beta[c, i] = at_rows[c] @ vt[i]
            gamma[c, i] = u[:, i] @ at_cells[c] / sigma[i]
    if grey:
        basis_beta[1:] = basis_beta[0] * (amplitude[1:] / amplitude[0])[:, None, None]
        gamma[1:] = gamma[0]
    prefix = np.zeros((3, rank, n + 1))
    widths = np.diff(structs.texel_gamma(gamma_step, n, np.arange(n + 1), gamma_warp))
    prefix[..., 1:] = np.cumsum(widths * gamma, axis=-1)
    return GammaBasis(basis_beta, gamma, prefix, float(beta_min), float(beta_max), rank)


# --------------------------------------------------------------------------- the stage


@dataclass
class TextureTables:
    """One textured light's tables on the device, as the row walks read them: a feature of
    the walk (clrays/stages/features.py, cl/walk_features.h's LIGHT_TEXTURE)."""

    params: object  # textured_integrand_t
    basis: object  # float[]: B, then P (cl/light_texture.h)
    prefix: object  # float[slices][n + 1][3][rank + 1]: a record per cell boundary
    rank: int

    def defines(self) -> dict:
        return {"LIGHT_TEXTURE": 1}

    def args(self) -> tuple:
        """The kernel arguments of LIGHT_TEXTURE_ARGS."""
        return self.params, self.basis, self.prefix


def light_texture(device: Device, buffers: FrameBuffers, light_index: int, epipolar: Epipolar,
                  integrand: DeviceIntegrand, timer: StageTimer) -> TextureTables:
    """Stage light_texture for one textured light: the low-rank integrand in γ (host), the
    rectified texture's per-row prefix sums (device)."""
    start = time.perf_counter()
    scene = buffers.inputs.scene
    light = scene.lights[light_index]
    directional = isinstance(light, DirectionalLight)
    n, slices = int(epipolar.params["gamma_samples"]), int(epipolar.params["slices"])
    gamma_step = epipolar.gamma_step  # (the host's SVD needs the ranges: read back from the device)
    n_beta = max(integrand.n_beta, 16)  # (not `tables`, which reads the table back)
    rank = scene.render.svd_rank
    basis = gamma_basis("directional" if directional else "point", scene.medium,
                        light.irradiance if directional else light.intensity, epipolar.d_el,
                        epipolar.beta_min, epipolar.beta_max, gamma_step, n, n_beta, rank,
                        epipolar.gamma_warp)
    params = np.zeros(1, dtype=structs.textured_integrand_dtype)
    params["beta_min"], params["beta_max"] = basis.beta_min, basis.beta_max
    params["n_beta"], params["rank"], params["gamma_samples"], params["slices"] = n_beta, rank, n, slices
    params["textured"] = 1
    params_buffer = device.buffer(params, writable=False)
    packed = np.concatenate([basis.basis_beta.ravel(), basis.prefix.ravel()]).astype(np.float32)
    basis_buffer = device.buffer(packed, writable=False)
    # Γ[cell][channel][rank]: the prefix kernel reads a cell's at once.
    gamma_buffer = device.buffer(np.ascontiguousarray(basis.gamma.transpose(2, 0, 1), dtype=np.float32),
                                 writable=False)
    timer.add_host("light_texture", (time.perf_counter() - start) * 1e3)
    prefix = TEXTURE_PREFIX.allocate(device, frame_sizes(buffers.inputs))  # (rank, n and slices: the scene's)
    event = device.kernel("light_texture", "light_texture_prefix", {"TEXTURE_RANK": rank})(
        device.queue, (slices,), None, buffers.lights, epipolar.buffer, buffers.light_textures, buffers.texels,
        params_buffer, gamma_buffer, np.int32(cell_samples(light, gamma_step, epipolar.gamma_warp)), prefix)
    timer.add("light_texture", event)
    return TextureTables(params_buffer, basis_buffer, prefix, rank)
