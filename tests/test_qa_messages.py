"""QA: error messages that named the wrong problem.

1. ``RuleSet.load`` (and ``from_source`` / ``from_sources``) check a file alone, so the
   README's ``anchor.tmr``, a model file using the prelude's ``position`` and ``dx``, is
   refused with "unknown embedding 'position'" while ``topomech check`` accepts it (it loads
   model files with the shipped prelude and common rules, as ``RuleSet.from_model_sources``
   does). The loaders keep refusing it, with a last ``hint:`` line saying how to load it.
2. ``Simulation.set_vertex_field`` and ``set_fixed`` reported a right shape as the problem
   (booleans for a ``vec3`` embedding), a 0-d array as shape ``(1,)``, and a ``(V,)`` array
   for a ``vec3`` embedding as a type mismatch at every vertex.

The tests of part 2 named ``test_core_*`` need the rebuilt extension
(``crates/topomech-py/src/sim.rs``); those named ``test_wrapper_*`` need it and the change to
``Simulation.set_fixed`` / ``set_vertex_field`` in ``python/topomech/simulation.py`` (a 0-d
array kept 0-d: ``np.asarray(a, order="C")`` instead of ``np.ascontiguousarray(a)``).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import topomech
from topomech import RuleError, RuleSet

README = Path(__file__).resolve().parent.parent / "README.md"

HINT = re.compile(
    r"^hint: (?P<files>.+) declares? (a model|models): load (it|them) with "
    r"RuleSet\.from_model_sources \(or topomech\.Model\.load\), which adds the shipped prelude "
    r"and common rules declaring position, rest, velocity, force, mass, dx, \.\.\., as "
    r"`topomech check` and a simulation do; (?P<loader>RuleSet\.\w+) does not$"
)


def readme_anchor() -> str:
    """The text of ``anchor.tmr`` as the README's "Writing a model" section writes it."""
    text = README.read_text(encoding="utf-8")
    marker = text.index("<!-- readme-test: file anchor.tmr -->")
    start = text.index("```\n", marker) + len("```\n")
    return text[start : text.index("```", start)]


#: The README's model with a real error besides the prelude's names: two writes of one orbit.
CONFLICT_RULE = """
rule anchor_twice {
  left { v : <1,2> hook }
  compute {
    v.k_anchor = 1.0
    v.k_anchor = 2.0
  }
}
"""


def with_conflict(text: str) -> str:
    return text.replace("\nmodel anchor", CONFLICT_RULE + "\nmodel anchor")


def hint_of(e: pytest.ExceptionInfo[RuleError]) -> re.Match[str]:
    """The hint line, the last of the message, checked against :data:`HINT`."""
    last = str(e.value).splitlines()[-1]
    m = HINT.match(last)
    assert m, last
    return m


# ------------------------------------------------------------- 1. model files and the prelude


def test_load_of_the_readme_model_says_how_to_load_it(tmp_path: Path) -> None:
    """``topomech check anchor.tmr`` accepts the README's model; ``RuleSet.load`` refuses it
    (it checks the file alone) and says, in a last ``hint:`` line, that the file declares a
    model to load with ``RuleSet.from_model_sources``, which accepts it. The diagnostics are
    the checker's lines alone (the hint is not one of them)."""
    path = tmp_path / "anchor.tmr"
    path.write_text(readme_anchor(), encoding="utf-8")
    r = subprocess.run(
        [sys.executable, "-m", "topomech", "check", str(path)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("ok: 3 rules and 1 model in 1 file"), r.stdout
    with pytest.raises(RuleError, match="unknown embedding 'position'") as e:
        RuleSet.load([path])
    m = hint_of(e)
    assert m["files"] == str(path)
    assert m["loader"] == "RuleSet.load"
    assert str(e.value).splitlines()[:-1] == e.value.diagnostics
    assert not any(d.startswith("hint") for d in e.value.diagnostics)
    rules = RuleSet.from_model_sources([(str(path), path.read_text(encoding="utf-8"))])
    assert [m["name"] for m in rules.models() if m["file"] == str(path)] == ["anchor"]


def test_from_source_and_from_sources_say_it_too() -> None:
    """``from_source`` and ``from_sources`` check the text alone too: the same hint, naming
    the loader and the file (several model files: all of them, "declare models")."""
    text = readme_anchor()
    with pytest.raises(RuleError) as e:
        RuleSet.from_source(text, "anchor.tmr")
    m = hint_of(e)
    assert (m["files"], m["loader"]) == ("anchor.tmr", "RuleSet.from_source")
    with pytest.raises(RuleError) as e:
        RuleSet.from_sources([("anchor.tmr", text)])
    m = hint_of(e)
    assert (m["files"], m["loader"]) == ("anchor.tmr", "RuleSet.from_sources")
    other = text.replace("model anchor(", "model anchor_b(").replace("rule anchor_", "rule b_")
    other = other.replace("anchor_init(k)", "b_init(k)").replace(
        "step   anchor_force", "step   b_force"
    )
    other = other.replace("jvp    anchor_jvp", "jvp    b_jvp")
    with pytest.raises(RuleError) as e:
        RuleSet.from_sources([("a.tmr", text), ("plain.tmr", "dimension 2\n"), ("b.tmr", other)])
    m = hint_of(e)
    assert m["files"] == "a.tmr and b.tmr"
    assert "declare models: load them" in str(e.value)


def test_a_model_file_with_a_real_error() -> None:
    """A model file with a real error (a write conflict): ``RuleSet.from_sources`` reports
    it beside the prelude's names, with the hint; ``from_model_sources`` (as the hint says)
    reports the write conflict alone, and no hint."""
    text = with_conflict(readme_anchor())
    with pytest.raises(RuleError) as e:
        RuleSet.from_sources([("conflict.tmr", text)])
    hint_of(e)
    assert any("error[embedding-write-conflict]" in d for d in e.value.diagnostics)
    with pytest.raises(RuleError) as e:
        RuleSet.from_model_sources([("conflict.tmr", text)])
    assert len(e.value.diagnostics) == 1, e.value.diagnostics
    assert "error[embedding-write-conflict]: rule 'anchor_twice'" in str(e.value)
    assert "hint" not in str(e.value)


def test_no_hint_where_it_does_not_apply(tmp_path: Path) -> None:
    """No hint for a rule file without a model (an unknown embedding is its own error), for a
    model file refused for something else than an unknown embedding, and none from
    ``from_model_sources``."""
    with pytest.raises(RuleError) as e:
        RuleSet.from_source(
            "dimension 2\nrule r { left { v : <1,2> hook } compute { v.zz = 1.0 } }\n", "r.tmr"
        )
    assert "unknown embedding 'zz'" in str(e.value)
    assert "hint" not in str(e.value)
    # a model file that declares what it uses, refused for two writes of one orbit
    own = (
        "dimension 2\nembedding k : f64 on <1,2>\nembedding f : vec3 on <1,2>\n"
        "rule i(x: f64) { left { v : <1,2> hook } compute {\n v.k = x\n v.k = 2.0\n } }\n"
        "model m { init i(1.0)\n forces f }\n"
    )
    with pytest.raises(RuleError) as e:
        RuleSet.from_source(own, "own.tmr")
    assert "hint" not in str(e.value)
    path = tmp_path / "anchor.tmr"
    path.write_text(with_conflict(readme_anchor()), encoding="utf-8")
    with pytest.raises(RuleError) as e:
        RuleSet.from_model_sources([("anchor.tmr", path.read_text(encoding="utf-8"))])
    assert "hint" not in str(e.value)


def test_load_with_an_unreadable_file_beside_a_model_file(tmp_path: Path) -> None:
    """``RuleSet.load`` of a directory and a model file: refused as before (the directory's
    error at 1:1), with no hint and no hang (only regular files are read for the hint)."""
    path = tmp_path / "anchor.tmr"
    path.write_text(readme_anchor(), encoding="utf-8")
    with pytest.raises(RuleError) as e:
        RuleSet.load([tmp_path, path])
    assert f"{tmp_path}:1:1: error[file]" in str(e.value)


# ------------------------------------------------------------- 2. shapes and types of values


@pytest.fixture(scope="module")
def beam() -> topomech.Simulation:
    """The shipped beam with the co-rotational model (vertex embeddings: velocity (vec3),
    fixed (bool), mass (f64, derived), point_id (i64))."""
    g, _ = topomech.read_gmap(topomech.sample("beam.msh"))
    return topomech.Simulation(g, models=["corotational"])


@pytest.fixture(scope="module")
def anchored(tmp_path_factory: pytest.TempPathFactory) -> topomech.Simulation:
    """A 2-D sheet of 4 triangles with the README's anchor model (``k_anchor``: an f64
    vertex embedding)."""
    path = tmp_path_factory.mktemp("anchor") / "anchor.tmr"
    path.write_text(readme_anchor(), encoding="utf-8")
    points = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]], float)
    tris = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    g = topomech.GMap.from_mesh(points, [("triangle", tris)])
    return topomech.Simulation(g, models=[topomech.Model.load(path)], density=2.0)


def test_core_booleans_for_a_vec3_embedding(beam: topomech.Simulation) -> None:
    """Booleans of the right shape for a vec3 embedding: a TypeError naming the type, not a
    shape error (and booleans of shape (V,), a TypeError too, not a mismatch at every
    vertex). Nothing is written. Needs the rebuilt extension."""
    n = beam.n_vertices
    before = beam.velocities().copy()
    want = (
        f"'velocity' is a vec3 embedding: booleans given (it takes numbers of shape (V, 3) = "
        f"({n}, 3))"
    )
    for values in (np.ones((n, 3), bool), np.ones(n, bool), np.array(True)):
        with pytest.raises(TypeError) as e:
            beam.core.set_vertex_field("velocity", values)
        assert str(e.value) == want
        with pytest.raises(TypeError) as e:
            beam.set_vertex_field("velocity", values)
        assert str(e.value) == want
    np.testing.assert_array_equal(beam.velocities(), before)


def test_core_wrong_shape_for_a_vec3_embedding(beam: topomech.Simulation) -> None:
    """Numbers of shape (V,) for a vec3 embedding: a ValueError saying it takes (V, 3), with
    V's value, and the shape given (a 0-d array as ``()``). Needs the rebuilt extension."""
    n = beam.n_vertices
    for values, got in (
        (np.ones(n), f"({n},)"),
        (np.ones((n, 2)), f"({n}, 2)"),
        (np.ones((n - 1, 3)), f"({n - 1}, 3)"),
        (np.array(2.0), "()"),
    ):
        with pytest.raises(ValueError, match="values for 'velocity'") as e:
            beam.core.set_vertex_field("velocity", values)
        assert str(e.value) == (
            f"values for 'velocity' (a vec3 embedding) must have shape (V, 3) = ({n}, 3), got {got}"
        )
    with pytest.raises(ValueError, match=re.escape(f"= ({n}, 3), got ({n},)")):
        beam.set_vertex_field("velocity", np.ones(n))


def test_core_bool_embedding(beam: topomech.Simulation) -> None:
    """Numbers for a bool embedding: a TypeError naming the type (ints and floats alike); a
    wrong shape: a ValueError saying it takes (V,). Needs the rebuilt extension."""
    n = beam.n_vertices
    want = f"'fixed' is a bool embedding: numbers given (it takes booleans of shape (V,) = ({n},))"
    numbers: list[Any] = [np.ones(n), np.ones(n, np.int64), np.ones((n, 3))]
    for values in numbers:
        with pytest.raises(TypeError) as e:
            beam.core.set_vertex_field("fixed", values)
        assert str(e.value) == want
    with pytest.raises(TypeError) as e:
        beam.set_vertex_field("fixed", numbers[1])
    assert str(e.value) == want
    with pytest.raises(ValueError, match="values for 'fixed'") as shape:
        beam.core.set_vertex_field("fixed", np.ones((n, 3), bool))
    assert str(shape.value) == (
        f"values for 'fixed' (a bool embedding) must have shape (V,) = ({n},), got ({n}, 3)"
    )


def test_core_f64_embedding(anchored: topomech.Simulation) -> None:
    """An f64 vertex embedding (the anchor model's ``k_anchor``): (V, 3) numbers are a shape
    error saying (V,), booleans a type error; (V,) numbers are written. Needs the rebuilt
    extension."""
    n = anchored.n_vertices
    with pytest.raises(ValueError, match="values for 'k_anchor'") as e:
        anchored.core.set_vertex_field("k_anchor", np.ones((n, 3)))
    assert str(e.value) == (
        f"values for 'k_anchor' (an f64 embedding) must have shape (V,) = ({n},), got ({n}, 3)"
    )
    with pytest.raises(TypeError) as kind:
        anchored.core.set_vertex_field("k_anchor", np.ones(n, bool))
    assert str(kind.value) == (
        f"'k_anchor' is an f64 embedding: booleans given (it takes numbers of shape (V,) = ({n},))"
    )
    anchored.set_vertex_field("k_anchor", np.full(n, 7.0))
    np.testing.assert_array_equal(anchored.vertex_field("k_anchor"), np.full(n, 7.0))


def test_right_values_are_still_written(beam: topomech.Simulation) -> None:
    """The right values are written as before (vec3, bool), and the kernel's own refusals are
    unchanged: an unknown, a derived and an i64 embedding (SimulationError)."""
    n = beam.n_vertices
    v = np.zeros((n, 3))
    v[:, 1] = np.arange(n)
    beam.set_vertex_field("velocity", v)
    np.testing.assert_array_equal(beam.velocities(), v)
    held = np.zeros(n, bool)
    held[:3] = True
    before = beam.fixed().copy()
    beam.set_vertex_field("fixed", held)
    np.testing.assert_array_equal(beam.fixed(), held)
    beam.set_vertex_field("fixed", before)
    beam.set_vertex_field("velocity", np.zeros((n, 3)))
    with pytest.raises(topomech.SimulationError, match="no vertex embedding 'nope'"):
        beam.set_vertex_field("nope", v)
    with pytest.raises(topomech.SimulationError, match="derived"):
        beam.set_vertex_field("mass", np.ones(n))
    with pytest.raises(topomech.SimulationError, match="has type i64"):
        beam.set_vertex_field("point_id", np.ones(n))


def test_core_set_fixed_reports_a_0d_mask_as_shape_empty(beam: topomech.Simulation) -> None:
    """The kernel's ``set_fixed`` reports a 0-d mask's shape as ``()``."""
    n = beam.n_vertices
    with pytest.raises(ValueError, match="mask must have shape") as e:
        beam.core.set_fixed(np.array(True))
    assert str(e.value) == f"mask must have shape (V,) = ({n},), got ()"


def test_wrapper_0d_arrays_are_reported_as_shape_empty(beam: topomech.Simulation) -> None:
    """``Simulation.set_fixed`` and ``set_vertex_field`` keep a 0-d array 0-d (numpy's
    ``ascontiguousarray`` made it (1,)), so the message names its shape ``()``. Needs the
    simulation.py change and the rebuilt extension."""
    n = beam.n_vertices
    for mask in (np.array(True), True):
        with pytest.raises(ValueError, match="mask must have shape") as e:
            beam.set_fixed(mask)
        assert str(e.value) == f"mask must have shape (V,) = ({n},), got ()"
    with pytest.raises(ValueError, match="values for 'velocity'") as e:
        beam.set_vertex_field("velocity", np.array(2.0))
    assert str(e.value) == (
        f"values for 'velocity' (a vec3 embedding) must have shape (V, 3) = ({n}, 3), got ()"
    )
