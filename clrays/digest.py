"""The digest every reuse key is made of (clrays.reuse): a BLAKE2b of numbers, strings, numpy
arrays (dtype, shape and bytes) and dataclasses (field by field; one with a `digest_parts`
method by what that returns), so two digests agree only when every part is bit-identical. A module of its own, which imports nothing of clrays, so
that the scene's relief records (clrays.scene.relief_frame) digest their texels as the
stages' keys do."""
from __future__ import annotations

import dataclasses
import hashlib
from pathlib import PurePath
from typing import Any

import numpy as np


def digest(*parts: Any) -> bytes:
    """16-byte BLAKE2b of the parts (module docstring); `None` and tuples nest."""
    h = hashlib.blake2b(digest_size=16)
    _feed(h, parts)
    return h.digest()


def _feed(h, value: Any) -> None:
    if isinstance(value, np.ndarray):
        array = np.ascontiguousarray(value)
        h.update(f"a{array.dtype.str}{array.shape}".encode())
        h.update(array.reshape(-1).view(np.uint8) if array.size else b"")  # its bytes, not a copy of them
    elif isinstance(value, (bytes, bytearray)):
        h.update(b"b%d:" % len(value) + bytes(value))
    elif isinstance(value, (bool, int, float, str, type(None), np.generic, PurePath)):
        text = repr(value.item() if isinstance(value, np.generic) else value)
        h.update(f"{type(value).__name__}:{text};".encode())
    elif isinstance(value, (tuple, list)):
        h.update(b"(%d" % len(value))
        for item in value:
            _feed(h, item)
        h.update(b")")
    elif isinstance(value, dict):
        h.update(b"{%d" % len(value))
        for key in sorted(value, key=repr):
            _feed(h, key)
            _feed(h, value[key])
        h.update(b"}")
    elif hasattr(type(value), "digest_parts"):  # an object that names what stands for it (a texture's digest)
        h.update(type(value).__name__.encode() + b"<")
        _feed(h, value.digest_parts())
        h.update(b">")
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        h.update(type(value).__name__.encode() + b"<")
        for f in dataclasses.fields(value):
            h.update(f.name.encode() + b"=")
            _feed(h, getattr(value, f.name))
        h.update(b">")
    else:
        raise TypeError(f"cannot digest a {type(value).__name__}")
