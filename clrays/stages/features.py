"""What a row walk may carry besides the tree and the integrand, on the host side of
cl/walk_features.h (docs/design.md §4.5, "Features of the walk"): a light's texture (stage
light_texture: `TextureTables`), its rectified translucent layers (stage translucency:
`RectifiedLayers`), the blockers that place its runs' ends (clrays/stages/shaft_edges.py:
`ShaftEdges`), the reliefs it cuts itself (clrays/stages/relief_cuts.py: `ReliefCuts`) and
where the medium is and how dense (clrays/stages/medium_field.py: `MediumField`).
Each offers its build defines (`defines()`) and its kernel arguments (`args()`); a walking kernel built with a feature's defines takes its arguments after its
own, in the order of `walk_features` (the kernel's WALK_FEATURE_ARGS). A feature the frame
does not have is None, adds nothing, and leaves the kernel as it was without it.
"""
from __future__ import annotations

from typing import Protocol


class WalkFeature(Protocol):
    def defines(self) -> dict: ...

    def args(self) -> tuple: ...


def walk_features(texture: WalkFeature | None, layers: WalkFeature | None,
                  edges: WalkFeature | None = None, reliefs: WalkFeature | None = None,
                  medium: WalkFeature | None = None) -> tuple[WalkFeature, ...]:
    """The features a walk carries, in cl/walk_features.h's order: texture, layers, edges,
    reliefs, medium."""
    return present(texture, layers, edges, reliefs, medium)


def present(*features: WalkFeature | None) -> tuple[WalkFeature, ...]:
    """The features a frame has, in the order given (a kernel's argument groups' order); the
    same interface serves the kernels that look translucent layers up without walking a row
    (raymarch and the camera's composite: cl/translucency.h's TRANSLUCENCY_ARGS)."""
    return tuple(feature for feature in features if feature is not None)


def feature_defines(features: tuple[WalkFeature, ...], defines: dict | None = None) -> dict:
    """A walking kernel's build defines: its own, then each feature's."""
    merged = dict(defines or {})
    for feature in features:
        merged.update(feature.defines())
    return merged


def feature_args(features: tuple[WalkFeature, ...]) -> tuple:
    """The kernel arguments every feature appends, in order."""
    return tuple(argument for feature in features for argument in feature.args())
