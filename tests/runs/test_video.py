"""`--video out.mp4`: H.264 through imageio-ffmpeg's bundled ffmpeg, read back with the
same library (frame count, padded even size, pixel format, and a picture close to the
frames)."""
from __future__ import annotations

import re

import numpy as np
import pytest
from PIL import Image

from conftest import run_cli as run
from test_sequence import write_scene

imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")


def read_mp4(path) -> tuple[dict, list[np.ndarray]]:
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    width, height = meta["size"]
    frames = [np.frombuffer(frame, np.uint8).reshape(height, width, 3) for frame in reader]
    return meta, frames


def test_mp4_has_every_frame_at_an_even_size(tmp_path):
    scene = write_scene(tmp_path, 7)
    code, out = run("sequence", scene, "-o", tmp_path / "f_{:02d}.png", "--video", tmp_path / "a.mp4",
                    "--set", "image.width=47", "--set", "image.height=31")  # odd: padded to 48×32
    assert code == 0, out
    meta, frames = read_mp4(tmp_path / "a.mp4")
    assert len(frames) == 7 and meta["size"] == (48, 32) and meta["fps"] == 12
    assert "h264" in meta["codec"] and "yuv420p" in meta["pix_fmt"]
    first = np.asarray(Image.open(tmp_path / "f_00.png")).astype(float)
    # CRF 18 on a tiny frame: close to the PNG, far from black.
    assert np.abs(frames[0][:31, :47].astype(float) - first).mean() < 6 and first.mean() > 5


def test_crf_and_video_options_reach_the_encoder(tmp_path):
    scene = write_scene(tmp_path, 3)
    sizes = {}
    for crf in (10, 40):
        out = tmp_path / f"crf{crf}.mp4"
        code, text = run("sequence", scene, "-o", tmp_path / "f_{}.png", "--video", out, "--crf", crf,
                         "--video-option", "preset=ultrafast", "--set", "image.width=96", "--set", "image.height=64")
        assert code == 0, text
        sizes[crf] = out.stat().st_size
    assert sizes[40] < sizes[10]
    code, text = run("sequence", scene, "-o", tmp_path / "f_{}.png", "--video", tmp_path / "x.mp4",
                     "--video-option", "preset=nonsense")
    # The frames were there (the run's summary line), then the encoder's refusal in one line.
    error = text.strip().splitlines()[-1]
    assert code == 1 and text.count("clrays: error") == 1, text
    assert re.search(r"x\.mp4: ffmpeg failed: .*invalid preset 'nonsense'$", error) and not (tmp_path / "x.mp4").exists()
