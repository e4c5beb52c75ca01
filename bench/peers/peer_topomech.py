"""topomech itself, through its Python API (`topomech.Simulation`): `corotational` on the
tetrahedra, `stretch_cumulated` on the cloth's triangle edges, symplectic Euler, the same dt
and mesh as every peer. On the tetrahedra also its stable Neo-Hookean (`neohookean`, Smith,
de Goes & Kim 2018, with the paper's Lame reparametrisation), timed and run on the
cantilevers, to set beside Newton's Neo-Hookean on the same meshes. The worker runs it with
RAYON_NUM_THREADS=1: one thread, like every peer."""

from __future__ import annotations

from typing import Any

import common as C
import numpy as np


def setup() -> dict[str, Any]:
    import os

    import topomech

    threads = int(os.environ.get("RAYON_NUM_THREADS", "0")) or os.cpu_count()
    return {
        "version": topomech.__version__,
        "threads": threads,
        "precision": "f64",
        "device": f"cpu (topomech.Simulation, RAYON_NUM_THREADS={threads})",
    }


def make_sim(
    case: C.Case, damping: float, integrator: str = "symplectic_euler", model: str | None = None
) -> Any:
    import topomech

    if case.kind == "tet":
        g = C.topomech_tet_map(case.cells)
        return topomech.Simulation(
            g,
            models=[{"kind": model or "corotational"}],
            density=C.DENSITY,
            young=C.YOUNG,
            poisson=C.POISSON,
            damping=damping,
            gravity=list(C.GRAVITY),
            fixed=[C.BEAM_FIXED],
            integrator=integrator,
            dt=case.dt,
        )
    g = C.topomech_cloth_map(case.cells)
    return topomech.Simulation(
        g,
        models=[
            {
                "kind": model or "stretch_cumulated",
                "stiffness": C.CLOTH_STIFFNESS,
                "damping": C.CLOTH_DAMPING,
            }
        ],
        density=C.CLOTH_DENSITY,
        damping=damping,
        gravity=list(C.GRAVITY),
        fixed=[C.CLOTH_FIXED],
        integrator=integrator,
        dt=case.dt,
    )


def forces_at(case: C.Case, pos: np.ndarray, vel: np.ndarray) -> np.ndarray:
    sim = make_sim(case, 0.0)
    sim.set_positions(pos)
    sim.set_velocities(vel)
    return sim.forces()


def timing(case: C.Case) -> dict[str, Any]:
    sim = make_sim(case, 0.0)
    mesh = C.tet_mesh(case.cells) if case.kind == "tet" else C.cloth_mesh(case.cells)
    if not np.array_equal(sim.rest_positions(), mesh.points):
        raise RuntimeError("vertex order differs from the exported mesh")
    out = C.time_steps(sim.step, warmup=2, budget_s=3.0, min_batches=5, max_batches=15)
    out["model"] = "corotational" if case.kind == "tet" else "stretch_cumulated"
    if case.kind == "tet":
        nh = make_sim(case, 0.0, model="neohookean")
        t = C.time_steps(nh.step, warmup=2, budget_s=3.0, min_batches=5, max_batches=15)
        out["time_per_step_ms_neohookean"] = t["time_per_step_ms"]
    return out


def accuracy(case: C.Case, ref: dict[str, Any]) -> dict[str, Any]:
    mesh = C.tet_mesh(case.cells)
    sim = make_sim(case, 2.0 * ref["omega_1"])
    steps = round(C.ACCURACY_TIME / case.dt)
    sim.step(steps)
    out = {
        "model": "corotational, symplectic Euler",
        "steps": steps,
        "tip_deflection": C.tip_deflection(mesh, sim.positions()),
        "max_speed_end": float(np.linalg.norm(sim.velocities(), axis=1).max()),
    }
    # Its stable Neo-Hookean on the same beam, the same steps (Newton's tet model, to compare
    # at equal accuracy)
    nh = make_sim(case, 2.0 * ref["omega_1"], model="neohookean")
    nh.step(steps)
    out["variants"] = [
        {
            "name": "stable Neo-Hookean (neohookean, Smith 2018 reparametrised)",
            "tip_deflection": C.tip_deflection(mesh, nh.positions()),
        }
    ]
    # The kernel's own static solve of linear FEM: a check of the numpy reference.
    st = make_sim(case, 0.0, integrator="static", model="linear_fem")
    st.step(1)
    out["static_linear_fem_tip"] = C.tip_deflection(mesh, st.positions())
    return out
