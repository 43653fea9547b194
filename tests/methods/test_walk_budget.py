"""The walk's cost on lattice-like scenes and the error it keeps (docs/walk.md, "A relief's
shadow cut per ray"): a ray of scenes/lattice.yaml spends most of its walk reading its α
bin's outline edges, so the bins are made fine enough that few of those miss its
half-plane; that changes no crossing a ray finds, and the image stays the same to the bit.
Whatever makes the walk cheaper must keep minmax within 0.5 % relative RMSE of `exact` on
these scenes at small sizes."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.scene.load import load_scene
from clrays.stages import relief_cuts as cuts

LATTICE = Path(__file__).resolve().parents[2] / "scenes" / "lattice.yaml"


def _lattice(tmp_path, size: tuple[int, int], camera: str | None = None, sun: str | None = None):
    """scenes/lattice.yaml at `size`, with another camera or sun direction where given."""
    text = LATTICE.read_text().replace("textures/lattice.png", str(LATTICE.parent / "textures" / "lattice.png"))
    if camera is not None:
        text = text[:text.index("camera:")] + camera + text[text.index("lights:"):]
    if sun is not None:
        text = text.replace("direction: [0.25, -0.45, 1.0]", f"direction: {sun}")
    path = tmp_path / "lattice.yaml"
    path.write_text(text)
    return load_scene(path, overrides=[f"image.width={size[0]}", f"image.height={size[1]}"])


def _render_binned(renderer, scene, monkeypatch, entries_per_edge: int):
    """The minmax image with the bins doubled towards `entries_per_edge` (0: only until every
    bin holds RELIEF_CROSSINGS edges at most), and what alpha_bins was given and gave."""
    from clrays.session import Renderer

    seen = {}
    alpha_bins = cuts.alpha_bins

    def recorded(ends, u, w):
        binned = alpha_bins(ends, u, w)
        seen.update(ends=ends, u=u, w=w, bins=binned[0], offsets=binned[1])
        return binned

    monkeypatch.setattr(cuts, "ENTRIES_PER_EDGE", entries_per_edge)
    monkeypatch.setattr(cuts, "alpha_bins", recorded)
    image = np.array(Renderer(renderer.device, reuse=False).render(scene, "minmax").image, copy=True)
    monkeypatch.undo()
    return image, seen


def _edges_read_and_crossing(seen, samples: int = 2000) -> tuple[float, float]:
    """Over rays at α spread evenly across the outline's angles: the mean count of edges a ray
    reads (its bin's) and of those whose arc of α holds the ray's α (which cross its plane)."""
    x, y = seen["ends"] @ seen["u"], seen["ends"] @ seen["w"]
    alpha = np.arctan2(y, x)
    sweep = np.remainder(alpha[:, 1] - alpha[:, 0] + math.pi, 2 * math.pi) - math.pi
    low, high = np.minimum(alpha[:, 0], alpha[:, 0] + sweep), np.maximum(alpha[:, 0], alpha[:, 0] + sweep)
    rays = np.random.default_rng(5).uniform(np.percentile(low, 1), np.percentile(high, 99), samples)
    bins = seen["bins"]
    counts = np.diff(seen["offsets"])
    read = counts[np.floor((rays + math.pi) / (2 * math.pi) * bins).astype(int)]
    crossing = ((low[None, :] <= rays[:, None]) & (rays[:, None] <= high[None, :])).sum(axis=1)
    return float(read.mean()), float(crossing.mean())


def test_finer_bins_read_fewer_edges_and_make_the_same_image(renderer, monkeypatch):
    """The lattice from its own camera: with the bins doubled only until none holds over 256
    edges (4096), a ray read 1.6× the edges that cross its half-plane (132 for 82);
    doubled on towards 16 entries per edge (16384), 1.16×. The crossings a ray finds are the
    same, in the same order, so the image is the same to the bit."""
    scene = load_scene(LATTICE, overrides=["image.width=96", "image.height=54"])
    coarse, coarse_bins = _render_binned(renderer, scene, monkeypatch, 0)
    fine, fine_bins = _render_binned(renderer, scene, monkeypatch, cuts.ENTRIES_PER_EDGE)
    np.testing.assert_array_equal(fine, coarse)
    assert fine.max() > 0
    assert fine_bins["bins"] > coarse_bins["bins"]
    assert fine_bins["offsets"][-1] >= cuts.ENTRIES_PER_EDGE * len(fine_bins["ends"])
    coarse_read, crossing = _edges_read_and_crossing(coarse_bins)
    fine_read, _ = _edges_read_and_crossing(fine_bins)
    print(f"edges a ray reads: {coarse_read:.1f} at {coarse_bins['bins']} bins, {fine_read:.1f} at "
          f"{fine_bins['bins']}, {crossing:.1f} crossing its half-plane")
    assert fine_read < 1.25 * crossing < coarse_read


def test_the_bins_stop_doubling_at_the_entry_limit(monkeypatch):
    """Doubling towards ENTRIES_PER_EDGE never passes MAX_BINNED_EDGES: a wide outline keeps
    the bins where the next doubling would write more entries than that."""
    rng = np.random.default_rng(11)
    centres = rng.normal(size=(3000, 1, 3)) * [3.0, 3.0, 1.0]
    ends = centres + rng.normal(size=(3000, 2, 3)) * 0.2
    u, w = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    unlimited = cuts.alpha_bins(ends, u, w)
    assert unlimited[1][-1] >= cuts.ENTRIES_PER_EDGE * len(ends) or unlimited[0] == cuts.MAX_BINS
    monkeypatch.setattr(cuts, "MAX_BINNED_EDGES", int(unlimited[1][-1]) - 1)
    limited = cuts.alpha_bins(ends, u, w)
    assert limited is not None and limited[0] < unlimited[0] and limited[1][-1] <= cuts.MAX_BINNED_EDGES


# Lattice-like scenes against exact at small sizes, relative RMSE over the whole image, depth
# edges out, measured on Intel's CPU runtime: 0.208 % at 160×90 from the scene's camera.
SCENES = {
    "own camera, 160×90": dict(size=(160, 90)),
    "low sun, 96×54": dict(size=(96, 54), sun="[0.2, -0.2, 1.0]"),
    "along the shafts, 96×54": dict(size=(96, 54), camera="camera: {position: [0.3, 1.2, 1.5], "
                                                          "look_at: [0.0, 2.6, -4.2], fov_deg: 70, far: 12}\n"),
}


@pytest.mark.parametrize("name", list(SCENES))
def test_the_lattice_walk_keeps_its_error_against_exact(renderer, tmp_path, name):
    scene = _lattice(tmp_path, **SCENES[name])
    exact = renderer.render(scene, "exact").image
    error = image_error(renderer.render(scene, "minmax").image, exact, depth_edges(depth_map(scene)))
    print(f"lattice, {name}: minmax against exact: {error}")
    assert exact.max() > 0 and error.pixels > 0
    assert error.rmse < 0.005
