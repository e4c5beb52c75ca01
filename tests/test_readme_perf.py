"""The README's engine benchmark figures are what ``scripts/readme_perf.py`` generates from
``bench/results.json``: a ``make bench`` whose results were not carried into the README
(``make readme-perf``), or a figure typed into that section by hand, fails here."""

from __future__ import annotations

import copy
import importlib.util
import json
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "readme_perf", ROOT / "scripts" / "readme_perf.py"
    )
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["readme_perf"] = module
    spec.loader.exec_module(module)
    return module


def _results() -> dict:  # type: ignore[type-arg]
    return json.loads((ROOT / "bench" / "results.json").read_text(encoding="utf-8"))


def test_the_readme_performance_section_is_generated_from_the_results() -> None:
    perf = _script()
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert perf.rewrite(readme, _results()) == readme, (
        "README.md's section between <!-- perf:begin --> and <!-- perf:end --> is not what "
        "bench/results.json gives: run `make readme-perf` (or scripts/readme_perf.py)"
    )


def test_new_results_change_the_section_and_check_says_so(tmp_path: Path) -> None:
    perf = _script()
    results = copy.deepcopy(_results())
    case = next(c for c in results["cases"] if c["target"] == 100_000)
    case["ratio"] = 1.2345
    readme = tmp_path / "README.md"
    readme.write_text((ROOT / "README.md").read_text(encoding="utf-8"), encoding="utf-8")
    new = tmp_path / "results.json"
    new.write_text(json.dumps(results), encoding="utf-8")
    args = ["--results", str(new), "--readme", str(readme)]
    assert perf.main([*args, "--check"]) == 1
    assert perf.main(args) == 0
    assert "| 1.2x |" in readme.read_text(encoding="utf-8")
    assert perf.main([*args, "--check"]) == 0


def test_the_markers_must_be_there_once() -> None:
    perf = _script()
    with pytest.raises(SystemExit, match="perf:begin"):
        perf.rewrite("# no markers\n", _results())
