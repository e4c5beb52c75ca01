"""``topomech.GMap``: the kernel's G-map with mesh conversions (numpy and meshio)."""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple, TypedDict, Union

import numpy as np
import numpy.typing as npt

from topomech import _core
from topomech._cells import (
    FlatMesh,
    cell_dimension,
    embedding_name,
    flat_to_blocks,
    real_array,
    to_flat,
)
from topomech._core import FileFormatError, MeshError, TopologyError

if TYPE_CHECKING:
    import meshio

__all__ = [
    "BuildReport",
    "CellCounts",
    "EmbeddingSpec",
    "EmbeddingValues",
    "GMap",
    "format_option",
]

PathLike = Union[str, "os.PathLike[str]"]


class CellCounts(TypedDict):
    """What :meth:`GMap.cell_counts` returns."""

    darts: int
    vertices: int
    edges: int
    faces: int
    volumes: int
    components: int
    boundary: int


class EmbeddingValues(NamedTuple):
    """An embedding read one row per orbit (:meth:`GMap.embedding`,
    :meth:`Simulation.embedding <topomech.Simulation.embedding>`)."""

    #: One row per orbit: shape ``(n,)`` float64 / int64 / bool for ``f64`` / ``i64`` /
    #: ``bool``, ``(n, 2)`` / ``(n, 3)`` float64 for ``vec2`` / ``vec3``, ``(n, R, C)`` float64
    #: for a matrix ``matRxC`` (``mat3`` is ``(n, 3, 3)``).
    values: npt.NDArray[Any]
    #: int64 ``(n,)``: the smallest dart id of each orbit, increasing; row k is the orbit of
    #: ``darts[k]`` (``GMap.orbit(darts[k], orbit)`` lists its darts).
    darts: npt.NDArray[np.int64]
    #: The orbit type as written, e.g. ``"<1,2,3>"`` (a vertex of a 3-map).
    orbit: str


class EmbeddingSpec(NamedTuple):
    """An embedding's declaration (:meth:`GMap.embeddings`)."""

    #: Its name.
    name: str
    #: Its value type: ``f64``, ``i64``, ``bool``, ``vec2``, ``vec3``, ``matN`` or ``matRxC``.
    type: str
    #: The orbit type its values live on, e.g. ``"<1,2,3>"``.
    orbit: str
    #: Whether it is derived (an aggregate of another embedding, recomputed, never written).
    derived: bool


def as_embedding_array(spec: EmbeddingSpec | None, values: Any) -> npt.NDArray[Any]:
    """``values`` as an array of the dtype the embedding ``spec`` holds, converting only
    where nothing is lost or reinterpreted: integers and floats to float64 for real types,
    integers to int64 for ``i64``. Anything else is passed on unchanged for the kernel to
    refuse by name (a float array for an ``i64`` embedding, numbers for a ``bool`` one).
    Without a spec (an unknown name) an empty array: the kernel refuses the name before
    reading values. Raises ValueError, naming the embedding, for values numpy cannot make
    an array of (rows of different lengths)."""
    if spec is None:
        return np.empty(0)
    type_ = spec.type
    try:
        a = np.asarray(values)
    except (ValueError, TypeError) as e:
        raise ValueError(
            f"values for {spec.name!r} ({type_} on {spec.orbit}) are not an array of one row "
            f"per orbit, all of one shape: {e}"
        ) from None
    if type_ == "bool":
        return a
    if type_ == "i64":
        if a.dtype.kind in "iu" and np.can_cast(a.dtype, np.int64, "safe"):
            return a.astype(np.int64)
        return a
    if a.dtype.kind in "iuf":
        return a.astype(np.float64)
    return a


@dataclass(frozen=True)
class BuildReport:
    """What building a map changed or noticed (input cell and point indices)."""

    #: Cells whose vertex order was reversed (with ``reorient=True``, the default).
    reoriented: list[int] = field(default_factory=list)
    #: Points used by no cell: they are not in the map.
    unused_points: list[int] = field(default_factory=list)
    #: Pinched points: their cells touch only at them (one particle with
    #: ``pinched="merge"``, one per side with ``pinched="split"``).
    pinched: list[int] = field(default_factory=list)
    #: ``(dropped cell, kept cell)`` for each duplicate dropped with ``duplicates="merge"``.
    merged_duplicates: list[tuple[int, int]] = field(default_factory=list)
    #: A surface with a component that cannot be oriented (a Moebius strip), accepted.
    non_orientable: bool = False


#: How each caller spells an option: ``python`` keywords, ``cli`` flags, ``scene`` keys.
STYLES = ("python", "cli", "scene")


def format_option(name: str, value: str, style: str) -> str:
    """The user's spelling of build option ``name`` set to ``value`` (as in
    ``MeshError.option``): ``style`` is ``"python"`` (``pinched="split"``, ``reorient=True``,
    ``linear=True``), ``"cli"`` (``--pinched split``, ``--reorient``, ``--linear``) or
    ``"scene"`` (``mesh.pinched = "split"``, ``mesh.reorient = true``,
    ``mesh.order = "linear"``). Raises ``ValueError`` for another style."""
    flag = value in ("true", "false")
    if style == "python":
        if flag:
            return f"{name}={value.capitalize()}"
        return f'{name}="{value}"'
    if style == "cli":
        option = "--" + name.replace("_", "-")
        if flag:
            return option if value == "true" else "--no-" + name.replace("_", "-")
        return f"{option} {value}"
    if style == "scene":
        if name == "linear":
            return 'mesh.order = "linear"' if value == "true" else 'mesh.order = "keep"'
        if flag:
            return f"mesh.{name} = {value}"
        return f'mesh.{name} = "{value}"'
    raise ValueError(f"style must be one of {', '.join(STYLES)}, got {style!r}")


def _with_hint(e: MeshError, style: str) -> MeshError:
    """``e`` with the option that would accept the mesh appended in ``style``."""
    option = getattr(e, "option", None)
    if option is None:
        return e
    verb = {"python": "pass", "cli": "use", "scene": "set"}[style]
    err = MeshError(f"{e}; to accept it {verb} {format_option(option[0], option[1], style)}")
    err.option = option
    return err


class GMap:
    """A generalized map of dimension 2 (a surface) or 3 (a volume).

    Build one from a mesh with :meth:`from_mesh` or :meth:`from_meshio`, or load a ``.tmg``
    file with :meth:`load`. The kernel object is :attr:`core`; this class adds the mesh
    conversions and delegates the rest.

    >>> g = GMap.from_mesh([[0, 0], [1, 0], [0, 1]], [("triangle", [[0, 1, 2]])])
    >>> g.cell_counts()["edges"]
    3
    """

    __slots__ = ("_core", "report")

    def __init__(self, core: _core.GMap, report: BuildReport | None = None) -> None:
        if not isinstance(core, _core.GMap):
            raise TypeError(
                "GMap wraps a topomech._core.GMap; build one with GMap.from_mesh, "
                "GMap.from_meshio or GMap.load"
            )
        self._core = core
        #: What building the map changed or noticed (empty for a loaded map).
        self.report = report if report is not None else BuildReport()

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_flat(
        cls,
        points: Any,
        kinds: list[str],
        offsets: Any,
        connectivity: Any,
        reorient: bool = True,
        *,
        pinched: str = "merge",
        duplicates: str = "refuse",
    ) -> GMap:
        """From the kernel's flat layout (see :mod:`topomech._cells`); options as
        :meth:`from_mesh`."""
        if not isinstance(reorient, (bool, np.bool_)):
            raise TypeError(
                f"reorient must be True or False, got {reorient!r} ({type(reorient).__name__})"
            )
        core, report = _core.GMap.from_flat(
            real_array(points, "points"),
            list(kinds),
            np.ascontiguousarray(offsets, dtype=np.int64),
            np.ascontiguousarray(connectivity, dtype=np.int64),
            reorient,
            pinched,
            duplicates,
        )
        return cls(
            core,
            BuildReport(
                reoriented=list(report["reoriented"]),
                unused_points=list(report["unused_points"]),
                pinched=list(report["pinched"]),
                merged_duplicates=[(int(a), int(b)) for a, b in report["merged_duplicates"]],
                non_orientable=bool(report["non_orientable"]),
            ),
        )

    @classmethod
    def from_mesh(
        cls,
        points: Any,
        cells: Any,
        reorient: bool = True,
        *,
        pinched: str = "merge",
        duplicates: str = "refuse",
        kind: str | None = None,
        _style: str = "python",
    ) -> GMap:
        """From points ``(N, 2)`` or ``(N, 3)`` and cells.

        ``cells`` is a list of ``(meshio_type, array)`` pairs or meshio ``CellBlock`` objects,
        a ``{meshio_type: array}`` dict, or one array with ``kind="tetra"`` (say). Types:
        ``triangle``, ``quad``, ``polygon`` (a list of vertex lists), ``tetra``, ``hexahedron``,
        ``wedge``, ``pyramid``, with VTK's vertex order. Cells are numbered in the order given
        (the ``cell_id`` of the map's elements); points keep their indices (``point_id``).

        Options:

        - ``reorient`` (default ``True``): cells listed with the opposite orientation are
          turned and listed in :attr:`report` ``.reoriented``; with ``False`` they are refused.
        - ``pinched``: points where cells touch only at a point are one particle
          (``"merge"``, default), one particle per side (``"split"``), or refused
          (``"refuse"``); listed in ``report.pinched``.
        - ``duplicates``: cells with the same points as an earlier cell are refused
          (``"refuse"``, default) or dropped (``"merge"``, listed in
          ``report.merged_duplicates``).

        Raises :class:`MeshError` naming every offending cell or point (degenerate, twisted,
        folded, duplicate, overlapping cells, non-conforming interfaces, ...); when an option
        would accept the mesh the message says which and ``MeshError.option`` holds
        ``(name, value)``.
        Raises ``ValueError`` for an unknown ``pinched`` or ``duplicates`` value, and
        ``TypeError`` for points that are not real numbers (booleans, strings, complex
        values, dates; ``ValueError`` for a masked array with masked entries).
        """
        flat = to_flat(points, cells, kind)
        # points in a plane pad to z = 0: every volume cell would be flat (refused as
        # degenerate, cell by cell); say what is wrong instead
        shape = np.shape(points)
        if len(shape) == 2 and shape[1] == 2:
            volumes = sorted({k for k in flat.kinds if cell_dimension(k) == 3})
            if volumes:
                raise MeshError(
                    f"{', '.join(volumes)} cells need points with 3 coordinates; these have 2 "
                    f"(points of shape {shape}): a volume of points in a plane is flat"
                )
        try:
            return cls.from_flat(*flat, reorient=reorient, pinched=pinched, duplicates=duplicates)
        except MeshError as e:
            raise _with_hint(e, _style) from None

    @classmethod
    def from_meshio(
        cls,
        mesh: meshio.Mesh,
        reorient: bool = True,
        *,
        pinched: str = "merge",
        duplicates: str = "refuse",
        linear: bool = False,
        _style: str = "python",
    ) -> GMap:
        """From a ``meshio.Mesh``, keeping the cells of the highest dimension (the lower
        dimensional ones, such as the boundary triangles Gmsh writes beside tetrahedra, are
        dropped with a warning naming them). Second-order cells (``tetra10``, ``triangle6``,
        ...) are refused (:class:`MeshError` naming them and ``linear=True``) unless
        ``linear=True``, which keeps their corner nodes (a warning says how many). Other
        options and errors as :meth:`from_mesh`."""
        from topomech.io import _linearize, select_cells

        if not isinstance(linear, (bool, np.bool_)):
            raise TypeError(f"linear must be True or False, got {linear!r}")
        kept, dropped = select_cells(mesh.cells)
        if dropped:
            what = ", ".join(map(str, dropped))
            warnings.warn(f"dropped {what}: lower-dimensional cells", stacklevel=2)
        notes: list[str] = []
        kept = _linearize(list(kept), range(len(kept)), bool(linear), notes, _style)
        for note in notes:
            warnings.warn(note, stacklevel=2)
        return cls.from_mesh(
            mesh.points,
            kept,
            reorient,
            pinched=pinched,
            duplicates=duplicates,
            _style=_style,
        )

    @classmethod
    def load(cls, path: PathLike) -> GMap:
        """A map saved by :meth:`save` (a ``.tmg`` file). The map is taken as written: check
        :meth:`violations` before trusting one from elsewhere.

        Raises :class:`FileNotFoundError` naming the path for a file that does not exist, and
        :class:`FileFormatError` naming it for a file that cannot be opened or is not a
        regular file (a directory, or an endless stream such as ``/dev/zero`` or a FIFO,
        refused before reading), and for a truncated or corrupt file (as
        :meth:`from_bytes`)."""
        p = os.fspath(path)
        try:
            return cls(_core.GMap.load(p))
        except FileFormatError as e:
            if p in str(e):
                raise
            raise FileFormatError(f"{p}: {e}") from None

    @classmethod
    def from_bytes(cls, data: bytes) -> GMap:
        """A map from the bytes of a ``.tmg`` file.

        Raises :class:`FileFormatError` for bytes that are not a ``.tmg`` file, of another
        version, truncated, or corrupt (with the byte offset and what is wrong); every count
        in the file is checked against the bytes left before anything is allocated for it, so
        a short file never asks for more memory than its own size implies."""
        return cls(_core.GMap.from_bytes(bytes(data)))

    # ------------------------------------------------------------------ output

    def save(self, path: PathLike) -> None:
        """Saves the map with its embeddings to a ``.tmg`` file (round-trip exact). Raises
        :class:`FileNotFoundError` when the folder does not exist, :class:`FileFormatError`
        naming the path when the file cannot be written."""
        self._core.save(os.fspath(path))

    def to_bytes(self) -> bytes:
        """The bytes of the map's ``.tmg`` file."""
        return self._core.to_bytes()

    def to_flat(self) -> FlatMesh:
        """``(points, kinds, offsets, connectivity)``: one point per vertex, one cell per face
        (2D) or volume (3D)."""
        return FlatMesh(*self._core.to_flat())

    def to_meshio(self) -> meshio.Mesh:
        """The map as a ``meshio.Mesh`` (polygons of 3 and 4 vertices become triangles and
        quads; the cell order is kept)."""
        import meshio

        points, kinds, offsets, connectivity = self._core.to_flat()
        blocks = flat_to_blocks(kinds, offsets, connectivity)
        return meshio.Mesh(points, [(b.type, b.data) for b in blocks])

    # ------------------------------------------------------------------ queries

    @property
    def core(self) -> _core.GMap:
        """The kernel object."""
        return self._core

    @property
    def dimension(self) -> int:
        """2 (surface) or 3 (volume)."""
        return self._core.dimension

    @property
    def n_darts(self) -> int:
        """The number of darts."""
        return self._core.n_darts

    @property
    def version(self) -> int:
        """The topology version: it changes with every change of links or darts."""
        return self._core.version

    def cell_counts(self) -> CellCounts:
        """Darts, vertices, edges, faces, volumes, connected components, and boundary cells
        (faces in 3D, edges in 2D)."""
        c = self._core.cell_counts()
        return CellCounts(
            darts=c["darts"],
            vertices=c["vertices"],
            edges=c["edges"],
            faces=c["faces"],
            volumes=c["volumes"],
            components=c["components"],
            boundary=c["boundary"],
        )

    def is_valid(self) -> bool:
        """Whether every invariant of a G-map holds."""
        return self._core.is_valid()

    def violations(self) -> list[str]:
        """Each violated invariant, described."""
        return self._core.violations()

    def check(self) -> None:
        """Raises :class:`TopologyError` listing the violated invariants, if any."""
        v = self._core.violations()
        if v:
            shown = "\n  ".join(v[:20])
            more = f"\n  ... and {len(v) - 20} more" if len(v) > 20 else ""
            raise TopologyError(f"the G-map breaks {len(v)} invariant(s):\n  {shown}{more}")

    def positions(self) -> npt.NDArray[np.float64]:
        """Vertex positions ``(V, 3)``, row k for the vertex labelled k in
        :meth:`vertex_labels`. Rows follow the input point order for a map built from a mesh
        (its ``particle`` embedding; unused points left out, a pinched point kept as one
        particle is one row), else the vertex orbits by their smallest dart."""
        return self._core.positions()

    def vertex_labels(self) -> npt.NDArray[np.int64]:
        """The vertex row of each dart, int64 ``(capacity,)`` (-1 for removed darts); rows as
        in :meth:`positions`."""
        return self._core.vertex_labels()

    def alpha(self, i: int, dart: int) -> int:
        """``alpha_i(dart)`` (the dart itself when free)."""
        return self._core.alpha(i, dart)

    def orbit(self, dart: int, orbit: str) -> npt.NDArray[np.int64]:
        """The darts of the orbit of ``dart`` of type ``orbit`` (e.g. ``"<0,1>"``)."""
        return self._core.orbit(dart, orbit)

    def sew(self, i: int, a: int, b: int) -> None:
        """Sews ``a`` and ``b`` along dimension ``i``."""
        self._core.sew(i, a, b)

    def unsew(self, i: int, a: int) -> None:
        """Unsews ``a`` along dimension ``i``."""
        self._core.unsew(i, a)

    def embedding(self, name: str) -> EmbeddingValues:
        """The embedding ``name`` as numpy arrays, one row per orbit of its orbit type:
        ``(values, darts, orbit)`` (see :class:`EmbeddingValues` for the shapes and dtypes).
        Rows are the orbits in increasing order of their smallest dart, which ``darts``
        holds. Every orbit has a value: one that was never written reads 0 (or False). A
        derived embedding is recomputed first if its source changed.

        Raises :class:`KeyError` for an unknown name (the message lists the map's
        embeddings).

        >>> g = GMap.from_mesh([[0, 0], [1, 0], [0, 1]], [("triangle", [[0, 1, 2]])])
        >>> values, darts, orbit = g.embedding("position")
        >>> values.shape, darts.dtype, orbit
        ((3, 3), dtype('int64'), '<1,2>')
        """
        return EmbeddingValues(*self._core.embedding(embedding_name(name)))

    def set_embedding(self, name: str, values: Any) -> None:
        """Writes every value of the stored embedding ``name``: ``values`` has the shape and
        row order :meth:`embedding` returns (one row per orbit, by smallest dart). Integer
        and float arrays are converted to float64 for real types and integer arrays to int64
        for ``i64``; other dtypes are refused. Derived embeddings are recomputed after the
        write. Nothing is written when it raises:

        - :class:`KeyError` for an unknown name (listing the map's embeddings);
        - :class:`TypeError` for a dtype that does not fit (a float array for ``i64``);
        - :class:`ValueError` for another shape (rows of different lengths too), or a NaN or
          infinite value (naming the embedding, the first bad row and its dart), or, for
          ``particle`` (the vertex numbering), values that number no rows: a negative row, a
          row past the number of vertex orbits, an unused row below the largest, or one row
          for vertex orbits at different positions; or, for ``point_id`` and ``cell_id``
          (the input numbering, see below), a value below -1 or one point for two vertices
          of one element (naming the embedding, the value, its dart and row, and the
          element);
        - :class:`EmbeddingError` for a derived embedding (write its source).

        ``point_id`` (on vertices) and ``cell_id`` (on faces in 2D, volumes in 3D) carry the
        input mesh's numbering to the written meshes' ``point_id`` and ``cell_id`` data: each
        value is an index of the input (>= 0) or -1 for none (a vertex a rule created), and
        the vertices of one element are distinct points (-1 aside), as the cells of a mesh
        are. They are not unique: a point split into several vertices (``pinched="split"``,
        a fracture, a cut) keeps its ``point_id`` on each, and the pieces of a cell that a
        rule subdivides keep its ``cell_id``."""
        name = embedding_name(name)
        specs = {s.name: s for s in self.embeddings()}
        self._core.set_embedding(name, as_embedding_array(specs.get(name), values))

    def embeddings(self) -> list[EmbeddingSpec]:
        """Every embedding's name, type, orbit type and whether it is derived, in declaration
        order."""
        return [EmbeddingSpec(*e) for e in self._core.embeddings()]

    def embedding_names(self) -> list[str]:
        """The embeddings' names."""
        return self._core.embedding_names()

    def embedding_info(self, name: str) -> dict[str, Any]:
        """Name, type, orbit, policy and derivation of an embedding."""
        return self._core.embedding_info(name)

    def memory_bytes(self) -> int:
        """Bytes used by the topology and the embeddings."""
        return self._core.memory_bytes()

    def __repr__(self) -> str:
        return f"topomech.GMap(dimension={self.dimension}, darts={self.n_darts})"
