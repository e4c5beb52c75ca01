"""The ``topomech`` command.

Each subcommand is a pair of functions: ``_add_NAME(subparsers)`` declares its arguments and
``_run_NAME(args) -> exit code`` does the work. Exit codes: 0 success, 1 the input was read but
is not valid (an invalid G-map), 2 the input cannot be read or is refused (the reason goes to
stderr, without a traceback).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Callable

from topomech import __version__
from topomech._core import TopomechError
from topomech._gmap import GMap
from topomech.io import DroppedBlock, read_gmap, write_vtu

__all__ = ["build_parser", "main"]

EXIT_OK = 0
EXIT_INVALID = 1
EXIT_REFUSED = 2

#: Violations listed by `info` before "... and N more".
MAX_VIOLATIONS_SHOWN = 20


def _note(msg: str) -> None:
    print(f"topomech: note: {msg}", file=sys.stderr)


def _error(msg: str) -> None:
    print(f"topomech: error: {msg}", file=sys.stderr)


# ---------------------------------------------------------------------------------- info


def _add_info(sub: Any) -> None:
    p = sub.add_parser(
        "info",
        help="build the G-map of a mesh file and print its cell counts and validity",
        description=(
            "Read a mesh file (any format meshio reads, or a saved G-map .tmg), build its "
            "G-map and print darts, dimension, cells, connected components, boundary and "
            "validity. Exit 0 when the map is valid, 1 when it is not, 2 when the file "
            "cannot be read or the mesh is refused."
        ),
    )
    p.add_argument("mesh_file", metavar="MESH_FILE", type=Path)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument(
        "--reorient",
        action="store_true",
        help="turn inverted cells over instead of refusing them",
    )
    p.set_defaults(run=_run_info)


def _summary(path: Path, g: GMap, dropped: Sequence[DroppedBlock]) -> dict[str, Any]:
    counts = g.cell_counts()
    valid = g.is_valid()
    violations = [] if valid else g.violations()
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
        "reoriented": list(g.report.reoriented),
        "unused_points": list(g.report.unused_points),
        "memory_bytes": g.memory_bytes(),
    }


def _print_summary(s: dict[str, Any]) -> None:
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
        ("valid", "yes" if s["valid"] else f"NO ({s['n_violations']} violations)"),
        ("memory", f"{s['memory_bytes'] / 1024:.1f} KiB"),
    ]
    for k, v in rows:
        print(f"{k:<11} {v}")


def _report_notes(s: dict[str, Any]) -> None:
    if s["dropped"]:
        what = ", ".join(str(DroppedBlock(**d)) for d in s["dropped"])
        _note(f"dropped {what}: lower-dimensional than the {s['dimension']}D cells")
    if s["reoriented"]:
        cells = s["reoriented"]
        shown = ", ".join(map(str, cells[:20])) + (", ..." if len(cells) > 20 else "")
        _note(f"reoriented {len(cells)} inverted cell(s): {shown}")
    if s["unused_points"]:
        _note(f"{len(s['unused_points'])} point(s) used by no cell were left out")
    if not s["valid"]:
        for v in s["violations"]:
            print(f"topomech: violation: {v}", file=sys.stderr)
        more = s["n_violations"] - len(s["violations"])
        if more > 0:
            print(f"topomech: ... and {more} more violations", file=sys.stderr)


def _run_info(args: argparse.Namespace) -> int:
    g, dropped = read_gmap(args.mesh_file, reorient=args.reorient)
    s = _summary(args.mesh_file, g, dropped)
    _report_notes(s)
    if args.json:
        print(json.dumps(s))
    else:
        _print_summary(s)
    return EXIT_OK if s["valid"] else EXIT_INVALID


# ---------------------------------------------------------------------------------- demo


def _add_demo(sub: Any) -> None:
    p = sub.add_parser(
        "demo",
        help="build a demo mesh, write it as VTU and print its info",
        description=(
            "Generate a box of tetrahedra, build its G-map, write it as VTU (and as a saved "
            "G-map .tmg) under the output directory, and print its info."
        ),
    )
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="output directory")
    p.add_argument("-n", type=int, default=4, help="cubes along each side (default 4)")
    p.add_argument(
        "--element",
        default="tetra",
        choices=["tetra", "hexahedron", "wedge", "pyramid", "mixed"],
        help="volume element (default tetra)",
    )
    p.set_defaults(run=_run_demo)


def _run_demo(args: argparse.Namespace) -> int:
    from topomech import _core

    if args.n < 1:
        _error(f"-n must be at least 1, got {args.n}")
        return EXIT_REFUSED
    flat = _core.box(args.n, args.n, args.n, 1.0, 1.0, 1.0, args.element)
    g = GMap.from_flat(*flat)
    args.out.mkdir(parents=True, exist_ok=True)
    vtu = args.out / f"box_{args.element}.vtu"
    tmg = args.out / f"box_{args.element}.tmg"
    write_vtu(g, vtu)
    g.save(tmg)
    code = _run_info(argparse.Namespace(mesh_file=vtu, json=False, reorient=False))
    print(f"\nwrote {vtu} (open it in ParaView) and {tmg} (the saved G-map)")
    return code


# ---------------------------------------------------------------------------------- main

#: The subcommands, in the order `--help` lists them.
SUBCOMMANDS: list[Callable[[Any], None]] = [_add_info, _add_demo]


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


def main(argv: Sequence[str] | None = None) -> int:
    """Runs the command line ``argv`` (default: ``sys.argv[1:]``); returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        code: int = args.run(args)
    except TopomechError as e:  # InternalError included: a bug, reported without a traceback
        _error(str(e))
        return EXIT_REFUSED
    except OSError as e:
        _error(f"{e.filename or ''}: {e.strerror or e}" if e.filename else str(e))
        return EXIT_REFUSED
    return code


if __name__ == "__main__":
    sys.exit(main())
