"""Frames in flight (Renderer.submit, PendingFrame): the host prepares frame N+1 while the
device renders frame N, and the image of N is read only when asked for. The images are
those of one frame at a time, bit for bit; two frames in flight keep their own buffers;
a result is read once; and `clrays sequence` writes the same files, manifest and reports
in the same order, also when a frame fails or is interrupted."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from clrays.device import Device
from clrays.runs.frame_manifest import MANIFEST
from clrays.runs.sequence import render_sequence
from clrays.scene.load import load_scene
from clrays.session import MAX_FRAMES_IN_FLIGHT, Renderer
from conftest import TEST_DEVICE

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def orbit(width: int = 64, height: int = 36, *overrides: str):
    return load_scene(SCENES / "orbit.yaml", overrides=[f"image.width={width}", f"image.height={height}", *overrides])


def orbit_frames(count: int = 4, *overrides: str, size: tuple[int, int] = (64, 36)) -> list:
    scene = orbit(*size, *overrides)
    return [scene.animation.scene_at(scene, frame) for frame in range(count)]


def in_flight(renderer: Renderer, scenes: list) -> list:
    """The results of `scenes`, each submitted before the one before it is read."""
    results, pending = [], None
    for scene in scenes:
        submitted = renderer.submit(scene)
        if pending is not None:
            results.append(pending.result())
        pending = submitted
    return results + [pending.result()]


@pytest.mark.parametrize("reuse", [True, False])
@pytest.mark.parametrize("overrides", [(), ("image.spp=4",), ("render.aovs=[depth, in_scatter, in_scatter_light0]",)],
                         ids=["default", "4 spp", "passes"])
def test_frames_in_flight_are_the_frames_rendered_one_at_a_time(device, reuse, overrides):
    scenes = orbit_frames(4, *overrides)
    session = Renderer(device, reuse=reuse)
    one_at_a_time = [session.render(scene) for scene in scenes]
    pipelined = in_flight(Renderer(device, reuse=reuse), scenes)
    for index, (expected, got) in enumerate(zip(one_at_a_time, pipelined)):
        np.testing.assert_array_equal(got.image, expected.image, err_msg=f"frame {index}")
        assert got.stage_status == expected.stage_status
        assert set(got.stage_ms) == set(expected.stage_ms) and all(ms >= 0 for ms in got.stage_ms.values())
        assert got.samples == expected.samples and got.device_bytes == expected.device_bytes
        assert got.host_waits == expected.host_waits >= 1  # the image's read is one wait, in result()
        assert got.wall_ms > 0
        assert (got.passes is None) == (expected.passes is None) == ("passes" not in str(overrides) and
                                                                      "aovs" not in str(overrides))
        for name in (expected.passes or {}):
            np.testing.assert_array_equal(got.passes[name], expected.passes[name], err_msg=f"{name}, frame {index}")


def test_two_frames_in_flight_keep_their_own_buffers(device):
    """On a CPU device the image is the pooled buffer the kernels wrote (no copy with
    reuse off): the second frame in flight must get another one, and reading it first must
    leave the first frame's image as it renders alone. (At 96×54 the image's buffer is
    large enough to come from the pool: POOLED_BYTES.)"""
    first_scene, second_scene = orbit_frames(4, size=(96, 54))[::3]
    alone = Renderer(device, reuse=False).render(first_scene).image
    renderer = Renderer(device, reuse=False)
    first = renderer.submit(first_scene)
    second = renderer.submit(second_scene)
    second_image = second.result().image
    assert not first.done  # its image not read until asked for
    first_image = first.result().image
    np.testing.assert_array_equal(first_image, alone)
    assert not np.array_equal(first_image, second_image)
    assert not np.shares_memory(first_image, second_image)
    # And an image read before the next frame is submitted stays as it was.
    kept = first_image.copy()
    renderer.submit(second_scene).result()
    np.testing.assert_array_equal(first_image, kept)


def test_a_result_is_read_once(device):
    pending = Renderer(device).submit(orbit_frames(1)[0])
    result = pending.result()
    assert pending.done and pending.result() is result


def test_a_submit_past_the_bound_reads_the_oldest_frame(device):
    renderer = Renderer(device, reuse=False)
    scenes = orbit_frames(MAX_FRAMES_IN_FLIGHT + 1)
    pending = [renderer.submit(scene) for scene in scenes]
    assert pending[0].done and not any(frame.done for frame in pending[1:])
    expected = [Renderer(device, reuse=False).render(scene).image for scene in scenes]
    for frame, image in zip(pending, expected):
        np.testing.assert_array_equal(frame.result().image, image)


def test_a_frame_identical_to_one_in_flight_takes_its_image(device):
    """The frame cache keeps an image once it is read: a second submit of the same scene
    reads the first one's, and renders nothing."""
    scene = orbit_frames(1)[0]
    renderer = Renderer(device)
    first = renderer.submit(scene)
    second = renderer.submit(scene)
    assert first.done
    assert set(second.result().stage_status.values()) == {"reused"}
    np.testing.assert_array_equal(second.result().image, first.result().image)
    second.result().image[:] = 0  # each caller's copy: the kept image is not changed
    np.testing.assert_array_equal(renderer.render(scene).image, first.result().image)


def test_exact_frames_submit_and_read_at_once():
    scene = load_scene(SCENES / "orbit.yaml", overrides=["image.width=8", "image.height=6"])
    result = Renderer().submit(scene, "exact").result()
    assert result.method == "exact" and result.image.shape == (6, 8, 3) and np.isfinite(result.image).all()


# --------------------------------------------------------------------------- clrays sequence


def sequence_outputs(folder: Path) -> tuple[dict[str, bytes], list[dict]]:
    files = {path.name: path.read_bytes() for path in sorted(folder.glob("f_*"))}
    return files, [json.loads(line) for line in (folder / MANIFEST).read_text().splitlines()]


def test_a_sequence_in_flight_writes_what_one_at_a_time_writes(tmp_path, device):
    scene = orbit()
    calls = {}
    for way in (True, False):
        calls[way] = []
        report = render_sequence(scene, tmp_path / str(way) / "f_{:02d}.png", range(4), renderer=Renderer(device),
                                 in_flight=way, on_frame=lambda frame, path, result, way=way: calls[way].append(frame))
        assert report.rendered == [0, 1, 2, 3] and not report.kept
    assert calls[True] == calls[False] == [0, 1, 2, 3]
    assert sequence_outputs(tmp_path / "True") == sequence_outputs(tmp_path / "False")


def test_kept_frames_are_reported_in_order_between_frames_in_flight(tmp_path, device):
    scene = orbit()
    pattern = tmp_path / "f_{:02d}.npy"
    render_sequence(scene, pattern, range(5), renderer=Renderer(device), in_flight=True)
    for frame in (0, 2, 3):
        (tmp_path / f"f_{frame:02d}.npy").unlink()
    order = []
    report = render_sequence(scene, pattern, range(5), renderer=Renderer(device), in_flight=True,
                             on_frame=lambda frame, path, result: order.append((frame, result is None)))
    assert order == [(0, False), (1, True), (2, False), (3, False), (4, True)]
    assert report.rendered == [0, 2, 3] and report.kept == [1, 4]
    alone = Renderer(device, reuse=False)
    for frame in range(5):
        np.testing.assert_array_equal(np.load(tmp_path / f"f_{frame:02d}.npy"),
                                      alone.render(scene.animation.scene_at(scene, frame)).image)


@pytest.mark.parametrize("failure", [KeyboardInterrupt, RuntimeError])
def test_a_frame_that_fails_in_flight_still_has_the_one_before_written(tmp_path, device, monkeypatch, failure):
    """Frame 1 fails (or Ctrl-C) while frame 0 is in flight: frame 0 is written and in the
    manifest, as when each frame was written before the next began."""
    renderer = Renderer(device)
    real_submit, submitted = Renderer.submit, []

    def submit_then_fail(self, *args, **kwargs):
        submitted.append(args[0])
        if len(submitted) == 2:
            raise failure("frame 1")
        return real_submit(self, *args, **kwargs)

    monkeypatch.setattr(Renderer, "submit", submit_then_fail)
    written = []
    with pytest.raises(failure, match="frame 1"):
        render_sequence(orbit(), tmp_path / "f_{:02d}.npy", range(3), renderer=renderer, in_flight=True,
                        on_frame=lambda frame, path, result: written.append(frame))
    assert written == [0] and sorted(p.name for p in tmp_path.glob("f_*")) == ["f_00.npy"]
    assert [json.loads(line)["file"] for line in (tmp_path / MANIFEST).read_text().splitlines()] == ["f_00.npy"]


def test_the_pool_hands_no_buffer_of_a_frame_in_flight_to_the_next(tmp_path):
    """Many frames through a sequence in flight on one pooled device: each file is the
    frame rendered alone on a fresh device."""
    pooled = Device(TEST_DEVICE)
    if pooled.pool_bytes() is None:
        pytest.skip("only a CPU device pools its buffers")
    scene = orbit(96, 54)
    report = render_sequence(scene, tmp_path / "f_{:02d}.npy", range(6), renderer=Renderer(pooled, reuse=False),
                             in_flight=True)
    fresh = Renderer(Device(TEST_DEVICE), reuse=False)
    for frame, path in zip(range(6), report.paths):
        np.testing.assert_array_equal(np.load(path), fresh.render(scene.animation.scene_at(scene, frame)).image,
                                      err_msg=f"frame {frame}")


@pytest.mark.parametrize("in_flight", [True, False, None])
def test_a_frame_is_written_after_the_next_is_submitted_only_in_flight(tmp_path, device, monkeypatch, in_flight):
    """In flight, frame N's file is written after frame N+1 is submitted; one at a time,
    before. By default (None) a sequence is in flight where the session's device gains
    from it: not on a CPU device."""
    real_submit, written_at_submit = Renderer.submit, []

    def submit(self, scene, *args, **kwargs):
        written_at_submit.append(sorted(p.name for p in tmp_path.glob("f_*")))
        return real_submit(self, scene, *args, **kwargs)

    monkeypatch.setattr(Renderer, "submit", submit)
    renderer = Renderer(device)
    render_sequence(orbit(), tmp_path / "f_{:02d}.npy", range(3), renderer=renderer, in_flight=in_flight)
    overlapped = renderer.frames_in_flight_win if in_flight is None else in_flight
    if in_flight is None:
        assert overlapped == (not device.is_cpu)
    expected = [[], [], ["f_00.npy"]] if overlapped else [[], ["f_00.npy"], ["f_00.npy", "f_01.npy"]]
    assert written_at_submit == expected


def test_a_session_without_a_device_has_no_frames_in_flight_to_gain_from():
    assert Renderer().frames_in_flight_win is False
