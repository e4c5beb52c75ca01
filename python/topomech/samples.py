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

import errno
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


def copy_samples(folder: str | Path = ".", *, overwrite: bool = False) -> list[Path]:
    """Copies every sample into ``folder`` (made if missing) and returns their paths there.
    A file of the same name that already holds the sample is kept; one that differs (a
    sample the user edited) is replaced only with ``overwrite``, else
    :class:`FileExistsError` names it before anything is copied. :class:`NotADirectoryError`
    when ``folder`` is a file."""
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(
            errno.ENOTDIR, "not a folder: samples are copied into one", str(out)
        )
    out.mkdir(parents=True, exist_ok=True)
    targets = [(sample(name), out / name) for name in SAMPLES]
    if not overwrite:
        for src, dst in targets:
            if dst.exists() and (not dst.is_file() or dst.read_bytes() != src.read_bytes()):
                raise FileExistsError(
                    errno.EEXIST,
                    "exists and differs from the sample (edited?); not replaced without "
                    "overwrite (topomech samples --copy DIR --overwrite)",
                    str(dst),
                )
    for src, dst in targets:
        if not (dst.is_file() and dst.read_bytes() == src.read_bytes()):
            shutil.copyfile(src, dst)
    return [dst for _, dst in targets]
