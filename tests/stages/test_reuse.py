"""A render session re-runs only the stages whose inputs changed, and reuse never
changes an image: every frame here is compared bit for bit with a frame computed from
scratch."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import clrays.session
from clrays.session import Renderer
from clrays.reuse import StageCache, digest, scene_digest
from clrays.scene.model import Phase
from clrays.scene.load import parse_scene

from conftest import DirectionalLight, PointLight, SpotLight, box_triangles, grid_plane, make_scene, v3

SMALL = dict(width=40, height=30, shadow_map=128, slices=64, gamma_samples=128)


def _slats():
    return np.concatenate([grid_plane(0.0, 6.0, 2)] + [box_triangles(v3(x, 2.5, -3), v3(x + 0.4, 2.7, 3))
                                                        for x in (-2.0, -1.0, 0.0, 1.0)])


ANIMATED = """\
version: 1
image: {width: 40, height: 30}
camera: {position: [0, 2, 8], look_at: [0, 1, 0], far: 30}
lights:
  - {type: point, position: [0.3, 5, -0.5], intensity: 60}
  - {type: spot, position: [-2, 6, 1], direction: [0.2, -1, 0], cone_deg: 35, intensity: 80}
medium: {sigma_s: 0.06, sigma_a: 0.01, phase: {type: hg, g: 0.3}}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 14, segments: 2}
  - {type: box, min: [-2, 2.5, -3], max: [-1.6, 2.7, 3]}
  - {type: box, min: [0, 2.5, -3], max: [0.4, 2.7, 3]}
  - {type: sphere, center: [1.5, 0.8, 0.5], radius: 0.8, segments: 12}
render: {shadow_map: 128, slices: 64, gamma_samples: 128, steps: 64}
animation:
  frames: [0, 11]
  camera:   # moves over 0-3, then stands still
    - {frame: 0, position: [0, 2, 8]}
    - {frame: 3, position: [3, 2.5, 7]}
  lights:
    - light: 0   # power changes over 3-5; moves over 9-10
      keys:
        - {frame: 3, intensity: 60, position: [0.3, 5, -0.5]}
        - {frame: 5, intensity: [90, 70, 50]}
        - {frame: 9, position: [0.3, 5, -0.5]}
        - {frame: 10, position: [1.0, 5.5, 0]}
  objects:
    - object: 3  # the sphere moves over 5-7
      keys:
        - {frame: 5, translate: [0, 0, 0]}
        - {frame: 7, translate: [-0.5, 0.2, 0]}
  medium:        # thickens over 7-9
    - {frame: 7, sigma_s: 0.06}
    - {frame: 9, sigma_s: [0.1, 0.08, 0.06]}
"""

#: What each frame of ANIMATED must reuse (frame 0 computes everything).
EXPECTED_REUSE = {
    1: {"raster.shadow"},  # camera moves, lights static
    3: {"raster.shadow"},  # camera arrives (frame 3 != 2)
    4: {"raster.camera", "raster.shadow", "rectify", "minmax"},  # only the power changes
    # The sphere moves (both maps, the view). The β and γ ranges happen to stay, but they live
    # on the device and the integrand is keyed on what decides them, the camera depth among it.
    6: set(),
    8: {"raster.camera", "raster.shadow", "rectify", "minmax"},  # only the medium changes
    11: {"raster.camera", "raster.shadow", "rectify", "minmax", "integrand", "traverse", "visibility", "shade"},  # same as 10
}


@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_sequence_with_reuse_equals_without(device, method):
    scene = parse_scene(ANIMATED)
    session, scratch = Renderer(device), Renderer(device, reuse=False)
    for frame in scene.animation.frames:
        frame_scene = scene.animation.scene_at(scene, frame)
        kept = session.render(frame_scene, method)
        fresh = scratch.render(frame_scene, method)
        np.testing.assert_array_equal(kept.image, fresh.image, err_msg=f"frame {frame}")
        assert not fresh.reused
        if method == "minmax" and frame in EXPECTED_REUSE:
            assert set(kept.reused) == EXPECTED_REUSE[frame], (frame, kept.stage_status)
        if method == "raymarch" and frame == 4:
            assert set(kept.reused) == {"raster.camera", "raster.shadow"}


def test_integrand_follows_what_decides_the_ranges(device):
    """The β and γ ranges the integrand's tables span stay on the device, so its key holds
    what decides them (camera depth, light geometry, camera, image) instead of their values:
    the tables are kept while those, the medium and the light's power stay, and rebuilt when
    the medium or a light's power changes; every image equals one computed from scratch."""
    lights = [PointLight(v3(0.3, 5, -0.5), np.full(3, 60.0)),
              SpotLight(v3(-2, 6, 1), v3(0.2, -1, 0) / np.hypot(0.2, 1), 35.0, np.full(3, 80.0))]
    scene = make_scene(_slats(), lights, **SMALL)
    session, scratch = Renderer(device), Renderer(device, reuse=False)
    brighter_spot = replace(lights[1], intensity=np.full(3, 120.0))
    frames = [
        (scene, "computed"),
        (replace(scene, background=np.full(3, 0.2)), "reused"),  # shading alone
        (replace(scene, medium=replace(scene.medium, sigma_a=np.full(3, 0.03))), "computed"),
        (replace(scene, lights=(lights[0], brighter_spot)), "reused 1 of 2"),  # the spot's power
        (replace(scene, lights=(lights[0], brighter_spot)), None),  # the same frame: kept whole
    ]
    for frame, integrand in frames:
        kept = session.render(frame)
        if integrand is None:
            assert set(kept.stage_status.values()) == {"reused"}
        else:
            assert kept.stage_status["integrand"] == integrand, kept.stage_status
        np.testing.assert_array_equal(kept.image, scratch.render(frame).image)


def test_one_light_moving_keeps_the_others(device):
    scene = parse_scene(ANIMATED)
    session = Renderer(device)
    session.render(scene.animation.scene_at(scene, 9))
    moved = session.render(scene.animation.scene_at(scene, 10))
    assert moved.stage_status["raster.shadow"] == "reused 1 of 2"
    assert moved.stage_status["rectify"] == "reused 1 of 2"
    np.testing.assert_array_equal(moved.image,
                                  Renderer(device, reuse=False).render(scene.animation.scene_at(scene, 10)).image)


SWEEPS = {
    "sigma_s": [dict(sigma_s=s) for s in (0.02, 0.05, 0.1, 0.05)],
    "slices": [dict(slices=s) for s in (32, 64, 32)],
    "integrand": [dict(integrand="svd"), dict(integrand="table"), dict(integrand="svd", svd_rank=2)],
    "phase": [dict(phase=Phase("hg", g)) for g in (0.0, 0.5, -0.3)],
    "traversal": [dict(traversal="tree"), dict(traversal="scan")],
}


@pytest.mark.parametrize("sweep", list(SWEEPS))
def test_sweep_with_reuse_equals_independent_renders(device, sweep):
    sun = v3(0.3, -1, 0.2) / np.linalg.norm(v3(0.3, -1, 0.2))
    lights = [PointLight(v3(0.3, 5, -0.5), np.full(3, 60.0)), DirectionalLight(sun, np.full(3, 1.5))]
    session, scratch = Renderer(device), Renderer(device, reuse=False)
    for n, settings in enumerate(SWEEPS[sweep]):
        scene = make_scene(_slats(), lights, **{**SMALL, **settings})
        kept, fresh = session.render(scene), scratch.render(scene)
        np.testing.assert_array_equal(kept.image, fresh.image, err_msg=f"{sweep} point {n}")
        if n:
            assert {"raster.camera", "raster.shadow"} <= set(kept.reused)
        if n and sweep in ("sigma_s", "integrand", "phase"):
            assert {"rectify", "minmax"} <= set(kept.reused)


def test_identical_frame_is_kept_whole(renderer):
    scene = make_scene(_slats(), **SMALL)
    first = renderer.render(scene)
    again = renderer.render(scene)
    ran = {stage for stage, status in first.stage_status.items() if status != "skipped"}
    assert set(again.reused) == ran and not again.stage_ms  # every stage that ran; the skipped ones stay out
    np.testing.assert_array_equal(first.image, again.image)
    again.image[:] = -1  # results are copies: the kept image is untouched
    np.testing.assert_array_equal(renderer.render(scene).image, first.image)
    assert renderer.render(scene, "raymarch").stage_status["raymarch"] == "computed"  # the method is an input


def test_a_frame_that_keeps_nothing_digests_nothing(device, monkeypatch):
    """Without reuse no key is made: digesting a mesh costs milliseconds a frame (bench/RESULTS.md history,
    host stages); the image is the one a keeping session renders."""
    import clrays.digest

    scene = make_scene(_slats(), lights=[PointLight(v3(0.3, 5, -0.5), np.full(3, 60.0)),
                                         DirectionalLight(v3(0.2, -1, 0.1) / np.linalg.norm([0.2, -1, 0.1]),
                                                          np.full(3, 2.0))], **SMALL)
    kept = Renderer(device).render(scene).image
    fed = []
    feed = clrays.digest._feed
    monkeypatch.setattr(clrays.digest, "_feed", lambda h, value: fed.append(1) or feed(h, value))
    image = Renderer(device, reuse=False).render(scene).image
    assert not fed
    np.testing.assert_array_equal(image, kept)


def test_geometry_passes_are_kept_per_instance():
    """Geometry.bounds and farthest_from pass over every vertex once per instance (the last point
    for farthest_from), and hand out copies."""
    geometry = make_scene(_slats()).geometry
    points = geometry.triangles.reshape(-1, 3)
    lo, hi = geometry.bounds()
    np.testing.assert_array_equal(lo, points.min(axis=0))
    np.testing.assert_array_equal(hi, points.max(axis=0))
    lo[:] = 99.0  # a caller's change stays its own
    np.testing.assert_array_equal(geometry.bounds()[0], points.min(axis=0))
    for eye in ([0, 2, 8], [1, 1, 1], [0, 2, 8]):
        assert geometry.farthest_from(eye) == float(np.sqrt(((points - eye) ** 2).sum(axis=1).max()))
    moved = replace(geometry, triangles=geometry.triangles + 1.0)  # a new instance: its own passes
    np.testing.assert_array_equal(moved.bounds()[1], points.max(axis=0) + 1.0)


def test_exact_frames_are_kept_too(renderer):
    scene = make_scene(box_triangles(v3(-1, 2, -1), v3(1, 2.2, 1)), width=8, height=6)
    assert renderer.render(scene, "exact").stage_status == {"exact": "computed"}
    assert renderer.render(scene, "exact").stage_status == {"exact": "reused"}


def test_no_medium_runs_no_volume_stage(renderer):
    result = renderer.render(make_scene(_slats(), sigma_s=0.0, **SMALL))
    for stage in ("rectify", "minmax", "integrand", "traverse"):
        assert result.stage_status[stage] == "skipped" and stage not in result.stage_ms


@pytest.mark.parametrize("light", [
    SpotLight(v3(0, 4, -2), v3(0, 0.3, 1) / np.hypot(0.3, 1), 30.0, np.full(3, 80.0)),  # over the slats: an empty map
    DirectionalLight(v3(0, -1, 0), np.full(3, 2.0)),
])
def test_nothing_casting_a_shadow_skips_the_tree(device, monkeypatch, light):
    triangles = [] if isinstance(light, DirectionalLight) else _slats()
    # A light that casts no shadow is walked per pixel (its 16 slices are too few lines to
    # sample along), so the full path it stands for is the per-pixel walk too; epipolar
    # sampling of the full texture differs from it by its interpolation (tests/methods/test_epipolar.py).
    scene = make_scene(triangles, [light], **SMALL, sampling="pixel")
    skipping, full = Renderer(device), Renderer(device, reuse=False)
    result = skipping.render(scene)
    assert result.stage_status["rectify"] == "skipped" and result.stage_status["minmax"] == "skipped"
    monkeypatch.setattr(clrays.session, "map_is_empty", lambda device, shadow_map: False)  # the full path
    assert full.render(scene).stage_status["rectify"] == "computed"
    # One lit run either way; only where float32 clips the run's end can differ.
    np.testing.assert_allclose(result.image, full.render(scene).image, rtol=1e-5, atol=1e-7 * result.image.max())
    assert result.image.max() > 0


def test_a_shadowing_light_walks_its_tree(renderer):
    result = renderer.render(make_scene(_slats(), [SpotLight(v3(0, 5, 0), v3(0, -1, 0), 30.0, np.full(3, 80.0))],
                                        **SMALL))
    assert result.stage_status["rectify"] == "computed"


def test_module_render_reuses_between_calls():
    import clrays

    scene = make_scene(_slats(), **SMALL)
    clrays.render(scene)
    assert "raster.shadow" in clrays.render(replace(scene, medium=replace(scene.medium, sigma_a=np.full(3, 0.02))),
                                            stats=True).reused
    assert not clrays.render(scene, stats=True, reuse=False).reused


def test_digest_tells_apart_what_differs():
    a = np.zeros(4, np.float32)
    assert digest(a) != digest(a.astype(np.float64)) and digest(a) != digest(a.reshape(2, 2))
    assert digest(1, 2) != digest((1, 2)) and digest(0.0) != digest(-0.0) and digest(1) != digest(1.0)
    assert digest(np.arange(3.0)) == digest(np.arange(3.0))
    scene = make_scene(_slats())
    assert scene_digest(scene) == scene_digest(replace(scene, source="elsewhere.yaml"))
    assert scene_digest(scene) != scene_digest(replace(scene, render=replace(scene.render, slices=32)))
    assert scene_digest(scene, render=False) == scene_digest(replace(scene, render=replace(scene.render, slices=32)),
                                                             render=False)


def test_stage_cache_keeps_the_most_recent():
    cache = StageCache(2)
    for key in (b"a", b"b", b"c"):
        cache.put("s", key, key.upper())
    assert cache.get("s", b"a") == (False, None) and cache.get("s", b"c") == (True, b"C")
    cache.put("s", b"d", 1, scale=2)
    assert len(cache) == 3
    with pytest.raises(ValueError):
        StageCache(0)


def test_the_bvh_tree_outlives_a_moving_camera(device, monkeypatch):
    """The visibility stage's BVH: its tree is built once per geometry, its boxes refit
    only when the eye moves (not when the camera only turns), and every frame is the
    frame computed from scratch."""
    import clrays.stages.visibility as stage

    calls = {"tree": 0, "refit": 0}

    def counted(name, function):
        def wrapper(*args, **kwargs):
            calls[name] += 1
            return function(*args, **kwargs)
        return wrapper

    monkeypatch.setattr(stage, "TOUCHING_ENTRIES", 0)  # the rays take the BVH, not a thumbnail's lists
    monkeypatch.setattr(stage, "bvh_build_tree", counted("tree", stage.bvh_build_tree))
    monkeypatch.setattr(stage, "bvh_build_refit", counted("refit", stage.bvh_build_refit))
    session = Renderer(device)
    base = make_scene(_slats(), **SMALL)
    cameras = [base.camera, replace(base.camera, look_at=base.camera.look_at + v3(0.5, 0.2, 0)),
               replace(base.camera, position=base.camera.position + v3(1.0, 0.3, 0))]
    for camera in cameras:
        scene = replace(base, camera=camera)
        kept = session.render(scene)
        np.testing.assert_array_equal(kept.image, Renderer(device, reuse=False).render(scene).image)
    # The scratch renders above count too: 3 trees and 3 refits of their own.
    assert calls == {"tree": 1 + 3, "refit": 2 + 3}


def test_the_bvh_is_built_only_for_a_shadow_ray(device, monkeypatch):
    """The maps decide every sample of a floor under a spot with nothing between: no
    shadow ray, no BVH (no `bvh` time). Slats over the floor leave shadow edges to rays:
    then it is built, once, and kept for the next frame."""
    import clrays.stages.visibility as stage

    real, built = stage.bvh_build_tree, []

    def counted(*args):
        built.append(1)
        return real(*args)

    monkeypatch.setattr(stage, "bvh_build_tree", counted)
    monkeypatch.setattr(stage, "TOUCHING_ENTRIES", 0)  # the rays take the BVH, not a thumbnail's lists
    session = Renderer(device)
    floor = make_scene(grid_plane(0.0, 6.0, 2), [SpotLight(v3(0, 4, 0), v3(0, -1, 0), 30.0, np.full(3, 30.0))],
                       **SMALL)
    assert "bvh" not in session.render(floor).stage_ms and built == []
    slats = make_scene(_slats(), **SMALL)
    denser = replace(slats, medium=replace(slats.medium, sigma_s=np.full(3, 0.08)))  # the same surfaces
    first, second = session.render(slats), session.render(denser)
    assert "bvh" in first.stage_ms and "bvh" not in second.stage_ms and built == [1]
    np.testing.assert_array_equal(second.image, Renderer(device, reuse=False).render(denser).image)


def test_shading_normals_are_part_of_a_kept_bound_map(device, monkeypatch):
    """The texels the visibility stage reads follow the shading normals (they turn a surface
    away from the light and offset the shadow ray's start), so the bunny drawn flat and then
    smooth in one session must not reuse the flat frame's bound maps: it renders as it does
    alone. (Measured before the normals were in the key: 25 of the smooth frame's texels
    were never drawn.)"""
    from pathlib import Path

    from clrays.scene.load import load_scene

    path = Path(__file__).resolve().parents[2] / "scenes" / "bunny.yaml"
    size = ["image.width=160", "image.height=90"]
    flat, smooth = (load_scene(path, size + [f"objects.1.normals={normals}"]) for normals in ("flat", "smooth"))
    import clrays.session

    drawn = []
    draw = clrays.session.visibility_bound
    monkeypatch.setattr(clrays.session, "visibility_bound", lambda *args: drawn.append(1) or draw(*args))
    session = Renderer(device)
    session.render(flat)
    kept = session.render(smooth)
    assert len(drawn) == 2  # the smooth frame draws its own bound map
    alone = Renderer(device, reuse=False).render(smooth)
    assert np.array_equal(kept.image, alone.image)
