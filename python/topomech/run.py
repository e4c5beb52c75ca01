"""Running a scene to files: frames, the final state and a summary.

:func:`run_scene` writes, under the output directory:

- ``summary.json``: what ran and how it ended (see :func:`run_scene` for the keys);
- ``final.tmg``, with ``save_map`` (``topomech run --save-map``) after a topology change (a
  cut, a fracture): the final map itself with every embedding (:meth:`GMap.save`; about 4
  KB per tetrahedron for a co-rotational run), which :func:`read_gmap` and ``topomech info``
  read back with its pieces apart, where ``final.vtu`` of pieces that moved into each other
  is refused as a mesh (overlapping cells);
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
  see :mod:`topomech.render`) and ``preview.mp4`` when imageio-ffmpeg's encoder is installed;
- for ``static`` and ``implicit_euler`` runs: ``solver.csv``, one row a step: ``step``,
  ``time``, ``integrator``, ``linear_solver``, ``preconditioner``, ``iterations`` (Newton
  iterations, static; linear iterations, implicit Euler), ``linear_iterations``, ``residual``,
  ``relative_residual``, ``tolerance``, ``converged`` (1 or 0) and ``load_steps``. A step
  whose linear solve stopped at ``max_iterations`` above its tolerance is taken with the
  approximate solution and makes the run end with a :class:`SolverWarning` (a note on the
  command line); a static solve that does not converge is an error (a divergence).

``summary.json`` splits the run's wall time (``time.perf_counter``) into ``timings``:
``setup_s`` (reading the scene, building the mesh and the simulation, preparing the output
folder; from the CLI, from the moment its command line is read), ``stepping_s`` (the
:meth:`Simulation.step` calls alone), ``output_s`` (the frames, the energies recorded after
each step, ``final.vtu``, ``animation.pvd``, the view data, the summary, and the moments
between the steps: the progress display), ``preview_s`` (``preview.gif``, ``preview.mp4``,
``energy.png``) and ``total_s``. Every moment of the run counts for the phase it falls in, so
the four parts add up to ``total_s``; the total runs until the summary is complete, just
before ``summary.json`` is written. ``wall_seconds`` is ``total_s`` (kept for
compatibility), ``step_seconds`` is ``stepping_s`` and ``steps_per_second`` is ``steps /
stepping_s``. ``mesh`` gives the cell counts (``darts``, ``vertices``, ``edges``, ``faces``,
``volumes``, ``components``) of the ``input`` (the map as built from the scene's mesh, before
any step) and of the ``final`` map; they differ after a cut or a fracture, which split
vertices. The top-level ``darts``, ``vertices``, ... are the final ones.

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
from topomech._core import (
    DivergenceError,
    MeshError,
    SceneError,
    SimulationError,
    TopomechError,
)
from topomech._manifest import OutputError, OutputFolder
from topomech._output import OutputCells, check_fields, field_values
from topomech._solver_log import SolverLog, SolverWarning
from topomech.recording import Recorder
from topomech.scene import Scene, load_scene, name_problem

if TYPE_CHECKING:
    import meshio

    from topomech._gmap import PathLike
    from topomech.simulation import Simulation

__all__ = ["OutputError", "Progress", "ProgressLog", "run_scene", "write_pvd"]

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
    "mesh",
    "timings",
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


#: The default of :func:`run_scene`'s ``log_interval``: the environment variable
#: ``TOPOMECH_PROGRESS_INTERVAL_S`` (seconds), else :data:`LOG_INTERVAL_S`.
LOG_INTERVAL_ENV = "TOPOMECH_PROGRESS_INTERVAL_S"
LOG_INTERVAL_S = 10.0


def log_interval_default() -> float:
    """The progress log's interval: ``$TOPOMECH_PROGRESS_INTERVAL_S`` when it is a finite
    number >= 0, else :data:`LOG_INTERVAL_S`."""
    text = os.environ.get(LOG_INTERVAL_ENV, "").strip()
    if text:
        with contextlib.suppress(ValueError):
            v = float(text)
            if math.isfinite(v) and v >= 0:
                return v
    return LOG_INTERVAL_S


def _secs(x: float) -> str:
    """Seconds for a log line: one decimal under a minute, whole seconds above."""
    return f"{x:.1f}" if x < 60 else f"{x:.0f}"


class ProgressLog:
    """Progress as log lines, for a stream that is not a terminal (a pipe, a file, a CI log):
    ``NAME: step N/M, t = T s, X steps/s, ETA E s``, at most one every ``interval`` seconds,
    and one at the end (``done in S s``, or ``stopped`` when the run stopped early). The rate
    is over the wall time since the first step began (frames included), so the ETA holds; the
    report's steps/s counts the stepping alone."""

    def __init__(
        self,
        label: str,
        total: int,
        stream: TextIO | None = None,
        interval: float = LOG_INTERVAL_S,
    ) -> None:
        self.label = label
        self.total = total
        self.stream = stream if stream is not None else sys.stdout
        self.interval = interval
        self.start = time.perf_counter()
        self.last = self.start
        self.lines = 0
        self.closed = False  # the stream went away (a pipe closed early): no more lines

    def _line(self, done: int, t: float, now: float, tail: str) -> None:
        if self.closed:
            return
        elapsed = now - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        try:
            self.stream.write(
                f"{self.label}: step {done}/{self.total}, t = {t:.6g} s, {rate:.0f} steps/s, "
                f"{tail}\n"
            )
            self.stream.flush()
        except (OSError, ValueError):
            # `topomech run X | head -1`: the run goes on and writes its files; the report
            # meets the closed pipe as before
            self.closed = True
            return
        self.lines += 1

    def update(self, done: int, t: float) -> None:
        """After step ``done``, at simulated time ``t``: a line when ``interval`` seconds
        have passed since the last one (or since the start)."""
        now = time.perf_counter()
        if now - self.last < self.interval or done >= self.total:
            return  # the last step's line is the end line
        self.last = now
        elapsed = now - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = f"ETA {_secs((self.total - done) / rate)} s" if rate > 0 else "ETA unknown"
        self._line(done, t, now, eta)

    def close(self, done: int, t: float) -> None:
        """The end line."""
        now = time.perf_counter()
        tail = f"done in {_secs(now - self.start)} s" if done >= self.total else "stopped"
        self._line(done, t, now, tail)


#: The phases of a run's wall time, as ``summary.json``'s ``timings`` names them (``_s``).
TIMING_PHASES = ("setup", "stepping", "output", "preview")

#: The timing phase of each phase of :data:`PHASES`: the moments from entering one phase to
#: entering the next count for it (the steps phase: all but the ``Simulation.step`` calls,
#: which the loop counts as stepping itself).
_TIMING_OF = {
    "setup": "setup",
    "steps": "output",
    "frames": "output",
    "final": "output",
    "view": "output",
    "previews": "preview",
    "summary": "output",
}


class _Clock:
    """Splits a run's wall time into :data:`TIMING_PHASES`: each moment counts for the phase
    current then, so the parts add up to the total."""

    def __init__(self, start: float) -> None:
        self.start = start
        self.mark = start
        self.current = "setup"
        self.spent = dict.fromkeys(TIMING_PHASES, 0.0)

    def to(self, phase: str) -> None:
        """From now on the time counts for ``phase``."""
        now = time.perf_counter()
        self.spent[self.current] += now - self.mark
        self.mark = now
        self.current = phase

    def timings(self) -> dict[str, float]:
        """The time spent so far in each phase (``setup_s``, ...) and ``total_s``."""
        self.to(self.current)
        out = {f"{p}_s": self.spent[p] for p in TIMING_PHASES}
        out["total_s"] = self.mark - self.start
        return out


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
        """Writes the VTU at ``path`` through a file beside it (``<name>.part``), renamed
        when complete and removed on any failure, so that an interruption (Ctrl-C, SIGTERM,
        a full disk) never leaves a truncated VTU under the name (QA: a frame cut off by a
        signal was left, and meshio could not read it)."""
        import meshio

        part = path.with_name(path.name + ".part")
        try:
            meshio.write(os.fspath(part), self.mesh(), file_format="vtu")
            part.replace(path)
        except BaseException:
            with contextlib.suppress(OSError):
                part.unlink()
            raise


def _input_cells(sc: Scene) -> FlatMesh | None:
    """The cells of the scene's mesh file as the map was built from them (``cell_id``
    numbers them), or None for a generated mesh, a saved map or a file that cannot be read
    again (the output then orients the cells at rest without them). The file is not read
    again: :meth:`Scene.file_mesh` keeps what building the simulation read."""
    m = sc.mesh
    if m.file is None or m.file.suffix.lower() == ".tmg":
        return None
    try:
        # read again only when the scene was built elsewhere: what the file had to say was
        # said the first time
        with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):
            warnings.simplefilter("ignore")
            mesh = sc.file_mesh()
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
#: The kernel's message for a blade that crossed nothing (k: its index among the blades).
_BLADE_MISSED = re.compile(r"blade (\d+) moved from t = \S+ to t = \S+ and crossed nothing")


def _describe_event(e: dict[str, Any]) -> str:
    """An event as a message shows it: ``a cut at t = 0.5 along the plane ...``."""
    if e.get("kind") == "blade":
        return f"a blade moving from t = {float(e['start']):g} to t = {float(e['end']):g}"
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
    b = _BLADE_MISSED.search(message)
    if b is not None:
        blades = [i for i, e in enumerate(sc.events) if e.get("kind") == "blade"]
        k = int(b.group(1))
        return blades[k] if k < len(blades) else None
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
    timed = [(i, float(e["time"])) for i, e in enumerate(sc.events) if "time" in e]
    due = [i for i, t in timed if lower < t <= sim.time + tol]
    done = sum(1 for c in sim.topology_changes() if c["kind"] == "cut" and c["step"] == sim.steps)
    if done < len(due) and float(sc.events[due[done]]["time"]) == t_msg:
        return due[done]
    same = [i for i, t in timed if t == t_msg]
    return same[0] if same else None


#: What a run is doing, as an interruption or an I/O error reports it (``error.phase``).
PHASES = {
    "setup": "setting up (building the simulation, preparing the output folder)",
    "steps": "stepping",
    "frames": "writing a frame",
    "final": "writing final.vtu and animation.pvd",
    "view": "writing the view data and energies",
    "previews": "rendering the previews",
    "summary": "writing summary.json",
}


def _interrupted(phase: str, sim: Simulation | None, steps_requested: int) -> dict[str, Any]:
    """The summary's ``error`` for a Ctrl-C during ``phase``."""
    done = sim.steps if sim is not None else 0
    err: dict[str, Any] = {
        "type": "interrupted",
        "message": (f"interrupted while {PHASES[phase]}, after {done} of {steps_requested} steps"),
        "phase": phase,
        "steps_done": done,
    }
    if phase == "steps":
        err["step"] = done + 1
    return err


def _failed_path(e: OSError, writing: Sequence[Path]) -> str:
    """The file an OSError is about: its ``filename``, else the one of the files being
    written that was touched last (the others of ``writing`` were written before it, or not
    yet created), else the first of them."""
    if e.filename is not None:
        # a VTU is written through `<name>.part` (see _Writer.write): the file is `<name>`
        name = os.fsdecode(e.filename)
        return name.removesuffix(".part") if name.endswith(".vtu.part") else name
    best: tuple[int, int] | None = None
    found: Path | None = None
    for i, p in enumerate(writing):
        with contextlib.suppress(OSError):
            key = (os.lstat(p).st_mtime_ns, i)
            if best is None or key > best:
                best, found = key, p
    if found is None and writing:
        found = writing[0]
    return str(found) if found is not None else "(unknown file)"


def _io_error(e: OSError, phase: str, writing: Sequence[Path], steps: int) -> dict[str, Any]:
    """The summary's ``error`` for a file that could not be written."""
    import errno

    path = _failed_path(e, writing)
    reason = e.strerror or str(e) or type(e).__name__
    return {
        "type": "io",
        "message": f"{path}: could not be written: {reason} (while {PHASES[phase]})",
        "path": path,
        "errno": errno.errorcode.get(e.errno, None) if e.errno is not None else None,
        "phase": phase,
        "steps_done": steps,
    }


@contextlib.contextmanager
def _interrupts_held() -> Any:
    """SIGINT and SIGTERM (which ``topomech run`` handles as Ctrl-C) held back, delivered on
    leaving, in the main thread, where that is possible: the summary of an interruption is
    written whole."""
    import signal
    import threading

    held = False
    signals = {signal.SIGINT, signal.SIGTERM}
    if hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread():
        with contextlib.suppress(OSError, ValueError):
            signal.pthread_sigmask(signal.SIG_BLOCK, signals)
            held = True
    try:
        yield
    finally:
        if held:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, signals)


def _enter(phase: str) -> None:
    """Marks the start of ``phase`` (tests replace it to interrupt a run at a given phase)."""


def run_scene(
    scene: Scene | PathLike,
    out: PathLike | None = None,
    *,
    steps: int | None = None,
    every: int | None = None,
    progress: bool | Callable[[int, int], None] = False,
    preview: bool = True,
    video: bool = True,
    overwrite: bool = False,
    log: bool | TextIO = False,
    log_interval: float | None = None,
    started: float | None = None,
    save_map: bool = False,
) -> dict[str, Any]:
    """Runs a scene (a :class:`Scene` or a scene file) and writes its outputs under ``out``
    (default ``out/<scene name>``); ``steps`` and ``every`` override the scene's;
    ``save_map`` writes ``final.tmg`` after a topology change (see the module's
    documentation). Returns the
    summary written to ``summary.json``: ``scene``, ``name``, ``dimension``, ``models``,
    ``integrator``, ``dt``, ``steps`` (done), ``steps_requested``, ``time``, ``darts``,
    ``vertices``, ``edges``, ``faces``, ``volumes``, ``components`` (connected components of
    the final map: 2 or more once a cut or a fracture split the object), ``topology_changes``
    (a list of ``{"step", "time", "kind": "cut" | "fracture", "unsewn"}``, ``unsewn`` counting
    the faces, in 3D, or edges, in 2D, opened), ``total_mass``, ``kinetic_energy``,
    ``momentum``, ``max_displacement``, ``solver`` (static and implicit Euler runs: the
    last step's :meth:`Simulation.solver_report`, with the worst relative residual over the
    run and the number of steps that needed load stepping, and the run's totals
    ``steps_solved``, ``steps_not_converged``, ``total_iterations``,
    ``total_linear_iterations``, ``mean_linear_iterations`` and ``max_relative_residual``
    (see :mod:`topomech._solver_log`; per step in ``solver.csv``); null for explicit
    integrators),
    ``frames``, ``mesh`` (``{"input": counts, "final": counts}``, the counts being
    ``darts``, ``vertices``, ``edges``, ``faces``, ``volumes`` and ``components``: of the
    map as built, before any step, and at the end), ``timings`` (``setup_s``,
    ``stepping_s``, ``output_s``, ``preview_s`` and ``total_s``, their sum: see the module's
    documentation), ``wall_seconds`` (``total_s``), ``step_seconds`` (``stepping_s``),
    ``steps_per_second`` (``steps / stepping_s``), ``outputs`` and
    ``topomech_version`` (a number that is not finite, after a divergence, is null; one not
    known, after an interruption during set-up, is null too); plus ``error`` when the run
    stopped early: ``type`` and ``message`` always; ``"divergence"`` with ``step`` and
    ``vertex``; ``"simulation"`` with ``step``; ``"event"`` (a timed cut that separated
    nothing) with ``step`` and ``event``; ``"io"`` (a file could not be written: a full disk,
    a file size limit) with ``path`` (the file), ``errno`` (``"ENOSPC"``, ...), ``phase``
    and ``steps_done``; ``"interrupted"`` (Ctrl-C) with ``phase`` and ``steps_done`` (and
    ``step``, the step cut short, when the phase is ``"steps"``). The phases are
    ``setup``, ``steps``, ``frames``, ``final``, ``view``, ``previews``, ``summary``.

    The output folder keeps a manifest, ``.topomech-manifest.jsonl`` (see
    :mod:`topomech._manifest`): each file is listed there before it is created, and a rerun
    removes only what it lists, never following a symbolic link. A folder holding files that
    no manifest lists is refused (:class:`~topomech._manifest.OutputError`, nothing written)
    unless ``overwrite``: then files named like the outputs are replaced and the others
    kept. A missing or empty folder is fine.

    After an interruption or an I/O error what was written stays and ``summary.json`` says
    what happened: after Ctrl-C during the steps or a frame, ``final.vtu`` and the view data
    are still written (not the previews); after an I/O error nothing more but the summary.
    A Ctrl-C is raised again (:class:`KeyboardInterrupt`) once the summary is written (any
    KeyboardInterrupt counts as one: ``topomech run`` raises it for SIGTERM too). When
    ``summary.json`` itself cannot be written the summary is returned with an ``io`` error
    naming it (and ``outputs.summary`` null).

    ``progress``: True for a progress bar on stderr, or a callable ``(done, total)``.
    ``log``: progress as log lines (:class:`ProgressLog`) on stdout (True) or on the stream
    given, at most one every ``log_interval`` seconds (default: the environment variable
    ``TOPOMECH_PROGRESS_INTERVAL_S``, else 10) and one at the end. ``started``: the
    :func:`time.perf_counter` value at which the run began (the command line passes the
    moment it started reading its arguments), so that ``timings.setup_s`` counts from it;
    default: the call.
    ``preview``: track the energies and render ``preview.gif``, ``energy.png`` (and
    ``preview.mp4`` with ``video``, when an encoder is installed); the frames for the viewer
    (``view.json``) are written either way. ``outputs`` names each file written (None for
    those that were not).
    Raises :class:`SceneError` for a scene that is refused (nothing is written then), an
    event after the end of the run included (with ``steps`` too), an unknown name in
    ``output.fields`` (naming ``output.fields[i]`` and the available names) and, without
    ``out``, a scene name that is not a plain folder name; :class:`OutputError` for an
    output folder that is refused (see above) or cannot be created.
    """
    clock = _Clock(started if started is not None else time.perf_counter())
    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    if steps is not None or every is not None:
        sc = sc.with_steps(steps, every)
    if out is None:
        problem = name_problem(sc.name)
        if problem is not None:
            where = str(sc.path) if sc.path is not None else "<scene>"
            raise SceneError(f"{where}: name: {problem}")
    out_dir = Path(out) if out is not None else Path("out") / sc.name
    folder = OutputFolder(out_dir, overwrite=overwrite)
    folder.check()
    frames_dir = out_dir / "frames"

    sim: Simulation | None = None
    recorder: Recorder | None = None
    writer: _Writer | None = None
    solver_log = SolverLog()
    frames: list[tuple[float, str]] = []
    error: dict[str, Any] | None = None
    outputs: dict[str, str | None] = {
        "view": None,
        "energy": None,
        "preview": None,
        "video": None,
        "energy_plot": None,
        "solver": None,
        "map": None,
    }
    final_written = False
    input_counts: dict[str, int] | None = None
    phase = "setup"
    writing: list[Path] = []  # the files the phase is writing, for an OSError's message
    bar: Progress | None = None
    lines: ProgressLog | None = None

    def enter(name: str, files: Sequence[str] = ()) -> None:
        """Starts a phase that writes ``files`` (listed in the manifest first)."""
        nonlocal phase, writing
        phase = name
        clock.to(_TIMING_OF[name])
        _enter(name)
        writing = [folder.add(f) for f in files]

    def stop(e: BaseException) -> None:
        """Records why the run stops (the first reason counts)."""
        nonlocal error
        if error is not None and error["type"] in ("interrupted", "io"):
            return
        if isinstance(e, KeyboardInterrupt):
            new = _interrupted(phase, sim, sc.steps)
        else:
            assert isinstance(e, OSError)
            new = _io_error(e, phase, writing, sim.steps if sim is not None else 0)
        if error is not None:
            new["after"] = error  # a divergence, say, whose outputs were being written
        error = new

    try:
        _enter("setup")
        sim = sc.build()
        input_counts = _counts(sim)
        fields = check_fields(sim, getattr(sc, "fields", ()), sc.path)
        cells = OutputCells(sim, _input_cells(sc))
        try:
            cells.elements()
        except (MeshError, SimulationError) as e:
            # refused before a step is taken and before the output folder is made: every
            # frame and final.vtu list the elements by kind (a saved map whose volumes a
            # rewrite made general polyhedra has none of a kind)
            where = str(sc.path) if sc.path is not None else "<scene>"
            raise SceneError(
                f"{where}: mesh.file: the run's output files (final.vtu, the frames) list "
                f"its cells by kind, and this map's are not of a kind: {e} (step such a map "
                "from Python, topomech.Simulation, and write it with topomech.io.write_gmap to "
                "a .vtu, every volume a polyhedron, or a .tmg)"
            ) from None
        folder.prepare()
        for rel in ("view.bin", "view.json", "energy.csv"):
            folder.add(rel)  # before the recorder starts: it may write them as it goes
        writer = _Writer(sim, cells, fields)
        recorder = Recorder(sim, sc, energy=preview, cells=cells, out_dir=out_dir)

        def frame() -> None:
            assert writer is not None
            assert recorder is not None
            assert sim is not None
            name = f"frame_{len(frames):05d}.vtu"
            enter("frames", ["frames"])
            frames_dir.mkdir(exist_ok=True)
            # (and the file it is written through, see _Writer.write: listed, so that a
            # kill leaving it does not make the folder look like the user's)
            enter("frames", [f"frames/{name}", f"frames/{name}.part"])
            writer.write(frames_dir / name)
            recorder.frame()
            frames.append((sim.time, f"frames/{name}"))
            enter("steps")

        recorder.start()

        if sc.every > 0:
            frame()
        enter("steps")
        report: Callable[[int, int], None] | None = None
        if progress is True:
            bar = Progress(sc.name, sc.steps)
        elif callable(progress):
            report = progress
        if log is not False:
            interval = log_interval if log_interval is not None else log_interval_default()
            stream = None if log is True else log
            lines = ProgressLog(sc.name, sc.steps, stream, interval)
        try:
            for k in range(1, sc.steps + 1):
                clock.to("stepping")
                sim.core.step(1)  # the kernel's: the run reports unmet tolerances at its end
                clock.to("output")
                solver_log.after_step(sim)
                recorder.after_step()
                if sc.every > 0 and (k % sc.every == 0 or k == sc.steps):
                    frame()
                if bar is not None:
                    bar.update(k)
                if lines is not None:
                    lines.update(k, sim.time)
                if report is not None:
                    report(k, sc.steps)
        except DivergenceError as e:
            solver_log.after_step(sim, failed=True)
            error = {
                "type": "divergence",
                "message": str(e),
                "step": int(e.step),
                "vertex": None if e.vertex is None else int(e.vertex),
                "point": None if e.point is None else int(e.point),
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
                        f"nothing at step {sim.steps} (t = {sim.time:g}): it misses the object, "
                        "or every face it meets is open already, or the element centroids it "
                        "meets lie on it (a centroid on it is on neither side)"
                    ),
                    "step": sim.steps,
                    "event": missed,
                }
        finally:
            clock.to("output")
            if bar is not None:
                with contextlib.suppress(OSError, ValueError):
                    bar.close(sim.steps)
            if lines is not None:
                with contextlib.suppress(OSError, ValueError):
                    lines.close(sim.steps, sim.time)
    except (KeyboardInterrupt, OSError) as e:
        if isinstance(e, OSError) and not folder.prepared:
            raise  # not one of the run's files (a preparation failure is an OutputError)
        stop(e)

    # what is left to write after the steps: the final state and the view data (also after a
    # Ctrl-C during the steps or a frame), then the previews (not after a Ctrl-C)
    changes: list[dict[str, Any]] = []
    interrupted_early = error is not None and error["type"] == "interrupted"
    io_failed = error is not None and error["type"] == "io"
    in_setup = error is not None and error.get("phase") == "setup"
    if (
        sim is not None
        and writer is not None
        and recorder is not None
        and not io_failed
        and not in_setup
    ):
        try:
            enter("final", ["final.vtu", "final.vtu.part"])
            writer.write(out_dir / "final.vtu")
            final_written = True
            if save_map and sim.topology_changes():
                # the cut map itself: its pieces may have moved into each other, which a mesh
                # file cannot tell apart from one body (final.vtu would be refused as input)
                # (written whole, then renamed: an interruption leaves no truncated map)
                enter("final", ["final.tmg", "final.tmg.part"])
                sim.gmap().save(out_dir / "final.tmg.part")
                (out_dir / "final.tmg.part").replace(out_dir / "final.tmg")
                outputs["map"] = "final.tmg"
            if frames:
                enter("final", ["animation.pvd"])
                write_pvd(out_dir / "animation.pvd", frames)
            if solver_log.rows:
                enter("final", ["solver.csv"])
                outputs["solver"] = (
                    "solver.csv" if solver_log.write(out_dir / "solver.csv") else None
                )
            changes = [dict(c) for c in sim.topology_changes()]
            enter("view", ["view.bin", "view.json", "energy.csv"])
            recorder.finish()
            outputs["view"] = "view.json" if recorder.write_view(out_dir, changes) else None
            outputs["energy"] = (
                "energy.csv" if recorder.write_energy(out_dir / "energy.csv") else None
            )
            folder.adopt()
            if preview and not interrupted_early:
                enter("previews", ["preview.gif", "preview.mp4", "energy.png"])
                from topomech.render import render_previews

                outputs.update(render_previews(out_dir, video=video, name=sc.name, events=changes))
                folder.adopt()
        except (KeyboardInterrupt, OSError) as e:
            stop(e)
    elif sim is not None:
        changes = [dict(c) for c in sim.topology_changes()]

    clock.to("output")
    summary = _summary(sc, sim, clock, input_counts, frames, outputs, final_written, changes)
    if sim is not None:
        summary["solver"] = solver_log.summary(summary["solver"])
    if error is not None:
        summary["error"] = error
    try:
        try:
            if not folder.prepared:  # interrupted during set-up
                folder.prepare()
            folder.adopt()
            enter("summary", ["summary.json"])
            _write_summary(out_dir / "summary.json", summary)
        except KeyboardInterrupt as e:
            stop(e)
            summary["error"] = error
            with _interrupts_held():
                _write_summary(folder.add("summary.json"), summary)
    except OSError as e:
        stop(e)
        summary["error"] = error
        summary["outputs"]["summary"] = None
    safe: dict[str, Any] = _json_safe(summary)
    if error is not None and error["type"] == "interrupted":
        raise KeyboardInterrupt
    unmet = solver_log.warning()
    if unmet is not None:
        warnings.warn(unmet, SolverWarning, stacklevel=2)
    return safe


def _write_summary(path: Path, summary: dict[str, Any]) -> None:
    """Writes ``summary.json``; a file left half-written (by a full disk, a Ctrl-C) is
    removed."""
    text = json.dumps(_json_safe(summary), indent=2, allow_nan=False)
    try:
        path.write_text(text + "\n", encoding="utf-8")
    except BaseException:
        with contextlib.suppress(OSError):
            path.unlink()
        raise


def _counts(sim: Simulation) -> dict[str, int]:
    """The cell counts of the simulation's map now (``mesh.input`` and ``mesh.final``)."""
    c = sim.gmap().cell_counts()
    return {
        "darts": c["darts"],
        "vertices": c["vertices"],
        "edges": c["edges"],
        "faces": c["faces"],
        "volumes": c["volumes"],
        "components": c["components"],
    }


def _summary(
    sc: Scene,
    sim: Simulation | None,
    clock: _Clock,
    input_counts: dict[str, int] | None,
    frames: list[tuple[float, str]],
    outputs: dict[str, str | None],
    final_written: bool,
    changes: list[dict[str, Any]],
) -> dict[str, Any]:
    """The summary of a run (see :func:`run_scene`); the values a simulation that was never
    built would give are null."""
    known: dict[str, Any] = {}
    final_counts: dict[str, int] | None = None
    if sim is not None:
        # of the final map: a topology change changes them
        counts = final_counts = _counts(sim)
        known = {
            "dimension": sim.dimension,
            "steps": sim.steps,
            "time": sim.time,
            "darts": counts["darts"],
            "vertices": counts["vertices"],
            "edges": counts["edges"],
            "faces": counts["faces"],
            "volumes": counts["volumes"],
            "components": counts["components"],
            "total_mass": sim.total_mass(),
            "kinetic_energy": sim.kinetic_energy(),
            "momentum": [float(x) for x in sim.momentum()],
            "max_displacement": _max_displacement(sim),
            "solver": sim.solver_report(),
        }
    summary: dict[str, Any] = {
        "scene": str(sc.path) if sc.path is not None else None,
        "name": sc.name,
        "dimension": None,
        "models": sc.config["models"],
        "integrator": sc.integrator,
        "dt": sc.dt,
        "steps": 0,
        "steps_requested": sc.steps,
        "time": 0.0,
        "darts": None,
        "vertices": None,
        "edges": None,
        "faces": None,
        "volumes": None,
        "components": None,
        "topology_changes": changes,
        "total_mass": None,
        "kinetic_energy": None,
        "momentum": None,
        "max_displacement": None,
        "solver": None,
        "frames": len(frames),
        "mesh": {"input": input_counts, "final": final_counts},
        "timings": None,
        "wall_seconds": None,
        "step_seconds": None,
        "steps_per_second": None,
        "outputs": {
            "summary": "summary.json",
            "final": "final.vtu" if final_written else None,
            "animation": "animation.pvd" if frames and final_written else None,
            **outputs,
            "frames": [f for _, f in frames],
        },
        "topomech_version": __version__,
    }
    summary.update(known)
    # last: the total runs until the summary is complete
    timings = clock.timings()
    stepping = timings["stepping_s"]
    summary["timings"] = timings
    summary["wall_seconds"] = timings["total_s"]
    summary["step_seconds"] = stepping
    if sim is not None and stepping > 0:
        summary["steps_per_second"] = sim.steps / stepping
    return summary
