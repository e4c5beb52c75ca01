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


def test_a_bench_output_replaces_its_section_once_written(tmp_path: Path) -> None:
    """``bench/kernel.txt`` and ``bench/topology.txt`` (what ``make bench`` tees) become the
    README's kernel and topology figures; before they exist the sections stay as they are."""
    perf = _script()
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert perf.rewrite(readme, _results(), tmp_path) == perf.rewrite(readme, _results())
    (tmp_path / "kernel.txt").write_text(
        "kernel benchmark: box of 8 tetrahedra\n", encoding="utf-8"
    )
    new = perf.rewrite(readme, _results(), tmp_path)
    kernel = new.split("<!-- perf-kernel:begin -->\n")[1].split("<!-- perf-kernel:end -->")[0]
    assert kernel == perf.raw_section(
        "kernel benchmark: box of 8 tetrahedra\n",
        "kernel.txt",
        "cargo bench -p topomech-gmap --bench kernel",
    )
    assert "```text\nkernel benchmark: box of 8 tetrahedra\n```" in kernel
    begin, end = "<!-- perf-topology:begin -->", "<!-- perf-topology:end -->"
    kept = readme.split(begin)[1].split(end)[0]
    assert new.split(begin)[1].split(end)[0] == kept  # no topology.txt: as it was


def test_the_sections_made_from_files_in_the_repository_are_current() -> None:
    """Where bench/kernel.txt or bench/topology.txt is in the repository, the README's section
    is what it gives (the first test covers it too; this one names the file)."""
    perf = _script()
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for name, (file, command) in perf.RAW.items():
        path = ROOT / "bench" / file
        if path.is_file():
            section = readme.split(f"<!-- {name}:begin -->\n")[1].split(f"<!-- {name}:end -->")[0]
            want = perf.raw_section(path.read_text(encoding="utf-8"), file, command)
            assert section == want, f"bench/{file} is not in README.md: run `make readme-perf`"
