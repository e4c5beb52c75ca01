"""A scene run reads its mesh file once: building the map, the groups of the boundary
conditions and the output cells share what was read (it used to read the file three times,
which for a large Gmsh file tripled the set-up)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import meshio
import numpy as np
import pytest

import topomech.io
from topomech.run import run_scene


def test_a_run_reads_its_mesh_file_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Counts the calls of topomech.io.read_mesh during a run whose fixes select input points
    (so the groups are needed) and whose outputs list the input cells: exactly one."""
    points = np.array(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]],
        dtype=float,
    )
    cells = [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 4]]))]
    mesh_file = tmp_path / "two.vtu"
    meshio.write(mesh_file, meshio.Mesh(points, cells))
    scene = tmp_path / "scene.toml"
    scene.write_text(
        f"""
[mesh]
file = "{mesh_file.name}"
[[model]]
kind = "corotational"
[[fix]]
points = [0, 1, 2]
[world]
gravity = [0.0, 0.0, -9.81]
[integrator]
dt = 1e-3
steps = 2
[output]
every = 1
"""
    )
    calls: list[Any] = []
    real = topomech.io.read_mesh

    def counting(*args: Any, **kwargs: Any) -> Any:
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(topomech.io, "read_mesh", counting)
    summary = run_scene(scene, tmp_path / "out", preview=False)
    assert "error" not in summary
    assert len(calls) == 1, calls
    # the output cells are still the input's: cell_id numbers them in input order
    final = meshio.read(tmp_path / "out" / "final.vtu")
    np.testing.assert_array_equal(final.cell_data["cell_id"][0], [0, 1])
