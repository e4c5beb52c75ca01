"""The ``[mesh]`` table (:class:`MeshSpec`: a mesh file with its import options, or a
generator) and reading the mesh a scene names: the file imported, or the mesh generated.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from topomech import _core
from topomech._core import FileFormatError, MeshError, MeshReadError
from topomech._gmap import GMap
from topomech.scene._table import _Fail, _or, _show, _Table

if TYPE_CHECKING:
    import meshio

    from topomech.io import ImportedMesh


#: The box generator's elements: scene name -> kernel name.
BOX_ELEMENTS = {
    "tet": "tetra",
    "tetra": "tetra",
    "hex": "hexahedron",
    "hexahedron": "hexahedron",
    "wedge": "wedge",
    "pyramid": "pyramid",
    "mixed": "mixed",
}
#: The grid generator's elements: scene name -> kernel name.
GRID_ELEMENTS = {
    "tri": "triangle",
    "triangle": "triangle",
    "quad": "quad",
    "mixed": "mixed",
}
GENERATORS = ("box", "grid", "rectangle")


@dataclass(frozen=True)
class MeshSpec:
    """The ``[mesh]`` table: a file, or a generator with its element, size and cells."""

    #: The mesh file (absolute, or relative to the working directory).
    file: Path | None = None
    #: ``box``, ``grid`` or ``rectangle``.
    generator: str | None = None
    #: The generator's element, as the kernel names it (``tetra``, ``triangle``, ...).
    element: str | None = None
    size: tuple[float, ...] = ()
    cells: tuple[int, ...] = ()
    #: ``mesh.reorient``: turn the cells of a mesh file listed with the opposite orientation
    #: over, so that all agree (default); false refuses them.
    reorient: bool = True
    #: ``mesh.pinched``: a point where cells touch only at it: ``"merge"`` (default: one
    #: particle), ``"split"`` (one vertex per side) or ``"refuse"``.
    pinched: str = "merge"
    #: ``mesh.duplicates``: cells listed twice: ``"refuse"`` (default) or ``"merge"``.
    duplicates: str = "refuse"
    #: ``mesh.order``: ``"as-is"`` (default: second-order cells are refused) or ``"linear"``
    #: (their corner nodes are kept, the other nodes left out).
    order: str = "as-is"

    @property
    def linear(self) -> bool:
        """Whether second-order cells keep their corner nodes (``mesh.order = "linear"``)."""
        return self.order == "linear"

    @property
    def dimension(self) -> int | None:
        """3 for a box, 2 for a grid, None for a file (known once read)."""
        if self.generator is None:
            return None
        return 3 if self.generator == "box" else 2


#: How many violated invariants a refused saved map lists.
MAX_VIOLATIONS_LISTED = 20


def _check_saved_map(g: GMap, path: Path, fail: _Fail) -> None:
    """Refuses a saved map (``.tmg``) that breaks a G-map invariant, listing the violations
    (as ``topomech info`` does), naming ``mesh.file``."""
    violations = g.violations()
    if not violations:
        return
    shown = "\n  ".join(violations[:MAX_VIOLATIONS_LISTED])
    more = len(violations) - MAX_VIOLATIONS_LISTED
    tail = f"\n  ... and {more} more" if more > 0 else ""
    what = f"{path} is not a valid G-map: it breaks {len(violations)} invariant(s)"
    raise fail("mesh.file", f"{what}:\n  {shown}{tail}")


#: The scene key of each import option (a kernel refusal names the one that would accept).
_MESH_OPTION_KEYS = {
    "reorient": "mesh.reorient",
    "pinched": "mesh.pinched",
    "duplicates": "mesh.duplicates",
    "linear": "mesh.order",
}


def _mesh(t: _Table, base: Path | None, fail: _Fail) -> MeshSpec:
    from topomech.io import DUPLICATES, ORDERS, PINCHED

    file = t.string("file")
    generator = t.string("generator")
    if file is not None and generator is not None:
        raise fail(t.key("generator"), "give either mesh.file or mesh.generator, not both")
    if file is None and generator is None:
        raise fail("mesh", "give mesh.file (a mesh file) or mesh.generator (box, grid)")
    if file is not None and not file.strip():
        raise fail(t.key("file"), "empty: give the mesh file's path")
    reorient_v = t._get("reorient")
    if reorient_v is not None and not isinstance(reorient_v, bool):
        raise fail(t.key("reorient"), f"expected true or false, got {_show(reorient_v)}")
    if file is not None:
        pinched = t.choice("pinched", PINCHED, PINCHED[0])
        duplicates = t.choice("duplicates", DUPLICATES, DUPLICATES[0])
        order = t.choice("order", ORDERS, ORDERS[0])
        t.done()
        p = Path(file).expanduser()
        if not p.is_absolute() and base is not None:
            p = base / p
        return MeshSpec(
            file=p,
            reorient=True if reorient_v is None else reorient_v,
            pinched=pinched,
            duplicates=duplicates,
            order=order,
        )
    for k in ("reorient", "pinched", "duplicates", "order"):
        if t._get(k) is not None:
            raise fail(t.key(k), "only for a mesh file (mesh.file)")
    if generator not in GENERATORS:
        raise fail(
            t.key("generator"), f"unknown generator {_show(generator)} (expected {_or(GENERATORS)})"
        )
    if generator == "box":
        elements, n, default_element = BOX_ELEMENTS, 3, "tet"
    else:
        elements, n, default_element = GRID_ELEMENTS, 2, "quad"
    element = t.choice("element", list(elements), default_element)
    size = t.vector("size", n, (1.0,) * n, positive=True)
    cells = t.int_vector("cells", n, (1,) * n)
    t.done()
    return MeshSpec(generator=generator, element=elements[element], size=size, cells=cells)


def _load_mesh(m: MeshSpec, fail: _Fail, read: dict[str, Any]) -> ImportedMesh:
    """The mesh ``m`` names, imported with its options (a file) or generated; see
    :meth:`Scene.load_mesh`. The meshio mesh of a file is kept in ``read["mesh"]``."""
    from topomech.io import ImportedMesh, import_mesh

    if m.file is not None:
        if not m.file.exists():
            raise fail("mesh.file", f"no such file: {m.file}")
        try:
            imported = import_mesh(
                m.file,
                reorient=m.reorient,
                pinched=m.pinched,
                duplicates=m.duplicates,
                linear=m.order == "linear",
                _style="scene",
            )
        except (MeshReadError, MeshError, FileFormatError) as e:
            option = getattr(e, "option", None)
            key = _MESH_OPTION_KEYS.get(option[0], "mesh.file") if option else "mesh.file"
            raise fail(key, str(e)) from e
        if imported.mesh is None:
            # a saved map (.tmg) is taken as written: refuse one that is not a G-map
            _check_saved_map(imported.gmap, m.file, fail)
        else:
            read["mesh"] = imported.mesh
        for note in imported.notes:
            print(f"topomech: note: {m.file.name}: {note}", file=sys.stderr)
        return imported
    try:
        if m.generator == "box":
            (nx, ny, nz), (sx, sy, sz) = m.cells, m.size
            flat = _core.box(nx, ny, nz, sx, sy, sz, m.element or "tetra")
        else:
            (nx, ny), (sx, sy) = m.cells, m.size
            flat = _core.grid(nx, ny, sx, sy, m.element or "quad")
        return ImportedMesh(GMap.from_flat(*flat), None, [], [])
    except (ValueError, MeshError) as e:
        raise fail("mesh", str(e)) from e


def _file_mesh(m: MeshSpec, fail: _Fail, read: dict[str, Any]) -> meshio.Mesh:
    """The mesh file ``m`` names, as read (once: kept in ``read["mesh"]``); see
    :meth:`Scene.file_mesh`."""
    from topomech.io import GMAP_SUFFIX, read_mesh

    if m.file is None or m.file.suffix.lower() == GMAP_SUFFIX:
        raise ValueError("the scene's mesh is not read from a mesh file")
    cached = read.get("mesh")
    if cached is not None:
        return cached
    kwargs: dict[str, Any] = {}
    if m.linear:
        kwargs["linear"] = True
    try:
        mesh, _ = read_mesh(m.file, **kwargs)
    except (MeshReadError, MeshError, OSError) as e:
        raise fail("mesh.file", str(e)) from e
    read["mesh"] = mesh
    return mesh
