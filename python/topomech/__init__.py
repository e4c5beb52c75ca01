"""topomech: topology-based physical simulation on generalized maps (G-maps).

Build a G-map from a mesh, inspect it, save it::

    import topomech
    g = topomech.GMap.from_mesh(points, [("tetra", tets)])
    g.cell_counts()        # {'darts': ..., 'vertices': ..., ...}
    g.save("body.tmg")

Mesh files go through :mod:`topomech.io` (meshio); rule files (``.tmr``) through
:class:`RuleSet` (:mod:`topomech.rules`); simulations through :class:`Simulation`
(:mod:`topomech.simulation`), built from a map and a model list or from a scene file
(:func:`load_scene`, :mod:`topomech.scene`) and run to files by :func:`run_scene`
(:mod:`topomech.run`); topology changes during a run (timed cuts, fracture, tearing) are
part of the configuration, and :meth:`Simulation.topology_changes` lists them; the command
line is ``topomech``.
Every error topomech raises is a :class:`TopomechError`.
"""

from topomech._core import (
    ApplyError,
    BusyError,
    DivergenceError,
    EmbeddingError,
    FileFormatError,
    InternalError,
    MeshError,
    MeshReadError,
    RuleError,
    SceneError,
    SimulationError,
    TopologyError,
    TopomechError,
    __version__,
)
from topomech._gmap import BuildReport, CellCounts, EmbeddingSpec, EmbeddingValues, GMap
from topomech._solver_log import SolverWarning
from topomech.io import read_gmap, read_mesh, write_vtu
from topomech.models import Model
from topomech.notebook import show
from topomech.rules import ApplyReport, RuleInfo, RuleSet
from topomech.run import run_scene
from topomech.samples import sample, samples
from topomech.scene import Scene, load_scene, shipped_scenes
from topomech.simulation import (
    ModelInfo,
    Simulation,
    TopologyChange,
    TopologyResult,
    available_models,
)

__all__ = [
    "ApplyError",
    "ApplyReport",
    "BuildReport",
    "BusyError",
    "CellCounts",
    "DivergenceError",
    "EmbeddingError",
    "EmbeddingSpec",
    "EmbeddingValues",
    "FileFormatError",
    "GMap",
    "InternalError",
    "MeshError",
    "MeshReadError",
    "Model",
    "ModelInfo",
    "RuleError",
    "RuleInfo",
    "RuleSet",
    "Scene",
    "SceneError",
    "Simulation",
    "SimulationError",
    "SolverWarning",
    "TopologyChange",
    "TopologyError",
    "TopologyResult",
    "TopomechError",
    "__version__",
    "available_models",
    "load_scene",
    "read_gmap",
    "read_mesh",
    "run_scene",
    "sample",
    "samples",
    "shipped_scenes",
    "show",
    "write_vtu",
]
