"""Render passes (AOVs): the terms a frame's image is made of, for compositing
(docs/scene-format.md, "Render passes").

Per pixel, over its `image.spp` sample rays (each ray's first surface at distance D, or
none within the camera's far: then D = far and the "surface" is the background):

- `transmittance` T = mean over the samples of e^{-σt·D};
- `surface` S = mean(L_surf · e^{-σt·D}) / T: the radiance leaving the first surface (the
  background colour where there is none), before attenuation, weighted by its attenuation
  (with one sample per pixel, L_surf itself); 0 where T = 0;
- `in_scatter` I = mean of the medium's radiance reaching the eye along the ray, every light's;
- `in_scatter_light<i>`: the same, light i's alone;
- `depth` = the nearest sample's distance D along its ray to a surface; +∞ where no sample
  meets one (a .png maps it to grey as depth / far, white there).

So that, up to float32 rounding, the image = S × T + I (the background's term, its colour
× its attenuation to the far end, is S × T where no surface is seen), and
I = Σ_i in_scatter_light<i>. A frame asked for no pass computes and allocates none.
"""
from __future__ import annotations

import re
from glob import escape as glob_escape
from pathlib import Path

import numpy as np

from .image_io import check_finite, check_output_path, write_atomic, write_exr, write_frame, write_image
from .physics.radiometry import effective_far

#: The passes every scene has; `in_scatter_light<i>` are the others, one per light.
PASSES = ("in_scatter", "transmittance", "surface", "depth")
_PER_LIGHT = re.compile(r"^in_scatter_light(0|[1-9][0-9]{0,3})$")


def pass_problem(name: object, light_count: int) -> str | None:
    """What is wrong with a pass name for a scene with `light_count` lights, or None."""
    if not isinstance(name, str):
        return "a pass name"
    if name in PASSES:
        return None
    match = _PER_LIGHT.match(name)
    if match is None:
        return f"one of {', '.join(PASSES)} or in_scatter_light<i>"
    if int(match[1]) >= light_count:
        return f"in_scatter_light<i> with i below the scene's {light_count} light(s)"
    return None


def per_light_indices(names) -> list[int]:
    """The lights whose own in-scattering the passes `names` ask for, in order."""
    return sorted({int(match[1]) for match in map(_PER_LIGHT.match, names) if match})


def assemble(names, transmittance, attenuated_surface, in_scatter, depth, per_light=None) -> dict[str, np.ndarray]:
    """The requested passes, float32, from per-pixel means (float64 or float32): T, mean(L_surf·T),
    the in-scattering, the depth (H, W) and, for `in_scatter_light<i>`, {i: (H, W, 3)}."""
    transmittance = np.asarray(transmittance, dtype=np.float64)
    surface = np.divide(attenuated_surface, transmittance, out=np.zeros_like(transmittance),
                        where=transmittance > 0)
    out = {}
    for name in names:
        if name == "transmittance":
            out[name] = transmittance
        elif name == "surface":
            out[name] = surface
        elif name == "in_scatter":
            out[name] = in_scatter
        elif name == "depth":
            out[name] = depth
        else:
            out[name] = per_light[int(_PER_LIGHT.match(name)[1])]
    return {name: np.ascontiguousarray(value, dtype=np.float32) for name, value in out.items()}


def samples_to_pixels(samples: np.ndarray, height: int, width: int, spp: int) -> np.ndarray:
    """(samples, 4) float32 per camera sample (sample = pixel · spp + s) → (H, W, 3) float64 means."""
    return samples.reshape(height, width, spp, -1)[..., :3].astype(np.float64).mean(axis=2)


def pass_path(output: Path, name: str) -> Path:
    """Where a .png or .npy output's pass goes: `<stem>.<pass>.<ext>` beside it."""
    return output.with_name(f"{output.stem}.{name}{output.suffix}")


def pass_paths(output: Path, names) -> list[Path]:
    """Every file a render to `output` with the passes `names` writes, the image first."""
    if output.suffix.lower() == ".exr" or not names:
        return [output]
    return [output, *(pass_path(output, name) for name in names)]


def written_pass_files(output: Path) -> list[Path]:
    """The pass files beside a .png or .npy `output` that some render wrote (any pass name,
    `<stem>.<pass>.<ext>`): what goes with a frame that is rendered again."""
    if output.suffix.lower() == ".exr":
        return []
    prefix, suffix = f"{output.stem}.", output.suffix
    return [path for path in output.parent.glob(f"{glob_escape(output.stem)}.*{suffix}")
            if (name := path.name[len(prefix):-len(suffix)]) in PASSES or _PER_LIGHT.match(name)]


def exr_layers(image: np.ndarray, passes: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The channels of a multi-layer EXR: the image in R, G, B; each pass as `<name>.R/.G/.B`,
    depth as `depth.Z` (how Nuke and Blender name a layer's channels)."""
    channels = {"R": image[..., 0], "G": image[..., 1], "B": image[..., 2]}
    for name, value in passes.items():
        if name == "depth":
            channels["depth.Z"] = value
        else:
            channels.update({f"{name}.{c}": value[..., k] for k, c in enumerate("RGB")})
    return {name: np.ascontiguousarray(value, dtype=np.float32) for name, value in channels.items()}


def depth_as_grey(depth: np.ndarray, far: float) -> np.ndarray:
    """A depth pass as linear grey (H, W, 3) for a .png: depth / far, 1 where no surface."""
    grey = np.minimum(np.where(np.isfinite(depth), depth / far, 1.0), 1.0)
    return np.repeat(grey[..., None], 3, axis=2).astype(np.float32)


def write_render(path, result, scene, exposure: float, subject: str) -> str:
    """Write a RenderResult's image and its passes (if any) beside it, each checked finite
    (depth: finite or +∞) and written atomically; returns the `file_digest` of the file at
    `path` (what a sequence's manifest ties the frame to)."""
    image = check_finite(result.image, subject)
    passes = result.passes
    for name, value in (passes or {}).items():
        check_finite(np.where(np.isposinf(value), 0.0, value) if name == "depth" else value, subject)
    return write_with_passes(path, image, passes, exposure, effective_far(scene))


def write_with_passes(path: str | Path, radiance: np.ndarray, passes: dict[str, np.ndarray] | None,
                      exposure: float = 0.0, far: float = 1.0) -> str:
    """Write the image and its render passes (clrays.passes), each atomically; returns the
    `file_digest` of the file at `path`. `.exr`: one multi-layer file (`exr_layers`).
    `.png` and `.npy`: the image at `path` and each pass at `<stem>.<pass>.<ext>`; a .png's
    depth is 8-bit grey, depth / `far` (white where no surface), and its other passes as the
    image is encoded."""
    path = check_output_path(path)
    if not passes:
        return write_frame(path, radiance, exposure)
    suffix = path.suffix.lower()
    if suffix == ".exr":
        channels = exr_layers(np.asarray(radiance, dtype=np.float32), passes)
        return write_atomic(path, lambda temporary: write_exr(temporary, channels), content_digest=True)
    for name, value in passes.items():
        target = pass_path(path, name)
        if name == "depth" and suffix == ".png":
            grey = np.round(depth_as_grey(value, far) * 255).astype(np.uint8)

            def write(temporary: str, grey=grey) -> None:
                from PIL import Image

                Image.fromarray(grey, mode="RGB").save(temporary, format="PNG")

            write_atomic(check_output_path(target), write)
        else:
            write_image(target, value, exposure)
    # The image last: a file at `path` means its passes are there too (sequence skips it).
    return write_frame(path, radiance, exposure)
