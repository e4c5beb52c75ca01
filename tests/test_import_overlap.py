"""Issue 13, mesh import: cells whose interiors overlap without sharing a face are refused.

Before: two interpenetrating tetrahedra (no shared point), a tetrahedron inside a hexahedron,
or a triangle lying across a planar mesh were imported silently (their mass counted twice).
Now the reader refuses them naming both cells, with the same message from ``GMap.from_mesh``,
``read_mesh`` + ``from_meshio``, ``topomech info`` and a scene. The overlaps are built by hand
so that a point of one cell lies strictly inside the other (analytic); the negatives tile
their domain exactly, so any refusal would be a false positive.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

import topomech
from topomech import GMap, MeshError, _core
from topomech.io import read_mesh
from topomech.scene import parse_scene

UNIT_TET = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
# the second tetrahedron is the first moved by (0.2, 0.2, 0.2): its corner (0.2, 0.2, 0.2)
# lies inside the first (coordinates sum to 0.6 < 1)
TWO_TETS = np.vstack([UNIT_TET, UNIT_TET + 0.2])
TWO_CELLS = [("tetra", np.array([[0, 1, 2, 3], [4, 5, 6, 7]]))]
MESSAGE = "1 overlapping pair(s) of cells (their interiors intersect): cells 0 and 1"


def test_interpenetrating_tetrahedra_are_refused_naming_both() -> None:
    with pytest.raises(MeshError) as e:
        GMap.from_mesh(TWO_TETS, TWO_CELLS)
    assert MESSAGE in str(e.value), str(e.value)


def test_tetrahedra_sharing_a_vertex_are_refused() -> None:
    far = np.array([[1.5, 0.2, 0.2], [0.2, 1.5, 0.2], [0.2, 0.2, 1.5]])
    points = np.vstack([UNIT_TET, far])
    cells = [("tetra", np.array([[0, 1, 2, 3], [0, 4, 5, 6]]))]
    with pytest.raises(MeshError, match="cells 0 and 1"):
        GMap.from_mesh(points, cells)


def test_hexahedron_overlapping_a_tetrahedron_is_refused() -> None:
    cube = np.array(
        [[x, y, z] for z in (0.0, 1.0) for y in (0.0, 1.0) for x in (0.0, 1.0)],
        dtype=np.float64,
    )
    hexa = np.array([[0, 1, 3, 2, 4, 5, 7, 6]])  # VTK order
    points = np.vstack([cube, UNIT_TET + 0.5])
    cells = [("hexahedron", hexa), ("tetra", np.array([[8, 9, 10, 11]]))]
    with pytest.raises(MeshError, match=r"overlapping pair.*cells 0 and 1"):
        GMap.from_mesh(points, cells)


def test_triangle_across_a_planar_mesh_is_refused() -> None:
    points = np.array(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 0], [1.3, 0.3, 0], [0.3, 1.3, 0]],
        dtype=np.float64,
    )
    cells = [("triangle", np.array([[0, 1, 2], [3, 4, 5]]))]
    with pytest.raises(MeshError, match="cells 0 and 1"):
        GMap.from_mesh(points, cells)


def test_info_read_mesh_and_scene_give_the_same_message(tmp_path: Path) -> None:
    path = tmp_path / "overlap.vtu"
    meshio.write(path, meshio.Mesh(TWO_TETS, TWO_CELLS))
    mesh, _dropped = read_mesh(path)
    with pytest.raises(MeshError) as e:
        GMap.from_meshio(mesh)
    assert MESSAGE in str(e.value), str(e.value)
    r = subprocess.run(
        [sys.executable, "-m", "topomech", "info", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode != 0
    assert MESSAGE in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
    scene = """
[mesh]
file = "overlap.vtu"

[[model]]
kind = "corotational"

[integrator]
kind = "symplectic_euler"
dt = 1e-3
steps = 2
"""
    with pytest.raises((topomech.SceneError, MeshError)) as s:
        parse_scene(scene, tmp_path / "scene.toml").build()
    assert MESSAGE in str(s.value), str(s.value)


def _blocks(kinds: list[str], offsets: np.ndarray, conn: np.ndarray) -> list[tuple[str, object]]:
    """One cell block per cell, in order (so cell ids are kept)."""
    out: list[tuple[str, object]] = []
    for i, kind in enumerate(kinds):
        verts = conn[offsets[i] : offsets[i + 1]]
        out.append((kind, [verts.tolist()] if kind == "polygon" else verts.reshape(1, -1)))
    return out


@pytest.mark.parametrize("element", ["tetra", "hexahedron", "wedge", "pyramid", "mixed"])
@pytest.mark.parametrize("cells", [(1, 1, 1), (3, 2, 2), (5, 4, 3)])
def test_generator_boxes_are_accepted(element: str, cells: tuple[int, int, int]) -> None:
    points, kinds, offsets, conn = _core.box(*cells, 1.0, 2.0, 0.5, element)
    g = GMap.from_mesh(points, _blocks(kinds, offsets, conn))
    assert g.is_valid()


@pytest.mark.parametrize("element", ["triangle", "quad", "mixed"])
@pytest.mark.parametrize("cells", [(1, 1), (4, 3), (9, 5)])
def test_generator_grids_are_accepted(element: str, cells: tuple[int, int]) -> None:
    points, kinds, offsets, conn = _core.grid(*cells, 1.0, 0.7, element)
    g = GMap.from_mesh(points, _blocks(kinds, offsets, conn))
    assert g.is_valid()


@pytest.mark.parametrize("scale", [1e-90, 1e100])
def test_touching_pieces_at_extreme_scales_are_accepted(scale: float) -> None:
    # three unit tetrahedra with their own points: the second touches the first at a point
    # (its corner (1, 0, 0)), the third (the first mirrored in z = 0) along the face z = 0
    points = np.vstack(
        [UNIT_TET, UNIT_TET + np.array([1.0, 0, 0]), UNIT_TET * np.array([1.0, 1, -1])]
    )
    cells = [("tetra", np.array([[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]]))]
    g = GMap.from_mesh(points * scale, cells)
    assert g.is_valid()
