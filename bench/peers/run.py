"""Peer benchmark: topomech against Newton, Taichi and pyPBD on the same meshes, timing and
accuracy. Run by `make bench-peers` (which builds .venv-peers with topomech and the peers);
by hand: `.venv-peers/bin/python bench/peers/run.py [--peers a,b] [--cases x,y]
[--timeout S]`. Writes bench/peers.json and bench/peers.md.

Cases (bench/peers/common.py): the meshes come from topomech's own generators and are
exported as arrays, so every peer gets the same vertices and elements.
- tet_1600 / tet_12800: a beam 1.0 x 0.2 x 0.2 m of tetrahedra (box generator, 6 tets per
  cell, so 1,632 and 12,672 tets: the nearest counts), clamped at x = 0, gravity -y,
  E = 1e7 Pa, nu = 0.3, 1000 kg/m^3; FEM (topomech `corotational`).
- cloth_32 / cloth_64: a 1 x 1 m cloth of 32x32 / 64x64 quad cells split in two triangles
  (33x33 / 65x65 vertices), springs on every triangle edge (topomech `stretch_cumulated`),
  pinned at two corners, gravity out of its plane.
- cantilever_240 / cantilever_1632 (accuracy): the shipped cantilever scene's beam (10x2x2
  cells) and the tet_1600 beam, run with viscous damping c = 2 omega_1 for 0.5 s; the tip
  deflection (mean y-displacement of the x = L vertices) against the static linear-FEM
  solution on the same mesh (numpy, dense, independent of topomech; topomech's own static
  `linear_fem` solve is reported beside it as a check).

JSON schema (bench/peers.json), version "topomech-peers/1":
{
  "schema": "topomech-peers/1",
  "generated": ISO time, "wall_seconds": float,
  "machine": {"cpu", "logical_cpus", "os", "python", "date", "git_commit",
              "load_average_at_start"},
  "cases": {NAME: {"kind": "tet"|"cloth", "cells": [...], "dt": s, "vertices": int,
                   "tets": int (tet) | "triangles", "springs": int (cloth), "note": str}},
  "reference": {NAME: {"tip_deflection": m, "method": str, "omega_1": 1/s,
                       "dt_stable": s, "damping": 1/s, "time": s}},
  "peers": {PEER: {"status": "ok" | "not installable here: REASON" | "error: REASON",
                   "version", "threads", "precision", "device", "notes"}},
  "timing": [{"peer", "case", "kind", "size": str, "model": str,
              "time_per_step_ms": float, "threads": int, "steps_timed": int, ...extra}
             | {"peer", "case", "error": str} | {"peer", "case", "skipped": str}],
  "accuracy": [{"peer", "case", "model", "tip_deflection": m, "reference": m,
                "rel_error": float (|tip - ref| / |ref|), "steps": int,
                "variants": [{"name", "tip_deflection", "rel_error"}], ...extra}
               | {"peer", "case", "error": str} | {"peer", "case", "skipped": str}]
}
time_per_step_ms is the median over timed batches (after warm-up) of wall time per step of
dt; every peer and topomech run on one thread.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import common as C  # noqa: E402

ROOT = HERE.parent.parent
PEERS = ["topomech", "newton", "taichi", "pypbd"]
TITLES = {"topomech": "topomech", "newton": "Newton", "taichi": "Taichi", "pypbd": "pyPBD"}
# The PyPI package each peer needs (the Makefile records install failures per package).
PACKAGES = {"newton": "newton", "taichi": "taichi", "pypbd": "pypbd"}
# Timing cases whose mesh and loading are an accuracy case's.
SAME_MESH = {"tet_1600": "cantilever_1632"}
STATUS_DIR = ROOT / ".venv-peers" / "install-status"

NOTES = {
    "topomech": "topomech.Simulation: `corotational` (tets), `stretch_cumulated` (cloth), "
    "symplectic Euler; RAYON_NUM_THREADS=1 (one thread, like every peer).",
    "newton": "SolverSemiImplicit on the warp CPU device, contact off; tets: its stable "
    "Neo-Hookean (Smith 2018), the only tet model it has, given the Lame parameters of "
    "(E, nu); cloth: its damped springs on the same edges; f32.",
    "taichi": "Our own Taichi kernels of topomech's models (co-rotational FEM via "
    "ti.polar_decompose; Provot springs), symplectic Euler, arch=cpu, "
    "cpu_max_num_threads=1, f64; forces checked against topomech's.",
    "pypbd": "FEM-based PBD tets (addSolidConstraints method 2, given E and nu); cloth: XPBD "
    "distance constraints (no damping); default 5 sub-steps x 1 iteration per step; "
    "no collision detection; OMP_NUM_THREADS=1.",
}


def case_meta(case: C.Case) -> dict[str, Any]:
    meta: dict[str, Any] = {
        "kind": case.kind,
        "cells": list(case.cells),
        "dt": case.dt,
        "note": case.note,
    }
    if case.kind == "tet":
        m = C.tet_mesh(case.cells)
        meta.update(vertices=len(m.points), tets=len(m.tets))
    else:
        c = C.cloth_mesh(case.cells)
        meta.update(vertices=len(c.points), triangles=len(c.tris), springs=len(c.edges))
    return meta


def size_label(meta: dict[str, Any]) -> str:
    if meta["kind"] == "tet":
        return f"{meta['tets']:,} tets, {meta['vertices']:,} vertices"
    return (
        f"{meta['cells'][0]}x{meta['cells'][1]} cells, {meta['vertices']:,} vertices, "
        f"{meta['springs']:,} springs"
    )


def install_problem(peer: str) -> str | None:
    pkg = PACKAGES.get(peer)
    if pkg is None:
        return None
    f = STATUS_DIR / f"{pkg}.status"
    if f.exists():
        text = f.read_text().strip()
        if text != "ok":
            return text or "pip install failed"
    return None


def run_peer(peer: str, refs_path: Path, cases: list[str], timeout: float) -> list[dict]:
    with tempfile.NamedTemporaryFile("r", suffix=".jsonl", delete=False) as tf:
        out_path = Path(tf.name)
    env = dict(
        os.environ,
        OMP_NUM_THREADS="1",
        OPENBLAS_NUM_THREADS="1",
        MKL_NUM_THREADS="1",
        RAYON_NUM_THREADS="1",  # topomech's rules run in parallel chunks (rayon) otherwise
        TI_LOG_LEVEL="warn",
    )
    cmd = [sys.executable, str(HERE / "worker.py"), peer, str(refs_path), str(out_path), *cases]
    t0 = time.perf_counter()
    timed_out = False
    try:
        proc = subprocess.run(cmd, env=env, timeout=timeout, capture_output=True, text=True)
        rc = proc.returncode
        tail = (proc.stderr or "").strip().splitlines()[-3:]
    except subprocess.TimeoutExpired:
        timed_out, rc, tail = True, None, []
    lines = [json.loads(s) for s in out_path.read_text().splitlines() if s.strip()]
    out_path.unlink()
    wall = time.perf_counter() - t0
    print(
        f"  {peer}: {len(lines)} records in {wall:.0f} s"
        + (" (timed out)" if timed_out else "")
        + (f" (exit {rc})" if rc else "")
    )
    if timed_out:
        lines.append({"peer": peer, "abort": f"stopped after the {timeout:.0f} s limit"})
    elif rc:
        lines.append({"peer": peer, "abort": f"worker exited {rc}: " + " | ".join(tail)})
    return lines


def machine() -> dict[str, Any]:
    """The keys bench/report.py reads for the engine bench, plus python and the load."""
    cpu = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        commit = (
            subprocess.run(
                ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
            ).stdout.strip()
            or None
        )
    except OSError:
        commit = None
    return {
        "cpu": cpu,
        "logical_cpus": os.cpu_count(),
        "os": platform.platform(),
        "python": platform.python_version(),
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "git_commit": commit,
        "load_average_at_start": [round(x, 2) for x in os.getloadavg()],
    }


def rel_error(tip: float, ref: float) -> float:
    return abs(tip - ref) / abs(ref)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--peers", default=",".join(PEERS))
    ap.add_argument("--cases", default="", help="comma-separated case names (default: all)")
    ap.add_argument("--timeout", type=float, default=420.0, help="seconds per peer")
    ap.add_argument("--out", default=str(ROOT / "bench"))
    ap.add_argument(
        "--markdown-only", action="store_true", help="rewrite peers.md from peers.json, run nothing"
    )
    args = ap.parse_args()
    if args.markdown_only:
        doc = json.loads((Path(args.out) / "peers.json").read_text())
        (Path(args.out) / "peers.md").write_text(markdown(doc, list(doc["peers"])))
        return 0
    peers = [p for p in args.peers.split(",") if p]
    only = [c for c in args.cases.split(",") if c]
    t_start = time.perf_counter()
    mach = machine()

    all_cases = C.TIMING_CASES + C.ACCURACY_CASES
    cases = {c.name: case_meta(c) for c in all_cases if not only or c.name in only}
    refs: dict[str, Any] = {}
    for c in C.ACCURACY_CASES:
        if only and c.name not in only:
            continue
        r = C.static_reference(C.tet_mesh(c.cells))
        r.update(
            method="numpy dense linear FEM, K u = m g, x = 0 clamped",
            damping=2.0 * r["omega_1"],
            time=C.ACCURACY_TIME,
        )
        if c.dt >= r["dt_stable"]:
            raise SystemExit(f"{c.name}: dt {c.dt} above the stable bound {r['dt_stable']}")
        refs[c.name] = r
    print("references:", {k: round(v["tip_deflection"], 6) for k, v in refs.items()})
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as tf:
        json.dump(refs, tf)
        refs_path = Path(tf.name)

    peer_info: dict[str, Any] = {}
    timing: list[dict[str, Any]] = []
    accuracy: list[dict[str, Any]] = []
    for peer in peers:
        info: dict[str, Any] = {"notes": NOTES.get(peer, "")}
        problem = install_problem(peer)
        records = [] if problem else run_peer(peer, refs_path, only, args.timeout)
        setup = next((r for r in records if "setup" in r or "setup_error" in r), None)
        if problem:
            info["status"] = f"not installable here: {problem}"
        elif setup is None:
            abort = next((r["abort"] for r in records if "abort" in r), "no output")
            info["status"] = f"error: {abort}"
        elif "setup_error" in setup:
            err = setup["setup_error"]
            info["status"] = (
                f"not installable here: {err}" if "ModuleNotFoundError" in err else f"error: {err}"
            )
        else:
            info.update(status="ok", **setup["setup"])
        peer_info[peer] = info
        abort = next((r["abort"] for r in records if "abort" in r), None)
        for part, lst, names in (
            ("timing", timing, C.TIMING_CASES),
            ("accuracy", accuracy, C.ACCURACY_CASES),
        ):
            for c in names:
                if only and c.name not in only:
                    continue
                rec = next(
                    (r for r in records if r.get("part") == part and r.get("case") == c.name), None
                )
                row: dict[str, Any] = {"peer": peer, "case": c.name}
                if info["status"] != "ok":
                    row["skipped"] = info["status"]
                elif rec is None:
                    row["error"] = abort or "no result"
                elif "error" in rec:
                    row["error"] = rec["error"]
                else:
                    res = dict(rec["result"])
                    if part == "timing":
                        row.update(
                            kind=c.kind,
                            size=size_label(cases[c.name]),
                            threads=info.get("threads"),
                            **res,
                        )
                    else:
                        ref = refs[c.name]["tip_deflection"]
                        res["reference"] = ref
                        res["rel_error"] = rel_error(res["tip_deflection"], ref)
                        for v in res.get("variants", []):
                            v["rel_error"] = rel_error(v["tip_deflection"], ref)
                        if "static_linear_fem_tip" in res:
                            res["static_linear_fem_rel_diff"] = rel_error(
                                res["static_linear_fem_tip"], ref
                            )
                        row.update(res)
                    row["wall_s"] = rec.get("wall_s")
                lst.append(row)
    refs_path.unlink()
    # Accuracy beside speed: the timing rows of a mesh that has an accuracy run carry its error.
    for row in timing:
        acc = SAME_MESH.get(row["case"])
        a = next((r for r in accuracy if r["peer"] == row["peer"] and r["case"] == acc), None)
        if a is not None and "rel_error" in a:
            row["cantilever_case"] = acc
            row["cantilever_rel_error"] = a["rel_error"]

    doc = {
        "schema": "topomech-peers/1",
        "generated": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "wall_seconds": round(time.perf_counter() - t_start, 1),
        "machine": mach,
        "cases": cases,
        "reference": refs,
        "peers": peer_info,
        "timing": timing,
        "accuracy": accuracy,
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "peers.json").write_text(json.dumps(doc, indent=1) + "\n")
    (out / "peers.md").write_text(markdown(doc, peers))
    print(f"wrote {out / 'peers.json'} and {out / 'peers.md'} in {doc['wall_seconds']} s")
    return 0


def _pct(e: float) -> str:
    return f"{100 * e:.3g}%" if e >= 1e-3 else f"{100 * e:.2g}%"


def _ms(row: dict[str, Any] | None) -> str:
    if row is None:
        return "-"
    if "skipped" in row:
        return "not installable" if "not installable" in row["skipped"] else "not run"
    if "error" in row:
        return "error"
    t = row["time_per_step_ms"]
    return f"{t:.3g}" if t < 100 else f"{t:.0f}"


def _timed(doc: dict[str, Any], peer: str, case: str) -> dict[str, Any] | None:
    """The timing row of ``peer`` on ``case`` that has a time per step, if any."""
    return next(
        (
            r
            for r in doc["timing"]
            if r["peer"] == peer and r["case"] == case and "time_per_step_ms" in r
        ),
        None,
    )


def _variant_error(doc: dict[str, Any], peer: str, case: str | None, start: str) -> str:
    """The tip error of the accuracy variant of ``peer`` on ``case`` whose name starts with
    ``start``, as a percentage, or ``-``."""
    a = next((x for x in doc["accuracy"] if x["peer"] == peer and x["case"] == case), None)
    for v in (a or {}).get("variants", []):
        if v["name"].startswith(start) and "rel_error" in v:
            return _pct(v["rel_error"])
    return "-"


def markdown(doc: dict[str, Any], peers: list[str]) -> str:
    L: list[str] = []
    mach = doc["machine"]
    L.append("# topomech against its peers\n")
    L.append(
        f"Generated by `make bench-peers` ({doc['generated']}, {mach['logical_cpus']} CPUs, "
        f"load {mach['load_average_at_start'][0]} at start, commit {mach['git_commit']}, "
        f"Python {mach['python']}, {doc['wall_seconds']:.0f} s). "
        "Schema and method: bench/peers/run.py. Every engine on one thread.\n"
    )
    L.append("## Time per step (ms, median)\n")
    L.append("| case | size | dt (s) | " + " | ".join(TITLES[p] for p in peers) + " |")
    L.append("|---|---|---|" + "---|" * len(peers))
    for name, meta in doc["cases"].items():
        if not any(r["case"] == name for r in doc["timing"]):
            continue
        cells = []
        for p in peers:
            row = next((r for r in doc["timing"] if r["peer"] == p and r["case"] == name), None)
            cells.append(_ms(row))
        L.append(f"| {name} | {size_label(meta)} | {meta['dt']:g} | " + " | ".join(cells) + " |")
    L.append("")
    L.append("topomech's time over each peer's (above 1: topomech slower):\n")
    L.append("| case | " + " | ".join(TITLES[p] for p in peers if p != "topomech") + " |")
    L.append("|---|" + "---|" * (len(peers) - 1))
    for name in doc["cases"]:
        mine = _timed(doc, "topomech", name)
        if mine is None:
            continue
        cells = []
        for p in peers:
            if p == "topomech":
                continue
            row = _timed(doc, p, name)
            cells.append(
                "-" if row is None else f"{mine['time_per_step_ms'] / row['time_per_step_ms']:.1f}x"
            )
        L.append(f"| {name} | " + " | ".join(cells) + " |")
    L.append("")
    summary = [r for r in doc["timing"] if "cantilever_rel_error" in r]
    if summary:
        case = summary[0]["case"]
        L.append(f"## Speed and accuracy together ({case}: {summary[0]['size']})\n")
        L.append("| engine | model | ms per step | tip error at rest | other settings |")
        L.append("|---|---|---|---|---|")
        for r in summary:
            acc = next(
                a
                for a in doc["accuracy"]
                if a["peer"] == r["peer"] and a["case"] == r["cantilever_case"]
            )
            other = "; ".join(
                f"{v['name']}: {_pct(v['rel_error'])}" for v in acc.get("variants", [])
            )
            L.append(
                f"| {TITLES[r['peer']]} | {r['model']} | {_ms(r)} | "
                f"{_pct(r['cantilever_rel_error'])} | {other or '-'} |"
            )
        L.append("")
    L.append("## Cantilever accuracy (tip deflection at rest vs. static linear FEM)\n")
    L.append("| case | reference (m) | engine | model | tip (m) | error | notes |")
    L.append("|---|---|---|---|---|---|---|")
    for name, ref in doc["reference"].items():
        for p in peers:
            row = next((r for r in doc["accuracy"] if r["peer"] == p and r["case"] == name), None)
            if row is None:
                continue
            head = f"| {name} | {ref['tip_deflection']:.6f} | {TITLES[p]} |"
            if "skipped" in row or "error" in row:
                L.append(f"{head} - | - | - | {row.get('skipped') or row.get('error')} |")
                continue
            notes = []
            for v in row.get("variants", []):
                notes.append(f"{v['name']}: {v['tip_deflection']:.6f} ({_pct(v['rel_error'])})")
            if "static_linear_fem_tip" in row:
                notes.append(
                    f"topomech static linear_fem: {row['static_linear_fem_tip']:.6f} "
                    f"(diff {row['static_linear_fem_rel_diff']:.1e})"
                )
            if "substeps" in row:
                notes.insert(
                    0, f"{row['substeps']} sub-steps x {row['iterations']} iteration(s) (defaults)"
                )
            notes.append(f"max speed at end {row['max_speed_end']:.1e} m/s")
            L.append(
                f"{head} {row['model']} | {row['tip_deflection']:.6f} | "
                f"{_pct(row['rel_error'])} | " + "; ".join(notes) + " |"
            )
    L.append("")
    L.append(
        "Reference: "
        + next(iter(doc["reference"].values()))["method"]
        + "; dynamic runs: symplectic Euler with viscous damping c = 2 omega_1 "
        f"(critical for the first bending mode) for {C.ACCURACY_TIME} s.\n"
        if doc["reference"]
        else ""
    )
    L.append("## Engines\n")
    for p in peers:
        info = doc["peers"][p]
        line = f"- **{TITLES[p]}**"
        if info["status"] != "ok":
            line += f": {info['status']}."
        else:
            line += (
                f" {info.get('version')} ({info.get('device')}, {info.get('precision')}, "
                f"{info.get('threads')} thread)."
            )
        L.append(line + " " + info.get("notes", ""))
    checks = [r for r in doc["timing"] if "model_check_rel_force_diff" in r]
    if checks:
        L.append("")
        L.append(
            "Taichi kernels against topomech's forces at a perturbed, rotated, moving "
            "state (max relative difference): "
            + ", ".join(f"{r['case']} {r['model_check_rel_force_diff']:.1e}" for r in checks)
            + "."
        )
    nh = [r for r in doc["timing"] if "time_per_step_ms_neohookean" in r]
    if nh:
        L.append("")
        L.append(
            "## Neo-Hookean against Newton's (same meshes; tip error of the cantilever of the "
            "same mesh)\n"
        )
        L.append(
            "| case | topomech neohookean ms | Newton ms | topomech / Newton | "
            "topomech neohookean tip error | Newton tip error (Smith's Lame parameters) |"
        )
        L.append("|---|---|---|---|---|---|")
        for r in nh:
            new = _timed(doc, "newton", r["case"])
            acc_case = SAME_MESH.get(r["case"])
            ms = r["time_per_step_ms_neohookean"]
            L.append(
                f"| {r['case']} | {ms:.3g} | {_ms(new)} | "
                + ("-" if new is None else f"{ms / new['time_per_step_ms']:.1f}x")
                + f" | {_variant_error(doc, 'topomech', acc_case, 'stable Neo-Hookean')} | "
                f"{_variant_error(doc, 'newton', acc_case, 'Smith reparametrisation')} |"
            )
        L.append(
            "\nBoth are the stable Neo-Hookean of Smith, de Goes & Kim 2018; Newton's in f32, "
            "topomech's in f64. Newton's tip error is that of its run given Smith's "
            "reparametrised Lame parameters (its documented ones are far off, above)."
        )
    pb = [r for r in doc["timing"] if "time_per_step_ms_1_substep" in r]
    if pb:
        L.append("")
        L.append(
            "pyPBD with one sub-step per step instead of its default: "
            + ", ".join(f"{r['case']} {r['time_per_step_ms_1_substep']:.3g} ms" for r in pb)
            + "."
        )
    L.append("")
    return "\n".join(L)


if __name__ == "__main__":
    sys.exit(main())
