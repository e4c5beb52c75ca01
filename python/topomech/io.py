"""Mesh files in and out, through meshio (Gmsh .msh 1, 2 and 4, VTK, VTU, OBJ, and the rest).

A G-map is built from cells of one dimension: :func:`read_mesh` keeps the cells of the highest
dimension in the file (volumes if any, else surfaces) and returns the blocks it dropped, such
as the boundary triangles and lines Gmsh writes beside tetrahedra. Named sets travel with the
mesh: Gmsh physical groups (of any dimension) and meshio point and cell sets become
``point_sets``, ``cell_sets_kept`` and ``facet_sets`` (see :func:`read_mesh`).

What is read beyond meshio's own readers, each with a note:

- a file whose extension lies (a ``.vtk`` holding VTU XML, a ``.msh`` holding legacy VTK) is
  read by its content once the extension's readers fail;
- Gmsh 4.1 and 4.0 files with physical tags on only some entities (meshio refuses them): the
  tags that exist are kept; a Gmsh 4.0 file (header "4", which meshio takes for 4.1) is read
  as 4.0;
- Gmsh 1 files (``$NOD``/``$ELM``);
- second-order cells (``tetra10``, ``hexahedron20``/``27``, ``wedge15``/``18``,
  ``pyramid13``/``14``, ``triangle6``/``7``, ``quad8``/``9``, ``line3``, VTK Lagrange cells)
  with ``linear=True``: their corner nodes are kept, the other nodes become unused points.
  Without it they are refused, naming the option.

:func:`import_mesh` reads a file and builds its map with the import options (``reorient``,
``pinched``, ``duplicates``, ``linear``) and returns the notes saying what was done, worded
for the front end that asked (Python keywords, CLI flags or scene keys).
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import numpy.typing as npt

from topomech import _gmap
from topomech._cells import MESH_FILE_CELLS, CellBlock, cell_dimension
from topomech._core import MeshError, MeshReadError
from topomech._gmap import GMap, PathLike
from topomech._paths import missing_file

if TYPE_CHECKING:
    import meshio

__all__ = [
    "DUPLICATES",
    "ORDERS",
    "PINCHED",
    "DroppedBlock",
    "ImportedMesh",
    "build_gmap",
    "build_notes",
    "format_option",
    "import_mesh",
    "linear_type",
    "read_gmap",
    "read_mesh",
    "select_cells",
    "write_format",
    "write_gmap",
    "write_vtu",
]

#: The extension of a saved G-map (read by :func:`read_gmap` without meshio).
GMAP_SUFFIX = ".tmg"

#: Values of the ``pinched`` import option (the first is the default).
PINCHED = ("merge", "split", "refuse")
#: Values of the ``duplicates`` import option (the first is the default).
DUPLICATES = ("refuse", "merge")
#: Values of a scene's ``mesh.order`` (the first is the default): ``"as-is"`` refuses
#: second-order cells, ``"linear"`` keeps their corner nodes.
ORDERS = ("as-is", "linear")
#: The front ends' spellings of an option (see :func:`format_option`).
STYLES = ("python", "cli", "scene")

#: Cells, points or groups named in one note or error before "... and N more".
MAX_LISTED = 20


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


def _select(blocks: Sequence[CellBlock]) -> tuple[list[int], list[int]]:
    """Indices of the kept and of the dropped blocks among ``blocks`` (empty blocks are in
    neither). Raises :class:`MeshError` when there are no surface or volume cells at all."""
    nonempty = [k for k, b in enumerate(blocks) if len(b.data) > 0]
    dims = {k: cell_dimension(blocks[k].type) for k in nonempty}
    top = max((d for d in dims.values() if d in (2, 3)), default=None)
    if top is None:
        if not nonempty:
            raise MeshError("the mesh has no cells")
        if all(d is not None for d in dims.values()):
            found = ", ".join(f"{len(blocks[k].data)} {blocks[k].type}" for k in nonempty)
            raise MeshError(f"the mesh has no surface or volume cells (found {found})")
    kept: list[int] = []
    dropped: list[int] = []
    for k in nonempty:
        d = dims[k]
        if d is not None and top is not None and d < top:
            dropped.append(k)
        else:
            kept.append(k)
    return kept, dropped


def select_cells(cells: Sequence[Any]) -> tuple[list[CellBlock], list[DroppedBlock]]:
    """Keeps the non-empty blocks of the highest dimension (3 if there are volume cells, else
    2) and lists the others. Blocks of unknown type are kept, so that building the map names
    them. Raises :class:`MeshError` when there are no surface or volume cells at all."""
    blocks = [_block(b) for b in cells]
    kept, dropped = _select(blocks)
    return [blocks[k] for k in kept], [_dropped(blocks[k]) for k in dropped]


def _dropped(b: CellBlock) -> DroppedBlock:
    return DroppedBlock(b.type, len(b.data), cell_dimension(b.type) or 0)


# ------------------------------------------------------------------------- option spellings


def format_option(name: str, value: str, style: str) -> str:
    """An import option as the user writes it: ``style`` ``"python"`` (``pinched="split"``,
    ``reorient=True``, ``linear=True``), ``"cli"`` (``--pinched split``, ``--reorient``,
    ``--no-reorient``, ``--linear``) or ``"scene"`` (``mesh.pinched = "split"``,
    ``mesh.reorient = true``, ``mesh.order = "linear"``). ``value`` is the option's value as
    text (``"true"``, ``"split"``). Uses the kernel bindings' spelling when they have it."""
    kernel = getattr(_gmap, "format_option", None)
    if kernel is not None:
        with contextlib.suppress(Exception):
            return str(kernel(name, value, style))
    if style not in STYLES:
        raise ValueError(f"unknown option style {style!r} (expected python, cli or scene)")
    flag = value.lower() in ("true", "1", "yes")
    if style == "python":
        if name in ("reorient", "linear"):
            return f"{name}={flag}"
        return f'{name}="{value}"'
    if style == "cli":
        if name in ("reorient", "linear"):
            return f"--{name}" if flag else f"--no-{name}"
        return f"--{name} {value}"
    if name == "linear":
        return 'mesh.order = "linear"' if flag else 'mesh.order = "as-is"'
    if name == "reorient":
        return f"mesh.reorient = {'true' if flag else 'false'}"
    return f'mesh.{name} = "{value}"'


def _listed(items: Sequence[Any], limit: int = MAX_LISTED) -> str:
    shown = ", ".join(map(str, items[:limit]))
    more = len(items) - limit
    return f"{shown} and {more} more" if more > 0 else shown


# ------------------------------------------------------------------------- reading


def _formats_for(p: Path) -> list[str] | None:
    """meshio's candidate formats for a file name (``.vtu``, ``.msh``, ``.vtk.gz``, ...);
    None for an extension meshio does not know."""
    import meshio

    table: dict[str, list[str]] = meshio.extension_to_filetypes
    suffixes = [s.lower() for s in p.suffixes]
    for k in range(len(suffixes)):
        ext = "".join(suffixes[k:])
        if ext in table:
            # `.msh` is Gmsh's far more often than ANSYS's: try Gmsh first.
            return sorted(table[ext], key=lambda f: f != "gmsh")
    return None


def _unknown_extension(p: Path) -> MeshReadError:
    import meshio

    known = ", ".join(sorted(meshio.extension_to_filetypes))
    ext = p.suffix or "(none)"
    return MeshReadError(f"{p}: unknown mesh file extension {ext}; meshio reads {known}")


#: What :func:`_sniff` names, in words for the notes.
_FORMAT_WORDS = {
    "gmsh": "Gmsh",
    "gmsh1": "Gmsh 1",
    "vtu": "VTU XML",
    "vtk": "legacy VTK",
    "xdmf": "XDMF",
    "obj": "Wavefront OBJ",
    "off": "OFF",
    "ply": "PLY",
    "stl": "STL",
    "medit": "Medit",
    "abaqus": "Abaqus",
}
_OBJ_KEYWORDS = {"v", "vn", "vt", "f", "o", "g", "s", "l", "mtllib", "usemtl"}


def _sniff(head: bytes) -> str | None:
    """The format of a file from its first bytes, None if unrecognised."""
    text = head.lstrip(b"\xef\xbb\xbf \t\r\n")
    if text.startswith((b"$MeshFormat", b"$Comments")):
        return "gmsh"
    if text.startswith(b"$NOD"):
        return "gmsh1"
    if text.startswith((b"<?xml", b"<VTKFile", b"<Xdmf")):
        if b"<Xdmf" in text:
            return "xdmf"
        if b"UnstructuredGrid" in text:
            return "vtu"
        return None
    if text.startswith(b"# vtk DataFile"):
        return "vtk"
    if text.startswith(b"MeshVersionFormatted"):
        return "medit"
    if text[:3] == b"ply":
        return "ply"
    if text.startswith(b"OFF"):
        return "off"
    if text.startswith(b"solid"):
        return "stl"
    upper = text[:200].upper()
    if upper.startswith((b"*HEADING", b"*NODE", b"**")):
        return "abaqus"
    words = set()
    for line in text.splitlines()[:50]:
        tok = line.split(maxsplit=1)
        if tok and not tok[0].startswith(b"#"):
            words.add(tok[0].decode("ascii", "replace"))
    if "v" in words and words <= _OBJ_KEYWORDS:
        return "obj"
    return None


class _GmshTags:
    """The physical tags of each Gmsh 4 entity, as ``{dim: {entity tag: [tags]}}``, caught
    while meshio reads the file (meshio keeps only one per entity, and fails when some
    entities have none)."""

    def __init__(self) -> None:
        self.entities: tuple[dict[int, list[int]], ...] | None = None


class _Untagged(dict):  # type: ignore[type-arg]
    """Physical tags by entity; an entity the file does not declare (meshio's own 4.1 writer
    leaves some out) has none."""

    def __missing__(self, key: Any) -> list[int]:
        return [0]


@contextlib.contextmanager
def _gmsh4_partial_tags(tags: _GmshTags) -> Iterator[None]:
    """meshio's Gmsh 4.0 and 4.1 readers build their ``gmsh:physical`` cell data from the
    element blocks whose entity has physical tags only, so a file where some entities have
    none (what Gmsh writes with ``Mesh.SaveAll = 1`` and physical groups on part of the
    model) ends with fewer tag arrays than cell blocks, and meshio refuses it ("Incompatible
    cell data"). While reading, give untagged entities the tag 0 (Gmsh's tags are positive,
    so 0 means none) and catch every entity's real tags for the groups."""
    try:
        from meshio.gmsh import _gmsh40, _gmsh41
    except ImportError:  # another meshio layout: read as meshio does
        yield
        return
    patched: list[tuple[Any, Any]] = []
    for module in (_gmsh40, _gmsh41):
        original = getattr(module, "_read_entities", None)
        if original is None:
            continue

        def read_entities(*args: Any, _original: Any = original, **kwargs: Any) -> Any:
            result = _original(*args, **kwargs)
            # 4.1 returns (physical tags, bounding entities), 4.0 the physical tags alone
            physical = result[0] if isinstance(result, tuple) and len(result) == 2 else result
            tags.entities = tuple(
                {int(t): [int(x) for x in v] for t, v in d.items()} for d in physical
            )
            padded = tuple(
                _Untagged({t: (list(v) if len(v) else [0]) for t, v in d.items()}) for d in physical
            )
            return (padded, result[1]) if physical is not result else padded

        patched.append((module, original))
        module._read_entities = read_entities
    try:
        yield
    finally:
        for module, original in patched:
            module._read_entities = original


def _gmsh_version(p: Path) -> str | None:
    """The version a Gmsh file's header gives (``"4"``, ``"4.1"``, ``"2.2"``), None if none."""
    with contextlib.suppress(OSError), p.open("rb") as f:
        lines = f.read(4096).splitlines()
        for k, line in enumerate(lines[:-1]):
            if line.strip() == b"$MeshFormat":
                fields = lines[k + 1].split()
                return fields[0].decode("ascii", "replace") if fields else None
    return None


def _read_gmsh40(p: Path, tags: _GmshTags) -> tuple[meshio.Mesh | None, str, str]:
    """A Gmsh file whose header says version "4" read as 4.0: Gmsh writes "4" for 4.0, but
    meshio takes "4" for 4.1."""
    try:
        from meshio.gmsh import _gmsh40
        from meshio.gmsh import main as gmsh_main
    except ImportError:
        return None, "", "no Gmsh 4.0 reader"
    readers = getattr(gmsh_main, "_readers", None)
    if not isinstance(readers, dict):
        return None, "", "no Gmsh 4.0 reader"
    saved = readers.get("4")
    readers["4"] = _gmsh40
    try:
        return _quiet_read(p, "gmsh", tags)
    finally:
        readers["4"] = saved


def _quiet_read(
    p: Path, fmt: str, tags: _GmshTags | None = None
) -> tuple[meshio.Mesh | None, str, str]:
    """``meshio.read`` with its prints captured: meshio prints to stdout and calls
    ``sys.exit(1)`` when a reader fails. Returns the mesh (or None), what meshio printed, and
    why it failed."""
    import meshio

    out = io.StringIO()
    guard = _gmsh4_partial_tags(tags) if tags is not None else contextlib.nullcontext()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out), guard:
            mesh = meshio.read(p, file_format=fmt)
    except KeyboardInterrupt:
        raise
    except MemoryError as e:
        # a count in the file (garbage, or a file too big for this machine) asked for more
        # memory than there is: a reason, not a MemoryError traceback
        return None, out.getvalue(), f"out of memory reading it ({e}): a count in it is too large"
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


# Gmsh element types and their node counts (the same in Gmsh 1 and 2).
_GMSH_NODES = {
    1: 2, 2: 3, 3: 4, 4: 4, 5: 8, 6: 6, 7: 5, 8: 3, 9: 6, 10: 9, 11: 10, 12: 27,
    13: 18, 14: 14, 15: 1, 16: 8, 17: 20, 18: 15, 19: 13,
}  # fmt: skip


def _gmsh1_to_gmsh22(p: Path, text: str) -> str:
    """A Gmsh 1 file (``$NOD``/``$ELM``) rewritten as the Gmsh 2.2 ASCII file it is (same
    element types and node orders; the region numbers become the physical and elementary
    tags). Raises :class:`MeshReadError` naming the line of a malformed file."""
    lines = text.splitlines()
    out = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat"]
    k = 0

    def fail(line: int, why: str) -> MeshReadError:
        return MeshReadError(f"{p}: cannot read this Gmsh 1 file: line {line + 1}: {why}")

    def count_at(i: int, what: str) -> int:
        try:
            return int(lines[i].strip())
        except (IndexError, ValueError):
            raise fail(i, f"expected the number of {what}") from None

    seen_nodes = seen_elements = False
    while k < len(lines):
        head = lines[k].strip()
        if not head:
            k += 1
            continue
        if head == "$NOD":
            n = count_at(k + 1, "nodes")
            body = lines[k + 2 : k + 2 + n]
            for j, line in enumerate(body):
                if len(line.split()) != 4:
                    raise fail(k + 2 + j, f"expected 'number x y z', got {line.strip()!r}")
            end = k + 2 + n
            if end >= len(lines) or lines[end].strip() != "$ENDNOD":
                raise fail(min(end, len(lines) - 1), f"expected $ENDNOD after {n} nodes")
            out += ["$Nodes", str(n), *body, "$EndNodes"]
            seen_nodes = True
            k = end + 1
        elif head == "$ELM":
            n = count_at(k + 1, "elements")
            conv = []
            for j in range(n):
                i = k + 2 + j
                f = lines[i].split() if i < len(lines) else []
                try:
                    num, typ, phys, elem, nn = (int(x) for x in f[:5])
                except ValueError:
                    raise fail(i, f"expected an element, got {' '.join(f)!r}") from None
                if typ not in _GMSH_NODES:
                    raise fail(i, f"element {num} has unknown type {typ}")
                if nn != _GMSH_NODES[typ] or len(f) != 5 + nn:
                    raise fail(
                        i,
                        f"element {num} of type {typ} must list {_GMSH_NODES[typ]} nodes, "
                        f"lists {len(f) - 5}",
                    )
                conv.append(f"{num} {typ} 2 {phys} {elem} {' '.join(f[5:])}")
            end = k + 2 + n
            if end >= len(lines) or lines[end].strip() != "$ENDELM":
                raise fail(min(end, len(lines) - 1), f"expected $ENDELM after {n} elements")
            out += ["$Elements", str(n), *conv, "$EndElements"]
            seen_elements = True
            k = end + 1
        elif head.startswith("$"):  # another section: skip it
            name = head[1:]
            k += 1
            while k < len(lines) and lines[k].strip().upper() != f"$END{name}".upper():
                k += 1
            k += 1
        else:
            raise fail(k, f"expected a section ($NOD, $ELM), got {head!r}")
    if not (seen_nodes and seen_elements):
        raise MeshReadError(f"{p}: cannot read this Gmsh 1 file: it lacks $NOD or $ELM")
    return "\n".join(out) + "\n"


def _read_gmsh1(p: Path, tags: _GmshTags) -> meshio.Mesh:
    text = p.read_bytes().decode("ascii", errors="replace")
    converted = _gmsh1_to_gmsh22(p, text)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d) / "converted.msh"
        tmp.write_text(converted)
        mesh, _, reason = _quiet_read(tmp, "gmsh", tags)
    if mesh is None:
        raise MeshReadError(f"{p}: cannot read this Gmsh 1 file: {reason}")
    return mesh


def _read_as(
    p: Path, fmt: str, tags: _GmshTags, notes: list[str]
) -> tuple[meshio.Mesh | None, str, str]:
    """:func:`_quiet_read` in one format, Gmsh files with the partial-tags workaround and, for
    a header saying "4", a second try as Gmsh 4.0."""
    if fmt != "gmsh":
        return _quiet_read(p, fmt)
    mesh, printed, reason = _quiet_read(p, fmt, tags)
    if mesh is None and _gmsh_version(p) == "4":
        mesh, printed, reason40 = _read_gmsh40(p, tags)
        if mesh is None:
            return None, printed, f"{reason}; as Gmsh 4.0: {reason40}"
        notes.append(f"read {p.name} as Gmsh 4.0 (its header says version 4)")
    return mesh, printed, reason


_VTU_PIECE = re.compile(rb"<Piece\b([^>]*)>")
_VTU_COUNT = re.compile(rb"""\b(NumberOf(?:Points|Cells))\s*=\s*["'](\d+)["']""")


def _vtu_without_cells(p: Path) -> MeshReadError | None:
    """The error for a VTU file whose pieces all declare no cells (meshio fails on it with
    "need at least one array to concatenate" or "Inconsistent data!"), else None. Reads the
    file's first MiB: a piece's counts are in its opening tag, before its data."""
    with p.open("rb") as f:
        head = f.read(1 << 20)
    points = cells = pieces = 0
    for m in _VTU_PIECE.finditer(head):
        counts = {k.decode(): int(v) for k, v in _VTU_COUNT.findall(m.group(1))}
        if "NumberOfCells" not in counts:
            return None
        pieces += 1
        points += counts.get("NumberOfPoints", 0)
        cells += counts["NumberOfCells"]
    if pieces == 0 or cells:
        return None
    only = "and no points" if points == 0 else f"only {points} point{'s' if points > 1 else ''}"
    return MeshReadError(f"{p}: the VTU file has no cells, {only}: there is no mesh to read")


def _read_raw(p: Path) -> tuple[meshio.Mesh, str | None, _GmshTags, list[str]]:
    """The whole file as meshio reads it, the format it was read as (None when meshio's own
    choice), the Gmsh entity tags, and notes."""
    formats = _formats_for(p)
    tags = _GmshTags()
    notes: list[str] = []
    reasons: list[str] = []
    tried: set[str] = set()
    for fmt in formats or []:
        tried.add(fmt)
        mesh, printed, reason = _read_as(p, fmt, tags, notes)
        if mesh is not None and (len(mesh.cells) or len(mesh.points)):
            if printed.strip():
                print(f"meshio: {_clean(printed)}", file=sys.stderr)
            return mesh, fmt, tags, notes
        if fmt == "vtu" and (empty := _vtu_without_cells(p)) is not None:
            raise empty
        reasons.append(f"as {fmt}: {reason or 'no points and no cells'}")
    with p.open("rb") as f:
        head = f.read(4096)
    sniffed = _sniff(head)
    if sniffed is None or sniffed in tried:
        if formats is None:
            raise _unknown_extension(p)
        raise MeshReadError(f"{p}: cannot read this file as a mesh ({'; '.join(reasons)})")
    ext = p.suffix or "(no extension)"
    why = "its extension is unknown" if formats is None else f"the {ext} reader failed"
    words = _FORMAT_WORDS.get(sniffed, sniffed)
    if sniffed == "gmsh1":
        mesh = _read_gmsh1(p, tags)
        notes.append(f"read {p.name} as a Gmsh 1 file ($NOD/$ELM), by its content ({why})")
        return mesh, "gmsh", tags, notes
    mesh, printed, reason = _read_as(p, sniffed, tags, notes)
    if mesh is None and sniffed == "vtu" and (empty := _vtu_without_cells(p)) is not None:
        raise empty
    if mesh is None:
        reasons.append(f"as {sniffed} (by its content): {reason}")
        raise MeshReadError(f"{p}: cannot read this file as a mesh ({'; '.join(reasons)})")
    notes.append(f"read {p.name} as {words} by its content ({why})")
    return mesh, sniffed, tags, notes


# ------------------------------------------------------------------------- second order

_LINEAR_CORNERS = {
    "line": 2,
    "triangle": 3,
    "quad": 4,
    "tetra": 4,
    "hexahedron": 8,
    "wedge": 6,
    "pyramid": 5,
}
_LAGRANGE_LINEAR = {
    "CURVE": "line",
    "TRIANGLE": "triangle",
    "QUADRILATERAL": "quad",
    "TETRAHEDRON": "tetra",
    "HEXAHEDRON": "hexahedron",
    "WEDGE": "wedge",
    "PYRAMID": "pyramid",
}


def linear_type(cell_type: str) -> str | None:
    """The linear cell type whose corners a higher-order meshio cell type starts with
    (``tetra10`` -> ``tetra``, ``VTK_LAGRANGE_HEXAHEDRON`` -> ``hexahedron``); None for a
    linear or unknown type. meshio and VTK list the corner nodes first."""
    if cell_type.startswith("VTK_LAGRANGE_"):
        return _LAGRANGE_LINEAR.get(cell_type[len("VTK_LAGRANGE_") :])
    m = re.fullmatch(r"([a-z]+)(\d+)", cell_type)
    if m and m.group(1) in _LINEAR_CORNERS and int(m.group(2)) > _LINEAR_CORNERS[m.group(1)]:
        return m.group(1)
    return None


# ------------------------------------------------------------------------- named sets


def _gmsh_groups(
    mesh: meshio.Mesh, tags: _GmshTags
) -> dict[str, list[tuple[int, npt.NDArray[np.int64]]]]:
    """Gmsh physical groups as ``{name: [(block, cell indices), ...]}``: from every entity's
    tags (Gmsh 4) or from the per-element ``gmsh:physical`` tags (Gmsh 1 and 2)."""
    names: dict[tuple[int, int], str] = {}
    for name, value in (mesh.field_data or {}).items():
        v = np.asarray(value).ravel()
        if len(v) >= 2:
            names[(int(v[1]), int(v[0]))] = str(name)

    def name_of(dim: int, tag: int) -> str:
        return names.get((dim, tag), str(tag))

    groups: dict[str, list[tuple[int, npt.NDArray[np.int64]]]] = {}
    physical = mesh.cell_data.get("gmsh:physical")
    geometrical = mesh.cell_data.get("gmsh:geometrical")
    for b, block in enumerate(mesh.cells):
        n = len(block.data)
        dim = cell_dimension(str(block.type))
        if n == 0 or dim is None:
            continue
        if tags.entities is not None and geometrical is not None and b < len(geometrical):
            entity = int(np.asarray(geometrical[b]).ravel()[0])
            for t in tags.entities[dim].get(entity, []) if dim < len(tags.entities) else []:
                groups.setdefault(name_of(dim, t), []).append((b, np.arange(n, dtype=np.int64)))
        elif physical is not None and b < len(physical):
            per_cell = np.asarray(physical[b]).ravel().astype(np.int64)
            for t in np.unique(per_cell):
                if t > 0:
                    idx = np.flatnonzero(per_cell == t).astype(np.int64)
                    groups.setdefault(name_of(dim, int(t)), []).append((b, idx))
    return groups


def _meshio_cell_sets(mesh: meshio.Mesh) -> dict[str, list[tuple[int, npt.NDArray[np.int64]]]]:
    """meshio's cell sets (``{name: [indices per block]}``) as ``{name: [(block, cell
    indices)]}``, leaving out meshio's own Gmsh bookkeeping."""
    out: dict[str, list[tuple[int, npt.NDArray[np.int64]]]] = {}
    for name, per_block in (getattr(mesh, "cell_sets", None) or {}).items():
        if str(name).startswith("gmsh:"):
            continue
        for b, idx in enumerate(per_block):
            if idx is None or b >= len(mesh.cells):
                continue
            a = np.asarray(idx).ravel().astype(np.int64)
            if a.size:
                out.setdefault(str(name), []).append((b, a))
    return out


@dataclass
class _Sets:
    point_sets: dict[str, npt.NDArray[np.int64]] = field(default_factory=dict)
    cell_sets_kept: dict[str, npt.NDArray[np.int64]] = field(default_factory=dict)
    facet_sets: dict[str, list[tuple[str, npt.NDArray[np.int64]]]] = field(default_factory=dict)


def _named_sets(
    mesh: meshio.Mesh,
    blocks: Sequence[CellBlock],
    kept: Sequence[int],
    groups: dict[str, list[tuple[int, npt.NDArray[np.int64]]]],
) -> _Sets:
    sets = _Sets()
    first: dict[int, int] = {}
    at = 0
    for b in kept:
        first[b] = at
        at += len(blocks[b].data)
    points: dict[str, list[npt.NDArray[np.int64]]] = {}
    cells: dict[str, list[npt.NDArray[np.int64]]] = {}
    for name, members in groups.items():
        for b, idx in members:
            data = blocks[b].data
            if isinstance(data, np.ndarray) and data.ndim == 2:
                nodes = np.asarray(data[idx], dtype=np.int64)
                points.setdefault(name, []).append(nodes.ravel())
            else:
                rows = [np.asarray(data[int(i)], dtype=np.int64) for i in idx]
                nodes = np.concatenate(rows) if rows else np.zeros(0, np.int64)
                points.setdefault(name, []).append(nodes)
            if b in first:
                cells.setdefault(name, []).append(first[b] + idx)
            elif (cell_dimension(blocks[b].type) or 0) >= 1 and isinstance(data, np.ndarray):
                facets = np.asarray(data[idx], dtype=np.int64)
                sets.facet_sets.setdefault(name, []).append((blocks[b].type, facets))
    for name, value in (getattr(mesh, "point_sets", None) or {}).items():
        points.setdefault(str(name), []).append(np.asarray(value, dtype=np.int64).ravel())
    sets.point_sets = {k: np.unique(np.concatenate(v)) for k, v in points.items()}
    sets.cell_sets_kept = {k: np.unique(np.concatenate(v)) for k, v in cells.items()}
    return sets


# ------------------------------------------------------------------------- read_mesh


def read_mesh(
    path: PathLike, *, linear: bool = False, _style: str = "python"
) -> tuple[meshio.Mesh, list[DroppedBlock]]:
    """Reads a mesh file with meshio; returns a mesh holding only the cells of the highest
    dimension, and the blocks dropped.

    The file is read by its extension's readers, then, when they fail (or the extension is
    unknown), by its content (``$MeshFormat``, ``$NOD``, ``<VTKFile``, ``# vtk DataFile``,
    OBJ ``v`` lines, ...). Gmsh 1 files and Gmsh 4.1 files with physical tags on only some
    entities are read. Second-order cells are refused unless ``linear=True``, which keeps
    their corner nodes (the other nodes stay in ``points``, used by no cell).

    The returned ``meshio.Mesh`` also carries:

    - ``point_sets``: ``dict[str, ndarray (k,) int64]``, input point indices of each meshio
      point set and of each Gmsh physical group (of any dimension: every node of its
      elements);
    - ``cell_sets_kept``: ``dict[str, ndarray (k,) int64]``, indices into the kept cells
      (concatenated in order: the ``cell_id`` of the built map) of each group or cell set;
    - ``facet_sets``: ``dict[str, list[tuple[str, ndarray (k, n) int64]]]``, the
      lower-dimensional cells (boundary triangles, lines, ...) of each group or cell set, as
      (meshio cell type, input point indices);
    - ``notes``: ``list[str]``, what was done beyond a plain read.

    Gmsh groups are named by ``$PhysicalNames``; an unnamed physical tag N is named ``"N"``.

    Raises :class:`FileNotFoundError` naming the path for a file that does not exist,
    :class:`MeshReadError` (with the path and the reason) for an unreadable, truncated or
    garbage file, or one that is not a regular file (a directory, or a device or FIFO such as
    ``/dev/zero``: an endless stream), and :class:`MeshError` for a file without surface or volume
    cells or with second-order cells (without ``linear=True``; ``.option`` is then
    ``("linear", "true")``). What meshio prints while reading goes to stderr, never stdout.
    """
    import meshio

    p = Path(path)
    if not p.exists():
        raise missing_file(p)
    if p.is_dir():
        raise MeshReadError(f"{p}: is a directory, not a mesh file")
    if not p.is_file():
        # a device or FIFO (/dev/zero, a named pipe) may be an endless stream
        raise MeshReadError(
            f"{p}: not a regular file (a device, FIFO or socket); a mesh is read only from "
            "a regular file"
        )
    if not os.access(p, os.R_OK):
        raise MeshReadError(f"{p}: permission denied")
    raw, _fmt, tags, notes = _read_raw(p)
    _check_indices(p, raw)
    blocks = [_block(b) for b in raw.cells]
    groups = _gmsh_groups(raw, tags)
    for name, members in _meshio_cell_sets(raw).items():
        # meshio's Gmsh 4 reader makes cell sets of the named physical groups: same cells.
        if name not in groups:
            groups[name] = members
    try:
        kept, dropped = _select(blocks)
    except MeshError as e:
        # the file it was read from, as the other read errors name it
        raise MeshError(f"{p}: {e}") from None
    blocks = _linearize(blocks, kept, linear, notes, _style)
    sets = _named_sets(raw, blocks, kept, groups)
    out = meshio.Mesh(raw.points, [(blocks[k].type, blocks[k].data) for k in kept])
    out.point_sets = sets.point_sets
    out.cell_sets_kept = sets.cell_sets_kept
    out.facet_sets = sets.facet_sets
    out.notes = notes
    return out, _merge_dropped([_dropped(blocks[k]) for k in dropped])


def _merge_dropped(dropped: Sequence[DroppedBlock]) -> list[DroppedBlock]:
    """One entry per cell type (Gmsh 4 writes a block per entity), in first-seen order."""
    counts: dict[tuple[str, int], int] = {}
    for d in dropped:
        counts[(d.type, d.dimension)] = counts.get((d.type, d.dimension), 0) + d.n_cells
    return [DroppedBlock(t, n, dim) for (t, dim), n in counts.items()]


def _linearize(
    blocks: list[CellBlock], kept: Sequence[int], linear: bool, notes: list[str], style: str
) -> list[CellBlock]:
    """The blocks with higher-order cells cut to their corners (``linear``), or the error
    naming the second-order cells among the kept ones."""
    first = 0
    found: list[str] = []
    for k in kept:
        b = blocks[k]
        if linear_type(b.type) is not None:
            n = len(b.data)
            span = f"cell {first}" if n == 1 else f"cells {first}-{first + n - 1}"
            found.append(f"{n} {b.type} ({span})")
        first += len(b.data)
    if not found:
        return blocks
    if not linear:
        hint = format_option("linear", "true", style)
        err = MeshError(
            f"the mesh has second-order cells: {_listed(found)}; topomech builds linear "
            f"cells: to keep their corner nodes and leave the other nodes out, pass {hint}"
        )
        err.option = ("linear", "true")  # type: ignore[attr-defined, unused-ignore]
        raise err
    out = list(blocks)
    corner_nodes: list[npt.NDArray[np.int64]] = []
    other_nodes: list[npt.NDArray[np.int64]] = []
    cut: list[str] = []
    for k, b in enumerate(blocks):
        lin = linear_type(b.type)
        if lin is None or not isinstance(b.data, np.ndarray) or b.data.ndim != 2:
            continue
        nc = _LINEAR_CORNERS[lin]
        data = np.asarray(b.data, dtype=np.int64)
        out[k] = CellBlock(lin, np.ascontiguousarray(data[:, :nc]))
        corner_nodes.append(data[:, :nc].ravel())
        other_nodes.append(data[:, nc:].ravel())
        if k in kept:
            cut.append(f"{len(data)} {b.type}")
    kept_corners = (
        np.unique(np.concatenate([np.asarray(out[k].data).ravel() for k in kept]))
        if kept
        else np.zeros(0, np.int64)
    )
    others = (
        np.setdiff1d(np.concatenate(other_nodes), kept_corners)
        if other_nodes
        else np.zeros(0, np.int64)
    )
    flag = format_option("linear", "true", style)
    notes.append(
        f"kept the corner nodes of {_listed(cut)} second-order cell(s) ({flag}): "
        f"{len(others)} other node(s) are used by no cell now"
    )
    return out


def _check_indices(p: Path, mesh: meshio.Mesh) -> None:
    """A truncated file can parse into cells that point past the points: say it is the file,
    not the mesh, that is broken."""
    n = len(mesh.points)
    if n == 0 and any(len(b.data) for b in mesh.cells):
        raise MeshReadError(f"{p}: cannot read this file as a mesh: it has cells but no points")
    for b in mesh.cells:
        data = b.data
        if isinstance(data, np.ndarray) and data.size and data.dtype.kind in "iu":
            if int(data.min()) < 0:
                bad = np.flatnonzero((np.atleast_2d(data) < 0).any(axis=1)).tolist()
                raise MeshReadError(
                    f"{p}: cannot read this file as a mesh: {len(bad)} {b.type} cell(s) of "
                    f"its block refer to nodes the file does not define (cells {_listed(bad)} "
                    "of the block; truncated or corrupt file?)"
                )
            hi = int(data.max())
            if hi >= n:
                raise MeshReadError(
                    f"{p}: cannot read this file as a mesh: its {b.type} cells refer to "
                    f"point {hi} but it has only {n} points (truncated or corrupt file?)"
                )


# ------------------------------------------------------------------------- building


@dataclass
class ImportedMesh:
    """A mesh file read and its map built (:func:`import_mesh`)."""

    #: The map.
    gmap: GMap
    #: The mesh read (only the kept cells, with its named sets: see :func:`read_mesh`);
    #: None for a saved G-map (``.tmg``).
    mesh: meshio.Mesh | None
    #: The lower-dimensional blocks left out.
    dropped: list[DroppedBlock]
    #: What was done, one sentence each, in the front end's spelling.
    notes: list[str]


def _supported(name: str) -> bool:
    import inspect

    try:
        return name in inspect.signature(GMap.from_mesh).parameters
    except (TypeError, ValueError):
        return False


def _check_choice(name: str, value: str, choices: Sequence[str], style: str) -> None:
    if value not in choices:
        allowed = ", ".join(format_option(name, c, style) for c in choices)
        raise ValueError(f"{format_option(name, value, style)}: expected one of {allowed}")


def build_gmap(
    mesh: meshio.Mesh,
    *,
    reorient: bool = True,
    pinched: str = "merge",
    duplicates: str = "refuse",
    _style: str = "python",
) -> GMap:
    """The map of a mesh :func:`read_mesh` returned, with the import options. A refusal
    (:class:`MeshError`) names the option that would accept the mesh in ``_style``'s
    spelling."""
    _check_choice("pinched", pinched, PINCHED, _style)
    _check_choice("duplicates", duplicates, DUPLICATES, _style)
    kwargs: dict[str, Any] = {"reorient": reorient}
    for name, value, default in (
        ("pinched", pinched, "merge"),
        ("duplicates", duplicates, "refuse"),
    ):
        if _supported(name):
            kwargs[name] = value
        elif value != default:
            raise MeshError(
                f"{format_option(name, value, _style)} is not supported by this build of the kernel"
            )
    styled = _supported("_style")
    if styled:
        kwargs["_style"] = _style
    try:
        return GMap.from_mesh(mesh.points, mesh.cells, **kwargs)
    except MeshError as e:
        if styled or _style == "python":
            raise
        # A kernel without the styled hint words it in Python: say it the user's way.
        option = getattr(e, "option", None)
        if option is None and "reorient=True" in str(e):
            option = ("reorient", "true")
        text = str(e).replace("reorient=True", format_option("reorient", "true", _style))
        err = MeshError(text)
        err.option = option  # type: ignore[attr-defined, unused-ignore]
        raise err from None


def build_notes(g: GMap, pinched_option: str = "merge") -> list[str]:
    """What building the map changed, from its :attr:`GMap.report`, one sentence each
    (``pinched_option``: the ``pinched`` option it was built with)."""
    r = g.report
    notes: list[str] = []
    reoriented = list(getattr(r, "reoriented", []))
    if reoriented:
        notes.append(
            f"reoriented {len(reoriented)} cell(s) listed with the opposite orientation "
            f"(now consistent): {_listed(reoriented)}"
        )
    if getattr(r, "non_orientable", False):
        notes.append(
            "the surface is not orientable (a Moebius strip or the like): no orientation "
            "agrees across every edge; accepted as a valid G-map (a G-map needs no "
            "orientation)"
        )
    pinched = list(getattr(r, "pinched", []))
    if pinched:
        done = (
            "split into one vertex per side"
            if pinched_option == "split"
            else "each kept as one particle"
        )
        notes.append(
            f"{len(pinched)} pinched point(s) (the cells around each meet only there, or along an "
            f"edge through it), {done}: {_listed(pinched)}"
        )
    merged = list(getattr(r, "merged_duplicates", []))
    if merged:
        pairs = [f"{a} (= {b})" for a, b in merged]
        notes.append(f"merged {len(merged)} duplicate cell(s), dropped: {_listed(pairs)}")
    unused = list(getattr(r, "unused_points", []))
    if unused:
        notes.append(
            f"{len(unused)} point(s) used by no cell left out: {_listed(unused)} (the other "
            "points keep their input order; point_id gives each vertex's input index)"
        )
    return notes


def import_mesh(
    path: PathLike,
    *,
    reorient: bool = True,
    pinched: str = "merge",
    duplicates: str = "refuse",
    linear: bool = False,
    _style: str = "python",
) -> ImportedMesh:
    """Reads a mesh file (:func:`read_mesh`) or a saved G-map (``.tmg``) and builds its map
    with the import options:

    - ``reorient`` (default True): turn cells listed with the opposite orientation over;
      False refuses them;
    - ``pinched``: ``"merge"`` (default; a point where cells touch only at it stays one
      particle), ``"split"`` (one vertex per side), ``"refuse"``;
    - ``duplicates``: ``"refuse"`` (default) or ``"merge"`` cells with the same vertices;
    - ``linear``: keep the corner nodes of second-order cells.

    The notes say what was done, in ``_style``'s spelling (``"python"``, ``"cli"`` or
    ``"scene"``). Raises :class:`FileNotFoundError` naming the path for a file that does
    not exist, :class:`MeshReadError` for a mesh file that cannot be read,
    :class:`FileFormatError` for a ``.tmg`` file that cannot be read (as
    :meth:`GMap.load`), :class:`MeshError` for a refused mesh (``.option``, when set, names
    the option that would accept it), ``ValueError`` for an unknown option value."""
    p = Path(path)
    _check_choice("pinched", pinched, PINCHED, _style)
    _check_choice("duplicates", duplicates, DUPLICATES, _style)
    if p.suffix.lower() == GMAP_SUFFIX:
        return ImportedMesh(GMap.load(p), None, [], [])
    mesh, dropped = read_mesh(p, linear=linear, _style=_style)
    g = build_gmap(mesh, reorient=reorient, pinched=pinched, duplicates=duplicates, _style=_style)
    notes = list(getattr(mesh, "notes", []))
    if dropped:
        what = ", ".join(map(str, dropped))
        notes.append(f"dropped {what}: lower-dimensional than the {g.dimension}D cells")
    return ImportedMesh(g, mesh, dropped, notes + build_notes(g, pinched))


def read_gmap(
    path: PathLike,
    reorient: bool = True,
    *,
    pinched: str = "merge",
    duplicates: str = "refuse",
    linear: bool = False,
) -> tuple[GMap, list[DroppedBlock]]:
    """A G-map from a file: a saved map (``.tmg``) or any mesh file meshio reads, built with
    the import options of :func:`import_mesh` (errors as there: :class:`FileNotFoundError`
    for a file that does not exist)."""
    m = import_mesh(path, reorient=reorient, pinched=pinched, duplicates=duplicates, linear=linear)
    return m.gmap, m.dropped


def write_vtu(gmap: GMap, path: PathLike) -> None:
    """Writes the map's points and cells to a VTU file.

    A volume map whose volumes are not all tetrahedra, hexahedra, wedges and pyramids (general
    polyhedra after a rewrite such as ``split_edge``) is written with every volume as a VTK
    polyhedron (cell type 42, ``VTK_POLYHEDRON``: its faces as point cycles, their normals
    pointing out by the right-hand rule), since a VTU file cannot mix polyhedra with other
    cells (meshio's limit); ParaView and VTK read them. Reading such a file back into a map is
    not supported (save a ``.tmg`` for that). Raises :class:`topomech.MeshError` when the
    cells cannot be listed (an open or non-orientable volume, an open face)."""
    import meshio

    try:
        mesh = gmap.to_meshio()
    except MeshError:
        if gmap.dimension != 3:
            raise
        mesh = polyhedra_meshio(gmap)
    meshio.write(os.fspath(path), mesh, file_format="vtu")


def polyhedra_meshio(gmap: GMap) -> meshio.Mesh:
    """The map's volumes, every one as a general polyhedron, as a ``meshio.Mesh`` (cell blocks
    ``polyhedron<n>``, ``n`` the number of points of the cell, in the map's volume order; each
    cell a list of faces, each face an ``int64`` array of point indices, oriented outward).
    Raises :class:`topomech.MeshError` for a map that is not 3D or an open or non-orientable
    volume."""
    import meshio

    points, cell_offsets, face_offsets, connectivity = gmap.core.to_polyhedra()
    faces = [
        connectivity[face_offsets[f] : face_offsets[f + 1]] for f in range(len(face_offsets) - 1)
    ]
    blocks: list[tuple[str, list[list[npt.NDArray[np.int64]]]]] = []
    for c in range(len(cell_offsets) - 1):
        cell = faces[cell_offsets[c] : cell_offsets[c + 1]]
        kind = f"polyhedron{len(np.unique(np.concatenate(cell)))}"
        if blocks and blocks[-1][0] == kind:
            blocks[-1][1].append(cell)
        else:
            blocks.append((kind, [cell]))
    return meshio.Mesh(points, blocks)


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
    as a mesh file in the format of the extension (``.vtu``, ``.vtk``, ``.msh``, ...); a
    ``.vtu`` also takes volumes of no cell kind (general polyhedra after a rewrite), every
    volume then a VTK polyhedron (see :func:`write_vtu`). Raises ``ValueError`` when the
    extension names no format or the format cannot hold the map's cells (Gmsh has no
    polygons and takes one cell kind per file, say; STL keeps triangles only and OFF and
    Medit skip polygons, which the file read back shows; a writer needs a package that is
    not installed), :class:`topomech.MeshError` naming the file and the volume when a
    volume is of no cell kind and the format is not VTU, or when the cells cannot be listed
    (an open volume); nothing is left written then."""
    fmt = write_format(path)
    if fmt == "tmg":
        gmap.save(path)
        return
    try:
        _write_cells(gmap, path, fmt)
    except MeshError as e:
        # the map's cells could not be listed (extracted before anything is written): a
        # map whose volumes a rewrite made general polyhedra has none other mesh files hold
        # (a .vtu holds them, see write_vtu)
        instead = "a .tmg (topomech's own format)" if fmt == "vtu" else "a .vtu or a .tmg"
        raise MeshError(
            f"{path}: {e}; {MESH_FILE_CELLS}: write the map as {instead} instead"
        ) from None


def _write_cells(gmap: GMap, path: PathLike, fmt: str) -> None:
    """:func:`write_gmap` for a mesh file of format ``fmt``."""
    if fmt == "vtu":
        write_vtu(gmap, path)
    else:
        import meshio

        mesh = gmap.to_meshio()
        kinds = {b.type for b in mesh.cells}
        if fmt.startswith("gmsh") and len(kinds) > 1:
            # meshio's Gmsh writers need an entity per cell block (gmsh:dim_tags), which a
            # map does not have: its message was about that input (QA)
            raise _unwritable(
                path,
                mesh,
                lambda k: f"meshio writes one cell kind per Gmsh file, and the map has {k}",
            )
        try:
            meshio.write(os.fspath(path), mesh, file_format=fmt)
        except (MemoryError, KeyboardInterrupt, OSError):
            raise
        except Exception as e:  # meshio's writers raise KeyError for cells they cannot hold
            reason = f"{type(e).__name__}: {e}"
            if isinstance(e, ModuleNotFoundError):
                # a format whose writer needs a package not installed (XDMF needs h5py): not a
                # limit of the format (QA)
                reason = (
                    f"meshio's {fmt} writer needs the Python package {e.name!r}, which is not "
                    f"installed (pip install {e.name})"
                )
            raise _unwritable(
                path,
                mesh,
                lambda kinds: f"cannot write the map as {fmt} (cells: {kinds}): {reason}",
            ) from e
        _refuse_dropped_cells(path, fmt, mesh)


def _unwritable(path: PathLike, mesh: Any, why: Callable[[str], str]) -> ValueError:
    """The refusal of a mesh file meshio could not write whole: what it left at ``path`` is
    removed, and the message is ``why`` of the map's cell kinds (``"polygon, quad"``)."""
    with contextlib.suppress(OSError):
        Path(path).unlink()
    kinds = ", ".join(sorted({b.type for b in mesh.cells}))
    return ValueError(f"{path}: {why(kinds)}; write .vtu or .tmg instead")


def _refuse_dropped_cells(path: PathLike, fmt: str, mesh: Any) -> None:
    """Reads back the mesh file ``path`` that meshio wrote as ``fmt`` from ``mesh`` and, when
    it holds fewer cells (STL keeps triangles only, OFF and Medit skip polygons, each with a
    warning only), removes it and raises ``ValueError``: a written file silently missing
    cells is lost data. A file meshio cannot read back is left as written."""
    import meshio

    written = sum(len(b.data) for b in mesh.cells)
    try:
        # (meshio's STL reader warns of overflows on a file it wrote without triangles)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            back = meshio.read(os.fspath(path), file_format=fmt)
    except (MemoryError, KeyboardInterrupt):
        raise
    except Exception:  # a format meshio writes but reads otherwise: no check
        return
    found = sum(len(b.data) for b in back.cells)
    if found < written:
        raise _unwritable(
            path,
            mesh,
            lambda kinds: (
                f"the {fmt} format cannot hold all of the map's cells ({kinds}): "
                f"{written} written, {found} in the file"
            ),
        )
