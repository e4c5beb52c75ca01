"""Embedding consistency at application time (issue 14): a library modeling rule
(``RuleSet.library``) applied to a simulation's map, which carries embeddings the library's
file does not declare (``rest``, ``velocity``, ``f_ext``, ``corner_mass``, ``young``, ...),
gives every orbit made only of new darts a value by the embedding's policy, taken from the old
orbits the new darts copy (the hook dart of their row): ``mean`` the mean, ``copy`` the first
one's value, ``sum`` zero (so totals are kept); an embedding with policy ``error`` makes the
application refused, naming it, with the map unchanged.

What is checked against what: the expected values are computed here with numpy from the map
read before the application (means of the face's or edge's vertex values), compared to 1e-12
(a mean of a few O(1) numbers rounds at ~1e-16); totals of ``sum`` embeddings to 1e-12
relative; and a scan of every copy/mean embedding of the result: where every old orbit holds a
nonzero value, no new orbit may hold exactly zero (an unset value). Before this change the new
orbits were left at zero: the mean checks and the scan fail on that code.
"""

from __future__ import annotations

import numpy as np
import pytest

import topomech
from topomech import ApplyError, GMap, RuleSet, _core


def sim_map() -> GMap:
    """A 3x2 quad grid's simulation map, with nonzero velocities and external loads."""
    sim = topomech.Simulation(
        GMap.from_flat(*_core.grid(3, 2, 1.0, 1.0, "quad")), models=["shear_isotropic"]
    )
    n = sim.n_vertices
    rng = np.random.default_rng(14)
    sim.set_velocities(rng.uniform(0.5, 1.5, (n, 3)))
    sim.set_external_forces(rng.uniform(0.5, 1.5, (n, 3)))
    return sim.gmap()


def value_at(g: GMap, name: str, dart: int) -> np.ndarray:
    values, darts, orbit = g.embedding(name)
    for row, d in enumerate(darts):
        if dart in g.orbit(int(d), orbit):
            return np.asarray(values[row])
    raise AssertionError(f"dart {dart} not in any row of {name}")


def new_rows(g: GMap, name: str, n_before: int) -> list[int]:
    """Rows of `name` whose orbit is made only of darts created by the application."""
    _, darts, orbit = g.embedding(name)
    return [r for r, d in enumerate(darts) if g.orbit(int(d), orbit).min() >= n_before]


def assert_nothing_left_at_zero(g: GMap, before: GMap, n_before: int) -> int:
    """Every copy/mean embedding whose old orbits are all nonzero has no new orbit at zero.
    Returns how many (embedding, new orbit) pairs were checked."""
    checked = 0
    for spec in g.embeddings():
        info = g.embedding_info(spec.name)
        if spec.derived or info["policy"] not in ("copy", "mean"):
            continue
        old, _, _ = before.embedding(spec.name)
        if old.dtype == np.bool_ or len(old) == 0:
            continue
        flat_old = np.asarray(old, dtype=float).reshape(len(old), -1)
        if not np.all(np.any(flat_old != 0.0, axis=1)):
            continue
        values, _, _ = g.embedding(spec.name)
        flat = np.asarray(values, dtype=float).reshape(len(values), -1)
        for r in new_rows(g, spec.name, n_before):
            assert np.any(flat[r] != 0.0), f"{spec.name} left at zero on a new orbit (row {r})"
            checked += 1
    return checked


def test_triangulate_face_on_a_simulation_map() -> None:
    g = sim_map()
    before = GMap.from_bytes(g.to_bytes())
    n_before = g.n_darts
    face = g.orbit(0, "<0,1>")
    corners = sorted({int(g.orbit(int(d), "<1,2>").min()) for d in face})
    assert len(corners) == 4
    rest_want = np.mean([value_at(g, "rest", d) for d in corners], axis=0)
    vel_want = np.mean([value_at(g, "velocity", d) for d in corners], axis=0)
    f_ext_total = g.embedding("f_ext")[0].sum(axis=0)
    young_face = value_at(g, "young", 0)

    rules = RuleSet.library(2)
    rules.apply(g, "triangulate_face", at=0)
    assert g.is_valid()
    assert g.n_darts == n_before + 16, "a quad's triangulation adds 2 darts per face dart"
    centre = n_before + 8  # the node n2 (the centre's darts) is created after n1
    pos = value_at(g, "position", centre)
    assert np.allclose(pos, np.mean([value_at(before, "position", d) for d in corners], axis=0))
    # mean policy: the centroid of the rest positions, the mean velocity
    np.testing.assert_allclose(value_at(g, "rest", centre), rest_want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(value_at(g, "velocity", centre), vel_want, rtol=0, atol=1e-12)
    # sum policy: the centre's load is zero and the total load is kept
    np.testing.assert_array_equal(value_at(g, "f_ext", centre), np.zeros(3))
    np.testing.assert_allclose(g.embedding("f_ext")[0].sum(axis=0), f_ext_total, rtol=1e-12)
    # copy on the face orbit: every new triangle keeps the face's Young's modulus
    for d in g.orbit(centre, "<1,2>"):
        assert value_at(g, "young", int(d)) == young_face
    assert assert_nothing_left_at_zero(g, before, n_before) > 0


def test_split_edge_everywhere_on_a_simulation_map() -> None:
    g = sim_map()
    before = GMap.from_bytes(g.to_bytes())
    n_before = g.n_darts
    f_ext_total = g.embedding("f_ext")[0].sum(axis=0)
    rules = RuleSet.library(2)
    rules.apply(g, "split_edge")
    assert g.is_valid()
    assert g.n_darts == 2 * n_before
    # every new vertex's rest position is its edge's midpoint (mean of the two endpoints,
    # which the split edge keeps as its alpha0-neighbours' vertices)
    rest, darts, _ = g.embedding("rest")
    pos, _, _ = g.embedding("position")
    rows = new_rows(g, "rest", n_before)
    assert len(rows) == 17, "a 3x2 grid has 17 edges"
    for r in rows:
        d = int(darts[r])
        a = int(g.alpha(0, d))  # an old dart of one endpoint A (n0 -0- n1)
        b_dart = int(before.alpha(0, a))
        want = (value_at(before, "rest", a) + value_at(before, "rest", b_dart)) / 2
        np.testing.assert_allclose(rest[r], want, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rest[r], pos[r], rtol=0, atol=1e-12)  # at rest: equal
    np.testing.assert_allclose(g.embedding("f_ext")[0].sum(axis=0), f_ext_total, rtol=1e-12)
    assert assert_nothing_left_at_zero(g, before, n_before) > 0


TAG_RULES = """dimension 2
embedding position : vec3 on <1,2> policy mean
embedding tagged   : f64 on <1,2> policy error

rule tag {
  left { v : <1,2> hook }
  compute { v.tagged = 2.0 }
}
"""


def test_error_policy_refuses_naming_the_embedding() -> None:
    """A map carrying `tagged` (policy error, from another rule file) refuses the library's
    split_edge, naming the rule, the embedding, its orbit and policy; nothing changes."""
    g = GMap.from_flat(*_core.grid(2, 1, 2.0, 1.0, "quad"))
    RuleSet.from_source(TAG_RULES, "tagged.tmr").apply(g, "tag")
    n = g.n_darts
    pos = g.positions().copy()
    with pytest.raises(ApplyError) as e:
        RuleSet.library(2).apply(g, "split_edge", at=0)
    msg = str(e.value)
    assert (
        "rule 'split_edge' creates <1,2> orbits made only of new darts (e.g. at dart d16), "
        "where embedding 'tagged' (f64 on <1,2>, policy error) has no value" in msg
    ), msg
    assert g.n_darts == n
    assert g.is_valid()
    np.testing.assert_array_equal(g.positions(), pos)
    tagged = g.embedding("tagged")[0]
    np.testing.assert_array_equal(tagged, np.full(len(tagged), 2.0))
