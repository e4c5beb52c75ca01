"""README.md, run as written: every shell, console and Python block in it.

The fenced blocks of README.md run in README order, in one empty temporary folder (as a
reader would in one terminal), with ``topomech`` and ``python`` being this interpreter's.
What a block needs comes from the README itself: its examples copy the shipped samples
(``topomech samples --copy .``) and write their files from earlier blocks. A marker (an HTML
comment, invisible on GitHub) on the line right before a block says what to do with it:

- ``<!-- readme-test: file NAME -->``: the block is written to ``NAME`` (any language: a rule
  file, a scene, a script that a later block runs);
- ``<!-- readme-test: skip (REASON) -->``: the block is not run; the reason is required
  (``make test`` itself, a 10-minute benchmark, a server that runs until Ctrl-C, ...);
- ``<!-- readme-test: numbers vary (REASON) -->`` before a ``console`` block: its output is
  compared with every number a wildcard (timings).

Unmarked ``sh``/``bash`` blocks run line by line (a line starting with a space or ``#``
continues the comment of the line above), each line must exit 0. ``console`` blocks hold
``$ COMMAND`` lines, each followed by its output as shown: the command must exit 0 with
exactly that stdout (``...`` stands for any text within a line). ``python`` blocks run in a
fresh interpreter and must exit 0. Blocks in other languages (rule text, the layout) are
not run unless marked ``file``; a TOML block that is not a file is a part of a scene, which
is completed into a scene on the sample beam that must load and build. A failure names the
line of README.md where the block or command is.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

README = Path(__file__).resolve().parent.parent / "README.md"
RUNNABLE = {"sh", "bash", "console", "python"}
#: Seconds one command or Python block may take.
TIMEOUT_S = 300

_MARKER = re.compile(r"<!-- readme-test: (?P<what>.*?) -->")
_FILE = re.compile(r"file (?P<name>[\w.-]+)")
_SKIP = re.compile(r"skip \((?P<reason>[^)]*\S[^)]*)\)")
_NUMBERS = re.compile(r"numbers vary \((?P<reason>[^)]*\S[^)]*)\)")
_NUMBER = re.compile(r"\d+(?:[.,]\d+)*(?:e[+-]?\d+)?")


@dataclass
class Block:
    line: int  #: line of the opening fence in README.md (1-based)
    info: str  #: the fence's language
    body: str
    marker: str | None  #: the text of the marker right before the fence, if any

    def lines(self) -> list[tuple[int, str]]:
        """``(README line, text)`` of each line of the body."""
        return [(self.line + 1 + i, t) for i, t in enumerate(self.body.splitlines())]


def readme_blocks(text: str | None = None) -> list[Block]:
    """Every fenced block of README.md, with the marker right before it."""
    lines = (README.read_text(encoding="utf-8") if text is None else text).splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        if lines[i].startswith("```"):
            start, info = i, lines[i][3:].strip()
            j = i + 1
            while j < len(lines) and lines[j] != "```":
                j += 1
            assert j < len(lines), f"README.md:{start + 1}: block never closed"
            m = _MARKER.fullmatch(lines[start - 1].strip()) if start > 0 else None
            body = "".join(f"{t}\n" for t in lines[start + 1 : j])
            blocks.append(Block(start + 1, info, body, m["what"] if m else None))
            i = j + 1
        else:
            i += 1
    return blocks


def _markers(text: str) -> list[tuple[int, str, bool]]:
    """``(line, marker text, followed by a fence)`` of every marker in the README."""
    lines = text.splitlines()
    out = []
    for n, t in enumerate(lines):
        for m in _MARKER.finditer(t):
            fence_next = n + 1 < len(lines) and lines[n + 1].startswith("```")
            out.append((n + 1, m["what"], fence_next and t.strip() == m[0]))
    return out


def _commands(block: Block) -> list[tuple[int, str, list[str]]]:
    """``(line, command, expected stdout lines)`` of a console block."""
    out: list[tuple[int, str, list[str]]] = []
    for n, t in block.lines():
        if t.startswith("$ "):
            out.append((n, t[2:], []))
        else:
            assert out, f"README.md:{n}: output before any command: {t!r}"
            out[-1][2].append(t)
    return out


def _shell_lines(block: Block) -> list[tuple[int, str]]:
    """``(line, command)`` of each command of a sh block (comment lines dropped)."""
    return [(n, t) for n, t in block.lines() if t.strip() and not t[0].isspace() and t[0] != "#"]


def _matches(want: list[str], got: list[str], numbers_vary: bool) -> bool:
    if len(want) != len(got):
        return False
    for w, g in zip(want, got):
        parts = re.split(r"(\.\.\.)", w)
        pattern = ""
        for p in parts:
            if p == "...":
                pattern += ".*"
            elif numbers_vary:
                pieces = _NUMBER.split(p)
                pattern += r"[\d.,e+-]+".join(re.escape(x) for x in pieces)
            else:
                pattern += re.escape(p)
        if not re.fullmatch(pattern, g):
            return False
    return True


def _environment(tmp: Path) -> dict[str, str]:
    """``topomech`` and ``python`` first on the PATH, both this interpreter's."""
    bin_dir = tmp.parent / f"{tmp.name}-bin"
    bin_dir.mkdir(exist_ok=True)
    for name, args in (("topomech", "-m topomech"), ("python", "")):
        shim = bin_dir / name
        shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" {args} "$@"\n', encoding="utf-8")
        shim.chmod(0o755)
    env = dict(os.environ)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["MPLBACKEND"] = "Agg"
    env.pop("TOPOMECH_PROGRESS_INTERVAL_S", None)
    return env


def _run(command: str, cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["bash", "-o", "pipefail", "-c", command],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
    )


def _failure(line: int, what: str, r: subprocess.CompletedProcess[str]) -> str:
    return (
        f"README.md:{line}: {what} exited {r.returncode}\n"
        f"--- stdout\n{r.stdout}--- stderr\n{r.stderr}"
    )


def test_every_marker_is_right_before_a_block_and_says_what_it_does() -> None:
    text = README.read_text(encoding="utf-8")
    for line, what, before_fence in _markers(text):
        assert before_fence, (
            f"README.md:{line}: a readme-test marker must be alone on the line right before a fenced block"
        )
        assert _FILE.fullmatch(what) or _SKIP.fullmatch(what) or _NUMBERS.fullmatch(what), (
            f"README.md:{line}: {what!r}: expected 'file NAME', 'skip (REASON)' or "
            "'numbers vary (REASON)', each reason non-empty"
        )
    for b in readme_blocks(text):
        if b.marker is not None and _NUMBERS.fullmatch(b.marker):
            assert b.info == "console", f"README.md:{b.line}: 'numbers vary' is for console blocks"


def test_every_block_runs_or_says_why_not() -> None:
    """Every sh, bash, console and python block is run, written as a file or skipped with a
    reason; a block in another language says which (a bare fence is for text only)."""
    runnable = 0
    for b in readme_blocks():
        if b.info in RUNNABLE and (b.marker is None or not _SKIP.fullmatch(b.marker)):
            runnable += 1
        assert b.info in RUNNABLE | {"toml", "text", "tmr", ""}, f"README.md:{b.line}: {b.info}"
    assert runnable >= 15, runnable  # the README's examples, not a handful


def test_the_tutorial_has_its_steps() -> None:
    """The "Writing a model" tutorial's files and commands are there (a marker lost in an
    edit would skip a step)."""
    text = README.read_text(encoding="utf-8")
    tutorial = text.split("## Writing a model\n", 1)[1].split("\n## ", 1)[0]
    first = text[: text.index("## Writing a model\n")].count("\n")
    blocks = readme_blocks(text)
    inside = [b for b in blocks if first < b.line <= first + tutorial.count("\n")]
    files = [b.marker.split(" ", 1)[1] for b in inside if b.marker and _FILE.fullmatch(b.marker)]
    assert files == ["anchor.tmr", "anchored.toml", "check.py", "in_python.py"]
    commands = [c for b in inside if b.info == "console" for _, c, _ in _commands(b)]
    assert commands == [
        "topomech check anchor.tmr",
        "topomech models anchor.tmr",
        "topomech run anchored.toml --quiet --no-preview",
        "python check.py",
        "python in_python.py",
    ]


def test_matching_of_shown_output() -> None:
    assert _matches(["took 1.2 s (63 steps/s)"], ["took 0.04 s (1,183 steps/s)"], True)
    assert not _matches(["took 1.2 s"], ["took 0.04 s"], False)
    assert _matches(["scene  x (.../x.toml)"], ["scene  x (/a/b/x.toml)"], False)
    assert not _matches(["a", "b"], ["a"], True)


def test_the_readme_runs_as_written(tmp_path: Path) -> None:
    env = _environment(tmp_path)
    ran = 0
    for b in readme_blocks():
        marker = b.marker or ""
        if _FILE.fullmatch(marker):
            (tmp_path / marker.split(" ", 1)[1]).write_text(b.body, encoding="utf-8")
            continue
        if _SKIP.fullmatch(marker) or b.info not in RUNNABLE:
            continue
        ran += 1
        if b.info == "python":
            r = subprocess.run(
                [sys.executable, "-"],
                input=b.body,
                cwd=tmp_path,
                env=env,
                capture_output=True,
                text=True,
                timeout=TIMEOUT_S,
            )
            assert r.returncode == 0, _failure(b.line, "this python block", r)
        elif b.info == "console":
            for line, command, want in _commands(b):
                r = _run(command, tmp_path, env)
                assert r.returncode == 0, _failure(line, f"$ {command}", r)
                got = r.stdout.splitlines()
                assert _matches(want, got, bool(_NUMBERS.fullmatch(marker))), (
                    f"README.md:{line}: $ {command}: the output differs from the README's\n"
                    f"--- README\n" + "\n".join(want) + "\n--- got\n" + r.stdout
                )
        else:
            for line, command in _shell_lines(b):
                r = _run(command, tmp_path, env)
                assert r.returncode == 0, _failure(line, f"$ {command}", r)
    assert ran > 0


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("<!-- readme-test: skip () -->\n```sh\nmake test\n```\n", "reason"),
        ("<!-- readme-test: skip -->\n```sh\nmake test\n```\n", "reason"),
        ("<!-- readme-test: file a.py -->\n\n```python\n```\n", "right before"),
    ],
)
def test_a_marker_without_its_reason_or_block_is_refused(
    text: str, problem: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    fake = tmp_path / "README.md"
    fake.write_text(text, encoding="utf-8")
    monkeypatch.setattr(sys.modules[__name__], "README", fake)
    with pytest.raises(AssertionError, match=problem):
        test_every_marker_is_right_before_a_block_and_says_what_it_does()


#: What a TOML fragment of the README (a table or two of a scene) is completed with to make a
#: scene: the sample beam, held at x = 0, 1 s of implicit Euler (the fragments' events fit).
_SCENE_BASE = """
[mesh]
file = "beam.msh"
[material]
density = 1000.0
[integrator]
kind = "implicit_euler"
dt = 1e-3
steps = 1000
"""
_WORLD = "[world]\ngravity = [0.0, -9.81, 0.0]\n"
_MODEL = '[[model]]\nkind = "corotational"\nyoung = 1e7\npoisson = 0.3\n'


def test_every_toml_fragment_is_a_valid_part_of_a_scene(tmp_path: Path) -> None:
    """The README's TOML blocks that are not whole files (a fix, a load, an event, ...) are
    completed into a scene on the sample beam, which must load and build: every key, group
    and point they name exists."""
    import topomech

    (tmp_path / "beam.msh").write_bytes(topomech.sample("beam.msh").read_bytes())
    checked = 0
    for b in readme_blocks():
        if b.info != "toml" or (b.marker and _FILE.fullmatch(b.marker)):
            continue
        text = b.body
        if "[mesh]" not in text:
            base = _SCENE_BASE
            if "[integrator]" in text:  # the fragment's own (its solver keys)
                base = base[: base.index("[integrator]")]
            text += base
        if "[world]" not in text:
            text += _WORLD
        if "[[model]]" not in text:
            text += _MODEL
        path = tmp_path / f"block_{b.line}.toml"
        path.write_text(text, encoding="utf-8")
        try:
            topomech.load_scene(path).build()
        except topomech.TopomechError as e:
            raise AssertionError(f"README.md:{b.line}: this TOML block: {e}\n{text}") from None
        checked += 1
    assert checked >= 7, checked


_PATH = re.compile(r"(?<![\w/.])(?:tests|crates|python|bench|scripts|docs)/[\w./{},*-]*[\w*}]")


def _expand(path: str) -> list[str]:
    """``a{2,3}b`` as ``a2b``, ``a3b``."""
    m = re.search(r"\{([^{}]*)\}", path)
    if m is None:
        return [path]
    return [
        x for alt in m[1].split(",") for x in _expand(path[: m.start()] + alt + path[m.end() :])
    ]


#: Files the README names that ``make bench`` writes (absent until its first run that does).
_WRITTEN_BY_BENCH = {"bench/kernel.txt", "bench/topology.txt"}


def test_every_file_the_readme_names_exists() -> None:
    """A test, a source file or a folder of the repository named in the README is there
    (``*`` a glob, ``{a,b}`` both)."""
    root = README.parent
    text = README.read_text(encoding="utf-8")
    missing = []
    for n, line in enumerate(text.splitlines(), 1):
        for m in _PATH.finditer(line):
            for path in _expand(m[0]):
                if path not in _WRITTEN_BY_BENCH and not any(root.glob(path)):
                    missing.append(f"README.md:{n}: {path}")
    assert not missing, "\n".join(missing)


def test_the_status_names_every_command() -> None:
    """The status paragraph lists the commands `topomech --help` has, no more, no fewer."""
    from topomech.cli import build_parser

    text = README.read_text(encoding="utf-8")
    m = re.search(r"with its `topomech (\w+)`,(.*?) commands\.", text, re.DOTALL)
    assert m is not None, "the status paragraph lists the commands"
    named = [m[1], *re.findall(r"`(\w+)`", m[2])]
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    assert sorted(named) == sorted(sub.choices), named  # type: ignore[arg-type]


def test_the_table_of_models_is_the_shipped_models() -> None:
    """Each row of the README's table of models is a shipped kind and its dimensions."""
    import topomech

    text = README.read_text(encoding="utf-8")
    table = text.split("| `kind` | dims |", 1)[1].split("\n\n", 1)[0]
    rows = set()
    for line in table.splitlines():
        m = re.match(r"\| `(\w+)` \| ([23]D(?:, [23]D)?) \|", line)
        if m:
            rows.add((m[1], tuple(int(d[0]) for d in m[2].split(", "))))
    shipped = set()
    for model in topomech.available_models():
        shipped.add((model["kind"], tuple(model["dims"])))
    # a kind shipped once per dimension is one row per dimension (corotational)
    assert rows == shipped
