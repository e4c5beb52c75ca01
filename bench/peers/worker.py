"""Runs one peer's cases in its own process (so that a peer that hangs, crashes or cannot
be imported costs only its own results): `worker.py PEER REFS_JSON OUT_JSONL [CASE...]`.

Writes one JSON object per line to OUT_JSONL as each case finishes: first
{"peer", "setup": {...}} (or {"peer", "setup_error": "..."}), then
{"peer", "part": "timing" | "accuracy", "case", "result": {...} | "error": "..."}.
"""

from __future__ import annotations

import importlib
import json
import os
import sys
import time
import traceback
from pathlib import Path
from typing import TextIO

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import common as C


def main() -> int:
    peer, refs_path, out_path, *only = sys.argv[1:]
    refs = json.loads(Path(refs_path).read_text())
    with Path(out_path).open("a", buffering=1) as out:
        return run(peer, refs, only, out)


def run(peer: str, refs: dict, only: list[str], out: TextIO) -> int:
    def emit(obj: dict) -> None:
        out.write(json.dumps({"peer": peer, **obj}) + "\n")

    try:
        mod = importlib.import_module(f"peer_{peer}")
        info = mod.setup()
    except Exception as e:
        emit({"setup_error": f"{type(e).__name__}: {e}"})
        return 0
    emit({"setup": info})
    for case in C.TIMING_CASES:
        if only and case.name not in only:
            continue
        t0 = time.perf_counter()
        try:
            emit(
                {
                    "part": "timing",
                    "case": case.name,
                    "result": mod.timing(case),
                    "wall_s": time.perf_counter() - t0,
                }
            )
        except Exception as e:
            traceback.print_exc()
            emit({"part": "timing", "case": case.name, "error": f"{type(e).__name__}: {e}"})
    for case in C.ACCURACY_CASES:
        if only and case.name not in only:
            continue
        t0 = time.perf_counter()
        try:
            emit(
                {
                    "part": "accuracy",
                    "case": case.name,
                    "result": mod.accuracy(case, refs[case.name]),
                    "wall_s": time.perf_counter() - t0,
                }
            )
        except Exception as e:
            traceback.print_exc()
            emit({"part": "accuracy", "case": case.name, "error": f"{type(e).__name__}: {e}"})
    return 0


if __name__ == "__main__":
    sys.exit(main())
