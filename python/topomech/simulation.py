"""``topomech.Simulation``: physical models stepped on a copy of a G-map.

Every model is a rule file (see ``crates/physics/models``); a step applies the models' force
rules, sums the forces on each vertex and integrates. The state is the map's embeddings;
per-vertex arrays come out in row order: row k is the particle numbered k by the map's
``particle`` embedding, the input point order for a map built from a mesh (unused points
left out; :meth:`Simulation.point_ids` gives each row's input point). A map without that
numbering (generators, old ``.tmg`` files) gets the vertex orbit order, that of
:meth:`GMap.vertex_labels`. A topology change (cut, fracture, tearing) never renumbers rows:
the vertices it splits off are appended (:class:`TopologyResult`)::

    >>> import topomech
    >>> g = topomech.GMap.from_mesh(
    ...     [[0, 0], [1, 0], [1, 1], [0, 1]], [("triangle", [[0, 1, 2], [0, 2, 3]])]
    ... )
    >>> sim = topomech.Simulation(
    ...     g,
    ...     models=[{"kind": "stretch_elementary", "stiffness": 1e3}],
    ...     density=1.0,
    ...     fixed=["x < 1e-9"],
    ...     integrator="symplectic_euler",
    ...     dt=1e-3,
    ... )
    >>> round(sim.total_mass(), 12)  # density x area
    1.0
    >>> sim.step(10)
    >>> sim.positions().shape, sim.steps
    ((4, 3), 10)

A simulation that cannot be built raises :class:`SimulationError`; a step that diverges
raises :class:`DivergenceError` (with ``step``, ``vertex``: the row in the per-vertex arrays,
and ``point``: that row's input point, which differs from the row where the mesh has points no
cell uses) and leaves the state as it was before that step.
"""

from __future__ import annotations

import operator
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypedDict, Union

import numpy as np
import numpy.typing as npt

from topomech import _core
from topomech._cells import _unmasked, embedding_name, real_array
from topomech._core import DivergenceError, SimulationError
from topomech._gmap import EmbeddingSpec, EmbeddingValues, GMap, as_embedding_array
from topomech._solver_log import SolverWarning
from topomech.models import Model, ParamDefault, model_files_of

if TYPE_CHECKING:
    import scipy.sparse

    from topomech._gmap import PathLike

__all__ = [
    "DivergenceError",
    "ModelInfo",
    "Simulation",
    "SimulationError",
    "TopologyChange",
    "TopologyResult",
    "available_models",
]

#: A model as :class:`Simulation` takes it: its kind alone, ``{"kind": ..., param: value}``
#: (a real number for an ``f64`` parameter, 3 for a ``vec3`` one), or a
#: :class:`topomech.Model`.
ModelArg = Union[str, Mapping[str, Union[str, float, Sequence[float]]], Model]


class ModelInfo(TypedDict):
    """A model topomech ships (:func:`available_models`)."""

    #: The name scenes and :class:`Simulation` use.
    kind: str
    #: The mesh dimensions it exists in (2: surfaces, 3: volumes).
    dims: list[int]
    #: Its parameters with their defaults: a float (``f64``), a list of 3 floats (``vec3``) or
    #: None (required). The continuous models have none: they use the material's ``young``
    #: and ``poisson``.
    params: dict[str, ParamDefault]
    #: What it needs of the mesh (``edges``, ``tetrahedra``).
    needs: str
    #: Whether it is a continuous model, computed per element from the material's ``young``
    #: and ``poisson`` (the springs and bending models take their stiffness instead).
    per_element: bool


class TopologyChange(TypedDict):
    """A topology change that happened during a run (:meth:`Simulation.topology_changes`)."""

    #: The step after which it happened (0: before the first step).
    step: int
    #: The simulated time then.
    time: float
    #: ``cut`` (a timed event or :meth:`Simulation.cut`), ``blade`` (a step of a blade
    #: event, or :meth:`Simulation.cut_swept`) or ``fracture``.
    kind: str
    #: Faces (3D) or edges (2D) unsewn.
    unsewn: int


@dataclass(frozen=True)
class TopologyResult:
    """What a topology change did (:meth:`Simulation.cut`, :meth:`Simulation.fracture`)."""

    #: Faces (3D) or edges (2D) unsewn (0: nothing changed).
    unsewn: int
    #: The rows appended for the vertices the change split off, int64 ``(k,)``, increasing;
    #: each new row's :meth:`Simulation.point_ids` entry is the input point it was split from.
    #: Existing rows never change meaning.
    added_rows: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


def available_models() -> list[ModelInfo]:
    """The models this build of topomech ships, with their parameters' defaults, as dicts
    (:class:`ModelInfo`); ``topomech.Model.shipped(kind)`` gives one as a
    :class:`topomech.Model` (with ``has_jvp`` and the integrators it allows).

    >>> [m["kind"] for m in available_models()][:2]
    ['stretch_elementary', 'stretch_cumulated']
    """
    return [
        ModelInfo(
            kind=m["kind"],
            dims=list(m["dims"]),
            params=dict(m["params"]),
            needs=m["needs"],
            per_element=bool(m["per_element"]),
        )
        for m in _core.models()
    ]


#: The integrators that solve linear systems (the solver keys apply to them only).
_SOLVING = ("implicit_euler", "static")


def _check_solver_keys(cfg: Mapping[str, Any]) -> None:
    """Refuses solver keys that would be ignored: any with an explicit integrator,
    ``preconditioner`` with a solver other than ``pcg`` or ``auto``, ``max_iterations`` with
    ``direct`` (it iterates nothing). Raises :class:`SimulationError` naming the key."""
    given = [
        k for k in ("linear_solver", "preconditioner", "tolerance", "max_iterations") if k in cfg
    ]
    integrator = cfg.get("integrator", "symplectic_euler")
    if given and isinstance(integrator, str) and integrator not in _SOLVING:
        raise SimulationError(
            f"{given[0]}: only used by the integrators 'implicit_euler' and 'static', and "
            f"this simulation's is {integrator!r}"
        )
    solver = cfg.get("linear_solver", "auto")
    if "preconditioner" in cfg and solver not in ("auto", "pcg"):
        raise SimulationError(
            f"preconditioner: only used by linear_solver='pcg' (or 'auto'), not {solver!r}"
        )
    if "max_iterations" in cfg and solver == "direct":
        raise SimulationError(
            "max_iterations: the direct solver iterates nothing (it applies to 'cg', 'pcg' "
            "and 'auto')"
        )


def _index(v: Any, what: str) -> Any:
    """``v`` as a Python int when it is an integer of any kind (numpy's included); left as
    it is otherwise, for the kernel to refuse with its message."""
    if isinstance(v, bool):
        return v
    try:
        return operator.index(v)
    except TypeError:
        return v


def _step_count(n: Any) -> int:
    """``n`` as a number of steps for :meth:`Simulation.step`: an int (numpy's included)
    from 0 to 2**63 - 1, the kernel's count being a signed 64-bit integer (the scenes'
    bound, ``_INT_MAX``, and its message). A bool is refused (``step(True)`` would run one
    step)."""
    from topomech.scene._table import _INT_MAX, _too_large

    if isinstance(n, (bool, np.bool_)):
        raise TypeError(f"n must be an int (a number of steps), got {n!r}")
    try:
        k = operator.index(n)
    except TypeError:
        raise TypeError(f"n must be an int (a number of steps), got {type(n).__name__}") from None
    if k < 0:
        raise ValueError(f"n must be >= 0, got {k}")
    if k > _INT_MAX:
        raise ValueError(f"n {_too_large(k)}")
    return k


def _csr(parts: tuple[Any, Any, Any, int]) -> scipy.sparse.csr_matrix:
    """A ``scipy.sparse.csr_matrix`` from the kernel's ``(indptr, indices, data, n)``."""
    import scipy.sparse

    indptr, indices, data, n = parts
    return scipy.sparse.csr_matrix((data, indices, indptr), shape=(n, n))


def _check_dimensions(models: Any, gmap: Any) -> None:
    """Refuses a :class:`Model` declared for other dimensions than the map's, naming it and
    its file (the kernel would only say that the file's dimension differs)."""
    dim = getattr(gmap, "dimension", None)
    for i, m in enumerate(models):
        if isinstance(m, Model) and isinstance(dim, int) and dim not in m.dimensions:
            dims = " or ".join(f"{d}D" for d in m.dimensions)
            source = f" ({m.file})" if m.file is not None else ""
            raise SimulationError(
                f"models[{i}]: model '{m.name}'{source} runs on {dims} maps, this map is {dim}D"
            )


def _check_as_scene(cfg: Mapping[str, Any], gmap: Any, model_files: Any = None) -> None:
    """Refuses, with ``ValueError`` naming the argument (``models[0].stiffness: must be >=
    0, got -5.0``), what a scene refuses and the kernel does not: a shipped model's
    parameter out of its range, a region that sets no material value. The checks are the
    scene's own (:mod:`topomech.scene`), so that the two cannot drift apart. ``model_files``:
    the user's rule files given with the configuration (:func:`_model_files_arg`); a shipped
    model's name that they declare is the user's model, left to the kernel."""
    from topomech.scene._material import check_region_args
    from topomech.scene._models import check_model_args, user_model_names

    models, regions = cfg.get("models"), cfg.get("regions")
    if isinstance(models, (list, tuple)):
        dim = getattr(gmap, "dimension", None)
        user = user_model_names(models, model_files)
        check_model_args(models, dim if isinstance(dim, int) else None, user)
    if isinstance(regions, (list, tuple)):
        check_region_args(regions)


def _model_files_arg(*wheres: Mapping[str, Any] | None) -> Any:
    """The ``model_files`` given in ``config`` and the keyword arguments together: None when
    neither gives one, else their pairs in one list (or the first value that is not a list
    or a tuple, which the kernel refuses)."""
    found = [w["model_files"] for w in wheres if w is not None and w.get("model_files") is not None]
    if not found:
        return None
    for f in found:
        if not isinstance(f, (list, tuple)):
            return f
    return [pair for f in found for pair in f]


class Simulation:
    """Physical models on a copy of a G-map, stepped in time.

    ``config`` (a dict) or keyword arguments, mirroring the kernel's configuration (a key
    given ``None`` keeps its default: no ground, no events, no fracture, ...):

    - ``models``: a list of model kinds, dicts ``{"kind": ..., param: value}`` (a real
      number for an ``f64`` parameter, a sequence of 3 for a ``vec3`` one;
      :func:`available_models` lists the shipped ones with their parameters), or
      :class:`topomech.Model` objects (``Model.load("anchor.tmr").with_params(k=5.0)``: a
      model from the user's rule file, whose text is passed on as ``model_files``);
    - ``model_files``: ``(file name, text)`` pairs of the user's rule files declaring the
      models named by kind (filled in from :class:`topomech.Model` objects);
    - ``density`` (per volume in 3D, per area in 2D), ``young``, ``poisson`` (the material of
      the continuous models), ``damping`` (viscous, 1/s), ``gravity`` (3 numbers);
    - ``fixed``: predicates on the rest position ``x``, ``y``, ``z`` in the rule language
      (``"x < 1e-9"``, ``"y > 0.99 && x < 0.01"``) selecting vertices held in place;
    - ``prescribed``: ``(predicate, [dx, dy, dz])`` pairs holding vertices at a displacement
      from their rest position;
    - ``regions``: dicts ``{"where": predicate on the element's rest centroid, "density":
      ..., "young": ..., "poisson": ...}`` giving some elements another material;
    - ``ground``: a ground plane, or None: ``{"point": [x, y, z], "normal": [nx, ny, nz]}``
      (the normal points to the side bodies stay on; without it, the opposite of gravity, or
      +y without gravity), or a number ``h``: the plane at height ``h`` along that default
      normal (``y = h`` under gravity along -y, ``z = h`` under gravity along -z). A free
      vertex that goes below it is put back onto it and loses its velocity into it;
    - ``integrator``: ``explicit_euler``, ``symplectic_euler``, ``implicit_euler`` or
      ``static`` (each step solves for the equilibrium); ``dt``: the time step;
    - ``linear_solver`` (``implicit_euler`` and ``static``): ``"cg"`` (conjugate gradients on
      the models' Jacobian-vector products, matrix-free), ``"pcg"`` (the same, preconditioned
      by ``preconditioner``: ``"block_jacobi"``, the default, or ``"jacobi"``), ``"direct"``
      (the Jacobian assembled into a sparse matrix and factored by faer's sparse Cholesky)
      or ``"auto"`` (the default: chosen by the integrator and the size, see the README's
      Solvers section); ``tolerance``: the relative residual a solve must reach (implicit
      Euler: of its linear system, default 1e-6; static: of the force balance, default
      1e-10); ``max_iterations``: the most iterations of the iterative linear solver in
      one solve;
    - ``events``: topology changes at given times, dicts ``{"time": t, "kind": "cut",
      "plane": {"normal": [nx, ny, nz], "offset": o}}`` (elements whose centroids lie on
      opposite sides of the plane ``normal . x = offset`` are separated) or ``{"time": t,
      "kind": "cut", "where": predicate}`` (a predicate on the centroid ``x``, ``y``, ``z``
      of the face, in 3D, or edge, in 2D, shared by two elements). An event happens after
      the first step that reaches its time; one that separates nothing makes that step raise
      :class:`SimulationError` (``... misses the object``);
    - ``fracture``: ``{"criterion": "stress" | "strain", "threshold": x}``, tested after
      every step: ``stress`` opens a face between two tetrahedra whose mean largest
      principal stress exceeds ``x`` (Pa, 3D only), ``strain`` a face whose edges' mean
      spring strain ``l / l0 - 1`` exceeds ``x`` (3D), or an edge whose strain does (2D:
      tearing).

    After a topology change the vertices on the opened faces or edges are split (their
    copies keep the position and velocity and get new rows at the end), so
    :attr:`n_vertices` grows; existing rows keep their meaning and the total mass stays the
    same.

    Rows are particles: a pinched input vertex kept as one particle (its cells touch only at
    it, built with ``pinched="merge"``) is one row made of several vertex orbits of the map;
    they move together, and its mass and force are the sums over them.

    The kernel object is :attr:`core`.
    """

    __slots__ = ("_core",)

    def __init__(
        self,
        gmap: GMap | _core.GMap,
        config: Mapping[str, Any] | None = None,
        **kwargs: Any,
    ) -> None:
        if config is not None and not isinstance(config, Mapping):
            # (a list of models passed where the configuration goes, say)
            raise TypeError(
                f"config: expected a mapping of configuration keys (models, dt, ...), got a "
                f"{type(config).__name__}; models go in config['models'] or models=[...]"
            )
        cfg = dict(config) if config is not None else None
        _check_solver_keys({**(cfg or {}), **kwargs})
        given_files = _model_files_arg(cfg, kwargs)
        for where in (cfg, kwargs):
            if where is not None and "max_iterations" in where:
                where["max_iterations"] = _index(where["max_iterations"], "max_iterations")
            if where is not None:
                _check_as_scene(where, gmap, given_files)
            if where is not None and isinstance(where.get("models"), (list, tuple)):
                _check_dimensions(where["models"], gmap)
                models, files = model_files_of(list(where["models"]))
                where["models"] = models
                if files:
                    where["model_files"] = [*where.get("model_files", []), *files]
        self._core = _core.Simulation(gmap, cfg, **kwargs)

    @classmethod
    def from_core(cls, core: _core.Simulation) -> Simulation:
        """Wraps a kernel simulation."""
        if not isinstance(core, _core.Simulation):
            raise TypeError(f"expected a topomech._core.Simulation, got {type(core).__name__}")
        sim = cls.__new__(cls)
        sim._core = core
        return sim

    @classmethod
    def from_scene(cls, path: PathLike) -> Simulation:
        """The simulation a scene file (TOML) describes: ``load_scene(path).build()``.
        Raises :class:`FileNotFoundError` for a scene file that does not exist,
        :class:`SceneError` for a refused scene."""
        from topomech.scene import load_scene

        return load_scene(path).build()

    # ------------------------------------------------------------------ stepping

    def step(self, n: int = 1) -> None:
        """Runs ``n`` time steps; raises :class:`DivergenceError` on divergence, and when a
        ``static`` step's solve does not converge or an ``implicit_euler`` step's linear
        system breaks down (not positive definite, singular; the message gives the relative
        residual and the tolerance; :meth:`solver_report` the details). The state is then the
        one before the failed step. An ``implicit_euler`` step whose ``cg``/``pcg`` stops at
        ``max_iterations`` above its tolerance is taken with the approximate solution and
        raises one :class:`topomech.SolverWarning` for the call. ``n`` is an int from 0 to
        2**63 - 1 (:class:`TypeError` for another type, a bool included;
        :class:`ValueError` outside that range)."""
        n = _step_count(n)
        report = self._core.solver_report()
        before = report["not_converged_steps"] if report is not None else 0
        self._core.step(n)
        report = self._core.solver_report()
        if report is not None and report["not_converged_steps"] > before:
            warnings.warn(
                f"{report['not_converged_steps'] - before} of the {n} steps did not reach "
                f"the tolerance {report['tolerance']:g} (the last: relative residual "
                f"{report['relative_residual']:.3e} with {report['linear_solver']}): they "
                "used the approximate solution found; raise max_iterations, or use "
                "linear_solver='direct'",
                SolverWarning,
                stacklevel=2,
            )

    # ------------------------------------------------------------------ topology

    def cut(self, normal: Any, offset: float) -> TopologyResult:
        """Cuts now along the plane ``normal . x = offset`` (``normal``: 3 numbers, not all
        zero; ``offset`` in the positions' unit): every face (3D) or edge (2D) between two
        elements whose centroids lie on opposite sides is unsewn and the vertices on it split
        (a centroid whose distance to the plane is within 1e-12 of the other's counts as on
        the plane, as for a blade: rounding does not open part of the faces of a plane
        through centroids). Returns a :class:`TopologyResult`: how many faces or edges were
        unsewn (0 when the plane misses the object; nothing changes then) and the rows
        appended for the split vertices. Raises :class:`TypeError` / :class:`ValueError` for
        a bad argument."""
        unsewn, added = self._core.cut(normal, offset)
        return TopologyResult(unsewn=int(unsewn), added_rows=np.asarray(added, dtype=np.int64))

    def cut_swept(self, start: Any, end: Any) -> TopologyResult:
        """Cuts now along the quad a blade sweeps moving from the segment ``start`` to the
        segment ``end`` (each 2 points ``[[x, y, z], [x, y, z]]``, in the positions' unit):
        every face (3D) or edge (2D) between two elements whose current centroids the quad
        separates (the segment between them crosses it) is unsewn and the vertices on it
        split. A segment that turns between ``start`` and ``end`` (its end points move
        linearly) sweeps a ruled surface: the sweep is cut into strips in which it turns by
        at most 1 degree, each tested as a quad, so one call cuts what many smaller sweeps of
        the same motion cut. Elements are separated along their faces, never split. A blade
        running during the run is an event (``{"kind": "blade", "start": t0, "end": t1, "from": ...,
        "to": ...}`` in ``events``; a scene's ``[[event]] kind = "blade"``), which cuts along
        what it sweeps each step. Returns a :class:`TopologyResult` (0 unsewn when it crosses
        nothing); raises :class:`TypeError` / :class:`ValueError` for points that are not 2
        finite 3-vectors, and :class:`SimulationError` for a segment whose two points
        coincide, coordinates beyond 1e100 in magnitude, or a sweep of nothing, refused as a
        blade event's is: ``end`` the same segment as ``start`` (``its segment must move:
        ... so it would sweep nothing``), or the four points on one line (the segment
        sliding along itself). A quad far thinner than it is long (its width below about
        1e-12 of its length) is tested with a relative tolerance that treats its thin
        triangle as degenerate: faces it crosses may stay sewn."""
        unsewn, added = self._core.cut_swept(start, end)
        return TopologyResult(unsewn=int(unsewn), added_rows=np.asarray(added, dtype=np.int64))

    def prepare_cuts(self) -> None:
        """Builds now what cuts search the faces (3D) or edges (2D) with: the compiled
        guards of :meth:`cut` and :meth:`cut_swept` (one row per face side, about the cost of
        setting up one step rule each). Cuts then only run and patch them; the first cut
        builds them otherwise. A simulation builds those of the cuts, blades and fracture its
        configuration declares when it is set up. Call it before an interactive session's
        first cut; cuts give the same results either way, bit for bit."""
        self._core.prepare_cuts()

    def fracture(self, criterion: str, threshold: float) -> TopologyResult:
        """Opens now every face (3D) or edge (2D) where ``criterion`` (``"stress"`` or
        ``"strain"``, see the ``fracture`` setting) exceeds ``threshold``; returns a
        :class:`TopologyResult` (how many were opened, the rows appended). The stress
        criterion (the mean of the two tetrahedra's largest principal stresses, Pa) needs
        tetrahedra and the FEM rules: a simulation built with a stress ``fracture`` or with
        an FEM model (``corotational``, ``linear_fem``, ...) has them; a surface, or a 3D
        simulation with springs only, raises :class:`SimulationError` saying which, and so
        does a mesh with volumes that are not tetrahedra, which would never open by stress
        (as a configured stress ``fracture`` is refused when the simulation is built)."""
        unsewn, added = self._core.fracture(criterion, threshold)
        return TopologyResult(unsewn=int(unsewn), added_rows=np.asarray(added, dtype=np.int64))

    def solver_report(self) -> dict[str, Any] | None:
        """What the solve of the last ``static`` or ``implicit_euler`` step did: a dict with
        ``integrator``, ``iterations`` (Newton iterations over every load increment, or
        conjugate-gradient iterations), ``residual`` (the norm of the residual force on the
        free vertices, or of the linear system), ``relative_residual`` (divided by the load),
        ``tolerance``, ``converged``, ``load_steps`` (the load increments the static solve
        took: more than 1 when automatic load stepping was needed), ``load_fraction`` (of
        the load reached), ``worst_relative_residual`` (over every step so far),
        ``load_stepped_steps`` (how many steps needed load stepping), ``linear_solver``,
        ``preconditioner``, ``linear_iterations`` and ``jacobian`` (``rules``, or
        ``finite_differences`` for a static solve the models' ``jvp`` rules did not bring to
        balance, taken again on central differences of the forces). None before the first
        such step and for the explicit integrators. After a step that raised
        :class:`DivergenceError` it describes that step."""
        return self._core.solver_report()

    def stiffness_matrix(self) -> scipy.sparse.csr_matrix:
        """The stiffness matrix ``K = -df/dx`` of the models' forces at the current positions,
        a ``scipy.sparse.csr_matrix`` of shape ``(3 V, 3 V)`` (N/m), degree of freedom
        ``3 * row + axis`` (rows as :meth:`positions`; fixed vertices included: drop their
        rows and columns, ``~np.repeat(sim.fixed(), 3)``, for a constrained problem).
        Assembled from the models' Jacobian-vector-product rules (the same ones the
        solvers use) by compressed probing (Curtis, Powell & Reid 1974, "On the estimation of
        sparse Jacobian matrices", IMA J. Appl. Math. 13, doi:10.1093/imamat/13.1.117), so it
        is exactly the operator the ``cg``/``pcg`` solvers apply. Symmetric for the shipped
        models; the co-rotational models give the warped stiffness ``R K R^T`` (dR/dx
        omitted, as in their implicit solves). Raises :class:`SimulationError` when a model
        has no Jacobian-vector-product rules."""
        return _csr(self._core.stiffness_matrix())

    def mass_matrix(self) -> scipy.sparse.csr_matrix:
        """The lumped mass matrix, a diagonal ``scipy.sparse.csr_matrix`` of shape
        ``(3 V, 3 V)`` (kg): each row's mass (:meth:`masses`) on its 3 degrees of freedom.
        With :meth:`stiffness_matrix` it gives the generalized eigenproblem ``K u = w^2 M u``
        of modal analysis (see the README's Solvers section)."""
        return _csr(self._core.mass_matrix())

    def topology_changes(self) -> list[TopologyChange]:
        """The topology changes so far, in order."""
        return [
            TopologyChange(
                step=int(c["step"]),
                time=float(c["time"]),
                kind=str(c["kind"]),
                unsewn=int(c["unsewn"]),
            )
            for c in self._core.topology_changes()
        ]

    # ------------------------------------------------------------------ state

    @property
    def core(self) -> _core.Simulation:
        """The kernel object."""
        return self._core

    def positions(self) -> npt.NDArray[np.float64]:
        """Current positions ``(V, 3)``."""
        return self._core.positions()

    def velocities(self) -> npt.NDArray[np.float64]:
        """Current velocities ``(V, 3)``."""
        return self._core.velocities()

    def rest_positions(self) -> npt.NDArray[np.float64]:
        """Rest positions ``(V, 3)``: the positions when the simulation was built."""
        return self._core.rest_positions()

    def displacements(self) -> npt.NDArray[np.float64]:
        """Positions minus rest positions ``(V, 3)``."""
        return self._core.positions() - self._core.rest_positions()

    def forces(self) -> npt.NDArray[np.float64]:
        """The models' forces plus the external loads (:meth:`external_forces`) on each
        vertex at the current state ``(V, 3)``, computed now (without gravity and viscous
        damping; summed over the orbits of a row)."""
        return self._core.forces()

    def set_external_forces(self, forces: Any) -> None:
        """Sets the external loads ``f_ext`` (N), an array-like ``(V, 3)`` of finite numbers:
        constant (dead) forces added to the models' forces at every step, and balanced by the
        ``static`` integrator. They replace the loads set before. :mod:`topomech.loads` makes
        them from point forces, tractions and pressures. When a cut or fracture splits a
        vertex, its load is divided equally between the copies (the total is kept). Raises
        :class:`ValueError` for a wrong shape, a non-finite value (naming the row) or masked
        entries (of a numpy masked array), :class:`TypeError` for values that are not real
        numbers (complex, booleans, dates, strings)."""
        self._core.set_external_forces(real_array(forces, "external forces"))

    def external_forces(self) -> npt.NDArray[np.float64]:
        """The external loads ``f_ext`` ``(V, 3)`` (N); zeros unless set."""
        return self._core.external_forces()

    def masses(self) -> npt.NDArray[np.float64]:
        """Lumped vertex masses ``(V,)`` (summed over the orbits of a row)."""
        return self._core.masses()

    def fixed(self) -> npt.NDArray[np.bool_]:
        """Whether each vertex is held (fixed or at a prescribed displacement) ``(V,)``."""
        return self._core.fixed()

    def point_ids(self) -> npt.NDArray[np.int64]:
        """The input point index of each row, int64 ``(V,)`` (-1 for none). A row appended by
        a topology change has the point it was split from."""
        return self._core.point_ids()

    def elements(self) -> tuple[npt.NDArray[np.int64], list[npt.NDArray[np.int64]]]:
        """Every element (volume in 3D, face in 2D), in the map's order: the index of the
        input cell each was built from, int64 ``(E,)`` (-1 when unknown), and each element's
        vertex rows, int64 arrays (VTK order for volumes, oriented so that the rest volume is
        positive; the face's cycle in 2D)."""
        ids, rows = self._core.elements()
        return ids, list(rows)

    def set_fixed(self, mask: Any) -> None:
        """Holds the rows where ``mask`` (bool ``(V,)``) is true in place, with zero velocity
        (a moving vertex held stops), frees the others (keeping their velocity). Raises
        :class:`ValueError` for a wrong shape and :class:`SimulationError` when it would free
        a vertex without mass (naming them); :class:`ValueError` also for masked entries of
        a numpy masked array."""
        a = np.asarray(_unmasked(mask, "mask"))
        if a.dtype != np.bool_:
            raise TypeError(f"mask must be an array of bool, got dtype {a.dtype}")
        self._core.set_fixed(np.asarray(a, order="C"))

    def set_vertex_field(self, name: str, values: Any) -> None:
        """Writes the vertex embedding ``name`` from one value per row: ``(V,)`` numbers for an
        ``f64`` embedding, ``(V, 3)`` for a ``vec3`` one, ``(V,)`` bools for a ``bool`` one
        (every orbit of a row gets the row's value; a force embedding, ``f_*``, is the row's
        total and goes to its first orbit alone). An embedding the rules declare but the map
        does not hold yet is added. Raises :class:`SimulationError` for an unknown, derived or
        non-vertex embedding or non-finite values (naming the rows), :class:`TypeError` for
        booleans given for a number embedding or numbers for a bool one, and
        :class:`ValueError` for a wrong shape (naming the shape the embedding's type takes)
        or masked entries of a numpy masked array."""
        name = embedding_name(name)
        a = np.asarray(_unmasked(values, f"values for {name!r}"))
        if a.dtype != np.bool_:
            a = real_array(a, f"values for {name!r}")
        self._core.set_vertex_field(name, np.asarray(a, order="C"))

    def set_positions(self, positions: Any) -> None:
        """Sets the positions from an array-like ``(V, 3)`` of finite real numbers (complex
        values, booleans, dates and strings raise :class:`TypeError`; masked entries of a
        numpy masked array :class:`ValueError`)."""
        self._core.set_positions(real_array(positions, "positions"))

    def set_velocities(self, velocities: Any) -> None:
        """Sets the velocities from an array-like ``(V, 3)`` of finite real numbers (complex
        values, booleans, dates and strings raise :class:`TypeError`; masked entries of a
        numpy masked array :class:`ValueError`). A held vertex keeps zero velocity: a
        non-zero one for a held row raises :class:`SimulationError` naming the rows, and
        nothing is set."""
        self._core.set_velocities(real_array(velocities, "velocities"))

    def vertex_field(self, name: str) -> npt.NDArray[Any]:
        """The values of a vertex embedding, one row per vertex (the rows of
        :meth:`positions`) (``(V,)`` for scalars,
        ``(V, 3)`` for ``vec3``, ``(V, R, C)`` for matrices; masses and forces, ``mass``,
        ``force``, ``f_*``, summed over the orbits of a row). An unknown name, or an embedding
        on another orbit, raises :class:`EmbeddingError`; :meth:`embedding` reads any
        embedding, one row per orbit; :meth:`set_vertex_field` writes one row per vertex."""
        return self._core.embedding(embedding_name(name))

    def embedding(self, name: str) -> EmbeddingValues:
        """The embedding ``name`` of the simulated map, one row per orbit of its orbit type,
        as :meth:`GMap.embedding` returns it: ``(values, darts, orbit)``, rows in increasing
        order of each orbit's smallest dart (not the per-vertex row order of
        :meth:`vertex_field`). It reads what no per-vertex array shows: a force on each corner
        of an element (``f_corot`` on ``<1,2>`` in 3D), a per-element stiffness (``k_elem``,
        ``(E, 12, 12)``), a volume. Raises :class:`KeyError` for an unknown name, listing the
        embeddings; :class:`TypeError` for a name that is not a str."""
        return EmbeddingValues(*self._core.orbit_embedding(embedding_name(name)))

    def set_embedding(self, name: str, values: Any) -> None:
        """Writes every value of the stored embedding ``name`` in the layout of
        :meth:`embedding` (as :meth:`GMap.set_embedding`); derived embeddings (the
        vertex ``mass``, a sum of ``corner_mass``) are recomputed and the next step starts
        from the values written. What a model's init rules computed once at set-up from an
        embedding is not computed again: writing ``young`` or ``poisson`` after set-up
        changes no stiffness of the FEM models (their ``k_elem``, ``t_vertex``, ``t_edge``...,
        computed from them then); write those, or build a new simulation. Nothing is written
        when it raises: :class:`KeyError`,
        :class:`TypeError`, :class:`ValueError` and :class:`EmbeddingError` as
        :meth:`GMap.set_embedding`; :class:`ValueError` also when the orbits of one particle
        (a pinched vertex kept as one row) would get different positions, velocities or other
        shared vertex values; :class:`SimulationError` for the embeddings that number rows
        and elements (``particle``, ``point_id``, ``cell_id``, ``vertex0``, ``face0``);
        :class:`ValueError` for values no material has: a ``density``, ``young`` or
        ``corner_mass`` not positive, a ``poisson`` outside (-1, 0.5), naming the value and
        its row; :class:`SimulationError` for a non-zero velocity given to a held vertex
        (``velocity``; a held vertex keeps zero velocity), and ``fixed`` holds as
        :meth:`set_fixed` does (stopping the vertices it holds)."""
        name = embedding_name(name)
        specs = {s.name: s for s in self.embeddings()}
        self._core.set_orbit_embedding(name, as_embedding_array(specs.get(name), values))

    def embeddings(self) -> list[EmbeddingSpec]:
        """Every embedding of the simulated map: name, type, orbit type and whether it is
        derived, in declaration order."""
        return [EmbeddingSpec(*e) for e in self._core.embeddings()]

    def total_mass(self) -> float:
        """Sum of the vertex masses."""
        return self._core.total_mass()

    def kinetic_energy(self) -> float:
        """Sum of m |v|^2 / 2."""
        return self._core.kinetic_energy()

    def momentum(self) -> npt.NDArray[np.float64]:
        """Sum of m v ``(3,)``."""
        return self._core.momentum()

    def gmap(self) -> GMap:
        """A copy of the simulated map with every embedding (positions as they are now)."""
        return GMap(self._core.gmap())

    @property
    def time(self) -> float:
        """Simulated time."""
        return self._core.time

    @property
    def steps(self) -> int:
        """Steps done."""
        return self._core.steps

    @property
    def n_vertices(self) -> int:
        """The number of vertices V: the rows of every per-vertex array (particles)."""
        return self._core.n_vertices

    @property
    def dimension(self) -> int:
        """2 (surface) or 3 (volume)."""
        return self._core.dimension

    @property
    def dt(self) -> float:
        """The time step."""
        return self._core.dt

    @property
    def topology_version(self) -> int:
        """Changes whenever a topology change (a cut, a fracture) relinks the map's darts."""
        return self._core.topology_version

    @property
    def integrator(self) -> str:
        """The integrator's name."""
        return self._core.integrator

    def __repr__(self) -> str:
        return (
            f"topomech.Simulation(dimension={self.dimension}, vertices={self.n_vertices}, "
            f"integrator={self.integrator!r}, steps={self.steps}, time={self.time:g})"
        )

    def _repr_html_(self) -> str:
        """Jupyter's view: a summary table and the current mesh in the viewer
        (:func:`topomech.notebook.simulation_html`)."""
        from topomech.notebook import simulation_html

        return simulation_html(self)
