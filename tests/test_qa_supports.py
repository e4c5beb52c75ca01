"""QA: supports that hold one vertex at two positions (``[[fix]]`` tables selecting by
``points`` or ``group``, alone or mixed with ``where``), and the Python API's
:class:`topomech.Simulation` refusing the model parameters and regions a scene refuses."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

import topomech
from topomech import GMap, _core, cli
from topomech.loads import LoadError, apply_conditions, held_positions, select_vertices
from topomech.models import shipped_models
from topomech.scene import parse_scene

BAR = """
name = "bar"
[mesh]
generator = "box"
element = "tet"
size = [1.0, 0.2, 0.2]
cells = [5, 1, 1]
[[model]]
kind = "linear_fem"
[world]
gravity = [0.0, 0.0, 0.0]
[integrator]
kind = "static"
dt = 1.0
steps = 1
"""

#: The input points of the bar's end x = 0 (its 4 corners).
END = "[0, 6, 12, 18]"
#: The same vertices by predicate.
WHERE = '"x < 1e-9"'


def _fixes(*tables: str) -> str:
    return BAR + "".join(f"[[fix]]\n{t}\n" for t in tables)


def _at_end(sim: topomech.Simulation) -> Any:
    return sim.rest_positions()[:, 0] < 1e-9


# ---------------------------------------------------------------------------- bug 1


def test_points_holding_a_vertex_at_two_displacements_are_refused() -> None:
    """Two [[fix]] tables by points giving the same vertices two displacements: refused
    naming both tables, the vertex and its rest position (the last table used to win)."""
    text = _fixes(
        f"points = {END}\ndisplacement = [0.0, 0.0, -0.01]",
        f"points = {END}\ndisplacement = [0.0, 0.0, 0.01]",
    )
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(text).build()
    msg = str(e.value)
    assert e.value.key == "fix[1]"
    assert "fix[1]: moves vertex 0 (at rest [0.0, 0.0, 0.0]) by [0.0, 0.0, 0.01]" in msg
    assert "which fix[0] holds at another position" in msg


def test_the_cli_exits_2_on_conflicting_supports(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``topomech run`` on the reported scene (points, two displacements) exits 2 with the
    message naming both tables, and writes no result."""
    scene = tmp_path / "r1.toml"
    scene.write_text(
        _fixes(
            f"points = {END}\ndisplacement = [0.0, 0.0, -0.01]",
            f"points = {END}\ndisplacement = [0.0, 0.0, 0.01]",
        )
    )
    out = tmp_path / "out"
    assert cli.main(["run", str(scene), "--out", str(out), "--no-preview", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "fix[1]: moves vertex 0" in err
    assert "fix[0]" in err
    assert not (out / "final.vtu").exists()


@pytest.mark.parametrize(
    ("first", "second"),
    [
        (None, None),
        ([0.0, 0.0, 0.01], [0.0, 0.0, 0.01]),
        (None, [0.0, 0.0, 0.0]),
        ([0.0, 0.0, 0.0], None),
    ],
)
def test_points_holding_a_vertex_at_one_position_are_accepted(
    first: list[float] | None, second: list[float] | None
) -> None:
    """Two tables may hold the same vertices at the same position: both in place, the same
    displacement, or in place and a zero displacement (as the kernel accepts between
    predicates); the vertices end there."""

    def table(sel: str, d: list[float] | None) -> str:
        return sel if d is None else f"{sel}\ndisplacement = {d}"

    sim = parse_scene(_fixes(table(f"points = {END}", first), table("points = [0, 6]", second)))
    built = sim.build()
    end = _at_end(built)
    assert built.fixed()[end].all()
    assert built.fixed().sum() == 4
    want = np.zeros(3) if first is None else np.asarray(first)
    rest = built.rest_positions()[end]
    assert np.array_equal(built.positions()[end], rest + want)


@pytest.mark.parametrize(
    ("first", "second", "message"),
    [
        # a predicate held in place, points displaced
        (
            f"where = {WHERE}",
            f"points = {END}\ndisplacement = [0.0, 0.0, 0.01]",
            "fix[1]: moves vertex 0 (at rest [0.0, 0.0, 0.0]) by [0.0, 0.0, 0.01], which "
            "fix[0] holds in place",
        ),
        # points displaced, a predicate held in place after them
        (
            f"points = {END}\ndisplacement = [0.0, 0.0, 0.01]",
            f"where = {WHERE}",
            "fix[1]: holds vertex 0 (at rest [0.0, 0.0, 0.0]) in place, which fix[0] moves "
            "by [0.0, 0.0, 0.01]",
        ),
        # a predicate displaced, points held in place
        (
            f"where = {WHERE}\ndisplacement = [0.0, 0.0, 0.01]",
            "points = [6]",
            "fix[1]: holds vertex 6 (at rest [0.0, 0.2, 0.0]) in place, which fix[0] moves",
        ),
        # a predicate and points at two displacements
        (
            f"where = {WHERE}\ndisplacement = [0.0, 0.0, 0.01]",
            f"points = {END}\ndisplacement = [0.0, 0.0, 0.02]",
            "which fix[0] holds at another position (displacement [0.0, 0.0, 0.01])",
        ),
    ],
)
def test_mixed_where_and_points_at_two_positions_are_refused(
    first: str, second: str, message: str
) -> None:
    """A ``where`` table and a ``points`` table holding shared vertices at two positions
    are refused, whichever comes first, naming both tables (the kernel checks predicates
    only, so this went unnoticed)."""
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(_fixes(first, second)).build()
    assert message in str(e.value)
    assert e.value.key == "fix[1]"


def test_mixed_where_and_points_at_one_displacement_are_accepted() -> None:
    """A ``where`` table and a ``points`` table giving shared vertices the same
    displacement are accepted (one position)."""
    sim = parse_scene(
        _fixes(
            f"where = {WHERE}\ndisplacement = [0.0, 0.0, 0.01]",
            "points = [0, 6]\ndisplacement = [0.0, 0.0, 0.01]",
        )
    ).build()
    end = _at_end(sim)
    assert np.array_equal(sim.positions()[end], sim.rest_positions()[end] + [0.0, 0.0, 0.01])


@pytest.mark.parametrize(
    ("second", "refused"),
    [
        # another float, but 0.2 + it is 0.2 + 0.01: one position
        ([0.0, 0.0, 0.01000000000000001], False),
        ([0.0, 0.0, 0.01 + 1e-12], True),  # no tolerance: another position
    ],
)
def test_points_compare_positions_as_predicates_do(second: list[float], refused: bool) -> None:
    """Points tables are held to the kernel's rule between predicates, tolerance included
    (none: the positions ``rest + d`` are compared exactly, not the displacements): the same
    pair of displacements on the vertices at z = 0.2 is refused, or accepted, in both."""
    a = [0.0, 0.0, 0.01]
    for sel in ('where = "x < 1e-9 && z > 0.1"', "points = [12, 18]"):
        text = _fixes(f"{sel}\ndisplacement = {a}", f"{sel}\ndisplacement = {second}")
        if refused:
            with pytest.raises(topomech.SceneError, match=r"fix\[[01]\]"):
                parse_scene(text).build()
        else:
            sim = parse_scene(text).build()
            top = sim.rest_positions()[:, 2] > 0.1
            assert sim.fixed()[top].sum() == 2


BEAM = """
name = "beam"
[mesh]
file = "beam.msh"
[[model]]
kind = "linear_fem"
[[fix]]
group = "top"
[[fix]]
group = "clamp"
displacement = [0.0, 0.0, 0.01]
[world]
gravity = [0.0, 0.0, 0.0]
[integrator]
kind = "static"
dt = 1.0
steps = 1
"""


def test_groups_holding_shared_vertices_at_two_positions_are_refused(tmp_path: Path) -> None:
    """On the sample beam, ``top`` held in place and ``clamp`` displaced share vertices:
    refused naming both tables (it ran, moving vertices ``top`` holds); ``clamp`` alone
    displaced still runs."""
    (tmp_path / "beam.msh").write_bytes(topomech.sample("beam.msh").read_bytes())
    scene = tmp_path / "beam.toml"
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(BEAM, scene).build()
    assert e.value.key == "fix[1]"
    assert "which fix[0] holds in place" in str(e.value)
    alone = BEAM.replace('[[fix]]\ngroup = "top"\n', "")
    sim = parse_scene(alone, scene).build()
    assert sim.fixed().any()


def _held_sim() -> tuple[topomech.Simulation, Any]:
    """The bar with its end held in place by predicate, and the bar's mask of points 0, 6."""
    sim = parse_scene(_fixes(f"where = {WHERE}")).build()
    return sim, select_vertices(sim, points=[0, 6])


def test_a_refused_support_changes_nothing() -> None:
    """apply_conditions refusing a support leaves the simulation as it was: no hold, no
    position, no load, no initial velocity of the other conditions applied."""
    sim, _ = _held_sim()
    before = (sim.fixed(), sim.positions(), sim.external_forces(), sim.velocities())
    conditions = {
        "held": [
            ("fix[1]", {"points": [23]}, [0.0, 0.01, 0.0]),
            ("fix[2]", {"points": [0, 6]}, [0.0, 0.0, 0.01]),
        ],
        "supports": [
            ("fix[0]", {"where": "x < 1e-9"}, None),
            ("fix[1]", {"points": [23]}, [0.0, 0.01, 0.0]),
            ("fix[2]", {"points": [0, 6]}, [0.0, 0.0, 0.01]),
        ],
        "loads": [("load[0]", {"kind": "point", "force": [1.0, 0, 0], "select": {"points": [5]}})],
        "initial": [("initial", {"velocity": [1.0, 0, 0], "displacement": None, "select": {}})],
    }
    with pytest.raises(LoadError) as e:
        apply_conditions(sim, conditions)
    assert e.value.key == "fix[2]"
    after = (sim.fixed(), sim.positions(), sim.external_forces(), sim.velocities())
    for b, a in zip(before, after):
        assert np.array_equal(b, a)


@pytest.mark.parametrize(
    ("field", "value", "says"),
    [
        ("velocity", [1.0, 2.0], "expected 3 finite numbers"),
        ("velocity", "fast", "must be real numbers"),
        ("displacement", [0.0, float("nan"), 0.0], "expected 3 finite numbers"),
        ("displacement", [True, 0, 0], "boolean"),
        ("displacement", [[0.0, 0.0, 0.0]] * 2, "expected 3 finite numbers"),
    ],
)
def test_an_initial_field_is_checked_before_anything_is_set(
    field: str, value: Any, says: str
) -> None:
    """An ``initial`` velocity or displacement given to apply_conditions directly (not
    through a scene, whose parser checks it) must be 3 finite numbers: before, a wrong one
    failed in numpy after the held vertices had moved, or was broadcast. The refusal names
    the key and field, and changes nothing."""
    sim, _ = _held_sim()
    before = (sim.fixed(), sim.positions(), sim.velocities())
    init = {"velocity": None, "displacement": None, "select": {}}
    init[field] = value
    conditions = {
        "held": [("fix[1]", {"points": [23]}, [0.0, 0.01, 0.0])],
        "initial": [("initial", init)],
    }
    with pytest.raises(LoadError, match=says) as e:
        apply_conditions(sim, conditions)
    assert e.value.key == f"initial.{field}"
    after = (sim.fixed(), sim.positions(), sim.velocities())
    for b, a in zip(before, after):
        assert np.array_equal(b, a)


def test_apply_conditions_without_supports_checks_the_held_vertices() -> None:
    """Given only ``held`` (no ``supports``), apply_conditions still refuses a displacement
    moving a vertex the simulation holds, naming its key, and changes nothing."""
    sim, _ = _held_sim()
    before = sim.positions()
    with pytest.raises(LoadError, match="already held at") as e:
        apply_conditions(sim, {"held": [("fix[1]", {"points": [0]}, [0.0, 0.0, 0.01])]})
    assert e.value.key == "fix[1]"
    assert np.array_equal(sim.positions(), before)


def test_held_positions_moves_a_held_vertex() -> None:
    """held_positions called again moves vertices it holds (a quasi-static loop moving its
    held boundary step by step relies on it); only a scene's conflicting tables are refused,
    by apply_conditions."""
    sim, mask = _held_sim()
    rest = sim.rest_positions()
    held_positions(sim, mask, [0.0, 0.0, 0.01])
    assert np.array_equal(sim.positions()[mask], rest[mask] + [0.0, 0.0, 0.01])
    held_positions(sim, mask, None)
    assert np.array_equal(sim.positions()[mask], rest[mask] + [0.0, 0.0, 0.01])
    assert sim.fixed()[mask].all()


# ---------------------------------------------------------------------------- bug 2


def _gmap(dim: int) -> GMap:
    if dim == 3:
        return GMap.from_flat(*_core.box(2, 1, 1, 1.0, 0.5, 0.5, "tetra"))
    return GMap.from_flat(*_core.grid(2, 1, 1.0, 0.5, "triangle"))


#: (kind, dimension, parameter) of every f64 parameter of every shipped model.
F64_PARAMS = sorted(
    {
        (m.name, min(m.dimensions), p)
        for m in shipped_models()
        for p, ty in m.param_types.items()
        if ty == "f64"
    }
)


def _scene_with_model(kind: str, dim: int, param: str, value: float) -> str:
    mesh = (
        'generator = "box"\nsize = [1.0, 0.5, 0.5]\ncells = [2, 1, 1]'
        if dim == 3
        else 'generator = "grid"\nsize = [1.0, 0.5]\ncells = [2, 1]'
    )
    return f'[mesh]\n{mesh}\n[[model]]\nkind = "{kind}"\n{param} = {value!r}\n'


def test_every_shipped_f64_parameter_is_listed() -> None:
    """The parametrized checks below cover the parameters of every kind (stiffness, damping,
    thickness)."""
    assert {p for _, _, p in F64_PARAMS} >= {"stiffness", "damping", "thickness"}


@pytest.mark.parametrize(("kind", "dim", "param"), F64_PARAMS)
def test_a_negative_model_parameter_is_refused_as_in_a_scene(
    kind: str, dim: int, param: str
) -> None:
    """Every f64 parameter of every shipped model: a negative value is refused by
    Simulation (it was accepted) with the scene's words, naming ``models[0].<param>``, in
    the keyword and the config-dict forms."""
    with pytest.raises(topomech.SceneError) as scene_error:
        parse_scene(_scene_with_model(kind, dim, param, -5.0))
    assert f"model[0].{param}: must be >= 0, got -5.0" in str(scene_error.value)
    with pytest.raises(ValueError, match="must be >= 0") as api_error:
        topomech.Simulation(_gmap(dim), models=[{"kind": kind, param: -5.0}])
    assert str(api_error.value) == f"models[0].{param}: must be >= 0, got -5.0"
    with pytest.raises(ValueError, match="must be >= 0"):
        topomech.Simulation(_gmap(dim), {"models": [{"kind": kind, param: np.float32(-5.0)}]})


def test_the_reported_model_parameters_are_refused() -> None:
    """The report's case: ``stiffness=-5.0, damping=-1.0`` is refused naming the stiffness
    (the first the scene checks); a negative damping alone names the damping."""
    g = _gmap(3)
    with pytest.raises(ValueError, match=r"^models\[0\]\.stiffness: must be >= 0, got -5\.0$"):
        topomech.Simulation(
            g, models=[{"kind": "stretch_cumulated", "stiffness": -5.0, "damping": -1.0}]
        )
    with pytest.raises(ValueError, match=r"^models\[1\]\.damping: must be >= 0, got -1\.0$"):
        topomech.Simulation(
            g, models=["stretch_elementary", {"kind": "stretch_cumulated", "damping": -1.0}]
        )


def test_valid_model_parameters_are_still_accepted() -> None:
    """Zero and positive values (numpy numbers too) are accepted, and the kernel still
    gives its own message for what it refuses itself (a type, a non-finite number)."""
    topomech.Simulation(
        _gmap(3), models=[{"kind": "stretch_cumulated", "stiffness": np.int64(0), "damping": 0.0}]
    )
    topomech.Simulation(_gmap(2), models=[{"kind": "corotational", "thickness": 0.5}])
    with pytest.raises(TypeError, match=r"models\[0\]\['stiffness'\] must be a number"):
        topomech.Simulation(_gmap(3), models=[{"kind": "stretch_cumulated", "stiffness": "a"}])
    with pytest.raises(ValueError, match=r"models\[0\]\['stiffness'\] must be finite"):
        topomech.Simulation(
            _gmap(3), models=[{"kind": "stretch_cumulated", "stiffness": float("nan")}]
        )


def test_a_region_with_no_material_value_is_refused_as_in_a_scene() -> None:
    """A region with only ``where`` is refused by Simulation with the scene's words (it was
    accepted and did nothing); one with a value is accepted."""
    text = BAR + '[[material.region]]\nwhere = "x < 0.5"\n'
    with pytest.raises(topomech.SceneError, match=r"material\.region\[0\]: a region needs"):
        parse_scene(text)
    g = _gmap(3)
    with pytest.raises(
        ValueError, match=r"^regions\[0\]: a region needs density, young or poisson$"
    ):
        topomech.Simulation(g, models=["linear_fem"], regions=[{"where": "x < 0.5"}])
    with pytest.raises(ValueError, match=r"^regions\[1\]: a region needs"):
        topomech.Simulation(
            g,
            {
                "models": ["linear_fem"],
                "regions": [{"where": "x < 0.5", "young": 2e6}, {"where": "x > 0.5"}],
            },
        )
    topomech.Simulation(g, models=["linear_fem"], regions=[{"where": "x < 0.5", "density": 2e3}])
