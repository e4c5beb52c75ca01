"""`topomech info`: bounding box, cells by kind and quality figures (issue 12), in text and
JSON, checked against values computed by hand for cells whose volume, area and inradius are
known in closed form.

Tolerances: the figures are sums of a few dozen products of coordinates of order 1, so they
agree with the closed forms to a few ulps; 1e-12 relative leaves room for that and nothing
more. The mesh placed at 5e6 m loses the digits its coordinates cannot hold (an ulp of 5e6 is
about 1e-9), hence 1e-6 there.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import meshio
import numpy as np
import pytest

import topomech
from topomech import cli
from topomech._cells import mesh_figures

REL = 1e-12


def info_json(path: Path, capsys: pytest.CaptureFixture[str], *flags: str) -> dict[str, Any]:
    code = cli.main(["info", str(path), "--json", *flags])
    out = capsys.readouterr().out
    assert code == 0, out
    data: dict[str, Any] = json.loads(out)
    return data


def write(tmp_path: Path, name: str, points: Any, cells: list[tuple[str, Any]]) -> Path:
    path = tmp_path / name
    meshio.write(path, meshio.Mesh(np.asarray(points, dtype=float), cells))
    return path


CUBE = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]


def test_two_unit_hexahedra(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # Two unit cubes side by side: volume 1 each, longest over shortest edge 1, box [0,2]x[0,1]^2.
    pts = np.array([*CUBE, [2, 0, 0], [2, 1, 0], [2, 0, 1], [2, 1, 1]], dtype=float)
    hexes = np.array([[0, 1, 2, 3, 4, 5, 6, 7], [1, 8, 9, 2, 5, 10, 11, 6]])
    data = info_json(write(tmp_path, "hex.vtu", pts, [("hexahedron", hexes)]), capsys)
    assert data["bounding_box"] == {"min": [0.0, 0.0, 0.0], "max": [2.0, 1.0, 1.0]}
    assert data["cells_by_kind"] == {"hexahedron": 2}
    q = data["quality"]
    assert q["min_volume"] == pytest.approx(1.0, rel=REL)
    assert q["max_volume"] == pytest.approx(1.0, rel=REL)
    assert q["worst_aspect_ratio"] == pytest.approx(1.0, rel=REL)
    assert (data["reoriented"], data["reoriented_cells"]) == (0, [])


def _tet_aspect(p: np.ndarray) -> float:
    """Longest edge over inradius (3 V / total face area), over 2 sqrt(6), by hand."""
    v = abs(np.linalg.det(np.array([p[1] - p[0], p[2] - p[0], p[3] - p[0]]))) / 6
    faces = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]
    s = sum(np.linalg.norm(np.cross(p[b] - p[a], p[c] - p[a])) / 2 for a, b, c in faces)
    edges = [np.linalg.norm(p[i] - p[j]) for i in range(4) for j in range(i + 1, 4)]
    return float(max(edges) / (3 * v / s) / (2 * math.sqrt(6)))


def test_tetrahedra_volume_and_aspect(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A regular tetrahedron (aspect 1 by construction of the normalisation, volume
    # a^3 / (6 sqrt 2)), a corner tetrahedron (volume 1/6, aspect (3/2 + sqrt(3)/2) / sqrt(3))
    # and a sliver (four nearly coplanar points whose edges are all alike: longest over
    # shortest edge is only sqrt 2, but it is flat, and this measure says so).
    s3 = math.sqrt(3.0)
    regular = np.array([[0, 0, 0], [1, 0, 0], [0.5, s3 / 2, 0], [0.5, s3 / 6, math.sqrt(2 / 3)]])
    corner = np.array([[3, 0, 0], [4, 0, 0], [3, 1, 0], [3, 0, 1]], dtype=float)
    h = 0.01
    sliver = np.array([[6, 0, 0], [7, 1, 0], [7, 0, h], [6, 1, h]], dtype=float)
    pts = np.vstack([regular, corner, sliver])
    tets = np.arange(12).reshape(3, 4)
    # orient each positively (the import would turn them over anyway, with a note)
    for k in range(3):
        p = pts[tets[k]]
        if np.linalg.det(np.array([p[1] - p[0], p[2] - p[0], p[3] - p[0]])) < 0:
            tets[k, [1, 2]] = tets[k, [2, 1]]
    data = info_json(write(tmp_path, "tets.vtu", pts, [("tetra", tets)]), capsys)
    q = data["quality"]
    assert data["cells_by_kind"] == {"tetra": 3}
    sliver_volume = (
        abs(
            np.linalg.det(
                np.array([sliver[1] - sliver[0], sliver[2] - sliver[0], sliver[3] - sliver[0]])
            )
        )
        / 6
    )
    assert q["min_volume"] == pytest.approx(sliver_volume, rel=REL)
    assert q["max_volume"] == pytest.approx(1 / 6, rel=REL)  # the corner one
    assert _tet_aspect(regular) == pytest.approx(1.0, rel=REL)
    assert _tet_aspect(corner) == pytest.approx((1.5 + s3 / 2) / s3, rel=REL)
    assert q["worst_aspect_cell"] == 2
    assert q["worst_aspect_ratio"] == pytest.approx(_tet_aspect(sliver), rel=REL)
    assert q["worst_aspect_ratio"] > 20  # flat, though its edges differ by sqrt 2 at most
    alone = mesh_figures(regular, [("tetra", np.arange(4).reshape(1, 4))], 3)["quality"]
    assert alone["min_volume"] == pytest.approx(1 / (6 * math.sqrt(2)), rel=REL)
    assert alone["worst_aspect_ratio"] == pytest.approx(1.0, rel=REL)
    figures = mesh_figures(pts, [("tetra", tets[:2])], 3)["quality"]
    assert figures["worst_aspect_ratio"] == pytest.approx(_tet_aspect(corner), rel=REL)
    assert figures["worst_aspect_cell"] == 1


def test_wedge_and_pyramid_volumes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # Half a unit cube (a wedge, volume 1/2) and a pyramid on a unit square of height 1
    # (volume 1/3), disjoint.
    wedge_pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]]
    pyr_pts = [[3, 0, 0], [4, 0, 0], [4, 1, 0], [3, 1, 0], [3.5, 0.5, 1]]
    pts = np.array(wedge_pts + pyr_pts, dtype=float)
    # VTK's wedge has its first triangle turning clockwise seen from the second: whichever
    # way these are listed, the import orients them and the volume is the same.
    data = info_json(
        write(
            tmp_path,
            "mixed.vtu",
            pts,
            [("wedge", np.array([[0, 2, 1, 3, 5, 4]])), ("pyramid", np.array([[6, 7, 8, 9, 10]]))],
        ),
        capsys,
    )
    q = data["quality"]
    assert data["cells_by_kind"] == {"wedge": 1, "pyramid": 1}
    assert q["min_volume"] == pytest.approx(1 / 3, rel=REL)
    assert q["max_volume"] == pytest.approx(1 / 2, rel=REL)
    # longest over shortest edge: the wedge's sqrt(2) over 1; the pyramid's slant edge
    # sqrt(0.25 + 0.25 + 1) = sqrt(1.5) over 1 — the wedge (cell 0) is worst
    assert q["worst_aspect_ratio"] == pytest.approx(math.sqrt(2), rel=REL)
    assert q["worst_aspect_cell"] == 0


def test_surface_areas_and_text(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # An equilateral triangle (area sqrt(3)/4, aspect 1), a 2 x 1 rectangle (area 2, edge
    # ratio 2) and a right isosceles triangle (aspect from its inradius 2 A / P, below), in
    # 2D: areas, not volumes.
    s3 = math.sqrt(3.0)
    pts = np.array(
        [
            [0, 0, 0],
            [1, 0, 0],
            [0.5, s3 / 2, 0],
            [2, 0, 0],
            [4, 0, 0],
            [4, 1, 0],
            [2, 1, 0],
            [5, 0, 0],
            [6, 0, 0],
            [5, 1, 0],
        ]
    )
    path = write(
        tmp_path,
        "surface.vtu",
        pts,
        [
            ("triangle", np.array([[0, 1, 2]])),
            ("quad", np.array([[3, 4, 5, 6]])),
            ("triangle", np.array([[7, 8, 9]])),
        ],
    )
    data = info_json(path, capsys)
    q = data["quality"]
    assert data["dimension"] == 2
    assert data["cells_by_kind"] == {"triangle": 2, "quad": 1}
    assert "min_volume" not in q
    assert q["min_area"] == pytest.approx(s3 / 4, rel=REL)
    assert q["max_area"] == pytest.approx(2.0, rel=REL)
    right = (1 + 1 + math.sqrt(2)) * math.sqrt(2) / (4 * s3 * 0.5)  # l_max P / (4 sqrt3 A)
    assert right < 2
    assert q["worst_aspect_ratio"] == pytest.approx(2.0, rel=REL)
    assert q["worst_aspect_cell"] == 1
    figures = mesh_figures(pts, [("triangle", np.array([[0, 1, 2], [7, 8, 9]]))], 2)["quality"]
    assert figures["worst_aspect_ratio"] == pytest.approx(right, rel=REL)
    assert cli.main(["info", str(path)]) == 0
    text = capsys.readouterr().out
    assert "cells       2 triangle, 1 quad" in text
    assert "bounds      min (0, 0, 0), max (6, 1, 0)" in text
    assert "area        min 0.433013, max 2" in text
    assert "aspect      worst 2 (cell 1)" in text
    assert "reoriented  0" in text


def test_polygons_and_large_coordinates(tmp_path: Path) -> None:
    # A regular hexagon of side 1 (area 3 sqrt(3) / 2) and a unit cube at 5e6 m: the
    # figures are computed relative to each cell's centroid, so the far mesh measures right.
    angles = np.arange(6) * np.pi / 3
    hexagon = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(6)])
    q = mesh_figures(hexagon, [("polygon", [list(range(6))])], 2)["quality"]
    assert q["min_area"] == pytest.approx(3 * math.sqrt(3) / 2, rel=REL)
    assert q["worst_aspect_ratio"] == pytest.approx(1.0, rel=REL)
    far = np.array(CUBE, dtype=float) + 5e6
    f = mesh_figures(far, [("hexahedron", np.arange(8).reshape(1, 8))], 3)
    assert f["quality"]["min_volume"] == pytest.approx(1.0, rel=1e-6)
    assert f["bounding_box"]["min"] == [5e6, 5e6, 5e6]


def test_info_on_a_saved_map_and_reoriented_count(tmp_path: Path) -> None:
    # A saved G-map has no mesh file behind it: the figures come from the map's own cells.
    # The JSON of a mesh with an inverted cell says how many were turned and which.
    pts = np.array(CUBE, dtype=float)
    g = topomech.GMap.from_mesh(pts, [("hexahedron", np.arange(8).reshape(1, 8))])
    g.save(tmp_path / "cube.tmg")
    r = subprocess.run(
        [sys.executable, "-m", "topomech", "info", str(tmp_path / "cube.tmg"), "--json"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    assert data["cells_by_kind"] == {"hexahedron": 1}
    assert data["quality"]["min_volume"] == pytest.approx(1.0, rel=REL)
    # two disjoint corner tetrahedra, the second listed with the opposite orientation
    pts2 = np.vstack([pts[[0, 1, 3, 4]], pts[[0, 1, 3, 4]] + [5, 0, 0]])
    path = write(tmp_path, "inv.vtu", pts2, [("tetra", np.array([[0, 1, 2, 3], [4, 6, 5, 7]]))])
    r = subprocess.run(
        [sys.executable, "-m", "topomech", "info", str(path), "--json"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    assert (data["reoriented"], data["reoriented_cells"]) == (1, [1])
    assert data["quality"]["min_volume"] == pytest.approx(1 / 6, rel=REL)


def test_info_on_a_map_of_general_polyhedra(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A tetrahedron whose edge `split_edge` split is a volume of 5 vertices and 4 faces (two
    of them quads), a cell of no kind: `info` on its .tmg gives the map's counts, its
    validity and the vertices' bounding box, lists no cells, says why in a note (stderr and
    the JSON's notes), and exits 0 (it exited 2, describing nothing). Writing it to a .vtu
    gives a polyhedron (see test_io's polyhedra tests); to another mesh file it is refused
    (exit 2, naming the volume, nothing written)."""
    tet = write(
        tmp_path, "t.vtu", [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [("tetra", [[0, 1, 2, 3]])]
    )
    tmg = tmp_path / "t.tmg"
    code = cli.main(["apply", str(tet), "@library", "split_edge", "--at", "0", "--out", str(tmg)])
    assert code == 0
    capsys.readouterr()
    data = info_json(tmg, capsys)
    assert (data["vertices"], data["faces"], data["volumes"], data["valid"]) == (5, 4, 1, True)
    assert data["cells_by_kind"] == {}
    assert data["bounding_box"] == {"min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 1.0]}
    assert data["quality"]["min_volume"] is None
    assert any("5 vertices and 4 faces" in n for n in data["notes"]), data["notes"]
    code = cli.main(["info", str(tmg)])
    out, err = capsys.readouterr()
    assert code == 0
    assert "not listed (see the note)" in out
    assert "a .vtu also holds general polyhedra" in err
    code = cli.main(
        ["apply", str(tet), "@library", "split_edge", "--at", "0", "--out", str(tmp_path / "x.vtu")]
    )
    assert code == 0
    assert [c.type for c in meshio.read(tmp_path / "x.vtu").cells] == ["polyhedron5"]
    capsys.readouterr()
    code = cli.main(
        ["apply", str(tet), "@library", "split_edge", "--at", "0", "--out", str(tmp_path / "x.msh")]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert "5 vertices and 4 faces (2 triangles, 2 quads)" in err
    assert "write the map as a .vtu or a .tmg" in err
    assert not (tmp_path / "x.msh").exists()
    # a second split: every face counted, by its sides (the pentagons were left out)
    code = cli.main(
        ["apply", str(tmg), "@library", "split_edge", "--at", "1", "--out", str(tmp_path / "y.msh")]
    )
    assert code == 2
    assert "6 vertices and 4 faces (2 triangles, 2 pentagons)" in capsys.readouterr().err


def test_a_run_of_a_map_of_general_polyhedra_is_refused_before_it_steps(tmp_path: Path) -> None:
    """`topomech run` of a scene whose saved map has a general polyhedron (after
    `split_edge`) is refused at set-up, naming `mesh.file` and the volume, before any step
    and before the output folder is made (it stepped to the end, then failed writing
    final.vtu with exit 2 and no summary: the results lost)."""
    tet = write(
        tmp_path, "t.vtu", [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [("tetra", [[0, 1, 2, 3]])]
    )
    tmg = tmp_path / "t.tmg"
    assert (
        cli.main(["apply", str(tet), "@library", "split_edge", "--at", "0", "--out", str(tmg)]) == 0
    )
    scene = tmp_path / "s.toml"
    scene.write_text(
        '[mesh]\nfile = "t.tmg"\n[[model]]\nkind = "stretch_cumulated"\n'
        '[integrator]\nkind = "symplectic_euler"\ndt = 0.001\nsteps = 5\n[output]\nevery = 0\n',
        encoding="utf-8",
    )
    out = tmp_path / "out"
    with pytest.raises(topomech.SceneError, match=r"mesh\.file: .*5 vertices and 4 faces"):
        topomech.run_scene(scene, out=out)
    assert not out.exists()
    assert cli.main(["run", str(scene), "--out", str(out)]) == 2
    assert not out.exists()


def test_a_mesh_of_lines_only_is_refused_naming_the_file(tmp_path: Path) -> None:
    """A mesh file with line cells only has no surface or volume: refused with the file's
    name, as the other read errors are (QA: the name was missing)."""
    path = write(
        tmp_path, "lines.vtu", [[0, 0, 0], [1, 0, 0], [1, 1, 0]], [("line", [[0, 1], [1, 2]])]
    )
    with pytest.raises(topomech.MeshError, match=r"lines\.vtu: the mesh has no surface or volume"):
        topomech.read_mesh(path)


def test_a_simulation_of_a_map_with_broken_links_names_the_violation() -> None:
    """A saved map whose alpha_0 of dart 0 was overwritten (the file's layout: a 26-byte
    header, the alive flags, then alpha_0) loads, and `info` reports it; a `Simulation` of
    it is refused saying the map is not a valid G-map and naming the violation (QA: it ran
    the set-up rules, and one of them reported a non-finite value)."""
    import struct

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    g = topomech.GMap.from_mesh(pts, {"tetra": np.array([[0, 1, 2, 3], [1, 2, 3, 4]])})
    data = bytearray(g.to_bytes())
    capacity = struct.unpack_from("<I", data, 22)[0]
    assert capacity == g.n_darts
    struct.pack_into("<I", data, 26 + capacity, 5)
    broken = topomech.GMap.from_bytes(bytes(data))
    assert not broken.is_valid()
    with pytest.raises(topomech.SimulationError, match=r"the map is not a valid G-map: .*alpha0"):
        topomech.Simulation(broken, models=["linear_fem"])
