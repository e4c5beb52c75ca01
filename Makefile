# topomech: build, test and demo targets. Needs Rust (cargo) and Python 3.9+ (3.11 preferred).
#
#   make venv     .venv with the build and test tools
#   make develop  build the extension (release, the wheel's build) and install the package
#                 into .venv (editable)
#   make test     cargo fmt/clippy/test, then ruff, mypy, stubtest and pytest (with the wheel's
#                 test: its build starts first, in the background)
#   make wheel    a stripped abi3 manylinux2014 wheel into target/wheels (scripts/wheel.py)
#   make demo     run `topomech demo` (writes out/demo)
#   make bench    kernel benchmarks, the cost of topology changes (and of cuts against the faces
#                 they unsew at 1e4/1e5/1e6 tets: bench/topology.png), the engine against
#                 hand-written baselines (writes bench/results.md, bench/results.json and
#                 the kernel's and topology's output, bench/kernel.txt, bench/topology.txt),
#                 then `make readme-perf`
#   make readme-perf  rewrite README.md's benchmark figures from those files
#   make bench-previews  previews against stepping per shipped scene (bench/previews.md)
#   make bench-peers  topomech against Newton, Taichi and pyPBD in their own .venv-peers
#                 (writes bench/peers.md and bench/peers.json)
#   make browser  playwright into .venv, and Debian's chromium when missing (for the viewer's
#                 browser tests; never fails: without them those tests are skipped)
#   make docs-pictures  run every shipped scene, write its picture under docs/scenes
#   make clean    remove build outputs and the venv
#
# Stamp files under .venv make the targets idempotent: `make test` twice rebuilds nothing
# unless a Rust source, a rule file (.tmr, compiled into the crates), a Cargo manifest or
# pyproject.toml changed.

SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV := .venv
VPY := $(VENV)/bin/python
CARGO ?= cargo

RUST_SOURCES := $(shell find crates -name '*.rs' -o -name '*.tmr' -o -name Cargo.toml) Cargo.toml Cargo.lock
VENV_STAMP := $(VENV)/.stamp-venv
DEVELOP_STAMP := $(VENV)/.stamp-develop
# Linters are pinned to a minor (ruff) or major (mypy) version: new releases add checks.
DEV_TOOLS := maturin>=1.9.4,<2 numpy meshio pytest hypothesis ruff>=0.17,<0.18 mypy>=2,<3 \
	pillow>=10.1 matplotlib>=3.7 scipy imageio-ffmpeg>=0.4.9 playwright>=1.40 scikit-fem gmsh \
	nbclient ipykernel ziglang>=0.13 pytest-xdist

.PHONY: venv develop test rust-test py-test lint demo bench clean browser docs-pictures

venv: $(VENV_STAMP)

# The set-up steps print one line each; their output goes to a log under .venv, printed
# only when a step fails (then the recipe fails too).
$(VENV_STAMP):
	@mkdir -p $(VENV)
	@echo "make: setting up $(VENV) (pip's output: $(VENV)/venv.log)"
	@{ test -x $(VPY) || $(PYTHON) -m venv $(VENV); } > $(VENV)/venv.log 2>&1 \
		&& $(VPY) -m pip install --quiet --upgrade pip >> $(VENV)/venv.log 2>&1 \
		&& $(VPY) -m pip install --quiet $(foreach t,$(DEV_TOOLS),'$(t)') >> $(VENV)/venv.log 2>&1 \
		|| { cat $(VENV)/venv.log >&2; echo "make: setting up $(VENV) failed (log: $(VENV)/venv.log)" >&2; exit 1; }
	@touch $@

develop: $(DEVELOP_STAMP)

# The extension is the wheel's (scripts/wheel.py develop: the zig release build, installed as
# an editable package, as `maturin develop` would): one release build serves both. Where
# the wheel cannot be built (no zig; exit 2), `maturin develop --release` does it instead.
$(DEVELOP_STAMP): $(VENV_STAMP) $(RUST_SOURCES) pyproject.toml
	@echo "make: building the extension and installing the package (log: $(VENV)/develop.log)"
	@VIRTUAL_ENV=$(abspath $(VENV)) PATH=$(abspath $(VENV))/bin:$$PATH; export VIRTUAL_ENV PATH; \
		$(VPY) scripts/wheel.py develop > $(VENV)/develop.log 2>&1; rc=$$?; \
		if [ $$rc = 2 ]; then $(VENV)/bin/maturin develop --release --quiet >> $(VENV)/develop.log 2>&1; rc=$$?; fi; \
		if [ $$rc != 0 ]; then cat $(VENV)/develop.log >&2; echo "make: the build failed (log: $(VENV)/develop.log)" >&2; exit 1; fi
	@touch $@

test: wheel-start rust-test develop lint py-test

rust-test:
	$(CARGO) fmt --all --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings
	$(CARGO) test

lint: $(DEVELOP_STAMP)
	$(VENV)/bin/ruff check python tests
	$(VENV)/bin/ruff format --check python tests
	MYPY_CACHE_DIR=$(VENV)/.mypy_cache $(VPY) -m mypy
	MYPY_CACHE_DIR=$(VENV)/.mypy_cache $(VPY) -m mypy.stubtest topomech._core

py-test: $(DEVELOP_STAMP) browser
	$(VPY) -m pytest -q -n auto

# The wheel: a release build with zig (the ziglang package) for glibc 2.17, in target/wheel
# (its log: .venv/wheel.log, printed when it fails); up to date when newer than every source.
# `make test` starts it first, in the background at the lowest priority (wheel-start), so
# that it uses the CPU the other steps leave idle; tests/test_wheel.py waits for it, then
# installs it into a fresh venv and runs the demo there.
.PHONY: wheel wheel-start
wheel: $(VENV_STAMP)
	@$(VPY) scripts/wheel.py build

wheel-start: $(VENV_STAMP)
	@$(VPY) scripts/wheel.py start

browser: $(VENV_STAMP)
	scripts/install_browser.sh $(VPY)

docs-pictures: $(DEVELOP_STAMP)
	$(VPY) scripts/make_docs_pictures.py

# --overwrite: out/demo may hold the outputs of a version that kept no manifest (they are
# replaced; other files there are kept)
demo: $(DEVELOP_STAMP)
	@$(VENV)/bin/topomech demo --overwrite

# 7.6 minutes on 2 cores on 2026-12-05 (everything below, the previews included); the engine
# bench skips, and records as skipped, a size that the
# previous one predicts over its budget (TOPOMECH_BENCH_* variables: crates/physics/benches/engine.rs).
bench:
	set -o pipefail; $(CARGO) bench -p topomech-gmap --bench kernel | tee bench/kernel.txt
	set -o pipefail; $(CARGO) bench -p topomech-physics --bench topology | tee bench/topology.txt
	$(CARGO) bench -p topomech-physics --bench cut_scaling
	@$(MAKE) --no-print-directory $(VENV_STAMP)
	$(VPY) bench/topology_plot.py
	$(CARGO) bench -p topomech-physics --bench engine
	$(PYTHON) bench/report.py
	@$(MAKE) --no-print-directory bench-previews
	@$(MAKE) --no-print-directory readme-perf

# The previews' cost against the stepping, per shipped scene (bench/previews.md and .json;
# names the scenes whose previews take longer than their stepping and longer than 0.15 s).
.PHONY: bench-previews
bench-previews: $(DEVELOP_STAMP)
	$(VPY) bench/previews.py

# The README's sections between <!-- perf...:begin --> and <!-- perf...:end -->, from the
# results (tests/test_readme_perf.py fails when one differs).
.PHONY: readme-perf
readme-perf:
	$(PYTHON) scripts/readme_perf.py

# The peers live in their own virtualenv, never in .venv: nothing in `make test` needs them.
# Each peer's install may fail on its own; bench/peers/run.py then reports it as "not
# installable here: <pip's last error line>" (from .venv-peers/install-status/).
PEERS_VENV := .venv-peers
PEERS_PY := $(PEERS_VENV)/bin/python
PEER_PACKAGES := newton==1.8.0 taichi==1.7.4 pypbd==2.2.2

.PHONY: bench-peers
bench-peers:
	test -x $(PEERS_PY) || $(PYTHON) -m venv $(PEERS_VENV)
	$(PEERS_PY) -m pip install --quiet --upgrade pip
	$(PEERS_PY) -m pip install --quiet 'maturin>=1.9.4,<2' numpy
	VIRTUAL_ENV=$(abspath $(PEERS_VENV)) PATH=$(abspath $(PEERS_VENV))/bin:$$PATH \
		$(PEERS_VENV)/bin/maturin develop --release --quiet
	mkdir -p $(PEERS_VENV)/install-status
	for spec in $(PEER_PACKAGES); do \
		name=$${spec%%==*}; log=$(PEERS_VENV)/install-status/$$name.log; \
		if $(PEERS_PY) -m pip install --quiet "$$spec" > $$log 2>&1; then \
			echo ok > $(PEERS_VENV)/install-status/$$name.status; \
		else \
			echo "$$spec not installed, see bench/peers/run.py's report"; \
			(grep -E '^ERROR|Error' $$log || tail -n 1 $$log) | tail -n 1 \
				> $(PEERS_VENV)/install-status/$$name.status; \
		fi; \
	done
	$(PEERS_PY) bench/peers/run.py

clean:
	$(CARGO) clean
	rm -rf $(VENV) out .pytest_cache .ruff_cache .mypy_cache .hypothesis
	rm -f python/topomech/_core*.so python/topomech/_core*.pyd
	find python tests -name __pycache__ -type d -prune -exec rm -rf {} +
