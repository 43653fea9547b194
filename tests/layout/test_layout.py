"""Layer 1: the facts host and device share agree on the device. Every struct of
cl/common.h has the size and field offsets of its numpy dtype, and every constant of
clrays/structs.py reaches the kernels with the same value (float32 for floats, bit for bit)."""
import numpy as np
import pyopencl as cl
import pytest

from clrays import structs
from clrays.device import build_options, kernel_dir
from clrays.scene.model import TRAVERSALS
from clrays.structs import STRUCTS


def _run_probe(device, body: str, out: np.ndarray) -> np.ndarray:
    """Build a one-work-item kernel `probe(global T* out)` around `body` the way the
    stages are built (`build_options`), run it and read `out` back."""
    c_type = {np.int32: "int", np.float32: "float", np.uint32: "uint"}[out.dtype.type]
    source = f'#include "common.h"\nkernel void probe(global {c_type}* out) {{\n{body}\n}}\n'
    program = cl.Program(device.context, source).build(options=build_options())
    buffer = cl.Buffer(device.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    program.probe(device.queue, (1,), None, buffer)
    cl.enqueue_copy(device.queue, out, buffer).wait()
    return out


def test_struct_layout_matches_device(device):
    lines, expected = [], []
    for name, dtype in STRUCTS.items():
        lines.append(f"{{ {name} probe; out[{len(expected)}] = (int)sizeof({name});")
        expected.append(dtype.itemsize)
        for field in dtype.names:
            lines.append(f"  out[{len(expected)}] = (int)((char*)&probe.{field} - (char*)&probe);")
            expected.append(dtype.fields[field][1])
        lines.append("}")
    out = _run_probe(device, "\n".join(lines), np.zeros(len(expected), np.int32))
    assert out.tolist() == expected


def test_every_dtype_is_16_byte_aligned():
    # float4 members need 16-byte alignment, so arrays of these structs must be too.
    for name, dtype in STRUCTS.items():
        assert dtype.itemsize % 16 == 0, name


@pytest.mark.parametrize("kind", ["int", "uint", "float"])
def test_constants_reach_the_device_unchanged(device, kind):
    """The kernels see each constant as Python defines it; a float as float32 (the literal
    must not round differently, nor become a double: `sizeof` says which type it has)."""
    python_type = {"int": int, "uint": np.uint32, "float": float}[kind]
    names = [name for name, value in structs.KERNEL_CONSTANTS.items() if type(value) is python_type]
    assert names
    dtype = {"int": np.int32, "uint": np.uint32, "float": np.float32}[kind]
    body = "\n".join(f"out[{2 * i}] = {name}; out[{2 * i + 1}] = ({kind})sizeof({name});"
                     for i, name in enumerate(names))
    out = _run_probe(device, body, np.zeros(2 * len(names), dtype))
    values, sizes = out[0::2], out[1::2]
    for name, value, size in zip(names, values, sizes):
        expected = dtype(structs.KERNEL_CONSTANTS[name])
        assert value.tobytes() == expected.tobytes(), f"{name}: device {value!r}, Python {expected!r}"
        assert int(size) == 4, f"{name} is {int(size)} bytes on the device, not a 32-bit {kind}"


def test_every_kernel_constant_is_passed():
    """Each shared constant is one `-D` option, with a literal of its C type."""
    options = build_options({"TRAVERSAL": structs.TRAVERSAL_SCAN})
    assert options[0] == f"-I{kernel_dir()}"
    assert options[-1] == f"-DTRAVERSAL={structs.TRAVERSAL_SCAN}"
    assert set(structs.KERNEL_CONSTANTS) == {option[2:].split("=")[0] for option in options[1:-1]}
    assert structs.c_literal(structs.LAMP_RADIUS_REL) == "9.999999974752427e-07f"
    assert structs.c_literal(structs.DEPTH_EMPTY) == "0x7f800000u"


def test_a_build_without_the_constants_fails_with_the_reason(device):
    program = cl.Program(device.context, '#include "common.h"\nkernel void probe(global int* out) { out[0] = 0; }\n')
    with pytest.raises(cl.RuntimeError, match="the constants of clrays/structs.py are missing"):
        program.build(options=[f"-I{kernel_dir()}"])


def test_modules_that_name_a_constant_use_this_value():
    """The host code outside clrays.structs that repeats a constant (the float64 reference,
    the integrand tables, the traversal's index into TRAVERSALS) agrees with it."""
    from clrays.physics import radiometry
    from clrays.stages import integrand

    assert radiometry.LAMP_RADIUS_REL == structs.LAMP_RADIUS_REL
    assert integrand.SIN_BETA_MIN == structs.SIN_BETA_MIN
    assert TRAVERSALS.index("tree") == structs.TRAVERSAL_TREE
    assert TRAVERSALS.index("scan") == structs.TRAVERSAL_SCAN


def test_the_wheel_lists_every_package():
    """pyproject.toml names the packages a wheel ships one by one: a new subpackage left out
    would import in the source tree and be missing after `pip install`."""
    import tomllib
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    listed = set(tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(init.parent.relative_to(root).parts) for init in (root / "clrays").rglob("__init__.py")}
    assert found - listed == set()
