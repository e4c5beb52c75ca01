"""Embeddings from Python, one row per orbit (issue 14): ``GMap.embedding`` /
``GMap.set_embedding`` / ``GMap.embeddings`` and the same on a ``Simulation``
(``Simulation.embedding`` / ``Simulation.set_embedding`` / ``embeddings``).

What is checked against what:

- rows: each row's dart is the smallest dart of its orbit (``GMap.orbit``), rows by that dart,
  one per orbit (the number of vertices from ``cell_counts``); vertex values equal
  ``GMap.positions`` through ``vertex_labels`` (an independent path in the kernel);
- physics: a corner force (``f_corot`` on ``<1,2>``, one value per corner of a tetrahedron)
  summed over each vertex's corners equals ``Simulation.forces()`` (the kernel's own
  accumulation), and the per-corner masses sum to ``total_mass`` (= density x volume, an
  analytic value); tolerances are a few ulps of the largest term (only the summation order
  differs);
- writes: what is written reads back bit for bit (every embedding type the kernel has:
  f64, i64, bool, vec2, vec3, square and rectangular matrices) on a map of several thousand
  orbits, and through ``.tmg`` bytes; a write of ``velocity`` shows in ``velocities()`` and
  the next step moves each vertex by dt v (symplectic Euler at rest, no load: exact); a write of
  ``corner_mass`` refreshes the derived ``mass``;
- refusals: unknown name (KeyError listing the embeddings), wrong shape or dtype, NaN /
  infinity (naming the embedding, the row and its dart), derived embeddings, numbering
  embeddings of a simulation, welded particles given two positions; nothing is written by a
  refused call, and no input turns into an ``InternalError`` (a Rust panic).

Every test here fails on the code before this change (the methods did not exist).
"""

from __future__ import annotations

import numpy as np
import pytest

import topomech
from topomech import EmbeddingError, EmbeddingValues, GMap, InternalError, SimulationError, _core

# two tetrahedra sharing the face (1, 2, 3)
TET_POINTS = np.array(
    [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]
)
TETS = [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 4]]))]


def tet_sim(**kw: object) -> topomech.Simulation:
    cfg: dict[str, object] = {
        "models": ["corotational"],
        "density": 1000.0,
        "young": 1e5,
        "poisson": 0.3,
        "damping": 0.0,
        "gravity": [0.0, 0.0, 0.0],
        "integrator": "symplectic_euler",
        "dt": 1e-3,
    }
    cfg.update(kw)
    return topomech.Simulation(GMap.from_mesh(TET_POINTS, TETS), **cfg)  # type: ignore[arg-type]


def box_map(n: int) -> GMap:
    return GMap.from_flat(*_core.box(n, n, n, 1.0, 1.0, 1.0, "tetra"))


# ---------------------------------------------------------------------------- reading


def test_rows_are_orbits_by_smallest_dart_and_match_positions() -> None:
    g = GMap.from_mesh(TET_POINTS, TETS)
    ev = g.embedding("position")
    assert isinstance(ev, EmbeddingValues)
    values, darts, orbit = ev
    assert orbit == "<1,2,3>"
    assert darts.dtype == np.int64
    assert values.dtype == np.float64
    assert values.shape == (g.cell_counts()["vertices"], 3) == (5, 3)
    assert np.all(np.diff(darts) > 0), "rows in increasing order of their dart"
    for d in darts:
        assert d == g.orbit(int(d), orbit).min(), "each row's dart is its orbit's smallest"
    # every dart belongs to exactly one row's orbit
    covered = np.sort(np.concatenate([g.orbit(int(d), orbit) for d in darts]))
    assert np.array_equal(covered, np.arange(g.n_darts))
    # the same positions as the per-vertex array, through the vertex labels
    labels = g.vertex_labels()
    assert np.array_equal(values, g.positions()[labels[darts]])


def test_embeddings_lists_names_types_orbits() -> None:
    sim = tet_sim()
    specs = {s.name: s for s in sim.embeddings()}
    assert (specs["position"].type, specs["position"].orbit) == ("vec3", "<1,2,3>")
    assert specs["mass"].derived
    assert not specs["corner_mass"].derived
    assert (specs["k_elem"].type, specs["k_elem"].orbit) == ("mat12", "<0,1,2>")
    g = sim.gmap()
    assert [s.name for s in g.embeddings()] == g.embedding_names()
    assert g.embeddings() == sim.embeddings()


def test_matrix_shapes_and_per_element_stiffness() -> None:
    sim = tet_sim()
    k, darts, orbit = sim.embedding("k_elem")
    assert orbit == "<0,1,2>"
    assert k.shape == (2, 12, 12)
    assert len(darts) == 2
    # a linear elastic stiffness is symmetric and annihilates rigid translations
    for ke in k:
        assert np.allclose(ke, ke.T, rtol=0, atol=1e-9 * np.abs(ke).max())
        for a in range(3):
            t = np.zeros(12)
            t[a::3] = 1.0
            assert np.abs(ke @ t).max() <= 1e-9 * np.abs(ke).max()
    x_rest, _, _ = sim.embedding("x_rest")
    assert x_rest.shape == (2, 12, 1), "a rectangular mat12x1 keeps its (R, C)"
    dm_inv, _, _ = sim.embedding("dm_inv")
    assert dm_inv.shape == (2, 3, 3)


def test_corner_forces_sum_to_vertex_forces() -> None:
    """f_corot lives on the corners <1,2> of each tetrahedron; the vertex force that forces()
    returns is their sum over the vertex's corners (the models' accumulation)."""
    sim = tet_sim(gravity=[0.0, 0.0, -9.81])
    sim.step(5)
    rng = np.random.default_rng(7)
    sim.set_positions(sim.positions() + 0.05 * rng.standard_normal((sim.n_vertices, 3)))
    total = sim.forces()
    assert np.abs(total).max() > 1.0, "a deformed state has forces"
    f, darts, orbit = sim.embedding("f_corot")
    assert orbit == "<1,2>"
    assert f.shape == (8, 3), "4 corners per tetrahedron"
    rows = sim.gmap().vertex_labels()[darts]
    summed = np.zeros_like(total)
    np.add.at(summed, rows, f)
    assert np.allclose(summed, total, rtol=0, atol=1e-12 * np.abs(f).max())


def test_masses_sum_to_total_mass() -> None:
    sim = tet_sim()
    volume = 1.0 / 6.0 + abs(np.linalg.det(TET_POINTS[[2, 3, 4]] - TET_POINTS[1])) / 6.0
    m, _, orbit = sim.embedding("mass")
    assert orbit == "<1,2,3>"
    assert np.isclose(m.sum(), sim.total_mass(), rtol=1e-14)
    assert np.isclose(sim.total_mass(), 1000.0 * volume, rtol=1e-14)
    cm, _, corner = sim.embedding("corner_mass")
    assert corner == "<1,2>"
    assert np.isclose(cm.sum(), sim.total_mass(), rtol=1e-14)


# ---------------------------------------------------------------------------- writing


def test_every_embedding_round_trips_exactly_on_thousands_of_orbits() -> None:
    """Random values written on every stored embedding of a 3D and a 2D simulation's map
    (f64, i64, bool, vec2, vec3, mat3, mat12, mat12x1, ...) read back bit for bit, directly
    and through .tmg bytes."""
    rng = np.random.default_rng(2026)
    g3 = topomech.Simulation(box_map(6), models=["corotational"]).gmap()
    g2 = topomech.Simulation(
        GMap.from_flat(*_core.grid(40, 40, 1.0, 1.0, "quad")), models=["shear_isotropic"]
    ).gmap()
    types = set()
    for g in (g3, g2):
        written = {}
        for spec in g.embeddings():
            if spec.derived:
                continue
            values, darts, _ = g.embedding(spec.name)
            if values.dtype == np.bool_:
                new = rng.random(values.shape) < 0.5
            elif spec.name == "particle":  # the vertex numbering: another numbering
                new = rng.permutation(values)
            elif spec.name in ("point_id", "cell_id"):
                # input numberings: indices >= 0 (-1: none), no point twice in an element
                high = rng.permutation(len(values)).astype(np.int64) * 2**40
                new = high + rng.integers(0, 2**40, values.shape, dtype=np.int64)
            elif values.dtype == np.int64:
                new = rng.integers(-(2**62), 2**62, values.shape, dtype=np.int64)
            else:
                new = rng.standard_normal(values.shape) * 10.0 ** rng.integers(-300, 300)
            g.set_embedding(spec.name, new)
            written[spec.name] = (new, darts)
            types.add(spec.type)
        back = GMap.from_bytes(g.to_bytes())
        for name, (new, darts) in written.items():
            for h in (g, back):
                values, d, _ = h.embedding(name)
                assert np.array_equal(d, darts)
                assert values.dtype == new.dtype, name
                assert np.array_equal(values, new), name
        assert g.is_valid()
    assert {"f64", "i64", "bool", "vec2", "vec3", "mat3", "mat12", "mat12x1"} <= types
    assert len(g3.embedding("position").darts) == 7**3, "several hundred vertices"
    assert len(g3.embedding("he_volume").darts) > 5000, "several thousand half-edges"


def test_write_velocities_then_step() -> None:
    sim = tet_sim()
    v, darts, _ = sim.embedding("velocity")
    assert not v.any()
    rest, rdarts, _ = sim.embedding("rest")
    assert np.array_equal(rdarts, darts)
    new = np.column_stack([rest[:, 1], -rest[:, 0], 0.5 * rest[:, 2]])  # per-orbit values
    sim.set_embedding("velocity", new)
    rows = sim.gmap().vertex_labels()[darts]
    expect = np.zeros((sim.n_vertices, 3))
    expect[rows] = new
    assert np.array_equal(sim.velocities(), expect)
    x0 = sim.positions()
    sim.step()
    # at rest with no load the forces are zero: v stays and x moves by dt v (symplectic Euler)
    assert np.allclose(sim.velocities(), expect, rtol=0, atol=1e-9)
    assert np.allclose(sim.positions(), x0 + sim.dt * expect, rtol=0, atol=1e-12)


def test_write_positions_matches_set_positions() -> None:
    a, b = tet_sim(), tet_sim()
    x, darts, _ = a.embedding("position")
    rng = np.random.default_rng(3)
    x = x + 0.05 * rng.standard_normal(x.shape)
    a.set_embedding("position", x)
    rows = a.gmap().vertex_labels()[darts]
    per_row = np.zeros((a.n_vertices, 3))
    per_row[rows] = x
    b.set_positions(per_row)
    assert np.array_equal(a.positions(), per_row)
    assert np.array_equal(a.forces(), b.forces())
    a.step(3)
    b.step(3)
    assert np.array_equal(a.positions(), b.positions())


def test_write_corner_mass_refreshes_derived_mass() -> None:
    sim = tet_sim()
    m0 = sim.total_mass()
    cm, _, _ = sim.embedding("corner_mass")
    sim.set_embedding("corner_mass", 2.0 * cm)
    assert np.isclose(sim.total_mass(), 2.0 * m0, rtol=1e-14)
    m, _, _ = sim.embedding("mass")
    assert np.isclose(m.sum(), 2.0 * m0, rtol=1e-14)
    g = sim.gmap()
    g.set_embedding("corner_mass", cm)
    assert np.isclose(g.embedding("mass").values.sum(), m0, rtol=1e-14)


def test_python_lists_and_integer_arrays_are_converted() -> None:
    g = GMap.from_mesh(TET_POINTS, TETS)
    x = g.embedding("position").values
    g.set_embedding("position", np.rint(x * 2).astype(np.int32))
    assert np.array_equal(g.embedding("position").values, np.rint(x * 2))
    g.set_embedding("position", (x + 1).tolist())
    assert np.array_equal(g.embedding("position").values, x + 1)


# ---------------------------------------------------------------------------- refusals


def test_unknown_name_is_a_key_error_listing_embeddings() -> None:
    g = GMap.from_mesh(TET_POINTS, TETS)
    sim = tet_sim()
    for call in (
        lambda: g.embedding("velocty"),
        lambda: g.set_embedding("velocty", np.zeros(3)),
        lambda: sim.embedding("velocty"),
        lambda: sim.set_embedding("velocty", np.zeros(3)),
    ):
        with pytest.raises(KeyError, match=r"no embedding named 'velocty'.*position"):
            call()


def test_wrong_shape_dtype_and_values_are_refused_and_nothing_is_written() -> None:
    sim = tet_sim()
    g = sim.gmap()
    before = g.to_bytes()
    x = g.embedding("position").values
    with pytest.raises(
        ValueError,
        match=r"'position' \(vec3 on <1,2,3>\) must have shape "
        r"\(n, 3\) = \(5, 3\).*got \(4, 3\)",
    ):
        g.set_embedding("position", x[:4])
    with pytest.raises(ValueError, match=r"shape \(n, 3\) = \(5, 3\).*got \(15,\)"):
        g.set_embedding("position", x.ravel())
    bad = x.copy()
    bad[3, 1] = np.nan
    bad[4, 0] = np.inf
    d3 = int(g.embedding("position").darts[3])
    with pytest.raises(
        ValueError,
        match=rf"'position' must be finite: row 3 \(the orbit of "
        rf"dart {d3}\).*2 rows are not finite",
    ):
        g.set_embedding("position", bad)
    with pytest.raises(TypeError, match=r"'particle'.*int64.*float64"):
        g.set_embedding("particle", g.embedding("particle").values + 0.5)
    with pytest.raises(TypeError, match=r"'fixed'.*bool"):
        g.set_embedding("fixed", np.zeros(5))
    with pytest.raises(TypeError, match=r"'position'.*float64"):
        g.set_embedding("position", np.zeros((5, 3), dtype=bool))
    with pytest.raises(EmbeddingError, match=r"'mass' is derived"):
        g.set_embedding("mass", g.embedding("mass").values)
    assert g.to_bytes() == before, "a refused write changes nothing"
    # the same refusals on the simulation, plus its numbering and its welded rows
    x0 = sim.positions()
    with pytest.raises(ValueError, match=r"must be finite: row 3"):
        sim.set_embedding("position", bad)
    with pytest.raises(EmbeddingError, match=r"'mass' is derived"):
        sim.set_embedding("mass", np.ones(5))
    for name in ("particle", "point_id", "vertex0"):
        with pytest.raises(SimulationError, match=rf"'{name}' numbers the simulation"):
            sim.set_embedding(name, sim.embedding(name).values)
    assert np.array_equal(sim.positions(), x0)


def test_a_particle_numbering_that_numbers_no_rows_is_refused() -> None:
    """Regression: ``GMap.set_embedding("particle", ...)`` accepted any int64 values: all
    zeros collapsed every written vertex onto one point, and negative, gapped or huge rows
    were written and then silently ignored (the rows fell back to the orbit order). Each is
    now a ValueError naming the embedding, the problem and the row (its dart), and nothing
    is written; a permutation of the rows is a numbering and is accepted."""
    g = GMap.from_flat(*_core.grid(2, 1, 2.0, 1.0, "quad"))
    before = g.to_bytes()
    p, darts, _ = g.embedding("particle")
    assert sorted(p.tolist()) == list(range(6))
    d = [int(x) for x in darts]
    cases = [
        (
            np.zeros(6, dtype=np.int64),
            rf"give particle row 0 to vertices at different positions: the vertex of dart "
            rf"{d[0]} \(row 0 of the values\) at .* and the vertex of dart {d[1]} \(row 1 of the values\) at ",
        ),
        (p - 3, r"must not be negative: -\d for the vertex of dart \d+ \(row \d of the values\)"),
        (np.where(p == 5, 3_000_000_000, p), r"must be below 6: 3000000000 for the vertex"),
        (np.where(p == 5, 7, p), r"must be below 6: 7 for the vertex of dart"),
    ]
    for values, match in cases:
        with pytest.raises(
            ValueError,
            match=r"values for 'particle' \(the vertex numbering: a row "
            r"0\.\.n-1 for each of the 6 vertex orbits\) " + match,
        ):
            g.set_embedding("particle", values)
    assert g.to_bytes() == before, "a refused numbering is not written"
    # a permutation renumbers the rows: the written points follow it
    perm = (5 - p).astype(np.int64)
    g.set_embedding("particle", perm)
    assert g.embedding("particle").values.tolist() == perm.tolist()
    points = g.to_flat()[0]
    x = g.embedding("position").values
    assert np.array_equal(points[perm], x)


def test_a_particle_numbering_with_gaps_is_refused() -> None:
    """Rows must be 0..n-1, every one used; orbits at one place may share a row (a pinched
    point kept as one particle)."""
    pts = np.array(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]],
        dtype=float,
    )
    tets = [("tetra", np.array([[0, 1, 2, 3], [0, 4, 6, 5]]))]
    g = GMap.from_mesh(pts, tets, pinched="split")
    p = g.embedding("particle").values
    assert sorted(p.tolist()) == list(range(8)), "the pinched point is two rows"
    merged = np.where(p == 7, 0, p).astype(np.int64)  # point 0's two orbits as one row: fine
    g.set_embedding("particle", merged)
    assert g.to_flat()[0].shape == (7, 3)
    gapped = np.where(p == 7, 0, np.where(p == 3, 7, p)).astype(np.int64)  # no row 3
    with pytest.raises(
        ValueError, match=r"must use every row below the largest, 7: no vertex has row 3$"
    ):
        g.set_embedding("particle", gapped)
    assert g.embedding("particle").values.tolist() == merged.tolist()


def test_input_numbering_below_minus_one_is_refused() -> None:
    """Regression: ``set_embedding("point_id", ...)`` and ``set_embedding("cell_id", ...)``
    took any int64: a -7 was written into final.vtu's ``point_id`` and ``cell_id`` data as if
    it were an index of the input mesh. They hold an input index (>= 0) or -1 for none (a
    vertex a rule created has point_id -1); anything below -1 is a ValueError naming the
    embedding, the value and the orbit's dart, and nothing is written."""
    for dim, g in (
        (2, GMap.from_flat(*_core.grid(2, 1, 2.0, 1.0, "quad"))),
        (3, GMap.from_mesh(TET_POINTS, TETS)),
    ):
        before = g.to_bytes()
        element = "face" if dim == 2 else "volume"
        for name, orbit, what in (
            ("point_id", "vertex", "the input point of each vertex"),
            ("cell_id", element, f"the input cell of each {element}"),
        ):
            values, darts, _ = g.embedding(name)
            bad = values.copy()
            bad[-1] = -7
            with pytest.raises(
                ValueError,
                match=rf"values for '{name}' \({what}: its index in the mesh the map was "
                rf"built from, or -1 for none\) must be -1 or more: -7 for the {orbit} of "
                rf"dart {darts[-1]} \(row {len(values) - 1} of the values\)$",
            ):
                g.set_embedding(name, bad)
            assert g.to_bytes() == before, "a refused numbering is not written"
            # -1 (none) is taken, and so is any other index of an input the map does not know
            ok = values.copy()
            ok[0], ok[-1] = -1, 10**12
            g.set_embedding(name, ok)
            assert g.embedding(name).values.tolist() == ok.tolist()
            g.set_embedding(name, values)


def test_a_point_twice_in_one_element_is_refused() -> None:
    """Regression: ``set_embedding("point_id", ...)`` accepted one input point for two
    vertices of one element, which no input cell has (its corners are distinct points): the
    written element then matched no input cell and was written in the map's vertex order, and
    a point group selected both vertices. Refused naming the point, both vertices (darts and
    value rows) and the element; -1 (no input point) may repeat, as the vertices a rule adds
    to one face all carry it."""
    g = GMap.from_mesh(TET_POINTS, TETS)
    before = g.to_bytes()
    values, darts, _ = g.embedding("point_id")
    rows = {int(p): k for k, p in enumerate(values)}
    bad = values.copy()
    bad[rows[4]] = 1  # point 4 of tetrahedron (1, 2, 3, 4) renamed 1: that tet has 1 twice
    with pytest.raises(
        ValueError,
        match=r"values for 'point_id' .* must differ between the vertices of one volume: "
        rf"point 1 for the vertex of dart {darts[rows[1]]} \(row {rows[1]} of the values\) and the vertex "
        rf"of dart {darts[rows[4]]} \(row {rows[4]} of the values\), both on the volume of dart \d+$",
    ):
        g.set_embedding("point_id", bad)
    assert g.to_bytes() == before
    # point 0 and point 4 share no tetrahedron: one id for both is a point split in two
    split = values.copy()
    split[rows[4]] = 0
    g.set_embedding("point_id", split)
    none = np.full_like(values, -1)
    g.set_embedding("point_id", none)
    assert g.embedding("point_id").values.tolist() == none.tolist()


def test_numbering_the_kernel_writes_is_taken_back() -> None:
    """What the kernel itself writes reads back and writes again unchanged: duplicates
    included. A pinched point split in two keeps its point_id on both vertices, the pieces
    of a face cut by a rule keep its cell_id, and the vertices the rule adds have point_id
    -1. (The contract is not uniqueness: these are the input's numbers carried through
    topology changes.)"""
    pts = [[0, 0], [1, 0], [0, 1], [-1, 0], [0, -1]]
    g = GMap.from_mesh(pts, [("triangle", [[0, 1, 2], [0, 3, 4]])], pinched="split")
    assert sorted(g.embedding("point_id").values.tolist()) == [0, 0, 1, 2, 3, 4]
    quads = GMap.from_mesh(
        [[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [2, 1]],
        [("quad", [[0, 1, 2, 3], [1, 4, 5, 2]])],
    )
    topomech.RuleSet.library(2).apply(quads, "quad_subdivide", [0])
    assert quads.embedding("cell_id").values.tolist().count(0) == 4
    assert quads.embedding("point_id").values.tolist().count(-1) == 9
    for m in (g, quads):
        before = m.to_bytes()
        for name in ("point_id", "cell_id"):
            m.set_embedding(name, m.embedding(name).values)
        assert m.to_bytes() == before


def test_ragged_values_and_unknown_names_say_so() -> None:
    """Regression: rows of different lengths raised numpy's own message (naming no
    embedding), and did so before an unknown name was refused with KeyError."""
    g = GMap.from_mesh(TET_POINTS, TETS)
    sim = tet_sim()
    ragged = [[0.0, 0.0, 0.0]] * 4 + [[0.0, 0.0]]
    for obj in (g, sim):
        with pytest.raises(KeyError, match=r"no embedding named 'nope'"):
            obj.set_embedding("nope", ragged)
        with pytest.raises(
            ValueError,
            match=r"values for 'position' \(vec3 on <1,2,3>\) are not an array of one row per "
            r"orbit, all of one shape: ",
        ):
            obj.set_embedding("position", ragged)


def test_welded_particle_needs_one_position() -> None:
    """Two tetrahedra touching only at point 0, kept as one particle (pinched="merge"): two
    vertex orbits, one row. Giving them two positions is refused; one is accepted."""
    pts = np.array(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]],
        dtype=float,
    )
    tets = [("tetra", np.array([[0, 1, 2, 3], [0, 4, 6, 5]]))]
    sim = topomech.Simulation(GMap.from_mesh(pts, tets), models=["corotational"])
    assert sim.n_vertices == 7
    x, darts, _ = sim.embedding("position")
    assert len(darts) == 8, "the pinched point is two vertex orbits"
    rows = sim.gmap().vertex_labels()[darts]
    k0, k1 = np.flatnonzero(rows == rows[np.argmax(np.bincount(rows))])
    moved = x.copy()
    moved[k0] += 0.1
    with pytest.raises(ValueError, match=rf"rows {k0} and {k1} .* are one particle"):
        sim.set_embedding("position", moved)
    moved[k1] += 0.1
    sim.set_embedding("position", moved)
    assert np.allclose(sim.positions()[rows[k0]], x[k0] + 0.1, rtol=0, atol=0)
    # masses are per orbit: two different values on the welded orbits are fine
    m = sim.embedding("corner_mass").values
    sim.set_embedding("corner_mass", m * np.linspace(1.0, 2.0, len(m)))


def test_no_input_reaches_a_panic() -> None:
    """Odd inputs to the kernel methods directly (no Python conversion): each is refused with
    TypeError, ValueError or KeyError, never InternalError (a Rust panic)."""
    g = box_map(2)
    core = g.core
    sim = topomech.Simulation(box_map(2), models=["corotational"])
    n = len(g.embedding("position").darts)
    odd = [
        None,
        3.0,
        "position",
        [[0.0, 0.0, 0.0]] * n,
        np.zeros(()),
        np.zeros((n, 3, 1)),
        np.zeros((0, 3)),
        np.zeros((n, 3), dtype=np.float32),
        np.zeros((n, 3), dtype=object),
        np.zeros((n, 3), dtype=complex),
        np.zeros((3, n)).T,  # not contiguous: accepted, read in logical order
        np.zeros((n, 6))[:, ::2],
        np.full((n, 3), np.nan),
        np.full((n, 3), -np.inf),
        np.zeros((n * 3,)),
    ]
    for name in ("position", "particle", "fixed", "nope", "", "mass"):
        for a in odd:
            for call in (core.set_embedding, sim._core.set_orbit_embedding):
                try:
                    call(name, a)  # type: ignore[arg-type]
                except (TypeError, ValueError, KeyError, EmbeddingError, SimulationError):
                    pass
                except InternalError as e:  # pragma: no cover - the failure being tested
                    pytest.fail(f"{name} {a!r}: a panic crossed: {e}")
    assert g.is_valid()
    assert np.isfinite(sim.positions()).all()
