"""GIF output: one palette for all frames, chosen over the colours the frames hold and
dithered onto, so a light's glow keeps its smooth falloff in 256 colours."""
from __future__ import annotations

import io

import numpy as np
from PIL import Image

from clrays.runs.video import write_gif


def glow_in_fog(height: int = 120, width: int = 160, shift: int = 0) -> np.ndarray:
    """An 8-bit frame like a render's: dim fog over most of it (a gentle vertical ramp) and a
    small bright glow (radius ~24 px) around a light, which holds few pixels but many colours."""
    y, x = np.mgrid[0:height, 0:width].astype(float)
    fog = 12 + 40 * y / height
    falloff = np.exp(-np.hypot(x - 60 - shift, y - 30) / 14.0)
    colour = np.array([1.0, 0.9, 0.75])
    return np.clip(fog[..., None] * np.array([0.9, 0.85, 0.8]) + 240 * falloff[..., None] * colour, 0,
                   255).round().astype(np.uint8)


def decoded(data: bytes | str) -> list[np.ndarray]:
    with Image.open(io.BytesIO(data) if isinstance(data, bytes) else data) as gif:
        frames = []
        for index in range(gif.n_frames):
            gif.seek(index)
            frames.append(np.asarray(gif.convert("RGB")).astype(float))
    return frames


def block_means(image: np.ndarray, block: int = 4) -> np.ndarray:
    """Means over block × block squares: dithering keeps them, bands do not."""
    h, w = image.shape[0] // block * block, image.shape[1] // block * block
    return image[:h, :w].reshape(h // block, block, w // block, block, -1).mean(axis=(1, 3))


def test_a_glow_keeps_its_falloff_without_rings(tmp_path):
    frame = glow_in_fog()
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 256  # more colours than a GIF holds
    write_gif([frame], tmp_path / "a.gif", 40)
    (ours,) = decoded(str(tmp_path / "a.gif"))
    plain = io.BytesIO()  # what clrays wrote before: Pillow's adaptive palette, not dithered
    Image.fromarray(frame).save(plain, format="GIF")
    (before,) = decoded(plain.getvalue())
    # A ring is a band of pixels all off the same way, so it shows in the mean of a block;
    # dithering's noise averages out there.
    worst = {name: np.abs(block_means(image) - block_means(frame.astype(float))).max()
             for name, image in (("ours", ours), ("before", before))}
    print(f"GIF, worst 4×4 block mean off by (levels): {worst}; largest pixel error: ours "
          f"{np.abs(ours - frame).max():.0f}, before {np.abs(before - frame).max():.0f}")
    assert worst["before"] > 4, worst  # the rings (8.4 levels when measured)
    assert worst["ours"] < 1.5, worst  # 1.25 measured
    assert np.abs(ours - frame).max() < np.abs(before - frame).max() / 2  # 10 against 35 levels


def test_frames_share_one_palette_and_keep_their_order(tmp_path):
    frames = [glow_in_fog(shift=shift) for shift in (0, 20, 40)]
    write_gif(frames, tmp_path / "a.gif", 80)
    with Image.open(tmp_path / "a.gif") as gif:
        assert gif.n_frames == 3 and gif.info["loop"] == 0 and gif.info["duration"] == 80
    for source, image in zip(frames, decoded(str(tmp_path / "a.gif"))):
        assert np.abs(block_means(image) - block_means(source.astype(float))).mean() < 1.0
        assert np.abs(image - source).max() <= 12
