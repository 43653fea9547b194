"""Sequences and sweeps on a 2-worker dask LocalCluster (real processes, each with its own
PoCL session): the same bytes as in-process, a worker killed mid-run, resume; and a plain
run that never imports dask or imageio-ffmpeg."""
from __future__ import annotations

import contextlib
import csv
import json
import os
import re
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from clrays.runs.sequence import render_sequence
from clrays.runs.sweep import run_sweep
from clrays.scene.load import load_scene
from clrays.session import Renderer
from test_sequence import write_scene

distributed = pytest.importorskip("distributed")
from clrays.runs.distributed import CONNECT_TIMEOUT_S, DaskExecutor  # noqa: E402

FRAMES = 12
SMALL = ["image.width=32", "image.height=24"]


@pytest.fixture(scope="module")
def executor():
    # Spawned workers inherit CLRAYS_DEVICE, which conftest pins to the test device.
    with DaskExecutor(workers=2) as running:
        running.client.wait_for_workers(2, timeout=120)
        yield running


def _file_bytes(folder: Path, pattern: str = "f_*") -> dict[str, bytes]:
    return {path.name: path.read_bytes() for path in sorted(folder.glob(pattern))}


def test_sequence_on_two_workers_is_byte_identical(tmp_path, executor):
    # Only the camera moves (no object keys), so a session reuses the shadow map.
    scene = load_scene(write_scene(tmp_path, FRAMES), SMALL + ["animation.objects=[]"])
    here, there = tmp_path / "here", tmp_path / "there"
    render_sequence(scene, here / "f_{:03d}.npy", renderer=Renderer())
    report = render_sequence(scene, there / "f_{:03d}.npy", executor=executor)
    assert report.rendered == list(range(FRAMES)) and not report.kept
    assert _file_bytes(there) == _file_bytes(here) and len(_file_bytes(here)) == FRAMES
    # Each worker rendered its run of frames on one session: beyond its first frame, the
    # shadow map (the light stands still) was reused.
    reused = sum(result.stage_status.get("raster.shadow") == "reused" for result in report.results.values())
    assert reused >= FRAMES - 2 - 2  # work stealing may move a frame or two to the other worker


def _rows(folder: Path) -> list[dict[str, str]]:
    """results.csv without what depends on timing or on which session rendered a point
    (`reused` / `computed`: a worker's first point computes what in-process was reused)."""
    with open(folder / "results.csv", newline="") as f:
        return [{key: value for key, value in row.items() if not key.endswith("_ms") and key not in ("reused", "computed")}
                for row in csv.DictReader(f)]


def test_sweep_on_two_workers_gives_the_same_rows_and_images(tmp_path, executor):
    scene = write_scene(tmp_path, 2)
    spec = ["medium.sigma_s=0.03,0.08", "render.slices=32,64,128"]
    # With a reference, so the workers also compute the error columns (and cache the references).
    options = dict(overrides=SMALL, contact_sheet=False, reference="raymarch:64")
    here = run_sweep(scene, spec, tmp_path / "here", renderer=Renderer(), **options)
    there = run_sweep(scene, spec, tmp_path / "there", executor=executor, **options)
    assert all(row["error_mean_pct"] for row in there.rows)
    assert sorted(there.rendered) == list(range(6)) and len(here.rows) == 6
    assert _rows(tmp_path / "there") == _rows(tmp_path / "here")
    assert _file_bytes(tmp_path / "there", "*.png") == _file_bytes(tmp_path / "here", "*.png")


def test_a_worker_killed_midway_loses_only_its_frame_and_resume_renders_nothing_twice(tmp_path, executor):
    scene = load_scene(write_scene(tmp_path, 24), ["image.width=64", "image.height=48"])
    pattern = tmp_path / "run" / "f_{:03d}.npy"
    client = executor.client
    before = set(client.scheduler_info()["workers"])
    killed_at = []

    def kill_one_worker(frame, path, result):
        if not killed_at:
            victim = sorted(client.scheduler_info()["workers"])[0]
            # Exit a moment after replying, so that the call returns; the worker's frames are in flight.
            client.run(lambda: threading.Timer(0.1, os._exit, (1,)).start(), workers=[victim])
            killed_at.append(time.monotonic())

    report = render_sequence(scene, pattern, on_frame=kill_one_worker, executor=executor)
    assert sorted(report.rendered + report.kept) == list(range(24))
    assert set(client.scheduler_info()["workers"]) != before  # the victim did die (its nanny restarts it)
    reference = tmp_path / "here"
    render_sequence(scene, reference / "f_{:03d}.npy", renderer=Renderer())
    assert _file_bytes(tmp_path / "run") == _file_bytes(reference)

    again = render_sequence(scene, pattern, executor=executor)
    assert again.rendered == [] and again.kept == list(range(24))
    client.wait_for_workers(2, timeout=120)


def _running_tasks(dask_worker) -> int:
    return len(dask_worker.state.all_running_tasks)  # cancelled tasks still running included


def _wait_until_idle(client, timeout: float = 120.0) -> None:
    """Until no worker thread runs a task, cancelled ones included (an interrupted run
    cancels its futures, but a frame already running finishes and writes its file): a
    fixed sleep raced such frames on a loaded machine."""
    deadline = time.monotonic() + timeout
    while any(client.processing().values()) or any(client.run(_running_tasks).values()):
        assert time.monotonic() < deadline, f"workers still busy after {timeout:g} s"
        time.sleep(0.1)


def test_an_interrupted_run_resumes_with_the_missing_frames_only(tmp_path, executor):
    scene = load_scene(write_scene(tmp_path, FRAMES), SMALL)
    pattern = tmp_path / "f_{:03d}.png"

    def stop_after_four(frame, path, result):
        if result is not None and len([p for p in tmp_path.glob("f_*.png")]) >= 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_sequence(scene, pattern, on_frame=stop_after_four, executor=executor)
    _wait_until_idle(executor.client)  # a frame in flight on a worker may still land; it then counts as done
    present = {int(p.stem[2:]) for p in tmp_path.glob("f_*.png")}
    assert 4 <= len(present) < FRAMES
    resumed = render_sequence(scene, pattern, executor=executor)
    assert set(resumed.rendered).isdisjoint(present) and set(resumed.kept) == present
    assert sorted(resumed.rendered + resumed.kept) == list(range(FRAMES))


def test_cli_sweep_on_local_workers(tmp_path):
    from conftest import run_cli

    scene = write_scene(tmp_path, 2)
    code, out = run_cli("sweep", scene, "--set", "render.slices=32,64", *[a for s in SMALL for a in ("--set", s)],
                        "--workers", "2", "-o", tmp_path / "sweep")
    assert code == 0, out
    assert "2 points rendered" in out and (tmp_path / "sweep" / "contact_sheet.png").exists()


def test_a_plain_render_and_sequence_never_import_dask_or_the_video_encoder(tmp_path):
    scene = write_scene(tmp_path, 3)
    script = (
        "import sys\n"
        "from clrays.cli import main\n"
        f"for args in (['render', {str(scene)!r}, '-o', {str(tmp_path / 'a.png')!r}, '--set', 'image.width=16'],\n"
        f"             ['sequence', {str(scene)!r}, '-o', {str(tmp_path / 'f_{}.png')!r}, '--video',\n"
        f"              {str(tmp_path / 'a.gif')!r}, '--set', 'image.width=16']):\n"
        "    try:\n"
        "        main(args)\n"
        "    except SystemExit as exit:\n"
        "        assert not exit.code, exit.code\n"
        "loaded = sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed', 'imageio_ffmpeg'))\n"
        "print('loaded:', loaded)\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert done.returncode == 0, done.stderr
    assert "loaded: []" in done.stdout, done.stdout


# --------------------------------------------------------------------------- connections that fail

class Listener:
    """A TCP listener on 127.0.0.1 that accepts and then stays silent, or sends `greeting`."""

    def __init__(self, greeting: bytes | None = None):
        self.socket = socket.create_server(("127.0.0.1", 0))
        self.address = f"tcp://127.0.0.1:{self.socket.getsockname()[1]}"
        self.greeting, self.connections = greeting, []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                connection, _ = self.socket.accept()
            except OSError:
                return
            self.connections.append(connection)
            if self.greeting is not None:
                with contextlib.suppress(OSError):
                    connection.sendall(self.greeting)

    def close(self):
        for connection in self.connections:
            connection.close()
        self.socket.close()


def _closed_port() -> str:
    with socket.create_server(("127.0.0.1", 0)) as probe:
        return f"tcp://127.0.0.1:{probe.getsockname()[1]}"  # free again once closed


_FRESH_PROCESS = """
import json, sys, time
from click.testing import CliRunner
from clrays.cli import main

def peak_mb():  # this process's own high-water mark (ru_maxrss would count the pytest process it came from)
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:")) / 1024

results = []
for args in json.loads(sys.argv[1]):
    start = time.perf_counter()
    result = CliRunner().invoke(main, args)
    results.append([result.exit_code, result.output, time.perf_counter() - start, peak_mb()])
print(json.dumps(results))
"""


def _in_a_fresh_process(runs: list[list[str]], timeout: float) -> list[tuple[int, str, float, float]]:
    """Each command line's (exit code, output, seconds, peak MB so far), run one after
    another by the CLI in one new process."""
    done = subprocess.run([sys.executable, "-c", _FRESH_PROCESS, json.dumps(runs)], capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_scheduler_that_is_not_there_or_not_dask_is_one_line_within_seconds(tmp_path):
    silent = Listener()
    # Garbage whose first 8 bytes, read as dask's frame length, claim 3.07 EiB (a MemoryError before).
    garbage = Listener(struct.pack("<Q", int(3.07 * 2**60)) + b"\xff" * 4096)
    short_garbage = Listener(struct.pack("<Q", 16) + b"\xff" * 16)  # a length dask would read, then not msgpack
    cases = [
        ("garbage", r"--scheduler garbage: expected a dask scheduler address tcp://HOST:PORT"),
        ("tcp://", r"--scheduler tcp://: expected a dask scheduler address tcp://HOST:PORT"),
        ("tcp://head:99999", r"the port must be a number in \[1, 65535\], got '99999'"),
        ("tcp://head:²", r"the port must be a number in \[1, 65535\], got '²'"),
        ("ucx://head:8786", r"only tcp:// is supported"),
        (_closed_port(), r"cannot connect: connection refused"),
        (silent.address, rf"connected, but no dask scheduler greeting within {CONNECT_TIMEOUT_S:g} s"),
        (garbage.address, r"not a dask scheduler: its greeting claims 3\.07 EiB"),
        (short_garbage.address, r"not a dask scheduler: its greeting is not dask's"),
    ]
    scene = write_scene(tmp_path, 2)
    try:
        results = _in_a_fresh_process([["sweep", str(scene), "--set", "render.slices=32,64", "--scheduler", address,
                                        "-o", str(tmp_path / "sweep")] for address, _ in cases], timeout=180)
    finally:
        for server in (silent, garbage, short_garbage):
            server.close()
    for (address, pattern), (code, output, seconds, peak_mb) in zip(cases, results):
        lines = output.strip().splitlines()
        assert code == 1 and len(lines) == 1, (address, output)
        assert lines[0].startswith(f"clrays: error: --scheduler {address}") and re.search(pattern, lines[0]), lines[0]
        assert seconds < 20 and peak_mb < 2000, (address, seconds, peak_mb)
    assert not (tmp_path / "sweep" / "results.csv").exists()


def test_a_running_scheduler_is_reached_through_the_probe(executor):
    # The module's LocalCluster, reached by its address as an external scheduler is.
    with DaskExecutor(scheduler=executor._cluster.scheduler_address) as remote:
        assert len(remote.client.scheduler_info()["workers"]) == 2
    assert executor.client.scheduler_info()["workers"]  # leaving it closed the client alone, not the cluster


def test_more_local_workers_than_the_machine_holds_are_refused_before_any_starts():
    from clrays.runs.distributed import local_worker_limit
    from conftest import run_cli

    limit, reason = local_worker_limit()
    asked = [limit + 1] + ([32] if limit < 32 else [])  # 32: once exit 0, with 150 lines of worker tracebacks
    for workers in asked:
        start = time.perf_counter()
        code, out = run_cli("sweep", "scenes/demo.yaml", "--set", "render.slices=32,64", "--workers", workers,
                            "-o", "/nonexistent/sweep")
        assert code == 1 and out.strip().splitlines() == [
            f"clrays: error: --workers {workers}: at most {limit} local workers on this machine ({reason}); "
            f"use --scheduler for more machines"], out
        assert time.perf_counter() - start < 5


def test_local_workers_shut_down_without_a_word():
    # A worker's own log (with 32 workers, heartbeats that met the closing scheduler printed
    # 90 to 150 lines of tracebacks) stays off the terminal; the run's results say what failed.
    script = (
        "import logging\n"
        "from clrays.runs.distributed import DaskExecutor\n"
        "if __name__ == '__main__':\n"
        "    with DaskExecutor(workers=1) as executor:\n"
        "        executor.client.run(lambda: logging.getLogger('distributed.worker').error('a worker complains'))\n"
        "    print('closed')\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert done.returncode == 0 and done.stdout == "closed\n", done.stderr[-2000:]
    assert done.stderr == "", done.stderr[-2000:]


def test_a_worker_renders_over_a_frame_of_another_scene(tmp_path):
    """A worker skips a frame only where the manifest ties the file to this scene: a file
    another run's late task wrote there (of another --set) is rendered over, not kept."""
    from clrays.runs.distributed import render_frame_task
    from clrays.runs.frame_manifest import FrameManifest, frame_digest

    scene = load_scene(write_scene(tmp_path, 2))
    path = tmp_path / "f_00.npy"
    key = frame_digest(scene, None, 0.0, ".npy")
    path.write_bytes(b"an image of another scene")
    options = dict(scene=scene, method=None, exposure=0.0, reuse=False, overwrite=False)
    assert render_frame_task((0, str(path), key), **options) is not None
    assert FrameManifest(tmp_path).matches(path, key)
    assert render_frame_task((0, str(path), key), **options) is None  # now it is this scene's
