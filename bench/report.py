#!/usr/bin/env python3
"""Writes bench/results.md from bench/results.json (the engine bench) and bench/peers.json
(the peers' bench, if it exists). Python standard library only.

    python3 bench/report.py [--results bench/results.json] [--peers bench/peers.json]
                            [--out bench/results.md]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
MODEL_TITLES = {
    "cloth": "cloth (cumulated stretch springs)",
    "corotational": "co-rotational tetrahedra",
    "mass_tensor": "mass-tensor tetrahedra",
    "neohookean": "stable Neo-Hookean tetrahedra",
}


def fmt_ms(s: float | None) -> str:
    if s is None:
        return "-"
    ms = s * 1e3
    if ms >= 100:
        return f"{ms:,.0f}"
    if ms >= 1:
        return f"{ms:.2f}"
    return f"{ms:.4f}"


def fmt_num(x: float | None, digits: int = 2) -> str:
    if x is None:
        return "-"
    return f"{x:,.{digits}f}"


def fmt_int(x: float | None) -> str:
    return "-" if x is None else f"{round(x):,}"


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out


def engine_step(case: dict[str, Any], threads: int) -> float | None:
    for e in case.get("engine", []):
        if e.get("threads") == threads:
            return e.get("step_s")
    return None


def machine_lines(m: dict[str, Any]) -> list[str]:
    cores = m.get("logical_cpus")
    phys = m.get("physical_cores")
    core_txt = f"{cores} logical CPUs" + (f" ({phys} physical cores)" if phys else "")
    mem = m.get("memory_gib")
    return [
        f"Machine: {m.get('cpu', 'unknown')}, {core_txt}"
        + (f", {mem} GiB memory" if mem is not None else "")
        + f"; {m.get('os', '')}; {m.get('rustc', '')}.",
        f"Measured {m.get('date', '?')}"
        + (f" at commit {m['git_commit']}" if m.get("git_commit") else "")
        + ".",
    ]


def limit_section(res: dict[str, Any]) -> list[str]:
    """The baselines against the hardware: the least time a step can take on this machine
    (crates/physics/benches/baselines `Work`, rates probed in the same run)."""
    rates = res.get("rates")
    cases = [c for c in res.get("cases", []) if c.get("status") == "ok" and c.get("limit")]
    if not rates or not cases:
        return []
    out = ["## Baselines against the hardware limit (1 thread)", ""]
    out.append(
        "The limit of a step is max(bytes moved / bandwidth, operations / their rate + square "
        "roots and divisions / their rate): the compulsory traffic and the arithmetic of the "
        "baseline's formulas (`Work` in `crates/physics/benches/baselines`; the co-rotational "
        "polar decomposition counted as one Newton iteration, a lower bound), the rates "
        "probed in this run on one thread: the bandwidth of a triad over the case's working "
        "set (in cache for the small cases; "
        f"{rates['bandwidth_bytes_per_s'] / 1e9:.1f} GB/s from memory, on 3 x 64 MiB), "
        f"{rates['flops_per_s'] / 1e9:.2f} Gflop/s, "
        f"{rates['sqrt_div_per_s'] / 1e9:.3f} G square roots or divisions/s."
    )
    out.append("")
    rows = []
    for c in cases:
        lim = c["limit"]
        rows.append(
            [
                MODEL_TITLES.get(c["model"], c["model"]),
                f"{fmt_int(c['elements'])} {c['element']}s",
                fmt_ms(c["baseline"]["step_s"]),
                fmt_ms(lim["step_s"]),
                f"{lim['bound']} ({lim['bandwidth_bytes_per_s'] / 1e9:.0f} GB/s)",
                f"**{fmt_num(lim['baseline_over_limit'])}**",
                fmt_num(c["ratio"]),
                fmt_num((engine_step(c, 1) or c["engine"][0]["step_s"]) / lim["step_s"]),
            ]
        )
    out += table(
        [
            "model",
            "elements",
            "baseline ms/step",
            "limit ms/step",
            "bound",
            "baseline / limit",
            "engine / baseline",
            "engine / limit",
        ],
        rows,
    )
    out.append("")
    return out


def engine_sections(res: dict[str, Any]) -> list[str]:
    cases = res.get("cases", [])
    settings = res.get("settings", {})
    out: list[str] = []
    out += machine_lines(res.get("machine", {}))
    out.append("")
    dt = settings.get("dt", "?")
    samples = settings.get("max_samples", "?")
    tol = settings.get("tolerance", 1e-9)
    out.append(
        "One full step: every interaction rule, the accumulation of forces per vertex and "
        f"symplectic Euler (dt = {dt}), through the rules (`Simulation::step`), against a "
        "hand-written flat-array kernel of the same algorithm "
        "(`crates/physics/benches/baselines`), single-threaded, f64. Elements: quads for the "
        f"cloth, tetrahedra for the volumes. Times are medians of up to {samples} samples; both "
        "sides take the same steps and must end at the same positions (the last column: largest "
        "position difference relative to the motion; the bench aborts above "
        f"{tol:g}). Targets (issue 15): ratio at most 1.2 at 10^5 and 10^6 elements, two "
        "threads at least 1.8x faster than one, memory per element at most 1.5x the "
        "baseline's, set-up plus first step under 1 s at 10^5 tets and 12 s at 10^6."
    )
    out.append("")

    out.append("## Engine vs hand-written baseline (1 thread)")
    out.append("")
    rows = []
    for c in cases:
        name = MODEL_TITLES.get(c["model"], c["model"])
        n = f"{fmt_int(c['elements'])} {c['element']}s"
        if c.get("status") != "ok":
            rows.append([name, n, "-", "-", "-", "-", "-", c.get("reason", "skipped")])
            continue
        t1 = engine_step(c, 1) or c["engine"][0]["step_s"]
        first = c.get("first_steps_s") or [None]
        agree = c["agreement"]
        rows.append(
            [
                name,
                n,
                fmt_ms(t1),
                fmt_ms(c["baseline"]["step_s"]),
                f"**{fmt_num(c['ratio'])}**",
                fmt_num(c.get("setup_engine_s"), 1) + " / " + fmt_num(first[0], 2),
                fmt_num(c.get("setup_baseline_s"), 2),
                f"{agree['max_relative_difference']:.1e} after {agree['steps']} steps",
            ]
        )
    out += table(
        [
            "model",
            "elements",
            "engine ms/step",
            "baseline ms/step",
            "ratio",
            "engine setup s / first step s",
            "baseline setup s",
            "agreement",
        ],
        rows,
    )
    out.append("")

    out += limit_section(res)

    threads = settings.get("threads", [1, 2])
    others = [t for t in threads if t != 1]
    if others:
        out.append("## Threads (engine, rayon pool)")
        out.append("")
        rows = []
        for c in cases:
            if c.get("status") != "ok":
                continue
            t1 = engine_step(c, 1)
            row = [
                MODEL_TITLES.get(c["model"], c["model"]),
                f"{fmt_int(c['elements'])} {c['element']}s",
                fmt_ms(t1),
            ]
            for t in others:
                tk = engine_step(c, t)
                row += [fmt_ms(tk), f"{t1 / tk:.2f}x" if t1 and tk else "-"]
            rows.append(row)
        header = ["model", "elements", "1 thread ms/step"]
        for t in others:
            header += [f"{t} threads ms/step", f"speedup {t} threads"]
        out += table(header, rows)
        out.append("")

    out.append("## Scaling: time per element and step (ns), engine (baseline)")
    out.append("")
    sizes = sorted({c["target"] for c in cases})
    rows = []
    for model in dict.fromkeys(c["model"] for c in cases):
        mc = {c["target"]: c for c in cases if c["model"] == model}
        row = [MODEL_TITLES.get(model, model)]
        measured = []
        for s in sizes:
            c = mc.get(s)
            if c is None or c.get("status") != "ok":
                row.append(c.get("status", "skipped") if c is not None else "-")
                continue
            e, b = c["engine_ns_per_element"], c["baseline_ns_per_element"]
            measured.append((c["elements"], e, b))
            row.append(f"{fmt_num(e, 0)} ({fmt_num(b, 1)})")
        if len(measured) >= 2:
            (n0, e0, b0), (n1, e1, b1) = measured[0], measured[-1]
            row.append(f"{e1 / e0:.2f} ({b1 / b0:.2f}) from {fmt_int(n0)} to {fmt_int(n1)}")
        else:
            row.append("-")
        rows.append(row)
    out += table(
        ["model"] + [f"~{s:.0e}".replace("e+0", "e") for s in sizes] + ["growth per element"], rows
    )
    out.append("")
    out.append(
        "Growth per element: time per element at the largest measured size over the smallest "
        "(1.00 is linear)."
    )
    out.append("")

    out.append("## Memory per element (bytes)")
    out.append("")
    rows = []
    for c in cases:
        if c.get("status") != "ok":
            continue
        m = c["memory"]
        rows.append(
            [
                MODEL_TITLES.get(c["model"], c["model"]),
                f"{fmt_int(c['elements'])} {c['element']}s",
                fmt_int(m["engine_bytes_per_element"]),
                fmt_int(m["topology_bytes_per_element"]),
                fmt_int(m["embedding_index_bytes_per_element"]),
                fmt_int(m["embedding_values_bytes_per_element"]),
                fmt_int(m.get("embedding_other_bytes_per_element")),
                f"{fmt_num(m['darts_per_element'], 0)} / {fmt_int(m['embeddings'])}",
                fmt_int(m["baseline_bytes_per_element"]),
                f"{m['engine_bytes_per_element'] / m['baseline_bytes_per_element']:.1f}x",
            ]
        )
    out += table(
        [
            "model",
            "elements",
            "engine",
            "topology",
            "slot indices",
            "values",
            "other",
            "darts / embeddings",
            "baseline",
            "engine / baseline",
        ],
        rows,
    )
    out.append("")
    out.append(
        "Engine: the G-map's `memory_bytes()` (alpha links and liveness; the dart-to-slot "
        "tables, 4 bytes per dart, one per orbit type while its embeddings share it (none for "
        "`<>`); every embedding's value column, and slot use counts, free lists and spare "
        "vector capacity as `other`). Baseline: its flat arrays "
        "(positions, velocities, forces, rest positions, 1/mass, fixed flags, element or edge "
        "data)."
    )
    out.append("")
    largest: dict[str, dict[str, Any]] = {}
    for c in cases:
        if c.get("status") == "ok":
            largest[c["model"]] = c
    for model, c in largest.items():
        emb = c["memory"]["by_embedding"][:8]
        parts = ", ".join(
            f"`{e['name']}` {e['orbit']} {fmt_int(e['bytes_per_element'])}" for e in emb
        )
        out.append(
            f"- largest embeddings, {MODEL_TITLES.get(model, model)} at "
            f"{fmt_int(c['elements'])} {c['element']}s: {parts}"
        )
    out.append("")
    return out


def scalar(x: Any) -> str:
    if isinstance(x, float):
        return f"{x:.4g}"
    if isinstance(x, (list, tuple)):
        return ", ".join(scalar(v) for v in x)
    return str(x)


def flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            flat.update(flatten(v, key + "."))
        else:
            flat[key] = v
    return flat


def records_table(records: list[Any]) -> list[str]:
    dicts = [flatten(r) for r in records if isinstance(r, dict)]
    if not dicts:
        return ["- " + scalar(r) for r in records]
    cols: list[str] = []
    for d in dicts:
        for k in d:
            if k not in cols:
                cols.append(k)
    return table(cols, [[scalar(d.get(k, "")) for k in cols] for d in dicts])


def peer_cell(rec: dict[str, Any] | None, value: str) -> str:
    if rec is None:
        return "-"
    for key in ("error", "skipped"):
        if key in rec:
            text = str(rec[key])
            return f"{key}: {text[:60]}" + ("..." if len(text) > 60 else "")
    return value


def peers_v1(peers: dict[str, Any]) -> list[str]:
    """The peers' results in the `topomech-peers/1` schema (bench/peers/run.py)."""
    out: list[str] = []
    m = peers.get("machine", {})
    load = m.get("load_average_at_start")
    out.append(
        f"From `bench/peers.json` (`make bench-peers`, {m.get('date', '?')}, commit "
        f"{m.get('git_commit', '?')}, {m.get('cpu', '?')}, {m.get('logical_cpus', '?')} CPUs"
        + (f", load {load[0]} at start" if load else "")
        + "); every engine on one thread. Method and details: `bench/peers/run.py`, "
        "`bench/peers.md`."
    )
    out.append("")
    names = list(peers.get("peers", {}))
    rows = []
    for name, p in peers.get("peers", {}).items():
        rows.append(
            [
                name,
                str(p.get("status", "?")),
                str(p.get("version", "-")),
                str(p.get("precision", "-")),
                str(p.get("threads", "-")),
            ]
        )
    out += table(["peer", "status", "version", "precision", "threads"], rows)
    out.append("")

    def by_case(records: list[dict[str, Any]]) -> dict[str, dict[str, dict[str, Any]]]:
        cases: dict[str, dict[str, dict[str, Any]]] = {}
        for r in records:
            cases.setdefault(r.get("case", "?"), {})[r.get("peer", "?")] = r
        return cases

    timing = by_case(peers.get("timing", []))
    if timing:
        out.append("### Time per step (ms, median, one thread)")
        out.append("")
        rows = []
        for case, recs in timing.items():
            size = next((r["size"] for r in recs.values() if "size" in r), "")
            row = [case, size]
            for name in names:
                r = recs.get(name)
                t = r.get("time_per_step_ms") if r else None
                row.append(peer_cell(r, f"{t:.3g}" if t is not None else "-"))
            rows.append(row)
        out += table(["case", "size", *names], rows)
        out.append("")
    accuracy = by_case(peers.get("accuracy", []))
    if accuracy:
        out.append("### Accuracy: cantilever tip deflection against a static linear-FEM solve")
        out.append("")
        rows = []
        for case, recs in accuracy.items():
            ref = peers.get("reference", {}).get(case, {}).get("tip_deflection")
            row = [case, f"{ref:.6f} m" if ref is not None else "-"]
            for name in names:
                r = recs.get(name)
                e = r.get("rel_error") if r else None
                tip = r.get("tip_deflection") if r else None
                value = (
                    f"{100 * e:.3g}% ({tip:.6f} m)" if e is not None and tip is not None else "-"
                )
                row.append(peer_cell(r, value))
            rows.append(row)
        out += table(["case", "reference", *names], rows)
        out.append("")
        out.append(
            "Relative error of the tip deflection at rest; other settings of each peer (variants) "
            "are in `bench/peers.md`."
        )
        out.append("")
    return out


def peers_section(path: Path) -> list[str]:
    out = ["## Peers", ""]
    if not path.exists():
        out.append(f"No peer results (`{path.name}` is missing): run `make bench-peers`.")
        out.append("")
        return out
    try:
        peers = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        out.append(f"`{path.name}` could not be read ({e}): run `make bench-peers` again.")
        out.append("")
        return out
    if isinstance(peers, dict) and str(peers.get("schema", "")).startswith("topomech-peers/1"):
        return out + peers_v1(peers)
    out.append(
        f"From `{path.name}` (written by `make bench-peers`; schema in `bench/peers/run.py`)."
    )
    out.append("")
    if isinstance(peers, list):
        out += records_table(peers)
        out.append("")
        return out
    if not isinstance(peers, dict):
        out.append(scalar(peers))
        out.append("")
        return out
    if isinstance(peers.get("machine"), dict):
        out += machine_lines(peers["machine"])
        out.append("")
    for key, val in peers.items():
        if key == "machine":
            continue
        if isinstance(val, list):
            out.append(f"### {key}")
            out.append("")
            out += records_table(val)
            out.append("")
        elif isinstance(val, dict):
            out.append(f"### {key}")
            out.append("")
            if all(isinstance(v, dict) for v in val.values()):
                out += records_table([{"name": k, **v} for k, v in val.items()])
            else:
                out += records_table([val])
            out.append("")
        else:
            out.append(f"- {key}: {scalar(val)}")
    out.append("")
    return out


def renamed_section(res: dict[str, Any]) -> list[str]:
    """The renamed copy of a shipped rule file against the original (issue 6)."""
    r = res.get("renamed_copy")
    if not r:
        return []
    same = "yes" if r.get("identical_forces") else "**no**"
    out = [
        "## A user's copy of a shipped rule file",
        "",
        "The co-rotational rule file with every rule and embedding of the model renamed, as a "
        "user would copy it into a file of their own, against the shipped file: one application "
        "of the force rule on the same mesh, one thread, medians of alternated samples. The "
        "engine knows no rule by name, so both compile to the same plan.",
        "",
    ]
    out += table(
        [
            "rule",
            "elements",
            "shipped ms",
            "renamed copy ms",
            "ratio",
            "forces bit for bit",
            "plan bytes (shipped / copy)",
        ],
        [
            [
                f"{r['rule']} / {r['renamed_rule']}",
                f"{fmt_int(r['elements'])} {r['element']}s",
                fmt_ms(r["shipped_s"]),
                fmt_ms(r["renamed_s"]),
                fmt_num(r["ratio"], 3),
                same,
                f"{fmt_int(r['shipped_plan_bytes'])} / {fmt_int(r['renamed_plan_bytes'])}",
            ]
        ],
    )
    out.append("")
    return out


def hyperelastic_section(res: dict[str, Any]) -> list[str]:
    """Neo-Hookean and St. Venant-Kirchhoff tetrahedra beside co-rotational ones (issue 14)."""
    r = res.get("hyperelastic")
    if not r:
        return []
    out = [
        "## Hyperelastic tetrahedra beside co-rotational",
        "",
        "Stable Neo-Hookean and St. Venant-Kirchhoff (rule files written with generic built-ins "
        "only) and co-rotational tetrahedra on the same deformed mesh: one full step (symplectic "
        "Euler) and one Jacobian-vector product (the cost of a conjugate-gradient iteration of "
        "`implicit_euler` and `static`), one thread, medians of alternated samples.",
        "",
    ]
    out += table(
        ["model", "elements", "step ms", "step / co-rotational", "JVP ms", "JVP / co-rotational"],
        [
            [
                m["model"],
                f"{fmt_int(r['elements'])} {r['element']}s",
                fmt_ms(m["step_s"]),
                fmt_num(m["step_ratio"], 2),
                fmt_ms(m["jvp_s"]),
                fmt_num(m["jvp_ratio"], 2),
            ]
            for m in r["models"]
        ],
    )
    out.append("")
    return out


def solvers_section(res: dict[str, Any]) -> list[str]:
    """Implicit Euler against symplectic Euler, linear iterations, static cantilevers (issue 17)."""
    r = res.get("solvers")
    if not r:
        return []
    out = [
        "## Implicit and static solves",
        "",
        "Implicit Euler with the default solver settings (block-Jacobi preconditioned conjugate "
        "gradients to 1e-6, warm-started, the preconditioner kept across steps) against "
        "symplectic Euler on the same beam and model, dt 1e-3, from rest under gravity, one "
        "thread: medians of timed steps (the first implicit step, which builds the coupling "
        "graph and the preconditioner, apart). Linear iterations per step, means.",
        "",
    ]
    rows = []
    for c in r.get("implicit", []):
        its = {i["solver"]: i["mean_iterations"] for i in c["iterations"]}
        rows.append(
            [
                c["model"],
                fmt_int(c["elements"]),
                fmt_ms(c["implicit_step_s"]),
                fmt_ms(c["symplectic_step_s"]),
                fmt_num(c["ratio"], 1),
                fmt_ms(c["first_implicit_step_s"]),
                fmt_num(its.get("cg"), 1),
                fmt_num(its.get("jacobi_pcg"), 1),
                fmt_num(its.get("block_jacobi_pcg"), 1),
            ]
        )
    out += table(
        [
            "model",
            "tets",
            "implicit ms",
            "symplectic ms",
            "ratio",
            "first implicit ms",
            "cg its",
            "Jacobi-PCG its",
            "block-Jacobi-PCG its",
        ],
        rows,
    )
    out += [
        "",
        "Static co-rotational cantilevers under gravity, to 1e-8 relative residual with the "
        "default linear solver, and their deflection against another solve.",
        "",
    ]
    out += table(
        [
            "tets",
            "time s (with the coupling graph)",
            "solver",
            "Newton its",
            "load steps",
            "one assembly s",
            "against",
            "max difference",
        ],
        [
            [
                fmt_int(c["elements"]),
                fmt_num(c.get("total_s", c["time_s"]), 2),
                c["linear_solver"],
                fmt_int(c["newton_iterations"]),
                fmt_int(c["load_steps"]),
                fmt_num(c.get("assembly_s"), 2),
                f"{c['against']} ({fmt_num(c['against_time_s'], 2)} s)",
                f"{c['relative_difference']:.1e}",
            ]
            for c in r.get("static", [])
        ],
    )
    out.append("")
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--results", type=Path, default=HERE / "results.json")
    ap.add_argument("--peers", type=Path, default=HERE / "peers.json")
    ap.add_argument("--out", type=Path, default=HERE / "results.md")
    args = ap.parse_args(argv)
    lines = ["# topomech benchmark results", ""]
    if args.results.exists():
        lines += engine_sections(json.loads(args.results.read_text()))
    else:
        lines += [f"No engine results (`{args.results}` is missing): run `make bench`.", ""]
    if args.results.exists():
        lines += renamed_section(json.loads(args.results.read_text()))
        lines += hyperelastic_section(json.loads(args.results.read_text()))
        lines += solvers_section(json.loads(args.results.read_text()))
    lines += peers_section(args.peers)
    args.out.write_text("\n".join(lines).rstrip("\n") + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
