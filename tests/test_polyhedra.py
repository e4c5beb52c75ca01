"""Writing volume maps whose volumes a rewrite made general polyhedra (``split_edge``) to a
VTU file as VTK polyhedra (cell type 42), the one mesh format that holds them.

What is checked, against geometry computed here from the file meshio reads back: the file's
points are the map's vertex rows; it has one polyhedron per volume; the faces of each
polyhedron enclose a positive volume (normals out by the right-hand rule, VTK's convention) and
the volumes add up to the box's (to 1e-12 relative: a few thousand products of order-one
coordinates, each rounded once); each face inside the box is listed twice, once by each of its
polyhedra, running opposite ways (consistent orientation), and each boundary face once.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import meshio
import numpy as np
import numpy.typing as npt
import pytest

import topomech
from topomech import GMap, RuleSet
from topomech.io import import_mesh, write_gmap


def box_of_tets(size: tuple[float, float, float] = (2.0, 1.0, 1.5)) -> GMap:
    """A 2 x 2 x 1 box of 6-tet cubes, sheared by a linear map of determinant 1 (the faces
    stay planar; the volume stays the box's)."""
    nx, ny, nz = 2, 2, 1
    pts = np.array(
        [
            [i * size[0] / nx, j * size[1] / ny, k * size[2] / nz]
            for k in range(nz + 1)
            for j in range(ny + 1)
            for i in range(nx + 1)
        ]
    )
    pts[:, 0] += 0.1 * pts[:, 1] + 0.05 * pts[:, 2]

    def v(i: int, j: int, k: int) -> int:
        return (k * (ny + 1) + j) * (nx + 1) + i

    tets = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                c = [v(i + a, j + b, k + e) for e in (0, 1) for b in (0, 1) for a in (0, 1)]
                # six tetrahedra around the diagonal c0 - c7
                for p, q in ((1, 3), (3, 2), (2, 6), (6, 4), (4, 5), (5, 1)):
                    tets.append([c[0], c[p], c[q], c[7]])
    return GMap.from_mesh(pts, [("tetra", np.array(tets))])


def face_volume6(points: npt.NDArray[np.float64], faces: list[npt.NDArray[np.int64]]) -> float:
    """Six times the volume the faces enclose, each fanned from its first point to the
    polyhedron's first point (divergence theorem)."""
    o = points[faces[0][0]]
    v = 0.0
    for f in faces:
        a = points[f[0]] - o
        for k in range(1, len(f) - 1):
            v += float(np.dot(a, np.cross(points[f[k]] - o, points[f[k + 1]] - o)))
    return v


def canonical(cycle: list[int]) -> tuple[int, ...]:
    """The cycle started at its smallest point (same direction)."""
    k = cycle.index(min(cycle))
    return tuple(cycle[k:] + cycle[:k])


def split(g: GMap, times: int) -> GMap:
    rules = RuleSet.library(3)
    for k in range(times):
        rules.apply(g, "split_edge", at=7 * k)
    return g


@pytest.mark.parametrize("times", [1, 5])
def test_general_polyhedra_are_written_to_vtu_with_outward_faces(
    tmp_path: Path, times: int
) -> None:
    g = split(box_of_tets(), times)
    assert g.is_valid()
    with pytest.raises(topomech.MeshError, match="not a tetra"):
        g.to_meshio()
    path = tmp_path / "poly.vtu"
    write_gmap(g, path)
    m = meshio.read(path)
    np.testing.assert_array_equal(m.points, g.positions())
    cells = [cell for block in m.cells for cell in block.data]
    assert all(b.type.startswith("polyhedron") for b in m.cells)
    assert len(cells) == g.cell_counts()["volumes"] == 24
    total = 0.0
    by_key: dict[tuple[int, ...], list[tuple[int, ...]]] = defaultdict(list)
    for cell in cells:
        v6 = face_volume6(m.points, cell)
        assert v6 > 0.0
        total += v6 / 6.0
        for f in cell:
            by_key[tuple(sorted(int(x) for x in f))].append(canonical([int(x) for x in f]))
    assert total == pytest.approx(2.0 * 1.0 * 1.5, rel=1e-12)
    boundary = 0
    for key, cycles in by_key.items():
        assert len(cycles) in (1, 2), key
        if len(cycles) == 2:
            a, b = cycles
            assert canonical(list(reversed(a))) == b, (a, b)
        else:
            boundary += 1
    # the box's boundary: 2 triangles per square, 2 x (2x2 + 2x1 + 2x1) squares
    assert boundary == 2 * 2 * (4 + 2 + 2)


def test_a_map_of_polyhedra_is_refused_by_other_formats_and_not_read_back(
    tmp_path: Path,
) -> None:
    """Other mesh formats cannot hold general polyhedra: refused naming the volume, nothing
    written, the message pointing to .vtu and .tmg. A VTU of polyhedra is for viewing:
    reading it into a map is refused, naming the cell type."""
    g = split(box_of_tets(), 1)
    for name in ("poly.msh", "poly.vtk"):
        with pytest.raises(topomech.MeshError, match=r"write the map as a \.vtu or a \.tmg"):
            write_gmap(g, tmp_path / name)
        assert not (tmp_path / name).exists()
    path = tmp_path / "poly.vtu"
    write_gmap(g, path)
    with pytest.raises(topomech.MeshError, match=r"is a polyhedron\d+, a general polyhedron"):
        import_mesh(path)


def test_standard_cells_stay_cells_of_their_kind(tmp_path: Path) -> None:
    """A map of tetrahedra only is written as tetrahedra, not as polyhedra (the fallback is
    for maps with a general polyhedron only)."""
    g = box_of_tets()
    path = tmp_path / "tets.vtu"
    write_gmap(g, path)
    assert [b.type for b in meshio.read(path).cells] == ["tetra"]


def test_mixed_kinds_to_gmsh_and_a_writer_missing_its_package_say_why(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two cell kinds to .msh: meshio's Gmsh writers take one kind per file (its own message
    asked for entity tags the map does not have: QA). A writer needing a package that is
    not installed (XDMF's h5py) names the package instead of calling it a format's limit.
    Nothing is left written either way."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], dtype=float)
    g = GMap.from_mesh(
        pts, [("quad", np.array([[0, 1, 2, 3]])), ("triangle", np.array([[1, 4, 2]]))]
    )
    with pytest.raises(
        ValueError,
        match="meshio writes one cell kind per Gmsh file, and the map has quad, triangle",
    ):
        write_gmap(g, tmp_path / "mixed.msh")
    assert not (tmp_path / "mixed.msh").exists()

    def needs_h5py(*a: object, **k: object) -> None:
        raise ModuleNotFoundError("No module named 'h5py'", name="h5py")

    monkeypatch.setattr(meshio, "write", needs_h5py)
    with pytest.raises(
        ValueError, match=r"meshio's xdmf writer needs the Python package 'h5py'.*pip install h5py"
    ):
        write_gmap(g, tmp_path / "m.xdmf")
    assert not (tmp_path / "m.xdmf").exists()
