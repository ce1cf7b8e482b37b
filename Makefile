# Two entry points for a fresh Debian/Ubuntu machine: `make demo` and `make test`.
# Each creates .venv, installs what it needs (and the system libraries those
# packages load), then runs.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: test demo tour proto lint bench bench-swarm install clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet -e '.[dev,pointcloud,registration]'
	bash scripts/ensure-syslibs.sh
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q

demo: $(STAMP)
	$(VENV)/bin/mapctl demo

tour: $(STAMP)
	bash scripts/tour.sh

proto: $(STAMP)
	bash scripts/gen-proto.sh mapapi/_pb

lint: $(STAMP)
	$(VENV)/bin/ruff check mapapi mapctl tests
	$(VENV)/bin/ruff format --check mapapi mapctl tests
	$(VENV)/bin/mypy mapapi mapctl

bench: $(STAMP)
	$(VENV)/bin/mapctl bench local

bench-swarm: $(STAMP)
	bash scripts/bench-swarm.sh

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
