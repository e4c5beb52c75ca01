"""Loads (point forces, tractions, pressures), the ground plane and initial fields.

Every load is checked against an independent reference: the exact integral of the load over
the faces (total force, first moment), the analytic direction of a pressure, or a linear
elasticity solve by scikit-fem on the same tetrahedral mesh.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import topomech
from topomech import loads
from topomech.scene import parse_scene

BAR = """
[mesh]
generator = "box"
element = "{element}"
size = [1.0, 0.2, 0.3]
cells = [{n}, 2, 2]

[[model]]
kind = "linear_fem"
young = 1e6
poisson = 0.3

[[fix]]
where = "x < 1e-9"

[world]
gravity = [0.0, 0.0, 0.0]

[integrator]
kind = "static"
dt = 1.0
steps = 1
"""


def _bar(load: str, element: str = "tet", n: int = 5) -> topomech.Simulation:
    return parse_scene(BAR.format(element=element, n=n) + load).build()


def _box(element: str, cells: tuple[int, int, int] = (2, 2, 2)) -> topomech.Simulation:
    nx, ny, nz = cells
    flat = topomech._core.box(nx, ny, nz, 1.0, 0.2, 0.3, element)
    g = topomech.GMap.from_flat(*flat)
    models = ["linear_fem"] if element == "tetra" else ["stretch_elementary"]
    return topomech.Simulation(g, models=models, gravity=[0.0, 0.0, 0.0])


# ------------------------------------------------------------------ consistent nodal loads


@pytest.mark.parametrize("element", ["tetra", "hexahedron", "wedge", "pyramid"])
def test_traction_total_force_and_first_moment(element: str) -> None:
    """A uniform traction t on the face x = 1 (area 0.2 x 0.3) of a box: the nodal loads add
    up to t A, and their first moment sum_a x_a (x) f_a equals t (x) integral of x dA = t (x)
    A c (c the face centroid), which holds for consistent loads on any linear or bilinear
    face. Both are sums of a few numbers of size 1: 1e-12 relative."""
    sim = _box(element)
    t = np.array([1.5, -2.0, 0.5])
    f = loads.surface_load(sim, traction=t, where="x > 1 - 1e-9")
    area = 0.2 * 0.3
    np.testing.assert_allclose(f.sum(axis=0), t * area, rtol=1e-12, atol=1e-14)
    x = sim.rest_positions()
    moment = np.einsum("vi,vj->ij", x, f)
    centroid = np.array([1.0, 0.1, 0.15])
    np.testing.assert_allclose(moment, np.outer(centroid, t) * area, rtol=1e-12, atol=1e-14)
    # only the vertices of that face are loaded
    assert np.all(f[x[:, 0] < 1 - 1e-9] == 0.0)


def test_pressure_on_a_trapezoid_is_consistent() -> None:
    """One hexahedron whose top face is a trapezoid (not a parallelogram). A pressure p on
    it: the total force is -p n A, and the first moment is -p n (x) integral of x dA with the
    area centroid of the trapezoid, not the mean of its corners: lumping a quarter on each
    corner would miss it, 2x2 Gauss on the bilinear map gets it exactly (1e-12)."""
    pts = np.array(
        [
            [0, 0, 0],
            [2, 0, 0],
            [2, 1, 0],
            [0, 1, 0],
            [0, 0, 1],
            [2, 0, 1],
            [1.5, 1, 1],
            [0.5, 1, 1],
        ],
        dtype=float,
    )
    g = topomech.GMap.from_mesh(pts, [("hexahedron", [list(range(8))])])
    sim = topomech.Simulation(g, models=["stretch_elementary"], gravity=[0.0, 0.0, 0.0])
    p = 3.0
    f = loads.surface_load(sim, pressure=p, where="z > 1 - 1e-9")
    # trapezoid in z = 1: bottom edge y = 0 of length 2, top edge y = 1 of length 1
    a, b, h = 2.0, 1.0, 1.0
    area = (a + b) / 2 * h
    yc = h * (a + 2 * b) / (3 * (a + b))
    centroid = np.array([1.0, yc, 1.0])
    n = np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(f.sum(axis=0), -p * n * area, rtol=1e-12, atol=1e-14)
    moment = np.einsum("vi,vj->ij", sim.rest_positions(), f)
    np.testing.assert_allclose(moment, np.outer(centroid, -p * n * area), rtol=1e-12, atol=1e-13)
    lumped = np.einsum("vi,vj->ij", pts[4:], np.tile(-p * n * area / 4, (4, 1)))
    assert abs(lumped[1, 2] - moment[1, 2]) > 1e-2  # the check can tell them apart


@pytest.mark.parametrize("element", ["tetra", "hexahedron", "wedge", "pyramid"])
def test_linearly_varying_pressure_moments(element: str) -> None:
    """A hydrostatic-like pressure p = 1 + 10 z on the face x = 1 (y in [0, 0.2], z in
    [0, 0.3]): the total force is -e_x times the integral of p dA, and the first moment
    sum_a x_a (x) f_a equals the integral of x (x) (-p e_x) dA (degree 2: the 3-point
    triangle rule and 2x2 Gauss on the quads are exact), computed here by hand:
    int dA = 0.06, int z dA = 0.009, int y dA = 0.006, int z^2 dA = 0.0018,
    int y z dA = 0.0009, int y^2 dA = 0.0008 (1e-12)."""
    sim = _box(element)
    f = loads.surface_load(sim, pressure="1 + 10 * z", where="x > 1 - 1e-9")
    i1, iz, iy, izz, iyz = 0.06, 0.009, 0.006, 0.0018, 0.0009
    total = i1 + 10 * iz
    np.testing.assert_allclose(f.sum(axis=0), [-total, 0.0, 0.0], rtol=1e-12, atol=1e-14)
    moment = np.einsum("vi,vj->ij", sim.rest_positions(), f)
    expected = np.zeros((3, 3))
    expected[0, 0] = -total  # x = 1 on the face
    expected[1, 0] = -(iy + 10 * iyz)
    expected[2, 0] = -(iz + 10 * izz)
    np.testing.assert_allclose(moment, expected, rtol=1e-12, atol=1e-14)
    # the same load as a Python function of the points, and a varying traction
    g = loads.surface_load(sim, pressure=lambda q: 1 + 10 * q[:, 2], where="x > 1 - 1e-9")
    np.testing.assert_allclose(g, f, rtol=1e-12, atol=1e-15)
    t = loads.surface_load(sim, traction=["-1 - 10 * z", 0.0, 0.0], where="x > 1 - 1e-9")
    np.testing.assert_allclose(t, f, rtol=1e-12, atol=1e-15)


def test_linearly_varying_edge_traction_2d() -> None:
    """2D: a shear traction t_y = y (N/m) on the edge x = 2 (y in [0, 1]): total 1/2, first
    moment int y^2 dy = 1/3 (2-point Gauss is exact to degree 3; 1e-12)."""
    g = topomech.GMap.from_flat(*topomech._core.grid(4, 3, 2.0, 1.0, "triangle"))
    sim = topomech.Simulation(g, models=["stretch_elementary"], gravity=[0.0, 0.0, 0.0])
    f = loads.surface_load(sim, traction=[0.0, "y", 0.0], where="x > 2 - 1e-9")
    np.testing.assert_allclose(f.sum(axis=0), [0.0, 0.5, 0.0], atol=1e-14)
    np.testing.assert_allclose((sim.rest_positions()[:, 1] * f[:, 1]).sum(), 1 / 3, rtol=1e-12)


def test_hydrostatic_pressure_in_a_scene() -> None:
    """A scene's pressure may be an expression of the rest x, y, z: the loads equal those of
    the Python call (bit for bit), and a bad expression is refused naming its key."""
    text = BAR.format(element="tet", n=2) + (
        '[[load]]\nkind = "pressure"\npressure = "1e3 * (0.3 - z)"\nwhere = "y < 1e-9"\n'
    )
    sim = parse_scene(text).build()
    ref = loads.surface_load(sim, pressure="1e3 * (0.3 - z)", where="y < 1e-9")
    np.testing.assert_array_equal(sim.external_forces(), ref)
    assert sim.external_forces()[:, 1].sum() > 0  # pushes into the face y = 0: along +y
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(text.replace("(0.3 - z)", "(0.3 - depth)"))
    assert e.value.key == "load[0].pressure"
    assert "unknown variable or parameter 'depth'" in str(e.value)
    assert "rule '" not in str(e.value)  # the user wrote no rule
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(text.replace('pressure = "1e3 * (0.3 - z)"', 'traction = ["x", "y"]'))
    assert e.value.key == "load[0].traction"


@pytest.mark.parametrize("element", ["tetra", "hexahedron", "wedge", "pyramid"])
def test_pressure_on_a_closed_surface_adds_to_zero(element: str) -> None:
    """A uniform pressure on every boundary face of a box: the integral of n dA over a closed
    surface is zero, so the loads add up to zero (1e-12 of p A); on the face x = 1 alone it
    pushes along -x (the inward normal) with p A."""
    sim = _box(element)
    f = loads.surface_load(sim, pressure=2.0, where="true")
    assert np.abs(f.sum(axis=0)).max() < 1e-12
    assert np.abs(f).max() > 0.0
    f1 = loads.surface_load(sim, pressure=2.0, where="x > 1 - 1e-9")
    np.testing.assert_allclose(f1.sum(axis=0), [-2.0 * 0.06, 0.0, 0.0], atol=1e-14)


@pytest.mark.parametrize("element", ["triangle", "quad"])
def test_edge_traction_and_pressure_2d(element: str) -> None:
    """2D: a traction on the edge x = 2 (length 1) of a 2 x 1 rectangle is a force per unit
    length (N/m): its total is t L; a pressure pushes along the inward normal (-x), and on
    the whole boundary of the rectangle adds to zero. Exact up to rounding (1e-12)."""
    g = topomech.GMap.from_flat(*topomech._core.grid(4, 3, 2.0, 1.0, element))
    sim = topomech.Simulation(g, models=["stretch_elementary"], gravity=[0.0, 0.0, 0.0])
    f = loads.surface_load(sim, traction=[0.0, 0.25, 0.0], where="x > 2 - 1e-9")
    np.testing.assert_allclose(f.sum(axis=0), [0.0, 0.25, 0.0], atol=1e-14)
    x = sim.rest_positions()
    # first moment: integral of y dL on the edge is 1/2
    np.testing.assert_allclose((x[:, 1] * f[:, 1]).sum(), 0.25 * 0.5, atol=1e-14)
    p = loads.surface_load(sim, pressure=3.0, where="x > 2 - 1e-9")
    np.testing.assert_allclose(p.sum(axis=0), [-3.0, 0.0, 0.0], atol=1e-14)
    closed = loads.surface_load(sim, pressure=3.0, where="true")
    assert np.abs(closed.sum(axis=0)).max() < 1e-12


def test_point_load_by_points_and_where() -> None:
    """A point force goes, whole, on each selected vertex: by input point indices (rows are
    input points for a generated mesh) and by predicate."""
    sim = _box("tetra")
    f = loads.point_load(sim, [0.0, 0.0, -5.0], points=[3, 7])
    assert np.count_nonzero(f[:, 2]) == 2
    ids = getattr(sim, "point_ids", lambda: np.arange(sim.n_vertices))()
    assert set(np.asarray(ids)[f[:, 2] != 0].tolist()) == {3, 7}
    np.testing.assert_array_equal(f[f[:, 2] != 0], [[0.0, 0.0, -5.0]] * 2)
    g = loads.point_load(sim, [1.0, 0.0, 0.0], where="x > 1 - 1e-9 && y < 1e-9 && z < 1e-9")
    assert g.sum(axis=0).tolist() == [1.0, 0.0, 0.0]


def test_external_forces_are_kept_and_balanced() -> None:
    """The loads set stay as set (steps do not reset them), the forces include them, and a
    free body under a constant load accelerates by F / M (momentum F t after n steps of
    symplectic Euler, exact for a constant force up to rounding: 1e-9)."""
    g = topomech.GMap.from_flat(*topomech._core.box(2, 1, 1, 1.0, 1.0, 1.0, "tetra"))
    sim = topomech.Simulation(
        g,
        models=[{"kind": "stretch_elementary", "stiffness": 1e3}],
        gravity=[0.0, 0.0, 0.0],
        dt=1e-3,
        density=10.0,
    )
    f = np.zeros((sim.n_vertices, 3))
    f[:, 0] = 1.0
    sim.set_external_forces(f)
    sim.step(10)
    np.testing.assert_array_equal(sim.external_forces(), f)
    np.testing.assert_allclose(
        sim.momentum(), [sim.n_vertices * 1.0 * 10e-3, 0, 0], rtol=1e-9, atol=1e-15
    )
    bad = f.copy()
    bad[2, 1] = math.nan
    with pytest.raises(ValueError, match="row 2"):
        sim.set_external_forces(bad)
    with pytest.raises(ValueError, match="shape"):
        sim.set_external_forces(f[:-1])
    # a scalar names its own shape, (), not (1,); None and strings are not numbers (numpy
    # read None as NaN; QA)
    with pytest.raises(ValueError, match=r"got \(\)"):
        sim.set_external_forces(np.array(1.0))
    with pytest.raises(TypeError, match="must be real numbers, got None"):
        sim.set_external_forces(None)
    with pytest.raises(TypeError, match="must be real numbers"):
        sim.set_external_forces([["a", "b", "c"]] * sim.n_vertices)
    np.testing.assert_array_equal(sim.external_forces(), f)  # nothing written


# ------------------------------------------------------------------ against scikit-fem


def _skfem_bar(
    sim: topomech.Simulation,
    traction: np.ndarray,
    young: float,
    poisson: float,
    loaded: Any = lambda x: x[0] > 1 - 1e-9,
) -> Any:
    """Linear elasticity with scikit-fem on the simulation's own tetrahedra: fixed at x = 0,
    a uniform traction on the boundary facets where ``loaded`` holds (default: x = 1).
    Returns the nodal displacements (V, 3) in row order."""
    skfem = pytest.importorskip("skfem")
    from skfem.helpers import dot
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    _, kinds, _, conn = sim.gmap().to_flat()
    assert set(kinds) == {"tetra"}
    tets = np.asarray(conn).reshape(-1, 4)
    # the rest positions: the map's points are where the vertices are now
    mesh = skfem.MeshTet(sim.rest_positions().T.copy(), tets.T.copy())
    e = skfem.ElementVector(skfem.ElementTetP1())
    basis = skfem.Basis(mesh, e)
    k = skfem.asm(linear_elasticity(*lame_parameters(young, poisson)), basis)
    right = mesh.facets_satisfying(loaded, boundaries_only=True)
    fbasis = skfem.FacetBasis(mesh, e, facets=right)

    @skfem.LinearForm
    def load(v: Any, w: Any) -> Any:
        return dot(np.asarray(traction)[:, None, None], v)

    rhs = skfem.asm(load, fbasis)
    clamp = basis.get_dofs(lambda x: x[0] < 1e-9)
    u = skfem.solve(*skfem.condense(k, rhs, D=clamp))
    return u[basis.nodal_dofs].T


@pytest.mark.parametrize(
    ("load", "traction"),
    [
        ('kind = "traction"\ntraction = [0.0, -100.0, 50.0]', [0.0, -100.0, 50.0]),
        ('kind = "pressure"\npressure = 2000.0', [-2000.0, 0.0, 0.0]),
    ],
)
def test_bar_static_solve_matches_scikit_fem(load: str, traction: list[float]) -> None:
    """A bar of tetrahedra fixed at x = 0 with a traction (bending and torsion-free shear)
    or a pressure (compression) on its end x = 1, solved by the static integrator of
    linear_fem, against scikit-fem's P1 linear elasticity on the same mesh: the same
    discrete problem, so the displacements agree to the solvers' tolerance (the static solve
    stops at a residual of 1e-10 of the load; 1e-6 of the largest displacement)."""
    pytest.importorskip("skfem")
    sim = _bar(f'[[load]]\n{load}\nwhere = "x > 1 - 1e-9"\n')
    sim.step()
    ref = _skfem_bar(sim, np.array(traction), 1e6, 0.3)
    u = sim.displacements()
    scale = np.abs(ref).max()
    assert scale > 1e-6
    np.testing.assert_allclose(u, ref, atol=1e-6 * scale)


def test_shipped_pressure_cantilever_matches_scikit_fem() -> None:
    """The shipped scene pressure_cantilever (1 kPa on the top face z = 0.2 of a clamped
    beam) against scikit-fem with the traction -p e_z on the same facets of the same mesh:
    agreement to 1e-6 of the tip deflection, which is of the order of the Euler-Bernoulli
    value (0.0188 m; linear tetrahedra lock in bending, so between a third and all of it)."""
    pytest.importorskip("skfem")
    sim = topomech.load_scene("pressure_cantilever").build()
    sim.step()
    ref = _skfem_bar(sim, np.array([0.0, 0.0, -1e3]), 1e7, 0.3, lambda x: x[2] > 0.2 - 1e-9)
    u = sim.displacements()
    tip = -ref[:, 2].min()
    assert 0.0188 / 3 < tip < 0.0188
    np.testing.assert_allclose(u, ref, atol=1e-6 * tip)


# ------------------------------------------------------------------ ground and initial fields

FALL = """
[mesh]
generator = "box"
element = "tet"
size = [0.2, 0.2, 0.2]
cells = [1, 1, 1]

[[model]]
kind = "stretch_elementary"
stiffness = 1e4

[material]
density = 100.0

[world]
gravity = [0.0, 0.0, -9.81]
{ground}

[integrator]
kind = "symplectic_euler"
dt = 1e-3
steps = 600

[initial]
displacement = [0.0, 0.0, 0.3]
"""


@pytest.mark.parametrize(
    "ground",
    [
        "ground = { point = [0.0, 0.0, 0.0] }",
        "ground = 0.0",
        "ground = { point = [5.0, -3.0, 0.0], normal = [0.0, 0.0, 2.0] }",
    ],
)
def test_ground_under_gravity_along_minus_z(ground: str) -> None:
    """Gravity along -z: the ground's default normal is +z (the opposite of gravity), so a
    box dropped from z = 0.3 lands on z = 0 and stays there (no vertex below it, up to
    rounding: 1e-12), whether the plane is given by a point, by a height or with an explicit
    normal. Before the ground knew its normal, the plane was y = h and the box fell through."""
    sim = parse_scene(FALL.format(ground=ground)).build()
    assert sim.positions()[:, 2].min() == pytest.approx(0.3)
    sim.step(600)
    z = sim.positions()[:, 2]
    assert z.min() >= -1e-12
    assert z.min() < 1e-3  # it did land


def test_ground_height_keeps_meaning_y_under_default_gravity() -> None:
    """Back-compatibility: a number under gravity along -y is the plane y = h."""
    text = FALL.format(ground="ground = -0.1").replace("[0.0, 0.0, -9.81]", "[0.0, -9.81, 0.0]")
    sim = parse_scene(text).build()
    sim.step(600)
    assert sim.positions()[:, 1].min() >= -0.1 - 1e-12
    assert sim.positions()[:, 1].min() < -0.1 + 1e-3


def test_tilted_ground_keeps_tangential_motion() -> None:
    """A plane through the origin with normal (0, 1, 1)/sqrt(2) under gravity along -z:
    every vertex ends on or above it (1e-12), and the body slides down the slope, which
    goes towards +y (z = -y on the plane): the ground removes only the normal velocity."""
    text = FALL.format(
        ground="ground = { point = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 1.0] }"
    ).replace("displacement = [0.0, 0.0, 0.3]", "displacement = [0.0, 0.0, 0.05]")
    sim = parse_scene(text).build()
    sim.step(600)
    x = sim.positions()
    assert ((x[:, 1] + x[:, 2]) / math.sqrt(2)).min() >= -1e-12
    assert sim.momentum()[1] > 0


def test_initial_velocity_gives_the_momentum() -> None:
    """[initial] velocity = v on every vertex: the momentum is M v (M the total mass, 1e-12)
    and stays M v without gravity or fixes (internal forces add to zero, 1e-9)."""
    text = FALL.format(ground="").replace("[0.0, 0.0, -9.81]", "[0.0, 0.0, 0.0]")
    text = text.replace("displacement = [0.0, 0.0, 0.3]", "velocity = [1.0, -2.0, 0.5]")
    sim = parse_scene(text).build()
    m = sim.total_mass()
    np.testing.assert_allclose(sim.momentum(), m * np.array([1.0, -2.0, 0.5]), rtol=1e-12)
    sim.step(50)
    np.testing.assert_allclose(sim.momentum(), m * np.array([1.0, -2.0, 0.5]), rtol=1e-9)


def test_initial_displacement_moves_positions_not_rest() -> None:
    """[initial] displacement on a selection moves the positions of those free vertices,
    not their rest positions (the body starts deformed); fixed vertices stay."""
    text = BAR.format(element="tet", n=4) + (
        '[[initial]]\ndisplacement = [0.0, 0.0, 0.01]\nwhere = "x > 0.5"\n'
        "[[initial]]\nvelocity = [0.0, 1.0, 0.0]\npoints = [0, 1]\n"
    )
    sim = parse_scene(text).build()
    rest = sim.rest_positions()
    d = sim.displacements()
    moved = rest[:, 0] > 0.5
    # rest + 0.01 - rest: 1e-15 of rounding
    np.testing.assert_allclose(d[moved], [[0.0, 0.0, 0.01]] * int(moved.sum()), atol=1e-15)
    np.testing.assert_array_equal(d[~moved], 0.0)
    # point 0 is on the fixed end x = 0 (held: it keeps zero velocity), point 1 is free
    fixed = sim.fixed()
    assert fixed[0]
    assert not fixed[1]
    expected = np.zeros((sim.n_vertices, 3))
    expected[1] = [0.0, 1.0, 0.0]
    np.testing.assert_array_equal(sim.velocities(), expected)


# ------------------------------------------------------------------ refusals name the key


@pytest.mark.parametrize(
    ("extra", "key", "words"),
    [
        ('[[load]]\nkind = "twist"\nwhere = "true"\n', "load[0].kind", "unknown load kind"),
        (
            '[[load]]\nkind = "traction"\nforce = [1.0, 0.0, 0.0]\nwhere = "true"\n',
            "load[0].force",
            "takes traction",
        ),
        ('[[load]]\nkind = "pressure"\nwhere = "true"\n', "load[0].pressure", "missing"),
        ('[[load]]\nkind = "point"\nforce = [1.0, 0.0, 0.0]\n', "load[0]", "missing the selection"),
        (
            '[[load]]\nkind = "point"\nforce = [1.0, 0.0]\nwhere = "true"\n',
            "load[0].force",
            "array of 3",
        ),
        (
            '[[load]]\nkind = "point"\nforce = [1.0, 0.0, 0.0]\nwhere = "true"\npoints = [1]\n',
            "load[0].points",
            "not both",
        ),
        (
            '[[load]]\nkind = "pressure"\npressure = 1.0\nwhere = "x >"\n',
            "load[0].where",
            "bad predicate",
        ),
        (
            '[[load]]\nkind = "pressure"\npressure = 1.0\nwhere = "true"\nsize = 2\n',
            "load[0].size",
            "unknown key",
        ),
        ("[initial]\nspeed = [1.0, 0.0, 0.0]\n", "initial.speed", "unknown key"),
        ("[initial]\nwhere = 'x > 0'\n", "initial", "velocity"),
        ("[world.ground]\nnormal = [0.0, 0.0, 1.0]\n", "world.ground.point", "missing"),
        (
            "[world.ground]\npoint = [0.0, 0.0, 0.0]\nnormal = [0.0, 0.0, 0.0]\n",
            "world.ground.normal",
            "zero",
        ),
        (
            "[world.ground]\npoint = [0.0, 0.0, 0.0]\nup = [0.0, 0.0, 1.0]\n",
            "world.ground.up",
            "unknown key",
        ),
        # the bar is solved statically, which would balance it as if the plane were not there
        ("[world]\nground = -1.0\n", "world.ground", "does not model contact"),
    ],
)
def test_bad_keys_are_named(extra: str, key: str, words: str) -> None:
    """Every refusal of a load, initial or ground key names the key by its path."""
    text = BAR.format(element="tet", n=2).replace("[world]\ngravity = [0.0, 0.0, 0.0]\n", "")
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(text + extra)
    assert e.value.key == key, str(e.value)
    assert words in str(e.value)


def test_load_that_selects_nothing_names_its_key() -> None:
    """A surface load whose predicate selects no boundary face is refused when the scene is
    built, naming the load's key."""
    sc = parse_scene(
        BAR.format(element="tet", n=2)
        + '[[load]]\nkind = "pressure"\npressure = 1.0\nwhere = "x > 5"\n'
    )
    with pytest.raises(topomech.SceneError) as e:
        sc.build()
    assert e.value.key == "load[0]"
    assert "selects no boundary face" in str(e.value)


def test_2d_scene_edge_traction_is_balanced_by_the_reactions() -> None:
    """A 2D scene (a 2 x 1 rectangle of triangles with springs, held at x = 0) with a shear
    traction of 0.25 N/m on its right edge (length 1): the loads total 0.25 N, and after the
    static solve the free vertices are in equilibrium (1e-8 N) and the reactions of the held
    ones carry the whole load (the springs' forces add to zero)."""
    text = """
[mesh]
generator = "grid"
element = "tri"
size = [2.0, 1.0]
cells = [4, 2]

[[model]]
kind = "stretch_elementary"
stiffness = 100.0

[[fix]]
where = "x < 1e-9"

[[load]]
kind = "traction"
traction = [0.0, 0.25, 0.0]
where = "x > 2 - 1e-9"

[world]
gravity = [0.0, 0.0, 0.0]

[integrator]
kind = "static"
dt = 1.0
steps = 1
"""
    sim = parse_scene(text).build()
    np.testing.assert_allclose(sim.external_forces().sum(axis=0), [0.0, 0.25, 0.0], atol=1e-15)
    sim.step()
    f = sim.forces()
    held = sim.fixed()
    assert np.abs(f[~held]).max() < 1e-8
    np.testing.assert_allclose(f[held].sum(axis=0), [0.0, 0.25, 0.0], atol=1e-8)
    assert sim.displacements()[:, 1].max() > 1e-3


def test_ground_from_python_and_bad_ground_keys() -> None:
    """Python takes the ground as a dict; an unknown key of it is a TypeError naming it, a
    missing point a ValueError, a zero normal a SimulationError naming the ground."""
    g = topomech.GMap.from_flat(*topomech._core.box(1, 1, 1, 1.0, 1.0, 1.0, "tetra"))
    kw: dict[str, Any] = {"models": ["stretch_elementary"], "gravity": [0.0, 0.0, -1.0]}
    topomech.Simulation(g, ground={"point": [0.0, 0.0, -1.0]}, **kw)
    with pytest.raises(TypeError, match=r"ground\.up: unknown key"):
        topomech.Simulation(g, ground={"point": [0.0, 0.0, 0.0], "up": [0, 0, 1]}, **kw)
    with pytest.raises(ValueError, match=r"ground\.point: missing"):
        topomech.Simulation(g, ground={"normal": [0.0, 0.0, 1.0]}, **kw)
    with pytest.raises(topomech.SimulationError, match="ground: the normal"):
        topomech.Simulation(g, ground={"point": [0.0, 0.0, 0.0], "normal": [0, 0, 0]}, **kw)


def test_a_cut_keeps_the_total_load() -> None:
    """A vertex split by a cut divides its load equally between its copies (policy sum of
    f_ext): the number of rows grows, the total load does not (1e-12)."""
    g = topomech.GMap.from_flat(*topomech._core.box(2, 1, 1, 1.0, 1.0, 1.0, "tetra"))
    sim = topomech.Simulation(g, models=["linear_fem"], gravity=[0.0, 0.0, 0.0])
    n = sim.n_vertices
    f = np.tile([0.0, 0.0, 1.0], (n, 1))
    sim.set_external_forces(f)
    result = sim.cut([1.0, 0.0, 0.0], 0.5)
    unsewn = result if isinstance(result, int) else result.unsewn
    assert unsewn > 0
    assert sim.n_vertices > n
    np.testing.assert_allclose(sim.external_forces().sum(axis=0), [0.0, 0.0, n], rtol=1e-12)


def test_energy_of_a_loaded_run_counts_the_load_as_a_potential(tmp_path: Path) -> None:
    """A run's energy.csv counts the external loads' work as a potential beside gravity
    (-f_ext . u), not as elastic energy: after the static solve of the pressure-loaded
    cantilever (linear FEM), the elastic energy is u . K u / 2 = f_ext . u / 2 (Clapeyron;
    the trapezoid rule is exact for linear forces: 1e-9 relative), the load's potential is
    -f_ext . u, and the total is -f_ext . u / 2."""
    from topomech import cli

    out = tmp_path / "out"
    assert cli.main(["run", "pressure_cantilever", "--out", str(out), "--quiet"]) == 0
    rows = (out / "energy.csv").read_text().splitlines()
    head = rows[0].split(",")
    last = dict(zip(head, map(float, rows[-1].split(","))))
    sim = topomech.load_scene("pressure_cantilever").build()
    sim.step()
    work = float((sim.external_forces() * sim.displacements()).sum())
    assert work > 0
    assert last["elastic"] == pytest.approx(work / 2, rel=1e-9)
    assert last["gravitational"] == pytest.approx(-work, rel=1e-9)
    assert last["total"] == pytest.approx(-work / 2, rel=1e-9)


def test_a_load_failing_when_evaluated_names_its_part_and_its_points() -> None:
    """A load whose expression or ``where`` checks but cannot be evaluated at some point (a
    NaN pressure, ``clamp`` with crossed bounds) is a SceneError whose key names the part at
    fault (``load[0].pressure``, ``load[0].where``) and whose message says what the points
    are (quadrature points, face centroids), with no rule name."""
    base = BAR.format(element="tet", n=2)
    for load, key, words in (
        (
            'pressure = "1e3 * sqrt(0.1 - z)"\nwhere = "y < 1e-9"\n',
            "load[0].pressure",
            "quadrature points",
        ),
        (
            'pressure = 1.0\nwhere = "clamp(x, 1.0, 0.0) > 0.0"\n',
            "load[0].where",
            "rest centroids",
        ),
    ):
        with pytest.raises(topomech.SceneError) as e:
            parse_scene(base + '[[load]]\nkind = "pressure"\n' + load).build()
        assert e.value.key == key, str(e.value)
        assert words in str(e.value), str(e.value)
        assert "rule '" not in str(e.value)


def test_a_fix_or_region_failing_when_evaluated_is_keyed_by_its_scene_key() -> None:
    """A ``[[fix]]`` (held, or with a displacement) or ``[[material.region]]`` predicate that
    checks but fails when the kernel evaluates it (``clamp`` with crossed bounds) is a
    SceneError keyed by the table's ``where`` (not the kernel's own list index), naming the
    point it was evaluated at, with no rule name."""
    base = BAR.format(element="tet", n=2)
    bad = "clamp(x, 1.0, 0.0) > 0.0"
    for extra, key, words in (
        (f'[[fix]]\nwhere = "{bad}"\n', "fix[1].where", "vertex at rest position"),
        (
            f'[[fix]]\nwhere = "{bad}"\ndisplacement = [0.01, 0.0, 0.0]\n',
            "fix[1].where",
            "vertex at rest position",
        ),
        (
            f'[[material.region]]\nwhere = "x > 0.3 && {bad}"\ndensity = 2000.0\n',
            "material.region[0].where",
            "element whose rest centroid is",
        ),
    ):
        with pytest.raises(topomech.SceneError) as e:
            parse_scene(base + extra).build()
        assert e.value.key == key, str(e.value)
        assert words in str(e.value), str(e.value)
        assert "rule '" not in str(e.value)


def test_a_load_function_returning_nan_names_the_point() -> None:
    """A traction given as a Python function that returns NaN somewhere: the LoadError says
    the values are not finite and where, and a wrong shape says the shape it must have."""
    sim = parse_scene(BAR.format(element="tet", n=2)).build()
    with pytest.raises(loads.LoadError) as e:
        loads.surface_load(
            sim, pressure=lambda p: np.where(p[:, 2] < 0.1, 1.0, np.nan), where="y < 1e-9"
        )
    assert "not finite" in str(e.value)
    with pytest.raises(loads.LoadError) as e:
        loads.surface_load(sim, pressure=lambda p: np.zeros((len(p), 3)), where="y < 1e-9")
    assert "it must return (n,) values" in str(e.value)
