"""Newton (the successor of warp.sim) on the CPU: `SolverSemiImplicit` (symplectic Euler),
contact off (no shapes, particle hash grid removed, triangle contact disabled).

The model is built from particles and elements directly (`add_particle`, `add_tetrahedron`,
`add_spring`) so that nothing but the elements is evaluated: `add_soft_mesh` would also add
surface triangles and bending edges of zero stiffness that the solver still evaluates.

- tetrahedra: Newton's only tetrahedral model, the stable Neo-Hookean of Smith et al. 2018,
  given the Lame parameters of (E, nu) as its documentation asks (`k_mu`, `k_lambda`). At
  small strain it is linear elasticity with mu' = 3/4 mu and lambda' = lambda - 5/8 mu (its
  rest-stability terms); the accuracy run also reports Smith's reparametrisation
  (mu = 4/3 mu, lambda = lambda + 5/6 mu), which restores the linear limit.
- cloth: Newton's damped springs (the same Provot force) on the same edges, with the same
  summed stiffness and damping.

Warp's CPU backend runs kernels on one thread, in f32 (Newton's arrays are f32).
Viscous damping for the accuracy runs is our own warp kernel, -c m v added to the particle
forces before each step, which makes Newton's update a = f/m + g - c v like topomech's.
"""

from __future__ import annotations

from typing import Any

import common as C
import numpy as np

wp: Any = None
newton: Any = None


def setup() -> dict[str, Any]:
    global wp, newton
    import warp

    wp = warp
    wp.config.quiet = True
    wp.init()
    import newton as nt

    newton = nt
    return {
        "version": f"newton {nt.__version__}, warp {wp.__version__}",
        "threads": 1,
        "precision": "f32",
        "device": "cpu (warp CPU backend, single-threaded)",
    }


_damp_kernel = None


def _damping_kernel() -> Any:
    global _damp_kernel
    if _damp_kernel is None:

        @wp.kernel
        def add_viscous(
            v: wp.array(dtype=wp.vec3),
            m: wp.array(dtype=float),
            c: float,
            f: wp.array(dtype=wp.vec3),
        ):
            i = wp.tid()
            f[i] = f[i] - c * m[i] * v[i]

        _damp_kernel = add_viscous
    return _damp_kernel


def _build(case: C.Case, variant: str = "lame") -> tuple[Any, Any]:
    builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=wp.vec3(*C.GRAVITY))
    if case.kind == "tet":
        mesh = C.tet_mesh(case.cells)
        mu, lam = C.lame()
        if variant == "smith":
            mu, lam = 4.0 / 3.0 * mu, lam + 5.0 / 6.0 * mu
    else:
        mesh = C.cloth_mesh(case.cells)
    for p, m, fx in zip(mesh.points, mesh.masses, mesh.fixed):
        builder.add_particle(
            wp.vec3(*map(float, p)), wp.vec3(0.0, 0.0, 0.0), 0.0 if fx else float(m), radius=0.0
        )
    if case.kind == "tet":
        for t in mesh.tets:
            vol = builder.add_tetrahedron(
                int(t[0]), int(t[1]), int(t[2]), int(t[3]), k_mu=mu, k_lambda=lam, k_damp=0.0
            )
            if vol <= 0.0:
                raise RuntimeError("Newton refused an inverted tetrahedron")
    else:
        for (i, j), nf in zip(mesh.edges, mesh.edge_faces):
            builder.add_spring(
                int(i), int(j), C.CLOTH_STIFFNESS * float(nf), C.CLOTH_DAMPING * float(nf), 0.0
            )
    model = builder.finalize(device="cpu")
    model.particle_grid = None  # no particle-particle contact
    return mesh, model


def _stepper(model: Any, dt: float, damping: float = 0.0) -> tuple[Any, Any]:
    solver = newton.solvers.SolverSemiImplicit(model, enable_tri_contact=False)
    states = [model.state(), model.state()]
    control = model.control()
    masses = wp.array(model.particle_mass.numpy(), dtype=float, device="cpu")
    kern = _damping_kernel() if damping > 0.0 else None

    def step(k: int) -> None:
        for _ in range(k):
            s0, s1 = states
            s0.clear_forces()
            if kern is not None:
                wp.launch(
                    kern,
                    dim=model.particle_count,
                    inputs=[s0.particle_qd, masses, damping, s0.particle_f],
                    device="cpu",
                )
            solver.step(s0, s1, control, None, dt)
            states.reverse()
        wp.synchronize()

    return step, states


def timing(case: C.Case) -> dict[str, Any]:
    _mesh, model = _build(case)
    step, _ = _stepper(model, case.dt)
    out = C.time_steps(step, warmup=20, budget_s=2.0)
    out["model"] = (
        "stable Neo-Hookean tets (Smith 2018), SemiImplicit"
        if case.kind == "tet"
        else "damped springs on triangle edges, SemiImplicit"
    )
    return out


def accuracy(case: C.Case, ref: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {"model": "stable Neo-Hookean (Lame parameters of E, nu)"}
    steps = round(C.ACCURACY_TIME / case.dt)
    for variant in ("lame", "smith"):
        mesh, model = _build(case, variant)
        step, states = _stepper(model, case.dt, 2.0 * ref["omega_1"])
        step(steps)
        pos = states[0].particle_q.numpy().astype(np.float64)
        vel = states[0].particle_qd.numpy().astype(np.float64)
        tip = C.tip_deflection(mesh, pos)
        if variant == "lame":
            out.update(
                tip_deflection=tip,
                steps=steps,
                max_speed_end=float(np.linalg.norm(vel, axis=1).max()),
            )
        else:
            out["variants"] = [
                {"name": "Smith reparametrisation (mu 4/3, lambda + 5/6 mu)", "tip_deflection": tip}
            ]
    return out
