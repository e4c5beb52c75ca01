"""topomech: topology-based physical simulation on generalized maps (G-maps).

Build a G-map from a mesh, inspect it, save it::

    import topomech
    g = topomech.GMap.from_mesh(points, [("tetra", tets)])
    g.cell_counts()        # {'darts': ..., 'vertices': ..., ...}
    g.save("body.tmg")

Mesh files go through :mod:`topomech.io` (meshio); rule files (``.tmr``) through
:class:`RuleSet` (:mod:`topomech.rules`); the command line is ``topomech``.
Every error topomech raises is a :class:`TopomechError`.
"""

from topomech._core import (
    ApplyError,
    EmbeddingError,
    FileFormatError,
    InternalError,
    MeshError,
    MeshReadError,
    RuleError,
    TopologyError,
    TopomechError,
    __version__,
)
from topomech._gmap import BuildReport, CellCounts, GMap
from topomech.io import read_gmap, read_mesh, write_vtu
from topomech.rules import ApplyReport, RuleInfo, RuleSet

__all__ = [
    "ApplyError",
    "ApplyReport",
    "BuildReport",
    "CellCounts",
    "EmbeddingError",
    "FileFormatError",
    "GMap",
    "InternalError",
    "MeshError",
    "MeshReadError",
    "RuleError",
    "RuleInfo",
    "RuleSet",
    "TopologyError",
    "TopomechError",
    "__version__",
    "read_gmap",
    "read_mesh",
    "write_vtu",
]
