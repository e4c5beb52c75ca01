"""Shared fixtures: small hand-made meshes, and cell counts computed independently of the
kernel (unique edges and faces from the point and cell lists)."""

from __future__ import annotations

import signal
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import pytest

# A shell starts a background job (`make test &`) with SIGINT ignored, Python then installs no
# KeyboardInterrupt handler, and every process it starts inherits the ignored signal: the
# tests that send SIGINT (tests/test_hardening_*.py) need the handler a terminal gives, so it
# is restored here (in each pytest-xdist worker too; their children then start with SIGINT
# at its default).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# Faces of each volume kind as local vertex lists, VTK order. Only the vertex sets matter for
# counting, so these are written independently of the kernel's (oriented) tables.
VOLUME_FACES: dict[str, list[tuple[int, ...]]] = {
    "tetra": [(0, 1, 2), (0, 1, 3), (1, 2, 3), (0, 2, 3)],
    "hexahedron": [
        (0, 1, 2, 3),
        (4, 5, 6, 7),
        (0, 1, 5, 4),
        (1, 2, 6, 5),
        (2, 3, 7, 6),
        (3, 0, 4, 7),
    ],
    "wedge": [(0, 1, 2), (3, 4, 5), (0, 1, 4, 3), (1, 2, 5, 4), (2, 0, 3, 5)],
    "pyramid": [(0, 1, 2, 3), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)],
}

#: The README's anchor model ("Writing a model"): per-vertex springs to the rest positions,
#: on a surface, with its Jacobian rule.
ANCHOR = """\
dimension 2
embedding k_anchor  : f64  on <1,2>
embedding f_anchor  : vec3 on <1,2>
embedding df_anchor : vec3 on <1,2>

rule anchor_init(k: f64) {
  left { v : <1,2> hook }
  compute { v.k_anchor = k }
}
rule anchor_force {
  left { v : <1,2> hook }
  compute { v.f_anchor = -v.k_anchor * (v.position - v.rest) }
}
rule anchor_jvp {
  left { v : <1,2> hook }
  compute { v.df_anchor = -v.k_anchor * v.dx }
}

model anchor(k: f64 = 10.0) {
  init   anchor_init(k)
  step   anchor_force
  forces f_anchor
  jvp    anchor_jvp -> df_anchor
  needs  "vertices"
}
"""

SURFACE_TYPES = {"triangle", "quad", "polygon"}


def iter_cells(cells: Any) -> Iterable[tuple[str, list[int]]]:
    """(type, vertices) for every cell of a list of (type, array) pairs or a dict."""
    items = cells.items() if isinstance(cells, dict) else cells
    for item in items:
        t, data = (item.type, item.data) if hasattr(item, "type") else item
        for c in data:
            yield str(t), [int(v) for v in c]


class _UnionFind:
    def __init__(self, n: int) -> None:
        self.parent = list(range(n))

    def find(self, x: int) -> int:
        while self.parent[x] != x:
            self.parent[x] = self.parent[self.parent[x]]
            x = self.parent[x]
        return x

    def union(self, a: int, b: int) -> None:
        self.parent[self.find(a)] = self.find(b)


def _polygon_edges(poly: Sequence[int]) -> list[tuple[int, int]]:
    k = len(poly)
    return [tuple(sorted((poly[i], poly[(i + 1) % k]))) for i in range(k)]  # type: ignore[misc]


def independent_counts(cells: Any) -> dict[str, int]:
    """The counts a G-map of these cells must have, from the cell lists alone: vertices used,
    unique edges, unique faces, cells, darts, boundary cells, components (cells joined through
    shared edges in 2D, shared faces in 3D). Valid for meshes whose vertices and edges are
    manifold, like every fixture here."""
    cl = list(iter_cells(cells))
    vertices = {v for _, c in cl for v in c}
    is_3d = any(t in VOLUME_FACES for t, _ in cl)
    uf = _UnionFind(len(cl))
    if not is_3d:
        edge_users: dict[tuple[int, int], list[int]] = {}
        darts = 0
        for k, (_, c) in enumerate(cl):
            darts += 2 * len(c)
            for e in _polygon_edges(c):
                edge_users.setdefault(e, []).append(k)
        for users in edge_users.values():
            for u in users[1:]:
                uf.union(users[0], u)
        return {
            "darts": darts,
            "vertices": len(vertices),
            "edges": len(edge_users),
            "faces": len(cl),
            "volumes": 0,
            "components": len({uf.find(k) for k in range(len(cl))}),
            "boundary": sum(1 for u in edge_users.values() if len(u) == 1),
        }
    face_users: dict[frozenset[int], list[int]] = {}
    edges: set[tuple[int, int]] = set()
    darts = 0
    for k, (t, c) in enumerate(cl):
        for local in VOLUME_FACES[t]:
            face = [c[i] for i in local]
            darts += 2 * len(face)
            face_users.setdefault(frozenset(face), []).append(k)
            edges.update(_polygon_edges(face))
    for users in face_users.values():
        for u in users[1:]:
            uf.union(users[0], u)
    return {
        "darts": darts,
        "vertices": len(vertices),
        "edges": len(edges),
        "faces": len(face_users),
        "volumes": len(cl),
        "components": len({uf.find(k) for k in range(len(cl))}),
        "boundary": sum(1 for u in face_users.values() if len(u) == 1),
    }


def euler(counts: dict[str, int]) -> int:
    """V - E + F - C."""
    return counts["vertices"] - counts["edges"] + counts["faces"] - counts["volumes"]


def flat_to_cells(
    kinds: Sequence[str], offsets: Any, connectivity: Any
) -> list[tuple[str, list[list[int]]]]:
    """Flat layout -> one (type, [cell]) block per cell, with volume kinds as meshio names."""
    out: list[tuple[str, list[list[int]]]] = []
    for c, k in enumerate(kinds):
        verts = [int(v) for v in connectivity[offsets[c] : offsets[c + 1]]]
        out.append((k, [verts]))
    return out


def tet_volume(points: np.ndarray, tet: Sequence[int]) -> float:
    p = points[list(tet)]
    return float(np.dot(np.cross(p[1] - p[0], p[2] - p[0]), p[3] - p[0]) / 6.0)


# ---------------------------------------------------------------------------------- meshes
# Each fixture is (points, cells) with cells as a list of (meshio type, array) pairs; every
# cell is positively oriented (VTK order), and 2D faces are counter-clockwise.


@pytest.fixture
def two_triangles() -> tuple[np.ndarray, list[tuple[str, Any]]]:
    points = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    return points, [("triangle", np.array([[0, 1, 2], [0, 2, 3]]))]


@pytest.fixture
def quads() -> tuple[np.ndarray, list[tuple[str, Any]]]:
    # 3 x 2 quads
    points = np.array([[x, y] for y in range(3) for x in range(4)], dtype=float)
    q = [
        [y * 4 + x, y * 4 + x + 1, (y + 1) * 4 + x + 1, (y + 1) * 4 + x]
        for y in range(2)
        for x in range(3)
    ]
    return points, [("quad", np.array(q))]


@pytest.fixture
def mixed_surface() -> tuple[np.ndarray, list[tuple[str, Any]]]:
    # a quad, a triangle on its right, and a pentagon on top of both
    points = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1], [1, 2]], dtype=float)
    return points, [
        ("quad", np.array([[0, 1, 4, 3]])),
        ("triangle", np.array([[1, 2, 5], [1, 5, 4]])),
        ("polygon", [[3, 4, 5, 6]]),
    ]


@pytest.fixture
def two_tets() -> tuple[np.ndarray, list[tuple[str, Any]]]:
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    assert all(tet_volume(points, t) > 0 for t in tets)
    return points, [("tetra", tets)]


@pytest.fixture
def two_hexes() -> tuple[np.ndarray, list[tuple[str, Any]]]:
    points = np.array(
        [[x, y, z] for z in range(2) for y in range(2) for x in range(3)], dtype=float
    )

    def idx(x: int, y: int, z: int) -> int:
        return z * 6 + y * 3 + x

    hexes = [
        [idx(x, 0, 0), idx(x + 1, 0, 0), idx(x + 1, 1, 0), idx(x, 1, 0),
         idx(x, 0, 1), idx(x + 1, 0, 1), idx(x + 1, 1, 1), idx(x, 1, 1)]
        for x in range(2)
    ]  # fmt: skip
    return points, [("hexahedron", np.array(hexes))]


@pytest.fixture
def two_wedges() -> tuple[np.ndarray, list[tuple[str, Any]]]:
    # a unit cube cut along its diagonal plane x = y into two prisms; a positive wedge (Gmsh's,
    # VTK's) has its first triangle counter-clockwise seen from the second.
    points = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
        dtype=float,
    )
    wedges = np.array([[0, 1, 2, 4, 5, 6], [0, 2, 3, 4, 6, 7]])
    return points, [("wedge", wedges)]


@pytest.fixture
def two_pyramids() -> tuple[np.ndarray, list[tuple[str, Any]]]:
    # an octahedron: two pyramids sharing their square base
    points = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1], [0.5, 0.5, -1]], dtype=float
    )
    return points, [("pyramid", np.array([[0, 1, 2, 3, 4], [0, 3, 2, 1, 5]]))]


@pytest.fixture
def mixed_volume() -> tuple[np.ndarray, list[tuple[str, Any]]]:
    # a hexahedron, a pyramid on its top face, and a tetrahedron on one side of the pyramid
    points = np.array(
        [
            [0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
            [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
            [0.5, 0.5, 1.5],
            [0.5, -0.5, 1.5],
        ],
        dtype=float,
    )  # fmt: skip
    tet = [4, 5, 8, 9]
    if tet_volume(points, tet) < 0:
        tet = [5, 4, 8, 9]
    return points, [
        ("hexahedron", np.array([[0, 1, 2, 3, 4, 5, 6, 7]])),
        ("pyramid", np.array([[4, 5, 6, 7, 8]])),
        ("tetra", np.array([tet])),
    ]


@pytest.fixture(autouse=True)
def _sigpipe_ignored() -> Iterable[None]:
    """Python ignores SIGPIPE (a write to a closed pipe raises BrokenPipeError instead), but
    gmsh's initialize() resets it to the default in C, where signal.getsignal cannot see it:
    after a test that meshes with gmsh, a later test whose encoder subprocess dies (the MP4
    writer's) would kill the whole pytest process with SIGPIPE. Restored after every test."""
    yield
    if hasattr(signal, "SIGPIPE"):
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)
