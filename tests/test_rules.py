"""Rules from Python: loading and its diagnostics, the shipped library applied to every
generated mesh (counts checked against formulas computed from the cell lists alone), hooks
and parameters checked at the boundary, and refusals that leave the map unchanged."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import topomech
from topomech import _core
from topomech.io import write_gmap
from topomech.rules import RuleSet

from conftest import VOLUME_FACES, flat_to_cells, independent_counts

LIBRARY_RULES = {
    2: [
        "split_edge",
        "triangulate_face",
        "quad_subdivide",
        "unsew_edge",
        "sew_edge",
        "remove_face",
    ],
    3: [
        "split_edge",
        "triangulate_face",
        "quad_subdivide",
        "unsew_face",
        "sew_face",
        "remove_volume",
    ],
}
UNSEW = {2: "unsew_edge", 3: "unsew_face"}
SEW = {2: "sew_edge", 3: "sew_face"}
REMOVE = {2: "remove_face", 3: "remove_volume"}

#: Every generator element, small enough to keep the suite fast.
MESHES = [
    *[(2, e) for e in ("triangle", "quad", "mixed")],
    *[(3, e) for e in ("tetra", "hexahedron", "wedge", "pyramid", "mixed")],
]

DIAGNOSTIC = re.compile(
    r"^(?P<file>[^:]+):(?P<line>\d+):(?P<col>\d+): (?P<sev>error|warning)\[(?P<cond>[a-z-]+)\]: .+$"
)

PARAM_RULES = """dimension 2
embedding position : vec3 on <1,2> policy mean

rule scale(f: f64) {
  left { v : <1,2> hook }
  compute { v.position = v.position * f }
}

rule move(d: vec3) {
  left { v : <1,2> hook }
  compute { v.position = v.position + d }
}

rule times(n: i64) {
  left { v : <1,2> hook }
  compute { v.position = v.position * n }
}

rule transform(m: mat3) {
  left { v : <1,2> hook }
  compute { v.position = m * v.position }
}

rule flip(on: bool) {
  left { v : <1,2> hook }
  where on
  compute { v.position = -v.position }
}
"""


def flat_mesh(dim: int, element: str) -> tuple[Any, list[str], Any, Any]:
    if dim == 2:
        return _core.grid(3, 2, 3.0, 2.0, element)
    return _core.box(2, 2, 1, 2.0, 2.0, 1.0, element)


def sum_face_degrees(cells: list[tuple[str, list[list[int]]]]) -> int:
    """Sides of every face, summed over the unique faces, from the cell lists alone."""
    faces: set[frozenset[int]] = set()
    total = 0
    for t, block in cells:
        for c in block:
            if t not in VOLUME_FACES:
                total += len(c)
                continue
            for local in VOLUME_FACES[t]:
                key = frozenset(c[i] for i in local)
                if key not in faces:
                    faces.add(key)
                    total += len(local)
    return total


@pytest.fixture(params=MESHES, ids=[f"{d}d-{e}" for d, e in MESHES])
def mesh(request: pytest.FixtureRequest) -> tuple[int, topomech.GMap, dict[str, int], int, int]:
    """(dimension, map, independent counts, sum of face degrees, number of cells)."""
    dim, element = request.param
    kinds, offsets, conn = flat_mesh(dim, element)[1:]
    cells = flat_to_cells(kinds, offsets, conn)
    g = topomech.GMap.from_flat(*flat_mesh(dim, element))
    return dim, g, independent_counts(cells), sum_face_degrees(cells), len(kinds)


def counts(g: topomech.GMap) -> dict[str, int]:
    assert g.is_valid(), g.violations()[:5]
    return dict(g.cell_counts())


# ---------------------------------------------------------------------------------- loading


@pytest.mark.parametrize("dim", [2, 3])
def test_library_loads_without_warnings(dim: int) -> None:
    rules = RuleSet.library(dim)
    assert rules.dimension == dim
    assert rules.rule_names() == LIBRARY_RULES[dim]
    assert rules.warnings == []
    assert repr(rules).startswith(f"topomech.RuleSet(dimension={dim}")


def test_no_shipped_rule_file_divides_two_integers() -> None:
    """Every shipped model, glue and topology file loads for each dimension it serves (after
    the prelude and common rules, as a simulation loads it) without an integer-division
    warning (a quotient of two integers): each would be printed on every load."""
    models = Path(__file__).parents[1] / "crates" / "physics" / "models"
    if not models.is_dir():
        pytest.skip("the shipped rule files are in the source tree")
    prelude = ("prelude.tmr", (models / "prelude.tmr").read_text(encoding="utf-8"))
    loaded = set()
    for f in sorted(models.glob("*.tmr")):
        text = f.read_text(encoding="utf-8")
        for dim in RuleSet.file_dimensions(text) or [2, 3]:
            common = f"common{dim}d.tmr"
            sources = [prelude, (common, (models / common).read_text(encoding="utf-8"))]
            if f.name.startswith("topology") and f.name != "topology.tmr":
                topology = (models / "topology.tmr").read_text(encoding="utf-8")
                sources.append(("topology.tmr", topology))
            if f.name not in {name for name, _ in sources}:
                sources.append((f.name, text))
            warned = RuleSet.from_sources(sources, dim).warnings
            assert not [w for w in warned if "integer-division" in w], warned
            loaded.add(f.name)
    assert len(loaded) >= 14, loaded


@pytest.mark.parametrize("dim", [-1, 0, 1, 4, 2**70])
def test_library_of_an_unsupported_dimension(dim: int) -> None:
    with pytest.raises((ValueError, OverflowError)):
        RuleSet.library(dim)


def test_rule_info() -> None:
    lib = RuleSet.library(2)
    assert lib.rule_info("split_edge") == {
        "name": "split_edge",
        "file": "modeling2d.tmr",
        "params": [],
        "hooks": 1,
        "changes_topology": True,
    }
    assert lib.rule_info("sew_edge")["hooks"] == 2
    rules = RuleSet.from_source(PARAM_RULES, "p.tmr")
    info = rules.rule_info("transform")
    assert info["params"] == [("m", "mat3")]
    assert info["file"] == "p.tmr"
    assert not info["changes_topology"]
    with pytest.raises(topomech.ApplyError, match="no rule named 'nope'"):
        rules.rule_info("nope")


def test_the_hierarchy() -> None:
    for cls in (topomech.RuleError, topomech.ApplyError):
        assert issubclass(cls, topomech.TopomechError)
        assert cls.__module__ == "topomech._core"
    assert topomech.RuleSet is RuleSet


def test_rule_error_carries_every_diagnostic() -> None:
    src = """dimension 2
embedding position : vec3 on <1,2> policy mean

rule lift {
  left { v : <1,2> hook }
  compute { v.position = v.position + true }
}

rule lift {
  left { v : <1,2> hook }
}
"""
    with pytest.raises(topomech.RuleError) as info:
        RuleSet.from_source(src, "broken.tmr")
    e = info.value
    assert e.diagnostics == [
        "broken.tmr:6:37: error[type]: rule 'lift': cannot add vec3 and bool",
        "broken.tmr:9:1: error[name]: rule 'lift' is already defined at broken.tmr:4:1",
    ]
    assert str(e) == "\n".join(e.diagnostics)
    assert e.warnings == []


def test_syntax_error_position() -> None:
    with pytest.raises(topomech.RuleError) as info:
        RuleSet.from_source("dimension 2\nrule r { left { a <0> hook } }\n", "s.tmr")
    (line,) = info.value.diagnostics
    m = DIAGNOSTIC.match(line)
    assert m is not None, line
    assert (m["file"], m["line"], m["col"], m["sev"], m["cond"]) == (
        "s.tmr",
        "2",
        "19",
        "error",
        "syntax",
    )


def test_warnings_do_not_refuse() -> None:
    src = "dimension 2\nembedding position : vec3 on <1,2>\nrule idle(f: f64) {\n  left { v : <1,2> hook }\n}\n"
    rules = RuleSet.from_source(src, "w.tmr")
    assert rules.warnings == [
        "w.tmr:3:11: warning[unused]: rule 'idle': parameter 'f' is never used"
    ]


def test_load_files_together(tmp_path: Path) -> None:
    a = tmp_path / "a.tmr"
    b = tmp_path / "b.tmr"
    a.write_text(PARAM_RULES)
    b.write_text(
        "dimension 2\nembedding position : vec3 on <1,2> policy mean\n"
        "rule twice {\n  left { v : <1,2> hook }\n  compute { v.position = v.position * 2.0 }\n}\n"
    )
    rules = RuleSet.load([a, str(b)])
    assert rules.rule_names()[-1] == "twice"
    assert RuleSet.load(b).rule_names() == ["twice"]
    assert rules.rule_info("twice")["file"] == str(b)


def test_load_a_missing_file(tmp_path: Path) -> None:
    missing = tmp_path / "missing.tmr"
    with pytest.raises(FileNotFoundError, match=r"No such file or directory: .*missing\.tmr"):
        RuleSet.load([missing])
    with pytest.raises(
        topomech.RuleError, match=re.escape(f"{tmp_path}:1:1: error[file]: cannot read the file")
    ):
        RuleSet.load([tmp_path])  # exists, cannot be read
    with pytest.raises(ValueError, match="at least one"):
        RuleSet.load([])


def test_files_of_different_dimensions_are_refused() -> None:
    with pytest.raises(topomech.RuleError, match=r"b\.tmr:1:\d+: error\[dimension\]"):
        RuleSet.from_sources([("a.tmr", "dimension 2\n"), ("b.tmr", "dimension 3\n")])


# ---------------------------------------------------------------------------------- library


def test_split_every_edge(mesh: tuple) -> None:
    dim, g, c0, _deg, _cells = mesh
    rules = RuleSet.library(dim)
    assert rules.count_matches(g, "split_edge") == c0["edges"]
    report = rules.apply(g, "split_edge")
    assert report["matches"] == c0["edges"]
    assert report["deleted"] == 0
    c = counts(g)
    assert c["darts"] == c0["darts"] + report["created"]
    assert (c["vertices"], c["edges"], c["faces"], c["volumes"], c["components"]) == (
        c0["vertices"] + c0["edges"],
        2 * c0["edges"],
        c0["faces"],
        c0["volumes"],
        c0["components"],
    )


def test_triangulate_every_face(mesh: tuple) -> None:
    dim, g, c0, deg, _cells = mesh
    report = RuleSet.library(dim).apply(g, "triangulate_face")
    assert report["matches"] == c0["faces"]
    c = counts(g)
    assert (c["vertices"], c["edges"], c["faces"], c["volumes"]) == (
        c0["vertices"] + c0["faces"],
        c0["edges"] + deg,
        deg,
        c0["volumes"],
    )


def test_quad_subdivide(mesh: tuple) -> None:
    dim, g, c0, deg, _cells = mesh
    report = RuleSet.library(dim).apply(g, "quad_subdivide")
    assert report["matches"] == c0["components"] == 1
    c = counts(g)
    assert (c["vertices"], c["edges"], c["faces"], c["volumes"]) == (
        c0["vertices"] + c0["edges"] + c0["faces"],
        2 * c0["edges"] + deg,
        deg,
        c0["volumes"],
    )


def _signed_areas(points: np.ndarray, cells: Any) -> list[float]:
    """Twice the signed area (in the plane z = 0) of every polygon (a list of point indices)."""
    areas = []
    for cell in cells:
        p = np.asarray(points)[np.asarray(cell)]
        q = np.roll(p, -1, axis=0)
        areas.append(float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1])))
    return areas


@pytest.mark.parametrize("element", ["quad", "triangle", "mixed"])
@pytest.mark.parametrize("turned", [False, True], ids=["ccw", "cw"])
@pytest.mark.parametrize("rule", ["quad_subdivide", "split_edge", "triangulate_face"])
def test_written_faces_keep_the_input_orientation_after_a_2d_rule(
    tmp_path: Path, element: str, turned: bool, rule: str
) -> None:
    """Regression: after ``quad_subdivide`` the faces written to a file had mixed
    orientations (each face started at its smallest dart, of either orientation class), so
    half the normals were flipped. Every written face has the sign of the input's faces."""
    import meshio

    points, kinds, offsets, conn = _core.grid(3, 2, 3.0, 2.0, element)
    cells = [conn[a:b] for a, b in zip(offsets[:-1], offsets[1:])]
    if turned:  # every face clockwise: still one consistent orientation, kept as it is
        cells = [c[::-1] for c in cells]
        conn = np.concatenate(cells).astype(conn.dtype)
    sign = -1.0 if turned else 1.0
    assert all(a * sign > 0 for a in _signed_areas(points, cells))
    g = topomech.GMap.from_flat(points, kinds, offsets, conn)
    assert g.report.reoriented == []
    RuleSet.library(2).apply(g, rule)
    path = tmp_path / "out.vtu"
    write_gmap(g, path)
    back = meshio.read(path)
    areas = _signed_areas(back.points, [c for block in back.cells for c in block.data])
    assert len(areas) == g.cell_counts()["faces"] >= len(kinds)
    assert g.cell_counts()["vertices"] > len(points)
    flipped = [i for i, a in enumerate(areas) if a * sign <= 0]
    assert flipped == [], f"{rule}: faces {flipped} of {len(areas)} are turned"


def test_unsew_everything_then_remove_every_cell(mesh: tuple) -> None:
    dim, g, c0, _deg, n_cells = mesh
    rules = RuleSet.library(dim)
    interior = (c0["edges"] if dim == 2 else c0["faces"]) - c0["boundary"]
    assert rules.apply(g, UNSEW[dim])["matches"] == interior
    c = counts(g)
    assert c["components"] == n_cells
    corners = sum(len(cell) for _, block in flat_to_cells(*g.to_flat()[1:]) for cell in block)
    assert c["vertices"] == corners, "every cell has its own vertices"
    report = rules.apply(g.core, REMOVE[dim])  # the kernel map works too
    assert report == {"matches": n_cells, "created": 0, "deleted": c0["darts"]}
    assert g.n_darts == 0
    assert g.is_valid()


@pytest.mark.parametrize("dim", [2, 3])
def test_sew_undoes_unsew_at_explicit_darts(dim: int) -> None:
    g = topomech.GMap.from_flat(*flat_mesh(dim, "hexahedron" if dim == 3 else "quad"))
    rules = RuleSet.library(dim)
    before = g.to_bytes()
    d = next(d for d in range(g.n_darts) if g.alpha(dim, d) != d)
    p = g.alpha(dim, d)
    assert rules.apply(g, UNSEW[dim], at=np.int64(d)) == {"matches": 1, "created": 0, "deleted": 0}
    assert g.alpha(dim, d) == d
    with pytest.raises(
        topomech.ApplyError,
        match=rf"does not match at d{d}: arc a -{dim}- b: dart d{d} is {dim}-free",
    ):
        rules.apply(g, UNSEW[dim], at=d)
    rules.apply(g, SEW[dim], at=np.array([d, p]))
    assert g.is_valid()
    assert g.alpha(dim, d) == p
    assert counts(g) == dict(topomech.GMap.from_bytes(before).cell_counts())


# ---------------------------------------------------------------------------------- refusals


@pytest.fixture
def quads() -> topomech.GMap:
    return topomech.GMap.from_flat(*_core.grid(2, 1))


def boundary_dart(g: topomech.GMap) -> int:
    return next(d for d in range(g.n_darts) if g.alpha(2, d) == d)


def test_no_match_names_why_and_changes_nothing(quads: topomech.GMap) -> None:
    rules = RuleSet.library(2)
    before = quads.to_bytes()
    d = boundary_dart(quads)
    with pytest.raises(
        topomech.ApplyError, match=rf"rule 'unsew_edge' does not match at d{d}: .*2-free"
    ):
        rules.apply(quads, "unsew_edge", at=[d])
    assert quads.to_bytes() == before


def test_hooks_are_checked(quads: topomech.GMap) -> None:
    rules = RuleSet.library(2)
    n = quads.n_darts
    for bad in (-1, -(2**31), -(2**63), n, 2**32, 2**40):
        with pytest.raises(IndexError, match=rf"dart {bad} is out of range"):
            rules.apply(quads, "unsew_edge", at=[bad])
    with pytest.raises(IndexError, match="out of range"):
        rules.apply(quads, "unsew_edge", at=[2**100])
    with pytest.raises(TypeError, match="at must be a dart or a list of darts"):
        rules.apply(quads, "unsew_edge", at="0")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        rules.apply(quads, "unsew_edge", at=[0.5])  # type: ignore[list-item]
    with pytest.raises(
        topomech.ApplyError, match=r"rule 'sew_edge': it has 2 hook\(s\), 1 dart\(s\) given"
    ):
        rules.apply(quads, "sew_edge", at=[0])
    with pytest.raises(topomech.ApplyError, match="it has 2 hooks: apply it at explicit darts"):
        rules.apply(quads, "sew_edge")
    with pytest.raises(topomech.ApplyError, match="no rule named 'nope'"):
        rules.apply(quads, "nope")
    assert quads.is_valid()


def test_the_map_must_fit_the_rules(quads: topomech.GMap) -> None:
    with pytest.raises(
        topomech.ApplyError, match="the rules are for dimension 3, the map has dimension 2"
    ):
        RuleSet.library(3).apply(quads, "split_edge")
    with pytest.raises(TypeError, match=r"gmap must be a topomech\.GMap"):
        RuleSet.library(2).apply(object(), "split_edge")  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------- parameters


def sorted_rows(a: Any) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    return a[np.lexsort(a.T[::-1])]


@pytest.mark.parametrize(
    ("rule", "params", "expected"),
    [
        ("scale", {"f": 2}, lambda p: 2 * p),
        ("scale", {"f": np.float32(0.5)}, lambda p: 0.5 * p),
        ("move", {"d": [1, 0, -2]}, lambda p: p + np.array([1, 0, -2])),
        ("move", {"d": (0.5, 0.5, 0.5)}, lambda p: p + 0.5),
        ("move", {"d": np.array([1, 2, 3])}, lambda p: p + np.array([1, 2, 3])),
        ("times", {"n": 3}, lambda p: 3 * p),
        ("times", {"n": np.int64(-1)}, lambda p: -p),
        (
            "transform",
            {"m": [[0, -1, 0], [1, 0, 0], [0, 0, 1]]},
            lambda p: p @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]).T,
        ),
        ("transform", {"m": 2 * np.eye(3)}, lambda p: 2 * p),
        ("flip", {"on": True}, lambda p: -p),
        ("flip", {"on": np.bool_(False)}, lambda p: p),
    ],
)
def test_parameters_are_converted_to_the_declared_type(
    quads: topomech.GMap, rule: str, params: dict[str, Any], expected: Any
) -> None:
    rules = RuleSet.from_source(PARAM_RULES)
    p0 = quads.positions()
    rules.apply(quads, rule, params=params)
    np.testing.assert_allclose(
        sorted_rows(quads.positions()), sorted_rows(expected(p0)), atol=1e-12
    )


@pytest.mark.parametrize(
    ("rule", "params", "error", "message"),
    [
        ("scale", {}, topomech.ApplyError, r"rule 'scale': missing parameter 'f' \(f64\)"),
        (
            "scale",
            {"f": 1, "g": 2},
            topomech.ApplyError,
            r"unknown parameter 'g' \(it takes f: f64\)",
        ),
        (
            "scale",
            {"f": True},
            TypeError,
            r"parameter 'f' of rule 'scale' is f64: expected a number, got bool",
        ),
        ("scale", {"f": "2"}, TypeError, "expected a number, got str"),
        ("scale", {"f": [2.0]}, TypeError, "expected a number, got list"),
        ("scale", {"f": float("nan")}, ValueError, "not finite"),
        ("scale", {1: 2}, TypeError, "parameter names must be str"),
        ("scale", [("f", 1)], TypeError, "params must be a dict"),
        ("move", {"d": [1, 2]}, ValueError, r"is vec3: expected 3 numbers, got shape \(2,\)"),
        ("move", {"d": [1, 2, 3, 4]}, ValueError, r"got shape \(4,\)"),
        ("move", {"d": [1, 2, "x"]}, TypeError, "found str at index 2"),
        ("move", {"d": [1, True, 0]}, TypeError, "found bool at index 1"),
        ("move", {"d": [[1, 2, 3]]}, ValueError, r"got shape \(1, 3\)"),
        ("move", {"d": np.array(["a", "b", "c"])}, TypeError, "expected an array of numbers"),
        ("move", {"d": 3.0}, TypeError, "expected a list of numbers or a numpy array, got float"),
        ("move", {"d": [0, float("inf"), 0]}, ValueError, "not finite"),
        ("times", {"n": 2.0}, TypeError, "is i64: expected an int, got float"),
        ("times", {"n": 2**70}, ValueError, "does not fit in 64 bits"),
        ("times", {"n": False}, TypeError, "expected an int, got bool"),
        (
            "transform",
            {"m": np.eye(2)},
            ValueError,
            r"is mat3: expected a 3x3 matrix \(shape \(3, 3\)\), got shape \(2, 2\)",
        ),
        (
            "transform",
            {"m": [[1, 0, 0], [0, 1], [0, 0, 1]]},
            ValueError,
            "rows have different lengths",
        ),
        ("transform", {"m": [[1, 0, 0], 0, [0, 0, 1]]}, TypeError, "found list at index 0"),
        ("transform", {"m": np.zeros((3, 3, 1))}, ValueError, r"got shape \(3, 3, 1\)"),
        ("flip", {"on": 1}, TypeError, "is bool: expected a bool, got int"),
    ],
)
def test_bad_parameters_raise(
    quads: topomech.GMap, rule: str, params: Any, error: type[Exception], message: str
) -> None:
    rules = RuleSet.from_source(PARAM_RULES)
    before = quads.to_bytes()
    with pytest.raises(error, match=message):
        rules.apply(quads, rule, params=params)
    with pytest.raises(error, match=message):
        rules.count_matches(quads, rule, params=params)
    assert quads.to_bytes() == before


# ---------------------------------------------------------------------------------- properties


@pytest.mark.parametrize("dim", [2, 3])
def test_rules_at_any_darts_apply_or_refuse_and_never_panic(dim: int) -> None:
    """Every rule of the library at arbitrary darts (out of range and negative included):
    either it applies and the map stays valid, or it raises ApplyError or IndexError and the
    map is byte for byte unchanged; never InternalError."""
    rules = RuleSet.library(dim)
    base = topomech.GMap.from_flat(*flat_mesh(dim, "mixed"))
    # half the interior cut, so that the sew rules find free pairs too
    cut: list[int] = []
    sewn = 0
    for d in range(base.n_darts):
        if base.alpha(dim, d) > d:
            sewn += 1
            if sewn % 2:
                rules.apply(base, UNSEW[dim], at=d)
                cut.append(d)
    data = base.to_bytes()
    n = base.n_darts
    darts = st.integers(-3, n + 3) | st.sampled_from(cut)
    outcomes: set[str] = set()

    @settings(max_examples=150, deadline=None, derandomize=True)
    @given(name=st.sampled_from(LIBRARY_RULES[dim]), a=darts, b=darts)
    def check(name: str, a: int, b: int) -> None:
        g = topomech.GMap.from_bytes(data)
        at = [a, b] if rules.rule_info(name)["hooks"] == 2 else [a]
        try:
            rules.apply(g, name, at=at)
        except (topomech.ApplyError, IndexError):
            assert g.to_bytes() == data
            outcomes.add("refused")
        else:
            assert g.is_valid(), g.violations()[:5]
            outcomes.add("applied")

    check()
    assert outcomes == {"applied", "refused"}


@pytest.mark.parametrize("bad", [True, False, 2.0, "3"])
def test_a_dimension_that_is_not_an_integer_is_refused(bad: object) -> None:
    """`dimension=True` was read as 1 ("got 1"); a bool, a float or a string is a TypeError
    naming what was given (numpy integers are integers)."""
    import numpy as np

    with pytest.raises(TypeError, match=r"dimension must be 2 or 3 \(or None\), got"):
        RuleSet.from_source("dimension 2 3\n", dimension=bad)
    assert RuleSet.from_source("dimension 2 3\n", dimension=np.int64(3)).dimension == 3
    # the library and the shipped models too (True was read as 1, 2.0 as 2)
    with pytest.raises(TypeError, match="dimension must be 2 or 3"):
        RuleSet.library(bad)
    with pytest.raises(TypeError, match="dimension must be 2 or 3"):
        topomech.Model.shipped("corotational", bad)
