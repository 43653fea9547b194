"""The integrand stage's host side (clrays/integrand.py) against independent quadrature.

The reference everywhere is scipy.integrate.quad of I(β, γ) written out here from
docs/design.md §2–§3 (not the module's own integrand_exact), and once the radiometric
integral over distance s along a concrete 3-D ray, which pins down the change of
variables and the sign of the phase angle.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import ellipeinc

from clrays.stages.integrand import (C_AMPLITUDE, C_D_EL, C_G, C_S_END, C_SIGMA_T, N_CONSTANTS, build_integrand,
                              integrand_exact, segment_radiance)
from clrays.scene.model import Phase

PI = math.pi
D_EL = 2.0
SIGMA_S = (0.1, 0.2, 0.3)
POWER = (10.0, 20.0, 30.0)
SIGMA_T = {"zero": (0.0, 0.0, 0.0), "small": (0.01, 0.02, 0.04), "medium": (0.2, 0.3, 0.5)}
PHASES = {"iso": Phase(), "hg+0.3": Phase("hg", 0.3), "hg-0.5": Phase("hg", -0.5)}
BETAS = (1e-3, 0.05, 0.7, 1.6, 2.6, PI - 1e-2)
# Point light: fractions of the whole ray [0, π-β). Directional: distances s along the ray.
POINT_SPANS = ((0.0, 1.0), (0.1, 0.45), (0.5, 0.8), (0.3, 0.35))
S_MAX = 50.0
DIRECTIONAL_SPANS = ((0.0, S_MAX), (0.0, 5.0), (3.0, 20.0), (30.0, 45.0))
CASES = [(s, p) for s in SIGMA_T for p in PHASES]


# --------------------------------------------------------------------------- the reference


def hg(c, g):
    return (1 - g * g) / (4 * PI * (1 + g * g - 2 * g * c) ** 1.5)


def design_integrand(gamma, kind, sigma_t, g, beta, channel):
    """I(β, γ) of docs/design.md §2 (point) and §3 (directional), one channel, scalars."""
    ss, st, power = SIGMA_S[channel], sigma_t[channel], POWER[channel]
    if kind == "point":
        if not 0 <= gamma < PI - beta:
            return 0.0
        ratio = (math.sin(beta) + math.sin(gamma)) / math.sin(beta + gamma)
        return ss * power * hg(math.cos(beta + gamma), g) * math.exp(-st * D_EL * ratio) / (D_EL * math.sin(beta))
    return ss * power * hg(math.cos(beta), g) * math.exp(-st * gamma / math.sin(beta)) / math.sin(beta)


def reference(kind, sigma_t, g, beta, gamma0, gamma1):
    """∫ I dγ over [γ0, γ1] per channel by adaptive quadrature. For β → 0 the point light's
    integrand falls to 0 in a layer ~σt·d_el·β wide before γ = π-β: hint it to quad."""
    hints = [PI - beta - k * beta for k in (0.5, 1, 2, 5, 20)] if kind == "point" else []
    hints = [p for p in hints if gamma0 < p < gamma1] or None
    return np.array([quad(design_integrand, gamma0, gamma1, args=(kind, sigma_t, g, beta, c), epsabs=0.0,
                          epsrel=1e-11, limit=500, points=hints)[0] for c in range(3)])


@lru_cache(maxsize=None)
def cases(kind, sigma_name, phase_name):
    """[(β, γ0, γ1, is_whole_ray, reference (3,), whole-ray reference (3,))] over the test grid."""
    sigma_t, g = SIGMA_T[sigma_name], PHASES[phase_name].g
    out = []
    for beta in BETAS:
        if kind == "point":
            spans = [(a * (PI - beta), b * (PI - beta)) for a, b in POINT_SPANS]
        else:
            spans = [(a * math.sin(beta), b * math.sin(beta)) for a, b in DIRECTIONAL_SPANS]
        whole = reference(kind, sigma_t, g, beta, *spans[0])
        for i, (g0, g1) in enumerate(spans):
            out.append((beta, g0, g1, i == 0, whole if i == 0 else reference(kind, sigma_t, g, beta, g0, g1), whole))
    return out


@lru_cache(maxsize=None)
def tables(mode, kind, sigma_name, phase_name, rank=4, **kw):
    return build_integrand(mode, kind, SIGMA_S, SIGMA_T[sigma_name], PHASES[phase_name], POWER, D_EL, 0.0, PI, PI,
                           rank=rank, s_max=S_MAX, **kw)


def errors(t, kind, sigma_name, phase_name):
    """(relative error, error relative to the whole ray, is_whole_ray) for every case and channel."""
    rel, to_ray, whole = [], [], []
    for beta, g0, g1, is_whole, ref, ray in cases(kind, sigma_name, phase_name):
        value = segment_radiance(t, beta, g0, g1)
        rel.extend(np.abs(value / ref - 1))
        to_ray.extend(np.abs(value - ref) / ray)
        whole.extend([is_whole] * 3)
    return np.array(rel), np.array(to_ray), np.array(whole)


# --------------------------------------------------------------------------- the integrand itself


@pytest.mark.parametrize("kind", ["point", "directional"])
def test_integrand_exact_is_the_design_formula(kind):
    rng = np.random.default_rng(7)
    beta = rng.uniform(1e-3, PI - 1e-3, 200)
    gamma = rng.uniform(0, 1, 200) * ((PI - beta) if kind == "point" else 3.0)
    for phase_name, sigma_name in [("hg+0.3", "medium"), ("iso", "zero"), ("hg-0.5", "small")]:
        phase, sigma_t = PHASES[phase_name], SIGMA_T[sigma_name]
        got = integrand_exact(kind, SIGMA_S, sigma_t, phase, POWER, D_EL, beta, gamma)
        want = [[design_integrand(gm, kind, sigma_t, phase.g, b, c) for c in range(3)] for b, gm in zip(beta, gamma)]
        # Far out on the ray exp(-σt·d_el·ratio) reaches e^-200, where the 1e-16 rounding of
        # ratio is amplified ~200-fold (the module computes sin(β+γ) as sin(π-β-γ)).
        np.testing.assert_allclose(got, want, rtol=1e-10)
    # Off the ray: behind the eye (γ < 0), and for a point light γ ≥ π-β (the ray's point at infinity).
    assert np.all(integrand_exact(kind, SIGMA_S, SIGMA_T["zero"], Phase(), POWER, D_EL, 1.0, -0.1) == 0)
    if kind == "point":
        assert np.all(integrand_exact(kind, SIGMA_S, SIGMA_T["zero"], Phase(), POWER, D_EL, 1.0, PI - 0.5) == 0)


def phase_cos(light_dir_prop, x, eye):
    to_eye = (eye - x) / np.linalg.norm(eye - x)
    return float(light_dir_prop @ to_eye)


def test_point_light_change_of_variables_and_phase_sign():
    """∫ e^{-σt s}·σs·ρ(cosθ)·I·e^{-σt d}/d² ds along a concrete ray, θ from the actual vectors
    (light → x against x → eye), equals ∫ I(β, γ) dγ with cosθ = cos(β+γ); the opposite sign
    would be off by tens of percent, so the check has teeth."""
    eye, light = np.array([0.3, -0.2, 0.5]), np.array([2.0, 1.5, -0.7])
    d_el = float(np.linalg.norm(light - eye))
    axis = (light - eye) / d_el
    side = np.cross(axis, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    sigma_s, sigma_t, intensity, g = 0.3, 0.45, 5.0, 0.6
    phase = Phase("hg", g)
    for beta in (0.4, 2.2):
        view = math.cos(beta) * axis + math.sin(beta) * side
        s0, s1 = 0.7, 6.0

        def along_s(s):
            x = eye + s * view
            d = float(np.linalg.norm(x - light))
            cos_theta = phase_cos((x - light) / d, x, eye)
            return math.exp(-sigma_t * s) * sigma_s * hg(cos_theta, g) * intensity * math.exp(-sigma_t * d) / d**2

        want = quad(along_s, s0, s1, epsabs=0, epsrel=1e-12, limit=200)[0]
        # docs/design.md §2: γ of the point at distance s on ray β.
        gamma0, gamma1 = (math.atan2(s * math.sin(beta), d_el - s * math.cos(beta)) for s in (s0, s1))
        # ... and the s ↔ γ relations of the triangle, at the far end.
        x1 = eye + s1 * view
        assert math.isclose(s1, d_el * math.sin(gamma1) / math.sin(beta + gamma1), rel_tol=1e-12)
        assert math.isclose(np.linalg.norm(x1 - light), d_el * math.sin(beta) / math.sin(beta + gamma1),
                            rel_tol=1e-12)
        assert math.isclose(phase_cos((x1 - light) / np.linalg.norm(x1 - light), x1, eye), math.cos(beta + gamma1),
                            rel_tol=1e-12)

        def in_gamma(gm, sign):
            return (sigma_s * intensity * hg(sign * math.cos(beta + gm), g)
                    * math.exp(-sigma_t * d_el * (math.sin(beta) + math.sin(gm)) / math.sin(beta + gm))
                    / (d_el * math.sin(beta)))

        assert quad(in_gamma, gamma0, gamma1, args=(1,), epsrel=1e-12)[0] == pytest.approx(want, rel=1e-10)
        assert abs(quad(in_gamma, gamma0, gamma1, args=(-1,), epsrel=1e-12)[0] / want - 1) > 0.3
        got = quad(lambda gm: integrand_exact("point", sigma_s, sigma_t, phase, intensity, d_el, beta, gm)[0],
                   gamma0, gamma1, epsrel=1e-12)[0]
        assert got == pytest.approx(want, rel=1e-10)
        t = build_integrand("table", "point", sigma_s, sigma_t, phase, intensity, d_el, 0.0, PI, PI)
        np.testing.assert_allclose(segment_radiance(t, beta, gamma0, gamma1), want, rtol=1e-4)


def test_directional_light_change_of_variables_and_phase_sign():
    """Same for a directional light: ω points towards the light (ω = -direction of travel),
    β = angle(view, ω), γ = s·sinβ is the distance from the eye's light line, cosθ = cosβ."""
    travel = np.array([-1.0, -2.0, 0.5])
    travel /= np.linalg.norm(travel)
    omega = -travel
    side = np.cross(omega, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    eye = np.array([0.1, 0.2, 0.3])
    sigma_s, sigma_t, irradiance, g = 0.3, 0.45, 2.0, 0.6
    t = build_integrand("analytic", "directional", sigma_s, sigma_t, Phase("hg", g), irradiance, 0.0, 0.0, PI, 10.0)
    for beta in (0.3, 2.5):
        view = math.cos(beta) * omega + math.sin(beta) * side
        s0, s1 = 0.7, 6.0
        cos_theta = phase_cos(travel, eye + view, eye)
        want = quad(lambda s: math.exp(-sigma_t * s) * sigma_s * hg(cos_theta, g) * irradiance, s0, s1,
                    epsrel=1e-12)[0]
        gammas = []
        for s in (s0, s1):
            p = s * view
            gammas.append(float(np.linalg.norm(p - (p @ omega) * omega)))  # distance from the light line
        assert gammas[1] == pytest.approx(s1 * math.sin(beta), rel=1e-12)
        assert cos_theta == pytest.approx(math.cos(beta), rel=1e-12)
        got = quad(lambda gm: integrand_exact("directional", sigma_s, sigma_t, Phase("hg", g), irradiance, 0.0,
                                              beta, gm)[0], *gammas, epsrel=1e-12)[0]
        assert got == pytest.approx(want, rel=1e-10)
        np.testing.assert_allclose(segment_radiance(t, beta, *gammas), want, rtol=1e-12)
        # The other sign of cosθ is far off.
        wrong = quad(lambda s: math.exp(-sigma_t * s) * sigma_s * hg(-cos_theta, g) * irradiance, s0, s1)[0]
        assert abs(wrong / want - 1) > 0.3


# --------------------------------------------------------------------------- modes against quadrature


@pytest.mark.parametrize("sigma_name,phase_name", CASES)
def test_table_point_light(sigma_name, phase_name):
    rel, _, _ = errors(tables("table", "point", sigma_name, phase_name), "point", sigma_name, phase_name)
    assert rel.max() <= 3e-4  # the brief asks 1e-3; measured ≤ 9.4e-5 on this grid (docs/integrand.md)


# Rank-4 SVD, measured on this grid: (max relative error of whole rays, max error of any
# segment relative to its whole ray). Asserted with a factor 2 of margin.
SVD_RANK_4_MEASURED = {
    ("zero", "iso"): (1e-12, 1e-12), ("zero", "hg+0.3"): (1.4e-5, 1.1e-4), ("zero", "hg-0.5"): (2.3e-5, 2.1e-3),
    ("small", "iso"): (9.1e-4, 9.1e-4), ("small", "hg+0.3"): (3.8e-4, 6.4e-4), ("small", "hg-0.5"): (5.0e-3, 6.0e-3),
    ("medium", "iso"): (5.3e-4, 6.0e-3), ("medium", "hg+0.3"): (1.0e-3, 2.4e-3), ("medium", "hg-0.5"): (1.3e-2, 6.3e-2),
}


@pytest.mark.parametrize("sigma_name,phase_name", CASES)
def test_svd_point_light_rank_4(sigma_name, phase_name):
    """The paper's rank-4 SVD. Its error is an absolute one (the SVD minimises L2 over the
    (β, x) samples), so a sub-interval is judged against its whole ray: relative to the
    sub-interval alone it reaches 0.28 in the attenuated far tails (docs/integrand.md)."""
    rel, to_ray, whole = errors(tables("svd", "point", sigma_name, phase_name), "point", sigma_name, phase_name)
    whole_measured, to_ray_measured = SVD_RANK_4_MEASURED[sigma_name, phase_name]
    assert rel[whole].max() <= 2 * whole_measured
    assert to_ray.max() <= 2 * to_ray_measured


@pytest.mark.parametrize("sigma_name,phase_name", [("small", "iso"), ("medium", "hg+0.3"), ("medium", "hg-0.5"),
                                                   ("zero", "hg-0.5")])
def test_svd_error_falls_with_rank(sigma_name, phase_name):
    mean_error = [errors(tables("svd", "point", sigma_name, phase_name, rank=r), "point", sigma_name,
                         phase_name)[1].mean() for r in (1, 4, 8)]
    # Mean error relative to the whole ray; measured ratios rank1/rank4 ≥ 16, rank4/rank8 ≥ 4.6.
    assert mean_error[0] > 3 * mean_error[1]
    assert mean_error[1] > 3 * mean_error[2]


@pytest.mark.parametrize("sigma_name", ["zero", "small", "medium"])
def test_analytic_point_light_sigma_t_zero(sigma_name):
    if sigma_name != "zero":
        with pytest.raises(ValueError, match="no closed form"):
            tables("analytic", "point", sigma_name, "iso")
        return
    rel, _, _ = errors(tables("analytic", "point", "zero", "iso"), "point", "zero", "iso")
    assert rel.max() <= 1e-9


@pytest.mark.parametrize("sigma_name,phase_name", CASES)
def test_directional_light_all_modes(sigma_name, phase_name):
    """analytic is exact; table and svd run in distance s, where the directional integrand is
    separable, so even rank 1 is as good as the table."""
    analytic, _, _ = errors(tables("analytic", "directional", sigma_name, phase_name), "directional", sigma_name,
                            phase_name)
    assert analytic.max() <= 1e-9
    table, _, _ = errors(tables("table", "directional", sigma_name, phase_name), "directional", sigma_name,
                         phase_name)
    assert table.max() <= 3e-4  # measured ≤ 1.2e-4
    svd, _, _ = errors(tables("svd", "directional", sigma_name, phase_name, rank=1), "directional", sigma_name,
                       phase_name)
    assert svd.max() <= 3e-4


def test_directional_analytic_sigma_t_to_zero_is_continuous():
    a0 = build_integrand("analytic", "directional", SIGMA_S, 0.0, Phase("hg", 0.3), POWER, 0, 0, PI, 10)
    a1 = build_integrand("analytic", "directional", SIGMA_S, 1e-13, Phase("hg", 0.3), POWER, 0, 0, PI, 10)
    beta, g0, g1 = np.array([1e-3, 0.5, 3.0]), np.array([0.0, 0.1, 0.0]), np.array([1e-3, 2.0, 0.5])
    np.testing.assert_allclose(segment_radiance(a1, beta, g0, g1), segment_radiance(a0, beta, g0, g1), rtol=1e-9)


def test_hg_point_light_closed_form_needs_elliptic_integral():
    """∫ρ_HG(cos u)du = [E(φ|m) - m·sinφ·cosφ/sqrt(1 - m·sin²φ)] / (2π(1+g)), φ = u/2,
    m = -4g/(1-g)²: non-elementary, so analytic refuses it (the device has no E(φ|m))."""
    for g in (0.3, -0.5):
        m = -4 * g / (1 - g) ** 2

        def primitive(u):
            phi = u / 2
            return (ellipeinc(phi, m) - m * math.sin(phi) * math.cos(phi) / math.sqrt(1 - m * math.sin(phi) ** 2)) \
                / (2 * PI * (1 + g))

        for u0, u1 in ((0.1, 1.3), (0.5, 3.1), (0.0, PI)):
            want = quad(lambda u: hg(math.cos(u), g), u0, u1, epsrel=1e-13)[0]
            assert primitive(u1) - primitive(u0) == pytest.approx(want, rel=1e-12)
    with pytest.raises(ValueError, match="elliptic"):
        build_integrand("analytic", "point", SIGMA_S, 0.0, Phase("hg", 0.3), POWER, D_EL, 0, PI, PI)


# --------------------------------------------------------------------------- edges of the domain


@pytest.mark.parametrize("mode", ["table", "svd", "analytic"])
def test_gamma_is_clamped_onto_the_ray(mode):
    t = tables(mode, "point", "zero", "iso")
    for beta in (1e-3, 1.0, PI - 1e-2):
        whole = segment_radiance(t, beta, 0.0, PI - beta)
        np.testing.assert_allclose(segment_radiance(t, beta, -0.3, PI), whole, rtol=1e-14)
        np.testing.assert_allclose(segment_radiance(t, beta, PI - beta, PI + 1), 0.0, atol=1e-12 * whole.max())


@pytest.mark.parametrize("mode", ["table", "svd"])
def test_beta_limits_stay_finite_and_continuous(mode):
    t = tables(mode, "point", "medium", "hg-0.5")
    at_pi = segment_radiance(t, PI, 0.0, 0.1)  # γ range collapses: any γ1 > 0 is the whole ray
    near_pi = segment_radiance(t, PI - 1e-6, 0.0, 1e-6)
    assert np.all(np.isfinite(at_pi)) and np.all(at_pi > 0)
    np.testing.assert_allclose(at_pi, near_pi, rtol=1e-5)
    at_zero = segment_radiance(t, 0.0, 0.0, 1.0)
    assert np.all(np.isfinite(at_zero)) and np.all(at_zero > 0)


def test_table_on_a_beta_sub_range():
    t = build_integrand("table", "point", SIGMA_S, SIGMA_T["medium"], PHASES["hg+0.3"], POWER, D_EL, 0.5, 2.0, PI,
                        n_beta=64)
    for beta in (0.5, 0.9, 1.3, 2.0):
        for a, b in POINT_SPANS:
            g0, g1 = a * (PI - beta), b * (PI - beta)
            want = reference("point", SIGMA_T["medium"], 0.3, beta, g0, g1)
            np.testing.assert_allclose(segment_radiance(t, beta, g0, g1), want, rtol=1e-3)


def test_float32_tables_keep_the_error():
    t = tables("table", "point", "medium", "hg-0.5").float32()
    assert t.prefix.dtype == np.float32 and t.constants.dtype == np.float32
    rel, _, _ = errors(t, "point", "medium", "hg-0.5")
    assert rel.max() <= 1e-3


# --------------------------------------------------------------------------- API and layout


def test_layout_and_shapes():
    t = build_integrand("table", "spot", SIGMA_S, SIGMA_T["small"], Phase("hg", 0.3), POWER, D_EL, 0.1, 3.0, 2.0,
                        n_beta=32, n_gamma=64)
    assert (t.mode, t.light_kind, t.n_beta, t.n_gamma, t.rank) == ("table", "point", 32, 64, 0)
    assert t.prefix.shape == (3, 32, 64) and t.prefix.flags.c_contiguous and t.basis_beta is None
    assert t.constants.shape == (3, N_CONSTANTS)
    np.testing.assert_allclose(t.constants[:, C_AMPLITUDE], np.multiply(SIGMA_S, POWER))
    np.testing.assert_allclose(t.constants[:, C_SIGMA_T], SIGMA_T["small"])
    assert np.all(t.constants[:, C_D_EL] == D_EL) and np.all(t.constants[:, C_G] == 0.3)
    assert np.all(t.prefix[:, :, 0] == 0) and np.all(np.diff(t.prefix, axis=-1) >= 0)

    s = build_integrand("svd", "point", SIGMA_S, SIGMA_T["small"], Phase(), POWER, D_EL, 0, PI, PI, n_beta=32,
                        n_gamma=64, rank=3)
    assert s.basis_beta.shape == (3, 3, 32) and s.prefix_gamma.shape == (3, 3, 64) and s.prefix is None

    d = build_integrand("table", "directional", SIGMA_S, SIGMA_T["medium"], Phase(), POWER, 0, 0, PI, 5.0)
    np.testing.assert_allclose(d.constants[:, C_S_END], 20.0 / 0.2)  # no s_max: optical depth 20 of the thinnest
    a = build_integrand("analytic", "directional", SIGMA_S, 0.0, Phase(), POWER, 0, 0, PI, 5.0)
    assert a.prefix is None and a.basis_beta is None and (a.n_beta, a.n_gamma, a.rank) == (0, 0, 0)

    beta = np.linspace(0.1, 3.0, 12).reshape(3, 4)
    assert segment_radiance(t, beta, 0.0, 0.5).shape == (3, 4, 3)
    assert segment_radiance(a, 1.0, 0.0, 0.5).shape == (3,)


@pytest.mark.parametrize("kwargs,match", [
    (dict(mode="fast"), "mode: expected one of table, svd, analytic"),
    (dict(light_kind="area"), "light kind"),
    (dict(d_el=0.0), "d_el: expected a finite distance > 0"),
    (dict(beta_min=1.0, beta_max=0.5), "beta range"),
    (dict(gamma_max=0.0), "gamma_max"),
    (dict(sigma_t=(0.1, -1, 0)), "sigma_t: expected finite values >= 0"),
    (dict(sigma_s=(1, 2)), "sigma_s: expected a scalar or 3 values"),
    (dict(phase=Phase("hg", 1.0)), r"phase.g: expected \(-1, 1\)"),
    (dict(mode="svd", rank=65), "rank: expected 1..64"),
    (dict(n_gamma=1), "n_gamma >= 2"),
    (dict(light_kind="directional", sigma_t=(0, 0.1, 0.1)), "needs s_max"),
    (dict(mode="analytic", sigma_t=0.1), "no closed form"),
])
def test_bad_input_is_one_clear_line(kwargs, match):
    args = dict(mode="table", light_kind="point", sigma_s=SIGMA_S, sigma_t=0.0, phase=Phase(), power=POWER,
                d_el=D_EL, beta_min=0.0, beta_max=PI, gamma_max=PI)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match) as info:
        build_integrand(**args)
    assert str(info.value).startswith("integrand: ") and "\n" not in str(info.value)
