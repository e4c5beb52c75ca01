"""A rule application that would write a non-finite value (NaN or an infinity) to an embedding
fails naming the rule, the embedding and the dart, and writes nothing: from Python
(``RuleSet.apply``, everywhere and at given darts) and from the CLI (``topomech apply``: exit
code 1, the message, no output file). In a simulation step the same failure stays a
``DivergenceError`` naming the step and the vertex, with the last good state kept."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

import topomech
from topomech import _core
from topomech.rules import RuleSet

# On the 3 x 2 grid of [0, 3] x [0, 2] the vertices on x = 1 get an infinite or NaN position
# (1 / 0 times their coordinates); the others a finite one. The rule writes `velocity` first,
# finite everywhere and different for each `at`, so "writes nothing" is checked on an
# embedding the rule did compute.
BLOW = """dimension 2
embedding position : vec3 on <1,2> policy mean
embedding velocity : vec3 on <1,2>

rule blow(at: f64) {
  left { v : <1,2> hook }
  compute {
    v.velocity = vec3(at, 2.0, 3.0)
    v.position = v.position / (x(v.position) - at)
  }
}

rule still {
  left { v : <1,2> hook }
  compute { v.velocity = vec3(-1.0, 0.0, 0.0) }
}
"""

DART = re.compile(r"at dart d(\d+)")


def grid() -> topomech.GMap:
    return topomech.GMap.from_flat(*_core.grid(3, 2, 3.0, 2.0, "quad"))


def prepared(rules: RuleSet) -> topomech.GMap:
    """The grid with a `velocity` embedding holding values (written by `still`), so that a
    comparison of the whole map, bit for bit, sees any write of the failing rule (an
    application declares the embeddings its rule uses even when it fails, as when it does not
    match: that is not a write)."""
    g = grid()
    assert rules.apply(g, "still")["matches"] == 12
    return g


def x_of_dart(g: topomech.GMap, d: int) -> float:
    return float(g.positions()[g.vertex_labels()[d]][0])


def check_message(msg: str, g: topomech.GMap) -> None:
    """The message names the rule, the embedding and a dart on x = 1 (where the value is not
    finite), and says that nothing was written."""
    assert "rule 'blow'" in msg, msg
    assert "'position'" in msg, msg
    assert "non-finite" in msg, msg
    assert "nothing was written" in msg, msg
    m = DART.search(msg)
    assert m is not None, msg
    assert x_of_dart(g, int(m.group(1))) == pytest.approx(1.0, abs=1e-12)


def test_apply_everywhere_fails_and_writes_nothing() -> None:
    rules = RuleSet.from_source(BLOW)
    g = prepared(rules)
    before = g.to_bytes()
    with pytest.raises(topomech.ApplyError) as info:
        rules.apply(g, "blow", params={"at": 1.0})
    check_message(str(info.value), g)
    # bit for bit the same map: neither the velocity nor any finite position was written
    assert g.to_bytes() == before
    # a harmless parameter applies (the failure is the value's, not the rule's)
    assert rules.apply(g, "blow", params={"at": 10.0})["matches"] == 12
    assert g.to_bytes() != before
    assert np.isfinite(g.positions()).all()


def test_apply_at_a_dart_fails_and_writes_nothing() -> None:
    rules = RuleSet.from_source(BLOW)
    g = prepared(rules)
    labels, pos = g.vertex_labels(), g.positions()
    bad = next(d for d in range(g.n_darts) if pos[labels[d]][0] == 1.0)
    before = g.to_bytes()
    with pytest.raises(topomech.ApplyError) as info:
        rules.apply(g, "blow", at=bad, params={"at": 1.0})
    check_message(str(info.value), g)
    assert g.to_bytes() == before


def test_cli_apply_exits_1_names_rule_embedding_dart_and_writes_no_file(tmp_path: Path) -> None:
    points, _kinds, _offsets, conn = _core.grid(3, 2, 3.0, 2.0, "quad")
    mesh_path = tmp_path / "quads.vtu"
    meshio.write(mesh_path, meshio.Mesh(points, [("quad", conn.reshape(-1, 4))]))
    rule_path = tmp_path / "blow.tmr"
    rule_path.write_text(BLOW)
    out = tmp_path / "out.vtu"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "topomech",
            "apply",
            str(mesh_path),
            str(rule_path),
            "blow",
            "--everywhere",
            "--param",
            "at=1",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode == 1, r.stderr
    assert r.stdout == ""
    g, _ = topomech.read_gmap(mesh_path)  # the same map the CLI read, same dart numbering
    check_message(r.stderr, g)
    assert not out.exists()


def test_a_non_finite_force_in_a_step_is_a_divergence_naming_the_step_and_vertex() -> None:
    """A vertex moved to 1e306 makes its springs' forces overflow to infinity: the force rule
    refuses to write them, and the step reports a DivergenceError (the same kind as before
    rules checked their writes) naming the step, the spring rule and a vertex of one of the
    overflowing springs, with positions and velocities as before the step."""
    g = topomech.GMap.from_flat(*_core.grid(4, 2, 1.0, 0.5, "triangle"))
    sim = topomech.Simulation(
        g,
        models=[{"kind": "stretch_elementary", "stiffness": 1e3}],
        density=2.0,
        fixed=["x < 1e-9"],
        integrator="symplectic_euler",
        dt=1e-3,
    )
    rest = sim.positions()
    far = int(np.argmax(rest[:, 0] + rest[:, 1]))  # the corner (1, 0.5)
    x = rest.copy()
    x[far] = [1e306, 1e306, 0.0]
    sim.set_positions(x)
    v0 = sim.velocities()
    with pytest.raises(topomech.DivergenceError) as info:
        sim.step()
    e = info.value
    assert e.step == 1
    assert "diverged at step 1" in str(e)
    assert "stretch_elementary" in e.why, e.why
    assert "non-finite" in e.why, e.why
    # the vertex is an end of an overflowing spring: the far corner or one of its neighbours
    assert np.linalg.norm(rest[e.vertex] - rest[far]) < 0.4, e.vertex
    np.testing.assert_array_equal(sim.positions(), x)
    np.testing.assert_array_equal(sim.velocities(), v0)
