#!/usr/bin/env python3
"""Rewrites the README's benchmark figures from what ``make bench`` wrote, so that the README
says what the last run measured, never typed figures. Python standard library only.

- between ``<!-- perf:begin -->`` and ``<!-- perf:end -->``: the engine against its
  baselines, from ``bench/results.json``;
- between ``<!-- perf-kernel:begin -->`` and ``<!-- perf-kernel:end -->``, and the same
  with ``perf-topology``: the output of the kernel and topology benches, ``bench/kernel.txt``
  and ``bench/topology.txt`` (``make bench`` writes them); while a file is missing (before the
  first ``make bench`` that writes it) its section is left as it is.

    python3 scripts/readme_perf.py            # rewrite README.md
    python3 scripts/readme_perf.py --check    # exit 1 (and say so) when README.md differs

``make readme-perf`` runs it, and ``make bench`` runs that at its end;
``tests/test_readme_perf.py`` fails when the README's section is not what this script
generates from the results in the repository.
"""

from __future__ import annotations

import argparse
import json
import sys
import textwrap
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
BEGIN = "<!-- perf:begin -->"
END = "<!-- perf:end -->"
#: The sections holding a bench's output as it printed it: marker name -> file, command.
RAW = {
    "perf-kernel": ("kernel.txt", "cargo bench -p topomech-gmap --bench kernel"),
    "perf-topology": ("topology.txt", "cargo bench -p topomech-physics --bench topology"),
}
#: The ratio to the hand-written baseline that issue 15 set as the target, at 10^5 and 10^6.
TARGET = 1.2
TITLES = {
    "cloth": "cumulated stretch springs, quad cloth",
    "corotational": "co-rotational FEM",
    "mass_tensor": "mass-tensor",
    "neohookean": "stable Neo-Hookean",
}
SHORT = {
    "cloth": "cloth",
    "corotational": "co-rotational",
    "mass_tensor": "mass-tensor",
    "neohookean": "Neo-Hookean",
}
UNITS = {"quad": "quads", "tet": "tets"}


def _ms(s: float) -> str:
    """Milliseconds with 3 significant digits (``12.0``, ``5.63``, ``376``)."""
    ms = s * 1e3
    if ms >= 100:
        return f"{ms:,.0f}"
    if ms >= 10:
        return f"{ms:.1f}"
    return f"{ms:.2f}" if ms >= 1 else f"{ms:.3f}"


def _x(r: float) -> str:
    return f"{r:.1f}x"


def _engine(case: dict[str, Any], threads: int) -> dict[str, Any] | None:
    return next((e for e in case.get("engine", []) if e.get("threads") == threads), None)


def _size(case: dict[str, Any]) -> str:
    unit = UNITS.get(case["element"], case["element"])
    return f"{case['elements']:,} {unit}"


def _power(target: int) -> str:
    return f"10^{len(str(target)) - 1}"


def section(results: dict[str, Any]) -> str:
    """The README text between the markers (without them), from the bench's results."""
    m, st = results["machine"], results["settings"]
    cases = [c for c in results["cases"] if c.get("status") == "ok"]
    big = [c for c in cases if c["target"] >= 100_000]
    skipped = [c for c in results["cases"] if c.get("status") != "ok"]
    out = [
        "`make bench` runs `crates/physics/benches/engine.rs` (the engine against hand-written "
        "flat-array baselines of the same algorithms, positions checked equal to "
        f"{st['tolerance']:g} before timing) and writes `bench/results.md` and "
        "`bench/results.json`; this part of the README is generated from the latter "
        "(`scripts/readme_perf.py`: `make readme-perf`, which `make bench` runs at its end). "
        f"The last run: {m['date']}, commit {m['git_commit']}, {m['cpu']}, "
        f"{m['logical_cpus']} logical CPUs, {m['memory_gib']} GiB, {m['os']}, {m['rustc']}, "
        f"{st['profile']} build; one step of {st['integrator']} (dt = {st['dt']:g}); median of "
        f"up to {st['max_samples']} samples, engine on 1 thread unless said:",
        "",
        "| model | elements | engine ms/step | baseline ms/step | ratio | 2 threads "
        "| map bytes/element | baseline / hardware limit |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c in big:
        one, two = _engine(c, 1), _engine(c, 2)
        speed = f"{two['speedup_vs_1']:.2f}x faster" if two else "-"
        mem = c.get("memory", {}).get("engine_bytes_per_element")
        lim = c.get("limit")
        lim_txt = f"{_x(lim['baseline_over_limit'])} ({lim['bound']})" if lim else "-"
        out.append(
            f"| {TITLES.get(c['model'], c['model'])} | {_size(c)} "
            f"| {_ms(one['step_s']) if one else '-'} "
            f"| {_ms(c['baseline']['step_s'])} | {_x(c['ratio'])} | {speed} "
            f"| {f'{mem:,.0f}' if mem is not None else '-'} | {lim_txt} |"
        )
    out.append("")
    for c in skipped:
        out.append(
            f"Not measured in that run: {TITLES.get(c['model'], c['model'])} at "
            f"{_power(c['target'])} ({c.get('status')})."
        )
    if skipped:
        out.append("")
    at5 = [c for c in big if c["target"] == 100_000]
    met = all(c["ratio"] <= TARGET for c in big)
    ratios = ", ".join(f"{SHORT.get(c['model'], c['model'])} {_x(c['ratio'])}" for c in at5)
    out.append(
        f"**The {TARGET}x target (issue 15: the engine within {TARGET}x of the baseline at 10^5 "
        f"and 10^6 elements) is {'met' if met else 'not met'}**: {ratios} at 10^5 in this run."
    )
    speedups = [_engine(c, 2)["speedup_vs_1"] for c in big if _engine(c, 2)]  # type: ignore[index]
    if speedups:
        out.append(
            f"Two threads: {min(speedups):.1f}-{max(speedups):.1f}x at 10^5 and 10^6 in this run."
        )
    setup = "; ".join(
        f"{SHORT.get(c['model'], c['model'])} at {_size(c)} {c['setup_engine_s']:.1f} s "
        f"plus {c['first_steps_s'][0]:.1f} s for the first step"
        for c in big
    )
    out.append(f"Set-up (building the map and the simulation, then the first step): {setup}.")
    copy = results.get("renamed_copy")
    if copy:
        out.append(
            f"A renamed copy of the {copy['model']} rule file (a user's own file) runs at the "
            f"shipped file's speed: ratio {copy['ratio']:.2f} on {copy['elements']:,} "
            f"{UNITS.get(copy['element'], copy['element'])}, forces "
            f"{'bit for bit equal' if copy['identical_forces'] else 'different'}, the same plan "
            f"size{'' if copy['shipped_plan_bytes'] == copy['renamed_plan_bytes'] else ' (not)'}"
            ' (section "A user\'s copy of a shipped rule file" of `bench/results.md`).'
        )
    hyper = results.get("hyperelastic")
    if hyper:
        ref = hyper["reference"]
        others = [h for h in hyper["models"] if h["model"] != ref]
        out.append(
            f"Beside {ref} tetrahedra ({hyper['elements']:,} "
            f"{UNITS.get(hyper['element'], 'elements')}, "
            "the same deformed mesh), a step costs "
            + " and ".join(f"{h['step_ratio']:.1f}x ({h['model']})" for h in others)
            + " and a Jacobian-vector product "
            + " and ".join(f"{h['jvp_ratio']:.1f}x" for h in others)
            + ' (section "Hyperelastic tetrahedra beside co-rotational" of `bench/results.md`).'
        )
    return "".join(_wrap(line) for line in _paragraphs(out))


def _paragraphs(lines: list[str]) -> list[str]:
    """Consecutive prose lines joined into one (table rows and blank lines kept)."""
    out: list[str] = []
    for line in lines:
        prose = line and not line.startswith("|")
        if prose and out and out[-1] and not out[-1].startswith("|"):
            out[-1] += " " + line
        else:
            out.append(line)
    return out


def _wrap(line: str) -> str:
    if not line or line.startswith("|"):
        return line + "\n"
    return textwrap.fill(line, width=96, break_long_words=False, break_on_hyphens=False) + "\n"


def raw_section(output: str, file: str, command: str) -> str:
    """The README text for a bench's output ``output`` (``bench/FILE``)."""
    return (
        f"What `{command}` printed in the last `make bench` (`bench/{file}`, which it writes;"
        " generated by `make readme-perf`):\n\n"
        f"```text\n{output.rstrip()}\n```\n"
    )


def _replace(readme: str, begin: str, end: str, text: str) -> str:
    if readme.count(begin) != 1 or readme.count(end) != 1:
        raise SystemExit(f"README.md must hold {begin} and {end} once each")
    head, rest = readme.split(begin)
    _, tail = rest.split(end)
    return f"{head}{begin}\n{text}{end}{tail}"


def rewrite(readme: str, results: dict[str, Any], bench: Path | None = None) -> str:
    """``readme`` with its sections between the markers replaced (the raw outputs' from the
    files in ``bench``, default: the repository's bench folder, where they exist)."""
    readme = _replace(readme, BEGIN, END, section(results))
    for name, (file, command) in RAW.items():
        path = (ROOT / "bench" if bench is None else bench) / file
        if path.is_file():
            text = raw_section(path.read_text(encoding="utf-8"), file, command)
            readme = _replace(readme, f"<!-- {name}:begin -->", f"<!-- {name}:end -->", text)
    return readme


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", type=Path, default=ROOT / "bench" / "results.json")
    ap.add_argument("--readme", type=Path, default=ROOT / "README.md")
    ap.add_argument("--check", action="store_true", help="only say whether README.md differs")
    args = ap.parse_args(argv)
    results = json.loads(args.results.read_text(encoding="utf-8"))
    old = args.readme.read_text(encoding="utf-8")
    new = rewrite(old, results, args.results.parent)
    if args.check:
        if new != old:
            print(
                f"{args.readme}: the performance section is not what {args.results} gives; "
                "run `make readme-perf`",
                file=sys.stderr,
            )
            return 1
        return 0
    if new != old:
        args.readme.write_text(new, encoding="utf-8")
        print(f"{args.readme}: performance section rewritten from {args.results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
