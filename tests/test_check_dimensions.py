"""`topomech check` on a rule file that serves both dimensions (`dimension 2 3`, or no
dimension line) checks it for 2-maps and for 3-maps and says so; a file that is wrong in one
of them is refused, naming that dimension (before: such a file was refused with "load the
rules for a dimension (load_sources_for)", an API name, whatever it held)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import topomech
from topomech import RuleError, _core, cli
from topomech.rules import RuleSet

BOTH = """dimension 2 3
embedding position : vec3 on <1,2,3>
embedding w : f64 on <0,2,3>
rule edge_weight {
  left { a : <0,2,3> hook }
  compute { a.w = count<0,2,3>(a) }
}
"""

# an arc of label 3 between two nodes can never match on a 2-map (alpha3 is free there): the
# checker refuses it for dimension 2 and accepts it for dimension 3
ONLY_3D = """dimension 2 3
embedding position : vec3 on <1,2,3>
rule glue_volumes {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
}
"""

MODEL = """dimension 2 3
embedding f_anchor : vec3 on <1,2,3>
rule anchor_force(k: f64) {
  left { v : <1,2,3> hook }
  compute { v.f_anchor = -k * (v.position - v.rest) }
}
model anchor(k: f64 = 10.0) {
  init   anchor_force(k)
  step   anchor_force(k)
  forces f_anchor
}
"""


def check(tmp_path: Path, text: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    f = tmp_path / "rules.tmr"
    f.write_text(text)
    rc = cli.main(["check", str(f)])
    return rc, capsys.readouterr().out


def test_a_file_for_both_dimensions_is_checked_for_each(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rc, out = check(tmp_path, BOTH, capsys)
    assert rc == 0
    assert "ok: 1 rule in 1 file (checked for dimensions 2 and 3)" in out
    rc, out = check(tmp_path, BOTH.replace("dimension 2 3\n", ""), capsys)
    assert rc == 0, out
    assert "checked for dimensions 2 and 3" in out


def test_a_file_wrong_in_one_dimension_is_refused_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rc, out = check(tmp_path, ONLY_3D, capsys)
    assert rc == 1
    assert "for dimension 2 (the files serve 2-maps and 3-maps):" in out
    assert "for dimension 3" not in out
    assert "rules.tmr:4:" in out  # the arc, at its line
    assert "load_sources_for" not in out


def test_a_model_file_for_both_dimensions_is_checked_with_the_prelude(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`position`, `rest` come from the shipped prelude: the file declares only its own."""
    rc, out = check(tmp_path, MODEL, capsys)
    assert rc == 0, out
    assert "1 model" in out
    assert "dimensions 2 and 3" in out


def test_an_empty_file_is_not_answered_with_an_api_name(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rc, out = check(tmp_path, "", capsys)
    assert "load_sources_for" not in out
    assert rc == 0


def test_the_same_error_in_both_dimensions_is_said_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A syntax error does not depend on the dimension: one line, no per-dimension header."""
    rc, out = check(tmp_path, BOTH.replace("compute {", "compute {{"), capsys)
    assert rc == 1
    assert "for dimension" not in out
    assert len([x for x in out.splitlines() if "error[syntax]" in x]) == 1, out


@pytest.mark.parametrize("header", ["dimension 2 3\n", ""], ids=["dimension-2-3", "no-line"])
def test_from_source_without_a_dimension_says_how_to_give_one(header: str) -> None:
    """Regression: ``RuleSet.from_source`` on a ``dimension 2 3`` file said "load the rules for
    a dimension (load_sources_for)", a Rust function a Python user cannot call. It now says
    what the file serves and which argument to pass, and that argument loads it."""
    text = header + BOTH.replace("dimension 2 3\n", "")
    with pytest.raises(RuleError) as e:
        RuleSet.from_source(text, "both.tmr")
    msg = str(e.value)
    assert "load_sources" not in msg
    assert msg.startswith("both.tmr:1:1: error[dimension]: "), msg
    assert "serves 2-maps and 3-maps" in msg
    assert msg.endswith("pass dimension=2 (surfaces) or dimension=3 (volumes)"), msg
    for dim in (2, 3):
        assert RuleSet.from_source(text, "both.tmr", dimension=dim).dimension == dim
    with pytest.raises(ValueError, match="dimension must be 2 or 3, got 4"):
        RuleSet.from_source(text, dimension=4)


def test_load_takes_a_dimension_for_a_file_serving_both(tmp_path: Path) -> None:
    f = tmp_path / "both.tmr"
    f.write_text(BOTH)
    with pytest.raises(RuleError, match=r"pass dimension=2 \(surfaces\) or dimension=3"):
        RuleSet.load(f)
    for dim in (2, 3):
        rules = RuleSet.load(f, dimension=dim)
        assert rules.dimension == dim
        assert rules.rule_names() == ["edge_weight"]
    # the dimension a file says still wins over none, and disagrees with another one
    with pytest.raises(RuleError, match="serves dimension 2, not dimension 3"):
        RuleSet.from_source(BOTH.replace("dimension 2 3", "dimension 2"), dimension=3)


def test_apply_loads_a_file_serving_both_for_the_map(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``topomech apply`` with a ``dimension 2 3`` rule file loads it for the map's
    dimension (it was refused with the Rust function's name)."""
    rules = tmp_path / "both.tmr"
    rules.write_text(BOTH)
    for dim, mesh in (
        (2, _core.grid(2, 1, 2.0, 1.0, "quad")),
        (3, _core.box(1, 1, 1, 1.0, 1.0, 1.0, "hexahedron")),
    ):
        src = tmp_path / f"in{dim}.tmg"
        topomech.GMap.from_flat(*mesh).save(src)
        out = tmp_path / f"out{dim}.tmg"
        rc = cli.main(
            ["apply", str(src), str(rules), "edge_weight", "--everywhere", "--out", str(out)]
        )
        captured = capsys.readouterr()
        assert rc == 0, captured.err
        assert "load_sources" not in captured.err
        g = topomech.GMap.load(out)
        assert g.dimension == dim
        w = g.embedding("w")
        # darts per edge: 2 on the sheet's boundary, 4 inside it; 4 on the lone cube's edges
        assert set(np.unique(w.values).tolist()) == ({2.0, 4.0} if dim == 2 else {4.0})
