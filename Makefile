# crowdstudy: the two commands of the README are `make demo` and `make test`.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
export CROWDSTUDY_CACHE := $(CURDIR)/build/cache
export WARP_CACHE_PATH := $(CURDIR)/build/warp-cache
export MPLBACKEND := Agg
export PYTHONUNBUFFERED := 1

.PHONY: setup demo test test-fast lint figures bench docs results constraints clean

setup:
	@bash scripts/setup.sh

demo: setup
	$(VENV)/bin/crowdstudy demo

# pytest-xdist: one worker per CPU core, each test file on one worker (module fixtures once),
# the files in the order tests/conftest.py gives them (the slowest first)
test: setup
	$(PY) -m pytest -q -n auto --dist loadfile --no-loadscope-reorder

test-fast: setup
	$(PY) -m pytest -q -n auto --dist loadfile --no-loadscope-reorder -m "not slow and not browser"

# ruff's lint and format check on every Python folder, pyright on the package (settings in
# pyproject.toml); .pre-commit-config.yaml runs the same on each commit
LINT_DIRS := crowdstudy tests benchmarks paper_figs scripts analysis
lint: setup
	$(VENV)/bin/ruff check $(LINT_DIRS)
	$(VENV)/bin/ruff format --check $(LINT_DIRS)
	$(VENV)/bin/pyright

figures: setup
	$(PY) paper_figs/make_all.py

bench: setup
	$(VENV)/bin/crowdstudy bench all

# The documentation site, offline, into build/site (open build/site/index.html). Warnings
# are errors. The CLI, API, file-format and results pages are generated at build time
# (scripts/docs_hooks.py, scripts/results_pages.py).
docs: setup
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --quiet
	@echo "[docs] built build/site/index.html"

# Publish benchmark reports in the docs: copy build/bench/NAME.json (from `crowdstudy bench
# NAME`) to docs/results/data/ for each NAME in RESULTS (default: the ones published already),
# with its figure build/bench/NAME.png where there is one.
RESULTS ?= $(basename $(notdir $(wildcard docs/results/data/*.json)))
results:
	@mkdir -p docs/results/data
	@for name in $(RESULTS); do \
	    test -f build/bench/$$name.json || { echo "[results] build/bench/$$name.json missing: run crowdstudy bench first" >&2; exit 1; }; \
	    cp build/bench/$$name.json docs/results/data/$$name.json && echo "[results] docs/results/data/$$name.json"; \
	    if test -f build/bench/$$name.png; then \
	        cp build/bench/$$name.png docs/results/data/$$name.png && echo "[results] docs/results/data/$$name.png"; fi; \
	done

# Re-resolve the newest allowed versions into constraints.txt (then `make test`, commit it).
constraints:
	@bash scripts/update_constraints.sh

clean:
	rm -rf build demo_out paper_figs/out paper_figs/cache
