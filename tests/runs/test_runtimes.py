"""The OpenCL runtimes clrays finds (clrays/runtimes.py, `clrays info`) and what the first
run on a device prints."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from clrays import runtimes
from conftest import TEST_DEVICE

REPO = Path(__file__).resolve().parents[2]


def _clrays(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess:
    """`clrays ARGS` in a fresh process: the ICD loader reads its vendors once per process."""
    clean = {k: v for k, v in os.environ.items() if k not in ("OCL_ICD_VENDORS", "CLRAYS_DEVICE")}
    return subprocess.run([sys.executable, "-m", "clrays.cli", *args], capture_output=True, text=True,
                          env={**clean, **env}, cwd=REPO, timeout=600)


def test_a_pip_runtime_joins_the_systems_vendors(tmp_path, monkeypatch):
    system = tmp_path / "system"
    system.mkdir()
    (system / "vendor.icd").write_text("libvendor.so\n")
    library = tmp_path / "lib" / "libintelocl.so"
    monkeypatch.setenv("OPENCL_VENDOR_PATH", str(system))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    entries = runtimes._vendor_entries([library])
    assert entries == {"vendor.icd": "libvendor.so\n", "clrays-libintelocl.icd": f"{library}\n"}
    folder = runtimes._write_vendors(entries)
    assert {path.name: path.read_text() for path in folder.iterdir()} == entries
    assert runtimes._write_vendors(entries) == folder  # the same list: the same folder, untouched


def test_the_users_own_vendors_win(monkeypatch):
    monkeypatch.setattr(runtimes, "_registered", False)
    monkeypatch.setattr(runtimes, "pip_runtime_libraries", lambda: [Path("/nowhere/libintelocl.so")])
    monkeypatch.setenv("OCL_ICD_VENDORS", "/the/users/vendors")
    runtimes.register()
    assert os.environ["OCL_ICD_VENDORS"] == "/the/users/vendors"


def test_a_runtime_registered_twice_is_listed_once_with_one_default(tmp_path):
    # PoCL's library named a second time (as a system-wide PoCL of the same build would be):
    # the loader then reports two platforms alike in every name and version.
    import pyopencl

    library = next((Path(pyopencl.__file__).parent / ".libs").glob("libpocl*.so*"), None)
    if library is None:
        pytest.skip("this pyopencl carries no PoCL library of its own")
    vendors = tmp_path / "vendors"
    vendors.mkdir()
    (vendors / "pocl-again.icd").write_text(f"{library}\n")
    run = _clrays("info", env={"OCL_ICD_VENDORS": str(vendors)})
    assert run.returncode == 0, run.stderr
    devices = [line for line in run.stdout.splitlines() if "/" in line and "CUs" in line]
    pocl = [line for line in devices if "Portable Computing Language" in line]
    assert len(pocl) == 1, run.stdout
    assert sum(line.startswith("*") for line in devices) == 1, run.stdout


def test_the_first_run_says_it_builds_and_keeps_the_compiler_quiet(tmp_path):
    env = {"XDG_CACHE_HOME": str(tmp_path / "cache"), "POCL_CACHE_DIR": str(tmp_path / "pocl"),
           "CLRAYS_DEVICE": TEST_DEVICE}
    render = ("render", "scenes/demo.yaml", "-o", str(tmp_path / "d.png"), "--set", "image.width=16",
              "--set", "image.height=9")
    first = _clrays(*render, env=env)
    assert first.returncode == 0, first.stderr
    lines = first.stderr.splitlines()
    notices = [line for line in lines if line.startswith("building OpenCL kernels for ")]
    assert len(notices) == 1, first.stderr
    assert notices[0].startswith("building OpenCL kernels for ")
    assert notices[0].endswith(" (first run, cached after)")
    assert not any("generated" in line for line in lines), first.stderr
    again = _clrays(*render, env=env)
    assert again.returncode == 0 and "building OpenCL kernels" not in again.stderr, again.stderr


def test_a_default_device_loads_no_pip_runtime():
    # Intel's runtime costs a process about 100 MB once the loader opens it; the default
    # device is a GPU or PoCL's, so only another named device (or `clrays info`) opens it,
    # or the default where PoCL cannot build for this CPU.
    clean = {k: v for k, v in os.environ.items() if k not in ("OCL_ICD_VENDORS", "CLRAYS_DEVICE")}
    specs = ("'pocl'", "'Portable Computing Language'")
    for spec in (("None",) + specs if runtimes.pocl_builds_here() else specs):
        shown = subprocess.run([sys.executable, "-c", f"import os; from clrays.device import Device; Device({spec}); "
                                "print(os.environ.get('OCL_ICD_VENDORS'))"], capture_output=True, text=True,
                               env=clean, cwd=REPO, timeout=300)
        assert shown.returncode == 0, shown.stderr
        assert shown.stdout.strip() == "None", spec


def test_a_named_runtime_that_is_not_installed_says_how_to_install_it(monkeypatch):
    from clrays.device import select_device
    from clrays.errors import DeviceError

    monkeypatch.setattr(runtimes, "pip_runtime_libraries", lambda: [])
    with pytest.raises(DeviceError, match=r"no platform .* contains it \(see `clrays info`\); Intel's CPU runtime "
                                          r"installs with pip install 'clrays\[intel-cpu\]'"):
        select_device("intel-gpu-none")
    with pytest.raises(DeviceError, match=r"contains it \(see `clrays info`\)$"):
        select_device("no-such-device")


def test_the_pocl_verdict_is_probed_once_and_kept(tmp_path, monkeypatch):
    monkeypatch.delenv("CLRAYS_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    calls = []

    def probe(command, **kwargs):
        calls.append(command)
        return subprocess.CompletedProcess(command, 1)  # the probe kernel did not build

    monkeypatch.setattr(runtimes.subprocess, "run", probe)
    assert runtimes.pocl_builds_here() is False
    assert runtimes.pocl_builds_here() is False
    assert len(calls) == 1  # the second answer came from the cache
    kept = list((tmp_path / "clrays" / "pocl-builds").iterdir())
    assert [path.read_text() for path in kept] == ["no\n"]


def test_a_probe_that_cannot_run_says_yes_and_keeps_nothing(tmp_path, monkeypatch):
    monkeypatch.delenv("CLRAYS_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setattr(runtimes.subprocess, "run",
                        lambda command, **kwargs: subprocess.CompletedProcess(command, -11))  # crashed
    assert runtimes.pocl_builds_here() is True
    assert not (tmp_path / "clrays" / "pocl-builds").exists()


def test_where_pocl_cannot_build_the_default_device_is_another_cpu_runtime(tmp_path):
    """A CPU PoCL's compiler does not know (told by the kept verdict): with Intel's runtime
    installed, the default device is Intel's, and a render works; PoCL named outright fails
    in one line that names the runtime to install."""
    if not runtimes.pip_runtime_libraries():
        pytest.skip("Intel's CPU runtime is not installed (make intel-cpu)")
    from clrays.runtimes import _cpu_identity  # the verdict's key, as pocl_builds_here makes it
    import hashlib
    from importlib import metadata

    key = hashlib.sha256(f"{_cpu_identity()}|{metadata.version('pyopencl')}|{sys.version_info[:2]}".encode())
    verdicts = tmp_path / "clrays" / "pocl-builds"
    verdicts.mkdir(parents=True)
    (verdicts / key.hexdigest()[:16]).write_text("no\n")
    run = _clrays("info", env={"XDG_CACHE_HOME": str(tmp_path)})
    assert run.returncode == 0, run.stderr
    default = [line for line in run.stdout.splitlines() if line.startswith("*") and "CUs" in line]
    assert len(default) == 1 and "Portable Computing Language" not in default[0], run.stdout
