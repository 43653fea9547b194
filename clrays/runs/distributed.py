"""Sequences and sweeps on a dask.distributed cluster: `--scheduler ADDRESS` (a running
scheduler) or `--workers N` (a LocalCluster of N processes on this machine).

    with DaskExecutor(workers=2) as executor:
        render_sequence(scene, "out/frame_{:04d}.png", executor=executor)

Only this module imports dask, and only `--scheduler` / `--workers` import this module,
so a run without them never loads dask (tests/runs/test_distributed.py checks it).

How the work is split (docs/design.md §7, stage reuse):
- one task per frame or sweep point, so a worker that dies loses only the item it was
  rendering; dask hands its other items, and that one, to the workers left;
- the items are cut into one contiguous run per worker (frames in order; sweep points in
  `execution_order`, which puts the points that share stages side by side), each run
  bound to its worker with loose restrictions and decreasing priority, so a worker
  renders its run in order on one `Renderer` and reuses what consecutive items share;
- each worker keeps one `Renderer` per process on the device its own environment names
  (`CLRAYS_DEVICE`), so a multi-GPU node runs one worker per GPU;
- a worker writes its item's image itself (atomically) and sends back only the timings;
  `results.csv` is written by the client alone, so a killed run resumes as in-process.
Output paths must be reachable from the workers (a shared file system on a cluster).
"""
from __future__ import annotations

import os
import threading
import uuid
import weakref
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from ..errors import ClraysError

#: Seconds to wait for a scheduler or for the local workers to come up.
CONNECT_TIMEOUT_S = 60


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise ClraysError("--scheduler/--workers need dask.distributed: "
                          "pip install 'clrays[distributed]'") from None
    return distributed


class DaskExecutor:
    """A dask client for the length of a run (a context manager).

    scheduler: address of a running scheduler (`tcp://host:8786`); workers: else the number
    of worker processes of a LocalCluster started here (one thread each, as a worker holds
    one OpenCL session); device: the LocalCluster workers' `CLRAYS_DEVICE` (an external
    cluster's workers follow their own environment)."""

    def __init__(self, scheduler: str | None = None, workers: int | None = None, device: str | None = None):
        if (scheduler is None) == (workers is None):
            raise ClraysError("give either --scheduler ADDRESS or --workers N, not both")
        self.scheduler, self.workers, self.device = scheduler, workers, device
        self.client = None
        self._cluster = None
        self._runs = weakref.WeakSet()  # `run` generators still open, closed before the client

    def __enter__(self) -> DaskExecutor:
        distributed = _import_distributed()
        if self.scheduler is not None:
            try:
                self.client = distributed.Client(self.scheduler, timeout=CONNECT_TIMEOUT_S)
            except (OSError, TimeoutError) as exc:
                raise ClraysError(f"--scheduler {self.scheduler}: cannot connect: {exc}") from None
        else:
            env = {"CLRAYS_DEVICE": self.device} if self.device else {}
            self._cluster = distributed.LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                                     dashboard_address=":0", env=env)
            self.client = distributed.Client(self._cluster)
        self.client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        return self

    def __exit__(self, *exc_info) -> None:
        for run in list(self._runs):  # a run left by an exception cancels its tasks while the client is up
            run.close()
        if self.client is not None:
            self.client.close()
        if self._cluster is not None:
            self._cluster.close()

    def busy_label(self) -> str:
        """`k/n workers busy`, for the progress bar."""
        processing = self.client.processing()
        return f"{sum(1 for keys in processing.values() if keys)}/{len(processing)} workers busy"

    def run(self, function: Callable, items: Sequence, shared: dict[str, Any]) -> Iterator[tuple[Any, Any]]:
        """(item, function(item, **shared)) for every item, as they finish on the workers.

        items go to the workers in contiguous runs, in order (see the module's docstring);
        `shared` is sent to each worker once. Leaving the loop early cancels what is left."""
        run = self._run(function, items, shared)
        self._runs.add(run)
        return run

    def _run(self, function: Callable, items: Sequence, shared: dict[str, Any]) -> Iterator[tuple[Any, Any]]:
        distributed = _import_distributed()
        items = list(items)
        if not items:
            return
        workers = sorted(self.client.scheduler_info()["workers"])
        # In a list, so that a tuple or dict travels as one value rather than one per element.
        shared_futures = {name: self.client.scatter([value], broadcast=True, hash=False)[0]
                          for name, value in shared.items()}
        run_id = uuid.uuid4().hex[:8]
        per_worker = -(-len(items) // len(workers))
        futures = {}
        for position, item in enumerate(items):
            worker, place = divmod(position, per_worker)
            future = self.client.submit(function, item, **shared_futures, key=f"clrays-{run_id}-{position}",
                                        workers=[workers[worker]], allow_other_workers=True,
                                        priority=per_worker - place, pure=False)
            futures[future] = item
        try:
            for future in distributed.as_completed(futures):
                value = future.result()
                item = futures.pop(future)
                future.release()  # collected: a worker lost later is not asked to render it again
                yield item, value
        finally:
            self.client.cancel(list(futures))
            for future in shared_futures.values():
                future.release()


# --------------------------------------------------------------------------- on the workers

_session_lock = threading.Lock()  # one render at a time per process, whatever the worker's thread count
_sessions: dict[bool, Any] = {}
_references: dict[str, Any] = {}
_warmed: set = set()  # kernel configurations this worker's session has run (sweep warm-up)


def _worker_renderer(reuse: bool):
    """The process's `Renderer` (one per reuse setting), on the device `CLRAYS_DEVICE` names."""
    from ..session import Renderer

    if reuse not in _sessions:
        _sessions[reuse] = Renderer(None, reuse=reuse)
    return _sessions[reuse]


def _slim(result):
    """A RenderResult without its image and passes, which the worker has written: only times travel."""
    return replace(result, image=np.zeros((0, 0, 3), np.float32), passes=None)


def render_frame_task(item: tuple[int, str], *, scene, method: str | None, exposure: float, reuse: bool,
                      overwrite: bool):
    """Render one frame of a sequence on a worker and write its file: item = (frame, path).
    Returns the slimmed RenderResult, or None when the file is there already (a task
    run again after its worker died, having written it)."""
    from ..passes import write_render

    frame, path = item
    path = Path(path)
    if path.exists() and not overwrite:
        return None
    with _session_lock:
        frame_scene = scene.animation.scene_at(scene, frame) if scene.animation is not None else scene
        result = _worker_renderer(reuse).render(frame_scene, method)
        write_render(path, result, frame_scene, exposure, f"frame {frame}")
    return _slim(result)


def render_point_task(item, *, folder: str, exposure: float, against, reuse: bool, progress: bool = False):
    """Render one sweep point on a worker, write its image and return its results.csv row:
    item = (point, scene, image name, scene digest), as `run_sweep` lists them."""
    from .references import ReferenceCache
    from .point import REFERENCES, render_point

    point, scene, name, digest_hex = item
    with _session_lock:
        renderer = _worker_renderer(reuse)
        references = None
        if against is not None:
            references = _references.setdefault(folder, ReferenceCache(Path(folder) / REFERENCES, renderer))
        return render_point(renderer, references, against, point, scene, Path(folder), name, digest_hex, exposure,
                            _warmed)


def pin_to_core(core: int) -> None:
    """Pin this process (every thread, and those it starts later) to one CPU core: for the
    benchmark of bench/dask_workers.py."""
    for thread in os.listdir("/proc/self/task"):
        os.sched_setaffinity(int(thread), {core})
