# Every target bootstraps .venv from a bare python3 (3.11+) and the pinned requirements.lock.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# The optional engines the tests exercise (CI installs and tests them; the demo does not need them).
EXTRAS_STAMP := $(VENV)/.installed-extras

.PHONY: demo test test-fast bench lint clean

# requirements-interop.lock: MAVProxy for tests/flights/test_interop.py, without its GUI dependencies.
$(STAMP): requirements.lock requirements-interop.lock pyproject.toml
	$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11) and "fleetline needs Python 3.11+")'
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -r requirements.lock
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --no-deps -r requirements-interop.lock
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	touch $(STAMP)

$(EXTRAS_STAMP): $(STAMP) requirements-ns3.lock requirements-study.lock
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -r requirements-ns3.lock
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -r requirements-study.lock
	touch $(EXTRAS_STAMP)

demo: $(STAMP)
	$(BIN)/python -m gcs.cli.demo

# The fast tier on both cores (pure policy and unit tests: no timing, no process, no IP socket),
# then the flights, two files at a time: they wait on mission time more than they compute
# (0.9 of a core for both workers), and lower their speed-up on a busy machine. One file per
# worker (--dist loadfile), so a module's flight fixture flies once.
# --durations: the slowest tests in every CI log, to keep CI under 15 minutes on a busy machine.
test: $(EXTRAS_STAMP)
	$(BIN)/python -m pytest -q -m "not slow" -n 2 --durations=5
	$(BIN)/python -m pytest -q -m slow -n 2 --dist loadfile --durations=15

# Unit, core, property and conformance tests: no process started, no IP socket (< 90 s).
test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow" -n 2

bench: $(EXTRAS_STAMP)
	$(BIN)/python -m bench

lint: $(STAMP)
	$(BIN)/ruff check fleetline fleetwire gcs medium planner vehicles tests bench
	$(BIN)/ruff format --check fleetline fleetwire gcs medium planner vehicles tests bench
	$(BIN)/mypy

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis .mypy_cache .ruff_cache
