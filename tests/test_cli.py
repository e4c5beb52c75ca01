"""The `topomech` command: output, notes and exit codes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

import topomech
from topomech import _core, cli

from conftest import independent_counts

JSON_KEYS = {
    "darts",
    "dimension",
    "vertices",
    "edges",
    "faces",
    "volumes",
    "components",
    "boundary",
    "valid",
}


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """The CLI in a fresh interpreter, as a user runs it."""
    return subprocess.run(
        [sys.executable, "-m", "topomech", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=120,
        check=False,
    )


@pytest.fixture
def tet_file(tmp_path: Path) -> tuple[Path, dict[str, int]]:
    points, _kinds, _offsets, conn = _core.box(2, 1, 1, 2.0, 1.0, 1.0, "tetra")
    cells = [("tetra", conn.reshape(-1, 4))]
    path = tmp_path / "box.msh"
    meshio.write(path, meshio.Mesh(points, cells), file_format="gmsh22", binary=False)
    return path, independent_counts(cells)


def test_info_json_is_exactly_one_object(tet_file: tuple) -> None:
    path, expected = tet_file
    r = run("info", str(path), "--json")
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("\n") == 1
    data = json.loads(r.stdout)
    assert isinstance(data, dict)
    assert data.keys() >= JSON_KEYS
    assert {k: data[k] for k in expected} == expected
    assert data["dimension"] == 3
    assert data["valid"] is True
    assert "Traceback" not in r.stderr


def test_info_json_of_a_refused_file_is_an_error_object(tmp_path: Path) -> None:
    """A script reading `info --json` gets an object naming the file and why, on a file
    that cannot be read or a mesh that is refused: exit 2, the reason on stderr too."""
    missing = tmp_path / "missing.vtu"
    flat = tmp_path / "flat.vtu"
    points = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]
    meshio.write(flat, meshio.Mesh(points, [("tetra", [[0, 1, 2, 3]])]))
    for path in (missing, flat):
        r = run("info", str(path), "--json")
        assert r.returncode == 2, r.stderr
        assert r.stdout.count("\n") == 1
        data = json.loads(r.stdout)
        assert data["file"] == str(path)
        assert data["error"]
        assert data["error"] in r.stderr or str(path) in r.stderr
        assert "Traceback" not in r.stderr


def test_info_text(tet_file: tuple) -> None:
    path, expected = tet_file
    r = run("info", str(path))
    assert r.returncode == 0, r.stderr
    lines = dict(line.split(None, 1) for line in r.stdout.splitlines())
    assert lines["darts"] == str(expected["darts"])
    assert lines["volumes"] == str(expected["volumes"])
    assert lines["boundary"] == f"{expected['boundary']} faces"
    assert lines["valid"] == "yes"


def test_info_on_a_surface_counts_boundary_edges(tmp_path: Path, quads: tuple) -> None:
    points, cells = quads
    path = tmp_path / "quads.vtu"
    meshio.write(path, meshio.Mesh(np.column_stack([points, np.zeros(len(points))]), cells))
    assert cli.main(["info", str(path), "--json"]) == 0


# meshio's Gmsh 4.1 writer needs entity tags for several cell types: those files get one type.
@pytest.mark.parametrize(
    ("name", "kwargs", "fixture"),
    [
        ("a.msh", {"file_format": "gmsh22", "binary": False}, "mixed_volume"),
        ("b.msh", {"file_format": "gmsh22", "binary": True}, "mixed_volume"),
        ("c.msh", {"file_format": "gmsh", "binary": False}, "two_hexes"),
        ("d.msh", {"file_format": "gmsh", "binary": True}, "two_wedges"),
        ("e.vtu", {}, "mixed_volume"),
        ("f.vtk", {}, "mixed_volume"),
        ("g.vtk", {"binary": False}, "two_pyramids"),
    ],
)
def test_info_reads_every_format(
    name: str,
    kwargs: dict,
    fixture: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    request: pytest.FixtureRequest,
) -> None:
    points, cells = request.getfixturevalue(fixture)
    path = tmp_path / name
    meshio.write(path, meshio.Mesh(points, cells), **kwargs)
    assert cli.main(["info", str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert {k: data[k] for k in JSON_KEYS - {"valid", "dimension"}} == independent_counts(cells)


def test_info_reads_obj(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], mixed_surface: tuple
) -> None:
    points, cells = mixed_surface
    path = tmp_path / "s.obj"
    meshio.write(path, topomech.GMap.from_mesh(points, cells).to_meshio())
    assert cli.main(["info", str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["dimension"] == 2
    assert data["faces"] == 4
    assert data["boundary"] == independent_counts(cells)["boundary"]


def test_info_reads_a_saved_gmap(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], two_hexes: tuple
) -> None:
    g = topomech.GMap.from_mesh(*two_hexes)
    g.save(tmp_path / "h.tmg")
    assert cli.main(["info", str(tmp_path / "h.tmg"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert {k: data[k] for k in g.cell_counts()} == dict(g.cell_counts())


# What Gmsh 4.1 writes for a meshed tetrahedron: the boundary triangles (on a surface entity)
# beside the volume element.
GMSH41_TET_WITH_BOUNDARY = """\
$MeshFormat
4.1 0 8
$EndMeshFormat
$Entities
0 0 1 1
1 0 0 0 1 1 1 0 0
1 0 0 0 1 1 1 0 1 1
$EndEntities
$Nodes
1 4 1 4
3 1 0 4
1
2
3
4
0 0 0
1 0 0
0 1 0
0 0 1
$EndNodes
$Elements
2 5 1 5
2 1 2 4
1 1 3 2
2 1 2 4
3 2 3 4
4 1 4 3
3 1 4 1
5 1 2 3 4
$EndElements
"""


@pytest.mark.parametrize("variant", ["gmsh41-literal", "gmsh22-meshio"])
def test_gmsh_boundary_triangles_are_dropped_with_a_note(variant: str, tmp_path: Path) -> None:
    path = tmp_path / "tet.msh"
    if variant == "gmsh41-literal":
        path.write_text(GMSH41_TET_WITH_BOUNDARY)
    else:
        points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
        mesh = meshio.Mesh(
            points,
            [
                ("triangle", np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])),
                ("tetra", np.array([[0, 1, 2, 3]])),
            ],
        )
        meshio.write(path, mesh, file_format="gmsh22", binary=False)
    r = run("info", str(path), "--json")
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    assert (data["volumes"], data["faces"], data["boundary"], data["vertices"]) == (1, 4, 4, 4)
    assert data["dropped"] == [{"type": "triangle", "n_cells": 4, "dimension": 2}]
    assert "note: dropped 4 triangle cells (2D): lower-dimensional than the 3D cells" in r.stderr


def test_reorient_flag(tmp_path: Path) -> None:
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    path = tmp_path / "inverted.vtu"
    meshio.write(path, meshio.Mesh(points, [("tetra", np.array([[0, 2, 1, 3]]))]))
    # Issue 12: cells listed with the opposite orientation are ordinary input, turned over by
    # default (and counted: `reoriented` is the count, `reoriented_cells` the list);
    # --no-reorient refuses them, and the refusal names the CLI flag, not a Python keyword.
    r = run("info", str(path), "--no-reorient")
    assert r.returncode == 2
    assert "inverted" in r.stderr
    assert "cell 0" in r.stderr
    assert "--reorient" in r.stderr
    assert "reorient=True" not in r.stderr
    assert "Traceback" not in r.stderr
    for flags in ([], ["--reorient"]):
        r = run("info", str(path), *flags, "--json")
        assert r.returncode == 0, r.stderr
        data = json.loads(r.stdout)
        assert (data["reoriented"], data["reoriented_cells"]) == (1, [0])
        assert "reoriented 1 cell(s) listed with the opposite orientation" in r.stderr


@pytest.mark.parametrize("case", ["missing", "garbage", "truncated", "directory", "refused"])
def test_exit_2_when_the_file_cannot_be_read(case: str, tmp_path: Path, tet_file: tuple) -> None:
    path = tmp_path / f"{case}.msh"
    if case == "garbage":
        path.write_bytes(bytes(range(256)) * 8)
    elif case == "truncated":
        data = tet_file[0].read_bytes()
        path.write_bytes(data[: len(data) // 2])
    elif case == "directory":
        path.mkdir()
    elif case == "refused":
        path = tmp_path / "nonmanifold.vtu"
        pts = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]], dtype=float)
        meshio.write(
            path, meshio.Mesh(pts, [("triangle", np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]))])
        )
    r = run("info", str(path), "--json")
    assert r.returncode == 2
    # stdout: one object saying why, for a script that reads it; the reason on stderr too
    error = json.loads(r.stdout)
    assert error["file"] == str(path)
    assert error["error"] in r.stderr
    assert r.stderr.startswith("topomech: error: ")
    assert "Traceback" not in r.stderr
    if case != "refused":
        assert path.name in r.stderr


def test_truncated_binary_gmsh(tmp_path: Path, tet_file: tuple) -> None:
    points, _kinds, _offsets, conn = _core.box(2, 2, 2, 1.0, 1.0, 1.0, "tetra")
    full = tmp_path / "full.msh"
    meshio.write(
        full, meshio.Mesh(points, [("tetra", conn.reshape(-1, 4))]), file_format="gmsh", binary=True
    )
    data = full.read_bytes()
    for frac in (0.2, 0.5, 0.9, 0.99):
        cut = tmp_path / f"cut{frac}.msh"
        cut.write_bytes(data[: int(len(data) * frac)])
        assert cli.main(["info", str(cut)]) == 2


def test_exit_1_when_the_map_is_not_valid(
    monkeypatch: pytest.MonkeyPatch, tet_file: tuple, capsys: pytest.CaptureFixture[str]
) -> None:
    # No public operation builds an invalid map (sew and unsew refuse to break one), so the
    # validity check is replaced in-process.
    monkeypatch.setattr(topomech.GMap, "is_valid", lambda self: False)
    monkeypatch.setattr(
        topomech.GMap, "violations", lambda self: ["alpha0 is not an involution (simulated)"]
    )
    assert cli.main(["info", str(tet_file[0]), "--json"]) == 1
    out, err = capsys.readouterr()
    data = json.loads(out)
    assert data["valid"] is False
    assert data["violations"] == ["alpha0 is not an involution (simulated)"]
    assert "violation: alpha0 is not an involution" in err
    assert cli.main(["info", str(tet_file[0])]) == 1
    assert "valid       NO (1 violations)" in capsys.readouterr().out


def test_internal_errors_exit_2_without_traceback(
    monkeypatch: pytest.MonkeyPatch, tet_file: tuple, capsys: pytest.CaptureFixture[str]
) -> None:
    def boom(self: object) -> None:
        _core._panic_for_tests("simulated")

    monkeypatch.setattr(topomech.GMap, "cell_counts", boom)
    assert cli.main(["info", str(tet_file[0])]) == 2
    assert "internal error in topomech" in capsys.readouterr().err


def test_usage_errors_exit_2() -> None:
    r = run("info")
    assert r.returncode == 2
    assert "MESH_FILE" in r.stderr
    r = run("frobnicate")
    assert r.returncode == 2


def test_version() -> None:
    r = run("--version")
    assert r.returncode == 0
    assert r.stdout.strip() == f"topomech {topomech.__version__}"


def test_console_script_is_installed() -> None:
    script = Path(sys.executable).parent / "topomech"
    if not script.exists():
        pytest.skip("package not installed as a console script in this environment")
    r = subprocess.run([str(script), "--help"], capture_output=True, text=True, check=False)
    assert r.returncode == 0
    for cmd in ("info", "demo"):
        assert cmd in r.stdout
