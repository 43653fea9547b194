"""OpenCL runtimes that pip installs, made visible to the ICD loader before its first call.

pyopencl's loader finds PoCL (pocl-binary-distribution) by itself, and the system's
runtimes in /etc/OpenCL/vendors. Intel's CPU runtime (`pip install 'clrays[intel-cpu]'`,
the intel-opencl-rt package) puts `libintelocl.so` in the environment's `lib/`, where no
loader looks. So, unless the user has set OCL_ICD_VENDORS themselves, clrays points it at a
vendors folder of its own: the system's `.icd` files, and one naming that library. The
loader reads OCL_ICD_VENDORS once, at its first call, so `register()` runs before
pyopencl's first platform query (clrays.device), and only where a device other than the
default or PoCL is named, or `clrays info` lists them all: once loaded, Intel's runtime
holds about 100 MB of the process.

The library's own dependencies (libimf, libsvml, TBB) sit beside it, where its RUNPATH
($ORIGIN) finds them: no LD_LIBRARY_PATH is needed.
"""
from __future__ import annotations

import hashlib
import os
import platform
import stat
import subprocess
import sys
import tempfile
from importlib import metadata
from pathlib import Path

from .errors import OutputError
from .outputs import cache_root, open_file, writes_confined

#: Where the loader looks when neither OCL_ICD_VENDORS nor OPENCL_VENDOR_PATH says otherwise.
SYSTEM_VENDORS = Path("/etc/OpenCL/vendors")
#: The pip packages of CPU runtimes, and the library in each that the loader opens.
PIP_RUNTIMES = {"intel-opencl-rt": "libintelocl.so"}

_registered = False


def pip_runtime_libraries() -> list[Path]:
    """The OpenCL libraries of the PIP_RUNTIMES installed in this environment."""
    found = []
    for package, library in PIP_RUNTIMES.items():
        try:
            distribution = metadata.distribution(package)
        except metadata.PackageNotFoundError:
            continue
        for entry in distribution.files or ():
            if entry.name == library:
                path = Path(distribution.locate_file(entry)).resolve()
                if path.is_file():
                    found.append(path)
                    break
    return found


def _vendor_entries(libraries: list[Path]) -> dict[str, str]:
    """File name → contents of the vendors folder: the system's `.icd` files (unreadable
    ones left out, as the loader would), then one per library."""
    system = Path(os.environ.get("OPENCL_VENDOR_PATH") or SYSTEM_VENDORS)
    entries = {}
    try:
        icd_files = sorted(system.glob("*.icd"))
    except OSError:
        icd_files = []
    for icd in icd_files:
        try:
            entries[icd.name] = icd.read_text()
        except OSError:
            continue
    for library in libraries:
        entries[f"clrays-{library.stem}.icd"] = f"{library}\n"
    return entries


def _write_vendors(entries: dict[str, str]) -> Path:
    """A folder holding exactly `entries`, named by their digest, so processes that agree
    share it and none ever changes one another reads: written beside its final name, then
    renamed into place (the first rename wins; a later writer's copy is dropped)."""
    digest = hashlib.sha256(repr(sorted(entries.items())).encode()).hexdigest()[:16]
    fallback = () if writes_confined() else (Path(tempfile.gettempdir()) / f"clrays-{os.getuid()}",)
    for root in (cache_root(), *fallback):  # confined (--confine): the cache alone
        folder = root / f"opencl-vendors-{digest}"
        if _own_folder(folder):
            return folder
        try:
            root.mkdir(parents=True, exist_ok=True)
            staging = Path(tempfile.mkdtemp(prefix=".vendors-", dir=root))
            for name, text in entries.items():
                (staging / name).write_text(text)
            try:
                staging.rename(folder)
            except OSError:  # another process renamed its copy first
                for child in staging.iterdir():
                    child.unlink()
                staging.rmdir()
            if _own_folder(folder):
                return folder
        except OSError:
            continue  # an unwritable cache: try the temporary folder
    raise OSError("no writable folder for the OpenCL vendors list")


def _own_folder(folder: Path) -> bool:
    """Whether `folder` is a directory of this user's, not a link: the libraries its `.icd`
    files name are loaded, so a folder another user made (in the shared temporary folder)
    or a link to one is never taken."""
    try:
        info = os.lstat(folder)
    except OSError:
        return False
    return stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid()


def register() -> None:
    """Point the ICD loader at the pip-installed runtimes too (once per process; a no-op
    when there are none, or when the user has set OCL_ICD_VENDORS)."""
    global _registered
    if _registered:
        return
    _registered = True
    if os.environ.get("OCL_ICD_VENDORS"):
        return
    libraries = pip_runtime_libraries()
    if not libraries:
        return
    try:
        os.environ["OCL_ICD_VENDORS"] = str(_write_vendors(_vendor_entries(libraries)))
    except OSError:
        pass  # the runtime stays unseen; PoCL and the system's runtimes are there as before


# --------------------------------------------------------------------------- PoCL on this CPU

#: Builds a one-line kernel on PoCL's device: exit 0 when it builds, 1 when the build fails,
#: 2 when there is no PoCL platform.
_POCL_PROBE = """
import sys
import pyopencl as cl
platforms = [p for p in cl.get_platforms() if "pocl" in p.vendor.lower()]
if not platforms:
    sys.exit(2)
context = cl.Context(platforms[0].get_devices()[:1])
try:
    cl.Program(context, "__kernel void probe(__global float *a) { a[0] = 1.0f; }").build()
except cl.RuntimeError:
    sys.exit(1)
"""


def _cpu_identity() -> str:
    """What names this CPU to a compiler: the vendor, family, model and model name of
    /proc/cpuinfo's first processor (else the platform's description)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as cpuinfo:
            first = cpuinfo.read(16384).split("\n\n", 1)[0]
    except OSError:
        return f"{platform.machine()} {platform.processor()}"
    keys = ("vendor_id", "cpu family", "model", "model name", "CPU implementer", "CPU part")
    fields = [line for line in first.splitlines() if line.split(":", 1)[0].strip() in keys]
    return f"{platform.machine()} " + "; ".join(" ".join(line.split()) for line in fields)


def pocl_builds_here() -> bool:
    """Whether PoCL's compiler builds kernels for this CPU. The PoCL that pyopencl's wheel
    carries (3.0, LLVM 14) names a CPU newer than its LLVM (AMD's Zen 5, say) 'generic',
    which LLVM's x86 target refuses, so every build fails there; Intel's CPU runtime
    (`clrays[intel-cpu]`) then serves instead. Found by building a one-line kernel in a
    child process (this process's loader must not be called yet: see `register`), once per
    CPU and pyopencl, and kept in the cache; a probe that cannot run at all says yes, so
    that the build's own error speaks."""
    try:
        pyopencl = metadata.version("pyopencl")
    except metadata.PackageNotFoundError:
        return True
    key = hashlib.sha256(f"{_cpu_identity()}|{pyopencl}|{sys.version_info[:2]}".encode()).hexdigest()[:16]
    verdict = cache_root() / "pocl-builds" / key
    try:
        return verdict.read_text().strip() == "yes"
    except OSError:
        pass
    environment = {k: v for k, v in os.environ.items() if k != "OCL_ICD_VENDORS"}
    try:
        code = subprocess.run([sys.executable, "-c", _POCL_PROBE], env=environment, timeout=120,
                              stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL).returncode
    except (OSError, subprocess.SubprocessError):
        return True
    if code not in (0, 1):
        return True
    try:  # written beside its name, then renamed: a reader sees the whole verdict or none
        verdict.parent.mkdir(parents=True, exist_ok=True)
        staging = verdict.with_name(f".{key}.{os.getpid()}")
        fd = open_file(staging, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        with os.fdopen(fd, "w") as file:
            file.write("yes\n" if code == 0 else "no\n")
        staging.replace(verdict)
    except (OSError, OutputError):
        pass  # an unwritable cache, or something not ours in it: probe again next time
    return code == 0
