"""The :class:`Scene` (what a scene file says, built into a :class:`Simulation` by
:meth:`Scene.build`), :func:`parse_scene`, which reads every table through the other modules
of :mod:`topomech.scene`, and finding and reading scene files (:func:`load_scene`,
:func:`shipped_scenes`, :func:`find_scene`).
"""

from __future__ import annotations

import difflib
import re
import sys
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from topomech._core import SimulationError
from topomech._gmap import GMap
from topomech._paths import missing_file, read_text_file
from topomech.loads import LoadError, MeshGroups, apply_conditions
from topomech.models import Model
from topomech.scene._conditions import _fixes, _ground, _initial, _loads
from topomech.scene._events import _check_fracture, _events, _fracture
from topomech.scene._material import _material, _young_poisson
from topomech.scene._mesh import MeshSpec, _file_mesh, _load_mesh, _mesh
from topomech.scene._models import _check_models, _model_files_of, _model_origins, _models
from topomech.scene._table import _Fail, _show, _Table, name_problem
from topomech.simulation import Simulation

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.9 and 3.10 only
    import tomli as tomllib

if TYPE_CHECKING:
    import meshio

    from topomech._gmap import PathLike
    from topomech.io import ImportedMesh


#: The integrators a scene can name.


class SceneWarning(UserWarning):
    """Something in a scene that runs but may not do what was meant (a blade that stops
    part-way); the CLI prints it as a note."""


INTEGRATORS = ("explicit_euler", "symplectic_euler", "implicit_euler", "static")
#: The linear solvers of ``implicit_euler`` and ``static`` (``integrator.linear_solver``).
LINEAR_SOLVERS = ("auto", "cg", "pcg", "direct")
#: The preconditioners of ``pcg`` (``integrator.preconditioner``).
PRECONDITIONERS = ("jacobi", "block_jacobi")
#: The smallest ``integrator.tolerance`` (the kernel's ``MIN_TOLERANCE``).
MIN_TOLERANCE = 1e-14
#: The ``[integrator]`` keys of the linear solver.
SOLVER_KEYS = ("linear_solver", "preconditioner", "tolerance", "max_iterations")
#: The integrators that solve linear systems (the only ones the solver keys apply to).
_SOLVING = ("implicit_euler", "static")


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
    #: ``supports`` (every ``[[fix]]`` table, ``where`` ones included, to refuse two that
    #: hold one vertex at two positions), ``loads`` and ``initial``, each entry with its
    #: scene key.
    conditions: dict[str, Any] = field(default_factory=dict)
    #: The user's models (``[[model]] file = ...``), by index in ``config["models"]``.
    user_models: dict[int, Model] = field(default_factory=dict)
    #: The mesh file as read (``"mesh"``: the meshio mesh of the kept cells), kept so that a
    #: run reads the file once: building, the groups of the loads and the output cells.
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
        """The events, as :class:`Simulation` takes them: timed cuts (``time``, ``kind`` and
        ``plane`` or ``where``) and blades (``kind = "blade"``, ``start``, ``end``, ``from``,
        ``to``)."""
        return list(self.config.get("events", []))

    def _fail(self) -> _Fail:
        return _Fail(str(self.path) if self.path is not None else "<scene>")

    def check_events(self) -> None:
        """Refuses an event that the run would never reach (its time after ``steps x dt``,
        or any time in a run of no step), naming ``event[i].time``."""
        end = self.end_time
        for i, e in enumerate(self.events):
            if e.get("kind") == "blade":
                t = float(e["start"])
                if t >= end:
                    raise self._fail()(
                        f"event[{i}].start",
                        f"t = {t:g} is not before the end of the run (t = {end:g}: "
                        f"{_n_steps(self.steps)} of dt {self.dt:g}): the blade would never move",
                    )
                stop = float(e["end"])
                if stop > end + 1e-9 * self.dt:
                    # allowed (a shortened run, a preview), but said: the cut is partial
                    warnings.warn(
                        SceneWarning(
                            f"{self._fail().source}: event[{i}].end: t = {stop:g} is after the end "
                            f"of the run (t = {end:g}: {_n_steps(self.steps)} of dt "
                            f"{self.dt:g}): the blade stops part-way and cuts only what it "
                            "crossed by then"
                        ),
                        stacklevel=2,
                    )
                continue
            t = float(e["time"])
            if self.steps == 0:
                # an event happens at the end of the step that reaches its time: none here
                raise self._fail()(
                    f"event[{i}].time",
                    f"t = {t:g}, but the run takes no step (steps = 0): the event would never "
                    "happen",
                )
            if t > end + 1e-9 * self.dt:
                raise self._fail()(
                    f"event[{i}].time",
                    f"t = {t:g} is after the end of the run (t = {end:g}: "
                    f"{_n_steps(self.steps)} of dt {self.dt:g}): the event would never happen",
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
        return _load_mesh(self.mesh, self._fail(), self._read)

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
        except (ValueError, TypeError) as e:
            # an argument Simulation's own checks refuse ("models[0].stiffness: ..."): named
            # by the scene's key when the message names the argument
            key, problem = _arg_key(str(e))
            raise fail(key, f"cannot build the simulation: {problem}") from e
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
        return _file_mesh(self.mesh, self._fail(), self._read)

    def _key_of(self, message: str) -> str | None:
        """The key a kernel refusal is about: the first predicate or model kind it quotes."""
        m = _KERNEL_SUBJECT.search(message)
        if m is None:
            return None
        what = _KERNEL_WHAT[m.group(1)]
        twice = _LISTED_TWICE.search(message)
        if what == "model" and twice is not None:
            return f"model[{twice.group(1)}].kind"  # the second listing is the extra one
        for w, value, key in self.origins:
            if w == what and value == m.group(2):
                return key
        return None


#: What kernel messages quote: a predicate or a model kind.
_KERNEL_SUBJECT = re.compile(
    r"(fix predicate|prescribed-displacement predicate|material region|model) '([^']*)'"
)
#: The kernel's refusal of a model listed twice, and the index of its second listing.
_LISTED_TWICE = re.compile(r"is listed twice \(models \d+ and (\d+)\)")
_KERNEL_WHAT = {
    "fix predicate": "fix",
    "prescribed-displacement predicate": "prescribed",
    "material region": "region",
    "model": "model",
}


#: The argument of :class:`Simulation` a ``ValueError`` of its checks starts with, and the
#: scene's key for it.
_ARG_KEY = re.compile(r"^(models|regions)\[(\d+)\]((?:\.\w+)?): ")
_ARG_TABLE = {"models": "model", "regions": "material.region"}


def _arg_key(message: str) -> tuple[str | None, str]:
    """The scene's key a refusal of :class:`Simulation`'s arguments names (``models[0].k:
    ...`` is ``model[0].k``) and the rest of the message; None and the whole message when it
    names none."""
    m = _ARG_KEY.match(message)
    if m is None:
        return None, message
    return f"{_ARG_TABLE[m.group(1)]}[{m.group(2)}]{m.group(3)}", message[m.end() :]


def _default_every(steps: int) -> int:
    return max(1, steps // 50)


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


def parse_scene(text: str, path: PathLike | None = None, *, base: PathLike | None = None) -> Scene:
    """A scene from TOML text. ``path`` names the scene in messages (and is its location:
    mesh files are relative to its directory, or to ``base``, or to the working directory).
    Raises :class:`TypeError` when ``text`` is not a str (bytes included: decode them first)."""
    if isinstance(text, (bytes, bytearray, memoryview)):
        raise TypeError(
            f"text: parse_scene takes the TOML text as str, got {type(text).__name__}: decode "
            "it first, e.g. data.decode('utf-8')"
        )
    if not isinstance(text, str):
        raise TypeError(f"text: parse_scene takes the TOML text as str, got {type(text).__name__}")
    p = Path(path) if path is not None else None
    fail = _Fail(str(p) if p is not None else "<scene>")
    base_dir = Path(base) if base is not None else (p.parent if p is not None else None)
    try:
        # (a byte-order mark, which some editors write first, is not TOML)
        data = tomllib.loads(text.removeprefix("\ufeff"))
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

    material = _material(top.table("material"), fail)
    origins = list(material.origins)
    models, set_by, user_models = _models(top.tables("model"), mesh.dimension, base_dir, fail)
    origins += _model_origins(models, user_models, top.tables("model"))
    young, poisson = _young_poisson(material, set_by, fail)

    fixed, prescribed, held, fix_origins, supports = _fixes(top.tables("fix"), fail)
    origins += fix_origins
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
    solver = _solver(integ, kind, fail)
    integ.done(SOLVER_KEYS)
    if kind == "static" and ground is not None:
        raise fail(
            "world.ground",
            "the static integrator does not model contact with the ground (it would balance"
            " the body as if the plane were not there): hold the vertices the ground supports"
            ' ([[fix]]), or use integrator.kind = "implicit_euler"',
        )

    out = top.table("output")
    every_v = out.integer("every", None, minimum=0)
    fields = _output_fields(out, fail)
    out.done()
    events = _events(top.tables("event"), fail)
    fracture = _fracture(top, fail)
    top.done(("fracture", "initial"))  # read with has() when absent

    config: dict[str, Any] = {
        "models": models,
        "density": material.density,
        "young": young,
        "poisson": poisson,
        "damping": material.damping,
        "gravity": list(gravity),
        "fixed": fixed,
        "prescribed": [(w, list(d)) for w, d in prescribed],
        "regions": material.regions,
        "ground": ground,
        "integrator": kind,
        "dt": dt,
        **solver,
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
        conditions={"held": held, "supports": supports, "loads": loads, "initial": initial},
        user_models=user_models,
    )
    scene.check_events()
    return scene


def _solver(integ: _Table, kind: str, fail: _Fail) -> dict[str, Any]:
    """The ``[integrator]`` keys of the linear solver: ``linear_solver``, ``preconditioner``,
    ``tolerance`` (relative residual, in (0, 1)) and ``max_iterations`` (>= 1), as the
    simulation's configuration entries (only those given). Refused for the explicit
    integrators (they solve nothing) and ``preconditioner`` with a solver other than ``pcg``
    or ``auto``."""
    given = [
        k
        for k in ("linear_solver", "preconditioner", "tolerance", "max_iterations")
        if integ.has(k)
    ]
    if given and kind not in _SOLVING:
        raise fail(
            integ.key(given[0]),
            f"only used by the integrators {_or_names(_SOLVING)}, and this scene's is {kind!r}",
        )
    out: dict[str, Any] = {}
    if integ.has("linear_solver"):
        out["linear_solver"] = integ.choice("linear_solver", LINEAR_SOLVERS, "auto")
    if integ.has("preconditioner"):
        out["preconditioner"] = integ.choice("preconditioner", PRECONDITIONERS, "block_jacobi")
        if out.get("linear_solver", "auto") not in ("auto", "pcg"):
            raise fail(
                integ.key("preconditioner"),
                f'only used by linear_solver = "pcg" (or "auto"), and this scene\'s is '
                f"{out['linear_solver']!r}",
            )
    if integ.has("tolerance"):
        tol = integ.number("tolerance", positive=True)
        assert tol is not None
        if not tol < 1.0:
            raise fail(integ.key("tolerance"), f"must be below 1 (a relative residual), got {tol}")
        out["tolerance"] = tol
    if integ.has("max_iterations"):
        out["max_iterations"] = integ.integer("max_iterations", minimum=1)
        if out.get("linear_solver") == "direct":
            raise fail(
                integ.key("max_iterations"),
                'the direct solver iterates nothing (max_iterations applies to "cg", "pcg" '
                'and "auto")',
            )
    if integ.has("tolerance") and not out["tolerance"] >= MIN_TOLERANCE:
        raise fail(
            integ.key("tolerance"),
            f"must be at least {MIN_TOLERANCE:g}, got {out['tolerance']:g} (below it rounding "
            "in f64 arithmetic hides whether a solve reached it)",
        )
    return out


def _n_steps(n: int) -> str:
    """``1 step``, ``n steps``."""
    return f"{n} step" if n == 1 else f"{n} steps"


def _or_names(names: tuple[str, ...]) -> str:
    return " and ".join(repr(n) for n in names)


def load_scene(path: PathLike) -> Scene:
    """Reads a scene file (TOML); ``path`` may also name a shipped scene (see
    :func:`shipped_scenes`). Raises :class:`FileNotFoundError` when it names neither (as
    :func:`find_scene`), :class:`SceneError` naming the key of any problem of the file (a
    mesh or model file it names that does not exist included: that is the scene's key to
    fix)."""
    p = find_scene(path)
    try:
        text = read_text_file(p, "scene file")
    except UnicodeDecodeError as e:
        raise _Fail(str(p))(None, f"not UTF-8 text (byte {e.start})") from None
    except FileNotFoundError:
        raise missing_file(p) from None  # removed since find_scene saw it
    except OSError as e:
        raise _Fail(str(p))(None, f"cannot read the scene file: {e.strerror or e}") from None
    return parse_scene(text, p)


def shipped_scenes() -> dict[str, Path]:
    """The scenes shipped with topomech, by name (``topomech run NAME`` runs one)."""
    d = Path(__file__).parent.with_name("scenes")  # topomech/scenes, beside this package
    return {p.stem: p for p in sorted(d.glob("*.toml"))}


def find_scene(spec: PathLike) -> Path:
    """The scene file ``spec`` names: an existing file, else a shipped scene of that name
    (with or without ``.toml``). Raises :class:`FileNotFoundError` naming ``spec`` and the
    shipped scenes when neither exists, :class:`SceneError` for a directory."""
    p = Path(spec)
    if p.exists():
        if p.is_dir():
            raise _Fail(str(p))(None, "is a directory, not a scene file")
        return p
    shipped = shipped_scenes()
    name = p.name[: -len(".toml")] if p.name.endswith(".toml") else p.name
    if p.parent == Path() and name in shipped:
        return shipped[name]
    close = difflib.get_close_matches(name, shipped, n=3) if p.parent == Path() else []
    hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
    raise missing_file(
        p,
        f"no such scene file, and no shipped scene of that name{hint} "
        f"(shipped: {', '.join(shipped)})",
    )
