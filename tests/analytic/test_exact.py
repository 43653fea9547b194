"""The `exact` reference renderer against independent references.

The references here share nothing with clrays.reference.exact / clrays.physics.radiometry except the pixel
rays (`camera.primary_rays`, the one definition of pixel rays): they integrate the
model of docs/design.md §1 in the ray parameter s with scipy's adaptive `quad`, evaluate the
light, phase function and visibility with their own code, and find the discontinuities
of the integrand (cone crossings, shadow boundaries) by sign changes on a dense grid
refined by bisection, then pass them to `quad` as breakpoints.

Tolerances: `quad` runs at epsrel 1e-11, the renderer at its default relative tol 1e-10,
and breakpoints found by bisection are within 1e-13 of the true boundary (moving one
changes an integral by < 1e-13 × max integrand). Agreement is therefore expected near
1e-11 (observed: ≤ 1e-13 unoccluded, ≤ 2e-11 with cone edges); the tests assert 1e-9,
100× above the worst pixel (those near the light, where both integrands peak like 1/d²).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from clrays.physics import geometry
from clrays.scene.camera import primary_rays
from clrays.reference.exact import render_exact
from clrays.physics.geometry import lit_intervals, raycast
from clrays.physics.radiometry import cone_interval, in_scatter_segments, phase
from clrays.scene.model import (Camera, DirectionalLight, Geometry, Image, Medium, Phase, PointLight, Render, Scene,
                          SpotLight)

SIGMA_S = (0.05, 0.12, 0.2)
SIGMA_A = (0.01, 0.0, 0.06)


def v3(*xs) -> np.ndarray:
    return np.array(xs, dtype=np.float64)


def unit(*xs) -> np.ndarray:
    v = v3(*xs)
    return v / np.linalg.norm(v)


def scene_of(lights, triangles=None, albedo=0.8, width=24, height=16, spp=1, position=(0, 2, 8),
             look_at=(0, 2.5, 0), fov_deg=60.0, far=30.0, sigma_s=SIGMA_S, sigma_a=SIGMA_A, phase=None,
             background=(0.2, 0.3, 0.4)) -> Scene:
    """A Scene built directly (no YAML loader)."""
    tri = np.zeros((0, 3, 3)) if triangles is None else np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    return Scene(
        image=Image(width, height, spp),
        camera=Camera(v3(*position), v3(*look_at), v3(0, 1, 0), fov_deg, far),
        lights=tuple(lights),
        medium=Medium(np.broadcast_to(v3(*np.atleast_1d(sigma_s)), (3,)).copy(),
                      np.broadcast_to(v3(*np.atleast_1d(sigma_a)), (3,)).copy(), phase or Phase()),
        background=np.broadcast_to(v3(*np.atleast_1d(background)), (3,)).copy(),
        geometry=Geometry(tri, np.full((len(tri), 3), albedo), np.zeros(len(tri), np.int32)),
        render=Render(method="exact"),
    )


def box(lo, hi) -> np.ndarray:
    """12 triangles of an axis-aligned box."""
    lo, hi = v3(*lo), v3(*hi)
    c = np.array([[(hi if i >> k & 1 else lo)[k] for k in range(3)] for i in range(8)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return np.array([[c[a], c[b], c[d]] for a, b, cc, d in quads for b, d in ((b, cc), (cc, d))])


def slab(o, d, lo, hi):
    """Analytic ray-box intersection: (t_enter, t_exit) for rays o + t·d (vectorised)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - o) / d, (hi - o) / d
    return np.max(np.minimum(t1, t2), axis=-1), np.min(np.maximum(t1, t2), axis=-1)


def rays(scene) -> np.ndarray:
    return primary_rays(scene.camera, scene.image)[:, :, 0, :]


# ---- independent reference ------------------------------------------------------------

def ref_phase(c, ph: Phase):
    if ph.type == "isotropic":
        return 1 / (4 * math.pi)
    g = ph.g
    return (1 - g * g) / (4 * math.pi * (1 + g * g - 2 * g * c) ** 1.5)


def ref_integrand(scene, light, v, ch):
    """s ↦ e^{-σt s}·σs·ρ(cosθ)·Lin(x_s) for channel ch, written from docs/design.md §1 (V = 1)."""
    m = scene.medium
    ss, st = m.sigma_s[ch], m.sigma_s[ch] + m.sigma_a[ch]
    e = scene.camera.position
    if isinstance(light, DirectionalLight):
        c = float(np.dot(light.direction, -v))
        k = ss * light.irradiance[ch] * ref_phase(c, m.phase)
        return lambda s: k * math.exp(-st * s)

    def f(s):
        w = e + s * v - light.position
        d = math.sqrt(float(w @ w))
        return math.exp(-st * s) * ss * ref_phase(float(-(w @ v)) / d, m.phase) * light.intensity[ch] \
            * math.exp(-st * d) / (d * d)
    return f


def ref_quad(f, a, b, breaks=()):
    pts = [p for p in breaks if a < p < b]
    return quad(f, a, b, points=pts or None, epsabs=0.0, epsrel=1e-11, limit=400)[0]


def sign_changes(pred, a, b, n=4001):
    """Where the boolean pred(s) flips on [a, b]: grid of n points, then bisection to 1e-13."""
    s = np.linspace(a, b, n)
    p = pred(s)
    out = []
    for i in np.flatnonzero(p[1:] != p[:-1]):
        lo, hi = s[i], s[i + 1]
        while hi - lo > 1e-13 * max(1.0, abs(hi)):
            mid = 0.5 * (lo + hi)
            if pred(np.array([mid]))[0] == p[i]:
                lo = mid
            else:
                hi = mid
        out.append(0.5 * (lo + hi))
    return [a, *out, b], p


def segments_triangle(x, y, tri):
    """Segments x_k → y (y (3,) or (N, 3)) against one triangle: plane crossing, then
    barycentric sign tests at the crossing point (vectorised over k)."""
    p0, p1, p2 = tri
    n = np.cross(p1 - p0, p2 - p0)
    y = np.broadcast_to(y, x.shape)
    dx, dy = (x - p0) @ n, (y - p0) @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = dx / (dx - dy)
    z = x + t[:, None] * (y - x)
    inside = (dx * dy) < 0
    for a, b in ((p0, p1), (p1, p2), (p2, p0)):
        inside &= np.cross(b - a, z - a) @ n >= 0
    return inside


# ---- 1. unoccluded lights against quad -------------------------------------------------

@pytest.mark.parametrize("ph", [Phase(), Phase("hg", 0.3), Phase("hg", -0.5)], ids=["iso", "hg+0.3", "hg-0.5"])
def test_point_light_unoccluded_matches_quad(ph):
    light = PointLight(v3(0.13, 3.07, -0.4), v3(20.0, 30.0, 10.0))
    scene = scene_of([light], phase=ph)
    img = render_exact(scene)
    dirs = rays(scene)
    far = scene.camera.far
    ref = np.empty_like(img)
    for i, j in np.ndindex(img.shape[:2]):
        v = dirs[i, j]
        s0 = float((light.position - scene.camera.position) @ v)
        for ch in range(3):
            ref[i, j, ch] = ref_quad(ref_integrand(scene, light, v, ch), 0.0, far, [s0]) \
                + scene.background[ch] * math.exp(-(SIGMA_S[ch] + SIGMA_A[ch]) * far)
    np.testing.assert_allclose(img, ref, rtol=1e-9, atol=0)
    assert img.max() > 20 * np.median(img)  # the light is in view: the peak was exercised


def test_spot_light_unoccluded_matches_quad():
    light = SpotLight(v3(0.2, 4.5, -1.0), unit(0.3, -1.0, 0.25), 22.0, v3(40.0, 25.0, 30.0))
    scene = scene_of([light], phase=Phase("hg", 0.4), background=0.0)
    img = render_exact(scene)
    dirs = rays(scene)
    e, far = scene.camera.position, scene.camera.far
    cos_cone = math.cos(math.radians(light.cone_deg))
    ref = np.zeros_like(img)
    edge_pixels = 0
    for i, j in np.ndindex(img.shape[:2]):
        v = dirs[i, j]

        def inside(s):
            w = e + s[:, None] * v - light.position
            return w @ light.direction >= cos_cone * np.linalg.norm(w, axis=1)
        cuts, state = sign_changes(inside, 0.0, far)
        edge_pixels += len(cuts) > 2
        s0 = float((light.position - e) @ v)
        # pieces alternate between inside and outside, starting with state[0]
        for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
            if state[0] != (k % 2 == 1):
                for ch in range(3):
                    ref[i, j, ch] += ref_quad(ref_integrand(scene, light, v, ch), a, b, [s0])
    assert edge_pixels > 50 and np.count_nonzero(ref[..., 0] == 0) > 10
    np.testing.assert_allclose(img, ref, rtol=1e-9, atol=1e-13)


def test_directional_light_matches_quad():
    light = DirectionalLight(unit(0.4, -1.0, 0.3), v3(2.0, 3.0, 1.5))
    scene = scene_of([light], phase=Phase("hg", 0.7))
    img = render_exact(scene)
    dirs = rays(scene)
    far = scene.camera.far
    for i, j in [(0, 0), (5, 7), (15, 23), (8, 12)]:
        for ch in range(3):
            ref = ref_quad(ref_integrand(scene, light, dirs[i, j], ch), 0.0, far) \
                + scene.background[ch] * math.exp(-(SIGMA_S[ch] + SIGMA_A[ch]) * far)
            assert img[i, j, ch] == pytest.approx(ref, rel=1e-10)


def test_directional_closed_form_thin_medium_limit():
    """σt → 0: (e^{-σt a} - e^{-σt b})/σt → b - a without cancellation."""
    light = DirectionalLight(unit(0, -1, 0), v3(1.0, 1.0, 1.0))
    medium = Medium(v3(1e-30, 1e-18, 1e-9), v3(0, 0, 0), Phase())
    v = unit(1, 0, 0)[None]
    got = in_scatter_segments(light, medium, v3(0, 0, 0), v, 2.0, 7.0)[0]
    # ∫_2^7 e^{-σt s} ds = 5·(1 - σt·(2 + 7)/2 + O(σt²)), the O(σt²) term below 1e-17 relative
    expected = medium.sigma_s / (4 * math.pi) * 5.0 * (1 - medium.sigma_s * 4.5)
    np.testing.assert_allclose(got, expected, rtol=1e-14)


# ---- 2. one occluding triangle ---------------------------------------------------------

def test_occluding_triangle_matches_quad_with_visibility():
    light = PointLight(v3(0.1, 4.0, -0.2), v3(30.0, 30.0, 30.0))
    tri = np.array([[[-1.2, 3.0, -0.9], [1.1, 3.1, -1.0], [0.2, 2.9, 1.3]]])
    scene = scene_of([light], triangles=tri, phase=Phase("hg", 0.3), look_at=(0, 1.5, 0), fov_deg=70.0)
    img = render_exact(scene)
    free = render_exact(scene_of([light], phase=Phase("hg", 0.3), look_at=(0, 1.5, 0), fov_deg=70.0))
    dirs = rays(scene)
    e, far = scene.camera.position, scene.camera.far
    ref = np.zeros_like(img)
    shadowed = np.zeros(img.shape[:2], bool)
    for i, j in np.ndindex(img.shape[:2]):
        v = dirs[i, j]
        # the camera ray against the triangle (its underside faces away from the light: L_surf = 0)
        hit = segments_triangle(e[None], e + 2 * far * v, tri[0])[0]
        if hit:
            n = np.cross(tri[0, 1] - tri[0, 0], tri[0, 2] - tri[0, 0])
            D = float((tri[0, 0] - e) @ n / (v @ n))
        else:
            D = far
            ref[i, j] = scene.background * np.exp(-(scene.medium.sigma_t) * far)

        def lit(s):
            return ~segments_triangle(e + s[:, None] * v, light.position, tri[0])
        cuts, state = sign_changes(lit, 0.0, D)
        shadowed[i, j] = len(cuts) > 2 or not state[0]
        s0 = float((light.position - e) @ v)
        for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
            if state[0] != (k % 2 == 1):
                for ch in range(3):
                    ref[i, j, ch] += ref_quad(ref_integrand(scene, light, v, ch), a, b, [s0])
    assert shadowed.sum() > 40
    assert np.all(img[shadowed] < free[shadowed])
    np.testing.assert_allclose(img, ref, rtol=1e-9, atol=0)


# ---- 3. surface term -------------------------------------------------------------------

def test_surface_term_with_box_shadow_closed_form():
    light = PointLight(v3(2.0, 5.0, -2.0), v3(40.0, 50.0, 60.0))
    lo, hi = v3(-0.8, 1.0, -0.6), v3(0.6, 2.0, 0.7)
    floor = np.array([[[-10, 0, -10], [10, 0, 10], [10, 0, -10]], [[-10, 0, -10], [-10, 0, 10], [10, 0, 10]]], float)
    tris = np.concatenate([floor, box(lo, hi)])
    sigma_a = (0.02, 0.05, 0.1)
    scene = scene_of([light], triangles=tris, albedo=0.7, position=(1, 5, 9), look_at=(0, 0, 0), width=64,
                     height=48, sigma_s=0.0, sigma_a=sigma_a)
    img = render_exact(scene)
    dirs = rays(scene).reshape(-1, 3)
    e = scene.camera.position
    sigma_t = v3(*sigma_a)
    t_floor = -e[1] / dirs[:, 1]
    x = e + t_floor[:, None] * dirs
    on_floor = (t_floor > 0) & np.all(np.abs(x[:, [0, 2]]) < 10 - 1e-6, axis=1)
    margin = 1e-6
    # camera ray clearly misses the box (with a margin, so edge pixels are skipped)
    te, tx = slab(e, dirs, lo - margin, hi + margin)
    visible = on_floor & ~((te <= tx) & (tx > 0) & (te < t_floor))
    # light segment from the floor point: clearly blocked or clearly free
    seg = light.position - x
    te_in, tx_in = slab(x, seg, lo + margin, hi - margin)
    te_out, tx_out = slab(x, seg, lo - margin, hi + margin)
    blocked = (te_in <= tx_in) & (tx_in > 0) & (te_in < 1)
    free = ~((te_out <= tx_out) & (tx_out > 0) & (te_out < 1))
    d = np.linalg.norm(seg, axis=1)
    cos = seg[:, 1] / d
    closed = 0.7 / math.pi * light.intensity * np.exp(-sigma_t * d[:, None]) * (cos / d**2)[:, None] \
        * np.exp(-sigma_t * t_floor[:, None])
    got = img.reshape(-1, 3)
    in_shadow, in_light = visible & blocked, visible & free
    assert in_shadow.sum() > 50 and in_light.sum() > 1000
    assert np.all(got[in_shadow] == 0.0)
    np.testing.assert_allclose(got[in_light], closed[in_light], rtol=1e-12)
    miss = ~on_floor & (slab(e, dirs, lo, hi)[0] > slab(e, dirs, lo, hi)[1])
    np.testing.assert_allclose(got[miss], np.broadcast_to(scene.background * np.exp(-sigma_t * 30.0), got[miss].shape))


# ---- 4. raycast ------------------------------------------------------------------------

def test_raycast_matches_slab(monkeypatch):
    rng = np.random.default_rng(7)
    lo, hi = v3(-1.0, 0.5, -2.0), v3(2.0, 1.5, -1.0)
    tris = box(lo, hi)
    o = rng.uniform(-4, 4, (3000, 3))
    o[:500] = rng.uniform(lo, hi, (500, 3))  # some start inside the box
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    te, tx = slab(o, d, lo, hi)
    hit = (te <= tx) & (tx > 0)
    expected = np.where(hit, np.where(te > 0, te, tx), np.inf)
    # a ray through an edge or corner may go either way: skip the few that come near one
    clear = ~hit | (np.abs(tx - te) > 1e-7)
    t, idx = raycast(o, d, tris)
    np.testing.assert_array_equal(idx[clear] >= 0, hit[clear])
    np.testing.assert_allclose(t[clear & hit], expected[clear & hit], rtol=1e-12, atol=1e-12)
    assert np.all(np.isinf(t[idx < 0]))
    # the hit lies on the triangle that was reported
    x = o[hit] + t[hit, None] * d[hit]
    n = np.cross(tris[idx[hit], 1] - tris[idx[hit], 0], tris[idx[hit], 2] - tris[idx[hit], 0])
    assert np.max(np.abs(np.einsum("ij,ij->i", x - tris[idx[hit], 0], n / np.linalg.norm(n, axis=1)[:, None]))) < 1e-12
    # t_max cuts hits off; tiny chunks give the same answer as one big one
    t_cut, idx_cut = raycast(o, d, tris, t_max=2.0)
    np.testing.assert_array_equal(idx_cut >= 0, (idx >= 0) & (t < 2.0))
    monkeypatch.setattr(geometry, "BUDGET_BYTES", geometry._RAYCAST_PAIR_BYTES * 5)
    t_small, idx_small = raycast(o, d, tris)
    np.testing.assert_array_equal(t_small, t)
    np.testing.assert_array_equal(idx_small, idx)


# ---- 5. quadrature convergence ---------------------------------------------------------

@pytest.mark.parametrize("light", [PointLight(v3(0.0, 2.2, 0.5), v3(20.0, 30.0, 40.0)),
                                   SpotLight(v3(0.0, 3.2, 0.0), unit(0.2, -1.0, 0.3), 30.0, v3(20.0, 30.0, 40.0))],
                         ids=["point", "spot"])
def test_quadrature_converges_under_doubling(light):
    """Whole images with a fixed composite Gauss–Legendre rule (no adaptivity): 8 and 16
    panels agree to 1e-9 in a dense, strongly forward-scattering medium with an occluder
    and the light in view, and the adaptive default agrees with both."""
    tri = np.array([[[-0.8, 1.8, -0.5], [0.9, 1.9, -0.4], [0.1, 1.7, 1.2]]])
    scene = scene_of([light], triangles=tri, phase=Phase("hg", 0.8), sigma_s=(0.3, 0.6, 0.1),
                     sigma_a=(0.2, 0.0, 0.4), look_at=(0, 2.2, 0))
    coarse = render_exact(scene, panels=8, tol=None)
    fine = render_exact(scene, panels=16, tol=None)
    adaptive = render_exact(scene)
    np.testing.assert_allclose(coarse, fine, rtol=1e-9, atol=0)
    np.testing.assert_allclose(adaptive, fine, rtol=1e-10, atol=0)


def _max_rel(x, ref):
    """Largest relative difference over the entries where ref ≠ 0 (deep-medium values underflow)."""
    nz = ref != 0
    return float(np.max(np.abs(x[nz] / ref[nz] - 1)))


def _hard_segments(n, rng):
    """Segments of rays from [-10, 10]³, half of them aimed within 1e-8..1 of the light at the origin."""
    o = rng.uniform(-10, 10, (n, 3))
    d = rng.normal(size=(n, 3))
    near = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-8, 0, (n, 1)) - o
    d[: n // 2] = near[: n // 2]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    a = rng.uniform(0, 5, n)
    return o, d, a, a + rng.uniform(0, 30, n)


def test_segment_quadrature_doubling_and_adaptivity():
    """Straight at `in_scatter_segments`: (1) in a medium up to σt = 1 with HG g = 0.99 and
    rays passing 1e-8 from the light, 8 → 16 panels moves nothing by 1e-9 (while 2 panels
    is visibly off, so the check has teeth); (2) in a thick medium (up to 35 optical depths
    per unit length) a fixed 8-panel rule is not enough, and the adaptive default matches
    a 512-panel rule to 1e-10."""
    light = PointLight(v3(0, 0, 0), v3(1.0, 2.0, 3.0))
    o, d, a, b = _hard_segments(300, np.random.default_rng(1))
    mild = Medium(v3(0.5, 0.05, 0.3), v3(0.5, 0.0, 0.1), Phase("hg", 0.99))
    p2, p8, p16 = (in_scatter_segments(light, mild, o, d, a, b, panels=p, tol=None) for p in (2, 8, 16))
    np.testing.assert_allclose(p8, p16, rtol=1e-9, atol=0)
    assert _max_rel(p2, p16) > 1e-6
    thick = Medium(v3(5.0, 1.0, 5.0), v3(5.0, 0.0, 30.0), Phase("hg", 0.9))
    ref = in_scatter_segments(light, thick, o, d, a, b, panels=512, tol=None)
    fixed = in_scatter_segments(light, thick, o, d, a, b, panels=8, tol=None)
    adaptive = in_scatter_segments(light, thick, o, d, a, b)
    assert _max_rel(fixed, ref) > 1e-7
    np.testing.assert_allclose(adaptive, ref, rtol=1e-10, atol=1e-300)  # atol: subnormals


# ---- visibility, cone and image plumbing ------------------------------------------------

@pytest.mark.parametrize("light", [PointLight(v3(0.3, 5.0, 0.2), v3(1.0, 1.0, 1.0)),
                                   DirectionalLight(unit(0.3, -1.0, -0.2), v3(1.0, 1.0, 1.0))],
                         ids=["point", "directional"])
def test_lit_intervals_match_sampled_visibility(light):
    """Union of overlapping shadow volumes (two boxes: 24 triangles, shared edges) against a
    direct segment-triangle test at many points along random rays."""
    rng = np.random.default_rng(3)
    tris = np.concatenate([box((-1, 1, -1), (1, 2, 1)), box((0.5, 2.5, 0.0), (1.5, 3.0, 0.8))])
    e = v3(0.2, 1.5, 6.0)
    d = unit(0, 0, -1) + rng.normal(scale=0.25, size=(200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    D = np.full(200, 12.0)
    ray, a, b = lit_intervals(e, d, D, light, tris)
    s = np.linspace(0, 12, 2401)[1:-1]
    mismatches = 0
    for r in range(200):
        x = e + s[:, None] * d[r]
        # a directional light is a point light far away along -direction
        target = x - 100.0 * light.direction if isinstance(light, DirectionalLight) else light.position
        shadow = np.zeros(len(s), bool)
        for t in tris:
            shadow |= segments_triangle(x, target, t)
        lit = np.zeros(len(s), bool)
        for lo_, hi_ in zip(a[ray == r], b[ray == r]):
            lit |= (s >= lo_) & (s <= hi_)
        # disagreement is allowed only within 1e-9 of an interval end (the grid can land on one)
        ends = np.concatenate([a[ray == r], b[ray == r], [np.inf]])
        near = np.min(np.abs(s[:, None] - ends[None, :]), axis=1) < 1e-9
        mismatches += np.count_nonzero((lit == shadow) & ~near)
    assert mismatches == 0
    assert len(ray) > 250  # the shadows really cut rays into several lit pieces


def test_cone_interval_matches_sampling():
    rng = np.random.default_rng(5)
    for cone in (10.0, 45.0, 89.0, 90.0):
        light = SpotLight(v3(0, 3, 0), unit(0.1, -1, 0.2), cone, v3(1, 1, 1))
        o = rng.uniform(-5, 5, (300, 3))
        d = rng.normal(size=(300, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        a, b = cone_interval(light, o, d, np.zeros(300), np.full(300, 10.0))
        s = np.linspace(0, 10, 1001)
        w = o[:, None, :] + s[None, :, None] * d[:, None, :] - light.position
        inside = w @ light.direction >= math.cos(math.radians(cone)) * np.linalg.norm(w, axis=2)
        mine = (s[None, :] >= a[:, None]) & (s[None, :] <= b[:, None])
        near = (np.abs(s[None, :] - a[:, None]) < 1e-9) | (np.abs(s[None, :] - b[:, None]) < 1e-9)
        assert not np.any((mine != inside) & ~near), cone


def test_ray_through_light_is_finite_and_converges():
    """A pixel centre aimed exactly at the light: h → 0 is clamped, the value stays finite;
    the pixel *average* (∝ ∫ dA/h, integrable) converges under supersampling."""
    light = PointLight(v3(0.0, 2.0, 0.0), v3(10.0, 10.0, 10.0))
    base = dict(width=9, height=9, look_at=(0, 2, 0), position=(0, 2, 8), fov_deg=20.0)
    one = render_exact(scene_of([light], **base))
    assert np.all(np.isfinite(one)) and one[4, 4, 0] > one[4, 3, 0]
    by_spp = [render_exact(scene_of([light], spp=n, **base), rows=slice(4, 5))[0, 4, 0] for n in (16, 64, 256)]
    assert abs(by_spp[2] - by_spp[1]) < 0.6 * abs(by_spp[1] - by_spp[0])


def test_rows_spp_and_lights_add_up():
    p = PointLight(v3(0.3, 3.0, -1.0), v3(5.0, 6.0, 7.0))
    s = SpotLight(v3(-0.5, 4.0, 0.0), unit(0, -1, 0.1), 30.0, v3(9.0, 8.0, 7.0))
    dl = DirectionalLight(unit(0.2, -1, 0.1), v3(0.5, 0.4, 0.3))
    tris = box((-0.5, 0.5, -0.5), (0.5, 1.5, 0.5))
    kw = dict(triangles=tris, width=12, height=8, spp=4)
    full = render_exact(scene_of([p, s, dl], **kw))
    parts = sum(render_exact(scene_of([x], **kw, background=0.0)) for x in (p, s, dl))
    bg_only = render_exact(scene_of([], **kw))
    np.testing.assert_allclose(full, parts + bg_only, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(render_exact(scene_of([p, s, dl], **kw), rows=slice(2, 5)), full[2:5])
    assert phase(np.array([1.0]), Phase("hg", 0.5))[0] == pytest.approx(0.75 / (4 * math.pi * 0.125))
