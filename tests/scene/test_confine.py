"""--confine and CLRAYS_CONFINE: a scene may read only the files in its own folder (and
below), symbolic links resolved, whatever field names them: meshes, relief maps, light
textures. Without them, a scene reads any file the user can (a command line tool's normal)."""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest

from clrays.errors import SceneError
from clrays.scene import files
from clrays.scene.load import load_scene
from conftest import run_cli

HEAD = """version: 1
image: {width: 16, height: 9}
camera: {position: [0, 1, 5], look_at: [0, 0, 0]}
"""
POINT = "lights: [{type: point, position: [0, 3, 3], intensity: 10}]\n"
#: field → the scene text naming FILE there, and the extension of such a file
FIELDS = {
    "objects.0.file": (HEAD + POINT + "objects: [{type: mesh, file: FILE}]\n", ".obj"),
    "objects.0.depth_map": (HEAD + POINT + "objects: [{type: relief, center: [0, 0, 0], normal: [0, 0, 1], up: [0, 1, 0], "
                                           "size: [1, 1], height: 0.1, depth_map: FILE}]\n", ".npy"),
    "objects.0.albedo_map": (HEAD + POINT + "objects: [{type: relief, center: [0, 0, 0], normal: [0, 0, 1], up: [0, 1, 0], "
                                            "size: [1, 1], height: 0.1, depth_map: d.npy, albedo_map: FILE}]\n",
                             ".npy"),
    "lights.0.texture": (HEAD + "lights: [{type: spot, position: [0, 4, 0], direction: [0, -1, 0], cone_deg: 30, "
                                "intensity: 50, texture: FILE}]\n", ".npy"),
}


def write_asset(path: Path) -> Path:
    """A file the field accepts: a one-triangle OBJ, or a 4 × 4 image in [0, 1]."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".obj":
        path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    else:
        np.save(path, np.linspace(0, 1, 16).reshape(4, 4))
    return path


@pytest.fixture
def layout(tmp_path):
    """tmp/service/scenes/{scene.yaml, assets/}, and tmp/secret/ beside the service's folder."""
    scenes = tmp_path / "service" / "scenes"
    scenes.mkdir(parents=True)
    write_asset(scenes / "d.npy")
    return scenes, tmp_path / "secret"


def scene_naming(scenes: Path, field: str, name: str) -> Path:
    text, _ = FIELDS[field]
    path = scenes / "scene.yaml"
    path.write_text(text.replace("FILE", name))
    return path


def outside_names(scenes: Path, secret: Path, suffix: str) -> dict[str, str]:
    """The ways a scene can name a file outside its folder: up with `..`, an absolute
    path, and a link inside that points out."""
    target = write_asset(secret / f"data{suffix}")
    (scenes / "assets").mkdir(exist_ok=True)
    link = scenes / "assets" / f"link{suffix}"
    link.symlink_to(target)
    return {"dot-dot": f"../../secret/data{suffix}", "absolute": str(target), "symlink": f"assets/link{suffix}"}


@pytest.mark.parametrize("field", list(FIELDS))
def test_confined_scenes_cannot_name_files_outside_their_folder(layout, field, monkeypatch):
    scenes, secret = layout
    _, suffix = FIELDS[field]
    names = outside_names(scenes, secret, suffix)
    for how, name in names.items():
        scene = scene_naming(scenes, field, name)
        load_scene(scene)  # unconfined: read, as before
        files.confine_scene_files(True)
        try:
            with pytest.raises(SceneError) as refused:
                load_scene(scene)
        finally:
            files.confine_scene_files(False)
        message = str(refused.value)
        assert "\n" not in message
        assert re.match(rf"{re.escape(str(scene))}:\d+:\d+: {re.escape(field)}: expected .*got '", message), message
        assert f"{scenes / name})" in message, message  # the path as named (scenes / an absolute one is that one)
        assert f"outside the scene's folder {os.path.realpath(scenes)}" in message, message
        assert "(files confined by --confine)" in message, (how, message)
    # CLRAYS_CONFINE does the same without the option.
    monkeypatch.setenv("CLRAYS_CONFINE", "1")
    with pytest.raises(SceneError, match=r"outside the scene's folder .*\(files confined by CLRAYS_CONFINE\)"):
        load_scene(scene_naming(scenes, field, names["dot-dot"]))


@pytest.mark.parametrize("field", list(FIELDS))
def test_files_inside_the_folder_stay_readable(layout, field, monkeypatch):
    scenes, _ = layout
    _, suffix = FIELDS[field]
    write_asset(scenes / "assets" / f"ok{suffix}")
    (scenes / "assets" / f"inner{suffix}").symlink_to(scenes / "assets" / f"ok{suffix}")
    monkeypatch.setenv("CLRAYS_CONFINE", "1")
    for name in (f"assets/ok{suffix}", f"assets/../assets/ok{suffix}", str(scenes / "assets" / f"ok{suffix}"),
                 f"assets/inner{suffix}"):  # `..` that stays inside, absolute inside, a link inside to inside
        load_scene(scene_naming(scenes, field, name))


def test_a_confined_scene_cannot_tell_which_outside_files_exist(layout, monkeypatch):
    scenes, secret = layout
    monkeypatch.setenv("CLRAYS_CONFINE", "1")
    messages = []
    for name in ("../../secret/data.obj", "../../secret/nothing.obj"):
        write_asset(secret / "data.obj")
        with pytest.raises(SceneError) as refused:
            load_scene(scene_naming(scenes, "objects.0.file", name))
        messages.append(str(refused.value).replace("nothing", "data"))
    assert messages[0] == messages[1] and "outside the scene's folder" in messages[0]


def test_confinement_follows_the_scene_files_folder_through_a_linked_scene(layout, tmp_path, monkeypatch):
    # The scene file itself may be a link: the files it names are looked for beside the link
    # (as without --confine) and must lie in that folder once resolved.
    scenes, _ = layout
    write_asset(scenes / "m.obj")
    scene = scene_naming(scenes, "objects.0.file", "m.obj")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "scene.yaml").symlink_to(scene)
    monkeypatch.setenv("CLRAYS_CONFINE", "1")
    with pytest.raises(SceneError, match=r"objects\.0\.file: .*no such file"):
        load_scene(elsewhere / "scene.yaml")  # m.obj is not beside the link
    load_scene(scene)


@pytest.mark.parametrize("value, on", [("1", True), ("yes", True), ("TRUE", True), ("anything", True), ("0", False),
                                       ("false", False), ("off", False), ("", False)])
def test_clrays_confine_values(monkeypatch, value, on):
    monkeypatch.setenv("CLRAYS_CONFINE", value)
    assert (files.confinement() == "CLRAYS_CONFINE") == on


@pytest.mark.parametrize("command", [["render", "-o", "{out}/a.png"], ["sequence", "-o", "{out}/f_{{}}.png"],
                                     ["sweep", "--set", "render.slices=32,64", "-o", "{out}/sweep"],
                                     ["compare", "-o", "{out}/compare"], ["relief-to-mesh", "-o", "{out}/m.ply"],
                                     ["bench", "--out", "{out}/bench"],
                                     ["tune", "--target-error", "1", "-o", "{out}/tuned.yaml"]])
def test_every_command_that_loads_a_scene_takes_confine(layout, tmp_path, command):
    scenes, secret = layout
    field = "objects.0.depth_map"  # a relief, which relief-to-mesh needs too
    scene = scene_naming(scenes, field, outside_names(scenes, secret, ".npy")["dot-dot"])
    name, *rest = command
    (tmp_path / "out").mkdir()
    arguments = [name, scene, *(argument.format(out=tmp_path / "out") for argument in rest)]
    code, output = run_cli(*arguments, "--confine")
    lines = output.strip().splitlines()
    assert code == 1 and lines[-1].startswith("clrays: error: ") and "outside the scene's folder" in lines[-1], output
    assert f"{scene}:" in lines[-1] and field in lines[-1]
    assert len([line for line in lines if "error" in line]) == 1, output
    # The flag ends with the run: the same command without it reads the file.
    assert files.confinement() is None
