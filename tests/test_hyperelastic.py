"""Stable Neo-Hookean and St. Venant-Kirchhoff tetrahedra (the rule file
crates/physics/models/hyperelastic3d.tmr) against a numpy implementation written here from the
formulas: the first Piola-Kirchhoff stress of each energy and the standard tetrahedron force
f_i = -V P grad(N_i), and, separately, minus the complex-step gradient of the total energy.
Scenes name the models like the shipped ones; at small strain they agree with linear FEM."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

import topomech
from topomech import _core
from topomech.run import run_scene

Array = npt.NDArray[np.float64]
YOUNG, POISSON = 1e6, 0.3


def lame(young: float, nu: float) -> tuple[float, float]:
    """(mu, lambda) of linear elasticity."""
    return young / (2 * (1 + nu)), young * nu / ((1 + nu) * (1 - 2 * nu))


def neohookean_params(young: float, nu: float) -> tuple[float, float, float]:
    """Smith, de Goes & Kim 2018 (doi:10.1145/3180491): Lame parameters matching linear
    elasticity at small strain (mu = 4/3 mu_lin, lambda = lambda_lin + 5/6 mu_lin) and
    alpha = 1 + 3 mu / (4 lambda), which makes the rest state stress-free."""
    mu0, lam0 = lame(young, nu)
    mu, lam = 4 / 3 * mu0, lam0 + 5 / 6 * mu0
    return mu, lam, 1 + 3 * mu / (4 * lam)


def piola(kind: str, f: Array) -> Array:
    """First Piola-Kirchhoff stress P(F) for a stack of F, shape (T, 3, 3)."""
    ft = np.swapaxes(f, 1, 2)
    if kind == "neohookean":
        mu, lam, alpha = neohookean_params(YOUNG, POISSON)
        ic = np.einsum("tij,tij->t", f, f)
        j = np.linalg.det(f)
        djdf = j[:, None, None] * np.linalg.inv(ft)  # d det F / dF = J F^-T
        return (mu * (1 - 1 / (ic + 1)))[:, None, None] * f + (lam * (j - alpha))[
            :, None, None
        ] * djdf
    mu, lam = lame(YOUNG, POISSON)
    e = 0.5 * (ft @ f - np.eye(3))
    tr = np.trace(e, axis1=1, axis2=2)
    return f @ (2 * mu * e + lam * tr[:, None, None] * np.eye(3))


def energy_density(kind: str, f: npt.NDArray[np.complex128]) -> npt.NDArray[np.complex128]:
    """Psi(F), complex-safe (for complex-step differentiation)."""
    ft = np.swapaxes(f, 1, 2)
    if kind == "neohookean":
        mu, lam, alpha = neohookean_params(YOUNG, POISSON)
        ic = np.einsum("tij,tij->t", f, f)
        j = np.linalg.det(f)
        return mu / 2 * (ic - 3) + lam / 2 * (j - alpha) ** 2 - mu / 2 * np.log(ic + 1)
    mu, lam = lame(YOUNG, POISSON)
    e = 0.5 * (ft @ f - np.eye(3))
    tr = np.trace(e, axis1=1, axis2=2)
    return mu * np.einsum("tij,tij->t", e, e) + lam / 2 * tr**2


def shape_gradients(rest: Array, tets: npt.NDArray[np.int64]) -> tuple[Array, Array]:
    """Gradients of the four linear shape functions of each tetrahedron, (T, 4, 3), and the
    rest volumes, (T,): solving [1 X]^T c = I per element (independent of any edge matrix)."""
    t = len(tets)
    a = np.ones((t, 4, 4))
    a[:, :, 1:] = rest[tets]
    coeffs = np.linalg.inv(a)  # column i: the coefficients (c0, grad) of N_i
    grads = np.swapaxes(coeffs[:, 1:, :], 1, 2)
    vol = np.abs(np.linalg.det(a)) / 6
    return grads, vol


def deformation_gradients(x: Array, tets: npt.NDArray[np.int64], grads: Array) -> Array:
    """F = sum_i x_i grad(N_i)^T, (T, 3, 3)."""
    return np.einsum("tia,tib->tab", x[tets], grads)


def reference_forces(kind: str, rest: Array, x: Array, tets: npt.NDArray[np.int64]) -> Array:
    """f_i = -V P grad(N_i), summed over the elements of each vertex."""
    grads, vol = shape_gradients(rest, tets)
    p = piola(kind, deformation_gradients(x, tets, grads))
    per_corner = -vol[:, None, None] * np.einsum("tab,tib->tia", p, grads)
    out = np.zeros_like(x)
    np.add.at(out, tets, per_corner)
    return out


def complex_step_forces(kind: str, rest: Array, x: Array, tets: npt.NDArray[np.int64]) -> Array:
    """-dE/dx with E = sum V Psi(F), by the complex step (Squire & Trapp 1998): exact to
    rounding, no subtraction."""
    grads, vol = shape_gradients(rest, tets)
    h = 1e-30
    out = np.zeros_like(x)
    for v in range(len(x)):
        for a in range(3):
            xc = x.astype(np.complex128)
            xc[v, a] += 1j * h
            f = np.einsum("tia,tib->tab", xc[tets], grads)
            out[v, a] = -np.sum(vol * energy_density(kind, f)).imag / h
    return out


def sim(kind: str, **kw: object) -> topomech.Simulation:
    g = topomech.GMap.from_flat(*_core.box(3, 2, 2, 1.0, 0.8, 0.6, "tetra"))
    cfg: dict[str, object] = {
        "models": [{"kind": kind}],
        "young": YOUNG,
        "poisson": POISSON,
        "gravity": [0.0, 0.0, 0.0],
    }
    cfg.update(kw)
    return topomech.Simulation(g, **cfg)


def tets_of(s: topomech.Simulation) -> npt.NDArray[np.int64]:
    _, rows = s.elements()
    assert all(len(r) == 4 for r in rows)
    return np.array(rows, dtype=np.int64)


def twisted(rest: Array) -> Array:
    """A large non-affine deformation: stretch, shear, bend and twist (strains of tens of
    percent), no element inverted."""
    x, y, z = rest.T
    theta = 0.8 * x
    c, s = np.cos(theta), np.sin(theta)
    u = 1.3 * x + 0.2 * y**2
    v = 0.8 * y + 0.25 * x * z
    w = z + 0.3 * x * y - 0.1 * z**2
    return np.stack([u, c * v - s * w, s * v + c * w + 0.05 * u * u], axis=1)


KINDS = ["neohookean", "stvk"]


@pytest.mark.parametrize("kind", KINDS)
def test_large_deformation_forces_equal_numpy(kind: str) -> None:
    """The rules' forces equal the numpy stress-based reference to 1e-10 of the largest force
    (both are rounding-exact; the gap is rounding, ~1e-14), and the complex-step gradient of
    the energy to 1e-10 (it checks that P is the derivative of the stated energy)."""
    s = sim(kind)
    rest = s.rest_positions()
    tets = tets_of(s)
    x = twisted(rest)
    grads, _ = shape_gradients(rest, tets)
    j = np.linalg.det(deformation_gradients(x, tets, grads))
    assert j.min() > 0.3
    assert j.max() - j.min() > 0.2  # large: volumes change by tens of percent
    s.set_positions(x)
    ours = s.forces()
    ref = reference_forces(kind, rest, x, tets)
    scale = np.abs(ref).max()
    assert scale > 1e4
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(
        ours, complex_step_forces(kind, rest, x, tets), rtol=0, atol=1e-10 * scale
    )


@pytest.mark.parametrize("kind", KINDS)
def test_zero_force_at_rest_and_under_rotation(kind: str) -> None:
    """P(I) = 0 and P(R) = R P(I) = 0: the forces vanish to rounding (1e-9 of E h^2) at rest and
    after a large rigid rotation and translation; a 5% stretch does not."""
    s = sim(kind)
    rest = s.rest_positions()
    scale = YOUNG * 0.3**2
    assert np.abs(s.forces()).max() < 1e-9 * scale
    angle = 2.0
    axis = np.array([0.4, -1.0, 2.0]) / np.linalg.norm([0.4, -1.0, 2.0])
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    r = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    s.set_positions(rest @ r.T + [1.0, -2.0, 0.5])
    assert np.abs(s.forces()).max() < 1e-9 * scale
    s.set_positions(rest * [1.05, 1.0, 1.0])
    assert np.abs(s.forces()).max() > 1e-3 * scale


SCENE = """
[mesh]
generator = "box"
element = "tet"
size = [2.0, 0.4, 0.4]
cells = [5, 1, 1]

[[model]]
kind = "{kind}"
young = 1e7
poisson = 0.3

[material]
density = 1000.0
damping = {damping}

[[fix]]
where = "x < 1e-9"

[world]
gravity = [0.0, {gy}, 0.0]

[integrator]
kind = "{integrator}"
dt = {dt}
steps = {steps}

[output]
every = 0
"""


def run(
    tmp_path: Path, kind: str, integrator: str, gy: float, dt: float, steps: int, damping: float
) -> float:
    scene = tmp_path / f"{kind}_{integrator}.toml"
    scene.write_text(
        SCENE.format(kind=kind, integrator=integrator, gy=gy, dt=dt, steps=steps, damping=damping)
    )
    summary = run_scene(scene, tmp_path / f"out_{kind}_{integrator}", preview=False, video=False)
    assert summary["steps"] == steps
    return float(summary["max_displacement"])


@pytest.mark.parametrize("kind", KINDS)
def test_scene_static_cantilever_matches_linear_fem(tmp_path: Path, kind: str) -> None:
    """A scene naming the model runs (static solve of a cantilever under a small load, a
    deflection ~2e-6 of the length): its largest displacement equals linear FEM's to 1e-5
    (measured ~3e-7: the models are linear elasticity to O(strain); Neo-Hookean without the
    small-strain Lame parameters of Smith et al. is off by tens of percent)."""
    ours = run(tmp_path, kind, "static", -1e-3, 1.0, 1, 0.0)
    linear = run(tmp_path, "linear_fem", "static", -1e-3, 1.0, 1, 0.0)
    assert 1e-7 < linear < 1e-5
    assert abs(ours - linear) <= 1e-5 * linear


def beam_run(kind: str, integrator: str, dt: float, steps: int) -> Array:
    """The displacement field of a clamped beam under a small load after `steps` steps."""
    g = topomech.GMap.from_flat(*_core.box(5, 1, 1, 2.0, 0.4, 0.4, "tetra"))
    s = topomech.Simulation(
        g,
        models=[{"kind": kind}],
        young=1e7,
        poisson=0.3,
        density=1000.0,
        damping=0.5,
        gravity=[0.0, -1e-3, 0.0],
        fixed=["x < 1e-9"],
        integrator=integrator,
        dt=dt,
    )
    s.step(steps)
    return s.positions() - s.rest_positions()


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize(
    ("integrator", "dt", "steps"),
    [
        ("explicit_euler", 5e-5, 400),
        ("symplectic_euler", 5e-5, 400),
        ("implicit_euler", 2e-3, 20),
        ("static", 1.0, 1),
    ],
)
def test_each_integrator_matches_linear_fem_at_small_strain(
    kind: str, integrator: str, dt: float, steps: int
) -> None:
    """Every integrator runs the model; at small strain the displacement field equals linear
    FEM's run to 1e-5 of the largest displacement (the explicit runs last 0.02 s, a wave's
    crossing of the beam, below the stability limit h / c ~ 2e-3 s; the clamp's elastic
    response is in the field, not only the free fall)."""
    ours = beam_run(kind, integrator, dt, steps)
    linear = beam_run("linear_fem", integrator, dt, steps)
    scale = np.linalg.norm(linear, axis=1).max()
    assert scale > 0
    gap = np.linalg.norm(ours - linear, axis=1).max() / scale
    assert gap <= 1e-5


def test_models_are_listed() -> None:
    for kind in KINDS:
        listed = [m for m in topomech.available_models() if m["kind"] == kind]
        assert listed == [
            {"kind": kind, "dims": [3], "params": {}, "needs": "tetrahedra", "per_element": True}
        ]


@pytest.mark.parametrize("kind", KINDS)
def test_a_hexahedral_mesh_is_refused(kind: str) -> None:
    g = topomech.GMap.from_flat(*_core.box(2, 1, 1, 1.0, 0.5, 0.5, "hexahedron"))
    with pytest.raises(topomech.SimulationError, match=f"model '{kind}' matches nothing"):
        topomech.Simulation(g, models=[{"kind": kind}])
