"""Layer 1: every struct of cl/common.h has the size and field offsets of its numpy dtype."""
import numpy as np
import pyopencl as cl

from clrays.device import kernel_dir
from clrays.structs import STRUCTS


def test_struct_layout_matches_device(device):
    lines, expected = [], []
    for name, dtype in STRUCTS.items():
        lines.append(f"{{ {name} probe; global_out[{len(expected)}] = (int)sizeof({name});")
        expected.append(dtype.itemsize)
        for field in dtype.names:
            lines.append(f"  global_out[{len(expected)}] = (int)((char*)&probe.{field} - (char*)&probe);")
            expected.append(dtype.fields[field][1])
        lines.append("}")
    source = '#include "common.h"\nkernel void layout(global int* global_out) {\n' + "\n".join(lines) + "\n}\n"
    program = cl.Program(device.context, source).build(options=[f"-I{kernel_dir()}"])
    out = np.zeros(len(expected), np.int32)
    buffer = cl.Buffer(device.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    program.layout(device.queue, (1,), None, buffer)
    cl.enqueue_copy(device.queue, out, buffer).wait()
    assert out.tolist() == expected


def test_every_dtype_is_16_byte_aligned():
    # float4 members need 16-byte alignment, so arrays of these structs must be too.
    for name, dtype in STRUCTS.items():
        assert dtype.itemsize % 16 == 0, name
