"""A sequence's record of its finished frames (`MANIFEST`, beside the frames): what lets a
resumed run tell a finished frame from a stale one, or from one another run wrote, and what
a dask worker appends to once its frame is written (docs/limits.md, "finished frames of a
sequence")."""
from __future__ import annotations

import json
import os
from pathlib import Path

from ..errors import OutputError
from ..exposure import AUTO_PERCENTILE, AUTO_WHITE, EV_LIMIT
from ..image_io import file_digest, write_atomic
from ..outputs import open_file
from ..reuse import digest, scene_digest
from ..scene.files import FileRefused, read_regular_file
from ..scene.limits import MAX_RUN_RECORD_BYTES
from ..scene.model import Scene


#: Beside the frames, in each folder that holds some: one JSON line per frame written,
#: {"file": name, "digest": `frame_digest`, "content": `file_digest` of its bytes}, the
#: last line of a file counting, so that a resumed run can tell a finished frame from a
#: stale one, or from one another run wrote.
MANIFEST = ".clrays-frames.jsonl"


def frame_digest(frame_scene: Scene, method: str | None, exposure: float, suffix: str) -> str:
    """Everything a frame file depends on: the frame's scene (`reuse.scene_digest`), the
    method, the format, and the exposure where the format applies it."""
    method = method or frame_scene.render.method
    return digest("frame file", scene_digest(frame_scene), method, suffix,
                  exposure if suffix == ".png" else 0.0).hex()


class FrameManifest:
    """The frames of one folder (MANIFEST): appended a line after each frame file is
    written, so a frame costs one short write however long the sequence. A frame counts as
    finished only when its line holds the digest of its scene and the digest of the very
    bytes in its file: a frame without a line (a run killed between the two), of another
    scene, or overwritten by another run is rendered again."""

    def __init__(self, folder: Path):
        self.path = folder / MANIFEST
        self.entries: dict[str, tuple[str, str]] = {}  # file name → (frame digest, content digest)
        text, lines = self._read(), 0
        for line in text.splitlines():
            try:
                entry = json.loads(line)
                self.entries[str(entry["file"])] = (str(entry["digest"]), str(entry["content"]))
                lines += 1
            except (ValueError, TypeError, KeyError):
                pass  # a line cut short by a crash: its frame counts as stale
        if (text and not text.endswith("\n")) or lines > 2 * len(self.entries) + 64:
            self._rewrite()  # a torn last line would join the next, and replaced lines pile up

    def _read(self) -> str:
        try:
            return read_regular_file(self.path, MAX_RUN_RECORD_BYTES, follow_links=False).decode("utf-8", "replace")
        except FileRefused as exc:
            if not os.path.lexists(self.path):
                return ""
            raise OutputError(f"{self.path}: cannot read the frame manifest: {exc}; remove it (its frames are "
                              f"rendered again)") from None

    def _line(self, name: str) -> str:
        frame_digest_hex, content = self.entries[name]
        return json.dumps({"file": name, "digest": frame_digest_hex, "content": content}) + "\n"

    def _rewrite(self) -> None:
        text = "".join(self._line(name) for name in sorted(self.entries))
        write_atomic(self.path, lambda temporary: Path(temporary).write_text(text, encoding="utf-8"))

    def matches(self, path: Path, frame_digest_hex: str) -> bool:
        entry = self.entries.get(path.name)
        return entry is not None and entry[0] == frame_digest_hex and file_digest(path) == entry[1]

    def record(self, path: Path, frame_digest_hex: str, content: str | None) -> None:
        """After `path` is written: `content` is the `file_digest` of what was written."""
        if content is not None:
            self.entries[path.name] = (frame_digest_hex, content)
            append_frame_line(path, frame_digest_hex, content)


def append_frame_line(path: Path, frame_digest_hex: str, content: str) -> None:
    """Append frame `path`'s line to the MANIFEST beside it, once the frame is written (here
    or on a dask worker): one write of one short line with O_APPEND, whatever the length
    of the sequence; opened as `clrays.outputs` asks (a link or a FIFO there is one line)."""
    manifest = path.parent / MANIFEST
    line = json.dumps({"file": path.name, "digest": frame_digest_hex, "content": content}) + "\n"
    try:
        fd = open_file(manifest, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
        try:
            os.write(fd, line.encode())
        finally:
            os.close(fd)
    except OSError as exc:
        raise OutputError(f"{manifest}: cannot write: {exc.strerror or exc}") from None


#: In the folder a sequence locks (`sequence.lock_folder`): the stops `--exposure auto` chose
#: for its frames, {"sequence": `sequence_exposure_key`, "ev": stops}, so that a resumed run,
#: or one of other frames of the same sequence, exposes its frames alike (and finds the
#: frames already written to be its own).
EXPOSURE_RECORD = ".clrays-exposure.json"


def sequence_exposure_key(scene: Scene, method: str | None) -> str:
    """What the frames of a sequence share, whichever of them are rendered: the scene, its
    animation and the method (and how `auto` chooses)."""
    return digest("sequence exposure", scene_digest(scene), scene.animation, method or scene.render.method,
                  AUTO_PERCENTILE, AUTO_WHITE).hex()


def recorded_exposure(folder: Path, key: str) -> float | None:
    """The stops recorded in `folder` for the sequence `key`, or None: none recorded, of
    another sequence, or unreadable (then `auto` chooses again, and the frames exposed
    otherwise are rendered again)."""
    try:
        record = json.loads(read_regular_file(folder / EXPOSURE_RECORD, MAX_RUN_RECORD_BYTES))
        if not isinstance(record, dict) or record.get("sequence") != key:
            return None
        stops = float(record["ev"])
    except (FileRefused, ValueError, TypeError, KeyError):
        return None
    return stops if abs(stops) <= EV_LIMIT else None


def record_exposure(folder: Path, key: str, stops: float) -> None:
    text = json.dumps({"sequence": key, "ev": stops}) + "\n"
    write_atomic(folder / EXPOSURE_RECORD, lambda temporary: Path(temporary).write_text(text, encoding="utf-8"))
