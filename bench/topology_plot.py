#!/usr/bin/env python3
"""Draws bench/topology.png and writes bench/topology_scaling.md from
bench/topology_scaling.json (`cargo bench -p topomech-physics --bench cut_scaling`): the cost
of a cut, with the first step after it, in steady steps, against the faces it unsewed, one
line per mesh size. Needs matplotlib (in the project's .venv).

    python bench/topology_plot.py [--results bench/topology_scaling.json] [--out bench]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent


def table(res: dict[str, Any]) -> list[str]:
    out = [
        "# Cut cost against faces unsewn",
        "",
        "`cargo bench -p topomech-physics --bench cut_scaling` (`crates/physics/benches/"
        f"cut_scaling.rs`): boxes of tetrahedra, {res['model']}, {res['threads']} thread. Each "
        "cut is the square a blade sweeps across part of a cross-section "
        "(`Simulation::cut_swept`), timed with the first step after it, in steady steps of "
        "the same mesh. Target (issue 16): at 10^5 tets, a cut of about 1,300 faces plus the "
        "next step under 10 steps, a single-face cut plus the next step under 2. The "
        "compiled guards the cuts find their faces with are built once before them "
        "(`Simulation::prepare_cuts`; a simulation builds those of the cuts it declares at "
        "set-up): *guards ms*.",
        "",
        "| tets | steady step ms | guards ms | square (fraction of the section) | faces unsewn "
        "| cut ms | next step ms | steps |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for s in res["sizes"]:
        if s.get("status") != "ok":
            out.append(f"| {s['tets']:,} | - | - | - | - | - | - | {s.get('status')} |")
            continue
        guards = s.get("prepare_cuts_s")
        guards_ms = "-" if guards is None else f"{guards * 1e3:.0f}"
        for c in s["cuts"]:
            out.append(
                f"| {s['tets']:,} | {s['step_s'] * 1e3:.2f} | {guards_ms} | {c['fraction']:g} "
                f"| {c['faces']:,} "
                f"| {c['cut_s'] * 1e3:.1f} | {c['next_step_s'] * 1e3:.1f} | {c['steps']:.1f} |"
            )
    idle = [s for s in res["sizes"] if s.get("status") == "ok" and "fracture_idle" in s]
    if idle:
        out += [
            "",
            "## A step with fracture enabled, nothing breaking",
            "",
            "Two fresh simulations of each box, one with a strain criterion at 50% tested "
            "after every step, stepped in turn: medians of 9 alternated steps. Target (issue "
            "16): under 1.2 plain steps at 10^5 tets, reported at 10^6.",
            "",
            "| tets | plain step ms | step with fracture ms | plain steps |",
            "|---|---|---|---|",
        ]
        for s in idle:
            f = s["fracture_idle"]
            if f is None:
                out.append(f"| {s['tets']:,} | - | - | skipped: memory |")
                continue
            out.append(
                f"| {s['tets']:,} | {f['plain_step_s'] * 1e3:.2f} "
                f"| {f['fracture_step_s'] * 1e3:.2f} | {f['steps']:.2f} |"
            )
    return out


def plot(res: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=110)
    for s in res["sizes"]:
        if s.get("status") != "ok":
            continue
        cuts = [c for c in s["cuts"] if c["faces"] > 0]
        if not cuts:
            continue  # nothing to draw on log axes (the table lists them)
        ax.plot(
            [c["faces"] for c in cuts],
            [c["steps"] for c in cuts],
            marker="o",
            label=f"{s['tets']:,} tets (step {s['step_s'] * 1e3:.1f} ms)",
        )
    ax.axhline(10, color="grey", linestyle="--", linewidth=0.8)
    ax.text(1.1, 10.5, "target at 10^5: 10 steps", color="grey", fontsize=8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("faces unsewn by the cut")
    ax.set_ylabel("cut + next step, in steady steps")
    ax.set_title(f"Cut cost ({res['model']}, {res['threads']} thread)")
    ax.grid(True, which="both", linewidth=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", type=Path, default=HERE / "topology_scaling.json")
    ap.add_argument("--out", type=Path, default=HERE)
    args = ap.parse_args(argv)
    try:
        res = json.loads(args.results.read_text(encoding="utf-8"))
        lines = table(res)
    except (OSError, ValueError) as e:
        print(f"topology_plot.py: {args.results}: {e}", file=sys.stderr)
        return 2
    except (KeyError, TypeError, AttributeError, IndexError) as e:
        print(
            f"topology_plot.py: {args.results}: not a cut_scaling result "
            f"(crates/physics/benches/cut_scaling.rs): {type(e).__name__} {e}",
            file=sys.stderr,
        )
        return 2
    if not args.out.is_dir():
        print(f"topology_plot.py: {args.out}: no such folder", file=sys.stderr)
        return 2
    md = args.out / "topology_scaling.md"
    md.write_text("\n".join(lines) + "\n", encoding="utf-8")
    plot(res, args.out / "topology.png")
    print(f"wrote {md} and {args.out / 'topology.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
