"""Issue 13: a long rule application answers Ctrl-C within a second.

Before the engine polled for interrupts, ``RuleSet.apply`` ran to its end with the GIL
released: SIGINT was only seen when it returned (15 s after the signal here, on main), and
``topomech apply`` then died with a ``KeyboardInterrupt`` traceback. Each test runs the
application in a subprocess on a map generated here, sends SIGINT a second or two in, and
asserts that the process answers within ``ANSWER_S`` (its first line of output after the
signal): ``KeyboardInterrupt`` with the map valid and unchanged, or exit 130 with one line on
stderr, no Rust panic, no traceback and no output file.

The rule is a computation rule whose guard (a long but shallow expression, false everywhere)
costs tens of microseconds per evaluation: the whole application is matching, which the
engine interrupts between tries (the guard has one value on a vertex, so it is evaluated once
per vertex, on the vertices' matches). ``ANSWER_S`` is generous against a loaded machine; the engine polls
every 10 ms.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path
from typing import IO

import pytest

from topomech import GMap, _core

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="SIGINT to a subprocess")

#: Seconds allowed between SIGINT and the end of the process.
ANSWER_S = 2.0
#: Grid size: 4 * N^2 darts, (N + 1)^2 vertices, each one guard evaluation.
N = 180

# a guard with ~900 arithmetic operations that is false everywhere (the position is >= 0),
# written as 30 bracketed sums of 30 terms: long but only ~60 deep
_TERM = " + ".join(["x(v.position) * 1.0001"] * 30)
_GUARD = " + ".join([f"({_TERM})"] * 30) + " < -1.0"
RULES = textwrap.dedent(
    f"""\
    dimension 2
    embedding position : vec3 on <1,2>
    embedding mark : f64 on <1,2>

    rule slow {{
      left {{ v : <1,2> hook }}
      where {_GUARD}
      compute {{
        v.mark = 1.0
      }}
    }}
    """
)


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _interrupt(p: subprocess.Popen[str], after_s: float, answer: IO[str]) -> tuple[float, str]:
    """Sends SIGINT `after_s` seconds from now; returns (seconds until the process printed its
    first line on `answer` after the signal, that line). Measured to the answer, not to the
    exit: the interpreter's shutdown on a loaded machine is not what is tested."""
    time.sleep(after_s)
    assert p.poll() is None, "the application ended before the signal: make the map bigger"
    t = time.monotonic()
    p.send_signal(signal.SIGINT)
    timer = threading.Timer(60, p.kill)
    timer.start()
    try:
        line = answer.readline()
    finally:
        timer.cancel()
    return time.monotonic() - t, line


SCRIPT = textwrap.dedent(
    """\
    import sys, time
    from topomech import GMap, RuleSet, _core
    g = GMap.from_flat(*_core.grid({n}, {n}))
    rules = RuleSet.load(sys.argv[1])
    before = g.positions().copy()
    print("ready", flush=True)
    t = time.monotonic()
    try:
        rules.apply(g, "slow")
    except KeyboardInterrupt:
        ok = g.is_valid() and (g.positions() == before).all()
        print("interrupted", round(time.monotonic() - t, 3), ok, flush=True)
        sys.exit(130)
    print("finished", round(time.monotonic() - t, 3), flush=True)
    """
)


def test_ruleset_apply_answers_ctrl_c_with_keyboard_interrupt(tmp_path: Path) -> None:
    rules = tmp_path / "slow.tmr"
    rules.write_text(RULES)
    p = subprocess.Popen(
        [sys.executable, "-c", SCRIPT.format(n=N), str(rules)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(),
    )
    assert p.stdout is not None
    assert p.stdout.readline().strip() == "ready"
    took, line = _interrupt(p, 1.0, p.stdout)
    out, err = p.communicate(timeout=60)
    out = line + out
    assert p.returncode == 130, (out, err)
    assert out.startswith("interrupted"), out
    assert out.split()[2] == "True", f"the map changed or is invalid: {out}"
    assert took < ANSWER_S, f"{took:.2f} s from SIGINT to exit"
    assert "panicked" not in err, err
    assert "RUST_BACKTRACE" not in err, err


def test_cli_apply_exits_130_on_ctrl_c_and_writes_nothing(tmp_path: Path) -> None:
    src = tmp_path / "in.tmg"
    GMap.from_flat(*_core.grid(N, N)).save(src)
    rules = tmp_path / "slow.tmr"
    rules.write_text(RULES)
    out_file = tmp_path / "out.tmg"
    # the command line's main, called once the package is imported (a SIGINT during the
    # import, on a loaded machine, would test the import, not the application)
    runner = (
        "import sys; from topomech.cli import main; print('ready', flush=True); "
        "sys.exit(main(sys.argv[1:]))"
    )
    p = subprocess.Popen(
        [
            *[sys.executable, "-c", runner, "apply", str(src), str(rules), "slow"],
            *["--everywhere", "--out", str(out_file)],
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(),
    )
    assert p.stdout is not None
    assert p.stderr is not None
    assert p.stdout.readline().strip() == "ready"
    took, line = _interrupt(p, 1.5, p.stderr)
    out, err = p.communicate(timeout=60)
    err = line + err
    assert p.returncode == 130, (out, err)
    lines = err.strip().splitlines()
    assert lines == ["topomech: error: interrupted while applying rule 'slow'; nothing written"], (
        err
    )
    assert "Traceback" not in err
    assert "panicked" not in err
    assert took < ANSWER_S, f"{took:.2f} s from SIGINT to exit"
    assert not out_file.exists()
