"""Every bad input raises the right exception class, with a message naming the cell or point."""

from __future__ import annotations

import numpy as np
import pytest

import topomech
from topomech import _core

TET_POINTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)


def test_the_hierarchy() -> None:
    for cls in (
        topomech.MeshError,
        topomech.MeshReadError,
        topomech.TopologyError,
        topomech.EmbeddingError,
        topomech.FileFormatError,
        topomech.InternalError,
    ):
        assert issubclass(cls, topomech.TopomechError)
        assert cls.__module__ == "topomech._core"
    assert issubclass(topomech.TopomechError, Exception)


@pytest.mark.parametrize("bad", [-1, -(2**31), -(2**63)])
def test_negative_index_names_the_cell_and_never_wraps(bad: int) -> None:
    cells = [("tetra", [[0, 1, 2, 3], [1, 2, 3, bad]])]
    with pytest.raises(topomech.MeshError, match=rf"cell 1 .*vertex {bad}\b"):
        topomech.GMap.from_mesh(TET_POINTS, cells)


def test_negative_index_in_the_flat_layout() -> None:
    with pytest.raises(topomech.MeshError, match=r"cell 0 \(polygon\) refers to vertex -1"):
        _core.GMap.from_flat(TET_POINTS, ["polygon"], np.array([0, 3]), np.array([0, 1, -1]), False)


def test_out_of_range_index_names_the_cell_and_vertex() -> None:
    with pytest.raises(topomech.MeshError, match=r"cell 1\b.*vertex 9\b.*5 points"):
        topomech.GMap.from_mesh(TET_POINTS, [("tetra", [[0, 1, 2, 3], [1, 2, 3, 9]])])


def test_huge_unsigned_index_is_out_of_range() -> None:
    cells = [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 2**64 - 1]], dtype=np.uint64))]
    with pytest.raises(topomech.MeshError, match=r"cell 1\b"):
        topomech.GMap.from_mesh(TET_POINTS, cells)


@pytest.mark.parametrize(
    ("cell_type", "verts"),
    [
        ("tetra", [0, 1, 2]),
        ("triangle", [0, 1, 2, 3]),
        ("quad", [0, 1, 2]),
        ("hexahedron", [0, 1, 2, 3]),
    ],
)
def test_wrong_vertex_count_names_the_cell(cell_type: str, verts: list[int]) -> None:
    with pytest.raises(
        topomech.MeshError, match=rf"cell 0 is a {cell_type} with {len(verts)} vertices"
    ):
        topomech.GMap.from_mesh(TET_POINTS, [(cell_type, [verts])])


def test_wrong_vertex_count_in_a_ragged_block() -> None:
    with pytest.raises(topomech.MeshError, match=r"cell 1 is a triangle with 4 vertices"):
        topomech.GMap.from_mesh(TET_POINTS, [("triangle", [[0, 1, 2], [0, 1, 2, 3]])])


def test_wrong_vertex_count_reaching_the_kernel() -> None:
    with pytest.raises(topomech.MeshError, match=r"cell 0 is a tetra with 5 vertices, expected 4"):
        _core.GMap.from_flat(
            TET_POINTS, ["tetra"], np.array([0, 5]), np.array([0, 1, 2, 3, 4]), False
        )


def test_degenerate_triangle_with_a_repeated_vertex() -> None:
    with pytest.raises(topomech.MeshError, match=r"cell 1 is degenerate"):
        topomech.GMap.from_mesh([[0, 0], [1, 0], [0, 1]], [("triangle", [[0, 1, 2], [0, 0, 1]])])


def test_degenerate_flat_tetrahedron() -> None:
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float)
    with pytest.raises(topomech.MeshError, match=r"cell 0 is degenerate"):
        topomech.GMap.from_mesh(points, [("tetra", [[0, 1, 2, 3]])])


def test_inverted_tet_is_refused_without_reorient() -> None:
    # issue 12: reorient is the default now, so the refusal needs reorient=False
    cells = [("tetra", [[0, 1, 2, 3], [1, 3, 2, 4]])]
    with pytest.raises(topomech.MeshError, match=r"cell 1 \(tetra\) is inverted.*reorient=True"):
        topomech.GMap.from_mesh(TET_POINTS, cells, reorient=False)
    assert topomech.GMap.from_mesh(TET_POINTS, cells).report.reoriented == [1]


def test_inverted_tet_is_turned_over_with_reorient() -> None:
    cells = [("tetra", [[0, 1, 2, 3], [1, 3, 2, 4]])]
    g = topomech.GMap.from_mesh(TET_POINTS, cells, reorient=True)
    assert g.report.reoriented == [1]
    assert g.is_valid()
    good = topomech.GMap.from_mesh(TET_POINTS, [("tetra", [[0, 1, 2, 3], [1, 2, 3, 4]])])
    assert g.cell_counts() == good.cell_counts()


def test_non_manifold_edge_in_2d() -> None:
    points = [[0, 0], [1, 0], [0.5, 1], [0.5, -1], [0.5, 2]]
    tris = [[0, 1, 2], [1, 0, 3], [0, 1, 4]]
    with pytest.raises(topomech.MeshError, match=r"non-manifold edge .*cells \[0, 1, 2\]"):
        topomech.GMap.from_mesh(points, [("triangle", tris)])


def test_non_manifold_face_in_3d() -> None:
    points = np.array(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 1], [0.2, 0.2, -1], [0.3, 0.3, 2]],
        dtype=float,
    )
    tets = [[0, 1, 2, 3], [0, 2, 1, 4], [0, 1, 2, 5]]
    with pytest.raises(topomech.MeshError, match=r"non-manifold face .*cells \[0, 1, 2\]"):
        topomech.GMap.from_mesh(points, [("tetra", tets)])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_point_is_named(bad: float) -> None:
    points = TET_POINTS.copy()
    points[2, 1] = bad
    with pytest.raises(topomech.MeshError, match=r"point 2 has a non-finite coordinate"):
        topomech.GMap.from_mesh(points, [("tetra", [[0, 1, 2, 3]])])


def test_mixed_dimensions_are_refused() -> None:
    with pytest.raises(topomech.MeshError, match=r"cell 1 is a tetra"):
        topomech.GMap.from_mesh(TET_POINTS, [("triangle", [[0, 1, 2]]), ("tetra", [[0, 1, 2, 3]])])


def test_no_cells() -> None:
    with pytest.raises(topomech.MeshError, match="no cells"):
        topomech.GMap.from_mesh(TET_POINTS, [("tetra", np.zeros((0, 4), dtype=int))])


@pytest.mark.parametrize("cell_type", ["tetra10", "triangle6", "hexahedron27", "quad8", "wedge15"])
def test_higher_order_cells_are_refused(cell_type: str) -> None:
    with pytest.raises(topomech.MeshError, match=rf"cell 0 is a {cell_type}: higher-order"):
        topomech.GMap.from_mesh(TET_POINTS, [(cell_type, [[0, 1, 2, 3]])])


def test_lower_dimensional_and_unknown_cells_are_refused() -> None:
    with pytest.raises(topomech.MeshError, match=r"cell 1 is a line, a 1D cell"):
        topomech.GMap.from_mesh(TET_POINTS, [("triangle", [[0, 1, 2]]), ("line", [[0, 1]])])
    with pytest.raises(topomech.MeshError, match=r"unknown type 'blob'"):
        topomech.GMap.from_mesh(TET_POINTS, [("blob", [[0, 1, 2]])])
    with pytest.raises(topomech.MeshError, match=r"cell 0 has unknown kind \"blob\""):
        _core.GMap.from_flat(TET_POINTS, ["blob"], np.array([0, 3]), np.array([0, 1, 2]), False)


def test_non_integer_indices_are_refused() -> None:
    with pytest.raises(
        topomech.MeshError, match=r"cell 0 \(triangle\) has a vertex index that is not an integer"
    ):
        topomech.GMap.from_mesh(TET_POINTS, [("triangle", [[0, 1.5, 2]])])
    # integral floats are fine
    g = topomech.GMap.from_mesh(TET_POINTS, [("triangle", [[0.0, 1.0, 2.0]])])
    assert g.cell_counts()["faces"] == 1


@pytest.mark.parametrize(
    ("points", "match"),
    [
        (np.zeros((5, 4)), r"points must have shape \(N, 2\) or \(N, 3\), got \(5, 4\)"),
        (np.zeros(5), r"got \(5,\)"),
    ],
)
def test_bad_points_are_value_errors(points: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        topomech.GMap.from_mesh(points, [("triangle", [[0, 1, 2]])])


def test_points_that_are_not_numbers_are_type_errors() -> None:
    """Strings are refused as not numbers, as every other real array is (numpy would read
    "1.0" as 1.0)."""
    with pytest.raises(TypeError, match="points must be real numbers"):
        topomech.GMap.from_mesh([["a", "b", "c"]], [("triangle", [[0, 1, 2]])])


def test_bad_cells_argument() -> None:
    with pytest.raises(TypeError, match="kind="):
        topomech.GMap.from_mesh(TET_POINTS, np.array([[0, 1, 2, 3]]))
    with pytest.raises(ValueError, match="kind= is only for a single cell array"):
        topomech.GMap.from_mesh(TET_POINTS, {"tetra": [[0, 1, 2, 3]]}, kind="tetra")
    with pytest.raises(TypeError, match="cells must be"):
        topomech.GMap.from_mesh(TET_POINTS, 42)
    with pytest.raises(ValueError, match=r"must be a 2D array"):
        topomech.GMap.from_mesh(TET_POINTS, [("tetra", [0, 1, 2, 3])])


# ------------------------------------------------------------------ the flat layout's checks


def _flat(**over: object) -> dict[str, object]:
    args: dict[str, object] = {
        "points": TET_POINTS,
        "kinds": ["tetra"],
        "offsets": np.array([0, 4]),
        "connectivity": np.array([0, 1, 2, 3]),
        "reorient": False,
    }
    args.update(over)
    return args


@pytest.mark.parametrize(
    ("over", "exc", "match"),
    [
        (
            {"points": np.zeros((5, 4))},
            ValueError,
            r"points must have shape \(N, 3\), got \(5, 4\)",
        ),
        (
            {"points": np.zeros((5, 3), dtype=np.float32)},
            TypeError,
            r"points must be a numpy array of dtype float64, got a float32 array",
        ),
        (
            {"points": [[0.0, 0.0, 0.0]]},
            TypeError,
            r"points must be a numpy array of dtype float64, got list",
        ),
        (
            {"offsets": np.array([0, 4, 4])},
            ValueError,
            r"offsets must have shape \(M \+ 1,\) = \(2,\) for 1 kinds, got \(3,\)",
        ),
        ({"offsets": np.array([1, 4])}, ValueError, r"offsets\[0\] must be 0"),
        (
            {"offsets": np.array([0, 3])},
            ValueError,
            r"offsets\[-1\] = 3 must equal the length of connectivity \(4\)",
        ),
        ({"offsets": np.array([[0, 4]])}, ValueError, r"offsets must have shape"),
        (
            {"connectivity": np.array([0, 1, 2, 3], dtype=np.int32)},
            TypeError,
            r"connectivity must be a numpy array of dtype int64",
        ),
        ({"kinds": "tetra"}, TypeError, r"str"),
    ],
)
def test_flat_layout_checks(over: dict[str, object], exc: type, match: str) -> None:
    with pytest.raises(exc, match=match):
        _core.GMap.from_flat(**_flat(**over))


def test_decreasing_offsets() -> None:
    with pytest.raises(ValueError, match=r"non-decreasing: offsets\[2\] = 3 < offsets\[1\] = 4"):
        _core.GMap.from_flat(
            **_flat(
                kinds=["tetra", "tetra"], offsets=np.array([0, 4, 3]), connectivity=np.arange(3)
            )
        )


def test_panics_become_internal_errors() -> None:
    with pytest.raises(topomech.InternalError, match=r"Rust panic at .*: boom; please report"):
        _core._panic_for_tests("boom")
    # the module still works afterwards
    assert _core.grid(1, 1, 1.0, 1.0, "quad")[1] == ["polygon"]


def test_import_turns_glibc_fast_bins_off() -> None:
    """Importing the extension turns glibc malloc's fast bins off (a topology change stalled
    in their consolidation: the README's "Memory allocator"), except where the environment's
    GLIBC_TUNABLES sets mxfast itself, and nowhere but Linux with glibc."""
    import os
    import platform

    tuned = topomech._core._malloc_tuned
    glibc = platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"
    by_env = any(
        e.split("=", 1)[0] == "glibc.malloc.mxfast" and "=" in e
        for e in os.environ.get("GLIBC_TUNABLES", "").split(":")
    )
    assert tuned is (glibc and not by_env)
