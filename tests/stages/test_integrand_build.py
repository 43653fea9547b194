"""The `table` integrand built on the device (cl/integrand_build.cl) against the host's
float64 build of the same rule (clrays/stages/integrand.py _prefix_rows).

The tolerance, 1e-5 of a row's largest value, is 200× below the table's own error (a
segment is within 2e-3 at 128 × 512, docs/integrand.md): float32 rounding of the cells,
PoCL's sin and exp and the compensated running sum must stay that far below it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from clrays.scene.model import Phase
from clrays.stages.integrand import build_integrand, device_table, read_device_table

# (light kind, σs, σt, phase, d_el, β range)
CASES = {
    "point, hg fog": ("point", 0.05, 0.08, Phase("hg", 0.5), 3.0, (0.0, math.pi)),
    "point, rgb medium": ("point", [0.05, 0.02, 0.01], [0.1, 0.06, 0.03], Phase("isotropic", 0.0), 3.0, (0.01, 3.0)),
    "point, no extinction": ("point", 0.05, 0.0, Phase("isotropic", 0.0), 2.0, (0.0, math.pi)),
    "point, dense and forward": ("point", 0.3, 0.9, Phase("hg", 0.8), 10.0, (1e-4, math.pi - 1e-4)),
    "directional, hg": ("directional", 0.05, 0.08, Phase("hg", -0.3), 0.0, (0.1, 2.9)),
    "directional, a clear channel": ("directional", [0.05, 0.04, 0.03], [0.0, 0.05, 0.1], Phase("isotropic", 0.0), 0.0,
                                     (0.0, math.pi)),
}
RELATIVE_TOLERANCE = 1e-5


@pytest.mark.parametrize("name", CASES)
@pytest.mark.parametrize("size", [(128, 512), (16, 64)])
def test_device_table_matches_host(device, name, size):
    kind, sigma_s, sigma_t, phase, d_el, (beta_min, beta_max) = CASES[name]
    extra = {"s_max": 30.0} if kind == "directional" else {}
    args = ("table", kind, sigma_s, sigma_t, phase, 5.0, d_el, beta_min, beta_max, 0.5, *size)
    host = build_integrand(*args, **extra).prefix
    skeleton = build_integrand(*args, rows=False, **extra)
    assert skeleton.prefix is None
    built = read_device_table(device, device_table(device, skeleton), skeleton)
    assert np.isfinite(built).all()
    assert (built[..., 0] == 0).all()
    row_max = np.abs(host).max(axis=-1, keepdims=True)
    error = np.abs(built - host) / np.where(row_max > 0, row_max, 1.0)
    assert error.max() <= RELATIVE_TOLERANCE, f"{name}: {error.max():.2e} of the row's largest value"
