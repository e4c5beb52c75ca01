"""A file that does not exist is :class:`FileNotFoundError` naming it, from every reader of
the Python API, as :func:`open` and :meth:`Model.load <topomech.Model.load>` raise it.

Before, each reader said it its own way: ``GMap.load`` raised ``FileFormatError``,
``RuleSet.load`` a ``RuleError`` at ``1:1``, ``read_mesh``, ``read_gmap`` and
``import_mesh`` a ``MeshReadError``, ``load_scene`` a ``SceneError``: a caller had to catch
five classes to tell "no such file" from "a file that is wrong". topomech's own classes are
now for files that exist and are refused, which these tests check beside each reader.
"""

from __future__ import annotations

import errno
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import topomech
from topomech import GMap, Model, RuleSet, cli, io
from topomech.scene import find_scene, load_scene

TRIANGLE = ([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], [("triangle", [[0, 1, 2]])])


def assert_missing(info: pytest.ExceptionInfo[FileNotFoundError], path: Path) -> None:
    """The error is the one `open` raises for ``path``: ENOENT, its name in the message."""
    e = info.value
    assert type(e) is FileNotFoundError
    assert e.errno == errno.ENOENT
    assert os.fspath(e.filename) == str(path)
    assert repr(str(path)) in str(e)


READERS: dict[str, tuple[str, Callable[[Path], Any]]] = {
    "GMap.load": ("map.tmg", GMap.load),
    "_core.GMap.load": ("map.tmg", lambda p: topomech._core.GMap.load(str(p))),
    "RuleSet.load": ("rules.tmr", RuleSet.load),
    "RuleSet.load (list)": ("rules.tmr", lambda p: RuleSet.load([p])),
    "read_mesh": ("mesh.msh", io.read_mesh),
    "read_gmap": ("mesh.vtu", topomech.read_gmap),
    "read_gmap (.tmg)": ("map.tmg", topomech.read_gmap),
    "import_mesh": ("mesh.obj", io.import_mesh),
    "import_mesh (.tmg)": ("map.tmg", io.import_mesh),
    "load_scene": ("scene.toml", load_scene),
    "Simulation.from_scene": ("scene.toml", topomech.Simulation.from_scene),
    "Model.load": ("model.tmr", Model.load),
}


@pytest.mark.parametrize("reader", list(READERS))
@pytest.mark.parametrize("as_str", [False, True], ids=["Path", "str"])
def test_a_missing_file_is_file_not_found(reader: str, as_str: bool, tmp_path: Path) -> None:
    name, read = READERS[reader]
    path = tmp_path / "nowhere" / name
    with pytest.raises(FileNotFoundError) as info:
        read(str(path) if as_str else path)  # type: ignore[arg-type]
    assert_missing(info, path)


def test_a_missing_rule_file_among_several_is_named(tmp_path: Path) -> None:
    """RuleSet.load of several files names the first that does not exist (the others
    exist); one that exists but cannot be read is still a RuleError."""
    good = tmp_path / "good.tmr"
    good.write_text("dimension 2\nembedding position : vec3 on <1,2>\n")
    missing = tmp_path / "missing.tmr"
    with pytest.raises(FileNotFoundError) as info:
        RuleSet.load([good, missing, tmp_path / "also_missing.tmr"])
    assert_missing(info, missing)
    with pytest.raises(topomech.RuleError, match=r"error\[file\]: cannot read the file"):
        RuleSet.load([good, tmp_path])  # a directory: exists, cannot be read


def test_a_scene_name_that_is_neither_a_file_nor_shipped(tmp_path: Path) -> None:
    """find_scene and load_scene: the message lists the shipped scenes."""
    for f in (find_scene, load_scene):
        with pytest.raises(FileNotFoundError, match="no shipped scene of that name") as info:
            f("no_such_scene")
        assert info.value.filename == "no_such_scene"
        assert "corotational" in str(info.value)


def test_saving_into_a_missing_folder(tmp_path: Path) -> None:
    """GMap.save into a folder that does not exist: FileNotFoundError, as open(path, 'w')
    and the mesh writers (write_gmap to .vtu) raise it."""
    g = GMap.from_mesh(*TRIANGLE)
    path = tmp_path / "nowhere" / "map.tmg"
    with pytest.raises(FileNotFoundError) as info:
        g.save(path)
    assert_missing(info, path)
    with pytest.raises(FileNotFoundError):
        io.write_gmap(g, tmp_path / "nowhere" / "map.vtu")


def test_files_that_exist_keep_their_errors(tmp_path: Path) -> None:
    """A file that exists and is wrong is refused by topomech's own class, as before."""
    junk = tmp_path / "junk.tmg"
    junk.write_bytes(b"this is not a map at all")
    with pytest.raises(topomech.FileFormatError, match="magic"):
        GMap.load(junk)
    with pytest.raises(topomech.FileFormatError, match=re.escape(f"{tmp_path}: not a regular")):
        GMap.load(tmp_path)  # a directory
    garbage = tmp_path / "garbage.msh"
    garbage.write_text("hello\nthis is not a mesh\n")
    with pytest.raises(topomech.MeshReadError, match=r"garbage\.msh: cannot read"):
        io.read_mesh(garbage)
    with pytest.raises(topomech.MeshReadError, match="is a directory"):
        io.read_mesh(tmp_path)
    bad = tmp_path / "bad.tmr"
    bad.write_text("dimension 2\nthis is not a rule\n")
    with pytest.raises(topomech.RuleError, match=r"bad\.tmr:2"):
        RuleSet.load(bad)
    scene = tmp_path / "bad.toml"
    scene.write_text(
        "[mesh]\nfile = 'nope.msh'\n[[model]]\nkind = 'corotational'\n"
        "[[fix]]\nwhere = 'x < 1e-9'\n[integrator]\nsteps = 2\n"
    )
    with pytest.raises(topomech.SceneError, match=r"mesh\.file: no such file"):
        load_scene(scene).build()  # a file the scene names: the scene's key to fix


@pytest.mark.parametrize(
    "args",
    [
        ["info", "{missing}"],
        ["info", "--json", "{missing}"],
        ["apply", "{missing}", "@library", "split_edge", "--everywhere", "--out", "{out}"],
        ["run", "{missing}"],
    ],
    ids=["info", "info --json", "apply", "run"],
)
def test_the_cli_names_a_missing_file_and_exits_2(
    args: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    suffix = ".toml" if args[0] == "run" else ".vtu"
    missing = tmp_path / f"missing{suffix}"
    out = tmp_path / "out.vtu"
    argv = [a.format(missing=missing, out=out) for a in args]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert f"topomech: error: {missing}: " in err
    assert "Traceback" not in err
    assert not out.exists()
