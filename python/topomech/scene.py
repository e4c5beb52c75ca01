"""Scenes: a simulation described in a TOML file.

A scene names a mesh (a file, or a generated box or rectangle), the models, the material,
the fixed vertices, gravity, the integrator and how often to write frames::

    name = "beam"                      # optional (default: the file name)
    description = "..."                # optional

    [mesh]
    file = "beam.msh"                  # relative to the scene file; or:
    # generator = "box", element = "tet", size = [1.0, 0.2, 0.2], cells = [10, 2, 2]
    # reorient = true                  # a file's import options: orient cells alike (default)
    # pinched = "merge"                # cells touching at a point: merge | split | refuse
    # duplicates = "refuse"            # cells listed twice: refuse | merge
    # order = "as-is"                  # as-is (second order refused) | linear (corners kept)

    [[model]]                          # one table per model, summed
    kind = "corotational"
    young = 1e6                        # young/poisson set the material's
    poisson = 0.3
    # [[model]]                        # a model from the user's rule file (relative to
    # file = "anchor.tmr"              #   the scene), name = "..." when it declares
    # k = 50.0                         #   several; its parameters as keys

    [material]
    density = 1000.0                   # per volume in 3D, per area in 2D
    damping = 0.0                      # viscous, 1/s
    [[material.region]]                # elements whose rest centroid satisfies `where`
    where = "x > 0.5"
    young = 2e6

    [[fix]]                            # vertices held in place; select them by one of:
    where = "x < 1e-9"                 # a predicate on the rest position x, y, z,
    # points = [0, 5, 7]               # input point indices (the mesh file's numbering),
    # group = "clamp"                  # a Gmsh physical group or meshio point/cell set
    # displacement = [0.0, 0.1, 0.0]   # held at this displacement instead of in place

    [[load]]                           # dead loads, integrated once over the rest shape
    kind = "traction"                  # point | traction | pressure
    traction = [0.0, -1e3, 0.0]        # Pa on faces (3D), N/m on edges (2D)
    where = "x > 1 - 1e-9"             # on the boundary faces (3D) or edges (2D) whose rest
                                       # centroid satisfies it; or points = [...] (faces
                                       # whose vertices are all these points), group = "..."
    # kind = "pressure", pressure = 1e3   # along the inward normal: force -p n dA
    # pressure = "1e4 * (0.2 - z)"     # a value may vary: an expression of the rest x, y, z
    # kind = "point", force = [0, 0, -10] # N on each selected vertex (where/points/group)

    [initial]                          # or [[initial]] tables, each with its selection
    velocity = [1.0, 0.0, 0.0]         # m/s (free vertices)
    displacement = [0.0, 0.0, 0.01]    # m, moves the positions (the rest shape stays)
    # where = "x > 0.5"                # optional selection (where/points/group): default all

    [world]
    gravity = [0.0, -9.81, 0.0]
    # ground = { point = [0.0, 0.0, -0.5], normal = [0.0, 0.0, 1.0] }   # a ground plane; the
                                       # normal (the side bodies stay on) defaults to the
                                       # opposite of gravity
    # ground = -0.5                    # or the plane at this height along that default
                                       # normal (y = -0.5 under gravity along -y)

    [integrator]
    kind = "symplectic_euler"          # explicit_euler | symplectic_euler | implicit_euler | static
    dt = 1e-3
    steps = 1000

    [output]
    every = 10                         # a frame every N steps (0: none); default steps / 50
    fields = ["mass", "force"]         # more point data in final.vtu and the frames: mass,
                                       # force, or any vertex embedding (vec3, f64, bool, i64)

    [[event]]                          # a topology change at a time (one table per event)
    time = 0.5                         # s, >= 0, at most the end of the run (steps x dt)
    kind = "cut"
    plane = { normal = [1.0, 0.0, 0.0], offset = 0.5 }   # separates the elements whose
                                       # centroids lie on opposite sides of normal . x = offset
    # where = "abs(x - 0.5) < 0.01"    # or: opens the faces (3D) or edges (2D) between two
                                       # elements whose centroid x, y, z satisfies it

    [fracture]                         # tested after every step
    criterion = "stress"               # stress: mean largest principal stress of the two
                                       # tetrahedra of a face (Pa, tetrahedra only); strain:
                                       # spring strain l / l0 - 1 (the mean over a face's
                                       # edges in 3D, an edge's in 2D: tearing)
    threshold = 1e6                    # a face (3D) or edge (2D) opens above it

Generators: ``box`` (``element`` ``tet``, ``hex``, ``wedge``, ``pyramid`` or ``mixed``; ``size``
and ``cells`` of 3) and ``grid`` or ``rectangle`` (``element`` ``tri``, ``quad`` or ``mixed``;
``size`` and ``cells`` of 2, in the plane z = 0); the box has a corner at the origin.
Predicates are expressions of the rule language over ``x``, ``y``, ``z``
(``x < 1e-9 && y > 0.1``, ``abs(z - 0.5) < 0.01``).

Every problem raises :class:`SceneError` naming the key by its path: ``integrator.dtt:
unknown key``, ``material.density: expected a number, got "abc"``, ``model[1].kind: ...``
(arrays of tables are numbered from 0). An event after the end of the run (``time`` past
``steps x dt``, also when a shorter step count is asked for) is refused as
``event[i].time: ... after the end of the run``. A cut that separates nothing when its time
comes (a plane or predicate that misses the object) cannot be known before the run: that
step fails (see :func:`topomech.run.run_scene`).
"""

from __future__ import annotations

import difflib
import json
import math
import re
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

from topomech import _core
from topomech._core import (
    FileFormatError,
    MeshError,
    MeshReadError,
    RuleError,
    SceneError,
    SimulationError,
)
from topomech._gmap import GMap
from topomech.loads import (
    LOAD_KINDS,
    LoadError,
    MeshGroups,
    apply_conditions,
    compile_expression,
    compile_predicate,
)
from topomech.models import Model
from topomech.models import model_files_of as _model_files_pairs
from topomech.simulation import ModelInfo, Simulation, available_models

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.9 and 3.10 only
    import tomli as tomllib

if TYPE_CHECKING:
    import meshio

    from topomech._gmap import PathLike
    from topomech.io import ImportedMesh

__all__ = [
    "EVENT_KINDS",
    "FRACTURE_CRITERIA",
    "INTEGRATORS",
    "PLANNED_MODELS",
    "MeshSpec",
    "Scene",
    "SceneError",
    "find_scene",
    "load_scene",
    "parse_scene",
    "shipped_scenes",
]

#: The integrators a scene can name.
INTEGRATORS = ("explicit_euler", "symplectic_euler", "implicit_euler", "static")

#: Models of the paper that scenes may name but this build does not ship yet.
PLANNED_MODELS = (
    "shear_isotropic",
    "shear_anisotropic",
    "shear_volumic",
    "bending_linear",
    "bending_angular",
)

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

#: The kinds of ``[[event]]`` tables.
EVENT_KINDS = ("cut",)

#: The fracture criteria.
FRACTURE_CRITERIA = ("stress", "strain")

#: Keys of a model table that set the material rather than the model.
MATERIAL_KEYS_IN_MODEL = ("young", "poisson")


def _show(value: Any) -> str:
    """A TOML value as a message shows it: strings quoted, booleans lowercase."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, (str, list)):
        try:
            return json.dumps(value)
        except (TypeError, ValueError):
            return repr(value)
    return str(value)


class _Table:
    """A TOML table being read: each getter checks a key's type and range and names the key
    by its full path; :meth:`done` refuses the keys nobody asked for."""

    def __init__(self, data: Mapping[str, Any], path: str, fail: _Fail) -> None:
        self.data = data
        self.path = path
        self.fail = fail
        self.known: list[str] = []

    def key(self, k: str) -> str:
        return f"{self.path}.{k}" if self.path else k

    def has(self, k: str) -> bool:
        return k in self.data

    def _get(self, k: str) -> Any:
        self.known.append(k)
        return self.data.get(k)

    @overload
    def number(
        self, k: str, default: float, *, positive: bool = ..., nonneg: bool = ...
    ) -> float: ...
    @overload
    def number(
        self, k: str, default: None = None, *, positive: bool = ..., nonneg: bool = ...
    ) -> float | None: ...
    def number(
        self,
        k: str,
        default: float | None = None,
        *,
        positive: bool = False,
        nonneg: bool = False,
    ) -> float | None:
        v = self._get(k)
        if v is None:
            return default
        return _number(v, self.key(k), self.fail, positive=positive, nonneg=nonneg)

    @overload
    def integer(self, k: str, default: int, *, minimum: int = ...) -> int: ...
    @overload
    def integer(self, k: str, default: None = None, *, minimum: int = ...) -> int | None: ...
    def integer(self, k: str, default: int | None = None, *, minimum: int = 0) -> int | None:
        v = self._get(k)
        if v is None:
            return default
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(self.key(k), f"expected an integer, got {_show(v)}")
        if v < minimum:
            raise self.fail(self.key(k), f"must be >= {minimum}, got {v}")
        return v

    @overload
    def string(self, k: str, default: str) -> str: ...
    @overload
    def string(self, k: str, default: None = None) -> str | None: ...
    def string(self, k: str, default: str | None = None) -> str | None:
        v = self._get(k)
        if v is None:
            return default
        if not isinstance(v, str):
            raise self.fail(self.key(k), f"expected a string, got {_show(v)}")
        return v

    def choice(self, k: str, choices: Sequence[str], default: str) -> str:
        v = self.string(k, default)
        if v not in choices:
            raise self.fail(self.key(k), f"unknown value {_show(v)} (expected {_or(choices)})")
        return v

    @overload
    def vector(
        self, k: str, n: int, default: tuple[float, ...], *, positive: bool = ...
    ) -> tuple[float, ...]: ...
    @overload
    def vector(
        self, k: str, n: int, default: None = None, *, positive: bool = ...
    ) -> tuple[float, ...] | None: ...
    def vector(
        self, k: str, n: int, default: tuple[float, ...] | None = None, *, positive: bool = False
    ) -> tuple[float, ...] | None:
        v = self._get(k)
        if v is None:
            return default
        if not isinstance(v, list) or len(v) != n:
            raise self.fail(self.key(k), f"expected an array of {n} numbers, got {_show(v)}")
        return tuple(
            _number(x, f"{self.key(k)}[{i}]", self.fail, positive=positive) for i, x in enumerate(v)
        )

    def int_vector(self, k: str, n: int, default: tuple[int, ...]) -> tuple[int, ...]:
        v = self._get(k)
        if v is None:
            return default
        if not isinstance(v, list) or len(v) != n:
            raise self.fail(self.key(k), f"expected an array of {n} integers, got {_show(v)}")
        out = []
        for i, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, int):
                raise self.fail(f"{self.key(k)}[{i}]", f"expected an integer, got {_show(x)}")
            if x < 1:
                raise self.fail(f"{self.key(k)}[{i}]", f"must be >= 1, got {x}")
            out.append(x)
        return tuple(out)

    def table(self, k: str) -> _Table:
        v = self._get(k)
        if v is None:
            v = {}
        if not isinstance(v, dict):
            raise self.fail(self.key(k), f"expected a table, got {_show(v)}")
        return _Table(v, self.key(k), self.fail)

    def tables(self, k: str) -> list[_Table]:
        """An array of tables (``[[k]]``); a single table ``[k]`` is refused, naming the
        double brackets."""
        v = self._get(k)
        if v is None:
            return []
        if isinstance(v, dict):
            raise self.fail(self.key(k), f"expected an array of tables: write [[{self.key(k)}]]")
        if not isinstance(v, list) or not all(isinstance(t, dict) for t in v):
            raise self.fail(self.key(k), f"expected an array of tables, got {_show(v)}")
        return [_Table(t, f"{self.key(k)}[{i}]", self.fail) for i, t in enumerate(v)]

    def done(self, extra: Sequence[str] = ()) -> None:
        """Refuses every key not read (nor in ``extra``), suggesting the closest known one."""
        known = [*self.known, *extra]
        for k in self.data:
            if k not in known:
                close = difflib.get_close_matches(k, known, n=1)
                hint = f"; did you mean '{close[0]}'?" if close else ""
                if k in _SPELLED_ELSEWHERE and _SPELLED_ELSEWHERE[k][0] in known:
                    hint = f"; write {_SPELLED_ELSEWHERE[k][1]}"
                expected = f" (known: {', '.join(sorted(set(known)))})" if known else ""
                raise self.fail(self.key(k), f"unknown key{hint}{expected}")


#: Keys people write that a scene spells otherwise: the key, the key that is known where
#: this one is written, and the hint.
_SPELLED_ELSEWHERE = {
    "linear": ("order", 'order = "linear" (keep the corner nodes of second-order cells)'),
}


class _Fail:
    """Makes the :class:`SceneError` of a scene: ``FILE: KEY: problem``."""

    def __init__(self, source: str) -> None:
        self.source = source

    def __call__(self, key: str | None, problem: str) -> SceneError:
        where = f"{key}: " if key else ""
        err = SceneError(f"{self.source}: {where}{problem}")
        err.key = key
        err.source = self.source
        return err


#: The longest scene name, in UTF-8 bytes (a file name's limit on common file systems).
MAX_NAME_BYTES = 255


def name_problem(name: str) -> str | None:
    """Why ``name`` cannot be a scene's name, or None when it can. The name is the output
    folder's name (``out/<name>``) and is shown in previews, so it must be one plain folder
    name: not empty, not ``.`` or ``..``, no path separator (``/``, ``\\``) or drive colon,
    no NUL or other control character, no leading or trailing blank, no leading ``-``, at most
    :data:`MAX_NAME_BYTES` bytes."""
    if not name:
        return "the name is empty"
    if name in (".", ".."):
        return f"{_show(name)} is not a folder name (it names a folder above or itself)"
    for ch in name:
        if ch in "/\\":
            return f"{_show(name)} contains a path separator {_show(ch)}: give a plain name"
        if ch == ":":
            return f"{_show(name)} contains ':' (a drive or stream separator): give a plain name"
        if ord(ch) < 32 or ord(ch) == 127:
            return f"{_show(name)} contains the control character U+{ord(ch):04X}"
    if not name.strip():
        return "the name is only blanks"
    if name != name.strip():
        return f"{_show(name)} begins or ends with a blank: a folder name that is easy to miss"
    if name.startswith("-"):
        return f"{_show(name)} begins with '-': a shell would read the folder as an option"
    if len(name.encode("utf-8", "surrogatepass")) > MAX_NAME_BYTES:
        return f"the name is longer than {MAX_NAME_BYTES} bytes"
    return None


def _number(
    v: Any, key: str, fail: _Fail, *, positive: bool = False, nonneg: bool = False
) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise fail(key, f"expected a number, got {_show(v)}")
    x = float(v)
    if not math.isfinite(x):
        raise fail(key, f"must be finite, got {_show(v)}")
    if positive and x <= 0:
        raise fail(key, f"must be positive, got {_show(v)}")
    if nonneg and x < 0:
        raise fail(key, f"must be >= 0, got {_show(v)}")
    return x


def _or(items: Sequence[str]) -> str:
    items = [f"'{i}'" for i in items]
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} or {items[-1]}"


_DIAGNOSTIC = re.compile(r"^.*?:(\d+):(\d+): error\[([\w-]+)\]: (?:rule '\w+': )?(.*)$")


def _check_predicate(pred: str, key: str, fail: _Fail) -> str:
    """Checks a predicate the way the kernel will compile it (one expression of the rule
    language over ``x``, ``y``, ``z``, the guard of a rule built around it, never rule text),
    so that a bad one is named by its key and the place in it (line and column)."""
    if not pred.strip():
        raise fail(key, "the predicate is empty")
    try:
        _core.check_predicate(pred, key)
    except RuleError as e:
        problems = []
        for line in e.diagnostics:
            m = _DIAGNOSTIC.match(line)
            if m is None:
                problems.append(line)
                continue
            row, col = int(m.group(1)), int(m.group(2))
            at = f"line {row}, column {col}" if row > 1 else f"column {col}"
            problems.append(f"{at}: {m.group(4)}")
        raise fail(key, f"bad predicate {_show(pred)}: {'; '.join(problems)}") from None
    return pred


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


@dataclass(frozen=True)
class Scene:
    """A scene read from TOML: the mesh, the simulation's configuration and the run."""

    #: Its name (``name`` in the file, else the file's stem).
    name: str
    #: The scene file (None for a scene parsed from text).
    path: Path | None
    mesh: MeshSpec
    #: The configuration :class:`Simulation` takes (models, material, fixed, ...).
    config: dict[str, Any]
    #: Steps to run.
    steps: int
    #: A frame every this many steps; 0 for none.
    every: int
    description: str = ""
    #: Whether the file gives ``output.every`` (else it follows the step count).
    every_given: bool = False
    #: ``output.fields``: the extra point data of the output meshes (``mass``, ``force`` or
    #: a vertex embedding's name; checked against the simulation by
    #: :func:`topomech.run.run_scene`).
    fields: tuple[str, ...] = ()
    #: ``(what, value, key)`` for each predicate and model kind (``what``: ``fix``,
    #: ``prescribed``, ``region`` or ``model``), to name the key of a kernel refusal.
    origins: tuple[tuple[str, str, str], ...] = ()
    #: What :meth:`build` applies after the kernel's configuration (see
    #: :func:`topomech.loads.apply_conditions`): ``held`` (fixes by points or group),
    #: ``loads`` and ``initial``, each entry with its scene key.
    conditions: dict[str, Any] = field(default_factory=dict)
    #: The mesh file as read (``"mesh"``: the meshio mesh of the kept cells), kept so that a
    #: run reads the file once: building, the groups of the loads and the output cells.
    #: The user's models (``[[model]] file = ...``), by index in ``config["models"]``.
    user_models: dict[int, Model] = field(default_factory=dict)
    _read: dict[str, Any] = field(default_factory=dict, init=False, compare=False, repr=False)

    @property
    def integrator(self) -> str:
        """The integrator's name."""
        return str(self.config["integrator"])

    @property
    def dt(self) -> float:
        """The time step."""
        return float(self.config["dt"])

    @property
    def models(self) -> list[str]:
        """The model kinds, in order."""
        return [str(m["kind"]) for m in self.config["models"]]

    @property
    def end_time(self) -> float:
        """The time at the end of the run: ``steps x dt``."""
        return self.steps * self.dt

    @property
    def events(self) -> list[dict[str, Any]]:
        """The timed events, as :class:`Simulation` takes them (``time``, ``kind`` and
        ``plane`` or ``where``)."""
        return list(self.config.get("events", []))

    def _fail(self) -> _Fail:
        return _Fail(str(self.path) if self.path is not None else "<scene>")

    def check_events(self) -> None:
        """Refuses an event that the run would never reach (its time after ``steps x dt``),
        naming ``event[i].time``."""
        end = self.end_time
        for i, e in enumerate(self.events):
            t = float(e["time"])
            if t > end + 1e-9 * self.dt:
                raise self._fail()(
                    f"event[{i}].time",
                    f"t = {t:g} is after the end of the run (t = {end:g}: {self.steps} steps "
                    f"of dt {self.dt:g}): the event would never happen",
                )

    def with_steps(self, steps: int | None = None, every: int | None = None) -> Scene:
        """The scene with another step count or frame interval. The frame interval stays
        the file's ``output.every`` if it gives one, else it follows the steps (steps / 50).
        Raises :class:`SceneError` when an event falls after the end of the shorter run."""
        steps = self.steps if steps is None else steps
        if every is not None:
            sc = replace(self, steps=steps, every=every, every_given=True)
        else:
            every = self.every if self.every_given else _default_every(steps)
            sc = replace(self, steps=steps, every=every)
        sc.check_events()
        return sc

    def load_gmap(self) -> GMap:
        """The scene's G-map: the mesh file read, or the generated mesh."""
        return self.load_mesh().gmap

    def load_mesh(self) -> ImportedMesh:
        """The scene's mesh file read and its map built with the ``mesh.*`` options
        (``reorient``, ``pinched``, ``duplicates``, ``order``): the map, the mesh read with
        its named sets (``.mesh``, see :func:`topomech.io.read_mesh`), the dropped blocks and
        the notes, which are also printed to stderr. For a generated mesh ``.mesh`` is None.
        Raises :class:`SceneError` naming ``mesh.file``, or the ``mesh.*`` key of the option
        that would accept a refused mesh; a saved map (``.tmg``) that cannot be read or is not
        a valid G-map is refused naming ``mesh.file``, with its violated invariants."""
        from topomech.io import ImportedMesh, import_mesh

        fail = self._fail()
        m = self.mesh
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
                self._read["mesh"] = imported.mesh
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

    def build(self, gmap: GMap | None = None) -> Simulation:
        """The simulation (on ``gmap``, by default :meth:`load_gmap`'s). Raises
        :class:`SceneError` when the kernel refuses it (a model that does not exist in the
        mesh's dimension or matches nothing, a predicate that selects nothing, ...), with
        the :class:`SimulationError` as its cause."""
        fail = self._fail()
        self.check_events()
        g = self.load_gmap() if gmap is None else gmap
        _check_models(self.config["models"], g.dimension, fail, self.user_models)
        _check_fracture(self.config.get("fracture"), g, fail)
        try:
            sim = Simulation(g, self.config)
        except SimulationError as e:
            raise fail(self._key_of(str(e)), f"cannot build the simulation: {e}") from e
        if any(self.conditions.get(k) for k in ("held", "loads", "initial")):
            groups = self.mesh_groups() if self._uses_groups() else None
            try:
                apply_conditions(sim, self.conditions, groups)
            except LoadError as e:
                raise fail(e.key, str(e)) from e
        return sim

    def _uses_groups(self) -> bool:
        held = [sel for _, sel, _ in self.conditions.get("held", [])]
        others = [c["select"] for w in ("loads", "initial") for _, c in self.conditions.get(w, [])]
        # points too: without the simulation's point_ids, rows are matched to the file's points
        return any("group" in sel or "points" in sel for sel in [*held, *others])

    def mesh_groups(self) -> MeshGroups:
        """The named groups of the scene's mesh file (Gmsh physical groups, meshio point and
        cell sets; see :func:`topomech.io.read_mesh`); none for a generated mesh."""
        m = self.mesh
        if m.file is None:
            return MeshGroups()
        from topomech.io import GMAP_SUFFIX

        if m.file.suffix.lower() == GMAP_SUFFIX:
            return MeshGroups()  # a saved map keeps its numbering (point_id), not groups
        return MeshGroups.from_meshio(self.file_mesh())

    def file_mesh(self) -> meshio.Mesh:
        """The scene's mesh file as read (:func:`topomech.io.read_mesh` with ``mesh.order``:
        the kept cells and the named sets), read once per scene: :meth:`load_mesh` keeps what
        it read. Raises :class:`SceneError` naming ``mesh.file`` when the file cannot be read,
        ValueError for a generated mesh or a saved map (``.tmg``), which have no mesh file."""
        from topomech.io import GMAP_SUFFIX, read_mesh

        m = self.mesh
        if m.file is None or m.file.suffix.lower() == GMAP_SUFFIX:
            raise ValueError("the scene's mesh is not read from a mesh file")
        cached = self._read.get("mesh")
        if cached is not None:
            return cached
        kwargs: dict[str, Any] = {}
        if m.linear:
            kwargs["linear"] = True
        try:
            mesh, _ = read_mesh(m.file, **kwargs)
        except (MeshReadError, MeshError, OSError) as e:
            raise self._fail()("mesh.file", str(e)) from e
        self._read["mesh"] = mesh
        return mesh

    def _key_of(self, message: str) -> str | None:
        """The key a kernel refusal is about: the first predicate or model kind it quotes."""
        m = _KERNEL_SUBJECT.search(message)
        if m is None:
            return None
        what = _KERNEL_WHAT[m.group(1)]
        for w, value, key in self.origins:
            if w == what and value == m.group(2):
                return key
        return None


#: What kernel messages quote: a predicate or a model kind.
_KERNEL_SUBJECT = re.compile(
    r"(fix predicate|prescribed-displacement predicate|material region|model) '([^']*)'"
)
_KERNEL_WHAT = {
    "fix predicate": "fix",
    "prescribed-displacement predicate": "prescribed",
    "material region": "region",
    "model": "model",
}


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


def _check_fracture(fracture: Mapping[str, Any] | None, g: GMap, fail: _Fail) -> None:
    """Refuses the stress criterion on a mesh it cannot measure: it needs tetrahedra."""
    if fracture is None or fracture["criterion"] != "stress":
        return
    if g.dimension != 3:
        raise fail(
            "fracture.criterion",
            "the stress criterion needs a volume mesh of tetrahedra, the mesh is 2D "
            "(a surface tears by 'strain')",
        )
    others = sorted(set(g.to_flat().kinds) - {"tetra"})
    if others:
        raise fail(
            "fracture.criterion",
            f"the stress criterion measures tetrahedra only, the mesh has {', '.join(others)} "
            "cells (use 'strain')",
        )


def _events(tables: list[_Table], fail: _Fail) -> list[dict[str, Any]]:
    """The ``[[event]]`` tables as :class:`Simulation` takes them."""
    events: list[dict[str, Any]] = []
    for t in tables:
        time = t.number("time", nonneg=True)
        kind = t.string("kind")
        t.done(extra=("plane", "where"))
        if time is None:
            raise fail(t.key("time"), "missing: when the event happens (s, >= 0)")
        if kind is None:
            raise fail(t.key("kind"), f"missing: the event's kind ({_or(EVENT_KINDS)})")
        if kind not in EVENT_KINDS:
            raise fail(
                t.key("kind"), f"unknown event kind {_show(kind)} (expected {_or(EVENT_KINDS)})"
            )
        event: dict[str, Any] = {"time": time, "kind": kind}
        if t.has("plane") and t.has("where"):
            raise fail(
                t.key("where"),
                f"give either {t.key('plane')} or {t.key('where')}, not both",
            )
        if t.has("plane"):
            p = t.table("plane")
            normal = p.vector("normal", 3)
            offset = p.number("offset")
            p.done()
            if normal is None:
                raise fail(p.key("normal"), "missing: the plane's normal [nx, ny, nz]")
            if all(x == 0.0 for x in normal):
                raise fail(p.key("normal"), "must not be zero")
            if offset is None:
                raise fail(p.key("offset"), "missing: the plane is normal . x = offset")
            event["plane"] = {"normal": list(normal), "offset": offset}
        elif t.has("where"):
            where = _required_str(t, "where", fail)
            event["where"] = _check_predicate(where, t.key("where"), fail)
        else:
            raise fail(
                t.path,
                "missing the cut's geometry: give plane = { normal = [nx, ny, nz], "
                'offset = d } or where = "predicate on x, y, z"',
            )
        events.append(event)
    return events


def _fracture(top: _Table, fail: _Fail) -> dict[str, Any] | None:
    """The ``[fracture]`` table as :class:`Simulation` takes it (None without one)."""
    if not top.has("fracture"):
        return None
    t = top.table("fracture")
    t.done(extra=("criterion", "threshold"))
    if not t.has("criterion"):
        raise fail(t.key("criterion"), f"missing: {_or(FRACTURE_CRITERIA)}")
    criterion = t.choice("criterion", FRACTURE_CRITERIA, "strain")
    threshold = t.number("threshold", positive=True)
    if threshold is None:
        unit = "a stress in Pa" if criterion == "stress" else "a strain, l / l0 - 1"
        raise fail(t.key("threshold"), f"missing: {unit} above which a face or edge opens")
    return {"criterion": criterion, "threshold": threshold}


def _default_every(steps: int) -> int:
    return max(1, steps // 50)


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


def _model_entries(kind: str, dim: int | None) -> list[ModelInfo]:
    """The catalogue's entries for ``kind`` (one per set of dimensions), those of dimension
    ``dim`` only when it is known."""
    return [
        m for m in available_models() if m["kind"] == kind and (dim is None or dim in m["dims"])
    ]


def _takes(kind: str, dim: int | None) -> list[str]:
    """The keys a ``[[model]]`` table of ``kind`` may have beside ``kind``."""
    params: list[str] = []
    for m in _model_entries(kind, dim):
        params += [p for p in m["params"] if p not in params]
    return [*params, *MATERIAL_KEYS_IN_MODEL]


def _check_models(
    models: list[dict[str, Any]],
    dim: int,
    fail: _Fail,
    user_models: Mapping[int, Model] | None = None,
) -> None:
    """Refuses a model that does not exist in dimension ``dim``, or a parameter it does not
    take there, naming the key (``model[i].file`` for a user's model, by index in
    ``user_models``)."""
    for i, spec in enumerate(models):
        user = (user_models or {}).get(i)
        if user is not None:
            if dim not in user.dimensions:
                raise fail(f"model[{i}].file", _wrong_dimension(user, dim))
            continue
        kind = spec["kind"]
        if not _model_entries(kind, dim):
            entries = _model_entries(kind, None)
            dims = sorted({d for m in entries for d in m["dims"]})
            needs = " or ".join(m["needs"] for m in entries)
            want = " or ".join(f"{d}D" for d in dims)
            raise fail(
                f"model[{i}].kind",
                f"model '{kind}' needs a {want} mesh ({needs}), the mesh is {dim}D",
            )
        takes = _takes(kind, dim)
        for p in spec:
            if p != "kind" and p not in takes:
                raise fail(
                    f"model[{i}].{p}",
                    f"model '{kind}' takes no parameter '{p}' on a {dim}D mesh "
                    f"(it takes {', '.join(takes)})",
                )


def _models(
    tables: list[_Table], dim: int | None, base: Path | None, fail: _Fail
) -> tuple[list[dict[str, Any]], dict[str, tuple[str, float]], dict[int, Model]]:
    """The models for :class:`Simulation`, the material values they set (young, poisson),
    each with the key that set it first, and the user's models (``[[model]] file = ...``)
    by table index. ``dim`` is the mesh's dimension when the scene says it (a generator),
    else None: the models are checked again once it is known. Model files are relative to
    ``base`` (the scene's folder)."""
    if not tables:
        raise fail("model", "no model: add a [[model]] table with a kind or a file")
    kinds = list(dict.fromkeys(m["kind"] for m in available_models()))
    models: list[dict[str, Any]] = []
    set_by: dict[str, tuple[str, float]] = {}
    user_models: dict[int, Model] = {}
    for i, t in enumerate(tables):
        if t.has("file"):
            if t.has("kind"):
                raise fail(
                    t.key("kind"),
                    "give either kind (a shipped model) or file (a rule file), not both",
                )
            user = _user_model(t, i, dim, base, fail)
            models.append(user.config_entry())
            user_models[i] = user
            continue
        kind = t.string("kind")
        if kind is None:
            raise fail(
                t.key("kind"),
                f"missing: the model's kind ({_or(kinds)}), or file (a rule file declaring it)",
            )
        if kind not in kinds:
            if kind in PLANNED_MODELS:
                raise fail(
                    t.key("kind"),
                    f"model '{kind}' is not available yet (available: {', '.join(kinds)})",
                )
            raise fail(t.key("kind"), f"unknown model '{kind}' (known: {', '.join(kinds)})")
        if dim is not None:
            _check_models([{"kind": kind}], dim, _Renumber(fail, i))
        takes = _takes(kind, dim)
        for k in t.data:
            if k not in ("kind", *takes):
                close = difflib.get_close_matches(k, takes, n=1)
                hint = f"; did you mean '{close[0]}'?" if close else ""
                raise fail(
                    t.key(k),
                    f"unknown key{hint} (model '{kind}' takes {', '.join(takes)})",
                )
        spec: dict[str, Any] = {"kind": kind}
        for p in takes:
            if p in MATERIAL_KEYS_IN_MODEL:
                continue
            v = t.number(p, nonneg=True)
            if v is not None:
                spec[p] = v
        for p in MATERIAL_KEYS_IN_MODEL:
            v = t.number(p)
            if v is None:
                continue
            if p in set_by and set_by[p][1] != v:
                other, was = set_by[p]
                raise fail(
                    t.key(p),
                    f"{v:g} differs from {other} = {was:g} (the material has one {p})",
                )
            set_by.setdefault(p, (t.key(p), v))
        models.append(spec)
    return models, set_by, user_models


def _user_model(t: _Table, i: int, dim: int | None, base: Path | None, fail: _Fail) -> Model:
    """The model of a ``[[model]] file = "..."`` table: the file (relative to ``base``) read
    and checked with the shipped common rules, the model picked by ``name`` (needed when the
    file declares several), its parameters from the table's other keys. Refusals name
    ``model[i].file`` (an unreadable or refused file: the checker's ``FILE:LINE:COL`` lines
    follow), ``model[i].name`` or ``model[i].<param>``."""
    file = _required_str(t, "file", fail)
    path = Path(file).expanduser()
    if not path.is_absolute() and base is not None:
        path = base / path
    key = t.key("file")
    try:
        declared = Model.load_all(path)
    except UnicodeDecodeError as e:
        raise fail(
            key, f"cannot read the rule file {path}: not UTF-8 text (byte {e.start})"
        ) from None
    except OSError as e:
        raise fail(key, f"cannot read the rule file {path}: {e.strerror or e}") from None
    except RuleError as e:
        raise fail(key, f"the rule file is refused:\n{e}") from None
    if not declared:
        raise fail(key, f"{path} declares no model")
    names = ", ".join(m.name for m in declared)
    name = t.string("name")
    if name is None:
        if len(declared) > 1:
            raise fail(
                t.key("name"),
                f"missing: {path} declares several models ({names}); say which with name",
            )
        model = declared[0]
    else:
        found = [m for m in declared if m.name == name]
        if not found:
            raise fail(t.key("name"), f"{path} declares no model '{name}' (it declares: {names})")
        model = found[0]
    if dim is not None and dim not in model.dimensions:
        raise fail(key, _wrong_dimension(model, dim))
    params = list(model.params)
    takes = ", ".join(params) if params else "no parameter"
    for k in t.data:
        if k in ("file", "name"):
            continue
        if k not in params:
            close = difflib.get_close_matches(k, params, n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise fail(t.key(k), f"unknown key{hint} (model '{model.name}' takes {takes})")
        if model.param_types.get(k) != "f64":
            raise fail(
                t.key(k),
                f"model '{model.name}': '{k}' is a {model.param_types.get(k)}; only f64 "
                "parameters can be set from a scene",
            )
    values: dict[str, float] = {}
    for p in params:
        if model.param_types.get(p) == "f64":
            v = t.number(p)
            if v is not None:
                values[p] = v
    for p, default in model.params.items():
        if default is None and p not in values:
            raise fail(
                t.key(p), f"missing: model '{model.name}' has no default for parameter '{p}'"
            )
    return model.with_params(**values)


def _model_files_of(models: list[Model]) -> list[tuple[str, str]]:
    """The ``(file, text)`` pairs of the user's models' rule files, each once."""
    return _model_files_pairs(list(models))[1]


def _wrong_dimension(model: Model, dim: int) -> str:
    dims = " or ".join(f"{d}D" for d in model.dimensions)
    return f"model '{model.name}' runs on {dims} meshes, the mesh is {dim}D"


def _output_fields(t: _Table, fail: _Fail) -> tuple[str, ...]:
    """``output.fields``: a list of distinct names (which names exist is known once the
    simulation is built)."""
    v = t._get("fields")
    if v is None:
        return ()
    key = t.key("fields")
    if not isinstance(v, list):
        raise fail(key, f"expected an array of field names, got {_show(v)}")
    seen: dict[str, int] = {}
    for i, name in enumerate(v):
        if not isinstance(name, str):
            raise fail(f"{key}[{i}]", f"expected a field name (a string), got {_show(name)}")
        if name in seen:
            raise fail(f"{key}[{i}]", f"{_show(name)} is already {key}[{seen[name]}]")
        seen[name] = i
    return tuple(v)


class _Renumber(_Fail):
    """A :class:`_Fail` that reads ``model[0]`` as ``model[i]`` (checking one model alone)."""

    def __init__(self, fail: _Fail, i: int) -> None:
        super().__init__(fail.source)
        self.i = i

    def __call__(self, key: str | None, problem: str) -> SceneError:
        if key is not None and key.startswith("model[0]"):
            key = f"model[{self.i}]" + key[len("model[0]") :]
        return super().__call__(key, problem)


def parse_scene(text: str, path: PathLike | None = None, *, base: PathLike | None = None) -> Scene:
    """A scene from TOML text. ``path`` names the scene in messages (and is its location:
    mesh files are relative to its directory, or to ``base``, or to the working directory)."""
    p = Path(path) if path is not None else None
    fail = _Fail(str(p) if p is not None else "<scene>")
    base_dir = Path(base) if base is not None else (p.parent if p is not None else None)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise fail(None, f"invalid TOML: {e}") from None
    top = _Table(data, "", fail)
    name = top.string("name", p.stem if p is not None else "scene")
    problem = name_problem(name)
    if problem is not None:
        given = top.has("name")
        raise fail(
            "name", f"{problem}{'' if given else ' (the name comes from the file name: give one)'}"
        )
    description = top.string("description", "")

    if not top.has("mesh"):
        raise fail("mesh", "missing table [mesh] (give mesh.file or mesh.generator)")
    mesh = _mesh(top.table("mesh"), base_dir, fail)

    mat = top.table("material")
    density = mat.number("density", 1000.0, positive=True)
    damping = mat.number("damping", 0.0, nonneg=True)
    young = mat.number("young", positive=True)
    poisson = mat.number("poisson")
    regions = []
    origins: list[tuple[str, str, str]] = []
    for r in mat.tables("region"):
        region: dict[str, Any] = {
            "where": _check_predicate(_required_str(r, "where", fail), r.key("where"), fail)
        }
        for k, pos in (("density", True), ("young", True), ("poisson", False)):
            v = r.number(k, positive=pos)
            if v is not None:
                if k == "poisson":
                    _check_poisson(v, r.key(k), fail)
                region[k] = v
        r.done()
        if len(region) == 1:
            raise fail(r.path, "a region needs density, young or poisson")
        regions.append(region)
        origins.append(("region", region["where"], r.key("where")))
    mat.done()

    if poisson is not None:
        _check_poisson(poisson, "material.poisson", fail)
    models, set_by, user_models = _models(top.tables("model"), mesh.dimension, base_dir, fail)
    model_tables = top.tables("model")
    for i, m in enumerate(models):
        if i not in user_models:
            key = f"model[{i}].kind"
        elif model_tables[i].has("name"):
            key = f"model[{i}].name"
        else:
            key = f"model[{i}].file"
        origins.append(("model", m["kind"], key))
    for what, v in (("young", young), ("poisson", poisson)):
        if what in set_by and v is not None and set_by[what][1] != v:
            key, from_model = set_by[what]
            raise fail(
                key,
                f"{from_model:g} differs from material.{what} = {v:g} "
                f"(the material has one {what})",
            )
    if "young" in set_by:
        key, young = set_by["young"]
        if young <= 0:
            raise fail(key, f"must be positive, got {young:g}")
    if "poisson" in set_by:
        key, poisson = set_by["poisson"]
        _check_poisson(poisson, key, fail)
    young = 1e6 if young is None else young
    poisson = 0.3 if poisson is None else poisson

    fixed: list[str] = []
    prescribed: list[tuple[str, tuple[float, ...]]] = []
    held: list[tuple[str, dict[str, Any], list[float] | None]] = []
    for f in top.tables("fix"):
        sel = _selection(f, fail, required=True, in_python=False)
        disp = f.vector("displacement", 3)
        f.done()
        if "where" not in sel:
            held.append((f.path, sel, None if disp is None else list(disp)))
            continue
        pred = sel["where"]
        if disp is None:
            fixed.append(pred)
            origins.append(("fix", pred, f.key("where")))
        else:
            prescribed.append((pred, disp))
            origins.append(("prescribed", pred, f.key("where")))
    loads = _loads(top.tables("load"), fail)
    initial = _initial(top, fail)

    world = top.table("world")
    gravity = world.vector("gravity", 3, (0.0, -9.81, 0.0))
    ground = _ground(world, fail)
    world.done()

    integ = top.table("integrator")
    kind = integ.choice("kind", INTEGRATORS, "symplectic_euler")
    dt = integ.number("dt", 1e-3, positive=True)
    steps = integ.integer("steps", 100, minimum=0)
    integ.done()

    out = top.table("output")
    every_v = out.integer("every", None, minimum=0)
    fields = _output_fields(out, fail)
    out.done()
    events = _events(top.tables("event"), fail)
    fracture = _fracture(top, fail)
    top.done()

    config: dict[str, Any] = {
        "models": models,
        "density": density,
        "young": young,
        "poisson": poisson,
        "damping": damping,
        "gravity": list(gravity),
        "fixed": fixed,
        "prescribed": [(w, list(d)) for w, d in prescribed],
        "regions": regions,
        "ground": ground,
        "integrator": kind,
        "dt": dt,
        "events": events,
        "fracture": fracture,
    }
    model_files = _model_files_of(list(user_models.values()))
    if model_files:
        config["model_files"] = model_files
    scene = Scene(
        name=name,
        path=p,
        mesh=mesh,
        config=config,
        steps=steps,
        every=every_v if every_v is not None else _default_every(steps),
        description=description,
        every_given=every_v is not None,
        fields=fields,
        origins=tuple(origins),
        conditions={"held": held, "loads": loads, "initial": initial},
        user_models=user_models,
    )
    scene.check_events()
    return scene


def _selection(t: _Table, fail: _Fail, *, required: bool, in_python: bool = True) -> dict[str, Any]:
    """The selection of a ``[[fix]]``, ``[[load]]`` or ``[initial]`` table: exactly one of
    ``where`` (a predicate on x, y, z), ``points`` (input point indices) or ``group`` (a
    group name of the mesh file); ``{}`` when none is given and none is ``required``.
    ``in_python``: the predicate is evaluated by :mod:`topomech.loads` (on face centroids,
    or vertices of an initial field), which reads the scalar part of the rule language
    only; a fix's predicate is compiled by the kernel."""
    given = [k for k in ("where", "points", "group") if t.has(k)]
    t.known += [k for k in ("where", "points", "group") if k not in t.known]
    if len(given) > 1:
        raise fail(
            t.key(given[1]),
            f"give one selection: {t.key(given[0])} or {t.key(given[1])}, not both",
        )
    if not given:
        if required:
            raise fail(
                t.path,
                'missing the selection: where = "predicate on x, y, z", points = [input '
                'point indices] or group = "a group of the mesh file"',
            )
        return {}
    k = given[0]
    if k == "where":
        pred = _check_predicate(_required_str(t, "where", fail), t.key("where"), fail)
        if in_python:
            try:
                compile_predicate(pred)
            except LoadError as e:
                raise fail(t.key("where"), str(e)) from None
        return {"where": pred}
    if k == "group":
        name = _required_str(t, "group", fail)
        if not name:
            raise fail(t.key("group"), "the group name is empty")
        return {"group": name}
    v = t._get("points")
    if not isinstance(v, list) or not v:
        raise fail(t.key("points"), f"expected a non-empty array of point indices, got {_show(v)}")
    for i, x in enumerate(v):
        if isinstance(x, bool) or not isinstance(x, int):
            raise fail(f"{t.key('points')}[{i}]", f"expected an integer, got {_show(x)}")
        if x < 0:
            raise fail(f"{t.key('points')}[{i}]", f"point indices are >= 0, got {x}")
    return {"points": list(v)}


#: The key holding each load kind's value.
_LOAD_VALUE = {"point": "force", "traction": "traction", "pressure": "pressure"}


def _loads(tables: list[_Table], fail: _Fail) -> list[tuple[str, dict[str, Any]]]:
    """The ``[[load]]`` tables: ``(key, {"kind", value, "select"})``."""
    loads: list[tuple[str, dict[str, Any]]] = []
    for t in tables:
        kind = t.string("kind")
        if kind is None:
            raise fail(t.key("kind"), f"missing: the load's kind ({_or(LOAD_KINDS)})")
        if kind not in LOAD_KINDS:
            raise fail(
                t.key("kind"), f"unknown load kind {_show(kind)} (expected {_or(LOAD_KINDS)})"
            )
        want = _LOAD_VALUE[kind]
        for other in _LOAD_VALUE.values():
            if other != want and t.has(other):
                raise fail(
                    t.key(other),
                    f"a {kind} load takes {want}, not {other}",
                )
        value: Any
        raw = t.data.get(want)
        if kind == "pressure" and isinstance(raw, str):
            value = _expression(t, want, raw, t.key(want), fail)
        elif kind == "traction" and isinstance(raw, list) and any(isinstance(v, str) for v in raw):
            if len(raw) != 3:
                raise fail(t.key(want), f"expected an array of 3 numbers, got {_show(raw)}")
            value = [
                _expression(t, want, v, f"{t.key(want)}[{i}]", fail)
                if isinstance(v, str)
                else _number(v, f"{t.key(want)}[{i}]", fail)
                for i, v in enumerate(raw)
            ]
        elif kind == "pressure":
            value = t.number("pressure")
        else:
            vec = t.vector(want, 3)
            value = None if vec is None else list(vec)
        if value is None:
            unit = {
                "force": "[fx, fy, fz] in N on each selected vertex",
                "traction": "[tx, ty, tz] in Pa (3D faces) or N/m (2D edges)",
                "pressure": "a number in Pa (3D faces) or N/m (2D edges), along the inward normal",
            }[want]
            raise fail(t.key(want), f"missing: {unit}")
        sel = _selection(t, fail, required=True)
        t.done()
        loads.append((t.path, {"kind": kind, want: value, "select": sel}))
    return loads


def _expression(t: _Table, k: str, text: str, key: str, fail: _Fail) -> str:
    """A load's value given as an expression of x, y, z (checked now, evaluated on the rest
    faces when the scene is built)."""
    t.known.append(k)
    try:
        compile_expression(text)
    except LoadError as e:
        raise fail(key, str(e)) from None
    return text


def _initial(top: _Table, fail: _Fail) -> list[tuple[str, dict[str, Any]]]:
    """The ``[initial]`` table (or ``[[initial]]`` tables): ``(key, {"velocity",
    "displacement", "select"})``."""
    if not top.has("initial"):
        return []
    tables = (
        [top.table("initial")] if isinstance(top.data["initial"], dict) else top.tables("initial")
    )
    out: list[tuple[str, dict[str, Any]]] = []
    for t in tables:
        velocity = t.vector("velocity", 3)
        displacement = t.vector("displacement", 3)
        sel = _selection(t, fail, required=False)
        t.done()
        if velocity is None and displacement is None:
            raise fail(t.path, "give velocity = [vx, vy, vz] or displacement = [dx, dy, dz]")
        out.append(
            (
                t.path,
                {
                    "velocity": None if velocity is None else list(velocity),
                    "displacement": None if displacement is None else list(displacement),
                    "select": sel,
                },
            )
        )
    return out


def _ground(world: _Table, fail: _Fail) -> float | dict[str, list[float]] | None:
    """``world.ground``: a number (a height along the opposite of gravity), or a table
    ``{ point = [..], normal = [..] }`` (normal optional: the opposite of gravity)."""
    if isinstance(world.data.get("ground"), dict):
        g = world.table("ground")
        point = g.vector("point", 3)
        normal = g.vector("normal", 3)
        g.done()
        if point is None:
            raise fail(g.key("point"), "missing: a point [x, y, z] of the ground plane")
        out: dict[str, list[float]] = {"point": list(point)}
        if normal is not None:
            if all(x == 0.0 for x in normal):
                raise fail(g.key("normal"), "must not be zero")
            out["normal"] = list(normal)
        return out
    return world.number("ground")


def _required_str(t: _Table, k: str, fail: _Fail) -> str:
    v = t.string(k)
    if v is None:
        raise fail(t.key(k), "missing")
    return v


def _check_poisson(v: float, key: str, fail: _Fail) -> None:
    if not -1.0 < v < 0.5:
        raise fail(key, f"must be in (-1, 0.5), got {v:g}")


def load_scene(path: PathLike) -> Scene:
    """Reads a scene file (TOML); ``path`` may also name a shipped scene (see
    :func:`shipped_scenes`). Raises :class:`SceneError` naming the key of any problem."""
    p = find_scene(path)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise _Fail(str(p))(None, f"not UTF-8 text (byte {e.start})") from None
    except OSError as e:
        raise _Fail(str(p))(None, f"cannot read the scene file: {e.strerror or e}") from None
    return parse_scene(text, p)


def shipped_scenes() -> dict[str, Path]:
    """The scenes shipped with topomech, by name (``topomech run NAME`` runs one)."""
    d = Path(__file__).with_name("scenes")
    return {p.stem: p for p in sorted(d.glob("*.toml"))}


def find_scene(spec: PathLike) -> Path:
    """The scene file ``spec`` names: an existing file, else a shipped scene of that name
    (with or without ``.toml``). Raises :class:`SceneError` when neither exists."""
    p = Path(spec)
    if p.exists():
        if p.is_dir():
            raise _Fail(str(p))(None, "is a directory, not a scene file")
        return p
    shipped = shipped_scenes()
    name = p.name[: -len(".toml")] if p.name.endswith(".toml") else p.name
    if p.parent == Path() and name in shipped:
        return shipped[name]
    raise _Fail(str(p))(
        None,
        f"no such scene file, and no shipped scene of that name (shipped: {', '.join(shipped)})",
    )
