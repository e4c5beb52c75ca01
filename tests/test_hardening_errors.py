"""Hardening of the errors people see (issue 13): a map or simulation used from two threads
at once raises a topomech `BusyError` naming the object (not PyO3's `RuntimeError: Already
mutably borrowed`); `topomech info X | head` exits quietly on a closed pipe; a NaN, an
infinity and a negative value of a setting raise the same exception class."""

from __future__ import annotations

import math
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import topomech
from topomech import _core, cli

# ------------------------------------------------------------------------------ busy objects


def _sheet(n: int) -> topomech.GMap:
    points, kinds, offsets, connectivity = _core.grid(n, n, 1.0, 1.0, "quad")
    return topomech.GMap(_core.GMap.from_flat(points, kinds, offsets, connectivity)[0])


def _contend(
    busy: Callable[[], None], other: Callable[[], Any], seconds: float = 5.0
) -> tuple[list[BaseException], int]:
    """Runs `busy` in a loop in a thread while this thread calls `other` in a loop; returns
    the exceptions `other` raised and how many calls succeeded. Stops at the first
    `BusyError` after a few calls, or after `seconds`."""
    stop = threading.Event()
    failures: list[BaseException] = []

    def worker() -> None:
        try:
            while not stop.is_set():
                busy()
        except BaseException as e:
            failures.append(e)

    t = threading.Thread(target=worker)
    t.start()
    raised: list[BaseException] = []
    ok = 0
    deadline = time.monotonic() + seconds
    try:
        while time.monotonic() < deadline:
            try:
                other()
                ok += 1
            except Exception as e:
                raised.append(e)
                if sum(isinstance(r, topomech.BusyError) for r in raised) >= 3:
                    break
            time.sleep(0)
    finally:
        stop.set()
        t.join(timeout=60)
    assert not failures, failures
    return raised, ok


def _simulation(n: int = 40) -> topomech.Simulation:
    return topomech.Simulation(
        _sheet(n),
        models=[{"kind": "stretch_elementary", "stiffness": 1e3}],
        density=1.0,
        fixed=["y < 1e-9"],
        gravity=[0.0, -9.81, 0.0],
        integrator="symplectic_euler",
        dt=1e-4,
    )


@pytest.mark.parametrize(
    "call",
    [
        lambda sim: sim.positions(),
        lambda sim: sim.time,
        lambda sim: sim.kinetic_energy(),
        lambda sim: sim.step(1),
        lambda sim: sim.set_velocities(np.zeros((sim.n_vertices, 3))),
    ],
    ids=["positions", "time", "kinetic_energy", "step", "set_velocities"],
)
def test_simulation_used_by_two_threads_raises_busy_error(call: Callable[[Any], Any]) -> None:
    sim = _simulation()
    n = sim.n_vertices
    raised, _ = _contend(lambda: sim.step(5), lambda: call(sim))
    runtime = [e for e in raised if type(e) is RuntimeError]
    assert not runtime, f"PyO3's borrow error leaked: {runtime[0]}"
    assert raised, "the other thread never found the simulation busy"
    for e in raised:
        assert isinstance(e, topomech.BusyError), repr(e)
        assert isinstance(e, topomech.TopomechError)
        assert "Simulation is busy" in str(e)
        assert "another thread" in str(e)
    # the simulation is still usable and whole
    sim.step(1)
    assert sim.positions().shape == (n, 3)
    assert np.isfinite(sim.positions()).all()


def test_gmap_changed_while_another_thread_reads_it_raises_busy_error() -> None:
    g = _sheet(120)
    core = g.core
    n = core.n_darts

    def sew() -> None:
        core.sew(0, n + 10, n + 11)  # darts out of range: an IndexError when not busy

    raised, _ = _contend(lambda: core.violations(), sew)
    assert raised
    assert not [e for e in raised if type(e) is RuntimeError]
    busy = [e for e in raised if isinstance(e, topomech.BusyError)]
    assert busy, "the other thread never found the map busy"
    assert "GMap is busy" in str(busy[0])
    assert all(isinstance(e, (topomech.BusyError, IndexError)) for e in raised), raised
    assert g.is_valid()


SCALE = """dimension 2
embedding position : vec3 on <1,2> policy mean

rule scale(f: f64) {
  left { v : <1,2> hook }
  compute { v.position = v.position * f }
}
"""


def test_gmap_read_while_a_rule_runs_on_it_raises_busy_error() -> None:
    g = _sheet(120)
    rules = topomech.RuleSet.from_source(SCALE, "scale.tmr")
    n = g.n_darts
    raised, _ = _contend(
        lambda: rules.count_matches(g, "scale", {"f": 1.0}), lambda: g.core.n_darts
    )
    assert raised, "the other thread never found the map busy"
    assert all(isinstance(e, topomech.BusyError) for e in raised), raised
    assert "GMap is busy: another thread is changing it" in str(raised[0])
    assert g.n_darts == n


def test_busy_error_is_exported() -> None:
    assert issubclass(topomech.BusyError, topomech.TopomechError)
    assert "BusyError" in topomech.__all__


# ------------------------------------------------------------------------------ closed pipe


def test_info_into_a_closed_pipe_exits_quietly(tmp_path: Path) -> None:
    path = tmp_path / "sheet.tmg"
    _sheet(3).save(path)
    for _ in range(3):
        p = subprocess.Popen(
            [sys.executable, "-m", "topomech", "info", str(path)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        assert p.stdout is not None
        assert p.stderr is not None
        p.stdout.close()  # `| head` that read nothing and left
        err = p.stderr.read().decode()
        code = p.wait(timeout=60)
        assert "Traceback" not in err, err
        assert "BrokenPipeError" not in err, err
        assert "Exception ignored" not in err, err
        assert err == ""
        assert code == cli.EXIT_BROKEN_PIPE == 141


# ------------------------------------------------------------------------------ bad settings

BAD = [math.nan, math.inf, -math.inf, -1.0]


def _build(**settings: Any) -> None:
    g = topomech.GMap.from_mesh(
        [[0, 0], [1, 0], [1, 1], [0, 1]], [("triangle", [[0, 1, 2], [0, 2, 3]])]
    )
    config: dict[str, Any] = {
        "models": [{"kind": "stretch_elementary", "stiffness": 1e3}],
        "density": 1.0,
        "integrator": "symplectic_euler",
        "dt": 1e-3,
    }
    config.update(settings)
    topomech.Simulation(g, config)


@pytest.mark.parametrize("key", ["dt", "density", "young", "damping"])
def test_nan_infinite_and_negative_settings_raise_the_same_exception(key: str) -> None:
    raised: list[BaseException] = []
    for value in BAD:
        try:
            _build(**{key: value})
        except Exception as e:
            raised.append(e)
        else:
            pytest.fail(f"{key} = {value} was accepted")
    assert {type(e) for e in raised} == {ValueError}, raised
    assert all(key in str(e) for e in raised), raised


@pytest.mark.parametrize(
    ("key", "value", "good"),
    [
        ("dt", 0.0, 1e-4),
        ("density", 0.0, 2.0),
        ("young", 0.0, 1e5),
        ("poisson", 0.5, 0.49),
        ("poisson", -1.0, -0.99),
        ("damping", -1e-9, 0.0),
    ],
)
def test_settings_out_of_range_raise_value_error(key: str, value: float, good: float) -> None:
    with pytest.raises(ValueError, match=key):
        _build(**{key: value})
    _build(**{key: good})  # the nearest good value is accepted


@pytest.mark.parametrize(
    "region",
    [
        {"where": "x > 0.5", "density": -1.0},
        {"where": "x > 0.5", "young": -5.0},
        {"where": "x > 0.5", "poisson": 0.7},
    ],
)
def test_region_values_out_of_range_raise_value_error(region: dict[str, Any]) -> None:
    with pytest.raises(ValueError, match=r"regions\[0\]"):
        _build(regions=[region])
