"""Progressive cutting by a blade (``[[event]] kind = "blade"``, ``Simulation.cut_swept``): the
shipped ``blade_cut`` scene opens the middle of a stretched slab step by step while the blade
moves down through it, exactly the faces a plane cut there opens (the blade sweeps that
plane), and the gap widens behind it until the halves spring back to their grips; the scene
keys are refused clearly when wrong."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import meshio
import numpy as np
import pytest

import topomech
from test_topology_scenes import BOX, check_pieces
from topomech import cli
from topomech.scene import parse_scene


def _gap(mesh: meshio.Mesh) -> float:
    """How far apart the two copies of the split vertices are along x, at their widest: a
    vertex the cut splits becomes two points with the same ``point_id``; 0 before any split
    (computed from the frame's points alone)."""
    ids = np.asarray(mesh.point_data["point_id"])
    x = mesh.points[:, 0]
    gap = 0.0
    for pid in np.unique(ids):
        copies = x[ids == pid]
        if len(copies) > 1:
            gap = max(gap, float(copies.max() - copies.min()))
    return gap


def test_blade_cut_opens_the_slab_progressively(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "blade"
    code = cli.main(["run", "blade_cut", "--out", str(out), "--quiet"])
    assert code == 0, capsys.readouterr().err
    s = check_pieces(out, "blade")
    changes = s["topology_changes"]
    # progressive: the faces open over several steps, while the blade moves (0 to 0.5 s)
    assert len(changes) >= 4, changes
    assert all(0.0 < c["time"] <= 0.5 + 1e-9 for c in changes)
    # what the plane cut x = 0.5 opens on the same slab: the blade sweeps that plane
    sim = topomech.load_scene("blade_cut").build()
    want = sim.cut([1.0, 0.0, 0.0], 0.5).unsewn
    assert sum(c["unsewn"] for c in changes) == want == 32
    assert s["components"] == 2
    # the preview's frames: no gap before the blade reaches the slab, then a gap that widens
    # to the grips' 0.05 m pull on each half (each half's rest length 0.5 held from its grip)
    frames = sorted((out / "frames").glob("frame_*.vtu"))
    gaps = [_gap(meshio.read(f)) for f in frames]
    first = next(i for i, g in enumerate(gaps) if g > 0)
    assert first >= 2, f"the blade reaches the slab's centroids after t = 0.11 s: {gaps}"
    # the halves spring back to their grips, each 0.05 m: the copies end 0.1 m apart
    assert gaps[-1] == pytest.approx(0.1, abs=0.01), gaps
    assert gaps[first] < gaps[-1] / 2, f"the gap opens progressively: {gaps}"
    assert (out / "preview.gif").exists()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scene"].endswith("blade_cut.toml")


def test_a_blade_from_python_is_the_plane_cut() -> None:
    """`Simulation(events=[{"kind": "blade", ...}])` and `Simulation.cut_swept`."""
    sc = topomech.load_scene("blade_cut")
    blade = sc.events[0]
    sim = sc.build()
    want = sim.cut([1.0, 0.0, 0.0], 0.5).unsewn
    once = sc.build().cut_swept(blade["from"], blade["to"])
    assert once.unsewn == want
    assert len(once.added_rows) > 0
    g = sc.load_gmap()
    s = topomech.Simulation(
        g,
        models=[{"kind": "corotational"}],
        gravity=[0.0, 0.0, 0.0],
        dt=0.01,
        events=[
            {"kind": "blade", "start": 0.0, "end": 0.05, "from": blade["from"], "to": blade["to"]}
        ],
    )
    s.step(10)
    assert sum(c["unsewn"] for c in s.topology_changes()) == want
    with pytest.raises(ValueError, match=r"events\[0\]\['to'\] must be 2 points"):
        topomech.Simulation(
            sc.load_gmap(),
            models=["corotational"],
            events=[
                {
                    "kind": "blade",
                    "start": 0.0,
                    "end": 1.0,
                    "from": blade["from"],
                    "to": [[0, 0, 0]],
                }
            ],
        )
    with pytest.raises(
        ValueError, match=r"events\[0\] \(a blade\): its end must be a finite time after"
    ):
        topomech.Simulation(
            sc.load_gmap(),
            models=["corotational"],
            events=[
                {
                    "kind": "blade",
                    "start": 1.0,
                    "end": 1.0,
                    "from": blade["from"],
                    "to": blade["to"],
                }
            ],
        )
    with pytest.raises(ValueError, match="must be 3 numbers"):
        sc.build().cut_swept([[0, 0], [1, 1]], blade["to"])


BLADE = 'kind = "blade"\nstart = 0.0\nend = 0.004\n'
SEG = "from = [[1.0, -1.0, 0.5], [1.0, 2.0, 0.5]]\nto = [[1.0, -1.0, 0.6], [1.0, 2.0, 0.6]]\n"


@pytest.mark.parametrize(
    ("event", "key", "problem"),
    [
        ('kind = "blade"\nend = 1\n' + SEG, "event[0].start", "missing"),
        ('kind = "blade"\nstart = 0\n' + SEG, "event[0].end", "missing"),
        (
            'kind = "blade"\nstart = 0.002\nend = 0.001\n' + SEG,
            "event[0].end",
            "must be after start",
        ),
        (BLADE + "to = [[1, 0, 0], [1, 1, 0]]\n", "event[0].from", "missing"),
        (BLADE + "from = [[1, 0, 0], [1, 1, 0]]\n", "event[0].to", "missing"),
        (
            BLADE + "from = [[1, 0, 0]]\nto = [[1, 0, 0], [1, 1, 0]]\n",
            "event[0].from",
            "expected 2 points",
        ),
        (
            BLADE + "from = [[1, 0], [1, 1, 0]]\nto = [[1, 0, 0], [1, 1, 0]]\n",
            "event[0].from[0]",
            "expected an array of 3 numbers",
        ),
        (
            BLADE + "from = [[1, 0, 0], [1, 0, 0]]\nto = [[1, 0, 0], [1, 1, 0]]\n",
            "event[0].from",
            "must differ",
        ),
        (
            BLADE + "from = [[1, 0, 0], [1, 1, 0]]\nto = [[1, 0, 0], [1, 1, 0]]\n",
            "event[0].to",
            "would not move",
        ),
        (
            # sliding along its own line sweeps nothing either (named here, not left to the
            # kernel's refusal of the event, which was a traceback in `topomech run`)
            BLADE + "from = [[1, 0, 0], [1, 1, 0]]\nto = [[1, 2, 0], [1, 3, 0]]\n",
            "event[0].to",
            "the blade would slide along its own line, so it would sweep nothing",
        ),
        (
            BLADE + "from = [[1, 0, 0], [1, 1, 0]]\nto = [[1, 1, 0], [1, 0, 0]]\n",
            "event[0].to",
            "on the line of event[0].from",
        ),
        (
            BLADE + "from = [[1, 1e200, 0], [1, 0, 0]]\nto = [[1, 0, 0], [1, 1, 0]]\n",
            "event[0].from[0][1]",
            "at most 1e100 in magnitude",
        ),
        (
            BLADE + "from = [[1, 1, 0], [1, 0, 0]]\nto = [[1, 0, 0], [-1e101, 1, 0]]\n",
            "event[0].to[1][0]",
            "at most 1e100 in magnitude",
        ),
        (BLADE + SEG + "time = 0.001\n", "event[0].time", "give start and end"),
        (BLADE + SEG + "speed = 3\n", "event[0].speed", "unknown key"),
        (
            'kind = "blade"\nstart = 0.01\nend = 0.02\n' + SEG,
            "event[0].start",
            "the blade would never move",
        ),
    ],
)
def test_bad_blades(event: str, key: str, problem: str) -> None:
    with pytest.raises(topomech.SceneError) as e:
        parse_scene(BOX + "[[event]]\n" + event)
    assert f"{key}: " in str(e.value), str(e.value)
    assert problem in str(e.value)


def test_cut_swept_refuses_a_sweep_of_nothing_as_a_blade_event_does() -> None:
    """`cut_swept(A, A)` (a blade that does not move) and a sweep along the segment's own line
    returned 0 unsewn silently, while a blade event that does not move is refused as sweeping
    nothing: the call now refuses both with the words of the blade event's refusal (the same
    check in the kernel), and a blade event sliding along its line is refused too."""
    sc = topomech.load_scene("blade_cut")
    a = [[0.5, -0.2, -0.1], [0.5, 1.2, -0.1]]
    along = [[0.5, 0.3, -0.1], [0.5, 1.7, -0.1]]  # the same line, moved along it
    still = (
        "its segment must move: it is the same segment at its start and at its end, so it "
        "would sweep nothing"
    )
    sliding = (
        "its segment must move off its own line: its end points at its start and at its end "
        "lie on one line, so it would sweep nothing"
    )
    for end, words in ((a, still), (along, sliding), (a[::-1], sliding)):
        with pytest.raises(topomech.SimulationError) as e:
            sc.build().cut_swept(a, end)
        assert str(e.value) == f"the blade: {words}", str(e.value)
        event = {"kind": "blade", "start": 0.0, "end": 0.01, "from": a, "to": end}
        with pytest.raises(ValueError, match=re.escape(f"events[0] (a blade): {words}")):
            topomech.Simulation(sc.load_gmap(), models=["corotational"], events=[event])
    # a sweep across its line still cuts
    assert sc.build().cut_swept(a, [[0.5, -0.2, 1.1], [0.5, 1.2, 1.1]]).unsewn > 0


def test_blade_kind_and_timing_refusals(tmp_path: Path) -> None:
    """A misspelled kind is said as such (not as unknown keys of a cut), in scenes and in
    Python; a blade still moving when the run ends is said (a warning: it cuts only what it
    crossed by then); a blade that crosses nothing by its end stops the run like a cut that
    misses; numpy arrays are points too."""
    with pytest.raises(topomech.SceneError, match=r'event\[0\].kind: unknown event kind "Blade"'):
        parse_scene(BOX + '[[event]]\nkind = "Blade"\nstart = 0.0\nend = 0.004\n' + SEG)
    with pytest.warns(UserWarning, match=r"event\[0\].end: t = 0.01 is after the end.*part-way"):
        parse_scene(BOX + '[[event]]\nkind = "blade"\nstart = 0.0\nend = 0.01\n' + SEG)
    sc = topomech.load_scene("blade_cut")
    blade = sc.events[0]
    with pytest.raises(
        ValueError, match=r"unknown event kind 'Blade' \(expected 'cut' or 'blade'\)"
    ):
        topomech.Simulation(
            sc.load_gmap(),
            models=["corotational"],
            events=[{"kind": "Blade", "start": 0.0, "end": 1.0, "from": blade["from"]}],
        )
    s = topomech.Simulation(
        sc.load_gmap(),
        models=["corotational"],
        gravity=[0.0, 0.0, 0.0],
        dt=0.01,
        events=[
            {
                "kind": "blade",
                "start": 0.0,
                "end": 0.05,
                "from": np.array(blade["from"]),
                "to": np.array(blade["to"]),
            }
        ],
    )
    s.step(6)
    assert sum(c["unsewn"] for c in s.topology_changes()) == 32
    far = [[5.0, 0.0, 0.0], [5.0, 1.0, 0.0]]
    # (not far[::-1]: the same line reversed sweeps nothing, refused when it is set up)
    far_below = [[5.0, 0.0, -1.0], [5.0, 1.0, -1.0]]
    miss = topomech.Simulation(
        sc.load_gmap(),
        models=["corotational"],
        dt=0.01,
        events=[{"kind": "blade", "start": 0.0, "end": 0.02, "from": far, "to": far_below}],
    )
    miss.step(1)
    with pytest.raises(topomech.TopomechError, match="crossed nothing: it misses the object"):
        miss.step(1)


def _cut_then_blade(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], blade: str
) -> tuple[dict[str, Any], str]:
    """A run of a box cut at x = 1 at t = 0 and swept by the blade ``blade`` (its ``from``
    and ``to`` lines) from t = 0 to 0.002: it stops (exit 1) with the blade's event error;
    the summary's error and stderr."""
    from test_topology_scenes import box_with, run_cli, summary_of

    scene = box_with(
        tmp_path,
        '[[event]]\ntime = 0.0\nkind = "cut"\nplane = { normal = [1, 0, 0], offset = 1.0 }\n'
        '[[event]]\nkind = "blade"\nstart = 0.0\nend = 0.002\n' + blade,
    )
    out = tmp_path / "o"
    code, err = run_cli([str(scene), "--out", str(out)], capsys)
    assert code == 1, err
    error: dict[str, Any] = summary_of(out)["error"]
    assert error["type"] == "event", error
    assert error["event"] == 1
    assert "event[1] (a blade moving from t = 0 to t = 0.002)" in error["message"]
    return error, err


def test_a_blade_that_misses_stops_the_run_as_an_event(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Beside a plane cut that does cut, a blade that crosses nothing by its end stops the run:
    the summary's error is an ``event`` naming it, as for a timed cut that misses."""
    _, err = _cut_then_blade(
        tmp_path,
        capsys,
        "from = [[50.0, 0.0, 0.0], [50.0, 1.0, 0.0]]\nto = [[50.0, 0.0, 1.0], [50.0, 1.0, 1.0]]\n",
    )
    assert "misses the object" in err


def test_a_blade_over_faces_a_cut_opened_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A blade that sweeps only faces the plane cut opened before it crosses nothing sewn: the
    run stops as for a blade that misses, and the message says that every face it met may
    be open already (it said only that it misses the object, which it does not: QA)."""
    error, _ = _cut_then_blade(
        tmp_path,
        capsys,
        "from = [[1.0, -0.1, -0.1], [1.0, -0.1, 1.1]]\nto = [[1.0, 1.1, -0.1], [1.0, 1.1, 1.1]]\n",
    )
    assert "or every face it meets is open already" in error["message"]


def test_prepare_cuts_changes_no_result() -> None:
    """``Simulation.prepare_cuts`` builds the compiled guards the plane cut and the blade
    search the faces with before the first cut: the same cuts, with and without it, unsew the same faces and give
    the same positions and rows, bit for bit (the guards are evaluated by the same
    arithmetic either way)."""
    runs = []
    for prepare in (False, True):
        sim = topomech.load_scene("blade_cut").build()
        if prepare:
            sim.prepare_cuts()
        sim.step(2)
        a = sim.cut([1.0, 0.0, 0.0], 0.5)
        sim.step(1)
        b = sim.cut_swept(
            [[0.25, 1.2, -0.1], [0.25, 1.2, 1.1]], [[0.25, -0.2, -0.1], [0.25, -0.2, 1.1]]
        )
        sim.step(1)
        runs.append((a.unsewn, b.unsewn, a.added_rows, b.added_rows, sim.positions()))
    (a0, b0, ra0, rb0, x0), (a1, b1, ra1, rb1, x1) = runs
    assert a0 == a1 > 0
    assert b0 == b1
    assert np.array_equal(ra0, ra1)
    assert np.array_equal(rb0, rb1)
    assert np.array_equal(x0, x1)


def test_cut_arguments_are_refused_by_name() -> None:
    """A plane cut's bad arguments raise the exception of their kind, naming the argument:
    something that is not 3 numbers a TypeError (a wrong count a ValueError), a number too
    large for a float a ValueError saying so."""
    sim = topomech.load_scene("blade_cut").build()
    with pytest.raises(TypeError, match="normal must be 3 numbers, got NoneType"):
        sim.cut(None, 0.5)
    with pytest.raises(TypeError, match="normal must be 3 numbers, got str"):
        sim.cut("abc", 0.5)
    with pytest.raises(TypeError, match=r"normal\[0\] must be a number, got complex"):
        sim.cut([1j, 0, 0], 0.5)
    with pytest.raises(ValueError, match="normal must be 3 numbers, got 2"):
        sim.cut([1, 0], 0.5)
    with pytest.raises(ValueError, match="offset is too large for a float"):
        sim.cut([1, 0, 0], 10**400)
    assert sim.cut(np.array([1, 0, 0], dtype=np.int32), 0.5).unsewn > 0
