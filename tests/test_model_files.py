"""A model the user writes as a rule file, run from a scene (``topomech run``, a subprocess),
from Python (``Simulation``) and listed and checked by the CLI (``topomech models``,
``topomech check``).

The model: per-vertex anchor springs ``f = -k (x - x_rest)`` with their exact Jacobian
``df = -k dx``. Under gravity ``g`` each free vertex of mass ``m`` carries its own weight on
its own spring, so the equilibrium is ``u = m g / k`` at each vertex (independent of the
mesh: the vertices do not interact). A single free vertex oscillates with the period
``T = 2 pi sqrt(m / k)``.
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

import topomech
from topomech import Model, RuleError, SceneError, SimulationError
from topomech.cli import main
from topomech.samples import sample

from conftest import ANCHOR

#: The same model without Jacobian rules (explicit integrators only).
ANCHOR_NO_JVP = ANCHOR.replace("  jvp    anchor_jvp -> df_anchor\n", "")

K = 50.0
G = 9.81
DENSITY = 2.0
DAMPING = 20.0

#: Integrators the anchor model allows, with (dt, steps). The damped explicit runs settle:
#: the error decays like exp(-c t / 2) with c = 20 1/s; 6 s leave ~1e-26 of the start.
RUNS = {
    "static": (1.0, 1),
    "implicit_euler": (1e-3, 6000),
    "symplectic_euler": (1e-3, 6000),
    "explicit_euler": (1e-3, 6000),
}


def _write(folder: Path, name: str, text: str) -> Path:
    p = folder / name
    p.write_text(text, encoding="utf-8")
    return p


def _scene(integrator: str, *, file: str = "anchor.tmr", extra: str = "") -> str:
    dt, steps = RUNS.get(integrator, (1e-3, 10))
    return f"""\
name = "anchored"

[mesh]
generator = "grid"
element = "triangle"
size = [1.5, 1.0]
cells = [3, 2]

[[model]]
file = "{file}"
k = {K}
{extra}
[material]
density = {DENSITY}
damping = {DAMPING}

[world]
gravity = [0.0, -{G}, 0.0]

[integrator]
kind = "{integrator}"
dt = {dt}
steps = {steps}

[output]
every = {steps}
fields = ["mass"]
"""


def _check_m_g_over_k(u: np.ndarray, m: np.ndarray, what: str) -> None:
    """Each vertex's displacement equals m g / k (downward), to 1e-10 of |m g / k|."""
    assert len(m) > 4, what
    assert np.all(m > 0), what
    want = np.zeros_like(u)
    want[:, 1] = -m * G / K
    scale = m * G / K
    err = np.abs(u - want).max(axis=1) / scale
    assert err.max() <= 1e-10, f"{what}: worst relative error {err.max():.3e}"


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


# ------------------------------------------------------------------------ the done-when test


@pytest.mark.parametrize("integrator", list(RUNS))
def test_a_new_model_file_runs_from_a_scene_with_topomech_run(
    tmp_path: Path, integrator: str
) -> None:
    """`topomech run` on a scene naming the user's file: the last frame's displacement is
    m g / k at every vertex (the frame's `mass` field gives m), to 1e-10."""
    _write(tmp_path, "anchor.tmr", ANCHOR)
    scene = _write(tmp_path, "anchored.toml", _scene(integrator))
    out = tmp_path / "out"
    r = _cli("run", scene, "--out", out, "--no-preview")
    assert r.returncode == 0, r.stderr + r.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["models"] == [{"kind": "anchor", "k": K}]
    assert summary["integrator"] == integrator
    last = meshio.read(out / "final.vtu")
    u = np.asarray(last.point_data["displacement"])
    m = np.asarray(last.point_data["mass"])
    _check_m_g_over_k(u, m, f"topomech run, {integrator}")


@pytest.mark.parametrize("integrator", list(RUNS))
def test_a_new_model_file_runs_from_python(tmp_path: Path, integrator: str) -> None:
    """`Simulation(models=[Model.load(path).with_params(k=K)])`, each integrator the model
    allows: every vertex settles at m g / k, to 1e-10."""
    path = _write(tmp_path, "anchor.tmr", ANCHOR)
    model = Model.load(path).with_params(k=K)
    dt, steps = RUNS[integrator]
    g = topomech.GMap.from_flat(*topomech._core.grid(3, 2, 1.5, 1.0, "triangle"))
    sim = topomech.Simulation(
        g,
        models=[model],
        density=DENSITY,
        damping=DAMPING,
        gravity=[0.0, -G, 0.0],
        integrator=integrator,
        dt=dt,
    )
    sim.step(steps)
    _check_m_g_over_k(sim.displacements(), sim.masses(), f"Simulation, {integrator}")


def test_an_undamped_single_vertex_oscillates_with_period_2_pi_sqrt_m_over_k(
    tmp_path: Path,
) -> None:
    """One free vertex (the others held), no gravity, released from u0 = 0.01 along x:
    symplectic Euler keeps the oscillation, whose period is 2 pi sqrt(m / k). Measured from
    the zero crossings of u over 5 periods; symplectic Euler's period error is O((w dt)^2)
    (w dt = 0.01 here: ~1e-5 relative), checked to 1e-3 relative."""
    path = _write(tmp_path, "anchor.tmr", ANCHOR)
    g = topomech.GMap.from_flat(*topomech._core.grid(1, 1, 1.0, 1.0, "triangle"))
    sim = topomech.Simulation(
        g,
        models=[Model.load(path, params={"k": K})],
        density=DENSITY,
        damping=0.0,
        gravity=[0.0, 0.0, 0.0],
        integrator="symplectic_euler",
        fixed=["x < 0.5 || y < 0.5"],
        dt=1.0,  # replaced below once m is known
    )
    free = np.flatnonzero(~sim.fixed())
    assert len(free) == 1
    v = int(free[0])
    m = float(sim.masses()[v])
    period = 2 * math.pi * math.sqrt(m / K)
    dt = period / 628.0
    sim = topomech.Simulation(
        g,
        models=[Model.load(path, params={"k": K})],
        density=DENSITY,
        damping=0.0,
        gravity=[0.0, 0.0, 0.0],
        integrator="symplectic_euler",
        fixed=["x < 0.5 || y < 0.5"],
        dt=dt,
    )
    x = sim.positions()
    x[v, 0] += 0.01
    sim.set_positions(x)
    ts, us = [], []
    for _ in range(int(5.5 * 628)):
        sim.step()
        ts.append(sim.time)
        us.append(sim.displacements()[v, 0])
    u = np.asarray(us)
    t = np.asarray(ts)
    up = np.flatnonzero((u[:-1] < 0) & (u[1:] >= 0))  # upward zero crossings
    assert len(up) >= 5
    cross = t[up] + (t[up + 1] - t[up]) * (-u[up]) / (u[up + 1] - u[up])
    measured = float(np.diff(cross).mean())
    assert abs(measured - period) <= 1e-3 * period, (measured, period)


# ------------------------------------------------------------------ no jvp: explicit only


def test_a_model_without_jvp_is_refused_for_static_and_implicit_from_python(
    tmp_path: Path,
) -> None:
    path = _write(tmp_path, "anchor.tmr", ANCHOR_NO_JVP)
    model = Model.load(path)
    assert not model.has_jvp
    assert model.integrators == ("explicit_euler", "symplectic_euler")
    g = topomech.GMap.from_flat(*topomech._core.grid(2, 2, 1.0, 1.0, "triangle"))
    for integrator in ("static", "implicit_euler"):
        with pytest.raises(SimulationError, match="model 'anchor' has no Jacobian rules"):
            topomech.Simulation(g, models=[model], integrator=integrator)
    sim = topomech.Simulation(g, models=[model], integrator="symplectic_euler")
    sim.step(2)
    assert sim.steps == 2


def test_a_model_without_jvp_is_refused_for_static_from_a_scene(tmp_path: Path) -> None:
    """Through `topomech run` (exit 2, the message names the model and the scene key) and
    through `load_scene(...).build()`."""
    _write(tmp_path, "anchor.tmr", ANCHOR_NO_JVP)
    scene = _write(tmp_path, "anchored.toml", _scene("static"))
    with pytest.raises(SceneError, match="model 'anchor' has no Jacobian rules") as e:
        topomech.load_scene(scene).build()
    assert e.value.key == "model[0].file"
    r = _cli("run", scene, "--out", tmp_path / "out", "--no-preview")
    assert r.returncode == 2, r.stdout + r.stderr
    assert "model[0].file" in r.stderr
    assert "model 'anchor' has no Jacobian rules" in r.stderr


# --------------------------------------------------------------------- scene refusals


def _scene_error(tmp_path: Path, text: str) -> SceneError:
    scene = _write(tmp_path, "s.toml", text)
    with pytest.raises(SceneError) as e:
        topomech.load_scene(scene).build()
    return e.value


TWO = ANCHOR + ANCHOR.split("model anchor", 1)[1].join(["\nmodel anchor_too", ""])


def test_scene_model_file_refusals_name_the_key(tmp_path: Path) -> None:
    _write(tmp_path, "anchor.tmr", ANCHOR)
    _write(tmp_path, "two.tmr", TWO)
    base = _scene("symplectic_euler")
    cases = [
        # kind and file together
        (
            base.replace('file = "anchor.tmr"', 'kind = "corotational"\nfile = "anchor.tmr"'),
            "model[0].kind",
            "not both",
        ),
        # a missing file
        (base.replace("anchor.tmr", "nowhere.tmr"), "model[0].file", "cannot read"),
        # unknown parameter: the model's parameters named
        (
            base.replace(f"k = {K}", "stiffness = 3.0"),
            "model[0].stiffness",
            "model 'anchor' takes k",
        ),
        # several models, no name
        (
            base.replace("anchor.tmr", "two.tmr"),
            "model[0].name",
            "declares several models (anchor, anchor_too)",
        ),
        # unknown name
        (
            base.replace('file = "anchor.tmr"', 'file = "two.tmr"\nname = "nope"'),
            "model[0].name",
            "declares no model 'nope' (it declares: anchor, anchor_too)",
        ),
    ]
    for text, key, words in cases:
        e = _scene_error(tmp_path, text)
        assert e.key == key, (key, str(e))
        assert words in str(e), str(e)


def test_scene_picks_a_named_model_of_a_file(tmp_path: Path) -> None:
    _write(tmp_path, "two.tmr", TWO)
    text = _scene("symplectic_euler").replace(
        'file = "anchor.tmr"', 'file = "two.tmr"\nname = "anchor_too"'
    )
    scene = topomech.load_scene(_write(tmp_path, "s.toml", text))
    assert scene.models == ["anchor_too"]
    sim = scene.build()
    sim.step(3)
    assert sim.steps == 3


def test_a_required_parameter_missing_is_refused(tmp_path: Path) -> None:
    _write(tmp_path, "anchor.tmr", ANCHOR.replace("k: f64 = 10.0", "k: f64"))
    e = _scene_error(tmp_path, _scene("symplectic_euler").replace(f"k = {K}\n", ""))
    assert e.key == "model[0].k", str(e)
    assert "no default for parameter 'k'" in str(e)


def test_a_refused_rule_file_is_reported_at_file_line_col(tmp_path: Path) -> None:
    bad = ANCHOR.replace("init   anchor_init(k)", "init   anchor_init(k, k)")
    path = _write(tmp_path, "anchor.tmr", bad)
    line = bad.splitlines().index("  init   anchor_init(k, k)") + 1
    e = _scene_error(tmp_path, _scene("symplectic_euler"))
    assert e.key == "model[0].file"
    assert f"{path}:{line}:10: error[arity]" in str(e), str(e)
    with pytest.raises(RuleError, match=rf"anchor.tmr:{line}:10: error\[arity\]"):
        Model.load(path)


# -------------------------------------------------------------------------------- Python


def test_model_load_and_shipped(tmp_path: Path) -> None:
    path = _write(tmp_path, "two.tmr", TWO)
    with pytest.raises(ValueError, match=r"declares several models \(anchor, anchor_too\)"):
        Model.load(path)
    with pytest.raises(ValueError, match="declares no model 'x'"):
        Model.load(path, "x")
    m = Model.load(path, "anchor_too")
    assert (m.name, m.params, m.dimensions, m.needs, m.has_jvp, m.file) == (
        "anchor_too",
        {"k": 10.0},
        (2,),
        "vertices",
        True,
        str(path),
    )
    assert m.with_params(k=3).values == {"k": 3.0}
    # what a simulation runs it with: the value set, else the default (params stays the
    # declared defaults)
    assert m.param_values == {"k": 10.0}
    assert m.with_params(k=3).param_values == {"k": 3.0}
    assert m.with_params(k=3).params == {"k": 10.0}
    with pytest.raises(ValueError, match=r"has no parameter 'q' \(it has: k\)"):
        m.with_params(q=1.0)
    with pytest.raises(ValueError, match="finite"):
        m.with_params(k=math.inf)
    s = Model.shipped("corotational", 2)
    assert (s.params, s.dimensions, s.has_jvp, s.file) == ({"thickness": 1.0}, (2,), True, None)
    assert Model.shipped("bending_angular").integrators == ("explicit_euler", "symplectic_euler")
    with pytest.raises(ValueError, match="no shipped model 'nope'"):
        Model.shipped("nope")


def test_a_shipped_model_object_runs_like_its_kind() -> None:
    g = topomech.GMap.from_flat(*topomech._core.grid(2, 2, 1.0, 1.0, "triangle"))
    runs = []
    for m in (
        {"kind": "stretch_elementary", "stiffness": 300.0},
        Model.shipped("stretch_elementary").with_params(stiffness=300.0),
    ):
        sim = topomech.Simulation(g, models=[m], fixed=["y < 1e-9"], dt=1e-3)
        sim.step(20)
        runs.append(sim.positions())
    assert np.array_equal(runs[0], runs[1])
    assert not np.array_equal(
        runs[0],
        topomech.Simulation(g, models=["stretch_elementary"], fixed=["y < 1e-9"]).positions(),
    )


# ----------------------------------------------------------------------------------- CLI


def test_cli_models_lists_shipped_and_file_models(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    assert "stretch_elementary\n" in out
    assert "  parameters: stiffness: f64 = 1000, damping: f64 = 0" in out
    path = _write(tmp_path, "anchor.tmr", ANCHOR)
    nojvp = _write(tmp_path, "nojvp.tmr", ANCHOR_NO_JVP.replace("model anchor", "model loose"))
    assert main(["models", str(path), str(nojvp)]) == 0
    out = capsys.readouterr().out
    assert out == (
        f"anchor  ({path})\n"
        "  dimensions: 2\n"
        "  parameters: k: f64 = 10\n"
        "  needs: vertices\n"
        "  jacobian: yes (integrators: explicit_euler, symplectic_euler, implicit_euler, "
        "static)\n"
        f"loose  ({nojvp})\n"
        "  dimensions: 2\n"
        "  parameters: k: f64 = 10\n"
        "  needs: vertices\n"
        "  jacobian: no (integrators: explicit_euler, symplectic_euler)\n"
    )
    assert main(["models", "--json", str(path)]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert listed == [
        {
            "name": "anchor",
            "file": str(path),
            "params": {"k": {"type": "f64", "default": 10.0}},
            "dimensions": [2],
            "needs": "vertices",
            "has_jvp": True,
            "integrators": ["explicit_euler", "symplectic_euler", "implicit_euler", "static"],
        }
    ]


def test_cli_models_of_a_refused_or_missing_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = _write(tmp_path, "bad.tmr", ANCHOR.replace("forces f_anchor", "forces f_nothing"))
    assert main(["models", str(bad)]) == 1
    assert f"{bad}:" in capsys.readouterr().out
    assert main(["models", str(tmp_path / "none.tmr")]) == 2
    assert "cannot read the rule file" in capsys.readouterr().err


def test_cli_check_loads_the_shipped_common_rules_for_a_model_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The anchor file uses position, rest and dx without declaring them: clean."""
    path = _write(tmp_path, "anchor.tmr", ANCHOR)
    assert main(["check", str(path)]) == 0
    assert capsys.readouterr().out == (
        "ok: 3 rules and 1 model in 1 file (with the shipped common rules of dimension 2)\n"
    )


def test_cli_apply_loads_a_model_file_as_check_does(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`topomech apply` on a model file loads the shipped common rules first, as `check`
    does: before, `check anchor.tmr` said ok while `apply ... anchor.tmr anchor_init` refused
    the file with `unknown embedding 'position'` (and 'dx')."""
    path = _write(tmp_path, "anchor.tmr", ANCHOR)
    sheet = sample("sheet.obj")
    out = tmp_path / "x.tmg"
    args = ["apply", str(sheet), str(path), "anchor_init", "--everywhere", "--param", "k=5"]
    assert main([*args, "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert "unknown embedding" not in captured.err, captured.err
    assert captured.out.startswith("matches: 81\n"), captured.out
    assert np.allclose(topomech.GMap.load(out).embedding("k_anchor").values, 5.0)
    # a file without a model is loaded alone, as before: its undeclared embeddings refused
    plain = _write(tmp_path, "plain.tmr", ANCHOR.split("model anchor")[0])
    args = ["apply", str(sheet), str(plain), "anchor_init", "--everywhere", "--param", "k=5"]
    assert main([*args, "--out", str(out)]) == 2
    assert "unknown embedding 'position'" in capsys.readouterr().err


def _line_col(text: str, needle: str) -> tuple[int, int]:
    for i, line in enumerate(text.splitlines()):
        if needle in line:
            return i + 1, line.index(needle) + 1
    raise AssertionError(needle)


#: Mistakes in a model declaration, each reported by `topomech check` at FILE:LINE:COL:
#: (the broken text, the line it is on, the token it points at, the condition, words of
#: the message).
MISTAKES = [
    # an unknown rule in a model
    (
        ANCHOR.replace("step   anchor_force", "step   anchor_fource"),
        "step   anchor_fource",
        "anchor_fource",
        "name",
        "anchor_fource",
    ),
    # a wrong arity
    (
        ANCHOR.replace("init   anchor_init(k)", "init   anchor_init(k, k)"),
        "init   anchor_init(k, k)",
        "anchor_init",
        "arity",
        "rule 'anchor_init' takes 1 argument(s)",
    ),
    # a force embedding not on a sub-orbit of the vertex (<0,1>: the face's darts)
    (
        ANCHOR.replace("f_anchor  : vec3 on <1,2>", "f_anchor  : vec3 on <0,1>").replace(
            "v.f_anchor = -v.k_anchor * (v.position - v.rest)", "v.k_anchor = 1.0"
        ),
        "forces f_anchor",
        "f_anchor",
        "type",
        "force 'f_anchor' is a vec3 on <0,1>; it must be a vec3 on a sub-orbit of the vertex",
    ),
    # a jvp output that is not a vector embedding
    (
        ANCHOR.replace("-> df_anchor", "-> k_anchor"),
        "jvp    anchor_jvp -> k_anchor",
        "k_anchor",
        "type",
        "k_anchor",
    ),
]


@pytest.mark.parametrize("case", range(len(MISTAKES)))
def test_cli_check_reports_model_mistakes_at_file_line_col(tmp_path: Path, case: int) -> None:
    """Through the CLI (a subprocess): exit 1 and the diagnostic at the mistake's
    FILE:LINE:COL, with the shipped common rules loaded (no other error)."""
    text, on_line, token, condition, words = MISTAKES[case]
    path = _write(tmp_path, "anchor.tmr", text)
    r = _cli("check", path)
    assert r.returncode == 1, r.stdout + r.stderr
    rows = text.splitlines()
    line = next(i for i, t in enumerate(rows) if on_line in t) + 1
    col = rows[line - 1].index(token) + 1
    errors = [x for x in r.stdout.splitlines() if ": error[" in x]
    assert errors, r.stdout
    assert errors[0].startswith(f"{path}:{line}:{col}: error[{condition}]"), (r.stdout, line, col)
    assert words in errors[0], r.stdout
    assert "common2d.tmr" not in r.stdout


def test_python_refusals_name_the_model(tmp_path: Path) -> None:
    """A required parameter not set, and a 2D model on a 3D map: refused naming the model
    (and its file)."""
    path = _write(tmp_path, "req.tmr", ANCHOR.replace("k: f64 = 10.0", "k: f64"))
    m = Model.load(path)
    assert m.params == {"k": None}
    assert m.missing == ["k"]
    g2 = topomech.GMap.from_flat(*topomech._core.grid(2, 2, 1.0, 1.0, "triangle"))
    with pytest.raises(SimulationError, match="model 'anchor': parameter 'k' is required"):
        topomech.Simulation(g2, models=[m])
    g3 = topomech.GMap.from_flat(*topomech._core.box(1, 1, 1, 1.0, 1.0, 1.0, "tetra"))
    with pytest.raises(
        SimulationError,
        match=rf"models\[0\]: model 'anchor' \({re.escape(str(path))}\) runs "
        "on 2D maps, this map is 3D",
    ):
        topomech.Simulation(g3, models=[m.with_params(k=1.0)])


def test_a_users_force_embedding_is_an_output_field(tmp_path: Path) -> None:
    """`output.fields` names the model's own force embedding `f_anchor` (a vec3 on the vertex,
    which exists on the map once the force rule has run): the final file carries it, equal to
    -k u at every vertex (the anchor's law, to 1e-12 of |k u|: one subtraction and product)."""
    _write(tmp_path, "anchor.tmr", ANCHOR)
    text = _scene("static").replace('fields = ["mass"]', 'fields = ["mass", "f_anchor"]')
    scene = _write(tmp_path, "anchored.toml", text)
    out = tmp_path / "out"
    r = _cli("run", scene, "--out", out, "--no-preview")
    assert r.returncode == 0, r.stderr + r.stdout
    last = meshio.read(out / "final.vtu")
    u = np.asarray(last.point_data["displacement"])
    f = np.asarray(last.point_data["f_anchor"])
    scale = K * np.abs(u).max()
    assert scale > 0
    assert np.abs(f + K * u).max() <= 1e-12 * scale


def test_an_unknown_output_field_lists_each_available_name_once(tmp_path: Path) -> None:
    _write(tmp_path, "anchor.tmr", ANCHOR)
    text = _scene("static").replace('fields = ["mass"]', 'fields = ["no_such_field"]')
    scene = _write(tmp_path, "anchored.toml", text)
    r = _cli("run", scene, "--out", tmp_path / "out", "--no-preview")
    assert r.returncode != 0
    err = r.stderr + r.stdout
    assert "unknown field 'no_such_field'" in err, err
    listed = err.split("available: ", 1)[1]
    for name in ("velocity", "fixed", "point_id", "f_anchor"):
        assert listed.count(name) == 1, (name, listed)


def test_a_model_file_in_a_dict_says_how_to_give_it() -> None:
    g = topomech.GMap.from_flat(*topomech._core.grid(2, 2, 1.0, 1.0, "triangle"))
    with pytest.raises(
        TypeError, match=r"models\[0\]\['file'\]: a model from a rule file is given"
    ):
        topomech.Simulation(g, models=[{"file": "anchor.tmr"}])


def test_a_model_file_that_is_not_utf8_is_named(tmp_path: Path) -> None:
    """``Model.load`` on a file that is not UTF-8: the UnicodeDecodeError names the file."""
    bad = tmp_path / "binary.tmr"
    bad.write_bytes(b"\xff\xfe model m() {}\n")
    with pytest.raises(UnicodeDecodeError, match=r"binary\.tmr: not UTF-8 text"):
        topomech.Model.load(bad)


def test_an_unused_parameter_with_a_default_is_a_warning_not_a_lost_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A model parameter with a default that no rule call passes on gets a warning from
    `topomech check` (exit 0), and the model stays: `Model.load` finds it, with the
    parameter (QA: the warning dropped the model, and the file then declared none)."""
    from topomech import cli

    path = _write(
        tmp_path,
        "anchor.tmr",
        ANCHOR.replace("model anchor(k: f64 = 10.0)", "model anchor(k: f64 = 10.0, c: f64 = 3.0)"),
    )
    assert cli.main(["check", str(path)]) == 0
    out, err = capsys.readouterr()
    assert "warning[unused-parameter]" in out + err
    assert "1 model" in out + err
    m = Model.load(path)
    assert m.params == {"k": 10.0, "c": 3.0}
