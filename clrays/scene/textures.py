"""Reading a light's texture (a gobo, a cookie, a cloud shadow) from an image file into
linear RGB texels (docs/scene-format.md, lights; docs/light-textures.md).

    pixels = read_texture(Path("gobo.png"))      # (H, W, 3) float32, linear, finite, >= 0

- `.png`: 8-bit grey, grey+alpha, RGB, RGBA or palette, or 16-bit grey. PNG files hold
  sRGB-encoded values, so they are decoded to linear with the sRGB transfer function
  (IEC 61966-2-1); alpha is ignored.
- `.exr`: float RGB (or a single Y channel), read through OpenEXR; already linear.
- `.npy`: a float or integer array of shape (H, W), (H, W, 1) or (H, W, 3), taken as
  linear values as they are.

Row 0 is the top of the image. Any problem raises TextureError with one line that does
not name the file (the caller does).

A point light's cube texture (`cube_from_faces`, `cube_from_cross`) is six square faces
stacked in rows, +x, -x, +y, -y, +z, -z (docs/light-textures.md, "Point lights: a cube").
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from .files import FileRefused, read_regular_file

#: Largest texture file read (bytes) and largest side (texels): every texel goes to the
#: device as a float4, so 4096² texels are 256 MiB there.
MAX_TEXTURE_BYTES = 256 << 20
MAX_TEXTURE_SIDE = 4096
TEXTURE_FORMATS = (".png", ".exr", ".npy")


class TextureError(ValueError):
    """A texture file that cannot be used; the message is one line saying what was found, without the path."""


def srgb_to_linear(encoded: np.ndarray) -> np.ndarray:
    """The sRGB decoding of values in [0, 1] (IEC 61966-2-1, the inverse of what an 8-bit
    PNG writer applies)."""
    c = np.asarray(encoded, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def read_texture(path: Path) -> np.ndarray:
    """Linear RGB texels (H, W, 3) float32 of a texture file (module docstring).

    Raises TextureError for a missing or unreadable file, an unknown extension, an array
    that is not an image (1-D, 4-D, 2 channels), an empty image or one with a side over
    MAX_TEXTURE_SIDE, and texels that are NaN, infinite or negative."""
    suffix = Path(path).suffix.lower()
    if suffix not in TEXTURE_FORMATS:
        raise TextureError(f"a {suffix or 'file without an extension'} file, not {', '.join(TEXTURE_FORMATS)}")
    try:
        data = read_regular_file(path, MAX_TEXTURE_BYTES)
    except FileRefused as exc:
        raise TextureError(str(exc)) from None
    if suffix == ".npy":
        pixels = _npy(data)
    elif suffix == ".png":
        pixels = _png(data)
    else:
        pixels = _exr(path)
    return check_texels(pixels)


def check_texels(pixels) -> np.ndarray:
    """An array as texture texels (H, W, 3) float32: shape, size and values checked."""
    a = np.asarray(pixels)
    if a.dtype.kind not in "fiub":
        raise TextureError(f"an array of dtype {a.dtype}, not numbers")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] != 3:
        raise TextureError(f"an array of shape {tuple(np.shape(pixels))}, not an image of shape (H, W) or (H, W, 3)")
    height, width = a.shape[:2]
    if height < 1 or width < 1 or max(height, width) > MAX_TEXTURE_SIDE:
        raise TextureError(f"an image of {width}×{height} texels, not sides in [1, {MAX_TEXTURE_SIDE}]")
    a = a.astype(np.float64)
    bad = ~np.isfinite(a)
    if bad.any():
        y, x, _ = np.argwhere(bad)[0]
        raise TextureError(f"{a[y, x][bad[y, x]][0]} at texel (x={x}, y={y}), {int(bad.any(axis=2).sum())} "
                           f"non-finite texel(s) in all: texels must be finite")
    if (a < 0).any():
        y, x, _ = np.argwhere(a < 0)[0]
        raise TextureError(f"{a[y, x].min():g} at texel (x={x}, y={y}), {int((a < 0).any(axis=2).sum())} "
                           f"negative texel(s) in all: a light cannot take light away")
    if a.max() > np.finfo(np.float32).max / 16:
        raise TextureError(f"a texel of {a.max():g}, over {np.finfo(np.float32).max / 16:.3g} (float32 on the "
                           f"device)")
    return np.ascontiguousarray(a, dtype=np.float32)


def _npy(data: bytes) -> np.ndarray:
    try:
        return np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise TextureError(f"not a .npy array ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None


def _png(data: bytes) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as image:
            if image.format != "PNG":
                raise TextureError(f"a {image.format or 'non-PNG'} image named .png")
            if max(image.size) > MAX_TEXTURE_SIDE:
                raise TextureError(f"an image of {image.size[0]}×{image.size[1]} texels, not sides in "
                                   f"[1, {MAX_TEXTURE_SIDE}]")
            if image.mode in ("I;16", "I;16B", "I;16L", "I"):  # 16-bit grey
                encoded = np.asarray(image, dtype=np.float64) / 65535.0
            else:
                encoded = np.asarray(image.convert("RGB"), dtype=np.float64) / 255.0
    except (UnidentifiedImageError, OSError, SyntaxError) as exc:
        raise TextureError(f"not a readable PNG image ({exc})") from None
    return srgb_to_linear(np.clip(encoded, 0.0, 1.0))


def _exr(path: Path) -> np.ndarray:
    import OpenEXR

    try:
        with OpenEXR.File(str(path)) as exr:
            channels = exr.channels()
            if "RGB" in channels:
                return np.asarray(channels["RGB"].pixels)
            if all(name in channels for name in "RGB"):
                return np.stack([np.asarray(channels[name].pixels) for name in "RGB"], axis=-1)
            if "Y" in channels:
                return np.asarray(channels["Y"].pixels)
            raise TextureError(f"an EXR image with channels {', '.join(sorted(channels)) or 'none'}, not RGB or Y")
    except TextureError:
        raise
    except Exception as exc:  # OpenEXR raises bare exceptions for broken files
        raise TextureError(f"not a readable EXR image ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") \
            from None


#: The cross layout's cells (column, row) of the faces +x, -x, +y, -y, +z, -z: a camera at the
#: light turning right sees +x, +z, -x, -z along the middle row; +y above +z, -y below it.
CROSS_CELLS = ((0, 1), (2, 1), (1, 0), (1, 2), (1, 1), (3, 1))


def cube_from_faces(faces: list[np.ndarray]) -> np.ndarray:
    """Six face images (+x, -x, +y, -y, +z, -z) as one cube texture (6·s, s, 3)."""
    sizes = {face.shape[:2] for face in faces}
    if len(sizes) != 1 or any(h != w for h, w in sizes):
        raise TextureError("faces of sizes " + ", ".join(f"{w}×{h}" for h, w in (f.shape[:2] for f in faces))
                           + ", not six square images of one size")
    return np.ascontiguousarray(np.concatenate(faces, axis=0))


def cube_from_cross(cross: np.ndarray) -> np.ndarray:
    """A cross of 4 × 3 square cells (CROSS_CELLS) as one cube texture (6·s, s, 3)."""
    height, width = cross.shape[:2]
    if width * 3 != height * 4 or width % 4:
        raise TextureError(f"a {width}×{height} image, not a cross of 4 × 3 square cells (width:height = 4:3)")
    s = width // 4
    return cube_from_faces([cross[row * s:(row + 1) * s, col * s:(col + 1) * s] for col, row in CROSS_CELLS])
