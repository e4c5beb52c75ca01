"""The README's "Writing a model" tutorial, run exactly as written.

Every fenced block after a ``<!-- tutorial file: NAME -->`` marker is written to ``NAME`` in
an empty temporary folder; every ``console`` block after a ``<!-- tutorial run -->`` marker
holds commands (``$ ...`` lines), each followed by the output the README states: the command
is run there (``topomech`` as ``python -m topomech``, ``python`` as this interpreter) and must
exit 0 with exactly that output on stdout. The blocks run in README order, so the tutorial's
final check (every vertex at ``m g / k`` to 1e-10) is asserted by the output it prints.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

README = Path(__file__).resolve().parent.parent / "README.md"

#: A marker, then the fenced block after it (its info string, its body).
_BLOCK = re.compile(
    r"<!-- tutorial (file: (?P<name>[^ ]+)|run) -->\n```(?P<info>[a-z]*)\n(?P<body>.*?)^```$",
    re.DOTALL | re.MULTILINE,
)


def tutorial_blocks() -> list[tuple[str | None, str, str]]:
    """``(file name or None for a run block, info string, body)`` of each marked block."""
    text = README.read_text(encoding="utf-8")
    section = text.split("## Writing a model\n", 1)[1].split("\n## ", 1)[0]
    return [(m["name"], m["info"], m["body"]) for m in _BLOCK.finditer(section)]


def _commands(body: str) -> list[tuple[str, str]]:
    """``(command, expected stdout)`` pairs of a console block."""
    out: list[tuple[str, list[str]]] = []
    for line in body.splitlines():
        if line.startswith("$ "):
            out.append((line[2:], []))
        else:
            assert out, f"output before any command: {line!r}"
            out[-1][1].append(line)
    return [(c, "".join(f"{x}\n" for x in lines)) for c, lines in out]


def _argv(command: str) -> list[str]:
    argv = shlex.split(command)
    if argv[0] == "topomech":
        return [sys.executable, "-m", "topomech", *argv[1:]]
    if argv[0] == "python":
        return [sys.executable, *argv[1:]]
    raise AssertionError(f"the tutorial runs topomech or python only: {command}")


def test_the_tutorial_has_its_steps() -> None:
    """The blocks this test runs are there (a marker lost in an edit would skip a step)."""
    blocks = tutorial_blocks()
    files = [name for name, _, _ in blocks if name is not None]
    assert files == ["anchor.tmr", "anchored.toml", "check.py", "in_python.py"]
    commands = [c for name, _, body in blocks if name is None for c, _ in _commands(body)]
    assert commands == [
        "topomech check anchor.tmr",
        "topomech models anchor.tmr",
        "topomech run anchored.toml --quiet --no-preview",
        "python check.py",
        "python in_python.py",
    ]


def test_the_readme_tutorial_runs_as_written(tmp_path: Path) -> None:
    for name, info, body in tutorial_blocks():
        if name is not None:
            (tmp_path / name).write_text(body, encoding="utf-8")
            continue
        assert info == "console", info
        for command, want in _commands(body):
            r = subprocess.run(
                _argv(command), cwd=tmp_path, capture_output=True, text=True, timeout=300
            )
            assert r.returncode == 0, f"$ {command}\n{r.stdout}{r.stderr}"
            assert r.stdout == want, f"$ {command}\n{r.stdout}"
