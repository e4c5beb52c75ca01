"""Running a scene to files: frames, the final state and a summary.

:func:`run_scene` writes, under the output directory:

- ``summary.json``: what ran and how it ended (see :func:`run_scene` for the keys);
- ``final.vtu``: the last state, points at the current positions in the simulation's row
  order (the input point order), point data ``displacement``, ``velocity``, ``fixed`` (1 for
  held vertices), ``point_id`` (the input point index of each row) and the scene's
  ``output.fields`` (``mass``, ``force``, vertex embeddings), cells in the input's order and
  orientation at rest with cell data ``cell_id`` (the input cell index; see
  :mod:`topomech._output`);
- ``frames/frame_NNNNN.vtu``: a frame every ``every`` steps, frame 0 being the initial state
  (and the last state as a last frame when the step count is not a multiple of ``every``),
  with ``animation.pvd``, the ParaView collection of the frames and their times;
- ``view.json`` and ``view.bin``: the frames for ``topomech view`` and the previews
  (positions, fields, surfaces and, for small maps, darts with their alpha links; see
  :mod:`topomech.recording`);
- with ``preview`` (the default): ``energy.csv`` (kinetic, gravitational, elastic and total
  energy at every step) and ``energy.png``, ``preview.gif`` (the frames rendered headless,
  see :mod:`topomech.render`) and ``preview.mp4`` when imageio-ffmpeg's encoder is installed.

A divergence stops the run: what was written stays, ``final.vtu`` holds the last good state,
and ``summary.json`` has an ``error`` entry naming the step and the vertex.

Topology changes (the scene's ``[[event]]`` cuts, ``[fracture]``) split vertices: the files
written after one have more points (the copies of the split vertices, at the same place at
first) and cells that reference them, so the pieces come apart in the frames. The summary
lists the changes (``topology_changes``) and counts the final map's connected ``components``.
A cut that separates nothing when its time comes (it misses the object) stops the run after
that step, like a divergence: the summary's ``error`` has ``type`` ``"event"``, the ``event``
index and a message naming ``event[i]``.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO
from xml.sax.saxutils import quoteattr

import numpy as np

from topomech import __version__
from topomech._cells import FlatMesh, to_flat
from topomech._core import DivergenceError, SimulationError, TopomechError
from topomech._output import OutputCells, check_fields, field_values
from topomech.recording import Recorder
from topomech.scene import Scene, load_scene

if TYPE_CHECKING:
    import meshio

    from topomech._gmap import PathLike
    from topomech.simulation import Simulation

__all__ = ["Progress", "run_scene", "write_pvd"]

#: The keys every summary has (an ``error`` entry is added when the run fails).
SUMMARY_KEYS = (
    "scene",
    "name",
    "dimension",
    "models",
    "integrator",
    "dt",
    "steps",
    "steps_requested",
    "time",
    "darts",
    "vertices",
    "edges",
    "faces",
    "volumes",
    "components",
    "topology_changes",
    "total_mass",
    "kinetic_energy",
    "momentum",
    "max_displacement",
    "solver",
    "frames",
    "wall_seconds",
    "step_seconds",
    "steps_per_second",
    "outputs",
    "topomech_version",
)


class Progress:
    """A one-line progress bar on a stream (``\\r`` updates, at most 10 a second)."""

    def __init__(self, label: str, total: int, stream: TextIO | None = None) -> None:
        self.label = label
        self.total = total
        self.stream = stream if stream is not None else sys.stderr
        self.start = time.perf_counter()
        self.last = 0.0
        self.width = 0

    def update(self, done: int, *, force: bool = False) -> None:
        now = time.perf_counter()
        if not force and now - self.last < 0.1:
            return
        self.last = now
        frac = done / self.total if self.total else 1.0
        bar = "#" * int(30 * frac)
        elapsed = now - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = f" eta {(self.total - done) / rate:.0f}s" if rate > 0 and done < self.total else ""
        line = (
            f"{self.label} [{bar:<30}] {100 * frac:3.0f}% step {done}/{self.total} "
            f"{rate:.0f} steps/s{eta}"
        )
        pad = " " * max(0, self.width - len(line))
        self.width = len(line)
        self.stream.write(f"\r{line}{pad}")
        self.stream.flush()

    def close(self, done: int) -> None:
        self.update(done, force=True)
        self.stream.write("\n")
        self.stream.flush()


class _Writer:
    """Writes VTU files of the simulation's current state: points in row order, point data
    ``displacement``, ``velocity``, ``fixed``, ``point_id`` and the scene's
    ``output.fields``, cells in the user's orientation with cell data ``cell_id`` (see
    :mod:`topomech._output`)."""

    def __init__(self, sim: Simulation, cells: OutputCells, fields: Sequence[str] = ()) -> None:
        self.sim = sim
        self.cells = cells
        self.fields = tuple(fields)

    def mesh(self) -> meshio.Mesh:
        import meshio

        blocks, ids = self.cells.blocks()
        x = self.sim.positions()
        point_data: dict[str, Any] = {
            "displacement": x - self.sim.rest_positions(),
            "velocity": self.sim.velocities(),
            "fixed": self.sim.fixed().astype(np.uint8),
            "point_id": self.cells.point_ids(),
        }
        for name in self.fields:
            point_data[name] = field_values(self.sim, name)
        return meshio.Mesh(x, blocks, point_data=point_data, cell_data={"cell_id": ids})

    def write(self, path: Path) -> None:
        import meshio

        meshio.write(os.fspath(path), self.mesh(), file_format="vtu")


def _input_cells(sc: Scene) -> FlatMesh | None:
    """The cells of the scene's mesh file as the map was built from them (``cell_id``
    numbers them), or None for a generated mesh, a saved map or a file that cannot be read
    again (the output then orients the cells at rest without them)."""
    m = sc.mesh
    if m.file is None or m.file.suffix.lower() == ".tmg":
        return None
    from topomech.io import read_mesh

    linear = m.linear
    try:
        # read again: what it had to say was said the first time
        with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):
            warnings.simplefilter("ignore")
            read: Any = read_mesh
            mesh, _ = read(m.file, linear=True) if linear else read(m.file)
        return to_flat(mesh.points, mesh.cells)
    except (TopomechError, ValueError, TypeError, OSError):
        return None


def write_pvd(path: Path, frames: list[tuple[float, str]]) -> None:
    """A ParaView collection (``.pvd``) of ``(time, file)`` frames, files relative to it."""
    lines = [
        '<?xml version="1.0"?>',
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
        "  <Collection>",
        *(
            f'    <DataSet timestep="{t!r}" group="" part="0" file={quoteattr(f)}/>'
            for t, f in frames
        ),
        "  </Collection>",
        "</VTKFile>",
    ]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _max_displacement(sim: Simulation) -> float:
    """The largest displacement norm, scaled so that huge (diverging) values do not
    overflow."""
    d = sim.displacements()
    if len(d) == 0:
        return 0.0
    m = np.abs(d).max(axis=1)
    safe = np.where(m > 0, m, 1.0)
    return float((m * np.sqrt(((d / safe[:, None]) ** 2).sum(axis=1))).max())


def _json_safe(x: Any) -> Any:
    """``x`` with non-finite floats as None: JSON has no infinities or NaN."""
    if isinstance(x, float):
        return x if np.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_json_safe(v) for v in x]
    return x


#: The kernel's message for a timed cut that separates nothing.
_MISSED = re.compile(r"at t = (\S+) separates nothing: it misses the object")


def _describe_event(e: dict[str, Any]) -> str:
    """An event as a message shows it: ``a cut at t = 0.5 along the plane ...``."""
    if "plane" in e:
        n = ", ".join(f"{float(x):g}" for x in e["plane"]["normal"])
        geometry = f"along the plane normal [{n}], offset {float(e['plane']['offset']):g}"
    else:
        geometry = f"where {json.dumps(e.get('where'))}"
    return f"a {e['kind']} at t = {float(e['time']):g} {geometry}"


def _missed_event(sc: Scene, sim: Simulation, message: str) -> int | None:
    """The index of the event whose cut separated nothing in the step just done, from the
    kernel's message: events due at this step run in order, and each one that cut something
    is recorded as a change at this step, so the one that failed comes after those."""
    m = _MISSED.search(message)
    if m is None:
        return None
    try:
        t_msg = float(m.group(1))
    except ValueError:
        return None
    tol = 1e-9 * sim.dt
    # due now and not at the step before (the first step takes every event up to its time)
    lower = -math.inf if sim.steps <= 1 else sim.time - sim.dt + tol
    due = [i for i, e in enumerate(sc.events) if lower < float(e["time"]) <= sim.time + tol]
    done = sum(1 for c in sim.topology_changes() if c["kind"] == "cut" and c["step"] == sim.steps)
    if done < len(due) and float(sc.events[due[done]]["time"]) == t_msg:
        return due[done]
    same = [i for i, e in enumerate(sc.events) if float(e["time"]) == t_msg]
    return same[0] if same else None


def run_scene(
    scene: Scene | PathLike,
    out: PathLike | None = None,
    *,
    steps: int | None = None,
    every: int | None = None,
    progress: bool | Callable[[int, int], None] = False,
    preview: bool = True,
    video: bool = True,
) -> dict[str, Any]:
    """Runs a scene (a :class:`Scene` or a scene file) and writes its outputs under ``out``
    (default ``out/<scene name>``); ``steps`` and ``every`` override the scene's. Returns the
    summary written to ``summary.json``: ``scene``, ``name``, ``dimension``, ``models``,
    ``integrator``, ``dt``, ``steps`` (done), ``steps_requested``, ``time``, ``darts``,
    ``vertices``, ``edges``, ``faces``, ``volumes``, ``components`` (connected components of
    the final map: 2 or more once a cut or a fracture split the object), ``topology_changes``
    (a list of ``{"step", "time", "kind": "cut" | "fracture", "unsewn"}``, ``unsewn`` counting
    the faces, in 3D, or edges, in 2D, opened), ``total_mass``, ``kinetic_energy``,
    ``momentum``, ``max_displacement``, ``solver`` (static and implicit Euler runs: the
    last step's :meth:`Simulation.solver_report`, with the worst relative residual over the
    run and the number of steps that needed load stepping; null for explicit integrators),
    ``frames``, ``wall_seconds`` (the whole run),
    ``step_seconds`` (in steps only), ``steps_per_second``, ``outputs`` and
    ``topomech_version`` (a number that is not finite, after a divergence, is null); plus
    ``error`` (``type``, ``message``, and ``step``, ``vertex`` for a divergence, ``event`` for
    a timed cut that separated nothing) when a step failed.

    ``progress``: True for a progress bar on stderr, or a callable ``(done, total)``.
    ``preview``: track the energies and render ``preview.gif``, ``energy.png`` (and
    ``preview.mp4`` with ``video``, when an encoder is installed); the frames for the viewer
    (``view.json``) are written either way. ``outputs`` names each file written (None for
    those that were not).
    Raises :class:`SceneError` for a scene that is refused (nothing is written then), an
    event after the end of the run included (with ``steps`` too), and an unknown name in
    ``output.fields`` (naming ``output.fields[i]`` and the available names).
    """
    t0 = time.perf_counter()
    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    if steps is not None or every is not None:
        sc = sc.with_steps(steps, every)
    out_dir = Path(out) if out is not None else Path("out") / sc.name
    sim = sc.build()
    fields = check_fields(sim, getattr(sc, "fields", ()), sc.path)

    out_dir.mkdir(parents=True, exist_ok=True)
    frames_dir = out_dir / "frames"
    for old in frames_dir.glob("frame_*.vtu") if frames_dir.is_dir() else ():
        old.unlink()
    for stale in (
        "animation.pvd",
        "final.vtu",
        "summary.json",
        "view.json",
        "view.bin",
        "viewer.html",
        "energy.csv",
        "energy.png",
        "preview.gif",
        "preview.mp4",
    ):
        (out_dir / stale).unlink(missing_ok=True)
    cells = OutputCells(sim, _input_cells(sc))
    writer = _Writer(sim, cells, fields)
    recorder = Recorder(sim, sc, energy=preview, cells=cells, out_dir=out_dir)
    frames: list[tuple[float, str]] = []

    def frame() -> None:
        frames_dir.mkdir(exist_ok=True)
        name = f"frame_{len(frames):05d}.vtu"
        writer.write(frames_dir / name)
        recorder.frame()
        frames.append((sim.time, f"frames/{name}"))

    recorder.start()

    if sc.every > 0:
        frame()
    bar: Progress | None = None
    report: Callable[[int, int], None] | None = None
    if progress is True:
        bar = Progress(sc.name, sc.steps)
    elif callable(progress):
        report = progress
    error: dict[str, Any] | None = None
    step_seconds = 0.0
    try:
        for k in range(1, sc.steps + 1):
            ts = time.perf_counter()
            sim.step()
            step_seconds += time.perf_counter() - ts
            recorder.after_step()
            if sc.every > 0 and (k % sc.every == 0 or k == sc.steps):
                frame()
            if bar is not None:
                bar.update(k)
            if report is not None:
                report(k, sc.steps)
    except DivergenceError as e:
        error = {
            "type": "divergence",
            "message": str(e),
            "step": int(e.step),
            "vertex": int(e.vertex),
        }
    except SimulationError as e:
        missed = _missed_event(sc, sim, str(e))
        if missed is None:
            error = {"type": "simulation", "message": str(e), "step": sim.steps + 1}
        else:
            error = {
                "type": "event",
                "message": (
                    f"event[{missed}] ({_describe_event(sc.events[missed])}) separates "
                    f"nothing at step {sim.steps} (t = {sim.time:g}): it misses the object"
                ),
                "step": sim.steps,
                "event": missed,
            }
    except KeyboardInterrupt:
        error = {"type": "interrupted", "message": "interrupted", "step": sim.steps + 1}
    finally:
        if bar is not None:
            bar.close(sim.steps)
    writer.write(out_dir / "final.vtu")
    counts = sim.gmap().cell_counts()  # of the final map: a topology change changes them
    if frames:
        write_pvd(out_dir / "animation.pvd", frames)
    changes = [dict(c) for c in sim.topology_changes()]
    recorder.finish()
    outputs: dict[str, str | None] = {
        "view": "view.json" if recorder.write_view(out_dir, changes) else None,
        "energy": "energy.csv" if recorder.write_energy(out_dir / "energy.csv") else None,
        "preview": None,
        "video": None,
        "energy_plot": None,
    }
    if preview and (error is None or error["type"] != "interrupted"):
        from topomech.render import render_previews

        outputs.update(render_previews(out_dir, video=video, name=sc.name, events=changes))
    summary: dict[str, Any] = {
        "scene": str(sc.path) if sc.path is not None else None,
        "name": sc.name,
        "dimension": sim.dimension,
        "models": sc.config["models"],
        "integrator": sc.integrator,
        "dt": sc.dt,
        "steps": sim.steps,
        "steps_requested": sc.steps,
        "time": sim.time,
        "darts": counts["darts"],
        "vertices": counts["vertices"],
        "edges": counts["edges"],
        "faces": counts["faces"],
        "volumes": counts["volumes"],
        "components": counts["components"],
        "topology_changes": changes,
        "total_mass": sim.total_mass(),
        "kinetic_energy": sim.kinetic_energy(),
        "momentum": [float(x) for x in sim.momentum()],
        "max_displacement": _max_displacement(sim),
        "solver": sim.solver_report(),
        "frames": len(frames),
        "wall_seconds": time.perf_counter() - t0,
        "step_seconds": step_seconds,
        "steps_per_second": sim.steps / step_seconds if step_seconds > 0 else None,
        "outputs": {
            "summary": "summary.json",
            "final": "final.vtu",
            "animation": "animation.pvd" if frames else None,
            **outputs,
            "frames": [f for _, f in frames],
        },
        "topomech_version": __version__,
    }
    if error is not None:
        summary["error"] = error
    summary = _json_safe(summary)
    text = json.dumps(summary, indent=2, allow_nan=False)
    (out_dir / "summary.json").write_text(text + "\n", encoding="utf-8")
    if error is not None and error["type"] == "interrupted":
        raise KeyboardInterrupt
    return summary
