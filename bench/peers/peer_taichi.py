"""Taichi peer: our own Taichi kernels (CPU backend, one thread, f64) of the same models as
topomech's, integrated the same way (symplectic Euler, viscous damping):

- tetrahedra: co-rotational linear FEM (Mueller & Gross 2004), f_a = -V R sigma(eps) g_a with
  R the polar rotation of F = Ds Dm^-1 and eps = sym(R^T F - I), which is exactly
  -R K (R^T x - X) for a linear tetrahedron (topomech's `corotational`);
- cloth: Provot springs on every triangle edge, stiffness and damping summed over the
  triangles on the edge (topomech's `stretch_cumulated`).

`model_check` compares these forces with topomech's (`Simulation.forces()`) at a perturbed,
rotated, moving state: the same model, not just the same class.
"""

from __future__ import annotations

from typing import Any

import common as C
import numpy as np

ti: Any = None


def setup() -> dict[str, Any]:
    global ti
    import taichi

    ti = taichi
    ti.init(
        arch=ti.cpu, cpu_max_num_threads=1, default_fp=ti.f64, offline_cache=True, log_level=ti.WARN
    )
    return {
        "version": ".".join(map(str, ti.__version__)),
        "threads": 1,
        "precision": "f64",
        "device": "cpu (taichi arch=cpu, cpu_max_num_threads=1)",
    }


def _make_sim(case: C.Case, damping: float) -> Any:
    vec3 = ti.types.vector(3, ti.f64)
    mesh = C.tet_mesh(case.cells) if case.kind == "tet" else C.cloth_mesh(case.cells)
    n = len(mesh.points)
    x = ti.Vector.field(3, ti.f64, shape=n)
    v = ti.Vector.field(3, ti.f64, shape=n)
    f = ti.Vector.field(3, ti.f64, shape=n)
    inv_m = ti.field(ti.f64, shape=n)
    x.from_numpy(mesh.points)
    v.fill(0.0)
    w = np.where(mesh.fixed, 0.0, 1.0 / mesh.masses)
    inv_m.from_numpy(w)
    g = vec3(*C.GRAVITY)
    dt = case.dt
    c = float(damping)

    if case.kind == "tet":
        mu, lam = C.lame()
        nt = len(mesh.tets)
        tets = ti.Vector.field(4, ti.i32, shape=nt)
        dminv = ti.Matrix.field(3, 3, ti.f64, shape=nt)
        vol = ti.field(ti.f64, shape=nt)
        tets.from_numpy(mesh.tets.astype(np.int32))
        x0 = mesh.points[mesh.tets[:, 0]]
        dm = np.stack([mesh.points[mesh.tets[:, i]] - x0 for i in (1, 2, 3)], axis=2)
        dminv.from_numpy(np.linalg.inv(dm))
        vol.from_numpy(mesh.volumes)

        @ti.func
        def element_forces():
            for t in range(nt):
                a, b, cc, d = tets[t][0], tets[t][1], tets[t][2], tets[t][3]
                xa = x[a]
                ds = ti.Matrix.cols([x[b] - xa, x[cc] - xa, x[d] - xa])
                fm = ds @ dminv[t]
                r, _s = ti.polar_decompose(fm, ti.f64)
                gm = r.transpose() @ fm - ti.Matrix.identity(ti.f64, 3)
                eps = 0.5 * (gm + gm.transpose())
                sigma = 2.0 * mu * eps + lam * eps.trace() * ti.Matrix.identity(ti.f64, 3)
                h = -vol[t] * (r @ sigma) @ dminv[t].transpose()
                fb = vec3(h[0, 0], h[1, 0], h[2, 0])
                fc = vec3(h[0, 1], h[1, 1], h[2, 1])
                fd = vec3(h[0, 2], h[1, 2], h[2, 2])
                f[b] += fb
                f[cc] += fc
                f[d] += fd
                f[a] -= fb + fc + fd

    else:
        ne = len(mesh.edges)
        ends = ti.Vector.field(2, ti.i32, shape=ne)
        rest = ti.field(ti.f64, shape=ne)
        ke = ti.field(ti.f64, shape=ne)
        kd = ti.field(ti.f64, shape=ne)
        ends.from_numpy(mesh.edges.astype(np.int32))
        rest.from_numpy(mesh.rest)
        ke.from_numpy(C.CLOTH_STIFFNESS * mesh.edge_faces.astype(np.float64))
        kd.from_numpy(C.CLOTH_DAMPING * mesh.edge_faces.astype(np.float64))

        @ti.func
        def element_forces():
            for e in range(ne):
                i, j = ends[e][0], ends[e][1]
                dd = x[j] - x[i]
                ln = dd.norm()
                u = dd / ln
                fs = (ke[e] * (ln - rest[e]) + kd[e] * (v[j] - v[i]).dot(u)) * u
                f[i] += fs
                f[j] -= fs

    @ti.kernel
    def compute_forces():
        for i in range(n):
            f[i] = vec3(0.0, 0.0, 0.0)
        element_forces()

    @ti.kernel
    def step_kernel():
        for i in range(n):
            f[i] = vec3(0.0, 0.0, 0.0)
        element_forces()
        for i in range(n):
            if inv_m[i] > 0.0:
                vel = v[i] + dt * (f[i] * inv_m[i] + g - c * v[i])
                v[i] = vel
                x[i] += dt * vel

    def step(k: int) -> None:
        for _ in range(k):
            step_kernel()
        ti.sync()

    return mesh, step, x, v, f, compute_forces


def model_check(case: C.Case) -> float:
    """Max |f_taichi - f_topomech| / max |f_topomech| at a perturbed state."""
    import peer_topomech

    mesh, _step, x, v, f, compute_forces = _make_sim(case, 0.0)
    rng = np.random.default_rng(1)
    n = len(mesh.points)
    # a rotation of 0.3 rad about z plus small random displacements, random velocities
    th = 0.3
    rot = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    scale = 0.01 if case.kind == "tet" else 0.003
    pos = mesh.points @ rot.T + scale * rng.standard_normal((n, 3))
    vel = rng.standard_normal((n, 3))
    x.from_numpy(pos)
    v.from_numpy(vel)
    compute_forces()
    ours = f.to_numpy()
    theirs = peer_topomech.forces_at(case, pos, vel)
    return float(np.abs(ours - theirs).max() / np.abs(theirs).max())


def timing(case: C.Case) -> dict[str, Any]:
    _mesh, step, *_ = _make_sim(case, 0.0)
    out = C.time_steps(step, warmup=20, budget_s=2.0)
    out["model"] = (
        "co-rotational linear FEM (own Taichi kernel)"
        if case.kind == "tet"
        else "Provot springs on triangle edges (own Taichi kernel)"
    )
    out["model_check_rel_force_diff"] = model_check(case)
    return out


def accuracy(case: C.Case, ref: dict[str, Any]) -> dict[str, Any]:
    damping = 2.0 * ref["omega_1"]
    mesh, step, x, v, *_ = _make_sim(case, damping)
    steps = round(C.ACCURACY_TIME / case.dt)
    step(steps)
    pos = x.to_numpy()
    return {
        "model": "co-rotational linear FEM (own Taichi kernel)",
        "tip_deflection": C.tip_deflection(mesh, pos),
        "steps": steps,
        "max_speed_end": float(np.linalg.norm(v.to_numpy(), axis=1).max()),
    }
