"""Mesh files from other tools (issue 12): one file per writer (scikit-fem, Gmsh 2 and 4 in
ASCII and binary, a VTU written by hand as another tool would, Abaqus from meshio), files whose
extension lies, Gmsh 1, Gmsh 4.1 with physical tags on only some entities, second-order cells,
the named sets read_mesh keeps (contract C4), and the import options in each front end's
spelling (Python keywords, CLI flags, scene keys).

Every comparison is exact (integer indices, coordinates copied digit for digit by the writers)
except where a file stores coordinates in text with fewer digits: those say their tolerance.
"""

from __future__ import annotations

import inspect
import json
import re
import subprocess
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import meshio
import numpy as np
import pytest

import topomech
from topomech.io import import_mesh, linear_type, read_gmap, read_mesh
from topomech.scene import load_scene, parse_scene

from conftest import independent_counts


def run(*args: str) -> subprocess.CompletedProcess[str]:
    """The CLI in a fresh interpreter, as a user runs it."""
    return subprocess.run(
        [sys.executable, "-m", "topomech", *args],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def rows(cells: Iterable[Any]) -> list[tuple[str, tuple[int, ...]]]:
    """Every cell as (type, vertices), in order."""
    return [(str(b.type), tuple(int(v) for v in c)) for b in cells for c in b.data]


# Two positively oriented tetrahedra sharing the face (1, 2, 3).
TWO_TETS_POINTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
TWO_TETS = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])


# ------------------------------------------------------------------------- one file per writer


def test_scikit_fem_meshes_load_as_written(tmp_path: Path) -> None:
    # scikit-fem's own meshes, saved by scikit-fem: MeshTri lists its triangles with mixed
    # orientations (issue 12), which is ordinary input: the map is built (reoriented by
    # default) with skfem's points in skfem's order and its cells as skfem lists them.
    skfem = pytest.importorskip("skfem")
    for mesh, name in (
        (skfem.MeshTri().refined(3), "tri.vtk"),
        (skfem.MeshTet().refined(2), "tet.msh"),
    ):
        path = tmp_path / name
        mesh.save(str(path))
        m, dropped = read_mesh(path)
        assert dropped == []
        np.testing.assert_array_equal(m.points[:, : mesh.p.shape[0]], mesh.p.T)
        kind = "triangle" if mesh.t.shape[0] == 3 else "tetra"
        expected = [(kind, tuple(int(v) for v in c)) for c in mesh.t.T]
        assert rows(m.cells) == expected
        g = import_mesh(path).gmap
        counts = independent_counts([(kind, mesh.t.T)])
        assert {k: v for k, v in g.cell_counts().items()} == counts


@pytest.mark.parametrize(
    ("file_format", "binary"),
    [("gmsh22", False), ("gmsh22", True), ("gmsh", False), ("gmsh", True)],
    ids=["v2-ascii", "v2-binary", "v4.1-ascii", "v4.1-binary"],
)
def test_gmsh_files_written_by_meshio_keep_cells_and_groups(
    file_format: str, binary: bool, tmp_path: Path
) -> None:
    # meshio's Gmsh writers, with a named physical group on the tetrahedra ("body") and one on
    # a boundary triangle ("bottom"): the tetrahedra are kept in order, the triangle is
    # dropped from the map but kept as a facet set, and both groups give their points.
    path = tmp_path / "two.msh"
    mesh = meshio.Mesh(
        TWO_TETS_POINTS,
        [("triangle", np.array([[0, 2, 1]])), ("tetra", TWO_TETS)],
        cell_data={
            "gmsh:physical": [np.array([2]), np.array([1, 1])],
            "gmsh:geometrical": [np.array([1]), np.array([1, 1])],
        },
        field_data={"body": np.array([1, 3]), "bottom": np.array([2, 2])},
    )
    if file_format == "gmsh":  # meshio's 4.1 writer needs each node's entity (dim, tag)
        mesh.point_data["gmsh:dim_tags"] = np.array([[2, 1]] * 3 + [[3, 1]] * 2)
    meshio.write(path, mesh, file_format=file_format, binary=binary)
    m, dropped = read_mesh(path)
    np.testing.assert_array_equal(m.points, TWO_TETS_POINTS)
    assert rows(m.cells) == [("tetra", tuple(c)) for c in TWO_TETS.tolist()]
    assert dropped == [("triangle", 1, 2)]
    np.testing.assert_array_equal(m.cell_sets_kept["body"], [0, 1])
    np.testing.assert_array_equal(m.point_sets["body"], [0, 1, 2, 3, 4])
    np.testing.assert_array_equal(m.point_sets["bottom"], [0, 1, 2])
    [(kind, tris)] = m.facet_sets["bottom"]
    assert kind == "triangle"
    np.testing.assert_array_equal(tris, [[0, 2, 1]])
    assert "bottom" not in m.cell_sets_kept


VTU_BY_HAND = """<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">
  <UnstructuredGrid>
    <Piece NumberOfPoints="5" NumberOfCells="2">
      <Points>
        <DataArray type="Float64" NumberOfComponents="3" format="ascii">
          0 0 0  1 0 0  0 1 0  0 0 1  1 1 1
        </DataArray>
      </Points>
      <Cells>
        <DataArray type="Int64" Name="connectivity" format="ascii">0 1 2 3 1 2 3 4</DataArray>
        <DataArray type="Int64" Name="offsets" format="ascii">4 8</DataArray>
        <DataArray type="UInt8" Name="types" format="ascii">10 10</DataArray>
      </Cells>
    </Piece>
  </UnstructuredGrid>
</VTKFile>
"""


def test_a_vtu_written_by_another_tool(tmp_path: Path) -> None:
    # A VTU as ParaView-era tools write it by hand (ASCII data arrays, Int64 offsets):
    # the same two tetrahedra, read exactly.
    path = tmp_path / "hand.vtu"
    path.write_text(VTU_BY_HAND)
    m, dropped = read_mesh(path)
    assert dropped == []
    np.testing.assert_array_equal(m.points, TWO_TETS_POINTS)
    assert rows(m.cells) == [("tetra", tuple(c)) for c in TWO_TETS.tolist()]
    assert m.notes == []


@pytest.mark.parametrize(
    ("points", "cells", "only"),
    [
        (np.zeros((0, 3)), [], "and no points"),
        (np.zeros((3, 3)), [], "only 3 points"),
        (np.zeros((0, 3)), [("triangle", np.zeros((0, 3), dtype=int))], "and no points"),
    ],
    ids=["empty", "points-only", "empty-block"],
)
def test_a_vtu_without_cells_says_so(
    tmp_path: Path, points: np.ndarray, cells: list, only: str
) -> None:
    """Regression: a VTU with no cells was refused with meshio's own words ("need at least one
    array to concatenate", "Inconsistent data!"). The error names the file and says it has
    no cells, in each reader and from a lying extension (read by its content)."""
    for name in ("empty.vtu", "empty.vtk"):
        path = tmp_path / name
        meshio.write(path, meshio.Mesh(points, cells), file_format="vtu")
        want = rf"^{re.escape(str(path))}: the VTU file has no cells, {only}: there is no mesh"
        for read in (read_mesh, read_gmap, import_mesh):
            with pytest.raises(topomech.MeshReadError, match=want) as e:
                read(path)
            assert "concatenate" not in str(e.value)
            assert "Inconsistent" not in str(e.value)


def test_meshio_point_and_cell_sets_are_kept(tmp_path: Path) -> None:
    # Abaqus *NSET/*ELSET, written by meshio: a point set, a cell set on the tetrahedra (an
    # index into the kept cells) and one on the boundary triangle (a facet set).
    path = tmp_path / "sets.inp"
    mesh = meshio.Mesh(
        TWO_TETS_POINTS,
        [("tetra", TWO_TETS), ("triangle", np.array([[0, 1, 2]]))],
        point_sets={"tip": np.array([4])},
        cell_sets={
            "second": [np.array([1]), np.array([], dtype=int)],
            "bottom": [np.array([], dtype=int), np.array([0])],
        },
    )
    meshio.write(path, mesh, file_format="abaqus")
    m, _ = read_mesh(path)
    np.testing.assert_array_equal(m.point_sets["tip"], [4])
    np.testing.assert_array_equal(m.point_sets["second"], [1, 2, 3, 4])
    np.testing.assert_array_equal(m.cell_sets_kept["second"], [1])
    assert [(k, a.tolist()) for k, a in m.facet_sets["bottom"]] == [("triangle", [[0, 1, 2]])]


def test_tetgen_files_numbered_from_one(tmp_path: Path) -> None:
    # TetGen's .node/.ele pair, numbered from 1, the first tetrahedron listed with the
    # opposite orientation (TetGen-style tools disagree on it): read with the points in file
    # order, turned over by default, and counted.
    (tmp_path / "tg.node").write_text("5 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n")
    (tmp_path / "tg.ele").write_text("2 4 0\n1 1 3 2 4\n2 2 3 4 5\n")
    m = import_mesh(tmp_path / "tg.ele")
    assert m.mesh is not None
    np.testing.assert_array_equal(m.mesh.points, TWO_TETS_POINTS)
    assert rows(m.mesh.cells) == [("tetra", (0, 2, 1, 3)), ("tetra", (1, 2, 3, 4))]
    assert m.gmap.report.reoriented == [0]
    assert m.gmap.cell_counts() == independent_counts([("tetra", TWO_TETS)])


# ------------------------------------------------------------------------- lying extensions


def _legacy_vtk(path: Path) -> None:
    meshio.write(path, meshio.Mesh(TWO_TETS_POINTS, [("tetra", TWO_TETS)]), file_format="vtk")


def _gmsh(path: Path) -> None:
    meshio.write(path, meshio.Mesh(TWO_TETS_POINTS, [("tetra", TWO_TETS)]), file_format="gmsh22")


def _obj(path: Path) -> None:
    path.write_text("# a hand-made OBJ\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 4\nf 1 4 3\n")


@pytest.mark.parametrize(
    ("name", "write", "words"),
    [
        ("xml.vtk", lambda p: p.write_text(VTU_BY_HAND), "VTU XML"),
        ("legacy.msh", _legacy_vtk, "legacy VTK"),
        ("gmsh.vtu", _gmsh, "Gmsh"),
        ("gmsh.vtk", _gmsh, "Gmsh"),
        ("noext", _gmsh, "Gmsh"),
        ("surface.vtk", _obj, "Wavefront OBJ"),
    ],
)
def test_a_lying_extension_is_read_by_content(
    name: str, write: Any, words: str, tmp_path: Path
) -> None:
    # The extension's readers fail (or the extension is unknown), the first bytes say what
    # the file is: it is read as that, with a note naming what was done.
    path = tmp_path / name
    write(path)
    m, _ = read_mesh(path)
    assert len(m.notes) == 1
    assert f"as {words} by its content" in m.notes[0]
    if name == "surface.vtk":
        assert rows(m.cells) == [("triangle", (0, 1, 3)), ("triangle", (0, 3, 2))]
    else:
        np.testing.assert_array_equal(m.points, TWO_TETS_POINTS)
        assert rows(m.cells) == [("tetra", tuple(c)) for c in TWO_TETS.tolist()]
    r = run("info", str(path), "--json")
    assert r.returncode == 0, r.stderr
    assert "by its content" in r.stderr


def test_garbage_is_still_refused_naming_what_was_tried(tmp_path: Path) -> None:
    # Sniffing must not turn garbage into a mesh: the extension's readers' reasons are given.
    path = tmp_path / "garbage.vtk"
    path.write_text("nothing a mesh reader knows\n")
    with pytest.raises(topomech.MeshReadError, match=r"garbage\.vtk: cannot read this file"):
        read_mesh(path)


# ------------------------------------------------------------------------- Gmsh 1

GMSH1 = """$NOD
5
10 0 0 0
20 1 0 0
30 0 1 0
40 0 0 1
50 1 1 1
$ENDNOD
$ELM
3
1 4 1 1 4 10 20 30 40
2 4 1 1 4 20 30 40 50
3 2 5 2 3 10 20 30
$ENDELM
"""


def test_gmsh1_files_are_read(tmp_path: Path) -> None:
    # Gmsh 1 ($NOD/$ELM), node numbers not 1..n: the points in file order, the tetrahedra by
    # those numbers, the region numbers as unnamed groups "1" and "5".
    path = tmp_path / "old.msh"
    path.write_text(GMSH1)
    m, dropped = read_mesh(path)
    np.testing.assert_array_equal(m.points, TWO_TETS_POINTS)
    assert rows(m.cells) == [("tetra", tuple(c)) for c in TWO_TETS.tolist()]
    assert dropped == [("triangle", 1, 2)]
    assert "Gmsh 1 file" in m.notes[0]
    np.testing.assert_array_equal(m.cell_sets_kept["1"], [0, 1])
    np.testing.assert_array_equal(m.point_sets["5"], [0, 1, 2])
    assert [(k, a.tolist()) for k, a in m.facet_sets["5"]] == [("triangle", [[0, 1, 2]])]
    g, _ = read_gmap(path)
    assert g.cell_counts() == independent_counts([("tetra", TWO_TETS)])


def test_a_broken_gmsh1_file_names_the_line(tmp_path: Path) -> None:
    path = tmp_path / "broken.msh"
    path.write_text(GMSH1.replace("2 4 1 1 4 20 30 40 50", "2 4 1 1 4 20 30 40"))
    with pytest.raises(
        topomech.MeshReadError,
        match=r"Gmsh 1 file: line 12: element 2 .*must list 4 nodes, lists 3",
    ):
        read_mesh(path)


def test_an_element_on_an_undefined_node_names_the_file(tmp_path: Path) -> None:
    # Gmsh 4.1 refers to nodes by tag: an element on a tag the file never defines is a broken
    # file, said as such, whether meshio fails on it or maps the unknown tag to -1.
    from topomech.io import _check_indices

    path = tmp_path / "undefined.msh"
    path.write_text(GMSH41_PARTIAL.replace("2 2 3 4 5\n", "2 2 3 4 9\n"))
    with pytest.raises(topomech.MeshReadError, match=r"undefined\.msh: cannot read this file"):
        read_mesh(path)
    mapped = meshio.Mesh(TWO_TETS_POINTS, [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, -1]]))])
    with pytest.raises(topomech.MeshReadError, match=r"1 tetra cell\(s\) .*cells 1 of the block"):
        _check_indices(path, mapped)


# ------------------------------------------------------------------------- Gmsh 4.1, gmsh itself


def _gmsh_box(tmp_path: Path, version: float, binary: bool, save_all: bool) -> Path:
    """A unit cube meshed by Gmsh, with a named physical group on the volume ("body"), a
    named one on the face x = 0 ("left") and an unnamed one (tag 77) on the face x = 1;
    the other faces, edges and corners have no physical tags."""
    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("box")
        gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(3, [1], name="body")
        faces = {}
        for d, t in gmsh.model.getEntities(2):
            x = gmsh.model.occ.getCenterOfMass(d, t)[0]
            faces[round(x, 6)] = t
        gmsh.model.addPhysicalGroup(2, [faces[0.0]], name="left")
        gmsh.model.addPhysicalGroup(2, [faces[1.0]], tag=77)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
        gmsh.option.setNumber("Mesh.SaveAll", int(save_all))
        gmsh.model.mesh.generate(3)
        gmsh.option.setNumber("Mesh.MshFileVersion", version)
        gmsh.option.setNumber("Mesh.Binary", int(binary))
        path = tmp_path / f"box_{version}_{int(binary)}.msh"
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


@pytest.mark.parametrize(
    ("version", "binary", "save_all"),
    [
        (4.1, False, True),
        (4.1, True, True),
        (4.0, False, True),
        (2.2, False, False),
        (2.2, True, False),
    ],
    ids=[
        "v4.1-ascii-partial-tags",
        "v4.1-binary-partial-tags",
        "v4.0-ascii-partial-tags",
        "v2-ascii",
        "v2-binary",
    ],
)
def test_gmsh_files_written_by_gmsh(
    version: float, binary: bool, save_all: bool, tmp_path: Path
) -> None:
    # Gmsh 4.1 with Mesh.SaveAll = 1 writes every element, most on entities without physical
    # tags: meshio alone refuses such a file ("Incompatible cell data 'gmsh:physical'"). The
    # tags that exist are kept. (Gmsh 2 with SaveAll drops every physical tag, so the v2
    # files are written as users write them, without SaveAll: only the grouped elements.)
    # Gmsh 4.0 (ASCII only) has the same problem, and its header says "4", which meshio
    # takes for 4.1: it is read as 4.0, with a note.
    path = _gmsh_box(tmp_path, version, binary, save_all)
    if version >= 4:
        # meshio raises a ValueError, or prints and exits (4.0 read as 4.1)
        with pytest.raises((ValueError, SystemExit)):
            meshio.read(path)
    m, dropped = read_mesh(path)
    assert m.notes == (
        ["read box_4.0_0.msh as Gmsh 4.0 (its header says version 4)"] if version == 4.0 else []
    )
    [block] = m.cells
    assert block.type == "tetra"
    assert {d.type for d in dropped} <= {"vertex", "line", "triangle"}
    x = m.points[:, 0]
    # Gmsh writes the corners of the OCC box exactly, and nodes on the face x = 0 with x = 0
    # exactly (they come from meshing that face): exact comparisons.
    np.testing.assert_array_equal(m.point_sets["left"], np.flatnonzero(x == 0.0))
    np.testing.assert_array_equal(m.point_sets["77"], np.flatnonzero(x == 1.0))
    np.testing.assert_array_equal(m.cell_sets_kept["body"], np.arange(len(block.data)))
    np.testing.assert_array_equal(m.point_sets["body"], np.unique(block.data))
    for name, plane in (("left", 0.0), ("77", 1.0)):
        [(kind, tris)] = m.facet_sets[name]
        assert kind == "triangle"
        assert (x[tris] == plane).all()
        assert len(np.unique(tris)) == len(m.point_sets[name])
    g = import_mesh(path).gmap
    counts = g.cell_counts()
    assert counts["volumes"] == len(block.data)
    assert counts["components"] == 1
    # The boundary of the map's volumes covers the faces x = 0 and x = 1 with exactly the
    # triangles Gmsh wrote for them.
    assert counts["boundary"] == independent_counts([("tetra", block.data)])["boundary"]


GMSH41_PARTIAL = """$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
1
3 1 "body"
$EndPhysicalNames
$Entities
0 0 1 1
1 0 0 0 1 1 1 0 0
1 0 0 0 1 1 1 1 1 1 1
$EndEntities
$Nodes
1 5 1 5
3 1 0 5
1
2
3
4
5
0 0 0
1 0 0
0 1 0
0 0 1
1 1 1
$EndNodes
$Elements
2 3 1 3
2 1 2 1
3 1 3 2
3 1 4 2
1 1 2 3 4
2 2 3 4 5
$EndElements
"""


def test_gmsh41_written_by_hand_with_an_untagged_surface(tmp_path: Path) -> None:
    # The same case without the gmsh package: the surface entity has no physical tag, the
    # volume has "body".
    path = tmp_path / "partial.msh"
    path.write_text(GMSH41_PARTIAL)
    m, dropped = read_mesh(path)
    assert rows(m.cells) == [("tetra", tuple(c)) for c in TWO_TETS.tolist()]
    assert dropped == [("triangle", 1, 2)]
    assert set(m.point_sets) == {"body"}
    np.testing.assert_array_equal(m.cell_sets_kept["body"], [0, 1])
    assert m.facet_sets == {}
    # An entity in two physical groups (meshio keeps only the first tag): both are kept.
    path.write_text(GMSH41_PARTIAL.replace("1 0 0 0 1 1 1 1 1 1 1", "1 0 0 0 1 1 1 2 1 5 1 1"))
    m, _ = read_mesh(path)
    assert set(m.cell_sets_kept) == {"body", "5"}
    np.testing.assert_array_equal(m.cell_sets_kept["5"], [0, 1])


# ------------------------------------------------------------------------- second order


def _tetra10(tets: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """tetra10 cells (VTK order: corners, then the midpoints of edges 01 12 02 03 13 23)
    from linear ones; shared edges share their midside node."""
    mid: dict[tuple[int, int], int] = {}
    pts = list(points)
    out = []
    for t in tets:
        row = list(t)
        for a, b in ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)):
            key = tuple(sorted((int(t[a]), int(t[b]))))
            if key not in mid:
                mid[key] = len(pts)
                pts.append((points[key[0]] + points[key[1]]) / 2)
            row.append(mid[key])
        out.append(row)
    return np.array(pts), np.array(out)


def test_second_order_cells_are_refused_naming_the_option_then_kept_linear(tmp_path: Path) -> None:
    # tetra10 in a VTU: refused by default, the message saying they are second order and
    # naming linear=True; with it, the corners are the original tetrahedra and the 9 midside
    # nodes become unused points the map leaves out.
    pts, cells = _tetra10(TWO_TETS, TWO_TETS_POINTS)
    path = tmp_path / "quadratic.vtu"
    meshio.write(path, meshio.Mesh(pts, [("tetra10", cells)]))
    with pytest.raises(
        topomech.MeshError, match=r"second-order cells: 2 tetra10 \(cells 0-1\)"
    ) as e:
        read_mesh(path)
    assert "pass linear=True" in str(e.value)
    assert getattr(e.value, "option", None) == ("linear", "true")
    m, _ = read_mesh(path, linear=True)
    assert rows(m.cells) == [("tetra", tuple(c)) for c in TWO_TETS.tolist()]
    assert "kept the corner nodes of 2 tetra10 second-order cell(s)" in m.notes[0]
    assert "9 other node(s)" in m.notes[0]
    imported = import_mesh(path, linear=True)
    assert imported.gmap.report.unused_points == list(range(5, 14))
    assert any("9 point(s) used by no cell left out" in n for n in imported.notes)


def test_second_order_2d_gmsh(tmp_path: Path) -> None:
    # triangle6 with line3 boundary edges in a Gmsh 2 file: the lines become linear facets too.
    points = np.array([[0, 0], [1, 0], [0, 1], [0.5, 0], [0.5, 0.5], [0, 0.5]], dtype=float)
    path = tmp_path / "tri6.msh"
    meshio.write(
        path,
        meshio.Mesh(
            np.column_stack([points, np.zeros(6)]),
            [("line3", np.array([[0, 1, 3]])), ("triangle6", np.array([[0, 1, 2, 3, 4, 5]]))],
            cell_data={
                "gmsh:physical": [np.array([4]), np.array([1])],
                "gmsh:geometrical": [np.array([1]), np.array([1])],
            },
        ),
        file_format="gmsh22",
        binary=False,
    )
    with pytest.raises(topomech.MeshError, match=r"1 triangle6 \(cell 0\)"):
        read_mesh(path)
    m, dropped = read_mesh(path, linear=True)
    assert rows(m.cells) == [("triangle", (0, 1, 2))]
    assert dropped == [("line", 1, 1)]
    assert [(k, a.tolist()) for k, a in m.facet_sets["4"]] == [("line", [[0, 1]])]


CORNERS = {
    "hexahedron": np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    ),
    "wedge": np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]]),
    "pyramid": np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]]),
    "quad": np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]),
}


@pytest.mark.parametrize(
    ("cell_type", "n_nodes"),
    [
        ("hexahedron20", 20),
        ("hexahedron27", 27),
        # (meshio 5.3 cannot hold wedge15 or pyramid13/14 cells at all: no file gives them)
        ("wedge18", 18),
        ("quad8", 8),
        ("quad9", 9),
    ],
)
def test_every_second_order_kind_keeps_its_corners(
    cell_type: str, n_nodes: int, tmp_path: Path
) -> None:
    # One cell of each kind in a VTU (meshio's VTK cell numbers): its corners are the first
    # nodes (VTK's order), the others are left out as unused points.
    kind = linear_type(cell_type)
    assert kind is not None
    corners = CORNERS[kind].astype(float)
    extra = np.random.default_rng(0).random((n_nodes - len(corners), 3)) * 0.5 + 0.25
    if kind == "quad":
        extra[:, 2] = 0.0
    path = tmp_path / f"{cell_type}.vtu"
    cell = np.arange(n_nodes).reshape(1, -1)
    meshio.write(path, meshio.Mesh(np.vstack([corners, extra]), [(cell_type, cell)]))
    with pytest.raises(topomech.MeshError, match=rf"1 {cell_type} \(cell 0\)"):
        read_mesh(path)
    m = import_mesh(path, linear=True)
    assert m.mesh is not None
    assert rows(m.mesh.cells) == [(kind, tuple(range(len(corners))))]
    assert m.gmap.report.unused_points == list(range(len(corners), n_nodes))


def test_linear_type_names() -> None:
    assert linear_type("tetra10") == "tetra"
    assert linear_type("hexahedron27") == "hexahedron"
    assert linear_type("wedge15") == "wedge"
    assert linear_type("pyramid13") == "pyramid"
    assert linear_type("quad9") == "quad"
    assert linear_type("line3") == "line"
    assert linear_type("VTK_LAGRANGE_TETRAHEDRON") == "tetra"
    for linear in ("tetra", "triangle", "polygon5", "polygon", "vertex", "quad"):
        assert linear_type(linear) is None


# ------------------------------------------------------------------------- options, per front end


@pytest.fixture
def inverted(tmp_path: Path) -> Path:
    path = tmp_path / "inverted.vtu"
    meshio.write(path, meshio.Mesh(TWO_TETS_POINTS[:4], [("tetra", np.array([[0, 2, 1, 3]]))]))
    return path


@pytest.fixture
def quadratic(tmp_path: Path) -> Path:
    pts, cells = _tetra10(TWO_TETS, TWO_TETS_POINTS)
    path = tmp_path / "quadratic.vtu"
    meshio.write(path, meshio.Mesh(pts, [("tetra10", cells)]))
    return path


def test_python_defaults_reorient_and_refuses_when_asked(inverted: Path) -> None:
    g, _ = read_gmap(inverted)
    assert g.report.reoriented == [0]
    with pytest.raises(topomech.MeshError, match="inverted") as e:
        read_gmap(inverted, reorient=False)
    assert "cell 0" in str(e.value)
    assert "reorient=True" in str(e.value)


def test_cli_options_on_info_and_apply(inverted: Path, quadratic: Path, tmp_path: Path) -> None:
    # Every command that reads a mesh takes the import options, and its messages name them as
    # CLI flags, never as Python keywords.
    r = run("info", str(quadratic))
    assert r.returncode == 2
    assert "--linear" in r.stderr
    assert "linear=True" not in r.stderr
    r = run("info", str(quadratic), "--linear", "--json")
    assert r.returncode == 0, r.stderr
    assert "note: kept the corner nodes of 2 tetra10 second-order cell(s) (--linear)" in r.stderr
    assert json.loads(r.stdout)["volumes"] == 2
    out = tmp_path / "out.vtu"
    r = run(
        "apply",
        str(inverted),
        "@library",
        "nothing",
        "--everywhere",
        "--out",
        str(out),
        "--no-reorient",
    )
    assert r.returncode == 2
    assert "--reorient" in r.stderr
    assert "reorient=True" not in r.stderr
    r = run(
        "apply",
        str(quadratic),
        "@library",
        "nothing",
        "--everywhere",
        "--out",
        str(out),
        "--pinched",
        "split",
        "--duplicates",
        "merge",
    )
    assert "--linear" in r.stderr  # refused for its second-order cells, named as a flag
    r = run("info", str(inverted), "--pinched", "sideways")
    assert r.returncode == 2
    assert "invalid choice: 'sideways'" in r.stderr


SCENE = """
[mesh]
file = "{file}"
{extra}

[[model]]
kind = "corotational"
young = 1e5
poisson = 0.3

[integrator]
kind = "symplectic_euler"
dt = 1e-4
steps = 1
"""


def _scene(tmp_path: Path, mesh: Path, extra: str) -> Path:
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.format(file=mesh.name, extra=extra))
    return path


def test_scene_mesh_options(inverted: Path, quadratic: Path, tmp_path: Path) -> None:
    # mesh.reorient (default true), mesh.order, mesh.pinched, mesh.duplicates: validated,
    # passed on, and a refusal names the scene key that would accept the mesh.
    sc = load_scene(_scene(tmp_path, inverted, ""))
    assert sc.mesh.reorient is True
    assert sc.load_gmap().report.reoriented == [0]
    sc = load_scene(_scene(tmp_path, inverted, "reorient = false"))
    with pytest.raises(topomech.SceneError, match=r"mesh.reorient: .*mesh.reorient = true"):
        sc.load_gmap()
    sc = load_scene(_scene(tmp_path, quadratic, ""))
    with pytest.raises(topomech.SceneError, match=r'mesh.order: .*mesh.order = "linear"') as e:
        sc.load_gmap()
    assert "linear=True" not in str(e.value)
    sc = load_scene(_scene(tmp_path, quadratic, 'pinched = "split"\nduplicates = "merge"'))
    assert (sc.mesh.order, sc.mesh.pinched, sc.mesh.duplicates) == ("as-is", "split", "merge")
    sc = load_scene(_scene(tmp_path, quadratic, 'order = "linear"'))
    assert (sc.mesh.order, sc.mesh.pinched, sc.mesh.duplicates) == ("linear", "merge", "refuse")
    assert sc.load_gmap().cell_counts()["volumes"] == 2
    for extra, key in (
        ('order = "quadratic"', "mesh.order"),
        ('pinched = "weld"', "mesh.pinched"),
        ('duplicates = "keep"', "mesh.duplicates"),
        ("reorient = 1", "mesh.reorient"),
    ):
        with pytest.raises(topomech.SceneError, match=rf"{key}: "):
            load_scene(_scene(tmp_path, quadratic, extra))
    text = '[mesh]\ngenerator = "box"\norder = "linear"\n[[model]]\nkind = "corotational"\n'
    # load_mesh gives the mesh read with its sets (for loads and selections), None for a
    # generated mesh.
    gmsh1 = tmp_path / "old.msh"
    gmsh1.write_text(GMSH1)
    imported = load_scene(_scene(tmp_path, gmsh1, "")).load_mesh()
    assert imported.mesh is not None
    np.testing.assert_array_equal(imported.mesh.point_sets["5"], [0, 1, 2])
    assert any("Gmsh 1" in n for n in imported.notes)
    generated = parse_scene(text.replace('order = "linear"\n', "")).load_mesh()
    assert generated.mesh is None
    assert generated.gmap.cell_counts()["volumes"] > 0
    with pytest.raises(topomech.SceneError, match=r"mesh.order: only for a mesh file"):
        parse_scene(text)


# ------------------------------------------------------------------------- pinched, duplicates

_KERNEL_OPTIONS = {"pinched", "duplicates"} <= set(
    inspect.signature(topomech.GMap.from_mesh).parameters
)
needs_kernel_options = pytest.mark.skipif(
    not _KERNEL_OPTIONS, reason="the kernel build has no pinched/duplicates options yet (H1)"
)


def _gmsh2_duplicated_element(tmp_path: Path) -> Path:
    """What Gmsh 2 writes for an element in two physical groups: the element twice, once per
    group (here the second tetrahedron, in groups 1 and 2)."""
    path = tmp_path / "twice.msh"
    path.write_text(
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n5\n"
        "1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n$EndNodes\n$Elements\n3\n"
        "1 4 2 1 1 1 2 3 4\n2 4 2 1 1 2 3 4 5\n3 4 2 2 1 2 3 4 5\n$EndElements\n"
    )
    return path


def _pinched(tmp_path: Path) -> Path:
    """Two tetrahedra touching only at point 0."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]])
    path = tmp_path / "pinched.vtu"
    meshio.write(
        path, meshio.Mesh(pts.astype(float), [("tetra", np.array([[0, 1, 2, 3], [0, 4, 6, 5]]))])
    )
    return path


def test_duplicated_gmsh2_element_groups_point_at_both_copies(tmp_path: Path) -> None:
    # Both copies are kept cells (cell 1 in group "1", cell 2 in group "2"): the sets index
    # the cells as given, whatever the duplicates option later makes of them.
    m, _ = read_mesh(_gmsh2_duplicated_element(tmp_path))
    np.testing.assert_array_equal(m.cell_sets_kept["1"], [0, 1])
    np.testing.assert_array_equal(m.cell_sets_kept["2"], [2])


@needs_kernel_options
def test_duplicates_option_in_each_front_end(tmp_path: Path) -> None:
    path = _gmsh2_duplicated_element(tmp_path)
    with pytest.raises(topomech.MeshError, match='duplicates="merge"'):
        import_mesh(path)
    m = import_mesh(path, duplicates="merge")
    assert m.gmap.cell_counts()["volumes"] == 2
    assert any("merged 1 duplicate cell" in n for n in m.notes)
    r = run("info", str(path))
    assert r.returncode == 2
    assert "--duplicates merge" in r.stderr
    assert 'duplicates="merge"' not in r.stderr
    r = run("info", str(path), "--duplicates", "merge", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["merged_duplicates"] == [[2, 1]]
    sc = load_scene(_scene(tmp_path, path, ""))
    with pytest.raises(topomech.SceneError, match=r'mesh.duplicates: .*mesh.duplicates = "merge"'):
        sc.load_gmap()


@needs_kernel_options
def test_pinched_option_in_each_front_end(tmp_path: Path) -> None:
    path = _pinched(tmp_path)
    m = import_mesh(path)
    assert m.gmap.report.pinched == [0]
    assert any("1 pinched point(s)" in n and "one particle" in n for n in m.notes)
    m = import_mesh(path, pinched="split")
    assert any("split into one vertex per side" in n for n in m.notes)
    r = run("info", str(path), "--pinched", "refuse")
    assert r.returncode == 2
    assert "--pinched" in r.stderr
    assert "pinched=" not in r.stderr
    sc = load_scene(_scene(tmp_path, path, 'pinched = "refuse"'))
    with pytest.raises(topomech.SceneError, match=r"mesh.pinched: .*mesh.pinched = "):
        sc.load_gmap()


def test_build_notes_wording() -> None:
    # The notes from a build report, for every field the kernel reports (the fields H1 adds
    # are read with getattr, so a report without them gives no note about them).
    from types import SimpleNamespace

    from topomech.io import build_notes

    report = SimpleNamespace(
        reoriented=list(range(25)),
        unused_points=[7],
        pinched=[3, 9],
        merged_duplicates=[(5, 2)],
        non_orientable=True,
    )
    g = SimpleNamespace(report=report)
    notes = build_notes(g, "split")  # type: ignore[arg-type]
    assert notes[0].startswith("reoriented 25 cell(s)")
    assert notes[0].endswith("19 and 5 more")
    assert "not orientable" in notes[1]
    assert notes[2] == (
        "2 pinched point(s) (the cells around each meet only there, or along an edge through "
        "it), split into one vertex per side: 3, 9"
    )
    assert notes[3] == "merged 1 duplicate cell(s), dropped: 5 (= 2)"
    assert notes[4].startswith("1 point(s) used by no cell left out: 7")
    assert (
        build_notes(SimpleNamespace(report=SimpleNamespace(reoriented=[], unused_points=[]))) == []
    )  # type: ignore[arg-type]
