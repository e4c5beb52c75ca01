"""The ``topomech`` command.

Each subcommand is a pair of functions: ``_add_NAME(subparsers)`` declares its arguments and
``_run_NAME(args) -> exit code`` does the work. Exit codes: 0 success, 1 the input was read but
fails on its merits (an invalid G-map, a rule the checker refuses, a rule that does not apply,
a simulation that diverges, a timed cut that misses the object when its time comes, a run
that cannot write one of its files: a full disk), 2 a file
cannot be read or is refused (a scene included, with an event after the end of the run, and
an output directory holding files topomech did not write), or
the arguments are wrong (the reason goes to stderr, without a traceback); 130 a run
interrupted by Ctrl-C and 143 one stopped by SIGTERM (``kill``, a batch scheduler, a
container's stop), handled as Ctrl-C is: what was written stays, with its summary.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import signal
import sys
import threading
import time
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, Callable, TextIO

from topomech import __version__
from topomech._cells import MESH_FILE_CELLS, flat_to_blocks, mesh_figures
from topomech._core import ApplyError, MeshError, RuleError, SceneError, TopomechError
from topomech._paths import read_text_file
from topomech.io import DUPLICATES, PINCHED, ImportedMesh, import_mesh, write_format, write_gmap
from topomech.models import Model, shipped_models
from topomech.rules import _MODEL_DECLARATION, ParamValue, RuleSet

__all__ = ["build_parser", "main"]

EXIT_OK = 0
EXIT_INVALID = 1
EXIT_REFUSED = 2
#: Ctrl-C during `run` or `demo` (the shell's code for SIGINT).
EXIT_INTERRUPTED = 130
#: SIGTERM during `run` or `demo` (the shell's code for it): handled as Ctrl-C is.
EXIT_TERMINATED = 128 + int(getattr(signal, "SIGTERM", 15))

#: Violations listed by `info` before "... and N more".
MAX_VIOLATIONS_SHOWN = 20


def _note(msg: str) -> None:
    print(f"topomech: note: {msg}", file=sys.stderr)


def _error(msg: str) -> None:
    print(f"topomech: error: {msg}", file=sys.stderr)


#: The scene warnings printed so far (a scene is checked more than once: each said once).
_scene_warnings: set[str] = set()
_default_showwarning = warnings.showwarning


def _show_scene_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: TextIO | None = None,
    line: str | None = None,
) -> None:
    """A :class:`topomech.scene.SceneWarning` as a note (once); other warnings as Python
    shows them."""
    from topomech._solver_log import SolverWarning
    from topomech.scene import SceneWarning

    if issubclass(category, (SceneWarning, SolverWarning)):
        if str(message) not in _scene_warnings:
            _scene_warnings.add(str(message))
            _note(str(message))
        return
    _default_showwarning(message, category, filename, lineno, file, line)


# ---------------------------------------------------------------------------------- info


def _add_import_options(p: argparse.ArgumentParser) -> None:
    """The options of every command that reads a mesh file."""
    g = p.add_argument_group(
        "import options", "how a mesh file becomes a G-map (ignored for a saved .tmg)"
    )
    g.add_argument(
        "--reorient",
        action=argparse.BooleanOptionalAction,
        default=True,
        help=(
            "turn cells listed with the opposite orientation over, so that all agree "
            "(default); --no-reorient refuses them"
        ),
    )
    g.add_argument(
        "--pinched",
        choices=PINCHED,
        default=PINCHED[0],
        help=(
            "points where cells touch only at that point: merge (default: one particle), "
            "split (one vertex per side), refuse"
        ),
    )
    g.add_argument(
        "--duplicates",
        choices=DUPLICATES,
        default=DUPLICATES[0],
        help="cells listed twice (same vertices): refuse (default) or merge",
    )
    g.add_argument(
        "--linear",
        action="store_true",
        help=(
            "keep the corner nodes of second-order cells (tetra10, hexahedron20, triangle6, "
            "...); the other nodes are left out"
        ),
    )


def _import(path: Path, args: argparse.Namespace) -> ImportedMesh:
    """The mesh file read and built with the command's import options; the notes go to
    stderr."""
    m = import_mesh(
        path,
        reorient=args.reorient,
        pinched=args.pinched,
        duplicates=args.duplicates,
        linear=args.linear,
        _style="cli",
    )
    for n in m.notes:
        _note(n)
    return m


def _add_info(sub: Any) -> None:
    p = sub.add_parser(
        "info",
        help="build the G-map of a mesh file and print its cell counts, quality and validity",
        description=(
            "Read a mesh file (any format meshio reads, or a saved G-map .tmg), build its "
            "G-map and print darts, dimension, cells, connected components, boundary, "
            "validity, the bounding box, the cells by kind and quality figures: the smallest "
            "and largest cell volume (3D) or area (2D) and the worst aspect ratio. The aspect "
            "ratio of a triangle or tetrahedron is its longest edge over its inradius, "
            "divided by that of the equilateral cell (2*sqrt(3) for a triangle, 2*sqrt(6) "
            "for a tetrahedron), so 1 for the best cell and growing without bound for a "
            "flat one; for other cells it is the longest edge over the shortest (1 for a "
            "square or cube). What the import did (cells reoriented, points left out, ...) "
            "goes to stderr as notes. Exit 0 when the map is valid, 1 when it is not, 2 "
            "when the file cannot be read or the mesh is refused."
        ),
    )
    p.add_argument("mesh_file", metavar="MESH_FILE", type=Path)
    p.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object on stdout ({file, error} when the file cannot be read "
        "or the mesh is refused)",
    )
    _add_import_options(p)
    p.set_defaults(run=_run_info)


def _summary(path: Path, m: ImportedMesh) -> dict[str, Any]:
    g, dropped = m.gmap, m.dropped
    notes = list(m.notes)
    counts = g.cell_counts()
    valid = g.is_valid()
    violations = [] if valid else g.violations()
    r = g.report
    reoriented = [int(c) for c in r.reoriented]
    if m.mesh is not None:
        points, blocks = m.mesh.points, [(str(b.type), b.data) for b in m.mesh.cells]
        dropped_cells = sorted(int(a) for a, _ in r.merged_duplicates)
        if dropped_cells:
            import numpy as np

            # the figures describe the cells that became the map: duplicates merged away are
            # not counted (cell indices run over the blocks in order, as the kernel's do)
            kept, start = [], 0
            for t, data in blocks:
                data = np.asarray(data)
                lo, hi = np.searchsorted(dropped_cells, [start, start + len(data)])
                drop = np.asarray(dropped_cells[lo:hi], dtype=np.int64) - start
                keep = np.ones(len(data), dtype=bool)
                keep[drop] = False
                if keep.any():
                    kept.append((t, data[keep]))
                start += len(data)
            blocks = kept
    else:
        try:
            points, kinds, offsets, connectivity = g.to_flat()
            blocks = [(b.type, b.data) for b in flat_to_blocks(kinds, offsets, connectivity)]
        except MeshError as e:
            # a map whose cells are not the kinds a mesh file holds (a rewrite made a volume
            # a general polyhedron): its counts and validity are the map's; the cells are
            # not listed, and the note says why (it can be written to a .vtu as polyhedra)
            points, blocks = g.positions(), []
            notes.append(f"cells by kind and quality not given: {e} ({MESH_FILE_CELLS})")
            _note(notes[-1])
    figures = mesh_figures(points, blocks, g.dimension)
    if not blocks and len(points):
        # the bounding box of the vertices (the figures' is of the points cells use)
        figures["bounding_box"] = {
            "min": [float(v) for v in points.min(axis=0)],
            "max": [float(v) for v in points.max(axis=0)],
        }
    return {
        "file": str(path),
        "darts": counts["darts"],
        "dimension": g.dimension,
        "vertices": counts["vertices"],
        "edges": counts["edges"],
        "faces": counts["faces"],
        "volumes": counts["volumes"],
        "components": counts["components"],
        "boundary": counts["boundary"],
        "boundary_kind": "faces" if g.dimension == 3 else "edges",
        "valid": valid,
        "violations": violations[:MAX_VIOLATIONS_SHOWN],
        "n_violations": len(violations),
        "dropped": [d._asdict() for d in dropped],
        "reoriented": len(reoriented),
        "reoriented_cells": reoriented,
        "unused_points": [int(i) for i in r.unused_points],
        "pinched": [int(i) for i in getattr(r, "pinched", [])],
        "merged_duplicates": [[int(a), int(b)] for a, b in getattr(r, "merged_duplicates", [])],
        "non_orientable": bool(getattr(r, "non_orientable", False)),
        **figures,
        "notes": notes,
        "memory_bytes": g.memory_bytes(),
    }


def _print_summary(s: dict[str, Any]) -> None:
    box = s["bounding_box"]
    q = s["quality"]
    size = "volume" if s["dimension"] == 3 else "area"
    aspect = q["worst_aspect_ratio"]
    rows = [
        ("file", s["file"]),
        ("dimension", s["dimension"]),
        ("darts", s["darts"]),
        ("vertices", s["vertices"]),
        ("edges", s["edges"]),
        ("faces", s["faces"]),
        ("volumes", s["volumes"]),
        ("components", s["components"]),
        ("boundary", f"{s['boundary']} {s['boundary_kind']}"),
        (
            "cells",
            ", ".join(f"{n} {k}" for k, n in s["cells_by_kind"].items())
            or "not listed (see the note)",
        ),
        (
            "bounds",
            f"min ({', '.join(f'{x:.6g}' for x in box['min'])}), "
            f"max ({', '.join(f'{x:.6g}' for x in box['max'])})",
        ),
        (size, f"min {_g(q[f'min_{size}'])}, max {_g(q[f'max_{size}'])}"),
        (
            "aspect",
            "-" if aspect is None else f"worst {aspect:.4g} (cell {q['worst_aspect_cell']})",
        ),
        ("reoriented", s["reoriented"]),
        ("valid", "yes" if s["valid"] else f"NO ({s['n_violations']} violations)"),
        ("memory", f"{s['memory_bytes'] / 1024:.1f} KiB"),
    ]
    for k, v in rows:
        print(f"{k:<11} {v}")


def _g(x: float | None) -> str:
    return "-" if x is None else f"{x:.6g}"


def _report_violations(s: dict[str, Any]) -> None:
    if not s["valid"]:
        for v in s["violations"]:
            print(f"topomech: violation: {v}", file=sys.stderr)
        more = s["n_violations"] - len(s["violations"])
        if more > 0:
            print(f"topomech: ... and {more} more violations", file=sys.stderr)


def _run_info(args: argparse.Namespace) -> int:
    try:
        m = _import(args.mesh_file, args)
    except (TopomechError, OSError) as e:
        if args.json:
            # a script reading stdout gets an object saying why (the reason is on stderr
            # too, and the exit code is 2 as without --json)
            reason = str(e) if isinstance(e, TopomechError) else (e.strerror or str(e))
            print(json.dumps({"file": str(args.mesh_file), "error": reason}))
        raise
    s = _summary(args.mesh_file, m)
    _report_violations(s)
    if args.json:
        print(json.dumps(s))
    else:
        _print_summary(s)
    return EXIT_OK if s["valid"] else EXIT_INVALID


# ---------------------------------------------------------------------------------- run


#: ``--quiet`` of ``run`` and ``demo``.
QUIET_HELP = "no progress bar, no progress lines and no report (errors are still printed)"

#: What ``run`` and ``demo`` say of their progress and report.
PROGRESS_HELP = (
    "While stepping: a progress bar on stderr when stderr is a terminal; a line on stdout "
    "('NAME: step N/M, t = T s, X steps/s, ETA E s') at most every 10 s "
    "(TOPOMECH_PROGRESS_INTERVAL_S sets the interval) and one at the end when stdout or "
    "stderr is not a terminal. Then a report on stdout: the input and final mesh counts "
    "(when a cut or a fracture changed them) and the time spent in set-up, stepping "
    "(steps/s counts it alone), output and previews; --quiet prints none of them."
)


def _add_run(sub: Any) -> None:
    p = sub.add_parser(
        "run",
        help="run a scene (a TOML file, or the name of a shipped scene) and write its frames",
        description=(
            "Run the simulation a scene file describes (or a shipped scene by name: see "
            "--list) and write DIR/summary.json, DIR/final.vtu and, every output.every steps, "
            "DIR/frames/frame_NNNNN.vtu with DIR/animation.pvd (open it in ParaView), the "
            "frames for `topomech view DIR` (DIR/view.json, DIR/view.bin), and previews "
            "rendered headless: DIR/preview.gif (DIR/preview.mp4 when imageio-ffmpeg is "
            "installed), DIR/energy.png and DIR/energy.csv (kinetic, gravitational, elastic "
            "and total energy at every step; --no-preview skips them). Exit 0 "
            "when every step ran; 1 when the simulation diverged or a step failed, a timed "
            "cut that separates nothing (misses the object) included (what was written "
            "stays, summary.json has an 'error' entry naming the step, or the event); 2 when "
            "the scene is refused (the reason names the key), an event after the end of the "
            "run included (also when --steps shortens it), or when DIR holds files topomech "
            "did not write (see --overwrite). DIR keeps a manifest of what runs wrote there "
            "(DIR/.topomech-manifest.jsonl): a rerun removes only those files, never "
            "following a symbolic link. A file that cannot be written (a full disk) stops "
            "the run with exit 1, the message naming the file; Ctrl-C stops it with exit "
            "130, SIGTERM the same way with exit 143; either way summary.json says what "
            "happened. " + PROGRESS_HELP
        ),
    )
    p.add_argument("scene", metavar="SCENE", nargs="?", help="scene file (.toml) or shipped name")
    p.add_argument("--out", metavar="DIR", type=Path, help="output directory (default out/NAME)")
    p.add_argument("--steps", metavar="N", type=_count, help="steps to run (default: the scene's)")
    p.add_argument(
        "--every",
        metavar="N",
        type=_count,
        help="a frame every N steps, 0 for none (default: the scene's output.every)",
    )
    p.add_argument("--quiet", "-q", action="store_true", help=QUIET_HELP)
    p.add_argument(
        "--no-preview",
        dest="preview",
        action="store_false",
        help="no energies, no preview.gif/mp4 and no energy.png (a faster run)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help=(
            "write into DIR even when it holds files topomech did not write (files named "
            "like the outputs are replaced, the others kept)"
        ),
    )
    p.add_argument(
        "--save-map",
        action="store_true",
        help=(
            "after a cut or a fracture, also write DIR/final.tmg: the final map, its pieces "
            "apart (final.vtu of pieces that moved into each other is refused as a mesh)"
        ),
    )
    p.add_argument("--list", action="store_true", help="list the shipped scenes and exit")
    p.set_defaults(run=_run_run)


def _count(text: str) -> int:
    """A ``--steps`` or ``--every`` count: an integer from 0 to what a scene's
    ``integrator.steps`` and ``output.every`` take (a signed 64-bit integer), refused with
    the scene's message otherwise."""
    from topomech.scene._table import _INT_MAX, _too_large

    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if n < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {n}")
    if n > _INT_MAX:
        raise argparse.ArgumentTypeError(_too_large(n))
    return n


def _list_scenes() -> int:
    from topomech.scene import load_scene, shipped_scenes

    for name, path in shipped_scenes().items():
        sc = load_scene(path)
        first = sc.description.strip().splitlines()[0] if sc.description.strip() else ""
        print(f"{name:<20} {first}")
    return EXIT_OK


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def _mesh_counts(c: dict[str, Any], dimension: int) -> str:
    cells = "volumes" if dimension == 3 else "faces"
    return f"{c['vertices']} vertices, {c[cells]} {cells}, {c['darts']} darts"


def _mesh_rows(s: dict[str, Any]) -> list[tuple[str, str]]:
    """The report's mesh line: the input's counts; and a line with the final ones when they
    differ (a cut or a fracture split vertices)."""
    dim = s["dimension"]
    mesh = s.get("mesh") or {}
    final = mesh.get("final") or s
    first = mesh.get("input")
    if first is None or first == final:
        return [("mesh", f"{dim}D, {_mesh_counts(final, dim)}")]
    return [
        ("mesh", f"{dim}D, {_mesh_counts(first, dim)} (input)"),
        ("final mesh", _mesh_counts(final, dim)),
    ]


def _time_row(s: dict[str, Any]) -> str:
    """The report's time line: the total, then its parts (they add up to it)."""
    t = s.get("timings")
    if t is None:
        return f"{s['wall_seconds']:.2f} s"
    rate = s["steps_per_second"]
    per = f" ({rate:.0f} steps/s)" if rate is not None else ""
    return (
        f"{t['total_s']:.2f} s: set-up {t['setup_s']:.2f} s, stepping {t['stepping_s']:.2f} s"
        f"{per}, output {t['output_s']:.2f} s, previews {t['preview_s']:.2f} s"
    )


def _topology_rows(s: dict[str, Any]) -> list[tuple[str, str]]:
    """The report's line on topology changes, when there were some."""
    changes = s.get("topology_changes") or []
    if not changes:
        return []
    kinds: dict[str, int] = {}
    for c in changes:
        kinds[c["kind"]] = kinds.get(c["kind"], 0) + 1
    # a blade opens faces over several steps: counted as steps of cutting, not as blades
    what = ", ".join(
        f"blade cuts in {_plural(n, 'step')}" if k == "blade" else _plural(n, k)
        for k, n in kinds.items()
    )
    opened = sum(int(c["unsewn"]) for c in changes)
    cells = "faces" if s["dimension"] == 3 else "edges"
    first = changes[0]
    return [
        (
            "topology",
            f"{what}: {opened} {cells} opened from step {first['step']} "
            f"(t = {_fmt(first['time'])}); {_plural(s['components'], 'component')}",
        )
    ]


def _report(s: dict[str, Any], out: Path) -> None:
    rows = [
        ("scene", f"{s['name']} ({s['scene']})"),
        *_mesh_rows(s),
        ("models", ", ".join(m["kind"] for m in s["models"])),
        (
            "integrator",
            f"{s['integrator']}, dt {_fmt(s['dt'])}, {s['steps']} steps, t = {_fmt(s['time'])}",
        ),
        ("mass", _fmt(s["total_mass"])),
        *_topology_rows(s),
        ("max disp.", _fmt(s["max_displacement"])),
        ("kinetic", _fmt(s["kinetic_energy"])),
        ("took", _time_row(s)),
    ]
    for k, v in rows:
        print(f"{k:<11} {v}")
    wrote = [out / "summary.json", out / "final.vtu"]
    if s["outputs"].get("map"):
        wrote.append(out / s["outputs"]["map"])
    if s["outputs"]["animation"]:
        wrote.append(out / "animation.pvd")
    frames = f" ({s['frames']} frames in {out / 'frames'})" if s["frames"] else ""
    print(f"{'wrote':<11} {', '.join(map(str, wrote))}{frames}")
    previews = [
        out / s["outputs"][k]
        for k in ("preview", "video", "energy_plot")
        if s["outputs"].get(k) is not None
    ]
    if previews:
        print(f"{'previews':<11} {', '.join(map(str, previews))}")
    if s["outputs"].get("view"):
        print(f"{'view':<11} topomech view {out}")


def _isatty(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def _progress_kinds(quiet: bool) -> tuple[bool, bool]:
    """(a progress bar on stderr, progress lines on stdout) for ``run`` and ``demo``: the bar
    when stderr is a terminal, the lines when stdout or stderr is not one (a pipe, a file, a
    CI log: what a bar cannot draw on, or what nobody watches); neither with ``--quiet``."""
    if quiet:
        return False, False
    tty_out, tty_err = _isatty(sys.stdout), _isatty(sys.stderr)
    return tty_err, not (tty_out and tty_err)


@contextlib.contextmanager
def _sigterm_interrupts() -> Iterator[list[int]]:
    """For the block, SIGTERM raises :class:`KeyboardInterrupt` as Ctrl-C does, so that a run
    told to stop (``kill``, a batch scheduler, a container's stop) writes what it did and its
    summary instead of dying at once; the list yielded gets the signal's number when it came.
    The handler in place before is put back on leaving. Nothing changes where Python cannot
    handle signals (another thread than the main one), where SIGTERM is ignored (the parent
    asked for it) or where a handler not installed from Python holds it."""
    received: list[int] = []
    sigterm = getattr(signal, "SIGTERM", None)
    if sigterm is None or threading.current_thread() is not threading.main_thread():
        yield received
        return
    old = signal.getsignal(sigterm)
    if old is None or old == signal.SIG_IGN:
        yield received
        return

    def interrupt(signum: int, frame: Any) -> None:
        received.append(signum)
        raise KeyboardInterrupt

    signal.signal(sigterm, interrupt)
    try:
        yield received
    finally:
        signal.signal(sigterm, old)


def _run_scene_cli(
    scene: str,
    out: Path | None,
    steps: int | None,
    every: int | None,
    quiet: bool,
    preview: bool = True,
    overwrite: bool = False,
    save_map: bool = False,
) -> tuple[int, Path | None]:
    """Runs a scene for ``run`` and ``demo``: the exit code and the output directory. Ctrl-C
    and SIGTERM stop the run the same way (:func:`_sigterm_interrupts`), the exit code says
    which came."""
    from topomech.run import OutputError, run_scene
    from topomech.scene import load_scene

    out_dir = out
    received: list[int] = []
    try:
        # the handler is put back as the interruption leaves: a second SIGTERM while the
        # message is printed ends the process as it would have before
        with _sigterm_interrupts() as received:
            sc = load_scene(scene)
            if steps is not None or every is not None:
                sc = sc.with_steps(steps, every)
            out_dir = out if out is not None else Path("out") / sc.name
            bar, log = _progress_kinds(quiet)
            summary = run_scene(
                sc,
                out_dir,
                progress=bar,
                log=log,
                preview=preview,
                overwrite=overwrite,
                started=_started[0],
                save_map=save_map,
            )
    except (SceneError, OutputError) as e:
        _error(str(e))
        return EXIT_REFUSED, None
    except KeyboardInterrupt:
        # name the folder only when the run left its summary there
        wrote = out_dir is not None and (out_dir / "summary.json").is_file()
        where = f"; what was written is in {out_dir} (see summary.json)" if wrote else ""
        what, code = (
            ("terminated (SIGTERM)", EXIT_TERMINATED)
            if received
            else ("interrupted", EXIT_INTERRUPTED)
        )
        _error(f"{what}{where}")
        return code, out_dir if wrote else None
    err = summary.get("error")
    if err is not None:
        _error(f"{sc.name}: {err['message']}")
        if summary["outputs"].get("summary") is None:
            kept = f"what was written is in {out_dir}; summary.json could not be written"
        else:
            kept = f"what was written is in {out_dir} (summary.json has the error)"
        _note(f"stopped after {summary['steps']} of {summary['steps_requested']} steps; {kept}")
        return EXIT_INVALID, out_dir
    if not quiet:
        _report(summary, out_dir)
    assert out_dir is not None
    return EXIT_OK, out_dir


def _run_run(args: argparse.Namespace) -> int:
    if args.list:
        if args.scene is not None:
            _error(f"--list takes no SCENE (got {args.scene!r}): list the scenes, or run one")
            return EXIT_REFUSED
        return _list_scenes()
    if args.scene is None:
        _error("give a SCENE (a .toml file or a shipped scene's name; --list lists them)")
        return EXIT_REFUSED
    code, _ = _run_scene_cli(
        args.scene,
        args.out,
        args.steps,
        args.every,
        args.quiet,
        args.preview,
        args.overwrite,
        args.save_map,
    )
    return code


# ---------------------------------------------------------------------------------- demo

#: The shipped scene `topomech demo` runs.
DEMO_SCENE = "corotational"


def _add_demo(sub: Any) -> None:
    p = sub.add_parser(
        "demo",
        help=f"run the default scene (the shipped '{DEMO_SCENE}' beam) and write its frames",
        description=(
            f"Run the shipped scene '{DEMO_SCENE}' (a cantilever beam of tetrahedra, "
            "co-rotational FEM, bending under gravity, fixed at x = 0) end to end and write "
            "its frames, final state and summary under the output directory, as "
            f"`topomech run {DEMO_SCENE}` does. " + PROGRESS_HELP
        ),
    )
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="output directory")
    p.add_argument("--steps", metavar="N", type=_count, help="steps to run (default: the scene's)")
    p.add_argument("--quiet", "-q", action="store_true", help=QUIET_HELP)
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="write into the output directory even when it holds files topomech did not write",
    )
    p.set_defaults(run=_run_demo)


def _run_demo(args: argparse.Namespace) -> int:
    code, out = _run_scene_cli(
        DEMO_SCENE, args.out, args.steps, None, args.quiet, overwrite=args.overwrite
    )
    if code == EXIT_OK and out is not None and not args.quiet:
        print(f"\nopen {out / 'animation.pvd'} in ParaView to watch the beam bend")
    return code


# ---------------------------------------------------------------------------------- view


def _add_view(sub: Any) -> None:
    p = sub.add_parser(
        "view",
        help="play a run's frames in a web viewer (with a dart view of the G-map)",
        description=(
            "Write OUT_DIR/viewer.html, a self-contained page (script and data inlined: it "
            "opens from disk, without network) that plays the frames `topomech run` wrote: "
            "play/pause, scrub, field coloring, wireframe, and a dart view drawing the "
            "G-map's darts and alpha links (for maps of a few thousand darts). Then serve "
            "OUT_DIR on 127.0.0.1 (a free port unless --port) and print the address, until "
            "Ctrl-C. Exit 0; 2 when OUT_DIR is missing, is not a run directory, or its view "
            "data cannot be read."
        ),
    )
    p.add_argument("out_dir", metavar="OUT_DIR", type=Path, help="a directory `topomech run` wrote")
    p.add_argument(
        "--html",
        "--no-serve",
        dest="serve",
        action="store_false",
        help="only write OUT_DIR/viewer.html (or --output) and print its path",
    )
    p.add_argument("--output", metavar="FILE", type=Path, help="where to write the page")
    p.add_argument(
        "--port",
        type=_port_arg,
        default=0,
        help="port to serve on, 0 to 65535 (default 0: a free one)",
    )
    p.add_argument("--open", action="store_true", help="open the page in the default browser")
    p.set_defaults(run=_run_view)


def _port_arg(text: str) -> int:
    """``--port``: an integer from 0 to 65535; anything else is a usage error (exit 2)."""
    from topomech.viewer import port_number

    try:
        return port_number(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _run_view(args: argparse.Namespace) -> int:
    from topomech.viewer import Server, ViewError, write_viewer

    try:
        if not args.serve:
            page = write_viewer(args.out_dir, args.output)
            print(f"wrote {page}")
            if args.open:
                import webbrowser

                webbrowser.open(page.resolve().as_uri())
            return EXIT_OK
        server = Server(args.out_dir, args.port)
    except ViewError as e:
        _error(str(e))
        return EXIT_REFUSED
    except OSError as e:  # the port is taken, the page cannot be written
        _error(f"cannot serve {args.out_dir}: {e.strerror or e}")
        return EXIT_REFUSED
    if args.output is not None:
        write_viewer(args.out_dir, args.output)
    server.start()
    print(f"serving {args.out_dir} at {server.url} (Ctrl-C stops)", flush=True)
    if args.open:
        import webbrowser

        webbrowser.open(server.url)
    try:
        server.thread.join()
    except KeyboardInterrupt:
        print("stopped")
    finally:
        server.stop()
    return EXIT_OK


# ---------------------------------------------------------------------------------- rules


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _read_rule_files(paths: Sequence[Path]) -> list[tuple[str, str]] | None:
    """``(name, text)`` of each rule file, named as given; None (each reason on stderr) when
    one cannot be read."""
    sources: list[tuple[str, str]] = []
    ok = True
    for p in paths:
        try:
            sources.append((str(p), read_text_file(p, "rule file")))
        except UnicodeDecodeError as e:
            _error(f"{p}: cannot read the rule file: not UTF-8 text (byte {e.start})")
            ok = False
        except OSError as e:
            _error(f"{p}: cannot read the rule file: {e.strerror or e}")
            ok = False
    return sources if ok else None


def _add_check(sub: Any) -> None:
    p = sub.add_parser(
        "check",
        help="check rule files (.tmr): one line per problem",
        description=(
            "Load the rule files together (they share their dimension and embeddings) and "
            "check every rule and model declaration. Files that declare a model are loaded "
            "after the shipped common rules of their dimension, as a simulation loads them "
            "(so they use position, rest, mass, ... without declaring them). Diagnostics go "
            "to stdout, one per line, as FILE:LINE:COL: error[CONDITION]: message (or "
            "warning[CONDITION]). Exit 0 when every rule is accepted (warnings allowed), with "
            "a last line 'ok: N rules in M files' ('ok: N rules and K models in M files (with "
            "the shipped common rules of dimension D)' for model files); 1 when the checker "
            "refuses something; 2 when a file cannot be read (the reason on stderr)."
        ),
    )
    p.add_argument("rule_files", metavar="FILE.tmr", nargs="+", type=Path)
    p.set_defaults(run=_run_check)


def _check_dimensions(sources: list[tuple[str, str]]) -> list[int | None]:
    """The dimensions to check rule files for: [None] when a file fixes one dimension (the
    checker then says which, and refuses files that disagree), [2, 3] when every file serves
    both (``dimension 2 3``, or no dimension line)."""
    dims = [set(RuleSet.file_dimensions(text)) or {2, 3} for _, text in sources]
    common = set.intersection(*dims) if dims else set()
    return [2, 3] if common == {2, 3} else [None]


def _run_check(args: argparse.Namespace) -> int:
    sources = _read_rule_files(args.rule_files)
    if sources is None:
        return EXIT_REFUSED
    # model files are checked as a simulation loads them: after the shipped common rules
    with_models = any(_MODEL_DECLARATION.search(text) for _, text in sources)
    dims = _check_dimensions(sources)
    checked: list[RuleSet] = []
    failures: list[tuple[int | None, list[str]]] = []
    for dim in dims:
        try:
            if with_models:
                checked.append(RuleSet.from_model_sources(sources, dim))
            else:
                checked.append(RuleSet.from_sources(sources, dim))
        except RuleError as e:
            failures.append((dim, [*e.diagnostics, *e.warnings]))
    if failures:
        # the same diagnostics for both dimensions (a syntax error, say) are said once
        same = len(failures) == len(dims) and all(f[1] == failures[0][1] for f in failures)
        for dim, lines in failures[:1] if same else failures:
            if dim is not None and not same:
                print(f"for dimension {dim} (the files serve 2-maps and 3-maps):")
            for line in lines:
                print(line)
        return EXIT_INVALID
    rules = checked[0]
    for line in rules.warnings:
        print(line)
    names = {name for name, _ in sources}
    n = sum(1 for r in rules.rule_names() if rules.rule_info(r)["file"] in names)
    warned = f" ({_plural(len(rules.warnings), 'warning')})" if rules.warnings else ""
    which = "dimensions 2 and 3" if len(dims) == 2 else f"dimension {rules.dimension}"
    if with_models:
        k = sum(1 for m in rules.models() if m["file"] in names)
        print(
            f"ok: {_plural(n, 'rule')} and {_plural(k, 'model')} in "
            f"{_plural(len(sources), 'file')}{warned} (with the shipped common rules of "
            f"{which})"
        )
    else:
        checked_for = f" (checked for {which})" if len(dims) == 2 else ""
        print(f"ok: {_plural(n, 'rule')} in {_plural(len(sources), 'file')}{warned}{checked_for}")
    return EXIT_OK


# ---------------------------------------------------------------------------------- models


def _add_models(sub: Any) -> None:
    p = sub.add_parser(
        "models",
        help="list models: the shipped ones, or those rule files declare",
        description=(
            "List models with their parameters (type and default; 'required' when none), "
            "the mesh dimensions they run on, what they need of the mesh, and whether they "
            "have Jacobian rules (jvp): with them every integrator (explicit_euler, "
            "symplectic_euler, implicit_euler, static), without them the explicit ones only. "
            "Without FILE the shipped models; with FILE the models each file declares (it is "
            "checked with the shipped common rules, as a simulation loads it: a refused file "
            "prints its diagnostics and exits 1; an unreadable one exits 2)."
        ),
    )
    p.add_argument("files", metavar="FILE.tmr", nargs="*", type=Path)
    p.add_argument("--json", action="store_true", help="print a JSON list instead")
    p.set_defaults(run=_run_models)


def _run_models(args: argparse.Namespace) -> int:
    if not args.files:
        models = shipped_models()
    else:
        models = []
        for path in args.files:
            try:
                found = Model.load_all(path)
            except UnicodeDecodeError as e:
                _error(f"{path}: cannot read the rule file: not UTF-8 text (byte {e.start})")
                return EXIT_REFUSED
            except OSError as e:
                _error(f"{path}: cannot read the rule file: {e.strerror or e}")
                return EXIT_REFUSED
            except RuleError as e:
                for line in [*e.diagnostics, *e.warnings]:
                    print(line)
                return EXIT_INVALID
            if not found:
                _note(f"{path}: declares no model")
            models += found
    if args.json:
        print(json.dumps([m.describe() for m in models], indent=2))
        return EXIT_OK
    for m in models:
        where = f"  ({m.file})" if m.file is not None else ""
        print(f"{m.name}{where}")
        print(f"  dimensions: {', '.join(str(d) for d in m.dimensions)}")
        params = [
            f"{p}: {m.param_types.get(p, 'f64')} = {_show_default(d)}" for p, d in m.params.items()
        ]
        print(f"  parameters: {', '.join(params) if params else 'none'}")
        print(f"  needs: {m.needs or '-'}")
        jvp = "yes" if m.has_jvp else "no"
        print(f"  jacobian: {jvp} (integrators: {', '.join(m.integrators)})")
    return EXIT_OK


def _show_default(d: Any) -> str:
    if d is None:
        return "required"
    if isinstance(d, (list, tuple)):
        return "[" + ", ".join(f"{x:g}" for x in d) + "]"
    return f"{d:g}"


#: The value of ``RULES`` that names the rules shipped with topomech.
LIBRARY = "@library"


def _dart_list(text: str) -> list[int]:
    """``--at 3,17``: darts, one per hook."""
    try:
        darts = [int(t) for t in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected darts separated by commas (e.g. 3,17), got {text!r}"
        ) from None
    if any(d < 0 for d in darts):
        raise argparse.ArgumentTypeError(f"darts are non-negative, got {text!r}")
    return darts


def _number(text: str) -> float | int:
    t = text.strip()
    try:
        return int(t)
    except ValueError:
        return float(t)


def _param(text: str) -> tuple[str, ParamValue]:
    """``--param NAME=VALUE``: a number, ``true``/``false``, numbers separated by commas (a
    vector), or rows separated by semicolons (a matrix)."""
    name, sep, value = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    v = value.strip()
    try:
        if v in ("true", "false"):
            return name, v == "true"
        if ";" in v:
            return name, [[_number(x) for x in row.split(",")] for row in v.split(";")]
        if "," in v:
            return name, [_number(x) for x in v.split(",")]
        return name, _number(v)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"parameter {name!r}: expected a number, true/false, numbers separated by commas "
            f"(a vector) or rows separated by semicolons (a matrix), got {value!r}"
        ) from None


def _add_apply(sub: Any) -> None:
    p = sub.add_parser(
        "apply",
        help="apply a rule to a mesh or saved G-map and write the result",
        description=(
            "Read INPUT (a mesh file meshio reads, or a saved G-map .tmg), load RULES (a rule "
            f"file, or {LIBRARY} for the rules shipped for the map's dimension; a file that "
            "declares a model is loaded after the shipped common rules of the map's dimension, "
            "as check and a simulation load it), apply RULE at "
            "every match (--everywhere) or once at the given hook darts (--at), and write "
            "OUTPUT: a saved G-map for .tmg, else a mesh file in the format of its extension "
            "(.vtu, .vtk, .msh, ...). Prints 'matches: N', 'created: N' and 'deleted: N' (darts) "
            "on stdout. Exit 0 on success (zero matches with --everywhere included); 1 when "
            "the rule does not match at --at or its application fails; 2 when a file cannot "
            "be read, the rule file is refused (its diagnostics on stderr) or an argument is "
            "wrong; 130 on Ctrl-C (nothing written unless it came while writing)."
        ),
    )
    p.add_argument("input", metavar="INPUT", type=Path, help="mesh file or saved G-map (.tmg)")
    p.add_argument("rules", metavar="RULES", help=f"rule file (.tmr), or {LIBRARY}")
    p.add_argument("rule", metavar="RULE", help="the rule's name")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument(
        "--everywhere", action="store_true", help="apply at every match (one-hook rules)"
    )
    where.add_argument(
        "--at",
        metavar="DART[,DART...]",
        type=_dart_list,
        help="apply once, with the hooks at these darts (one per hook, e.g. --at 3,17)",
    )
    p.add_argument(
        "--param",
        metavar="NAME=VALUE",
        action="append",
        default=[],
        type=_param,
        help=(
            "a parameter of the rule (repeat for each): a number, true/false, numbers "
            "separated by commas for a vector (gravity=0,-9.81,0), rows separated by "
            "semicolons for a matrix (m=1,0;0,1)"
        ),
    )
    p.add_argument("--out", metavar="OUTPUT", type=Path, required=True, help=".tmg or a mesh file")
    _add_import_options(p)
    p.set_defaults(run=_run_apply)


def _load_rules(spec: str, dimension: int) -> RuleSet | None:
    """The rule set named by ``RULES``; None (the reason on stderr) when refused."""
    if spec == LIBRARY:
        return RuleSet.library(dimension)
    sources = _read_rule_files([Path(spec)])
    if sources is None:
        return None
    # a file that serves both dimensions (`dimension 2 3`, or no line) is loaded for the map's
    serves_both = all(len(RuleSet.file_dimensions(text)) != 1 for _, text in sources)
    # a model file is loaded after the shipped common rules (position, rest, dx, mass, ...),
    # as `topomech check` and a simulation load it
    with_models = any(_MODEL_DECLARATION.search(text) for _, text in sources)
    load = RuleSet.from_model_sources if with_models else RuleSet.from_sources
    try:
        rules = load(sources, dimension if serves_both else None)
    except RuleError as e:
        for line in [*e.diagnostics, *e.warnings]:
            print(line, file=sys.stderr)
        _error(f"{spec}: the rule file is refused ({_plural(len(e.diagnostics), 'error')})")
        return None
    for line in rules.warnings:
        print(line, file=sys.stderr)
    if rules.dimension != dimension:
        _error(
            f"{spec}: the rules are for dimension {rules.dimension}, "
            f"the map has dimension {dimension}"
        )
        return None
    return rules


def _check_call(rules: RuleSet, args: argparse.Namespace, spec: str) -> str | None:
    """Why the rule, hooks and parameters asked for do not fit the rule, or None."""
    names = rules.rule_names()
    if args.rule not in names:
        return f"no rule named {args.rule!r} in {spec}; its rules: {', '.join(names)}"
    info = rules.rule_info(args.rule)
    hooks = _plural(info["hooks"], "hook")
    if args.everywhere and info["hooks"] != 1:
        return f"rule {args.rule!r} has {hooks}: give --at with one dart per hook"
    if args.at is not None and len(args.at) != info["hooks"]:
        return f"rule {args.rule!r} has {hooks}, --at gives {_plural(len(args.at), 'dart')}"
    declared = dict(info["params"])
    takes = ", ".join(f"{p}: {t}" for p, t in info["params"]) or "no parameters"
    given = [n for n, _ in args.param]
    for n in given:
        if n not in declared:
            return f"rule {args.rule!r} has no parameter {n!r} (it takes {takes})"
        if given.count(n) > 1:
            return f"parameter {n!r} is given more than once"
    missing = [f"{p} ({t})" for p, t in info["params"] if p not in given]
    if missing:
        return f"rule {args.rule!r} needs --param for {', '.join(missing)}"
    return None


def _run_apply(args: argparse.Namespace) -> int:
    """``topomech apply``; Ctrl-C exits :data:`EXIT_INTERRUPTED` with one line on stderr."""
    stage = ["reading the input"]
    try:
        return _apply(args, stage)
    except KeyboardInterrupt:
        if stage[0] == "writing":
            _error(f"interrupted while writing {args.out}; it may be incomplete")
        else:
            _error(f"interrupted while {stage[0]}; nothing written")
        return EXIT_INTERRUPTED


def _apply(args: argparse.Namespace, stage: list[str]) -> int:
    """The work of ``topomech apply``; ``stage[0]`` says what it is doing (for Ctrl-C)."""
    try:
        write_format(args.out)
    except ValueError as e:
        _error(str(e))
        return EXIT_REFUSED
    g = _import(args.input, args).gmap
    stage[0] = "loading the rules"
    rules = _load_rules(args.rules, g.dimension)
    if rules is None:
        return EXIT_REFUSED
    why = _check_call(rules, args, args.rules)
    if why is not None:
        _error(why)
        return EXIT_REFUSED
    stage[0] = f"applying rule {args.rule!r}"
    try:
        # answers Ctrl-C within milliseconds while matching and evaluating (the engine polls
        # the signal), raising KeyboardInterrupt with the map unchanged
        report = rules.apply(g, args.rule, args.at, dict(args.param))
    except ApplyError as e:
        _error(str(e))
        return EXIT_INVALID
    except (IndexError, TypeError, ValueError) as e:  # a dart or a parameter value
        _error(str(e))
        return EXIT_REFUSED
    violations = g.violations()
    if violations:
        for v in violations[:MAX_VIOLATIONS_SHOWN]:
            print(f"topomech: violation: {v}", file=sys.stderr)
        _error(f"rule {args.rule!r} left an invalid map; nothing written")
        return EXIT_INVALID
    stage[0] = "writing"
    try:
        write_gmap(g, args.out)
    except ValueError as e:
        _error(str(e))
        return EXIT_REFUSED
    print(f"matches: {report['matches']}")
    print(f"created: {report['created']}")
    print(f"deleted: {report['deleted']}")
    print(f"wrote: {args.out}")
    return EXIT_OK


# ---------------------------------------------------------------------------------- samples


def _add_samples(sub: Any) -> None:
    p = sub.add_parser(
        "samples",
        help="list the sample meshes shipped in the package, or copy them into a folder",
        description=(
            "List the sample meshes shipped in the package (name, size, what it holds, path); "
            "with --copy, copy them into a folder (made if missing) for the README's examples."
        ),
    )
    p.add_argument("--copy", metavar="DIR", type=Path, help="copy every sample into DIR")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="with --copy: replace files of the samples' names that differ from them",
    )
    p.set_defaults(run=_run_samples)


def _run_samples(args: argparse.Namespace) -> int:
    from topomech.samples import copy_samples, sample, samples

    if args.copy is not None:
        for path in copy_samples(args.copy, overwrite=args.overwrite):
            print(f"wrote {path}")
        return EXIT_OK
    for name, what in samples().items():
        path = sample(name)
        print(f"{name:<10} {path.stat().st_size / 1024:5.1f} KiB  {what}")
        print(f"{'':<10} {path}")
    return EXIT_OK


# ---------------------------------------------------------------------------------- main

#: The subcommands, in the order `--help` lists them.
SUBCOMMANDS: list[Callable[[Any], None]] = [
    _add_info,
    _add_check,
    _add_models,
    _add_apply,
    _add_run,
    _add_view,
    _add_demo,
    _add_samples,
]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="topomech",
        description="Topology-based physical simulation on generalized maps.",
    )
    parser.add_argument("--version", action="version", version=f"topomech {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in SUBCOMMANDS:
        add(sub)
    return parser


#: The exit code after stdout was closed early (``topomech info X | head``): 128 + SIGPIPE,
#: what a shell reports for a program that a closed pipe stopped.
EXIT_BROKEN_PIPE = 128 + getattr(signal, "SIGPIPE", 13)


def _quiet_stdout() -> None:
    """Points stdout at the null device, so that the interpreter's last flush at exit does not
    fail again on the closed pipe (as Python's documentation of SIGPIPE advises)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        pass  # stdout is not a file descriptor (a test's capture): nothing will flush it


#: When :func:`main` began (``time.perf_counter``): a run's set-up time counts from it.
_started: list[float | None] = [None]


def main(argv: Sequence[str] | None = None) -> int:
    """Runs the command line ``argv`` (default: ``sys.argv[1:]``); returns the exit code.

    A usage error exits 2 (``SystemExit``, from argparse). When stdout is closed before the
    output is written (``topomech info X | head``) it returns :data:`EXIT_BROKEN_PIPE`
    quietly, without a traceback."""
    _started[0] = time.perf_counter()
    try:
        args = build_parser().parse_args(argv)
        try:
            with warnings.catch_warnings():
                warnings.showwarning = _show_scene_warning
                code: int = args.run(args)
        except TopomechError as e:  # InternalError included: a bug, reported without a traceback
            _error(str(e))
            return EXIT_REFUSED
        except BrokenPipeError:
            raise
        except OSError as e:
            _error(f"{e.filename or ''}: {e.strerror or e}" if e.filename else str(e))
            return EXIT_REFUSED
        sys.stdout.flush()
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_BROKEN_PIPE
    return code


if __name__ == "__main__":
    sys.exit(main())
