"""What a directional light's shadow map covers (docs/design.md §4.1, the light views).

The map is orthographic along the light. Every occluder lies in the scene's bounding box,
so the map needs to cover the box's outline on a plane across the light and no more: a
point whose light ray misses that outline meets no geometry and is lit. The map is the
rectangle around that outline, its sides along the map's axes (right: the light's
direction crossed with the world's up, or with x for a light within about 25° of
vertical), so its texels may be longer one way than the other.

It was a square around the box's bounding sphere. For a room the rectangle is far
smaller: scenes/lattice.yaml's sphere is 13.0 units across, the rectangle 10.3 × 8.7;
scenes/sun.yaml's 16.1 against 12.2 × 10.5. Slats under a sun
(tests/stages/test_shaft_edges.py) went from 0.318 to 0.214 % relative RMSE against
`exact` with a 512² map, 0.162 to 0.127 % with 1024². The least-area rectangle, turned
to lie along an edge of the outline, was smaller still (the lattice's 10.5 × 8.1) but
put the slats' edges, which run along the world's axes as most scenes' do, across the
texels: 0.420 and 0.184 %. Depths along the light still start at the sphere's near side,
and the map depends on the bounds and the light alone, never on the eye, so a moving
camera keeps it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Widening of the map's rectangle and of the sphere that sets its depth origin: a vertex
#: on the bounds stays inside the map after float32 rounding.
MAP_MARGIN = 1.01


@dataclass(frozen=True)
class DirectionalMap:
    """A directional light's orthographic map in world space (float64)."""

    anchor: np.ndarray  # where its depths start: the centre of its near side
    right: np.ndarray  # unit, across the light
    up: np.ndarray  # unit, across the light and `right`
    half_width: float  # half the rectangle's extent along `right`
    half_height: float  # ... along `up`

    @property
    def texel_side(self) -> float:
        """The larger of the rectangle's two extents: its texels are at most this / n long."""
        return 2.0 * max(self.half_width, self.half_height)


def up_hint(forward) -> np.ndarray:
    """A light view's up before it is made square to `forward`: the world's y, or its x for
    a view within about 25° of vertical (any vector not parallel to forward serves)."""
    forward = np.asarray(forward, float)
    return np.array([0.0, 1.0, 0.0]) if abs(forward[1]) < 0.9 else np.array([1.0, 0.0, 0.0])


def directional_map(lo: np.ndarray, hi: np.ndarray, direction) -> DirectionalMap:
    """The map of a light shining along `direction` over the box [lo, hi] (module docstring)."""
    forward = np.asarray(direction, dtype=np.float64)
    forward = forward / np.linalg.norm(forward)
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    centre = (lo + hi) / 2
    radius = max(np.linalg.norm(hi - lo) / 2, 1e-6) * MAP_MARGIN
    right = np.cross(forward, up_hint(forward))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    a, b = (corners - centre) @ right, (corners - centre) @ up
    middle = centre + right * (a.max() + a.min()) / 2 + up * (b.max() + b.min()) / 2
    half_width = max(np.ptp(a) / 2, 1e-6 * radius) * MAP_MARGIN
    half_height = max(np.ptp(b) / 2, 1e-6 * radius) * MAP_MARGIN
    return DirectionalMap(middle - forward * radius, right, up, float(half_width), float(half_height))
