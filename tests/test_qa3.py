"""QA (third and fourth passes): held vertices keep zero velocity through the Python API,
and the Simulation's arguments are refused naming them."""

from __future__ import annotations

import numpy as np
import pytest

import topomech


def _beam() -> topomech.Simulation:
    g, _ = topomech.read_gmap(topomech.sample("beam.msh"))
    return topomech.Simulation(
        g, models=["corotational"], integrator="implicit_euler", dt=1e-3, gravity=[0, 0, -9.81]
    )


def test_holding_a_falling_body_stops_the_held_vertices() -> None:
    """Implicit Euler moved held vertices by the velocity they had when held (0.049 m in
    100 steps of a falling box), and the kinetic energy counted it: set_fixed now stops
    them, and they stay put."""
    sim = _beam()
    sim.step(20)
    held = sim.rest_positions()[:, 0] < 1e-9
    assert held.any()
    assert (sim.velocities()[held][:, 2] < -1e-3).all()
    sim.set_fixed(held)
    at = sim.positions()[held]
    assert np.array_equal(sim.velocities()[held], np.zeros((held.sum(), 3)))
    sim.step(20)
    assert np.array_equal(sim.positions()[held], at)
    assert np.array_equal(sim.velocities()[held], np.zeros((held.sum(), 3)))


def test_a_velocity_for_a_held_vertex_is_refused() -> None:
    """set_velocities and set_vertex_field('velocity') refuse a non-zero velocity on a held
    row, naming it, and change nothing; set_vertex_field('fixed') holds as set_fixed does
    (stopping the vertices)."""
    sim = _beam()
    sim.step(5)
    held = np.zeros(sim.n_vertices, dtype=bool)
    held[[3, 7]] = True
    sim.set_vertex_field("fixed", held)
    assert np.array_equal(sim.fixed(), held)
    assert np.array_equal(sim.velocities()[held], np.zeros((2, 3)))
    before = sim.velocities()
    v = before.copy()
    v[7] = [0.0, 0.0, 1.0]
    for write in (sim.set_velocities, lambda x: sim.set_vertex_field("velocity", x)):
        with pytest.raises(topomech.SimulationError, match=r"vertex 7 is held \(fixed\)"):
            write(v)
        assert np.array_equal(sim.velocities(), before)
    v[7] = 0.0
    sim.set_velocities(v)


def test_arguments_of_the_wrong_kind_are_named() -> None:
    """A list where the configuration goes, and a number as an embedding's name, raised
    TypeErrors from inside the library that named neither."""
    g, _ = topomech.read_gmap(topomech.sample("beam.msh"))
    with pytest.raises(TypeError, match=r"^config: expected a mapping .* got a list"):
        topomech.Simulation(g, [1, 2])  # type: ignore[arg-type]
    sim = topomech.Simulation(g, models=["corotational"])
    calls = [
        lambda: sim.embedding(3),  # type: ignore[arg-type]
        lambda: sim.vertex_field(3),  # type: ignore[arg-type]
        lambda: sim.set_vertex_field(3, sim.positions()),  # type: ignore[arg-type]
        lambda: sim.set_embedding(3, sim.positions()),  # type: ignore[arg-type]
        lambda: g.embedding(3),  # type: ignore[arg-type]
        lambda: g.set_embedding(3, g.positions()),  # type: ignore[arg-type]
    ]
    for call in calls:
        with pytest.raises(TypeError, match=r"^name: expected an embedding's name \(a str\)"):
            call()


def test_set_embedding_keeps_the_rules_of_the_supports() -> None:
    """set_embedding was a way round them (QA): a velocity for a held vertex is refused and
    nothing is written; 'fixed' written whole holds as set_fixed does, stopping the
    vertices it holds."""
    sim = _beam()
    sim.step(5)
    held = np.zeros(sim.n_vertices, dtype=bool)
    held[0] = True
    sim.set_fixed(held)
    before = sim.embedding("velocity").values
    with pytest.raises(topomech.SimulationError, match="vertex 0 is held"):
        sim.set_embedding("velocity", np.ones_like(before))
    assert np.array_equal(sim.embedding("velocity").values, before)
    fixed = sim.embedding("fixed").values.copy()
    fixed[:] = True
    sim.set_embedding("fixed", fixed)
    assert sim.fixed().all()
    assert not sim.velocities().any()
