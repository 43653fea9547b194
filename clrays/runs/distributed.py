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

import contextlib
import logging
import os
import socket
import struct
import threading
import uuid
import weakref
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

from ..errors import ClraysError

#: Seconds to wait for a scheduler: its TCP connection, its greeting, then the client's
#: registration. A scheduler answers in milliseconds; dask's own default, 30 s, retried
#: on a closed port for a minute, and waited forever on a port that accepts and is silent.
CONNECT_TIMEOUT_S = 5.0
#: Seconds to wait for the first worker: a LocalCluster's take a few seconds to start
#: (more on a loaded machine), a scheduler's may still be on their way.
WORKERS_TIMEOUT_S = 60.0
#: The most bytes of a scheduler's greeting (dask's handshake, about 60 bytes) read before
#: the client connects: a server that sends garbage is refused here, not allowed to make
#: dask allocate the exabytes its first 8 bytes claim.
MAX_GREETING_BYTES = 1 << 16
#: Memory of one local worker process rendering orbit.yaml at 640×360 on PoCL (unique set
#: size 375 MB; 245 MB at 160×90), the unit of the local worker limit (docs/limits.md).
WORKER_BYTES = 400 * 2**20


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise ClraysError("--scheduler/--workers need dask.distributed: "
                          "pip install 'clrays[distributed]'") from None
    return distributed


def parse_scheduler_address(text: str) -> tuple[str, int]:
    """(host, port) of a `--scheduler` address: tcp://HOST:PORT or HOST:PORT, the host a
    name, an IPv4 address or a bracketed IPv6 one ([::1]). Raises ClraysError otherwise."""
    expected = f"--scheduler {text}: expected a dask scheduler address tcp://HOST:PORT like tcp://head:8786"
    rest = text.strip()
    scheme, sep, tail = rest.partition("://")
    if sep:
        if scheme.lower() != "tcp":
            raise ClraysError(f"{expected}; got the scheme {scheme!r} (only tcp:// is supported)")
        rest = tail
    if rest.startswith("["):  # [IPv6]:port
        host, bracket, port = rest[1:].partition("]")
        if not bracket or not port.startswith(":"):
            raise ClraysError(expected)
        port = port[1:]
    else:
        host, _, port = rest.rpartition(":")
    if not host or any(c.isspace() or c in "/[]@?#" for c in host) or ":" in host and not rest.startswith("["):
        raise ClraysError(expected)
    if not (port.isascii() and port.isdecimal() and 1 <= int(port) <= 65535):
        raise ClraysError(f"{expected}; the port must be a number in [1, 65535], got {port!r}")
    return host, int(port)


def probe_scheduler(text: str, host: str, port: int, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Connect to a scheduler and read its greeting, with `timeout` for each and at most
    MAX_GREETING_BYTES, then answer it with the same greeting (a complete handshake, so the
    scheduler logs nothing). Raises ClraysError saying what failed: refused, no answer,
    silent, or not dask."""
    where = f"--scheduler {text}"
    try:
        connection = socket.create_connection((host, port), timeout=timeout)
    except socket.gaierror as exc:
        raise ClraysError(f"{where}: cannot connect: unknown host {host!r} ({exc.strerror})") from None
    except ConnectionRefusedError:
        raise ClraysError(f"{where}: cannot connect: connection refused (no scheduler listens there)") from None
    except TimeoutError:
        raise ClraysError(f"{where}: cannot connect: no answer within {timeout:g} s") from None
    except OSError as exc:
        raise ClraysError(f"{where}: cannot connect: {exc.strerror or exc}") from None
    with connection:
        try:
            connection.settimeout(timeout)
            header = _receive(connection, 8)
            (length,) = struct.unpack("<Q", header)
            if length > MAX_GREETING_BYTES:
                raise ClraysError(f"{where}: not a dask scheduler: its greeting claims {_bytes(length)}, dask's is "
                                  f"under {_bytes(MAX_GREETING_BYTES)}")
            body = _receive(connection, length)
            greeting = _decode_greeting(body)
            if not (isinstance(greeting, dict) and "pickle-protocol" in greeting):
                raise ValueError(f"a {type(greeting).__name__}, not a handshake")
            connection.sendall(header + body)
        except TimeoutError:
            raise ClraysError(f"{where}: connected, but no dask scheduler greeting within {timeout:g} s "
                              f"(is it a dask scheduler?)") from None
        except EOFError:
            raise ClraysError(f"{where}: the connection was closed before a dask scheduler's greeting") from None
        except (ValueError, TypeError, struct.error) as exc:
            raise ClraysError(f"{where}: not a dask scheduler: its greeting is not dask's ({exc})") from None
        except OSError as exc:
            raise ClraysError(f"{where}: the connection failed: {exc.strerror or exc}") from None


def _receive(connection: socket.socket, count: int) -> bytes:
    chunks, left = [], count
    while left:
        chunk = connection.recv(min(left, 1 << 16))
        if not chunk:
            raise EOFError
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def _decode_greeting(body: bytes):
    """A dask handshake message from its frames (distributed.comm.tcp's framing)."""
    from distributed.protocol.core import loads
    from distributed.protocol.utils import unpack_frames

    try:
        frames, rest = unpack_frames(body, partial=True)
        if rest:
            raise ValueError("frames beyond the greeting")
        return loads(frames, deserialize=False)
    except Exception as exc:  # noqa: BLE001 - struct, msgpack and dask raise their own types for garbage
        raise ValueError(_one_line(exc)) from None


def _bytes(count: int) -> str:
    for unit, size in (("EiB", 2**60), ("PiB", 2**50), ("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if count >= size:
            return f"{count / size:.2f} {unit}"
    return f"{count} bytes"


def local_worker_limit() -> tuple[int, str]:
    """The most `--workers` this machine can run, and why: one per CPU core this process
    may use (a worker renders on one thread, and PoCL's own threads share the cores), and
    no more than the available memory holds at WORKER_BYTES each."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    available = _available_memory()
    by_memory = max(1, available // WORKER_BYTES) if available else cores
    limit = max(1, min(cores, by_memory))
    reason = (f"{cores} CPU core{'s' if cores != 1 else ''}" if limit == cores else
              f"{available / 2**30:.1f} GiB of memory available, about {WORKER_BYTES // 2**20} MiB a worker")
    return limit, reason


def _available_memory() -> int | None:
    try:
        import psutil  # a dependency of distributed

        return int(psutil.virtual_memory().available)
    except (ImportError, OSError):
        return None


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
        if self.scheduler is not None:
            host, port = parse_scheduler_address(self.scheduler)  # before dask is imported: a typo costs nothing
            distributed = _import_distributed()
            probe_scheduler(self.scheduler, host, port)
            import dask

            try:  # the timeout bounds the client's connection, the setting those it opens while registering
                with dask.config.set({"distributed.comm.timeouts.connect": f"{CONNECT_TIMEOUT_S}s"}):
                    self.client = distributed.Client(self.scheduler, timeout=CONNECT_TIMEOUT_S)
            except Exception as exc:  # noqa: BLE001 - dask raises many types; the user needs one line
                raise ClraysError(f"--scheduler {self.scheduler}: cannot connect: {_one_line(exc)}") from None
        else:
            limit, reason = local_worker_limit()
            if self.workers > limit:
                raise ClraysError(f"--workers {self.workers}: at most {limit} local workers on this machine "
                                  f"({reason}); use --scheduler for more machines")
            distributed = _import_distributed()
            env = {"CLRAYS_DEVICE": self.device} if self.device else {}
            # The workers' own logs off: a task's error reaches the client with its result, and a
            # worker's heartbeat that meets the closing scheduler printed a traceback for nothing.
            try:
                self._cluster = distributed.LocalCluster(n_workers=self.workers, threads_per_worker=1,
                                                         processes=True, dashboard_address=":0", env=env,
                                                         silence_logs=logging.CRITICAL)
            except Exception as exc:  # noqa: BLE001 - e.g. "Nanny failed to start" when the machine is out of memory
                raise ClraysError(f"--workers {self.workers}: the local cluster did not start: {_one_line(exc)}") \
                    from None
            self.client = distributed.Client(self._cluster)
        try:
            self.client.wait_for_workers(1, timeout=WORKERS_TIMEOUT_S)
        except TimeoutError:
            self.__exit__(None, None, None)
            where = f"--scheduler {self.scheduler}" if self.scheduler is not None else f"--workers {self.workers}"
            raise ClraysError(f"{where}: no worker came up within {WORKERS_TIMEOUT_S:g} s") from None
        return self

    def __exit__(self, *exc_info) -> None:
        for run in list(self._runs):  # a run left by an exception cancels its tasks while the client is up
            run.close()
        # The client goes before the cluster, and the cluster waits for its workers to stop;
        # what dask logs on the way (connections closing under it) is not the user's business.
        with _quiet("distributed"):
            if self.client is not None:
                self.client.close()
                self.client = None
            if self._cluster is not None:
                self._cluster.close()
                self._cluster = None

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


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


@contextlib.contextmanager
def _quiet(name: str) -> Iterator[None]:
    """A logger (and its children) at CRITICAL for the length of a block."""
    logger = logging.getLogger(name)
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


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


def render_frame_task(item: tuple[int, str, str], *, scene, method: str | None, exposure: float, reuse: bool,
                      overwrite: bool):
    """Render one frame of a sequence on a worker, write its file and its manifest line:
    item = (frame, path, frame digest). Returns the slimmed RenderResult, or None when the
    frame is there already, of this scene (a task run again after its worker died, having
    written it). A file there of another scene (a task of an earlier run, still running
    when it was stopped, wrote it since) is rendered over."""
    from ..passes import write_render
    from .frame_manifest import FrameManifest, append_frame_line
    from ..scene.animation import scene_at

    frame, path, frame_digest_hex = item
    path = Path(path)
    if not overwrite and path.exists() and FrameManifest(path.parent).matches(path, frame_digest_hex):
        return None
    with _session_lock:
        frame_scene = scene_at(scene, frame)
        result = _worker_renderer(reuse).render(frame_scene, method)
        content = write_render(path, result, frame_scene, exposure, f"frame {frame}")
        append_frame_line(path, frame_digest_hex, content)
    return result.without_pixels()  # only times travel: the worker has written the image


def auto_exposure_task(frame: int, *, scene, method: str | None, reuse: bool) -> float:
    """`auto_ev` of a sequence's frame `frame`, rendered on a worker: what
    `sequence.sequence_exposure` takes the least of."""
    from ..exposure import auto_ev
    from ..scene.animation import scene_at

    with _session_lock:
        return auto_ev(_worker_renderer(reuse).render(scene_at(scene, frame), method).image)


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
            references = _references.setdefault(folder, ReferenceCache(Path(folder) / REFERENCES, renderer,
                                                                        below=folder))
        return render_point(renderer, references, against, point, scene, Path(folder), name, digest_hex, exposure,
                            _warmed)


def pin_to_core(core: int) -> None:
    """Pin this process (every thread, and those it starts later) to one CPU core: for the
    benchmark in bench/RESULTS.md history, "Sequences on Dask workers"."""
    for thread in os.listdir("/proc/self/task"):
        os.sched_setaffinity(int(thread), {core})
