"""Topology changes during a run: the shipped scenes that cut, tear and break (their summaries
list the changes, the final map has several components, the VTU files have the split
vertices as new points), the ``[[event]]`` and ``[fracture]`` keys of scenes and their
refusals, and the kernel's API (``Simulation.cut``, ``fracture``, ``topology_changes``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import meshio
import numpy as np
import pytest

import topomech
from topomech import _core, cli
from topomech.scene import parse_scene

BOX = """
[mesh]
generator = "box"
element = "tet"
size = [2.0, 1.0, 1.0]
cells = [2, 1, 1]

[[model]]
kind = "corotational"
young = 1e5

[world]
gravity = [0.0, 0.0, 0.0]

[integrator]
dt = 1e-3
steps = 5

[output]
every = 0
"""


def run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = cli.main(["run", *args, "--quiet"])
    return code, capsys.readouterr().err


def summary_of(out: Path) -> dict[str, Any]:
    s: dict[str, Any] = json.loads((out / "summary.json").read_text())
    return s


def components_of(mesh: meshio.Mesh) -> int:
    """Connected components of a mesh's cells through shared points (independent of the
    kernel's count)."""
    parent = list(range(len(mesh.points)))

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    used: set[int] = set()
    for block in mesh.cells:
        for cell in block.data:
            c = [int(v) for v in cell]
            used.update(c)
            for v in c[1:]:
                parent[find(v)] = find(c[0])
    return len({find(v) for v in used})


def check_pieces(out: Path, kind: str) -> dict[str, Any]:
    """The run at ``out`` changed the topology: its summary lists ``kind`` changes, the final
    map has 2+ components, and final.vtu has more points than the initial mesh, its cells
    using the new ones and falling apart into as many pieces as the summary says."""
    s = summary_of(out)
    assert "error" not in s, s.get("error")
    changes = s["topology_changes"]
    assert changes, "the topology changed"
    assert all(c["kind"] == kind and c["unsewn"] > 0 for c in changes)
    assert all(set(c) == {"step", "time", "kind", "unsewn"} for c in changes)
    assert [c["step"] for c in changes] == sorted(c["step"] for c in changes)
    assert s["components"] >= 2
    sc = topomech.load_scene(s["scene"])
    initial = sc.load_gmap().cell_counts()["vertices"]
    final = meshio.read(out / "final.vtu")
    assert len(final.points) == s["vertices"] > initial
    top = max(int(b.data.max()) for b in final.cells)
    assert top >= initial, "the cells reference the new points"
    assert components_of(final) == s["components"]
    return s


# ---------------------------------------------------------------------------- shipped scenes


def test_cube_cut(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cube"
    # 3 steps of 0.25 s pass the cut at t = 0.5
    code, err = run_cli(["cube_cut", "--out", str(out), "--steps", "3"], capsys)
    assert code == 0, err
    s = check_pieces(out, "cut")
    assert s["topology_changes"] == [{"step": 2, "time": 0.5, "kind": "cut", "unsewn": 32}]
    assert s["components"] == 2
    # the halves, 0.2 m apart: no point of the final mesh lies in the gap around x = 0.5
    x = meshio.read(out / "final.vtu").points[:, 0]
    assert not np.any((x > 0.45) & (x < 0.55))
    # the frames before the cut have the initial points, those after it the split ones
    first = meshio.read(out / "frames" / "frame_00000.vtu")
    last = meshio.read(out / "frames" / "frame_00003.vtu")
    assert len(first.points) == 125 < len(last.points) == s["vertices"]
    sc = topomech.load_scene("cube_cut")
    assert s["total_mass"] == pytest.approx(sc.build().total_mass(), rel=1e-12)


def test_cloth_tear(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cloth"
    code, err = run_cli(["cloth_tear", "--out", str(out), "--steps", "850", "--every", "0"], capsys)
    assert code == 0, err
    s = check_pieces(out, "fracture")
    assert s["dimension"] == 2


def test_beam_fracture(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "beam"
    code, err = run_cli(
        ["beam_fracture", "--out", str(out), "--steps", "700", "--every", "0"], capsys
    )
    assert code == 0, err
    s = check_pieces(out, "fracture")
    assert s["dimension"] == 3


def test_the_report_says_what_changed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["run", "cube_cut", "--out", str(tmp_path), "--steps", "2"]) == 0
    out = capsys.readouterr().out
    assert "1 cut: 32 faces opened from step 2 (t = 0.5); 2 components" in out


def test_a_run_without_changes(tmp_path: Path) -> None:
    scene = tmp_path / "box.toml"
    scene.write_text(BOX)
    s = topomech.run_scene(scene, tmp_path / "o")
    assert s["topology_changes"] == []
    assert s["components"] == 1


# ---------------------------------------------------------------------------- scene events


def box_with(tmp_path: Path, extra: str, steps: int = 5) -> Path:
    p = tmp_path / "scene.toml"
    p.write_text(BOX.replace("steps = 5", f"steps = {steps}") + extra)
    return p


def test_a_predicate_cut(tmp_path: Path) -> None:
    scene = box_with(
        tmp_path,
        '[[event]]\ntime = 0.002\nkind = "cut"\nwhere = "abs(x - 1.0) < 1e-6"\n',
    )
    s = topomech.run_scene(scene, tmp_path / "o", save_map=True)
    assert "error" not in s
    assert s["components"] == 2
    assert [(c["step"], c["kind"]) for c in s["topology_changes"]] == [(2, "cut")]
    # asked, the cut map itself is saved beside final.vtu (QA: a run's cut map could not be
    # had from the command line, and final.vtu of pieces that moved into each other is
    # refused as a mesh): it reads back with its two pieces and the final positions
    assert s["outputs"]["map"] == "final.tmg"
    g, _ = topomech.read_gmap(tmp_path / "o" / "final.tmg")
    counts = g.cell_counts()
    assert counts["components"] == 2
    assert {k: counts[k] for k in ("darts", "vertices", "volumes")} == {
        k: s["mesh"]["final"][k] for k in ("darts", "vertices", "volumes")
    }
    final = meshio.read(tmp_path / "o" / "final.vtu")
    assert np.allclose(np.sort(g.positions(), axis=0), np.sort(final.points, axis=0))
    # without a change, or not asked, no map is written
    plain = topomech.run_scene(box_with(tmp_path, ""), tmp_path / "p", save_map=True)
    assert plain["outputs"]["map"] is None
    assert not (tmp_path / "p" / "final.tmg").exists()
    unasked = topomech.run_scene(scene, tmp_path / "q")
    assert unasked["outputs"]["map"] is None
    assert not (tmp_path / "q" / "final.tmg").exists()


def test_a_cut_that_misses_stops_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = box_with(
        tmp_path,
        '[[event]]\ntime = 0.0\nkind = "cut"\nplane = { normal = [1, 0, 0], offset = 1.0 }\n'
        '[[event]]\ntime = 0.003\nkind = "cut"\nplane = { normal = [1, 0, 0], offset = 50 }\n',
    )
    out = tmp_path / "o"
    code, err = run_cli([str(scene), "--out", str(out)], capsys)
    assert code == 1
    assert "event[1]" in err
    assert "misses the object" in err
    s = summary_of(out)
    assert s["error"]["type"] == "event"
    assert s["error"]["event"] == 1
    assert s["error"]["step"] == 3
    assert (
        "event[1] (a cut at t = 0.003 along the plane normal [1, 0, 0], offset 50)"
        in (s["error"]["message"])
    )
    # the first event did cut, and what was written stays
    assert [c["step"] for c in s["topology_changes"]] == [1]
    assert (out / "final.vtu").is_file()


def test_an_event_after_the_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = box_with(
        tmp_path, '[[event]]\ntime = 1.0\nkind = "cut"\nwhere = "x > 0.9 && x < 1.1"\n'
    )
    code, err = run_cli([str(scene), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert "event[0].time" in err
    assert "after the end of the run" in err
    assert not (tmp_path / "o").exists()


def test_a_run_of_no_step_reaches_no_event(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An event at t = 0 happens at the end of the first step: a run of 0 steps never
    reaches it, and is refused as a run ending before any event is (QA: it exited 0 with
    the cut silently not made)."""
    scene = box_with(
        tmp_path, '[[event]]\ntime = 0.0\nkind = "cut"\nwhere = "x > 0.9 && x < 1.1"\n'
    )
    code, err = run_cli([str(scene), "--out", str(tmp_path / "o"), "--steps", "0"], capsys)
    assert code == 2
    assert "event[0].time: t = 0, but the run takes no step (steps = 0)" in err
    assert not (tmp_path / "o").exists()
    # one step reaches it; --save-map keeps the cut map
    code, _ = run_cli(
        [str(scene), "--out", str(tmp_path / "o1"), "--steps", "1", "--no-preview", "--save-map"],
        capsys,
    )
    assert code == 0
    assert summary_of(tmp_path / "o1")["outputs"]["map"] == "final.tmg"
    g, _ = topomech.read_gmap(tmp_path / "o1" / "final.tmg")
    assert g.cell_counts()["components"] == 2


def test_steps_that_end_before_an_event(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # the scene reaches its cut, one step fewer does not
    code, err = run_cli(["cube_cut", "--out", str(tmp_path / "o"), "--steps", "1"], capsys)
    assert code == 2
    assert "event[0].time: t = 0.5 is after the end of the run (t = 0.25" in err
    sc = topomech.load_scene("cube_cut")
    with pytest.raises(topomech.SceneError, match=r"event\[0\]\.time"):
        sc.with_steps(1)
    with pytest.raises(topomech.SceneError, match=r"event\[0\]\.time"):
        topomech.run_scene(sc, tmp_path / "p", steps=1)


@pytest.mark.parametrize(
    ("event", "key", "problem"),
    [
        ('time = 0.001\nkind = "split"\nwhere = "x > 1"', "event[0].kind", "unknown event kind"),
        ('time = 0.001\nwhere = "x > 1"', "event[0].kind", "missing"),
        ('kind = "cut"\nwhere = "x > 1"', "event[0].time", "missing"),
        ('time = -1\nkind = "cut"\nwhere = "x > 1"', "event[0].time", "must be >= 0"),
        (
            'time = 0.001\nkind = "cut"\nwhere = "x > 1"\n'
            "plane = { normal = [1, 0, 0], offset = 1 }",
            "event[0].where",
            "not both",
        ),
        ('time = 0.001\nkind = "cut"', "event[0]", "missing the cut's geometry"),
        (
            'time = 0.001\nkind = "cut"\nplane = { normal = [0, 0, 0], offset = 1 }',
            "event[0].plane.normal",
            "must not be zero",
        ),
        (
            'time = 0.001\nkind = "cut"\nplane = { normal = [1, 0], offset = 1 }',
            "event[0].plane.normal",
            "expected an array of 3 numbers",
        ),
        (
            'time = 0.001\nkind = "cut"\nplane = { normal = [1, 0, 0] }',
            "event[0].plane.offset",
            "missing",
        ),
        (
            'time = 0.001\nkind = "cut"\nplane = { normal = [1, 0, 0], ofset = 1 }',
            "event[0].plane.ofset",
            "unknown key; did you mean 'offset'?",
        ),
        ('time = 0.001\nkind = "cut"\nwhere = "x >"', "event[0].where", "bad predicate"),
        ('time = 0.001\nkind = "cut"\nwhere = "x > 1"\nat = 3', "event[0].at", "unknown key"),
    ],
)
def test_bad_events(event: str, key: str, problem: str) -> None:
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(BOX + "[[event]]\n" + event + "\n")
    assert f"{key}: " in str(e.value)
    assert problem in str(e.value)
    assert getattr(e.value, "key", None) == key


def test_a_single_event_table_is_refused() -> None:
    with pytest.raises(topomech.SceneError, match=r"event: expected an array of tables"):
        parse_scene(BOX + '[event]\ntime = 0.001\nkind = "cut"\nwhere = "x > 1"\n')


@pytest.mark.parametrize(
    ("table", "key", "problem"),
    [
        ('criterion = "heat"\nthreshold = 1', "fracture.criterion", "unknown value"),
        ("threshold = 1", "fracture.criterion", "missing"),
        ('criterion = "strain"', "fracture.threshold", "missing"),
        ('criterion = "strain"\nthreshold = 0', "fracture.threshold", "must be positive"),
        ('criterion = "strain"\nthreshold = "big"', "fracture.threshold", "expected a number"),
        ('criterion = "strain"\nthreshold = 1\nlimit = 2', "fracture.limit", "unknown key"),
    ],
)
def test_bad_fracture(table: str, key: str, problem: str) -> None:
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(BOX + "[fracture]\n" + table + "\n")
    assert f"{key}: " in str(e.value)
    assert problem in str(e.value)


def test_the_stress_criterion_needs_tetrahedra() -> None:
    surface = BOX.replace(
        'generator = "box"\nelement = "tet"', 'generator = "grid"\nelement = "tri"'
    )
    surface = surface.replace("size = [2.0, 1.0, 1.0]\ncells = [2, 1, 1]", "cells = [2, 2]")
    surface = surface.replace('kind = "corotational"\nyoung = 1e5', 'kind = "stretch_elementary"')
    sc = parse_scene(surface + '[fracture]\ncriterion = "stress"\nthreshold = 1e5\n')
    with pytest.raises(topomech.SceneError, match=r"fracture\.criterion: .*2D"):
        sc.build()
    hexes = parse_scene(
        BOX.replace('element = "tet"', 'element = "hex"')
        + '[fracture]\ncriterion = "stress"\nthreshold = 1e5\n'
    )
    with pytest.raises(topomech.SceneError, match=r"fracture\.criterion: .*hexahedron"):
        hexes.build()


def test_scene_config_reaches_the_kernel() -> None:
    sc = parse_scene(
        BOX
        + '[[event]]\ntime = 0.002\nkind = "cut"\nplane = { normal = [1, 0, 0], offset = 1 }\n'
        + '[fracture]\ncriterion = "strain"\nthreshold = 0.5\n'
    )
    assert sc.config["events"] == [
        {"time": 0.002, "kind": "cut", "plane": {"normal": [1.0, 0.0, 0.0], "offset": 1.0}}
    ]
    assert sc.config["fracture"] == {"criterion": "strain", "threshold": 0.5}
    sim = sc.build()
    sim.step(2)
    assert [c["kind"] for c in sim.topology_changes()] == ["cut"]


# ---------------------------------------------------------------------------- the API


def box_sim(**kw: Any) -> topomech.Simulation:
    g = topomech.GMap.from_flat(*_core.box(4, 2, 2, 2.0, 1.0, 1.0, "tetra"))
    cfg: dict[str, Any] = {"models": ["corotational"], "young": 1e5, "gravity": [0, -9.81, 0]}
    cfg.update(kw)
    return topomech.Simulation(g, cfg)


def test_cut_keeps_the_mass_and_splits_vertices() -> None:
    sim = box_sim()
    sim.step(3)
    m0, v0, x0 = sim.total_mass(), sim.n_vertices, sim.positions()
    version = sim.topology_version
    r = sim.cut([1.0, 0.0, 0.0], 1.0)
    assert r.unsewn == 8  # a 2 x 2 square of the box's grid, two triangles each
    assert sim.total_mass() == pytest.approx(m0, rel=1e-12)
    assert sim.n_vertices == v0 + 9  # the 3 x 3 vertices of the cut plane
    # appended, never renumbered: the old rows are where they were
    np.testing.assert_array_equal(r.added_rows, np.arange(v0, v0 + 9))
    np.testing.assert_array_equal(sim.positions()[:v0], x0)
    assert sim.topology_version != version
    # every vertex, old or split, is where a vertex was
    old = {tuple(p) for p in x0}
    assert all(tuple(p) in old for p in sim.positions())
    assert sim.topology_changes() == [{"step": 3, "time": sim.time, "kind": "cut", "unsewn": 8}]
    assert sim.gmap().cell_counts()["components"] == 2
    assert sim.gmap().is_valid()
    sim.step(5)
    assert np.isfinite(sim.positions()).all()


def test_a_cut_that_misses_changes_nothing() -> None:
    sim = box_sim()
    version = sim.topology_version
    r = sim.cut(np.array([0.0, 1.0, 0.0]), 10.0)
    assert r.unsewn == 0
    assert r.added_rows.shape == (0,)
    assert sim.topology_changes() == []
    assert sim.topology_version == version


def test_fracture_now() -> None:
    sim = box_sim(gravity=[0, 0, 0])
    x = sim.rest_positions()
    x[:, 0] *= np.where(x[:, 0] > 1.0, 1.5, 1.0)  # stretch the right half
    sim.set_positions(x)
    assert sim.fracture("strain", 10.0).unsewn == 0
    n = sim.fracture("strain", 0.2).unsewn
    assert n > 0
    assert sim.topology_changes()[-1]["kind"] == "fracture"
    with pytest.raises(ValueError, match="unknown criterion 'heat'"):
        sim.fracture("heat", 1.0)
    # the stress criterion needs the stress rules: those of the element models, or those a
    # stress fracture brings in
    springs = box_sim(models=["stretch_cumulated"])
    with pytest.raises(topomech.SimulationError, match="stress criterion"):
        springs.fracture("stress", 1e5)
    built = box_sim(
        models=["stretch_cumulated"], fracture={"criterion": "stress", "threshold": 1e9}
    )
    assert built.fracture("stress", 1e9).unsewn == 0


def test_timed_events_in_the_config() -> None:
    sim = box_sim(events=[{"time": 0.002, "kind": "cut", "where": "abs(x - 1.0) < 1e-6"}])
    sim.step(1)
    assert sim.topology_changes() == []
    sim.step(1)
    (change,) = sim.topology_changes()
    assert (change["step"], change["kind"], change["unsewn"]) == (2, "cut", 8)
    missing = box_sim(
        events=[{"time": 0.0, "kind": "cut", "plane": {"normal": [0, 0, 1], "offset": 9}}]
    )
    with pytest.raises(topomech.SimulationError, match="misses the object"):
        missing.step()


@pytest.mark.parametrize(
    ("key", "value", "error", "match"),
    [
        ("events", [{"time": 0, "kind": "melt", "where": "x > 1"}], ValueError, "unknown event"),
        ("events", [{"time": 0, "kind": "cut"}], ValueError, "no geometry"),
        (
            "events",
            [
                {
                    "time": 0,
                    "kind": "cut",
                    "where": "x > 1",
                    "plane": {"normal": [1, 0, 0], "offset": 1},
                }
            ],
            ValueError,
            "both 'plane' and 'where'",
        ),
        ("events", [{"time": -1, "kind": "cut", "where": "x > 1"}], ValueError, ">= 0"),
        ("events", [{"kind": "cut", "where": "x > 1"}], ValueError, "no 'time'"),
        ("events", [{"time": 0, "kind": "cut", "when": 1}], TypeError, "unknown key 'when'"),
        (
            "events",
            [{"time": 0, "kind": "cut", "plane": {"normal": [1, 0, 0]}}],
            ValueError,
            "both",
        ),
        ("events", "cut", TypeError, "must be a list"),
        ("fracture", {"criterion": "heat", "threshold": 1}, ValueError, "unknown criterion"),
        ("fracture", {"criterion": "strain"}, ValueError, "needs both"),
        ("fracture", {"criterion": "strain", "threshold": True}, TypeError, "must be a number"),
        ("fracture", "strain", TypeError, "must be a dict"),
    ],
)
def test_bad_config(key: str, value: Any, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        box_sim(**{key: value})
