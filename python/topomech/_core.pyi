"""The native kernel of topomech (Rust, PyO3). See the ``topomech`` package for the friendly API."""

import os
from collections.abc import Mapping, Sequence
from typing import Any, Protocol, final

import numpy as np
import numpy.typing as npt

__all__ = [
    "ApplyError",
    "BusyError",
    "DivergenceError",
    "EmbeddingError",
    "FileFormatError",
    "GMap",
    "InternalError",
    "MeshError",
    "MeshReadError",
    "RuleError",
    "RuleSet",
    "SceneError",
    "Simulation",
    "SimulationError",
    "TopologyError",
    "TopomechError",
    "__version__",
    "_malloc_tuned",
    "_panic_for_tests",
    "blade_sweep_problem",
    "box",
    "check_predicate",
    "eval_expression",
    "eval_predicate",
    "grid",
    "models",
]

__version__: str
#: Whether importing the module turned glibc malloc's fast bins off (Linux with glibc, unless
#: ``GLIBC_TUNABLES`` sets ``mxfast``): see the README's "Memory allocator".
_malloc_tuned: bool

_Path = str | os.PathLike[str]
_FlatMesh = tuple[npt.NDArray[np.float64], list[str], npt.NDArray[np.int64], npt.NDArray[np.int64]]
_FlatPolyhedra = tuple[
    npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]
]

class TopomechError(Exception):
    """Base class of every error raised by topomech."""

class MeshError(TopomechError):
    """A mesh that cannot become a G-map; the message names the cells or points. `option` is
    the `(name, value)` of the build option that would accept the mesh, or `None`."""

    option: tuple[str, str] | None

class MeshReadError(TopomechError):
    """A mesh file that cannot be read: unreadable, or not a mesh (a missing file raises
    FileNotFoundError)."""

class TopologyError(TopomechError):
    """A refused operation on darts, links or orbits, or a map that breaks an invariant."""

class EmbeddingError(TopomechError):
    """A refused operation on an embedding (unknown name, wrong type, stale derived value)."""

class FileFormatError(TopomechError):
    """A .tmg file that cannot be written or read back."""

class RuleError(TopomechError):
    """A rule file refused by the checker; the message has one line per error."""

    #: The errors, one ``FILE:LINE:COL: error[CONDITION]: message`` line each.
    diagnostics: list[str]
    #: The warnings, one ``FILE:LINE:COL: warning[CONDITION]: message`` line each.
    warnings: list[str]

class ApplyError(TopomechError):
    """A rule that does not apply (no match, wrong hooks or parameters); the map is unchanged."""

class SimulationError(TopomechError):
    """A simulation that cannot be built (unknown model, a model or predicate that matches
    nothing, a bad setting) or a step that fails."""

class DivergenceError(SimulationError):
    """A step that produced non-finite values; the state before the step is kept."""

    #: The step that failed (1-based).
    step: int
    #: The vertex (its row in the per-vertex arrays) where it was found, or None when the
    #: failure is a global linear solve's (no vertex means anything).
    vertex: int | None
    #: That row's input point (its index in the imported mesh's points, which differs from
    #: the row where the mesh has points no cell uses), or None where unknown (no vertex, a
    #: map without input numbering, a vertex a rule created).
    point: int | None
    #: What happened.
    why: str

class SceneError(TopomechError):
    """A scene file that is refused; the message names the key (e.g. ``integrator.dt``)."""

    #: The key's path (``integrator.dtt``, ``model[1].kind``), or None for the whole scene.
    key: str | None
    #: The scene file (or ``<scene>`` for a scene parsed from text).
    source: str

class BusyError(TopomechError):
    """A map or simulation used while another thread is using it (a call on it that runs
    without the GIL, such as ``Simulation.step`` or ``RuleSet.apply``, has not returned)."""

class InternalError(TopomechError):
    """A bug in topomech (a Rust panic, caught at the boundary). Please report it."""

@final
class GMap:
    """A generalized map of dimension 2 (surfaces) or 3 (volumes)."""

    @staticmethod
    def from_flat(
        points: npt.NDArray[np.float64],
        kinds: list[str],
        offsets: npt.NDArray[np.int64],
        connectivity: npt.NDArray[np.int64],
        reorient: bool = True,
        pinched: str = "merge",
        duplicates: str = "refuse",
    ) -> tuple[GMap, dict[str, Any]]: ...
    @staticmethod
    def load(path: _Path) -> GMap: ...
    @staticmethod
    def from_bytes(data: bytes) -> GMap: ...
    def save(self, path: _Path) -> None: ...
    def to_bytes(self) -> bytes: ...
    @property
    def dimension(self) -> int: ...
    @property
    def n_darts(self) -> int: ...
    @property
    def version(self) -> int: ...
    def cell_counts(self) -> dict[str, int]: ...
    def is_valid(self) -> bool: ...
    def violations(self) -> list[str]: ...
    def positions(self) -> npt.NDArray[np.float64]: ...
    def vertex_labels(self) -> npt.NDArray[np.int64]: ...
    def to_flat(self) -> _FlatMesh: ...
    def to_polyhedra(self) -> _FlatPolyhedra: ...
    def alpha(self, i: int, dart: int) -> int: ...
    def orbit(self, dart: int, orbit: str) -> npt.NDArray[np.int64]: ...
    def sew(self, i: int, a: int, b: int) -> None: ...
    def unsew(self, i: int, a: int) -> None: ...
    def embedding(self, name: str) -> tuple[npt.NDArray[Any], npt.NDArray[np.int64], str]: ...
    def set_embedding(self, name: str, values: npt.NDArray[Any]) -> None: ...
    def embeddings(self) -> list[tuple[str, str, str, bool]]: ...
    def embedding_names(self) -> list[str]: ...
    def embedding_info(self, name: str) -> dict[str, Any]: ...
    def int_embedding(self, name: str) -> npt.NDArray[np.int64]: ...
    def memory_bytes(self) -> int: ...

class _HasCore(Protocol):
    """A wrapper of a kernel map, such as ``topomech.GMap``."""

    @property
    def core(self) -> GMap: ...

@final
class RuleSet:
    """Rules loaded from rule files (``.tmr``) and checked."""

    @staticmethod
    def load(paths: Sequence[_Path], dimension: int | None = None) -> RuleSet: ...
    @staticmethod
    def from_source(text: str, name: str = "<string>", dimension: int | None = None) -> RuleSet: ...
    @staticmethod
    def from_sources(
        sources: Sequence[tuple[str, str]], dimension: int | None = None
    ) -> RuleSet: ...
    @staticmethod
    def file_dimensions(text: str) -> list[int]: ...
    @staticmethod
    def from_model_sources(
        sources: Sequence[tuple[str, str]], dimension: int | None = None
    ) -> RuleSet: ...
    @staticmethod
    def library(dimension: int) -> RuleSet: ...
    @property
    def dimension(self) -> int: ...
    @property
    def warnings(self) -> list[str]: ...
    def rule_names(self) -> list[str]: ...
    def rule_info(self, name: str) -> dict[str, Any]: ...
    def models(self) -> list[dict[str, Any]]: ...
    def apply(
        self,
        gmap: GMap | _HasCore,
        name: str,
        at: int | Sequence[int] | None = None,
        params: Mapping[str, Any] | None = None,
    ) -> dict[str, int]: ...
    def count_matches(
        self, gmap: GMap | _HasCore, name: str, params: Mapping[str, Any] | None = None
    ) -> int: ...

@final
class Simulation:
    """Physical models on a copy of a G-map, stepped in time."""

    def __new__(
        cls, gmap: GMap | _HasCore, config: Mapping[str, Any] | None = None, **kwargs: Any
    ) -> Simulation: ...
    def step(self, n: int = 1) -> None: ...
    def cut(
        self, normal: Sequence[float] | npt.NDArray[np.float64], offset: float
    ) -> tuple[int, npt.NDArray[np.int64]]: ...
    def cut_swept(self, start: Any, end: Any) -> tuple[int, npt.NDArray[np.int64]]: ...
    def prepare_cuts(self) -> None: ...
    def fracture(self, criterion: str, threshold: float) -> tuple[int, npt.NDArray[np.int64]]: ...
    def solver_report(self) -> dict[str, Any] | None: ...
    def stiffness_matrix(
        self,
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.float64], int]: ...
    def mass_matrix(
        self,
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.float64], int]: ...
    def topology_changes(self) -> list[dict[str, Any]]: ...
    def positions(self) -> npt.NDArray[np.float64]: ...
    def velocities(self) -> npt.NDArray[np.float64]: ...
    def rest_positions(self) -> npt.NDArray[np.float64]: ...
    def forces(self) -> npt.NDArray[np.float64]: ...
    def masses(self) -> npt.NDArray[np.float64]: ...
    def fixed(self) -> npt.NDArray[np.bool_]: ...
    def point_ids(self) -> npt.NDArray[np.int64]: ...
    def elements(self) -> tuple[npt.NDArray[np.int64], list[npt.NDArray[np.int64]]]: ...
    def set_fixed(self, mask: npt.NDArray[np.bool_]) -> None: ...
    def set_vertex_field(
        self, name: str, values: npt.NDArray[np.float64] | npt.NDArray[np.bool_]
    ) -> None: ...
    def set_positions(self, positions: npt.NDArray[np.float64]) -> None: ...
    def set_velocities(self, velocities: npt.NDArray[np.float64]) -> None: ...
    def set_external_forces(self, forces: npt.NDArray[np.float64]) -> None: ...
    def external_forces(self) -> npt.NDArray[np.float64]: ...
    def total_mass(self) -> float: ...
    def kinetic_energy(self) -> float: ...
    def momentum(self) -> npt.NDArray[np.float64]: ...
    def embedding(self, name: str) -> npt.NDArray[Any]: ...
    def orbit_embedding(self, name: str) -> tuple[npt.NDArray[Any], npt.NDArray[np.int64], str]: ...
    def set_orbit_embedding(self, name: str, values: npt.NDArray[Any]) -> None: ...
    def embeddings(self) -> list[tuple[str, str, str, bool]]: ...
    def gmap(self) -> GMap: ...
    @property
    def time(self) -> float: ...
    @property
    def steps(self) -> int: ...
    @property
    def n_vertices(self) -> int: ...
    @property
    def dimension(self) -> int: ...
    @property
    def dt(self) -> float: ...
    @property
    def topology_version(self) -> int: ...
    @property
    def integrator(self) -> str: ...

def models() -> list[dict[str, Any]]:
    """The models topomech ships: ``kind``, ``dims``, ``params`` (``{name: default}``, a
    default a float, a list of 3 floats or None for a required parameter), ``param_types``
    (``{name: "f64" | "vec3"}``), ``needs``, ``has_jvp``."""

def blade_sweep_problem(
    start: Sequence[Sequence[float]], end: Sequence[Sequence[float]]
) -> str | None:
    """Why a blade whose segment ``start`` moves to ``end`` sweeps nothing (it does not move,
    or its four points lie on one line), or None: the kernel's test of blade events."""

def check_predicate(text: str, label: str = "predicate") -> None:
    """Checks a predicate on the rest position ``x``, ``y``, ``z`` as a simulation builds it:
    one expression of the rule language, of type bool (no rule syntax). Raises
    :class:`RuleError` whose ``diagnostics`` name ``label`` and the line and column in
    ``text``."""

def eval_predicate(
    text: str, points: npt.NDArray[np.float64], label: str = "predicate"
) -> npt.NDArray[np.bool_]:
    """Evaluates a predicate on ``x``, ``y``, ``z`` at each row of ``points`` (float64
    ``(N, 3)``) with the kernel's own parser, checker and evaluator, as a scene's ``where``
    is: returns a bool array ``(N,)``. Raises :class:`RuleError` (diagnostics naming
    ``label``) for a refused text, ``ValueError`` naming the first point where it cannot be
    evaluated, ``TypeError``/``ValueError`` for points of another dtype or shape."""

def eval_expression(
    text: str, points: npt.NDArray[np.float64], label: str = "expression"
) -> npt.NDArray[np.float64]:
    """Evaluates a number-valued expression of the rule language (``f64``, or ``i64``
    converted; no quotient of two integers) on ``x``, ``y``, ``z`` at each row of ``points``
    with the kernel: returns a float64 array ``(N,)``. Raises as :func:`eval_predicate`, and
    ``ValueError`` naming a point where the value is not finite."""

def grid(
    nx: int, ny: int, sx: float = 1.0, sy: float = 1.0, element: str = "quad"
) -> _FlatMesh: ...
def box(
    nx: int,
    ny: int,
    nz: int,
    sx: float = 1.0,
    sy: float = 1.0,
    sz: float = 1.0,
    element: str = "hexahedron",
) -> _FlatMesh: ...
def _panic_for_tests(message: str) -> None:
    """Panics in Rust, for the tests of the panic guard."""
