"""The progress bar of a long run: a tqdm bar when asked for, else nothing at all, so a
run's loop reads the same either way."""
from __future__ import annotations


def counted(count: int, noun: str) -> str:
    """"1 frame", "3 frames": a count and its noun, in the plural where it is not 1."""
    return f"{count} {noun}{'' if count == 1 else 's'}"


class Progress:
    """A bar over `total` items (`unit`, e.g. "frame"), shown only when `enabled`.

    Use as a context manager; `advance(label)` after each item shows the label beside
    the bar. The bar closes on the way out, also when the run stops with an error."""

    def __init__(self, enabled: bool, total: int, unit: str, desc: str):
        self._bar = None
        if enabled:
            from tqdm import tqdm

            self._bar = tqdm(total=total, unit=unit, desc=desc)

    def advance(self, label: str) -> None:
        if self._bar is not None:
            self._bar.set_postfix_str(label, refresh=False)
            self._bar.update(1)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()
