"""pyPBD (the Python bindings of PositionBasedDynamics), contact off (no collision
detection attached to the time step controller), OpenMP limited to one thread
(OMP_NUM_THREADS=1, set by the worker before the import), double precision.

- tetrahedra: its FEM-based PBD tet constraints (`addSolidConstraints` method 2, Bender et
  al.: the element's St. Venant-Kirchhoff energy projected as a constraint), given E and nu.
  This is position-based: the equilibrium it settles at depends on the time step, the
  sub-steps and the iteration count, not only on the material; the accuracy run reports it
  at the defaults and for other iteration counts.
- cloth: XPBD distance constraints on the same edges, stiffness = the summed spring
  stiffness (compliance 1 / k); they have no damping term.

A pyPBD step of dt runs its default sub-steps (5) of one iteration each (its defaults, kept);
time_per_step_ms is per step of dt. Viscous damping for the accuracy runs: the velocities
are scaled by (1 - c dt) after each step, through the bindings (per particle).
"""

from __future__ import annotations

from typing import Any

import common as C
import numpy as np

pbd: Any = None
DEFAULTS: dict[str, int] = {}


def setup() -> dict[str, Any]:
    global pbd
    import importlib.metadata

    import pypbd

    pbd = pypbd
    ts = pbd.Simulation.getCurrent().getTimeStep()
    T = pbd.TimeStepController
    DEFAULTS.update(
        substeps=ts.getValueUInt(T.NUM_SUB_STEPS), iterations=ts.getValueUInt(T.MAX_ITERATIONS)
    )
    return {
        "version": importlib.metadata.version("pypbd"),
        "threads": 1,
        "precision": "f64",
        "device": "cpu (OpenMP, OMP_NUM_THREADS=1)",
    }


def _build(
    case: C.Case, substeps: int | None = None, iterations: int | None = None, young: float = C.YOUNG
) -> tuple[Any, Any, Any, dict[str, Any]]:
    sim = pbd.Simulation.getCurrent()
    model = pbd.SimulationModel()
    model.init()
    sim.setModel(model)  # no collision detection: contact off
    ts = sim.getTimeStep()
    T = pbd.TimeStepController
    # The controller outlives the model: set both every time (None: the library's default).
    ts.setValueUInt(T.NUM_SUB_STEPS, DEFAULTS["substeps"] if substeps is None else substeps)
    ts.setValueUInt(T.MAX_ITERATIONS, DEFAULTS["iterations"] if iterations is None else iterations)
    params = {
        "substeps": ts.getValueUInt(T.NUM_SUB_STEPS),
        "iterations": ts.getValueUInt(T.MAX_ITERATIONS),
        "velocity_iterations": ts.getValueUInt(T.MAX_ITERATIONS_V),
    }
    pbd.TimeManager.getCurrent().setTimeStepSize(case.dt)
    pbd.TimeManager.getCurrent().setTime(0.0)
    if case.kind == "tet":
        mesh = C.tet_mesh(case.cells)
        tm = model.addTetModel([p for p in mesh.points], mesh.tets.ravel().tolist())
        model.addSolidConstraints(tm, 2, young, C.POISSON, young, False, False)
    else:
        mesh = C.cloth_mesh(case.cells)
        model.addTriangleModel([p for p in mesh.points], mesh.tris.ravel().tolist())
        for (i, j), nf in zip(mesh.edges, mesh.edge_faces):
            model.addDistanceConstraint_XPBD(int(i), int(j), C.CLOTH_STIFFNESS * float(nf))
    pd = model.getParticles()
    if pd.size() != len(mesh.points):
        raise RuntimeError("pyPBD particle count differs from the mesh")
    for i, (m, fx) in enumerate(zip(mesh.masses, mesh.fixed)):
        pd.setMass(i, 0.0 if fx else float(m))
    got = np.array([pd.getPosition(i) for i in range(pd.size())]).reshape(-1, 3)
    if not np.allclose(got, mesh.points):
        raise RuntimeError("pyPBD reordered the particles")
    return sim, model, mesh, params


def _stepper(sim: Any, model: Any) -> Any:
    ts = sim.getTimeStep()

    def step(k: int) -> None:
        for _ in range(k):
            ts.step(model)

    return step


def timing(case: C.Case) -> dict[str, Any]:
    sim, model, _mesh, params = _build(case)
    out = C.time_steps(_stepper(sim, model), warmup=5, budget_s=2.0)
    out.update(params)
    # one sub-step per step, for reference
    sim, model, _mesh, _p1 = _build(case, substeps=1)
    one = C.time_steps(_stepper(sim, model), warmup=5, budget_s=1.0)
    out["time_per_step_ms_1_substep"] = one["time_per_step_ms"]
    out["model"] = (
        "FEM-based PBD tets (method 2)"
        if case.kind == "tet"
        else "XPBD distance constraints on triangle edges (no damping)"
    )
    return out


def _settle(
    case: C.Case,
    ref: dict[str, Any],
    substeps: int | None,
    iterations: int | None,
    young: float = C.YOUNG,
) -> dict[str, Any]:
    sim, model, mesh, params = _build(case, substeps, iterations, young)
    step = _stepper(sim, model)
    pd = model.getParticles()
    n = pd.size()
    keep = 1.0 - 2.0 * ref["omega_1"] * case.dt
    steps = round(C.ACCURACY_TIME / case.dt)
    for _ in range(steps):
        step(1)
        for i in range(n):
            pd.setVelocity(i, keep * pd.getVelocity(i))
    pos = np.array([pd.getPosition(i) for i in range(n)]).reshape(-1, 3)
    vel = np.array([pd.getVelocity(i) for i in range(n)]).reshape(-1, 3)
    return {
        "tip_deflection": C.tip_deflection(mesh, pos),
        "steps": steps,
        "max_speed_end": float(np.linalg.norm(vel, axis=1).max()),
        **params,
    }


def accuracy(case: C.Case, ref: dict[str, Any]) -> dict[str, Any]:
    out = {"model": "FEM-based PBD tets (method 2), defaults"}
    out.update(_settle(case, ref, None, None))
    variants = []
    for sub, it in ((1, 1), (1, 10), (5, 10)):
        r = _settle(case, ref, sub, it)
        variants.append(
            {
                "name": f"{sub} sub-step(s) x {it} iteration(s)",
                "tip_deflection": r["tip_deflection"],
            }
        )
    # Position-based: the answer does not follow the material. Same run with E / 100.
    r = _settle(case, ref, None, None, C.YOUNG / 100.0)
    variants.append({"name": "defaults with E / 100", "tip_deflection": r["tip_deflection"]})
    out["variants"] = variants
    return out
