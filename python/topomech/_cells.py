"""Meshes as meshio writes them (points and typed cell blocks) <-> the kernel's flat layout.

The kernel takes ``points`` float64 ``(N, 3)``, one kind name per cell (``polygon``, ``tetra``,
``hexahedron``, ``wedge``, ``pyramid``), ``offsets`` int64 ``(M + 1,)`` and ``connectivity``
int64. This module accepts what users have instead: 2D or 3D points, and cells as
``[(type, array), ...]`` pairs, meshio ``CellBlock`` objects, a ``{type: array}`` dict, or one
array with an explicit kind. Cells are numbered in the order given, across blocks; every
error names the cell.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from topomech._core import MeshError

__all__ = [
    "CellBlock",
    "FlatMesh",
    "cell_dimension",
    "flat_to_blocks",
    "mesh_figures",
    "normalize_cells",
    "normalize_points",
    "to_flat",
]

# meshio type -> (kernel kind, vertices per cell or None for any polygon).
LINEAR_TYPES: dict[str, tuple[str, int | None]] = {
    "triangle": ("polygon", 3),
    "quad": ("polygon", 4),
    "polygon": ("polygon", None),
    "tetra": ("tetra", 4),
    "hexahedron": ("hexahedron", 8),
    "wedge": ("wedge", 6),
    "pyramid": ("pyramid", 5),
}

_DIMENSION_BY_PREFIX = (
    ("vertex", 0),
    ("line", 1),
    ("triangle", 2),
    ("quad", 2),
    ("polygon", 2),
    ("tetra", 3),
    ("hexahedron", 3),
    ("wedge", 3),
    ("pyramid", 3),
)
_LAGRANGE_DIMENSION = {
    "CURVE": 1,
    "TRIANGLE": 2,
    "QUADRILATERAL": 2,
    "TETRAHEDRON": 3,
    "HEXAHEDRON": 3,
    "WEDGE": 3,
    "PYRAMID": 3,
}
_INT64_MAX = np.iinfo(np.int64).max


class CellBlock(NamedTuple):
    """Cells of one meshio type: ``data`` is ``(M, k)`` or, for polygons, a list of lists."""

    type: str
    data: Any


#: What a refusal of a map whose cells mesh files do not hold as cells of a kind (a general
#: polyhedron after a rewrite) says of mesh files.
MESH_FILE_CELLS = (
    "mesh files hold tetrahedra, hexahedra, wedges, pyramids and polygons; a .vtu also holds "
    "general polyhedra, every volume then written as one (for viewing: topomech does not read "
    "them back)"
)


class FlatMesh(NamedTuple):
    """The kernel's flat layout (see the module docstring)."""

    points: npt.NDArray[np.float64]
    kinds: list[str]
    offsets: npt.NDArray[np.int64]
    connectivity: npt.NDArray[np.int64]


def cell_dimension(cell_type: str) -> int | None:
    """The topological dimension of a meshio cell type, ``None`` if unknown."""
    if cell_type.startswith("VTK_LAGRANGE_"):
        return _LAGRANGE_DIMENSION.get(cell_type[len("VTK_LAGRANGE_") :])
    for prefix, dim in _DIMENSION_BY_PREFIX:
        suffix = cell_type[len(prefix) :]
        if cell_type.startswith(prefix) and (suffix == "" or suffix.isdigit()):
            return dim
    return None


def _unmasked(values: Any, what: str) -> Any:
    """``values``, or the data of a numpy masked array none of whose entries is masked.
    Raises :class:`ValueError` for a masked array with masked entries (``np.asarray`` would
    take the values under the mask as if they were valid)."""
    if isinstance(values, np.ma.MaskedArray):
        mask = np.ma.getmaskarray(values)
        if mask.any():
            raise ValueError(
                f"{what}: masked entries cannot be taken ({int(mask.sum())} of {mask.size} "
                "masked); fill them first, e.g. values.filled(0.0)"
            )
        return values.data
    return values


def _refuse_non_real(a: npt.NDArray[Any], values: Any, what: str) -> None:
    """Raises :class:`TypeError` when the array ``a`` (made of ``values``) does not hold real
    numbers: complex, booleans, dates or durations, strings, objects (see :func:`real_array`)."""
    if a.dtype.kind == "c":
        raise TypeError(f"{what} must be real numbers, got an array of {a.dtype}")
    if a.dtype.kind == "b":
        raise TypeError(f"{what} must be real numbers, got booleans")
    if a.dtype.kind in "Mm":
        raise TypeError(
            f"{what} must be real numbers, got an array of {a.dtype} (dates or durations)"
        )
    if a.dtype.kind in "OUSV":
        shown = "None" if values is None else f"an array of {a.dtype}"
        raise TypeError(f"{what} must be real numbers, got {shown}")


#: What an object array of points may not hold (besides None): not real numbers.
_NOT_REAL = (bool, np.bool_, str, bytes, complex, np.complexfloating, np.datetime64, np.timedelta64)


def embedding_name(name: Any) -> str:
    """``name`` when it is a str (an embedding's name); raises :class:`TypeError` naming
    the argument otherwise (the kernel's own message names neither the argument nor what it
    expects)."""
    if not isinstance(name, str):
        raise TypeError(f"name: expected an embedding's name (a str), got {type(name).__name__}")
    return name


def real_array(values: Any, what: str) -> npt.NDArray[np.float64]:
    """``values`` as a contiguous float64 array of the same shape (a 0-d array stays 0-d, so
    that a shape error names its real shape). Raises :class:`TypeError` for complex values
    (numpy would drop their imaginary parts with only a ``ComplexWarning``), for booleans
    (numpy would read ``True`` as 1.0: a mask passed where a force or a position was meant),
    for dates and durations (``datetime64``, ``timedelta64``: numpy would read them as their
    counts of units) and for values that are not numbers (``None``, strings, numeric ones
    included: numpy would read ``None`` as NaN, ``"1.0"`` as 1.0); :class:`ValueError` for a
    numpy masked array with masked entries (a masked array with none is taken as its
    data)."""
    values = _unmasked(values, what)
    a = np.asarray(values)
    _refuse_non_real(a, values, what)
    return np.asarray(a, dtype=np.float64, order="C")


def normalize_points(points: Any) -> npt.NDArray[np.float64]:
    """``points`` as float64 ``(N, 3)``; 2 columns get z = 0. Refuses what
    :func:`real_array` refuses (complex, booleans, dates, strings, objects, masked
    entries) with the same errors."""
    points = _unmasked(points, "points")
    try:
        raw = np.asarray(points)
    except (TypeError, ValueError) as e:
        raise ValueError(f"points must be a numeric array of shape (N, 2) or (N, 3): {e}") from e
    if raw.dtype.kind == "O":
        # numbers numpy holds as objects (Python ints beyond int64, fractions) are taken as
        # before; None, booleans, strings, complex values and dates are refused
        for v in raw.flat:
            if v is None or isinstance(v, _NOT_REAL):
                shown = "None" if v is None else f"{type(v).__name__} {v!r:.40}"
                raise TypeError(f"points must be real numbers, got {shown}")
    else:
        _refuse_non_real(raw, points, "points")
    try:
        p = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"points must be a numeric array of shape (N, 2) or (N, 3): {e}") from e
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"points must have shape (N, 2) or (N, 3), got {tuple(p.shape)}")
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    return np.ascontiguousarray(p)


def _is_block(item: Any) -> bool:
    if hasattr(item, "type") and hasattr(item, "data"):
        return True
    return isinstance(item, (tuple, list)) and len(item) == 2 and isinstance(item[0], str)


def normalize_cells(cells: Any, kind: str | None = None) -> list[CellBlock]:
    """The blocks of ``cells`` in order, whatever form it came in."""
    if kind is not None:
        if isinstance(cells, Mapping) or (
            isinstance(cells, (list, tuple)) and cells and _is_block(cells[0])
        ):
            raise ValueError("kind= is only for a single cell array, not for typed cell blocks")
        return [CellBlock(kind, cells)]
    if isinstance(cells, Mapping):
        return [CellBlock(str(t), d) for t, d in cells.items()]
    if isinstance(cells, np.ndarray):
        raise TypeError(
            "cells is a bare array: say what its cells are with kind=, e.g. kind='tetra'"
        )
    if isinstance(cells, Iterable) and not isinstance(cells, (str, bytes)):
        blocks = []
        for item in cells:
            if hasattr(item, "type") and hasattr(item, "data"):
                blocks.append(CellBlock(str(item.type), item.data))
            elif _is_block(item):
                blocks.append(CellBlock(item[0], item[1]))
            else:
                raise TypeError(
                    "cells must be (type, array) pairs, meshio CellBlocks, a {type: array} "
                    "dict, or one array with kind=; got an item "
                    f"{type(item).__name__} {item!r:.60}"
                )
        return blocks
    raise TypeError(
        "cells must be (type, array) pairs, meshio CellBlocks, a {type: array} dict, "
        f"or one array with kind=; got {type(cells).__name__}"
    )


def _kernel_kind(cell_type: str, first_cell: int) -> tuple[str, int | None]:
    if cell_type in LINEAR_TYPES:
        return LINEAR_TYPES[cell_type]
    if re.fullmatch(r"polygon\d+", cell_type):
        return "polygon", int(cell_type[len("polygon") :])
    dim = cell_dimension(cell_type)
    if dim in (2, 3):
        raise MeshError(
            f"cell {first_cell} is a {cell_type}: higher-order cells are not supported, "
            "use linear elements (triangle, quad, polygon, tetra, hexahedron, wedge, pyramid); "
            "topomech.io.read_mesh(path, linear=True) keeps the corner nodes of a file's "
            "second-order cells"
        )
    if dim is not None:
        raise MeshError(
            f"cell {first_cell} is a {cell_type}, a {dim}D cell: a G-map is built from "
            "surface (2D) or volume (3D) cells only"
        )
    if cell_type.startswith("polyhedron") and cell_type[len("polyhedron") :].isdigit():
        raise MeshError(
            f"cell {first_cell} is a {cell_type}, a general polyhedron (VTK_POLYHEDRON): "
            "topomech writes such cells to a .vtu for viewing but does not build a map from "
            "them; load the map saved as a .tmg instead, or use tetra, hexahedron, wedge or "
            "pyramid cells"
        )
    raise MeshError(
        f"cell {first_cell} has unknown type {cell_type!r}: expected triangle, quad, polygon, "
        "tetra, hexahedron, wedge or pyramid"
    )


def _index_array(data: Any, first_cell: int, cell_type: str) -> npt.NDArray[np.int64]:
    """A rectangular block of vertex indices as int64, refusing non-integers and overflow."""
    a = np.asarray(data)
    rows = np.atleast_2d(a)  # for messages: one row per cell
    if a.dtype.kind in "iu":
        if a.dtype.kind == "u" and a.size and a.max() > _INT64_MAX:
            row = int(np.argmax((rows > _INT64_MAX).any(axis=1)))
            raise MeshError(
                f"cell {first_cell + row} ({cell_type}) refers to vertex "
                f"{int(rows[row].max())}, which is out of range"
            )
        return a.astype(np.int64, copy=False)
    if a.dtype.kind == "f":
        bad = ~np.isfinite(rows) | (rows != np.round(rows))
        if bad.any():
            row = int(np.argmax(bad.any(axis=1)))
            raise MeshError(
                f"cell {first_cell + row} ({cell_type}) has a vertex index that is not an "
                f"integer: {rows[row].tolist()}"
            )
        if a.size and np.abs(a).max() > _INT64_MAX:
            raise MeshError(f"cells {first_cell}.. ({cell_type}) have vertex indices out of range")
        return a.astype(np.int64)
    if a.size == 0:
        return a.astype(np.int64)
    raise TypeError(
        f"the vertex indices of the {cell_type} cells from cell {first_cell} must be integers, "
        f"got an array of dtype {a.dtype}"
    )


def _ragged(data: Any) -> bool:
    if isinstance(data, np.ndarray):
        return bool(data.dtype == object)
    if isinstance(data, Sequence) and not isinstance(data, (str, bytes)):
        lengths = {len(c) if isinstance(c, (Sequence, np.ndarray)) else -1 for c in data}
        return len(lengths) > 1
    return False


def to_flat(points: Any, cells: Any, kind: str | None = None) -> FlatMesh:
    """The flat layout of points and cells in any accepted form (see the module docstring)."""
    pts = normalize_points(points)
    kinds: list[str] = []
    conn_parts: list[npt.NDArray[np.int64]] = []
    sizes: list[npt.NDArray[np.int64]] = []
    first = 0
    for block in normalize_cells(cells, kind):
        kernel_kind, nv = _kernel_kind(block.type, first)
        if _ragged(block.data):
            rows = [
                _index_array(np.asarray(c).reshape(1, -1), first + k, block.type)[0]
                for k, c in enumerate(block.data)
            ]
            if nv is not None:
                for k, r in enumerate(rows):
                    if len(r) != nv:
                        raise MeshError(
                            f"cell {first + k} is a {block.type} with {len(r)} vertices, "
                            f"expected {nv}"
                        )
            m = len(rows)
            row_sizes = np.array([len(r) for r in rows], dtype=np.int64)
            conn = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        else:
            a = _index_array(block.data, first, block.type)
            if a.size == 0 and a.ndim < 2:
                continue
            if a.ndim != 2:
                raise ValueError(
                    f"the {block.type} cells from cell {first} must be a 2D array "
                    f"(cells, vertices per cell), got shape {tuple(a.shape)}"
                )
            m = a.shape[0]
            if m == 0:
                continue
            if nv is not None and a.shape[1] != nv:
                raise MeshError(
                    f"cell {first} is a {block.type} with {a.shape[1]} vertices, expected {nv}"
                )
            row_sizes = np.full(m, a.shape[1], dtype=np.int64)
            conn = np.ascontiguousarray(a).reshape(-1)
        kinds.extend([kernel_kind] * m)
        sizes.append(row_sizes)
        conn_parts.append(conn)
        first += m
    offsets = np.zeros(len(kinds) + 1, dtype=np.int64)
    if sizes:
        np.cumsum(np.concatenate(sizes), out=offsets[1:])
    connectivity = np.concatenate(conn_parts) if conn_parts else np.zeros(0, dtype=np.int64)
    return FlatMesh(pts, kinds, offsets, connectivity.astype(np.int64, copy=False))


def flat_to_blocks(
    kinds: Sequence[str], offsets: npt.NDArray[np.int64], connectivity: npt.NDArray[np.int64]
) -> list[CellBlock]:
    """meshio cell blocks from the flat layout, keeping the cell order: consecutive cells of
    one meshio type share a block; polygons of 3 and 4 vertices are triangles and quads."""
    blocks: list[CellBlock] = []
    run_type: str | None = None
    run: list[npt.NDArray[np.int64]] = []

    def close() -> None:
        if run_type is not None and run:
            blocks.append(CellBlock(run_type, np.stack(run)))

    for c, kind in enumerate(kinds):
        verts = connectivity[offsets[c] : offsets[c + 1]]
        t = {3: "triangle", 4: "quad"}.get(len(verts), "polygon") if kind == "polygon" else kind
        if t != run_type or (t == "polygon" and run and len(run[0]) != len(verts)):
            close()
            run_type, run = t, []
        run.append(verts)
    close()
    return blocks


# ---------------------------------------------------------------------------- quality figures

#: Edges of each linear volume cell, in VTK's vertex order.
_EDGES: dict[str, list[tuple[int, int]]] = {
    "tetra": [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)],
    "hexahedron": [
        (0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4),
        (0, 4), (1, 5), (2, 6), (3, 7),
    ],
    "wedge": [(0, 1), (1, 2), (2, 0), (3, 4), (4, 5), (5, 3), (0, 3), (1, 4), (2, 5)],
    "pyramid": [(0, 1), (1, 2), (2, 3), (3, 0), (0, 4), (1, 4), (2, 4), (3, 4)],
}  # fmt: skip
#: The faces of each linear volume cell, outward for VTK's vertex order (the kernel's table):
#: every edge is walked once in each direction, so the signed volumes of the faces' cones add
#: up to the cell's. One table for the whole package (loads, outputs, previews, quality).
CELL_FACES: dict[str, tuple[tuple[int, ...], ...]] = {
    "tetra": ((0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2)),
    "hexahedron": (
        (0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7),
    ),
    "wedge": ((0, 2, 1), (3, 4, 5), (0, 1, 4, 3), (1, 2, 5, 4), (2, 0, 3, 5)),
    "pyramid": ((0, 3, 2, 1), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)),
}  # fmt: skip
#: The linear volume kind of each vertex count.
KIND_BY_SIZE = {4: "tetra", 5: "pyramid", 6: "wedge", 8: "hexahedron"}
_POLYGON_TYPES = ("triangle", "quad", "polygon")


def _polygon_vector_area(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """The vector area ``(M, 3)`` of polygons ``x`` ``(M, k, 3)`` (vertices in order)."""
    c = x.mean(axis=1, keepdims=True)
    d = x - c
    area: npt.NDArray[np.float64] = 0.5 * np.cross(d, np.roll(d, -1, axis=1)).sum(axis=1)
    return area


def _volume(kind: str, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """The volume ``(M,)`` of volume cells ``x`` ``(M, k, 3)``: the sum over the faces (each
    split into triangles about its centroid) of the signed volumes of the tetrahedra they
    make with the cell's centroid; positions are taken relative to that centroid."""
    x = x - x.mean(axis=1, keepdims=True)
    total = np.zeros(len(x))
    for face in CELL_FACES[kind]:
        f = x[:, list(face), :]
        fc = f.mean(axis=1)
        nxt = np.roll(f, -1, axis=1)
        for i in range(len(face)):
            a, b = f[:, i, :] - fc, nxt[:, i, :] - fc
            total += np.einsum("ij,ij->i", fc, np.cross(a, b)) / 6.0
    return np.abs(total)


def _edge_lengths(x: npt.NDArray[np.float64], edges: Sequence[tuple[int, int]]) -> Any:
    a = np.array([e[0] for e in edges])
    b = np.array([e[1] for e in edges])
    return np.linalg.norm(x[:, b, :] - x[:, a, :], axis=2)


def _figures_of(
    kind: str, x: npt.NDArray[np.float64]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """``(size, aspect)`` of cells ``x`` ``(M, k, 3)`` of one kind: volume or area, and the
    aspect ratio (see :func:`mesh_figures`)."""
    k = x.shape[1]
    with np.errstate(divide="ignore", invalid="ignore"):
        if kind in _POLYGON_TYPES:
            size = np.linalg.norm(_polygon_vector_area(x), axis=1)
            lengths = np.linalg.norm(np.roll(x, -1, axis=1) - x, axis=2)
            if k == 3:
                # longest edge / inradius (2 A / perimeter), over 2 sqrt(3) (equilateral)
                aspect = lengths.max(axis=1) * lengths.sum(axis=1) / (4.0 * np.sqrt(3.0) * size)
            else:
                aspect = lengths.max(axis=1) / lengths.min(axis=1)
        else:
            size = _volume(kind, x)
            lengths = _edge_lengths(x, _EDGES[kind])
            if kind == "tetra":
                faces = np.stack(
                    [
                        np.linalg.norm(_polygon_vector_area(x[:, list(f), :]), axis=1)
                        for f in CELL_FACES["tetra"]
                    ],
                    axis=1,
                ).sum(axis=1)
                # longest edge / inradius (3 V / surface), over 2 sqrt(6) (regular)
                aspect = lengths.max(axis=1) * faces / (6.0 * np.sqrt(6.0) * size)
            else:
                aspect = lengths.max(axis=1) / lengths.min(axis=1)
    aspect = np.where(np.isnan(aspect), np.inf, aspect)
    return size, aspect


def mesh_figures(points: Any, cells: Sequence[tuple[str, Any]], dimension: int) -> dict[str, Any]:
    """The bounding box, cells by kind and quality figures of a mesh of linear cells, as
    ``topomech info`` prints them::

        {"bounding_box": {"min": [x, y, z], "max": [x, y, z]},   # of the points cells use
         "cells_by_kind": {meshio type: count},
         "quality": {"min_volume" | "min_area": float, "max_volume" | "max_area": float,
                     "worst_aspect_ratio": float | None, "worst_aspect_cell": int | None}}

    Volumes in 3D, areas in 2D (units of the points cubed or squared). The aspect ratio of a
    triangle or tetrahedron is its longest edge over its inradius, divided by that of the
    equilateral triangle (2 sqrt 3) or regular tetrahedron (2 sqrt 6): 1 for the best cell,
    unbounded for a flat one (a sliver tetrahedron included, whose edges can all be alike).
    For quads, polygons, hexahedra, wedges and pyramids it is the longest edge over the
    shortest. ``worst_aspect_cell`` is the cell's index in ``cells`` concatenated (the
    ``cell_id``); a degenerate cell (zero size) has an infinite ratio, written as None.
    Cells of other types are counted but not measured."""
    pts = normalize_points(points)
    by_kind: dict[str, int] = {}
    sizes: list[npt.NDArray[np.float64]] = []
    aspects: list[npt.NDArray[np.float64]] = []
    ids: list[npt.NDArray[np.int64]] = []
    used: list[npt.NDArray[np.int64]] = []
    first = 0
    for cell_type, data in cells:
        if _ragged(data) or (isinstance(data, (list, tuple)) and cell_type == "polygon"):
            rows = [np.asarray(c, dtype=np.int64) for c in data]
            groups: dict[int, list[int]] = {}
            for i, r in enumerate(rows):
                groups.setdefault(len(r), []).append(i)
            parts = [(np.array(idx), np.stack([rows[i] for i in idx])) for idx in groups.values()]
        else:
            a = np.asarray(data, dtype=np.int64)
            parts = [(np.arange(len(a)), a.reshape(len(a), -1))]
        n = sum(len(idx) for idx, _ in parts)
        if n == 0:
            continue
        by_kind[cell_type] = by_kind.get(cell_type, 0) + n
        for idx, conn in parts:
            used.append(conn.ravel())
            kind = "polygon" if cell_type in _POLYGON_TYPES else cell_type
            if kind not in _EDGES and kind != "polygon":
                continue
            size, aspect = _figures_of(cell_type if kind != "polygon" else "polygon", pts[conn])
            sizes.append(size)
            aspects.append(aspect)
            ids.append(first + idx)
        first += n
    if used:
        u = pts[np.unique(np.concatenate(used))]
        box = {"min": u.min(axis=0).tolist(), "max": u.max(axis=0).tolist()}
    else:
        box = {"min": [0.0, 0.0, 0.0], "max": [0.0, 0.0, 0.0]}
    what = "volume" if dimension == 3 else "area"
    quality: dict[str, Any] = {
        f"min_{what}": None,
        f"max_{what}": None,
        "worst_aspect_ratio": None,
        "worst_aspect_cell": None,
    }
    if sizes:
        s, asp, cid = np.concatenate(sizes), np.concatenate(aspects), np.concatenate(ids)
        quality[f"min_{what}"] = float(s.min())
        quality[f"max_{what}"] = float(s.max())
        worst = int(np.argmax(asp))
        quality["worst_aspect_ratio"] = float(asp[worst]) if np.isfinite(asp[worst]) else None
        quality["worst_aspect_cell"] = int(cid[worst])
    return {"bounding_box": box, "cells_by_kind": by_kind, "quality": quality}
