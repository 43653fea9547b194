"""cl/lanes.h's loads of runs and transposes of records: what each lane of the vectors holds,
against the arrays they were read from (the kernels that use them are checked for the same
bits as before by their images; this pins the lane order itself)."""
import numpy as np
import pytest

from clrays.device import build_options

_PROBE = """
#include "common.h"
#include "lanes.h"
kernel void probe(global const float4* records, global const int* index, global const float* floats, int first,
                  global float* out)
{
    float_lanes x, y, z, w, even, odd;
    gather_records(records, vload8(0, index), &x, &y, &z, &w);
    load_pairs_run(floats, first, &even, &odd);
    float_lanes rows[8] = {x, y, z, w, even, odd, load_run(floats, first),
                           as_float8(load_int_run((global const int*)floats, first))};
    for (int k = 0; k < 8; ++k) vstore8(rows[k], k, out);
}
"""


@pytest.mark.parametrize("first", [0, 1, 5, 24])
def test_runs_and_records_land_in_lane_order(device, first):
    rng = np.random.default_rng(first)
    records = rng.standard_normal((40, 4)).astype(np.float32)
    index = rng.integers(0, len(records), 8).astype(np.int32)
    floats = rng.standard_normal(2 * (first + 8) + 8).astype(np.float32)
    out = device.buffer(nbytes=4 * 64)
    program = device.cl.Program(device.context, _PROBE).build(options=build_options())
    inputs = [device.buffer(array, writable=False) for array in (records, index, floats)]
    program.probe(device.queue, (1,), None, *inputs, np.int32(first), out)
    rows = device.read(out, 64, np.float32).reshape(8, 8)
    lanes = np.arange(8)
    np.testing.assert_array_equal(rows[:4], records[index].T)  # x, y, z, w of each lane's record
    np.testing.assert_array_equal(rows[4], floats[2 * (first + lanes)])
    np.testing.assert_array_equal(rows[5], floats[2 * (first + lanes) + 1])
    np.testing.assert_array_equal(rows[6], floats[first + lanes])
    np.testing.assert_array_equal(rows[7].view(np.int32), floats[first + lanes].view(np.int32))


_RUN_PROBE = """
#include "common.h"
#include "lanes.h"
kernel void probe(global const float4* records, int first, global float* out, global float4* stored,
                  global float* pairs)
{
    float_lanes x, y, z, w;
    load_records_run(records, first, &x, &y, &z, &w);
    float_lanes rows[4] = {x, y, z, w};
    for (int k = 0; k < 4; ++k) vstore8(rows[k], k, out);
    float_lanes runs[4];
    records_of_lanes(x, y, z, w, runs);
    for (int k = 0; k < 4; ++k) *(global float8_at_float*)((global float*)stored + 8 * k) = runs[k];
    store_pairs_run(pairs, 1, x, y);
}
"""


@pytest.mark.parametrize("first", [0, 3, 17])
def test_runs_of_records_load_and_store_in_lane_order(device, first):
    rng = np.random.default_rng(first)
    records = rng.standard_normal((first + 8, 4)).astype(np.float32)
    out, stored, pairs = device.buffer(nbytes=4 * 32), device.buffer(nbytes=16 * 8), device.buffer(nbytes=4 * 18)
    program = device.cl.Program(device.context, _RUN_PROBE).build(options=build_options())
    program.probe(device.queue, (1,), None, device.buffer(records, writable=False), np.int32(first), out, stored,
                  pairs)
    run = records[first:first + 8]
    np.testing.assert_array_equal(device.read(out, 32, np.float32).reshape(4, 8), run.T)  # x, y, z, w over lanes
    np.testing.assert_array_equal(device.read(stored, 32, np.float32).reshape(8, 4), run)  # back as records
    # lane k's (x, y) at floats 2·(1 + k) and the one after
    np.testing.assert_array_equal(device.read(pairs, 18, np.float32)[2:].reshape(8, 2), run[:, :2])
