"""Layers 3 and 4 for the references: raymarch against an independent quadrature of
the unoccluded integral, and raymarch converging to exact on scenes with occluders."""
import math

import numpy as np
import pytest
from scipy.integrate import quad

from clrays.camera import primary_rays
from clrays.metrics import depth_edges, depth_map, image_error
from clrays.primitives import box_triangles
from conftest import DirectionalLight, Phase, PointLight, SpotLight, grid_plane, make_scene, v3


def _phase(c, g):
    return (1 - g * g) / (4 * math.pi * (1 + g * g - 2 * g * c) ** 1.5)


def _quadrature_pixel(eye, d, light_pos, intensity, sigma_s, sigma_t, g, far):
    """∫0^far e^{-σt s}·σs·ρ(cosθ)·I·e^{-σt r}/r² ds, written out independently of clrays."""
    def integrand(s):
        x = eye + s * d
        w = x - light_pos
        r = math.sqrt(w @ w)
        cos_theta = -(w / r) @ d  # light's propagation (w/r) against the way to the eye (-d)
        return math.exp(-sigma_t * s) * sigma_s * _phase(cos_theta, g) * intensity * math.exp(-sigma_t * r) / (r * r)

    closest = float(np.clip((light_pos - eye) @ d, 0, far))
    return quad(integrand, 0, far, points=[closest], limit=400, epsabs=0, epsrel=1e-10)[0]


@pytest.mark.parametrize("g", [0.0, 0.3, -0.5])
def test_raymarch_unoccluded_point_light_matches_quadrature(renderer, g):
    light = PointLight(v3(0.3, 2.2, 0.5), np.full(3, 20.0))
    scene = make_scene(lights=[light], width=24, height=16, far=12.0, sigma_s=0.08, sigma_a=0.02,
                       phase=Phase("hg", g) if g else Phase(), steps=8192)
    image = renderer.render(scene, "raymarch").image[..., 0]
    dirs = primary_rays(scene.camera, scene.image)[:, :, 0]
    expected = np.array([[_quadrature_pixel(scene.camera.position, dirs[y, x], light.position, 20.0, 0.08, 0.10, g,
                                             12.0) for x in range(24)] for y in range(16)])
    # The pixel holding the light: its integral is ~π/h with h → 0, left to the stability suite.
    to_light = light.position - scene.camera.position
    angles = np.degrees(np.arccos(np.clip(dirs @ (to_light / np.linalg.norm(to_light)), -1, 1)))
    keep = angles > 2.5  # a pixel here spans about 3.3°
    relative = np.abs(image - expected) / expected
    assert relative[keep].max() < 0.005, f"worst {relative[keep].max():.4%}"


def _occluder_scene(light, **render):
    triangles = np.concatenate([grid_plane(0.0, 7.0, 4), box_triangles([-1.2, 2.0, -1.0], [0.4, 2.3, 0.6]),
                                box_triangles([1.0, 0.0, -1.5], [1.8, 1.4, -0.7])])
    return make_scene(triangles, [light], width=48, height=32, far=25.0, sigma_s=0.08, sigma_a=0.02, **render)


LIGHTS = {
    "point": PointLight(v3(0.0, 4.5, -0.5), np.full(3, 40.0)),
    "spot": SpotLight(v3(0.5, 4.5, 0.0), v3(-0.1, -1.0, -0.05) / np.linalg.norm([-0.1, -1.0, -0.05]), 40.0,
                      np.full(3, 60.0)),
    "directional": DirectionalLight(v3(0.3, -1.0, -0.2) / np.linalg.norm([0.3, -1.0, -0.2]), np.full(3, 1.5)),
}


@pytest.mark.parametrize("kind", LIGHTS)
def test_raymarch_converges_to_exact(renderer, kind):
    scene = _occluder_scene(LIGHTS[kind])
    reference = renderer.render(scene, "exact").image
    edges = depth_edges(depth_map(scene))
    errors = []
    for steps, shadow_map in [(32, 64), (256, 256), (2048, 1024)]:
        coarse = _occluder_scene(LIGHTS[kind], steps=steps, shadow_map=shadow_map)
        errors.append(image_error(renderer.render(coarse, "raymarch").image, reference, edges))
    means = [e.mean for e in errors]
    assert means[0] > means[1] > means[2], [str(e) for e in errors]
    assert errors[2].mean < 0.01 and errors[2].p99 < 0.05, str(errors[2])
