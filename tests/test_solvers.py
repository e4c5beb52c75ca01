"""The solvers of ``implicit_euler`` and ``static`` from Python and scenes (issue 17): the
``[integrator]`` keys ``linear_solver``, ``preconditioner``, ``tolerance`` and
``max_iterations`` (refused when unknown, out of range or meaningless for the integrator);
``solver.csv`` and the run totals in ``summary.json``; a warning when a linear solve stops at
``max_iterations``; and ``Simulation.stiffness_matrix()`` / ``mass_matrix()`` as scipy CSR
matrices, checked against scikit-fem's assembly on the same mesh, against the forces
themselves, and through a modal analysis whose frequency the dynamics reproduce.

The solvers' agreement with a dense direct solve (1e-8) is tested in Rust
(``crates/physics/tests/it/solvers.rs``); here each solver is run once through the whole
stack."""

from __future__ import annotations

import csv
import json
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg

import topomech
from topomech import cli
from topomech.scene import SceneError, parse_scene

BEAM = """
name = "beam"

[mesh]
generator = "box"
element = "tet"
size = [1.0, 0.2, 0.2]
cells = [5, 1, 1]

[[model]]
kind = "corotational"

[material]
density = 1000.0
young = 1e5
poisson = 0.3

[[fix]]
where = "x < 1e-9"

[integrator]
kind = "implicit_euler"
dt = 0.01
steps = 4
{extra}

[output]
every = 0
"""


def _scene(extra: str = "", kind: str = "implicit_euler") -> str:
    return BEAM.format(extra=extra).replace('kind = "implicit_euler"', f'kind = "{kind}"')


@pytest.mark.parametrize(
    ("extra", "key", "words"),
    [
        ('linear_solvr = "cg"', "integrator.linear_solvr", "did you mean 'linear_solver'"),
        ('linear_solver = "lu"', "integrator.linear_solver", "'auto', 'cg', 'pcg' or 'direct'"),
        ("linear_solver = 3", "integrator.linear_solver", "string"),
        ('preconditioner = "ilu"', "integrator.preconditioner", "'jacobi' or 'block_jacobi'"),
        (
            'linear_solver = "direct"\npreconditioner = "jacobi"',
            "integrator.preconditioner",
            'only used by linear_solver = "pcg"',
        ),
        ("tolerance = 0.0", "integrator.tolerance", "positive"),
        ("tolerance = -1e-6", "integrator.tolerance", "positive"),
        ("tolerance = 1.0", "integrator.tolerance", "below 1"),
        ("tolerance = nan", "integrator.tolerance", "finite"),
        ('tolerance = "1e-6"', "integrator.tolerance", "number"),
        ("max_iterations = 0", "integrator.max_iterations", ">= 1"),
        (
            'linear_solver = "direct"\nmax_iterations = 10',
            "integrator.max_iterations",
            "the direct solver iterates nothing",
        ),
        ("tolerance = 1e-300", "integrator.tolerance", "at least 1e-14"),
        ("max_iterations = 2.5", "integrator.max_iterations", "integer"),
    ],
)
def test_solver_keys_refused_when_unknown_or_out_of_range(extra: str, key: str, words: str) -> None:
    with pytest.raises(SceneError) as e:
        parse_scene(_scene(extra), "beam.toml")
    msg = str(e.value)
    assert key in msg, msg
    assert words in msg, msg


@pytest.mark.parametrize("kind", ["symplectic_euler", "explicit_euler"])
def test_solver_keys_refused_for_the_explicit_integrators(kind: str) -> None:
    with pytest.raises(SceneError) as e:
        parse_scene(_scene('linear_solver = "pcg"', kind), "beam.toml")
    msg = str(e.value)
    assert "integrator.linear_solver" in msg, msg
    assert kind in msg, msg


def test_solver_keys_reach_the_configuration() -> None:
    sc = parse_scene(
        _scene(
            'linear_solver = "pcg"\npreconditioner = "jacobi"\ntolerance = 1e-7\n'
            "max_iterations = 50"
        ),
        "beam.toml",
    )
    assert sc.config["linear_solver"] == "pcg"
    assert sc.config["preconditioner"] == "jacobi"
    assert sc.config["tolerance"] == 1e-7
    assert sc.config["max_iterations"] == 50
    # not given: the kernel's defaults (no entry)
    sc = parse_scene(_scene(), "beam.toml")
    assert "linear_solver" not in sc.config
    assert "tolerance" not in sc.config


def _run(
    tmp_path: Path, extra: str, kind: str = "implicit_euler", young: str = "1e5"
) -> tuple[int, dict[str, Any], str]:
    scene = tmp_path / "beam.toml"
    scene.write_text(_scene(extra, kind).replace("young = 1e5", f"young = {young}"))
    out = tmp_path / "out"
    code = cli.main(["run", str(scene), "--out", str(out), "--no-preview", "--quiet"])
    return code, json.loads((out / "summary.json").read_text()), str(out)


@pytest.mark.parametrize(
    ("solver", "preconditioner"),
    [("cg", None), ("pcg", "jacobi"), ("pcg", "block_jacobi"), ("direct", None), ("auto", None)],
)
def test_each_solver_runs_and_reports_per_step(
    tmp_path: Path, solver: str, preconditioner: str | None
) -> None:
    extra = f'linear_solver = "{solver}"'
    if preconditioner is not None:
        extra += f'\npreconditioner = "{preconditioner}"'
    code, summary, out = _run(tmp_path, extra)
    assert code == 0, summary.get("error")
    s = summary["solver"]
    assert s["integrator"] == "implicit_euler"
    if solver != "auto":
        assert s["linear_solver"] == solver
    expected_pc = preconditioner if solver == "pcg" else "none"
    if solver != "auto":
        assert s["preconditioner"] == expected_pc
    assert s["steps_solved"] == 4
    assert s["steps_not_converged"] == 0
    assert s["converged"] is True
    assert s["tolerance"] == 1e-6  # the implicit default
    assert summary["outputs"]["solver"] == "solver.csv"
    with (Path(out) / "solver.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["step"]) for r in rows] == [1, 2, 3, 4]
    assert all(r["converged"] == "1" for r in rows)
    assert all(float(r["relative_residual"]) <= 1e-6 for r in rows)
    assert sum(int(r["linear_iterations"]) for r in rows) == s["total_linear_iterations"]
    if solver == "direct":
        assert s["total_linear_iterations"] == 0
    elif solver != "auto":
        assert all(int(r["linear_iterations"]) >= 1 for r in rows)


def test_solvers_agree_on_the_implicit_step(tmp_path: Path) -> None:
    """Every solver gives the same positions after 4 implicit Euler steps: the linear
    systems are solved to a relative residual of 1e-10 (their condition number here is
    below 1e3, so the solutions agree to about 1e-7 of the displacement)."""
    finals = {}
    for solver in ("cg", "pcg", "direct"):
        sim = parse_scene(
            _scene(f'linear_solver = "{solver}"\ntolerance = 1e-10'), "beam.toml"
        ).build()
        sim.step(4)
        finals[solver] = sim.displacements()
    scale = np.abs(finals["direct"]).max()
    assert scale > 1e-6
    for solver in ("cg", "pcg"):
        assert np.abs(finals[solver] - finals["direct"]).max() <= 1e-7 * scale


def test_unmet_tolerance_warns_and_is_reported(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One conjugate-gradient iteration cannot solve the system to 1e-6: every step is
    taken with the approximate solution, counted as not converged, and the run ends with one
    SolverWarning (a note on the command line)."""
    code, summary, _ = _run(tmp_path, 'linear_solver = "cg"\nmax_iterations = 1')
    err = capsys.readouterr().err
    assert code == 0, summary.get("error")
    s = summary["solver"]
    assert s["steps_not_converged"] == 4
    assert s["converged"] is False
    assert s["max_relative_residual"] > 1e-6
    assert "(cg) did not reach its tolerance in 4 of 4 steps" in err, err
    assert 'linear_solver = "pcg" or "direct"' in err, err
    assert "max_iterations" in err
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        topomech.run_scene(
            parse_scene(_scene('linear_solver = "cg"\nmax_iterations = 1'), "beam.toml"),
            tmp_path / "again",
            preview=False,
        )
    assert [w.category for w in caught] == [topomech.SolverWarning]


def test_static_run_reports_newton_and_linear_iterations(tmp_path: Path) -> None:
    # stiff enough for a small deflection under its weight (about 4 mm)
    code, summary, out = _run(tmp_path, 'linear_solver = "pcg"', kind="static", young="1e8")
    assert code == 0, summary.get("error")
    s = summary["solver"]
    assert s["integrator"] == "static"
    assert s["linear_solver"] == "pcg"
    assert s["relative_residual"] <= 1e-10
    with (Path(out) / "solver.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 4
    # the first step finds the equilibrium (Newton, each iteration a PCG solve); the next
    # ones start there
    first = rows[0]
    assert int(first["iterations"]) >= 1
    assert int(first["linear_iterations"]) >= int(first["iterations"])
    assert s["total_iterations"] == sum(int(r["iterations"]) for r in rows)


# ---------------------------------------------------------------------- matrices


def _box(nx: int, ny: int, nz: int, sx: float, sy: float, sz: float) -> topomech.GMap:
    return topomech.GMap.from_flat(*topomech._core.box(nx, ny, nz, sx, sy, sz, "tetra"))


def _linear_sim(g: topomech.GMap, **kw: Any) -> topomech.Simulation:
    return topomech.Simulation(
        g,
        models=["linear_fem"],
        density=1000.0,
        young=1e6,
        poisson=0.3,
        gravity=[0.0, 0.0, 0.0],
        **kw,
    )


def _skfem_stiffness(points: np.ndarray, tets: np.ndarray, e: float, nu: float) -> Any:
    """Linear elasticity's P1 stiffness on the same mesh, by scikit-fem, in the dof order
    3 * vertex + axis."""
    skfem = pytest.importorskip("skfem")
    from skfem.helpers import ddot, sym_grad, trace

    mesh = skfem.MeshTet(points.T.copy(), tets.T.copy())
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP1()))
    lam = e * nu / ((1 + nu) * (1 - 2 * nu))
    mu = e / (2 * (1 + nu))

    @skfem.BilinearForm
    def stiffness(u: Any, v: Any, _w: Any) -> Any:
        eu, ev = sym_grad(u), sym_grad(v)
        return lam * trace(eu) * trace(ev) + 2 * mu * ddot(eu, ev)

    k = skfem.asm(stiffness, basis).tocsr()
    order = basis.nodal_dofs.T.reshape(-1)  # dof of (vertex, axis), vertex-major
    return k[order][:, order]


def test_stiffness_matrix_equals_scikit_fem_on_the_same_mesh() -> None:
    """linear_fem's assembled K equals scikit-fem's P1 linear-elasticity stiffness on the
    same tetrahedra (both exact integrals of constant-strain elements: they differ by
    rounding, 1e-10 of the largest entry)."""
    g = _box(3, 2, 2, 1.0, 0.5, 0.5)
    sim = _linear_sim(g)
    k = sim.stiffness_matrix()
    assert isinstance(k, scipy.sparse.csr_matrix)
    n = sim.n_vertices
    assert k.shape == (3 * n, 3 * n)
    _, cells = sim.elements()
    tets = np.array([c for c in cells if len(c) == 4])
    ref = _skfem_stiffness(sim.rest_positions(), tets, 1e6, 0.3)
    diff = abs(k - ref).max()
    assert diff <= 1e-10 * abs(ref).max(), diff


def test_stiffness_matrix_is_the_force_jacobian() -> None:
    """K (x - X) = -f for linear FEM (linear in x: exact up to rounding), K is symmetric,
    and rigid translations are in its null space; for co-rotational tetrahedra at rest it
    is the same matrix."""
    g = _box(3, 2, 2, 1.0, 0.5, 0.5)
    sim = _linear_sim(g)
    rng = np.random.default_rng(7)
    u = 1e-3 * rng.standard_normal((sim.n_vertices, 3))
    sim.set_positions(sim.rest_positions() + u)
    k = sim.stiffness_matrix()
    f = sim.forces()
    assert np.abs(k @ u.reshape(-1) + f.reshape(-1)).max() <= 1e-9 * np.abs(f).max()
    assert abs(k - k.T).max() <= 1e-10 * abs(k).max()
    t = np.tile([1.0, 0.0, 0.0], sim.n_vertices)
    assert np.abs(k @ t).max() <= 1e-9 * abs(k).max()
    corot = topomech.Simulation(
        g, models=["corotational"], young=1e6, poisson=0.3, gravity=[0.0, 0.0, 0.0]
    )
    k0 = _linear_sim(g).stiffness_matrix()
    assert abs(corot.stiffness_matrix() - k0).max() <= 1e-9 * abs(k0).max()


def test_mass_matrix_is_the_lumped_mass() -> None:
    sim = _linear_sim(_box(3, 2, 2, 1.0, 0.5, 0.5))
    m = sim.mass_matrix()
    assert isinstance(m, scipy.sparse.csr_matrix)
    assert m.nnz == 3 * sim.n_vertices
    assert np.array_equal(m.diagonal(), np.repeat(sim.masses(), 3))
    assert math.isclose(m.diagonal().sum(), 3 * 1000.0 * 0.25, rel_tol=1e-12)


def _first_mode(sim: topomech.Simulation) -> tuple[float, np.ndarray]:
    """The lowest angular frequency (rad/s) of the held beam and its mode shape ``(V, 3)``,
    from K u = w^2 M u on the free degrees of freedom by eigsh (shift-invert at 0)."""
    free = ~np.repeat(sim.fixed(), 3)
    k = sim.stiffness_matrix()[free][:, free]
    m = sim.mass_matrix()[free][:, free]
    w2, vecs = scipy.sparse.linalg.eigsh(k, k=1, M=m, sigma=0.0, which="LM")
    shape = np.zeros(3 * sim.n_vertices)
    shape[free] = vecs[:, 0]
    return math.sqrt(w2[0]), shape.reshape(-1, 3)


def test_modal_frequency_is_what_the_dynamics_do() -> None:
    """The first bending frequency from the matrices (eigsh) is the one the simulation
    itself oscillates at: started in that mode shape (small amplitude, no gravity, no
    damping), symplectic Euler's tip displacement crosses zero at the half periods pi / w.
    Symplectic Euler shifts the frequency by O((w dt)^2) ~ 1e-5 here, and the zero crossing
    is interpolated linearly between steps: the measured period agrees to 1e-3. The
    frequency is also the one scikit-fem's stiffness gives with the same lumped mass (1e-8),
    and above Euler-Bernoulli's (linear tetrahedra are stiffer in bending) by less than a
    factor 2."""
    g = _box(8, 1, 1, 1.0, 0.125, 0.125)
    dt = 2e-4
    sim = _linear_sim(g, fixed=["x < 1e-9"], integrator="symplectic_euler", dt=dt)
    w, shape = _first_mode(sim)
    tip = int(np.argmax(np.abs(shape[:, 1])))
    sim.set_positions(sim.rest_positions() + 1e-4 * shape / np.abs(shape).max())
    y = [1e-4 * shape[tip, 1] / np.abs(shape).max()]
    crossings: list[float] = []
    while len(crossings) < 2:
        sim.step()
        y.append(sim.displacements()[tip, 1])
        if y[-2] * y[-1] < 0:
            frac = y[-2] / (y[-2] - y[-1])
            crossings.append((len(y) - 2 + frac) * dt)
        assert len(y) < 20 * math.pi / (w * dt), "no oscillation"
    half_period = crossings[1] - crossings[0]
    assert abs(half_period - math.pi / w) <= 1e-3 * math.pi / w
    # scikit-fem's stiffness, the same lumped mass
    free = ~np.repeat(sim.fixed(), 3)
    _, cells = sim.elements()
    tets = np.array([c for c in cells if len(c) == 4])
    kref = _skfem_stiffness(sim.rest_positions(), tets, 1e6, 0.3)[free][:, free]
    m = sim.mass_matrix()[free][:, free]
    w2 = scipy.sparse.linalg.eigsh(kref, k=1, M=m, sigma=0.0, which="LM")[0][0]
    assert abs(math.sqrt(w2) - w) <= 1e-8 * w
    # Euler-Bernoulli cantilever: w1 = 1.8751^2 sqrt(E I / (rho A L^4)), I / A = h^2 / 12
    eb = 1.8751**2 * math.sqrt(1e6 * 0.125**2 / 12 / 1000.0)
    assert eb < w < 2 * eb, (w, eb)


def _heavy_cantilever(**kw: Any) -> topomech.Simulation:
    """A spring cantilever (6 x 1 x 1 cubes of tetrahedra, 2 m long) clamped at x = 0, no
    gravity: the load is set on its tip by the caller."""
    flat = topomech._core.box(6, 1, 1, 2.0, 0.25, 0.25, "tetra")
    return topomech.Simulation(
        topomech.GMap.from_flat(*flat),
        models=[{"kind": "stretch_elementary", "stiffness": 1e3}],
        gravity=[0.0, 0.0, 0.0],
        fixed=["x < 1e-9"],
        integrator="static",
        dt=1.0,
        **kw,
    )


def _tip_load(sim: topomech.Simulation, total: float) -> np.ndarray:
    load = np.zeros((sim.n_vertices, 3))
    tip = sim.rest_positions()[:, 0] > 2.0 - 1e-9
    load[tip, 1] = -total / tip.sum()
    return load


@pytest.mark.parametrize("solver", ["direct", "pcg"])
def test_load_stepping_equals_a_solve_in_100_small_load_steps(solver: str) -> None:
    """A tip load large enough that Newton from rest fails on the whole load (the report
    says the solve took several load increments) converges by automatic load stepping, and
    lands where 100 static steps of 1/100 of the load each land: the same equilibrium
    branch, to 1e-8 of the deflection (both solved to a relative residual of 1e-12, and the
    stiffness there is well conditioned: a few ulps of the forces move the solution by
    less). The residual is reported."""
    heavy = 40.0
    one = _heavy_cantilever(linear_solver=solver, tolerance=1e-12)
    one.set_external_forces(_tip_load(one, heavy))
    one.step()
    report = one.solver_report()
    assert report is not None
    assert report["converged"] is True
    assert report["load_steps"] > 1, report  # one Newton solve of the whole load failed
    assert report["relative_residual"] <= 1e-12
    assert report["linear_solver"] == solver

    ramp = _heavy_cantilever(linear_solver=solver, tolerance=1e-12)
    for k in range(1, 101):
        ramp.set_external_forces(_tip_load(ramp, heavy * k / 100))
        ramp.step()
        r = ramp.solver_report()
        assert r is not None
        assert r["converged"], (k, r)
    deflection = np.abs(one.displacements()).max()
    assert deflection > 0.5  # large: the nonlinear regime
    diff = np.abs(one.positions() - ramp.positions()).max()
    assert diff <= 1e-8 * deflection, diff


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"integrator": "explicit_euler", "linear_solver": "cg"}, "linear_solver: only used"),
        ({"integrator": "symplectic_euler", "tolerance": 1e-3}, "tolerance: only used"),
        (
            {"integrator": "implicit_euler", "linear_solver": "cg", "preconditioner": "jacobi"},
            "preconditioner: only used by linear_solver='pcg'",
        ),
        (
            {"integrator": "static", "linear_solver": "direct", "max_iterations": 5},
            "max_iterations: the direct solver iterates nothing",
        ),
    ],
)
def test_python_refuses_solver_keys_that_would_be_ignored(
    kwargs: dict[str, Any], words: str
) -> None:
    g = _box(2, 1, 1, 1.0, 0.5, 0.5)
    with pytest.raises(topomech.SimulationError, match=words):
        topomech.Simulation(g, models=["linear_fem"], **kwargs)


def test_python_takes_numpy_integers_and_refuses_tiny_tolerances() -> None:
    g = _box(2, 1, 1, 1.0, 0.5, 0.5)
    sim = topomech.Simulation(
        g, models=["linear_fem"], integrator="implicit_euler", max_iterations=np.int64(5)
    )
    sim.step()
    with pytest.raises(topomech.SimulationError, match="1e-14"):
        topomech.Simulation(g, models=["linear_fem"], integrator="static", tolerance=1e-300)


def test_simulation_step_warns_when_a_solve_stops_above_its_tolerance() -> None:
    """Simulation.step() itself (not only topomech run) says when an implicit Euler step
    was taken with a linear solve stopped at max_iterations: one SolverWarning per call."""
    sim = parse_scene(_scene('linear_solver = "cg"\nmax_iterations = 1'), "beam.toml").build()
    with pytest.warns(topomech.SolverWarning, match="3 of the 3 steps did not reach"):
        sim.step(3)
    report = sim.solver_report()
    assert report is not None
    assert report["not_converged_steps"] == 3
    good = parse_scene(_scene(), "beam.toml").build()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        good.step(3)  # converged: no warning


def test_matrices_refused_for_a_model_without_jacobian_rules() -> None:
    """A model without jvp rules would be missing from the matrix (silently zero): refused,
    naming it."""
    g = topomech.GMap.from_flat(*topomech._core.grid(3, 3, 1.0, 1.0, "triangle"))
    sim = topomech.Simulation(g, models=["bending_angular", "stretch_cumulated"])
    with pytest.raises(topomech.SimulationError, match="model 'bending_angular' has no Jacobian"):
        sim.stiffness_matrix()


def test_failed_static_step_is_in_solver_csv(tmp_path: Path) -> None:
    """A static step that fails ends the run (exit 1); solver.csv and the summary's totals
    still have its row."""
    code, summary, out = _run(tmp_path, 'linear_solver = "cg"\nmax_iterations = 1', "static")
    assert code == 1
    s = summary["solver"]
    assert s["steps_solved"] == 1
    assert s["steps_not_converged"] == 1
    with (Path(out) / "solver.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["step"], r["converged"]) for r in rows] == [("1", "0")]


def test_a_static_solve_failing_on_capped_linear_solves_says_so() -> None:
    """A static solve whose Newton directions come from conjugate-gradient solves stopped at
    `max_iterations` (3 here, on a linear beam under its weight that one direct solve
    balances) fails naming that cause and what to change, not the load (QA: the message
    said to try a smaller load or a finer mesh)."""
    g = topomech.GMap.from_flat(*topomech._core.box(6, 2, 2, 1.0, 0.2, 0.2, "tetra"))
    sim = topomech.Simulation(
        g,
        models=["linear_fem"],
        integrator="static",
        linear_solver="pcg",
        max_iterations=3,
        dt=1.0,
        young=1e6,
        gravity=[0, 0, -9.81],
        fixed=["x < 1e-9"],
    )
    with pytest.raises(topomech.DivergenceError) as e:
        sim.step()
    assert "linear solve stopped at max_iterations (3)" in str(e.value)
    assert "raise integrator.max_iterations, or use the direct solver" in str(e.value)
    assert "try a smaller load" not in str(e.value)
