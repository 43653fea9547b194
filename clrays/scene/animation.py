"""Keyframe animation: the `animation` block of a scene file, and a Scene per frame.

    scene = load_scene("scenes/orbit.yaml")
    for frame in scene.animation.frames:             # range(first, last + 1)
        frame_scene = scene.animation.scene_at(scene, frame)

A *track* is one animated property (the camera's position, light 0's intensity,
object 2's rotation, the medium's σs): its keys are (frame, value, easing), in
increasing frame order. Between two keys the value moves from the first to the second
as t goes 0 → 1 across the frames, with t reshaped by the first key's easing; before
the first key and after the last the value holds. Vectors and scalars interpolate
linearly, rotations (quaternions [w, x, y, z]) by SLERP, unit directions along the
great circle. Properties without a track keep the scene's own values. The format is in
docs/scene-format.md ("animation").
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Iterator, Literal, Mapping

import numpy as np

from .model import Box, Geometry, GridDensity, Medium, Phase, Scene
from .geometry import flat_normals
from .transforms import affine, quat_rotate, quat_to_matrix, slerp, transform_normals, transform_points

#: Easing curves: the fraction of the way from one key to the next at t in [0, 1].
EASINGS = {
    "linear": lambda t: t,
    "ease_in": lambda t: t * t,  # starts slow
    "ease_out": lambda t: 1.0 - (1.0 - t) * (1.0 - t),  # ends slow
    "ease_in_out": lambda t: t * t * (3.0 - 2.0 * t),  # smoothstep: slow at both ends
    "step": lambda t: 0.0,  # hold the key's value until the next key
}

#: Interpolation of a track's values: linear, SLERP of unit quaternions, or unit
#: directions along the great circle between them.
Kind = Literal["linear", "rotation", "direction"]

#: Camera space looks down -z with +y up (OpenGL), so an orientation q points the
#: camera along q·(0, 0, -1) with up q·(0, 1, 0).
CAMERA_FORWARD = np.array([0.0, 0.0, -1.0])
CAMERA_UP = np.array([0.0, 1.0, 0.0])


@dataclass(frozen=True)
class Key:
    frame: float
    value: np.ndarray | float
    easing: str = "linear"  # of the way from this key to the next


@dataclass(frozen=True)
class Track:
    kind: Kind
    keys: tuple[Key, ...]

    def at(self, frame: float):
        """The track's value at `frame` (a float: sub-frames interpolate too)."""
        keys = self.keys
        if frame <= keys[0].frame:
            return keys[0].value
        if frame >= keys[-1].frame:
            return keys[-1].value
        i = int(np.searchsorted([k.frame for k in keys], frame, side="right")) - 1
        a, b = keys[i], keys[i + 1]
        u = EASINGS[a.easing]((frame - a.frame) / (b.frame - a.frame))
        if u <= 0.0:  # exact key values at the keys, whatever the interpolation
            return a.value
        if u >= 1.0:
            return b.value
        if self.kind == "rotation":
            return slerp(a.value, b.value, u)
        if self.kind == "direction":
            return slerp_direction(a.value, b.value, u)
        return a.value + (b.value - a.value) * u


    def at_frames(self, frames: np.ndarray) -> np.ndarray:
        """`at` for many frames at once, (F,) or (F, n) float64: the same values, a loop over
        the keys rather than the frames, so checking 100 000 frames takes milliseconds.
        Linear and direction tracks only (rotations interpolate one frame at a time)."""
        assert self.kind in ("linear", "direction"), self.kind
        frames = np.asarray(frames, dtype=np.float64)
        keys = self.keys
        values = np.array([np.asarray(k.value, dtype=np.float64) for k in keys])
        segment = np.clip(np.searchsorted([k.frame for k in keys], frames, side="right") - 1, 0, len(keys) - 1)
        out = values[segment].copy()  # the key at or before each frame (and the first before it)
        for i in range(len(keys) - 1):
            rows = np.nonzero((segment == i) & (frames > keys[i].frame))[0]
            if not len(rows):
                continue
            a, b = values[i], values[i + 1]
            u = np.broadcast_to(EASINGS[keys[i].easing]((frames[rows] - keys[i].frame)
                                                       / (keys[i + 1].frame - keys[i].frame)), rows.shape)
            u = u.reshape(-1, *([1] * (values.ndim - 1)))
            if self.kind == "direction":
                angle = math.acos(float(np.clip(a @ b, -1.0, 1.0)))
                if math.sin(angle) < 1e-9:
                    v = a + (b - a) * u
                else:
                    v = (np.sin((1.0 - u) * angle) * a + np.sin(u * angle) * b) / math.sin(angle)
                v = v / np.linalg.norm(v, axis=-1, keepdims=True)
            else:
                v = a + (b - a) * u
            out[rows] = np.where(u <= 0.0, a, np.where(u >= 1.0, b, v))
        return out


def slerp_direction(a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    """The unit vector a fraction t of the way from unit a to unit b along the great
    circle (constant angular speed). a and b must not be opposite."""
    cos_angle = float(np.clip(a @ b, -1.0, 1.0))
    angle = math.acos(cos_angle)
    if math.sin(angle) < 1e-9:
        v = a + (b - a) * t
    else:
        v = (math.sin((1.0 - t) * angle) * a + math.sin(t * angle) * b) / math.sin(angle)
    return v / np.linalg.norm(v)


@dataclass(frozen=True)
class ObjectRig:
    """What an animated object is made of: its triangles (and a smooth object's vertex
    normals) before its transform, where they sit in `Scene.geometry`, and its static
    transform (the values its tracks replace)."""

    local: np.ndarray  # (T, 3, 3) float64, the object's own coordinates
    rows: slice  # its triangles in Scene.geometry.triangles
    translate: np.ndarray  # (3,)
    rotate: np.ndarray  # unit quaternion [w, x, y, z]
    scale: np.ndarray  # (3,)
    local_normals: np.ndarray | None = None  # (T, 3, 3) a smooth object's vertex normals; None: flat


@dataclass(frozen=True)
class DensityDrift:
    """A grid or noise density whose `offset` has keys (`medium: [{frame, offset}]`): a grid's
    `values` move with the offset (its `bounds` as written, at offset 0); noise is baked
    again over `bounds` at each offset, from `noise` = (frequency, octaves, seed,
    resolution) (clrays.scene.density_sources.bake_noise). `where` names the field for a
    failed bake."""

    bounds: Box
    values: np.ndarray | None = None
    noise: tuple | None = None
    where: str = ""

    def at(self, offset) -> GridDensity:
        offset = np.asarray(offset, dtype=np.float64)
        if self.noise is None:
            return GridDensity(self.values, Box(self.bounds.min + offset, self.bounds.max + offset))
        from .density_sources import bake_noise

        frequency, octaves, seed, resolution = self.noise
        return GridDensity(bake_noise(frequency, octaves, seed, offset, self.bounds, resolution, self.where),
                           self.bounds)


@dataclass(frozen=True)
class Animation:
    """Keyframed tracks and the frame range: see the module docstring."""

    fps: float
    first: int  # first frame, inclusive
    last: int  # last frame, inclusive
    camera: Mapping[str, Track] = field(default_factory=dict)  # position, look_at, up, orientation, fov_deg
    lights: Mapping[int, Mapping[str, Track]] = field(default_factory=dict)  # light index → its tracks
    objects: Mapping[int, tuple[ObjectRig, Mapping[str, Track]]] = field(default_factory=dict)
    medium: Mapping[str, Track] = field(default_factory=dict)  # sigma_s, sigma_a, g, offset
    drift: DensityDrift | None = None  # the density an `offset` track moves

    @property
    def frames(self) -> range:
        return range(self.first, self.last + 1)

    def time(self, frame: float) -> float:
        """Seconds from frame 0 at `fps`."""
        return frame / self.fps

    def scene_at(self, scene: Scene, frame: float) -> Scene:
        """The scene as it stands at `frame`: every track applied, no animation left."""
        return replace(scene, camera=self._camera(scene, frame), lights=self._lights(scene, frame),
                       medium=self._medium(scene, frame), geometry=self._geometry(scene, frame), animation=None)

    def _camera(self, scene: Scene, frame: float):
        tracks, camera = self.camera, scene.camera
        if not tracks:
            return camera
        changes = {name: tracks[name].at(frame) for name in ("position", "look_at", "up", "fov_deg") if name in tracks}
        if "orientation" in tracks:
            q = tracks["orientation"].at(frame)
            position = changes.get("position", camera.position)
            changes["look_at"] = position + quat_rotate(q, CAMERA_FORWARD)
            changes["up"] = quat_rotate(q, CAMERA_UP)
        return replace(camera, **changes)

    def _lights(self, scene: Scene, frame: float):
        lights = list(scene.lights)
        for index, tracks in self.lights.items():
            lights[index] = replace(lights[index], **{name: track.at(frame) for name, track in tracks.items()})
        return tuple(lights)

    def _medium(self, scene: Scene, frame: float) -> Medium:
        if not self.medium:
            return scene.medium
        medium = scene.medium
        changes = {name: self.medium[name].at(frame) for name in ("sigma_s", "sigma_a") if name in self.medium}
        if "g" in self.medium:
            changes["phase"] = Phase(type="hg", g=float(self.medium["g"].at(frame)))
        if "offset" in self.medium:
            changes["density"] = self.drift.at(self.medium["offset"].at(frame))
        return replace(medium, **changes)

    def _geometry(self, scene: Scene, frame: float) -> Geometry:
        if not self.objects:
            return scene.geometry
        triangles, normals = scene.geometry.triangles.copy(), scene.geometry.normals.copy()
        for rig, tracks in self.objects.values():
            parts = {"translate": rig.translate, "rotate": rig.rotate, "scale": rig.scale}
            parts.update({name: track.at(frame) for name, track in tracks.items()})
            matrix = affine(parts["translate"], quat_to_matrix(parts["rotate"]), parts["scale"])
            triangles[rig.rows] = transform_points(matrix, rig.local)
            normals[rig.rows] = (flat_normals(triangles[rig.rows]) if rig.local_normals is None
                                 else transform_normals(matrix, rig.local_normals))
        return replace(scene.geometry, triangles=triangles, normals=normals)


def frame_scenes(scene: Scene, frames=None) -> Iterator[tuple[int, Scene]]:
    """(frame, scene at that frame) for `frames` (default: the animation's range); a
    scene without an animation is one frame, 0."""
    if scene.animation is None:
        for frame in (frames if frames is not None else [0]):
            yield frame, scene
        return
    for frame in (frames if frames is not None else scene.animation.frames):
        yield frame, scene.animation.scene_at(scene, frame)


def scene_at(scene, frame: int):
    """Frame `frame` of `scene`'s animation; a still scene is its own frame."""
    return scene.animation.scene_at(scene, frame) if scene.animation is not None else scene
