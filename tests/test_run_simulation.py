"""The Simulation bindings: building from a map and a model list, stepping, arrays in and out,
errors at the boundary and from the kernel."""

from __future__ import annotations

import numpy as np
import pytest

import topomech
from topomech import _core


def beam(nx: int = 4, element: str = "tetra") -> topomech.GMap:
    return topomech.GMap.from_flat(*_core.box(nx, 1, 1, 1.0, 0.2, 0.2, element))


def plate() -> topomech.GMap:
    return topomech.GMap.from_flat(*_core.grid(4, 2, 1.0, 0.5, "triangle"))


def springs(g: topomech.GMap | None = None, **kw: object) -> topomech.Simulation:
    cfg: dict[str, object] = {
        "models": [{"kind": "stretch_elementary", "stiffness": 1e3}],
        "density": 2.0,
        "fixed": ["x < 1e-9"],
        "integrator": "symplectic_euler",
        "dt": 1e-3,
    }
    cfg.update(kw)
    return topomech.Simulation(g if g is not None else plate(), **cfg)


def test_exception_hierarchy() -> None:
    assert issubclass(topomech.SimulationError, topomech.TopomechError)
    assert issubclass(topomech.DivergenceError, topomech.SimulationError)
    assert issubclass(topomech.SceneError, topomech.TopomechError)
    assert not issubclass(topomech.SceneError, topomech.SimulationError)


def test_round_trip_arrays() -> None:
    g = plate()
    sim = springs(g)
    v = g.cell_counts()["vertices"]
    assert sim.n_vertices == v
    assert sim.dimension == 2
    for a in (sim.positions(), sim.velocities(), sim.rest_positions(), sim.forces()):
        assert a.shape == (v, 3)
        assert a.dtype == np.float64
    assert sim.masses().shape == (v,)
    assert sim.fixed().dtype == np.bool_
    assert sim.fixed().sum() == 3  # the left side of a 4 x 2 grid
    assert sim.momentum().shape == (3,)
    assert np.array_equal(sim.positions(), g.positions())
    assert sim.total_mass() == pytest.approx(2.0 * 1.0 * 0.5)
    assert sim.kinetic_energy() == 0.0


def test_step_moves_free_vertices_only() -> None:
    sim = springs()
    version = sim.topology_version
    sim.step(3)
    assert sim.topology_version == version  # no topology change
    assert sim.steps == 3
    assert sim.time == pytest.approx(3e-3)
    d = sim.displacements()
    held = sim.fixed()
    assert np.all(d[held] == 0.0)
    assert np.all(d[~held][:, 1] < 0)  # falling under gravity
    assert sim.kinetic_energy() > 0
    assert sim.momentum()[1] < 0
    sim.step(0)
    assert sim.steps == 3


def test_the_simulation_owns_a_copy_of_the_map() -> None:
    g = plate()
    before = g.positions().copy()
    names = g.embedding_names()
    sim = springs(g)
    sim.step(5)
    assert np.array_equal(g.positions(), before)
    assert g.embedding_names() == names
    copy = sim.gmap()
    assert isinstance(copy, topomech.GMap)
    assert copy.cell_counts() == g.cell_counts()
    assert np.array_equal(copy.positions(), sim.positions())
    assert "mass" in copy.embedding_names()


def test_config_dict_and_core_map() -> None:
    g = beam()
    sim = topomech.Simulation(
        g.core,
        {"models": ["corotational"], "young": 1e6, "poisson": 0.3, "density": 1000.0},
        fixed="x < 1e-9",
        integrator="implicit_euler",
        dt=1e-2,
    )
    assert sim.integrator == "implicit_euler"
    assert sim.dt == 1e-2
    assert sim.total_mass() == pytest.approx(1000.0 * 1.0 * 0.2 * 0.2)
    sim.step()
    assert np.isfinite(sim.positions()).all()


@pytest.mark.parametrize("element", ["tetra", "hexahedron", "wedge", "pyramid", "mixed"])
def test_total_mass_is_density_times_volume(element: str) -> None:
    sim = topomech.Simulation(
        topomech.GMap.from_flat(*_core.box(3, 2, 1, 1.5, 1.0, 0.5, element)),
        models=[{"kind": "stretch_cumulated", "stiffness": 10.0}],
        density=3.0,
    )
    assert sim.total_mass() == pytest.approx(3.0 * 1.5 * 1.0 * 0.5, rel=1e-12)
    assert sim.masses().sum() == pytest.approx(sim.total_mass())


def test_set_positions_and_velocities() -> None:
    sim = springs()
    x = sim.positions() + np.array([0.0, 0.0, 0.1])
    sim.set_positions(x)
    assert np.array_equal(sim.positions(), x)
    ones = np.ones((sim.n_vertices, 3))
    ones[sim.fixed()] = 0.0  # a held vertex keeps zero velocity
    sim.set_velocities(ones.tolist())  # array-like: converted
    assert np.array_equal(sim.velocities(), ones)
    with pytest.raises(
        ValueError, match=r"positions must have shape \(V, 3\) = \(15, 3\), got \(2, 3\)"
    ):
        sim.set_positions(np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"must have shape \(V, 3\), got \(15,\)"):
        sim.set_velocities(np.zeros(15))
    bad = sim.positions()
    bad[4, 1] = np.nan
    with pytest.raises(ValueError, match="positions must be finite: row 4"):
        sim.set_positions(bad)
    with pytest.raises(TypeError, match="dtype float64"):
        sim.core.set_positions(np.zeros((15, 3), dtype=np.int64))


def test_vertex_embeddings() -> None:
    sim = springs()
    assert np.array_equal(sim.vertex_field("mass"), sim.masses())
    assert np.array_equal(sim.vertex_field("position"), sim.positions())
    assert np.array_equal(sim.vertex_field("fixed"), sim.fixed())
    with pytest.raises(topomech.EmbeddingError, match="not on the vertex orbit <1,2>"):
        sim.vertex_field("spring_k")
    with pytest.raises(topomech.EmbeddingError, match="nope"):
        sim.vertex_field("nope")


def test_forces_are_zero_at_rest_and_restoring_when_stretched() -> None:
    sim = springs()
    assert np.allclose(sim.forces(), 0.0)
    x = sim.rest_positions()
    x[:, 0] *= 1.1  # stretch along x
    sim.set_positions(x)
    f = sim.forces()
    right = x[:, 0] == x[:, 0].max()
    assert np.all(f[right][:, 0] < 0)


def test_prescribed_and_regions() -> None:
    sim = topomech.Simulation(
        beam(),
        models=["linear_fem"],
        fixed=["x < 1e-9"],
        prescribed=[("x > 1 - 1e-9", [0.0, -0.01, 0.0])],
        regions=[{"where": "x > 0.5", "density": 2000.0}],
        density=1000.0,
    )
    held = sim.fixed()
    assert held.sum() == 8
    tip = sim.rest_positions()[:, 0] > 1 - 1e-9
    assert np.allclose(sim.displacements()[tip], [0.0, -0.01, 0.0])
    assert sim.total_mass() == pytest.approx(0.04 * (0.5 * 1000.0 + 0.5 * 2000.0))


@pytest.mark.parametrize(
    ("kw", "exc", "message"),
    [
        ({"models": ["spring"]}, topomech.SimulationError, "unknown model 'spring' (known: "),
        ({"models": []}, topomech.SimulationError, "no model given"),
        ({"models": [{"stiffness": 1.0}]}, ValueError, "models[0] has no 'kind'"),
        ({"models": [3]}, TypeError, "models[0] must be a model kind (str) or a dict"),
        (
            {"models": ["linear_fem"]},
            topomech.SimulationError,
            "needs a mesh of dimension 3, this one",
        ),
        (
            {"models": [{"kind": "stretch_elementary", "stifness": 1.0}]},
            topomech.SimulationError,
            "has no parameter 'stifness'",
        ),
        (
            {"models": [{"kind": "stretch_elementary", "young": 1e6}]},
            topomech.SimulationError,
            "has no parameter 'young' (it has: stiffness, damping): 'young' is the material's, "
            "read by the continuous models (declared per_element: corotational, linear_fem, "
            "...) only; this model does not use it",
        ),
        (
            {"models": [{"kind": "stretch_elementary", "params": {"stiffness": 1.0}}]},
            TypeError,
            "models[0]['params']: a model parameter is a real or 3 reals, got dict",
        ),
        (
            {"fixed": ["x < 4/3"]},
            topomech.SimulationError,
            "a quotient of two integers is an integer in the rule language (4/3 is 1",
        ),
        ({"dt": -1.0}, ValueError, "dt must be positive, got -1"),
        ({"dt": "big"}, TypeError, "dt must be a number, got str"),
        ({"dt": True}, TypeError, "dt must be a number, got bool"),
        ({"density": float("nan")}, ValueError, "density must be finite"),
        ({"gravity": [0.0, 1.0]}, ValueError, "gravity must be 3 numbers, got 2"),
        ({"integrator": "rk4"}, ValueError, "unknown integrator 'rk4'"),
        ({"fixed": ["x <"]}, topomech.SimulationError, "bad fixed-vertex predicate"),
        ({"fixed": ["x < -5"]}, topomech.SimulationError, "selects no vertex"),
        ({"fixed": [3]}, TypeError, "fixed[0] must be a str"),
        ({"regions": [{"where": "x > 0", "stiffness": 1.0}]}, TypeError, "unknown key 'stiffness'"),
        (
            {"prescribed": [("x < 1e-9",)]},
            ValueError,
            "prescribed[0] must be (predicate, [dx, dy, dz]), got 1 items",
        ),
        ({"densty": 1.0}, TypeError, "unknown configuration key 'densty'"),
    ],
)
def test_bad_configurations(kw: dict[str, object], exc: type[Exception], message: str) -> None:
    with pytest.raises(exc) as info:
        springs(**kw)
    assert message in str(info.value)


@pytest.mark.parametrize(("key", "value"), [("young", 1e5), ("poisson", 0.3)])
def test_material_key_in_a_continuous_model_says_how_to_set_it_from_python(
    key: str, value: float
) -> None:
    """A continuous model's dict with young or poisson is refused with advice a Python caller
    can follow (the simulation's keyword, or a region) and the scene's two places for it
    ([material], or the [[model]] table as the README's beam.toml has it) named correctly:
    before, the message sent everyone to a scene's [material] only."""
    with pytest.raises(topomech.SimulationError) as info:
        topomech.Simulation(beam(), models=[{"kind": "corotational", key: value}])
    msg = str(info.value)
    assert f"model 'corotational' has no parameter '{key}'" in msg, msg
    assert "it is set on the simulation, not in a model's parameters" in msg, msg
    assert f"Python: Simulation(..., {key}=...)" in msg, msg
    assert f'regions=[{{"where": ..., "{key}": ...}}]' in msg, msg
    assert f"or {key} = ... in the model's [[model]] table, which sets the material's" in msg
    # the advice works: the material given to the simulation
    sim = topomech.Simulation(beam(), models=["corotational"], **{key: value})
    sim.step()


def test_key_in_config_and_keywords() -> None:
    with pytest.raises(TypeError, match="'dt' is given both in config and as a keyword"):
        topomech.Simulation(plate(), {"models": ["stretch_elementary"], "dt": 1.0}, dt=2.0)


def test_not_a_map() -> None:
    with pytest.raises(TypeError, match=r"gmap must be a topomech\.GMap"):
        topomech.Simulation("beam.msh", models=["corotational"])  # type: ignore[arg-type]


def test_a_key_given_none_keeps_its_default() -> None:
    """`events=None` as `ground=None`: every configuration key given None is left at its
    default (the simulation is the one built without it)."""
    keys = ["events", "prescribed", "regions", "fracture", "ground", "model_files"]
    sim = springs(**dict.fromkeys(keys), gravity=[0.0, -9.81, 0.0])
    plain = springs(gravity=[0.0, -9.81, 0.0])
    sim.step(3)
    plain.step(3)
    assert np.array_equal(sim.positions(), plain.positions())
    # `fixed=None`: the default, nothing held
    assert springs(fixed=None).fixed().sum() == 0 < plain.fixed().sum()


def test_negative_step_count() -> None:
    with pytest.raises(ValueError, match="n must be >= 0, got -1"):
        springs().step(-1)


def test_divergence_keeps_the_last_good_state() -> None:
    sim = springs(
        models=[{"kind": "stretch_elementary", "stiffness": 1e6}],
        integrator="explicit_euler",
        dt=0.1,
    )
    with pytest.raises(topomech.DivergenceError) as info:
        sim.step(1000)
    e = info.value
    assert isinstance(e, topomech.SimulationError)
    assert e.step == sim.steps + 1
    assert 0 <= e.vertex < sim.n_vertices
    assert e.why
    assert f"diverged at step {e.step}" in str(e)
    assert f"at vertex row {e.vertex} (input point {e.point})" in str(e)
    assert e.point == sim.point_ids()[e.vertex]
    assert np.isfinite(sim.positions()).all()
    assert np.isfinite(sim.velocities()).all()


def test_divergence_names_the_input_point_where_it_differs_from_the_row() -> None:
    # the plate's points after two points no cell uses: every row is its input point plus
    # two, and the message names both (the row indexes positions(); the point, the mesh)
    points, kinds, offsets, connectivity = _core.grid(4, 2, 1.0, 0.5, "triangle")
    points = np.asarray(points)
    points = np.vstack([np.full((2, points.shape[1]), 9.0), points])
    g = topomech.GMap.from_flat(points, kinds, offsets, np.asarray(connectivity) + 2)
    assert g.report.unused_points == [0, 1]
    sim = springs(
        g,
        models=[{"kind": "stretch_elementary", "stiffness": 1e6}],
        integrator="explicit_euler",
        dt=0.1,
    )
    assert (sim.point_ids() == np.arange(sim.n_vertices) + 2).all()
    with pytest.raises(topomech.DivergenceError) as info:
        sim.step(1000)
    e = info.value
    assert e.vertex is not None
    assert e.point == e.vertex + 2
    assert f"at vertex row {e.vertex} (input point {e.point})" in str(e)


def test_repr() -> None:
    sim = springs()
    assert repr(sim).startswith("topomech.Simulation(dimension=2, vertices=15")
    assert repr(sim.core).startswith("<topomech._core.Simulation dimension=2")


def test_available_models() -> None:
    models = topomech.available_models()
    springs = [m for m in models if m["kind"] == "stretch_elementary"]
    assert springs == [
        {
            "kind": "stretch_elementary",
            "dims": [2, 3],
            "params": {"stiffness": 1000.0, "damping": 0.0},
            "needs": "edges",
            "per_element": False,
        }
    ]
    assert any(m["kind"] == "corotational" and 3 in m["dims"] for m in models)
    assert all(m["per_element"] for m in models if m["kind"] in ("corotational", "linear_fem"))


def test_a_real_quotient_in_a_predicate_is_accepted() -> None:
    """`x < 4.0/3` is the real quotient (every vertex of the plate, x <= 1); `x < 4/3` is
    refused (above) rather than read as `x < 1`."""
    sim = springs(fixed=["x < 4.0/3 && y < -1 / 3.0 + 1"])
    assert sim.fixed().sum() > 0


@pytest.mark.parametrize(
    "pred",
    [
        "x < 2*2/3",
        "x < (1+3)/3",
        "x < abs(-4)/3",
        "x < 4/--3",
        "let k = 3; x < 1/k",
        "x < clamp(4, 0, 9)/3",
        "x < select(true, 4, 5)/3",
        "x < { let a = 4; a }/3",
        "x < to_i64(4.0)/3",
        "x < sign(4)/sign(3)",
        "x < (if y > 0.0 { 4 } else { 5 })/3",
    ],
)
def test_an_integer_quotient_in_a_predicate_is_refused(pred: str) -> None:
    """Operands the rule language types i64 (literals, integer `let` names, arithmetic and
    built-ins by their signatures): their quotient is an integer (read as `x < 1` or
    `x < 0`), so the predicate is refused."""
    with pytest.raises(topomech.SimulationError, match="a quotient of two integers"):
        springs(fixed=[pred])


def test_a_quotient_by_a_real_let_is_accepted() -> None:
    """`let k = 3.0` is a real: `1/k` is the real quotient; a real binding shadows an
    integer one of the same name."""
    springs(fixed=["let k = 3.0; x < 1/k + 0.5"])
    springs(fixed=["let k = 3; let k = 3.0; x < 1/k + 0.5"])
    # reals by the built-ins' signatures: real quotients
    springs(fixed=["x < to_f64(4)/3", "x < clamp(4.0, 0.0, 9.0)/3", "x < floor(4.5)/3"])
