"""Layer 5: golden images. Small scenes rendered now against the float32 linear radiance
stored in tests/golden/data/, so that a change anywhere in the pipeline that moves an
image shows up, even where every other test's tolerance would let it through.

The references are PoCL renders, and PoCL renders are deterministic (the same process
or a fresh one, the same bits), so the tolerance only leaves room for a compiler's
reordering. On another device the comparison is skipped: float32 arithmetic there
rounds differently, and the technique tests (tests/methods) cover it.

Regenerate, after a change that is meant to move images, with
`pytest tests/golden --regen-golden`, and say in the commit why the images moved.
"""
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import clrays
from conftest import DirectionalLight, PointLight, SpotLight, box_triangles, grid_plane, make_scene, v3

DATA = Path(__file__).resolve().parent / "data"
SCENES_DIR = Path(__file__).resolve().parents[2] / "scenes"

#: Largest relative RMSE, sqrt(mean((image - golden)²)) / mean(golden) over all channels.
RELATIVE_RMSE_MAX = 1e-5


def _unit(*xs) -> np.ndarray:
    x = np.array(xs, dtype=float)
    return x / np.linalg.norm(x)


def _boxes() -> np.ndarray:
    """A floor, a slab on a post and a pillar: shafts, shadowed floor, a depth edge."""
    return np.concatenate([grid_plane(0.0, 8.0, 4), box_triangles([-1.2, 1.6, -1.0], [1.0, 1.9, 0.8]),
                           box_triangles([-0.2, 0.0, -0.2], [0.2, 1.6, 0.2]),
                           box_triangles([1.6, 0.0, -2.2], [2.4, 2.6, -1.4])])


def _made(light, **render):
    return make_scene(_boxes(), [light], width=64, height=64, position=(0, 2.2, 8), look_at=(0, 1.6, 0),
                      far=25.0, sigma_s=0.08, sigma_a=0.02, shadow_map=256, slices=128, gamma_samples=256,
                      **render)


POINT = PointLight(v3(0.4, 4.5, -0.6), np.full(3, 40.0))

_GLASS_ROW = ["image.width=64", "image.height=36", "render.transparency={type: depth_peeling, layers: 8}"]

#: name → (scene builder, method). Builders, so that collecting the tests loads nothing.
GOLDEN = {
    "point_box": (lambda: _made(POINT), "minmax"),
    # Uniform steps: the marcher before equiangular steps, whose golden stays as it was.
    "point_box_raymarch": (lambda: _made(POINT, steps=256, step_spacing="uniform"), "raymarch"),
    "point_box_raymarch_equiangular": (lambda: _made(POINT, steps=256), "raymarch"),
    "spot": (lambda: _made(SpotLight(v3(0.3, 5.0, -0.5), _unit(0.1, -1.0, 0.1), 35.0, np.full(3, 60.0))),
             "minmax"),
    "directional": (lambda: _made(DirectionalLight(_unit(0.35, -1.0, -0.25), np.full(3, 1.5))), "minmax"),
    "demo": (lambda: clrays.load_scene(SCENES_DIR / "demo.yaml",
                                       overrides=["image.width=64", "image.height=36", "render.shadow_map=512",
                                                  "render.slices=1024", "render.gamma_samples=1024"]),
             "minmax"),
    # Translucent panes composited by depth peeling: MBOIT's one walk (transparency_walk.cl) left
    # this path as it was, bit for bit (these were written before it).
    "glass_row_peeling": (lambda: clrays.load_scene(SCENES_DIR / "glass_row.yaml", overrides=_GLASS_ROW), "minmax"),
    "glass_row_peeling_raymarch": (lambda: clrays.load_scene(SCENES_DIR / "glass_row.yaml",
                                                             overrides=[*_GLASS_ROW, "render.steps=64",
                                                                       "render.step_spacing=uniform"]), "raymarch"),
}


def relative_rmse(image: np.ndarray, reference: np.ndarray) -> float:
    return float(np.sqrt(np.mean((image.astype(np.float64) - reference) ** 2)) / np.mean(reference))


def _write_failure(directory: Path, image: np.ndarray, reference: np.ndarray) -> list[Path]:
    """render.npy, reference.npy and diff.png (|difference|, brightest = largest) in `directory`."""
    paths = [directory / "render.npy", directory / "reference.npy", directory / "diff.png"]
    np.save(paths[0], image)
    np.save(paths[1], reference)
    difference = np.abs(image.astype(np.float64) - reference)
    scale = difference.max() if difference.max() > 0 else 1.0
    Image.fromarray(np.round(255 * difference / scale).astype(np.uint8)).save(paths[2])
    return paths


@pytest.mark.parametrize("name", GOLDEN)
def test_render_matches_golden_image(renderer, device, request, tmp_path, name):
    if "Portable Computing Language" not in device.device.platform.name:
        pytest.skip(f"golden images are PoCL renders; this session runs on {device.name}")
    build, method = GOLDEN[name]
    image = renderer.render(build(), method, reuse=False).image
    path = DATA / f"{name}.npy"
    if request.config.getoption("--regen-golden"):
        DATA.mkdir(exist_ok=True)
        np.save(path, image)
        pytest.skip(f"wrote {path}")
    assert path.is_file(), f"{path} is missing: run `pytest tests/golden --regen-golden`"
    reference = np.load(path)
    assert image.shape == reference.shape, f"shape {image.shape}, golden {reference.shape}"
    assert np.isfinite(image).all()
    error = relative_rmse(image, reference)
    if error > RELATIVE_RMSE_MAX:
        render_path, reference_path, diff_path = _write_failure(tmp_path, image, reference)
        pytest.fail(f"{name} ({method}): relative RMSE {error:.2e} > {RELATIVE_RMSE_MAX:.0e} against {path}\n"
                    f"  render:    {render_path}\n  reference: {reference_path}\n  diff:      {diff_path}")
