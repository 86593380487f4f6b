# The README's two commands are the contract: `make run` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test check lint format typecheck bench venv clean

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

venv: $(STAMP)

run: $(STAMP)
	$(BIN)/goniolab tui --config configs/lab-sim.toml --autostart --gloss-every 5

check: $(STAMP)
	$(BIN)/ruff check goniolab drivers sim tests bench
	$(BIN)/ruff format --check goniolab drivers sim tests bench
	$(BIN)/mypy

test: check
	$(BIN)/python -m pytest -n 2 -q

format: $(STAMP)
	$(BIN)/ruff check --fix goniolab drivers sim tests bench
	$(BIN)/ruff format goniolab drivers sim tests bench

bench: $(STAMP)
	$(BIN)/python bench/bench_optics.py

clean:
	rm -rf $(VENV) .mypy_cache .pytest_cache .ruff_cache
