#!/usr/bin/env python3
"""The previews' cost against the stepping, per shipped scene (`make bench`; needs the
package, e.g. .venv after `make develop`).

Runs every shipped scene in full with its previews (preview.gif, preview.mp4 when
imageio-ffmpeg is installed, energy.png), each in a fresh interpreter as `topomech run`
does (so that the previews pay for their own imports), and reads ``stepping_s`` and
``preview_s`` from its summary.json. Writes bench/previews.md and bench/previews.json and
prints the table, naming the scenes whose previews took longer than their stepping and
longer than ``--floor`` seconds (a scene that steps in a few milliseconds still pays for
starting the encoders and drawing a few frames); with ``--check``, exits 1 when there is
one.

    python bench/previews.py [--floor 0.15] [--repeat 3] [--check] [--no-video] [NAME ...]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent

PROBE = """
import json, sys
from topomech.run import run_scene
from topomech.scene import shipped_scenes
s = run_scene(shipped_scenes()[sys.argv[1]], sys.argv[2], video=sys.argv[3] == "1")
print(json.dumps({"timings": s["timings"], "frames": s["frames"], "steps": s["steps"],
                  "outputs": s["outputs"], "error": s.get("error")}))
"""


def measure(name: str, work: Path, repeat: int, video: bool = True) -> dict[str, Any]:
    runs = []
    for i in range(repeat):
        out = work / f"{name}-{i}"
        r = subprocess.run(
            [sys.executable, "-c", PROBE, name, str(out), "1" if video else "0"],
            capture_output=True,
            text=True,
            check=True,
        )
        runs.append(json.loads(r.stdout.strip().splitlines()[-1]))
    if runs[0]["error"]:
        raise SystemExit(f"{name}: {runs[0]['error']}")

    def med(key: str) -> float:
        return statistics.median(r["timings"][key] for r in runs)

    return {
        "scene": name,
        "steps": runs[0]["steps"],
        "frames": runs[0]["frames"],
        "video": runs[0]["outputs"].get("video") is not None,
        "stepping_s": med("stepping_s"),
        "preview_s": med("preview_s"),
        "output_s": med("output_s"),
        "setup_s": med("setup_s"),
    }


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("names", nargs="*", help="scenes (default: every shipped one)")
    ap.add_argument("--floor", type=float, default=0.15, help="seconds a preview may take")
    ap.add_argument("--repeat", type=int, default=3, help="runs per scene (the median)")
    ap.add_argument("--out", type=Path, default=HERE / "previews.md")
    ap.add_argument("--check", action="store_true", help="exit 1 when a scene is over")
    ap.add_argument("--no-video", action="store_true", help="without preview.mp4")
    args = ap.parse_args(argv)
    from topomech.scene import shipped_scenes

    names = args.names or list(shipped_scenes())
    rows = []
    with tempfile.TemporaryDirectory(prefix="topomech-bench-previews-") as tmp:
        for name in names:
            rows.append(measure(name, Path(tmp), max(1, args.repeat), not args.no_video))
            r = rows[-1]
            print(
                f"{name:<20} {r['frames']:>4} frames  stepping {r['stepping_s']:7.3f} s  "
                f"previews {r['preview_s']:7.3f} s",
                flush=True,
            )
    over = [r for r in rows if r["preview_s"] > r["stepping_s"] and r["preview_s"] > args.floor]
    lines = [
        "# Previews against stepping",
        "",
        "`make bench` (bench/previews.py): each shipped scene run in full with its previews "
        f"(median of {args.repeat}); `preview_s` and `stepping_s` from its summary.json. "
        f"The aim: previews take at most the stepping time, or {args.floor:g} s.",
        "",
        "| scene | steps | frames | mp4 | stepping (s) | previews (s) | previews / stepping |",
        "| --- | ---: | ---: | :---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        ratio = r["preview_s"] / r["stepping_s"] if r["stepping_s"] > 0 else float("inf")
        lines.append(
            f"| {r['scene']} | {r['steps']} | {r['frames']} | {'yes' if r['video'] else 'no'} "
            f"| {r['stepping_s']:.3f} | {r['preview_s']:.3f} | {ratio:.2f} |"
        )
    total_step = sum(r["stepping_s"] for r in rows)
    total_prev = sum(r["preview_s"] for r in rows)
    lines += ["", f"All scenes: stepping {total_step:.2f} s, previews {total_prev:.2f} s.", ""]
    args.out.write_text("\n".join(lines), encoding="utf-8")
    args.out.with_suffix(".json").write_text(
        json.dumps({"floor_s": args.floor, "scenes": rows}, indent=2) + "\n", encoding="utf-8"
    )
    print(f"wrote {args.out} and {args.out.with_suffix('.json')}")
    for r in over:
        print(
            f"previews of {r['scene']} took {r['preview_s']:.3f} s, more than its stepping "
            f"({r['stepping_s']:.3f} s) and {args.floor:g} s",
            file=sys.stderr,
        )
    return 1 if over and args.check else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
