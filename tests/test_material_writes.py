"""Values no material has, written into a running simulation (QA): a negative
``corner_mass`` made the total mass -192 and the steps ran; a negative ``young`` was taken;
complex positions lost their imaginary parts with only numpy's warning. The constructor and
the scenes refuse such materials; ``Simulation.set_embedding`` and the array setters now do
too, naming the embedding and the value, and write nothing."""

from __future__ import annotations

import numpy as np
import pytest

import topomech


def tet_box() -> topomech.Simulation:
    """Two tetrahedra sharing a face (an input mesh small enough to read)."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    g = topomech.GMap.from_mesh(pts, [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 4]]))])
    return topomech.Simulation(g, models=["corotational"], gravity=[0.0, 0.0, 0.0])


@pytest.mark.parametrize(
    ("name", "value", "why"),
    [
        ("corner_mass", -1.0, "must be positive and finite"),
        ("corner_mass", 0.0, "must be positive and finite"),
        ("density", -1000.0, "must be positive and finite"),
        ("young", -1e6, "must be positive and finite"),
        ("poisson", 0.5, r"must be in \(-1, 0.5\)"),
        ("poisson", -1.0, r"must be in \(-1, 0.5\)"),
    ],
)
def test_values_no_material_has_are_refused(name: str, value: float, why: str) -> None:
    sim = tet_box()
    values = sim.embedding(name).values.copy()
    before = sim.total_mass()
    values[-1] = value
    with pytest.raises(
        ValueError, match=rf"'{name}' {why}: got .* at row {len(values) - 1} of the values"
    ):
        sim.set_embedding(name, values)
    np.testing.assert_array_equal(sim.embedding(name).values[:-1], values[:-1])
    assert sim.embedding(name).values[-1] != value
    assert sim.total_mass() == before


def test_valid_material_values_are_written() -> None:
    """The check refuses only what no material has: doubled masses double the total mass."""
    sim = tet_box()
    before = sim.total_mass()
    sim.set_embedding("corner_mass", 2.0 * sim.embedding("corner_mass").values)
    assert sim.total_mass() == pytest.approx(2.0 * before, rel=1e-15)
    sim.set_embedding("poisson", np.full(len(sim.embedding("poisson").values), -0.5))
    sim.step()


@pytest.mark.parametrize("setter", ["set_positions", "set_velocities", "set_external_forces"])
def test_complex_arrays_are_refused(setter: str) -> None:
    sim = tet_box()
    x = sim.positions().astype(complex) + 1j
    before = sim.positions().copy()
    with pytest.raises(TypeError, match="must be real numbers, got an array of complex128"):
        getattr(sim, setter)(x)
    np.testing.assert_array_equal(sim.positions(), before)


@pytest.mark.parametrize("setter", ["set_positions", "set_velocities", "set_external_forces"])
def test_boolean_arrays_are_refused(setter: str) -> None:
    """A mask passed where forces or positions were meant (QA: numpy read True as 1.0 and the
    values were written): refused, nothing written."""
    sim = tet_box()
    before = (sim.positions().copy(), sim.velocities().copy(), sim.vertex_field("f_ext").copy())
    with pytest.raises(TypeError, match="must be real numbers, got booleans"):
        getattr(sim, setter)(np.ones((sim.n_vertices, 3), dtype=bool))
    np.testing.assert_array_equal(sim.positions(), before[0])
    np.testing.assert_array_equal(sim.velocities(), before[1])
    np.testing.assert_array_equal(sim.vertex_field("f_ext"), before[2])


def test_complex_points_are_refused() -> None:
    pts = np.zeros((4, 3), dtype=complex)
    with pytest.raises(TypeError, match="points must be real numbers"):
        topomech.GMap.from_mesh(pts, [("tetra", np.array([[0, 1, 2, 3]]))])


def test_a_huge_value_is_named_short() -> None:
    """1e308 is printed as 1e308 (QA: the message held all 309 digits)."""
    sim = tet_box()
    values = sim.embedding("poisson").values.copy()
    values[0] = 1e308
    with pytest.raises(ValueError, match=r"'poisson' must be in \(-1, 0.5\): got 1e308 at row 0 "):
        sim.set_embedding("poisson", values)


def test_complex_values_are_refused_everywhere_they_enter() -> None:
    """Every other entry point the QA found dropping imaginary parts with only numpy's
    warning: a vertex field, the gravity and density of a simulation, a plane cut's normal, a
    blade's points, a point load and a load's function, the flat mesh layout."""
    from topomech import loads

    sim = tet_box()
    v = np.zeros((sim.n_vertices, 3)) + 1j
    with pytest.raises(TypeError, match="must be real numbers"):
        sim.set_vertex_field("velocity", v)
    g = sim.gmap()
    for kw in ({"gravity": np.array([0, -9.81j, 0])}, {"density": np.complex128(1000)}):
        with pytest.raises(TypeError, match="must be a number, got complex"):
            topomech.Simulation(g, models=["corotational"], **kw)
    with pytest.raises(TypeError, match="must be a number, got complex"):
        sim.cut(np.array([1, 0j, 0]), 0.3)
    blade = np.array([[0.5, 1.2, -1.0], [0.5, 1.2, 2.0]], dtype=complex)
    with pytest.raises(TypeError):
        sim.cut_swept(blade, blade - 1.0)
    with pytest.raises(loads.LoadError, match="force must be real numbers"):
        loads.point_load(sim, np.array([0, 0, -5j]), points=[0])
    assert sim.total_mass() > 0
