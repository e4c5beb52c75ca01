#!/usr/bin/env python3
"""Writes the sample meshes shipped in the package (python/topomech/data/), small enough to
read in a diff and to run in the README's examples:

- ``beam.msh``: a 1 m x 0.2 m x 0.2 m beam of tetrahedra, Gmsh MSH 4.1 (ASCII), made with the
  ``gmsh`` Python package, with physical groups ``beam`` (the volume), ``clamp`` (the face
  x = 0), ``grip`` (the face x = 1) and ``top`` (the face z = 0.2);
- ``sheet.obj``: a 1 m x 1 m flat sheet of 8 x 8 quads in the plane z = 0 (Wavefront OBJ);
- ``block.vtu``: a 0.6 m x 0.2 m x 0.2 m block of 6 x 2 x 2 hexahedra (VTK XML, ASCII).

    .venv/bin/python scripts/make_samples.py [--out python/topomech/data]

Running it again writes the same files (``tests/test_samples.py`` checks what they hold).
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import meshio
import numpy as np

DATA = Path(__file__).resolve().parent.parent / "python" / "topomech" / "data"
#: The gmsh that wrote the shipped beam.msh (another version may mesh the beam otherwise).
GMSH_VERSION = "4.15.2"


def write_beam(path: Path) -> None:
    import gmsh

    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        # frontal: well-shaped tetrahedra, the same mesh every time
        gmsh.option.setNumber("Mesh.Algorithm3D", 4)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("beam")
        gmsh.model.occ.addBox(0.0, 0.0, 0.0, 1.0, 0.2, 0.2)
        gmsh.model.occ.synchronize()
        faces = {}
        for _, tag in gmsh.model.getEntities(2):
            x, y, z = gmsh.model.occ.getCenterOfMass(2, tag)
            faces[(round(x, 6), round(y, 6), round(z, 6))] = tag
        by_name = {
            "clamp": [t for (x, _, _), t in faces.items() if x == 0.0],
            "grip": [t for (x, _, _), t in faces.items() if x == 1.0],
            "top": [t for (_, _, z), t in faces.items() if z == 0.2],
        }
        gmsh.model.addPhysicalGroup(3, [1], name="beam")
        for name, tags in by_name.items():
            assert len(tags) == 1, (name, faces)
            gmsh.model.addPhysicalGroup(2, tags, name=name)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.1)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.1)
        gmsh.model.mesh.generate(3)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.option.setNumber("Mesh.Binary", 0)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


def write_sheet(path: Path, n: int = 8) -> None:
    lines = ["# a 1 m x 1 m sheet of 8 x 8 quads in the plane z = 0 (topomech sample)"]
    for j in range(n + 1):
        for i in range(n + 1):
            lines.append(f"v {i / n:.6g} {j / n:.6g} 0")
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i + 1  # OBJ counts from 1
            lines.append(f"f {a} {a + 1} {a + n + 2} {a + n + 1}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def write_block(path: Path, cells: tuple[int, int, int] = (6, 2, 2)) -> None:
    nx, ny, nz = cells
    h = 0.1
    pts = np.array(
        [[i * h, j * h, k * h] for k in range(nz + 1) for j in range(ny + 1) for i in range(nx + 1)]
    )

    def p(i: int, j: int, k: int) -> int:
        return (k * (ny + 1) + j) * (nx + 1) + i

    hexes = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                hexes.append(
                    [
                        p(i, j, k),
                        p(i + 1, j, k),
                        p(i + 1, j + 1, k),
                        p(i, j + 1, k),
                        p(i, j, k + 1),
                        p(i + 1, j, k + 1),
                        p(i + 1, j + 1, k + 1),
                        p(i, j + 1, k + 1),
                    ]
                )
    mesh = meshio.Mesh(pts, [("hexahedron", np.array(hexes, dtype=np.int64))])
    meshio.write(path, mesh, file_format="vtu", binary=False)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=DATA)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    write_beam(args.out / "beam.msh")
    write_sheet(args.out / "sheet.obj")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # meshio: "VTU ASCII files are only meant for debugging"
        write_block(args.out / "block.vtu")
    for name in ("beam.msh", "sheet.obj", "block.vtu"):
        print(f"{args.out / name}: {(args.out / name).stat().st_size:,} bytes")


if __name__ == "__main__":
    main()
