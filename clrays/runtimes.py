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
import stat
import tempfile
from importlib import metadata
from pathlib import Path

from .outputs import cache_root, writes_confined

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
