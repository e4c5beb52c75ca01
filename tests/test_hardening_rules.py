"""Issue 13 (hardening), the rule language: any text gives a rule set or a ``RuleError``.

A long chain of one binary operator (``1.0 + 1.0 + ...``, a few thousand terms) used to
overflow the stack and kill the Python process (SIGSEGV) in ``RuleSet.from_source``, in a
scene predicate and in ``topomech check``. Each case runs in a fresh interpreter, so a crash
is seen as a crash (a negative return code), not as a dead pytest. The parser now refuses an
expression deeper than 256 (a chain of n terms is depth n) with a ``syntax`` diagnostic at the
operator that goes too deep; the deepest accepted expression works.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

LIMIT = 256

HEAD = """dimension 2
embedding position : vec3 on <1,2>
embedding weight : f64 on <0,1>
"""


def chain(term: str, op: str, n: int) -> str:
    return f" {op} ".join([term] * n)


def rule_text(expr: str) -> str:
    """A rule file whose expression ``expr`` is on line 6."""
    return (
        HEAD + f"rule r {{\n  left {{ n0 : <0,1> hook }}\n  compute {{ n0.weight = {expr} }}\n}}\n"
    )


def python(code: str, *args: str) -> subprocess.CompletedProcess[str]:
    """``code`` in a fresh interpreter, under a 4 GiB address-space limit."""
    prelude = "import resource\nresource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))\n"
    return subprocess.run(
        [sys.executable, "-c", prelude + textwrap.dedent(code), *args],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def too_deep(col: int, line: int = 6) -> str:
    return (
        f":{line}:{col}: error[syntax]: expression nested too deeply: "
        f"depth {LIMIT + 1}, the limit is {LIMIT}"
    )


def test_long_operator_chain_in_from_source_is_a_rule_error_not_a_crash(tmp_path: Path) -> None:
    path = tmp_path / "chain.tmr"
    for op in ("+", "*", "&&"):
        path.write_text(rule_text(chain("1.0", op, 5000)))
        r = python(
            """
            import sys, topomech
            try:
                topomech.RuleSet.from_source(open(sys.argv[1]).read(), "chain.tmr")
            except topomech.RuleError as e:
                print("\\n".join(e.diagnostics))
            """,
            str(path),
        )
        assert r.returncode == 0, (r.returncode, r.stderr[-2000:])
        col = len(f"  compute {{ n0.weight = {chain('1.0', op, LIMIT)} ") + 1
        assert r.stdout.splitlines() == ["chain.tmr" + too_deep(col)], r.stdout


def test_operator_chain_at_the_limit_loads_and_runs() -> None:
    src = HEAD + (
        "rule r {\n  left { v : <1,2> hook }\n"
        f"  compute {{ v.position = {chain('v.position', '+', LIMIT)} }}\n}}\n"
    )
    r = python(
        f"""
        import numpy as np, topomech
        rules = topomech.RuleSet.from_source({src!r}, "chain.tmr")
        g = topomech.GMap.from_flat(*topomech._core.grid(2, 2, 1.0, 1.0, "quad"))
        p0 = g.positions().copy()
        assert rules.apply(g, "r")["matches"] == 9
        print(np.array_equal(g.positions(), {LIMIT} * p0), g.is_valid())
        """
    )
    assert r.returncode == 0, (r.returncode, r.stderr[-2000:])
    assert r.stdout.split() == ["True", "True"]


def test_long_operator_chain_in_a_scene_predicate_is_a_scene_error_not_a_crash() -> None:
    pred = chain("x", "+", 4000) + " < 0"
    scene = f"""
[mesh]
generator = "box"
element = "tet"
size = [1.0, 0.2, 0.2]
cells = [2, 1, 1]

[[model]]
kind = "corotational"

[[fix]]
where = "{pred}"
"""
    r = python(
        f"""
        import topomech
        from topomech.scene import parse_scene
        try:
            parse_scene({scene!r}, "scene.toml").build()
        except topomech.SceneError as e:
            print(e)
        """
    )
    assert r.returncode == 0, (r.returncode, r.stderr[-2000:])
    assert "fix[0].where" in r.stdout, r.stdout[-500:]
    assert f"expression nested too deeply: depth {LIMIT + 1}, the limit is {LIMIT}" in r.stdout


def test_topomech_check_on_a_long_operator_chain_names_the_place(tmp_path: Path) -> None:
    path = tmp_path / "chain.tmr"
    path.write_text(rule_text(chain("n0.weight", "-", 20000)))
    r = subprocess.run(
        [sys.executable, "-m", "topomech", "check", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode == 1, (r.returncode, r.stderr[-2000:])
    col = len(f"  compute {{ n0.weight = {chain('n0.weight', '-', LIMIT)} ") + 1
    assert r.stdout.splitlines() == [f"{path}{too_deep(col)}"]


def test_orbit_label_256_is_reported_as_256() -> None:
    r = python(
        f"""
        import topomech
        for body in ("left {{ a : <0,256> hook }}", "left {{ a : <0,1> hook  b : <0,1>  a -256- b }}"):
            try:
                topomech.RuleSet.from_source({HEAD!r} + "rule r {{ " + body + " }}", "l.tmr")
            except topomech.RuleError as e:
                print(e)
        """
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "node 'a' has label 256 outside 0..=2" in r.stdout, r.stdout
    assert "arc a -256- b has label 256 outside 0..=2" in r.stdout, r.stdout
    assert "255" not in r.stdout


def test_fuzzed_rule_texts_with_long_chains_give_a_rule_set_or_a_rule_error() -> None:
    """Mutations of a shipped rule file (long chains and deep nesting inserted where an
    expression starts, pieces deleted or duplicated), a fixed seed, under a memory limit."""
    library = Path(__file__).parent.parent / "crates/rules/library/modeling2d.tmr"
    r = python(
        """
        import random, sys, topomech
        text = open(sys.argv[1]).read()
        limit = int(sys.argv[2])
        rng = random.Random(13)
        ok = refused = 0
        for case in range(100):
            s = text
            for _ in range(rng.randint(1, 3)):
                k = rng.randrange(len(s) + 1)
                kind = rng.randrange(4)
                if kind == 0:
                    starts = [i + 2 for i in range(len(s)) if s.startswith("= ", i)]
                    k = rng.choice(starts) if starts else k
                    n = rng.choice([limit - 1, limit, limit + 1, 20000])
                    op = rng.choice(["+", "*", "-", "&&", "<"])
                    s = s[:k] + " " + f" {op} ".join(["1.0"] * n) + f" {op} " + s[k:]
                elif kind == 1:
                    n = rng.choice([limit, 5000])
                    s = s[:k] + "(" * n + "1.0" + ")" * n + s[k:]
                elif kind == 2:
                    s = s[:k] + s[k + rng.randrange(30):]
                else:
                    s = s[:k] + s[k:k + rng.randrange(30)] + s[k:]
            try:
                topomech.RuleSet.from_source(s, "m.tmr")
                ok += 1
            except topomech.RuleError as e:
                assert e.diagnostics, s
                refused += 1
        print(ok, refused)
        """,
        str(library),
        str(LIMIT),
    )
    assert r.returncode == 0, (r.returncode, r.stderr[-2000:])
    ok, refused = map(int, r.stdout.split())
    assert ok + refused == 100
    assert refused > 0
