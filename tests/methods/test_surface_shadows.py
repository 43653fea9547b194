"""Hard shadows on surfaces (`render.surface_shadows`, docs/design.md §4, visibility): the BVH against
brute force, and `exact` surface shadows against the `exact` reference in the cases that
break shadow maps (docs/stability.md, "Surface shadows"): a wire thinner than a texel, light
grazing a surface, a closed mesh, a light touching a surface, a scene far from the origin.

Most scenes have no medium, so that the reference is cheap and the surfaces are all that is
measured. Run with `-s` to see the numbers docs/stability.md quotes.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from clrays.bvh import build_bvh
from clrays.reference.exact import render_exact
from clrays.physics.geometry import raycast
from clrays.reference.metrics import depth_edges, depth_map, image_error, luminance
from clrays.scene.geometry import box_triangles
from conftest import DirectionalLight, PointLight, SpotLight, grid_plane, make_scene, v3, with_closed_solid


def occluded_by_bvh(bvh, triangles: np.ndarray, origin, target) -> bool:
    """Host walk of the BVH for one segment origin → target (float64): whether any
    triangle crosses it: the device walk's yardstick, slow in Python."""
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    origin, target = np.asarray(origin, float), np.asarray(target, float)
    d = target - origin
    if bvh.root < 0:
        candidates = list(range(len(tri)))
    else:
        candidates, stack = [], [0]
        lo, hi = bvh.node_bounds[0::2, :3].astype(float), bvh.node_bounds[1::2, :3].astype(float)
        while stack:
            node = stack.pop()
            with np.errstate(divide="ignore", invalid="ignore"):
                t0, t1 = (lo[node] - origin) / d, (hi[node] - origin) / d
            near = np.nanmax(np.minimum(t0, t1))
            far = np.nanmin(np.maximum(t0, t1))
            if near > min(far, 1.0) or far < 0:
                continue
            for child in bvh.node_children[node]:
                (candidates.append(-child - 1) if child < 0 else stack.append(int(child)))
    if not candidates:
        return False
    t, _ = raycast(origin, d, tri[candidates], t_max=1.0)
    return bool(np.isfinite(t[0]))



def unit(*xs) -> np.ndarray:
    x = np.array(xs, dtype=np.float64)
    return x / np.linalg.norm(x)


def mismatched_pixels(image, reference, scene, threshold=0.05) -> int:
    """Pixels, depth edges excluded, whose luminance differs from the reference's by more
    than `threshold` of the larger of the two (or of 1 % of the mean where both are dark)."""
    lum, ref = luminance(image), luminance(reference)
    scale = np.maximum(np.maximum(lum, ref), 0.01 * ref.mean())
    bad = (np.abs(lum - ref) > threshold * scale) & ~depth_edges(depth_map(scene))
    return int(bad.sum())


def compare(renderer, scene, label):
    """(exact-mode image, map-mode image, reference, exact-mode mismatches, map-mode mismatches)."""
    reference = render_exact(scene)
    exact = renderer.render(replace(scene, render=replace(scene.render, surface_shadows="exact")), "minmax").image
    mapped = renderer.render(replace(scene, render=replace(scene.render, surface_shadows="map")), "minmax").image
    bad_exact, bad_map = (mismatched_pixels(exact, reference, scene), mismatched_pixels(mapped, reference, scene))
    error = image_error(exact, reference, depth_edges(depth_map(scene)))
    print(f"{label}: surface_shadows exact {bad_exact} px off by > 5 % ({error}), map {bad_map} px")
    return exact, mapped, reference, bad_exact, bad_map


def lights(position, towards=(0.0, 0.0, 0.0)) -> dict:
    position = np.asarray(position, dtype=np.float64)
    return {
        "point": PointLight(position, np.full(3, 40.0)),
        "spot": SpotLight(position, unit(*(np.asarray(towards) - position)), 45.0, np.full(3, 60.0)),
        "directional": DirectionalLight(unit(*-position), np.full(3, 1.5)),
    }


# --------------------------------------------------------------------------- the BVH


def test_bvh_answers_as_brute_force():
    rng = np.random.default_rng(7)
    triangles = rng.random((300, 3, 3)) * 4.0
    triangles += 0.3 * rng.standard_normal((300, 1, 3))
    bvh = build_bvh(triangles)
    assert sorted(-bvh.node_children[bvh.node_children < 0] - 1) == list(range(300))
    for _ in range(200):
        origin, target = rng.random(3) * 4.0, rng.random(3) * 4.0
        t, _ = raycast(origin, target - origin, triangles, t_max=1.0)
        assert occluded_by_bvh(bvh, triangles, origin, target) == bool(np.isfinite(t[0]))


def test_bvh_of_one_and_two_triangles():
    one = build_bvh(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float))
    assert one.root == -1 and one.node_children.shape == (0, 2)
    two = build_bvh(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 1], [1, 0, 1], [0, 1, 1]]], float))
    assert sorted(two.node_children[0].tolist()) == [-2, -1]


# --------------------------------------------------------------------------- the shadows


def occluders():
    return np.concatenate([grid_plane(0.0, 6.0, 4), box_triangles([-1.5, 1.5, -1.0], [0.5, 1.8, 0.5]),
                           box_triangles([1.0, 0.0, -2.0], [1.8, 1.2, -1.2])])


def surface_scene(light, triangles=None, **settings):
    defaults = dict(width=48, height=32, position=(0, 5.0, 7), look_at=(0, 0.5, 0), far=30.0, sigma_s=0.0,
                    sigma_a=0.0, shadow_map=256)
    defaults.update(settings)
    return make_scene(occluders() if triangles is None else triangles, [light], **defaults)


@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
def test_exact_surface_shadows_match_the_reference(renderer, kind):
    """A coarse 64² map puts shadow edges a texel off (map: 6–7 px wrong, 0 for the sun here);
    exact surface shadows put them where the reference does."""
    scene = surface_scene(lights((0.3, 4.0, -0.5))[kind], shadow_map=64, width=64, height=36)
    exact, mapped, reference, bad_exact, bad_map = compare(renderer, scene, kind)
    assert bad_exact <= 1, f"{kind}: {bad_exact} pixels differ from exact (map: {bad_map})"


@pytest.mark.parametrize("kind", ["point", "directional"])
def test_antialiased_edges_converge_to_exact_at_the_same_spp(renderer, kind):
    scene = surface_scene(lights((0.3, 4.0, -0.5))[kind], spp=4, width=32, height=24)
    exact, _, reference, bad_exact, _ = compare(renderer, scene, f"{kind} spp 4")
    assert bad_exact <= 1
    assert image_error(exact, reference, depth_edges(depth_map(scene))).rmse < 0.005


def wire_scene(kind):
    """A wire 0.03 thick, 2 above the floor, turned 20° about the vertical: a 64² map's texel
    there is 0.1 (point: 2/64 rad at 3 from the light) to 0.2 (sun) wide, so the map sees
    the wire at some texel centres and not at others."""
    wire = box_triangles([-3.0, 2.0, -0.015], [3.0, 2.03, 0.015])
    c, s = np.cos(0.35), np.sin(0.35)
    wire = wire @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]).T
    return surface_scene(lights((0.2, 5.0, 0.5))[kind], np.concatenate([grid_plane(0.0, 6.0, 4), wire]),
                         shadow_map=64, width=64, height=36, position=(0, 4.0, 1.5), look_at=(0, 0, 0))


@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
def test_a_wire_thinner_than_a_texel_casts_its_shadow(renderer, kind):
    scene = wire_scene(kind)
    exact, mapped, reference, bad_exact, bad_map = compare(renderer, scene, f"wire, {kind}")
    assert bad_map >= 10, "the map alone must get the wire's shadow wrong (else the test tests nothing)"
    assert bad_exact <= 1


@pytest.mark.parametrize("elevation_deg", [1.0, 3.0])
def test_grazing_light_no_acne_no_peter_panning(renderer, elevation_deg):
    """A sun a few degrees above the floor: the floor is evenly lit (no acne) and the
    blocks' long shadows start at their feet (no peter-panning), at scales 1e-3 and 1e3 too."""
    elevation = np.radians(elevation_deg)
    sun = DirectionalLight(-unit(np.cos(elevation), np.sin(elevation), 0.3), np.full(3, 1.5))
    for scale in (1.0, 1e-3, 1e3):
        scene = surface_scene(sun, occluders() * scale, position=(0, 5.0 * scale, 7 * scale),
                              look_at=(0, 0.5 * scale, 0), far=30.0 * scale)
        exact, _, reference, bad_exact, _ = compare(renderer, scene, f"grazing {elevation_deg}°, scale {scale:g}")
        assert bad_exact <= 2


def closed_box(centre=(0.0, 1.0, 0.0), half=1.5):
    c = np.asarray(centre)
    return box_triangles(c - half, c + half)


def test_inside_a_closed_mesh_surfaces_are_dark(renderer):
    """The camera inside a closed box, the light outside: every surface it sees is dark."""
    triangles = np.concatenate([grid_plane(-1.0, 6.0, 2), closed_box()])
    for kind, light in lights((0.3, 5.0, -0.5)).items():
        scene = surface_scene(light, triangles, position=(0.2, 1.1, 0.9), look_at=(0, 0.8, -1.0), width=32,
                              height=24)
        image = renderer.render(scene, "minmax").image
        assert image.max() == 0.0, f"{kind}: {image.max():.3e} inside a closed box"


def test_inside_a_closed_mesh_the_medium_is_dark(renderer):
    """The box is a closed solid (as a loaded box or closed mesh is) around the eye and not
    the light: no light reaches what the camera sees (inputs.walled_off). From the shadow map
    alone, a layer about a texel thick behind the walls counted as lit: the largest pixel
    was 1.3 % (point) and 2.0 % (sun) of the same ray unshadowed at a 1024 map."""
    eye = np.array([0.0, 4.5, 7.0])
    triangles = np.concatenate([occluders(), box_triangles(eye - 0.5, eye + 0.5)])
    worst = 0.0
    for kind, light in lights((0.3, 4.0, -0.5)).items():
        scene = surface_scene(light, triangles, position=tuple(eye), look_at=(0, 0.8, 0), width=24, height=24,
                              sigma_s=0.08, sigma_a=0.02, shadow_map=1024)
        scene = with_closed_solid(scene, slice(len(occluders()), None))
        worst = max(worst, float(renderer.render(scene, "minmax").image.max()))
    print(f"camera in a closed box with fog: largest pixel {worst:.3e}")
    assert worst == 0.0


@pytest.mark.parametrize("kind", ["point", "spot"])
def test_a_light_touching_a_surface(renderer, kind):
    """A point light 1e-4 above the floor, a spot 1e-4 off a block's side aimed down and away
    from it: finite, and the lighting matches exact but for the pixels at the light itself."""
    light = PointLight(v3(0.3, 1e-4, -0.5), np.full(3, 40.0)) if kind == "point" else \
        SpotLight(v3(-0.5 + 1e-4, 0.5, -0.5), unit(1.0, -0.5, 0.0), 60.0, np.full(3, 60.0))
    triangles = np.concatenate([grid_plane(0.0, 6.0, 4), box_triangles([-1.5, 0.0, -1.0], [-0.5, 1.0, 0.0])])
    scene = surface_scene(light, triangles)
    exact, _, reference, bad_exact, _ = compare(renderer, scene, f"light touching, {kind}")
    assert np.isfinite(exact).all() and exact.min() >= 0.0
    assert bad_exact <= 2


@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
def test_translation_by_1e4_changes_nothing(renderer, kind):
    light = lights((0.3, 4.0, -0.5))[kind]
    scene = surface_scene(light)
    shift = np.array([1e4, -1e4, 1e4])
    moved_light = light if kind == "directional" else replace(light, position=light.position + shift)
    moved = surface_scene(moved_light, occluders() + shift, position=tuple(np.array([0, 5.0, 7]) + shift),
                          look_at=tuple(np.array([0, 0.5, 0]) + shift))
    here, there = renderer.render(scene, "minmax").image, renderer.render(moved, "minmax").image
    error = image_error(there, here, depth_edges(depth_map(scene)))
    print(f"{kind} moved by 1e4: {error}")
    assert error.rmse < 1e-3 and mismatched_pixels(there, here, scene) <= 1


@pytest.mark.parametrize("name", ["demo", "bunny", "behind", "sun"])
def test_the_maps_shadowed_test_answers_as_shadow_rays(renderer, monkeypatch, name):
    """Where the lit tests cannot decide, the 3 × 3 test reads the map as shadowed when
    all nine texels around the sample's own hold a blocker; a device built without it casts
    a shadow ray for each such sample. The images are the same: around the lookup's texel
    instead (the point moved off an inclined surface, up to a texel aside), the nine had
    left lit samples beside the slats' and the window frame's shadow edges outside, and
    called them shadowed (docs/design.md §4.6)."""
    from pathlib import Path

    from clrays import structs
    from clrays.device import Device
    from clrays.scene.load import load_scene
    from clrays.session import Renderer
    from conftest import TEST_DEVICE

    monkeypatch.setitem(structs.KERNEL_CONSTANTS, "VISIBILITY_SHADOWED_TEST", 0)
    every_ray = Renderer(Device(TEST_DEVICE))
    monkeypatch.undo()
    scenes = Path(__file__).resolve().parents[2] / "scenes"
    scene = load_scene(scenes / f"{name}.yaml", overrides=["image.width=480", "image.height=270",
                                                           "medium.sigma_s=0", "medium.sigma_a=0"])
    ours, rays = renderer.render(scene, reuse=False), every_ray.render(scene, reuse=False)
    assert ours.shadow_rays < rays.shadow_rays  # the test decided some samples
    differ = np.abs(luminance(ours.image) - luminance(rays.image)) > 1e-4 * np.maximum(luminance(rays.image), 1e-3)
    assert int(differ.sum()) == 0, f"{name}: {int(differ.sum())} pixels differ from the shadow rays'"


@pytest.mark.parametrize("name, size, pixel", [
    ("sun", (200, 150), (66, 129)),  # lit: its shadow ray passes 6e-6 below the window's top edge
    ("grate", (128, 72), (83, 71)),  # shadowed: its ray passes 9e-6 inside a slat's top corner
])
def test_a_point_beside_a_shadows_edge_gets_exacts_answer(renderer, name, size, pixel):
    """A floor point a few 1e-6 of the scene from a hard shadow's edge: its shadow ray's line
    passes through the point, as exact's does (lighting.h shadow_ray_start), so the two
    agree. When the ray left the surface along the normal (push = 2e-6·(|p| + d) ≈ 1e-5,
    a line shifted by that much) the pixel took the other side's answer: sun.yaml's read 0
    against exact's 0.353 (5.6 % of the frame's relative RMSE at 200×150), grate.yaml's 0.205
    against 0.026 (2.2 % at 128×72)."""
    from pathlib import Path

    from clrays.reference.exact import exact_pixels
    from clrays.scene.load import load_scene

    scenes = Path(__file__).resolve().parents[2] / "scenes"
    scene = load_scene(scenes / f"{name}.yaml", overrides=[f"image.width={size[0]}", f"image.height={size[1]}"])
    x, y = pixel
    ours = luminance(renderer.render(scene, "minmax").image[y, x])
    reference = luminance(exact_pixels(scene, np.array([y]), np.array([x]))[0])
    print(f"{name} {size}: pixel {pixel} reads {ours:.4f}, exact {reference:.4f}")
    assert abs(ours - reference) <= 0.01 * max(ours, reference)
