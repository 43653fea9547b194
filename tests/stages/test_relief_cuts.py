"""A relief's shadow cut per ray (clrays/stages/relief_cuts.py, cl/relief_cuts.h): its outline
seen from the light, the eye's own count, the α bins, and the walks against `exact` where
the eye itself lies in the relief's shadow."""
import math
from pathlib import Path

import numpy as np

from clrays.reference.metrics import depth_edges, depth_map, image_error, luminance
from clrays.scene.load import load_scene
from clrays.stages.relief_cuts import MAX_BINNED_EDGES, alpha_bins, eye_layers, nudged_eye, relief_outline
from conftest import DirectionalLight, PointLight, v3

LATTICE = Path(__file__).resolve().parents[2] / "scenes" / "lattice.yaml"
SUN = DirectionalLight(v3(0.0, -1.0, 0.0), np.ones(3))  # straight down


def _square(y: float = 0.0) -> np.ndarray:
    """Two triangles over [0, 1]² at height y, facing up, sharing the diagonal (0,0)–(1,1)."""
    a, b, c, d = [0.0, y, 0.0], [1.0, y, 0.0], [1.0, y, 1.0], [0.0, y, 1.0]
    return np.array([[a, c, b], [a, d, c]], dtype=np.float64)


def test_a_square_is_outlined_by_its_border():
    """Seen from above, the shared diagonal changes nothing: two triangles facing one way lie
    either side of it. Each of the four sides changes the count by one."""
    ends, change = relief_outline(_square(), SUN)
    assert len(ends) == 4 and (np.abs(change) == 1).all()
    middle = ends.mean(axis=1)
    assert not np.any(np.all(np.isclose(middle, [0.5, 0.0, 0.5]), axis=1))  # the diagonal is gone


def test_a_fold_counts_twice_and_an_edge_on_face_not_at_all():
    """A square folded back under itself along x = 1 (a ridge seen from the light): both
    halves lie on one side of the fold, which changes the count by two. A face that the
    light grazes lies on neither side of its edges."""
    b, c = [1.0, 0.0, 0.0], [1.0, 0.0, 1.0]
    back_a, back_d = [0.0, -0.5, 0.0], [0.0, -0.5, 1.0]
    folded = np.concatenate([_square(), np.array([[back_a, b, c], [back_a, c, back_d]])])
    ends, change = relief_outline(folded, SUN)
    at_fold = np.all(np.isclose(ends[:, :, 0], 1.0) & np.isclose(ends[:, :, 1], 0.0), axis=1)
    assert np.abs(change[at_fold]).tolist() == [2.0]
    wall = np.array([[[1.0, 0.0, 0.0], [1.0, -0.5, 1.0], [1.0, -0.5, 0.0]],
                     [[1.0, 0.0, 0.0], [1.0, 0.0, 1.0], [1.0, -0.5, 1.0]]])  # vertical: edge-on to the sun
    ends, change = relief_outline(np.concatenate([_square(), wall]), SUN)
    at_top = np.all(np.isclose(ends[:, :, 0], 1.0) & np.isclose(ends[:, :, 1], 0.0), axis=1)
    assert np.abs(change[at_top]).tolist() == [1.0]  # the square's side alone
    assert len(ends) == 4  # the wall's own edges change nothing


def test_the_eye_counts_what_lies_between_it_and_the_light():
    square = _square(2.0)
    assert eye_layers(square, np.array([0.3, 0.0, 0.6]), SUN) == 1
    assert eye_layers(square, np.array([1.3, 0.0, 0.6]), SUN) == 0
    assert eye_layers(square, np.array([0.3, 3.0, 0.6]), SUN) == 0  # above it: nothing towards the sun
    lamp = PointLight(v3(0.5, 1.0, 0.5), np.ones(3))
    assert eye_layers(square, np.array([0.3, 0.0, 0.6]), lamp) == 0  # the lamp is below the square
    assert eye_layers(np.concatenate([square, _square(1.5)]), np.array([0.3, 0.0, 0.6]), SUN) == 2
    # On the shared diagonal both triangles hold the eye's light ray; the walks start beside
    # it (nudged_eye), where one does; so on a vertex four triangles share.
    assert eye_layers(square, np.array([0.5, 0.0, 0.5]), SUN) == 2
    assert eye_layers(square, nudged_eye(np.array([0.5, 0.0, 0.5]), SUN, 10.0), SUN) == 1
    grid = np.concatenate([square + [dx, 0.0, dz] for dx in (0.0, 1.0) for dz in (0.0, 1.0)])
    lamp = PointLight(v3(1.0, 5.0, 1.0), np.ones(3))
    for light in (SUN, lamp):
        assert eye_layers(grid, nudged_eye(np.array([1.0, 0.0, 1.0]), light, 10.0), light) == 1
    nudge = nudged_eye(np.array([1.0, 0.0, 1.0]), lamp, 10.0) - [1.0, 0.0, 1.0]
    assert 5e-6 < np.linalg.norm(nudge) < 2e-5 and abs(nudge @ [0.0, 1.0, 0.0]) < 1e-12  # across the light ray


def test_every_edge_is_in_the_bins_of_the_angles_it_spans():
    rng = np.random.default_rng(7)
    ends = rng.normal(size=(300, 2, 3)) * [3.0, 3.0, 1.0]
    u, w = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    bins, offsets, binned, distance = alpha_bins(ends, u, w)
    assert offsets[-1] == len(binned) <= MAX_BINNED_EDGES
    for s in np.linspace(0.0, 1.0, 9):
        points = ends[:, 0] + s * (ends[:, 1] - ends[:, 0])
        alpha = np.arctan2(points @ w, points @ u)
        where = np.clip(np.floor((alpha + math.pi) / (2 * math.pi) * bins).astype(int), 0, bins - 1)
        for edge, bin_ in enumerate(where):
            assert edge in binned[offsets[bin_]:offsets[bin_ + 1]]
        # no point of an edge is nearer the light ray than its distance says
        assert (np.hypot(points @ u, points @ w) >= distance - 1e-12).all()


def _lattice_from(tmp_path, camera: str, lights: str | None = None):
    text = LATTICE.read_text()
    start, end = text.index("camera:"), text.index("lights:")
    text = text[:start] + camera + text[end:]
    if lights is not None:
        text = text[:text.index("lights:")] + lights + text[text.index("medium:"):]
    path = tmp_path / "lattice.yaml"
    path.write_text(text.replace("textures/lattice.png", str(LATTICE.parent / "textures" / "lattice.png")))
    return load_scene(path, overrides=["image.width=64", "image.height=40"])


def test_an_eye_in_the_lattices_shadow_matches_exact(renderer, tmp_path):
    """The eye on a bar's shadow in the sun's shaft, looking along it into the room: every ray
    starts shadowed (the eye's count is 1) and leaves the shadow where the bars' edges cross
    it. Measured against exact, whole image, depth edges out: 0.075 % relative RMSE."""
    scene = _lattice_from(tmp_path, "camera: {position: [0.5, 1.6, -2.1], look_at: [1.5, 0.6, 1.0], fov_deg: 70, "
                                    "far: 12}\n")
    triangles = scene.geometry.triangles[scene.geometry.reliefs[0].rows].astype(np.float64)
    assert eye_layers(triangles, np.asarray(scene.camera.position, np.float64), scene.lights[0]) == 1
    exact = renderer.render(scene, "exact").image
    error = image_error(renderer.render(scene, "minmax").image, exact, depth_edges(depth_map(scene)))
    print(f"eye in the lattice's shadow, 64×40, minmax against exact: {error}")
    assert exact.max() > 0 and error.rmse < 0.005


def test_the_lattices_sunlit_floor_matches_exact_pixel_for_pixel(renderer):
    """Surfaces seen through the lattice's holes: the maps' 3 × 3 shadowed test calls a
    sample shadowed when the nine texel centres around it are blocked, and a hole finer than
    a texel lets light through between them, so with a relief every sample the maps do not
    call lit casts its shadow ray (stages/visibility.py). Without the medium, at 320×180: no
    pixel off `exact` by 0.1 % (two floor pixels were 90 % and 73 % dark with the test)."""
    scene = load_scene(LATTICE, overrides=["image.width=320", "image.height=180", "medium.sigma_s=0",
                                           "medium.sigma_a=0"])
    exact = luminance(renderer.render(scene, "exact").image)
    ours = luminance(renderer.render(scene, "minmax").image)
    off = (np.abs(ours - exact) > 1e-3 * np.maximum(exact, 1e-2)) & ~depth_edges(depth_map(scene))
    assert exact.max() > 0 and int(off.sum()) == 0, np.argwhere(off)[:5].tolist()


def test_an_outline_the_bins_cannot_hold_is_read_from_the_map(renderer, monkeypatch):
    """Where no count of bins holds the outline within the limits (an eye right beside a
    large relief, or a relief of many edges at a grazing light), the light reads its
    relief from the map, as a device without 64-bit keys does: the same image."""
    from clrays.session import Renderer
    from clrays.stages import raster as raster_stage
    from clrays.stages import relief_cuts as cuts

    scene = load_scene(LATTICE, overrides=["image.width=48", "image.height=27"])
    cut = Renderer(renderer.device, reuse=False).render(scene, "minmax").image
    monkeypatch.setattr(cuts, "MAX_BINNED_EDGES", 1000)  # the lattice's 13 k edges take 39 k entries at 16 bins
    from_map = Renderer(renderer.device, reuse=False).render(scene, "minmax").image
    monkeypatch.setattr(raster_stage, "_atomic64", lambda device: False)
    no_keys = Renderer(renderer.device, reuse=False).render(scene, "minmax").image
    np.testing.assert_array_equal(from_map, no_keys)
    assert not np.array_equal(cut, from_map)
    monkeypatch.setattr(cuts, "MAX_BINNED_EDGES", 4 * 2**20)
    monkeypatch.setattr(cuts, "RELIEF_CROSSINGS", 4)  # every bin too full, even at MAX_BINS
    assert cuts.alpha_bins(np.random.default_rng(1).normal(size=(5000, 2, 3)), np.array([1.0, 0, 0]),
                           np.array([0, 1.0, 0])) is None
    assert cuts.alpha_bins(np.zeros((0, 2, 3)), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))[0] == cuts.MIN_BINS


def test_a_light_that_cuts_a_relief_walks_every_camera_sample(renderer):
    """The relief's shafts run along the epipolar lines and are finer than they are apart:
    its light walks every camera sample's rays, and `--stats` counts them all fixed up."""
    scene = load_scene(LATTICE, overrides=["image.width=32", "image.height=18"])
    counts = renderer.render(scene, "minmax", reuse=False).samples
    assert (counts.computed, counts.interpolated, counts.fixed_up) == (0, 0, 32 * 18)


def test_a_moving_camera_keeps_only_what_holds(renderer):
    """The outline is kept per light, its bins per eye: a session that keeps its stages gives
    each frame of a camera moving past the lattice bit for bit as one that keeps none."""
    from clrays.session import Renderer

    keeping, fresh = Renderer(renderer.device), Renderer(renderer.device, reuse=False)
    for x in (2.6, 1.0, 2.6):
        scene = load_scene(LATTICE, overrides=["image.width=40", "image.height=24", f"camera.position=[{x}, 1.4, 3.2]"])
        assert np.array_equal(keeping.render(scene, "minmax").image, fresh.render(scene, "minmax").image)


def test_an_empty_outline_leaves_only_the_eyes_count(renderer):
    """A relief seen edge-on from its light has no outline: no bin holds an edge, and the
    walks keep the eye's count alone."""
    from types import SimpleNamespace

    from clrays.inputs import frame_inputs
    from clrays.stages.rectify import epipolar_frame
    from clrays.stages.relief_cuts import relief_cuts

    inputs = frame_inputs(load_scene(LATTICE, overrides=["image.width=32", "image.height=18"]))
    params = epipolar_frame(inputs.scene, SimpleNamespace(inputs=inputs), 0)
    cuts = relief_cuts(renderer.device, inputs.scene, 0, (np.zeros((0, 2, 3)), np.zeros(0)),
                       np.asarray(inputs.eye_ws, np.float64), params)
    assert cuts is not None and cuts.eye_count == 0 and cuts.bins == 1024
