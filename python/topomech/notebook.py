"""Runs and simulations in Jupyter: :func:`show` displays a run directory's viewer page
(:func:`topomech.viewer.viewer_html`, self-contained: scripts, three.js and the run's data
inlined) in a notebook, and :meth:`Simulation._repr_html_ <topomech.Simulation>` a short
summary of a simulation with its current mesh in the same viewer.

The page goes into an ``<iframe srcdoc=...>``, sandboxed with ``allow-scripts`` only: its
scripts run in a document of their own (no access to the notebook's page, its styles or its
other outputs), and nothing is fetched from a server, so the output also works in an
exported HTML notebook. Outside a notebook, the objects show a one-line ``repr``.

>>> import topomech
>>> view = topomech.show("no/such/run")
Traceback (most recent call last):
...
topomech.recording.ViewError: no/such/run: no such directory
"""

from __future__ import annotations

import html
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Union

from topomech.recording import read_view

if TYPE_CHECKING:
    from topomech.simulation import Simulation

__all__ = ["RunView", "iframe", "show", "simulation_html"]

PathLike = Union[str, "os.PathLike[str]"]

#: The viewer's height in a notebook (pixels).
HEIGHT = 560
#: A simulation's ``_repr_html_`` shows its mesh in the viewer up to this many vertices
#: (the page inlines the mesh; larger ones show the table alone).
MAX_VIEW_VERTICES = 200_000


def iframe(page: str, *, height: int = HEIGHT, title: str = "topomech viewer") -> str:
    """An ``<iframe>`` whose ``srcdoc`` is the whole HTML document ``page`` (escaped for the
    attribute), sandboxed to run its scripts apart from the notebook."""
    return (
        f'<iframe srcdoc="{html.escape(page, quote=True)}" title="{html.escape(title)}" '
        f'sandbox="allow-scripts" width="100%" height="{int(height)}" '
        'style="border: 1px solid #ddd; width: 100%;"></iframe>'
    )


class RunView:
    """A run directory's viewer, displayed by Jupyter (:meth:`_repr_html_`). Raises
    :class:`~topomech.recording.ViewError` when the directory has no readable view data
    (checked at once; the page is built when displayed)."""

    def __init__(self, out_dir: PathLike, *, height: int = HEIGHT) -> None:
        self.out_dir = Path(out_dir)
        self.height = int(height)
        view = read_view(self.out_dir)
        self.name = str(view.meta.get("name", "run"))
        self.frames = len(view.frames)

    def html(self) -> str:
        """The viewer page itself (a whole HTML document)."""
        from topomech.viewer import viewer_html

        return viewer_html(self.out_dir)

    def _repr_html_(self) -> str:
        return iframe(self.html(), height=self.height, title=f"topomech viewer: {self.name}")

    def __repr__(self) -> str:
        return (
            f"topomech.show({os.fspath(self.out_dir)!r}): the viewer of run {self.name!r} "
            f"({self.frames} frames), displayed in a notebook"
        )


def show(out_dir: PathLike, *, height: int = HEIGHT) -> RunView:
    """The viewer of a run directory (what ``topomech run`` wrote) for a Jupyter notebook:
    the last expression of a cell, or ``IPython.display.display(topomech.show(out))``.
    Raises :class:`~topomech.recording.ViewError` when the directory has no readable view
    data."""
    return RunView(out_dir, height=height)


def _summary_rows(sim: Simulation) -> list[tuple[str, str]]:
    ids, _ = sim.elements()
    rows = [
        ("dimension", f"{sim.dimension}D"),
        ("vertices", f"{sim.n_vertices:,}"),
        ("elements", f"{len(ids):,}"),
        ("darts", f"{sim.core.gmap().n_darts:,}"),
        ("integrator", f"{sim.integrator} (dt = {sim.dt:g} s)"),
        ("time", f"{sim.time:g} s after {sim.steps:,} steps"),
    ]
    changes = sim.topology_changes()
    if changes:
        rows.append(("topology changes", f"{len(changes)}"))
    return rows


def _mesh_page(sim: Simulation) -> str:
    """The viewer page of the simulation's current state (one frame)."""
    from topomech.recording import Recorder
    from topomech.viewer import viewer_html

    with tempfile.TemporaryDirectory(prefix="topomech-show-") as tmp:
        rec = Recorder(sim, energy=False, out_dir=Path(tmp))
        try:
            rec.frame()
            rec.write_view(Path(tmp))
        finally:
            rec.close()
        return viewer_html(Path(tmp))


def simulation_html(sim: Simulation, *, mesh: bool = True, height: int = HEIGHT) -> str:
    """A simulation as HTML: a table (dimension, vertices, elements, darts, integrator,
    time, topology changes) and, with ``mesh`` and up to :data:`MAX_VIEW_VERTICES`
    vertices, its current mesh in the viewer (:func:`iframe`)."""
    cells = "".join(
        f'<tr><th style="text-align: left; padding-right: 1em;">{html.escape(k)}</th>'
        f'<td style="text-align: left;">{html.escape(v)}</td></tr>'
        for k, v in _summary_rows(sim)
    )
    out = (
        '<div class="topomech-simulation"><table><caption style="text-align: left;">'
        f"<b>topomech.Simulation</b></caption>{cells}</table>"
    )
    if mesh and sim.n_vertices <= MAX_VIEW_VERTICES:
        out += iframe(_mesh_page(sim), height=height, title="topomech viewer: simulation")
    elif mesh:
        out += (
            f"<p>{sim.n_vertices:,} vertices: too many to embed the mesh here; "
            "<code>topomech.show(out_dir)</code> shows a run's frames.</p>"
        )
    return out + "</div>"
