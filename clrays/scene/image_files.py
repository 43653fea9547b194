"""What an image file holds, read from its header before a pixel is decoded: its format
(which must be the one its name says) and its size. The scene's two image readers, relief
images (`clrays.scene.relief`) and light textures (`clrays.scene.textures`), both go
through here, so they refuse the same files, and each checks its size limit before it
decodes: a 657 KB PNG of zeros holds 13000² RGBA texels (676 MB decoded, 6.5 GB as
triangles), a 200-byte `.npy` can claim 36 GiB (docs/limits.md, "Image headers").

    height, width = image_shape(data, ".png")    # from the PNG's IHDR chunk, nothing decoded
    array = load_npy(data)                        # the header checked against the file first
"""
from __future__ import annotations

import io
import math
import struct
from pathlib import Path

import numpy as np


class ImageFileError(ValueError):
    """An image file that cannot be read; the message is one line, without the path."""


#: The first bytes of the formats a file named .png, .exr or .npy may turn out to hold.
_SIGNATURES = (
    (b"\x89PNG\r\n\x1a\n", "PNG"), (b"v/1\x01", "EXR"), (b"\x93NUMPY", "NPY"),
    (b"\xff\xd8\xff", "JPEG"), (b"GIF87a", "GIF"), (b"GIF89a", "GIF"), (b"II*\x00", "TIFF"),
    (b"MM\x00*", "TIFF"), (b"BM", "BMP"), (b"\x00\x00\x01\x00", "ICO"), (b"qoif", "QOI"),
)
_SUFFIX_FORMATS = {".png": "PNG", ".exr": "EXR", ".npy": "NPY"}


def sniffed_format(data: bytes) -> str | None:
    """The format the file's first bytes say (PNG, EXR, NPY, JPEG, GIF, TIFF, ...), or None."""
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return "WebP"
    return next((name for signature, name in _SIGNATURES if data.startswith(signature)), None)


def check_format(data: bytes, suffix: str) -> None:
    """Refuse a file whose content is not the format its extension names: a JPEG (lossy),
    GIF (a palette of 256) or TIFF (which may hold NaN) named .png is not read as a PNG."""
    expected = _SUFFIX_FORMATS[suffix]
    found = sniffed_format(data)
    if found != expected:
        raise ImageFileError(f"a {found} image named {suffix}" if found else
                             f"not a readable {expected} image (it does not start as one)")


def image_shape(data: bytes, suffix: str, path: Path | None = None) -> tuple[int, int]:
    """(height, width) of an image file's bytes from its header alone, after `check_format`.
    An EXR header is read from `path` (OpenEXR reads files, not bytes)."""
    check_format(data, suffix)
    if suffix == ".png":
        return png_shape(data)
    if suffix == ".npy":
        shape = npy_header(data)[0]
        if len(shape) < 2:
            raise ImageFileError(f"not a 2D image (an array of shape {shape})")
        return int(shape[0]), int(shape[1])
    return exr_shape(path)


def png_shape(data: bytes) -> tuple[int, int]:
    """(height, width) from a PNG's IHDR chunk, which the format puts first."""
    if len(data) < 24 or data[12:16] != b"IHDR":
        raise ImageFileError("not a readable PNG image (no IHDR chunk)")
    width, height = struct.unpack(">II", data[16:24])
    return height, width


#: Channels an EXR texture or depth map may hold: RGBA at most. OpenEXR decodes every
#: channel of every part, so a file of one small RGB part and a hidden large one, or of
#: hundreds of channels, would decode far past what its data window shows.
MAX_EXR_CHANNELS = 4


def exr_shape(path: Path) -> tuple[int, int]:
    """(height, width) of an EXR file's data window, from its header: one part of at most
    MAX_EXR_CHANNELS channels, so that the window bounds what decoding it costs."""
    import OpenEXR

    try:
        with OpenEXR.File(str(path), header_only=True) as exr:
            parts, header = len(exr.parts), exr.header()
            low, high = header["dataWindow"]
            channels = len(header.get("channels") or ())
    except Exception as exc:  # OpenEXR raises bare exceptions for broken files
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ImageFileError(f"not a readable EXR image ({detail})") from None
    if parts != 1:
        raise ImageFileError(f"an EXR of {parts} parts, not one image (save the image alone)")
    if channels > MAX_EXR_CHANNELS:
        raise ImageFileError(f"an EXR of {channels} channels, not an image of at most {MAX_EXR_CHANNELS} "
                             f"(R, G, B, A; save the image alone)")
    return int(high[1]) - int(low[1]) + 1, int(high[0]) - int(low[0]) + 1


def npy_header(data: bytes) -> tuple[tuple[int, ...], np.dtype, int]:
    """(shape, dtype, offset of the data) of a `.npy` file, checked against what the file
    holds: numbers only (no objects, nothing pickled), and shape × itemsize bytes present
    after the header, so `np.load` never allocates more than the file's size."""
    from numpy.lib import format as npy_format

    stream = io.BytesIO(data)
    try:
        version = npy_format.read_magic(stream)
        if version == (1, 0):
            shape, fortran, dtype = npy_format.read_array_header_1_0(stream)
        elif version in ((2, 0), (3, 0)):
            shape, fortran, dtype = npy_format.read_array_header_2_0(stream)
        else:
            raise ValueError(f"unknown .npy version {version}")
    except (ValueError, SyntaxError, TypeError, EOFError) as exc:  # numpy raises several for a broken header
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ImageFileError(f"not a .npy array ({detail[:120]})") from None
    if dtype.hasobject or dtype.kind not in "biuf" or dtype.fields is not None:
        raise ImageFileError(f"an array of dtype {dtype}, not numbers")
    claimed = math.prod(shape) * dtype.itemsize
    held = len(data) - stream.tell()
    if claimed > held:
        raise ImageFileError(f"a .npy header that claims {_shape_text(shape)} of {dtype} ({claimed:.3g} bytes), "
                             f"but the file holds {held} bytes after it")
    return tuple(int(n) for n in shape), dtype, stream.tell()


def load_npy(data: bytes) -> np.ndarray:
    """A `.npy` file's array, its header checked first (`npy_header`)."""
    npy_header(data)
    try:
        return np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise ImageFileError(f"not a .npy array ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") \
            from None


def _shape_text(shape) -> str:
    return " × ".join(str(n) for n in shape) if shape else "a scalar"
