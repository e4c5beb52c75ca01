"""vec3 model parameters, set from Python (``Model.with_params``, ``Simulation`` dicts) and
from scenes (``[[model]]`` tables, both ``file = ...`` and ``kind = ...``), listed by
``topomech models``.

The model: anchor springs pulling each vertex toward ``rest + offset``,
``f = -k (x - rest - offset)``, with the exact Jacobian ``df = -k dx``. Without gravity the
equilibrium of every free vertex is ``u = offset`` whatever its mass and the mesh (the
vertices do not interact); held vertices stay at rest.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import meshio
import numpy as np
import pytest

import topomech
from topomech import Model, SceneError, SimulationError
from topomech.cli import main
from topomech.models import shipped_models
from topomech.scene import parse_scene

ANCHOR_OFFSET = """\
dimension 2
embedding k_ao  : f64  on <1,2>
embedding u_ao  : vec3 on <1,2>
embedding f_ao  : vec3 on <1,2>
embedding df_ao : vec3 on <1,2>

rule ao_init(k: f64, offset: vec3) {
  left { v : <1,2> hook }
  compute { v.k_ao = k   v.u_ao = offset }
}
rule ao_force {
  left { v : <1,2> hook }
  compute { v.f_ao = -v.k_ao * (v.position - v.rest - v.u_ao) }
}
rule ao_jvp {
  left { v : <1,2> hook }
  compute { v.df_ao = -v.k_ao * v.dx }
}

model anchor_offset(k: f64 = 10.0, offset: vec3 = vec3(0, 0, 0)) {
  init   ao_init(k, offset)
  step   ao_force
  forces f_ao
  jvp    ao_jvp -> df_ao
  needs  "vertices"
}
"""

K = 50.0
OFFSET = (0.25, -0.5, 0.125)
DENSITY = 2.0
DAMPING = 20.0
#: The vertices held at rest.
FIXED = "x < 1e-9"

#: (dt, steps) per integrator. `static` is one linear solve: K = k I on the free vertices
#: (each vertex on its own spring), which the first Newton step with conjugate gradients
#: solves exactly, so only rounding remains: checked to 1e-12 of |offset| (the bound of
#: crates/physics/tests/it/model_files.rs for the same model). The damped implicit run settles:
#: with c = 20 1/s every vertex (k / m >= 100 1/s^2 on this mesh) is at least critically
#: damped or decays like exp(-c t / 2); 6 s leave ~1e-26 of the start, and each step's solve
#: is converged to 1e-8 of its residual: checked to 1e-10 of |offset|, as
#: tests/test_model_files.py checks the anchor model.
RUNS = {"static": (1.0, 1, 1e-12), "implicit_euler": (1e-3, 6000, 1e-10)}


def _write(folder: Path, name: str, text: str) -> Path:
    p = folder / name
    p.write_text(text, encoding="utf-8")
    return p


def _grid() -> topomech.GMap:
    return topomech.GMap.from_flat(*topomech._core.grid(3, 2, 1.5, 1.0, "triangle"))


def _check_offset(u: np.ndarray, rest: np.ndarray, want: Any, rtol: float, what: str) -> None:
    """Free vertices (rest x > 0) moved by ``want``, held ones (x = 0) not at all, each to
    ``rtol`` of |want|."""
    want = np.asarray(want, dtype=np.float64)
    held = rest[:, 0] < 1e-9
    assert held.any(), what
    assert (~held).sum() > 4, what
    scale = float(np.linalg.norm(want)) or 1.0
    err_free = np.abs(u[~held] - want).max() / scale
    err_held = np.abs(u[held]).max() / scale
    assert err_free <= rtol, f"{what}: free vertices off by {err_free:.3e} of |offset|"
    assert err_held <= rtol, f"{what}: held vertices moved by {err_held:.3e} of |offset|"


def _cli(*args: str | Path, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    env.pop("TOPOMECH_CLI_NO_SUBPROCESS", None)
    return subprocess.run(
        [sys.executable, "-m", "topomech", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=300,
    )


def _scene(integrator: str = "static", params: str = f"k = {K}\noffset = {list(OFFSET)}") -> str:
    dt, steps, _ = RUNS.get(integrator, (1e-3, 10, 0.0))
    return f"""\
name = "offset"

[mesh]
generator = "grid"
element = "triangle"
size = [1.5, 1.0]
cells = [3, 2]

[[model]]
file = "offset.tmr"
{params}

[material]
density = {DENSITY}
damping = {DAMPING}

[[fix]]
where = "{FIXED}"

[world]
gravity = [0.0, 0.0, 0.0]

[integrator]
kind = "{integrator}"
dt = {dt}
steps = {steps}

[output]
every = {steps}
"""


# ------------------------------------------------------------------- Model.with_params


@pytest.fixture
def model(tmp_path: Path) -> Model:
    return Model.load(_write(tmp_path, "offset.tmr", ANCHOR_OFFSET))


def test_a_vec3_parameter_is_declared_with_its_default(model: Model) -> None:
    assert model.params == {"k": 10.0, "offset": [0.0, 0.0, 0.0]}
    assert model.param_types == {"k": "f64", "offset": "vec3"}
    # the values a simulation runs it with: a vec3 as a tuple, its default's too
    assert model.param_values == {"k": 10.0, "offset": (0.0, 0.0, 0.0)}
    assert model.with_params(offset=[1, 2, 3]).param_values == {
        "k": 10.0,
        "offset": (1.0, 2.0, 3.0),
    }


@pytest.mark.parametrize(
    "value",
    [
        [0.25, -0.5, 0.125],
        (0.25, -0.5, 0.125),
        np.array([0.25, -0.5, 0.125]),
        np.array([0.25, -0.5, 0.125], dtype=np.float32),
        [np.float64(0.25), -0.5, np.float32(0.125)],
    ],
    ids=["list", "tuple", "array", "float32-array", "numpy-scalars"],
)
def test_with_params_takes_3_real_numbers_for_a_vec3(model: Model, value: Any) -> None:
    m = model.with_params(offset=value)
    assert m.values == {"offset": (0.25, -0.5, 0.125)}
    assert all(type(x) is float for x in m.values["offset"])
    entry = m.config_entry()
    assert entry == {"kind": "anchor_offset", "offset": [0.25, -0.5, 0.125]}
    assert type(entry["offset"]) is list
    # integers are real numbers too, and values set before are kept
    m2 = m.with_params(k=3)
    assert m2.values == {"offset": (0.25, -0.5, 0.125), "k": 3.0}
    assert model.with_params(offset=np.array([1, 2, 3])).values == {"offset": (1.0, 2.0, 3.0)}


@pytest.mark.parametrize("value", [np.array(3.0), np.array(3, dtype=np.int32), np.float32(3.0)])
def test_with_params_takes_a_0d_array_for_an_f64(model: Model, value: Any) -> None:
    """A 0-d numpy array is one number, as a numpy scalar is (QA: ``np.array(5.0)`` was
    refused as an ndarray while ``np.float32(5)`` was taken); a 0-d array of something else
    is refused naming what it holds."""
    assert model.with_params(k=value).values == {"k": 3.0}
    assert type(model.with_params(k=value).values["k"]) is float
    with pytest.raises(TypeError, match="parameter 'k' must be a real number, got bool"):
        model.with_params(k=np.array(True))


@pytest.mark.parametrize(
    ("params", "error", "words"),
    [
        # a vec3 given a scalar: the type expected
        (
            {"offset": 1.0},
            TypeError,
            "model 'anchor_offset': parameter 'offset' is a vec3: expected 3 real numbers "
            "(a list, a tuple or an array of shape (3,)), got a real number",
        ),
        ({"offset": "1, 2, 3"}, TypeError, "parameter 'offset' is a vec3: expected 3 real"),
        ({"offset": None}, TypeError, "parameter 'offset' is a vec3: expected 3 real"),
        # the wrong length
        (
            {"offset": [1.0, 2.0]},
            ValueError,
            "model 'anchor_offset': parameter 'offset' is a vec3: expected 3 real numbers, got 2",
        ),
        ({"offset": [1.0, 2.0, 3.0, 4.0]}, ValueError, "expected 3 real numbers, got 4"),
        ({"offset": []}, ValueError, "expected 3 real numbers, got 0"),
        (
            {"offset": np.zeros((3, 1))},
            ValueError,
            "parameter 'offset' is a vec3: expected 3 real numbers, got an array of shape (3, 1)",
        ),
        # not real numbers
        (
            {"offset": [1.0, "2", 3.0]},
            TypeError,
            "model 'anchor_offset': parameter 'offset' is a vec3: item 1 must be a real number, "
            "got str",
        ),
        ({"offset": [True, 0.0, 0.0]}, TypeError, "item 0 must be a real number, got bool"),
        ({"offset": [1.0, 2.0, 1j]}, TypeError, "item 2 must be a real number, got complex"),
        ({"offset": [[1.0], 2.0, 3.0]}, TypeError, "item 0 must be a real number, got list"),
        # not finite
        (
            {"offset": [0.0, math.nan, 0.0]},
            ValueError,
            "model 'anchor_offset': parameter 'offset' is a vec3: item 1 must be finite, got nan",
        ),
        ({"offset": np.array([0.0, 0.0, -np.inf])}, ValueError, "item 2 must be finite, got -inf"),
        # an f64 given a sequence: the type expected
        (
            {"k": [1.0, 2.0, 3.0]},
            TypeError,
            "model 'anchor_offset': parameter 'k' is an f64: expected one real number, got a "
            "list (sequences of 3 numbers are for vec3 parameters)",
        ),
        ({"k": np.array([1.0])}, TypeError, "parameter 'k' is an f64: expected one real number"),
        (
            {"k": (1.0,)},
            TypeError,
            "parameter 'k' is an f64: expected one real number, got a tuple",
        ),
        ({"k": 10**400}, ValueError, "parameter 'k' must be finite, got an integer too large"),
        ({"offset": [0, 10**400, 0]}, ValueError, "an item is an integer too large for f64"),
        ({"k": "1"}, TypeError, "model 'anchor_offset': parameter 'k' must be a real number"),
        ({"k": math.inf}, ValueError, "model 'anchor_offset': parameter 'k' must be finite"),
        # an unknown parameter
        ({"offsett": [0, 0, 0]}, ValueError, "has no parameter 'offsett' (it has: k, offset)"),
    ],
)
def test_with_params_refusals_name_the_model_and_parameter(
    model: Model, params: dict[str, Any], error: type[Exception], words: str
) -> None:
    with pytest.raises(error) as e:
        model.with_params(**params)
    assert words in str(e.value)


def test_model_load_takes_vec3_params(tmp_path: Path) -> None:
    path = _write(tmp_path, "offset.tmr", ANCHOR_OFFSET)
    m = Model.load(path, params={"offset": [1, 2, 3]})
    assert m.values == {"offset": (1.0, 2.0, 3.0)}
    with pytest.raises(ValueError, match="expected 3 real numbers, got 2"):
        Model.load(path, params={"offset": [1, 2]})


def test_describe_and_cli_models_show_vec3_defaults(
    tmp_path: Path, model: Model, capsys: pytest.CaptureFixture[str]
) -> None:
    described = model.describe()["params"]
    assert described == {
        "k": {"type": "f64", "default": 10.0},
        "offset": {"type": "vec3", "default": [0.0, 0.0, 0.0]},
    }
    path = _write(
        tmp_path,
        "o.tmr",
        ANCHOR_OFFSET.replace("offset: vec3 = vec3(0, 0, 0)", "offset: vec3 = vec3(1, -2.5, 0)"),
    )
    assert main(["models", str(path)]) == 0
    out = capsys.readouterr().out
    assert "  parameters: k: f64 = 10, offset: vec3 = [1, -2.5, 0]\n" in out
    assert main(["models", "--json", str(path)]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert listed[0]["params"] == {
        "k": {"type": "f64", "default": 10.0},
        "offset": {"type": "vec3", "default": [1.0, -2.5, 0.0]},
    }


# ---------------------------------------------------------------------- shipped models


def test_shipped_models_read_param_types() -> None:
    """Every shipped parameter's type is f64 or vec3, and its default agrees with it."""
    for m in shipped_models():
        assert set(m.params) == set(m.param_types), m.name
        for p, ty in m.param_types.items():
            assert ty in ("f64", "vec3"), (m.name, p, ty)
            d = m.params[p]
            if d is None:
                continue
            if ty == "vec3":
                assert isinstance(d, list), (m.name, p, d)
                assert len(d) == 3, (m.name, p, d)
                assert all(type(x) is float for x in d), (m.name, p, d)
            else:
                assert type(d) is float, (m.name, p, d)


#: A shipped model this build does not have, with a vec3 parameter (the kernel's catalogue
#: is replaced by the real one plus this entry).
PULL = {
    "kind": "pull",
    "dims": [2, 3],
    "params": {"stiffness": 1.0, "target": [0.0, 0.0, 1.0], "pivot": None},
    "param_types": {"stiffness": "f64", "target": "vec3", "pivot": "vec3"},
    "needs": "vertices",
    "has_jvp": True,
    "per_element": False,
}


@pytest.fixture
def with_pull(monkeypatch: pytest.MonkeyPatch) -> None:
    real = topomech._core.models()
    monkeypatch.setattr(topomech._core, "models", lambda: [*real, dict(PULL)])


@pytest.mark.usefixtures("with_pull")
def test_shipped_vec3_parameters_are_models_of_their_type(
    capsys: pytest.CaptureFixture[str],
) -> None:
    m = Model.shipped("pull")
    assert m.params == {"stiffness": 1.0, "target": [0.0, 0.0, 1.0], "pivot": None}
    assert m.param_types == {"stiffness": "f64", "target": "vec3", "pivot": "vec3"}
    assert m.with_params(target=(1, 2, 3)).config_entry() == {
        "kind": "pull",
        "target": [1.0, 2.0, 3.0],
    }
    with pytest.raises(TypeError, match="parameter 'target' is a vec3"):
        m.with_params(target=2.0)
    assert main(["models"]) == 0
    assert (
        "  parameters: stiffness: f64 = 1, target: vec3 = [0, 0, 1], pivot: vec3 = required\n"
        in capsys.readouterr().out
    )


def test_shipped_models_without_param_types_are_f64(monkeypatch: pytest.MonkeyPatch) -> None:
    """A kernel that lists no ``param_types`` (older builds): every parameter is an f64."""
    old = [{k: v for k, v in m.items() if k != "param_types"} for m in topomech._core.models()]
    monkeypatch.setattr(topomech._core, "models", lambda: old)
    models = shipped_models()
    assert models
    assert all(t == "f64" for m in models for t in m.param_types.values())
    assert Model.shipped("stretch_elementary").params == {"stiffness": 1000.0, "damping": 0.0}


# ------------------------------------------------------------------------------ scenes


def _scene_error(tmp_path: Path, text: str) -> SceneError:
    scene = _write(tmp_path, "s.toml", text)
    with pytest.raises(SceneError) as e:
        topomech.load_scene(scene)
    return e.value


def test_a_scene_sets_a_vec3_parameter_of_a_model_file(tmp_path: Path) -> None:
    _write(tmp_path, "offset.tmr", ANCHOR_OFFSET)
    scene = topomech.load_scene(_write(tmp_path, "s.toml", _scene()))
    assert scene.config["models"] == [{"kind": "anchor_offset", "k": K, "offset": list(OFFSET)}]
    assert scene.user_models[0].values == {"k": K, "offset": OFFSET}


@pytest.mark.parametrize(
    ("value", "key", "words"),
    [
        (
            "offset = 0.5",
            "model[0].offset",
            "parameter 'offset' of model 'anchor_offset' is vec3: expected an array of 3 "
            "numbers, got 0.5",
        ),
        (
            "offset = [0.5, 1.0]",
            "model[0].offset",
            "expected an array of 3 numbers, got [0.5, 1.0]",
        ),
        (
            "offset = [1, 2, 3, 4]",
            "model[0].offset",
            "expected an array of 3 numbers, got [1, 2, 3, 4]",
        ),
        (
            'offset = "0 0 1"',
            "model[0].offset",
            'is vec3: expected an array of 3 numbers, got "0 0 1"',
        ),
        (
            "offset = { x = 1 }",
            "model[0].offset",
            "is vec3: expected an array of 3 numbers, got a table",
        ),
        ('offset = [0.5, "a", 1.0]', "model[0].offset[1]", 'expected a number, got "a"'),
        ("offset = [0.5, true, 1.0]", "model[0].offset[1]", "expected a number, got true"),
        ("offset = [0.5, 1.0, inf]", "model[0].offset[2]", "must be finite, got inf"),
        ("offset = [nan, 1.0, 0.0]", "model[0].offset[0]", "must be finite, got nan"),
        (
            "k = [1.0, 2.0, 3.0]",
            "model[0].k",
            "parameter 'k' of model 'anchor_offset' is f64: expected a number, got [1.0, 2.0, 3.0]",
        ),
        ('k = "big"', "model[0].k", 'expected a number, got "big"'),
    ],
)
def test_a_scene_refuses_a_vec3_parameter_of_the_wrong_shape(
    tmp_path: Path, value: str, key: str, words: str
) -> None:
    _write(tmp_path, "offset.tmr", ANCHOR_OFFSET)
    e = _scene_error(tmp_path, _scene(params=value))
    assert e.key == key, str(e)
    assert f": {key}: " in str(e), str(e)
    assert words in str(e), str(e)


def test_the_second_model_table_is_named(tmp_path: Path) -> None:
    """The key names the table's index."""
    _write(tmp_path, "offset.tmr", ANCHOR_OFFSET)
    text = _scene().replace(
        "[material]", '[[model]]\nfile = "offset.tmr"\noffset = [1.0]\n\n[material]'
    )
    e = _scene_error(tmp_path, text)
    assert e.key == "model[1].offset", str(e)


def _pull_scene(params: str) -> str:
    return f"""\
[mesh]
generator = "grid"
element = "triangle"

[[model]]
kind = "stretch_elementary"

[[model]]
kind = "pull"
{params}
"""


@pytest.mark.usefixtures("with_pull")
def test_a_scene_sets_a_vec3_parameter_of_a_shipped_kind() -> None:
    scene = parse_scene(_pull_scene("target = [1, -2, 0.5]\nstiffness = 3.0"))
    assert scene.config["models"][1] == {
        "kind": "pull",
        "target": [1.0, -2.0, 0.5],
        "stiffness": 3.0,
    }
    for params, key, words in [
        (
            "target = 1.0",
            "model[1].target",
            "parameter 'target' of model 'pull' is vec3: expected an array of 3 numbers, got 1.0",
        ),
        (
            "target = [1.0, 2.0]",
            "model[1].target",
            "is vec3: expected an array of 3 numbers, got [1.0, 2.0]",
        ),
        ('target = [1.0, 2.0, "z"]', "model[1].target[2]", 'expected a number, got "z"'),
        (
            "stiffness = [1.0, 2.0, 3.0]",
            "model[1].stiffness",
            "parameter 'stiffness' of model 'pull' is f64: expected a number",
        ),
        # the f64 parameters of shipped kinds stay >= 0; a vec3's numbers have any sign
        ("stiffness = -1.0", "model[1].stiffness", "must be >= 0"),
    ]:
        with pytest.raises(SceneError) as e:
            parse_scene(_pull_scene(params))
        assert e.value.key == key, str(e.value)
        assert f": {key}: " in str(e.value), str(e.value)
        assert words in str(e.value), str(e.value)


# ---------------------------------------------------------------------- running them


@pytest.mark.parametrize("integrator", list(RUNS))
def test_a_vec3_parameter_set_in_a_scene_runs_with_topomech_run(
    tmp_path: Path, integrator: str
) -> None:
    """`topomech run` on a scene setting `offset = [...]`: in the final state every free
    vertex is at rest + offset, the held ones at rest; the summary lists the value."""
    _write(tmp_path, "offset.tmr", ANCHOR_OFFSET)
    scene = _write(tmp_path, "s.toml", _scene(integrator))
    out = tmp_path / "out"
    r = _cli("run", scene, "--out", out, "--no-preview")
    assert r.returncode == 0, r.stderr + r.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["models"] == [{"kind": "anchor_offset", "k": K, "offset": list(OFFSET)}]
    final = meshio.read(out / "final.vtu")
    u = np.asarray(final.point_data["displacement"], dtype=np.float64)
    rest = np.asarray(final.points, dtype=np.float64) - u
    _check_offset(u, rest, OFFSET, RUNS[integrator][2], f"topomech run, {integrator}")


def _python_forms(path: Path) -> dict[str, dict[str, Any]]:
    """The ways Python sets the parameter: a Model with a list or an array, and the dict
    form with the file's text."""
    text = path.read_text(encoding="utf-8")
    model = Model.load(path)
    return {
        "model-list": {"models": [model.with_params(k=K, offset=list(OFFSET))]},
        "model-array": {"models": [model.with_params(k=K, offset=np.array(OFFSET))]},
        "dict": {
            "models": [{"kind": "anchor_offset", "k": K, "offset": list(OFFSET)}],
            "model_files": [(str(path), text)],
        },
        "dict-tuple": {
            "models": [{"kind": "anchor_offset", "k": K, "offset": OFFSET}],
            "model_files": [(str(path), text)],
        },
    }


@pytest.mark.parametrize("form", ["model-list", "model-array", "dict", "dict-tuple"])
@pytest.mark.parametrize("integrator", list(RUNS))
def test_a_vec3_parameter_set_from_python_runs(tmp_path: Path, form: str, integrator: str) -> None:
    path = _write(tmp_path, "offset.tmr", ANCHOR_OFFSET)
    dt, steps, rtol = RUNS[integrator]
    sim = topomech.Simulation(
        _grid(),
        **_python_forms(path)[form],
        density=DENSITY,
        damping=DAMPING,
        gravity=[0.0, 0.0, 0.0],
        fixed=[FIXED],
        integrator=integrator,
        dt=dt,
    )
    sim.step(steps)
    _check_offset(sim.displacements(), sim.rest_positions(), OFFSET, rtol, f"{form}, {integrator}")


def test_a_vec3_default_is_used_when_not_set(tmp_path: Path) -> None:
    """Not set, the parameter keeps the file's default: from Python and from a scene."""
    default = (0.0, 0.1, -0.2)
    text = ANCHOR_OFFSET.replace("vec3(0, 0, 0)", "vec3(0.0, 0.1, -0.2)")
    path = _write(tmp_path, "offset.tmr", text)
    sim = topomech.Simulation(
        _grid(),
        models=[Model.load(path).with_params(k=K)],
        gravity=[0.0, 0.0, 0.0],
        fixed=[FIXED],
        integrator="static",
        dt=1.0,
    )
    sim.step()
    _check_offset(sim.displacements(), sim.rest_positions(), default, 1e-12, "default")
    scene = topomech.load_scene(_write(tmp_path, "s.toml", _scene(params=f"k = {K}")))
    sim = scene.build()
    sim.step()
    _check_offset(sim.displacements(), sim.rest_positions(), default, 1e-12, "scene default")


def test_the_simulation_refuses_a_parameter_of_the_wrong_type(tmp_path: Path) -> None:
    """The dict form is checked against the declaration when the simulation is built, naming
    the model and the parameter."""
    path = _write(tmp_path, "offset.tmr", ANCHOR_OFFSET)
    files = [(str(path), ANCHOR_OFFSET)]
    for params, words in [
        ({"offset": 1.0}, "parameter 'offset'"),
        ({"k": [1.0, 2.0, 3.0]}, "parameter 'k'"),
    ]:
        with pytest.raises((SimulationError, ValueError)) as e:
            topomech.Simulation(
                _grid(), models=[{"kind": "anchor_offset", **params}], model_files=files
            )
        assert "anchor_offset" in str(e.value), str(e.value)
        assert words in str(e.value), str(e.value)
    with pytest.raises((ValueError, TypeError), match=r"models\[0\]\['offset'\]"):
        topomech.Simulation(
            _grid(), models=[{"kind": "anchor_offset", "offset": [1.0, 2.0]}], model_files=files
        )
