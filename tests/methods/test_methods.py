"""Layers 3 and 4 for the references: raymarch against an independent quadrature of
the unoccluded integral, and raymarch converging to exact on scenes with occluders."""
import numpy as np
import pytest

from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.scene.geometry import box_triangles
from conftest import unoccluded_point_quadrature, DirectionalLight, Phase, PointLight, SpotLight, grid_plane, make_scene, v3


@pytest.mark.parametrize("g", [0.0, 0.3, -0.5])
def test_raymarch_unoccluded_point_light_matches_quadrature(renderer, g):
    light = PointLight(v3(0.3, 2.2, 0.5), np.full(3, 20.0))
    scene = make_scene(lights=[light], width=24, height=16, far=12.0, sigma_s=0.08, sigma_a=0.02,
                       phase=Phase("hg", g) if g else Phase(), steps=8192)
    image = renderer.render(scene, "raymarch").image[..., 0]
    expected, keep = unoccluded_point_quadrature(scene)
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
    print(kind, " | ".join(str(e) for e in errors))
    means = [e.mean for e in errors]
    assert means[0] > means[1] > means[2], [str(e) for e in errors]
    assert errors[2].mean < 0.01 and errors[2].p99 < 0.05, str(errors[2])
