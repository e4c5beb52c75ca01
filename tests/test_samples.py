"""The sample meshes shipped in the package (``topomech/data``), ``topomech.sample`` and
``topomech samples``: what each file holds, that they stay small, that
``scripts/make_samples.py`` writes them again byte for byte."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import topomech
from topomech.cli import main

ROOT = Path(__file__).resolve().parent.parent
NAMES = ["beam.msh", "sheet.obj", "block.vtu"]


def test_each_sample_is_in_the_package_and_small() -> None:
    assert list(topomech.samples()) == NAMES
    for name in NAMES:
        path = topomech.sample(name)
        assert path.is_file()
        assert path.parent == Path(topomech.__file__).parent / "data"
        assert path.stat().st_size < 64 * 1024, name


def test_an_unknown_sample_names_the_samples() -> None:
    with pytest.raises(KeyError, match=r"beam\.msh, sheet\.obj, block\.vtu"):
        topomech.sample("bean.msh")


def test_what_the_samples_hold() -> None:
    beam, dropped = topomech.read_gmap(topomech.sample("beam.msh"))
    counts = beam.cell_counts()
    assert (counts["volumes"], counts["vertices"], counts["components"]) == (308, 119, 1)
    assert [(d.type, d.n_cells) for d in dropped] == [("triangle", 74)]  # Gmsh's boundary
    mesh, _ = topomech.io.read_mesh(topomech.sample("beam.msh"))
    assert set(mesh.point_sets) == {"beam", "clamp", "grip", "top"}
    x = mesh.points
    assert np.all(x[mesh.point_sets["clamp"], 0] == 0.0)
    assert np.all(x[mesh.point_sets["grip"], 0] == 1.0)
    assert np.all(np.isclose(x[mesh.point_sets["top"], 2], 0.2))
    assert np.allclose(x.min(axis=0), [0, 0, 0])
    assert np.allclose(x.max(axis=0), [1, 0.2, 0.2])

    sheet, _ = topomech.read_gmap(topomech.sample("sheet.obj"))
    assert sheet.dimension == 2
    assert sheet.cell_counts()["faces"] == 64
    assert sheet.cell_counts()["vertices"] == 81

    block, _ = topomech.read_gmap(topomech.sample("block.vtu"))
    assert block.cell_counts()["volumes"] == 24
    assert block.report.reoriented == []
    for g in (beam, sheet, block):
        g.check()


def test_the_cli_lists_and_copies_the_samples(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["samples"]) == 0
    out = capsys.readouterr().out
    for name in NAMES:
        assert name in out
        assert str(topomech.sample(name)) in out
    assert main(["samples", "--copy", str(tmp_path / "here")]) == 0
    assert capsys.readouterr().out.splitlines() == [f"wrote {tmp_path / 'here' / n}" for n in NAMES]
    for name in NAMES:
        assert (tmp_path / "here" / name).read_bytes() == topomech.sample(name).read_bytes()


def test_the_samples_are_not_ignored_by_git() -> None:
    """Ignored files would not be committed (and maturin leaves them out of the wheel)."""
    paths = [str(topomech.sample(n).relative_to(ROOT)) for n in NAMES]
    r = subprocess.run(["git", "check-ignore", *paths], cwd=ROOT, capture_output=True, text=True)
    assert r.stdout == "", r.stdout


def _content(path: Path) -> tuple[object, ...]:
    import meshio

    m = meshio.read(path)
    cells = tuple((b.type, b.data.tolist()) for b in m.cells)
    sets = {k: [np.asarray(x).tolist() for x in v] for k, v in m.cell_sets.items()}
    return (m.points.tolist(), cells, sets)


@pytest.mark.skipif(importlib.util.find_spec("gmsh") is None, reason="no gmsh package")
def test_the_script_writes_the_same_meshes(tmp_path: Path) -> None:
    """``scripts/make_samples.py`` writes the shipped meshes again: the same bytes with the
    gmsh and meshio that wrote them, the same points, cells and groups with another meshio;
    with another gmsh (which may mesh the beam otherwise), the OBJ and VTU only."""
    import gmsh
    import meshio

    spec = importlib.util.spec_from_file_location(
        "make_samples", ROOT / "scripts" / "make_samples.py"
    )
    assert spec is not None
    assert spec.loader is not None
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    r = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "make_samples.py"), "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    names = NAMES if gmsh.__version__ == script.GMSH_VERSION else NAMES[1:]
    for name in names:
        shipped, again = topomech.sample(name), tmp_path / name
        assert _content(again) == _content(shipped), name
        if name != "block.vtu" or f"meshio v{meshio.__version__}" in shipped.read_text():
            assert again.read_bytes() == shipped.read_bytes(), name


def test_copy_keeps_an_edited_sample_unless_told(tmp_path: Path) -> None:
    """Copying again keeps identical files; a sample the user edited is not replaced (the
    error names it) unless overwrite; a file given as the folder is refused."""
    from topomech.samples import copy_samples, sample

    copy_samples(tmp_path)
    edited = tmp_path / "beam.msh"
    edited.write_bytes(edited.read_bytes() + b"% mine\n")
    with pytest.raises(FileExistsError) as e:
        copy_samples(tmp_path)
    assert e.value.filename == str(edited)
    assert edited.read_bytes().endswith(b"% mine\n")  # nothing lost
    copy_samples(tmp_path, overwrite=True)
    assert edited.read_bytes() == sample("beam.msh").read_bytes()
    with pytest.raises(NotADirectoryError):
        copy_samples(edited)
