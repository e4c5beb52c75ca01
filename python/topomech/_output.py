"""The cells and point data of the meshes a run writes (``final.vtu``, frames), in the user's
numbering and orientation.

- **Points** are the simulation's vertex rows (:meth:`Simulation.positions` order: the input
  point order for a mesh read from a file, unused points left out), with point data
  ``point_id``: the input point index of each row (rows added by a cut or a fracture carry
  the index of the point they were split from; -1 where there is none).
- **Cells** are the elements (volumes in 3D, faces in 2D) with cell data ``cell_id``: the
  index of the input cell each comes from (-1 where there is none: a generated mesh, an
  older build). When all of them are known the cells are written in input order.
- **Orientation** is the input's at rest, whatever the current positions: when the input
  cells are known (a mesh file), each element is the input cell's vertex list mapped to rows
  (within an element the point ids are distinct) — turned over as the kernel turned it when
  it was inverted (the kernel builds every cell positively oriented); otherwise each volume
  is oriented positively at the REST positions, and a face keeps the map's order (the map
  of a surface is consistently oriented). An element that is inverted now is thus written
  inverted, as it is, instead of silently turned over.

Until the simulation exposes ``point_ids()`` and ``elements()`` (the contract of the vertex
numbering), this falls back on the map's extraction: rows in vertex-label order,
``point_id`` = row, ``cell_id`` = -1.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from topomech._cells import CELL_FACES, KIND_BY_SIZE

if TYPE_CHECKING:
    from topomech._cells import FlatMesh
    from topomech.simulation import Simulation

__all__ = [
    "Elements",
    "OutputCells",
    "available_fields",
    "check_fields",
    "field_values",
    "point_ids",
    "reversed_cells",
    "signed_volumes",
]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: The vertex order of the same cell with the opposite orientation (the kernel's
#: ``reversed``; a polygon is read backwards).
REVERSAL: dict[str, tuple[int, ...]] = {
    "tetra": (0, 2, 1, 3),
    "hexahedron": (4, 5, 6, 7, 0, 1, 2, 3),
    "wedge": (3, 4, 5, 0, 1, 2),
    "pyramid": (0, 3, 2, 1, 4),
}


def signed_volumes(kind: str, cells: I64, points: F64) -> F64:
    """Signed volumes ``(E,)`` of ``(E, k)`` cells of one volume kind (m^3; positive for
    VTK's vertex order), summed over the tetrahedra from the centroid to each face's fan, as
    the kernel computes them. Differences are taken from the cell's first vertex, so large
    coordinates lose no precision."""
    p = points[cells]  # (E, k, 3)
    p = p - p[:, :1]
    c = p.mean(axis=1)
    vol = np.zeros(len(cells))
    for face in CELL_FACES[kind]:
        for t in range(1, len(face) - 1):
            a = p[:, face[0]] - c
            b = p[:, face[t]] - c
            d = p[:, face[t + 1]] - c
            vol += np.einsum("ij,ij->i", a, np.cross(b, d)) / 6.0
    return vol


def reversed_cells(kind: str, cells: I64) -> I64:
    """``(E, k)`` cells of one kind with the opposite orientation (the kernel's
    ``reversed``)."""
    if kind == "polygon":
        return np.ascontiguousarray(cells[:, ::-1])
    return np.ascontiguousarray(cells[:, list(REVERSAL[kind])])


def point_ids(sim: Simulation) -> I64:
    """The input point index of each vertex row ``(V,)`` (``Simulation.point_ids()``)."""
    return np.asarray(sim.point_ids(), dtype=np.int64)


@dataclass
class Elements:
    """The elements of one topology, in the user's orientation (see the module docstring):
    ``kinds[e]`` (meshio's names: ``triangle``, ``quad``, ``polygon``, ``tetra``, ...),
    ``rows[e]`` (vertex rows), ``cell_ids`` ``(E,)``."""

    kinds: list[str]
    rows: list[I64]
    cell_ids: I64
    #: How many elements took the input cell's vertex order.
    from_input: int = 0


def _kind_of(dimension: int, n: int) -> str:
    if dimension == 2:
        return {3: "triangle", 4: "quad"}.get(n, "polygon")
    return KIND_BY_SIZE.get(n, f"cell{n}")


def _map_elements(sim: Simulation) -> tuple[I64, list[I64]]:
    """``(cell_ids, rows)`` of every element in the map's order (``Simulation.elements()``)."""
    ids, rows = sim.elements()
    return np.asarray(ids, dtype=np.int64), [np.asarray(r, dtype=np.int64) for r in rows]


def _rotation_of(a: I64, b: I64) -> npt.NDArray[np.bool_]:
    """For ``(E, n)`` rows: whether each ``b[e]`` is a cyclic rotation of ``a[e]``."""
    n = a.shape[1]
    start = np.argmax(a == b[:, :1], axis=1)  # where b's first vertex sits in a
    idx = (start[:, None] + np.arange(n)[None, :]) % n
    return np.asarray((np.take_along_axis(a, idx, axis=1) == b).all(axis=1))


class OutputCells:
    """The elements of a simulation as the output meshes write them, computed again only
    when a topology change relinked the map (:attr:`Simulation.topology_version`).

    ``input_cells``: the mesh's input cells (the flat layout of the cells the map was built
    from, in the order that ``cell_id`` numbers), or None when unknown (a generator)."""

    def __init__(self, sim: Simulation, input_cells: FlatMesh | None = None) -> None:
        self.sim = sim
        self.input_cells = input_cells
        self._version: int | None = None
        self._elements: Elements | None = None
        self._point_ids: I64 | None = None
        self._blocks: tuple[int, list[tuple[str, I64]], list[I64]] | None = None

    def point_ids(self) -> I64:
        """``(V,)`` input point index of each row (see :func:`point_ids`)."""
        self.elements()
        assert self._point_ids is not None
        return self._point_ids

    def elements(self) -> Elements:
        """The elements of the current topology (see :class:`Elements`)."""
        version = self.sim.topology_version
        if self._elements is None or self._version != version:
            self._point_ids = point_ids(self.sim)
            self._elements = self._compute(self._point_ids)
            self._version = version
        return self._elements

    def _input_rows(self, cell_ids: I64, rows: I64, pid: I64) -> tuple[I64, npt.NDArray[np.bool_]]:
        """For ``(E, n)`` element rows: the input cells' vertex lists mapped to rows, and
        whether that mapping held (the element has exactly the input cell's points)."""
        e, n = rows.shape
        out = rows.copy()
        ok = np.zeros(e, dtype=bool)
        flat = self.input_cells
        if flat is None:
            return out, ok
        offsets = np.asarray(flat.offsets, dtype=np.int64)
        conn = np.asarray(flat.connectivity, dtype=np.int64)
        known = (cell_ids >= 0) & (cell_ids < len(offsets) - 1)
        safe = np.where(known, cell_ids, 0)
        known &= (offsets[safe + 1] - offsets[safe]) == n
        if not known.any():
            return out, ok
        sel = np.flatnonzero(known)
        q = conn[offsets[cell_ids[sel]][:, None] + np.arange(n)[None, :]]  # input point ids
        have = pid[rows[sel]]  # (S, n) point ids of the element's rows
        eq = have[:, None, :] == q[:, :, None]  # (S, n input, n rows)
        single = (eq.sum(axis=2) == 1).all(axis=1)
        k = np.argmax(eq, axis=2)
        mapped = np.take_along_axis(rows[sel], k, axis=1)
        out[sel[single]] = mapped[single]
        ok[sel[single]] = True
        return out, ok

    def _compute(self, pid: I64) -> Elements:
        sim = self.sim
        dim = sim.dimension
        cell_ids, rows = _map_elements(sim)
        rest = sim.rest_positions()
        kinds = [_kind_of(dim, len(r)) for r in rows]
        out_rows: list[I64] = list(rows)
        from_input = 0
        groups: dict[tuple[str, int], list[int]] = {}
        for i, (kind, r) in enumerate(zip(kinds, rows)):
            groups.setdefault((kind, len(r)), []).append(i)
        for (kind, _), members in groups.items():
            idx = np.array(members, dtype=np.int64)
            r = np.stack([rows[i] for i in members]).astype(np.int64)
            q, ok = self._input_rows(cell_ids[idx], r, pid)
            from_input += int(ok.sum())
            if dim == 3:
                if kind in CELL_FACES:
                    neg = signed_volumes(kind, q, rest) < 0
                    q[neg] = reversed_cells(kind, q[neg])
            else:
                # a face: the input order, turned over where the kernel turned it (the map's
                # cycle runs the other way round); the map's order without input
                flip = ok & ~_rotation_of(r, q)
                q[flip] = reversed_cells("polygon", q[flip])
            for j, i in enumerate(members):
                out_rows[i] = q[j]
        order = np.arange(len(rows))
        if len(cell_ids) and (cell_ids >= 0).all():
            order = np.argsort(cell_ids, kind="stable")
        return Elements(
            kinds=[kinds[i] for i in order],
            rows=[out_rows[i] for i in order],
            cell_ids=cell_ids[order],
            from_input=from_input,
        )

    def blocks(self) -> tuple[list[tuple[str, I64]], list[I64]]:
        """meshio cell blocks (consecutive elements of one type and size) and the
        ``cell_id`` of each block's cells."""
        el = self.elements()
        assert self._version is not None
        if self._blocks is not None and self._blocks[0] == self._version:
            return self._blocks[1], self._blocks[2]
        blocks: list[tuple[str, I64]] = []
        ids: list[I64] = []
        start = 0
        n = len(el.rows)
        while start < n:
            kind, size = el.kinds[start], len(el.rows[start])
            end = start + 1
            while end < n and el.kinds[end] == kind and len(el.rows[end]) == size:
                end += 1
            blocks.append((kind, np.stack(el.rows[start:end]).astype(np.int64)))
            ids.append(el.cell_ids[start:end])
            start = end
        self._blocks = (self._version, blocks, ids)
        return blocks, ids


# ------------------------------------------------------------------------------ fields

#: The fields computed rather than read from an embedding: per-vertex lumped mass (kg) and
#: the models' forces at the written state (N, :meth:`Simulation.forces`).
COMPUTED_FIELDS = ("mass", "force")
#: The embedding types written as point data.
FIELD_TYPES = ("vec3", "f64", "bool", "i64")


def available_fields(sim: Simulation) -> list[str]:
    """The names ``output.fields`` accepts for ``sim``: ``mass``, ``force`` and every vertex
    embedding of type vec3, f64, bool or i64, in that order (the embeddings sorted)."""
    g = sim.core.gmap()
    vertex = "<1,2,3>" if sim.dimension == 3 else "<1,2>"
    names: list[str] = list(COMPUTED_FIELDS)
    for name in sorted(g.embedding_names()):
        info = g.embedding_info(name)
        keep = str(info["orbit"]) == vertex and str(info["type"]) in FIELD_TYPES
        if keep and name not in names:
            names.append(name)
    return names


#: The point data every output file has: asked for in ``output.fields``, they are accepted and
#: not written twice.
ALWAYS_WRITTEN = ("displacement", "velocity", "fixed", "point_id")


def check_fields(sim: Simulation, fields: Sequence[str], source: object = None) -> list[str]:
    """``fields`` (the scene's ``output.fields``) checked against :func:`available_fields`,
    less the point data every file has anyway (:data:`ALWAYS_WRITTEN`) and repeated names;
    raises :class:`SceneError` naming the key ``output.fields[i]`` of every unknown name (all
    at once) and the available names."""
    from topomech.scene import _Fail

    fields = list(fields)
    if not fields:
        return []
    available = available_fields(sim)
    bad = [(i, f) for i, f in enumerate(fields) if f not in available and f not in ALWAYS_WRITTEN]
    if bad:
        # a model's force embeddings exist on the map once its step rules have run: compute
        # the forces at this state (which changes no position or velocity) and look again
        sim.forces()
        available = available_fields(sim)
        bad = [
            (i, f) for i, f in enumerate(fields) if f not in available and f not in ALWAYS_WRITTEN
        ]
    if bad:
        fail = _Fail(str(source) if source is not None else "<scene>")
        first, rest = bad[0], bad[1:]
        problem = f"unknown field {first[1]!r}"
        if rest:
            more = ", ".join(f"output.fields[{i}] {f!r}" for i, f in rest[:20])
            extra = f" and {len(rest) - 20} more" if len(rest) > 20 else ""
            problem += f" (also unknown: {more}{extra})"
        raise fail(
            f"output.fields[{first[0]}]",
            f"{problem}; available: {', '.join(f for f in available if f not in ALWAYS_WRITTEN)} "
            f"(and {', '.join(ALWAYS_WRITTEN)}, "
            "which every file has)",
        )
    return list(dict.fromkeys(f for f in fields if f not in ALWAYS_WRITTEN))


def field_values(sim: Simulation, name: str) -> npt.NDArray[np.generic]:
    """The point data of field ``name`` (see :func:`available_fields`): ``(V,)`` or
    ``(V, 3)`` per vertex row; bool as uint8 (VTK has no booleans)."""
    if name == "mass":
        values = sim.masses()
    elif name == "force":
        values = sim.forces()
    else:
        values = sim.vertex_field(name)
    a = np.asarray(values)
    if a.dtype == np.bool_:
        a = a.astype(np.uint8)
    return a
