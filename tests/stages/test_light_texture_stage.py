"""Stage light_texture against numpy: each cell's texture is the mean of the host's bilinear
lookups at the cell's evenly spaced points (`cell_samples`) on the same light rays, the prefix sums are
cumulative sums of T·Γ_i, and the low-rank integrand in γ converges with the rank
(docs/light-textures.md)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from clrays import structs
from clrays.device import StageTimer
from clrays.inputs import frame_inputs, upload
from clrays.physics.light_texture import light_texture as host_texture
from clrays.scene.model import LightTexture
from clrays.stages.integrand import integrand, integrand_exact
from clrays.stages.light_texture import cell_samples, gamma_basis, light_texture
from clrays.stages.raster import raster
from clrays.stages.rectify import rectify
from conftest import DirectionalLight, PointLight, SpotLight, grid_plane, make_scene, v3

TEXELS = np.random.default_rng(14).uniform(0.0, 2.0, (24, 40, 3)).astype(np.float32)
LIGHTS = {
    "spot": SpotLight(v3(0.3, 5.0, -0.5), v3(0.1, -1.0, 0.1) / np.linalg.norm([0.1, -1.0, 0.1]), 35.0,
                      np.full(3, 60.0), texture=LightTexture(TEXELS, "random")),
    "point": PointLight(v3(0.3, 4.0, -0.5), np.full(3, 60.0),
                        texture=LightTexture(np.concatenate([TEXELS[:24, :24] * (1 + f) for f in range(6)]), "cube")),
    "directional": DirectionalLight(v3(0.35, -1.0, -0.25) / np.linalg.norm([0.35, -1.0, -0.25]), np.full(3, 1.5),
                                    texture=LightTexture(TEXELS, "random"), texture_size=(1.3, 0.7)),
}
# The same sun with its edge texels extended (the kernel wraps a directional row's cells itself).
LIGHTS["directional, clamp"] = dataclasses.replace(LIGHTS["directional"], texture_wrap="clamp")


def _light_rays(scene, params, n, slices, at=0.5):
    """World-space points on the light ray of each (slice, cell), `at` of the way through the
    cell in its texel coordinate, as the kernel takes them."""
    alpha = params["alpha_min"] + (np.arange(slices) + 0.5) * params["alpha_step"]
    gamma = structs.texel_gamma(float(params["gamma_step"]), n, np.arange(n) + at, float(params["gamma_warp"]))
    r = (np.cos(alpha)[:, None, None] * params["u"][:3].astype(np.float64)
         + np.sin(alpha)[:, None, None] * params["w"][:3].astype(np.float64))
    axis = params["axis"][:3].astype(np.float64)
    light = scene.lights[0]
    if isinstance(light, DirectionalLight):
        return scene.camera.position + gamma[None, :, None] * r
    return light.position - axis * np.cos(gamma)[None, :, None] + r * np.sin(gamma)[None, :, None]


@pytest.mark.parametrize("kind", list(LIGHTS))
def test_rectified_texture_and_prefix_sums_match_numpy(device, kind):
    scene = make_scene(grid_plane(), [LIGHTS[kind]], width=32, height=18, slices=64, gamma_samples=128,
                       shadow_map=256, svd_rank=3)
    buffers = upload(device, frame_inputs(scene))
    timer = StageTimer()
    rastered = raster(device, buffers, timer)
    epipolar = rectify(device, buffers, rastered, 0, timer)
    tables = integrand(device, scene, scene.lights[0], epipolar, timer)
    texture = light_texture(device, buffers, 0, epipolar, tables, timer)
    n, slices, rank = int(epipolar.params["gamma_samples"]), int(epipolar.params["slices"]), texture.rank
    params = device.read(epipolar.buffer, (), structs.epipolar_dtype)
    samples = cell_samples(scene.lights[0], epipolar.gamma_step, epipolar.gamma_warp)
    assert samples > 1 or kind == "point"  # the spot's and the suns' cells are longer than a texel: a mean
    expected = np.mean([host_texture(scene.lights[0], _light_rays(scene, params, n, slices, (j + 0.5) / samples)
                                     .reshape(-1, 3)).reshape(slices, n, 3) for j in range(samples)], axis=0)
    # A record per cell boundary: [channel][term].
    prefix = device.read(texture.prefix, (slices, n + 1, 3, rank + 1), np.float32).astype(np.float64)
    prefix = prefix.transpose(0, 2, 3, 1)  # (slices, channel, term, boundary)
    step, warp = epipolar.gamma_step, epipolar.gamma_warp
    widths = np.diff(structs.texel_gamma(step, n, np.arange(n + 1), warp))  # each γ cell's length
    rectified = (np.diff(prefix[:, :, 0], axis=-1) / widths).transpose(0, 2, 1)  # term 0 is ∫T
    # Texel lookups of float32 coordinates: a texel of 2 changes by 2·Δx per texel of Δx.
    np.testing.assert_allclose(rectified, expected, atol=2e-3 * TEXELS.max())
    directional = isinstance(LIGHTS[kind], DirectionalLight)
    basis = gamma_basis("directional" if directional else "point", scene.medium,
                        LIGHTS[kind].irradiance if directional else LIGHTS[kind].intensity,
                        epipolar.d_el, epipolar.beta_min, epipolar.beta_max, step, n,
                        max(tables.tables.n_beta, 16), rank, warp)
    for term in range(1, rank + 1):
        cumulative = np.cumsum(widths * rectified.transpose(0, 2, 1) * basis.gamma[None, :, term - 1], axis=-1)
        scale = np.abs(cumulative).max()
        np.testing.assert_allclose(prefix[:, :, term, 1:], cumulative, atol=1e-5 * scale)


@pytest.mark.parametrize("light_kind, d_el", [("point", 6.0), ("directional", 0.0)])
def test_gamma_basis_converges_with_rank(light_kind, d_el):
    """max |K - Σ_i B_i·Γ_i| on the β rows × γ cells falls with the rank: the low-rank form the
    textured runs use. Measured, of max |K|, at ranks 1, 2, 4, 8: point 7.1e-2, 1.5e-2,
    5.0e-3, 1.0e-3; directional 1.7e-1, 6.7e-3, 2.9e-6, 4e-14. The runs need far less than
    this: the control variate leaves this error multiplied by the texture's variation within
    a run (docs/light-textures.md)."""
    from clrays.scene.model import Medium, Phase

    medium = Medium(np.full(3, 0.1), np.full(3, 0.02), Phase("hg", 0.4))
    beta_min, beta_max, step, n = 0.2, 2.6, 0.004, 512
    errors = []
    for rank in (1, 2, 4, 8):
        basis = gamma_basis(light_kind, medium, np.full(3, 50.0), d_el, beta_min, beta_max, step, n, 64, rank)
        t = np.linspace(0, 1, 64)
        beta = beta_min + (beta_max - beta_min) * np.sin(0.5 * math.pi * t) ** 2
        gamma = (np.arange(n) + 0.5) * step
        b, g = np.meshgrid(beta, gamma, indexing="ij")
        if light_kind == "point":
            g = np.minimum(g, (math.pi - b) * (1 - 1e-9))
        k = integrand_exact(light_kind, medium.sigma_s, medium.sigma_t, medium.phase, 50.0, d_el, b, g)
        k = k[..., 0] * np.sin(b)
        approx = np.einsum("ij,ik->jk", basis.basis_beta[0], basis.gamma[0])
        errors.append(np.abs(approx - k).max() / np.abs(k).max())
    assert errors[0] > errors[1] > errors[2] > errors[3], errors
    assert errors[2] < 1e-2, errors
