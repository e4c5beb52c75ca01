"""The run report and summary: the wall time split into set-up, stepping, output and
previews (adding up to the total; steps/s from the stepping alone), the input and final mesh
counts after a cut, progress lines when stdout is not a terminal (``--quiet`` silences
them), and the Makefile's quiet set-up steps."""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from topomech import cli
from topomech.run import LOG_INTERVAL_ENV, LOG_INTERVAL_S, ProgressLog, run_scene
from topomech.scene import load_scene

ROOT = Path(__file__).resolve().parent.parent
TIMING_KEYS = {"setup_s", "stepping_s", "output_s", "preview_s", "total_s"}
COUNT_KEYS = {"darts", "vertices", "edges", "faces", "volumes", "components"}
#: A progress line (not the end line).
PROGRESS = re.compile(
    r"^corotational: step (\d+)/(\d+), t = (\S+) s, (\d+) steps/s, ETA (\S+) s$", re.MULTILINE
)


def _env(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env.pop(LOG_INTERVAL_ENV, None)
    env.update(extra)
    return env


def _topomech(*args: str | Path, env: dict[str, str] | None = None) -> tuple[Any, float]:
    """`python -m topomech ARGS` with stdout and stderr piped; (the result, its wall time)."""
    t = time.perf_counter()
    r = subprocess.run(
        [sys.executable, "-m", "topomech", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        env=env if env is not None else _env(),
    )
    return r, time.perf_counter() - t


@pytest.fixture(scope="module")
def cube_cut(tmp_path_factory: pytest.TempPathFactory) -> tuple[Any, float, dict[str, Any]]:
    """The shipped cut scene run whole, previews included, piped as a CI log would be."""
    out = tmp_path_factory.mktemp("cube_cut") / "o"
    r, wall = _topomech("run", "cube_cut", "--out", out)
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    return r, wall, summary


def _row(stdout: str, label: str) -> str:
    rows = [line[12:] for line in stdout.splitlines() if line[:12].rstrip() == label]
    assert len(rows) == 1, (label, stdout)
    return rows[0]


def test_timings_add_up_to_the_total(cube_cut: tuple[Any, float, dict[str, Any]]) -> None:
    r, wall, s = cube_cut
    t = s["timings"]
    assert set(t) == TIMING_KEYS
    assert all(t[k] >= 0 for k in TIMING_KEYS)
    parts = t["setup_s"] + t["stepping_s"] + t["output_s"] + t["preview_s"]
    assert parts == pytest.approx(t["total_s"], rel=0.05)
    assert t["total_s"] <= wall  # measured inside the process
    assert t["preview_s"] > 0  # preview.gif was rendered
    assert s["outputs"]["preview"] == "preview.gif"
    # the old keys are kept: the total, the stepping, the rate from the stepping alone
    assert s["wall_seconds"] == t["total_s"]
    assert s["step_seconds"] == t["stepping_s"]
    assert s["steps_per_second"] == pytest.approx(s["steps"] / t["stepping_s"])
    # the report prints the same numbers
    took = _row(r.stdout, "took")
    m = re.fullmatch(
        r"(\S+) s: set-up (\S+) s, stepping (\S+) s \((\d+) steps/s\), "
        r"output (\S+) s, previews (\S+) s",
        took,
    )
    assert m is not None, took
    total, setup, stepping, rate, output, previews = m.groups()
    assert float(total) == pytest.approx(t["total_s"], abs=0.006)
    assert float(setup) == pytest.approx(t["setup_s"], abs=0.006)
    assert float(stepping) == pytest.approx(t["stepping_s"], abs=0.006)
    assert float(output) == pytest.approx(t["output_s"], abs=0.006)
    assert float(previews) == pytest.approx(t["preview_s"], abs=0.006)
    assert abs(int(rate) - s["steps"] / t["stepping_s"]) <= 0.5 + 1e-9


def test_input_and_final_mesh_after_a_cut(cube_cut: tuple[Any, float, dict[str, Any]]) -> None:
    r, _, s = cube_cut
    built = load_scene("cube_cut").load_gmap().cell_counts()
    mesh = s["mesh"]
    assert set(mesh) == {"input", "final"}
    assert set(mesh["input"]) == set(mesh["final"]) == COUNT_KEYS
    assert mesh["input"] == {k: built[k] for k in COUNT_KEYS}
    assert mesh["input"]["vertices"] == 125
    assert mesh["input"]["components"] == 1
    # the top-level counts are the final map's, as before
    assert mesh["final"] == {k: s[k] for k in COUNT_KEYS}
    assert mesh["final"]["vertices"] > 125  # the cut split the vertices of its plane
    assert mesh["final"]["components"] == 2
    assert mesh["final"]["volumes"] == mesh["input"]["volumes"] == 384
    fin = mesh["final"]
    assert _row(r.stdout, "mesh") == "3D, 125 vertices, 384 volumes, 9216 darts (input)"
    assert _row(r.stdout, "final mesh") == (
        f"{fin['vertices']} vertices, 384 volumes, {fin['darts']} darts"
    )


def test_one_mesh_line_without_a_topology_change(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "o"
    code = cli.main(["run", "corotational", "--out", str(out), "--steps", "2", "--no-preview"])
    assert code == 0
    printed = capsys.readouterr().out
    s = json.loads((out / "summary.json").read_text())
    assert s["mesh"]["input"] == s["mesh"]["final"]
    assert _row(printed, "mesh") == (
        f"3D, {s['vertices']} vertices, {s['volumes']} volumes, {s['darts']} darts"
    )
    assert "final mesh" not in printed
    assert s["timings"]["preview_s"] < 0.05  # --no-preview: nothing rendered


def test_a_piped_run_prints_progress_lines(tmp_path: Path) -> None:
    """stdout not a terminal: progress lines on stdout (here every step, the interval set to
    0 by the environment), an end line, then the report; nothing on stderr."""
    out = tmp_path / "o"
    args = ("run", "corotational", "--out", out, "--steps", "30", "--every", "0", "--no-preview")
    r, _ = _topomech(*args, env=_env(**{LOG_INTERVAL_ENV: "0"}))
    assert r.returncode == 0, r.stderr
    assert r.stderr == ""
    lines = PROGRESS.findall(r.stdout)
    assert [int(n) for n, *_ in lines] == list(range(1, 30))
    assert all(int(m) == 30 for _, m, *_ in lines)
    assert float(lines[9][2]) == pytest.approx(0.010)  # t = step * dt
    end = [x for x in r.stdout.splitlines() if x.startswith("corotational: step 30/30,")]
    assert len(end) == 1
    assert re.fullmatch(r"corotational: step 30/30, t = 0.03 s, \d+ steps/s, done in \S+ s", end[0])
    # the report comes after the progress
    assert r.stdout.index(end[0]) < r.stdout.index("scene       corotational")


def test_quiet_prints_no_progress(tmp_path: Path) -> None:
    for command in (
        ("run", "corotational", "--out", tmp_path / "o", "--steps", "30", "--no-preview"),
        ("demo", "--out", tmp_path / "d", "--steps", "30"),
    ):
        r, _ = _topomech(*command, "--quiet", env=_env(**{LOG_INTERVAL_ENV: "0"}))
        assert r.returncode == 0, r.stderr
        assert r.stdout == ""
        assert r.stderr == ""


def test_progress_lines_at_most_every_interval(tmp_path: Path) -> None:
    """The default interval (10 s) is longer than this run: only the end line."""
    stream = io.StringIO()
    scene = load_scene("corotational").with_steps(40, 0)
    s = run_scene(scene, tmp_path / "o", preview=False, log=stream)
    assert "error" not in s
    text = stream.getvalue()
    assert PROGRESS.findall(text) == []
    assert text.count("\n") == 1
    assert text.startswith("corotational: step 40/40, t = 0.04 s, ")
    # an interval of 0 logs every step, and the end
    stream = io.StringIO()
    run_scene(scene, tmp_path / "o", preview=False, log=stream, log_interval=0)
    assert len(PROGRESS.findall(stream.getvalue())) == 39
    assert stream.getvalue().count("\n") == 40


def test_progress_log_throttles_and_says_when_it_stopped(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = [100.0]
    monkeypatch.setattr(time, "perf_counter", lambda: clock[0])
    stream = io.StringIO()
    log = ProgressLog("corotational", 100, stream, interval=10.0)
    for k in range(1, 60):
        clock[0] += 0.5  # 2 steps/s: a line every 20 steps
        log.update(k, k * 1e-3)
    log.close(59, 0.059)
    lines = stream.getvalue().splitlines()
    assert lines == [
        "corotational: step 20/100, t = 0.02 s, 2 steps/s, ETA 40.0 s",
        "corotational: step 40/100, t = 0.04 s, 2 steps/s, ETA 30.0 s",
        "corotational: step 59/100, t = 0.059 s, 2 steps/s, stopped",
    ]
    assert LOG_INTERVAL_S == 10.0


@pytest.mark.parametrize(("value", "expected"), [("2.5", 2.5), ("0", 0.0), ("x", 10.0)])
def test_interval_from_the_environment(
    value: str, expected: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    from topomech.run import log_interval_default

    monkeypatch.setenv(LOG_INTERVAL_ENV, value)
    assert log_interval_default() == expected
    monkeypatch.setenv(LOG_INTERVAL_ENV, "-1")
    assert log_interval_default() == LOG_INTERVAL_S


def test_progress_kinds(monkeypatch: pytest.MonkeyPatch) -> None:
    """The bar when stderr is a terminal; lines when stdout or stderr is not one."""

    class Stream(io.StringIO):
        def __init__(self, tty: bool) -> None:
            super().__init__()
            self.tty = tty

        def isatty(self) -> bool:
            return self.tty

    for out_tty, err_tty, expected in [
        (True, True, (True, False)),
        (False, True, (True, True)),
        (True, False, (False, True)),
        (False, False, (False, True)),
    ]:
        monkeypatch.setattr(sys, "stdout", Stream(out_tty))
        monkeypatch.setattr(sys, "stderr", Stream(err_tty))
        assert cli._progress_kinds(quiet=False) == expected
        assert cli._progress_kinds(quiet=True) == (False, False)


# --------------------------------------------------------------------------- the Makefile


def _recipe(target: str) -> list[str]:
    """The recipe lines of ``target`` in the Makefile, continuation lines joined."""
    lines = (ROOT / "Makefile").read_text().splitlines()
    start = lines.index(f"{target}:") if f"{target}:" in lines else None
    if start is None:
        start = next(i for i, x in enumerate(lines) if x.startswith(f"{target}:"))
    recipe: list[str] = []
    for line in lines[start + 1 :]:
        if not line.startswith("\t"):
            break
        if recipe and recipe[-1].endswith("\\"):
            recipe[-1] = recipe[-1][:-1] + " " + line.strip()
        else:
            recipe.append(line.strip())
    return recipe


@pytest.mark.parametrize(
    ("target", "log"),
    [("$(VENV_STAMP)", "$(VENV)/venv.log"), ("$(DEVELOP_STAMP)", "$(VENV)/develop.log")],
)
def test_make_setup_steps_are_quiet_unless_they_fail(target: str, log: str) -> None:
    recipe = _recipe(target)
    assert recipe, target
    assert all(line.startswith("@") for line in recipe), recipe  # no command echoed
    commands = [
        x for x in recipe if "pip install" in x or "maturin develop" in x or "wheel.py" in x
    ]
    assert commands, recipe
    for c in commands:
        # every tool's output goes to the log; the log is printed only when a step fails
        # (`|| { cat LOG >&2; ...; exit 1; }`, or the exit status kept and tested)
        on_failure = c.split("|| {")[0].split("if [ $$rc != 0 ]")[0]
        for tool in re.split(r"&&|\|\||;" if "if [ $$rc" in c else r"&&|\|\|", on_failure):
            if "pip" in tool or "maturin" in tool or "-m venv" in tool or "wheel.py" in tool:
                assert re.search(rf">>? {re.escape(log)} 2>&1", tool), tool
        assert f"|| {{ cat {log} >&2;" in c or f"then cat {log} >&2;" in c, c
        assert c.rstrip().endswith(("exit 1; }", "exit 1; fi")), c
    echoes = [x for x in recipe if x.startswith("@echo")]
    assert len(echoes) == 1  # one line saying what it does and where the log is
    assert log in echoes[0]


def test_make_demo_echoes_no_command() -> None:
    assert _recipe("demo") == ["@$(VENV)/bin/topomech demo --overwrite"]


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
@pytest.mark.parametrize("fails", [False, True])
def test_make_venv_step_with_a_stand_in_python(tmp_path: Path, fails: bool) -> None:
    """The venv recipe run against a stand-in interpreter in a temporary folder (nothing is
    installed): its output reaches the terminal only when it fails."""
    fake = tmp_path / "python"
    venv = tmp_path / "v"
    fake.write_text(
        "#!/bin/sh\n"
        '[ "$1" = "-m" ] && [ "$2" = "venv" ] || exit 3\n'
        'mkdir -p "$3/bin"\n'
        f'printf \'#!/bin/sh\\necho "Collecting $*"; echo "noise" >&2; exit {int(fails)}\\n\''
        ' > "$3/bin/python"\n'
        'chmod +x "$3/bin/python"\n'
    )
    fake.chmod(0o755)
    r = subprocess.run(
        ["make", "-s", "-C", str(ROOT), f"VENV={venv}", f"PYTHON={fake}", f"{venv}/.stamp-venv"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    log = venv / "venv.log"
    assert "Collecting" in log.read_text()
    if fails:
        assert r.returncode != 0
        assert "Collecting" in r.stderr
        assert f"setting up {venv} failed (log: {log})" in r.stderr
        assert not (venv / ".stamp-venv").exists()
    else:
        assert r.returncode == 0, r.stderr
        assert r.stdout == f"make: setting up {venv} (pip's output: {log})\n"
        assert r.stderr == ""
        assert (venv / ".stamp-venv").exists()


def test_progress_log_on_a_closed_pipe_stops_quietly() -> None:
    """`topomech run X | head -1`: the log stops writing, the run goes on (before the log,
    nothing reached stdout until the report)."""

    class Closed(io.StringIO):
        def write(self, text: str) -> int:
            raise BrokenPipeError(32, "Broken pipe")

    log = ProgressLog("corotational", 10, Closed(), interval=0.0)
    log.update(1, 1e-3)
    log.update(2, 2e-3)
    log.close(10, 1e-2)
    assert log.closed
    assert log.lines == 0
