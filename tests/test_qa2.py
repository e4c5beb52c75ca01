"""QA: a user's model named like a shipped one is not checked as the shipped one, a shipped
:class:`topomech.Model` is, a scene turns a refused argument of :class:`topomech.Simulation`
into its error, held displacements are exactly 3 finite numbers checked before anything
changes, and masked entries are refused by ``set_vertex_field`` and ``set_fixed``."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import topomech
from topomech import GMap, _core, cli
from topomech._core import SceneError
from topomech.loads import LoadError, apply_conditions, held_positions
from topomech.scene import parse_scene

from conftest import ANCHOR

#: The README's anchor model ("Writing a model"), under the name of a shipped model.
SHADOW = ANCHOR.replace(
    "model anchor(k: f64 = 10.0) {\n  init   anchor_init(k)",
    "model stretch_elementary(stiffness: f64 = 10.0) {\n  init   anchor_init(stiffness)",
)
assert SHADOW != ANCHOR

SCENE = """
name = "shadow"
[mesh]
generator = "grid"
element = "triangle"
size = [1.0, 1.0]
cells = [2, 2]
[[model]]
{model}
[integrator]
kind = "symplectic_euler"
dt = 0.01
steps = 1
"""


def grid() -> GMap:
    """A 2x2 grid of triangles on the unit square: 9 vertices, rows in point order."""
    return GMap.from_flat(*_core.grid(2, 2, 1.0, 1.0, "triangle"))


def test_a_user_model_named_like_a_shipped_one_is_not_checked_as_it(tmp_path: Path) -> None:
    """A model of the user's file (``model_files`` or a :class:`Model` loaded from it) named
    ``stretch_elementary`` is the user's: a negative ``stiffness`` is the kernel's to judge,
    not refused with the shipped model's ``must be >= 0``."""
    g = grid()
    spec = {"kind": "stretch_elementary", "stiffness": -5.0}
    topomech.Simulation(g, models=[spec], model_files=[("shadow.tmr", SHADOW)])
    topomech.Simulation(g, {"model_files": [("shadow.tmr", SHADOW)]}, models=[spec])
    path = tmp_path / "shadow.tmr"
    path.write_text(SHADOW)
    topomech.Simulation(g, models=[topomech.Model.load(path).with_params(stiffness=-5.0)])
    # the shipped model is still checked
    with pytest.raises(ValueError, match=r"models\[0\]\.stiffness: must be >= 0"):
        topomech.Simulation(g, models=[spec])


def test_a_scene_runs_a_user_model_named_like_a_shipped_one(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``topomech run`` on a scene whose ``[[model]] file`` declares ``stretch_elementary``
    with ``stiffness = -5.0`` runs (it printed a traceback of the shipped model's check)."""
    (tmp_path / "shadow.tmr").write_text(SHADOW)
    scene = tmp_path / "shadow.toml"
    scene.write_text(SCENE.format(model='file = "shadow.tmr"\nstiffness = -5.0'))
    sim = topomech.Simulation.from_scene(scene)
    assert sim.n_vertices == 9
    rc = cli.main(["run", str(scene), "--out", str(tmp_path / "out"), "--no-preview"])
    assert rc == 0, capsys.readouterr().err


def test_scene_build_turns_an_argument_refusal_into_its_error(tmp_path: Path) -> None:
    """A ``ValueError`` of :class:`Simulation`'s own checks raised while a scene builds it is
    the scene's :class:`SceneError` (exit 2, no traceback), named by the scene's key."""
    sc = parse_scene(SCENE.format(model='kind = "stretch_elementary"'), tmp_path / "s.toml")
    bad = {**sc.config, "models": [{"kind": "stretch_elementary", "stiffness": -5.0}]}
    with pytest.raises(topomech.SceneError) as e:
        replace(sc, config=bad).build()
    assert e.value.key == "model[0].stiffness"
    assert str(e.value).endswith(
        "model[0].stiffness: cannot build the simulation: must be >= 0, got -5.0"
    )


@pytest.mark.parametrize(
    ("name", "dim", "param", "value"),
    [("stretch_elementary", 3, "stiffness", -1e3), ("corotational", 2, "thickness", -0.1)],
)
def test_a_shipped_model_object_is_checked(name: str, dim: int, param: str, value: float) -> None:
    """``Model.shipped(...).with_params(stiffness=-1e3)`` is refused as the dict
    ``{"kind": ..., "stiffness": -1e3}`` is (it was accepted)."""
    g = grid() if dim == 2 else GMap.from_flat(*_core.box(1, 1, 1, 1.0, 1.0, 1.0, "tet"))
    m = topomech.Model.shipped(name, dim).with_params(**{param: value})
    with pytest.raises(ValueError, match=rf"models\[0\]\.{param}: must be >= 0, got {value}"):
        topomech.Simulation(g, models=[m])


def _held(sim: topomech.Simulation, rows: list[int], disp: Any) -> list[Any]:
    return [("fix[0]", {"points": [5]}, [0.01, 0.0, 0.0]), ("fix[1]", {"points": rows}, disp)]


@pytest.mark.parametrize("disp", [[True, 0.0, 0.0], [0.01], [0.01, 0.0], [np.nan, 0, 0], "abc"])
def test_apply_conditions_checks_every_displacement_first(disp: Any) -> None:
    """A bad displacement of a later ``held`` support is refused with its key before any
    support is applied (point 5 was held and moved before ``fix[1]`` was refused)."""
    sim = topomech.Simulation(grid(), models=["stretch_elementary"])
    x0, fixed0 = sim.positions(), sim.fixed()
    with pytest.raises(LoadError, match=r"^displacement") as e:
        apply_conditions(sim, {"held": _held(sim, [7], disp)})
    assert e.value.key == "fix[1]"
    assert np.array_equal(sim.positions(), x0)
    assert np.array_equal(sim.fixed(), fixed0)


@pytest.mark.parametrize("disp", [[0.01], np.array([0.01]), [0.01, 0.0], [0.0, 0.0, 0.0, 0.0]])
def test_a_displacement_is_exactly_3_numbers(disp: Any) -> None:
    """``held_positions`` with a displacement of 1 number held at ``rest + [d, d, d]``
    (numpy's broadcast), one of 2 raised numpy's error: both are a :class:`LoadError`."""
    sim = topomech.Simulation(grid(), models=["stretch_elementary"])
    mask = np.zeros(sim.n_vertices, dtype=bool)
    mask[4] = True
    with pytest.raises(LoadError, match=re.escape("displacement: expected 3 finite numbers")):
        held_positions(sim, mask, disp)
    assert not sim.fixed().any()
    held_positions(sim, mask, (0.01, 0, 0))
    assert sim.positions()[4] == pytest.approx(sim.rest_positions()[4] + [0.01, 0, 0])


def test_set_vertex_field_and_set_fixed_refuse_masked_entries() -> None:
    """``set_vertex_field`` and ``set_fixed`` took the values under a masked array's mask, as
    ``set_positions`` does not; a masked array without masked entries is its data."""
    sim = topomech.Simulation(grid(), models=["stretch_elementary"])
    n = sim.n_vertices
    v = np.ma.masked_array(np.full((n, 3), 7.0), mask=False)
    v.mask[0, 0] = True
    with pytest.raises(ValueError, match="masked entries cannot be taken"):
        sim.set_vertex_field("velocity", v)
    assert not sim.velocities().any()
    fixed = np.ma.masked_array(np.ones(n, dtype=bool), mask=[True] + [False] * (n - 1))
    with pytest.raises(ValueError, match="masked entries cannot be taken"):
        sim.set_fixed(fixed)
    assert not sim.fixed().any()
    ok = np.zeros(n, dtype=bool)
    ok[0] = True
    sim.set_fixed(np.ma.masked_array(ok, mask=False))
    assert sim.fixed()[0]
    assert not sim.fixed()[1:].any()


def test_an_unknown_model_kind_suggests_the_closest() -> None:
    """``kind = "neo_hookean"`` said only that the model is unknown (QA)."""
    text = SCENE.format(model='kind = "neo_hookean"')
    with pytest.raises(
        SceneError, match=r"unknown model 'neo_hookean' \(did you mean 'neohookean'\? "
    ):
        parse_scene(text)
