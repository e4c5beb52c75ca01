"""`topomech run` and `topomech demo`: every shipped scene runs, its outputs parse, and the
exit codes say what happened (0 ran, 1 diverged, 2 refused, 130 interrupted)."""

from __future__ import annotations

import io
import json
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np
import pytest

import topomech
from topomech import cli
from topomech.run import Progress, run_scene
from topomech.scene import shipped_scenes

SUMMARY_KEYS = {
    "steps",
    "dt",
    "time",
    "darts",
    "vertices",
    "edges",
    "faces",
    "volumes",
    "total_mass",
    "kinetic_energy",
    "max_displacement",
    "wall_seconds",
    "steps_per_second",
    "models",
    "integrator",
    "scene",
}

SPRINGS = """
[mesh]
generator = "grid"
element = "tri"
size = [1.0, 1.0]
cells = [2, 2]

[[model]]
kind = "stretch_elementary"
stiffness = {stiffness}

[material]
density = 1.0

[[fix]]
where = "x < 1e-9"

[integrator]
kind = "{integrator}"
dt = {dt}
steps = {steps}

[output]
every = {every}
"""


def springs(tmp_path: Path, **kw: object) -> Path:
    values: dict[str, object] = {
        "stiffness": 100.0,
        "integrator": "symplectic_euler",
        "dt": 1e-3,
        "steps": 10,
        "every": 4,
    }
    values.update(kw)
    p = tmp_path / "springs.toml"
    p.write_text(SPRINGS.format(**values))
    return p


def check_outputs(out: Path, steps: int) -> dict:
    """Checks summary.json, final.vtu, animation.pvd and the frames; returns the summary."""
    summary = json.loads((out / "summary.json").read_text())
    assert summary.keys() >= SUMMARY_KEYS
    assert "error" not in summary
    assert summary["steps"] == steps
    assert summary["time"] == pytest.approx(steps * summary["dt"])
    assert summary["total_mass"] > 0
    final = meshio.read(out / "final.vtu")
    assert len(final.points) == summary["vertices"]
    assert final.point_data["displacement"].shape == (summary["vertices"], 3)
    assert final.point_data["velocity"].shape == (summary["vertices"], 3)
    n_cells = sum(len(b.data) for b in final.cells)
    assert n_cells == summary["volumes" if summary["dimension"] == 3 else "faces"]
    disp = np.linalg.norm(final.point_data["displacement"], axis=1).max()
    assert disp == pytest.approx(summary["max_displacement"])
    if summary["frames"]:
        root = ET.parse(out / "animation.pvd").getroot()
        assert root.tag == "VTKFile"
        assert root.get("type") == "Collection"
        sets = root.findall("./Collection/DataSet")
        assert len(sets) == summary["frames"]
        times = [float(d.get("timestep", "nan")) for d in sets]
        assert times[0] == 0.0
        assert times == sorted(times)
        for d in sets:
            frame = out / d.get("file", "")
            assert frame.is_file()
        assert len(meshio.read(out / sets[-1].get("file", "")).points) == summary["vertices"]
    return summary


@pytest.mark.parametrize("name", sorted(shipped_scenes()))
def test_every_shipped_scene_runs(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / name
    code = cli.main(["run", name, "--out", str(out), "--steps", "3"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    summary = check_outputs(out, 3)
    assert summary["name"] == name
    assert summary["frames"] >= 2  # the initial state and the last
    assert str(out / "animation.pvd") in captured.out
    assert summary["steps_requested"] == 3


def test_steps_override(tmp_path: Path) -> None:
    scene = springs(tmp_path, steps=100, every=0)
    s = run_scene(scene, tmp_path / "o", steps=7)
    assert s["steps"] == 7
    assert s["steps_requested"] == 7
    assert s["frames"] == 0
    assert not (tmp_path / "o" / "animation.pvd").exists()
    assert not (tmp_path / "o" / "frames").exists()
    check_outputs(tmp_path / "o", 7)


def test_frames_every_n_steps_and_the_last(tmp_path: Path) -> None:
    s = run_scene(springs(tmp_path, steps=10, every=4), tmp_path / "o")
    # steps 0, 4, 8 and the last, 10
    assert s["frames"] == 4
    root = ET.parse(tmp_path / "o" / "animation.pvd").getroot()
    times = [float(d.get("timestep", "nan")) for d in root.iter("DataSet")]
    assert times == pytest.approx([0.0, 4e-3, 8e-3, 10e-3])
    assert sorted(p.name for p in (tmp_path / "o" / "frames").iterdir()) == [
        f"frame_{k:05d}.vtu" for k in range(4)
    ]
    first = meshio.read(tmp_path / "o" / "frames" / "frame_00000.vtu")
    assert np.all(first.point_data["displacement"] == 0.0)
    assert first.point_data["fixed"].sum() == 3


def test_a_second_run_removes_stale_frames(tmp_path: Path) -> None:
    scene = springs(tmp_path, steps=10, every=1)
    run_scene(scene, tmp_path / "o")
    assert len(list((tmp_path / "o" / "frames").iterdir())) == 11
    run_scene(scene, tmp_path / "o", steps=2)
    assert len(list((tmp_path / "o" / "frames").iterdir())) == 3


def test_progress(tmp_path: Path) -> None:
    calls: list[tuple[int, int]] = []
    run_scene(
        springs(tmp_path, steps=5), tmp_path / "o", progress=lambda k, n: calls.append((k, n))
    )
    assert calls == [(k, 5) for k in range(1, 6)]
    stream = io.StringIO()
    bar = Progress("beam", 10, stream)
    bar.update(5, force=True)
    bar.close(10)
    text = stream.getvalue()
    assert text.startswith("\rbeam [###############               ]  50% step 5/10")
    assert "100% step 10/10" in text
    assert text.endswith("\n")


def test_divergence_exits_1_and_keeps_what_was_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = springs(
        tmp_path, stiffness=1e6, integrator="explicit_euler", dt=0.1, steps=1000, every=1
    )
    out = tmp_path / "o"
    code = cli.main(["run", str(scene), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1
    summary = json.loads((out / "summary.json").read_text())
    e = summary["error"]
    assert e["type"] == "divergence"
    assert summary["steps"] == e["step"] - 1 < 1000
    assert f"diverged at step {e['step']}" in err
    assert f"at vertex row {e['vertex']} (input point {e['point']})" in err
    assert "summary.json has the error" in err
    final = meshio.read(out / "final.vtu")
    assert np.isfinite(final.points).all()
    sets = ET.parse(out / "animation.pvd").getroot().findall("./Collection/DataSet")
    assert len(sets) == summary["frames"] == summary["steps"] + 1  # a frame per good step
    assert all((out / d.get("file", "")).is_file() for d in sets)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (("dt = 0.001", "dtt = 0.001"), "integrator.dtt: unknown key"),
        (("dt = 0.001", "dt = -0.001"), "integrator.dt: must be positive, got -0.001"),
        (
            ('kind = "stretch_elementary"', 'kind = "springs"'),
            "model[0].kind: unknown model 'springs'",
        ),
        (('where = "x < 1e-9"', 'where = "x <"'), 'fix[0].where: bad predicate "x <"'),
        (
            ('where = "x < 1e-9"', 'where = "x < -1"'),
            "fix[0].where: cannot build the simulation: fix predicate 'x < -1' selects no vertex",
        ),
        (('generator = "grid"', 'file = "missing.msh"'), "mesh.file: no such file"),
        (("density = 1.0", 'density = "abc"'), 'material.density: expected a number, got "abc"'),
    ],
)
def test_bad_scene_exits_2(
    edit: tuple[str, str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = springs(tmp_path)
    text = scene.read_text().replace(*edit)
    if "file =" in edit[1]:
        text = text.replace('element = "tri"\nsize = [1.0, 1.0]\ncells = [2, 2]\n', "")
    scene.write_text(text)
    out = tmp_path / "o"
    code = cli.main(["run", str(scene), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert f"topomech: error: {scene}: {message}" in err, err
    assert not out.exists()


def test_unknown_scene_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["run", "no_such_scene"]) == 2
    assert "no shipped scene of that name (shipped: " in capsys.readouterr().err


def test_run_needs_a_scene(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["run"]) == 2
    assert "give a SCENE" in capsys.readouterr().err


def test_list(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["run", "--list"]) == 0
    out = capsys.readouterr().out
    for name in shipped_scenes():
        assert name in out
    # a scene beside --list is a mistake, not ignored (QA)
    assert cli.main(["run", "--list", "beam"]) == 2
    assert "--list takes no SCENE (got 'beam')" in capsys.readouterr().err


def test_default_output_dir(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = springs(tmp_path)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", str(scene), "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    check_outputs(tmp_path / "out" / "springs", 10)


def test_scene_with_a_mesh_file(tmp_path: Path) -> None:
    g = topomech.GMap.from_flat(*topomech._core.box(3, 1, 1, 0.6, 0.2, 0.2, "tetra"))
    (tmp_path / "meshes").mkdir()
    topomech.write_vtu(g, tmp_path / "meshes" / "beam.vtu")
    scene = tmp_path / "beam.toml"
    scene.write_text(
        '[mesh]\nfile = "meshes/beam.vtu"\n[[model]]\nkind = "linear_fem"\n'
        '[[fix]]\nwhere = "x < 1e-9"\n[integrator]\nsteps = 2\n'
    )
    s = run_scene(scene, tmp_path / "o")
    assert s["volumes"] == 18
    check_outputs(tmp_path / "o", 2)


def test_demo_runs_end_to_end(tmp_path: Path) -> None:
    """As `make demo` runs it, in a fresh interpreter (fewer steps)."""
    out = tmp_path / "demo"
    r = subprocess.run(
        [sys.executable, "-m", "topomech", "demo", "--out", str(out), "--steps", "4"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    assert f"open {out / 'animation.pvd'} in ParaView" in r.stdout
    summary = check_outputs(out, 4)
    assert summary["name"] == "corotational"
    assert [m["kind"] for m in summary["models"]] == ["corotational"]
    assert summary["dimension"] == 3
    assert r.stderr == ""  # no progress bar when stderr is not a terminal


def test_ctrl_c_exits_130_and_keeps_what_was_written(tmp_path: Path) -> None:
    out = tmp_path / "o"
    p = subprocess.Popen(
        [sys.executable, "-m", "topomech", "run", "corotational", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    second = out / "frames" / "frame_00001.vtu"
    deadline = time.monotonic() + 60
    while not second.exists() and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    assert f"interrupted; what was written is in {out}" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["error"]["type"] == "interrupted"
    assert 0 < summary["steps"] < summary["steps_requested"]
    assert len(meshio.read(out / "final.vtu").points) == summary["vertices"]
