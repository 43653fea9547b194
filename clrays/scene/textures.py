"""Reading a light's texture (a gobo, a cookie, a cloud shadow) from an image file into
linear RGB texels (docs/scene-format.md, lights; docs/light-textures.md).

    pixels = read_texture(Path("gobo.png"))      # (H, W, 3) float32, linear, finite, >= 0
    cache = TextureCache()                        # within a scene: each file decoded once

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
import os
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import ClraysError
from .files import FileRefused, read_regular_file
from .image_files import ImageFileError, image_shape, load_npy, npy_header

#: Largest texture file read (bytes) and largest side (texels): every texel goes to the
#: device as a float4, so 4096² texels are 256 MiB there.
MAX_TEXTURE_BYTES = 256 << 20
MAX_TEXTURE_SIDE = 4096
#: Texels of all the lights' textures together, each texture shared by lights counted once:
#: 2²⁵, two 4096² textures or a cube of six 2048² faces, 512 MiB as float4 on the device
#: (docs/limits.md). A point light's cube of six 4096² faces (1.6 GB there) is refused.
MAX_SCENE_TEXTURE_TEXELS = 1 << 25
#: The largest texel: beyond it float32 sums of texels (bilinear, prefix sums) overflow.
MAX_TEXEL = float(np.finfo(np.float32).max) / 16
TEXTURE_FORMATS = (".png", ".exr", ".npy")


class TexelCrossingsError(ClraysError):
    """`exact` would cut its rays at more texel centres of a light's texture than it
    integrates (clrays.physics.light_texture.MAX_TEXEL_CROSSINGS); one line for the user."""


class TextureError(ValueError):
    """A texture file that cannot be used; the message is one line saying what was found, without the path.
    `face`: which of a cube's six files, when it is one of them."""

    face: int | None = None


def srgb_to_linear(encoded: np.ndarray) -> np.ndarray:
    """The sRGB decoding of values in [0, 1] (IEC 61966-2-1, the inverse of what an 8-bit
    PNG writer applies)."""
    c = np.asarray(encoded, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def read_texture(path: Path, check_shape: Callable[[int, int], None] | None = None) -> np.ndarray:
    """Linear RGB texels (H, W, 3) float32 of a texture file (module docstring).

    Raises TextureError for a missing or unreadable file, an unknown extension, content
    of another format than the extension says (a JPEG named .png), an array that is not
    an image (1-D, 4-D, 2 channels), an empty image or one with a side over
    MAX_TEXTURE_SIDE, and texels that are NaN, infinite or negative. The size comes from
    the file's header and is checked before anything is decoded, by
    `check_shape(height, width)` too when given (it raises TextureError)."""
    suffix = Path(path).suffix.lower()
    if suffix not in TEXTURE_FORMATS:
        raise TextureError(f"a {suffix or 'file without an extension'} file, not {', '.join(TEXTURE_FORMATS)}")
    try:
        data = read_regular_file(path, MAX_TEXTURE_BYTES)
    except FileRefused as exc:
        raise TextureError(str(exc)) from None
    try:
        if suffix == ".npy":
            shape = npy_header(data)[0]
            if len(shape) not in (2, 3):
                raise TextureError(f"an array of shape {shape}, not an image of shape (H, W) or (H, W, 3)")
        height, width = image_shape(data, suffix, path)
        if height < 1 or width < 1 or max(height, width) > MAX_TEXTURE_SIDE:
            raise TextureError(f"an image of {width}×{height} texels, not sides in [1, {MAX_TEXTURE_SIDE}]")
        if check_shape is not None:
            check_shape(height, width)
        if suffix == ".npy":
            pixels = load_npy(data)
        elif suffix == ".png":
            pixels = _png(data)
        else:
            pixels = _exr(path)
    except ImageFileError as exc:
        raise TextureError(str(exc)) from None
    return check_texels(pixels)


def check_texels(pixels) -> np.ndarray:
    """An array as texture texels (H, W, 3) float32: shape, size and values checked (in
    the array's own precision: a float64 copy of a 4096² texture is 400 MB)."""
    a = np.asarray(pixels)
    if a.dtype.kind not in "fiub":
        raise TextureError(f"an array of dtype {a.dtype}, not numbers")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] != 3):
        raise TextureError(f"an array of shape {tuple(np.shape(pixels))}, not an image of shape (H, W) or (H, W, 3)")
    height, width = a.shape[:2]
    if height < 1 or width < 1 or max(height, width) > MAX_TEXTURE_SIDE:
        raise TextureError(f"an image of {width}×{height} texels, not sides in [1, {MAX_TEXTURE_SIDE}]")
    if a.dtype.kind != "f":  # integers and booleans: finite, and within float32 (< 2⁶⁴)
        a = a.astype(np.float32)
    channels = a if a.ndim == 3 else a[..., None]
    bad = ~np.isfinite(channels)
    if bad.any():
        y, x, c = np.argwhere(bad)[0]
        raise TextureError(f"{channels[y, x, c]} at texel (x={x}, y={y}), {int(bad.any(axis=2).sum())} "
                           f"non-finite texel(s) in all: texels must be finite")
    negative = channels < 0
    if negative.any():
        y, x, _ = np.argwhere(negative)[0]
        raise TextureError(f"{channels[y, x].min():g} at texel (x={x}, y={y}), {int(negative.any(axis=2).sum())} "
                           f"negative texel(s) in all: a light cannot take light away")
    if float(channels.max()) > MAX_TEXEL:
        raise TextureError(f"a texel of {float(channels.max()):g}, over {MAX_TEXEL:.3g} (float32 on the device)")
    texels = np.ascontiguousarray(channels, dtype=np.float32)
    return texels if texels.shape[2] == 3 else np.repeat(texels, 3, axis=2)


#: 8- and 16-bit sRGB codes to linear float32 (a table: the decode of a 4096² PNG then
#: takes one 200 MB array, where float64 arithmetic on it took several of 400 MB).
_SRGB8 = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)
_SRGB16 = srgb_to_linear(np.arange(65536) / 65535.0).astype(np.float32)


def _png(data: bytes) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as image:
            if image.format != "PNG":
                raise TextureError(f"a {image.format or 'non-PNG'} image named .png")
            if image.mode in ("I;16", "I;16B", "I;16L", "I"):  # 16-bit grey
                return _SRGB16[np.clip(np.asarray(image), 0, 65535).astype(np.uint16)]
            return _SRGB8[np.asarray(image.convert("RGB"), dtype=np.uint8)]
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise TextureError(f"not a readable PNG image ({exc})") from None


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


def _file_key(path: Path) -> tuple | None:
    """What tells one file from another, and a changed file from itself; None when it
    cannot be stat'ed (reading it then says why)."""
    try:
        info = os.stat(path)
    except (OSError, ValueError):
        return None
    return info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns


class TextureCache:
    """The light textures of one scene as it is loaded: each file decoded once, however
    many lights use it, and each texture the lights share one array (which the device
    then holds once: `physics.light_texture.pack_light_textures`). 16 spot lights sharing
    a 4096² gobo decoded it 16 times (7.4 GB). The texels the scene's textures send to
    the device are counted against MAX_SCENE_TEXTURE_TEXELS from each file's header,
    before it is decoded.

        cache = TextureCache()
        texels = cache.image(Path("gobo.png"))           # (H, W, 3) float32
        cube = cache.cube_faces([Path("px.png"), ...])   # (6·s, s, 3)
    """

    def __init__(self, max_texels: int | None = None):
        self.max_texels = MAX_SCENE_TEXTURE_TEXELS if max_texels is None else max_texels
        self.texels = 0  # counted so far: each shared texture once
        self._decoded: dict[tuple, np.ndarray] = {}  # file key -> its texels
        self._textures: dict[tuple, np.ndarray] = {}  # what a texture is made of -> its texels
        self._brightest: dict[int, float] = {}  # id(texels) -> their largest value

    def brightest(self, texels: np.ndarray) -> float:
        """The largest value of texels this cache made (found once per texture)."""
        if id(texels) not in self._brightest:
            self._brightest[id(texels)] = float(texels.max())
        return self._brightest[id(texels)]

    def image(self, path: Path) -> np.ndarray:
        """A spot or directional light's texture: one file."""
        key = ("image", _file_key(path))
        if key in self._textures:
            return self._textures[key]
        return self._keep(key, self._decode(path, lambda height, width: height * width))

    def cube_faces(self, paths: list[Path]) -> np.ndarray:
        """A point light's cube from six square files (+x, -x, +y, -y, +z, -z)."""
        key = ("faces",) + tuple(_file_key(path) for path in paths)
        if key in self._textures:
            return self._textures[key]
        faces = []
        for index, path in enumerate(paths):
            try:
                faces.append(self._decode(path, lambda height, width: 6 * height * width))
            except TextureError as exc:
                exc.face = index  # which file of the six
                raise
        return self._keep(key, cube_from_faces(faces))

    def cube_cross(self, path: Path) -> np.ndarray:
        """A point light's cube from one cross image (6 of its 12 cells)."""
        key = ("cross", _file_key(path))
        if key in self._textures:
            return self._textures[key]
        return self._keep(key, cube_from_cross(self._decode(path, lambda height, width: height * width // 2)))

    def _decode(self, path: Path, texels_of: Callable[[int, int], int]) -> np.ndarray:
        """The file's texels, decoded at its first use, when the texture it makes
        (`texels_of(height, width)` texels) fits what is left."""
        def check(height: int, width: int) -> None:
            needed, left = texels_of(height, width), self.max_texels - self.texels
            if needed > left:
                raise TextureError(f"a texture of {needed} texels from an image of {width}×{height}, more than the "
                                   f"{left} left of the {self.max_texels} that all the lights' textures may hold "
                                   f"together (each is 16 bytes on the device)")

        key = _file_key(path)
        if key is not None and key in self._decoded:
            texels = self._decoded[key]
            check(*texels.shape[:2])
            return texels
        texels = read_texture(path, check)
        if key is not None:
            self._decoded[key] = texels
        return texels

    def _keep(self, key: tuple, texels: np.ndarray) -> np.ndarray:
        if None not in key:
            self._textures[key] = texels
        self.texels += texels.shape[0] * texels.shape[1]
        return texels


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
