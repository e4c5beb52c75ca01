"""Mesh files in and out, through meshio (Gmsh .msh 2 and 4, VTK, VTU, OBJ, and the rest).

A G-map is built from cells of one dimension: :func:`read_mesh` keeps the cells of the highest
dimension in the file (volumes if any, else surfaces) and returns the blocks it dropped, such
as the boundary triangles and lines Gmsh writes beside tetrahedra.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from topomech._cells import CellBlock, cell_dimension
from topomech._core import MeshError, MeshReadError
from topomech._gmap import GMap, PathLike

if TYPE_CHECKING:
    import meshio

__all__ = [
    "DroppedBlock",
    "read_gmap",
    "read_mesh",
    "select_cells",
    "write_format",
    "write_gmap",
    "write_vtu",
]

#: The extension of a saved G-map (read by :func:`read_gmap` without meshio).
GMAP_SUFFIX = ".tmg"


class DroppedBlock(NamedTuple):
    """Cells left out because they are of a lower dimension than the mesh."""

    type: str
    n_cells: int
    dimension: int

    def __str__(self) -> str:
        s = "s" if self.n_cells != 1 else ""
        return f"{self.n_cells} {self.type} cell{s} ({self.dimension}D)"


def _block(b: Any) -> CellBlock:
    if hasattr(b, "type") and hasattr(b, "data"):
        return CellBlock(str(b.type), b.data)
    return CellBlock(str(b[0]), b[1])


def select_cells(cells: Sequence[Any]) -> tuple[list[CellBlock], list[DroppedBlock]]:
    """Keeps the non-empty blocks of the highest dimension (3 if there are volume cells, else
    2) and lists the others. Blocks of unknown type are kept, so that building the map names
    them. Raises :class:`MeshError` when there are no surface or volume cells at all."""
    blocks = [_block(b) for b in cells]
    blocks = [b for b in blocks if len(b.data) > 0]
    dims = [cell_dimension(b.type) for b in blocks]
    top = max((d for d in dims if d in (2, 3)), default=None)
    if top is None:
        if not blocks:
            raise MeshError("the mesh has no cells")
        if all(d is not None for d in dims):
            found = ", ".join(f"{len(b.data)} {b.type}" for b in blocks)
            raise MeshError(f"the mesh has no surface or volume cells (found {found})")
    kept: list[CellBlock] = []
    dropped: list[DroppedBlock] = []
    for b, d in zip(blocks, dims):
        if d is not None and top is not None and d < top:
            dropped.append(DroppedBlock(b.type, len(b.data), d))
        else:
            kept.append(b)
    return kept, dropped


def _formats_for(p: Path) -> list[str]:
    """meshio's candidate formats for a file name (``.vtu``, ``.msh``, ``.vtk.gz``, ...)."""
    import meshio

    table: dict[str, list[str]] = meshio.extension_to_filetypes
    suffixes = [s.lower() for s in p.suffixes]
    for k in range(len(suffixes)):
        ext = "".join(suffixes[k:])
        if ext in table:
            # `.msh` is Gmsh's far more often than ANSYS's: try Gmsh first.
            return sorted(table[ext], key=lambda f: f != "gmsh")
    known = ", ".join(sorted(table))
    ext = p.suffix or "(none)"
    raise MeshReadError(f"{p}: unknown mesh file extension {ext}; meshio reads {known}")


def _quiet_read(p: Path, fmt: str) -> tuple[meshio.Mesh | None, str, str]:
    """``meshio.read`` with its prints captured: meshio prints to stdout and calls
    ``sys.exit(1)`` when a reader fails. Returns the mesh (or None), what meshio printed, and
    why it failed."""
    import meshio

    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            mesh = meshio.read(p, file_format=fmt)
    except (MemoryError, KeyboardInterrupt):
        raise
    except SystemExit:
        return None, out.getvalue(), _clean(out.getvalue()) or f"not a valid {fmt} file"
    except Exception as e:  # meshio's readers raise anything from ReadError to IndexError
        detail = _clean(out.getvalue())
        reason = f"{type(e).__name__}: {str(e).strip()}"
        return None, out.getvalue(), f"{detail}; {reason}" if detail else reason
    return mesh, out.getvalue(), ""


def _clean(text: str) -> str:
    """What meshio printed, on one line, without the generic "Couldn't read file" error it
    prints last, just before ``sys.exit``."""
    text = text.split("Error: Couldn't read file")[0]
    return "; ".join(line.strip() for line in text.splitlines() if line.strip())


def read_mesh(path: PathLike) -> tuple[meshio.Mesh, list[DroppedBlock]]:
    """Reads a mesh file with meshio; returns a mesh holding only the cells of the highest
    dimension, and the blocks dropped.

    Raises :class:`MeshReadError` (with the path and the reason) for a missing, unreadable,
    truncated or garbage file, and :class:`MeshError` for a file without surface or volume
    cells. What meshio prints while reading goes to stderr, never to stdout.
    """
    import meshio

    p = Path(path)
    if not p.exists():
        raise MeshReadError(f"{p}: no such file")
    if p.is_dir():
        raise MeshReadError(f"{p}: is a directory, not a mesh file")
    if not os.access(p, os.R_OK):
        raise MeshReadError(f"{p}: permission denied")
    reasons = []
    mesh = None
    for fmt in _formats_for(p):
        mesh, printed, reason = _quiet_read(p, fmt)
        if mesh is not None:
            if printed.strip():
                print(f"meshio: {_clean(printed)}", file=sys.stderr)
            break
        reasons.append(f"as {fmt}: {reason}")
    if mesh is None:
        raise MeshReadError(f"{p}: cannot read this file as a mesh ({'; '.join(reasons)})")
    _check_indices(p, mesh)
    kept, dropped = select_cells(mesh.cells)
    return meshio.Mesh(mesh.points, [(b.type, b.data) for b in kept]), dropped


def _check_indices(p: Path, mesh: meshio.Mesh) -> None:
    """A truncated file can parse into cells that point past the points: say it is the file,
    not the mesh, that is broken."""
    import numpy as np

    n = len(mesh.points)
    if n == 0 and any(len(b.data) for b in mesh.cells):
        raise MeshReadError(f"{p}: cannot read this file as a mesh: it has cells but no points")
    for b in mesh.cells:
        data = b.data
        if isinstance(data, np.ndarray) and data.size and data.dtype.kind in "iu":
            hi = int(data.max())
            if hi >= n:
                raise MeshReadError(
                    f"{p}: cannot read this file as a mesh: its {b.type} cells refer to "
                    f"point {hi} but it has only {n} points (truncated or corrupt file?)"
                )


def read_gmap(path: PathLike, reorient: bool = False) -> tuple[GMap, list[DroppedBlock]]:
    """A G-map from a file: a saved map (``.tmg``) or any mesh file meshio reads."""
    p = Path(path)
    if p.suffix.lower() == GMAP_SUFFIX:
        if not p.exists():
            raise MeshReadError(f"{p}: no such file")
        return GMap.load(p), []
    mesh, dropped = read_mesh(p)
    return GMap.from_mesh(mesh.points, mesh.cells, reorient), dropped


def write_vtu(gmap: GMap, path: PathLike) -> None:
    """Writes the map's points and cells to a VTU file."""
    import meshio

    meshio.write(os.fspath(path), gmap.to_meshio(), file_format="vtu")


def write_format(path: PathLike) -> str:
    """The format :func:`write_gmap` writes ``path`` in, from its extension: ``"tmg"`` (a
    saved G-map) or a meshio format name (``.msh`` is Gmsh's). Raises ``ValueError`` for an
    extension that names no format."""
    import meshio

    p = Path(path)
    if p.suffix.lower() == GMAP_SUFFIX:
        return "tmg"
    table: dict[str, list[str]] = meshio.extension_to_filetypes
    suffixes = [s.lower() for s in p.suffixes]
    for k in range(len(suffixes)):
        formats = table.get("".join(suffixes[k:]))
        if formats:
            return sorted(formats, key=lambda f: f != "gmsh")[0]
    known = ", ".join([GMAP_SUFFIX, *sorted(table)])
    raise ValueError(f"{p}: unknown output extension {p.suffix or '(none)'}; known: {known}")


def write_gmap(gmap: GMap, path: PathLike) -> None:
    """Writes a map: a saved G-map (round-trip exact) for ``.tmg``, else its points and cells
    as a mesh file in the format of the extension (``.vtu``, ``.vtk``, ``.msh``, ...).
    Raises ``ValueError`` when the extension names no format or the format cannot hold the
    map's cells (Gmsh has no polygons, say); nothing is left written then."""
    fmt = write_format(path)
    if fmt == "tmg":
        gmap.save(path)
    elif fmt == "vtu":
        write_vtu(gmap, path)
    else:
        import meshio

        mesh = gmap.to_meshio()
        try:
            meshio.write(os.fspath(path), mesh, file_format=fmt)
        except (MemoryError, KeyboardInterrupt, OSError):
            raise
        except Exception as e:  # meshio's writers raise KeyError for cells they cannot hold
            with contextlib.suppress(OSError):
                Path(path).unlink()
            kinds = ", ".join(sorted({b.type for b in mesh.cells}))
            raise ValueError(
                f"{path}: cannot write the map as {fmt} (cells: {kinds}): "
                f"{type(e).__name__}: {e}; write .vtu or .tmg instead"
            ) from e
