"""The .tmg format through Python, and mesh files through meshio."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import meshio
import numpy as np
import pytest

import topomech
from topomech import _core
from topomech.io import read_gmap, read_mesh, write_vtu

from conftest import independent_counts


@pytest.mark.parametrize("name", ["mixed_surface", "two_tets", "mixed_volume"])
def test_save_load_round_trip(name: str, request: pytest.FixtureRequest, tmp_path: Path) -> None:
    g = topomech.GMap.from_mesh(*request.getfixturevalue(name))
    path = tmp_path / "map.tmg"
    g.save(path)
    h = topomech.GMap.load(path)
    assert h.cell_counts() == g.cell_counts()
    np.testing.assert_array_equal(h.positions(), g.positions())
    np.testing.assert_array_equal(h.vertex_labels(), g.vertex_labels())
    assert h.embedding_names() == g.embedding_names()
    assert h.is_valid()
    # bytes and str paths too
    assert topomech.GMap.from_bytes(g.to_bytes()).cell_counts() == g.cell_counts()
    assert topomech.GMap.load(str(path)).n_darts == g.n_darts


def test_load_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"missing\.tmg"):
        topomech.GMap.load(tmp_path / "missing.tmg")
    junk = tmp_path / "junk.tmg"
    junk.write_bytes(b"this is not a map at all")
    with pytest.raises(topomech.FileFormatError, match="magic"):
        topomech.GMap.load(junk)


def test_every_truncation_is_a_format_error(two_tets: tuple) -> None:
    data = topomech.GMap.from_mesh(*two_tets).to_bytes()
    for k in range(0, len(data), max(1, len(data) // 200)):
        with pytest.raises(topomech.FileFormatError):
            topomech.GMap.from_bytes(data[:k])


def test_corrupted_bytes_never_crash(two_tets: tuple) -> None:
    data = bytearray(topomech.GMap.from_mesh(*two_tets).to_bytes())
    rng = np.random.default_rng(7)
    for _ in range(300):
        b = bytearray(data)
        for pos in rng.integers(0, len(b), size=3):
            b[pos] = int(rng.integers(0, 256))
        try:
            g = topomech.GMap.from_bytes(bytes(b))
        except topomech.FileFormatError:
            continue
        g.cell_counts()
        g.is_valid()


# ---------------------------------------------------------------------------- mesh files

VOLUME_FORMATS = [
    ("gmsh22-ascii.msh", {"file_format": "gmsh22", "binary": False}),
    ("gmsh41-ascii.msh", {"file_format": "gmsh", "binary": False}),
    ("gmsh41-binary.msh", {"file_format": "gmsh", "binary": True}),
    ("gmsh22-binary.msh", {"file_format": "gmsh22", "binary": True}),
    ("mesh.vtu", {}),
    ("mesh.vtk", {}),
]


def tet_box() -> tuple[np.ndarray, list[tuple[str, np.ndarray]]]:
    points, _kinds, _offsets, conn = _core.box(2, 2, 2, 1.0, 1.0, 1.0, "tetra")
    return points, [("tetra", conn.reshape(-1, 4))]


@pytest.mark.parametrize(("name", "kwargs"), VOLUME_FORMATS)
def test_read_volume_files(name: str, kwargs: dict, tmp_path: Path) -> None:
    points, cells = tet_box()
    path = tmp_path / name
    meshio.write(path, meshio.Mesh(points, cells), **kwargs)
    mesh, dropped = read_mesh(path)
    assert dropped == []
    g = topomech.GMap.from_meshio(mesh)
    assert g.cell_counts() == independent_counts(cells)


@pytest.mark.parametrize("name", ["surface.obj", "surface.vtu", "surface.vtk", "surface.msh"])
def test_read_surface_files(name: str, tmp_path: Path, mixed_surface: tuple) -> None:
    points, cells = mixed_surface
    g = topomech.GMap.from_mesh(points, cells)
    path = tmp_path / name
    meshio.write(path, g.to_meshio())
    h, dropped = read_gmap(path)
    assert dropped == []
    assert h.cell_counts() == independent_counts(cells)


def test_lower_dimensional_blocks_are_dropped_and_listed(tmp_path: Path) -> None:
    points, cells = tet_box()
    g = topomech.GMap.from_mesh(points, cells)
    boundary = boundary_triangles(cells[0][1])
    path = tmp_path / "with-boundary.msh"
    mesh = meshio.Mesh(
        points,
        [("triangle", boundary), ("tetra", cells[0][1]), ("line", np.array([[0, 1], [1, 2]]))],
    )
    meshio.write(path, mesh, file_format="gmsh22", binary=False)
    kept, dropped = read_mesh(path)
    assert [b.type for b in kept.cells] == ["tetra"]
    assert {(d.type, d.n_cells, d.dimension) for d in dropped} == {
        ("triangle", len(boundary), 2),
        ("line", 2, 1),
    }
    assert topomech.GMap.from_meshio(kept).cell_counts() == g.cell_counts()
    # from_meshio drops them too, and warns
    with pytest.warns(UserWarning, match=r"dropped 48 triangle cells \(2D\), 2 line cells \(1D\)"):
        assert topomech.GMap.from_meshio(mesh).cell_counts() == g.cell_counts()


def boundary_triangles(tets: np.ndarray) -> np.ndarray:
    """The faces used by exactly one tetrahedron."""
    faces = [
        [int(t[i]) for i in f] for t in tets for f in ((0, 1, 2), (0, 1, 3), (1, 2, 3), (0, 2, 3))
    ]
    uses = Counter(tuple(sorted(f)) for f in faces)
    return np.array([f for f in faces if uses[tuple(sorted(f))] == 1])


def test_write_vtu_round_trip(tmp_path: Path, mixed_volume: tuple) -> None:
    g = topomech.GMap.from_mesh(*mixed_volume)
    path = tmp_path / "out.vtu"
    write_vtu(g, path)
    h, _ = read_gmap(path)
    assert h.cell_counts() == g.cell_counts()


def test_read_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"No such file or directory: .*nothing\.msh"):
        read_mesh(tmp_path / "nothing.msh")
    with pytest.raises(topomech.MeshReadError, match="is a directory"):
        read_mesh(tmp_path)
    garbage = tmp_path / "garbage.msh"
    garbage.write_text("hello\nthis is not a mesh\n")
    with pytest.raises(
        topomech.MeshReadError, match=r"garbage\.msh: cannot read this file as a mesh \(as gmsh"
    ):
        read_mesh(garbage)
    unknown = tmp_path / "mesh.xyz123"
    unknown.write_text("1 2 3\n")
    with pytest.raises(topomech.MeshReadError, match=r"unknown mesh file extension \.xyz123"):
        read_mesh(unknown)


def test_files_without_surface_or_volume_cells(tmp_path: Path) -> None:
    path = tmp_path / "lines.vtu"
    meshio.write(path, meshio.Mesh(np.eye(3), [("line", np.array([[0, 1], [1, 2]]))]))
    with pytest.raises(topomech.MeshError, match=r"no surface or volume cells \(found 2 line\)"):
        read_mesh(path)
