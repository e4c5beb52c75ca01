"""Property tests: generated grids and boxes of random sizes have the counts their formulas and
an independent count give, and survive a save/load and a meshio round trip."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

import topomech
from topomech import _core

from conftest import euler, flat_to_cells, independent_counts

sizes = st.integers(min_value=1, max_value=7)


@settings(max_examples=40, deadline=None)
@given(nx=sizes, ny=sizes, element=st.sampled_from(["triangle", "quad", "mixed"]))
def test_grid_counts(nx: int, ny: int, element: str) -> None:
    flat = _core.grid(nx, ny, 2.0, 1.0, element)
    g = topomech.GMap.from_flat(*flat)
    c = g.cell_counts()
    assert c == independent_counts(flat_to_cells(*flat[1:]))
    assert c["vertices"] == (nx + 1) * (ny + 1)
    assert c["boundary"] == 2 * (nx + ny)
    assert c["components"] == 1
    assert euler(c) == 1
    squares = nx * ny
    if element == "quad":
        assert (c["faces"], c["edges"], c["darts"]) == (
            squares,
            nx * (ny + 1) + ny * (nx + 1),
            8 * squares,
        )
    if element == "triangle":
        assert (c["faces"], c["edges"], c["darts"]) == (
            2 * squares,
            nx * (ny + 1) + ny * (nx + 1) + squares,
            12 * squares,
        )
    assert g.is_valid()


@settings(max_examples=25, deadline=None)
@given(
    nx=st.integers(1, 3),
    ny=st.integers(1, 3),
    nz=st.integers(1, 3),
    element=st.sampled_from(["tetra", "hexahedron", "wedge", "pyramid", "mixed"]),
)
def test_box_counts(nx: int, ny: int, nz: int, element: str) -> None:
    flat = _core.box(nx, ny, nz, 1.0, 2.0, 3.0, element)
    g = topomech.GMap.from_flat(*flat)
    c = g.cell_counts()
    assert c == independent_counts(flat_to_cells(*flat[1:]))
    assert c["components"] == 1
    assert euler(c) == 1
    cubes = nx * ny * nz
    grid_points = (nx + 1) * (ny + 1) * (nz + 1)
    expected_volumes = {
        "tetra": 6 * cubes,
        "hexahedron": cubes,
        "wedge": 2 * cubes,
        "pyramid": 6 * cubes,
    }
    if element in expected_volumes:
        assert c["volumes"] == expected_volumes[element]
    if element in ("tetra", "hexahedron", "wedge"):
        assert c["vertices"] == grid_points
    if element == "pyramid":
        assert c["vertices"] == grid_points + cubes
    # the boundary of the box: 2 (xy + yz + zx) squares, each one quad or two triangles
    squares = 2 * (nx * ny + ny * nz + nz * nx)
    if element == "hexahedron":
        assert c["boundary"] == squares
    if element == "tetra":
        assert c["boundary"] == 2 * squares
    assert g.is_valid()


@settings(max_examples=15, deadline=None)
@given(
    nx=st.integers(1, 3),
    ny=st.integers(1, 3),
    element=st.sampled_from(["tetra", "mixed", "pyramid"]),
)
def test_round_trips_keep_counts_and_positions(nx: int, ny: int, element: str) -> None:
    g = topomech.GMap.from_flat(*_core.box(nx, ny, 1, 1.0, 1.0, 1.0, element))
    h = topomech.GMap.from_bytes(g.to_bytes())
    assert h.cell_counts() == g.cell_counts()
    assert (h.positions() == g.positions()).all()
    m = topomech.GMap.from_meshio(g.to_meshio())
    assert m.cell_counts() == g.cell_counts()
