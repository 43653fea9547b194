"""Writes that a hostile output folder could send elsewhere, and where clrays keeps its
caches (clrays.outputs): every file clrays writes, appends to or reads back in a folder it
writes is opened without following a link and must be a regular file, every folder it makes
there a directory; caches live in $CLRAYS_CACHE or the user's cache folder, never the
working directory; `--confine` confines writes too; `watch` leaves no stale pass and
creates its folder; a run's lock file goes with it."""
from __future__ import annotations

import fcntl
import os
import re
from pathlib import Path

import numpy as np
import pytest

from clrays.errors import OutputError
from conftest import run_cli as run
from test_hostile_outputs import animated, one_line

VICTIM_TEXT = "the victim's own bytes\n"


def victim(tmp_path: Path, name: str = "victim.txt") -> Path:
    path = tmp_path / name
    path.write_text(VICTIM_TEXT)
    return path


def assert_untouched(path: Path) -> None:
    assert path.read_text() == VICTIM_TEXT


def linked_elsewhere(tmp_path: Path, name: str) -> Path:
    """tmp_path/out/`name`, a link to the empty folder tmp_path/elsewhere; returns that folder."""
    (tmp_path / "out").mkdir()
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out" / name).symlink_to("../elsewhere")
    return tmp_path / "elsewhere"


def link_refused(out: str, path: Path) -> None:
    """The one line of a link refused at `path`."""
    assert re.fullmatch(rf"clrays: error: {re.escape(str(path))}: is a symbolic link; clrays .*\(remove it\)",
                        one_line(out)), out


# --------------------------------------------------------------------------- links in output folders


@pytest.mark.parametrize("name, reason", [
    # It exited 0 and appended a JSON line to victim.txt.
    (".clrays-frames.jsonl", "cannot read the frame manifest: a symbolic link, which clrays does not follow here; "
                             "remove it (its frames are rendered again)"),
    (".clrays-lock", "is a symbolic link; clrays writes nothing through a link in a folder it writes (remove it)")])
def test_a_manifest_or_lock_linked_elsewhere_is_neither_read_nor_written(tmp_path, name, reason):
    target = victim(tmp_path)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / name).symlink_to("../victim.txt")
    code, out = run("sequence", animated(tmp_path, 2), "-o", tmp_path / "out" / "f_{}.png", "--no-progress")
    assert code == 1
    assert one_line(out) == f"clrays: error: {tmp_path}/out/{name}: {reason}"
    assert_untouched(target)
    assert not list((tmp_path / "out").glob("f_*"))


def test_a_manifest_linked_after_it_was_read_is_not_appended_to(tmp_path):
    """The append opens the name again: a link put there since the read is refused too."""
    from clrays.runs.frame_manifest import MANIFEST, append_frame_line

    target = victim(tmp_path)
    (tmp_path / MANIFEST).symlink_to(target)
    with pytest.raises(OutputError, match=rf"^{re.escape(str(tmp_path / MANIFEST))}: is a symbolic link"):
        append_frame_line(tmp_path / "f_0.png", "0" * 32, "1" * 32)
    assert_untouched(target)


def test_a_sweeps_references_folder_linked_elsewhere_is_refused(tmp_path):
    # The reference caches (raymarch8-*.npy, edges-*.npy) were written into elsewhere/.
    elsewhere = linked_elsewhere(tmp_path, ".references")
    code, out = run("sweep", animated(tmp_path, 1), "--set", "medium.sigma_s=0.02,0.05", "--reference",
                    "raymarch:8", "-o", tmp_path / "out", "--no-progress")
    assert code == 1
    assert one_line(out) == (f"clrays: error: {tmp_path}/out/.references: is a symbolic link; clrays makes its own "
                             f"folder there and writes nothing through a link (remove it)")
    assert not list(elsewhere.iterdir())
    assert not list((tmp_path / "out").glob("*.png"))  # refused before the first point


def test_a_sequences_tuning_folder_linked_elsewhere_is_refused(tmp_path):
    """A sequence keeps its tuned settings in .references beside its frames."""
    scene = animated(tmp_path, 2)
    scene.write_text(scene.read_text().replace("steps: 16}", "steps: 16, target_error: 50}"))
    elsewhere = linked_elsewhere(tmp_path, ".references")
    code, out = run("sequence", scene, "-o", tmp_path / "out" / "f_{}.png", "--no-progress")
    assert code == 1
    link_refused(out, tmp_path / "out" / ".references")
    assert not list(elsewhere.iterdir())


@pytest.mark.parametrize("name, aov", [("x.png", None), ("x.in_scatter.png", "in_scatter")])
def test_an_image_or_pass_linked_elsewhere_is_refused_before_rendering(tmp_path, name, aov):
    # The rename replaced the link unseen; now the link is one line, before anything renders.
    target = victim(tmp_path, "victim.png")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / name).symlink_to(target)
    code, out = run("render", animated(tmp_path, 1), "-o", tmp_path / "out" / "x.png",
                    *(["--aov", aov] if aov else []))
    assert code == 1
    link_refused(out, tmp_path / "out" / name)
    assert_untouched(target)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [name]


@pytest.mark.parametrize("name, command", [
    ("t.yaml", ["tune", "--target-error", "1", "-o", "{out}/t.yaml"]),
    ("contact_sheet.png", ["sweep", "--set", "medium.sigma_s=0.02,0.05", "-o", "{out}"]),
    ("results.csv", ["sweep", "--set", "medium.sigma_s=0.02,0.05", "-o", "{out}", "--overwrite"]),
    ("v.gif", ["sequence", "-o", "{out}/f_{{}}.png", "--video", "{out}/v.gif"])])
def test_a_link_where_a_long_run_writes_last_is_refused_before_it_starts(tmp_path, name, command):
    """The tuned scene, a sweep's contact sheet and results (not read with --overwrite), a
    sequence's video: written after minutes of work, their links are one line before any of it."""
    target = victim(tmp_path)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / name).symlink_to(target)
    verb, *rest = command
    code, out = run(verb, animated(tmp_path, 2), *(part.format(out=tmp_path / "out") for part in rest),
                    "--no-progress")
    assert code == 1
    link_refused(out, tmp_path / "out" / name)
    assert_untouched(target)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [name]


def test_an_opencl_vendors_folder_that_is_a_link_is_not_taken(tmp_path, monkeypatch):
    """Its `.icd` files name libraries that are loaded: a link planted where the vendors
    folder goes is not followed; the list is written in the fallback folder instead."""
    import tempfile

    from clrays import runtimes

    monkeypatch.setenv("CLRAYS_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    entries = {"a.icd": "/nowhere/liba.so\n"}
    first = runtimes._write_vendors(entries)
    assert first.parent == tmp_path / "cache" and (first / "a.icd").read_text() == entries["a.icd"]
    planted = tmp_path / "planted"
    planted.mkdir()
    (planted / "a.icd").write_text("/attacker/libevil.so\n")
    for child in first.iterdir():
        child.unlink()
    first.rmdir()
    first.symlink_to(planted)
    again = runtimes._write_vendors(entries)
    assert again.parent == tmp_path / "tmp" / f"clrays-{os.getuid()}"
    assert not again.is_symlink() and (again / "a.icd").read_text() == entries["a.icd"]


def test_a_fifo_where_the_image_goes_is_one_line_and_no_wait(tmp_path):
    (tmp_path / "out").mkdir()
    os.mkfifo(tmp_path / "out" / "x.png")
    code, out = run("render", animated(tmp_path, 1), "-o", tmp_path / "out" / "x.png")
    assert code == 1
    assert one_line(out) == f"clrays: error: {tmp_path}/out/x.png: is a FIFO, not a regular file (remove it)"


def test_a_frame_folder_linked_elsewhere_is_refused(tmp_path):
    """Folders the frame number names are clrays': a link there is not followed."""
    elsewhere = linked_elsewhere(tmp_path, "00")
    code, out = run("sequence", animated(tmp_path, 2), "-o", tmp_path / "out" / "{:02d}" / "b.png", "--no-progress")
    assert code == 1
    assert one_line(out) == (f"clrays: error: {tmp_path}/out/00: is a symbolic link; clrays makes its own folder "
                             f"there and writes nothing through a link (remove it)")
    assert not list(elsewhere.iterdir())


def test_a_cached_reference_that_is_a_fifo_is_one_line(tmp_path):
    """A cached reference that is no regular file is refused (not replaced unseen), as any
    file clrays writes in a folder it writes."""
    from clrays.runs.references import EXACT, ReferenceCache

    cache = ReferenceCache(tmp_path / "cache")
    scene = _tiny_scene()
    pixels = (np.array([1, 2]), np.array([3, 4]))
    first = cache.radiance(scene, EXACT, pixels)  # the exact renderer on the host: no kernels
    entry, = (tmp_path / "cache").glob("exact-*.npy")
    entry.unlink()
    os.mkfifo(entry)
    with pytest.raises(OutputError, match=rf"^{re.escape(str(entry))}: is a FIFO, not a regular file"):
        ReferenceCache(tmp_path / "cache").radiance(scene, EXACT, pixels)
    entry.unlink()
    np.testing.assert_array_equal(ReferenceCache(tmp_path / "cache").radiance(scene, EXACT, pixels), first)


def _tiny_scene():
    from conftest import make_scene

    return make_scene(width=16, height=9)


def test_a_folder_the_user_links_is_the_users_choice(tmp_path):
    """`-o` into a folder that is itself a link (the user's): written through it."""
    (tmp_path / "real").mkdir()
    (tmp_path / "linked").symlink_to("real")
    code, out = run("relief-to-mesh", "scenes/lattice.yaml", "-o", tmp_path / "linked" / "m.ply")
    assert code == 0, out
    assert (tmp_path / "real" / "m.ply").is_file() and not (tmp_path / "real" / "m.ply").is_symlink()


# --------------------------------------------------------------------------- caches


@pytest.fixture
def no_cache_set(tmp_path, monkeypatch):
    """No $CLRAYS_CACHE; the user's cache folder in tmp_path/xdg; the working directory tmp_path/work."""
    import platformdirs

    # pyopencl's kernel cache is in the user's cache folder too: the one it had, not a first build.
    kernels = Path(os.environ.get("XDG_CACHE_HOME") or platformdirs.user_cache_dir()) / "pyopencl"
    (tmp_path / "xdg").mkdir()
    (tmp_path / "xdg" / "pyopencl").symlink_to(kernels, target_is_directory=True)
    monkeypatch.delenv("CLRAYS_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    (tmp_path / "work").mkdir()
    monkeypatch.chdir(tmp_path / "work")
    return tmp_path / "xdg" / "clrays"


def test_every_cache_is_in_one_folder(tmp_path, monkeypatch, no_cache_set):
    from clrays import runtimes
    from clrays.outputs import cache_root

    assert cache_root() == runtimes.cache_root() == no_cache_set
    monkeypatch.setenv("CLRAYS_CACHE", str(tmp_path / "mine"))
    assert cache_root() == tmp_path / "mine"
    monkeypatch.delenv("CLRAYS_CACHE")
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_root() == tmp_path / "home" / ".cache" / "clrays"
    assert not cache_root().is_relative_to(Path.cwd())


def test_commands_default_to_the_one_cache():
    from clrays.cli import bench, tune

    for command in (bench, tune):
        cache, = (parameter for parameter in command.params if parameter.name == "cache")
        assert cache.default is None  # then clrays.outputs.cache_root()
        assert ".cache/clrays" not in (cache.help or "").replace("~/.cache/clrays", "")


def test_tune_writes_its_cache_in_the_users_cache_not_the_working_directory(tmp_path, no_cache_set):
    # `.cache/clrays/{exact,edges,tuned}-*` landed in the working directory.
    scene = animated(tmp_path, 1, 16, 9)
    (tmp_path / "out").mkdir()
    code, out = run("tune", scene, "--target-error", "99", "--most-settings", "1", "--pixels", "16", "-o",
                    tmp_path / "out" / "t.yaml", "--no-progress", "--confine")
    assert code == 0, out
    assert (tmp_path / "out" / "t.yaml").is_file()
    assert list(no_cache_set.glob("exact-*.npy")) and list(no_cache_set.glob("edges-*.npy"))
    assert not list((tmp_path / "work").iterdir())


def test_tune_refuses_an_output_that_is_not_yaml(tmp_path):
    # It wrote YAML text into t.png.
    code, out = run("tune", animated(tmp_path, 1), "--target-error", "1", "-o", tmp_path / "t.png")
    assert code == 1
    assert one_line(out) == (f"clrays: error: {tmp_path}/t.png: the tuned scene is YAML: expected a .yaml or .yml "
                             f"output, got '.png'")
    assert not (tmp_path / "t.png").exists()


# --------------------------------------------------------------------------- confined writes


def test_confined_writes_stay_in_the_outputs_folders_and_the_cache(tmp_path, monkeypatch):
    from clrays.image_io import write_image
    from clrays import outputs

    monkeypatch.setenv("CLRAYS_CONFINE", "1")
    monkeypatch.setenv("CLRAYS_CACHE", str(tmp_path / "cache"))
    for folder in ("out", "other", "cache"):
        (tmp_path / folder).mkdir()
    (tmp_path / "out" / "sub").symlink_to("../other")  # a link in the output folder, out of it
    image = np.zeros((2, 2, 3), np.float32)
    try:
        outputs.allow_writes(tmp_path / "out")
        write_image(tmp_path / "out" / "a.npy", image)
        write_image(tmp_path / "cache" / "c.npy", image)
        for outside in (tmp_path / "other" / "b.npy", tmp_path / "out" / "sub" / "b.npy",
                        tmp_path / "out" / ".." / "b.npy"):
            with pytest.raises(OutputError, match=r": outside the folders this run may write into \(its outputs' "
                                                  r"and the cache .*; writes confined by CLRAYS_CONFINE\)$"):
                write_image(outside, image)
    finally:
        outputs.end_writes()
    assert sorted(p.name for p in tmp_path.rglob("*.npy")) == ["a.npy", "c.npy"]
    write_image(tmp_path / "other" / "b.npy", image)  # no command declared its outputs: not confined


def test_a_confined_render_writes_its_image(tmp_path):
    code, out = run("render", animated(tmp_path, 1, 16, 9), "-o", tmp_path / "out" / "x.png", "--confine")
    assert code == 0, out
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["x.png"]


# --------------------------------------------------------------------------- watch


def _watch_with_edit(tmp_path, renderer, edit) -> tuple[Path, list[str]]:
    """Two renders of a watched scene with the in_scatter pass, `edit(scene, out)` made after the first."""
    from clrays.runs.watch import watch

    scene = animated(tmp_path, 1, 16, 9)
    scene.write_text(scene.read_text().replace("steps: 16}", "steps: 16, aovs: [in_scatter]}"))
    out = tmp_path / "out"
    out.mkdir()
    lines = []

    def echo(line: str) -> None:
        lines.append(line)
        if line.startswith("render 1:"):
            edit(scene, out)

    renders, errors = watch(scene, out / "w.png", renderer=renderer, max_renders=2, interval=0.01, echo=echo)
    assert (renders, errors) == (2, 0), lines
    return out, lines


def _drop_aovs(scene: Path) -> None:
    scene.write_text(scene.read_text().replace(", aovs: [in_scatter]}", "}"))


def test_watch_removes_the_passes_an_edit_dropped(tmp_path, renderer):
    # out/w.in_scatter.png of the first render stayed beside the second's image.
    def edit(scene, out):
        assert (out / "w.in_scatter.png").is_file()
        _drop_aovs(scene)

    out, _ = _watch_with_edit(tmp_path, renderer, edit)
    assert sorted(p.name for p in out.iterdir()) == ["w.png"]


def test_watch_leaves_the_files_it_did_not_write(tmp_path, renderer):
    """A pass file replaced by someone else since the render, or a pass-like file no render
    of this watch wrote, stays."""
    def edit(scene, out):
        (out / "w.in_scatter.png").write_bytes(b"the user's own")
        (out / "w.transmittance.png").write_bytes(b"also the user's")
        _drop_aovs(scene)

    out, _ = _watch_with_edit(tmp_path, renderer, edit)
    assert sorted(p.name for p in out.iterdir()) == ["w.in_scatter.png", "w.png", "w.transmittance.png"]
    assert (out / "w.in_scatter.png").read_bytes() == b"the user's own"


def test_watch_creates_its_output_folder(tmp_path):
    code, out = run("watch", animated(tmp_path, 1, 16, 9), "-o", tmp_path / "new" / "sub" / "w.png",
                    "--max-renders", "1")
    assert code == 0, out
    assert (tmp_path / "new" / "sub" / "w.png").is_file()


# --------------------------------------------------------------------------- the lock


def test_the_lock_file_goes_with_the_run(tmp_path):
    from clrays.image_io import LOCK, folder_lock

    with folder_lock(tmp_path):
        assert (tmp_path / LOCK).is_file()
    assert not os.path.lexists(tmp_path / LOCK)
    code, out = run("sequence", animated(tmp_path, 2, 16, 9), "-o", tmp_path / "out" / "f_{}.npy", "--no-progress")
    assert code == 0, out
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [".clrays-frames.jsonl", "f_0.npy", "f_1.npy"]


def test_a_lock_taken_on_a_file_its_holder_removed_is_taken_again(tmp_path, monkeypatch):
    """The race that removing a lock file opens: run B opens the lock file, its holder A
    unlinks it and ends, B's flock succeeds on a file no one else will open. B must see
    that the name no longer leads to its file and lock the name anew, or a run C that
    creates the file afresh would hold the lock beside it."""
    from clrays import image_io

    real_lock, calls = image_io._lock, []

    def lock_then_lose_the_name(folder, path):
        fd, locked = real_lock(folder, path)
        calls.append(os.fstat(fd).st_ino)
        if len(calls) == 1:
            os.unlink(path)  # what A's end does between B's open and B's flock
        return fd, locked

    monkeypatch.setattr(image_io, "_lock", lock_then_lose_the_name)
    with image_io.folder_lock(tmp_path) as path:
        assert len(calls) == 2
        assert os.stat(path).st_ino == calls[1]
        other = os.open(path, os.O_RDWR)  # a third run, on the file the name leads to, finds it locked
        try:
            with pytest.raises(BlockingIOError):
                fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
        finally:
            os.close(other)
    assert not os.path.lexists(path)


def test_the_lock_of_another_is_never_removed(tmp_path):
    """A holder removes the lock file only while the name still leads to its own file."""
    from clrays.image_io import LOCK, folder_lock

    with folder_lock(tmp_path) as path:
        os.unlink(path)
        path.write_text("another run's lock\n")
    assert (tmp_path / LOCK).read_text() == "another run's lock\n"
