"""Mesh import from Python (issue 12, part H1): build options and report, MeshError.option,
the hint in the user's syntax, and the numbering embeddings.

The meshes are built here with known answers (which cells are turned, which points are
pinched, ...); indices are copied, never computed, so comparisons are exact."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import topomech
from topomech._gmap import format_option

TET_POINTS = np.array(
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]],
    dtype=float,
)


def embedding_per_orbit(g: topomech.GMap, name: str, orbit: str) -> dict[int, int]:
    """{smallest dart of each orbit: value of the i64 embedding `name` there}."""
    values_of = g.core.int_embedding(name)
    seen: set[int] = set()
    out: dict[int, int] = {}
    for d in range(g.n_darts):
        if d in seen:
            continue
        darts = [int(x) for x in g.orbit(d, orbit)]
        seen.update(darts)
        values = {int(values_of[x]) for x in darts}
        assert len(values) == 1, f"{name} differs on the orbit of {d}"
        out[min(darts)] = int(values.pop())
    return out


def test_inverted_cells_are_turned_by_default_and_refused_on_request() -> None:
    # cell 1 lists (1, 3, 2, 4): negative volume (checked by a determinant here)
    cells = [("tetra", [[0, 1, 2, 3], [1, 3, 2, 4]])]
    p = TET_POINTS
    m = np.array([p[3] - p[1], p[2] - p[1], p[4] - p[1]])
    assert np.linalg.det(m) < 0
    g = topomech.GMap.from_mesh(TET_POINTS, cells)
    assert g.report.reoriented == [1]
    assert g.is_valid()
    with pytest.raises(topomech.MeshError) as e:
        topomech.GMap.from_mesh(TET_POINTS, cells, reorient=False)
    assert e.value.option == ("reorient", "true")
    assert str(e.value).endswith("; to accept it pass reorient=True")


def test_pinched_point_options_and_report() -> None:
    # two triangles touching at point 2 only
    points = np.array([[0, 0], [1, 0], [1, 1], [2, 1], [1, 2]], dtype=float)
    cells = [("triangle", [[0, 1, 2], [2, 3, 4]])]
    g = topomech.GMap.from_mesh(points, cells)
    assert g.report.pinched == [2]
    rows = embedding_per_orbit(g, "particle", "<1,2>")
    ids = embedding_per_orbit(g, "point_id", "<1,2>")
    assert sorted(ids.values()) == [0, 1, 2, 2, 3, 4]
    assert all(rows[d] == ids[d] for d in rows), "merge: one row per point"
    g = topomech.GMap.from_mesh(points, cells, pinched="split")
    rows = embedding_per_orbit(g, "particle", "<1,2>")
    assert sorted(rows.values()) == [0, 1, 2, 3, 4, 5], "split: a new row 5"
    with pytest.raises(topomech.MeshError, match=r"point 2 \(cells \[0, 1\]\)") as e:
        topomech.GMap.from_mesh(points, cells, pinched="refuse")
    assert e.value.option == ("pinched", "split")
    assert 'pass pinched="split"' in str(e.value)
    with pytest.raises(ValueError, match="pinched must be"):
        topomech.GMap.from_mesh(points, cells, pinched="weld")


def test_duplicates_refused_or_merged() -> None:
    cells = [("tetra", [[0, 1, 2, 3], [3, 2, 1, 0], [1, 2, 3, 4]])]
    with pytest.raises(topomech.MeshError, match="cell 1 duplicates cell 0") as e:
        topomech.GMap.from_mesh(TET_POINTS, cells)
    assert e.value.option == ("duplicates", "merge")
    assert str(e.value).endswith('pass duplicates="merge"')
    g = topomech.GMap.from_mesh(TET_POINTS, cells, duplicates="merge")
    assert g.report.merged_duplicates == [(1, 0)]
    assert g.cell_counts()["volumes"] == 2
    assert sorted(embedding_per_orbit(g, "cell_id", "<0,1,2>").values()) == [0, 2]


def test_moebius_strip_is_reported_non_orientable() -> None:
    n, r, w = 10, 3.0, 0.5
    t = 2 * np.pi * np.arange(n) / n
    pts = []
    for ti in t:
        for s in (-1.0, 1.0):
            rad = r + s * w * np.cos(ti / 2)
            pts.append([rad * np.cos(ti), rad * np.sin(ti), s * w * np.sin(ti / 2)])
    quads = [[2 * i, 2 * i + 1, 2 * i + 3, 2 * i + 2] for i in range(n - 1)]
    quads.append([2 * n - 2, 2 * n - 1, 0, 1])  # the half twist
    g = topomech.GMap.from_mesh(np.array(pts), [("quad", quads)])
    assert g.report.non_orientable
    assert g.is_valid()
    c = g.cell_counts()
    assert c["vertices"] - c["edges"] + c["faces"] == 0  # Euler characteristic of a strip


def test_refusals_without_an_option_have_none() -> None:
    # a bow-tie quad: no option accepts it
    points = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    with pytest.raises(topomech.MeshError, match=r"cell 0 \(quad\): sides") as e:
        topomech.GMap.from_mesh(points, [("quad", [[0, 1, 3, 2]])])
    assert e.value.option is None
    assert "to accept it" not in str(e.value)


def test_hint_follows_the_callers_style() -> None:
    cells = [("tetra", [[0, 1, 2, 3], [3, 2, 1, 0]])]
    for style, text in [
        ("python", 'pass duplicates="merge"'),
        ("cli", "use --duplicates merge"),
        ("scene", 'set mesh.duplicates = "merge"'),
    ]:
        with pytest.raises(topomech.MeshError) as e:
            topomech.GMap.from_mesh(TET_POINTS, cells, _style=style)
        assert str(e.value).endswith(text), (style, str(e.value))
        # the kernel's message names no option: only the appended hint does
        assert str(e.value).count("duplicates") == 2, str(e.value)


@pytest.mark.parametrize(
    ("name", "value", "style", "spelled"),
    [
        ("pinched", "split", "python", 'pinched="split"'),
        ("pinched", "split", "cli", "--pinched split"),
        ("pinched", "split", "scene", 'mesh.pinched = "split"'),
        ("reorient", "true", "python", "reorient=True"),
        ("reorient", "true", "cli", "--reorient"),
        ("reorient", "true", "scene", "mesh.reorient = true"),
        ("linear", "true", "python", "linear=True"),
        ("linear", "true", "cli", "--linear"),
        ("linear", "true", "scene", 'mesh.order = "linear"'),
        ("duplicates", "merge", "cli", "--duplicates merge"),
    ],
)
def test_format_option(name: str, value: str, style: str, spelled: str) -> None:
    assert format_option(name, value, style) == spelled


def test_format_option_refuses_an_unknown_style() -> None:
    with pytest.raises(ValueError, match="style must be one of python, cli, scene"):
        format_option("reorient", "true", "toml")


def test_numbering_embeddings_follow_the_input() -> None:
    points = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1], [9, 9]], dtype=float)
    cells = [("quad", [[0, 1, 4, 3]]), ("triangle", [[1, 2, 5], [1, 5, 4]])]
    g = topomech.GMap.from_mesh(points, cells)
    assert g.report.unused_points == [6]
    ids = embedding_per_orbit(g, "point_id", "<1,2>")
    rows = embedding_per_orbit(g, "particle", "<1,2>")
    pos = g.positions()
    labels = g.vertex_labels()
    for d, p in ids.items():
        assert rows[d] == p, "all points before the unused one: row = point"
        assert np.array_equal(pos[labels[d]], [*points[p], 0.0])
    cell_ids = embedding_per_orbit(g, "cell_id", "<0,1>")
    assert sorted(cell_ids.values()) == [0, 1, 2]


def test_tmg_round_trip_keeps_the_numbering() -> None:
    cells = [("tetra", [[0, 1, 2, 3], [1, 3, 2, 4]])]
    g = topomech.GMap.from_mesh(TET_POINTS, cells)
    back = topomech.GMap.from_bytes(g.to_bytes())
    for name, orbit in [("point_id", "<1,2,3>"), ("particle", "<1,2,3>"), ("cell_id", "<0,1,2>")]:
        assert embedding_per_orbit(back, name, orbit) == embedding_per_orbit(g, name, orbit)


SKFEM_TRIANGLES: dict[str, Callable[[Any], Any]] = {
    "square": lambda s: s.MeshTri().refined(2),
    "circle": lambda s: s.MeshTri.init_circle(2),
    "lshaped": lambda s: s.MeshTri.init_lshaped().refined(1),
}


@pytest.mark.parametrize("name", sorted(SKFEM_TRIANGLES))
def test_scikit_fem_triangles_with_mixed_orientations_load(name: str) -> None:
    """scikit-fem lists half its triangles clockwise: they load, the fewer are turned (ties:
    the orientation of cell 0 wins), and every face then has the same signed area sign."""
    skfem = pytest.importorskip("skfem")
    m = SKFEM_TRIANGLES[name](skfem)
    p, t = m.p.T, m.t.T
    a, b = p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]
    signs = np.sign(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    pos, neg = int((signs > 0).sum()), int((signs < 0).sum())
    keep = signs[0] if pos == neg else (1 if pos > neg else -1)
    g = topomech.GMap.from_mesh(p, [("triangle", t)])
    assert g.report.reoriented == [int(i) for i in np.flatnonzero(signs != keep)]
    pts, _, _offsets, conn = g.to_flat()
    tri = conn.reshape(-1, 3)
    u, v = pts[tri[:, 1]] - pts[tri[:, 0]], pts[tri[:, 2]] - pts[tri[:, 0]]
    out = np.sign(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    assert np.all(out == out[0])
    with pytest.raises(topomech.MeshError, match="opposite orientations"):
        topomech.GMap.from_mesh(p, [("triangle", t)], reorient=False)


def test_scikit_fem_tetrahedra_negative_ones_are_turned() -> None:
    """scikit-fem's refined tetrahedral meshes have negative tetrahedra: exactly those (by a
    determinant computed here) are turned."""
    skfem = pytest.importorskip("skfem")
    m = skfem.MeshTet().refined(2)
    p, t = m.p.T, m.t.T
    d = np.linalg.det(np.stack([p[t[:, k]] - p[t[:, 0]] for k in (1, 2, 3)], axis=1))
    g = topomech.GMap.from_mesh(p, [("tetra", t)])
    assert g.report.reoriented == [int(i) for i in np.flatnonzero(d < 0)]
    assert g.is_valid()
    assert g.cell_counts()["volumes"] == len(t)
    with pytest.raises(topomech.MeshError, match=r"inverted cell\(s\)") as e:
        topomech.GMap.from_mesh(p, [("tetra", t)], reorient=False)
    assert f"{int((d < 0).sum())} inverted cell(s)" in str(e.value)


def test_from_meshio_takes_the_same_options() -> None:
    meshio = pytest.importorskip("meshio")
    m = meshio.Mesh(TET_POINTS, [("tetra", np.array([[0, 1, 2, 3], [3, 2, 1, 0]]))])
    with pytest.raises(topomech.MeshError, match=r"use --duplicates merge$"):
        topomech.GMap.from_meshio(m, _style="cli")
    g = topomech.GMap.from_meshio(m, duplicates="merge")
    assert g.report.merged_duplicates == [(1, 0)]
    assert g.report.unused_points == [4]


def test_int_embedding_refuses_other_types() -> None:
    g = topomech.GMap.from_mesh(TET_POINTS[:4], [("tetra", [[0, 1, 2, 3]])])
    with pytest.raises(topomech.EmbeddingError, match="'position' is vec3, not i64"):
        g.core.int_embedding("position")
    with pytest.raises(topomech.EmbeddingError, match="nope"):
        g.core.int_embedding("nope")
    assert sorted(set(g.core.int_embedding("point_id").tolist())) == [0, 1, 2, 3]
