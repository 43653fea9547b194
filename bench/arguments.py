"""The arguments the bench timing scripts share, checked so that a bad value is one line
from argparse. No clrays import here: bench/raster_ab.py and bench/host_stages.py import
clrays from another tree after parsing."""
from __future__ import annotations

import argparse


def image_size(text: str) -> str:
    """`--size`: WxH, both positive integers (argparse prints the error in one line)."""
    parts = text.split("x")
    if len(parts) != 2 or not all(part.isdigit() and int(part) > 0 for part in parts):
        raise argparse.ArgumentTypeError(f"expected WxH, e.g. 1280x720, got {text!r}")
    return text


def frame_count(text: str) -> int:
    """`--frames`: a positive integer."""
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return int(text)
