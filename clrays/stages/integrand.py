"""The integrand stage, host side: per-frame tables that turn a lit interval of a camera
ray into in-scattered radiance (docs/design.md §2–§4, stage 4 `integrand`).

A camera ray has view angle β; a lit interval of it is [γ0, γ1) in light angle γ (point
and spot lights, docs/design.md §2) or in perpendicular distance γ = s·sinβ (directional light,
docs/design.md §3). Its in-scattered radiance is ∫ I(β, γ) dγ with

    point/spot:   I(β, γ) = σs·I·ρ(cos(β+γ))·exp(-σt·d_el·(sinβ + sinγ)/sin(β+γ)) / (d_el·sinβ)
                  γ ∈ [0, π-β)   (γ → π-β is the ray's point at infinity)
    directional:  I(β, γ) = σs·E·ρ(cosβ)·exp(-σt·γ/sinβ) / sinβ,   γ ∈ [0, ∞)

per RGB channel. Every mode writes a segment as

    L(β, γ0, γ1) = row_scale(β) · [F(β, x(β, γ1)) - F(β, x(β, γ0))]

where x ∈ [0, 1] is a per-row coordinate and F(β, x) = ∫_0^x K(β, x') dx' is a prefix
integral of a bounded, smooth integrand K; the 1/sinβ singularity sits in row_scale, in
closed form:

    point/spot:   x = clamp(γ/(π-β), 0, 1)    K = sinβ·I(β, x·(π-β))     row_scale = (π-β)/sinβ
    directional:  x = clamp(s/s_end, 0, 1)    K = σs·E·ρ(cosβ)·e^{-σt·x·s_end}   row_scale = s_end
                  (s = γ/sinβ, the distance along the ray)

The point-light rows run to the ray's point at infinity, so β → π (whole ray in a sliver
of γ) keeps full resolution and nothing lies "beyond infinity"; the directional rows run
in distance, where the integrand is separable. The β nodes are uniform in t with
β = beta_min + (beta_max - beta_min)·sin²(πt/2): dense at both ends, because F has a
β·log β term at β → 0 (the ray beyond 2·d_el is squeezed into γ ∈ (π-2β, π-β)) and a
backward-peaked phase curves fast at β → π. docs/integrand.md gives the reasons and the
measured errors.

Modes (`mode`):
    table     F sampled on n_beta × n_gamma nodes, per-cell Gauss–Legendre in float64;
              bilinear lookup.
    svd       the paper's method: K sampled on 64 × 64 (t, x) nodes, truncated SVD
              K ≈ Σ_i B_i(β)·Γ_i(x), B_i on the n_beta β nodes and P_i(x) = ∫_0^x Γ_i on
              the n_gamma x nodes (Nyström extension of the singular vectors, prefix
              integrals by the same quadrature as `table`); linear lookups.
    analytic  closed forms: directional light (any phase), and point/spot light with
              σt = 0 and an isotropic phase. Everything else raises ValueError.

`segment_radiance` evaluates a segment exactly as the OpenCL kernel will (same clamps,
same interpolation), in float64. `tools/integrand_report.py` prints the error table of
docs/integrand.md.
"""
from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from .. import structs
from ..device import Device, StageTimer
from ..errors import ClraysError
from ..physics.radiometry import effective_far
from ..scene.model import INTEGRAND_MODES, DirectionalLight, Phase
from ..structs import SIN_BETA_MIN

MODES = INTEGRAND_MODES
LIGHT_KINDS = ("point", "directional")  # "spot" is accepted and treated as "point"

# The paper's SVD sampling grid, and so the largest rank it can keep.
SVD_SAMPLES = 64
# Singular values below this fraction of the largest are dropped (their Nyström
# extension divides by σ_i).
SVD_RELATIVE_CUTOFF = 1e-13
# Gauss–Legendre nodes per table cell. Cells are ~1e-3 wide in x and K is smooth on that
# scale (the one exception, the last cell of a point row, gets halving panels): 3 nodes
# agree with 8 to 6e-9 of the table's largest value, and the bench scenes' float32 tables with
# 8 nodes' but for 1 ulp in at most 3 of 65 536 entries (4 nodes: none), for 0.75× the
# build time (bench/RESULTS.md history, "Integrand build").
QUAD_NODES = 3
# Integrand values per chunk of rows: chunks that stay in the CPU's L2 cache build a 128 × 512
# table in 0.6× the time of one 400 000-value chunk in a plain Python process (in the
# renderer's, where PoCL is loaded, about the same time; bench/RESULTS.md history, host stages).
ROW_CHUNK_VALUES = 32768
# Directional rows end at this optical depth (of the least attenuating channel) when
# no s_max is given: the light beyond carries e^{-20} ≈ 2e-9 of the ray's radiance.
DIRECTIONAL_OPTICAL_DEPTH = 20.0

# Columns of IntegrandTables.constants, one row per RGB channel.
C_AMPLITUDE = 0  # σs·I (point/spot, W/sr/m) or σs·E (directional, W/m²/m)
C_SIGMA_T = 1  # σt, 1/m
C_D_EL = 2  # eye–light distance d_el (point/spot; 0 for directional)
C_G = 3  # Henyey–Greenstein g (0 for isotropic)
C_S_END = 4  # directional rows: end of the row in distance s (0 otherwise)
N_CONSTANTS = 5


@dataclass(frozen=True)
class IntegrandTables:
    """What the integrand kernel needs for one frame (float64, C-contiguous; the device
    copy is `astype(np.float32)` of each array).

    mode: "table" | "svd" | "analytic"; light_kind: "point" (also spot) | "directional".
    beta_min, beta_max: β range of the rows (radians); gamma_max: the γ range the caller
    asked for (recorded; point rows always cover the whole ray, directional rows run to
    constants[:, C_S_END] in distance).
    n_beta, n_gamma: table nodes (0 for analytic); rank: SVD terms kept (0 unless svd).
    prefix: table only, (3, n_beta, n_gamma) F(β_j, x_k).
    basis_beta: svd only, (3, rank, n_beta) B_i(β_j).
    prefix_gamma: svd only, (3, rank, n_gamma) P_i(x_k).
    constants: (3, N_CONSTANTS) per-channel constants, columns C_*.

    Nodes: β_j = beta_min + (beta_max - beta_min)·sin²(π/2·j/(n_beta-1)), x_k = k/(n_gamma-1).
    """

    mode: str
    light_kind: str
    beta_min: float
    beta_max: float
    gamma_max: float
    n_beta: int
    n_gamma: int
    rank: int
    prefix: np.ndarray | None
    basis_beta: np.ndarray | None
    prefix_gamma: np.ndarray | None
    constants: np.ndarray

    def float32(self) -> IntegrandTables:
        """The same tables rounded to float32, as the device stores them."""

        def f32(a):
            return None if a is None else np.ascontiguousarray(a, dtype=np.float32)

        return replace(self, prefix=f32(self.prefix), basis_beta=f32(self.basis_beta),
                       prefix_gamma=f32(self.prefix_gamma), constants=f32(self.constants))


# --------------------------------------------------------------------------- inputs


def _rgb(name: str, value) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    try:
        a = np.broadcast_to(a, (3,)).copy()
    except ValueError:
        raise ValueError(f"integrand: {name}: expected a scalar or 3 values (RGB), got shape {a.shape}") from None
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise ValueError(f"integrand: {name}: expected finite values >= 0, got {a.tolist()}")
    return a


def _light_kind(light_kind: str) -> str:
    if light_kind == "spot":
        return "point"
    if light_kind not in LIGHT_KINDS:
        raise ValueError(f"integrand: light kind: expected one of point, spot, directional, got {light_kind!r}")
    return light_kind


def _phase_g(phase: Phase) -> float:
    if phase.type == "isotropic":
        return 0.0
    if phase.type == "hg":
        g = float(phase.g)
        if not -1.0 < g < 1.0:
            raise ValueError(f"integrand: phase.g: expected (-1, 1), got {g}")
        return g
    raise ValueError(f"integrand: phase: expected isotropic or hg, got {phase.type!r}")


def hg_phase(cos_theta, g: float) -> np.ndarray:
    """Henyey–Greenstein ρ(cosθ) = (1-g²)/(4π(1+g²-2g·cosθ)^{3/2}); g = 0 is isotropic 1/(4π)."""
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), -1.0, 1.0)
    d = 1.0 + g * g - 2.0 * g * c
    return (1.0 - g * g) / (4.0 * math.pi * (d * np.sqrt(d)))  # d·√d: no pow()


# --------------------------------------------------------------------------- the integrand


def integrand_exact(light_kind, sigma_s, sigma_t, phase, power, d_el, beta, gamma) -> np.ndarray:
    """I(β, γ) pointwise in float64, shape broadcast(beta, gamma).shape + (3,).

    light_kind: "point", "spot" or "directional"; sigma_s, sigma_t: 1/m (scalar or RGB);
    phase: clrays.scene.model.Phase; power: radiant intensity I (W/sr, point/spot) or irradiance
    E (W/m², directional), scalar or RGB; d_el: eye–light distance (m, point/spot only);
    beta in (0, π) radians; gamma: light angle (point/spot, radians) or perpendicular
    distance s·sinβ (directional, m). Zero outside the ray (γ < 0, and γ ≥ π-β for a
    point light: those γ are behind the eye).
    """
    kind = _light_kind(light_kind)
    amplitude = _rgb("sigma_s", sigma_s) * _rgb("power", power)
    sigma_t = _rgb("sigma_t", sigma_t)
    g = _phase_g(phase)
    beta, gamma = np.broadcast_arrays(np.asarray(beta, dtype=np.float64), np.asarray(gamma, dtype=np.float64))
    beta, gamma = beta[..., None], gamma[..., None]
    sin_beta = np.sin(beta)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if kind == "point":
            d_el = float(d_el)
            delta = math.pi - beta
            on_ray = (gamma >= 0) & (gamma < delta)
            # sin(β+γ) = sin(π-β-γ): the second form keeps its relative precision as γ → π-β.
            sin_bg = np.sin(delta - gamma)
            ratio = np.where(on_ray, (sin_beta + np.sin(gamma)) / sin_bg, 0.0)
            attenuation = np.exp(-sigma_t * d_el * ratio)
            value = amplitude * hg_phase(np.cos(beta + gamma), g) * attenuation / (d_el * sin_beta)
        else:
            on_ray = gamma >= 0
            s = np.where(on_ray, gamma, 0.0) / sin_beta
            value = amplitude * hg_phase(np.cos(beta), g) * np.exp(-sigma_t * s) / sin_beta
    return np.where(on_ray, value, 0.0)


def _row_integrand(kind, consts, beta, x, cells=None) -> np.ndarray:
    """K(β, x) of the module docstring, shape (3, len(beta), x.shape[-1]) for 1-D beta and
    x of shape (m,) or (len(beta), m). x must lie in [0, 1) (the nodes used are interior).

    The point rows are the table build's whole cost: each step runs in place on one
    (rows, m) buffer. `cells` = (centres, offsets), with x the flattened offsets[:, None] +
    centres[None, :] (node-major), takes the two half-angle sines of each node from sines and
    cosines of centres·δ/2 and offsets·δ/2 by the angle-sum formulas (`_point_half_sines`):
    an eighth of the trigonometry. The prefix rows move by at most 2e-15 of their largest
    value against a direct evaluation, and no float32 entry of the bench scenes' tables
    moves (bench/RESULTS.md history, host stages)."""
    amplitude, sigma_t = consts[:, C_AMPLITUDE], consts[:, C_SIGMA_T]
    g = float(consts[0, C_G])
    beta = np.asarray(beta, dtype=np.float64)[:, None]
    x = np.asarray(x, dtype=np.float64)
    if kind == "point":
        d_el = float(consts[0, C_D_EL])
        # Rows are written in δ = π-β (sinβ = sinδ, β+γ = π-(1-x)δ); the floor keeps the
        # β = π row finite, where K tends to ρ(-1)·exp(-σt·d_el·(1+x)/(1-x)).
        delta = np.maximum(math.pi - beta, 1e-150)
        # Half angles: sinβ + sinγ = 2·sin((1+x)δ/2)·cos((1-x)δ/2) and sin(β+γ) =
        # 2·sin((1-x)δ/2)·cos((1-x)δ/2), so the ratio is sin((1+x)δ/2)/sin((1-x)δ/2), and
        # cos(β+γ) = 2·sin²((1-x)δ/2) - 1: two sines per node, no cosine.
        if cells is None:
            ratio = np.sin((1.0 + x) * (0.5 * delta))
            far = np.sin((1.0 - x) * (0.5 * delta))
        else:
            ratio, far = _point_half_sines(delta, *cells)
        ratio /= far  # (sinβ + sinγ) / sin(β+γ)
        # HG denominator 1 + g² - 2g·cos(β+γ) = (1+g)² - 4g·sin²((1-x)δ/2).
        d = np.multiply(far, far, out=far)
        d *= -4.0 * g
        d += (1.0 + g) * (1.0 + g)
        falloff = np.sqrt(d)
        falloff *= d  # d·√d: no pow()
        scale = (1.0 - g * g) / (4.0 * math.pi * d_el)  # ρ's numerator and 1/d_el
        out = np.empty((len(consts),) + ratio.shape)
        for c, row in enumerate(out):
            np.multiply(ratio, -sigma_t[c] * d_el, out=row)
            np.exp(row, out=row)
            row /= falloff
            row *= amplitude[c] * scale
        return out
    s_end = consts[:, C_S_END, None, None]
    return amplitude[:, None, None] * hg_phase(np.cos(beta), g) * np.exp(-sigma_t[:, None, None] * (x * s_end))


def _point_half_sines(delta, centres, offsets) -> tuple[np.ndarray, np.ndarray]:
    """sin((1+x)δ/2) and sin((1-x)δ/2) on x = offsets[:, None] + centres[None, :] (flattened,
    node-major: one run of all cells per node) for each row's δ = π-β, from sin and cos of
    centres·δ/2 and offsets·δ/2 by angle sums: with a = x·δ/2, sin(δ/2 ± a) =
    sin(δ/2)·cos a ± cos(δ/2)·sin a. Node-major keeps numpy's inner loops one row of cells
    long (cell-major loops over 4 nodes at a time and costs 3× as much)."""
    rows = len(delta)
    half = 0.5 * delta
    sin_c, cos_c = _progression_sin_cos(half, centres)
    sin_c, cos_c = sin_c[:, None, :], cos_c[:, None, :]
    b = offsets[None, :] * half
    sin_o, cos_o = np.sin(b)[:, :, None], np.cos(b)[:, :, None]
    cos_a = (cos_c * cos_o - sin_c * sin_o).reshape(rows, -1)
    sin_a = (sin_c * cos_o + cos_c * sin_o).reshape(rows, -1)
    cos_a *= np.sin(half)
    sin_a *= np.cos(half)
    near = np.add(cos_a, sin_a)  # sin((1+x)δ/2)
    cos_a -= sin_a  # sin((1-x)δ/2)
    return near, cos_a


def _progression_sin_cos(delta, centres, block=32) -> tuple[np.ndarray, np.ndarray]:
    """sin and cos of centres·δ, (rows, cells), for centres evenly spaced (the cells of a row):
    by angle sums from the first centre of each block of `block` cells and the offsets within a
    block, so that the sines and cosines are taken of 2·cells/block angles per row, not cells."""
    block = min(block, len(centres))
    a = centres[None, ::block] * delta  # each block's first centre
    b = (centres[:block] - centres[0])[None, :] * delta  # the offsets within a block
    sin_a, cos_a = np.sin(a)[:, :, None], np.cos(a)[:, :, None]
    sin_b, cos_b = np.sin(b)[:, None, :], np.cos(b)[:, None, :]
    sines = (sin_a * cos_b + cos_a * sin_b).reshape(len(delta), -1)[:, :len(centres)]
    cosines = (cos_a * cos_b - sin_a * sin_b).reshape(len(delta), -1)[:, :len(centres)]
    return sines, cosines


@functools.cache
def _gauss_legendre(n) -> tuple[np.ndarray, np.ndarray]:
    """leggauss(n) once: it solves an eigenproblem on every call (about 0.25 ms, twice per
    grey table). Callers must not write to the arrays."""
    return np.polynomial.legendre.leggauss(n)


def _prefix_rows(kind, consts, beta, n_gamma) -> np.ndarray:
    """F(β_j, x_k) = ∫_0^{x_k} K(β_j, x) dx on x_k = k/(n_gamma-1), (3, len(beta), n_gamma):
    Gauss–Legendre with QUAD_NODES per cell, summed in float64."""
    nodes, weights = _gauss_legendre(QUAD_NODES)
    edges = np.linspace(0.0, 1.0, n_gamma)
    h = edges[1] - edges[0]
    centres = 0.5 * (edges[:-1] + edges[1:])
    x = 0.5 * h * nodes[:, None] + centres[None, :]  # node-major, as _point_half_sines
    shared = _shared_channel(consts)
    if shared is not None:  # grey medium: one channel's table, scaled by each amplitude
        return consts[:, C_AMPLITUDE, None, None] * _prefix_rows(kind, shared, beta, n_gamma)
    out = np.zeros((len(consts), len(beta), n_gamma))
    rows_per_chunk = max(1, ROW_CHUNK_VALUES // x.size)
    for j0 in range(0, len(beta), rows_per_chunk):
        rows = slice(j0, j0 + rows_per_chunk)
        k = _row_integrand(kind, consts, beta[rows], x.ravel(), (centres, 0.5 * h * nodes)).reshape(
            len(consts), -1, *x.shape)
        cells = k[:, :, 0] * weights[0]  # Σ_n w_n·K(x_n), summed in node order
        for n in range(1, len(weights)):
            cells += k[:, :, n] * weights[n]
        cells *= 0.5 * h
        if kind == "point":
            cells[..., -1] = _last_cell(kind, consts, beta[rows], h, nodes, weights)
        out[:, rows, 1:] = np.cumsum(cells, axis=-1)
    return out


def _shared_channel(consts) -> np.ndarray | None:
    """When every channel has the same σt (and row end), the table differs between
    channels only by the amplitude σs·power: return one unit-amplitude channel to build
    once (3× less work for grey fog), else None."""
    if len(consts) == 1 or not np.array_equal(consts[:, [C_SIGMA_T, C_S_END]], consts[:1, [C_SIGMA_T, C_S_END]].repeat(len(consts), 0)):
        return None
    unit = consts[:1].copy()
    unit[:, C_AMPLITUDE] = 1.0
    return unit


def _last_cell(kind, consts, beta, h, nodes, weights) -> np.ndarray:
    """∫ K over the last cell [1-h, 1] on panels halving towards x = 1. For β → 0 the point
    light's K drops from e^{-σt·d_el}·ρ to 0 in a layer ~σt·d_el·β wide at x = 1 (the far
    half-ray), narrower than a cell; one Gauss–Legendre panel would miss it by ~1e-5."""
    edges = 1.0 - h * 0.5 ** np.arange(41)  # the last 1e-12·h is left out: K is bounded
    lo, hi = edges[:-1], edges[1:]
    x = (0.5 * (lo + hi))[:, None] + (0.5 * (hi - lo))[:, None] * nodes[None, :]
    k = _row_integrand(kind, consts, beta, x.ravel()).reshape(len(consts), len(beta), *x.shape)
    return (k @ weights) @ (0.5 * (hi - lo))


def _beta_nodes(beta_min, beta_max, n) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)
    return beta_min + (beta_max - beta_min) * np.sin(0.5 * math.pi * t) ** 2


# --------------------------------------------------------------------------- building


def build_integrand(mode, light_kind, sigma_s, sigma_t, phase, power, d_el, beta_min, beta_max, gamma_max,
                    n_beta=256, n_gamma=1024, rank=4, *, s_max=None, rows=True) -> IntegrandTables:
    """Build one frame's integrand tables (float64).

    mode: "table" | "svd" | "analytic". light_kind: "point" | "spot" | "directional".
    sigma_s, sigma_t: scattering and extinction coefficients, 1/m, scalar or RGB.
    phase: clrays.scene.model.Phase. power: I (W/sr) for point/spot, E (W/m²) for directional.
    d_el: eye–light distance (m), > 0 for point/spot; ignored for directional.
    beta_min, beta_max: the β range the rays need, 0 <= beta_min <= beta_max <= π.
    gamma_max: the γ range of the rectified map (> 0); recorded, see IntegrandTables.
    n_beta (default 256), n_gamma (default 1024): table nodes, >= 2. rank (default 4):
    SVD terms, 1..64. s_max (keyword, directional table/svd only): the longest camera
    ray in the medium (m); the rows end at s_end = min(s_max, 20/min σt). Required when
    some channel has σt = 0. rows=False (table only): everything but the prefix rows, which
    `device_table` then builds on the device.

    Raises ValueError (one line, starting "integrand:") on bad input and when `analytic`
    has no closed form for the light and medium.
    """
    if mode not in MODES:
        raise ValueError(f"integrand: mode: expected one of {', '.join(MODES)}, got {mode!r}")
    kind = _light_kind(light_kind)
    sigma_s, sigma_t, power = _rgb("sigma_s", sigma_s), _rgb("sigma_t", sigma_t), _rgb("power", power)
    g = _phase_g(phase)
    beta_min, beta_max, gamma_max = float(beta_min), float(beta_max), float(gamma_max)
    if not 0.0 <= beta_min <= beta_max <= math.pi:
        raise ValueError(f"integrand: beta range: expected 0 <= beta_min <= beta_max <= pi, "
                         f"got [{beta_min}, {beta_max}]")
    if not (math.isfinite(gamma_max) and gamma_max > 0):
        raise ValueError(f"integrand: gamma_max: expected a finite value > 0, got {gamma_max}")
    d_el = float(d_el) if kind == "point" else 0.0
    if kind == "point" and not (math.isfinite(d_el) and d_el > 0):
        raise ValueError(f"integrand: d_el: expected a finite distance > 0 (eye at the light has no epipolar "
                         f"coordinates; use the unshadowed closed form), got {d_el}")

    consts = np.zeros((3, N_CONSTANTS))
    consts[:, C_AMPLITUDE] = sigma_s * power
    consts[:, C_SIGMA_T] = sigma_t
    consts[:, C_D_EL] = d_el
    consts[:, C_G] = g

    if mode == "analytic":
        if kind == "point":
            if np.any(sigma_t > 0):
                raise ValueError("integrand: analytic: a point/spot light in an attenuating medium (sigma_t > 0) "
                                 "has no closed form; use mode table or svd")
            if g != 0.0:
                raise ValueError("integrand: analytic: a point/spot light with a Henyey-Greenstein phase needs the "
                                 "incomplete elliptic integral E(phi|m), which the device lacks; use mode table "
                                 "or svd (or an isotropic phase)")
        return IntegrandTables(mode, kind, beta_min, beta_max, gamma_max, 0, 0, 0, None, None, None, consts)

    n_beta, n_gamma, rank = int(n_beta), int(n_gamma), int(rank)
    if n_beta < 2 or n_gamma < 2:
        raise ValueError(f"integrand: table size: expected n_beta, n_gamma >= 2, got {n_beta} x {n_gamma}")
    if kind == "directional":
        sigma_ref = float(sigma_t.min())
        limit = DIRECTIONAL_OPTICAL_DEPTH / sigma_ref if sigma_ref > 0 else math.inf
        if s_max is not None:
            s_max = float(s_max)
            if not (math.isfinite(s_max) and s_max > 0):
                raise ValueError(f"integrand: s_max: expected a finite distance > 0, got {s_max}")
            limit = min(limit, s_max)
        if not math.isfinite(limit):
            raise ValueError(f"integrand: {mode} for a directional light with sigma_t = 0 in some channel needs "
                             "s_max, the longest camera ray in the medium")
        consts[:, C_S_END] = limit

    beta = _beta_nodes(beta_min, beta_max, n_beta)
    if mode == "table":
        prefix = _prefix_rows(kind, consts, beta, n_gamma) if rows else None
        return IntegrandTables(mode, kind, beta_min, beta_max, gamma_max, n_beta, n_gamma, 0,
                               None if prefix is None else np.ascontiguousarray(prefix), None, None, consts)

    if not 1 <= rank <= SVD_SAMPLES:
        raise ValueError(f"integrand: rank: expected 1..{SVD_SAMPLES}, got {rank}")
    beta_s = _beta_nodes(beta_min, beta_max, SVD_SAMPLES)
    x_s = (np.arange(SVD_SAMPLES) + 0.5) / SVD_SAMPLES
    samples = _row_integrand(kind, consts, beta_s, x_s)  # (3, 64, 64)
    # Nyström extension: B_i(β) = Σ_k K(β, x_k)·v_ik, Γ_i(x) = Σ_j K(β_j, x)·u_ji/σ_i, so
    # P_i(x) = Σ_j u_ji/σ_i·F(β_j, x) with F the accurate prefix rows. On the sample grid
    # this is exactly the truncated SVD; between samples it uses K itself, not a lerp.
    k_rows = _row_integrand(kind, consts, beta, x_s)  # (3, n_beta, 64)
    f_rows = _prefix_rows(kind, consts, beta_s, n_gamma)  # (3, 64, n_gamma)
    basis = np.zeros((3, rank, n_beta))
    prefix_gamma = np.zeros((3, rank, n_gamma))
    for c in range(3):
        u, sv, vt = np.linalg.svd(samples[c])
        for i in range(rank):
            if sv[i] <= SVD_RELATIVE_CUTOFF * sv[0] or sv[0] == 0.0:
                break
            basis[c, i] = k_rows[c] @ vt[i]
            prefix_gamma[c, i] = (u[:, i] / sv[i]) @ f_rows[c]
    return IntegrandTables(mode, kind, beta_min, beta_max, gamma_max, n_beta, n_gamma, rank,
                           None, np.ascontiguousarray(basis), np.ascontiguousarray(prefix_gamma), consts)


# --------------------------------------------------------------------------- evaluating (the kernel)


def _sin_beta(beta):
    return np.maximum(np.sin(beta), SIN_BETA_MIN)


def row_coord(tables: IntegrandTables, beta, gamma) -> np.ndarray:
    """x(β, γ) ∈ [0, 1], shape (3, ...) (per channel only through s_end)."""
    beta, gamma = np.asarray(beta, dtype=np.float64), np.asarray(gamma, dtype=np.float64)
    if tables.light_kind == "point":
        delta = np.maximum(math.pi - beta, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(delta > 0, gamma / delta, np.where(gamma > 0, 1.0, 0.0))
        return np.broadcast_to(np.clip(x, 0.0, 1.0), (3,) + x.shape)
    s = gamma / _sin_beta(beta)
    s_end = tables.constants[:, C_S_END].astype(np.float64).reshape((3,) + (1,) * s.ndim)
    return np.clip(s / s_end, 0.0, 1.0)


def row_scale(tables: IntegrandTables, beta) -> np.ndarray:
    """row_scale(β) of the module docstring, shape (3, ...)."""
    beta = np.asarray(beta, dtype=np.float64)
    if tables.light_kind == "point":
        delta = np.maximum(math.pi - beta, 0.0)
        # (π-β)/sinβ → 1 as β → π; below SIN_BETA_MIN the limit is used.
        scale = np.where(delta > SIN_BETA_MIN, delta / _sin_beta(beta), 1.0)
        return np.broadcast_to(scale, (3,) + scale.shape)
    s_end = tables.constants[:, C_S_END].astype(np.float64).reshape((3,) + (1,) * beta.ndim)
    return np.broadcast_to(s_end, (3,) + beta.shape)


def beta_coord(tables: IntegrandTables, beta) -> np.ndarray:
    """Fractional β node index t·(n_beta-1), the inverse of β = beta_min + span·sin²(πt/2):
    t = (2/π)·atan2(sqrt(β - beta_min), sqrt(beta_max - β)), precise at both ends in float32."""
    beta = np.asarray(beta, dtype=np.float64)
    span = tables.beta_max - tables.beta_min
    if span <= 0:
        return np.zeros(beta.shape)
    lo = np.sqrt(np.clip(beta - tables.beta_min, 0.0, span))
    hi = np.sqrt(np.clip(tables.beta_max - beta, 0.0, span))
    return (2.0 / math.pi) * np.arctan2(lo, hi) * (tables.n_beta - 1)


def _split(coord, n):
    """Integer cell index in [0, n-2] and the fraction in it (the kernel's floor/clamp)."""
    i = np.clip(np.floor(coord), 0, n - 2).astype(np.intp)
    return i, coord - i


def _lerp_rows(table, j, fj, x):
    """table (3, R, N): bilinear value at row j + fj, column x·(N-1), shape (3, ...)."""
    k, fk = _split(x * (table.shape[-1] - 1), table.shape[-1])
    c = np.arange(3).reshape((3,) + (1,) * (x.ndim - 1))

    def at(jj):
        return (1.0 - fk) * table[c, jj, k] + fk * table[c, jj, k + 1]

    return (1.0 - fj) * at(j) + fj * at(j + 1)


def segment_radiance(tables: IntegrandTables, beta, gamma0, gamma1) -> np.ndarray:
    """In-scattered radiance of the lit interval [γ0, γ1) of ray β: ∫ I(β, γ) dγ, shape
    broadcast(beta, gamma0, gamma1).shape + (3,), float64 (W/sr/m² per channel).

    Mirrors the OpenCL kernel step by step: row coordinates, the β node lookup, bilinear
    (table) or separable linear (svd) prefix lookups, the closed-form row scale; analytic
    evaluates the closed form. γ outside the ray is clamped onto it (so γ1 past the
    point at infinity gives the whole rest of the ray); γ0 <= γ1 is expected.
    """
    beta, gamma0, gamma1 = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (beta, gamma0, gamma1)))
    consts = tables.constants.astype(np.float64)
    shape_c = (3,) + (1,) * beta.ndim
    if tables.mode == "analytic":
        amplitude = consts[:, C_AMPLITUDE].reshape(shape_c)
        sin_beta = _sin_beta(beta)
        if tables.light_kind == "point":
            delta = np.maximum(math.pi - beta, 0.0)
            span = np.clip(gamma1, 0.0, delta) - np.clip(gamma0, 0.0, delta)
            d_el = consts[:, C_D_EL].reshape(shape_c)
            out = amplitude / (4.0 * math.pi * d_el * sin_beta) * span
        else:
            sigma_t = consts[:, C_SIGMA_T].reshape(shape_c)
            rho = hg_phase(np.cos(beta), float(consts[0, C_G]))
            s0 = np.maximum(gamma0, 0.0) / sin_beta
            ds = np.maximum(gamma1, 0.0) / sin_beta - s0
            # σs·E·ρ·(e^{-σt·s0} - e^{-σt·s1})/σt = σs·E·ρ·e^{-σt·s0}·(-expm1(-σt·Δs))/σt,
            # which tends to σs·E·ρ·Δs as σt → 0.
            with np.errstate(divide="ignore", invalid="ignore"):
                tail = np.where(sigma_t > 0, -np.expm1(-sigma_t * ds) / sigma_t, ds)
            out = amplitude * rho * np.exp(-sigma_t * s0) * tail
        return np.moveaxis(out, 0, -1)

    j, fj = _split(beta_coord(tables, beta), tables.n_beta)
    x0, x1 = row_coord(tables, beta, gamma0), row_coord(tables, beta, gamma1)
    if tables.mode == "table":
        prefix = tables.prefix.astype(np.float64)
        diff = _lerp_rows(prefix, j, fj, x1) - _lerp_rows(prefix, j, fj, x0)
    else:
        basis = tables.basis_beta.astype(np.float64)
        prefix_gamma = tables.prefix_gamma.astype(np.float64)
        diff = np.zeros((3,) + beta.shape)
        c = np.arange(3).reshape(shape_c)
        k0, fk0 = _split(x0 * (tables.n_gamma - 1), tables.n_gamma)
        k1, fk1 = _split(x1 * (tables.n_gamma - 1), tables.n_gamma)
        for i in range(tables.rank):
            b_i = (1.0 - fj) * basis[c, i, j] + fj * basis[c, i, j + 1]
            p_i = prefix_gamma[:, i]
            p1 = (1.0 - fk1) * p_i[c, k1] + fk1 * p_i[c, k1 + 1]
            p0 = (1.0 - fk0) * p_i[c, k0] + fk0 * p_i[c, k0 + 1]
            diff += b_i * (p1 - p0)
    return np.moveaxis(row_scale(tables, beta) * diff, 0, -1)


# --------------------------------------------------------------------------- the stage

#: Table size per light and frame: at 128 × 512 a segment's error is at most 2e-3
#: (median ~1e-6, whole rays ≤ 1e-3; docs/integrand.md), far below the method's
#: visibility error, and the tables build 4× faster than at 256 × 1024.
INTEGRAND_ROWS = 128
INTEGRAND_COLUMNS = 512
#: Smallest table. Its error (5e-4 at 32 × 128, tests/stages/test_minmax.py) stays far
#: below the visibility error of the small shadow map such an image gets.
MIN_INTEGRAND_ROWS = 16
MIN_INTEGRAND_COLUMNS = 64


def integrand_table_size(width: int, height: int) -> tuple[int, int]:
    """(β rows, x columns) of the tables for a width × height image: rows follow the
    image diagonal (the visible β range spans at most that many pixels), columns four
    times it, as powers of two clamped to [16, 128] × [64, 512], so 640×360 and larger
    keep 128 × 512 and a 16×9 thumbnail builds 32 × 128 (docs/design.md §7)."""
    diagonal = math.hypot(width, height)

    def clamped(value, low, high):
        return min(max(1 << math.ceil(math.log2(max(value, 1.0))), low), high)

    return (clamped(diagonal, MIN_INTEGRAND_ROWS, INTEGRAND_ROWS),
            clamped(4 * diagonal, MIN_INTEGRAND_COLUMNS, INTEGRAND_COLUMNS))

_MODE_IDS = {"table": structs.INTEGRAND_TABLE, "svd": structs.INTEGRAND_SVD, "analytic": structs.INTEGRAND_ANALYTIC}


#: Cells one integrand_cells work-item integrates at once, as float8 lanes (cl/lanes.h).
INTEGRAND_LANES = 8
TABLE_BUILD_DEFINES = {"LANES": INTEGRAND_LANES, "QUAD_NODES": QUAD_NODES}


def table_rows(tables: IntegrandTables) -> np.ndarray:
    """(n_beta, 4) float32: what cl/integrand_build.cl needs of each β row, from float64:
    (δ = π - β, β, ρ(cos β) (directional rows), 0)."""
    beta = _beta_nodes(tables.beta_min, tables.beta_max, tables.n_beta)
    rows = np.zeros((tables.n_beta, 4))
    rows[:, 0] = np.maximum(math.pi - beta, 1e-20)  # the β = π row stays finite, as _row_integrand's
    rows[:, 1] = beta
    rows[:, 2] = hg_phase(np.cos(beta), float(tables.constants[0, C_G]))
    return rows.astype(np.float32)


def grey_table(tables: IntegrandTables) -> bool:
    """Whether the device builds the `table` mode's F as one plane of unit amplitude: every
    channel has the same σt (and row end), so the channels' tables differ by their amplitude
    alone, which a segment multiplies in (cl/integrand.h). A third of the build, and a
    segment looks up one channel where it looked up three."""
    return tables.mode == "table" and _shared_channel(tables.constants) is not None


def wide_type(device: Device) -> type:
    """The numpy type of cl/visible_ranges.h's wide_t on `device`: float64 where it has doubles."""
    return np.float64 if "cl_khr_fp64" in device.device.extensions else np.float32


def device_rows(device: Device, tables: IntegrandTables, visible, params, timer: StageTimer | None = None):
    """On the device, from the visible rays' β range `visible` (clrays.stages.rectify.
    VisibleRanges), which the host does not read: the range written into `params`
    (integrand_t, with its `no_extent` flag) and, for the `table` mode, the rows
    `table_rows` would give (cl/integrand_build.cl integrand_rows), else None."""
    rows = device.buffer(nbytes=16 * tables.n_beta) if tables.mode == "table" else None
    g = device.buffer(np.array([tables.constants[0, C_G]], dtype=wide_type(device)), writable=False)
    event = device.kernel("integrand_build", "integrand_rows", TABLE_BUILD_DEFINES)(
        device.queue, (max(tables.n_beta, 1),), None, visible.bounds, np.int32(visible.directional), g,
        np.int32(tables.n_beta), rows, params)
    if timer is not None:
        timer.add("integrand", event)
    return rows


def device_table(device: Device, tables: IntegrandTables, timer: StageTimer | None = None, rows=None) -> object:
    """The `table` mode's prefix rows F(β_j, x_k), (3, n_beta, n_gamma) float32, or for a
    `grey_table` (1, n_beta, n_gamma) of unit amplitude, built on the device
    (cl/integrand_build.cl): the same rule as `_prefix_rows`, in float32, with a
    compensated running sum. The cells are independent, so the device takes them all at
    once where the host would loop over chunks of rows (docs/design.md §4.4). `rows`: the
    β rows on the device (`device_rows`); None: `table_rows(tables)`, uploaded."""
    c = tables.constants
    point = int(tables.light_kind == "point")
    grey = int(grey_table(tables))
    amplitude = structs.float4(np.ones(3) if grey else c[:, C_AMPLITUDE])
    sigma_t = structs.float4(c[:, C_SIGMA_T])
    d_el, g = np.float32(c[0, C_D_EL]), np.float32(c[0, C_G])
    n_beta, n_gamma = tables.n_beta, tables.n_gamma
    if rows is None:
        rows = device.buffer(table_rows(tables), writable=False)
    table = device.buffer(nbytes=4 * (1 if grey else 3) * n_beta * n_gamma)
    cells = device.kernel("integrand_build", "integrand_cells", TABLE_BUILD_DEFINES)
    prefix = device.kernel("integrand_build", "integrand_prefix", TABLE_BUILD_DEFINES)
    events = [
        cells(device.queue, (-(-(n_gamma - 1) // INTEGRAND_LANES), n_beta), None, rows, np.int32(point), amplitude,
              sigma_t, structs.float4(c[:, C_S_END]), d_el, g, np.int32(grey), np.int32(n_gamma), table),
        prefix(device.queue, (n_beta,), None, rows, np.int32(point), amplitude, sigma_t, d_el, g, np.int32(grey),
               np.int32(n_gamma), table),
    ]
    for event in events if timer is not None else ():
        timer.add("integrand", event)
    return table


class DeviceIntegrand:
    """One light's integrand tables, packed as `cl/integrand.h` reads them, on the device.
    A table built on the device is read back into `tables` only when asked for, and so is
    the β range the device wrote (`visible`, clrays.stages.rectify.VisibleRanges: where it
    came from; None: `tables` has it)."""

    def __init__(self, tables: IntegrandTables, params, data, device: Device | None = None, visible=None):
        self._tables = tables
        self.params = params  # integrand_t
        self.data = data  # float[]: the prefix table, or the SVD bases then prefix integrals
        self._device = device
        self._visible = visible

    @property
    def n_beta(self) -> int:
        """The tables' β rows, known on the host (no read back)."""
        return int(self._tables.n_beta)

    @property
    def tables(self) -> IntegrandTables:
        if self._visible is not None:
            beta_min, beta_max, gamma_max, _ = self._visible.host()
            self._tables = replace(self._tables, beta_min=beta_min, beta_max=beta_max, gamma_max=gamma_max)
            self._visible = None
        if self._tables.mode == "table" and self._tables.prefix is None:
            self._tables = replace(self._tables, prefix=read_device_table(self._device, self.data, self._tables))
        return self._tables


def read_device_table(device: Device, table, tables: IntegrandTables) -> np.ndarray:
    """(3, n_beta, n_gamma) float64: the table `device_table` built, each channel's plane
    (a grey table's one plane times each channel's amplitude)."""
    planes = 1 if grey_table(tables) else 3
    built = device.read(table, (planes, tables.n_beta, tables.n_gamma), np.float32).astype(np.float64)
    return tables.constants[:, C_AMPLITUDE, None, None] * built if planes == 1 else built


def integrand(device: Device, scene, light, epipolar, timer: StageTimer) -> DeviceIntegrand:
    """Stage integrand: one light's per-frame tables over the β and γ ranges of the
    visible rays (`epipolar`): the `table` mode's built on the device (`device_table`),
    from the β range the device holds (`device_rows`), without a host wait; the others
    on the host in float64 and uploaded (the `svd` mode reads the range back for its
    singular value decomposition)."""
    render, medium = scene.render, scene.medium
    device.program("integrand_build", TABLE_BUILD_DEFINES)  # built before the clock starts, as every stage's kernels
    start = time.perf_counter()
    directional = isinstance(light, DirectionalLight)
    n_beta, n_gamma = integrand_table_size(scene.image.width, scene.image.height)
    on_device = render.integrand != "svd"  # the host needs no β for the table's rows nor for analytic
    # A placeholder range where the device fills it in: it only passes the checks.
    beta_min, beta_max, gamma_max = (0.0, math.pi, math.pi) if on_device else epipolar.visible.host()[:3]
    try:
        tables = build_integrand(
            render.integrand, "directional" if directional else "point", medium.sigma_s, medium.sigma_t,
            medium.phase, light.irradiance if directional else light.intensity, epipolar.d_el,
            beta_min, beta_max, max(gamma_max, math.ulp(0.0)), rank=render.svd_rank, n_beta=n_beta, n_gamma=n_gamma,
            s_max=effective_far(scene) if directional and render.integrand != "analytic" else None,
            rows=render.integrand != "table")
    except ValueError as exc:  # e.g. `analytic` where no closed form exists
        where = f"{scene.source}: " if scene.source else ""
        raise ClraysError(f"{where}render.integrand: {str(exc).removeprefix('integrand: ')}") from exc
    params, data = pack_integrand(tables)
    params_buffer = device.buffer(params.reshape(1))
    rows = device_rows(device, tables, epipolar.visible, params_buffer, timer)  # the β range, on the device
    data = device_table(device, tables, timer, rows) if tables.mode == "table" else device.buffer(data, writable=False)
    packed = DeviceIntegrand(tables, params_buffer, data, device, epipolar.visible if on_device else None)
    timer.add_host("integrand", (time.perf_counter() - start) * 1e3)
    return packed


def pack_integrand(tables: IntegrandTables) -> tuple[np.ndarray, np.ndarray]:
    """integrand_t and the flat float32 table data that `cl/integrand.h` reads."""
    c = tables.constants
    params = np.zeros((), dtype=structs.integrand_dtype)
    params["amplitude"] = structs.float4(c[:, C_AMPLITUDE])
    params["sigma_t"] = structs.float4(c[:, C_SIGMA_T])
    params["s_end"] = structs.float4(c[:, C_S_END])
    params["beta_min"], params["beta_max"] = tables.beta_min, tables.beta_max
    params["d_el"], params["g"] = c[0, C_D_EL], c[0, C_G]
    params["mode"] = _MODE_IDS[tables.mode]
    params["n_beta"], params["n_gamma"], params["rank"] = tables.n_beta, tables.n_gamma, tables.rank
    params["light_type"] = structs.LIGHT_DIRECTIONAL if tables.light_kind == "directional" else structs.LIGHT_POINT
    params["grey"] = tables.prefix is None and grey_table(tables)  # device_table's one plane
    if tables.mode == "table":
        data = tables.prefix.ravel() if tables.prefix is not None else np.zeros(1)  # None: built on the device
    elif tables.mode == "svd":
        data = np.concatenate([tables.basis_beta.ravel(), tables.prefix_gamma.ravel()])
    else:
        data = np.zeros(1)
    return params, np.ascontiguousarray(data, dtype=np.float32)
