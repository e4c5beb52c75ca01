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
    # k = 50.0                         #   several; its parameters as keys, a vec3
    # offset = [0.0, 0.1, 0.0]         #   one as an array of 3 numbers

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

A scene file that does not exist (and names no shipped scene) raises
:class:`FileNotFoundError`, as every reader of topomech does for a missing file; every problem
of a scene file raises :class:`SceneError` naming the key by its path (a missing mesh or model
file included: ``mesh.file: no such file: ...``): ``integrator.dtt:
unknown key``, ``material.density: expected a number, got "abc"``, ``model[1].kind: ...``
(arrays of tables are numbered from 0). An event after the end of the run (``time`` past
``steps x dt``, also when a shorter step count is asked for) is refused as
``event[i].time: ... after the end of the run``. A cut that separates nothing when its time
comes (a plane or predicate that misses the object) cannot be known before the run: that
step fails (see :func:`topomech.run.run_scene`).

Where things are (the Rust side, ``crates/physics/src/``, splits along the same concepts):

- :mod:`._scene`: :class:`Scene`, :func:`parse_scene` (the order every table is read in),
  :func:`load_scene`, :func:`shipped_scenes`, :func:`find_scene`; ``[integrator]`` and
  ``[output]``;
- :mod:`._mesh`: ``[mesh]`` (:class:`MeshSpec`) and reading or generating the mesh;
- :mod:`._models`: ``[[model]]`` (shipped kinds and the user's model files);
- :mod:`._material`: ``[material]`` and ``[[material.region]]``;
- :mod:`._conditions`: ``[[fix]]``, ``[[load]]``, ``[initial]``, ``world.ground`` and the
  selections (``where``, ``points``, ``group``) they share;
- :mod:`._events`: ``[[event]]`` and ``[fracture]``;
- :mod:`._table`: reading a TOML table, the :class:`SceneError` of a key, the checks of
  numbers, names and predicates (imports none of the others).
"""

from __future__ import annotations

from topomech._core import SceneError
from topomech.scene._events import EVENT_KINDS, FRACTURE_CRITERIA
from topomech.scene._mesh import BOX_ELEMENTS as BOX_ELEMENTS
from topomech.scene._mesh import GENERATORS as GENERATORS
from topomech.scene._mesh import GRID_ELEMENTS as GRID_ELEMENTS
from topomech.scene._mesh import MAX_VIOLATIONS_LISTED as MAX_VIOLATIONS_LISTED
from topomech.scene._mesh import MeshSpec
from topomech.scene._models import MATERIAL_KEYS_IN_MODEL as MATERIAL_KEYS_IN_MODEL
from topomech.scene._models import PLANNED_MODELS
from topomech.scene._scene import (
    INTEGRATORS,
    Scene,
    SceneWarning,
    find_scene,
    load_scene,
    parse_scene,
    shipped_scenes,
)
from topomech.scene._table import MAX_NAME_BYTES as MAX_NAME_BYTES
from topomech.scene._table import _Fail as _Fail
from topomech.scene._table import name_problem as name_problem

__all__ = [
    "EVENT_KINDS",
    "FRACTURE_CRITERIA",
    "INTEGRATORS",
    "PLANNED_MODELS",
    "MeshSpec",
    "Scene",
    "SceneError",
    "SceneWarning",
    "find_scene",
    "load_scene",
    "parse_scene",
    "shipped_scenes",
]
