"""Edges of the divergence test of a step (found by QA): a load whose square overflows is a
divergence for implicit Euler's iterative solvers too (not a step taken with a NaN residual);
a fast vertex over a tiny time step is no runaway when its motion is small (the speed is
computed without overflow); a built-in refusing a non-finite argument (``polar``) names a
vertex like a non-finite value does."""

from __future__ import annotations

import numpy as np
import pytest

import topomech
from topomech import DivergenceError, Simulation


@pytest.fixture(scope="module")
def beam() -> topomech.GMap:
    g, _ = topomech.read_gmap(topomech.sample("beam.msh"))
    return g


@pytest.mark.parametrize("solver", ["cg", "pcg", "auto"])
def test_implicit_euler_refuses_a_load_whose_square_overflows(
    beam: topomech.GMap, solver: str
) -> None:
    sim = Simulation(
        beam,
        models=["linear_fem"],
        dt=1e-3,
        integrator="implicit_euler",
        linear_solver=solver,
        gravity=[0, 0, 0],
        fixed=["x < 1e-9"],
    )
    f = np.zeros((sim.n_vertices, 3))
    f[50] = [0.0, 0.0, 1e200]  # its square is beyond f64
    sim.set_external_forces(f)
    p0, v0 = sim.positions().copy(), sim.velocities().copy()
    with pytest.raises(DivergenceError) as e:
        sim.step()
    assert "no finite result" in str(e.value)
    assert e.value.vertex == 50
    # the state before the step, bit for bit, and no step counted
    assert np.array_equal(sim.positions(), p0)
    assert np.array_equal(sim.velocities(), v0)
    assert sim.steps == 0


@pytest.mark.parametrize(("dt", "speed"), [(1e-170, 1e155), (1e-300, 1e160)])
def test_a_fast_vertex_over_a_tiny_step_is_no_runaway(
    beam: topomech.GMap, dt: float, speed: float
) -> None:
    sim = Simulation(beam, models=["linear_fem"], dt=dt, gravity=[0, 0, 0])
    v = np.zeros((sim.n_vertices, 3))
    v[10] = [speed, 0.0, 0.0]  # moves speed * dt (1e-15 m or less) in the step
    sim.set_velocities(v)
    sim.step()
    assert sim.steps == 1


def test_a_real_runaway_of_a_huge_speed_says_how_far_not_inf(beam: topomech.GMap) -> None:
    sim = Simulation(beam, models=["linear_fem"], dt=1e-3, gravity=[0, 0, 0])
    v = np.zeros((sim.n_vertices, 3))
    v[10] = [1e160, 0.0, 0.0]  # moves 1e157 m: a runaway, finite
    sim.set_velocities(v)
    with pytest.raises(DivergenceError) as e:
        sim.step()
    assert "runaway" in str(e.value)
    # measured against the body's mass-weighted mean velocity, which the vertex drags along
    m = sim.masses()
    relative = 1e157 * (1.0 - m[10] / m.sum())
    assert f"carry it {relative:.3e}".replace("e+", "e") in str(e.value)
    assert e.value.vertex == 10


def test_a_builtin_refusing_a_non_finite_matrix_names_a_vertex(beam: topomech.GMap) -> None:
    sim = Simulation(beam, models=["corotational"], dt=1e-3, gravity=[0, 0, 0])
    p = sim.positions().copy()
    p[100] = [1e308, 1e308, -1e308]
    sim.set_positions(p)
    with pytest.raises(DivergenceError) as e:
        sim.step()
    assert "polar" in str(e.value)
    # a vertex of an element holding the bad vertex (the row of the dart the rule failed at)
    assert e.value.vertex is not None
