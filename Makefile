# Two entry points for a fresh Debian/Ubuntu machine: `make demo` and `make test`.
# Each creates .venv, installs what it needs into it, says what and why, then runs.
# `make demo` installs only what `mapctl demo` imports; `make test` everything the
# tests use (and the system library open3d loads). One stamp per set, so `make demo`
# then `make test` adds the test set to the same .venv.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
DEMO_STAMP := $(VENV)/.installed-demo
TEST_STAMP := $(VENV)/.installed-test
# `make check`: the tests without peer processes or swarms (the folders, less the tests
# marked slow), about a minute on 2 cores (tests/unit/test_makefile.py checks the list).
CHECK_TESTS := tests/unit tests/property tests/cli tests/sim

.PHONY: test check demo tour proto lint bench bench-swarm install clean bytecode

$(PY):
	@echo "==> creating the virtual environment $(VENV) with $(PYTHON); everything below installs into it"
	@$(PYTHON) -m venv $(VENV)
	@$(PY) -m pip install --quiet --upgrade pip

# What `mapctl demo` imports (mapctl/commands/demo.py, mapbench/demo/): the core
# dependencies, matplotlib for the two PNGs it draws and gtsam for `align`.
$(DEMO_STAMP): pyproject.toml | $(PY)
	@echo "==> installing mapapi and what the demo needs into $(VENV): click, rich, pyzmq, protobuf, numpy, matplotlib (the 'plot' extra) for its PNGs and gtsam (the 'registration' extra) to align the missions"
	@$(PY) -m pip install --quiet -e '.[plot,registration]'
	@touch $@

# The test set holds the demo set, so it marks both as installed.
$(TEST_STAMP): pyproject.toml | $(PY)
	@echo "==> installing mapapi and what the tests need into $(VENV): the test tools (the 'dev' extra: pytest, pytest-xdist, hypothesis, ruff, mypy, grpcio-tools, py-spy, evo), matplotlib, open3d-cpu for point clouds, gtsam for registration and rosbags for ROS bags"
	@$(PY) -m pip install --quiet -e '.[dev,plot,pointcloud,registration,rosbag]'
	@bash scripts/ensure-syslibs.sh
	@touch $@ $(DEMO_STAMP)

install: $(TEST_STAMP)

# Every mapctl command and peer daemon is a new Python process. Where
# PYTHONDONTWRITEBYTECODE is set (as on this project's machines) no process writes
# the compiled modules, so each compiled the whole package again: a third of a
# command's start, CPU time taken from the daemons it talks to. Compiled once here.
bytecode: | $(PY)
	@$(PY) -m compileall -q -j 0 mapapi mapctl mapbench

# Two test files at a time (pytest-xdist, one file per worker so that a file's
# shared fixtures run once): most tests wait on processes and sockets, and one at
# a time left a core idle. The tests marked `alone` measure the machine's timing
# (a daemon's loop lag under load), so they run afterwards with nothing beside them.
test: $(TEST_STAMP) bytecode
	@echo "==> running the whole test suite: about 12 minutes on 2 cores, two test files at a time, then the timing tests alone (make check: the quick part, about a minute and a half)"
	$(PY) -m pytest -n 2 --dist loadfile -m "not alone" --durations=10
	$(PY) -m pytest -m alone --durations=3

check: $(TEST_STAMP)
	@echo "==> running the quick tests ($(CHECK_TESTS), not the ones marked slow; 100 simulator seeds per mode, of make test's 300 + 200): about a minute on 2 cores; make test runs them all"
	SIM_SEEDS=100 $(PY) -m pytest $(CHECK_TESTS) -m "not slow" --durations=5

demo: $(DEMO_STAMP) bytecode
	$(VENV)/bin/mapctl demo

tour: $(DEMO_STAMP)
	bash scripts/tour.sh

proto: $(TEST_STAMP)
	bash scripts/gen-proto.sh mapapi/_pb

lint: $(TEST_STAMP)
	$(VENV)/bin/ruff check mapapi mapctl mapbench tests
	$(VENV)/bin/ruff format --check mapapi mapctl mapbench tests
	$(VENV)/bin/mypy mapapi mapctl mapbench

bench: $(TEST_STAMP)
	$(VENV)/bin/mapctl bench local

bench-swarm: $(TEST_STAMP)
	bash scripts/bench-swarm.sh

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
