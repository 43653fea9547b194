"""`camera.near` (docs/scene-format.md, camera): every camera ray starts at t0 = near / cos θ,
θ its angle to the view axis, as Cycles' Clip Start. The fog is gathered over [t0, D] and the
eye's transmittance measured from t0: `exact` against a float64 quadrature of its own, the
device methods against `exact`, near = 0 the same bits as a camera without it, the glTF
camera's `znear` read, bad values refused in one line."""
from __future__ import annotations

import importlib.util
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

from clrays.errors import ClraysError, SceneError
from clrays.reference.exact import exact_pixels
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.scene.camera import camera_basis, primary_rays
from clrays.scene.geometry import box_triangles
from clrays.scene.load import load_scene, parse_scene
from clrays.scene.model import Box, HeightDensity
from conftest import DirectionalLight, PointLight, SpotLight, grid_plane, make_scene, run_cli, v3

ROOT = Path(__file__).resolve().parents[2]


def _near(scene, near: float):
    return replace(scene, camera=replace(scene.camera, near=near))


# --------------------------------------------------------------------------- exact, by quadrature


def _fog_from(eye, d, start, end, light_pos, intensity, sigma_s, sigma_t) -> float:
    """∫_start^end e^{-σt·(s − start)}·σs·(1/4π)·I·e^{-σt·r}/r² ds (isotropic, unoccluded), by
    scipy: the in-scattering of a ray that begins at `start`, written out apart from clrays."""
    def integrand(s):
        r = float(np.linalg.norm(eye + s * d - light_pos))
        return math.exp(-sigma_t * (s - start)) * sigma_s / (4 * math.pi) * intensity * math.exp(-sigma_t * r) / r ** 2

    closest = float(np.clip((light_pos - eye) @ d, start, end))
    return quad(integrand, start, end, points=[closest], limit=400, epsabs=0, epsrel=1e-11)[0]


def test_exact_gathers_the_fog_from_each_rays_start():
    """A point light in empty fog, wide field of view: at the centre and in the corners
    (θ up to 41°, t0 = near / cos θ up to 2 m) `exact` is the quadrature from t0 with the
    transmittance measured from there, which is e^{σt·t0} times the eye's, less [0, t0]."""
    light = PointLight(v3(0.4, 2.5, 3.0), np.full(3, 30.0))
    scene = _near(make_scene(lights=[light], width=16, height=12, fov_deg=70.0, far=20.0, sigma_s=0.1,
                             sigma_a=0.05), 1.5)
    eye, medium = scene.camera.position, scene.medium
    ys, xs = np.array([0, 0, 6, 11, 11]), np.array([0, 15, 8, 0, 15])
    dirs = primary_rays(scene.camera, scene.image)[ys, xs, 0]
    starts = 1.5 / (dirs @ camera_basis(scene.camera)[2])
    assert starts.max() > 1.9  # the corners' rays start farther than near
    expected = [_fog_from(eye, d, t0, 20.0, light.position, 30.0, 0.1, 0.15) for d, t0 in zip(dirs, starts)]
    got = exact_pixels(scene, ys, xs)[:, 0]
    np.testing.assert_allclose(got, expected, rtol=1e-9)
    from_eye = [_fog_from(eye, d, 0.0, 20.0, light.position, 30.0, 0.1, 0.15) for d in dirs]
    assert np.abs(got / from_eye - 1.0).min() > 0.02  # near matters on every one of these rays
    # the same ray from the eye, the part before t0 taken off, times e^{σt·t0}
    before = [_fog_from(eye, d, 0.0, t0, light.position, 30.0, 0.1, 0.15) for d, t0 in zip(dirs, starts)]
    np.testing.assert_allclose(got, np.exp(0.15 * starts) * (np.array(from_eye) - before), rtol=1e-9)
    assert medium.sigma_t[0] == pytest.approx(0.15)


def test_exact_attenuates_a_surface_from_the_rays_start():
    """A wall 6 m ahead, no light on it but the fog's: its transmittance pass is
    e^{-σt·(D − t0)}, D the wall's distance along the ray."""
    wall = np.array([[[-20, -20, -4], [20, -20, -4], [20, 20, -4]], [[-20, -20, -4], [20, 20, -4], [-20, 20, -4]]])
    scene = _near(make_scene(wall, width=8, height=6, position=(0, 0, 2), look_at=(0, 0, 0), fov_deg=60.0,
                             sigma_s=0.1, sigma_a=0.1), 0.8)
    ys, xs = np.array([0, 3, 5]), np.array([0, 4, 7])
    parts = {}
    exact_pixels(scene, ys, xs, parts=parts)
    dirs = primary_rays(scene.camera, scene.image)[ys, xs, 0]
    cos_theta = -dirs[:, 2]
    depth, start = 6.0 / cos_theta, 0.8 / cos_theta
    np.testing.assert_allclose(parts["transmittance"][:, 0], np.exp(-0.2 * (depth - start)), rtol=1e-12)
    np.testing.assert_allclose(parts["depth"], depth, rtol=1e-12)


# --------------------------------------------------------------------------- the device methods


def _occluder_scene(light, near: float, **render):
    """tests/methods/test_methods.py's occluders, the camera nearer, near 1.2: t0 of 1.2 to
    1.5 m, e^{σt·t0} about 1.12, and the shadow of the near box crosses [0, t0]."""
    triangles = np.concatenate([grid_plane(0.0, 7.0, 4), box_triangles([-1.2, 2.0, -1.0], [0.4, 2.3, 0.6]),
                                box_triangles([1.0, 0.0, -1.5], [1.8, 1.4, -0.7])])
    return _near(make_scene(triangles, [light], width=48, height=32, position=(0, 2.2, 5), far=25.0,
                            sigma_s=0.08, sigma_a=0.02, **render), near)


LIGHTS = {
    "point": PointLight(v3(0.0, 4.5, -0.5), np.full(3, 40.0)),
    "spot": SpotLight(v3(0.5, 4.5, 0.0), v3(-0.1, -1.0, -0.05) / np.linalg.norm([-0.1, -1.0, -0.05]), 40.0,
                      np.full(3, 60.0)),
    "directional": DirectionalLight(v3(0.3, -1.0, -0.2) / np.linalg.norm([0.3, -1.0, -0.2]), np.full(3, 1.5)),
}

#: method → the bound on its relative RMSE against exact (depth edges out), and the settings.
#: raymarch: test_methods.py's bound at 2048 steps (mean 1 %); minmax at the measured sizes
#: as test_fine_occluders' 0.5 %.
METHODS = {"raymarch": (0.01, {"steps": 2048}), "minmax": (0.005, {}),
           "minmax_pixel": (0.005, {"sampling": "pixel"})}


@pytest.mark.parametrize("kind", LIGHTS)
@pytest.mark.parametrize("method", METHODS)
def test_the_device_methods_follow_exact_with_a_near_distance(renderer, kind, method):
    bound, settings = METHODS[method]
    scene = _occluder_scene(LIGHTS[kind], 1.2, **settings)
    exact = renderer.render(scene, "exact").image
    edges = depth_edges(depth_map(scene))
    error = image_error(renderer.render(scene, method.split("_")[0]).image, exact, edges)
    from_eye = image_error(renderer.render(_near(scene, 0.0), "exact").image, exact, edges)
    print(f"{kind} {method} near 1.2 against exact: {error}; exact without near: {from_eye}")
    assert error.rmse < bound, error
    assert from_eye.rmse > 5 * bound  # what near changes is well beyond the bound


#: A bounded height fog (docs/media.md) that the camera stands in: the near factor is then
#: 1 / T_e(t0) of that medium, not e^{σt·t0}.
BOUNDED_HEIGHT_FOG = dict(bounds=Box(v3(-4.0, 0.0, -4.0), v3(4.0, 5.0, 6.0)), density=HeightDensity(0.0, 1.5))


@pytest.mark.parametrize("kind", ["point", "directional"])
@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_a_near_distance_in_a_bounded_height_fog_follows_exact(renderer, kind, method):
    bound, settings = METHODS[method]
    scene = _occluder_scene(LIGHTS[kind], 1.2, **settings)
    scene = replace(scene, medium=replace(scene.medium, **BOUNDED_HEIGHT_FOG))
    exact = renderer.render(scene, "exact").image
    edges = depth_edges(depth_map(scene))
    error = image_error(renderer.render(scene, method).image, exact, edges)
    from_eye = image_error(renderer.render(_near(scene, 0.0), "exact").image, exact, edges)
    print(f"{kind} {method} near 1.2 in bounded height fog against exact: {error}; exact without near: {from_eye}")
    assert error.rmse < bound, error
    assert from_eye.rmse > 2 * bound  # what near changes is beyond the bound


def test_volume_moments_follows_raymarch_with_a_near_distance(renderer):
    """test_moments.py's single-step scene (one roof: one lit and one blocked run per ray),
    near 2: within its 3 % of raymarch, as without near."""
    from test_moments import single_step_scene

    scene = _near(single_step_scene("point"), 2.0)
    reference = renderer.render(scene, "raymarch").image
    error = image_error(renderer.render(scene, "volume_moments").image, reference)
    unclipped = image_error(renderer.render(_near(scene, 0.0), "raymarch").image, reference)
    print(f"volume_moments near 2 against raymarch: {error}; raymarch without near: {unclipped}")
    assert error.pixels > 500 and error.rmse < 0.03, error
    assert unclipped.rmse > 0.1


def test_the_passes_measure_from_each_rays_start(renderer):
    """`transmittance`, `in_scatter` and `in_scatter_light0` with near: minmax's against exact's
    parts, and the image their sum."""
    scene = replace(_occluder_scene(LIGHTS["point"], 1.2), render=replace(
        _occluder_scene(LIGHTS["point"], 1.2).render, aovs=("transmittance", "surface", "in_scatter",
                                                            "in_scatter_light0")))
    result = renderer.render(scene, "minmax")
    parts = {}
    from clrays.reference.exact import render_exact

    render_exact(scene, parts=parts)
    edges = depth_edges(depth_map(scene))
    assert image_error(result.passes["transmittance"], parts["transmittance"], edges).rmse < 1e-4
    assert image_error(result.passes["in_scatter"], parts["lights"][0], edges).rmse < 0.005
    np.testing.assert_allclose(result.passes["in_scatter_light0"], result.passes["in_scatter"], rtol=1e-5,
                               atol=1e-7)
    image = result.passes["surface"] * result.passes["transmittance"] + result.passes["in_scatter"]
    np.testing.assert_allclose(image, result.image, rtol=1e-4, atol=1e-6)


def test_per_light_passes_with_a_near_distance_in_a_bounded_fog_are_refused_in_one_line(renderer):
    """Their gain would be 1/T_e(t0) of the medium, which the host does not have: refused, not wrong."""
    scene = _occluder_scene(LIGHTS["point"], 1.2)
    scene = replace(scene, medium=replace(scene.medium, **BOUNDED_HEIGHT_FOG),
                    render=replace(scene.render, aovs=("in_scatter", "in_scatter_light0")))
    with pytest.raises(ClraysError, match=r"render\.aovs: the per-light in-scattering passes with camera\.near > 0 "
                                          r"need a homogeneous medium"):
        renderer.render(scene, "minmax")


@pytest.mark.parametrize("kind", ["gathered", "depth_peeling"])
@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_translucent_films_with_a_near_distance_follow_exact(renderer, method, kind):
    """scenes/glass_row.yaml (five films in the fog) at 64×36, near 1: the fog between the
    films and the light they reflect measured from each ray's start, in `exact`'s translucent
    path and in shade's composite alike. Within test_transparency.py's 1 % of exact, depth edges
    out (measured 0.010 % minmax, 0.007 % raymarch; 0.008 %, 0.007 % without near)."""
    overrides = ["image.width=64", "image.height=36", "camera.near=1", f"render.transparency={kind}"]
    scene = load_scene(ROOT / "scenes" / "glass_row.yaml", overrides=overrides)
    exact = renderer.render(scene, "exact").image
    edges = depth_edges(depth_map(scene))
    error = image_error(renderer.render(scene, method).image, exact, edges)
    assert error.rmse < 0.01, error
    assert image_error(renderer.render(_near(scene, 0.0), "exact").image, exact, edges).rmse > 0.05


# --------------------------------------------------------------------------- near = 0


DEMO = ROOT / "scenes" / "demo.yaml"
SMALL = ["image.width=48", "image.height=27"]


@pytest.mark.parametrize("method", ["minmax", "raymarch", "volume_moments"])
def test_near_0_is_the_camera_without_it(renderer, method):
    """near: 0 is the default: the same bits as the scene that does not name it (a near > 0
    changes them)."""
    without = load_scene(DEMO, SMALL + [f"render.method={method}", "render.steps=64"])
    assert without.camera.near == 0.0
    image = renderer.render(without, method).image
    assert np.array_equal(renderer.render(load_scene(DEMO, SMALL + ["camera.near=0", "render.steps=64"]),
                                          method).image, image)
    assert not np.array_equal(renderer.render(_near(without, 0.5), method).image, image)


# --------------------------------------------------------------------------- glTF and bad values


def _gltf_tool():
    spec = importlib.util.spec_from_file_location("make_gltf_example", ROOT / "tools" / "make_gltf_example.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    return tool


def _camera_file(tmp_path, znear) -> Path:
    tool = _gltf_tool()
    builder = tool.GltfBuilder()
    builder.node(extensions=tool.light_ref(builder.light(type="point", intensity=50.0 * 683)), translation=[0, 5, 0])
    builder.mesh(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), [[0, 1, 2]])
    builder.node(mesh=0, translation=[0, 0, -2])
    builder.node(camera=builder.camera(0.8, zfar=30.0, znear=znear), translation=[0, 1, 6])
    path = tmp_path / "camera.glb"
    path.write_bytes(builder.glb())
    return path


def test_the_gltf_cameras_znear_is_its_near(tmp_path):
    path = _camera_file(tmp_path, 0.1)
    assert load_scene(path).camera.near == 0.1
    assert load_scene(path, ["camera.near=0"]).camera.near == 0.0  # a camera of near alone: the file's
    np.testing.assert_array_equal(load_scene(path, ["camera.near=0.4"]).camera.position, [0, 1, 6])
    yaml = tmp_path / "scene.yaml"
    yaml.write_text("version: 1\nimage: {width: 32, height: 18}\ngltf: {file: camera.glb}\n"
                    "camera: {position: [0, 1, 6], look_at: [0, 1, 0]}\n")
    assert load_scene(yaml).camera.near == 0.0  # the scene's own camera: its own near
    assert load_scene(yaml, ["camera.near=0.25"]).camera.near == 0.25


BAD = [
    ("camera.near=-0.1", r"camera\.near: expected a number >= 0, got -0\.1$"),
    ("camera.near=.inf", r"camera\.near: expected a finite number >= 0, got \.inf$"),
    ("camera.near=30", r"camera\.near: expected a number in \[0, 30\) \(below camera\.far\), got 30$"),
    ("camera.near=abc", r"camera\.near: expected a number >= 0, got 'abc'$"),
]


@pytest.mark.parametrize("override, message", BAD)
def test_a_bad_near_is_one_line(override, message):
    text = "version: 1\nimage: {width: 8, height: 8}\ncamera: {position: [0, 0, 5], look_at: [0, 0, 0], far: 30}\n" \
           "lights: [{type: point, position: [0, 3, 0], intensity: 1}]\n"
    with pytest.raises(SceneError, match=message) as raised:
        parse_scene(text, overrides=[override])
    assert "\n" not in str(raised.value)


@pytest.mark.parametrize("znear, message", [(-1.0, r"cameras\.0\.perspective\.znear: expected a finite number >= 0"),
                                            (30.0, r"cameras\.0\.perspective\.znear: expected a distance in \[0, 30\)"),
                                            ("near", r"cameras\.0\.perspective\.znear: expected a finite number")])
def test_a_bad_znear_is_one_line(tmp_path, znear, message):
    path = _camera_file(tmp_path, znear)
    code, out = run_cli("render", path, "-o", tmp_path / "out.npy")
    assert code == 1 and len(out.strip().splitlines()) == 1, out
    assert re.search(message, out), out
    with pytest.raises(SceneError, match=message):
        load_scene(path, ["camera.near=0"])  # the file's camera is read first, its znear too
