"""Import options given the wrong way are named, and GMap.from_meshio takes ``linear`` like
read_mesh (issue 12's leftovers: ``reorient="no"`` used to raise an unnamed TypeError from the
binding, "'str' object is not an instance of 'bool'", and from_meshio had no way to keep the
corner nodes of a second-order mesh)."""

from __future__ import annotations

import warnings
from pathlib import Path

import meshio
import numpy as np
import pytest

import topomech
from topomech import GMap, MeshError

POINTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
MID = np.array([[0.5, 0, 0], [0.5, 0.5, 0], [0, 0.5, 0], [0, 0, 0.5], [0.5, 0, 0.5], [0, 0.5, 0.5]])


def tet10() -> meshio.Mesh:
    """One second-order tetrahedron (VTK order: corners, then the mid-edge nodes 01, 12, 20,
    03, 13, 23) with one second-order boundary triangle."""
    return meshio.Mesh(
        np.vstack([POINTS, MID]),
        [
            ("tetra10", np.array([[0, 1, 2, 3, 4, 5, 6, 7, 8, 9]])),
            ("triangle6", np.array([[0, 1, 2, 4, 5, 6]])),
        ],
    )


@pytest.mark.parametrize("value", ["no", "false", 0.5, None])
def test_a_reorient_that_is_not_a_bool_is_named(tmp_path: Path, value: object) -> None:
    path = tmp_path / "one.vtu"
    meshio.write(path, meshio.Mesh(POINTS, [("tetra", np.array([[0, 1, 2, 3]]))]))
    with pytest.raises(TypeError, match=r"reorient must be True or False, got"):
        topomech.read_gmap(path, reorient=value)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"reorient must be True or False"):
        GMap.from_mesh(POINTS, [("tetra", np.array([[0, 1, 2, 3]]))], value)  # type: ignore[arg-type]


def test_from_meshio_refuses_second_order_cells_naming_linear() -> None:
    with (
        pytest.warns(UserWarning, match="dropped 1 triangle6"),
        pytest.raises(MeshError, match=r"1 tetra10 \(cell 0\).*linear=True"),
    ):
        GMap.from_meshio(tet10())


def test_from_meshio_linear_keeps_the_corner_nodes() -> None:
    """The map of the corners: one tetrahedron (24 darts, 4 vertices) whose positions are the
    four corner points, the mid-edge nodes used by no cell."""
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        g = GMap.from_meshio(tet10(), linear=True)
    said = [str(w.message) for w in record]
    assert any("dropped 1 triangle6" in m for m in said), said
    assert any("kept the corner nodes of 1 tetra10" in m for m in said), said
    counts = g.cell_counts()
    assert (counts["darts"], counts["vertices"], counts["volumes"]) == (24, 4, 1)
    x = g.positions()
    assert sorted(map(tuple, np.round(x, 12))) == sorted(map(tuple, POINTS))


def test_a_saved_map_that_is_not_one_is_refused_naming_the_file(tmp_path: Path) -> None:
    """`GMap.load` and `topomech info` on bytes that are no .tmg file name the file (before:
    'not a topomech G-map file (bad magic header)' with no path)."""
    from topomech import FileFormatError, cli

    bad = tmp_path / "bad.tmg"
    bad.write_bytes(b"xx")
    with pytest.raises(FileFormatError, match=rf"^{bad}: not a topomech G-map file"):
        GMap.load(bad)
    assert cli.main(["info", str(bad)]) == 2
