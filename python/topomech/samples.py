"""Sample meshes shipped in the package (``topomech/data``), for the README's examples and
for trying things out::

    >>> import topomech
    >>> topomech.sample("beam.msh").name
    'beam.msh'
    >>> sorted(topomech.samples())
    ['beam.msh', 'block.vtu', 'sheet.obj']

``topomech samples`` lists them on the command line and ``topomech samples --copy DIR`` copies
them into a folder. ``scripts/make_samples.py`` in the repository writes them.
"""

from __future__ import annotations

import shutil
from pathlib import Path

_DATA = Path(__file__).resolve().parent / "data"

#: Each sample's name and what it holds.
SAMPLES: dict[str, str] = {
    "beam.msh": "1 x 0.2 x 0.2 m beam, 308 tetrahedra (Gmsh 4.1; groups beam clamp grip top)",
    "sheet.obj": "1 x 1 m flat sheet of 8 x 8 quads in the plane z = 0 (OBJ surface)",
    "block.vtu": "0.6 x 0.2 x 0.2 m block of 6 x 2 x 2 hexahedra (VTK XML)",
}


def samples() -> dict[str, str]:
    """The shipped samples: name -> what it holds."""
    return dict(SAMPLES)


def sample(name: str) -> Path:
    """The path of the shipped sample ``name`` (``"beam.msh"``, ``"sheet.obj"``,
    ``"block.vtu"``); a ``KeyError`` naming the samples for another name."""
    if name not in SAMPLES:
        raise KeyError(f"no sample {name!r}; the samples are {', '.join(SAMPLES)}")
    return _DATA / name


def copy_samples(folder: str | Path = ".") -> list[Path]:
    """Copies every sample into ``folder`` (made if missing; files of the same name are
    replaced) and returns the paths written."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    return [Path(shutil.copyfile(sample(name), out / name)) for name in SAMPLES]
