"""The OpenCL device: which one, its context and queue, and building the stage kernels.

Device choice: `--device` or `CLRAYS_DEVICE` (an index like `0:1` for platform 0,
device 1, or a case-insensitive substring of the platform's name or vendor or the
device's name, such as `pocl`, `intel` or `nvidia`); by default the first GPU, else
PoCL's CPU device, else the first device.
"""
from __future__ import annotations

import collections
import contextlib
import hashlib
import os
import signal
import sys
import threading
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Callable

import numpy as np

from . import runtimes, structs
from .errors import DeviceError, OutputError
from .outputs import make_folders_below, open_file


def kernel_dir() -> Path:
    """Folder of the `.cl` sources: inside the installed package (wheel) or the
    repository's `cl/` beside the package (editable install, source tree)."""
    try:
        packaged = Path(str(resources.files("clrays") / "cl"))
        if (packaged / "common.h").is_file():
            return packaged
    except (ModuleNotFoundError, TypeError):
        pass
    source_tree = Path(__file__).resolve().parent.parent / "cl"
    if (source_tree / "common.h").is_file():
        return source_tree
    raise DeviceError("OpenCL kernel sources not found (expected clrays/cl or cl/ beside the package)")


def build_options(defines: dict[str, object] | None = None, constants: dict[str, str] | None = None) -> list[str]:
    """Compiler options of every kernel build: `-I` on the kernel folder (headers, and
    pyopencl's cache sees their edits), the constants shared with Python as `-D`
    (`constants`, by default `clrays.structs.kernel_defines()`), then the stage's own `defines`."""
    constants = structs.kernel_defines() if constants is None else constants
    shared = [f"-D{name}={literal}" for name, literal in constants.items()]
    return [f"-I{kernel_dir()}"] + shared + [f"-D{k}={v}" for k, v in sorted((defines or {}).items())]


def _stderr_line(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


#: Where a Device says that it is building kernels no earlier run on this device built
#: (about 10 s on a 2-core CPU at the first run; a new feature or size builds a few more
#: programs, 10-50 s): one line on stderr by default; None says nothing.
build_notice: Callable[[str], None] | None = _stderr_line
#: Whether the OpenCL compiler's own output ("1 warning generated." and the like) reaches
#: stderr; the CLI's --debug sets it. Otherwise it is kept out of the terminal.
show_compiler_output = False


@contextlib.contextmanager
def _compiler_output():
    """What the OpenCL compiler writes to stderr (file descriptor 2) while the block runs,
    dropped unless `show_compiler_output`: PoCL's clang prints its diagnostics' count there
    itself, past Python's warnings. (A failed build's log comes with its DeviceError.)"""
    if show_compiler_output:
        yield
        return
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no descriptor 2 to redirect
        yield
        return
    with open(os.devnull, "wb") as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)


def _ignore_file_size_signal() -> None:
    """Put back Python's SIG_IGN for SIGXFSZ, which a runtime built on LLVM (Intel's) replaces
    with LLVM's crash handler when it starts or compiles: a write past a file-size limit then
    printed LLVM's "PLEASE submit a bug report" line before the write's own error (EFBIG),
    which clrays reports in one line. Only the main thread may set a handler."""
    if hasattr(signal, "SIGXFSZ") and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)


def _kernels_digest(device) -> str:
    """What decides whether this device has built these kernels before: the device and its
    driver, the kernel sources and the shared constants."""
    digest = hashlib.sha256()
    for text in (device.platform.name, device.platform.version, device.name, device.driver_version,
                 repr(sorted(structs.kernel_defines().items()))):
        digest.update(text.encode() + b"\0")
    for path in sorted(kernel_dir().glob("*.[ch]*")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:24]


def _import_cl(pip_runtimes: bool = False):
    """pyopencl; with `pip_runtimes`, the OpenCL runtimes pip installed (clrays.runtimes) made
    visible first, which works only before the ICD loader's first call (it reads its list of
    runtimes once per process). Only a named device needs them: Intel's runtime costs a
    process about 100 MB once loaded, and the default device is a GPU or PoCL's."""
    if pip_runtimes:
        runtimes.register()
    try:
        import pyopencl as cl
    except ImportError as exc:  # pragma: no cover - install problem
        raise DeviceError(f"pyopencl is not importable: {exc}") from exc
    return cl


def list_devices(pip_runtimes: bool = True) -> list[tuple[int, int, object, object]]:
    """(platform index, device index, platform, device) for every OpenCL device, each once:
    a runtime the loader finds twice (PoCL's wheel and the system's copy of the same
    build) shows two platforms alike in every name and version, and only the first counts.
    `pip_runtimes`: as `_import_cl`'s, on the process's first query."""
    cl = _import_cl(pip_runtimes)
    try:
        platforms = cl.get_platforms()
    except cl.Error as exc:
        raise DeviceError(f"no OpenCL platform found ({exc}); install pocl-binary-distribution") from exc
    found, seen = [], set()
    for p_index, platform in enumerate(platforms):
        try:
            devices = platform.get_devices()
        except cl.Error:
            continue
        for d_index, device in enumerate(devices):
            identity = (platform.name, platform.version, d_index, device.name, device.version, device.driver_version)
            if identity not in seen:
                seen.add(identity)
                found.append((p_index, d_index, platform, device))
    return found


def select_device(spec: str | None = None):
    """The device named by `spec` (or CLRAYS_DEVICE), else the first GPU, else PoCL's CPU
    device, else the first device."""
    spec = spec if spec is not None else os.environ.get("CLRAYS_DEVICE") or None
    # The default device and one named as PoCL need no runtime pip installed beside it,
    # unless PoCL cannot build for this CPU and one is there to serve instead.
    pip_runtimes = spec is not None and not any(name in spec.lower() for name in ("pocl", "portable"))
    pocl_builds = spec is not None or not runtimes.pip_runtime_libraries() or runtimes.pocl_builds_here()
    pip_runtimes = pip_runtimes or not pocl_builds
    cl = _import_cl(pip_runtimes)
    devices = list_devices(pip_runtimes)
    if not devices:
        raise DeviceError("no OpenCL device found; install pocl-binary-distribution for the CPU device")
    if spec is None:
        # The loader's order of runtimes is its own: PoCL, which the suite and its golden
        # images are for, comes before another CPU runtime (`--device intel` picks Intel's).
        gpus = [d for d in devices if d[3].type & cl.device_type.GPU]
        pocl = [d for d in devices if "pocl" in d[2].vendor.lower()]
        others = [d for d in devices if d not in pocl]
        return (gpus or (pocl if pocl_builds else others + pocl) or devices)[0][3]
    # (isdecimal, not isdigit: "²".isdigit() is true, and int() refuses it)
    if ":" in spec and all(part.isdecimal() for part in spec.split(":", 1)):
        p, d = (int(part) for part in spec.split(":", 1))
        for entry in devices:
            if entry[0] == p and entry[1] == d:
                return entry[3]
        raise DeviceError(f"device {spec}: no such platform:device (see `clrays info`)")
    needle = spec.lower()
    for entry in devices:
        # PoCL's platform is "Portable Computing Language": `pocl` is in its vendor only.
        names = (entry[2].name, entry[2].vendor, entry[3].name)
        if any(needle in name.lower() for name in names):
            return entry[3]
    hint = ""
    if "intel" in needle and not runtimes.pip_runtime_libraries():
        hint = "; Intel's CPU runtime installs with pip install 'clrays[intel-cpu]' (make intel-cpu)"
    raise DeviceError(f"device {spec!r}: no platform name or vendor, or device name, contains it "
                      f"(see `clrays info`){hint}")


@dataclass
class StageTimer:
    """Device time per stage label, from OpenCL profiling events."""

    events: dict[str, list] = field(default_factory=dict)
    host_ms: dict[str, float] = field(default_factory=dict)

    def add(self, label: str, event) -> None:
        self.events.setdefault(label, []).append(event)

    def add_host(self, label: str, milliseconds: float) -> None:
        """Time of a stage that runs on the host (table construction)."""
        self.host_ms[label] = self.host_ms.get(label, 0.0) + milliseconds

    @property
    def host_labels(self) -> frozenset[str]:
        """The stages timed on the host (wall clock), not by OpenCL events."""
        return frozenset(self.host_ms)

    def milliseconds(self) -> dict[str, float]:
        times = {}
        for label, events in self.events.items():
            total = 0.0
            for event in events:
                event.wait()
                total += (event.profile.end - event.profile.start) * 1e-6
            times[label] = total
        for label, ms in self.host_ms.items():
            times[label] = times.get(label, 0.0) + ms
        return times


#: The work-groups per compute unit a CPU launch gets (spread_local_size), so that uneven ones balance.
GROUPS_PER_UNIT = 32
#: The largest work-group spread_local_size makes (PoCL's largest), unless the device's is smaller.
MAX_CPU_GROUP = 4096
#: Work-items per work-group of Device.list_launch on a CPU device.
LIST_GROUP = 64
#: Device.fill on a CPU device: fills of at least this many bytes run as a kernel, each
#: work-item storing this many 16-byte vectors.
PARALLEL_FILL_BYTES = 1 << 20
FILL_VECTORS = 1024


def spread_local_size(global_size: tuple[int, ...], units: int, max_group: int = MAX_CPU_GROUP) -> tuple[int, ...]:
    """The largest work-group along the first axis of `global_size`, at most `max_group`,
    that divides it and leaves GROUPS_PER_UNIT work-groups for each of `units` compute
    units (1 along the others)."""
    first, rest = int(global_size[0]), int(np.prod(global_size[1:], dtype=np.int64))
    largest = max(1, min(first * rest // (GROUPS_PER_UNIT * units), max_group, first))
    size = next(d for d in range(largest, 0, -1) if first % d == 0)
    return (size,) + (1,) * (len(global_size) - 1)


class _Launcher:
    """A kernel whose launches that name no work-group shape take Device.local_size's."""

    def __init__(self, kernel, device: "Device"):
        self._kernel, self._device = kernel, device

    def __call__(self, queue, global_size, local_size, *args, **kwargs):
        if local_size is None:
            local_size = self._device.local_size(global_size)
        return self._kernel(queue, global_size, local_size, *args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._kernel, name)


#: On a CPU device a buffer is the process's own memory, and a frame frees its large
#: buffers and the next allocates them again: each time as fresh pages, faulted in inside
#: the kernels that first write them (demo.yaml at 1280×720: about 10 000 faults a frame,
#: most in visibility_clear, the fills and gather). Buffers of at least POOLED_BYTES with
#: no host data come instead from a pool (pyopencl.tools.MemoryPool) that keeps the buffers
#: a frame lets go of for the next frame's: the kernels that first write a frame's buffers
#: took 1.25× as long without it on demo, 1.11× on behind (docs/design.md §4.5, "Cost on
#: PoCL"). Every buffer a kernel reads is written first in its frame, as on any device,
#: whose fresh buffers hold whatever was there.
POOLED_BYTES = 1 << 16


class _Holding:
    """An array's memory, and what must live as long as it: numpy keeps this object as the
    base of the array it makes from it (and so of every view of that)."""

    def __init__(self, array: np.ndarray, owner):
        self.__array_interface__ = array.__array_interface__
        self._array, self._owner = array, owner


#: What the pool may hold unused after a frame, in units of the largest frame's device
#: bytes among the last POOL_WINDOW frames; beyond it the pool lets all of it go (a
#: sequence whose sizes fall). A frame the cache answers, or one that reuses most stages,
#: allocates little, and must not empty the pool the next full frame takes from.
POOL_HELD_FRAMES = 2
POOL_WINDOW = 8


class Device:
    """Context, profiling queue and a cache of built stage programs for one device."""

    def __init__(self, spec: str | None = None):
        cl = _import_cl()
        self.cl = cl
        self.device = select_device(spec)
        self.context = cl.Context([self.device])
        _ignore_file_size_signal()
        self.queue = cl.CommandQueue(self.context, properties=cl.command_queue_properties.PROFILING_ENABLE)
        self._programs: dict[tuple, object] = {}
        #: Milliseconds spent building programs so far: a sweep leaves them out of a point's time.
        self.build_ms = 0.0
        self._kernels: dict[tuple, object] = {}
        # The shared constants as they are now: every program this device builds later takes
        # them (a test builds a device with one changed, and changes it back at once).
        self._constants = structs.kernel_defines()
        self._spread = bool(self.device.type & cl.device_type.CPU)
        self._pool = None
        if self._spread:
            from pyopencl.tools import ImmediateAllocator, MemoryPool
            self._pool = MemoryPool(ImmediateAllocator(self.queue))
            self._recent_frame_bytes = collections.deque(maxlen=POOL_WINDOW)
        self._units = max(int(self.device.max_compute_units), 1)
        self._max_group = max(min(MAX_CPU_GROUP, int(self.device.max_work_group_size)), 1)
        self._local_sizes: dict[tuple, tuple] = {}
        self.allocated_bytes = 0
        #: Bytes allocated under each declared buffer's name (clrays.stages.buffers.BufferDecl)
        #: since the session's frame began, beside `allocated_bytes`.
        self.allocated_by_name: dict[str, int] = {}
        #: Times the host has waited for this device's queue to reach a point (a blocking
        #: read, a mapped buffer, a flag): each one drains the queue, and on a GPU leaves
        #: the device idle while the host enqueues again. RenderResult.host_waits counts a
        #: frame's.
        self.host_waits = 0
        self._deferred_waits: list | None = None  # (deferred_waits)
        self._announced = False  # whether this build burst (builds until a frame ends) was announced
        self._digest: str | None = None  # _kernels_digest, read once

    @property
    def is_cpu(self) -> bool:
        return self._spread

    @property
    def name(self) -> str:
        return f"{self.device.platform.name.strip()} / {self.device.name.strip()}"

    def _unwritable_cache(self) -> str:
        """Why PoCL cannot build here, where it is known, as the tail of a build error; ""
        otherwise: its kernel cache cannot be written (PoCL writes each program's source
        there first, so a full disk fails every build), or its compiler does not know this
        CPU (runtimes.pocl_builds_here)."""
        if "portable" not in self.device.platform.name.lower():
            return ""
        if not runtimes.pocl_builds_here():
            return (": PoCL's compiler does not know this CPU; install Intel's CPU runtime, which clrays "
                    "then uses by itself: pip install 'clrays[intel-cpu]' (make intel-cpu)")
        folder = Path(os.environ.get("POCL_CACHE_DIR")
                      or Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "pocl")
        try:
            folder.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryFile(dir=folder) as probe:
                probe.write(b"\0" * 65536)
                probe.flush()
                os.fsync(probe.fileno())
        except OSError as exc:
            return f": PoCL cannot write its kernel cache {folder} ({exc.strerror or exc}; free space there, or " \
                   f"set POCL_CACHE_DIR)"
        return ""

    def program(self, stage: str, defines: dict[str, object] | None = None):
        """Build (once) `cl/<stage>.cl` with `build_options(defines)`."""
        defines = defines or {}
        key = (stage, tuple(sorted(defines.items())))
        if key not in self._programs:
            path = kernel_dir() / f"{stage}.cl"
            options = build_options(defines, self._constants)
            marker = self._announce_build(stage, options)
            start = time.perf_counter()
            try:
                with warnings.catch_warnings(), _compiler_output():
                    warnings.simplefilter("ignore", self.cl.CompilerWarning)
                    self._programs[key] = self.cl.Program(self.context, path.read_text()).build(options=options)
                _ignore_file_size_signal()
            except self.cl.RuntimeError as exc:
                if show_compiler_output:  # --debug: the options and the compiler's log
                    raise DeviceError(f"{path}: build failed with options {' '.join(options)}:\n{exc}") from exc
                raise DeviceError(f"{path}: the OpenCL compiler could not build it"
                                  f"{self._unwritable_cache()} (run with --debug for its log)") from exc
            finally:
                self.build_ms += (time.perf_counter() - start) * 1e3
            if marker is not None:
                with contextlib.suppress(OSError, OutputError):  # a mark that cannot be made: announced again
                    make_folders_below(runtimes.cache_root(), marker.parent, "the cache")
                    os.close(open_file(marker, os.O_WRONLY | os.O_CREAT))
        return self._programs[key]

    def _announce_build(self, stage: str, options: list[str]) -> Path | None:
        """Before building a program: the marker file that says an earlier run built it on this
        device (to touch once the build succeeds), or None where one did (the driver's cache
        holds its binary, and the build is quick). The first program of a burst (the builds
        until the next frame ends) that no run built is announced with one line (build_notice):
        the first run's, or what is new."""
        if self._digest is None:
            self._digest = _kernels_digest(self.device)
        built = runtimes.cache_root() / "built-programs" / self._digest
        marker = built / hashlib.sha256("\0".join([stage, *options]).encode()).hexdigest()[:24]
        if marker.exists():
            return None
        if not self._announced and build_notice is not None:
            if built.is_dir():
                defines = [option[2:] for option in options[len(self._constants) + 1:]]  # the stage's own
                what = f"{stage}{' with ' + ' '.join(defines) if defines else ''}"
                what = what if len(what) <= 100 else what[:97] + "..."
                build_notice(f"building OpenCL kernels for {self.name}: {what} and any more this frame needs "
                             f"(new settings, cached after)")
            else:
                build_notice(f"building OpenCL kernels for {self.name} (first run, cached after)")
        self._announced = True
        return marker

    def kernel(self, stage: str, name: str, defines: dict[str, object] | None = None):
        """The kernel `name` of `cl/<stage>.cl`, retrieved once and reused."""
        key = (stage, name, tuple(sorted((defines or {}).items())))
        if key not in self._kernels:
            self._kernels[key] = _Launcher(self.cl.Kernel(self.program(stage, defines), name), self)
        return self._kernels[key]

    def local_size(self, global_size: tuple) -> tuple | None:
        """The work-group shape of a launch that names none: on a CPU device,
        spread_local_size's; on others, the driver's. PoCL makes a launch as few
        work-groups as it can: a small one is one work-group, which one core runs while
        the others wait (a frame's raster passes over its views' rows, or over a few
        hundred triangles, ran at one core's speed), and a large one a few dozen, whose
        uneven costs (walks where the shafts are) leave a core idle at the end."""
        if not self._spread:
            return None
        global_size = tuple(int(g) for g in global_size)
        if global_size not in self._local_sizes:
            self._local_sizes[global_size] = spread_local_size(global_size, self._units, self._max_group)
        return self._local_sizes[global_size]

    def counted_launch(self, count: int) -> tuple[tuple[int], tuple[int] | None]:
        """(global size, work-group shape) of a 1-D launch over `count` items whose kernel
        skips the work-items past `count`, a count that follows the scene and that the host
        knows (fix_up's list, before its length stayed on the device: list_launch). On a CPU device the work-group is the power of two
        nearest below spread_local_size's aim and the launch is padded to a multiple of it:
        PoCL compiles a kernel for each work-group size it has not cached (about 450 ms),
        and a divisor of each count would be a new size at nearly every frame."""
        if not self._spread:
            return (max(count, 1),), None
        aim = max(1, min(count // (GROUPS_PER_UNIT * self._units), self._max_group))
        group = 1 << (aim.bit_length() - 1)
        return (-(-max(count, 1) // group) * group,), (group,)

    def list_launch(self, bound: int) -> tuple[tuple[int], tuple[int] | None]:
        """(global size, work-group shape) of a 1-D launch over a list whose length the
        device alone knows, at most `bound` items, by a kernel that splits the list evenly
        over its work-items (cl/sampling.cl, fix_up): the host enqueues it without waiting
        to learn the length. On a device other than a CPU, a work-item per item of `bound`,
        those past the length returning at once. On a CPU device GROUPS_PER_UNIT work-groups
        per compute unit of LIST_GROUP work-items, whatever the length: each work-group a
        stretch of the list, as counted_launch's were, and one work-group size for PoCL
        to compile."""
        if not self._spread:
            return (max(bound, 1),), None
        group = min(LIST_GROUP, self._max_group)
        return (GROUPS_PER_UNIT * self._units * group,), (group,)

    def buffer(self, array: np.ndarray | None = None, nbytes: int | None = None, writable: bool = True,
               name: str | None = None):
        """A device buffer, filled from `array` or of `nbytes` uninitialised bytes; on a CPU
        device a large one of `nbytes` comes from the pool (POOLED_BYTES). `name`: the
        declaration it is allocated by (clrays.stages.buffers), whose bytes it counts."""
        mf = self.cl.mem_flags
        flags = mf.READ_WRITE if writable else mf.READ_ONLY
        if array is not None:
            array = np.ascontiguousarray(array)
            size = max(array.nbytes, 1)
            self.allocated_bytes += size
            if name is not None:
                self.allocated_by_name[name] = self.allocated_by_name.get(name, 0) + array.nbytes
            if array.nbytes == 0:
                return self.cl.Buffer(self.context, flags, 16)
            return self.cl.Buffer(self.context, flags | mf.COPY_HOST_PTR, hostbuf=array)
        self.allocated_bytes += nbytes
        if name is not None:
            self.allocated_by_name[name] = self.allocated_by_name.get(name, 0) + int(nbytes)
        if self._pool is not None and nbytes >= POOLED_BYTES:
            return self._pool.allocate(int(nbytes))
        return self.cl.Buffer(self.context, flags, max(int(nbytes), 16))

    def pool_bytes(self) -> tuple[int, int] | None:
        """(bytes the pool has allocated, bytes of them in use); None without a pool."""
        return None if self._pool is None else (self._pool.managed_bytes, self._pool.active_bytes)

    def end_frame(self, frame_bytes: int) -> None:
        """After a frame that allocated `frame_bytes` device bytes: the pool lets go of the
        buffers it holds unused when they are more than POOL_HELD_FRAMES of the largest of
        the last POOL_WINDOW frames. The next build starts a new burst (`_announce_build`)."""
        self._announced = False
        if self._pool is None:
            return
        self._recent_frame_bytes.append(frame_bytes)
        if self._pool.managed_bytes - self._pool.active_bytes > POOL_HELD_FRAMES * max(self._recent_frame_bytes):
            self._pool.free_held()

    def fill(self, buffer, value: np.ndarray, nbytes: int, timer: StageTimer | None = None, label: str = "fill"):
        """The first `nbytes` of `buffer` set to `value` (a 4- or 8-byte numpy scalar) over
        and over. On a CPU device a large fill is a kernel, which every core runs (PoCL's
        own fill runs on one thread while the others wait, for a frame's 25 MB cube map at
        1280×720 too: docs/design.md §4.5); the tail past the last 16-byte vector is the
        driver's."""
        value = np.asarray(value)
        vectors = nbytes // 16 if self._spread and nbytes >= PARALLEL_FILL_BYTES else 0
        event = None
        if vectors:
            pattern = np.frombuffer(np.tile(value, 16 // value.itemsize).tobytes(), np.uint32)
            event = self.kernel("fill", "fill_vectors", {"FILL_VECTORS": FILL_VECTORS})(
                self.queue, (-(-vectors // FILL_VECTORS),), None, buffer,
                self.cl.cltypes.make_uint4(*pattern.tolist()), np.int32(vectors))
            if timer is not None:
                timer.add(label, event)
        if 16 * vectors < nbytes:
            event = self.cl.enqueue_fill_buffer(self.queue, buffer, value, 16 * vectors, nbytes - 16 * vectors)
            if timer is not None:
                timer.add(label, event)
        return event

    def read_all(self, reads: list[tuple[object, tuple | int]], dtype) -> list[np.ndarray]:
        """Several buffers read at once, `reads` as (buffer, shape) pairs, with one wait for
        the last (this queue is in order, so the others are done then): the host waits once,
        not once per buffer. No read, no wait (OpenCL refuses an empty wait list with
        CL_INVALID_VALUE)."""
        arrays = [np.empty(shape, dtype=dtype) for _, shape in reads]
        events = [self.cl.enqueue_copy(self.queue, array, buffer, is_blocking=False)
                  for array, (buffer, _) in zip(arrays, reads)]
        if events:
            self.wait(events[-1])
        return arrays

    def read(self, buffer, shape, dtype) -> np.ndarray:
        out = np.empty(shape, dtype=dtype)
        self.wait(self.cl.enqueue_copy(self.queue, out, buffer, is_blocking=False))
        return out

    def wait(self, event) -> None:
        """The host waits for `event` (counted in `host_waits`); within `deferred_waits`,
        the event is kept for later instead."""
        if self._deferred_waits is not None:
            self._deferred_waits.append(event)
            return
        self.host_waits += 1
        event.wait()

    def collect(self, event) -> None:
        """The host takes what `event`'s command made, which it expects done (a copy enqueued
        before a later wait): it waits, counted in `host_waits`, only where it is not."""
        if event.command_execution_status != self.cl.command_execution_status.COMPLETE:
            self.wait(event)

    @contextlib.contextmanager
    def deferred_waits(self, events: list):
        """Within the block a read returns at once, its array not yet filled, and its event
        goes to `events`: the caller waits for the last of them (the queue is in order)
        before it touches any array read. A frame in flight reads its image so
        (clrays.session.PendingFrame), and the host goes on to the next frame meanwhile."""
        self._deferred_waits = events
        try:
            yield events
        finally:
            self._deferred_waits = None

    def read_in_place(self, buffer, shape, dtype) -> np.ndarray:
        """A buffer the frame is done with, as an array: on a CPU device the buffer's own
        memory, mapped, which is the host's (no copy: a 1280×720 image's 14.7 MB took
        3–5 ms to copy, and its fresh pages to fault in); on another device a read. The
        buffer lives as long as the array (and any view of it): a pooled one goes back to
        the pool only then."""
        if not self._spread:
            return self.read(buffer, shape, dtype)
        flags = self.cl.map_flags.READ | self.cl.map_flags.WRITE  # (the caller may write to its image)
        array, event = self.cl.enqueue_map_buffer(self.queue, buffer, flags, 0, shape, dtype, is_blocking=False)
        self.wait(event)
        return np.asarray(_Holding(array, buffer))
