"""Shared fixtures: one OpenCL device for the whole run (PoCL in CI), scene builders."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from clrays import runtimes
from clrays.scene.geometry import box_triangles

from clrays.scene.model import (Camera, DirectionalLight, Geometry, Image, Medium, Phase, PointLight, Render, Scene,
                          SpotLight)


#: The test session's OpenCL device: `CLRAYS_TEST_DEVICE` (a `--device` spec, as `make
#: test-device DEVICE=nvidia` sets it), else PoCL's CPU device whatever CLRAYS_DEVICE says,
#: so that `make test` runs where CI does; on a CPU that PoCL's compiler does not know,
#: Intel's CPU runtime (which `make` then installs). Set as CLRAYS_DEVICE for the whole
#: process, so the tests that make their own `Renderer()` or run the command line use it too.
TEST_DEVICE = os.environ.get("CLRAYS_TEST_DEVICE") or (
    "Portable Computing Language" if runtimes.pocl_builds_here() else "Intel")
os.environ["CLRAYS_DEVICE"] = TEST_DEVICE
#: Whether the spec names PoCL (tests whose bounds are PoCL's arithmetic mark themselves by it).
TEST_ON_POCL = any(name in TEST_DEVICE.lower() for name in ("portable", "pocl"))


def pytest_addoption(parser):
    parser.addoption("--regen-golden", action="store_true",
                     help="rewrite tests/golden/data/*.npy from this run instead of comparing with them")


def pytest_report_header(config):
    why = "CLRAYS_TEST_DEVICE" if os.environ.get("CLRAYS_TEST_DEVICE") else \
        "PoCL" if TEST_ON_POCL else "PoCL cannot build for this CPU"
    return f"clrays test device: {TEST_DEVICE!r} ({why})"


@pytest.fixture(scope="session")
def device():
    from clrays.device import Device

    return Device(TEST_DEVICE)


@pytest.fixture(scope="session")
def renderer(device):
    from clrays.session import Renderer

    return Renderer(device)


def run_cli(*args, env: dict[str, str] | None = None) -> tuple[int, str]:
    """Run the `clrays` command line in-process, with `env` added to the environment:
    (exit code, stdout and stderr as a terminal shows them)."""
    from click.testing import CliRunner

    from clrays.cli import main

    result = CliRunner().invoke(main, [str(a) for a in args], env=env, catch_exceptions=False)
    return result.exit_code, result.output


def v3(*xs) -> np.ndarray:
    return np.array(xs, dtype=np.float64)


def grid_plane(y=0.0, half=6.0, n=4) -> np.ndarray:
    """A horizontal square at height y, split into 2·n² triangles."""
    xs = np.linspace(-half, half, n + 1)
    tris = []
    for i in range(n):
        for j in range(n):
            a, b = (xs[i], y, xs[j]), (xs[i + 1], y, xs[j])
            c, d = (xs[i + 1], y, xs[j + 1]), (xs[i], y, xs[j + 1])
            tris += [[a, b, c], [a, c, d]]
    return np.array(tris, dtype=float)


#: The sizes the method and stage tests' tolerances were measured at. A scene that leaves
#: them unset gets sizes that follow its image (clrays.scene.costs), smaller on these
#: tests' 24×24 to 64×48 images; tests/scene/test_costs.py covers those, so make_scene
#: pins these unless a test passes its own (None: derived from the image).
MEASURED_SIZES = dict(shadow_map=1024, slices=1024, gamma_samples=1024)


def make_scene(triangles=None, lights=None, width=32, height=24, spp=1, position=(0, 2, 8), look_at=(0, 1, 0),
               fov_deg=50.0, far=30.0, sigma_s=0.05, sigma_a=0.01, phase=None, background=0.0, albedo=0.8,
               **render) -> Scene:
    """A small scene built directly (no YAML), for stage and method tests."""
    render = {**MEASURED_SIZES, **render}
    triangles = np.zeros((0, 3, 3)) if triangles is None else np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    lights = lights if lights is not None else [PointLight(v3(0, 4, 0), np.full(3, 30.0))]
    geometry = Geometry(triangles, np.full((len(triangles), 3), albedo), np.zeros(len(triangles), np.int32))
    return Scene(
        image=Image(width, height, spp),
        camera=Camera(v3(*position), v3(*look_at), v3(0, 1, 0), fov_deg, far),
        lights=tuple(lights),
        medium=Medium(np.full(3, float(sigma_s)), np.full(3, float(sigma_a)), phase or Phase()),
        background=np.full(3, float(background)),
        geometry=geometry,
        render=Render(**render),
    )


def with_closed_solid(scene: Scene, rows: slice) -> Scene:
    """`scene` with its triangles `rows` one closed solid, as loading a box, a sphere or a
    closed mesh marks it (`Geometry.outward`); make_scene's triangles are an open soup."""
    from dataclasses import replace

    from clrays.scene.geometry import closed_outward

    geometry = scene.geometry
    solid = geometry.triangles[rows]
    sign = closed_outward(solid.reshape(-1, 3), np.arange(3 * len(solid)).reshape(-1, 3))
    assert sign != 0, "the rows do not close a solid"
    outward, object_id = geometry.outward.copy(), geometry.object_id.copy()
    outward[rows], object_id[rows] = sign, object_id.max() + 1
    return replace(scene, geometry=replace(geometry, outward=outward, object_id=object_id))


def _hg(c, g):
    return (1 - g * g) / (4 * math.pi * (1 + g * g - 2 * g * c) ** 1.5)


def quadrature_pixel(eye, d, light_pos, intensity, sigma_s, sigma_t, g, far) -> float:
    """∫0^far e^{-σt s}·σs·ρ(cosθ)·I·e^{-σt r}/r² ds by scipy, written out independently of clrays."""
    from scipy.integrate import quad

    def integrand(s):
        x = eye + s * d
        w = x - light_pos
        r = math.sqrt(w @ w)
        cos_theta = -(w / r) @ d  # light's propagation (w/r) against the way to the eye (-d)
        return math.exp(-sigma_t * s) * sigma_s * _hg(cos_theta, g) * intensity * math.exp(-sigma_t * r) / (r * r)

    closest = float(np.clip((light_pos - eye) @ d, 0, far))
    return quad(integrand, 0, far, points=[closest], limit=400, epsabs=0, epsrel=1e-10)[0]


def unoccluded_point_quadrature(scene) -> tuple[np.ndarray, np.ndarray]:
    """Red channel of the in-scattered radiance of an empty scene lit by one point light,
    per pixel centre, and the mask of pixels more than 2.5° from the light (the pixel
    holding the light, ~π/h as h → 0, belongs to the stability suite)."""
    from clrays.scene.camera import primary_rays

    light, medium = scene.lights[0], scene.medium
    g = medium.phase.g if medium.phase.type == "hg" else 0.0
    dirs = primary_rays(scene.camera, scene.image)[:, :, 0]
    expected = np.array([[quadrature_pixel(scene.camera.position, d, light.position, light.intensity[0],
                                           medium.sigma_s[0], medium.sigma_t[0], g, scene.camera.far)
                          for d in row] for row in dirs])
    to_light = light.position - scene.camera.position
    angles = np.degrees(np.arccos(np.clip(dirs @ (to_light / np.linalg.norm(to_light)), -1, 1)))
    return expected, angles > 2.5


__all__ = ["v3", "box_triangles", "grid_plane", "make_scene", "PointLight", "SpotLight", "DirectionalLight", "Phase"]
