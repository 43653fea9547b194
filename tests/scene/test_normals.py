"""Shading normals: a mesh's vertex normals from its file or averaged from its faces,
carried through its transform by the inverse transpose, interpolated by the shade
kernel; `normals: flat` renders exactly as the same triangles written as triangles."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

from clrays.errors import SceneError
from clrays.reuse import scene_digest
from clrays.scene.camera import primary_rays
from clrays.scene.geometry import flat_normals
from clrays.scene.load import parse_scene
from clrays.scene.transforms import rotation_axis_angle

MESHES = Path(__file__).resolve().parents[2] / "scenes" / "meshes"

SCENE = """\
version: 1
image: {{width: {size}, height: {size}}}
camera: {{position: [0, 0, 4], look_at: [0, 0, 0], fov_deg: 40}}
lights: [{{type: directional, direction: [0.2, -0.3, -1], irradiance: 3}}]
medium: {{sigma_s: {sigma_s}}}
objects:
  - {{type: plane, center: [0, 0, -2], normal: [0, 0, 1], size: 8, segments: 2}}
  - {obj}
"""


def scene_text(obj: str, size: int = 48, sigma_s: float = 0.0) -> str:
    return SCENE.format(obj=obj, size=size, sigma_s=sigma_s)


def write_obj(path: Path, vertices, faces, normals=None) -> Path:
    """An OBJ with every coordinate written exactly (repr round-trips float64)."""
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in vertices]
    if normals is None:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    else:
        lines += [f"vn {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in normals]
        lines += [f"f {a + 1}//{a + 1} {b + 1}//{b + 1} {c + 1}//{c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def icosphere(tmp_path_factory) -> tuple[Path, trimesh.Trimesh]:
    """A unit icosphere (320 faces) without normals in its file, and the same with the exact
    sphere normals (each vertex's own position) as `vn`."""
    folder = tmp_path_factory.mktemp("icosphere")
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    write_obj(folder / "ico.obj", mesh.vertices, mesh.faces)
    write_obj(folder / "ico_vn.obj", mesh.vertices, mesh.faces, normals=mesh.vertices)
    return folder, mesh


def load(folder: Path, obj: str, **kw):
    return parse_scene(scene_text(obj, **kw), folder / "scene.yaml")


# --------------------------------------------------------------------------- loading


def test_mesh_defaults_to_smooth_and_other_objects_are_flat(icosphere):
    folder, mesh = icosphere
    g = load(folder, "{type: mesh, file: ico.obj}").geometry
    assert g.normals.shape == g.triangles.shape and g.normals.dtype == np.float64
    np.testing.assert_array_equal(g.smooth, g.object_id == 1)
    np.testing.assert_allclose(np.linalg.norm(g.normals, axis=-1), 1.0, atol=1e-12)
    plane = g.object_id == 0
    np.testing.assert_array_equal(g.normals[plane], flat_normals(g.triangles[plane]))
    np.testing.assert_allclose(g.normals[plane], np.broadcast_to([0, 0, 1], g.normals[plane].shape))
    # At the vertices of a sphere's tessellation, area-weighted face normals lie close to the
    # true normals (measured: 0.024 at most), far closer than the faces' own (0.19).
    sphere = g.triangles[g.object_id == 1]
    true = sphere / np.linalg.norm(sphere, axis=-1, keepdims=True)
    deviation = np.max(np.linalg.norm(g.normals[g.object_id == 1] - true, axis=-1))
    assert deviation < 0.03
    assert deviation < 0.3 * np.max(np.linalg.norm(flat_normals(sphere) - true, axis=-1))


def test_flat_mesh_holds_face_normals(icosphere):
    folder, _ = icosphere
    g = load(folder, "{type: mesh, file: ico.obj, normals: flat}").geometry
    assert not g.smooth.any()
    np.testing.assert_array_equal(g.normals, flat_normals(g.triangles))


def test_file_normals_are_used(icosphere):
    folder, mesh = icosphere
    g = load(folder, "{type: mesh, file: ico_vn.obj}").geometry
    sphere = g.triangles[g.object_id == 1]
    np.testing.assert_allclose(g.normals[g.object_id == 1], sphere, atol=1e-15)  # unit sphere: n = p


def test_area_weighting_and_shared_vertices(tmp_path):
    # Two triangles sharing the edge (0,1,2)-(0,2,3): one in z = 0 with area 2, one in
    # x = 0 with area 0.5. The shared vertices get the area-weighted mean, the others
    # their own face's normal.
    vertices = [[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 1]]
    write_obj(tmp_path / "hinge.obj", vertices, [[0, 1, 2], [0, 2, 3]])
    g = load(tmp_path, "{type: mesh, file: hinge.obj}").geometry
    hinge = g.normals[g.object_id == 1]
    shared = np.array([2.0, 0.0, 4.0]) / math.hypot(2.0, 4.0)  # 4·(0,0,1) + 1·(1,0,0), twice the areas
    np.testing.assert_allclose(hinge[0], [shared, [0, 0, 1], shared], atol=1e-15)
    np.testing.assert_allclose(hinge[1], [shared, shared, [1, 0, 0]], atol=1e-15)


def test_stl_shares_no_vertices_so_stays_faceted(tmp_path):
    g = load(tmp_path, f"{{type: mesh, file: {MESHES / 'cube.stl'}}}").geometry
    cube = g.object_id == 1
    np.testing.assert_allclose(g.normals[cube], flat_normals(g.triangles[cube]), atol=1e-15)


def test_non_uniform_scale_keeps_normals_perpendicular(icosphere):
    """The vertex normals of a unit sphere, scaled by S, rotated by R and translated by t,
    are the normals of the ellipsoid |S⁻¹ Rᵀ (q - t)| = 1 at its vertices q:
    ∇ ∝ R S⁻¹ p with p = S⁻¹ Rᵀ (q - t), the inverse transpose of R S applied to p."""
    folder, _ = icosphere
    scale, axis, angle, translate = np.array([1.0, 3.0, 0.5]), [1.0, 2.0, 0.5], 0.7, np.array([0.5, -1.0, 2.0])
    g = load(folder, "{type: mesh, file: ico_vn.obj, transform: {translate: [0.5, -1, 2], "
                     "rotate: {axis: [1, 2, 0.5], angle_deg: %r}, scale: [1, 3, 0.5]}}" % math.degrees(angle)).geometry
    q = g.triangles[g.object_id == 1]
    r = rotation_axis_angle(axis, angle)
    p = ((q - translate) @ r) / scale  # S⁻¹ Rᵀ (q - t), row vectors
    np.testing.assert_allclose(np.linalg.norm(p, axis=-1), 1.0, atol=1e-12)  # on the ellipsoid
    gradient = (p / scale) @ r.T
    expected = gradient / np.linalg.norm(gradient, axis=-1, keepdims=True)
    np.testing.assert_allclose(g.normals[g.object_id == 1], expected, atol=1e-12)
    # Mapped like a tangent (by R S) the normals would tilt off the surface by far more.
    naive = (p * scale) @ r.T
    naive /= np.linalg.norm(naive, axis=-1, keepdims=True)
    assert np.max(np.linalg.norm(naive - expected, axis=-1)) > 0.5


def test_animated_smooth_object_carries_its_normals(icosphere):
    folder, _ = icosphere
    text = scene_text("{type: mesh, file: ico_vn.obj}") + (
        "animation:\n  frames: [0, 2]\n  objects:\n    - object: 1\n      keys:\n"
        "        - {frame: 0, scale: 1}\n        - {frame: 2, scale: [1, 3, 1]}\n")
    s = parse_scene(text, folder / "scene.yaml")
    last = s.animation.scene_at(s, 2).geometry
    sphere = last.object_id == 1
    p = last.triangles[sphere] / [1.0, 3.0, 1.0]
    expected = p / [1.0, 3.0, 1.0]
    np.testing.assert_allclose(last.normals[sphere], expected / np.linalg.norm(expected, axis=-1, keepdims=True),
                               atol=1e-12)
    np.testing.assert_array_equal(last.smooth, s.geometry.smooth)
    np.testing.assert_array_equal(last.normals[~sphere], s.geometry.normals[~sphere])


@pytest.mark.parametrize("obj, pattern", [
    ("{type: box, min: [0, 0, 0], max: [1, 1, 1], normals: smooth}",
     r"objects\.1\.normals: expected no normals key on a box \(only a mesh chooses between its vertex normals "
     r"and flat shading; a sphere is shaded smooth, every other object flat\), got 'smooth'$"),
    ("{type: sphere, center: [0, 0, 0], radius: 1, normals: flat}", r"objects\.1\.normals: expected no normals key "
                                                                    r"on a sphere"),
    ("{type: mesh, file: ico.obj, normals: phong}", r"objects\.1\.normals: expected one of 'smooth', 'flat', "
                                                    r"got 'phong'$"),
])
def test_bad_normals(icosphere, obj, pattern):
    folder, _ = icosphere
    with pytest.raises(SceneError, match=r"scene\.yaml:\d+:\d+: " + pattern):
        load(folder, obj)


def test_normals_are_part_of_the_scene_digest(icosphere):
    folder, _ = icosphere
    smooth, flat = (load(folder, f"{{type: mesh, file: ico.obj, normals: {n}}}") for n in ("smooth", "flat"))
    np.testing.assert_array_equal(smooth.geometry.triangles, flat.geometry.triangles)
    assert scene_digest(smooth) != scene_digest(flat)


# --------------------------------------------------------------------------- rendering


@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_flat_mesh_renders_as_the_same_triangles(icosphere, renderer, method):
    folder, mesh = icosphere
    as_mesh = load(folder, "{type: mesh, file: ico.obj, normals: flat}", sigma_s=0.05)
    vertices = [[float(c) for c in v] for v in mesh.vertices]
    as_triangles = load(folder, f"{{type: triangles, vertices: {vertices}, faces: {mesh.faces.tolist()}}}",
                        sigma_s=0.05)
    np.testing.assert_array_equal(as_mesh.geometry.triangles, as_triangles.geometry.triangles)
    image_mesh = renderer.render(as_mesh, method=method).image
    image_triangles = renderer.render(as_triangles, method=method).image
    assert image_mesh.any()
    np.testing.assert_array_equal(image_mesh, image_triangles)


def test_smooth_sphere_has_no_facets(icosphere, renderer):
    """Inside the lit disc a smooth icosphere shades like the sphere it approximates: no
    step between neighbouring pixels, where the flat one steps at every facet edge."""
    folder, _ = icosphere
    size = 96
    images = {normals: renderer.render(load(folder, f"{{type: mesh, file: ico.obj, normals: {normals}}}",
                                            size=size)).image[..., 0]
              for normals in ("smooth", "flat")}
    scene = load(folder, "{type: mesh, file: ico.obj}", size=size)
    # Where the camera rays meet the unit sphere, away from its rim (where the tessellation's
    # silhouette differs from the sphere's): Lambert's cosine of the true sphere there.
    rays = primary_rays(scene.camera, scene.image)[:, :, 0]
    eye = scene.camera.position
    b = rays @ eye
    discriminant = b * b - (eye @ eye - 1.0)
    inner = discriminant > 0.5 * (discriminant.max())
    hit = eye + (-b - np.sqrt(np.maximum(discriminant, 0.0)))[..., None] * rays
    light = scene.lights[0]
    expected = 0.8 / math.pi * light.irradiance[0] * np.maximum(hit @ -light.direction, 0.0)

    def steps(image):
        dx = np.abs(np.diff(image, axis=1))[inner[:, 1:] & inner[:, :-1]]
        dy = np.abs(np.diff(image, axis=0))[inner[1:] & inner[:-1]]
        return np.concatenate([dx, dy]).max()

    # Measured (PoCL): largest step 0.022 smooth, 0.19 flat; mean error against the true
    # sphere 0.0024 smooth, 0.019 flat.
    assert steps(images["smooth"]) < 0.25 * steps(images["flat"])
    error = {n: np.abs(image - expected)[inner].mean() for n, image in images.items()}
    assert error["smooth"] < 0.3 * error["flat"]


def _sphere_as_flat_mesh(folder: Path, center, radius: float, segments: int = 48) -> str:
    """The same tessellation as `type: sphere` written as an OBJ, shaded flat: a sphere
    as it was shaded before spheres took their analytic normals."""
    from clrays.scene.geometry import sphere_triangles

    triangles = sphere_triangles(np.asarray(center, float), radius, segments).reshape(-1, 3)
    write_obj(folder / "flat_sphere.obj", triangles, np.arange(len(triangles)).reshape(-1, 3))
    return "{type: mesh, file: flat_sphere.obj, normals: flat"


def test_sphere_takes_its_analytic_normals():
    scene = parse_scene(scene_text("{type: sphere, center: [0.5, -0.25, 0.1], radius: 0.8}"))
    g = scene.geometry
    sphere = g.object_id == 1
    assert g.smooth[sphere].all() and not g.smooth[~sphere].any()
    expected = (g.triangles[sphere] - [0.5, -0.25, 0.1]) / 0.8
    np.testing.assert_allclose(g.normals[sphere], expected, atol=1e-12)


def test_the_demo_sphere_is_smooth(tmp_path, renderer):
    """The demo's sphere, lit by the demo's light, at 320×180 (the roof's slats and the haze
    left out: their shadow edges are steps of their own): along the lit cap no step
    between neighbouring pixels like the bands its 48 segments showed when it was shaded
    flat (that tessellation as a flat mesh, beside it), and Lambert's cosine of the true
    sphere within a fraction of the flat one's error."""
    demo = Path(__file__).resolve().parents[2] / "scenes" / "demo.yaml"
    center, radius = np.array([1.6, 1.0, 0.5]), 1.0
    text = "".join(line for line in demo.read_text().splitlines(keepends=True) if ", 4.6, " not in line)
    sphere_line = "{type: sphere, center: [1.6, 1.0, 0.5], radius: 1.0"
    assert sphere_line in text and "box" in text
    overrides = ["image.width=320", "image.height=180", "medium={sigma_s: 0}"]
    scenes = {"sphere": parse_scene(text, tmp_path / "demo.yaml", overrides),
              "flat": parse_scene(text.replace(sphere_line, _sphere_as_flat_mesh(tmp_path, center, radius)),
                                  tmp_path / "flat.yaml", overrides)}
    images = {name: renderer.render(scene).image for name, scene in scenes.items()}
    scene = scenes["sphere"]
    # The pixels whose rays meet the true sphere well inside its rim, on its lit side.
    rays = primary_rays(scene.camera, scene.image)[:, :, 0]
    eye = scene.camera.position - center
    b = rays @ eye
    discriminant = b * b - (eye @ eye - radius * radius)
    hit = eye + (-b - np.sqrt(np.maximum(discriminant, 0.0)))[..., None] * rays
    light = scene.lights[0]
    to_light = light.position - center - hit
    distance = np.linalg.norm(to_light, axis=-1)
    cosine = np.einsum("hwc,hwc->hw", hit / radius, to_light) / distance
    inner = (discriminant > 0.2 * discriminant.max()) & (cosine > 0.1)
    assert inner.sum() > 200
    albedo = np.array([0.8, 0.5, 0.3])  # the demo's, as the light's intensity
    expected = albedo / math.pi * light.intensity * (np.maximum(cosine, 0.0) / distance ** 2)[..., None]

    def steps(image):  # of what is left after the true sphere's shading: the bands
        grey = (image - expected).mean(axis=2)
        dx = np.abs(np.diff(grey, axis=1))[inner[:, 1:] & inner[:, :-1]]
        dy = np.abs(np.diff(grey, axis=0))[inner[1:] & inner[:-1]]
        return np.concatenate([dx, dy]).max()

    error = {name: np.abs(image - expected)[inner].mean() for name, image in images.items()}
    print(f"largest step {steps(images['sphere']):.4f} smooth, {steps(images['flat']):.4f} flat; mean error "
          f"{error['sphere']:.5f} smooth, {error['flat']:.5f} flat")
    # Measured (PoCL): largest step 0.0043 smooth, 0.133 flat; mean error 0.0021 smooth, 0.029 flat.
    assert steps(images["sphere"]) < 0.1 * steps(images["flat"])
    assert error["sphere"] < 0.2 * error["flat"]
