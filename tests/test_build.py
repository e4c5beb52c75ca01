"""GMap.from_mesh on small hand-made meshes of every element kind: the kernel's cell counts
against counts computed from the point and cell lists alone."""

from __future__ import annotations

import meshio
import numpy as np
import pytest

import topomech

from conftest import euler, independent_counts

FIXTURES_2D = ["two_triangles", "quads", "mixed_surface"]
FIXTURES_3D = ["two_tets", "two_hexes", "two_wedges", "two_pyramids", "mixed_volume"]


@pytest.mark.parametrize("name", FIXTURES_2D + FIXTURES_3D)
def test_counts_match_an_independent_count(name: str, request: pytest.FixtureRequest) -> None:
    points, cells = request.getfixturevalue(name)
    g = topomech.GMap.from_mesh(points, cells)
    expected = independent_counts(cells)
    assert g.cell_counts() == expected
    assert g.dimension == (3 if name in FIXTURES_3D else 2)
    assert g.n_darts == expected["darts"]
    assert g.is_valid()
    g.check()
    # every fixture is a disc or a ball
    assert euler(expected) == 1
    assert g.report.reoriented == []
    assert g.report.unused_points == []


@pytest.mark.parametrize("name", FIXTURES_2D + FIXTURES_3D)
def test_positions_are_the_used_points(name: str, request: pytest.FixtureRequest) -> None:
    points, cells = request.getfixturevalue(name)
    g = topomech.GMap.from_mesh(points, cells)
    pos = g.positions()
    p3 = np.column_stack([points, np.zeros(len(points))]) if points.shape[1] == 2 else points
    assert pos.shape == (len(p3), 3)
    assert pos.dtype == np.float64
    # the same set of rows, in the kernel's vertex order
    assert sorted(map(tuple, pos)) == sorted(map(tuple, p3))
    labels = g.vertex_labels()
    assert labels.shape == (g.n_darts,)
    assert labels.min() == 0
    assert labels.max() == len(p3) - 1


def test_cells_as_dict_blocks_and_kind(two_tets: tuple) -> None:
    points, cells = two_tets
    tets = cells[0][1]
    a = topomech.GMap.from_mesh(points, cells).cell_counts()
    assert topomech.GMap.from_mesh(points, {"tetra": tets}).cell_counts() == a
    assert topomech.GMap.from_mesh(points, [meshio.CellBlock("tetra", tets)]).cell_counts() == a
    assert topomech.GMap.from_mesh(points, tets, kind="tetra").cell_counts() == a
    assert topomech.GMap.from_mesh(points.tolist(), tets.tolist(), kind="tetra").cell_counts() == a


def test_unused_points_are_reported(two_triangles: tuple) -> None:
    points, cells = two_triangles
    points = np.vstack([points, [[5.0, 5.0]]])
    g = topomech.GMap.from_mesh(points, cells)
    assert g.report.unused_points == [4]
    assert g.cell_counts()["vertices"] == 4


def test_from_meshio_and_to_meshio_round_trip(mixed_volume: tuple) -> None:
    points, cells = mixed_volume
    g = topomech.GMap.from_meshio(meshio.Mesh(points, cells))
    m = g.to_meshio()
    assert [b.type for b in m.cells] == ["hexahedron", "pyramid", "tetra"]
    again = topomech.GMap.from_meshio(m)
    assert again.cell_counts() == g.cell_counts()


def test_to_meshio_keeps_polygons_and_order(mixed_surface: tuple) -> None:
    points, cells = mixed_surface
    m = topomech.GMap.from_mesh(points, cells).to_meshio()
    assert [b.type for b in m.cells] == ["quad", "triangle", "quad"]
    assert topomech.GMap.from_meshio(m).cell_counts() == independent_counts(cells)


def test_pentagon_goes_out_as_polygon() -> None:
    pts = [[np.cos(a), np.sin(a)] for a in np.linspace(0, 2 * np.pi, 6)[:-1]]
    g = topomech.GMap.from_mesh(pts, [("polygon", [[0, 1, 2, 3, 4]])])
    assert g.cell_counts()["edges"] == 5
    m = g.to_meshio()
    assert [(b.type, b.data.shape) for b in m.cells] == [("polygon", (1, 5))]


def test_to_flat_is_the_kernel_layout(two_hexes: tuple) -> None:
    points, cells = two_hexes
    flat = topomech.GMap.from_mesh(points, cells).to_flat()
    assert flat.kinds == ["hexahedron", "hexahedron"]
    assert flat.offsets.tolist() == [0, 8, 16]
    assert flat.points.shape == (12, 3)
    assert flat.connectivity.dtype == np.int64


def test_embeddings_hold_positions(two_tets: tuple) -> None:
    g = topomech.GMap.from_mesh(*two_tets)
    assert "position" in g.embedding_names()
    info = g.embedding_info("position")
    assert info["type"] == "vec3"
    assert info["orbit"] == "<1,2,3>"
    assert info["derived"] is None
    assert g.memory_bytes() > 0
    with pytest.raises(topomech.EmbeddingError, match="nope"):
        g.embedding_info("nope")


def test_gmap_wraps_only_kernel_maps() -> None:
    with pytest.raises(TypeError, match="from_mesh"):
        topomech.GMap("not a map")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        topomech._core.GMap()  # type: ignore[call-arg]
