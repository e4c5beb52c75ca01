"""Scene files: the TOML contract, every refusal naming its key, and what a scene builds."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest

import topomech
from topomech import _core
from topomech.scene import PLANNED_MODELS, parse_scene, shipped_scenes

BASE = """
[mesh]
generator = "box"
element = "tet"
size = [1.0, 0.2, 0.2]
cells = [4, 1, 1]

[[model]]
kind = "corotational"

[[fix]]
where = "x < 1e-9"

[integrator]
kind = "symplectic_euler"
dt = 1e-3
steps = 2
"""


def refusal(text: str, tmp_path: Path | None = None) -> topomech.SceneError:
    """The SceneError a scene gives, parsing or building."""
    path = (tmp_path or Path("/nonexistent")) / "scene.toml"
    with pytest.raises(topomech.SceneError) as info:
        parse_scene(text, path).build()
    return info.value


# ------------------------------------------------------------------------ keys and types


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        (
            BASE.replace("dt = 1e-3", "dtt = 1e-3"),
            "integrator.dtt",
            "unknown key; did you mean 'dt'?",
        ),
        ("title = 'x'\n" + BASE, "title", "unknown key"),
        (
            BASE.replace('element = "tet"', 'element = "tet"\nsizes = [1, 1, 1]'),
            "mesh.sizes",
            "unknown key",
        ),
        (
            BASE.replace('kind = "corotational"', 'kind = "corotational"\nstiffness = 3.0'),
            "model[0].stiffness",
            "unknown key (model 'corotational' takes young, poisson)",
        ),
        (
            BASE + '[[model]]\nkind = "stretch_elementary"\nstifness = 3.0\n',
            "model[1].stifness",
            "unknown key; did you mean 'stiffness'?",
        ),
        (
            BASE.replace('where = "x < 1e-9"', 'where = "x < 1e-9"\ndisp = [0, 0, 0]'),
            "fix[0].disp",
            "unknown key",
        ),
        (
            BASE + "[material]\n[[material.region]]\nwhere = 'x > 0.5'\nyoungs = 2e6\n",
            "material.region[0].youngs",
            "unknown key",
        ),
        (
            BASE + "[world]\ngravty = [0, 0, 0]\n",
            "world.gravty",
            "unknown key; did you mean 'gravity'?",
        ),
        (BASE + "[output]\nevry = 3\n", "output.evry", "unknown key; did you mean 'every'?"),
        (
            BASE.replace('element = "tet"', 'element = "tet"\nlinear = true'),
            "mesh.linear",
            'unknown key; write order = "linear"',
        ),
    ],
)
def test_unknown_keys_name_their_path(text: str, key: str, message: str) -> None:
    e = refusal(text)
    assert e.key == key
    assert f"{key}: {message}" in str(e)


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        (
            BASE + '[material]\ndensity = "abc"\n',
            "material.density",
            'expected a number, got "abc"',
        ),
        (BASE + "[material]\ndensity = true\n", "material.density", "expected a number, got true"),
        (BASE + "[material]\ndensity = 0.0\n", "material.density", "must be positive, got 0.0"),
        (BASE + "[material]\ndamping = -1.0\n", "material.damping", "must be >= 0"),
        (BASE + "[material]\npoisson = 0.5\n", "material.poisson", "must be in (-1, 0.5), got 0.5"),
        (BASE.replace("dt = 1e-3", "dt = -1e-3"), "integrator.dt", "must be positive, got -0.001"),
        (BASE.replace("dt = 1e-3", "dt = inf"), "integrator.dt", "must be finite"),
        (
            BASE.replace("steps = 2", "steps = 2.5"),
            "integrator.steps",
            "expected an integer, got 2.5",
        ),
        (BASE.replace("steps = 2", "steps = -1"), "integrator.steps", "must be >= 0, got -1"),
        (
            BASE.replace('kind = "symplectic_euler"', 'kind = "rk4"'),
            "integrator.kind",
            'unknown value "rk4" (expected',
        ),
        (
            BASE.replace("cells = [4, 1, 1]", "cells = [4, 1.5, 1]"),
            "mesh.cells[1]",
            "expected an integer, got 1.5",
        ),
        (
            BASE.replace("cells = [4, 1, 1]", "cells = [4, 0, 1]"),
            "mesh.cells[1]",
            "must be >= 1, got 0",
        ),
        # integers beyond 64 bits (Python's TOML reader takes any size) are refused by key,
        # not left to overflow in the binding (QA: a traceback, exit 1)
        (
            BASE.replace("cells = [4, 1, 1]", "cells = [99999999999999999999, 1, 1]"),
            "mesh.cells[0]",
            "must be at most 9223372036854775807 (a 64-bit integer)",
        ),
        (
            BASE.replace("steps = 2", "steps = 9223372036854775808"),
            "integrator.steps",
            "must be at most 9223372036854775807",
        ),
        (
            BASE + "[[fix]]\npoints = [0, 99999999999999999999]\n",
            "fix[1].points[1]",
            "must be at most 9223372036854775807",
        ),
        (
            BASE.replace("size = [1.0, 0.2, 0.2]", "size = [1.0, 0.2]"),
            "mesh.size",
            "expected an array of 3 numbers",
        ),
        (BASE.replace('element = "tet"', 'element = "tri"'), "mesh.element", 'unknown value "tri"'),
        (
            BASE.replace('generator = "box"', 'generator = "sphere"'),
            "mesh.generator",
            'unknown generator "sphere"',
        ),
        (
            BASE + "[world]\ngravity = [0, -9.81]\n",
            "world.gravity",
            "expected an array of 3 numbers, got [0, -9.81]",
        ),
        (
            BASE + "[world]\ngravity = [0, 'down', 0]\n",
            "world.gravity[1]",
            'expected a number, got "down"',
        ),
        (BASE + "[output]\nevery = -2\n", "output.every", "must be >= 0"),
        (BASE.replace("[[fix]]", "[fix]"), "fix", "expected an array of tables: write [[fix]]"),
        (
            BASE.replace('where = "x < 1e-9"', "where = 3"),
            "fix[0].where",
            "expected a string, got 3",
        ),
        (
            BASE.replace('where = "x < 1e-9"', 'where = "x < 1e-9"\ndisplacement = [0, 1]'),
            "fix[0].displacement",
            "expected an array of 3 numbers",
        ),
        (
            "integrator = 3\n" + BASE.split("[integrator]")[0],
            "integrator",
            "expected a table, got 3",
        ),
        (
            BASE + "[material]\n[[material.region]]\nwhere = 'x > 0.5'\n",
            "material.region[0]",
            "a region needs density, young or poisson",
        ),
    ],
)
def test_mistyped_values_name_their_key(text: str, key: str, message: str) -> None:
    e = refusal(text)
    assert e.key == key
    assert f"{key}: {message}" in str(e), str(e)


def test_message_names_the_file(tmp_path: Path) -> None:
    p = tmp_path / "beam.toml"
    p.write_text(BASE.replace("dt = 1e-3", "dtt = 1e-3"))
    with pytest.raises(topomech.SceneError, match=r"beam\.toml: integrator\.dtt: unknown key"):
        topomech.load_scene(p)


def test_a_byte_order_mark_is_skipped(tmp_path: Path) -> None:
    """A scene file some editor started with a UTF-8 byte-order mark reads as without it."""
    p = tmp_path / "beam.toml"
    p.write_text("\ufeff" + BASE, encoding="utf-8")
    assert topomech.load_scene(p).config == parse_scene(BASE).config


def test_invalid_toml() -> None:
    e = refusal(BASE + "[[[\n")
    assert e.key is None
    assert "invalid TOML" in str(e)
    assert "line" in str(e)


# ------------------------------------------------------------------------ mesh


def test_missing_mesh_table() -> None:
    e = refusal("[[model]]\nkind = 'corotational'\n")
    assert e.key == "mesh"
    assert "missing table [mesh]" in str(e)


def test_missing_mesh_file_is_named(tmp_path: Path) -> None:
    text = BASE.replace(
        'generator = "box"\nelement = "tet"\nsize = [1.0, 0.2, 0.2]\ncells = [4, 1, 1]',
        'file = "nope.msh"',
    )
    e = refusal(text, tmp_path)
    assert e.key == "mesh.file"
    assert f"no such file: {tmp_path / 'nope.msh'}" in str(e)


@pytest.mark.parametrize("empty", ["", "  "])
def test_an_empty_mesh_file_is_named(tmp_path: Path, empty: str) -> None:
    """`file = ""` was read as the scene's folder (QA: "`.`: is a directory")."""
    text = BASE.replace(
        'generator = "box"\nelement = "tet"\nsize = [1.0, 0.2, 0.2]\ncells = [4, 1, 1]',
        f'file = "{empty}"',
    )
    e = refusal(text, tmp_path)
    assert e.key == "mesh.file"
    assert "empty: give the mesh file's path" in str(e)


def test_mesh_file_and_generator_both() -> None:
    e = refusal(BASE.replace('generator = "box"', 'generator = "box"\nfile = "a.msh"'))
    assert e.key == "mesh.generator"
    assert "not both" in str(e)


def test_unreadable_mesh_file(tmp_path: Path) -> None:
    (tmp_path / "junk.vtu").write_text("not a mesh")
    text = BASE.replace(
        'generator = "box"\nelement = "tet"\nsize = [1.0, 0.2, 0.2]\ncells = [4, 1, 1]',
        'file = "junk.vtu"',
    )
    e = refusal(text, tmp_path)
    assert e.key == "mesh.file"
    assert "cannot read this file as a mesh" in str(e)


def test_mesh_file_is_relative_to_the_scene(tmp_path: Path) -> None:
    points, _kinds, _offsets, conn = _core.box(4, 1, 1, 1.0, 0.2, 0.2, "tetra")
    (tmp_path / "scenes").mkdir()
    meshio.write(
        tmp_path / "scenes" / "beam.vtu", meshio.Mesh(points, [("tetra", conn.reshape(-1, 4))])
    )
    text = BASE.replace(
        'generator = "box"\nelement = "tet"\nsize = [1.0, 0.2, 0.2]\ncells = [4, 1, 1]',
        'file = "beam.vtu"',
    )
    scene_file = tmp_path / "scenes" / "beam.toml"
    scene_file.write_text(text)
    sc = topomech.load_scene(scene_file)
    assert sc.mesh.file == tmp_path / "scenes" / "beam.vtu"
    sim = sc.build()
    assert sim.n_vertices == len(points)
    assert sim.total_mass() == pytest.approx(1000.0 * 1.0 * 0.2 * 0.2)


# ------------------------------------------------------------------------ models and material


def test_unknown_model() -> None:
    e = refusal(BASE.replace('kind = "corotational"', 'kind = "spring"'))
    assert e.key == "model[0].kind"
    assert "unknown model 'spring' (known: stretch_elementary" in str(e)


def test_planned_model_is_not_available_yet(monkeypatch: pytest.MonkeyPatch) -> None:
    available = {m["kind"] for m in topomech.available_models()}
    planned = [k for k in PLANNED_MODELS if k not in available]
    if not planned:
        # every planned model has landed: pretend one has not, to check the message
        planned = [PLANNED_MODELS[-1]]
        real = _core.models
        monkeypatch.setattr(_core, "models", lambda: [m for m in real() if m["kind"] != planned[0]])
    e = refusal(BASE.replace('kind = "corotational"', f'kind = "{planned[0]}"'))
    assert e.key == "model[0].kind"
    assert f"model '{planned[0]}' is not available yet (available: " in str(e)


def test_no_model() -> None:
    e = refusal(BASE.replace('[[model]]\nkind = "corotational"', ""))
    assert e.key == "model"
    assert "no model" in str(e)


def test_model_of_the_wrong_dimension() -> None:
    text = BASE.replace(
        'generator = "box"\nelement = "tet"\nsize = [1.0, 0.2, 0.2]\ncells = [4, 1, 1]',
        'generator = "grid"\nelement = "tri"',
    )
    e = refusal(text.replace('kind = "corotational"', 'kind = "linear_fem"'))
    assert e.key == "model[0].kind"
    assert "model 'linear_fem' needs a 3D mesh (tetrahedra), the mesh is 2D" in str(e)


def test_model_of_the_wrong_dimension_in_a_mesh_file(tmp_path: Path) -> None:
    """A mesh file's dimension is known once read: the check runs when the scene builds."""
    points, _kinds, _offsets, conn = _core.grid(2, 2, 1.0, 1.0, "triangle")
    meshio.write(tmp_path / "plate.vtu", meshio.Mesh(points, [("triangle", conn.reshape(-1, 3))]))
    text = BASE.replace(
        'generator = "box"\nelement = "tet"\nsize = [1.0, 0.2, 0.2]\ncells = [4, 1, 1]',
        'file = "plate.vtu"',
    )
    sc = parse_scene(
        text.replace('kind = "corotational"', 'kind = "linear_fem"'), tmp_path / "s.toml"
    )
    with pytest.raises(topomech.SceneError) as info:
        sc.build()
    assert info.value.key == "model[0].kind"
    assert "the mesh is 2D" in str(info.value)


def test_model_that_matches_nothing() -> None:
    e = refusal(
        BASE.replace('element = "tet"', 'element = "hex"').replace(
            'kind = "corotational"', 'kind = "linear_fem"'
        )
    )
    assert e.key == "model[0].kind"
    assert "matches nothing on this mesh: it needs tetrahedra" in str(e)
    assert isinstance(e.__cause__, topomech.SimulationError)


def test_two_models_with_different_young() -> None:
    text = BASE.replace(
        'kind = "corotational"',
        'kind = "corotational"\nyoung = 1e6\n[[model]]\nkind = "linear_fem"\nyoung = 2e6',
    )
    e = refusal(text)
    assert e.key == "model[1].young"
    assert "differs from model[0].young" in str(e)


def test_model_young_against_material_young() -> None:
    text = (
        BASE.replace('kind = "corotational"', 'kind = "corotational"\nyoung = 1e6')
        + "[material]\nyoung = 3e6\n"
    )
    e = refusal(text)
    assert e.key == "model[0].young"
    assert "differs from material.young" in str(e)


@pytest.mark.parametrize("key", ["young", "poisson"])
def test_material_keys_refused_in_a_spring_model_table(key: str) -> None:
    """Springs take their stiffness, not the material: a young or poisson in their table
    would be ignored, so it is refused, naming the key and what the model takes."""
    e = refusal(BASE.replace('kind = "corotational"', f'kind = "stretch_elementary"\n{key} = 0.3'))
    assert e.key == f"model[0].{key}"
    assert "model 'stretch_elementary' takes stiffness, damping" in str(e)


def test_model_young_sets_the_material() -> None:
    text = BASE.replace(
        'kind = "corotational"', 'kind = "corotational"\nyoung = 2.5e6\npoisson = 0.25'
    )
    sc = parse_scene(text)
    assert sc.config["young"] == 2.5e6
    assert sc.config["poisson"] == 0.25
    assert sc.config["models"] == [{"kind": "corotational"}]


# ------------------------------------------------------------------------ predicates


def test_bad_predicate() -> None:
    e = refusal(BASE.replace('where = "x < 1e-9"', 'where = "x <"'))
    assert e.key == "fix[0].where"
    assert 'bad predicate "x <"' in str(e)


def test_predicate_with_unknown_variable() -> None:
    e = refusal(BASE.replace('where = "x < 1e-9"', 'where = "w < 1"'))
    assert e.key == "fix[0].where"
    assert "unknown variable or parameter 'w'" in str(e)


def test_predicate_that_is_not_boolean() -> None:
    e = refusal(BASE.replace('where = "x < 1e-9"', 'where = "x + 1"'))
    assert "has type f64, expected bool" in str(e)


def test_predicate_that_selects_nothing() -> None:
    e = refusal(BASE.replace('where = "x < 1e-9"', 'where = "x < -1"'))
    assert e.key == "fix[0].where"
    assert "fix predicate 'x < -1' selects no vertex" in str(e)


def test_region_that_contains_nothing() -> None:
    e = refusal(BASE + "[material]\n[[material.region]]\nwhere = 'x > 10'\nyoung = 2e6\n")
    assert e.key == "material.region[0].where"
    assert "contains no element" in str(e)


def test_bad_region_predicate() -> None:
    e = refusal(BASE + "[material]\n[[material.region]]\nwhere = 'x >'\nyoung = 2e6\n")
    assert e.key == "material.region[0].where"


# ------------------------------------------------------------------------ what a scene builds


def test_scene_to_config() -> None:
    text = (
        BASE.replace(
            'where = "x < 1e-9"',
            'where = "x < 1e-9"\n[[fix]]\nwhere = "x > 1 - 1e-9"\ndisplacement = [0.0, 0.01, 0.0]',
        )
        + "[material]\ndensity = 500.0\ndamping = 0.5\n[[material.region]]\nwhere = 'x > 0.5'\nyoung = 2e6\n"
        + "[world]\ngravity = [0.0, 0.0, -1.0]\nground = -1.0\n"
    )
    sc = parse_scene(text, "beam.toml")
    assert sc.name == "beam"
    assert sc.config["fixed"] == ["x < 1e-9"]
    assert sc.config["prescribed"] == [("x > 1 - 1e-9", [0.0, 0.01, 0.0])]
    assert sc.config["regions"] == [{"where": "x > 0.5", "young": 2e6}]
    assert sc.config["gravity"] == [0.0, 0.0, -1.0]
    assert sc.config["ground"] == -1.0
    assert sc.config["density"] == 500.0
    assert sc.steps == 2
    assert sc.every == 1  # steps / 50, at least 1
    sim = sc.build()
    held = sim.fixed()
    rest = sim.rest_positions()
    assert held.sum() == 8  # the two end faces of a 4 x 1 x 1 box
    moved = rest[:, 0] > 1 - 1e-9
    assert np.allclose(sim.displacements()[moved], [0.0, 0.01, 0.0])


def test_defaults() -> None:
    sc = parse_scene('[mesh]\ngenerator = "grid"\n[[model]]\nkind = "stretch_elementary"\n')
    assert sc.integrator == "symplectic_euler"
    assert sc.dt == 1e-3
    assert sc.steps == 100
    assert sc.every == 2
    assert sc.config["gravity"] == [0.0, -9.81, 0.0]
    assert sc.mesh.cells == (1, 1)
    assert sc.mesh.element == "quad"


def test_with_steps_keeps_an_explicit_every() -> None:
    sc = parse_scene(BASE + "[output]\nevery = 7\n")
    assert sc.with_steps(1000).every == 7
    assert sc.with_steps(1000, 0).every == 0
    free = parse_scene(BASE)
    assert free.with_steps(1000).every == 20


@pytest.mark.parametrize(
    ("generator", "element", "size", "cells", "measure"),
    [
        ("box", "tet", [1.0, 0.2, 0.3], [4, 2, 1], 1.0 * 0.2 * 0.3),
        ("box", "hex", [2.0, 1.0, 0.5], [2, 2, 2], 2.0 * 1.0 * 0.5),
        ("box", "mixed", [1.0, 1.0, 1.0], [2, 1, 1], 1.0),
        ("grid", "tri", [1.0, 0.5], [4, 2], 0.5),
        ("rectangle", "mixed", [2.0, 1.0], [4, 2], 2.0),
    ],
)
def test_total_mass_is_density_times_measure(
    generator: str, element: str, size: list[float], cells: list[int], measure: float
) -> None:
    model = "stretch_elementary"
    text = (
        f'[mesh]\ngenerator = "{generator}"\nelement = "{element}"\nsize = {size}\ncells = {cells}\n'
        f'[[model]]\nkind = "{model}"\n[material]\ndensity = 7.5\n'
    )
    sim = parse_scene(text).build()
    assert sim.total_mass() == pytest.approx(7.5 * measure, rel=1e-12)


def test_shipped_scenes_parse() -> None:
    scenes = shipped_scenes()
    assert {
        "triangles",
        "mixed_surface",
        "hexahedra",
        "corotational",
        "mass_tensor",
        "mixed_volume",
        "cloth",
        "cantilever",
    } <= set(scenes)
    for name, path in scenes.items():
        sc = topomech.load_scene(path)
        assert sc.name == name
        assert sc.description
        assert sc.steps > 0
        # a shipped scene can be named without its path
        assert topomech.load_scene(name).path == path


def test_unknown_scene_name() -> None:
    with pytest.raises(FileNotFoundError, match="no shipped scene of that name"):
        topomech.load_scene("no_such_scene")


def test_from_scene() -> None:
    sim = topomech.Simulation.from_scene(shipped_scenes()["cantilever"])
    assert sim.integrator == "static"
    assert sim.dimension == 3


def test_model_listed_twice_names_the_second_listing(tmp_path: Path) -> None:
    """The kernel refuses a model listed twice; the scene names the second table (the one to
    remove), not the first."""
    text = BASE.replace(
        'kind = "corotational"', 'kind = "corotational"\n[[model]]\nkind = "corotational"'
    )
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(text, "dup.toml").build()
    assert e.value.key == "model[1].kind", str(e.value)
    assert "listed twice" in str(e.value)
