# crowdstudy: the two commands of the README are `make demo` and `make test`.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
export CROWDSTUDY_CACHE := $(CURDIR)/build/cache
export WARP_CACHE_PATH := $(CURDIR)/build/warp-cache
export MPLBACKEND := Agg
export PYTHONUNBUFFERED := 1

.PHONY: setup demo test test-fast figures bench constraints clean

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

figures: setup
	$(PY) paper_figs/make_all.py

bench: setup
	$(VENV)/bin/crowdstudy bench all

# Re-resolve the newest allowed versions into constraints.txt (then `make test`, commit it).
constraints:
	@bash scripts/update_constraints.sh

clean:
	rm -rf build demo_out paper_figs/out paper_figs/cache
