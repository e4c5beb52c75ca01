"""Boundary conditions and loads: selecting vertices and boundary faces, and turning point
forces, tractions and pressures into the constant per-vertex loads ``f_ext`` of a
:class:`~topomech.simulation.Simulation`.

Selections (every function takes exactly one):

- ``where``: a predicate of the rule language over ``x``, ``y``, ``z`` (``"x < 1e-9"``,
  ``"abs(z - 1) < 1e-6 && y > 0.5"``), on the rest position of a vertex, or on the rest
  centroid of a boundary face (3D) or edge (2D);
- ``points``: input point indices (the rows of the mesh's points array as read);
- ``group``: the name of a Gmsh physical group or a meshio point or cell set of the mesh
  (see :class:`MeshGroups`).

Loads are dead loads: they are integrated once, over the faces in the reference (rest)
configuration, and keep their direction and size whatever the body does. Units: point forces
in N; tractions and pressures in Pa (N/m^2) on the faces of a volume mesh (3D); on the
boundary edges of a surface mesh (2D) they are forces per unit length of edge (N/m): the
thickness of a plane-stress model is already in them (a total force ``F`` spread over an edge
of length ``L`` is a traction ``F / L``). A pressure ``p`` pushes on a face along its inward
normal: the force is ``-p n dA`` with ``n`` the outward unit normal (in 2D, the outward normal
of the edge in the plane of its face).

Consistent nodal loads (``f_a = integral of N_a t dA``): linear triangles and edges exactly
(each vertex gets a third, or a half, of the face's or edge's force), bilinear quadrilaterals
by 2x2 Gauss quadrature on the bilinear map (exact for a pressure on any quadrilateral and for
a traction on a plane parallelogram).

Boundary faces (edges in 2D) are the faces of the elements that belong to exactly one element.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, TypeVar

import numpy as np
import numpy.typing as npt

from topomech import _core
from topomech._cells import CELL_FACES, KIND_BY_SIZE, real_array

if TYPE_CHECKING:
    from topomech.simulation import Simulation

__all__ = [
    "LOAD_KINDS",
    "BoundaryFace",
    "LoadError",
    "MeshGroups",
    "apply_conditions",
    "boundary_faces",
    "check_supports",
    "compile_expression",
    "compile_predicate",
    "held_positions",
    "point_load",
    "select_faces",
    "select_vertices",
    "surface_load",
]

#: The kinds of load a scene's ``[[load]]`` table names.
LOAD_KINDS = ("point", "traction", "pressure")

#: How many offenders a message lists before "and N more".
LIST_LIMIT = 20


class LoadError(ValueError):
    """A selection or a load that cannot be applied: an unknown group, a selection that
    selects nothing, a facet that is not on the boundary. The message names the offenders
    (the first :data:`LIST_LIMIT`, then how many more); ``key`` is the scene key at fault
    when a scene's condition raised it (else None)."""

    def __init__(self, message: str, key: str | None = None, subkey: str | None = None) -> None:
        super().__init__(message)
        self.key = key
        #: The part of a condition at fault (``where``, ``pressure``, ``traction[1]``) when
        #: the error came from evaluating it: the scene key is then ``key.subkey``.
        self.subkey = subkey


_T = TypeVar("_T")


def _at(
    evaluate: Callable[[npt.NDArray[np.float64]], _T], subkey: str, points: str
) -> Callable[[npt.NDArray[np.float64]], _T]:
    """``evaluate`` whose evaluation errors name the condition's part (``subkey``) and what
    its points are (``points``: "vertices' rest positions", ...)."""

    def run(q: npt.NDArray[np.float64]) -> _T:
        try:
            return evaluate(q)
        except LoadError as e:
            raise LoadError(f"{e} (the points are {points})", subkey=subkey) from None

    return run


def _listed(items: Sequence[Any]) -> str:
    shown = ", ".join(str(x) for x in items[:LIST_LIMIT])
    more = len(items) - LIST_LIMIT
    return f"{shown} and {more} more" if more > 0 else shown


# ---------------------------------------------------------------------------- predicates


def _kernel(text: str, what: str, points: npt.NDArray[np.float64]) -> Any:
    """``text`` evaluated by the kernel at ``points`` (a predicate or an expression, as
    ``what`` says), its refusals as :class:`LoadError`."""
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    run = _core.eval_predicate if what == "predicate" else _core.eval_expression
    try:
        return run(text, pts, what)
    except _core.RuleError as e:
        raise LoadError(f"bad {what} {text!r}: {e}") from None
    except ValueError as e:
        raise LoadError(f"{what} {text!r}: {e}") from None


def compile_predicate(pred: str) -> Callable[[npt.NDArray[np.float64]], npt.NDArray[np.bool_]]:
    """A predicate of the rule language over ``x``, ``y``, ``z`` as a function of points
    ``(n, 3)`` returning a bool mask ``(n,)``, evaluated by the kernel
    (:func:`topomech._core.eval_predicate`): the parser, checker and evaluator of a scene's
    ``where``, so ``%``, comparisons, ``let``, ``if`` and comments mean here what they mean
    there. Raises :class:`LoadError` with the checker's message (a name other than ``x``,
    ``y``, ``z``, a syntax error, a quotient of two integers) when compiled, and naming the
    point where a built-in refuses its argument when evaluated. A comparison with NaN (the
    square root of a negative number) is false: that point is not selected."""
    _kernel(pred, "predicate", np.zeros((0, 3)))

    def evaluate(points: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
        return np.asarray(_kernel(pred, "predicate", points), dtype=bool)

    return evaluate


def compile_expression(expr: str) -> Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]]:
    """A number-valued expression of the rule language over ``x``, ``y``, ``z`` (the same
    syntax as :func:`compile_predicate`: ``"1e4 * (0.2 - z)"``) as a function of points
    ``(n, 3)`` returning values ``(n,)``, evaluated by the kernel
    (:func:`topomech._core.eval_expression`; an integer value is converted, a quotient of two
    integers is refused as in a predicate). Raises :class:`LoadError` with the checker's
    message when compiled; evaluating it where it is not a finite number raises
    :class:`LoadError` naming the point."""
    _kernel(expr, "expression", np.zeros((0, 3)))

    def evaluate(points: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.asarray(_kernel(expr, "expression", points), dtype=np.float64)

    return evaluate


# ---------------------------------------------------------------------------- groups


@dataclass
class MeshGroups:
    """The named groups of a mesh file (contract C4 of :func:`topomech.io.read_mesh`):
    ``point_sets`` (name -> input point indices), ``cell_sets`` (name -> indices of the kept
    cells, their ``cell_id``) and ``facet_sets`` (name -> lower-dimensional cells as
    ``(meshio type, (k, n) input point indices)`` pairs, e.g. the boundary triangles of a
    Gmsh physical surface)."""

    point_sets: dict[str, npt.NDArray[np.int64]] = field(default_factory=dict)
    cell_sets: dict[str, npt.NDArray[np.int64]] = field(default_factory=dict)
    facet_sets: dict[str, list[tuple[str, npt.NDArray[np.int64]]]] = field(default_factory=dict)
    #: The file's points ``(N, 2 or 3)``, when known: rows are matched to input points by
    #: their rest coordinates when the simulation does not say which point each row is.
    points: npt.NDArray[np.float64] | None = None

    @classmethod
    def from_meshio(cls, mesh: Any) -> MeshGroups:
        """The groups a mesh returned by :func:`topomech.io.read_mesh` carries (its
        ``point_sets``, ``cell_sets_kept`` and ``facet_sets`` attributes); a plain
        ``meshio.Mesh`` gives its ``point_sets`` only."""
        if mesh is None:
            return cls()
        if isinstance(mesh, tuple):
            raise TypeError(
                "MeshGroups.from_meshio takes the mesh, not the (mesh, dropped) pair that "
                "read_mesh returns: mesh, _ = topomech.io.read_mesh(path)"
            )
        point_sets = {
            str(k): np.asarray(v, dtype=np.int64).ravel()
            for k, v in (getattr(mesh, "point_sets", None) or {}).items()
        }
        cell_sets = {
            str(k): np.asarray(v, dtype=np.int64).ravel()
            for k, v in (getattr(mesh, "cell_sets_kept", None) or {}).items()
        }
        facet_sets = {
            str(k): [(str(t), np.asarray(a, dtype=np.int64).reshape(len(a), -1)) for t, a in v]
            for k, v in (getattr(mesh, "facet_sets", None) or {}).items()
        }
        points = getattr(mesh, "points", None)
        pts = None if points is None else np.asarray(points, dtype=np.float64)
        return cls(point_sets, cell_sets, facet_sets, pts)

    def names(self) -> list[str]:
        """Every group name, sorted."""
        return sorted({*self.point_sets, *self.cell_sets, *self.facet_sets})

    def _unknown(self, name: str) -> LoadError:
        names = self.names()
        known = f"the mesh has: {', '.join(names)}" if names else "the mesh has no named groups"
        return LoadError(f"unknown group '{name}' ({known})")

    def points_of(self, name: str, cells: Sequence[Sequence[int]] | None = None) -> set[int]:
        """The input points of group ``name``: its point set, the nodes of its facets, the
        vertices of its cells (``cells``: each kept cell's input points, by cell_id)."""
        if (
            name not in self.point_sets
            and name not in self.cell_sets
            and name not in self.facet_sets
        ):
            raise self._unknown(name)
        pts: set[int] = set()
        if name in self.point_sets:
            pts.update(int(p) for p in self.point_sets[name])
        for _, a in self.facet_sets.get(name, []):
            pts.update(int(p) for p in a.ravel())
        if name in self.cell_sets and cells is not None:
            for c in self.cell_sets[name]:
                if 0 <= c < len(cells):
                    pts.update(int(p) for p in cells[int(c)])
        return pts


# ---------------------------------------------------------------------------- the mesh seen by rows


@dataclass(frozen=True)
class BoundaryFace:
    """A face (3D) or edge (2D) on the boundary, at rest: ``rows`` are its vertex rows,
    ordered so that its normal points out of its element (in 2D: the edge's two rows),
    ``element`` the row index of its element in :func:`_elements`' order."""

    rows: tuple[int, ...]
    element: int


def _point_ids(sim: Simulation) -> npt.NDArray[np.int64]:
    """The input point of each row (``Simulation.point_ids()``; -1 for none)."""
    return np.asarray(sim.point_ids(), dtype=np.int64)


def _elements(sim: Simulation) -> tuple[npt.NDArray[np.int64], list[npt.NDArray[np.int64]]]:
    """Each element's cell_id and vertex rows (``Simulation.elements()``)."""
    ids, rows = sim.elements()
    return np.asarray(ids, dtype=np.int64), [np.asarray(r, dtype=np.int64) for r in rows]


def _element_faces(n: int, dim: int) -> tuple[tuple[int, ...], ...]:
    if dim == 2:
        return tuple((i, (i + 1) % n) for i in range(n))
    kind = KIND_BY_SIZE.get(n)
    if kind is None:
        raise LoadError(f"an element of {n} vertices has no known faces")
    return CELL_FACES[kind]


def boundary_faces(sim: Simulation) -> list[BoundaryFace]:
    """The faces (3D) or edges (2D) that belong to exactly one element, at rest, each turned
    so that its normal points out of its element."""
    rest = sim.rest_positions()
    dim = sim.dimension
    _, elements = _elements(sim)
    seen: dict[tuple[int, ...], list[tuple[tuple[int, ...], int]]] = {}
    for e, rows in enumerate(elements):
        for local in _element_faces(len(rows), dim):
            face = tuple(int(rows[i]) for i in local)
            seen.setdefault(tuple(sorted(face)), []).append((face, e))
    out: list[BoundaryFace] = []
    for owners in seen.values():
        if len(owners) != 1:
            continue
        face, e = owners[0]
        centre = rest[elements[e]].mean(axis=0)
        if dim == 3:
            area = _area_vector(rest[list(face)])
            if float(np.dot(area, rest[list(face)].mean(axis=0) - centre)) < 0:
                face = (face[0], *reversed(face[1:]))
        out.append(BoundaryFace(face, e))
    return out


def _area_vector(p: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """The vector area of a polygon (Newell): its unit normal times its area."""
    area: npt.NDArray[np.float64] = 0.5 * np.sum(np.cross(p, np.roll(p, -1, axis=0)), axis=0)
    return area


def _edge_normal(
    a: npt.NDArray[np.float64], b: npt.NDArray[np.float64], centre: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """The outward unit normal of edge ab in the plane of its face (centroid ``centre``)."""
    e = b - a
    w = centre - a
    inward = w - (np.dot(w, e) / np.dot(e, e)) * e
    n: npt.NDArray[np.float64] = -inward / np.linalg.norm(inward)
    return n


# ---------------------------------------------------------------------------- selections


def _one_selection(where: str | None, points: Any, group: str | None) -> None:
    given = [
        k for k, v in (("where", where), ("points", points), ("group", group)) if v is not None
    ]
    if len(given) != 1:
        raise LoadError(
            "give exactly one selection: where (a predicate), points (input point indices) "
            f"or group (a group name); got {', '.join(given) if given else 'none'}"
        )


def _cells_by_id(sim: Simulation, groups: MeshGroups | None) -> list[list[int]]:
    """Each kept cell's input points, by cell_id (for cell sets)."""
    ids, rows = _elements(sim)
    pid = _point_ids(sim)
    n = int(ids.max()) + 1 if len(ids) else 0
    cells: list[list[int]] = [[] for _ in range(n)]
    for cid, r in zip(ids, rows):
        if cid >= 0:
            cells[int(cid)] = [int(pid[i]) for i in r]
    return cells


def _rows_of_points(
    sim: Simulation, pts: Iterable[int], what: str, groups: MeshGroups | None
) -> npt.NDArray[np.bool_]:
    """The rows whose input point is in ``pts``; refuses points that are not vertices of the
    mesh, listing them all."""
    pid = _point_ids(sim)
    wanted = np.array(sorted({int(p) for p in pts}), dtype=np.int64)
    mask = np.isin(pid, wanted)
    missing = sorted(set(wanted.tolist()) - set(pid[mask].tolist()))
    if missing:
        raise LoadError(
            f"{what}: input points {_listed(missing)} are not vertices of the mesh "
            f"(points are numbered from 0; {sim.n_vertices} rows; unused points are left out)"
        )
    return mask


def select_vertices(
    sim: Simulation,
    *,
    where: str | None = None,
    points: Sequence[int] | npt.NDArray[np.integer[Any]] | None = None,
    group: str | None = None,
    groups: MeshGroups | None = None,
) -> npt.NDArray[np.bool_]:
    """The rows selected by one of ``where`` (a predicate on the rest position), ``points``
    (input point indices) or ``group`` (a name in ``groups``: every vertex of the group's
    points, facets or cells). Returns a bool mask ``(V,)``. Raises :class:`LoadError` when
    the selection is empty, a point is not a vertex, or the group is unknown (naming the
    groups that exist)."""
    _one_selection(where, points, group)
    if where is not None:
        mask = _at(compile_predicate(where), "where", "the vertices' rest positions")(
            sim.rest_positions()
        )
        what = f"predicate {where!r}"
    elif points is not None:
        pts = [_index(p, i) for i, p in enumerate(np.asarray(points).ravel().tolist())]
        mask = _rows_of_points(sim, pts, "points", groups)
        what = "points"
    else:
        assert group is not None
        g = groups if groups is not None else MeshGroups()
        pts_set = g.points_of(group, _cells_by_id(sim, groups) if group in g.cell_sets else None)
        pid = _point_ids(sim)
        mask = np.isin(pid, np.array(sorted(pts_set), dtype=np.int64))
        what = f"group '{group}'"
    if not mask.any():
        raise LoadError(f"{what} selects no vertex")
    return mask


def _index(p: Any, i: int) -> int:
    if isinstance(p, bool) or not isinstance(p, int):
        raise LoadError(f"points[{i}]: expected an integer point index, got {p!r}")
    if p < 0:
        raise LoadError(f"points[{i}]: point indices are >= 0, got {p}")
    return p


def select_faces(
    sim: Simulation,
    *,
    where: str | None = None,
    points: Sequence[int] | npt.NDArray[np.integer[Any]] | None = None,
    group: str | None = None,
    groups: MeshGroups | None = None,
) -> list[BoundaryFace]:
    """The boundary faces (3D) or edges (2D) selected by one of ``where`` (a predicate on
    the face's rest centroid), ``points`` (faces all of whose vertices are these input
    points) or ``group`` (the group's facets, which must lie on the boundary; or, for a
    group of points or cells, the boundary faces all of whose vertices are in it). Raises
    :class:`LoadError` when nothing is selected, a facet of the group is not a boundary face
    (listing them), or the group is unknown."""
    _one_selection(where, points, group)
    faces = boundary_faces(sim)
    rest = sim.rest_positions()
    if where is not None:
        centres = np.array([rest[list(f.rows)].mean(axis=0) for f in faces]).reshape(-1, 3)
        keep = _at(compile_predicate(where), "where", "the boundary faces' rest centroids")(centres)
        chosen = [f for f, k in zip(faces, keep) if k]
        what = f"predicate {where!r}"
    elif points is not None:
        pts = [_index(p, i) for i, p in enumerate(np.asarray(points).ravel().tolist())]
        mask = _rows_of_points(sim, pts, "points", groups)
        chosen = [f for f in faces if all(mask[r] for r in f.rows)]
        what = "points"
    else:
        assert group is not None
        g = groups if groups is not None else MeshGroups()
        if group in g.facet_sets:
            chosen = _facets_on_boundary(sim, faces, g.facet_sets[group], group, g)
        else:
            pts_set = g.points_of(
                group, _cells_by_id(sim, groups) if group in g.cell_sets else None
            )
            mask = np.isin(_point_ids(sim), np.array(sorted(pts_set), dtype=np.int64))
            chosen = [f for f in faces if all(mask[r] for r in f.rows)]
        what = f"group '{group}'"
    if not chosen:
        raise LoadError(f"{what} selects no boundary {'face' if sim.dimension == 3 else 'edge'}")
    return chosen


def _facets_on_boundary(
    sim: Simulation,
    faces: list[BoundaryFace],
    facets: list[tuple[str, npt.NDArray[np.int64]]],
    group: str,
    groups: MeshGroups | None,
) -> list[BoundaryFace]:
    """The boundary faces the group's facets (input point indices) are; refuses the facets
    that are not boundary faces, all of them."""
    pid = _point_ids(sim)
    by_points: dict[tuple[int, ...], BoundaryFace] = {}
    for f in faces:
        by_points.setdefault(tuple(sorted(int(pid[r]) for r in f.rows)), f)
    chosen: list[BoundaryFace] = []
    bad: list[str] = []
    for kind, arr in facets:
        for i, facet in enumerate(arr):
            key = tuple(sorted(int(p) for p in facet))
            if key in by_points:
                chosen.append(by_points[key])
            else:
                bad.append(f"{kind} {i} (points {list(map(int, facet))})")
    if bad:
        what = "faces" if sim.dimension == 3 else "edges"
        raise LoadError(
            f"group '{group}': {len(bad)} facets are not boundary {what} of the mesh: "
            f"{_listed(bad)}"
        )
    return chosen


# ---------------------------------------------------------------------------- loads

# 2x2 Gauss points on [-1, 1]^2, weight 1 each
_G = 1.0 / math.sqrt(3.0)
_GAUSS = ((-_G, -_G), (_G, -_G), (_G, _G), (-_G, _G))
# the triangle's edge midpoints (barycentric), weight 1/3 of the area each: exact to degree 2
_TRI = ((0.5, 0.5, 0.0), (0.0, 0.5, 0.5), (0.5, 0.0, 0.5))

#: A load's density at points ``(n, 3)``: tractions ``(n, 3)`` or pressures ``(n,)``.
Density = Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]]


def _face_nodal(
    p: npt.NDArray[np.float64], load: Density, pressure: bool
) -> npt.NDArray[np.float64]:
    """Consistent nodal forces ``(k, 3)`` of a traction or pressure density ``load`` on the
    face with corners ``p`` (outward-ordered): exact for a density linear in x on triangles
    and parallelograms (3-point and 2x2 Gauss rules)."""
    k = len(p)
    if k == 3:
        area = _area_vector(p)
        shape = np.array(_TRI)
        q = shape @ p
        f = -np.outer(load(q), area) / 3.0 if pressure else load(q) * (np.linalg.norm(area) / 3.0)
        tri: npt.NDArray[np.float64] = shape.T @ f
        return tri
    if k == 4:
        shapes, vectors = [], []
        for xi, eta in _GAUSS:
            shapes.append(
                0.25
                * np.array(
                    [
                        (1 - xi) * (1 - eta),
                        (1 + xi) * (1 - eta),
                        (1 + xi) * (1 + eta),
                        (1 - xi) * (1 + eta),
                    ]
                )
            )
            dxi = 0.25 * np.array([-(1 - eta), (1 - eta), (1 + eta), -(1 + eta)]) @ p
            deta = 0.25 * np.array([-(1 - xi), -(1 + xi), (1 + xi), (1 - xi)]) @ p
            vectors.append(np.cross(dxi, deta))
        shape, da = np.array(shapes), np.array(vectors)
        q = shape @ p
        f = -load(q)[:, None] * da if pressure else load(q) * np.linalg.norm(da, axis=1)[:, None]
        quad: npt.NDArray[np.float64] = shape.T @ f
        return quad
    # a polygon: a triangle per edge from its centroid (its share split evenly over the corners)
    c = p.mean(axis=0)
    out = np.zeros((k, 3))
    for i in range(k):
        j = (i + 1) % k
        f = _face_nodal(np.array([p[i], p[j], c]), load, pressure)
        out[i] += f[0]
        out[j] += f[1]
        out += f[2] / k
    return out


def _constant(c: float) -> Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]]:
    return lambda q: np.full(len(q), c)


def _real(value: Any) -> float:
    """``float(value)``, refusing with :class:`TypeError` a complex (numpy's complex scalars
    are Python complex, whose ``float`` drops the imaginary part with only a warning) and a
    boolean (``float(True)`` is 1.0: ``pressure=True`` would be 1 Pa)."""
    if isinstance(value, complex):
        raise TypeError("a complex number")
    if isinstance(value, (bool, np.bool_)):
        raise TypeError("a boolean")
    return float(value)


def _has_boolean(values: Any) -> bool:
    """Whether ``values`` is, or a list or tuple in it holds, a boolean."""
    if isinstance(values, (bool, np.bool_)):
        return True
    return isinstance(values, (list, tuple)) and any(_has_boolean(v) for v in values)


def _no_booleans(values: Any, what: str) -> None:
    """Raises :class:`LoadError` when the list or tuple ``values`` (a force, a displacement)
    holds a boolean: numpy reads ``[True, 0, 0]`` as ``[1, 0, 0]`` (an array of booleans is
    refused by :func:`real_array`)."""
    if _has_boolean(values):
        raise LoadError(f"{what}: expected 3 numbers, got a boolean in {values!r}")


def _density(value: Any, what: str, size: int) -> Density:
    """A load's density from a constant, a callable, or rule-language expressions."""
    if callable(value):
        fn = value

        def checked(q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
            try:
                v = real_array(fn(q), f"{what}: the function's values")
            except TypeError as e:
                raise LoadError(str(e)) from None
            want = "(n, 3)" if size == 3 else "(n,)"
            if v.shape != ((len(q), 3) if size == 3 else (len(q),)):
                raise LoadError(
                    f"{what}: the function returned shape {v.shape} for {len(q)} points "
                    f"(n = {len(q)}); it must return {want} values, one per point"
                )
            if not np.all(np.isfinite(v)):
                bad = int(np.argwhere(~np.isfinite(v.reshape(len(q), -1)))[0][0])
                p = ", ".join(f"{c:g}" for c in q[bad])
                raise LoadError(
                    f"{what}: the function returned {v[bad]} at ({p}), not finite "
                    "(the points are quadrature points on the boundary faces, at rest)"
                )
            return v

        return checked
    quadrature = "quadrature points on the boundary faces, at rest"
    if size == 1:
        if isinstance(value, str):
            return _at(compile_expression(value), what, quadrature)
        try:
            c = _real(value)
        except (TypeError, ValueError):
            raise LoadError(f"{what}: expected a number or an expression, got {value!r}") from None
        if not math.isfinite(c):
            raise LoadError(f"{what}: expected a finite number, got {value!r}")
        return _constant(c)
    items = list(value) if isinstance(value, (list, tuple, np.ndarray)) else None
    if items is None or len(items) != 3:
        raise LoadError(f"{what}: expected 3 numbers or expressions, got {value!r}")
    parts: list[Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]]] = []
    for i, v in enumerate(items):
        if isinstance(v, str):
            parts.append(_at(compile_expression(v), f"{what}[{i}]", quadrature))
        else:
            try:
                c = _real(v)
            except (TypeError, ValueError):
                raise LoadError(
                    f"{what}: expected 3 numbers or expressions, got {value!r}"
                ) from None
            if not math.isfinite(c):
                raise LoadError(f"{what}: expected finite numbers, got {value!r}")
            parts.append(_constant(c))
    return lambda q: np.stack([f(q) for f in parts], axis=1)


def surface_load(
    sim: Simulation,
    *,
    traction: Any = None,
    pressure: Any = None,
    where: str | None = None,
    points: Sequence[int] | npt.NDArray[np.integer[Any]] | None = None,
    group: str | None = None,
    groups: MeshGroups | None = None,
) -> npt.NDArray[np.float64]:
    """The consistent nodal loads ``(V, 3)`` (N) of a ``traction`` (a force per area, Pa,
    on faces in 3D; per length, N/m, on edges in 2D) or a ``pressure`` (same units, pushing
    along the inward normal: ``-p n dA``) on the boundary faces (3D) or edges (2D) of one
    selection (see :func:`select_faces`), integrated over the rest configuration. Each may
    be uniform (3 numbers, a number) or vary over the surface: a rule-language expression of
    ``x``, ``y``, ``z`` (per component for a traction: ``["0", "-1e3 * x", "0"]``;
    ``"1e4 * (0.2 - z)"`` for a hydrostatic pressure), or a Python function of the rest
    points ``(n, 3)`` returning ``(n, 3)`` tractions or ``(n,)`` pressures. The integration
    is exact for loads linear in x on triangles, edges and parallelograms. Add the result
    to the simulation's loads with ``sim.set_external_forces(sim.external_forces() + f)``.
    Raises :class:`LoadError` for a bad selection or value, or when both or neither of
    ``traction`` and ``pressure`` are given."""
    if (traction is None) == (pressure is None):
        raise LoadError("give exactly one of traction (a vector) and pressure (a number)")
    is_pressure = pressure is not None
    density = (
        _density(pressure, "pressure", 1) if is_pressure else _density(traction, "traction", 3)
    )
    faces = select_faces(sim, where=where, points=points, group=group, groups=groups)
    rest = sim.rest_positions()
    out = np.zeros((sim.n_vertices, 3))
    if sim.dimension == 3:
        for f in faces:
            nodal = _face_nodal(rest[list(f.rows)], density, is_pressure)
            for r, fr in zip(f.rows, nodal):
                out[r] += fr
        return out
    _, elements = _elements(sim)
    # 2-point Gauss on each edge: exact to degree 3
    s = np.array([(1 - _G) / 2, (1 + _G) / 2])
    shape = np.stack([1 - s, s], axis=1)
    for f in faces:
        ends = rest[list(f.rows)]
        length = float(np.linalg.norm(ends[1] - ends[0]))
        q = shape @ ends
        if is_pressure:
            centre = rest[elements[f.element]].mean(axis=0)
            n = _edge_normal(ends[0], ends[1], centre)
            forces = -np.outer(density(q), n) * (length / 2)
        else:
            forces = density(q) * (length / 2)
        nodal = shape.T @ forces
        out[f.rows[0]] += nodal[0]
        out[f.rows[1]] += nodal[1]
    return out


def point_load(
    sim: Simulation,
    force: Sequence[float] | npt.NDArray[np.float64],
    *,
    where: str | None = None,
    points: Sequence[int] | npt.NDArray[np.integer[Any]] | None = None,
    group: str | None = None,
    groups: MeshGroups | None = None,
) -> npt.NDArray[np.float64]:
    """The loads ``(V, 3)`` (N) of ``force`` (3 numbers) applied on each selected input point
    (see :func:`select_vertices`): a point that is several rows (a pinched point imported with
    ``pinched="split"``, a vertex split by a cut) gets ``force`` once, divided equally among
    its rows, so the total does not depend on how the point was split. Rows with no input
    point get ``force`` each. Raises :class:`LoadError` for a bad force or selection."""
    _no_booleans(force, "force")
    try:
        f = real_array(force, "force").reshape(-1)
    except TypeError as e:
        raise LoadError(str(e)) from None
    if f.shape != (3,) or not np.all(np.isfinite(f)):
        raise LoadError(f"force: expected 3 finite numbers, got {force!r}")
    mask = select_vertices(sim, where=where, points=points, group=group, groups=groups)
    pid = _point_ids(sim)
    share = np.ones(sim.n_vertices)
    known = mask & (pid >= 0)
    if known.any():
        ids, counts = np.unique(pid[known], return_counts=True)
        share[known] = counts[np.searchsorted(ids, pid[known])]
    out = np.zeros((sim.n_vertices, 3))
    out[mask] = f / share[mask, None]
    return out


def held_positions(
    sim: Simulation, mask: npt.NDArray[np.bool_], displacement: Sequence[float] | None
) -> None:
    """Holds the rows of ``mask`` (fixed), at ``rest + displacement`` when one is given
    (their velocity set to zero), keeping the rows already held. A row held already is moved
    to the new position: this is how a run moves its held vertices step by step (a scene's
    ``[[fix]]`` tables that hold one vertex at two positions are refused before, by
    :func:`check_supports` in :func:`apply_conditions`). Raises :class:`LoadError` for a
    displacement that is not 3 finite real numbers, having changed nothing."""
    d = None if displacement is None else _vector(displacement, "displacement")
    fixed = sim.fixed() | mask
    if d is not None:
        x = sim.positions()
        x[mask] = sim.rest_positions()[mask] + d
        sim.set_positions(x)
        v = sim.velocities()
        v[mask] = 0.0
        sim.set_velocities(v)
    sim.set_fixed(fixed)


def _vector(value: Any, what: str) -> npt.NDArray[np.float64]:
    """``value`` (a held or initial displacement, a velocity) as an array of shape ``(3,)``:
    exactly 3 finite real numbers (booleans refused: numpy reads ``[True, 0, 0]`` as ``[1,
    0, 0]``; one number or 2 are refused, not broadcast). Raises :class:`LoadError` naming
    ``what``."""
    _no_booleans(value, what)
    try:
        d = real_array(value, what).reshape(-1)
    except (TypeError, ValueError) as e:
        raise LoadError(str(e)) from None
    if d.shape != (3,) or not np.all(np.isfinite(d)):
        raise LoadError(f"{what}: expected 3 finite numbers, got {value!r}")
    return d


#: How a message refusing two holds of one vertex ends.
_HELD_ONE_WAY = (
    "a vertex is held one way (narrow one selection, or give both the same displacement)"
)

#: A support of :func:`check_supports`: its scene key, its selection and its displacement
#: (None: held in place).
Support = tuple[str, Mapping[str, Any], Sequence[float] | None]


def _point(p: npt.NDArray[np.float64]) -> str:
    return str([float(c) for c in p])


def _vertex(sim: Simulation, r: int, rest: npt.NDArray[np.float64]) -> str:
    """Row ``r`` as a message names it: its input point when that differs, its rest
    position."""
    pid = int(_point_ids(sim)[r])
    point = f"input point {pid}, " if pid >= 0 and pid != r else ""
    return f"vertex {r} ({point}at rest {_point(rest[r])})"


def check_supports(
    sim: Simulation,
    supports: Sequence[Support],
    groups: MeshGroups | None = None,
    masks: Mapping[str, npt.NDArray[np.bool_]] | None = None,
) -> list[npt.NDArray[np.bool_]]:
    """Refuses two supports (``(key, selection, displacement or None)``, in the order of the
    scene's ``[[fix]]`` tables) that hold one vertex at two positions: held in place is the
    rest position, a displacement ``d`` the position ``rest + d``, compared exactly (no
    tolerance, as the kernel compares them between predicates), so two supports may hold a
    vertex both in place or at the same displacement. Raises :class:`LoadError` with ``key``
    the later support's, naming the vertex (its row, input point and rest position) and the
    earlier support; or a selection's refusal with its key. ``masks``: selections already
    made, by key. Returns each support's mask. Changes nothing."""
    rest = sim.rest_positions()
    n = sim.n_vertices
    holder = np.full(n, -1, dtype=np.int64)
    held_at = np.zeros((n, 3))
    out: list[npt.NDArray[np.bool_]] = []
    for j, (key, sel, disp) in enumerate(supports):
        if masks is not None and key in masks:
            mask = masks[key]
        else:
            try:
                mask = select_vertices(sim, groups=groups, **sel)
            except LoadError as e:
                raise LoadError(str(e), f"{key}.{e.subkey}" if e.subkey else key) from e
        out.append(mask)
        try:
            at = rest if disp is None else rest + _vector(disp, "displacement")
        except LoadError as e:
            raise LoadError(str(e), key) from e
        both = mask & (holder >= 0)
        differ = both & np.any(held_at != at, axis=1)
        if differ.any():
            r = int(np.argmax(differ))
            other_key, _, other_disp = supports[int(holder[r])]
            vertex = _vertex(sim, r, rest)
            if disp is None:
                what = (
                    f"holds {vertex} in place, which {other_key} moves by "
                    f"{_point(np.asarray(other_disp, dtype=np.float64))}"
                )
            else:
                how = (
                    "in place"
                    if other_disp is None
                    else "at another position (displacement "
                    f"{_point(np.asarray(other_disp, dtype=np.float64))})"
                )
                by = _point(np.asarray(disp, dtype=np.float64))
                what = f"moves {vertex} by {by}, which {other_key} holds {how}"
            raise LoadError(f"{what}: {_HELD_ONE_WAY}", key)
        new = mask & (holder < 0)
        holder[new] = j
        held_at[new] = at[new]
    return out


def apply_conditions(
    sim: Simulation, conditions: Mapping[str, Any], groups: MeshGroups | None = None
) -> None:
    """Applies the conditions of a scene beyond the kernel's configuration (its
    :attr:`~topomech.scene.Scene.conditions`) to a simulation as built: ``held`` (``(key,
    selection, displacement or None)``: vertices held by points or group), ``loads``
    (``(key, {"kind", "force" | "traction" | "pressure", "select"})``) and ``initial``
    (``(key, {"select", "velocity", "displacement"})``: fields set on the free vertices of
    the selection, every vertex when it is empty; a displacement moves the positions, not the
    rest). ``supports``: every ``[[fix]]`` table as ``(key, selection, displacement or
    None)``, in order, those by ``where`` (which the kernel applied) included: two that hold
    one vertex at two positions are refused (see :func:`check_supports`); without it, the
    ``held`` ones are checked against each other, and a displacement that moves a vertex
    the simulation holds already is refused. Raises :class:`LoadError` with ``key`` the
    scene key at fault, having changed nothing."""
    bc = conditions
    held: list[Support] = list(bc.get("held", []))
    masks: dict[str, npt.NDArray[np.bool_]] = {}
    for key, sel, _ in held:
        try:
            masks[key] = select_vertices(sim, groups=groups, **sel)
        except LoadError as e:
            raise LoadError(str(e), f"{key}.{e.subkey}" if e.subkey else key) from e
    if held:
        supports = bc.get("supports")
        if supports is not None:
            check_supports(sim, supports, groups, masks)
        else:
            check_supports(sim, held, groups, masks)
            for key, _, disp in held:
                problem = _moved_held(sim, masks[key], disp)
                if problem is not None:
                    raise LoadError(problem, key)
    # everything computed before anything is set: a refusal leaves the simulation as it was
    fixed = sim.fixed()
    for key, _, _ in held:
        fixed = fixed | masks[key]
    loads = bc.get("loads", [])
    total = sim.external_forces() if loads else None
    for key, load in loads:
        sel = load["select"]
        assert total is not None
        try:
            if load["kind"] == "point":
                total += point_load(sim, load["force"], groups=groups, **sel)
            elif load["kind"] == "traction":
                total += surface_load(sim, traction=load["traction"], groups=groups, **sel)
            else:
                total += surface_load(sim, pressure=load["pressure"], groups=groups, **sel)
        except LoadError as e:
            raise LoadError(str(e), f"{key}.{e.subkey}" if e.subkey else key) from e
    initial: list[tuple[npt.NDArray[np.bool_], dict[str, Any]]] = []
    for key, init in bc.get("initial", []):
        try:
            mask = (
                np.ones(sim.n_vertices, dtype=bool)
                if not init["select"]
                else select_vertices(sim, groups=groups, **init["select"])
            )
        except LoadError as e:
            raise LoadError(str(e), f"{key}.{e.subkey}" if e.subkey else key) from e
        # each field 3 finite numbers, checked before anything is set
        fields: dict[str, npt.NDArray[np.float64]] = {}
        for name in ("displacement", "velocity"):
            if init.get(name) is not None:
                try:
                    fields[name] = _vector(init[name], name)
                except LoadError as e:
                    raise LoadError(str(e), f"{key}.{name}") from e
        initial.append((mask & ~fixed, fields))
    for key, _, disp in held:
        held_positions(sim, masks[key], disp)
    if total is not None:
        sim.set_external_forces(total)
    for free, fields in initial:
        if "displacement" in fields:
            x = sim.positions()
            x[free] += fields["displacement"]
            sim.set_positions(x)
        if "velocity" in fields:
            v = sim.velocities()
            v[free] = fields["velocity"]
            sim.set_velocities(v)


def _moved_held(
    sim: Simulation, mask: npt.NDArray[np.bool_], displacement: Sequence[float] | None
) -> str | None:
    """Why holding the rows of ``mask`` at ``rest + displacement`` is refused: it would move
    a row the simulation holds already (None when it would not)."""
    if displacement is None:
        return None
    x = sim.positions()
    rest = sim.rest_positions()
    rows = np.flatnonzero(mask & sim.fixed())
    moved = np.any(x[rows] != rest[rows] + np.asarray(displacement, dtype=np.float64), axis=1)
    if not moved.any():
        return None
    r = int(rows[np.argmax(moved)])
    return (
        f"moves {_vertex(sim, r, rest)}, which is already held at {_point(x[r])}: {_HELD_ONE_WAY}"
    )
