"""What a run keeps for looking at it: frames for the viewer and the previews, and energies.

:class:`Recorder` follows a :class:`Simulation` during :func:`topomech.run.run_scene`:

- **frames** (:meth:`Recorder.frame`): the positions, the fields (displacement magnitude,
  and von Mises stress for the continuous 3D models) and the topology they are drawn on
  (the elements as :mod:`topomech._output` writes them, vertex rows in the simulation's
  order). Positions are float32 relative to a local origin, :attr:`Recorder.origin` (the
  centre of the rest positions' bounding box, float64, recorded as ``origin`` in
  ``view.json``, with the ``bounds`` relative to it): a mesh placed far away — at 5e6 m,
  say — keeps float32's precision of its own size. A topology is recorded again only when
  the map's darts were relinked (a cut, a fracture): its surface polygons, its edges, each
  row's input point (``point_id``, shown by the viewer's picking) and, for maps of at most
  :data:`DART_LIMIT` darts, the darts themselves with their alpha links, so that the
  viewer's dart view shows links disappearing.
  The arrays go to ``view.bin`` (little-endian, 4 bytes per value) as they are recorded;
  only a few numbers per frame (its time, step, topology and offset in ``view.bin``) stay
  in memory, so a run's memory does not grow with its number of frames.
  :meth:`Recorder.write_view` completes them with ``view.json`` (the description) — see
  :func:`read_view`, which reads the arrays back one at a time.
- **energies** (:meth:`Recorder.after_step`), at every step: kinetic ``sum m |v|^2 / 2``;
  gravitational ``-sum m g . (x - X)`` (zero at the rest positions ``X``), with the
  potential ``-sum f_ext . (x - X)`` of the external loads (constant forces, like gravity:
  :meth:`Simulation.set_external_forces`) added to it; elastic, the work
  done against the models' conservative forces since the rest state: ``E(x_0)`` is the
  integral of ``-f . dx`` along the straight path from the rest positions to the initial
  ones (3-point Gauss-Legendre; zero when the run starts at rest), then every step adds
  ``-(f(x_k) + f(x_{k+1})) / 2 . (x_{k+1} - x_k)`` (the trapezoid rule: exact for forces
  linear in the positions — linear FEM, mass-tensor — and second order otherwise: with few,
  large steps far off, even below zero). The
  forces are the models' forces at zero velocity, so the dashpots of damped springs do no
  work here: what they and the viscous damping dissipate shows as the total
  ``kinetic + gravitational + elastic`` going down. Written as ``energy.csv``, a row per
  state as soon as its elastic energy is known (flushed at once: the file holds the run so
  far); :attr:`Recorder.energy` keeps only the last :data:`ENERGY_MEMORY` rows.

With ``out_dir``, :class:`Recorder` writes ``view.bin`` and ``energy.csv`` there directly;
without, it spools them to temporary files that :meth:`Recorder.write_view` and
:meth:`Recorder.write_energy` copy (in blocks) to where they are asked.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import tempfile
import weakref
from array import array
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from topomech._cells import CELL_FACES
from topomech._core import TopomechError
from topomech._output import OutputCells

if TYPE_CHECKING:
    from topomech.scene import Scene
    from topomech.simulation import Simulation

__all__ = [
    "DART_LIMIT",
    "VIEW_FORMAT",
    "Recorder",
    "ViewError",
    "read_energy",
    "read_view",
]

#: Maps with at most this many darts have their darts recorded for the dart view (28 bytes
#: a dart in view.bin, again after each topology change).
DART_LIMIT = 1_000_000
#: The ``format`` of ``view.json``.
VIEW_FORMAT = "topomech-view"
VIEW_VERSION = 2
#: The view format versions :func:`read_view` reads (1: positions absolute, no origin).
VIEW_VERSIONS = (1, 2)
#: The models whose stress is the linear-elastic one (von Mises is computed for them).
FEM_MODELS = {"linear_fem": "linear", "mass_tensor": "linear", "corotational": "corotated"}
#: ``energy.csv``'s columns.
ENERGY_COLUMNS = ("step", "time", "kinetic", "gravitational", "elastic", "total")
#: How many of the last states' energies :attr:`Recorder.energy` keeps in memory (all of them
#: are in ``energy.csv``).
ENERGY_MEMORY = 1000
#: Bytes copied at a time from a spooled file.
_BLOCK = 1 << 20

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

# Signs of the hexahedron's nodes in its reference cube (VTK order).
_HEX_SIGNS = np.array(
    [
        [-1, -1, -1],
        [1, -1, -1],
        [1, 1, -1],
        [-1, 1, -1],
        [-1, -1, 1],
        [1, -1, 1],
        [1, 1, 1],
        [-1, 1, 1],
    ],
    dtype=np.float64,
)


class ViewError(Exception):
    """A directory without readable view data (``view.json`` and ``view.bin``)."""


# ------------------------------------------------------------------------------ topology


@dataclass
class Topology:
    """What frames are drawn on, between two topology changes (its arrays are written to
    ``view.bin`` when it is recorded; only the current one keeps them in memory)."""

    step: int
    n_vertices: int
    #: The polygons drawn: the boundary faces of a volume mesh, every face of a surface.
    face_offsets: I64
    face_indices: I64
    #: Unique edges ``(E, 2)`` of the cells (the wireframe).
    edges: I64
    #: The cells (kernel kinds and vertex lists), for the stresses.
    cells: list[tuple[str, I64]]
    rest: F64
    #: Per dart (``-1`` for removed darts): vertex, alpha_0..alpha_3, face and volume ids;
    #: None for maps above :data:`DART_LIMIT`.
    darts: dict[str, I64] | None
    n_darts: int
    #: Each row's input point (``Simulation.point_ids``; -1 for a point the input did not
    #: have); None when the map has no ``point_id``.
    point_ids: I64 | None = None


@contextlib.contextmanager
def _naming(out_dir: Path | None, name: str) -> Iterator[None]:
    """Gives an OSError raised inside (a full disk: a write to an open file says no file name)
    the name of the file written, ``out_dir / name`` (or the spool's ``name``)."""
    try:
        yield
    except OSError as e:
        if e.filename is not None:
            raise
        where = os.fspath(out_dir / name) if out_dir is not None else f"{name} (spooled)"
        raise OSError(e.errno, e.strerror, where) from e


def _components(n: int, links: list[I64], live: npt.NDArray[np.bool_]) -> I64:
    """The smallest dart of each dart's orbit through ``links`` (label propagation)."""
    label = np.arange(n, dtype=np.int64)
    while True:
        new = label.copy()
        for a in links:
            new = np.minimum(new, new[a])
        new = np.where(live, new, -1)
        if np.array_equal(new, label):
            return label
        label = np.where(live, new, label)


def _dart_table(gmap: Any, dimension: int, row_of_label: I64 | None = None) -> dict[str, I64]:
    """Per dart: its vertex row (``row_of_label`` maps the map's vertex labels to the
    simulation's rows; None when they are the same), alpha links, face and volume."""
    labels = np.asarray(gmap.vertex_labels(), dtype=np.int64)
    n = len(labels)
    live = labels >= 0
    if row_of_label is not None:
        labels = np.where(live, row_of_label[np.maximum(labels, 0)], -1)
    alpha = np.tile(np.arange(n, dtype=np.int64), (4, 1))
    for i in range(dimension + 1):
        for d in np.flatnonzero(live):
            alpha[i, d] = gmap.alpha(i, int(d))
    face = _components(n, [alpha[0], alpha[1]], live)
    volume = (
        _components(n, [alpha[0], alpha[1], alpha[2]], live)
        if dimension == 3
        else np.where(live, 0, -1)
    )
    return {"vertex": labels, "alpha": alpha, "face": face, "volume": volume}


def _surface(cells: list[tuple[str, I64]], dimension: int) -> tuple[list[tuple[int, ...]], I64]:
    """The polygons to draw and the unique edges."""
    faces: list[tuple[int, ...]] = []
    edges: set[tuple[int, int]] = set()
    if dimension == 2:
        for _, c in cells:
            f = tuple(int(v) for v in c)
            faces.append(f)
    else:
        seen: dict[tuple[int, ...], int] = {}
        for kind, c in cells:
            for local in CELL_FACES.get(kind, ()):
                f = tuple(int(c[k]) for k in local)
                key = tuple(sorted(f))
                if key in seen:
                    seen[key] = -1
                else:
                    seen[key] = len(faces)
                    faces.append(f)
        faces = [f for f in faces if seen[tuple(sorted(f))] >= 0]
    for kind, c in cells:
        polys = (
            [tuple(int(v) for v in c)]
            if dimension == 2
            else [tuple(int(c[k]) for k in local) for local in CELL_FACES.get(kind, ())]
        )
        for p in polys:
            for a, b in zip(p, p[1:] + p[:1]):
                edges.add((min(a, b), max(a, b)))
    e = np.array(sorted(edges), dtype=np.int64).reshape(-1, 2)
    return faces, e


# ------------------------------------------------------------------------------ stresses


def _region_predicate(text: str) -> Any:
    """A region's ``where`` (rule-language predicate on x, y, z) as Python code, or None
    when it uses more than the arithmetic, comparisons and ``&& || !`` of the language."""
    py = text.replace("&&", " and ").replace("||", " or ")
    py = "".join(" not " if ch == "!" and nxt != "=" else ch for ch, nxt in zip(py, [*py[1:], ""]))
    py = py.replace("true", "True").replace("false", "False")
    try:
        return compile(py, "<region>", "eval")
    except SyntaxError:
        return None


_MATH = {"abs": abs, "min": min, "max": max, "sqrt": math.sqrt}


@dataclass
class _Material:
    young: float
    poisson: float
    #: ``(code, young, poisson)`` of the regions, in order (a later one wins).
    regions: list[tuple[Any, float | None, float | None]] = field(default_factory=list)

    def of(self, centroids: F64) -> tuple[F64, F64]:
        young = np.full(len(centroids), self.young)
        poisson = np.full(len(centroids), self.poisson)
        for code, e, nu in self.regions:
            if code is None or (e is None and nu is None):
                continue
            for k, (x, y, z) in enumerate(centroids):
                try:
                    hit = eval(code, {"__builtins__": {}}, {**_MATH, "x": x, "y": y, "z": z})
                except Exception:
                    hit = False
                if hit:
                    if e is not None:
                        young[k] = e
                    if nu is not None:
                        poisson[k] = nu
        return young, poisson


#: The largest float32: a recorded value beyond it is stored as infinite.
_F32_MAX = float(np.finfo(np.float32).max)


def _as_float32(a: F64) -> npt.NDArray[np.float32]:
    """``a`` as float32 for the view data, a value beyond float32's range (a displacement of
    1e300 m, the stress it gives) recorded as +-inf: non-finite, as the viewer and the
    previews take it (they leave such vertices out), instead of numpy's overflow warning."""
    a = np.asarray(a, dtype=np.float64)
    beyond = np.abs(a) > _F32_MAX  # (NaN compares False: stays NaN)
    if beyond.any():
        a = np.where(beyond, np.copysign(np.inf, a), a)
    return a.astype(np.float32)


def _von_mises(sigma: F64) -> F64:
    s = sigma
    return np.asarray(
        np.sqrt(
            0.5
            * (
                (s[:, 0, 0] - s[:, 1, 1]) ** 2
                + (s[:, 1, 1] - s[:, 2, 2]) ** 2
                + (s[:, 2, 2] - s[:, 0, 0]) ** 2
            )
            + 3.0 * (s[:, 0, 1] ** 2 + s[:, 1, 2] ** 2 + s[:, 0, 2] ** 2)
        ),
        dtype=np.float64,
    )


def element_stress(kind: str, rest: F64, x: F64, young: F64, poisson: F64, strain: str) -> F64:
    """Von Mises stress of each element of one kind (``(E, k)`` vertex rows ``rest``/``x``
    gathered as ``(E, k, 3)``), Hooke's law on the small strain: ``sym(F) - I`` for
    ``strain="linear"``, ``S - I`` with ``F = R S`` (polar decomposition) for
    ``"corotated"``; the deformation gradient ``F`` is the tetrahedron's (constant) or the
    hexahedron's at its centre."""
    if kind == "tetra":
        dm = np.transpose(rest[:, 1:] - rest[:, :1], (0, 2, 1))
        ds = np.transpose(x[:, 1:] - x[:, :1], (0, 2, 1))
    elif kind == "hexahedron":
        grad = _HEX_SIGNS / 8.0  # dN/dxi at the centre, (8, 3)
        dm = np.einsum("eai,ak->eik", rest, grad)
        ds = np.einsum("eai,ak->eik", x, grad)
    else:
        raise ValueError(kind)
    f = ds @ np.linalg.inv(dm)
    if strain == "corotated":
        u, _, vt = np.linalg.svd(f)
        flip = np.linalg.det(u @ vt) < 0
        u[flip, :, 2] *= -1
        r = u @ vt
        s = np.transpose(r, (0, 2, 1)) @ f
    else:
        s = f
    eps = 0.5 * (s + np.transpose(s, (0, 2, 1))) - np.eye(3)
    lam = young * poisson / ((1 + poisson) * (1 - 2 * poisson))
    mu = young / (2 * (1 + poisson))
    tr = np.trace(eps, axis1=1, axis2=2)
    sigma = lam[:, None, None] * tr[:, None, None] * np.eye(3) + 2 * mu[:, None, None] * eps
    return _von_mises(sigma)


# ------------------------------------------------------------------------------ energy


def _carry(old_rest: F64, old_x: F64, new_rest: F64, new_x: F64) -> I64:
    """The old vertex each vertex of a renumbered map comes from (a split vertex's copies
    keep its rest position; among old vertices sharing a rest position, the nearest)."""
    by_rest: dict[bytes, list[int]] = {}
    for i, r in enumerate(old_rest):
        by_rest.setdefault(r.tobytes(), []).append(i)
    src = np.empty(len(new_rest), dtype=np.int64)
    for j, r in enumerate(new_rest):
        cands = by_rest.get(r.tobytes())
        if not cands:
            cands = [int(np.argmin(((old_rest - r) ** 2).sum(axis=1)))]
        if len(cands) == 1:
            src[j] = cands[0]
        else:
            d = ((old_x[cands] - new_x[j]) ** 2).sum(axis=1)
            src[j] = cands[int(np.argmin(d))]
    return src


@dataclass
class _State:
    x: F64
    rest: F64
    version: int


class Recorder:
    """Frames and energies of a run (see the module docstring).

    ``out_dir``: the run's directory, where ``view.bin`` and ``energy.csv`` are written as
    frames and steps come (None: temporary files, copied by :meth:`write_view` and
    :meth:`write_energy`). Raises :class:`OSError` when they cannot be written."""

    def __init__(
        self,
        sim: Simulation,
        scene: Scene | None = None,
        *,
        energy: bool = True,
        dart_limit: int = DART_LIMIT,
        cells: OutputCells | None = None,
        out_dir: Path | None = None,
    ) -> None:
        self.sim = sim
        #: Where ``view.bin`` and ``energy.csv`` are written as the run goes (None: spooled).
        self.out_dir = Path(out_dir) if out_dir is not None else None
        #: The elements drawn (shared with the run's VTU writer).
        self.cells = cells if cells is not None else OutputCells(sim)
        #: The local origin (m, float64) the recorded float32 positions are relative to:
        #: the centre of the rest positions' bounding box.
        self.origin = np.zeros(3)
        rest = sim.rest_positions()
        finite = rest[np.isfinite(rest).all(axis=1)]
        if len(finite):
            self.origin = (finite.min(axis=0) + finite.max(axis=0)) / 2
        self.dart_limit = dart_limit
        cfg = scene.config if scene is not None else {}
        self.name = scene.name if scene is not None else "simulation"
        self.gravity = np.asarray(cfg.get("gravity", [0.0, 0.0, 0.0]), dtype=np.float64)
        models = cfg.get("models", [])
        self.damped = any(
            not isinstance(d, (list, tuple)) and float(d or 0.0) != 0.0
            for d in (m.get("damping", 0.0) for m in models)
        )
        kinds = {m["kind"] for m in models}
        self.strain: str | None = None
        if sim.dimension == 3 and kinds and kinds <= set(FEM_MODELS):
            self.strain = "corotated" if "corotational" in kinds else "linear"
        self.material = _Material(
            float(cfg.get("young", 1e6)),
            float(cfg.get("poisson", 0.3)),
            [
                (
                    _region_predicate(str(r.get("where", ""))),
                    float(r["young"]) if r.get("young") is not None else None,
                    float(r["poisson"]) if r.get("poisson") is not None else None,
                )
                for r in cfg.get("regions", [])
            ],
        )
        self.topologies: list[Topology] = []
        #: The ``view.json`` entries of :attr:`topologies` (their arrays' places in view.bin).
        self._topology_refs: list[dict[str, Any]] = []
        #: The fields recorded per frame, in their order in view.bin (after the positions).
        self.fields: tuple[str, ...] = ("displacement",)
        if self.strain is not None:
            self.fields = ("displacement", "von_mises")
        self._topo_version = -1
        # per frame, a few numbers only: the arrays are in view.bin
        self._frame_time = array("d")
        self._frame_step = array("q")
        self._frame_topology = array("q")
        self._frame_offset = array("q")
        self._frame_vertices = array("q")
        self._field_max: dict[str, float | None] = dict.fromkeys(self.fields)
        self._low: npt.NDArray[np.float32] | None = None
        self._high: npt.NDArray[np.float32] | None = None
        self._bin: IO[bytes] | None = None
        self._bin_size = 0
        # energies
        self.track_energy = energy
        #: The energies of the last :data:`ENERGY_MEMORY` states, by column (every state's
        #: are in ``energy.csv``).
        self.energy: dict[str, deque[float]] = {
            c: deque(maxlen=ENERGY_MEMORY) for c in ENERGY_COLUMNS
        }
        #: States recorded whose elastic energy is not known yet (at most two).
        self._rows: deque[list[float]] = deque()
        self._csv: IO[str] | None = None
        self._csv_writer: Any = None
        self._energy_rows = 0
        self._state: _State | None = None
        self._force: F64 | None = None
        self._elastic = 0.0
        self._masses: tuple[int, F64] | None = None
        self._pending: tuple[F64, F64, int] | None = None
        #: Whether the forces of a step are read from the kernel after it (its ``force``
        #: embedding holds those of the state before the step) instead of computed again:
        #: when they are the elastic forces (no damped model) of an integrator that computes
        #: them at the start of the step, and the vertices are never renumbered (no events,
        #: no fracture).
        self.lagged = (
            not self.damped
            and sim.integrator in ("explicit_euler", "symplectic_euler", "implicit_euler")
            and not cfg.get("events")
            and not cfg.get("fracture")
        )

    # -------------------------------------------------------------- frames

    def _bin_file(self) -> IO[bytes]:
        """``view.bin`` (or its spool), opened at the first array."""
        if self._bin is None:
            if self.out_dir is not None:
                self._bin = (self.out_dir / "view.bin").open("w+b")
            else:
                # open for the whole run (closed by close() or when the recorder is collected)
                self._bin = tempfile.TemporaryFile(prefix="topomech-view-")  # noqa: SIM115
            weakref.finalize(self, self._bin.close)
        return self._bin

    def _put(self, arrays: list[tuple[npt.NDArray[Any], str]]) -> list[dict[str, Any]]:
        """Appends arrays to view.bin (one write); their references for view.json."""
        refs, chunks = [], []
        offset = self._bin_size
        for a, dtype in arrays:
            arr = np.ascontiguousarray(a, dtype=np.dtype(dtype).newbyteorder("<"))
            refs.append({"offset": offset, "dtype": dtype, "shape": list(arr.shape)})
            chunks.append(arr.tobytes())
            offset += arr.nbytes
        with _naming(self.out_dir, "view.bin"):
            self._bin_file().write(b"".join(chunks))
        self._bin_size = offset
        return refs

    def _write_topology(self, t: Topology) -> None:
        names = list(t.darts) if t.darts is not None else []
        ids = [] if t.point_ids is None else [(t.point_ids, "i4")]
        refs = self._put(
            [(t.face_offsets, "i4"), (t.face_indices, "i4"), (t.edges, "i4")]
            + [(t.darts[k], "i4") for k in names if t.darts is not None]
            + ids
        )
        if ids:
            point_id_ref: dict[str, Any] | None = refs.pop()
        else:
            point_id_ref = None
        self._topology_refs.append(
            {
                "step": t.step,
                "vertices": t.n_vertices,
                "darts": t.n_darts,
                "face_offsets": refs[0],
                "face_indices": refs[1],
                "edges": refs[2],
                "dart_table": None if t.darts is None else dict(zip(names, refs[3:])),
                "point_id": point_id_ref,
            }
        )
        # the topology before this one is in view.bin: its arrays are not needed any more
        if self.topologies:
            old = self.topologies[-1]
            empty = np.zeros(0, dtype=np.int64)
            old.face_offsets, old.face_indices, old.edges = empty, empty, empty.reshape(0, 2)
            old.cells, old.rest, old.darts, old.point_ids = [], np.zeros((0, 3)), None, None
        self.topologies.append(t)

    def _topology(self) -> Topology:
        version = self.sim.topology_version
        if self.topologies and self._topo_version == version:
            return self.topologies[-1]
        gmap = self.sim.core.gmap()
        el = self.cells.elements()
        cells = list(zip(el.kinds, el.rows))
        faces, edges = _surface(cells, self.sim.dimension)
        f_off = np.zeros(len(faces) + 1, dtype=np.int64)
        f_off[1:] = np.cumsum([len(f) for f in faces])
        f_idx = np.array([v for f in faces for v in f], dtype=np.int64)
        n_darts = int(gmap.n_darts)
        darts = (
            _dart_table(gmap, self.sim.dimension, self._row_of_label())
            if n_darts <= self.dart_limit
            else None
        )
        try:
            point_ids: I64 | None = np.asarray(self.sim.point_ids(), dtype=np.int64)
        except TopomechError:
            point_ids = None
        topo = Topology(
            step=self.sim.steps,
            n_vertices=self.sim.n_vertices,
            face_offsets=f_off,
            face_indices=f_idx,
            edges=edges,
            cells=cells,
            rest=self.sim.rest_positions(),
            darts=darts,
            n_darts=n_darts,
            point_ids=point_ids,
        )
        self._write_topology(topo)
        self._topo_version = version
        return topo

    def _row_of_label(self) -> I64:
        """The simulation's row of each vertex label of its map (they differ when rows
        follow the input numbering): read by writing each row's index as its x coordinate,
        taking a copy of the map, and putting the positions back exactly."""
        x = self.sim.positions()
        if not np.isfinite(x).all():  # could not be put back: assume the same numbering
            return np.arange(len(x), dtype=np.int64)
        code = np.zeros_like(x)
        code[:, 0] = np.arange(len(x), dtype=np.float64)
        self.sim.set_positions(code)
        try:
            by_label = self.sim.core.gmap().positions()
        finally:
            self.sim.set_positions(x)
        return np.asarray(np.rint(by_label[:, 0]), dtype=np.int64)

    def _stress(self, topo: Topology, x: F64) -> npt.NDArray[np.float32]:
        """Von Mises per vertex: the mean of its elements'."""
        assert self.strain is not None
        total = np.zeros(len(x))
        count = np.zeros(len(x))
        for kind in ("tetra", "hexahedron"):
            rows = [c for k, c in topo.cells if k == kind]
            if not rows:
                continue
            idx = np.array(rows, dtype=np.int64)
            rest = topo.rest[idx]
            young, poisson = self.material.of(rest.mean(axis=1))
            with np.errstate(over="ignore", invalid="ignore"):
                # positions beyond the float range give an infinite or NaN stress: recorded
                # as non-finite (as those positions are)
                vm = element_stress(kind, rest, x[idx], young, poisson, self.strain)
            np.add.at(total, idx, np.repeat(vm[:, None], idx.shape[1], axis=1))
            np.add.at(count, idx, 1.0)
        return _as_float32(total / np.maximum(count, 1.0))

    @property
    def n_frames(self) -> int:
        """The number of frames recorded."""
        return len(self._frame_offset)

    def frame(self) -> None:
        """Records the current state as a frame: its arrays are appended to view.bin at once,
        a few numbers about it (time, step, topology, offset) kept in memory."""
        topo = self._topology()
        x = self.sim.positions()
        # everything is computed before anything is recorded: an interruption (Ctrl-C) in
        # between must not leave a frame without its fields (bytes written past the last
        # frame recorded are cut off by write_view)
        pos = _as_float32(x - self.origin)
        with np.errstate(over="ignore"):
            # a displacement beyond 1e154 squares to inf: recorded as inf, as in float32
            disp = np.linalg.norm(x - topo.rest, axis=1)
        values = [_as_float32(disp)]
        if "von_mises" in self.fields:
            values.append(self._stress(topo, x))
        refs = self._put([(pos, "f4")] + [(v, "f4") for v in values])
        finite = pos[np.isfinite(pos).all(axis=1)]
        if len(finite):
            low, high = finite.min(axis=0), finite.max(axis=0)
            self._low = low if self._low is None else np.minimum(self._low, low)
            self._high = high if self._high is None else np.maximum(self._high, high)
        for name, v in zip(self.fields, values):
            f = v[np.isfinite(v)]
            if len(f):
                hi, top = float(f.max()), self._field_max[name]
                self._field_max[name] = hi if top is None else max(top, hi)
        self._frame_time.append(float(self.sim.time))
        self._frame_step.append(int(self.sim.steps))
        self._frame_topology.append(len(self.topologies) - 1)
        self._frame_vertices.append(len(pos))
        self._frame_offset.append(int(refs[0]["offset"]))

    # -------------------------------------------------------------- energy

    def _external(self) -> F64:
        """The external loads ``f_ext`` (constant: their work is a potential, counted with
        gravity); zeros unless set."""
        return np.asarray(self.sim.external_forces(), dtype=np.float64)

    def _elastic_forces(self) -> F64:
        """The models' forces at the current positions and zero velocity (without the
        external loads, which the kernel's ``force`` includes)."""
        if not self.damped:
            return self.sim.forces() - self._external()
        v = self.sim.velocities()
        self.sim.set_velocities(np.zeros_like(v))
        try:
            return self.sim.forces() - self._external()
        finally:
            self.sim.set_velocities(v)

    def _mass(self) -> F64:
        version = self.sim.topology_version
        if self._masses is None or self._masses[0] != version:
            self._masses = (version, self.sim.masses())
        return self._masses[1]

    def _record_state(self, x: F64, rest: F64) -> None:
        """Kinetic and gravitational energy of the current state (its elastic energy is
        appended by :meth:`_complete`, once the force at ``x`` is known)."""
        m = self._mass()
        gravity = float(-(m[:, None] * (x - rest)).sum(axis=0) @ self.gravity)
        row = [
            float(self.sim.steps),
            float(self.sim.time),
            float(self.sim.kinetic_energy()),
            gravity - float((self._external() * (x - rest)).sum()),
        ]
        for c, v in zip(ENERGY_COLUMNS, row):
            self.energy[c].append(v)
        self._rows.append(row)

    def _energy_file(self) -> IO[str]:
        """``energy.csv`` (or its spool), opened with its header at the first row."""
        if self._csv is None:
            if self.out_dir is not None:
                fh: IO[str] = (self.out_dir / "energy.csv").open("w+", newline="", encoding="utf-8")
            else:
                fh = tempfile.TemporaryFile(  # noqa: SIM115 (open for the whole run)
                    "w+", newline="", encoding="utf-8", prefix="topomech-energy-"
                )
            weakref.finalize(self, fh.close)
            self._csv = fh
            self._csv_writer = csv.writer(fh)
            self._csv_writer.writerow(ENERGY_COLUMNS)
        return self._csv

    def _add_elastic(self, elastic: float) -> None:
        """The elastic energy of the oldest state recorded: its row is complete, written to
        energy.csv and flushed."""
        step, time, kinetic, gravitational = self._rows.popleft()
        total = kinetic + gravitational + elastic
        self.energy["elastic"].append(elastic)
        self.energy["total"].append(total)
        with _naming(self.out_dir, "energy.csv"):
            fh = self._energy_file()
            self._csv_writer.writerow(
                [
                    int(step),
                    *(repr(float(v)) for v in (time, kinetic, gravitational, elastic, total)),
                ]
            )
            fh.flush()
        self._energy_rows += 1

    def _complete(self, x: F64, rest: F64, version: int, f: F64) -> None:
        """Adds the work from the last state whose force is known to ``x`` (force ``f``)."""
        old = self._state
        assert old is not None
        assert self._force is not None
        if version == old.version:
            work = 0.5 * float(((self._force + f) * (x - old.x)).sum())
        else:  # renumbered: each new vertex's displacement from the vertex it comes from
            src = _carry(old.rest, old.x, rest, x)
            dx = x - old.x[src]
            copies = np.bincount(src, minlength=len(old.x)).astype(np.float64)
            before = (self._force[src] / copies[src][:, None] * dx).sum()
            work = 0.5 * float(before + (f * dx).sum())
        self._elastic -= work
        self._add_elastic(self._elastic)
        self._state = _State(x, rest, version)
        self._force = f

    def start(self) -> None:
        """Before the first step: the initial energies (the elastic one integrated from the
        rest positions)."""
        if not self.track_energy:
            return
        x0 = self.sim.positions()
        rest = self.sim.rest_positions()
        d = x0 - rest
        self._elastic = 0.0
        if np.any(d != 0.0):
            v0 = self.sim.velocities()
            nodes, weights = np.polynomial.legendre.leggauss(3)
            try:
                for t, w in zip((nodes + 1) / 2, weights / 2):
                    self.sim.set_positions(rest + t * d)
                    # a displacement far beyond any material's range (1e300 m) does work
                    # beyond the float range: an infinite or NaN energy, which the summary
                    # and the plots leave out
                    with np.errstate(over="ignore", invalid="ignore"):
                        work = float(w * (self._elastic_forces() * d).sum())
                    self._elastic -= work
            finally:
                self.sim.set_positions(x0)
                self.sim.set_velocities(v0)
        self._state = _State(x0, rest, self.sim.topology_version)
        self._force = self._elastic_forces()
        self._record_state(x0, rest)
        self._add_elastic(self._elastic)
        self._pending = None

    def after_step(self) -> None:
        """After each step: the energies, the elastic one by the work of the forces over the
        step (with :attr:`lagged`, that of the step before, whose end force the step just
        computed)."""
        if not self.track_energy or self._state is None:
            return
        x = self.sim.positions()
        version = self.sim.topology_version
        rest = self._state.rest if version == self._state.version else self.sim.rest_positions()
        if self.lagged:
            if self._pending is not None:
                # the step's forces were those of the state before it, at zero damping
                self._complete(*self._pending, self.sim.vertex_field("force") - self._external())
            # the row first: a pending state always has its row (an interruption between
            # the two leaves a row without a pending state, which finish drops)
            self._record_state(x, rest)
            self._pending = (x, rest, version)
        else:
            self._record_state(x, rest)
            self._complete(x, rest, version, self._elastic_forces())

    def finish(self) -> None:
        """After the last step: completes the last state's elastic energy (lagged mode), and
        forgets the rows whose elastic energy will not be known (a step interrupted while it
        was recorded)."""
        pending, self._pending = self._pending, None
        if pending is not None and self._rows:
            try:
                self._complete(*pending, self._elastic_forces())
            except TopomechError:
                self._drop_partial()
        self._drop_partial()

    def _drop_partial(self) -> None:
        """Forgets the states whose elastic energy will not be known (an interrupted step)."""
        while self._rows:
            self._rows.pop()
            for c in ("step", "time", "kinetic", "gravitational"):
                self.energy[c].pop()

    # -------------------------------------------------------------- output

    def write_energy(self, path: Path) -> bool:
        """Completes ``energy.csv`` at ``path`` (its rows are already written when ``path`` is
        ``out_dir/energy.csv``, else copied from the spool); False when no energies were
        tracked (nothing written then). States whose elastic energy is not known (an
        interrupted step) are left out."""
        self.finish()
        self._drop_partial()
        if self._csv is None or self._energy_rows == 0:
            return False
        self._csv.flush()
        _copy_to(self._csv, self.out_dir, "energy.csv", Path(path), None)
        return True

    def write_view(self, out_dir: Path, events: list[dict[str, Any]] | None = None) -> bool:
        """Completes the view data in ``out_dir``: ``view.bin`` (already written when
        ``out_dir`` is the recorder's, else copied from the spool) and ``view.json``, written
        frame by frame; False (nothing written) without frames."""
        if self.n_frames == 0 or self._bin is None:
            return False
        out_dir = Path(out_dir)
        fh = self._bin
        fh.flush()
        _copy_to(fh, self.out_dir, "view.bin", out_dir / "view.bin", self._bin_size)
        labels = {
            "displacement": ("displacement magnitude", "m"),
            "von_mises": ("von Mises stress", "Pa"),
        }
        fields_meta = {
            name: {
                "label": labels[name][0],
                "unit": labels[name][1],
                "min": 0.0,
                "max": self._field_max[name] or 0.0,
            }
            for name in self.fields
        }
        # relative to the origin, like the positions
        low = self._low if self._low is not None else np.zeros(3)
        high = self._high if self._high is not None else np.ones(3)
        up = _up_of(self.gravity)
        meta = {
            "format": VIEW_FORMAT,
            "version": VIEW_VERSION,
            "name": self.name,
            "dimension": self.sim.dimension,
            "up": [float(v) for v in up],
            "origin": [float(v) for v in self.origin],
            "bounds": {"min": [float(v) for v in low], "max": [float(v) for v in high]},
            "fields": fields_meta,
            "default_field": "von_mises" if "von_mises" in self.fields else "displacement",
            "dart_limit": self.dart_limit,
            "events": events or [],
            "topologies": self._topology_refs,
            "bin": "view.bin",
            "bin_bytes": self._bin_size,
        }
        head = json.dumps(meta)
        with (out_dir / "view.json").open("w", encoding="utf-8") as out:
            out.write(head[:-1] + ', "frames": [')
            for k in range(self.n_frames):
                out.write(", " if k else "")
                out.write(json.dumps(self._frame_entry(k)))
            out.write("]}")
        return True

    def close(self) -> None:
        """Closes view.bin and energy.csv (or their spools); :meth:`write_view` and
        :meth:`write_energy` must have been called before (they are done otherwise when
        the recorder is collected)."""
        for fh in (self._bin, self._csv):
            if fh is not None:
                fh.close()
        self._bin = self._csv = None

    def _frame_entry(self, k: int) -> dict[str, Any]:
        """Frame ``k``'s entry in view.json: its positions ``(V, 3)`` then each field
        ``(V,)``, float32, one after the other in view.bin."""
        n, offset = self._frame_vertices[k], self._frame_offset[k]
        fields = {}
        at = offset + 12 * n
        for name in self.fields:
            fields[name] = {"offset": at, "dtype": "f4", "shape": [n]}
            at += 4 * n
        return {
            "time": self._frame_time[k],
            "step": self._frame_step[k],
            "topology": self._frame_topology[k],
            "positions": {"offset": offset, "dtype": "f4", "shape": [n, 3]},
            "fields": fields,
        }


def _copy_to(fh: IO[Any], own_dir: Path | None, name: str, target: Path, size: int | None) -> None:
    """Makes ``target`` hold the recorded file ``fh`` (``own_dir/name`` when ``own_dir`` is
    set, else a spool): cut to ``size`` bytes (those of whole frames) when given, copied in
    blocks when ``target`` is another file."""
    if own_dir is not None:
        own = own_dir / name
        if size is not None and own.stat().st_size != size:
            fh.truncate(size)
            fh.seek(size)
        if target.exists() and own.samefile(target):
            return
    at = fh.tell()
    try:
        fh.seek(0)
        out: IO[Any] = (
            target.open("w", encoding="utf-8", newline="")
            if isinstance(fh, io.TextIOBase)
            else target.open("wb")
        )
        with out:
            left = size
            while left is None or left > 0:
                block = fh.read(_BLOCK if left is None else min(_BLOCK, left))
                if not block:
                    break
                out.write(block)
                if left is not None:
                    left -= len(block)
    finally:
        fh.seek(at)


# ------------------------------------------------------------------------------ reading


@dataclass
class View:
    """``view.json``, its arrays read from ``view.bin`` when asked, one at a time (a run's
    frames are never all in memory)."""

    meta: dict[str, Any]
    #: ``view.bin``.
    bin_path: Path
    directory: Path

    @property
    def data(self) -> bytes:
        """All of ``view.bin`` (for the viewer page, which inlines it)."""
        return self.bin_path.read_bytes()

    def array(self, ref: dict[str, Any]) -> npt.NDArray[Any]:
        """The array ``ref`` (``{"offset", "dtype", "shape"}`` of view.json) read from
        view.bin; raises :class:`ViewError` when the file ends before it."""
        dt = np.dtype(ref["dtype"]).newbyteorder("<")
        count = int(np.prod(ref["shape"])) if ref["shape"] else 1
        offset = int(ref["offset"])
        try:
            with self.bin_path.open("rb") as fh:
                fh.seek(offset)
                raw = fh.read(count * dt.itemsize)
        except OSError as e:
            msg = f"{self.bin_path}: cannot read the view data: {e.strerror or e}"
            raise ViewError(msg) from None
        if len(raw) != count * dt.itemsize:
            raise ViewError(
                f"{self.bin_path}: ends at byte {offset + len(raw)}, an array of view.json "
                f"ends at {offset + count * dt.itemsize} (truncated or from another run)"
            )
        return np.frombuffer(raw, dtype=dt, count=count).reshape(ref["shape"])

    @property
    def frames(self) -> list[dict[str, Any]]:
        frames: list[dict[str, Any]] = self.meta["frames"]
        return frames

    @property
    def origin(self) -> F64:
        """The local origin ``(3,)`` (m) the recorded positions are relative to (zero for
        view data of format version 1)."""
        return np.asarray(self.meta.get("origin", [0.0, 0.0, 0.0]), dtype=np.float64)

    def positions(self, k: int) -> npt.NDArray[np.float32]:
        """Frame ``k``'s positions ``(V, 3)`` float32, relative to :attr:`origin`."""
        return self.array(self.frames[k]["positions"])

    def world_positions(self, k: int) -> F64:
        """Frame ``k``'s positions ``(V, 3)`` in the simulation's frame (float64:
        :meth:`positions` plus :attr:`origin`)."""
        return np.asarray(self.positions(k), dtype=np.float64) + self.origin

    def field(self, k: int, name: str) -> npt.NDArray[np.float32]:
        return self.array(self.frames[k]["fields"][name])

    def topology(self, k: int) -> dict[str, Any]:
        t: dict[str, Any] = self.meta["topologies"][self.frames[k]["topology"]]
        return t

    def faces(self, k: int) -> list[npt.NDArray[np.int32]]:
        t = self.topology(k)
        off = self.array(t["face_offsets"])
        idx = self.array(t["face_indices"])
        return [idx[off[i] : off[i + 1]] for i in range(len(off) - 1)]


def read_view(out_dir: Path) -> View:
    """The view data of a run directory; raises :class:`ViewError` saying what is wrong."""
    out_dir = Path(out_dir)
    if not out_dir.exists():
        raise ViewError(f"{out_dir}: no such directory")
    if not out_dir.is_dir():
        raise ViewError(f"{out_dir}: not a directory")
    jpath = out_dir / "view.json"
    if not jpath.is_file():
        if (out_dir / "summary.json").is_file():
            raise ViewError(
                f"{out_dir}: the run wrote no frames to view (no view.json: output.every = 0, "
                "or a run by an older topomech); run it again with frames"
            )
        raise ViewError(
            f"{out_dir}: not a run directory (no view.json); write one with "
            "`topomech run SCENE --out DIR`"
        )
    try:
        meta = json.loads(jpath.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ViewError(f"{jpath}: cannot read the view description: {e}") from None
    if not isinstance(meta, dict) or meta.get("format") != VIEW_FORMAT:
        raise ViewError(f"{jpath}: not a topomech view description")
    if meta.get("version") not in VIEW_VERSIONS:
        raise ViewError(
            f"{jpath}: view format version {meta.get('version')!r}, this topomech reads "
            f"{' and '.join(map(str, VIEW_VERSIONS))}"
        )
    bpath = out_dir / str(meta.get("bin", "view.bin"))
    try:
        with bpath.open("rb") as fh:
            size = os.fstat(fh.fileno()).st_size
    except OSError as e:
        raise ViewError(f"{bpath}: cannot read the view data: {e.strerror or e}") from None
    if size != meta.get("bin_bytes"):
        raise ViewError(
            f"{bpath}: {size} bytes, view.json expects {meta.get('bin_bytes')} "
            "(truncated or from another run)"
        )
    if not meta.get("frames"):
        raise ViewError(f"{jpath}: no frames")
    return View(meta, bpath, out_dir)


def read_energy(path: Path) -> dict[str, F64]:
    """``energy.csv`` as columns."""
    with Path(path).open(encoding="utf-8", newline="") as fh:
        rows = list(csv.reader(fh))
    header, body = rows[0], rows[1:]
    cols = np.array(body, dtype=np.float64).reshape(len(body), len(header))
    return {h: cols[:, i] for i, h in enumerate(header)}


def _up_of(gravity: Any) -> np.ndarray:
    """The viewer's up direction, shape (3,): the unit vector opposite to ``gravity`` (any
    finite length: ``math.hypot`` does not overflow where the squares would), or +y for
    zero or non-finite gravity."""
    g = np.asarray(gravity, dtype=float).reshape(3)
    n = math.hypot(*(float(v) for v in g))
    if n == 0.0 or not math.isfinite(n):
        return np.array([0.0, 1.0, 0.0])
    return -g / n
