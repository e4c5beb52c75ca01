"""The meshes a run writes (final.vtu, frames) in the user's numbering and orientation.

A user's mesh file, with its points shuffled and some points used by no cell, is run through
`run_scene`; `final.vtu` and the frames are read back and compared with the file row by row:
`points - displacement` is the input point `point_id` names (also after a cut, whose new rows
carry the point they were split from), and every cell lists, through `point_id`, exactly the
input cell `cell_id` names, in the input's vertex order. A run that starts inverted and
recovers writes cells that topomech reads back without turning any over.

The simulation side of the numbering (`Simulation.point_ids()`, `Simulation.elements()`, rows
in input order) is another part of the work; until it is there, these tests give the
simulation those two methods by matching rest positions with the file's points (exact: the
map copies them), which is what the contract promises, and check everything the writer does
with them. With the real methods, they also check that rows follow the input order.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import meshio
import numpy as np
import numpy.typing as npt
import pytest

from topomech import GMap, _core, cli
from topomech._output import reversed_cells, signed_volumes
from topomech.recording import Recorder, read_view
from topomech.run import run_scene
from topomech.scene import Scene, SceneError, load_scene, parse_scene
from topomech.simulation import Simulation

#: Whether the simulation numbers rows itself (the vertex-numbering contract is merged).
REAL_CONTRACT = hasattr(Simulation, "point_ids") and hasattr(Simulation, "elements")


class _Emulated(Simulation):
    """`point_ids()` and `elements()` of the contract, found by matching rest positions with
    the input points (every input point is distinct in these meshes)."""

    __slots__ = ("_cells", "_points")

    _points: npt.NDArray[np.float64]
    _cells: list[npt.NDArray[np.int64]]

    def point_ids(self) -> npt.NDArray[np.int64]:
        lookup = {p.tobytes(): i for i, p in enumerate(self._points)}
        return np.array([lookup.get(r.tobytes(), -1) for r in self.rest_positions()])

    def elements(self) -> tuple[npt.NDArray[np.int64], list[npt.NDArray[np.int64]]]:
        pid = self.point_ids()
        key = {tuple(sorted(c.tolist())): k for k, c in enumerate(self._cells)}
        _, kinds, off, conn = self.core.gmap().to_flat()
        rows = [np.asarray(conn[off[c] : off[c + 1]], dtype=np.int64) for c in range(len(kinds))]
        ids = np.array([key.get(tuple(sorted(pid[r].tolist())), -1) for r in rows])
        return ids, rows


def _contract(
    monkeypatch: pytest.MonkeyPatch,
    points: npt.NDArray[np.float64],
    cells: list[npt.NDArray[np.int64]],
    start: Any = None,
) -> None:
    """Scenes build simulations with the contract's methods (emulated when missing), and
    `start(sim)` applied before the run."""
    build = Scene.build

    def patched(self: Scene, gmap: GMap | None = None) -> Simulation:
        sim = build(self, gmap)
        if not REAL_CONTRACT:
            emulated = _Emulated.from_core(sim.core)
            assert isinstance(emulated, _Emulated)
            emulated._points = np.asarray(points, dtype=np.float64)
            emulated._cells = cells
            sim = emulated
        if start is not None:
            start(sim)
        return sim

    monkeypatch.setattr(Scene, "build", patched)


def _user_mesh(
    dimension: int, seed: int = 7
) -> tuple[npt.NDArray[np.float64], str, npt.NDArray[np.int64]]:
    """A generated mesh with its points shuffled and 3 unused points inserted among them:
    points (N, 3), the meshio cell type, cells (M, k) in input point indices."""
    if dimension == 3:
        pts, _, off, conn = _core.box(4, 1, 1, 1.0, 0.25, 0.25, "tetra")
        ctype = "tetra"
    else:
        pts, _, off, conn = _core.grid(4, 2, 1.0, 0.5, "triangle")
        ctype = "triangle"
    pts = np.asarray(pts, dtype=np.float64)
    k = int(off[1] - off[0])
    cells = np.asarray(conn, dtype=np.int64).reshape(-1, k)
    rng = np.random.default_rng(seed)
    n = len(pts) + 3
    new_index = rng.permutation(n)[: len(pts)]  # old point i -> new index; 3 left unused
    points = rng.uniform(5.0, 6.0, size=(n, 3))  # the unused points: somewhere else
    points[new_index] = pts
    if dimension == 2:
        points[:, 2] = 0.0
    return points, ctype, new_index[cells]


def _write_scene(
    tmp: Path,
    dimension: int,
    *,
    cut: bool = False,
    extra: str = "",
    steps: int = 20,
) -> tuple[Path, npt.NDArray[np.float64], list[npt.NDArray[np.int64]]]:
    points, ctype, cells = _user_mesh(dimension)
    mesh_path = tmp / "user.vtu"
    meshio.write(mesh_path, meshio.Mesh(points, [(ctype, cells)]))
    model = (
        '[[model]]\nkind = "corotational"\nyoung = 1e5\npoisson = 0.3\n'
        if dimension == 3
        else '[[model]]\nkind = "stretch_elementary"\nstiffness = 1e4\n'
    )
    event = (
        '[[event]]\ntime = 0.01\nkind = "cut"\nplane = { normal = [1.0, 0.0, 0.0], offset = 0.5 }\n'
        if cut
        else ""
    )
    text = f"""
name = "user"
[mesh]
file = "user.vtu"
{model}
[material]
density = 100.0
[[fix]]
where = "x < 1e-9"
[integrator]
kind = "symplectic_euler"
dt = 1e-3
steps = {steps}
[output]
every = 5
{extra}
{event}
"""
    scene = tmp / "user.toml"
    scene.write_text(text)
    return scene, points, [np.asarray(c) for c in cells]


def _cells_of(m: meshio.Mesh) -> tuple[list[npt.NDArray[np.int64]], npt.NDArray[np.int64]]:
    cells = [np.asarray(c, dtype=np.int64) for b in m.cells for c in b.data]
    ids = np.concatenate([np.asarray(a, dtype=np.int64) for a in m.cell_data["cell_id"]])
    return cells, ids


def _check_numbering(
    path: Path, points: npt.NDArray[np.float64], cells: list[npt.NDArray[np.int64]]
) -> npt.NDArray[np.int64]:
    """The checks every output mesh passes; returns its point ids."""
    m = meshio.read(path)
    pid = np.asarray(m.point_data["point_id"], dtype=np.int64)
    assert len(pid) == len(m.points)
    assert (pid >= 0).all()
    # rest positions, row by row, are the input points named by point_id: exact up to the
    # round-off of x - (x - X) (1e-15 of coordinates of order 1)
    rest = m.points - m.point_data["displacement"]
    np.testing.assert_allclose(rest, points[pid], rtol=0, atol=1e-12)
    out_cells, ids = _cells_of(m)
    assert len(out_cells) == len(cells)
    # every input cell once, in input order, each in its input vertex order
    assert ids.tolist() == list(range(len(cells)))
    for c, k in zip(out_cells, ids):
        assert pid[c].tolist() == cells[k].tolist()
    return pid


@pytest.mark.parametrize("dimension", [2, 3])
def test_final_vtu_is_in_the_input_numbering(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, dimension: int
) -> None:
    """final.vtu and every frame: points in row order with the input point index, cells as
    the input lists them; the unused points are left out."""
    scene, points, cells = _write_scene(tmp_path, dimension)
    _contract(monkeypatch, points, cells)
    summary = run_scene(scene, tmp_path / "out", preview=False)
    assert "error" not in summary
    out = tmp_path / "out"
    used = np.unique(np.concatenate(cells))
    for f in [out / "final.vtu", *sorted((out / "frames").glob("*.vtu"))]:
        pid = _check_numbering(f, points, cells)
        assert sorted(pid.tolist()) == used.tolist()  # each used point once, no unused one
        if REAL_CONTRACT:
            assert pid.tolist() == used.tolist()  # rows follow the input point order
    # the run moved: the check above is not about the rest state only
    m = meshio.read(out / "final.vtu")
    assert np.abs(m.point_data["displacement"]).max() > 1e-6


@pytest.mark.parametrize("dimension", [2, 3])
def test_a_cut_appends_rows_with_the_point_they_were_split_from(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, dimension: int
) -> None:
    """After a cut the frames have more points; the new ones carry the point_id of the point
    they were split from (their rest position is that point's), the existing rows keep
    theirs, and every cell still lists its input cell."""
    scene, points, cells = _write_scene(tmp_path, dimension, cut=True)
    _contract(monkeypatch, points, cells)
    summary = run_scene(scene, tmp_path / "out", preview=False)
    assert "error" not in summary
    assert summary["topology_changes"]
    assert summary["topology_changes"][0]["unsewn"] > 0
    out = tmp_path / "out"
    first = _check_numbering(out / "frames" / "frame_00000.vtu", points, cells)
    last = _check_numbering(out / "final.vtu", points, cells)
    assert len(last) > len(first)
    # the points split are those on the cut plane x = 0.5: each now has 2 rows, the others 1
    count = np.bincount(last, minlength=len(points))
    on_plane = np.abs(points[:, 0] - 0.5) < 1e-12
    used = np.bincount(np.concatenate(cells), minlength=len(points)) > 0
    assert (count[on_plane & used] == 2).all()
    assert (count[~on_plane & used] == 1).all()
    if REAL_CONTRACT:
        assert last[: len(first)].tolist() == first.tolist()  # existing rows keep their meaning
        added = last[len(first) :]
        np.testing.assert_allclose(points[added][:, 0], 0.5, rtol=0, atol=1e-12)


COROTATIONAL = 'kind = "corotational"\nyoung = 1e4\npoisson = 0.3'


def _scene_text(mesh: str, steps: int = 150, model: str = COROTATIONAL) -> str:
    return f"""
name = "inverted"
[mesh]
{mesh}
[[model]]
{model}
[material]
density = 100.0
damping = 20.0
[world]
gravity = [0.0, 0.0, 0.0]
[integrator]
kind = "implicit_euler"
dt = 0.01
steps = {steps}
[output]
every = 50
"""


def _mirror(sim: Simulation) -> None:
    """Every element inverted: the rest positions mirrored through z = 0."""
    x = sim.rest_positions().copy()
    x[:, 2] = -x[:, 2]
    sim.set_positions(x)


def _volumes(m: meshio.Mesh) -> npt.NDArray[np.float64]:
    return np.concatenate(
        [signed_volumes(b.type, np.asarray(b.data, dtype=np.int64), m.points) for b in m.cells]
    )


@pytest.mark.parametrize("source", ["file", "generator"])
def test_a_run_that_recovers_from_an_inverted_start_writes_cells_topomech_accepts(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    source: str,
) -> None:
    """Start with every tetrahedron inverted (mirrored); the co-rotational model turns them
    back. final.vtu's cells have the rest orientation: positive now, and read back without
    reorienting (GMap.from_meshio with reorient=False accepts it, turning nothing over),
    while the first frame writes the inverted state as it is (negative volumes) instead of
    silently turning its cells over."""
    if source == "file":
        pts, _, _, conn = _core.box(2, 1, 1, 1.0, 0.5, 0.5, "tetra")
        points = np.asarray(pts, dtype=np.float64)
        cells = np.asarray(conn, dtype=np.int64).reshape(-1, 4)
        meshio.write(tmp_path / "m.vtu", meshio.Mesh(points, [("tetra", cells)]))
        text = _scene_text('file = "m.vtu"')
        _contract(monkeypatch, points, list(cells), start=_mirror)
    else:
        text = _scene_text('generator = "box"\nelement = "tet"\nsize = [1.0, 0.5, 0.5]')
        build = Scene.build

        def patched(self: Scene, gmap: GMap | None = None) -> Simulation:
            sim = build(self, gmap)
            _mirror(sim)
            return sim

        monkeypatch.setattr(Scene, "build", patched)
    scene = tmp_path / "inverted.toml"
    scene.write_text(text)
    summary = run_scene(scene, tmp_path / "out", preview=False)
    assert "error" not in summary
    out = tmp_path / "out"
    first = meshio.read(out / "frames" / "frame_00000.vtu")
    assert (_volumes(first) < 0).all()  # written as it is: inverted
    final = meshio.read(out / "final.vtu")
    vols = _volumes(final)
    rest = final.points - final.point_data["displacement"]
    at_rest = np.concatenate(
        [signed_volumes(b.type, np.asarray(b.data, dtype=np.int64), rest) for b in final.cells]
    )
    # recovered: every volume positive and back to its rest value (viscous damping 20/s
    # for 1.5 s, implicit Euler; 1e-3 is far tighter than an inverted cell's -200 %)
    assert (vols > 0).all()
    np.testing.assert_allclose(vols, at_rest, rtol=1e-3)
    g = GMap.from_meshio(final, reorient=False)
    assert g.report.reoriented == []
    assert g.cell_counts()["volumes"] == len(vols)
    # and `topomech info` reads it (exit 0: a valid map), turning nothing over
    assert cli.main(["info", "--json", str(out / "final.vtu")]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info.get("reoriented", 0) in (0, [])


def test_generated_cells_are_oriented_at_rest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without input cells (a generator), every output cell is positively oriented at the
    rest positions, whatever the current ones: the mirrored start's frame 0 has them all
    negative (exactly the rest volumes, negated)."""
    build = Scene.build

    def patched(self: Scene, gmap: GMap | None = None) -> Simulation:
        sim = build(self, gmap)
        _mirror(sim)
        return sim

    monkeypatch.setattr(Scene, "build", patched)
    for element in ("tet", "hex", "wedge", "pyramid"):
        text = _scene_text(
            f'generator = "box"\nelement = "{element}"\nsize = [1.0, 0.5, 0.5]\ncells = [2, 1, 1]',
            steps=0,
            model='kind = "stretch_elementary"\nstiffness = 1e3',
        )
        sc = parse_scene(text)
        out = tmp_path / element
        run_scene(sc, out, preview=False)
        m = meshio.read(out / "final.vtu")
        rest = m.points - m.point_data["displacement"]
        at_rest = np.concatenate(
            [signed_volumes(b.type, np.asarray(b.data, dtype=np.int64), rest) for b in m.cells]
        )
        now = _volumes(m)
        assert (at_rest > 0).all(), element
        np.testing.assert_allclose(now, -at_rest, rtol=1e-12)


# ------------------------------------------------------------------------------ fields


def test_output_fields_are_written_as_point_data(tmp_path: Path) -> None:
    """mass, force and vertex embeddings as point data of final.vtu and the frames. Checked
    against physics: the masses sum to the total mass (density x volume = 100 x 0.25 x
    0.25 x 1, to round-off), and at a static equilibrium under gravity the models' force on
    every free vertex balances its weight (f + m g = 0, to the solver's tolerance, 1e-6 of
    the largest weight)."""
    scene = tmp_path / "fields.toml"
    scene.write_text(
        """
[mesh]
generator = "box"
element = "tet"
size = [1.0, 0.25, 0.25]
cells = [4, 1, 1]
[[model]]
kind = "corotational"
young = 1e5
poisson = 0.3
[material]
density = 100.0
[[fix]]
where = "x < 1e-9"
[world]
gravity = [0.0, -9.81, 0.0]
[integrator]
kind = "static"
steps = 2
[output]
every = 1
fields = ["mass", "force", "rest"]
"""
    )
    summary = run_scene(scene, tmp_path / "out", preview=False)
    assert "error" not in summary
    out = tmp_path / "out"
    files = [out / "final.vtu", *sorted((out / "frames").glob("*.vtu"))]
    assert len(files) == 4  # final, frames 0, 1, 2
    for f in files:
        m = meshio.read(f)
        for name in ("mass", "force", "rest"):
            assert name in m.point_data, (f.name, name)
        assert m.point_data["mass"].shape == (len(m.points),)
        assert m.point_data["force"].shape == (len(m.points), 3)
        np.testing.assert_allclose(m.point_data["mass"].sum(), 100.0 * 0.25 * 0.25, rtol=1e-12)
        # the rest embedding is the rest position: points - displacement, to round-off
        rest = m.points - m.point_data["displacement"]
        np.testing.assert_allclose(m.point_data["rest"], rest, rtol=0, atol=1e-12)
    m = meshio.read(out / "final.vtu")
    mass, force = m.point_data["mass"], m.point_data["force"]
    free = m.point_data["fixed"] == 0
    weight = mass[:, None] * np.array([0.0, -9.81, 0.0])
    residual = force[free] + weight[free]
    assert np.abs(residual).max() <= 1e-6 * np.abs(weight).max()
    assert np.abs(force[free]).max() > 0.1 * np.abs(weight).max()  # not trivially zero


def test_unknown_output_fields_are_refused_naming_the_key_and_the_names(tmp_path: Path) -> None:
    """An unknown name, or an embedding that is not on the vertex orbit, is refused before
    anything is written, naming output.fields[i] (all of them) and the available names."""
    scene = tmp_path / "bad.toml"
    scene.write_text(
        """
[mesh]
generator = "box"
[[model]]
kind = "corotational"
[output]
fields = ["mass", "stress", "volume"]
"""
    )
    with pytest.raises(SceneError) as e:
        run_scene(load_scene(scene), tmp_path / "out", preview=False)
    msg = str(e.value)
    assert "output.fields[1]: unknown field 'stress'" in msg
    assert "output.fields[2] 'volume'" in msg  # volume is per element, not per vertex
    assert "available: mass, force," in msg
    assert "velocity" in msg
    assert e.value.key == "output.fields[1]"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("value", "problem"),
    [
        ('"mass"', "output.fields: expected an array of field names"),
        ("[1]", "output.fields[0]: expected a field name (a string), got 1"),
        ('["mass", "mass"]', 'output.fields[1]: "mass" is already output.fields[0]'),
    ],
)
def test_output_fields_must_be_a_list_of_distinct_names(value: str, problem: str) -> None:
    """The shape of output.fields is checked when the scene is read, naming the key."""
    text = (
        f'[mesh]\ngenerator = "box"\n[[model]]\nkind = "corotational"\n[output]\nfields = {value}\n'
    )
    with pytest.raises(SceneError, match=re.escape(problem)):
        parse_scene(text)


def test_view_data_follows_the_rows(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The view data draws the same rows as final.vtu: its last frame's positions plus the
    origin are final.vtu's points (to float32 precision of the mesh size, 1 m)."""
    scene, points, cells = _write_scene(tmp_path, 3)
    _contract(monkeypatch, points, cells)
    run_scene(scene, tmp_path / "out", preview=False)
    view = read_view(tmp_path / "out")
    m = meshio.read(tmp_path / "out" / "final.vtu")
    np.testing.assert_allclose(view.world_positions(len(view.frames) - 1), m.points, atol=1e-6)


@pytest.mark.parametrize("dimension", [2, 3])
def test_cells_the_import_turned_over_are_written_as_it_turned_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, dimension: int
) -> None:
    """A mesh with some cells listed the other way round (mixed triangle orientations,
    inverted tetrahedra), imported with reorient: each output cell is its input cell,
    reversed exactly where the import's report says it turned it, and the written mesh is
    consistently oriented (read back without reorienting, nothing to turn)."""
    points, ctype, cells = _user_mesh(dimension)
    flip = np.arange(len(cells)) % 3 == 1
    listed = cells.copy()
    if dimension == 3:
        listed[flip] = listed[flip][:, [0, 2, 1, 3]]
    else:
        listed[flip] = listed[flip][:, ::-1]
    meshio.write(tmp_path / "mixed.vtu", meshio.Mesh(points, [(ctype, listed)]))
    turned = set(GMap.from_mesh(points, [(ctype, listed)], reorient=True).report.reoriented)
    assert turned  # the import turns some over (which ones is the import's choice)
    model = COROTATIONAL if dimension == 3 else 'kind = "stretch_elementary"\nstiffness = 1e3'
    text = _scene_text('file = "mixed.vtu"\nreorient = true', steps=5, model=model)
    (tmp_path / "mixed.toml").write_text(text)
    _contract(monkeypatch, points, list(listed))
    assert "error" not in run_scene(tmp_path / "mixed.toml", tmp_path / "out", preview=False)
    m = meshio.read(tmp_path / "out" / "final.vtu")
    pid = np.asarray(m.point_data["point_id"], dtype=np.int64)
    out_cells, ids = _cells_of(m)
    assert ids.tolist() == list(range(len(listed)))
    reversal = [0, 2, 1, 3] if dimension == 3 else [2, 1, 0]
    for c, k in zip(out_cells, ids):
        expected = listed[k][reversal] if k in turned else listed[k]
        assert pid[c].tolist() == expected.tolist(), k
    g = GMap.from_meshio(m, reorient=False)
    assert g.report.reoriented == []


def test_the_dart_view_puts_each_dart_at_its_vertex_row(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The view's dart table names each dart's vertex by its row in the recorded positions:
    the row's position is the position the map gives the dart's vertex (exactly, after a cut
    has split vertices and the pieces moved apart)."""
    scene, points, cells = _write_scene(tmp_path, 3, cut=True)
    _contract(monkeypatch, points, cells)
    sim = load_scene(scene).build()
    sim.step(12)  # past the cut at t = 0.01
    assert sim.topology_changes()
    rec = Recorder(sim)
    rec.frame()
    table = rec.topologies[-1].darts
    assert table is not None
    g = sim.core.gmap()
    labels = np.asarray(g.vertex_labels())
    live = labels >= 0
    x = sim.positions()
    np.testing.assert_array_equal(x[table["vertex"][live]], g.positions()[labels[live]])
    # the recording put the positions back exactly
    np.testing.assert_array_equal(sim.positions(), x)


def test_signed_volumes_and_reversal_against_closed_forms() -> None:
    """The orientation test the writer uses: signed volumes of the unit cube's cells in VTK
    order are the closed forms (tetra 1/6, pyramid 1/3, wedge 1/2, hexahedron 1; exact in
    binary up to round-off, 1e-15), the reversed cells' are their negatives, and a translation
    by 5e6 m changes them by less than 1e-9 (differences are taken inside each cell)."""
    cube = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
        dtype=np.float64,
    )
    apex = np.vstack([cube, [[0.5, 0.5, 1.0]]])
    cases = {
        "tetra": ([0, 1, 3, 4], 1 / 6),
        "pyramid": ([0, 1, 2, 3, 8], 1 / 3),
        # a positive wedge (Gmsh's and VTK's) lists its first triangle counter-clockwise seen
        # from the second
        "wedge": ([0, 1, 3, 4, 5, 7], 1 / 2),
        "hexahedron": (list(range(8)), 1.0),
    }
    for kind, (cell, volume) in cases.items():
        c = np.array([cell], dtype=np.int64)
        for shift in (0.0, 5e6):
            v = signed_volumes(kind, c, apex + shift)
            np.testing.assert_allclose(v, [volume], rtol=0, atol=1e-15 if shift == 0 else 1e-9)
            r = signed_volumes(kind, reversed_cells(kind, c), apex + shift)
            np.testing.assert_allclose(r, [-volume], rtol=0, atol=1e-15 if shift == 0 else 1e-9)
        assert sorted(reversed_cells(kind, c)[0].tolist()) == sorted(cell)


def test_output_fields_naming_the_always_written_point_data_are_accepted(tmp_path: Path) -> None:
    """`displacement`, `velocity`, `fixed` and `point_id` are in every output file: naming them
    in output.fields is accepted (it used to refuse `displacement` as an unknown field) and
    writes each once, with the same values as without it."""
    body = """
[mesh]
generator = "box"
element = "tet"
size = [1.0, 0.25, 0.25]
cells = [2, 1, 1]
[[model]]
kind = "corotational"
[[fix]]
where = "x < 1e-9"
[world]
gravity = [0.0, -9.81, 0.0]
[integrator]
dt = 1e-3
steps = 3
[output]
every = 0
"""
    plain = tmp_path / "plain.toml"
    plain.write_text(body)
    named = tmp_path / "named.toml"
    named.write_text(body + 'fields = ["displacement", "velocity", "mass", "fixed", "point_id"]\n')
    run_scene(plain, tmp_path / "a", preview=False)
    summary = run_scene(named, tmp_path / "b", preview=False)
    assert "error" not in summary
    a = meshio.read(tmp_path / "a" / "final.vtu")
    b = meshio.read(tmp_path / "b" / "final.vtu")
    assert set(b.point_data) == set(a.point_data) | {"mass"}
    for name in ("displacement", "velocity", "fixed", "point_id"):
        np.testing.assert_array_equal(a.point_data[name], b.point_data[name])
