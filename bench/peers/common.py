"""Shared pieces of the peer benchmark: the cases, the meshes (topomech's own generators,
exported as arrays so that every peer runs on the same vertices and elements), the
independent linear-FEM reference (numpy only) and the timing helper.

Nothing here imports a peer; only numpy and topomech.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

# ------------------------------------------------------------------ material and loading

YOUNG = 1e7  # Pa, as the shipped cantilever scene
POISSON = 0.3
DENSITY = 1000.0  # kg/m^3
GRAVITY = (0.0, -9.81, 0.0)  # every case loads along -y (pyPBD's fixed gravity direction)
BEAM_SIZE = (1.0, 0.2, 0.2)  # m; clamped at x = 0

CLOTH_SIZE = 1.0  # m, square
CLOTH_DENSITY = 0.2  # kg/m^2
CLOTH_STIFFNESS = 1000.0  # N/m per elementary spring (one per triangle side)
CLOTH_DAMPING = 0.05  # N s/m per elementary spring (Provot)


def lame(young: float = YOUNG, poisson: float = POISSON) -> tuple[float, float]:
    """(mu, lambda) of an isotropic material."""
    mu = young / (2.0 * (1.0 + poisson))
    lam = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
    return mu, lam


# ------------------------------------------------------------------ cases


@dataclass(frozen=True)
class Case:
    """One benchmark case: a mesh, a model class and the time step all peers use."""

    name: str
    kind: str  # "tet" (FEM on a tet beam) or "cloth" (mass-spring on a triangle grid)
    cells: tuple[int, ...]  # box (nx, ny, nz) or grid (nx, ny)
    dt: float
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


# 6 tetrahedra per cell (topomech's box generator): 1,600 and 12,800 are not multiples of 6.
# The nearest beam-shaped counts: 17x4x4 cells = 1,632 tets, 33x8x8 cells = 12,672 tets.
TIMING_CASES = [
    Case("tet_1600", "tet", (17, 4, 4), 1.5e-4, "asked 1,600 tets; nearest with 6 tets/cell"),
    Case("tet_12800", "tet", (33, 8, 8), 7.5e-5, "asked 12,800 tets; nearest with 6 tets/cell"),
    Case("cloth_32", "cloth", (32, 32), 5e-5, "32x32 quad cells, each split in 2 triangles"),
    Case("cloth_64", "cloth", (64, 64), 2.5e-5, "64x64 quad cells, each split in 2 triangles"),
]

# The cantilever accuracy runs: the shipped cantilever scene's beam (10x2x2 cells, 240 tets)
# and the 1,632-tet timing beam. Viscous damping (1/s) near critical for the first bending
# mode (c = 2 omega_1, omega_1 from the reference's eigenvalues); run for ACCURACY_TIME
# simulated seconds (omega_1 t > 10), then compare the tip with the static reference.
ACCURACY_CASES = [
    Case("cantilever_240", "tet", (10, 2, 2), 2e-4, "the shipped cantilever scene's mesh"),
    Case("cantilever_1632", "tet", (17, 4, 4), 1.5e-4, "the tet_1600 timing mesh"),
]
ACCURACY_TIME = 0.5  # s


def case_by_name(name: str) -> Case:
    for c in TIMING_CASES + ACCURACY_CASES:
        if c.name == name:
            return c
    raise KeyError(name)


# ------------------------------------------------------------------ meshes


@dataclass
class TetMesh:
    points: np.ndarray  # (V, 3), topomech's vertex order
    tets: np.ndarray  # (T, 4), positively oriented
    fixed: np.ndarray  # (V,) bool: x = 0
    masses: np.ndarray  # (V,) lumped: density * volume / 4 per tet corner
    tip: np.ndarray  # indices of the vertices at x = L
    volumes: np.ndarray  # (T,)


@dataclass
class ClothMesh:
    points: np.ndarray  # (V, 3) in the plane y = 0 (x, z from the grid)
    tris: np.ndarray  # (F, 3)
    edges: np.ndarray  # (E, 2)
    edge_faces: np.ndarray  # (E,) number of triangles on each edge (1 or 2)
    rest: np.ndarray  # (E,) rest lengths
    fixed: np.ndarray  # (V,) bool: the two corners z = max, x = 0 or x = max
    masses: np.ndarray  # (V,) lumped: density * area / 3 per triangle corner


def tet_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    x0 = points[tets[:, 0]]
    d = np.stack([points[tets[:, i]] - x0 for i in (1, 2, 3)], axis=2)  # columns
    return np.linalg.det(d) / 6.0


def topomech_tet_map(cells: tuple[int, ...]) -> Any:
    """topomech's G-map of the beam (its `box` generator, as a scene's [mesh] builds it)."""
    import topomech
    from topomech import _core

    nx, ny, nz = cells
    sx, sy, sz = BEAM_SIZE
    return topomech.GMap.from_flat(*_core.box(nx, ny, nz, sx, sy, sz, "tetra"))


def topomech_cloth_map(cells: tuple[int, ...]) -> Any:
    """topomech's G-map of the cloth: its `grid` generator, rotated into the plane y = 0
    (grid x -> x, grid y -> z) so that gravity -y falls out of the plane."""
    import topomech
    from topomech import _core

    nx, ny = cells
    pts, kinds, offsets, conn = _core.grid(nx, ny, CLOTH_SIZE, CLOTH_SIZE, "triangle")
    pts = np.asarray(pts, dtype=np.float64)
    p3 = np.zeros((len(pts), 3))
    p3[:, 0] = pts[:, 0]
    p3[:, 2] = pts[:, 1]
    return topomech.GMap.from_flat(p3, kinds, offsets, conn)


def _flat_cells(gmap: Any, n: int) -> tuple[np.ndarray, np.ndarray]:
    flat = gmap.to_flat()
    points = np.asarray(flat.points if hasattr(flat, "points") else flat[0], dtype=np.float64)
    offsets = np.asarray(flat[2], dtype=np.int64)
    conn = np.asarray(flat[3], dtype=np.int64)
    assert np.all(np.diff(offsets) == n), "unexpected element kind"
    return points, conn.reshape(-1, n)


def tet_mesh(cells: tuple[int, ...]) -> TetMesh:
    """The beam as arrays, in the vertex order of topomech's simulation (the map's)."""
    points, tets = _flat_cells(topomech_tet_map(cells), 4)
    if points.shape[1] == 2:
        raise ValueError("expected 3D points")
    vol = tet_volumes(points, tets)
    neg = vol < 0
    tets = tets.copy()
    tets[neg, 2], tets[neg, 3] = tets[neg, 3].copy(), tets[neg, 2].copy()
    vol = np.abs(vol)
    masses = np.zeros(len(points))
    np.add.at(masses, tets.ravel(), np.repeat(DENSITY * vol / 4.0, 4))
    fixed = points[:, 0] < 1e-9
    tip = np.nonzero(points[:, 0] > BEAM_SIZE[0] - 1e-9)[0]
    return TetMesh(points, tets, fixed, masses, tip, vol)


def cloth_mesh(cells: tuple[int, ...]) -> ClothMesh:
    points, tris = _flat_cells(topomech_cloth_map(cells), 3)
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    edges, counts = np.unique(e, axis=0, return_counts=True)
    rest = np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1)
    a = points[tris[:, 1]] - points[tris[:, 0]]
    b = points[tris[:, 2]] - points[tris[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(a, b), axis=1)
    masses = np.zeros(len(points))
    np.add.at(masses, tris.ravel(), np.repeat(CLOTH_DENSITY * area / 3.0, 3))
    top = points[:, 2] > CLOTH_SIZE - 1e-9
    fixed = top & ((points[:, 0] < 1e-9) | (points[:, 0] > CLOTH_SIZE - 1e-9))
    return ClothMesh(points, tris, edges, counts, rest, fixed, masses)


CLOTH_FIXED = "z > 1.0 - 1e-9 && (x < 1e-9 || x > 1.0 - 1e-9)"
BEAM_FIXED = "x < 1e-9"


# ------------------------------------------------------------------ the linear reference


def tet_gradients(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """(T, 4, 3): the gradients of the four linear shape functions of each tetrahedron."""
    x0 = points[tets[:, 0]]
    dm = np.stack([points[tets[:, i]] - x0 for i in (1, 2, 3)], axis=2)
    inv = np.linalg.inv(dm)  # rows: gradients of N1, N2, N3
    g = np.empty((len(tets), 4, 3))
    g[:, 1:, :] = inv
    g[:, 0, :] = -inv.sum(axis=1)
    return g


def linear_stiffness(mesh: TetMesh, young: float = YOUNG, poisson: float = POISSON) -> np.ndarray:
    """The dense assembled linear-FEM stiffness (3V x 3V):
    K_ab = V (lambda g_a g_b^T + mu (g_a . g_b) I + mu g_b g_a^T) for each tetrahedron."""
    mu, lam = lame(young, poisson)
    g = tet_gradients(mesh.points, mesh.tets)
    v = mesh.volumes
    n = len(mesh.points)
    k = np.zeros((3 * n, 3 * n))
    eye = np.eye(3)
    for a in range(4):
        for b in range(4):
            ga, gb = g[:, a, :], g[:, b, :]
            blk = lam * np.einsum("ti,tj->tij", ga, gb) + mu * np.einsum("ti,tj->tij", gb, ga)
            blk += mu * np.einsum("ti,ti->t", ga, gb)[:, None, None] * eye
            blk *= v[:, None, None]
            ia, ib = mesh.tets[:, a], mesh.tets[:, b]
            for i in range(3):
                for j in range(3):
                    np.add.at(k, (3 * ia + i, 3 * ib + j), blk[:, i, j])
    return k


def static_reference(mesh: TetMesh) -> dict[str, Any]:
    """Linear static solve K u = m g with the x = 0 vertices clamped (numpy, dense).
    Returns the tip deflection (mean y-displacement of the x = L vertices, negative down) and
    the stable explicit time step bound 2 / omega_max of the lumped-mass system."""
    k = linear_stiffness(mesh)
    free = np.repeat(~mesh.fixed, 3)
    load = (mesh.masses[:, None] * np.asarray(GRAVITY)[None, :]).ravel()
    kff = k[np.ix_(free, free)]
    u = np.zeros(3 * len(mesh.points))
    u[free] = np.linalg.solve(kff, load[free])
    u = u.reshape(-1, 3)
    out: dict[str, Any] = {"tip_deflection": float(u[mesh.tip, 1].mean())}
    mf = np.repeat(mesh.masses, 3)[free]
    if kff.shape[0] <= 3000:
        s = 1.0 / np.sqrt(mf)
        w2 = np.linalg.eigvalsh(kff * s[:, None] * s[None, :])
        out["omega_1"] = float(math.sqrt(w2[0]))
        out["dt_stable"] = float(2.0 / math.sqrt(w2[-1]))
    return out


def tip_deflection(mesh: TetMesh, positions: np.ndarray) -> float:
    return float((positions[mesh.tip, 1] - mesh.points[mesh.tip, 1]).mean())


# ------------------------------------------------------------------ timing


def time_steps(
    step: Callable[[int], None],
    *,
    warmup: int,
    budget_s: float,
    min_batches: int = 5,
    max_batches: int = 30,
) -> dict[str, Any]:
    """Median time per step: runs `warmup` steps, sizes a batch to about budget_s / 10,
    then times batches until budget_s is spent (at least min_batches)."""
    step(warmup)
    t0 = time.perf_counter()
    step(1)
    one = max(time.perf_counter() - t0, 1e-7)
    batch = max(1, int(budget_s / 10.0 / one))
    per_step: list[float] = []
    spent = 0.0
    while len(per_step) < max_batches and (len(per_step) < min_batches or spent < budget_s):
        t0 = time.perf_counter()
        step(batch)
        dt = time.perf_counter() - t0
        spent += dt
        per_step.append(dt / batch)
    per_step.sort()
    return {
        "time_per_step_ms": 1e3 * float(np.median(per_step)),
        "time_per_step_min_ms": 1e3 * per_step[0],
        "steps_timed": batch * len(per_step),
        "batches": len(per_step),
        "warmup_steps": warmup + 1,
    }
