"""Selecting vertices and boundary faces for fixes and loads: by predicate, by a list of input
point indices, by a group name of the mesh file (Gmsh physical groups, meshio point and cell
sets). Unknown groups, points that are not vertices and facets off the boundary are refused
naming them all, and the scene key at fault.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import topomech
from topomech import loads
from topomech.loads import LoadError, MeshGroups
from topomech.scene import Scene, parse_scene

BOX = """
[mesh]
generator = "box"
element = "tet"
size = [1.0, 1.0, 1.0]
cells = [2, 2, 2]

[[model]]
kind = "linear_fem"
young = 1e6
poisson = 0.3

[world]
gravity = [0.0, 0.0, -9.81]

[integrator]
kind = "static"
dt = 1.0
steps = 1
"""


def _ids(sim: topomech.Simulation) -> np.ndarray:
    """The input point of each row (H2's point_ids, else rows are points)."""
    f = getattr(sim, "point_ids", None)
    return np.asarray(f()) if f is not None else np.arange(sim.n_vertices)


def _rest_of_points(sim: topomech.Simulation) -> dict[int, np.ndarray]:
    return dict(zip(_ids(sim).tolist(), sim.rest_positions()))


# ------------------------------------------------------------------ fixes


def test_fix_by_points_holds_exactly_those_points() -> None:
    """[[fix]] points = [...] holds the vertices of those input points and no other; with a
    displacement they start displaced (held there) and the rest stays at rest."""
    text = (
        BOX
        + "[[fix]]\npoints = [0, 1, 2]\n[[fix]]\npoints = [26]\ndisplacement = [0.0, 0.0, 0.05]\n"
    )
    sim = parse_scene(text).build()
    ids = _ids(sim)
    held = set(ids[sim.fixed()].tolist())
    assert held == {0, 1, 2, 26}
    d = sim.displacements()
    np.testing.assert_allclose(d[ids == 26], [[0.0, 0.0, 0.05]], atol=1e-15)  # rounding
    assert np.all(d[ids != 26] == 0.0)
    np.testing.assert_array_equal(sim.rest_positions(), sim.positions() - d)


def test_fix_by_points_and_by_predicate_agree() -> None:
    """The same face held by predicate and by the list of its points: the same fixed rows and
    the same static solution under gravity (bit for bit: the same problem)."""
    by_where = parse_scene(BOX + '[[fix]]\nwhere = "x < 1e-9"\n').build()
    pts = [p for p, x in _rest_of_points(by_where).items() if x[0] < 1e-9]
    assert len(pts) == 9
    by_points = parse_scene(BOX + f"[[fix]]\npoints = {pts}\n").build()
    np.testing.assert_array_equal(by_where.fixed(), by_points.fixed())
    by_where.step()
    by_points.step()
    np.testing.assert_array_equal(by_where.positions(), by_points.positions())


def _groups(sim: topomech.Simulation) -> MeshGroups:
    """Groups as read_mesh gives them (contract C4): a point set, a cell set, a facet set."""
    rest = _rest_of_points(sim)
    left = np.array(sorted(p for p, x in rest.items() if x[0] < 1e-9))
    top = [p for p, x in rest.items() if x[2] > 1 - 1e-9]
    # the top face's triangles: the boundary faces whose points are all on top
    faces = loads.select_faces(sim, points=top)
    ids = _ids(sim)
    tris = np.array([[ids[r] for r in f.rows] for f in faces])
    return MeshGroups(
        point_sets={"clamp": left},
        cell_sets={"first": np.array([0])},
        facet_sets={"lid": [("triangle", tris)]},
    )


def test_fix_and_load_by_group(monkeypatch: pytest.MonkeyPatch) -> None:
    """group = "clamp" (a point set) holds its points; a pressure on group = "lid" (a facet
    set of the top face, area 1) adds up to -p (0, 0, 1); a point force on group "first" (a
    cell set) goes on the 4 vertices of cell 0."""
    base = parse_scene(BOX + '[[fix]]\nwhere = "x < 1e-9"\n').build()
    groups = _groups(base)
    monkeypatch.setattr(Scene, "mesh_groups", lambda self: groups)
    text = (
        BOX
        + '[[fix]]\ngroup = "clamp"\n'
        + '[[load]]\nkind = "pressure"\npressure = 10.0\ngroup = "lid"\n'
        + '[[load]]\nkind = "point"\nforce = [1.0, 0.0, 0.0]\ngroup = "first"\n'
    )
    sim = parse_scene(text).build()
    np.testing.assert_array_equal(sim.fixed(), base.fixed())
    f = sim.external_forces()
    x = sim.rest_positions()
    on_top = x[:, 2] > 1 - 1e-9
    np.testing.assert_allclose(f[on_top].sum(axis=0), [0.0, 0.0, -10.0], atol=1e-12)
    assert np.count_nonzero(f[:, 0]) == 4
    np.testing.assert_allclose(f[:, 0].sum(), 4.0, atol=1e-15)


def test_unknown_group_names_the_groups_that_exist(monkeypatch: pytest.MonkeyPatch) -> None:
    """An unknown group is refused, naming the key and every group the mesh has."""
    base = parse_scene(BOX + '[[fix]]\nwhere = "x < 1e-9"\n').build()
    groups = _groups(base)
    monkeypatch.setattr(Scene, "mesh_groups", lambda self: groups)
    sc = parse_scene(BOX + '[[fix]]\ngroup = "clmap"\n')
    with pytest.raises(topomech.SceneError) as e:
        sc.build()
    assert e.value.key == "fix[0]"
    assert "unknown group 'clmap'" in str(e.value)
    assert "clamp, first, lid" in str(e.value)


def test_group_on_a_generated_mesh_is_refused() -> None:
    """A generated mesh has no groups: the refusal says so and names the key."""
    sc = parse_scene(
        BOX
        + '[[fix]]\nwhere = "x < 1e-9"\n[[load]]\nkind = "point"\nforce = [0.0, 0.0, 1.0]\ngroup = "tip"\n'
    )
    with pytest.raises(topomech.SceneError) as e:
        sc.build()
    assert e.value.key == "load[0]"
    assert "no named groups" in str(e.value)


def test_points_that_are_not_vertices_are_listed() -> None:
    """Points past the mesh are refused all at once (up to the printed limit)."""
    sc = parse_scene(BOX + "[[fix]]\npoints = [0, 1000, 1001, 5000]\n")
    with pytest.raises(topomech.SceneError) as e:
        sc.build()
    assert e.value.key == "fix[0]"
    assert "1000, 1001, 5000" in str(e.value)
    many = list(range(27, 60))
    with pytest.raises(LoadError, match="and 13 more"):
        loads.select_vertices(parse_scene(BOX).build(), points=many)


def test_facets_off_the_boundary_are_listed() -> None:
    """A facet set holding interior triangles cannot carry a surface load: every such facet
    is named."""
    sim = parse_scene(BOX + '[[fix]]\nwhere = "x < 1e-9"\n').build()
    rest = _rest_of_points(sim)
    centre = next(p for p, x in rest.items() if np.allclose(x, [0.5, 0.5, 0.5]))
    corner = next(p for p, x in rest.items() if np.allclose(x, [0.0, 0.0, 0.0]))
    mid = next(p for p, x in rest.items() if np.allclose(x, [0.5, 0.0, 0.0]))
    groups = MeshGroups(facet_sets={"inner": [("triangle", np.array([[centre, corner, mid]]))]})
    with pytest.raises(LoadError, match=r"1 facets are not boundary faces.*triangle 0"):
        loads.surface_load(sim, pressure=1.0, group="inner", groups=groups)


@pytest.mark.parametrize(
    ("table", "key", "words"),
    [
        ("[[fix]]\npoints = [0, 1.5]\n", "fix[0].points[1]", "expected an integer"),
        ("[[fix]]\npoints = [-1]\n", "fix[0].points[0]", ">= 0"),
        ("[[fix]]\npoints = []\n", "fix[0].points", "non-empty"),
        ('[[fix]]\ngroup = ""\n', "fix[0].group", "empty"),
        ('[[fix]]\ngroup = "a"\nwhere = "x < 0"\n', "fix[0].group", "not both"),
        ("[[fix]]\ndisplacement = [0.0, 0.0, 1.0]\n", "fix[0]", "missing the selection"),
        ('[[fix]]\npoint = [0]\nwhere = "x < 0"\n', "fix[0].point", "did you mean 'points'"),
    ],
)
def test_bad_selection_keys_are_named(table: str, key: str, words: str) -> None:
    """A bad selection is refused when the scene is read, naming the key."""
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(BOX + table)
    assert e.value.key == key, str(e.value)
    assert words in str(e.value)


def test_predicate_language_in_python_matches_the_kernel() -> None:
    """Vertex and face selections evaluate their predicates with the kernel
    (``_core.eval_predicate``), so the vertices they select are those the kernel's fix rule
    selects, including where Python's own operators would read the text otherwise: ``%`` of
    a negative number (the rule language keeps the dividend's sign: -0.75 % 0.5 is -0.25,
    Python's 0.25), comparisons of comparisons (``a < b == c < d`` compares two booleans;
    Python chains them), ``let``, ``if``, ``#`` comments, vector functions. Each predicate
    selects some vertices and not all (so a wrong reading would show)."""
    for pred in (
        "x < 1e-9 || abs(z - 1.0) < 1e-9",
        "!(y > 0.25) && max(x, z) >= 0.5",
        "min(x, y) * 2.0 + 1.0 > 1.5 && true",
        "(x - 0.75) % 0.5 < 0.0",
        "x < 0.75 == y < 0.25",
        "let s = x + y  # the sum of two coordinates\ns <= 1.0",
        "if z > 0.75 { x < 0.25 } else { y > 0.75 }",
        "norm(vec3(x, y, z)) < 0.8",
    ):
        toml = pred.replace("\n", "\\n")
        sim = parse_scene(BOX + f'[[fix]]\nwhere = "{toml}"\n').build()
        want = sim.fixed()
        assert 0 < want.sum() < len(want), pred
        mine = loads.select_vertices(sim, where=pred)
        np.testing.assert_array_equal(mine, want, err_msg=pred)


def test_load_predicates_keep_the_whole_rule_language() -> None:
    """A load's predicate is the kernel's rule language too: vector functions are read, and
    what the kernel refuses (an unknown name, ``4/3.``, a quotient of two integers) is a
    SceneError naming the load's key and the kernel's reason."""
    sim = parse_scene(BOX + '[[fix]]\nwhere = "norm(vec3(x, y, z)) < 0.1"\n').build()
    assert sim.fixed().sum() == 1
    ok = BOX + '[[load]]\nkind = "pressure"\npressure = 1.0\nwhere = "norm(vec3(x, y, z)) < 2"\n'
    parse_scene(ok)
    for pred, words in (
        ("norm(vec3(q, y, z)) < 2", "unknown variable or parameter 'q'"),
        ("x < 4/3.", "expected the end of the expression"),
        ("x < 4/3", "quotient of two integers"),
    ):
        with pytest.raises(topomech.SceneError) as e:
            parse_scene(BOX + f'[[load]]\nkind = "pressure"\npressure = 1.0\nwhere = "{pred}"\n')
        assert e.value.key == "load[0].where", pred
        assert words in str(e.value), (pred, str(e.value))
        assert "rule '" not in str(e.value), pred


# ------------------------------------------------------------------ a Gmsh file with groups


def _gmsh_bar(path: Path) -> None:
    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("bar")
        gmsh.model.occ.addBox(0, 0, 0, 1.0, 0.2, 0.2)
        gmsh.model.occ.synchronize()
        left = [
            t
            for d, t in gmsh.model.getEntities(2)
            if gmsh.model.occ.getCenterOfMass(d, t)[0] < 1e-6
        ]
        right = [
            t
            for d, t in gmsh.model.getEntities(2)
            if gmsh.model.occ.getCenterOfMass(d, t)[0] > 1 - 1e-6
        ]
        gmsh.model.addPhysicalGroup(2, left, name="clamp")
        gmsh.model.addPhysicalGroup(2, right, name="end")
        gmsh.model.addPhysicalGroup(3, [1], name="body")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.1)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


def test_gmsh_physical_groups_select_fixes_and_loads(tmp_path: Path) -> None:
    """A bar meshed by Gmsh with physical surfaces "clamp" (x = 0) and "end" (x = 1): the
    scene holds "clamp" and puts a traction on "end"; the loads add up to t x area (0.04 m^2,
    1e-12) and every held vertex is on x = 0. Needs read_mesh's groups (contract C4)."""
    msh = tmp_path / "bar.msh"
    _gmsh_bar(msh)
    mesh, _ = topomech.read_mesh(msh)
    if not hasattr(mesh, "facet_sets"):
        pytest.skip("read_mesh does not give the file's groups yet (contract C4)")
    scene = tmp_path / "bar.toml"
    scene.write_text(
        BOX.replace(
            'generator = "box"\nelement = "tet"\nsize = [1.0, 1.0, 1.0]\ncells = [2, 2, 2]',
            'file = "bar.msh"',
        )
        + '[[fix]]\ngroup = "clamp"\n[[load]]\nkind = "traction"\ntraction = [0.0, 0.0, -50.0]\ngroup = "end"\n'
    )
    sim = topomech.load_scene(scene).build()
    x = sim.rest_positions()
    assert np.all(x[sim.fixed()][:, 0] < 1e-9)
    assert sim.fixed().sum() == (x[:, 0] < 1e-9).sum()
    np.testing.assert_allclose(
        sim.external_forces().sum(axis=0), [0.0, 0.0, -50.0 * 0.04], rtol=1e-12
    )
    wrong = tmp_path / "wrong.toml"
    wrong.write_text(scene.read_text().replace('group = "clamp"', 'group = "clmap"'))
    with pytest.raises(topomech.SceneError, match=r"unknown group 'clmap'.*body, clamp, end"):
        topomech.load_scene(wrong).build()


def test_mesh_groups_from_a_meshio_mesh() -> None:
    """MeshGroups reads the groups read_mesh attaches to its mesh (contract C4), and a plain
    meshio mesh's own point sets; names are listed sorted, across the three kinds."""
    import meshio

    mesh = meshio.Mesh(
        np.zeros((4, 3)), [("tetra", np.array([[0, 1, 2, 3]]))], point_sets={"tip": [3]}
    )
    plain = MeshGroups.from_meshio(mesh)
    assert plain.names() == ["tip"]
    np.testing.assert_array_equal(plain.point_sets["tip"], [3])
    mesh.cell_sets_kept = {"body": np.array([0])}
    mesh.facet_sets = {"7": [("triangle", np.array([[0, 1, 2]]))]}
    groups = MeshGroups.from_meshio(mesh)
    assert groups.names() == ["7", "body", "tip"]
    assert groups.points_of("7") == {0, 1, 2}
    assert groups.points_of("body", [[0, 1, 2, 3]]) == {0, 1, 2, 3}
    with pytest.raises(LoadError, match=r"unknown group 'x' \(the mesh has: 7, body, tip\)"):
        groups.points_of("x")
