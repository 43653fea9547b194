"""Light textures in the scene format (docs/light-textures.md): the files a texture may be,
what their texels become, and a one-line error for each bad texture."""
from __future__ import annotations

import re

import numpy as np
import pytest
from PIL import Image

from conftest import run_cli
from clrays.errors import SceneError
from clrays.scene.load import load_scene
from clrays.scene.textures import read_texture, srgb_to_linear

SCENE = """version: 1
image: {width: 8, height: 6}
camera: {position: [0, 2, 6], look_at: [0, 1, 0]}
lights:
  - LIGHT
medium: {sigma_s: 0.1}
"""
SPOT = "{type: spot, position: [0, 4, 0], direction: [0, -1, 0], cone_deg: 30, intensity: 50, texture: TEX}"
SUN = "{type: directional, direction: [0, -1, 0], irradiance: 1, texture: TEX, texture_size: [2, 3]}"


def scene_with(tmp_path, light: str, texture: str = "t.npy"):
    path = tmp_path / "scene.yaml"
    path.write_text(SCENE.replace("LIGHT", light.replace("TEX", texture)))
    return path


def test_npy_texels_are_linear_and_grey_becomes_rgb(tmp_path):
    grey = np.arange(12, dtype=np.float64).reshape(3, 4) / 4
    np.save(tmp_path / "t.npy", grey)
    light = load_scene(scene_with(tmp_path, SPOT)).lights[0]
    assert light.texture.texels.shape == (3, 4, 3) and light.texture.texels.dtype == np.float32
    np.testing.assert_array_equal(light.texture.texels[..., 1], grey.astype(np.float32))


def test_png_texels_are_decoded_from_srgb(tmp_path):
    encoded = np.array([[[0, 128, 255], [188, 10, 64]]], dtype=np.uint8)
    Image.fromarray(encoded, "RGB").save(tmp_path / "t.png")
    texels = read_texture(tmp_path / "t.png")
    np.testing.assert_allclose(texels, srgb_to_linear(encoded / 255.0), rtol=1e-6)
    assert abs(texels[0, 0, 1] - 0.2158605) < 1e-6  # sRGB 128 is 21.6 % linear, not 50 %


def test_exr_texels_are_linear(tmp_path):
    import OpenEXR

    pixels = np.random.default_rng(14).uniform(0, 4, (5, 7, 3)).astype(np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": pixels}) as exr:
        exr.write(str(tmp_path / "t.exr"))
    np.testing.assert_array_equal(read_texture(tmp_path / "t.exr"), pixels)


def test_directional_texture_size_and_wrap(tmp_path):
    np.save(tmp_path / "t.npy", np.ones((2, 2, 3)))
    light = load_scene(scene_with(tmp_path, SUN.replace("}", ", texture_wrap: clamp}"))).lights[0]
    assert light.texture_size == (2.0, 3.0) and light.texture_wrap == "clamp"
    assert load_scene(scene_with(tmp_path, SUN)).lights[0].texture_wrap == "repeat"


def _bad(tmp_path, name, array):
    if array is not None:
        np.save(tmp_path / name, array)
    return name


BAD = [
    ("missing file", lambda d: "nowhere.png", r"got 'nowhere\.png': No such file or directory"),
    ("1-D array", lambda d: _bad(d, "t.npy", np.ones(16)),
     r"got 't\.npy': an array of shape \(16,\), not an image of shape \(H, W\) or \(H, W, 3\)"),
    ("NaN texels", lambda d: _bad(d, "t.npy", np.where(np.eye(4)[..., None] > 0, np.nan, 1.0) * np.ones(3)),
     r"got 't\.npy': nan at texel \(x=0, y=0\), 4 non-finite texel\(s\) in all: texels must be finite"),
    ("negative texels", lambda d: _bad(d, "t.npy", -np.ones((2, 3))),
     r"got 't\.npy': -1 at texel \(x=0, y=0\), 6 negative texel\(s\) in all: a light cannot take light away"),
    ("infinite texels", lambda d: _bad(d, "t.npy", np.full((2, 2), np.inf)), r"inf at texel \(x=0, y=0\)"),
    ("two channels", lambda d: _bad(d, "t.npy", np.ones((2, 2, 2))), r"an array of shape \(2, 2, 2\)"),
    ("not a png", lambda d: (d / "t.png").write_text("hello") and "t.png", r"not a readable PNG image"),
    ("unknown extension", lambda d: "t.jpg", r"a \.jpg file, not \.png, \.exr, \.npy"),
    ("a folder", lambda d: (d / "dir.npy").mkdir() or "dir.npy", r"not a regular file \(a directory\)"),
]


@pytest.mark.parametrize("make, pattern", [case[1:] for case in BAD], ids=[case[0] for case in BAD])
def test_a_bad_texture_is_one_line(tmp_path, make, pattern):
    """Each bad texture: exit 1, one line naming the file, the field and the value."""
    scene = scene_with(tmp_path, SPOT, make(tmp_path))
    code, output = run_cli("render", scene, "-o", tmp_path / "out.png")
    lines = output.strip().splitlines()
    assert code == 1 and len(lines) == 1, output
    assert re.search(r"scene\.yaml:5:\d+: lights\.0\.texture: expected a texture image \(\.png, \.exr or \.npy\) "
                     r"with finite texels >= 0, ", lines[0]), lines[0]
    assert re.search(pattern, lines[0]), lines[0]
    with pytest.raises(SceneError, match=pattern):
        load_scene(scene)


def test_texture_size_needs_a_texture(tmp_path):
    scene = scene_with(tmp_path, "{type: directional, direction: [0, -1, 0], irradiance: 1, texture_size: [1, 1]}")
    with pytest.raises(SceneError, match=r"lights\.0\.texture_size: expected no texture_size without a texture"):
        load_scene(scene)


def test_texture_size_must_be_positive(tmp_path):
    np.save(tmp_path / "t.npy", np.ones((2, 2)))
    with pytest.raises(SceneError, match=r"lights\.0\.texture_size\.1: expected a number > 0, got 0"):
        load_scene(scene_with(tmp_path, SUN.replace("[2, 3]", "[2, 0]")))


POINT = "{type: point, position: [0, 4, 0], intensity: 5, texture: TEX}"


def test_a_point_light_takes_six_faces_or_a_cross(tmp_path):
    faces = [np.full((4, 4), float(f)) for f in range(6)]
    for f, face in enumerate(faces):
        np.save(tmp_path / f"f{f}.npy", face)
    six = load_scene(scene_with(tmp_path, POINT, "[" + ", ".join(f"f{f}.npy" for f in range(6)) + "]"))
    cube = six.lights[0].texture.texels
    assert cube.shape == (24, 4, 3)
    np.testing.assert_array_equal(cube[::4, 0, 0], np.arange(6))
    cross = np.full((12, 16), -1.0)
    for f, (col, row) in enumerate(((0, 1), (2, 1), (1, 0), (1, 2), (1, 1), (3, 1))):
        cross[4 * row:4 * row + 4, 4 * col:4 * col + 4] = f
    np.save(tmp_path / "cross.npy", np.maximum(cross, 0))
    np.testing.assert_array_equal(load_scene(scene_with(tmp_path, POINT, "cross.npy")).lights[0].texture.texels,
                                  cube)


@pytest.mark.parametrize("texture, shapes, pattern", [
    ("[a.npy, a.npy]", {"a.npy": (4, 4)}, r"expected six texture files .*, got 2 files"),
    ("[a.npy, a.npy, a.npy, a.npy, a.npy, b.npy]", {"a.npy": (4, 4), "b.npy": (5, 5)},
     r"expected six square texture images of one size, got .*faces of sizes 4×4, 4×4, 4×4, 4×4, 4×4, 5×5"),
    ("a.npy", {"a.npy": (12, 12)}, r"expected a cross of 4 × 3 square cells.*a 12×12 image"),
    ("[a.npy, a.npy, a.npy, a.npy, a.npy, b.npy]", {"a.npy": (4, 4), "b.npy": (4,)},
     r"lights\.0\.texture\.5: expected a texture image .*an array of shape \(4,\)"),
])
def test_a_bad_cube_texture_is_one_line(tmp_path, texture, shapes, pattern):
    for name, shape in shapes.items():
        np.save(tmp_path / name, np.ones(shape))
    with pytest.raises(SceneError, match=pattern):
        load_scene(scene_with(tmp_path, POINT, texture))


def test_the_example_textures_are_what_make_gobo_draws():
    """scenes/textures/*.png are tools/make_gobo.py's output (it writes them; --check compares)."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    result = subprocess.run([sys.executable, str(root / "tools" / "make_gobo.py"), "--check"], capture_output=True,
                            text=True)
    assert result.returncode == 0, result.stderr


def test_texture_cache_decodes_a_file_once_and_counts_what_the_device_holds(tmp_path):
    """A file named by several lights is one array, counted once; the total is checked
    from each file's header before it is decoded; a cube counts its six faces."""
    from clrays.scene.textures import TextureCache, TextureError

    for name in ("a", "b"):
        np.save(tmp_path / f"{name}.npy", np.full((8, 8), 0.5))
    cache = TextureCache(max_texels=100)
    first = cache.image(tmp_path / "a.npy")
    assert cache.image(tmp_path / "a.npy") is first and cache.texels == 64
    with pytest.raises(TextureError, match=r"a texture of 64 texels from an image of 8×8, more than the 36 left of "
                                           r"the 100 that all the lights' textures may hold together"):
        cache.image(tmp_path / "b.npy")
    cube = TextureCache(max_texels=6 * 64)
    texels = cube.cube_faces([tmp_path / "a.npy"] * 6)
    assert texels.shape == (48, 8, 3) and cube.texels == 6 * 64
    assert cube.cube_faces([tmp_path / "a.npy"] * 6) is texels
    with pytest.raises(TextureError, match=r"a texture of 384 texels"):
        TextureCache(max_texels=6 * 64 - 1).cube_faces([tmp_path / "a.npy"] * 6)
