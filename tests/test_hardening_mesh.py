"""Issue 13, mesh import: an overflow is called an overflow, not a degenerate cell.

Before: a tetrahedron at coordinates 1e200 was *accepted* (its volume, ~1.7e599, is inf and
the checks compared NaN), and one of extent 1e-110 was refused as "degenerate (zero volume)"
(its squared edge length underflowed to 0). Now both are refused by name, with the cell, the
word overflow or underflow and the coordinate magnitude; `topomech info` on a file says the
same as the reader. Identical cells and two tetrahedra on the same side of their shared face
are refused (they already were; kept here under the issue's names).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

from topomech import GMap, MeshError


def _tet(scale: float) -> np.ndarray:
    return np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64) * scale


CELL = [("tetra", np.array([[0, 1, 2, 3]]))]


def test_overflowing_cell_is_refused_as_an_overflow() -> None:
    with pytest.raises(MeshError) as e:
        GMap.from_mesh(_tet(1e200), CELL)
    msg = str(e.value)
    assert "cell 0 (tetra): its volume overflows f64" in msg, msg
    assert "coordinates up to 1.000e200" in msg, msg
    assert "degenerate" not in msg


def test_underflowing_cell_is_refused_as_an_underflow_not_degenerate() -> None:
    with pytest.raises(MeshError) as e:
        GMap.from_mesh(_tet(1e-110), CELL)
    msg = str(e.value)
    assert "cell 0 (tetra): its volume underflows f64" in msg, msg
    assert "degenerate" not in msg


def test_representable_extremes_are_accepted() -> None:
    # volume 1.7e299 and 1.7e-28 (nanometre cells): both finite, normal f64 numbers
    for s in (1e100, 1e-9):
        g = GMap.from_mesh(_tet(s), CELL)
        assert g.is_valid()
        assert np.allclose(g.positions().max(), s, rtol=0, atol=s * 1e-15)


def test_info_names_the_overflow_as_the_reader_does(tmp_path: Path) -> None:
    path = tmp_path / "huge.vtu"
    meshio.write(path, meshio.Mesh(_tet(1e200), CELL))
    with pytest.raises(MeshError) as e:
        GMap.from_meshio(meshio.read(path))
    r = subprocess.run(
        [sys.executable, "-m", "topomech", "info", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode != 0
    assert "its volume overflows f64" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
    assert "its volume overflows f64" in str(e.value)


def test_identical_cells_are_refused() -> None:
    cells = [("tetra", np.array([[0, 1, 2, 3], [1, 2, 0, 3]]))]
    with pytest.raises(MeshError, match="cell 1 duplicates cell 0"):
        GMap.from_mesh(_tet(1.0), cells)


def test_two_tets_on_the_same_side_of_a_shared_face_are_refused() -> None:
    points = np.vstack([_tet(1.0), [[0.2, 0.2, 0.5]]])
    cells = [("tetra", np.array([[0, 1, 2, 3], [0, 2, 1, 4]]))]
    with pytest.raises(MeshError, match=r"folded pair.*cells 0 and 1"):
        GMap.from_mesh(points, cells)


def test_volume_cells_of_points_in_a_plane_are_refused_as_such() -> None:
    """Points with 2 coordinates and tetrahedra: every cell would be flat. The refusal says
    the cells need 3D points (QA: it listed the cells as degenerate, of zero volume)."""
    pts = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=float)
    with pytest.raises(MeshError, match=r"tetra cells need points with 3 coordinates"):
        GMap.from_mesh(pts, {"tetra": np.array([[0, 1, 2, 3]])})
    # a surface of 2D points is fine
    assert GMap.from_mesh(pts[:3], {"triangle": np.array([[0, 1, 2]])}).dimension == 2
