"""`topomech check` and `topomech apply`: output formats and exit codes."""

from __future__ import annotations

import re
import subprocess
import sys
import warnings
from pathlib import Path

import meshio
import numpy as np
import pytest

import topomech
from topomech import _core, cli

from conftest import flat_to_cells, independent_counts

DIAGNOSTIC = re.compile(
    r"^(?P<file>.+):(?P<line>\d+):(?P<col>\d+): (?P<sev>error|warning)\[(?P<cond>[a-z-]+)\]: .+$"
)

SCALE = """dimension 2
embedding position : vec3 on <1,2> policy mean

rule scale(f: f64) {
  left { v : <1,2> hook }
  compute { v.position = v.position * f }
}

rule move(d: vec3) {
  left { v : <1,2> hook }
  compute { v.position = v.position + d }
}
"""

# two different problems: a type error in the first rule, and the same name defined twice
BROKEN = """dimension 2
embedding position : vec3 on <1,2> policy mean

rule lift {
  left { v : <1,2> hook }
  compute { v.position = v.position + true }
}

rule lift {
  left { v : <1,2> hook }
}
"""


def run(*args: str) -> subprocess.CompletedProcess[str]:
    """The CLI in a fresh interpreter, as a user runs it."""
    return subprocess.run(
        [sys.executable, "-m", "topomech", *args],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


@pytest.fixture
def rule_files(tmp_path: Path) -> dict[str, Path]:
    files = {
        "scale": SCALE,
        "broken": BROKEN,
        "warn": "dimension 2\nembedding position : vec3 on <1,2> policy mean\nrule idle(f: f64) {\n  left { v : <1,2> hook }\n}\n",
        "volume": "dimension 3\n",
    }
    out = {}
    for name, text in files.items():
        out[name] = tmp_path / f"{name}.tmr"
        out[name].write_text(text)
    return out


@pytest.fixture
def quad_file(tmp_path: Path) -> tuple[Path, dict[str, int], np.ndarray]:
    """A 3 x 2 quad grid written as VTU; its independent counts and its points."""
    points, kinds, offsets, conn = _core.grid(3, 2, 3.0, 2.0, "quad")
    path = tmp_path / "quads.vtu"
    meshio.write(path, meshio.Mesh(points, [("quad", conn.reshape(-1, 4))]))
    return path, independent_counts(flat_to_cells(kinds, offsets, conn)), points


def sorted_rows(a: np.ndarray) -> np.ndarray:
    return a[np.lexsort(a.T[::-1])]


# ---------------------------------------------------------------------------------- check


def test_check_accepts_a_good_file(rule_files: dict[str, Path]) -> None:
    r = run("check", str(rule_files["scale"]))
    assert r.returncode == 0, r.stderr
    assert r.stdout == "ok: 2 rules in 1 file\n"


def test_check_prints_warnings_and_accepts(
    rule_files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["check", str(rule_files["warn"]), str(rule_files["scale"])]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out == [
        f"{rule_files['warn']}:3:11: warning[unused]: rule 'idle': parameter 'f' is never used",
        "ok: 3 rules in 2 files (1 warning)",
    ]


def test_check_warns_of_a_quotient_of_two_integers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`a.w = 1 / 2` (0: a quotient of two integers) passed `topomech check` silently, while
    a cut predicate refuses the same quotient: now a warning at its FILE:LINE:COL, and still
    ok (an integer quotient may be meant: to_i64(...) says so and silences it)."""
    path = tmp_path / "half.tmr"
    path.write_text(
        "dimension 2\nembedding w : f64 on <0>\n"
        "rule half {\n  left { a : <0> hook }\n  compute { a.w = 1 / 2 }\n}\n"
    )
    assert cli.main(["check", str(path)]) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"{path}:5:21: warning[integer-division]: rule 'half': a quotient of two integers is "
        "an integer, rounded toward zero (1 / 2 is 0, 7 / 2 is 3): write a real operand, e.g. "
        "1.0 / 2, for the real quotient, or to_i64(a / b) where the integer quotient is meant",
        "ok: 1 rule in 1 file (1 warning)",
    ]
    path.write_text(path.read_text().replace("1 / 2", "to_f64(to_i64(1 / 2))"))
    assert cli.main(["check", str(path)]) == 0
    assert capsys.readouterr().out == "ok: 1 rule in 1 file\n"


def test_check_refuses_with_one_line_per_problem(rule_files: dict[str, Path]) -> None:
    path = rule_files["broken"]
    r = run("check", str(path))
    assert r.returncode == 1
    lines = r.stdout.splitlines()
    assert lines == [
        f"{path}:6:37: error[type]: rule 'lift': cannot add vec3 and bool",
        f"{path}:9:1: error[name]: rule 'lift' is already defined at {path}:4:1",
    ]
    for line in lines:
        m = DIAGNOSTIC.match(line)
        assert m is not None, line
        assert (m["file"], m["sev"]) == (str(path), "error")


def test_check_loads_files_together(
    rule_files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """Files share their dimension: a 3D file beside a 2D one is refused."""
    assert cli.main(["check", str(rule_files["scale"]), str(rule_files["volume"])]) == 1
    (line,) = capsys.readouterr().out.splitlines()
    m = DIAGNOSTIC.match(line)
    assert m is not None, line
    assert (m["file"], m["cond"]) == (str(rule_files["volume"]), "dimension")


@pytest.mark.parametrize("case", ["missing", "directory", "binary"])
def test_check_exit_2_when_a_file_cannot_be_read(
    case: str, tmp_path: Path, rule_files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.tmr"
    if case == "directory":
        bad.mkdir()
    elif case == "binary":
        bad.write_bytes(b"\xff\xfe\x00dimension 2")
    assert cli.main(["check", str(rule_files["scale"]), str(bad)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.startswith(f"topomech: error: {bad}: cannot read the rule file")
    assert "Traceback" not in err


def test_check_missing_file_in_a_fresh_interpreter(tmp_path: Path) -> None:
    r = run("check", str(tmp_path / "nope.tmr"))
    assert r.returncode == 2
    assert r.stdout == ""
    assert "nope.tmr: cannot read the rule file: No such file or directory" in r.stderr


# ---------------------------------------------------------------------------------- apply


def test_apply_everywhere_to_vtu(quad_file: tuple, tmp_path: Path) -> None:
    path, c0, _points = quad_file
    out = tmp_path / "split.vtu"
    r = run("apply", str(path), "@library", "split_edge", "--everywhere", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == [
        f"matches: {c0['edges']}",
        f"created: {c0['darts']}",  # one new dart beside each dart of an edge
        "deleted: 0",
        f"wrote: {out}",
    ]
    mesh = meshio.read(out)
    assert len(mesh.points) == c0["vertices"] + c0["edges"]
    assert sum(len(b.data) for b in mesh.cells) == c0["faces"]


def test_apply_at_darts_and_back_through_tmg(
    quad_file: tuple, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """unsew_edge at one dart (--at D), then sew_edge at two (--at D,P) gives the map back."""
    path, c0, _points = quad_file
    g, _ = topomech.read_gmap(path)
    d = next(d for d in range(g.n_darts) if g.alpha(2, d) != d)
    p = g.alpha(2, d)
    cut = tmp_path / "cut.tmg"
    assert (
        cli.main(["apply", str(path), "@library", "unsew_edge", "--at", str(d), "--out", str(cut)])
        == 0
    )
    assert capsys.readouterr().out.startswith("matches: 1\n")
    assert topomech.GMap.load(cut).alpha(2, d) == d
    back = tmp_path / "back.tmg"
    assert (
        cli.main(
            ["apply", str(cut), "@library", "sew_edge", "--at", f"{d},{p}", "--out", str(back)]
        )
        == 0
    )
    h = topomech.GMap.load(back)
    assert h.is_valid()
    assert h.alpha(2, d) == p
    assert dict(h.cell_counts()) == c0


def test_apply_with_a_parameter(
    quad_file: tuple, rule_files: dict[str, Path], tmp_path: Path
) -> None:
    path, c0, points = quad_file
    out = tmp_path / "scaled.vtu"
    r = run(
        "apply",
        str(path),
        str(rule_files["scale"]),
        "scale",
        "--everywhere",
        "--param",
        "f=2.5",
        "--out",
        str(out),
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[:3] == [f"matches: {c0['vertices']}", "created: 0", "deleted: 0"]
    got = meshio.read(out).points
    np.testing.assert_allclose(sorted_rows(got), sorted_rows(2.5 * points), atol=1e-12)


def test_apply_with_a_vector_parameter(
    quad_file: tuple,
    rule_files: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    path, _c0, points = quad_file
    out = tmp_path / "moved.tmg"
    args = ["apply", str(path), str(rule_files["scale"]), "move", "--everywhere"]
    assert cli.main([*args, "--param", "d=0,-9.81,1", "--out", str(out)]) == 0
    got = topomech.GMap.load(out).positions()
    np.testing.assert_allclose(
        sorted_rows(got), sorted_rows(points + np.array([0, -9.81, 1])), atol=1e-12
    )


def test_apply_exit_1_when_the_rule_does_not_match(
    quad_file: tuple, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = quad_file[0]
    g, _ = topomech.read_gmap(path)
    d = next(d for d in range(g.n_darts) if g.alpha(2, d) == d)
    out = tmp_path / "out.tmg"
    assert (
        cli.main(["apply", str(path), "@library", "unsew_edge", "--at", str(d), "--out", str(out)])
        == 1
    )
    captured = capsys.readouterr()
    assert captured.out == ""
    assert (
        f"rule 'unsew_edge' does not match at d{d}: arc a -2- b: dart d{d} is 2-free"
        in captured.err
    )
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["@library", "nope", "--everywhere"],
            "no rule named 'nope' in @library; its rules: split_edge",
        ),
        (
            ["@library", "sew_edge", "--everywhere"],
            "rule 'sew_edge' has 2 hooks: give --at with one dart per hook",
        ),
        (["@library", "sew_edge", "--at", "0"], "rule 'sew_edge' has 2 hooks, --at gives 1 dart"),
        (["@library", "unsew_edge", "--at", "9999"], "dart 9999 is out of range"),
        (
            ["@library", "split_edge", "--everywhere", "--param", "f=1"],
            "rule 'split_edge' has no parameter 'f' (it takes no parameters)",
        ),
        (["SCALE", "scale", "--everywhere"], "rule 'scale' needs --param for f (f64)"),
        (
            ["SCALE", "scale", "--everywhere", "--param", "f=1", "--param", "f=2"],
            "parameter 'f' is given more than once",
        ),
        (
            ["SCALE", "move", "--everywhere", "--param", "d=1,2"],
            "parameter 'd' of rule 'move' is vec3: expected 3 numbers, got shape (2,)",
        ),
        (
            ["SCALE", "scale", "--everywhere", "--param", "f=true"],
            "parameter 'f' of rule 'scale' is f64: expected a number, got bool",
        ),
        (
            ["VOLUME", "split_edge", "--everywhere"],
            "the rules are for dimension 3, the map has dimension 2",
        ),
        (["BROKEN", "lift", "--everywhere"], "the rule file is refused (2 errors)"),
        (["MISSING", "scale", "--everywhere"], "cannot read the rule file"),
        (
            ["@library", "split_edge", "--everywhere", "--out", "OUT.xyz"],
            "unknown output extension .xyz",
        ),
    ],
)
def test_apply_exit_2_on_bad_arguments_or_files(
    args: list[str],
    message: str,
    quad_file: tuple,
    rule_files: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    names = {
        "SCALE": str(rule_files["scale"]),
        "VOLUME": str(rule_files["volume"]),
        "BROKEN": str(rule_files["broken"]),
        "MISSING": str(tmp_path / "missing.tmr"),
        "OUT.xyz": str(tmp_path / "out.xyz"),
    }
    args = [names.get(a, a) for a in args]
    if "--out" not in args:
        args += ["--out", str(tmp_path / "out.vtu")]
    assert cli.main(["apply", str(quad_file[0]), *args]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert message in captured.err
    assert "Traceback" not in captured.err
    assert not (tmp_path / "out.vtu").exists()
    if names["BROKEN"] in args:
        assert f"{names['BROKEN']}:6:37: error[type]:" in captured.err


def test_apply_exit_2_when_the_input_cannot_be_read(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.vtu"
    assert (
        cli.main(
            [
                "apply",
                str(tmp_path / "none.vtu"),
                "@library",
                "split_edge",
                "--everywhere",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "none.vtu: No such file or directory" in capsys.readouterr().err
    assert not out.exists()


def test_apply_exit_2_when_the_format_cannot_hold_the_cells(
    quad_file: tuple, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Gmsh has no polygons: the split quads (octagons) cannot be written as .msh."""
    out = tmp_path / "split.msh"
    assert (
        cli.main(
            [
                "apply",
                str(quad_file[0]),
                "@library",
                "split_edge",
                "--everywhere",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "cannot write the map as gmsh (cells: polygon)" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("suffix", [".stl", ".off", ".mesh"])
def test_apply_exit_2_when_the_format_would_drop_cells(
    quad_file: tuple, tmp_path: Path, capsys: pytest.CaptureFixture[str], suffix: str
) -> None:
    """STL keeps triangles only, OFF and Medit skip polygons, meshio only warning: a file
    missing cells is refused (read back and counted) and removed, not written with exit 0.
    A map of triangles only is written to STL whole."""
    out = tmp_path / f"split{suffix}"
    code = cli.main(
        ["apply", str(quad_file[0]), "@library", "split_edge", "--at", "0", "--out", str(out)]
    )
    assert code == 2
    assert "cannot hold all of the map's cells" in capsys.readouterr().err
    assert not out.exists()
    points, kinds, offsets, connectivity = _core.grid(3, 2, 1.0, 1.0, "triangle")
    g = topomech.GMap.from_flat(points, kinds, offsets, connectivity)
    whole = tmp_path / "triangles.stl"
    topomech.io.write_gmap(g, whole)
    with warnings.catch_warnings():  # meshio's STL reader tries the binary layout first
        warnings.simplefilter("ignore", RuntimeWarning)
        assert sum(len(b.data) for b in meshio.read(whole).cells) == 12


@pytest.mark.parametrize(
    "args",
    [
        ["@library", "split_edge", "--out", "o.vtu"],  # neither --everywhere nor --at
        ["@library", "split_edge", "--everywhere", "--at", "1", "--out", "o.vtu"],
        ["@library", "split_edge", "--at", "1,x", "--out", "o.vtu"],
        ["@library", "split_edge", "--at", "-1", "--out", "o.vtu"],
        ["@library", "split_edge", "--everywhere", "--param", "f", "--out", "o.vtu"],
        ["@library", "split_edge", "--everywhere", "--param", "f=abc", "--out", "o.vtu"],
        ["@library", "split_edge", "--everywhere"],  # no --out
    ],
)
def test_apply_usage_errors_exit_2(args: list[str], quad_file: tuple) -> None:
    with pytest.raises(SystemExit) as e:
        cli.main(["apply", str(quad_file[0]), *args])
    assert e.value.code == 2


def test_param_values() -> None:
    assert cli._param("f=2") == ("f", 2)
    assert cli._param(" f = 2.5 ") == ("f", 2.5)
    assert cli._param("on=true") == ("on", True)
    assert cli._param("on=false") == ("on", False)
    assert cli._param("gravity=0,-9.81,0") == ("gravity", [0, -9.81, 0])
    assert cli._param("m=1,0;0,1") == ("m", [[1, 0], [0, 1]])
    assert cli._dart_list("3,17") == [3, 17]
