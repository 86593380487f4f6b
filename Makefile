# The README's two commands are the contract: `make run` and `make test`.
# `make run` installs what the app needs and starts it on the simulated lab; `make test`
# adds the test and lint tools (pytest, ruff, mypy, the bluesky/PostgreSQL/dask extras).
# Each stage says what it does; pip shows a line per package it fetches or installs.
# --no-compile: pip does not byte-compile every module of every package it installs
# (scipy's, pandas', numba's test suites included), which took a fresh `make run` longer
# than everything else pip does; Python writes the bytecode of the modules the app
# actually imports on its first start (bench/README.md has the paired timing).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
RUN_STAMP := $(VENV)/.installed-run
DEV_STAMP := $(VENV)/.installed-dev
PIP    := $(BIN)/python -m pip install --disable-pip-version-check --progress-bar on --no-compile

.PHONY: run test check lint format typecheck bench venv clean

$(BIN)/python:
	@echo "goniolab: creating the virtual environment $(VENV) ..."
	$(PYTHON) -m venv $(VENV)

$(RUN_STAMP): pyproject.toml | $(BIN)/python
	@echo "goniolab: installing goniolab and the libraries it runs on into $(VENV) (a minute the first time) ..."
	$(PIP) -e .
	@touch $@

$(DEV_STAMP): pyproject.toml $(RUN_STAMP)
	@echo "goniolab: installing the test and lint tools and the optional extras ..."
	$(PIP) -e '.[dev]'
	@touch $@

venv: $(RUN_STAMP)

run: $(RUN_STAMP)
	@echo "goniolab: starting the TUI on the simulated lab (q quits) ..."
	$(BIN)/goniolab tui --config configs/lab-sim.toml --autostart --gloss-every 5

check: $(DEV_STAMP)
	$(BIN)/ruff check goniolab drivers sim labtoml tests bench
	$(BIN)/ruff format --check goniolab drivers sim labtoml tests bench
	$(BIN)/mypy

# Three workers on the two cores: the long end-to-end tests mostly wait (a lab clock at
# real time, a server starting, a driver's timeout), and a third worker runs other tests
# meanwhile; with two, a quarter to a half of the cores' time went idle (bench/README.md,
# "The test suite"). worksteal lets an idle worker take half of another's queue, and
# tests/conftest.py starts the tests marked slow first on each worker (the long end-to-end
# runs must not be the last ones left). --durations lists the slowest, to see one creep in.
# PYTHONDONTWRITEBYTECODE is dropped for the run: the suite starts hundreds of Python
# processes (xdist workers, `goniolab` subprocesses), and without bytecode each compiled the
# repository's modules again (about 5 s of CPU per worker's collection); Python writes them to
# the __pycache__ directories .gitignore already names, as any plain run does.
# 4 workers on 2 idle cores since the suite's CPU cut (issue 26): 170 s against 187 s for
# 3 in back-to-back pytest runs on a fresh clone (bench/README.md, "The suite's CPU")
PYTEST_WORKERS ?= 4
test: check
	env -u PYTHONDONTWRITEBYTECODE $(BIN)/python -m pytest -n $(PYTEST_WORKERS) --dist worksteal --durations=15 -q

format: $(DEV_STAMP)
	$(BIN)/ruff check --fix goniolab drivers sim labtoml tests bench
	$(BIN)/ruff format goniolab drivers sim labtoml tests bench

bench: $(RUN_STAMP)
	$(BIN)/python bench/bench_optics.py

clean:
	rm -rf $(VENV) .mypy_cache .pytest_cache .ruff_cache
