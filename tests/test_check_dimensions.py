"""`topomech check` on a rule file that serves both dimensions (`dimension 2 3`, or no
dimension line) checks it for 2-maps and for 3-maps and says so; a file that is wrong in one
of them is refused, naming that dimension (before: such a file was refused with "load the
rules for a dimension (load_sources_for)", an API name, whatever it held)."""

from __future__ import annotations

from pathlib import Path

import pytest

from topomech import cli

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
