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


@pytest.mark.parametrize("option", ["f=null", "y={elsewhere}", "an={elsewhere}", "vstats_file={elsewhere}",
                                    "passlogfile={elsewhere}", "x264-params=stats={elsewhere}", "-f=null"])
def test_only_encoding_options_reach_ffmpeg(tmp_path, option):
    # f=null wrote a 0-byte a.mp4 with exit 0 and "wrote a.mp4"; y= and an= made ffmpeg write a
    # second copy at any path, vstats_file= a text file.
    elsewhere = tmp_path / "elsewhere.mp4"
    scene = write_scene(tmp_path, 2)
    code, out = run("sequence", scene, "-o", tmp_path / "f_{}.png", "--video", tmp_path / "a.mp4",
                    "--video-option", option.format(elsewhere=elsewhere))
    key = option.partition("=")[0].lstrip("-")
    lines = out.strip().splitlines()
    assert code == 1 and len(lines) == 1, out
    assert re.fullmatch(rf"clrays: error: --video-option .*: '{re.escape(key)}' is not an encoding option clrays "
                        rf"passes to ffmpeg; expected one of crf, qp, preset, .*, movflags", lines[0]), lines[0]
    assert not list(tmp_path.glob("*.mp4")) and not list(tmp_path.glob("f_*.png"))  # refused before rendering


def test_aliases_and_listed_options_are_accepted():
    from pathlib import Path

    from clrays.runs.video import video_encoder_options

    chosen = video_encoder_options(Path("a.mp4"), 20, ["b=2M", "profile=high", "tune=animation", "g=12"])
    assert chosen["b:v"] == "2M" and chosen["profile:v"] == "high" and chosen["crf"] == "20"
    assert "b" not in chosen and "profile" not in chosen


def test_an_encoder_that_writes_nothing_is_an_error_not_a_video(tmp_path, monkeypatch):
    from clrays.errors import OutputError
    from clrays.runs.video import write_mp4

    monkeypatch.setattr(imageio_ffmpeg, "get_ffmpeg_exe", lambda: "true")  # exit 0, no file
    frames = [np.zeros((4, 4, 3), np.uint8)] * 2
    with pytest.raises(OutputError, match=r"a\.mp4: ffmpeg exited without writing the video$"):
        write_mp4(frames, tmp_path / "a.mp4", 12, {})
    assert not list(tmp_path.iterdir())
    with pytest.raises(OutputError, match=r"'f' is not an encoding option"):  # the library's callers too
        write_mp4(frames, tmp_path / "a.mp4", 12, {"f": "null"})
