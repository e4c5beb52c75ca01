"""Small input-handling nits a QA user found in the Python layer: points and arrays that are
not real numbers taken as numbers (booleans, strings, dates, masked entries), booleans taken
as counts and loads, counts beyond the kernel's range, ``parse_scene`` given something other
than text, wordings, a missing "did you mean" and numpy warnings leaking to stderr."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import topomech
from topomech import cli, loads
from topomech.recording import read_view
from topomech.scene import SceneError, find_scene, parse_scene

TET_POINTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
TET_CELLS = [("tetra", np.array([[0, 1, 2, 3]]))]


def tet_box() -> topomech.Simulation:
    """Two tetrahedra sharing a face."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    g = topomech.GMap.from_mesh(pts, [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 4]]))])
    return topomech.Simulation(g, models=["corotational"], gravity=[0.0, 0.0, 0.0])


def square() -> topomech.Simulation:
    """The two triangles of the unit square, fixed at x = 0."""
    g = topomech.GMap.from_mesh(
        [[0, 0], [1, 0], [1, 1], [0, 1]], [("triangle", [[0, 1, 2], [0, 2, 3]])]
    )
    return topomech.Simulation(
        g,
        models=[{"kind": "stretch_elementary", "stiffness": 1e3}],
        density=1.0,
        fixed=["x < 1e-9"],
        integrator="symplectic_euler",
        dt=1e-3,
    )


# ------------------------------------------------------------------ 1. points that are not numbers


@pytest.mark.parametrize(
    ("points", "match"),
    [
        (TET_POINTS.astype(bool), "points must be real numbers, got booleans"),
        (TET_POINTS.astype(str), r"points must be real numbers, got an array of <U"),
        (TET_POINTS.astype(bytes), r"points must be real numbers, got an array of \|S"),
        ([*TET_POINTS.tolist()[:3], ["1.0", "1.0", "1.0"]], "points must be real numbers"),
        ([*TET_POINTS.tolist()[:3], [None, 0.0, 0.0]], "got None"),
        (np.array([*TET_POINTS.tolist()[:3], [True, 0.0, 0.0]], dtype=object), "got bool True"),
        (np.array([*TET_POINTS.tolist()[:3], ["1", 0.0, 0.0]], dtype=object), "got str '1'"),
        (TET_POINTS.astype("datetime64[s]"), r"got an array of datetime64\[s\] \(dates"),
    ],
)
def test_points_that_are_not_numbers_are_type_errors(points: Any, match: str) -> None:
    """``from_mesh`` refuses boolean, string (numbers written as text included), object and
    date points with TypeError, as ``set_positions`` does (QA: they were read as 0/1 and as
    the numbers the strings spell)."""
    with pytest.raises(TypeError, match=match):
        topomech.GMap.from_mesh(points, TET_CELLS)


def test_points_numpy_holds_as_objects_are_still_taken() -> None:
    """Numbers numpy holds as objects (a Python int beyond int64, mixed with floats) are
    taken as before: only what is not a real number is refused."""
    big = 10**20
    pts = [[0, 0, 0], [big, 0.0, 0], [0, 1e20, 0], [0, 0, big]]
    assert np.asarray(pts).dtype == object
    g = topomech.GMap.from_mesh(pts, TET_CELLS)
    assert g.positions()[:, 0].max() == 1e20


def test_valid_points_are_unchanged() -> None:
    """Integers, float32, 2 columns and lists are taken as before."""
    for pts in (TET_POINTS.astype(np.int32), TET_POINTS.astype(np.float32), TET_POINTS.tolist()):
        g = topomech.GMap.from_mesh(pts, TET_CELLS)
        np.testing.assert_array_equal(np.sort(g.positions(), axis=0), np.sort(TET_POINTS, axis=0))
    g2 = topomech.GMap.from_mesh([[0, 0], [1, 0], [0, 1]], [("triangle", [[0, 1, 2]])])
    assert g2.positions().shape == (3, 3)


# ------------------------------------------------------------------ 2. dates and masked arrays


@pytest.mark.parametrize("setter", ["set_positions", "set_velocities", "set_external_forces"])
@pytest.mark.parametrize("dtype", ["datetime64[s]", "timedelta64[ms]"])
def test_dates_and_durations_are_refused(setter: str, dtype: str) -> None:
    """numpy converts datetime64/timedelta64 arrays to their counts of units: refused with
    TypeError naming the argument, nothing written."""
    sim = tet_box()
    before = (sim.positions().copy(), sim.velocities().copy(), sim.external_forces().copy())
    with pytest.raises(TypeError, match=rf"must be real numbers, got an array of {dtype[:5]}"):
        getattr(sim, setter)(np.ones((sim.n_vertices, 3)).astype(dtype))
    np.testing.assert_array_equal(sim.positions(), before[0])
    np.testing.assert_array_equal(sim.velocities(), before[1])
    np.testing.assert_array_equal(sim.external_forces(), before[2])


@pytest.mark.parametrize("setter", ["set_positions", "set_external_forces"])
def test_masked_entries_are_refused(setter: str) -> None:
    """A masked array with a masked entry is refused (numpy would take the value under the
    mask); nothing is written."""
    sim = tet_box()
    x = np.ma.masked_array(sim.positions() + 0.1, mask=np.zeros((sim.n_vertices, 3), bool))
    x[1, 2] = np.ma.masked
    before = (sim.positions().copy(), sim.external_forces().copy())
    with pytest.raises(ValueError, match=r"masked entries cannot be taken \(1 of 15 masked\)"):
        getattr(sim, setter)(x)
    np.testing.assert_array_equal(sim.positions(), before[0])
    np.testing.assert_array_equal(sim.external_forces(), before[1])


def test_a_masked_array_without_masked_entries_is_its_data() -> None:
    """A masked array none of whose entries is masked is taken as its data."""
    sim = tet_box()
    x = sim.positions() + 0.1
    sim.set_positions(np.ma.masked_array(x, mask=False))
    np.testing.assert_array_equal(sim.positions(), x)
    sim.set_external_forces(np.ma.masked_array(np.ones_like(x)))
    np.testing.assert_array_equal(sim.external_forces(), np.ones_like(x))


def test_masked_points_are_refused() -> None:
    """The points of ``from_mesh`` the same way."""
    pts = np.ma.masked_array(TET_POINTS, mask=False)
    pts[0, 0] = np.ma.masked
    with pytest.raises(ValueError, match="points: masked entries cannot be taken"):
        topomech.GMap.from_mesh(pts, TET_CELLS)
    assert topomech.GMap.from_mesh(np.ma.masked_array(TET_POINTS), TET_CELLS).n_darts > 0


# ------------------------------------------------------------------ 3. booleans as numbers


def test_a_boolean_pressure_is_refused() -> None:
    """``pressure=True`` was taken as 1 Pa (and ``[True, 0, 0]`` as a traction of 1)."""
    sim = square()
    for value in (True, np.True_):
        with pytest.raises(loads.LoadError, match="pressure: expected a number"):
            loads.surface_load(sim, pressure=value, where="x > 0.99")
    for value in ([True, 0, 0], (0, np.False_, 0), np.array([True, False, False])):
        with pytest.raises(loads.LoadError, match="traction: expected 3 numbers"):
            loads.surface_load(sim, traction=value, where="x > 0.99")
    # numbers as before
    f = loads.surface_load(sim, pressure=1, where="x > 0.99")
    assert f.sum() == pytest.approx(-1.0)


def test_a_boolean_in_a_point_force_or_a_displacement_is_refused() -> None:
    """``point_load(sim, [True, 0, 0])`` was a force of 1 N (numpy reads the list as ints);
    ``held_positions`` likewise for a displacement."""
    sim = square()
    with pytest.raises(loads.LoadError, match=r"force: expected 3 numbers, got a boolean"):
        loads.point_load(sim, [True, 0, 0], where="x > 0.99")
    mask = np.array([False, True, False, False])
    with pytest.raises(loads.LoadError, match="displacement: expected 3 numbers"):
        loads.held_positions(sim, mask, [True, 0.0, 0.0])
    assert not sim.fixed()[1]
    assert loads.point_load(sim, [1, 0, 0], where="x > 0.99").sum() == pytest.approx(2.0)


@pytest.mark.parametrize("n", [True, False, np.True_])
def test_step_refuses_a_boolean(n: Any) -> None:
    """``sim.step(True)`` ran one step."""
    sim = square()
    with pytest.raises(TypeError, match=r"n must be an int \(a number of steps\), got (np\.)?"):
        sim.step(n)
    assert sim.steps == 0


def test_step_takes_ints_as_before() -> None:
    """Ints (numpy's included) and 0 run as before; a float and a negative count are refused
    naming ``n``."""
    sim = square()
    sim.step()
    sim.step(np.int64(2))
    sim.step(0)
    assert sim.steps == 3
    with pytest.raises(TypeError, match="n must be an int"):
        sim.step(1.5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="n must be >= 0, got -1"):
        sim.step(-1)


# ------------------------------------------------------------------ 4. counts beyond 64 bits


@pytest.mark.parametrize("n", [2**63, 2**64, -(2**64)])
def test_step_beyond_int64_is_a_value_error(n: int) -> None:
    """``sim.step(2**64)`` raised ``OverflowError: Python int too large to convert to C
    long``."""
    sim = square()
    match = "n must be >= 0" if n < 0 else f"n must be at most {2**63 - 1} .*, got {n}"
    with pytest.raises(ValueError, match=match):
        sim.step(n)
    assert sim.steps == 0


@pytest.mark.parametrize("option", ["--steps", "--every"])
def test_cli_counts_beyond_int64_are_refused(
    option: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """``topomech run ... --steps 99999999999999999999999`` was accepted; the scene caps
    ``integrator.steps`` at a 64-bit integer, and the option now says so the same way."""
    with pytest.raises(SystemExit) as info:  # (refused before the scene is looked for)
        cli.main(["run", "no_such_scene", option, "99999999999999999999999"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert (
        f"argument {option}: must be at most 9223372036854775807 (a 64-bit integer), "
        "got 99999999999999999999999"
    ) in err, err


# ------------------------------------------------------------------ 5. parse_scene's argument


def test_parse_scene_refuses_what_is_not_text() -> None:
    """``parse_scene(123)`` raised an AttributeError about ``removeprefix``, and
    ``parse_scene(b"...")`` a TypeError saying the reverse of what was wrong."""
    with pytest.raises(TypeError, match=r"parse_scene takes the TOML text as str, got int$"):
        parse_scene(123)  # type: ignore[arg-type]
    with pytest.raises(
        TypeError,
        match=r"got bytes: decode it first, e\.g\. data\.decode\('utf-8'\)",
    ):
        parse_scene(b"[mesh]")  # type: ignore[arg-type]
    with pytest.raises(SceneError, match="mesh"):
        parse_scene("[mesh]")


# ------------------------------------------------------------------ 6. wording

_BLADE_SCENE = """
[mesh]
generator = "box"
element = "tet"
size = [1.0, 1.0, 1.0]
cells = [1, 1, 1]

[[model]]
kind = "corotational"
young = 1e5
poisson = 0.3

[material]
density = 1000.0

[integrator]
kind = "symplectic_euler"
dt = 0.01
steps = 1
"""


def test_one_step_is_said_in_the_singular() -> None:
    """``(t = 0.01: 1 steps of dt 0.01)`` now says ``1 step``."""
    text = _BLADE_SCENE + '\n[[event]]\ntime = 0.5\nkind = "cut"\nwhere = "x > 0.5"\n'
    with pytest.raises(SceneError, match=r"\(t = 0\.01: 1 step of dt 0\.01\)"):
        parse_scene(text)
    with pytest.raises(SceneError, match=r"\(t = 0\.02: 2 steps of dt 0\.01\)"):
        parse_scene(text.replace("steps = 1", "steps = 2"))


# ------------------------------------------------------------------ 7. did you mean


def test_an_unknown_scene_name_suggests_the_closest(capsys: pytest.CaptureFixture[str]) -> None:
    """``topomech run corotationall`` said only that there is no such scene."""
    assert cli.main(["run", "corotationall"]) == 2
    err = capsys.readouterr().err
    assert "no shipped scene of that name; did you mean 'corotational'? (shipped: " in err, err
    with pytest.raises(FileNotFoundError, match="did you mean 'cantilever' or "):
        find_scene("cantilevr")
    with pytest.raises(FileNotFoundError, match=r"of that name \(shipped: "):
        find_scene("no_such_scene")
    # a path in a directory is not a shipped name: no suggestion
    with pytest.raises(FileNotFoundError, match=r"of that name \(shipped: "):
        find_scene("some_dir/corotationall.toml")


# ------------------------------------------------------------------ 8. numpy warnings


_HUGE_SCENE = """
name = "huge"

[mesh]
generator = "box"
element = "tet"
size = [1.0, 1.0, 1.0]
cells = [1, 1, 1]

[[model]]
kind = "linear_fem"
young = 1e7
poisson = 0.3

[material]
density = 1000.0

[[fix]]
where = "x < 1e-9"

[[fix]]
where = "x > 0.999"
displacement = [1e300, 0.0, 0.0]

[integrator]
kind = "symplectic_euler"
dt = 1e-4
steps = 2
"""


def test_a_huge_displacement_runs_without_numpy_warnings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A ``[[fix]]`` displacement of 1e300 printed about 12 numpy RuntimeWarnings (overflow
    in the recorder's float32 cast, its stress and energy, the previews' geometry): the run
    now prints none, and the positions beyond float32 are recorded as non-finite."""
    scene = tmp_path / "huge.toml"
    scene.write_text(_HUGE_SCENE)
    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        code = cli.main(["run", str(scene), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "RuntimeWarning" not in err, err
    view = read_view(out)
    pos = np.asarray(view.positions(len(view.frames) - 1))
    assert np.isinf(pos).any()
    assert np.isfinite(pos[np.isfinite(pos).all(axis=1)]).all()


def test_float32_overflow_is_recorded_as_infinite() -> None:
    """The recorder's float32 cast makes a value beyond float32's range +-inf without a
    warning; NaN stays NaN and the rest is cast as before."""
    from topomech.recording import _as_float32

    a = np.array([1e300, -1e300, np.nan, 1.5, -3e38, 4e38])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        b = _as_float32(a)
    assert b.dtype == np.float32
    np.testing.assert_array_equal(b[[0, 1, 5]], [np.inf, -np.inf, np.inf])
    assert np.isnan(b[2])
    np.testing.assert_array_equal(b[[3, 4]], np.array([1.5, -3e38], dtype=np.float32))
