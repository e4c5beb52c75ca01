"""Scene predicates are parsed as one expression of the rule language, never spliced into
rule text: a predicate containing rule syntax is a bad predicate naming its key and column,
in a scene and in a Simulation's configuration; an ordinary predicate selects exactly the
vertices it says (checked against numpy on the rest positions)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
import pytest

import topomech
from topomech import _core
from topomech.scene import parse_scene


def bar() -> topomech.GMap:
    """The scenes' mesh: a 2 x 1 x 1 bar of 4 x 2 x 2 cubes of tetrahedra."""
    return topomech.GMap.from_flat(*_core.box(4, 2, 2, 2.0, 1.0, 1.0, "tetra"))


SCENE = """
[mesh]
generator = "box"
element = "tet"
size = [2.0, 1.0, 1.0]
cells = [4, 2, 2]

[[model]]
kind = "stretch_elementary"

[integrator]
kind = "symplectic_euler"
dt = 1e-3
steps = 2
"""

#: Predicates that close the guard they were once spliced into and define rules of their
#: own, with the column of the first token after the expression. The first two made valid
#: rule text in both the scene check and the kernel: the scene was built, rule `evil` with it.
EVIL = [
    (
        "x < 1e-9 } compute { v.fixed = true } } "
        "rule evil { left { v : <1,2,3> hook } where { true",
        10,
    ),
    (
        "true } compute { v.fixed = true } } "
        "rule evil(d: vec3) { left { v : <1,2,3> hook } where { true",
        6,
    ),
    (
        "x < 0 } rule evil { left { v : <1,2,3> hook } compute { v.fixed = true } } rule x {",
        7,
    ),
    ("x < 0 rule", 7),
    ("x < 0  x > 1", 8),
]

#: Where a scene's predicate goes, and the key that names it.
TABLES = [
    ("[[fix]]\nwhere = '{p}'\n", "fix[0].where"),
    ("[[fix]]\nwhere = '{p}'\ndisplacement = [0.0, 0.01, 0.0]\n", "fix[0].where"),
    ("[material]\n[[material.region]]\nwhere = '{p}'\nyoung = 2e6\n", "material.region[0].where"),
    ("[[event]]\ntime = 0.001\nkind = 'cut'\nwhere = '{p}'\n", "event[0].where"),
]


@pytest.mark.parametrize(("pred", "col"), EVIL)
@pytest.mark.parametrize(("table", "key"), TABLES)
def test_rule_syntax_in_a_scene_predicate_is_a_bad_predicate(
    pred: str, col: int, table: str, key: str
) -> None:
    """Refused when the scene is read, naming the key, the predicate and the column."""
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(SCENE + table.format(p=pred)).build()
    assert e.value.key == key, str(e.value)
    assert f'bad predicate "{pred}": column {col}: expected the end of the expression' in str(
        e.value
    )


@pytest.mark.parametrize(("pred", "col"), EVIL)
def test_rule_syntax_in_a_simulation_predicate_is_a_bad_predicate(pred: str, col: int) -> None:
    """The kernel refuses it too (a Simulation built from a configuration, no scene check),
    naming the configuration's key and the column, for each kind of predicate."""
    g = bar()
    cases: list[tuple[dict[str, object], str]] = [
        ({"fixed": ["x < 1e-9", pred]}, "fixed-vertex predicate fixed[1]"),
        (
            {"prescribed": [(pred, [0.0, 0.1, 0.0])]},
            "prescribed-displacement predicate prescribed[0]",
        ),
        ({"regions": [{"where": pred, "density": 2.0}]}, "material-region predicate regions[0]"),
        ({"events": [{"time": 0.1, "kind": "cut", "where": pred}]}, "cut predicate events[0]"),
    ]
    for kw, what in cases:
        with pytest.raises(topomech.SimulationError) as e:
            topomech.Simulation(g, models=["stretch_elementary"], **kw)  # type: ignore[arg-type]
        assert f"bad {what} " in str(e.value), str(e.value)
        assert f": column {col}: expected the end of the expression" in str(e.value)


#: What a predicate says it reads when it is given an embedding read (rule syntax).
READS_ONLY = (
    "is rule syntax, not allowed here: a predicate (or a load's expression) reads only the "
    "coordinates x, y, z of the point it is evaluated at"
)


@pytest.mark.parametrize(("table", "key"), TABLES)
@pytest.mark.parametrize(
    ("pred", "col", "what"),
    [
        ("v.position", 1, "'v.position' reads an embedding"),
        ("x(v.rest) > 0.5", 3, "'v.rest' reads an embedding"),
        ("mean<0>(v.position) > 0", 1, "'mean<0>(v.position)' aggregates over an orbit"),
    ],
)
def test_an_embedding_read_in_a_predicate_says_what_a_predicate_reads(
    pred: str, col: int, what: str, table: str, key: str
) -> None:
    """A predicate written in rule syntax, `where = "v.position"`, said `unknown embedding
    'position'` in a scene's cut (and `x(v.rest) > 0.5` passed a scene's fix): now refused
    at its column in every key, saying predicates read only x, y, z and their own lets; in
    a Simulation's configuration too."""
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(SCENE + table.format(p=pred)).build()
    assert e.value.key == key, str(e.value)
    assert f'bad predicate "{pred}": column {col}: {what}' in str(e.value), str(e.value)
    assert READS_ONLY in str(e.value)
    assert "unknown embedding" not in str(e.value)
    event = {"time": 0.1, "kind": "cut", "where": pred}
    with pytest.raises(topomech.SimulationError) as e2:
        topomech.Simulation(bar(), models=["stretch_elementary"], events=[event])
    assert f'bad cut predicate events[0] "{pred}": column {col}: {what}' in str(e2.value)
    assert READS_ONLY in str(e2.value)


def test_check_predicate_names_the_label_and_the_place() -> None:
    """``_core.check_predicate`` gives the diagnostics of the kernel's own construction."""
    _core.check_predicate("x < 0.5 && abs(y) > 1", "k")
    with pytest.raises(topomech.RuleError) as e:
        _core.check_predicate("x < 0\n} rule evil {", "fix[3].where")
    assert e.value.diagnostics[0].startswith("fix[3].where:2:1: error[syntax]: expected the end")
    with pytest.raises(topomech.RuleError) as e:
        _core.check_predicate("x < 1 && w > 0", "k")
    assert e.value.diagnostics[0].startswith("k:1:10: error[name]: ")
    assert "unknown variable or parameter 'w'" in e.value.diagnostics[0]


def test_a_long_operator_chain_is_the_depth_error() -> None:
    """4000 additions: the parser's depth error, from the scene check and from the kernel."""
    pred = " + ".join(["x"] * 4000) + " < 0"
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(SCENE + f"[[fix]]\nwhere = '{pred}'\n")
    assert e.value.key == "fix[0].where"
    assert "expression nested too deeply: depth 257, the limit is 256" in str(e.value)
    g = bar()
    with pytest.raises(topomech.SimulationError) as s:
        topomech.Simulation(g, models=["stretch_elementary"], fixed=[pred])
    assert "expression nested too deeply: depth 257, the limit is 256" in str(s.value)


Points = npt.NDArray[np.float64]
Mask = npt.NDArray[np.bool_]

#: Ordinary predicates and the same predicate in numpy on rest positions (n, 3).
ORDINARY: list[tuple[str, Callable[[Points], Mask]]] = [
    ("x < 1e-9", lambda p: p[:, 0] < 1e-9),
    (
        "x < 0.6 && !(y > 0.4) || z > 0.9",
        lambda p: (p[:, 0] < 0.6) & ~(p[:, 1] > 0.4) | (p[:, 2] > 0.9),
    ),
    ("let r = x - 1.0  abs(r) < 0.3", lambda p: np.abs(p[:, 0] - 1.0) < 0.3),
    (
        "if y > 0.5 { x < 0.6 } else { x > 1.4 }",
        lambda p: np.where(p[:, 1] > 0.5, p[:, 0] < 0.6, p[:, 0] > 1.4),
    ),
    ("{ let s = x + y  s <= 1.0 }", lambda p: p[:, 0] + p[:, 1] <= 1.0),
    ("norm(vec3(x - 2.0, y, z)) < 0.8", lambda p: np.linalg.norm(p - [2.0, 0, 0], axis=1) < 0.8),
]


@pytest.mark.parametrize(("pred", "numpy_pred"), ORDINARY)
def test_an_ordinary_predicate_selects_what_it_says(
    pred: str, numpy_pred: Callable[[Points], Mask]
) -> None:
    """The fixed vertices of a scene are those where numpy's evaluation of the same predicate
    on the rest positions holds (exact: the grid's coordinates are away from every bound)."""
    sim = parse_scene(SCENE + f"[[fix]]\nwhere = '{pred}'\n").build()
    want = numpy_pred(sim.rest_positions())
    assert 0 < want.sum() < len(want), pred
    np.testing.assert_array_equal(sim.fixed(), want, err_msg=pred)
