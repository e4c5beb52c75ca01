"""topomech: topology-based physical simulation on generalized maps (G-maps).

Build a G-map from a mesh, inspect it, save it::

    import topomech
    g = topomech.GMap.from_mesh(points, [("tetra", tets)])
    g.cell_counts()        # {'darts': ..., 'vertices': ..., ...}
    g.save("body.tmg")

Mesh files go through :mod:`topomech.io` (meshio); the command line is ``topomech``.
Every error topomech raises is a :class:`TopomechError`.
"""

from topomech._core import (
    EmbeddingError,
    FileFormatError,
    InternalError,
    MeshError,
    MeshReadError,
    TopologyError,
    TopomechError,
    __version__,
)
from topomech._gmap import BuildReport, CellCounts, GMap
from topomech.io import read_gmap, read_mesh, write_vtu

__all__ = [
    "BuildReport",
    "CellCounts",
    "EmbeddingError",
    "FileFormatError",
    "GMap",
    "InternalError",
    "MeshError",
    "MeshReadError",
    "TopologyError",
    "TopomechError",
    "__version__",
    "read_gmap",
    "read_mesh",
    "write_vtu",
]
