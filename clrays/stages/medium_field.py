"""Where the medium is and how dense, on the device: the walk feature MEDIUM_FIELD
(cl/medium.h, docs/media.md). A scene whose medium fills all space with one density
(`Medium.homogeneous`) has none, and its kernels are built as before; otherwise the walks
integrate each ray's lit runs from its own prefix of in-scattering, and shade attenuates
surfaces by the medium's transmittance along the light's path and the camera ray."""
from __future__ import annotations

import numpy as np

from .. import structs
from ..errors import ClraysError
from ..scene.model import GridDensity, HeightDensity, Medium


class MediumField:
    """The walk feature MEDIUM_FIELD: one medium_t (eye space) in a device buffer."""

    def __init__(self, buffer):
        self.buffer = buffer

    def defines(self) -> dict:
        return {"MEDIUM_FIELD": 1}

    def args(self) -> tuple:
        return (self.buffer,)


def medium_params(medium: Medium, eye_ws) -> np.ndarray:
    """medium_t of `medium`, its box and height base moved to eye space (the camera at the
    origin, as every position the kernels see: cl/common.h)."""
    eye = np.asarray(eye_ws, dtype=np.float64)
    params = np.zeros((), dtype=structs.medium_dtype)
    if medium.bounds is not None:
        params["bounded"] = 1
        params["box_min"] = structs.float4(np.asarray(medium.bounds.min, np.float64) - eye)
        params["box_max"] = structs.float4(np.asarray(medium.bounds.max, np.float64) - eye)
    if isinstance(medium.density, HeightDensity):
        params["height_base"] = medium.density.base - eye[1]
        params["inv_scale_height"] = 1.0 / medium.density.scale_height
    return params


def refuse_medium(medium: Medium, method: str) -> None:
    """One line where the device cannot render this medium with `method`: a density grid
    (its optical depth towards the light needs the per-light grid of docs/media.md, not yet
    on the device), and volume_moments, whose prefix sums are of the homogeneous integrand."""
    if medium.homogeneous:
        return
    if isinstance(medium.density, GridDensity):
        raise ClraysError(f"method {method}: medium.density of type grid is not supported on the device yet; "
                          "render it with --method exact")
    if method == "volume_moments":
        raise ClraysError("method volume_moments: medium.bounds and medium.density need method minmax "
                          "(its prefix sums hold the homogeneous medium's integrand only)")


def medium_field(device, medium: Medium, eye_ws, method: str) -> MediumField | None:
    """The frame's MEDIUM_FIELD, None for a homogeneous medium; ClraysError (one line) for a
    medium `method` cannot render (`refuse_medium`)."""
    if medium.homogeneous:
        return None
    refuse_medium(medium, method)
    return MediumField(device.buffer(medium_params(medium, eye_ws), writable=False))
